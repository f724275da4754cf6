"""Shader composition: ``#include`` resolution, defines, and errors that name file and line.

Every shader file lives under ``shaders/`` (``lib/`` for the shared math, one folder per
technique family). A file is composed by prepending ``#version 430``, the requested
``#define``s, and expanding ``#include "lib/x.glsl"`` lines recursively (each file at most
once). ``#line`` directives carry a file number so that a compiler message such as
``3:42(7): error ...`` is rewritten to ``lib/brdf.glsl:42``. Composition is strict: a
missing include or a define value that is not a plain number/identifier is an error naming
the shader. Composition needs no GPU, so tests check it everywhere.
"""
from __future__ import annotations

import re
import time
from pathlib import Path

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_ERRLOC = re.compile(r"\b(\d+):(\d+)\(\d+\)")
_DEFINE_VALUE = re.compile(r"^[-+]?[0-9A-Za-z_.()+\-*/ ]*$")


class ShaderError(RuntimeError):
    """A shader could not be composed or compiled; the message names file and line."""


def shader_roots() -> list[Path]:
    """Folders searched for shaders: inside the installed package first, then the checkout."""
    pkg = Path(__file__).resolve().parent.parent
    roots = [pkg / "shaders", pkg.parent / "shaders"]
    return [r for r in roots if r.is_dir()]


class ShaderSource:
    """A composed shader: text plus the table mapping #line file numbers to paths."""

    def __init__(self, name: str, text: str, files: list[str]):
        self.name = name
        self.text = text
        self.files = files

    def explain(self, message: str) -> str:
        """Rewrite compiler locations ``N:LINE(COL)`` into ``path:LINE``."""

        def sub(m):
            idx, line = int(m.group(1)), int(m.group(2))
            if 0 <= idx < len(self.files):
                return f"{self.files[idx]}:{line}"
            return m.group(0)

        return _ERRLOC.sub(sub, message)


class ShaderLibrary:
    def __init__(self, roots: list[Path] | None = None):
        self.roots = [Path(r) for r in (roots or shader_roots())]
        if not self.roots:
            raise ShaderError("GI Preview cannot find its 'shaders' folder next to the add-on")

    def find(self, rel: str) -> Path:
        for root in self.roots:
            p = root / rel
            if p.is_file():
                return p
        raise ShaderError(f"shader file '{rel}' not found in {', '.join(map(str, self.roots))}")

    def compose(self, rel: str, defines: dict | None = None) -> ShaderSource:
        files: list[str] = []
        seen: set[str] = set()
        out: list[str] = ["#version 430"]
        for key, value in sorted((defines or {}).items()):
            if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", str(key)):
                raise ShaderError(f"{rel}: bad define name {key!r}")
            if isinstance(value, bool):
                value = int(value)
            if isinstance(value, float):
                value = repr(float(value))
            if not _DEFINE_VALUE.match(str(value)):
                raise ShaderError(f"{rel}: define {key} has a value that is not a number or name: {value!r}")
            out.append(f"#define {key} {value}")

        def expand(path_rel: str, chain: tuple[str, ...]):
            if path_rel in chain:
                raise ShaderError(f"include cycle: {' -> '.join(chain + (path_rel,))}")
            if path_rel in seen:
                return
            seen.add(path_rel)
            idx = len(files)
            files.append(path_rel)
            text = self.find(path_rel).read_text()
            out.append(f"#line 1 {idx}")
            for n, line in enumerate(text.splitlines(), start=1):
                m = _INCLUDE.match(line)
                if m:
                    try:
                        expand(m.group(1), chain + (path_rel,))
                    except ShaderError as exc:
                        raise ShaderError(f"{path_rel}:{n}: {exc}") from None
                    out.append(f"#line {n + 1} {idx}")
                elif line.lstrip().startswith("#version"):
                    out.append("")  # the composer owns the version line
                else:
                    out.append(line)

        expand(rel, ())
        return ShaderSource(rel, "\n".join(out) + "\n", files)


_default: ShaderLibrary | None = None


def library() -> ShaderLibrary:
    global _default
    if _default is None:
        _default = ShaderLibrary()
    return _default


BRDF_LUT_UNIT = 30  # fixed texture unit of lib/brdf_tables.glsl's u_brdf_lut
LUT_ROWS = 16
_luts: dict = {}


