"""Cycles references for the comparison: fair settings, every setting restored, cached.

``render_cycles(scene, spp, kind, seed)`` renders the scene's camera, frame and resolution
with Cycles and returns ``(image, time_ms)``: image float32 (H, W, 4), linear, row 0 = bottom.
``get_reference(...)`` does the same through the on-disk cache (key: the exported scene's
fingerprint + kind + spp + bounces + resolution + seed + Blender version), so a material or
light change invalidates the entry and an unchanged scene is served from disk.

Fair settings (see BLENDER_NOTES.md, "Cycles defaults that spoil a numeric comparison"):
CPU device; box pixel filter of width 1 (each pixel integrates exactly its own square, like
a rasteriser's pixel centre sample averaged over jitter); no denoising (scene and every view
layer); no clamping (direct 0, indirect 0); ``blur_glossy`` 0; no adaptive sampling, no time
limit, no sample subset, view-layer sample overrides ignored; fixed seed, not animated;
light tree on (Cycles' default); caustics reflective and refractive on (Cycles' defaults);
no path guiding; no fast-GI approximation; film opaque, exposure 1; no motion blur, no
compositing, no sequencer, no border, 100 % resolution; output EXR float32 (scene-linear:
the view transform is also set to Standard/no look/exposure 0/gamma 1 so nothing else can
leak in).

Reference kinds (bounce limits set on purpose, ``KIND_BOUNCES``):

* ``full``: max 12 bounces, diffuse/glossy/transmission 12 each, transparent 8, volume 0
  (GI Preview does not render volumes): the ground truth.
* ``direct``: all bounces 0. Emission + light arriving straight from lights and the world
  (with shadows), reflected once by the first surface, diffuse and specular.
* ``one_bounce``: max 1, diffuse 1, glossy 1, transmission 1: direct light plus exactly one
  indirect bounce *of any lobe*. Chosen over "diffuse 1, glossy 0" because the truncation
  this reference removes is path *depth*: a one-bounce technique (RSM, LPV, DDGI, ReSTIR GI
  with one bounce, SSR) models paths camera -> surface -> surface -> light, whatever the
  lobes. With glossy 0 a mirror would show no reflection at all, and a technique that does
  reflect one bounce (SSR, probes) would be charged for it as "error".
* ``ao``: ambient occlusion as Cycles computes it (the Ambient Occlusion shader node,
  cosine-weighted, ``ao_distance``), rendered through a temporary material override with an
  emission = AO value, 0 bounces, transparent film; background pixels are 1 (unoccluded).
  Cycles' own AO *pass* is not used: with the PyPI bpy 5.0 module, neither ``save_render``
  nor ``render(write_still=True)`` writes any pass other than Combined into a multilayer
  EXR (checked), and Render Result pixels are not readable from Python. The temporary
  material is deleted afterwards.

Cancel: one Cycles render is a single blocking ``bpy.ops.render.render()`` call which cannot
be interrupted from Python; ``cancel()`` is checked before a render starts and after it ends
(the result is then discarded). Callers that render several things (the Cycles curve) check
it between renders.

Nothing is left behind: every touched setting is restored by :class:`SettingsGuard` in a
``finally`` (also on exceptions and cancel), temporary data-blocks are removed, and the
temporary EXR file is deleted. Only the 'Render Result' image keeps the last render, as it
does after any F12.
"""
from __future__ import annotations

import os
import re
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

import bpy

from ..compare import cache as _cache
from ..compare import imageio

KINDS = ("full", "direct", "one_bounce", "ao")
FAIR_SETTINGS_SUMMARY = (
    "CPU; box pixel filter 1 px; no denoising; no clamping (direct/indirect 0); filter glossy 0; "
    "no adaptive sampling, no time limit; fixed seed; light tree and caustics on (Cycles defaults); "
    "no path guiding, no fast GI; opaque film; no motion blur, compositing or sequencer; "
    "32-bit float EXR, scene-linear")
DEFAULT_SEED = 0
DEFAULT_AO_DISTANCE = 1.0

_B = ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces",
      "transparent_max_bounces")
KIND_BOUNCES = {
    "full": dict(zip(_B, (12, 12, 12, 12, 0, 8))),
    "direct": dict(zip(_B, (0, 0, 0, 0, 0, 8))),
    "one_bounce": dict(zip(_B, (1, 1, 1, 1, 0, 8))),
    "ao": dict(zip(_B, (0, 0, 0, 0, 0, 8))),
}


class ReferenceCancelled(Exception):
    """Raised when ``cancel()`` returned True before or after a Cycles render."""


def ensure_oiio():
    """Make Blender's bundled OpenImageIO importable (PyPI bpy needs this) and return it."""
    try:
        bpy.utils.expose_bundled_modules()
    except AttributeError:  # a Blender build where it is importable already
        pass
    return imageio.oiio()


