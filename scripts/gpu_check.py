#!/usr/bin/env python3
"""One-shot consistency and timing check of every technique on another machine (a GPU).

Two modes:

``--export DIR`` (needs the ``bpy`` module, e.g. ``.venv/bin/python``)
    Builds every demo scene (``addon/blender/demo_scenes.py``) and exports it through
    ``export.export_scene`` into ``DIR/<scene>.pkl``: a pickled dict holding the SceneData
    at the check resolution (``--res``, default 96x96) and the scene's camera exported at
    the timing resolution (``--timing-res``, default 1920x1080, so the 16:9 projection is
    Blender's own). The pickles hold only dataclasses, enums, plain Python values and numpy
    arrays: they load without bpy and under numpy 2.

``--check DIR --out OUT`` (bpy-free: numpy, moderngl and ``addon/render`` +
``addon/compare/metrics`` only; bpy, OpenImageIO and flip_evaluator are blocked from import)
    For every pickled scene and every registered technique id (quality 1, the engine's
    ``Technique Default`` denoiser) renders ``--samples`` accumulated frames at the pickled
    resolution through ``session.render`` as an F12 render does (camera cut, warm-up, seeds
    = accumulation index), in a fresh session per render, and records finite pixel count,
    mean, wall time, setup and frame time. Writes into OUT (at most four files):

    * ``images.npz``   one float32 (H, W, 3) array per ``<scene>__<technique>`` (row 0 = bottom)
    * ``results.json`` everything measured (renders, comparison, timing, errors, GL info)
    * ``results.md``   the same as tables
    * ``contact.png``  all images tiled (Standard view), scenes in rows, techniques in columns

    ``--compare REF`` (a folder written by an earlier ``--check``, e.g. on llvmpipe): relMSE
    of every image against REF's image of the same scene and technique, and the ratio of
    means. ``--timing``: at ``--timing-res`` on ``--timing-scenes``, per technique one
    untimed priming render (shader compiles, allocation, BVH), then one F12-like render
    whose every frame is timed on the GL thread (the session finishes GL work in each
    frame): warm-up frames are reported apart from the ``--timing-frames`` accumulated
    frames (median, min, max ms; one-time work inside a frame is subtracted as the session
    does), plus the GPU timer-query sum of the last frame's passes. A frame over
    ``--frame-limit-s`` ends that technique's timing (recorded). Budgets (``--check-budget-s``,
    ``--timing-budget-s``) skip what is left (recorded), and ``--deadline-s`` writes what
    has been measured and exits. Any technique that raises is recorded with its error and
    the run goes on (in a fresh session).

The GPU machine (Python 3.12, numpy 2, no bpy, no network; the repository root as working
directory with ``.gpucheck``, ``.whl`` and ``.gl`` carried), see scripts/gpu_check.md::

    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site:$PWD; \
    for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig; \
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json; \
    python3 scripts/gpu_check.py --check .gpucheck/scenes --compare .gpucheck/llvmpipe --timing \
        --out $OUT/gpu

Here (llvmpipe)::

    .venv/bin/python scripts/gpu_check.py --export .gpucheck/scenes
    .venv/bin/python scripts/gpu_check.py --check .gpucheck/scenes --out .gpucheck/llvmpipe
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.abc
import importlib.util
import json
import math
import os
import pickle
import platform
import statistics
import struct
import sys
import threading
import time
import traceback
import zlib

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON = os.path.join(REPO, "addon")
FORMAT = 1
SCENES = ("cornell", "glossy_spheres", "sunlit_room", "emissive_panel", "many_lights")
BLOCKED = ("bpy", "OpenImageIO", "flip_evaluator", "mathutils", "bmesh")
T0 = time.perf_counter()


def log(msg: str):
    print(f"[gpu_check {time.perf_counter() - T0:7.1f}s] {msg}", flush=True)


# ---------------------------------------------------------------------------- imports
class _Blocker(importlib.abc.MetaPathFinder):
    """Refuses the modules the bpy-free check must not use (so a stray import fails here,
    on a machine that has them, as it would on the GPU machine)."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"gpu_check --check must not import {name!r} (bpy-free mode)")
        return None


def import_package():
    """``gi_preview`` = this checkout's ``addon/`` (its __init__ imports bpy only in register())."""
    if "gi_preview" in sys.modules:
        return sys.modules["gi_preview"]
    spec = importlib.util.spec_from_file_location("gi_preview", os.path.join(ADDON, "__init__.py"),
                                                  submodule_search_locations=[ADDON])
    mod = importlib.util.module_from_spec(spec)
    sys.modules["gi_preview"] = mod
    spec.loader.exec_module(mod)
    return mod


