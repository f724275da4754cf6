"""The GI Preview render engine: a shim over bpy-free render sessions.

Each RenderEngine callback hands off to a function here; bpy is converted to SceneData
at one boundary (``export.export_scene``), the render runs on the GL thread
(``render.session``), and the result comes back as numpy arrays.

* F12 / ``blender -b file -E GI_PREVIEW -f N`` / animations: ``final_render``. Temporal
  state is kept across the frames of one animation job (``engine.is_animation``).
* Viewport: every Rendered 3D view (one RenderEngine each) has its own render session.
  ``view_update`` updates the scene incrementally from ``depsgraph.updates`` (moving an
  object re-reads matrices, not meshes); ``view_draw`` never waits for a render: it draws
  the newest finished image through Blender's ``gpu`` module and submits the next
  accumulated frame to the GL thread, whose completion tags a redraw, until
  ``viewport_samples`` frames are accumulated. Viewport frames run before the next frame
  of an F12 render, so both progress together.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import time

import bpy
import numpy as np

from ..render import probe_overlay, session, techniques
from ..render.gl import GLUnavailableError
from ..render.scene_data import Camera, SceneError
from ..render.shaders import ShaderError
from ..render.support import scene_support
from .export import SceneExporter, export_scene

log = logging.getLogger(__name__)

# Render passes beyond Combined: name -> (channels, chan_id, type)
BASE_PASSES = {
    "Depth": (1, "Z", "VALUE"),
    "Normal": (3, "XYZ", "VECTOR"),
    "DiffCol": (3, "RGB", "COLOR"),
    "Emit": (3, "RGB", "COLOR"),
}
EFFECT_PASS_CHANNELS = (3, "RGB", "COLOR")

# What the last final render did, for the panel and for scripts (machine-readable).
last_render: dict = {}

# Images to present instead of rendering (label, (H, W, 4) linear): "Compare with Cycles"
# fills render slots 1-3 through the engine, since a slot's pixels cannot be written from
# Python. Consumed one per render call.
display_queue: list = []


def present(engine, depsgraph, label: str, image: np.ndarray):
    """Write a ready image into the Render Result (the active render slot)."""
    scene = depsgraph.scene
    r = scene.render
    w = int(r.resolution_x * r.resolution_percentage / 100)
    h = int(r.resolution_y * r.resolution_percentage / 100)
    if image.shape[:2] != (h, w):
        engine.report({"ERROR"}, f"GI Preview: '{label}' is {image.shape[1]}x{image.shape[0]}, "
                                 f"the render is {w}x{h}")
        return
    result = engine.begin_result(0, 0, w, h)
    result.layers[0].passes["Combined"].rect = np.ascontiguousarray(image, np.float32).reshape(-1, 4)
    engine.end_result(result)
    engine.update_stats("", f"GI Preview: {label}")


def technique_passes(technique_id: str) -> dict:
    passes = dict(BASE_PASSES)
    try:
        tech = techniques.get(technique_id)()
    except ValueError:
        return passes
    for name in tech.outputs:
        passes.setdefault(name, EFFECT_PASS_CHANNELS)
    return passes


def _settings(scene):
    s = scene.gi_preview
    tid = s.technique
    if not tid:
        # a stored value no item has (a file saved by a version whose technique menu numbered
        # its items by position): render with AUTO and say so, rather than fail
        log.warning("GI Preview: the scene's saved technique is not one this version knows; "
                    "rendering with AUTO (pick a technique in Render Properties)")
        tid = "AUTO"
    return tid, int(s.quality), int(s.samples)


def _filter_options(scene) -> dict:
    """scene.gi_preview.denoiser / use_taa, as session.render options (end the graph)."""
    s = scene.gi_preview
    return {"denoiser": str(getattr(s, "denoiser", "NONE")), "use_taa": bool(getattr(s, "use_taa", False))}


def _auto_options(scene, technique: str) -> dict:
    """AUTO's Frame Budget / Target Error / Skip Below, as ``session.render(auto=...)``."""
    from .properties import auto_options

    return auto_options(scene.gi_preview, technique)


def _pass_params(scene, technique: str) -> dict:
    """The technique settings of the Render Properties (those not left at 0, "the Quality
    level's value"), as pass parameters for ``session.render(params=...)``."""
    from .properties import pass_overrides

    return pass_overrides(scene.gi_preview, technique)


