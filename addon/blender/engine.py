"""The GI Preview render engine: a shim over bpy-free render sessions.

Each RenderEngine callback hands off to a function here; bpy is converted to SceneData
at one boundary (``export.export_scene``), the render runs on the GL thread
(``render.session``), and the result comes back as numpy arrays.

* F12 / ``blender -b file -E GI_PREVIEW -f N`` / animations: ``final_render``. Temporal
  state is kept across the frames of one animation job (``engine.is_animation``).
* Viewport: ``view_update`` re-exports the scene when the depsgraph changed; ``view_draw``
  renders one more accumulated frame for the region's view (nothing is re-exported when
  only the view moved) and draws it through Blender's ``gpu`` module; redraws continue
  until ``viewport_samples`` frames are accumulated.
"""
from __future__ import annotations

import json
import logging
import time

import bpy
import numpy as np

from ..render import session, techniques
from ..render.gl import GLUnavailableError
from ..render.scene_data import Camera, SceneError
from ..render.shaders import ShaderError
from .export import export_scene

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
    return s.technique, int(s.quality), int(s.samples)


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
        res = session.render(data, technique, quality, samples, progress=engine.update_progress,
                             cancel=engine.test_break, keep_history=bool(engine.is_animation),
                             session="final")
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
        "passes": written, "available_passes": [p.name for p in layer.passes],
    }
    try:
        result.stamp_data_add_field("GI Preview", json.dumps(info))
    except Exception:  # stamp fields are optional metadata
        pass
    engine.end_result(result)
    last_render.clear()
    last_render.update(info)
    engine.update_stats("", res.stats_line())
    for s in res.skipped_passes:
        log.info("GI Preview: skipped pass %s (%s)", s.name, s.reason)


def register_passes(engine, scene, view_layer):
    engine.register_pass(scene, view_layer, "Combined", 4, "RGBA", "COLOR")
    try:
        tid = scene.gi_preview.technique
    except AttributeError:
        tid = "DIRECT"
    for name, (ch, chan, typ) in technique_passes(tid).items():
        engine.register_pass(scene, view_layer, name, ch, chan, typ)


# ------------------------------------------------------------------ viewport
class ViewportState:
    def __init__(self):
        self.data = None
        self.key = None
        self.texture = None
        self.error = None
        self.count = 0

    def free(self):
        self.texture = None


def view_update(engine, context, depsgraph):
    st = engine._viewport
    region = context.region
    scale = context.scene.gi_preview.viewport_scale
    w = max(4, int(region.width * scale))
    h = max(4, int(region.height * scale))
    try:
        # the camera is replaced at draw time by the region's view
        dummy = Camera("viewport", np.eye(4, dtype=np.float32), np.eye(4, dtype=np.float32))
        st.data = export_scene(depsgraph, width=w, height=h, view_camera=dummy)
        st.error = None
    except SceneError as exc:
        st.data, st.error = None, str(exc)
    st.key = None  # restart accumulation


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


def view_draw(engine, context, depsgraph):
    import gpu
    from gpu_extras.presets import draw_texture_2d

    st = engine._viewport
    scene = depsgraph.scene
    if st.data is None:
        if st.error:
            engine.update_stats("", f"GI Preview: {st.error}")
        return
    region = context.region
    scale = scene.gi_preview.viewport_scale
    w = max(4, int(region.width * scale))
    h = max(4, int(region.height * scale))
    data = st.data
    data.camera = _region_camera(context)
    data.width, data.height = w, h
    technique, quality, _ = _settings(scene)
    target = int(scene.gi_preview.viewport_samples)
    key = (technique, quality, w, h, data.camera.view.tobytes(), data.camera.projection.tobytes(), id(data))
    if key != st.key:
        st.key, st.count = key, 0
    if st.count < target or st.texture is None:
        try:
            res = session.render(data, technique, quality, 1, continue_accumulation=st.count > 0,
                                 keep_history=True, session="viewport")
        except (GLUnavailableError, SceneError, ShaderError, ValueError) as exc:
            engine.update_stats("", f"GI Preview: {exc}")
            return
        st.count = res.samples
        img = np.nan_to_num(res.image, nan=0.0, posinf=65504.0, neginf=0.0)
        img = np.clip(img, 0.0, 65504.0).astype(np.float32)
        buf = gpu.types.Buffer("FLOAT", w * h * 4, img.ravel())
        st.texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buf)
        engine.update_stats("", f"GI Preview {res.technique}: {st.count}/{target} samples, "
                                f"{res.frame_ms:.1f} ms/frame")
        if st.count < target:
            engine.tag_redraw()
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