# ---------------------------------------------------------------------------- export
def parse_res(s: str) -> tuple[int, int]:
    if "x" in s:
        w, h = s.lower().split("x")
        return int(w), int(h)
    return int(s), int(s)


def do_export(a):
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _checkout  # noqa: E402  (scripts/_checkout.py)

    _checkout.setup_blender()
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene

    out = os.path.abspath(a.export)
    os.makedirs(out, exist_ok=True)
    w, h = parse_res(a.res)
    tw, th = parse_res(a.timing_res)
    names = [s for s in (a.scenes.split(",") if a.scenes else [d[0] for d in demo_scenes.DEMO_SCENES]) if s]
    for name in names:
        t0 = time.perf_counter()
        sc = demo_scenes.build_demo(name, resolution=max(w, h))
        dg = reference.evaluated_depsgraph(sc)
        sd = export_scene(dg, width=w, height=h)
        wide = export_scene(dg, width=tw, height=th)
        blob = {"format": FORMAT, "name": name, "scene": sd, "timing_camera": wide.camera,
                "timing_size": (tw, th), "fingerprint": sd.fingerprint(),
                "triangles": sd.triangle_count, "lights": len(sd.lights),
                "exported_with": {"bpy": bpy.app.version_string, "numpy": np.__version__,
                                  "python": platform.python_version()}}
        path = os.path.join(out, f"{name}.pkl")
        with open(path + ".tmp", "wb") as f:
            pickle.dump(blob, f, protocol=4)
        os.replace(path + ".tmp", path)
        log(f"exported {name}: {sd.triangle_count} triangles, {len(sd.lights)} lights, {w}x{h} "
            f"(+ camera at {tw}x{th}), {os.path.getsize(path) / 1024:.0f} KiB in "
            f"{(time.perf_counter() - t0) * 1e3:.0f} ms")
    log("export done")


# ---------------------------------------------------------------------------- loading
def _fill_defaults(obj, seen=None):
    """Dataclass objects unpickled from an older scene_data.py get the defaults of fields
    added since (pickle restores ``__dict__`` as it was)."""
    seen = seen if seen is not None else set()
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            if f.name not in obj.__dict__:
                if f.default is not dataclasses.MISSING:
                    setattr(obj, f.name, f.default)
                elif f.default_factory is not dataclasses.MISSING:
                    setattr(obj, f.name, f.default_factory())
            _fill_defaults(getattr(obj, f.name, None), seen)
    elif isinstance(obj, (list, tuple)):
        for x in obj:
            _fill_defaults(x, seen)


def load_scenes(folder: str, wanted: list[str] | None) -> dict:
    out = {}
    names = sorted(f[:-4] for f in os.listdir(folder) if f.endswith(".pkl"))
    order = [s for s in SCENES if s in names] + [s for s in names if s not in SCENES]
    for name in order:
        if wanted and name not in wanted:
            continue
        with open(os.path.join(folder, f"{name}.pkl"), "rb") as f:
            blob = pickle.load(f)
        _fill_defaults(blob["scene"])
        _fill_defaults(blob.get("timing_camera"))
        out[name] = blob
    return out


def timing_scene(blob):
    """The scene at the timing resolution with the camera exported for that aspect."""
    sd = dataclasses.replace(blob["scene"])
    sd.width, sd.height = (int(v) for v in blob["timing_size"])
    sd.camera = blob["timing_camera"]
    return sd


# ---------------------------------------------------------------------------- output
def png_bytes(rgb8) -> bytes:
    """A minimal 8-bit RGB PNG encoder (zlib, filter 0), top row first."""
    import numpy as np

    a = np.ascontiguousarray(rgb8, np.uint8)
    h, w = a.shape[:2]
    raw = np.concatenate([np.zeros((h, 1), np.uint8), a.reshape(h, w * 3)], axis=1).tobytes()

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def contact_sheet(images: dict, scenes: list, techs: list):
    import numpy as np
    from gi_preview.compare.metrics import view_standard

    shapes = [v.shape for v in images.values()]
    if not shapes:
        return None
    h = max(s[0] for s in shapes)
    w = max(s[1] for s in shapes)
    pad = 2
    sheet = np.full((len(scenes) * (h + pad), len(techs) * (w + pad), 3), 40, np.uint8)
    for i, s in enumerate(scenes):
        for j, t in enumerate(techs):
            img = images.get(f"{s}__{t}")
            if img is None:
                continue
            ldr = (view_standard(img) * 255.0 + 0.5).astype(np.uint8)[::-1]  # bottom-up -> top row first
            y, x = i * (h + pad), j * (w + pad)
            sheet[y:y + ldr.shape[0], x:x + ldr.shape[1]] = ldr
    return sheet