def skipped_text(res) -> str:
    """What the planner left out, by effect with why ("glossy: no glossy surface in view"),
    rather than by internal pass name (passes of one effect are listed once)."""
    groups: dict = {}
    for sp in res.skipped_passes:
        eff = ", ".join(str(e).replace("_", " ") for e in sp.effects) or "other"
        groups.setdefault(eff, [])
        if sp.reason not in groups[eff]:
            groups[eff].append(sp.reason)
    return "; ".join(f"{e}: {', '.join(r)}" for e, r in groups.items())


def stats_text(res, target: int | None = None) -> str:
    """The status-bar line of a render: technique, quality, samples (of ``target`` in the
    viewport), frame time, and the skipped effects (``skipped_text``)."""
    from .properties import QUALITY_ITEMS, technique_label

    quality = {v: n for _i, n, _d, v in QUALITY_ITEMS}.get(int(res.quality), f"q{res.quality}")
    samples = f"{res.samples}/{target}" if target else f"{res.samples}"
    text = (f"GI Preview {technique_label(res.technique)} ({quality}) | {samples} samples | "
            f"{res.frame_ms:.1f} ms/frame")
    skipped = skipped_text(res)
    return f"{text} | skipped {skipped}" if skipped else text


def final_render(engine, depsgraph):
    if display_queue:
        label, image = display_queue.pop(0)
        present(engine, depsgraph, label, image)
        return
    scene = depsgraph.scene
    technique, quality, samples = _settings(scene)
    t0 = time.perf_counter()
    engine.update_stats("", "GI Preview: exporting scene")
    try:
        data = export_scene(depsgraph)
    except SceneError as exc:
        engine.report({"ERROR"}, str(exc))
        return
    for w in data.warnings:
        engine.report({"WARNING"}, w)
    export_ms = (time.perf_counter() - t0) * 1e3
    engine.update_stats("", f"GI Preview: rendering {technique} ({samples} samples)")
    try:
        # an animation keeps temporal state from frame to frame; its first frame starts from a
        # camera cut and warms the technique's state up, as a still F12 render does
        first = not engine.is_animation or scene.frame_current == scene.frame_start
        res = session.render(data, technique, quality, samples, progress=engine.update_progress,
                             cancel=engine.test_break, keep_history=bool(engine.is_animation),
                             session="final", camera_cut=True if first else None, warmup=first,
                             params=_pass_params(scene, technique), **_filter_options(scene),
                             **_auto_options(scene, technique))
    except session.Cancelled:
        return
    except (GLUnavailableError, SceneError, ShaderError, ValueError) as exc:
        engine.report({"ERROR"}, str(exc))
        return
    w, h = data.width, data.height
    passes = technique_passes(technique)
    result = engine.begin_result(0, 0, w, h)
    layer = result.layers[0]
    layer.passes["Combined"].rect = res.image.reshape(-1, 4)
    written = ["Combined"]
    for name, arr in res.aovs.items():
        p = layer.passes.find_by_name(name, "") if hasattr(layer.passes, "find_by_name") else None
        if p is None and name in layer.passes:
            p = layer.passes[name]
        if p is None:
            continue
        ch = p.channels
        a = arr.reshape(-1, arr.shape[-1])
        if a.shape[1] != ch:
            a = np.repeat(a[:, :1], ch, axis=1) if a.shape[1] < ch else a[:, :ch]
        p.rect = np.ascontiguousarray(a, np.float32)
        written.append(name)
    info = {
        "technique": res.technique, "requested": technique, "quality": quality, "samples": res.samples,
        "frame_ms": round(res.frame_ms, 3), "total_ms": round(res.total_ms, 3), "export_ms": round(export_ms, 3),
        "pass_ms": {k: round(v, 3) for k, v in res.pass_ms.items()}, "effects": res.effects,
        "skipped_passes": [s.as_dict() for s in res.skipped_passes], "warnings": res.warnings,
        "cancelled": res.cancelled, "frame": data.frame, "scene": scene.name,
        "setup_ms": round(res.setup_ms, 3), "prep_ms": round(res.prep_ms, 3), "warmup_frames": res.warmup_frames,
        "warmup_ms": round(res.warmup_ms, 3),
        "history_resets": list(res.history_resets),
        "passes": written, "available_passes": [p.name for p in layer.passes],
        "scene_support": scene_support(data),
        "auto": res.auto,
    }
    try:
        result.stamp_data_add_field("GI Preview", json.dumps(info))
    except Exception:  # stamp fields are optional metadata
        pass
    engine.end_result(result)
    last_render.clear()
    last_render.update(info)
    engine.update_stats("", stats_text(res))
    for s in res.skipped_passes:
        log.info("GI Preview: skipped pass %s (%s)", s.name, s.reason)


