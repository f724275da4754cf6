"""Compare with Cycles from the UI: operator, stored metrics, panel helper.

``GIPREVIEW_OT_compare`` ("gi_preview.compare") renders the current scene with GI Preview
(technique, quality and samples from ``scene.gi_preview``) and with Cycles (a cached, fair
reference, see ``reference.py``), measures the difference and shows it as images:

* "GI Preview: result"        the GI Preview frame (linear float)
* "GI Preview: Cycles"        the Cycles reference (linear float)
* "GI Preview: error"         per-pixel relMSE heat map (viridis, log scale 1e-4..1, magenta =
                              non-finite); display-encoded bytes marked Non-Color so no view
                              transform changes its colours
* "GI Preview: side by side"  left half GI Preview, right half Cycles, a 1-px white seam

Render slots: the three images also go into the Render Result's slots 1, 2, 3 (named "GI
Preview", "Cycles", "Error map"), so an artist flips between them with J in the Image Editor.
A slot's pixels cannot be written from Python (``RenderSlot`` has only ``name``/``clear()``),
so ``fill_render_slots`` runs one render per slot through the GI Preview engine, which
presents a queued ready image instead of rendering (``engine.display_queue``): nothing is
rendered twice. The error map is written linearised, so with the "Standard" view transform
it shows the heat map's exact colours; the "GI Preview: error" image keeps them under any
view transform.

The metrics of the last compare per technique are kept on the scene as JSON in
``scene.gi_preview_comparison.results_json`` (PropertyGroup ``GIPreviewComparison``, attached
by ``register_props()``); the Compare sub-panel (ui.py) draws them as a table.

Long renders: invoked from the UI, the operator runs in the background (``CompareJob``):
the GI Preview render goes to the GL thread without blocking (``session.submit_render``)
and the Cycles reference renders in a child process (``reference_worker``: a copy of the
.blend, the same fair settings and cache); a timer polls both and shows
``wm.progress_begin/update/end``, and Esc cancels within a fraction of a second, the Cycles
render included (the child is killed). ``execute`` (scripts, F3 redo, background) runs the
same steps in one go, with Cycles in this process.
"""
from __future__ import annotations

import json
import time

import numpy as np

import bpy

from ..compare import metrics as M
from . import reference

IMG_RESULT = "GI Preview: result"
IMG_CYCLES = "GI Preview: Cycles"
IMG_ERROR = "GI Preview: error"
IMG_SPLIT = "GI Preview: side by side"

_REF_ITEMS = [
    ("AUTO", "Auto", "The reference the technique models (e.g. one bounce for one-bounce GI)"),
    ("FULL", "Full", "Cycles with 12 bounces: the ground truth"),
    ("DIRECT", "Direct", "Cycles with 0 bounces: direct light only"),
    ("ONE_BOUNCE", "One Bounce", "Cycles with one indirect bounce of any kind"),
    ("AO", "AO", "Cycles ambient occlusion"),
]


class GIPreviewComparison(bpy.types.PropertyGroup):
    """The last comparison with Cycles per technique (JSON, written by gi_preview.compare)."""

    results_json: bpy.props.StringProperty(
        name="Comparison Results", default="{}", options={"HIDDEN"},
        description="JSON: technique -> metrics of its last comparison with Cycles")
    last_technique: bpy.props.StringProperty(name="Last Technique", default="")


def _set_image(name: str, rgba: np.ndarray, *, linear: bool = True) -> bpy.types.Image:
    """Create or replace the image ``name`` with (H, W, 4) pixels (row 0 = bottom)."""
    h, w = rgba.shape[:2]
    img = bpy.data.images.get(name)
    if img is not None and (tuple(img.size) != (w, h) or bool(img.is_float) != linear):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(name, width=w, height=h, alpha=True, float_buffer=linear)
    try:
        img.colorspace_settings.name = "Linear Rec.709" if linear else "Non-Color"
    except TypeError:
        pass
    px = np.ascontiguousarray(np.nan_to_num(rgba, nan=0.0, posinf=65504.0, neginf=0.0), np.float32)
    img.pixels.foreach_set(px.ravel())
    img.update()
    return img


