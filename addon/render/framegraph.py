"""The frame graph: passes that declare what they provide, read, write and keep.

The pass contract (docs/ARCHITECTURE.md):

* ``provides``: the effects a pass contributes (``Effect``); the planner runs a pass only
  when the scene calls for one of them, or when a running pass reads what it writes.
* ``reads`` / ``writes``: resource names (a pass that writes what a running pass reads
  runs too; ``optional_reads`` are used when present and pull nothing in) (``"gbuffer.normal"``, ``"shadow.atlas"``,
  ``"color"``); ``history``: resources kept across frames (reset on any parameter change).
* ``params``: ``Param`` declarations with ranges; ``quality_ladder``: one dict of parameter
  values per quality level (the cost/accuracy sweep walks it).
* ``compile(rc)`` allocates for the current size, ``execute(rc, frame)`` runs named steps.

Techniques (``techniques/``) are lists of passes. The graph is plain Python data; its
properties round-trip through ``get_properties``/``set_properties``.
"""
from __future__ import annotations

import enum
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .result import SkippedPass

log = logging.getLogger(__name__)


class Effect(str, enum.Enum):
    DIRECT = "direct"  # direct light from lights
    SHADOWS = "shadows"
    EMISSION = "emission"  # emissive surfaces seen directly and lighting others
    ENVIRONMENT = "environment"  # world background / world light
    INDIRECT_DIFFUSE = "indirect_diffuse"
    INDIRECT_SPECULAR = "indirect_specular"
    AO = "ao"


@dataclass(frozen=True)
class Param:
    name: str
    default: float | int | bool
    min: float | None = None
    max: float | None = None
    doc: str = ""

    def clamp(self, value):
        if isinstance(self.default, bool):
            return bool(value)
        if isinstance(self.default, int):
            value = int(round(value))
        else:
            value = float(value)
        if self.min is not None:
            value = max(self.min, value)
        if self.max is not None:
            value = min(self.max, value)
        return type(self.default)(value)


class Pass:
    """Base class of every pass. Subclasses set the class attributes and implement
    ``compile`` and ``execute``."""

    name: str = "pass"
    provides: frozenset = frozenset()
    reads: tuple = ()
    optional_reads: tuple = ()  # used if some running pass wrote them (e.g. shadows)
    writes: tuple = ()
    history: tuple = ()
    params: tuple = ()  # of Param
    quality_ladder: tuple = ()  # of dicts, index = quality level
    always: bool = False  # runs whatever the scene needs (e.g. the G-buffer, the final resolve)

    def __init__(self, quality: int | None = None, **props):
        self.props = {p.name: p.default for p in self.params}
        if quality is not None and self.quality_ladder:
            q = max(0, min(int(quality), len(self.quality_ladder) - 1))
            self.set_properties(self.quality_ladder[q])
        self.set_properties(props)
        self.history_valid = False

    # -------------------------------------------------------------- properties
    def get_properties(self) -> dict:
        return dict(self.props)

    def set_properties(self, props: dict):
        decl = {p.name: p for p in self.params}
        changed = False
        for k, v in props.items():
            if k not in decl:
                log.warning("pass %s: unknown property %r ignored", self.name, k)
                continue
            v = decl[k].clamp(v)
            if self.props.get(k) != v:
                self.props[k] = v
                changed = True
        if changed:
            self.reset_history()

    def __getitem__(self, key):
        return self.props[key]

    # -------------------------------------------------------------- lifecycle
    def compile(self, rc: "RenderContext"):
        """Allocate resources for ``rc.size``. Called when the size or scene layout changes."""

    def execute(self, rc: "RenderContext", frame: "FrameState"):
        raise NotImplementedError

    def reset_history(self):
        self.history_valid = False

    def release(self):
        """Free GL objects this pass owns (resources in rc.resources are freed by the graph)."""


@dataclass
class FrameState:
    """Per-frame values every pass can read."""

    index: int = 0  # frame number within the current accumulation (0 = first)
    sample: int = 0  # global sample counter (seeds)
    jitter: tuple = (0.0, 0.0)  # sub-pixel offset in pixels, in [-0.5, 0.5)
    view: np.ndarray | None = None
    proj: np.ndarray | None = None  # jittered projection
    proj_unjittered: np.ndarray | None = None
    prev_view_proj: np.ndarray | None = None
    camera_changed: bool = True
    scene_changed: bool = True
    seed: int = 0


class Resources(dict):
    """Named GL objects shared by passes (textures, buffers, framebuffers)."""

    def need(self, name: str, owner: str):
        if name not in self:
            raise KeyError(f"pass '{owner}' reads resource '{name}', which no pass has written")
        return self[name]

    def release(self):
        for obj in self.values():
            try:
                obj.release()
            except Exception:
                pass
        self.clear()