def register_passes(engine, scene, view_layer):
    engine.register_pass(scene, view_layer, "Combined", 4, "RGBA", "COLOR")
    try:
        tid = scene.gi_preview.technique or "AUTO"
    except AttributeError:
        tid = "DIRECT"
    for name, (ch, chan, typ) in technique_passes(tid).items():
        engine.register_pass(scene, view_layer, name, ch, chan, typ)


# ------------------------------------------------------------------ viewport
_view_serial = itertools.count(1)


class ViewportState:
    """One 3D view's viewport: its own render session (``session_key``), the exporter that
    keeps unchanged meshes between view updates, the render in flight and the newest
    image. Blender makes one RenderEngine per Rendered 3D view, and so one of these."""

    def __init__(self):
        self.data = None  # SceneData of the last view_update (camera/size set per draw)
        self.exporter = SceneExporter()
        self.key = None  # what the shown accumulation is of: view, size, technique, data
        self.texture = None
        self.error = None
        self.error_key = None
        self.count = 0  # samples accumulated for ``key``
        self.future = None  # the render in flight (one at a time)
        self.future_key = None
        self.session_key = None
        self.data_version = 0
        self.alive = True
        self.last_frame_ms = 0.0
        self.last_update = {}  # what the last view_update did (for tests and benchmarks)

    def session_for(self, region_data) -> tuple:
        if self.session_key is None:
            ptr = region_data.as_pointer() if hasattr(region_data, "as_pointer") else 0
            self.session_key = ("viewport", ptr, next(_view_serial))
        return self.session_key

    def free(self):
        """The view is gone: stop its render and free its session's GL resources."""
        self.alive = False
        if self.future is not None:
            self.future.cancel_event.set()
        self.texture = None
        if self.session_key is not None:
            try:
                session.release_session(self.session_key)
            except Exception:  # noqa: BLE001 - the GL thread may be gone at exit
                pass
            self.session_key = None


def view_update(engine, context, depsgraph):
    """Bring the viewport's SceneData up to date: a full export the first time, then only
    what ``depsgraph.updates`` says changed (moving an object re-reads matrices and lights,
    not meshes; see ``export.SceneExporter``)."""
    st = engine._viewport
    region = context.region
    scale = context.scene.gi_preview.viewport_scale
    w = max(4, int(region.width * scale))
    h = max(4, int(region.height * scale))
    t0 = time.perf_counter()
    try:
        # the camera is replaced at draw time by the region's view
        dummy = Camera("viewport", np.eye(4, dtype=np.float32), np.eye(4, dtype=np.float32))
        updates = None if st.data is None else list(depsgraph.updates)
        st.data = st.exporter.export(depsgraph, updates, width=w, height=h, view_camera=dummy)
        st.error = None
    except SceneError as exc:
        st.data, st.error = None, str(exc)
    st.data_version += 1
    st.last_update = dict(st.exporter.last_stats, ms=(time.perf_counter() - t0) * 1e3,
                          full=updates is None if st.error is None else True)


def _region_camera(context) -> Camera:
    rv3d = context.region_data
    view = np.array(rv3d.view_matrix, np.float64)
    proj = np.array(rv3d.window_matrix, np.float64)
    cam_world = np.linalg.inv(view).astype(np.float32)
    ortho = not rv3d.is_perspective
    # near/far from the projection (OpenGL convention)
    a, b = proj[2, 2], proj[2, 3]
    if ortho:
        near, far = (b + 1) / a, (b - 1) / a
    else:
        near, far = b / (a - 1), b / (a + 1)
    return Camera("viewport", cam_world, proj.astype(np.float32), "ORTHO" if ortho else "PERSP",
                  float(abs(near)), float(abs(far)))