# ---------------------------------------------------------------- settings guard
_SEG = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)(?:\[("([^"]*)"|\'([^\']*)\'|(-?\d+))\])?$')


def _split(path: str) -> list[tuple[str, object]]:
    out = []
    # split on dots outside of brackets/quotes
    parts, buf, depth, quote = [], "", 0, None
    for ch in path:
        if quote:
            buf += ch
            if ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        if ch == "." and depth == 0:
            parts.append(buf)
            buf = ""
        else:
            buf += ch
    parts.append(buf)
    for p in parts:
        m = _SEG.match(p)
        if not m:
            raise ValueError(f"bad attribute path segment {p!r} in {path!r}")
        key = m.group(3) if m.group(3) is not None else m.group(4)
        if key is None and m.group(5) is not None:
            key = int(m.group(5))
        out.append((m.group(1), key))
    return out


def resolve(root, path: str):
    """(owner, attribute name) of a dotted path like ``view_layers["ViewLayer"].cycles.use_denoising``."""
    segs = _split(path)
    obj = root
    for i, (name, key) in enumerate(segs):
        last = i == len(segs) - 1
        if last and key is None:
            return obj, name
        obj = getattr(obj, name)
        if key is not None:
            obj = obj[key]
    raise ValueError(f"path {path!r} ends in an item, not an attribute")


def _plain(v):
    """A comparable, detached copy of a property value (bpy arrays -> tuples)."""
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    try:
        if hasattr(v, "bl_rna") or hasattr(v, "rna_type"):
            return v  # an ID/struct pointer: compare by identity
    except ReferenceError:
        return None
    try:
        return tuple(v)
    except TypeError:
        return v


def get_path(root, path: str):
    owner, attr = resolve(root, path)
    return _plain(getattr(owner, attr))


class SettingsGuard:
    """Set attributes by path and put every one back on exit, even on exceptions.

    ``guard.set(path, value)`` records the original value the first time a path is touched,
    then sets. On exit values are restored in the order they were first set, with retries:
    some enums depend on others (``image_settings.color_depth`` is valid only for the file
    format it was recorded with), so a restore that fails is retried after the others, until
    no progress is made. Cleanups registered with ``on_exit`` run after the restore.
    ``touched`` lists the paths; ``snapshot()`` reads their current values.
    """

    def __init__(self, root):
        self.root = root
        self._orig: dict[str, object] = {}
        self._order: list[str] = []
        self._cleanups = []
        self.errors: list[str] = []

    @property
    def touched(self) -> list[str]:
        return list(self._order)

    def record(self, path: str):
        """Remember a path's current value (once) without changing it. Record every path
        before setting any when settings interact (setting ``file_format`` silently changes
        ``color_depth``: recording it afterwards would save the wrong original)."""
        if path not in self._orig:
            owner, attr = resolve(self.root, path)
            self._orig[path] = _plain(getattr(owner, attr))
            self._order.append(path)

    def set(self, path: str, value):
        self.record(path)
        owner, attr = resolve(self.root, path)
        setattr(owner, attr, value)

    def on_exit(self, fn):
        self._cleanups.append(fn)

    def snapshot(self, paths=None) -> dict:
        out = {}
        for p in (paths if paths is not None else self._order):
            try:
                out[p] = get_path(self.root, p)
            except Exception as e:  # noqa: BLE001
                out[p] = f"<error {e}>"
        return out

    def restore(self):
        pending = list(self._order)
        last_err = {}
        while pending:
            failed = []
            for p in pending:
                try:
                    owner, attr = resolve(self.root, p)
                    if _plain(getattr(owner, attr)) != self._orig[p]:
                        setattr(owner, attr, self._orig[p])
                except Exception as e:  # noqa: BLE001
                    failed.append(p)
                    last_err[p] = e
            if len(failed) == len(pending):
                self.errors.extend(f"could not restore {p}: {last_err[p]}" for p in failed)
                break
            pending = failed
        for fn in reversed(self._cleanups):
            try:
                fn()
            except Exception as e:  # noqa: BLE001
                self.errors.append(f"cleanup failed: {e}")
        self._cleanups.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.restore()
        return False


# ---------------------------------------------------------------- the settings
def _vl_path(vl) -> str:
    return f'view_layers["{vl.name}"]'


def fair_settings(scene, kind: str, spp: int, seed: int = DEFAULT_SEED,
                  width: int | None = None, height: int | None = None, *,
                  denoise: bool = False) -> list[tuple[str, object]]:
    """The (path relative to the scene, value) pairs applied for a reference, in order.

    ``denoise=True`` gives the ``cycles_denoised`` baseline instead: the same settings with
    :func:`denoise_settings` (OpenImageDenoise with albedo and normal guides) replacing
    "no denoising"."""
    if kind not in KINDS:
        raise ValueError(f"unknown reference kind {kind!r}; one of {KINDS}")
    s = [("render.engine", "CYCLES"),
         ("cycles.device", "CPU"),
         ("cycles.samples", int(spp)),
         ("cycles.use_adaptive_sampling", False),
         ("cycles.time_limit", 0.0),
         ("cycles.use_sample_subset", False),
         ("cycles.use_layer_samples", "IGNORE"),
         ("cycles.use_denoising", False),
         ("cycles.pixel_filter_type", "BOX"),
         ("cycles.filter_width", 1.0),
         ("cycles.sample_clamp_direct", 0.0),
         ("cycles.sample_clamp_indirect", 0.0),
         ("cycles.blur_glossy", 0.0),
         ("cycles.seed", int(seed)),
         ("cycles.use_animated_seed", False),
         ("cycles.use_light_tree", True),
         ("cycles.caustics_reflective", True),
         ("cycles.caustics_refractive", True),
         ("cycles.min_light_bounces", 0),
         ("cycles.min_transparent_bounces", 0),
         ("cycles.use_guiding", False),
         ("cycles.use_fast_gi", False),
         ("cycles.film_exposure", 1.0),
         ("cycles.use_camera_cull", False),
         ("cycles.use_distance_cull", False),
         ("cycles.texture_limit_render", "OFF")]
    for k, v in KIND_BOUNCES[kind].items():
        s.append((f"cycles.{k}", v))
    for vl in scene.view_layers:
        s.append((f"{_vl_path(vl)}.cycles.use_denoising", False))
    if denoise:
        dn = denoise_settings(scene)
        paths = {p for p, _ in dn}
        s = [(p, v) for p, v in s if p not in paths] + dn
    return s + output_settings(transparent=kind == "ao", width=width, height=height)


def denoise_settings(scene) -> list[tuple[str, object]]:
    """Cycles with Blender's OpenImageDenoise on the CPU, fed the albedo and normal guide
    passes (``RGB_ALBEDO_NORMAL``), prefilter "Accurate", quality "High": what an artist
    turns on for a quick, clean preview. Denoising is enabled on every view layer too
    (Cycles denoises only where both the scene and the layer flag are on)."""
    s = [("cycles.use_denoising", True),
         ("cycles.denoiser", "OPENIMAGEDENOISE"),
         ("cycles.denoising_input_passes", "RGB_ALBEDO_NORMAL"),
         ("cycles.denoising_prefilter", "ACCURATE")]
    for name, value in (("denoising_quality", "HIGH"), ("denoising_use_gpu", False)):
        if hasattr(scene.cycles, name):  # Blender 4.1+ / 4.2+
            s.append((f"cycles.{name}", value))
    for vl in scene.view_layers:
        s.append((f"{_vl_path(vl)}.cycles.use_denoising", True))
    return s


def eevee_settings(scene, samples: int, width: int | None = None,
                   height: int | None = None) -> list[tuple[str, object]]:
    """EEVEE (Blender 4.2+ ``BLENDER_EEVEE``) as an artist previews GI with it: ``samples``
    render samples, ray tracing on (``use_raytracing``, screen-space tracing at full
    resolution, its denoiser on, rays above roughness 0.5 from the horizon scan), fast GI
    (horizon scan) in "Global Illumination" mode, shadows on, no clamping of direct or
    indirect light (the Cycles references are not clamped either), pixel filter 1.5 px
    (Blender's default). Everything else stays as the scene has it; the output settings are
    the references' (:func:`output_settings`)."""
    e = [("render.engine", "BLENDER_EEVEE"),
         ("eevee.taa_render_samples", int(samples)),
         ("eevee.use_raytracing", True),
         ("eevee.ray_tracing_method", "SCREEN"),
         ("eevee.ray_tracing_options.resolution_scale", "1"),
         ("eevee.ray_tracing_options.use_denoise", True),
         ("eevee.ray_tracing_options.trace_max_roughness", 0.5),
         ("eevee.use_fast_gi", True),
         ("eevee.fast_gi_method", "GLOBAL_ILLUMINATION"),
         ("eevee.use_shadows", True),
         ("eevee.clamp_surface_direct", 0.0),
         ("eevee.clamp_surface_indirect", 0.0),
         ("render.filter_size", 1.5)]
    return e + output_settings(transparent=False, width=width, height=height)


def output_settings(*, transparent: bool, width: int | None = None,
                    height: int | None = None) -> list[tuple[str, object]]:
    """Film, post-processing and file settings shared by references and baselines: opaque
    (or transparent) film, no compositing/sequencer/border/motion blur, 100 %, 32-bit
    float EXR, scene-linear "Standard" view with nothing else applied."""
    s = [("render.film_transparent", bool(transparent)),
         ("render.use_compositing", False),
         ("render.use_sequencer", False),
         ("render.use_border", False),
         ("render.resolution_percentage", 100),
         ("render.use_motion_blur", False),
         ("render.image_settings.media_type", "IMAGE"),
         ("render.image_settings.file_format", "OPEN_EXR"),
         ("render.image_settings.color_depth", "32"),
         ("render.image_settings.color_mode", "RGBA"),
         ("render.image_settings.exr_codec", "ZIP"),
         ("render.image_settings.color_management", "FOLLOW_SCENE"),
         ("view_settings.view_transform", "Standard"),
         ("view_settings.look", "None"),
         ("view_settings.exposure", 0.0),
         ("view_settings.gamma", 1.0),
         ("view_settings.use_curve_mapping", False),
         ("view_settings.use_white_balance", False)]
    if width is not None:
        s.append(("render.resolution_x", int(width)))
    if height is not None:
        s.append(("render.resolution_y", int(height)))
    return s


def _ao_material(distance: float):
    mat = bpy.data.materials.new("GI Preview AO reference (temporary)")
    if mat.node_tree is None:  # Blender < 5: node trees are opt-in
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    ao = nt.nodes.new("ShaderNodeAmbientOcclusion")
    ao.samples = 16
    ao.only_local = False
    ao.inside = False
    ao.inputs["Distance"].default_value = float(distance)
    ao.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "ALL"
    nt.links.new(ao.outputs["AO"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def render_operator(scene, **kwargs):
    """``bpy.ops.render.render`` of ``scene`` at its own current frame, leaving the frame as
    it was. Blender's operator given ``scene=`` for a scene that is not the context's renders
    that scene at the context scene's frame and leaves it there; so the context's scene is
    overridden for the call instead, and a frame changed anyway is put back."""
    frame, subframe = scene.frame_current, scene.frame_subframe
    try:
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render(**kwargs)
    finally:
        if (scene.frame_current, scene.frame_subframe) != (frame, subframe):
            scene.frame_set(frame, subframe=subframe)


# test hook: the one call that renders (monkeypatched in tests to inject failures)
def _run_render(scene):
    render_operator(scene, use_viewport=False)


def render_cycles(scene, spp: int, kind: str = "full", seed: int = DEFAULT_SEED, *,
                  width: int | None = None, height: int | None = None,
                  ao_distance: float = DEFAULT_AO_DISTANCE, cancel=None,
                  guard_log: list | None = None, denoise: bool = False):
    """Render a Cycles reference of ``scene`` (its camera, frame, resolution unless width/
    height are given). Returns ``(image float32 (H, W, 4) row 0 bottom, time_ms)``; time_ms
    is the wall time of the render call (scene sync + BVH + path tracing [+ denoising]).

    ``denoise=True`` renders the ``cycles_denoised`` baseline (OpenImageDenoise with albedo
    and normal guides, :func:`denoise_settings`) instead of a reference.
    ``guard_log``: if a list is given, the touched paths are appended (for tests)."""
    if denoise and kind == "ao":
        raise ValueError("the 'ao' reference cannot be denoised")
    settings = fair_settings(scene, kind, spp, seed, width, height, denoise=denoise)
    return _render_with(scene, settings, "Cycles", ao_distance=ao_distance if kind == "ao" else None,
                        cancel=cancel, guard_log=guard_log)


def render_eevee(scene, samples: int, *, width: int | None = None, height: int | None = None,
                 cancel=None, guard_log: list | None = None):
    """Render ``scene`` with EEVEE and its ray-traced GI (:func:`eevee_settings`), every
    setting restored afterwards. Returns ``(image, time_ms)`` like :func:`render_cycles`.
    The first EEVEE render of a process compiles its shaders (tens of seconds on llvmpipe);
    :func:`baseline_curve` renders an untimed warm-up first and reports that cost apart."""
    settings = eevee_settings(scene, samples, width, height)
    return _render_with(scene, settings, "EEVEE", cancel=cancel, guard_log=guard_log)


def _render_with(scene, settings, engine_label: str, *, ao_distance=None, cancel=None,
                 guard_log=None):
    """Apply ``settings`` under a :class:`SettingsGuard`, render, read the EXR back, restore."""
    ensure_oiio()
    if scene.camera is None:
        raise RuntimeError(f"Scene '{scene.name}' has no camera: a {engine_label} render needs one")
    if cancel is not None and cancel():
        raise ReferenceCancelled(f"cancelled before the {engine_label} render")
    fd, tmp = tempfile.mkstemp(prefix="gi_preview_ref_", suffix=".exr")
    os.close(fd)
    guard = SettingsGuard(scene)
    try:
        with guard:
            for path, _ in settings:
                guard.record(path)
            for vl in scene.view_layers:
                guard.record(f"{_vl_path(vl)}.material_override")
            for path, value in settings:
                guard.set(path, value)
            if ao_distance is not None:
                mat = _ao_material(ao_distance)

                def _remove(m=mat):
                    bpy.data.materials.remove(m)
                guard.on_exit(_remove)
                for vl in scene.view_layers:
                    guard.set(f"{_vl_path(vl)}.material_override", mat)
            if guard_log is not None:
                guard_log.extend(guard.touched)
            t0 = time.perf_counter()
            _run_render(scene)
            time_ms = (time.perf_counter() - t0) * 1000.0
            rr = bpy.data.images.get("Render Result")
            if rr is None:
                raise RuntimeError(f"{engine_label} produced no Render Result")
            rr.save_render(tmp, scene=scene)
        image = imageio.read_exr(tmp)
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass
    if guard.errors:
        raise RuntimeError("settings not fully restored: " + "; ".join(guard.errors))
    if ao_distance is not None:
        a = image[:, :, 3:4]
        image[:, :, :3] = image[:, :, :3] + (1.0 - a)  # background (and edges) = unoccluded
        image[:, :, 3] = 1.0
    if cancel is not None and cancel():
        raise ReferenceCancelled(f"cancelled during the {engine_label} render")
    return image, time_ms


# ---------------------------------------------------------------- light-path passes
# Cycles' light-path passes by effect (render/effect_shares.py's names): the direct and
# indirect light passes are multiplied by their colour pass, as Cycles composes Combined
LIGHT_PASSES = ("Diffuse Direct", "Diffuse Indirect", "Diffuse Color", "Glossy Direct", "Glossy Indirect",
                "Glossy Color", "Transmission Direct", "Transmission Indirect", "Transmission Color",
                "Emission", "Environment")
_PASS_PROPS = {"Diffuse Direct": "use_pass_diffuse_direct", "Diffuse Indirect": "use_pass_diffuse_indirect",
               "Diffuse Color": "use_pass_diffuse_color", "Glossy Direct": "use_pass_glossy_direct",
               "Glossy Indirect": "use_pass_glossy_indirect", "Glossy Color": "use_pass_glossy_color",
               "Transmission Direct": "use_pass_transmission_direct",
               "Transmission Indirect": "use_pass_transmission_indirect",
               "Transmission Color": "use_pass_transmission_color", "Emission": "use_pass_emit",
               "Environment": "use_pass_environment"}


def _read_parts(path: str) -> dict:
    """Every part (subimage) of a multi-part EXR, as {layer name: (H, W, C)} row 0 = bottom
    (the compositor writes one part per pass)."""
    m = imageio.oiio()
    inp = m.ImageInput.open(path)
    if inp is None:
        raise RuntimeError(f"cannot read {path}: {m.geterror()}")
    out = {}
    try:
        i = 0
        while inp.seek_subimage(i, 0):
            spec = inp.spec()
            a = np.asarray(inp.read_image(i, 0, 0, spec.nchannels, "float"), np.float32)
            a = a.reshape(spec.height, spec.width, spec.nchannels)[::-1]
            name = str(spec.channelnames[0]).rsplit(".", 1)[0]
            out[name] = np.ascontiguousarray(a)
            i += 1
    finally:
        inp.close()
    return out


def render_cycles_light_passes(scene, spp: int, *, width: int | None = None, height: int | None = None,
                               seed: int = DEFAULT_SEED, guard_log: list | None = None) -> dict:
    """Cycles' light-path passes of ``scene`` (the full reference's settings) by effect:
    ``{"direct", "indirect_diffuse", "indirect_glossy", "transmission", "emission",
    "environment", "combined"}`` -> (H, W, 3) float32, row 0 = bottom.

    The passes reach a file only through the compositor (see the module notes on
    ``save_render``): a temporary compositor node group (Render Layers -> File Output,
    multilayer EXR) is set as the scene's ``compositing_node_group`` for the render; the
    view layer's pass switches, the node group and every render setting are restored or
    removed afterwards, so the user's scene is left as it was."""
    ensure_oiio()
    if scene.camera is None:
        raise RuntimeError(f"Scene '{scene.name}' has no camera: a Cycles render needs one")
    vl = scene.view_layers[0]
    settings = fair_settings(scene, "full", spp, seed, width, height)
    settings = [(p, v) for p, v in settings if p != "render.use_compositing"] + [("render.use_compositing", True)]
    settings += [(f"{_vl_path(vl)}.{prop}", True) for prop in _PASS_PROPS.values()]
    folder = tempfile.mkdtemp(prefix="gi_preview_passes_")
    guard = SettingsGuard(scene)
    out = {}
    try:
        with guard:
            for path, _ in settings:
                guard.record(path)
            guard.record("compositing_node_group")
            for path, value in settings:
                guard.set(path, value)
            ng = bpy.data.node_groups.new("gi_preview_light_passes", "CompositorNodeTree")
            guard.on_exit(lambda g=ng: bpy.data.node_groups.remove(g))
            rl = ng.nodes.new("CompositorNodeRLayers")
            rl.scene = scene
            rl.layer = vl.name
            fo = ng.nodes.new("CompositorNodeOutputFile")
            fo.directory = folder
            fo.file_name = "passes"
            fo.format.file_format = "OPEN_EXR_MULTILAYER"
            fo.format.color_depth = "32"
            for name in ("Image",) + LIGHT_PASSES:
                fo.file_output_items.new("RGBA", name)
                ng.links.new(rl.outputs[name], fo.inputs[name])
            guard.set("compositing_node_group", ng)
            if guard_log is not None:
                guard_log.extend(guard.touched)
            _run_render(scene)
        files = [f for f in os.listdir(folder) if f.endswith(".exr")]
        if not files:
            raise RuntimeError("Cycles wrote no light-pass file")
        layers = _read_parts(os.path.join(folder, files[0]))
    finally:
        for f in os.listdir(folder):
            try:
                os.unlink(os.path.join(folder, f))
            except OSError:
                pass
        try:
            os.rmdir(folder)
        except OSError:
            pass
    if guard.errors:
        raise RuntimeError("settings not fully restored: " + "; ".join(guard.errors))

    def layer(name):
        for k, v in layers.items():
            if k == name or k.endswith("." + name):
                return np.asarray(v[..., :3], np.float32)
        raise KeyError(f"pass {name!r} not in the file (layers: {sorted(layers)})")

    col = {k: layer(f"{k} Color") for k in ("Diffuse", "Glossy", "Transmission")}
    out["direct"] = sum(layer(f"{k} Direct") * col[k] for k in col)
    out["indirect_diffuse"] = layer("Diffuse Indirect") * col["Diffuse"]
    out["indirect_glossy"] = layer("Glossy Indirect") * col["Glossy"]
    out["transmission"] = layer("Transmission Indirect") * col["Transmission"]
    out["emission"] = layer("Emission")
    out["environment"] = layer("Environment")
    out["combined"] = layer("Image")
    return out


def cycles_effect_shares(scene, spp: int = 64, *, width: int | None = None, height: int | None = None) -> dict:
    """Each effect's share of the image's luminance from Cycles' light-path passes
    (:func:`render_cycles_light_passes`); the same definition as render/effect_shares.py."""
    from ..render.effect_shares import EFFECTS, LUMA

    p = render_cycles_light_passes(scene, spp, width=width, height=height)
    lum = {e: max(0.0, float(np.sum(np.asarray(p[e], np.float64) @ LUMA))) for e in EFFECTS}
    tot = sum(lum.values())
    return {e: (lum[e] / tot if tot > 0 else 0.0) for e in EFFECTS}


# ---------------------------------------------------------------- cached references
@dataclass
class Reference:
    image: np.ndarray
    time_ms: float
    spp: int
    kind: str
    seed: int
    bounces: dict
    width: int
    height: int
    cached: bool
    key: str
    fingerprint: str
    blender_version: str
    meta: dict = field(default_factory=dict)

    def info(self) -> dict:
        """JSON-friendly description (no pixels)."""
        return {"kind": self.kind, "spp": self.spp, "time_ms": self.time_ms, "seed": self.seed,
                "bounces": dict(self.bounces), "width": self.width, "height": self.height,
                "cached": self.cached, "key": self.key, "fingerprint": self.fingerprint,
                "blender_version": self.blender_version, "created": self.meta.get("created"),
                "ao_distance": self.meta.get("ao_distance")}


def default_cache_dir() -> str:
    """The installed extension's user folder (``references/``), else a user cache folder."""
    pkg = (__package__ or "").rsplit(".", 1)[0]
    if pkg.startswith("bl_ext."):
        try:
            return _cache.default_cache_dir(bpy.utils.extension_path_user(pkg, create=True))
        except Exception:  # noqa: BLE001 - fall back to the user cache
            pass
    return _cache.default_cache_dir()


def evaluated_depsgraph(scene, view_layer=None):
    """An evaluated depsgraph of ``scene`` (need not be the context scene)."""
    ctx = bpy.context
    vl = view_layer or (ctx.view_layer if getattr(ctx, "scene", None) == scene else scene.view_layers[0])
    if getattr(ctx, "scene", None) == scene and ctx.view_layer == vl:
        return ctx.evaluated_depsgraph_get()
    with ctx.temp_override(scene=scene, view_layer=vl):
        return bpy.context.evaluated_depsgraph_get()


def scene_fingerprint(scene, width: int, height: int, depsgraph=None) -> str:
    """The exported scene's fingerprint (geometry, materials, lights, camera, world, size)."""
    from .export import export_scene
    dg = depsgraph if depsgraph is not None else evaluated_depsgraph(scene)
    return export_scene(dg, width=width, height=height).fingerprint()


def resolution(scene) -> tuple[int, int]:
    r = scene.render
    return (int(r.resolution_x * r.resolution_percentage / 100),
            int(r.resolution_y * r.resolution_percentage / 100))


def get_reference(scene, kind: str = "full", spp: int = 256, *, seed: int = DEFAULT_SEED,
                  width: int | None = None, height: int | None = None, depsgraph=None,
                  fingerprint: str | None = None, cache_dir: str | None = None,
                  use_cache: bool = True, ao_distance: float = DEFAULT_AO_DISTANCE,
                  cancel=None) -> Reference:
    """A Cycles reference from the cache, or rendered (and stored). ``width``/``height``
    default to the scene's output resolution (percentage applied)."""
    ensure_oiio()
    w0, h0 = resolution(scene)
    width, height = int(width or w0), int(height or h0)
    fp = fingerprint or scene_fingerprint(scene, width, height, depsgraph)
    version = ".".join(str(v) for v in bpy.app.version)
    bounces = dict(KIND_BOUNCES[kind])
    extra = {"ao_distance": float(ao_distance)} if kind == "ao" else {}
    key = _cache.reference_key(fp, kind, spp, bounces, (width, height), seed, bpy.app.version, **extra)
    store = _cache.ReferenceCache(cache_dir or default_cache_dir())
    if use_cache:
        hit = store.get(key)
        if hit is not None and hit[0].shape[:2] == (height, width):
            image, meta = hit
            return Reference(image=image, time_ms=float(meta.get("time_ms", 0.0)), spp=int(spp),
                             kind=kind, seed=seed, bounces=bounces, width=width, height=height,
                             cached=True, key=key, fingerprint=fp, blender_version=version, meta=meta)
    image, time_ms = render_cycles(scene, spp, kind, seed, width=width, height=height,
                                   ao_distance=ao_distance, cancel=cancel)
    meta = {"spp": int(spp), "time_ms": time_ms, "blender_version": version, "bounces": bounces,
            "kind": kind, "seed": int(seed), "width": width, "height": height, "fingerprint": fp,
            "scene": scene.name, "settings": "box filter 1px, no denoise, no clamp, no blur_glossy, "
            "no adaptive, fixed seed, light tree, CPU", **extra}
    store.put(key, image, meta)
    meta["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    return Reference(image=image, time_ms=time_ms, spp=int(spp), kind=kind, seed=seed,
                     bounces=bounces, width=width, height=height, cached=False, key=key,
                     fingerprint=fp, blender_version=version, meta=meta)


def cycles_curve(scene, spp_list, reference: Reference, *, kind: str | None = None,
                 seed: int = DEFAULT_SEED + 1, metrics_fn=None, progress=None, cancel=None) -> list[dict]:
    """Cycles at each spp in ``spp_list`` (never cached: the times are the point), measured
    against ``reference``. A seed different from the reference's keeps the noise independent.
    Returns [{"spp", "time_ms", "relmse", "flip", "ssim"}], plus "image" (for callers)."""
    from ..compare import metrics as M
    metrics_fn = metrics_fn or (lambda t, r: M.compare(t, r))
    out = []
    for i, spp in enumerate(spp_list):
        if cancel is not None and cancel():
            raise ReferenceCancelled("cancelled during the Cycles curve")
        img, ms = render_cycles(scene, int(spp), kind or reference.kind, seed,
                                width=reference.width, height=reference.height, cancel=cancel)
        m = metrics_fn(img, reference.image)
        out.append({"spp": int(spp), "time_ms": ms, "relmse": m["relmse"], "flip": m.get("flip"),
                    "ssim": m.get("ssim"), "image": img})
        if progress is not None:
            progress(i + 1, len(spp_list), spp, ms)
    return out


# ---------------------------------------------------------------- baselines
BASELINES = ("cycles", "cycles_denoised", "eevee")
BASELINE_LABELS = {"cycles": "Cycles", "cycles_denoised": "Cycles + OpenImageDenoise",
                   "eevee": "EEVEE (ray tracing)"}


def render_baseline(scene, baseline: str, spp: int, kind: str = "full", seed: int = DEFAULT_SEED + 1, *,
                    width: int | None = None, height: int | None = None, cancel=None):
    """One render of a baseline (``cycles``, ``cycles_denoised``, ``eevee``) at ``spp``
    samples; returns ``(image, wall_ms)``. EEVEE and denoised Cycles exist for ``full`` only
    (EEVEE has no bounce limits to match the other reference kinds)."""
    if baseline not in BASELINES:
        raise ValueError(f"unknown baseline {baseline!r}; one of {BASELINES}")
    if baseline != "cycles" and kind != "full":
        raise ValueError(f"baseline {baseline!r} is measured against the 'full' reference only, not {kind!r}")
    if baseline == "eevee":
        return render_eevee(scene, spp, width=width, height=height, cancel=cancel)
    return render_cycles(scene, spp, kind, seed, width=width, height=height, cancel=cancel,
                         denoise=baseline == "cycles_denoised")


def baseline_curve(scene, baseline: str, spp_list, reference: Reference, *, seed: int = DEFAULT_SEED + 1,
                   setup_ms: float | None = None, warmup: int | bool = True, metrics_fn=None, progress=None,
                   cancel=None) -> dict:
    """A baseline's error-vs-time curve against ``reference``, per-frame time apart from setup.

    Each spp of ``spp_list`` is rendered once (never cached: the times are the point), after
    untimed warm-up renders (``warmup``: a count, or True for the default): one at the
    smallest spp for Cycles (it loads its kernels, OpenImageDenoise initialises); for EEVEE
    one at the smallest and one at the next spp, because EEVEE compiles shaders in its
    first render (about 35 s on llvmpipe with a cold Mesa shader cache, 4 s with a warm
    one) and again in its first render with more than one sample (+3 s at 64-128 px,
    measured: 6.0 s for 2 samples the first time, 3.3 s later). ``warmup_ms`` is their total;
    minus the timed renders at the same spp it is reported as ``first_render_extra_ms``.

    Timing (:func:`..compare.sweep.fit_setup`): the wall times are fitted as
    ``setup + per_sample * spp``. ``setup`` is what every render call pays once whatever the
    sample count (scene sync, BVH build, EEVEE's per-render set-up), ``per_sample`` the cost
    of one sample. A point's ``time_ms`` is the per-frame time without setup:
    ``wall_ms - setup_ms`` on the fitted line, i.e. ``per_sample * spp`` for Cycles and
    EEVEE. For ``cycles_denoised`` pass the plain Cycles curve's ``setup_ms``: the
    denoiser's own fixed cost is paid every frame, so it stays in ``time_ms``.

    Returns ``{"baseline", "label", "kind", "setup_ms", "per_sample_ms", "fit",
    "warmup_ms", "first_render_extra_ms", "points": [{"spp", "time_ms", "wall_ms",
    "setup_ms", "relmse", "flip", "ssim", "image"}]}`` (drop "image" before writing JSON).
    """
    from ..compare import metrics as M
    from ..compare import sweep
    metrics_fn = metrics_fn or (lambda t, r: M.compare(t, r))
    spp_list = sorted({int(s) for s in spp_list})
    if not spp_list or spp_list[0] < 1:
        raise ValueError(f"baseline {baseline}: spp list must hold positive integers, got {spp_list}")
    kw = dict(kind=reference.kind, seed=seed, width=reference.width, height=reference.height, cancel=cancel)
    n_warm = (2 if baseline == "eevee" else 1) if warmup is True else int(warmup)
    warm_spp = [spp_list[min(i, len(spp_list) - 1)] for i in range(n_warm)]
    warm_ms = None
    for spp in warm_spp:
        _, ms = render_baseline(scene, baseline, spp, **kw)
        warm_ms = (warm_ms or 0.0) + ms
    pts = []
    for i, spp in enumerate(spp_list):
        if cancel is not None and cancel():
            raise ReferenceCancelled(f"cancelled during the {baseline} curve")
        img, ms = render_baseline(scene, baseline, spp, **kw)
        m = metrics_fn(img, reference.image)
        pts.append({"spp": spp, "wall_ms": ms, "relmse": m["relmse"], "flip": m.get("flip"),
                    "ssim": m.get("ssim"), "image": img})
        if progress is not None:
            progress(i + 1, len(spp_list), spp, ms)
    fit = sweep.fit_setup([(p["spp"], p["wall_ms"]) for p in pts])
    setup = fit["setup_ms"] if setup_ms is None else max(0.0, min(float(setup_ms), min(p["wall_ms"] for p in pts)))
    for p in pts:
        fitted_wall = fit["setup_ms"] + fit["per_sample_ms"] * p["spp"] if fit["ok"] else p["wall_ms"]
        p["time_ms"] = max(fitted_wall - setup, 1e-3)
        p["setup_ms"] = setup
    return {"baseline": baseline, "label": BASELINE_LABELS[baseline], "kind": reference.kind,
            "setup_ms": setup, "per_sample_ms": fit["per_sample_ms"], "fit": fit,
            "warmup_ms": warm_ms,
            "warmup_renders": n_warm, "warmup_spp": warm_spp,
            "first_render_extra_ms": (warm_ms - sum(next(p["wall_ms"] for p in pts if p["spp"] == w)
                                                    for w in warm_spp)) if warm_ms is not None else None,
            "points": pts}