class RenderContext:
    """What passes see: the GL context, compiled programs, the GPU scene, resources, size."""

    def __init__(self, ctx, programs, gpu_scene, size: tuple[int, int]):
        self.ctx = ctx
        self.programs = programs
        self.scene = gpu_scene
        self.size = size  # (width, height)
        self.resources = Resources()
        self.timers: dict[str, float] = {}

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    def texture(self, name: str, components: int = 4, dtype: str = "f4", size=None, *, filter_linear=False):
        """Get or create a 2D texture resource of the frame size (or ``size``)."""
        size = tuple(size or self.size)
        tex = self.resources.get(name)
        if tex is not None and tex.size == size and tex.components == components and tex.dtype == dtype:
            return tex
        if tex is not None:
            tex.release()
        tex = self.ctx.texture(size, components, dtype=dtype)
        import moderngl

        tex.filter = (moderngl.LINEAR, moderngl.LINEAR) if filter_linear else (moderngl.NEAREST, moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        self.resources[name] = tex
        return tex

    def dispatch(self, program, groups_x: int, groups_y: int = 1, groups_z: int = 1):
        program.run(max(1, groups_x), max(1, groups_y), max(1, groups_z))

    def groups(self, local: int = 8) -> tuple[int, int]:
        return (self.width + local - 1) // local, (self.height + local - 1) // local


@dataclass
class Plan:
    active: list
    skipped: list[SkippedPass] = field(default_factory=list)


class FrameGraph:
    """An ordered list of passes, planned against the effects the scene calls for."""

    def __init__(self, passes: list[Pass]):
        names = [p.name for p in passes]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate pass names in graph: {names}")
        self.passes = list(passes)
        self._plan: Plan | None = None
        self._compiled_size = None

    def __iter__(self):
        return iter(self.passes)

    def find(self, name: str) -> Pass:
        for p in self.passes:
            if p.name == name:
                return p
        raise KeyError(name)

    # ------------------------------------------------------------------ planning
    def plan(self, needed: set, reasons: dict[str, str] | None = None) -> Plan:
        """Choose the passes to run: those that provide a needed effect or are ``always``,
        plus (transitively) every earlier pass that writes a resource a chosen pass reads.
        ``reasons`` maps an effect to why the scene does not need it."""
        reasons = reasons or {}
        chosen = [p.always or bool(p.provides & needed) for p in self.passes]
        # a kept pass pulls in the passes before it that write what it reads (producers run
        # before consumers: a later pass writing the same resource is not a producer of it)
        for i in range(len(self.passes) - 1, -1, -1):
            if not chosen[i]:
                continue
            for j in range(i - 1, -1, -1):
                if not chosen[j] and set(self.passes[i].reads).intersection(self.passes[j].writes):
                    chosen[j] = True
        active, skipped = [], []
        for p, c in zip(self.passes, chosen):
            if c:
                active.append(p)
            else:
                why = "; ".join(reasons.get(e, f"scene does not need {e.value}") for e in
                                sorted(p.provides, key=lambda e: e.value)) or "not needed"
                skipped.append(SkippedPass(p.name, sorted(e.value for e in p.provides), why))
        self._plan = Plan(active, skipped)
        return self._plan

    # ------------------------------------------------------------------ running
    def compile(self, rc: RenderContext, force: bool = False):
        if force or self._compiled_size != rc.size:
            for p in self.passes:
                p.compile(rc)
                p.reset_history()
            self._compiled_size = rc.size

    def execute(self, rc: RenderContext, frame: FrameState, *, timers: bool = True) -> dict[str, float]:
        """Run the planned passes; returns GPU milliseconds per pass (timer queries)."""
        if self._plan is None:
            raise RuntimeError("FrameGraph.execute before plan()")
        times: dict[str, float] = {}
        for p in self._plan.active:
            if timers:
                q = rc.ctx.query(time=True)
                with q:
                    p.execute(rc, frame)
                times[p.name] = q.elapsed / 1e6 if q.elapsed else 0.0
            else:
                t0 = time.perf_counter()
                p.execute(rc, frame)
                times[p.name] = (time.perf_counter() - t0) * 1e3
        return times

    def reset_history(self):
        for p in self.passes:
            p.reset_history()

    def get_properties(self) -> dict:
        return {p.name: p.get_properties() for p in self.passes}

    def set_properties(self, props: dict):
        for name, values in props.items():
            try:
                self.find(name).set_properties(values)
            except KeyError:
                log.warning("graph: unknown pass %r in properties", name)

    def release(self):
        for p in self.passes:
            p.release()