def _upload(st, res, w, h):
    import gpu

    img = np.nan_to_num(res.image, nan=0.0, posinf=65504.0, neginf=0.0)
    img = np.clip(img, 0.0, 65504.0).astype(np.float32)
    buf = gpu.types.Buffer("FLOAT", w * h * 4, img.ravel())
    st.texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buf)


def _redraw_callback(engine, st):
    """Called on the GL thread when a viewport frame is ready: ask Blender to redraw the view
    (``tag_redraw`` only sets a flag the window manager reads; Cycles calls it from its own
    threads too). Nothing is done once the view is gone."""
    def done(_fut):
        if st.alive:
            try:
                engine.tag_redraw()
            except (ReferenceError, RuntimeError):
                pass
    return done


def view_draw(engine, context, depsgraph):
    """Draw the newest finished image of this view and keep its accumulation going; never
    waits for a render. A finished frame is uploaded here; the next frame is submitted to
    the GL thread (``session.submit_render``, interactive priority: it runs before the next
    frame of an F12 render), and its completion tags a redraw."""
    from gpu_extras.presets import draw_texture_2d
    import gpu

    st = engine._viewport
    scene = depsgraph.scene
    region = context.region
    if st.data is None:
        if st.error:
            engine.update_stats("", f"GI Preview: {st.error}")
        return
    scale = scene.gi_preview.viewport_scale
    w = max(4, int(region.width * scale))
    h = max(4, int(region.height * scale))
    cam = _region_camera(context)
    technique, quality, _ = _settings(scene)
    target = int(scene.gi_preview.viewport_samples)
    show_probes = bool(getattr(scene.gi_preview, "show_probes", False))  # probe overlay (probe_overlay.py)
    params = _pass_params(scene, technique)
    key = (technique, quality, w, h, cam.view.tobytes(), cam.projection.tobytes(), st.data_version,
           tuple(_filter_options(scene).values()), show_probes, session.params_key(params))
    if key != st.key:
        st.key, st.count = key, 0
    # a finished frame: show it (even one of an older view: the newest image there is)
    fut = st.future
    if fut is not None and fut.done():
        st.future = None
        try:
            res = fut.result()
        except session.Cancelled:
            res = None
        except (GLUnavailableError, SceneError, ShaderError, ValueError) as exc:
            st.error, st.error_key = str(exc), st.future_key
            engine.update_stats("", f"GI Preview: {exc}")
            res = None
        if res is not None:
            rh, rw = res.image.shape[:2]
            _upload(st, res, rw, rh)
            st.last_frame_ms = res.frame_ms
            if st.future_key == st.key:
                st.count = res.samples
            engine.update_stats("", stats_text(res, target))
    # the next frame, unless one is in flight or the view has converged
    # (after an error, only once the view, settings or scene changed: no retry loop)
    if st.future is None and st.count < target and (st.error is None or st.error_key != st.key):
        data = dataclasses.replace(st.data, camera=cam, width=w, height=h)
        try:
            submit = probe_overlay.submit_render if show_probes else session.submit_render
            st.future = submit(
                data, technique, quality, 1, continue_accumulation=True, keep_history=True,
                session=st.session_for(context.region_data), on_done=_redraw_callback(engine, st),
                params=params, **_filter_options(scene), **_auto_options(scene, technique))
            st.future_key = st.key
            st.error = None
        except (GLUnavailableError, ValueError) as exc:
            st.error, st.error_key = str(exc), st.key
            engine.update_stats("", f"GI Preview: {exc}")
    if st.texture is None:
        return
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(st.texture, (0, 0), region.width, region.height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


class GIPreviewRenderEngine(bpy.types.RenderEngine):
    """GI Preview: real-time global illumination techniques, measured against Cycles."""

    bl_idname = "GI_PREVIEW"
    bl_label = "GI Preview"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # Material Preview shading uses EEVEE (look-dev), Rendered uses GI Preview

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._viewport = ViewportState()

    def __del__(self):
        try:
            self._viewport.free()
        except Exception:
            pass

    def render(self, depsgraph):
        final_render(self, depsgraph)

    def view_update(self, context, depsgraph):
        view_update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        view_draw(self, context, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        register_passes(self, scene, renderlayer)


classes = (GIPreviewRenderEngine,)