def side_by_side(ours: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Left half from ``ours``, right half from ``ref``, a white seam at the split."""
    out = np.array(ref, np.float32, copy=True)
    w = out.shape[1]
    half = w // 2
    out[:, :half] = ours[:, :half]
    out[:, half:half + 1, :3] = 1.0
    out[..., 3] = 1.0
    return out


SLOT_LABELS = ("GI Preview", "Cycles", "Error map")


def fill_render_slots(scene, images: list) -> bool:
    """Put (label, linear RGBA) images into the Render Result's slots 1, 2, 3 (J flips
    between them). Renders through the GI Preview engine's display queue, so nothing is
    rendered twice; the scene's engine is set to GI_PREVIEW for the calls and restored."""
    from . import engine as engine_mod

    old_engine = scene.render.engine
    try:
        scene.render.engine = "GI_PREVIEW"
        for i, (label, img) in enumerate(images):
            rr = bpy.data.images.get("Render Result")
            if rr is not None and len(rr.render_slots) > i:
                rr.render_slots.active_index = i
            engine_mod.display_queue[:] = [(label, img)]
            reference.render_operator(scene)
            rr = bpy.data.images.get("Render Result")
            if rr is not None and len(rr.render_slots) > i:
                rr.render_slots[i].name = label
        rr = bpy.data.images.get("Render Result")
        if rr is not None:
            rr.render_slots.active_index = 0
        return True
    finally:
        engine_mod.display_queue.clear()
        scene.render.engine = old_engine


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def load_results(scene) -> dict:
    comp = getattr(scene, "gi_preview_comparison", None)
    if comp is None:
        return {}
    try:
        d = json.loads(comp.results_json or "{}")
        return d if isinstance(d, dict) else {}
    except ValueError:
        return {}


def store_results(scene, technique: str, entry: dict):
    comp = getattr(scene, "gi_preview_comparison", None)
    if comp is None:
        return
    d = load_results(scene)
    d[technique] = entry
    comp.results_json = json.dumps(d, sort_keys=True)
    comp.last_technique = technique


def _settings(scene):
    gp = getattr(scene, "gi_preview", None)
    tech = getattr(gp, "technique", "DIRECT") if gp is not None else "DIRECT"
    samples = int(getattr(gp, "samples", 1)) if gp is not None else 1
    quality = int(getattr(gp, "quality", 1)) if gp is not None else 1
    return str(tech), quality, samples


def _reference_kind(technique: str, choice: str) -> str:
    if choice != "AUTO":
        return choice.lower()
    try:
        from ..render import session
        for t in session.available_techniques():
            if t.id == technique:
                return t.reference or "full"
    except Exception:  # noqa: BLE001 - unknown technique: compare with the full reference
        pass
    return "full"


def _scene_defaults(op, scene):
    """Reference kind and samples not given to the operator come from the Compare
    sub-panel's scene settings (also when run from F3 search or a script)."""
    gp = getattr(scene, "gi_preview", None)
    props = getattr(op, "properties", None)
    if gp is None or props is None:
        return
    if not props.is_property_set("reference") and hasattr(gp, "compare_reference"):
        op.reference = gp.compare_reference
    if not props.is_property_set("ref_spp") and hasattr(gp, "compare_samples"):
        op.ref_spp = int(gp.compare_samples)