def _fmt(v, spec=".3g"):
    if v is None:
        return "-"
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return format(v, spec) if isinstance(v, (int, float)) else str(v)


def markdown(state: dict) -> str:
    m = state["meta"]
    lines = [f"# gpu_check: {m.get('gl', {}).get('GL_RENDERER', '?')}", "",
             f"{m.get('gl', {}).get('GL_VERSION', '?')}; python {m['python']}, numpy {m['numpy']}, "
             f"moderngl {m.get('moderngl', '?')}; "
             + ", ".join(f"{k} {v}" for k, v in m["settings"].items() if v is not None), ""]
    if state.get("status"):
        lines += [f"**Status:** {state['status']}", ""]
    if state["renders"]:
        cmp = {(c["scene"], c["technique"]): c for c in state.get("compare", [])}
        lines += [f"## Renders ({m['settings'].get('res')}, {m['settings'].get('samples')} samples, quality 1)", "",
                  "| scene | technique | ok | finite px | mean | mean / ref | relMSE vs ref | warm-up | time s | frame ms | error |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in state["renders"]:
            c = cmp.get((r["scene"], r["technique"]), {})
            err = (r.get("error") or "").replace("|", "/").replace("\n", " ")[:120]
            fin = f"{r['finite_px']}/{r['pixels']}" if r.get("pixels") else "-"
            lines.append(f"| {r['scene']} | {r['technique']} | {'yes' if r['ok'] else 'NO'} | {fin} | "
                         f"{_fmt(r.get('mean'))} | {_fmt(c.get('mean_ratio'), '.4f')} | "
                         f"{_fmt(c.get('relmse'), '.3g')} | {_fmt(r.get('warmup_frames'))} | "
                         f"{_fmt(r.get('time_s'), '.2f')} | {_fmt(r.get('frame_ms'), '.1f')} | {err} |")
        lines.append("")
    if state.get("compare_meta"):
        lines += [f"Reference: {state['compare_meta']}", ""]
    if state.get("repeat"):
        lines += ["## Run to run (the same render twice on this machine)", "",
                  "| scene | technique | identical | relMSE | max abs diff |", "|---|---|---|---|---|"]
        for c in state["repeat"]:
            lines.append(f"| {c['scene']} | {c['technique']} | "
                         f"{'ERR ' + str(c['error'])[:80] if c.get('error') else ('yes' if c.get('identical') else 'no')} | "
                         f"{_fmt(c.get('relmse'))} | {_fmt(c.get('max_abs_diff'))} |")
        lines.append("")
    if state.get("timing"):
        lines += [f"## Timing ({m['settings'].get('timing_res')}, quality 1, ms per frame)", "",
                  "| scene | technique | warm-up frames | warm-up median | frames | median | min | max | GPU passes (last frame) | setup ms | note |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for t in state["timing"]:
            note = (t.get("note") or t.get("error") or "").replace("|", "/").replace("\n", " ")[:120]
            lines.append(f"| {t['scene']} | {t['technique']} | {_fmt(t.get('warmup_frames'))} | "
                         f"{_fmt(t.get('warmup_median_ms'), '.2f')} | {_fmt(t.get('frames'))} | "
                         f"{_fmt(t.get('median_ms'), '.2f')} | {_fmt(t.get('min_ms'), '.2f')} | "
                         f"{_fmt(t.get('max_ms'), '.2f')} | {_fmt(t.get('gpu_pass_ms'), '.2f')} | "
                         f"{_fmt(t.get('setup_ms'), '.0f')} | {note} |")
        lines.append("")
    if state.get("skipped"):
        lines += ["## Skipped", ""] + [f"- {s}" for s in state["skipped"]] + [""]
    return "\n".join(lines)


class Output:
    """Results kept in memory and written (atomically) to OUT after every step."""

    def __init__(self, out: str):
        self.out = out
        os.makedirs(out, exist_ok=True)
        self.lock = threading.RLock()
        self.state: dict = {"meta": {}, "renders": [], "compare": [], "repeat": [], "timing": [],
                             "skipped": [], "status": ""}
        self.images: dict = {}
        self.images_dirty = False

    def _write(self, name, data: bytes):
        p = os.path.join(self.out, name)
        with open(p + ".tmp", "wb") as f:
            f.write(data)
        os.replace(p + ".tmp", p)

    def flush(self, images: bool = False, sheet=None):
        with self.lock:
            self._write("results.json", json.dumps(self.state, indent=1, default=_json_default).encode())
            self._write("results.md", markdown(self.state).encode())
            if images and self.images_dirty:
                import numpy as np
                p = os.path.join(self.out, "images.npz")
                with open(p + ".tmp", "wb") as f:
                    np.savez_compressed(f, **self.images)
                os.replace(p + ".tmp", p)
                self.images_dirty = False
                if sheet is not None:
                    try:
                        s = sheet()
                        if s is not None:
                            self._write("contact.png", png_bytes(s))
                    except Exception as exc:  # noqa: BLE001 - a picture is optional
                        log(f"contact sheet failed: {exc!r}")


def source_hash() -> dict:
    """sha256 of the renderer's sources (shaders/, addon/render/): images of two runs are
    comparable as a consistency check only when these match."""
    import hashlib
    out = {}
    for top, exts in (("shaders", None), (os.path.join("addon", "render"), (".py",))):
        h = hashlib.sha256()
        n = 0
        for d, dirs, files in sorted(os.walk(os.path.join(REPO, top))):
            dirs.sort()
            if "__pycache__" in d:
                continue
            for f in sorted(files):
                if exts and not f.endswith(exts):
                    continue
                rel = os.path.relpath(os.path.join(d, f), REPO)
                with open(os.path.join(d, f), "rb") as fh:
                    h.update(rel.encode() + b"\0" + fh.read() + b"\0")
                n += 1
        out[top.replace(os.sep, "/")] = f"{h.hexdigest()[:16]} ({n} files)"
    return out


def _json_default(o):
    try:
        import numpy as np
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
    except ImportError:
        pass
    if dataclasses.is_dataclass(o):
        return dataclasses.asdict(o)
    return repr(o)


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


# ---------------------------------------------------------------------------- GL
def pick_device():
    """On EGL, the first device whose renderer is not a software one (GLCONTEXT_DEVICE_INDEX
    for the GL thread's context); nothing to do when the variable is set or no GPU shows."""
    if os.environ.get("GLCONTEXT_DEVICE_INDEX") or os.environ.get("GI_PREVIEW_GL_BACKEND", "egl") != "egl":
        return []
    import moderngl
    seen = []
    for i in range(4):
        try:
            ctx = moderngl.create_standalone_context(backend="egl", device_index=i)
        except Exception as exc:  # noqa: BLE001 - no such device
            seen.append(f"{i}: {str(exc).splitlines()[0][:80] if str(exc) else repr(exc)}")
            break
        r = ctx.info.get("GL_RENDERER", "?")
        ctx.release()
        seen.append(f"{i}: {r}")
        if not any(k in r.lower() for k in ("llvmpipe", "softpipe", "swrast", "lavapipe")):
            if i:
                os.environ["GLCONTEXT_DEVICE_INDEX"] = str(i)
            return seen
    return seen


# ---------------------------------------------------------------------------- check
def do_check(a):
    sys.meta_path.insert(0, _Blocker())
    out = Output(os.path.abspath(a.out))
    st = out.state
    try:
        import_package()
        import numpy as np
        import moderngl

        from gi_preview.compare import metrics
        from gi_preview.render import gl as glmod
        from gi_preview.render import session, techniques
    except Exception as exc:  # noqa: BLE001 - say why in the output folder too
        st["status"] = f"import failed: {type(exc).__name__}: {exc}"
        st["meta"] = {"python": platform.python_version(), "numpy": "?", "settings": {},
                      "traceback": traceback.format_exc()[-4000:]}
        log(st["status"])
        out.flush()
        return 2
    deadline = T0 + a.deadline_s
    st["meta"] = {"argv": sys.argv, "python": platform.python_version(), "numpy": np.__version__,
                  "moderngl": getattr(moderngl, "__version__", "?"), "platform": platform.platform(),
                  "started": time.strftime("%Y-%m-%d %H:%M:%S"), "sources": source_hash(),
                  "settings": {"res": "from the pickles", "samples": a.samples, "quality": 1,
                               "denoiser": "AUTO", "timing_res": a.timing_res if a.timing else None,
                               "timing_frames": a.timing_frames, "frame_limit_s": a.frame_limit_s}}
    st["status"] = "running"

    # hard deadline: write what there is and leave (a GPU hang inside one frame cannot be cancelled)
    def watchdog():
        while time.perf_counter() < deadline:
            time.sleep(1.0)
        with out.lock:
            st["status"] = f"stopped by --deadline-s {a.deadline_s:.0f} s"
            log(st["status"])
            try:
                out.flush(images=True)
            finally:
                os._exit(3)
    threading.Thread(target=watchdog, daemon=True, name="gpu_check-deadline").start()

    # ---- GL
    try:
        st["meta"]["egl_devices"] = pick_device()
    except Exception as exc:  # noqa: BLE001
        st["meta"]["egl_devices"] = [f"probe failed: {exc!r}"]
    try:
        g = glmod.get_gl()
        st["meta"]["gl"] = dict(g.info)
        st["meta"]["gl_limits"] = g.call(lambda: {k: g.ctx.info.get(k) for k in (
            "GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS", "GL_MAX_TEXTURE_SIZE", "GL_MAX_SHADER_STORAGE_BLOCK_SIZE")})
    except Exception as exc:  # noqa: BLE001
        st["status"] = f"no GL context: {exc}"
        log(st["status"])
        out.flush()
        return 2
    log(f"GL: {st['meta']['gl']} (EGL devices: {st['meta']['egl_devices']})")

    # ---- techniques and scenes
    infos = techniques.available()
    ids = [t.id for t in infos]
    if techniques.LOAD_ERRORS:
        st["meta"]["technique_load_errors"] = dict(techniques.LOAD_ERRORS)
    if a.techniques:
        ids = [t for t in a.techniques.split(",") if t]
    st["meta"]["techniques"] = ids
    wanted = [s for s in a.scenes.split(",") if s] if a.scenes else None
    try:
        scenes = load_scenes(a.check, wanted)
    except Exception as exc:  # noqa: BLE001
        st["status"] = f"loading the scenes failed: {type(exc).__name__}: {exc}"
        st["meta"]["traceback"] = traceback.format_exc()[-4000:]
        log(st["status"])
        out.flush()
        return 2
    st["meta"]["scenes"] = {n: {"size": [b["scene"].width, b["scene"].height], "triangles": b.get("triangles"),
                                "lights": b.get("lights"), "exported_with": b.get("exported_with")}
                            for n, b in scenes.items()}
    if scenes:
        s0 = next(iter(scenes.values()))["scene"]
        st["meta"]["settings"]["res"] = f"{s0.width}x{s0.height}"
    log(f"{len(ids)} techniques x {len(scenes)} scenes: {', '.join(ids)} | {', '.join(scenes)}")
    out.flush()
    sheet = lambda: contact_sheet(out.images, list(scenes), ids)  # noqa: E731
    counter = [0]

    def fresh_key():
        counter[0] += 1
        return ("gpu_check", counter[0])

    def release(key):
        try:
            f = session.release_session(key)
            if f is not None:
                f.result(timeout=60)
        except Exception as exc:  # noqa: BLE001
            log(f"  release of session {key} failed: {exc!r}")

    def render_one(sd, sname, tech) -> tuple[dict, object]:
        """One F12-like render in a fresh session: (record, RGB image or None)."""
        rec, img = {"scene": sname, "technique": tech, "ok": False}, None
        key = fresh_key()
        t0 = time.perf_counter()
        limit = t0 + a.render_limit_s
        try:
            r = session.render(sd, tech, 1, a.samples, session=key, denoiser="AUTO", camera_cut=True,
                               warmup=True, cancel=lambda: time.perf_counter() > limit)
            img = np.ascontiguousarray(r.image[..., :3], np.float32)
            fin = np.all(np.isfinite(img), axis=2)
            rgb_mean = [_num(np.mean(np.where(fin, img[..., c], 0.0))) for c in range(3)]
            rec.update(ok=not r.cancelled, pixels=int(fin.size), finite_px=int(fin.sum()),
                       mean=_num(np.mean(img[fin])) if fin.any() else None, mean_rgb=rgb_mean,
                       min=_num(img[fin].min()) if fin.any() else None,
                       max=_num(img[fin].max()) if fin.any() else None,
                       samples=r.samples, warmup_frames=r.warmup_frames, cancelled=r.cancelled,
                       frame_ms=r.frame_ms, setup_ms=r.setup_ms, total_ms=r.total_ms,
                       skipped_passes=[x.name for x in r.skipped_passes], passes=list(r.pass_order),
                       warnings=len(r.warnings))
            if r.cancelled:
                rec["error"] = f"cancelled after {r.samples} of {a.samples} samples (--render-limit-s)"
        except Exception as exc:  # noqa: BLE001 - one technique failing must not end the run
            rec["error"] = f"{type(exc).__name__}: {exc}"
            rec["traceback"] = traceback.format_exc()[-4000:]
        rec["time_s"] = round(time.perf_counter() - t0, 3)
        release(key)
        return rec, img

    # ---- consistency renders
    check_end = time.perf_counter() + a.check_budget_s
    for sname, blob in scenes.items():
        for tech in ids:
            if time.perf_counter() > check_end or time.perf_counter() > deadline - 20:
                with out.lock:
                    st["renders"].append({"scene": sname, "technique": tech, "ok": False,
                                          "error": "skipped: --check-budget-s spent"})
                    st["skipped"].append(f"render {sname}/{tech}: check budget spent")
                continue
            rec, img = render_one(blob["scene"], sname, tech)
            with out.lock:
                st["renders"].append(rec)
                if img is not None:
                    out.images[f"{sname}__{tech}"] = img
                    out.images_dirty = True
            log(f"{sname:15s} {tech:18s} {'ok ' if rec['ok'] else 'ERR'} {rec['time_s']:6.2f}s "
                f"mean {_fmt(rec.get('mean'))} finite {rec.get('finite_px', '-')}/{rec.get('pixels', '-')}"
                + (f"  {rec['error'][:200]}" if rec.get("error") else ""))
            out.flush()
    out.flush(images=True, sheet=sheet)
    log(f"renders done: {sum(r['ok'] for r in st['renders'])}/{len(st['renders'])} ok")

    # ---- run to run on this machine: the same renders again (float atomics, races, timing)
    for sname in [x for x in a.repeat.split(",") if x in scenes]:
        for tech in ids:
            first = out.images.get(f"{sname}__{tech}")
            if first is None:
                continue
            if time.perf_counter() > check_end or time.perf_counter() > deadline - 20:
                st["skipped"].append(f"repeat {sname}/{tech}: check budget spent")
                continue
            rec, img = render_one(scenes[sname]["scene"], sname, tech)
            c = {"scene": sname, "technique": tech, "time_s": rec["time_s"]}
            if img is None:
                c["error"] = rec.get("error")
            else:
                c["identical"] = bool(np.array_equal(img, first, equal_nan=True))
                c["relmse"] = _num(metrics.relmse(img, first))
                fin = np.all(np.isfinite(img), axis=2) & np.all(np.isfinite(first), axis=2)
                c["max_abs_diff"] = _num(np.max(np.abs(img[fin] - first[fin]))) if fin.any() else None
            with out.lock:
                st["repeat"].append(c)
            log(f"repeat {sname:12s} {tech:18s} "
                + ("identical" if c.get("identical") else f"relMSE {_fmt(c.get('relmse'))} max diff "
                   f"{_fmt(c.get('max_abs_diff'))}" if "error" not in c else f"ERR {c['error']}"))
        out.flush()

    # ---- comparison with a reference run (e.g. llvmpipe)
    if a.compare:
        try:
            ref_dir = os.path.abspath(a.compare)
            with np.load(os.path.join(ref_dir, "images.npz")) as z:
                ref = {k: np.asarray(z[k]) for k in z.files}
            try:
                with open(os.path.join(ref_dir, "results.json")) as f:
                    rmeta = json.load(f).get("meta", {})
            except Exception:  # noqa: BLE001
                rmeta = {}
            same_src = rmeta.get("sources") == st["meta"]["sources"]
            st["compare_meta"] = (f"{a.compare}: {rmeta.get('gl', {}).get('GL_RENDERER', '?')}, "
                                  f"{rmeta.get('settings', {}).get('samples', '?')} samples, "
                                  f"numpy {rmeta.get('numpy', '?')}; renderer sources "
                                  + ("identical" if same_src else
                                     f"DIFFER (reference {rmeta.get('sources')}, here {st['meta']['sources']})"))
            if rmeta.get("settings", {}).get("samples") not in (None, a.samples):
                st["compare_meta"] += f"; SAMPLES DIFFER ({rmeta['settings']['samples']} vs {a.samples})"
            for k, img in out.images.items():
                sname, tech = k.split("__", 1)
                c = {"scene": sname, "technique": tech}
                r_img = ref.get(k)
                if r_img is None:
                    c["error"] = "no reference image"
                elif r_img.shape != img.shape:
                    c["error"] = f"shape {img.shape} vs reference {r_img.shape}"
                else:
                    fin = np.all(np.isfinite(img), axis=2) & np.all(np.isfinite(r_img), axis=2)
                    c["relmse"] = _num(metrics.relmse(img, r_img))
                    mt, mr = float(np.mean(img[fin])) if fin.any() else float("nan"), \
                        float(np.mean(r_img[fin])) if fin.any() else float("nan")
                    c["mean"], c["ref_mean"] = _num(mt), _num(mr)
                    c["mean_ratio"] = _num(mt / mr) if mr != 0 else None
                    c["max_abs_diff"] = _num(np.max(np.abs(img[fin] - r_img[fin]))) if fin.any() else None
                    c["identical"] = bool(np.array_equal(img, r_img, equal_nan=True))
                st["compare"].append(c)
            missing = sorted(set(ref) - set(out.images))
            if missing:
                st["compare_meta"] += f"; {len(missing)} reference images not rendered here"
            log(f"compared {len(st['compare'])} images with {a.compare}")
        except Exception as exc:  # noqa: BLE001
            st["compare_meta"] = f"comparison failed: {type(exc).__name__}: {exc}"
            log(st["compare_meta"])
        out.flush()

    # ---- timing
    if a.timing:
        tw, th = parse_res(a.timing_res)
        timing_end = time.perf_counter() + a.timing_budget_s
        tscenes = [s for s in a.timing_scenes.split(",") if s in scenes]
        for sname in tscenes:
            blob = scenes[sname]
            sd = timing_scene(blob)
            if (sd.width, sd.height) != (tw, th):
                sd.width, sd.height = tw, th  # the pickled camera's aspect may differ then
            for tech in ids:
                rec = {"scene": sname, "technique": tech, "res": f"{sd.width}x{sd.height}"}
                if time.perf_counter() > timing_end or time.perf_counter() > deadline - 30:
                    rec["error"] = "skipped: --timing-budget-s spent"
                    with out.lock:
                        st["timing"].append(rec)
                        st["skipped"].append(f"timing {sname}/{tech}: timing budget spent")
                    continue
                key = fresh_key()
                t0 = time.perf_counter()
                try:
                    rec.update(time_technique(session, glmod, sd, tech, key, a, timing_end, deadline))
                except Exception as exc:  # noqa: BLE001
                    rec["error"] = f"{type(exc).__name__}: {exc}"
                    rec["traceback"] = traceback.format_exc()[-4000:]
                rec["wall_s"] = round(time.perf_counter() - t0, 3)
                release(key)
                with out.lock:
                    st["timing"].append(rec)
                log(f"timing {sname:12s} {tech:18s} median {_fmt(rec.get('median_ms'), '.2f')} ms "
                    f"over {rec.get('frames', 0)} (warm-up {rec.get('warmup_frames', '-')}: "
                    f"{_fmt(rec.get('warmup_median_ms'), '.2f')} ms) gpu {_fmt(rec.get('gpu_pass_ms'), '.2f')} ms "
                    f"wall {rec['wall_s']:.1f}s" + (f"  {(rec.get('note') or rec.get('error'))[:160]}"
                                                    if rec.get("note") or rec.get("error") else ""))
                out.flush()
    with out.lock:
        st["status"] = "done"
        end_src = source_hash()
        if end_src != st["meta"]["sources"]:
            st["meta"]["sources_at_end"] = end_src
            st["status"] = "done; the renderer sources CHANGED during the run (meta.sources_at_end)"
        st["meta"]["wall_s"] = round(time.perf_counter() - T0, 1)
        out.flush(images=True, sheet=sheet)
    log(f"done in {time.perf_counter() - T0:.1f} s -> {out.out}")
    bad = [r for r in st["renders"] if not r["ok"]]
    return 1 if bad else 0


def time_technique(session, glmod, sd, tech, key, a, timing_end, deadline) -> dict:
    """One priming render (compiles, allocation, BVH), then one F12-like render (warm-up +
    ``timing_frames``) whose frames are timed one by one on the GL thread."""
    rec: dict = {}
    t0 = time.perf_counter()
    limit = t0 + max(a.frame_limit_s * 4, 30.0)
    prime = session.render(sd, tech, 1, 1, session=key, denoiser="AUTO", camera_cut=True, warmup=False,
                           cancel=lambda: time.perf_counter() > limit)
    rec["prime_s"] = round(time.perf_counter() - t0, 3)
    rec["setup_ms"] = prime.setup_ms
    rec["prime_frame_ms"] = prime.frame_ms
    if prime.frame_ms > 3 * a.frame_limit_s * 1e3:  # a camera-cut frame (VXGI re-injects): allow more
        rec["note"] = (f"priming frame took {prime.frame_ms / 1e3:.1f} s > 3 x {a.frame_limit_s} s: "
                       f"not timed further")
        rec["frames"] = 0
        return rec
    stop_at = min(timing_end, deadline - 30)

    def job():
        sess = session._get_session(key)
        gen = sess.render_steps(sd, tech, 1, a.timing_frames, camera_cut=True, warmup=True, denoiser="AUTO")
        steps, note, result = [], None, None
        while True:
            s0 = sess._setup_clock()
            c0 = time.perf_counter()
            try:
                next(gen)
            except StopIteration as stop:
                result = stop.value
                break
            dt = (time.perf_counter() - c0) * 1e3 - (sess._setup_clock() - s0)
            steps.append(dt)
            if dt > a.frame_limit_s * 1e3:
                note = f"frame {len(steps)} took {dt / 1e3:.1f} s > {a.frame_limit_s} s: rest skipped"
                break
            if time.perf_counter() > stop_at:
                note = f"timing budget spent after {len(steps)} frames"
                break
        if result is None:
            gen.close()
        return steps, note, result

    steps, note, result = glmod.get_gl().submit_job(job, key=("session", key)).result()
    if result is not None:
        n_warm = int(result.warmup_frames)
        rec["gpu_pass_ms"] = _num(sum(result.pass_ms.values())) if result.pass_ms else None
        rec["pass_ms"] = {k: round(float(v), 3) for k, v in result.pass_ms.items()}
        rec["session_frame_ms"] = result.frame_ms
    else:
        n_warm = None
    rec["steps_ms"] = [round(x, 3) for x in steps]
    if n_warm is None:
        # stopped early: which steps were warm-up is not reported; the technique's declared count
        n_warm = min(len(steps), int(getattr(session.techniques.get(tech), "warmup_frames", 0) or 0))
        rec["warmup_frames_guessed"] = True
    warm, timed = steps[:n_warm], steps[n_warm:]
    rec["warmup_frames"] = len(warm)
    rec["warmup_median_ms"] = statistics.median(warm) if warm else None
    rec["warmup_total_ms"] = sum(warm) if warm else 0.0
    rec["frames"] = len(timed)
    if timed:
        rec["median_ms"] = statistics.median(timed)
        rec["min_ms"] = min(timed)
        rec["max_ms"] = max(timed)
    if note:
        rec["note"] = note
    return rec


# ---------------------------------------------------------------------------- main
def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--export", metavar="DIR", help="build and pickle the demo scenes (needs bpy)")
    g.add_argument("--check", metavar="DIR", help="render the pickled scenes (bpy-free)")
    p.add_argument("--out", metavar="OUT", help="--check: output folder")
    p.add_argument("--compare", metavar="REF", help="--check: folder of an earlier --check to compare with")
    p.add_argument("--timing", action="store_true", help="--check: also time every technique at --timing-res")
    p.add_argument("--res", default="96", help="--export: check resolution, N or WxH (default 96)")
    p.add_argument("--timing-res", default="1920x1080", help="timing resolution (default 1920x1080)")
    p.add_argument("--scenes", default="", help="comma-separated scene names (default: all)")
    p.add_argument("--techniques", default="", help="--check: comma-separated ids (default: every registered id)")
    p.add_argument("--samples", type=int, default=4, help="accumulated frames per check render (default 4)")
    p.add_argument("--repeat", default="cornell",
                   help="scenes rendered a second time to measure run-to-run differences here (default cornell; '' = none)")
    p.add_argument("--timing-scenes", default="cornell,sunlit_room", help="scenes timed (default cornell,sunlit_room)")
    p.add_argument("--timing-frames", type=int, default=8, help="timed accumulated frames (default 8)")
    p.add_argument("--frame-limit-s", type=float, default=5.0, help="a slower timed frame ends that technique's timing")
    p.add_argument("--render-limit-s", type=float, default=60.0, help="a check render is cancelled after this")
    p.add_argument("--check-budget-s", type=float, default=210.0, help="renders not started after this are skipped")
    p.add_argument("--timing-budget-s", type=float, default=130.0, help="timing not started after this is skipped")
    p.add_argument("--deadline-s", type=float, default=420.0, help="write what there is and exit after this")
    a = p.parse_args(argv)
    if a.export:
        do_export(a)
        return 0
    if not a.out:
        p.error("--check needs --out")
    return do_check(a)


if __name__ == "__main__":
    sys.exit(main())