def brdf_lut(ctx):
    """Cycles' GGX albedo tables (render/brdf_tables.py) as one R32F texture of ``ctx``
    (1024 x 15: GGX_E, GGX_EAVG, then GGX_SCHLICK_S, GGX_GLASS_E and GGX_GLASS_INV_E in four
    rows each, SHEEN_E, then SHEEN_ALBEDO of render/sheen_table.py), made once per context."""
    key = id(ctx)
    hit = _luts.get(key)
    if hit is not None and hit[0] is ctx:
        return hit[1]
    import numpy as np

    from . import brdf_tables as T

    data = np.zeros((LUT_ROWS, 1024), np.float32)
    data[0, :1024] = T.GGX_E
    data[1, :32] = T.GGX_EAVG
    data[2:6] = np.asarray(T.GGX_SCHLICK_S, np.float32).reshape(4, 1024)
    data[6:10] = np.asarray(T.GGX_GLASS_E, np.float32).reshape(4, 1024)
    data[10:14] = np.asarray(T.GGX_GLASS_INV_E, np.float32).reshape(4, 1024)
    data[14] = T.SHEEN_E
    from .sheen_table import SHEEN_ALBEDO
    data[15] = SHEEN_ALBEDO
    tex = ctx.texture((1024, LUT_ROWS), 1, data.tobytes(), dtype="f4")
    import moderngl

    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    _luts[key] = (ctx, tex)
    return tex


def bind_tables(ctx, prog) -> None:
    """Point a program's u_brdf_lut at the tables (texture and sampler unit)."""
    try:
        u = prog["u_brdf_lut"]
    except KeyError:
        return
    brdf_lut(ctx).use(BRDF_LUT_UNIT)
    u.value = BRDF_LUT_UNIT


_DRIVER_CACHE_SALT: int | None = None


def set_driver_cache_salt(salt: int | None):
    """Add ``#define GI_DRIVER_CACHE_SALT salt`` to every program compiled from now on (None:
    none). The driver's on-disk shader cache is keyed by the source, so a new salt makes every
    compile a cold one, as on a first start after installing the add-on or a driver, whatever
    this process or an earlier one compiled before. For measuring setup; renders are unchanged."""
    global _DRIVER_CACHE_SALT
    _DRIVER_CACHE_SALT = None if salt is None else int(salt)


def _salted(defines: dict | None) -> dict | None:
    if _DRIVER_CACHE_SALT is None:
        return defines
    return {**(defines or {}), "GI_DRIVER_CACHE_SALT": _DRIVER_CACHE_SALT}


class ProgramCache:
    """Compiled programs of one GL context, keyed by (stages, defines). Compile once, reuse."""

    def __init__(self, ctx, lib: ShaderLibrary | None = None):
        self.ctx = ctx
        self.lib = lib or library()
        self._programs: dict = {}
        self.compile_ms = 0.0  # total time spent composing and compiling (one-time setup)

    @staticmethod
    def _key(stages: dict, defines: dict | None):
        return (tuple(sorted(stages.items())), tuple(sorted((defines or {}).items())))

    def compute(self, rel: str, defines: dict | None = None):
        defines = _salted(defines)
        key = self._key({"comp": rel}, defines)
        prog = self._programs.get(key)
        if prog is None:
            t0 = time.perf_counter()
            src = self.lib.compose(rel, defines)
            try:
                prog = self.ctx.compute_shader(src.text)
            except Exception as exc:
                raise ShaderError(f"compiling {rel}: {src.explain(str(exc))}") from None
            bind_tables(self.ctx, prog)
            self._programs[key] = prog
            self.compile_ms += (time.perf_counter() - t0) * 1e3
        return prog

    def program(self, vertex: str, fragment: str | None = None, defines: dict | None = None,
                geometry: str | None = None):
        """A raster program; ``geometry`` adds a geometry stage (layered rendering with
        ``gl_Layer``: cube maps, voxelisation)."""
        defines = _salted(defines)
        key = self._key({"vert": vertex, "frag": fragment or "", "geom": geometry or ""}, defines)
        prog = self._programs.get(key)
        if prog is None:
            t0 = time.perf_counter()
            vs = self.lib.compose(vertex, defines)
            fs = self.lib.compose(fragment, defines) if fragment else None
            gs = self.lib.compose(geometry, defines) if geometry else None
            try:
                prog = self.ctx.program(vertex_shader=vs.text, fragment_shader=fs.text if fs else None,
                                        geometry_shader=gs.text if gs else None)
            except Exception as exc:
                msg = str(exc)
                low = msg.lower()
                where = fs if fs is not None and "fragment" in low else gs if gs is not None and "geometry" in low else vs
                raise ShaderError(f"compiling {vertex} + {geometry or ''} + {fragment}: {where.explain(msg)}") from None
            bind_tables(self.ctx, prog)
            self._programs[key] = prog
            self.compile_ms += (time.perf_counter() - t0) * 1e3
        return prog

    def release(self):
        for p in self._programs.values():
            try:
                p.release()
            except Exception:
                pass
        self._programs.clear()