class GIPREVIEW_OT_compare(bpy.types.Operator):
    """Render the scene with GI Preview and with Cycles (cached reference), and show the error map, a side-by-side image and the metrics"""

    bl_idname = "gi_preview.compare"
    bl_label = "Compare with Cycles"
    bl_options = {"REGISTER"}

    reference: bpy.props.EnumProperty(name="Reference", items=_REF_ITEMS, default="AUTO")
    ref_spp: bpy.props.IntProperty(name="Reference Samples", default=128, min=1, max=65536,
                                   description="Cycles samples of the reference")
    use_cache: bpy.props.BoolProperty(name="Use Cache", default=True,
                                      description="Reuse a stored reference of the unchanged scene")

    _timer = None
    _steps = None
    _state = None
    _job = None

    @classmethod
    def poll(cls, context):
        sc = getattr(context, "scene", None)
        if sc is None or sc.camera is None:
            cls.poll_message_set("The scene needs a camera")
            return False
        return True

    # ---------------------------------------------------------------- steps
    def _make_steps(self, context):
        scene = context.scene
        _scene_defaults(self, scene)
        st = self._state = {"scene": scene}
        tech, quality, samples = _settings(scene)
        st.update(technique=tech, quality=quality, samples=samples,
                  kind=_reference_kind(tech, self.reference))

        def render_ours():
            from . import reference as R
            from .export import export_scene
            from ..render import session
            t0 = time.perf_counter()
            dg = R.evaluated_depsgraph(scene, context.view_layer)
            sd = export_scene(dg)
            st["export_ms"] = (time.perf_counter() - t0) * 1e3
            st["fingerprint"] = sd.fingerprint()
            st["size"] = (sd.width, sd.height)
            from .engine import _auto_options, _filter_options, _pass_params
            # as F12 renders it: the technique settings and the filters of the render panel
            res = session.render(sd, technique=tech, quality=quality, samples=samples,
                                 params=_pass_params(scene, tech), **_filter_options(scene),
                                 **_auto_options(scene, tech))
            st["ours"] = res

        def render_ref():
            from . import reference as R
            w, h = st["size"]
            st["ref"] = R.get_reference(scene, st["kind"], self.ref_spp, width=w, height=h,
                                        fingerprint=st["fingerprint"], use_cache=self.use_cache)

        def measure():
            res, ref = st["ours"], st["ref"]
            img = np.asarray(res.image, np.float32)
            m = M.compare(img, ref.image)
            heat, legend = M.heatmap(img, ref.image)
            _set_image(IMG_RESULT, img)
            _set_image(IMG_CYCLES, ref.image)
            heat4 = np.concatenate([heat, np.ones(heat.shape[:2] + (1,), np.float32)], axis=2)
            _set_image(IMG_ERROR, heat4, linear=False)
            _set_image(IMG_SPLIT, side_by_side(img, ref.image))
            entry = {"technique": tech, "quality": quality, "samples": samples,
                     "reference": st["kind"], "ref_spp": ref.spp, "ref_time_ms": ref.time_ms,
                     "ref_cached": ref.cached, "ms_per_frame": float(res.frame_ms),
                     "setup_ms": st.get("export_ms", 0.0) + float(getattr(res, "setup_ms", 0.0) or 0.0),
                     "total_ms": float(res.total_ms), "relmse": m["relmse"], "flip": m["flip"],
                     "ssim": m["ssim"], "psnr": m["psnr"] if np.isfinite(m["psnr"]) else None,
                     "nonfinite_pixels": m["nonfinite_pixels"],
                     "skipped_passes": [s.as_dict() for s in res.skipped_passes],
                     "heatmap_range": [legend["vmin"], legend["vmax"]],
                     "time": time.strftime("%Y-%m-%d %H:%M:%S")}
            store_results(scene, tech, entry)
            st["entry"] = entry
            st["slots"] = [(SLOT_LABELS[0], img), (SLOT_LABELS[1], np.asarray(ref.image, np.float32)),
                           (SLOT_LABELS[2], np.concatenate([_srgb_to_linear(heat), heat4[..., 3:]], axis=2))]

        def slots():
            fill_render_slots(scene, st["slots"])

        return [("Rendering GI Preview", render_ours), ("Rendering Cycles reference", render_ref),
                ("Measuring", measure), ("Filling render slots", slots)]

    def _report_done(self):
        e = self._state["entry"]
        self.report({"INFO"}, f"{e['technique']} q{e['quality']} vs Cycles {e['reference']} "
                              f"({e['ref_spp']} spp{', cached' if e['ref_cached'] else ''}): "
                              f"relMSE {e['relmse']:.4g}, FLIP {e['flip']:.4g}, SSIM {e['ssim']:.4f}, "
                              f"{e['ms_per_frame']:.1f} ms/frame. Render slots 1-3: GI Preview, Cycles, "
                              f"error map (J flips); images '{IMG_SPLIT}', '{IMG_ERROR}'")

    # ---------------------------------------------------------------- blocking
    def execute(self, context):
        steps = self._make_steps(context)
        wm = context.window_manager
        wm.progress_begin(0, len(steps))
        try:
            for i, (_label, fn) in enumerate(steps):
                fn()
                wm.progress_update(i + 1)
        except Exception as e:  # noqa: BLE001 - shown to the user
            self.report({"ERROR"}, f"Compare with Cycles failed: {e}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self._report_done()
        return {"FINISHED"}

    # ---------------------------------------------------------------- modal (UI)
    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        job = self._job = CompareJob(self, context)
        try:
            job.start()
        except Exception as e:  # noqa: BLE001 - shown to the user
            job.cancel()
            self.report({"ERROR"}, f"Compare with Cycles failed: {e}")
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        context.workspace.status_text_set(f"GI Preview compare: {job.label}... (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def _finish(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            ms = job.cancel()
            self._finish(context)
            self.report({"WARNING"}, f"Compare with Cycles cancelled ({ms:.0f} ms)")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            ready = job.poll()
            if ready:
                job.finish()
        except Exception as e:  # noqa: BLE001
            job.cancel()
            self._finish(context)
            self.report({"ERROR"}, f"Compare with Cycles failed ({job.label}): {e}")
            return {"CANCELLED"}
        context.window_manager.progress_update(int(100 * job.fraction))
        if not ready:
            context.workspace.status_text_set(
                f"GI Preview compare: {job.label} {100 * job.fraction:.0f}%... (Esc to cancel)")
            return {"RUNNING_MODAL"}
        self._finish(context)
        self._report_done()
        for area in getattr(context.screen, "areas", []):
            area.tag_redraw()
        return {"FINISHED"}


class CompareJob:
    """The comparison run in the background (the modal operator's work), polled from a timer.

    ``start()`` exports the scene (main thread, short), submits the GI Preview render to the
    GL thread (``session.submit_render``: one frame at a time, the viewport keeps drawing)
    and starts the Cycles reference in a child process (``reference_worker.launch``; a cached
    reference is used at once). ``poll()`` returns True when both are done (``fraction``
    and ``label`` say where it is); ``finish()`` measures and fills the images and render
    slots. ``cancel()`` stops the GI Preview render at its next frame and kills the Cycles
    process; it returns how many milliseconds that took."""

    def __init__(self, op, context, *, reference_process=None):
        self.op = op
        self.context = context
        self.scene = context.scene
        self.steps = dict(op._make_steps(context))  # label -> fn (measure, slots are reused)
        self.st = op._state
        self.future = None
        self.ref_proc = None
        self.launch = reference_process
        self.label = "Exporting"
        self.fraction = 0.0
        self.cancelled = False

    def start(self):
        from . import reference as R
        from . import reference_worker as W
        from .export import export_scene
        from ..render import session

        st, scene = self.st, self.scene
        t0 = time.perf_counter()
        dg = R.evaluated_depsgraph(scene, self.context.view_layer)
        sd = export_scene(dg)
        st["export_ms"] = (time.perf_counter() - t0) * 1e3
        st["fingerprint"] = sd.fingerprint()
        st["size"] = w, h = (sd.width, sd.height)
        self.future = session.submit_render(sd, st["technique"], st["quality"], st["samples"],
                                            session="final", priority=session.PRIORITY_NORMAL)
        ref = None
        if self.op.use_cache:
            ref = W.cached_reference(scene, st["kind"], self.op.ref_spp, width=w, height=h,
                                     fingerprint=st["fingerprint"])
        if ref is not None:
            st["ref"] = ref
        else:
            launch = self.launch or W.launch
            self.ref_proc = launch(scene, st["kind"], self.op.ref_spp, width=w, height=h,
                                   fingerprint=st["fingerprint"])
        self.label = "Rendering GI Preview and the Cycles reference"

    def poll(self) -> bool:
        st = self.st
        if self.ref_proc is not None and "ref" not in st:
            ref = self.ref_proc.poll()  # raises with the child's output if it failed
            if ref is not None:
                st["ref"] = ref
        ours = self.future.progress if not self.future.done() else 1.0
        theirs = 1.0 if "ref" in st else (self.ref_proc.progress if self.ref_proc is not None else 0.0)
        self.fraction = 0.9 * (0.5 * ours + 0.5 * theirs)
        if self.future.done() and "ours" not in st:
            st["ours"] = self.future.result()
        if "ours" in st and "ref" in st:
            self.label = "Measuring"
            return True
        self.label = ("Rendering the Cycles reference" if "ours" in st else
                      "Rendering GI Preview" if "ref" in st else "Rendering GI Preview and the Cycles reference")
        return False

    def finish(self):
        self.steps["Measuring"]()
        self.label = "Filling render slots"
        self.steps["Filling render slots"]()
        self.fraction = 1.0

    def cancel(self) -> float:
        """Stop everything now; the milliseconds until the Cycles process was gone."""
        t0 = time.perf_counter()
        self.cancelled = True
        if self.future is not None:
            self.future.cancel_event.set()
        if self.ref_proc is not None:
            self.ref_proc.kill()
        return (time.perf_counter() - t0) * 1e3


def _fmt(v, f="{:.4g}"):
    """A metric for the Compare table ("-" when missing)."""
    if v is None:
        return "-"
    try:
        return f.format(v)
    except (TypeError, ValueError):
        return str(v)


classes = (GIPreviewComparison, GIPREVIEW_OT_compare)


def register_props():
    """Attach ``Scene.gi_preview_comparison`` (call after registering ``classes``)."""
    bpy.types.Scene.gi_preview_comparison = bpy.props.PointerProperty(type=GIPreviewComparison)


def unregister_props():
    if hasattr(bpy.types.Scene, "gi_preview_comparison"):
        del bpy.types.Scene.gi_preview_comparison
