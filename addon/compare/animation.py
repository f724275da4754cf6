"""Per-frame comparison of an animation with Cycles (``gi_compare.py --animation``).

Temporal techniques (SVGF, TAA, ReSTIR, probes, caches) are judged over an animation, not only
as a converged still: each frame is compared with a Cycles reference of that frame, and the
run reports

* ``relmse[t]``: error of the frame shown at index ``t`` against Cycles' frame ``t``;
* ``frame_diff[t]`` = mean |I_t - I_(t-1)| over pixels and RGB (linear), ours and Cycles';
  the **stability figure** is its mean over the moving frames, ours / Cycles' (boiling,
  flicker and lag show here);
* ``disoccluded[t]``: error in the pixels of frame ``t`` that were not visible in frame
  ``t-1`` (from the depth of both frames and the two cameras: off-screen or hidden);
* the **ghost trail**: the camera moves for ``move`` frames, then holds still for ``hold``
  frames; the *trail mask* is the final pose's pixels not visible from the pose ``trail_k``
  frames before the stop (for a light move: the pixels whose Cycles value changed by more
  than 20 % over those frames). Its error on every held frame ``t`` is compared with the
  *still level* of that frame: the same technique rendered with the camera still at the final
  pose from the start (same warm-up, as many frames), its error on the same frame ``t`` in the
  same mask. ``ratio_at_8`` is that ratio 8 frames after the stop; ``recovered_after`` is the
  first held frame within ``RECOVERY_TOLERANCE`` x its still level.

  Why frame ``t`` against frame ``t`` (a paired comparison) and not against a still run's tail:
  the session seeds a frame's noise with its frame counter, which both runs count alike (warm-up
  included), so on held frame ``t`` both render the same pose with the same seeds and jitter;
  only their histories differ, and what the history carries from before the stop is exactly
  what the trail measures. Measured on the 48-px Cornell pan (43 trail pixels, TAA, 12 seed
  offsets): the trail error at +8 and the still error of the same frame correlate at 0.91, the
  per-seed ratio spreads 0.95-1.42x (sd 0.13) where the +8 frame against the mean of the last 4
  frames of an 11-frame still run spread 0.66-1.68x; and that shorter run's level was not the
  still level at all: the still error keeps falling after frame 10 (0.0199 over its frames 7-10,
  0.0169 on frame 20), which biased the old ratio low by ~15 %.
  ``draws`` > 1 repeats both runs with independent noise (each draw after the first starts in
  the same sessions from a camera cut and a warm-up, as an F12 animation starts, so the frame
  counter runs on) and reports the ratio of the mean trail error to the mean still error per
  held frame (``ratio_at_8_per_draw`` keeps the single draws). A still run shorter than the
  moving run (a caller's own) falls back to the mean of its last ``STILL_TAIL`` frames.

Motions (``MOTIONS``): ``scene`` (the file's own animation, from ``frame_start``), ``orbit``
(the camera turns about the vertical axis through the point it looks at, ``amount`` degrees),
``dolly`` (towards that point, ``amount`` x its distance), ``pan`` (sideways, ``amount`` x the
distance), ``light`` (the most powerful lamp: a sun turns about the vertical by ``amount``
degrees, any other lamp moves along the camera's right axis by ``amount`` x the distance).
Built-in motions move the objects' ``matrix_world`` and put everything back afterwards
(scene frame included): comparing never changes the user's scene.

Cycles references per frame are small and cached (``cache.ReferenceCache``, keyed like the
still references plus ``denoise``): by default 256 spp + OpenImageDenoise (albedo + normal
guides), so their own frame-to-frame difference measures the motion and not Cycles' noise;
the part that is still noise is measured as ``cycles.noise_floor`` (mean |difference| of two
renders of frame 0 with different seeds) and reported beside it.

This module imports no bpy: the caller hands in the Blender scene and the add-on's modules
(``reference``, ``export``, ``session``), as ``scripts/gi_compare.py`` does.
"""
from __future__ import annotations

import base64
import html
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from . import cache as _cache

MOTIONS = ("orbit", "dolly", "pan", "light", "scene")
DEFAULT_AMOUNT = {"orbit": 12.0, "dolly": 0.15, "pan": 0.12, "light": 0.15, "scene": 0.0}
SUN_DEFAULT_DEGREES = 30.0
RECOVERY_TOLERANCE = 1.5  # trail error within 1.5x the still level counts as "gone"
TRAIL_K = 8
STILL_TAIL = 4
RELIT_THRESHOLD = 0.2


@dataclass
class AnimationSpec:
    """What to render: ``move`` frames of motion after the start pose, then ``hold`` still."""

    motion: str = "orbit"
    move: int = 12
    hold: int = 10
    amount: float | None = None
    ref_spp: int = 256
    ref_denoise: bool = True
    seed: int = 0
    warmup: bool = True        # the first frame runs the technique's warm-up (as an F12 animation does)
    still_run: bool = True     # render the still-camera run for the ghost-trail level
    draws: int = 1             # independent noise draws of the (moving, still) pair; see the module doc
    trail_k: int = TRAIL_K
    amount_default: bool = field(default=False, init=False)

    def __post_init__(self):
        if self.motion not in MOTIONS:
            raise ValueError(f"unknown animation motion {self.motion!r}; choose one of {', '.join(MOTIONS)}")
        if self.move < 1 or self.hold < 0:
            raise ValueError(f"an animation needs >= 1 moving frame and >= 0 held frames (got {self.move}, {self.hold})")
        if self.ref_spp < 1:
            raise ValueError("the per-frame Cycles references need >= 1 spp")
        if int(self.draws) < 1:
            raise ValueError(f"an animation needs >= 1 noise draw (got {self.draws})")
        self.amount_default = self.amount is None
        if self.amount is None:
            self.amount = DEFAULT_AMOUNT[self.motion]

    @property
    def frames(self) -> int:
        return self.move + 1 + self.hold

    def s(self, i: int) -> float:
        """Motion parameter of frame ``i``: 0 at the start pose, 1 from the stop on."""
        return min(i, self.move) / float(self.move)


# ---------------------------------------------------------------- motion paths (numpy)
def _rot_z(deg: float) -> np.ndarray:
    a = math.radians(deg)
    m = np.eye(4)
    m[0, 0], m[0, 1], m[1, 0], m[1, 1] = math.cos(a), -math.sin(a), math.sin(a), math.cos(a)
    return m


def camera_matrix(m0: np.ndarray, motion: str, s: float, amount: float, distance: float) -> np.ndarray:
    """The camera-to-world matrix at motion parameter ``s`` in [0, 1] (``m0`` at 0)."""
    m0 = np.asarray(m0, np.float64)
    pos, fwd, right = m0[:3, 3], -m0[:3, 2], m0[:3, 0]
    fwd = fwd / max(np.linalg.norm(fwd), 1e-12)
    m = m0.copy()
    if motion == "orbit":
        pivot = pos + fwd * distance
        t1, t2 = np.eye(4), np.eye(4)
        t1[:3, 3], t2[:3, 3] = -pivot, pivot
        m = t2 @ _rot_z(amount * s) @ t1 @ m0
    elif motion == "dolly":
        m[:3, 3] = pos + fwd * (amount * distance * s)
    elif motion == "pan":
        m[:3, 3] = pos + right / max(np.linalg.norm(right), 1e-12) * (amount * distance * s)
    return m


def light_matrix(l0: np.ndarray, is_sun: bool, s: float, amount: float, distance: float,
                 cam_right: np.ndarray) -> np.ndarray:
    """A lamp's matrix at ``s``: a sun turned about world Z (its position is irrelevant),
    another lamp moved along the camera's right axis."""
    l0 = np.asarray(l0, np.float64)
    if is_sun:
        r = _rot_z(amount * s)
        m = l0.copy()
        m[:3, :3] = r[:3, :3] @ l0[:3, :3]
        return m
    m = l0.copy()
    cr = np.asarray(cam_right, np.float64)
    m[:3, 3] = l0[:3, 3] + cr / max(np.linalg.norm(cr), 1e-12) * (amount * distance * s)
    return m


# ---------------------------------------------------------------- image measures
def relmse_map(a, b) -> np.ndarray:
    a = np.asarray(a, np.float64)[..., :3]
    b = np.asarray(b, np.float64)[..., :3]
    return np.mean((a - b) ** 2 / (b ** 2 + 1e-2), axis=-1)


def masked_mean(m: np.ndarray, mask) -> float | None:
    if mask is None:
        return float(np.mean(m))
    return float(np.mean(m[mask])) if mask.any() else None


def frame_diff(a, b) -> float:
    """Mean absolute difference of two linear frames over pixels and RGB."""
    return float(np.mean(np.abs(np.asarray(a, np.float64)[..., :3] - np.asarray(b, np.float64)[..., :3])))


def _rays(cam, h, w):
    inv = np.linalg.inv(np.asarray(cam.projection, np.float64))
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, (ys + 0.5) / h * 2 - 1, np.ones((h, w)), np.ones((h, w))], -1)
    v = ndc @ inv.T
    d = v[..., :3] / v[..., 3:4]
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return d @ np.asarray(cam.matrix_world, np.float64)[:3, :3].T


def disoccluded(cam0, cam1, depth0, depth1, rel_tol: float = 0.03) -> np.ndarray:
    """Pixels of pose 1 (row 0 = bottom) whose surface point was not visible from pose 0:
    off-screen there, or hidden (pose 0's depth at its projection is nearer by more than
    ``rel_tol`` of the distance). ``cam*``: SceneData cameras; ``depth*``: (H, W) distance
    along the view axis, >= 1e9 on the background (background pixels are never in the mask).
    For a static scene this is exactly what motion vectors + a depth test give."""
    depth0 = np.asarray(depth0, np.float64)
    depth1 = np.asarray(depth1, np.float64)
    h, w = depth1.shape
    d = _rays(cam1, h, w)
    fwd = np.asarray(cam1.forward, np.float64)
    P = np.asarray(cam1.position, np.float64) + d * (depth1 / np.maximum(d @ fwd, 1e-6))[..., None]
    vp0 = np.asarray(cam0.projection, np.float64) @ np.asarray(cam0.view, np.float64)
    clip = np.concatenate([P, np.ones((h, w, 1))], -1) @ vp0.T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (clip[..., :2] / clip[..., 3:4] * 0.5 + 0.5) * np.array([w, h])
    uv = np.nan_to_num(uv, nan=-1.0, posinf=-1.0, neginf=-1.0)
    ix, iy = np.floor(uv[..., 0]).astype(np.int64), np.floor(uv[..., 1]).astype(np.int64)
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h) & (clip[..., 3] > 0)
    d0 = np.full((h, w), np.inf)
    d0[inside] = depth0[iy[inside], ix[inside]]
    dz = (P - np.asarray(cam0.position, np.float64)) @ np.asarray(cam0.forward, np.float64)
    # one-sided, as documented: hidden only behind something nearer. (A two-sided test also
    # flagged a point that was on screen and unoccluded but whose nearest pixel centre saw the
    # background or a farther part of a grazing wall: at an edge pixel the projection lands a
    # fraction of a pixel beyond the silhouette; 48 of 91 trail pixels of the 48-px Cornell pan.)
    hidden = d0 < dz - rel_tol * np.maximum(dz, 1e-3)
    return (~inside | hidden) & (depth1 < 1e9)


def relit(ref0, ref1, threshold: float = RELIT_THRESHOLD) -> np.ndarray:
    """Pixels whose Cycles value changed by more than ``threshold`` (relative, luminance)."""
    y0 = np.asarray(ref0, np.float64)[..., :3].mean(-1)
    y1 = np.asarray(ref1, np.float64)[..., :3].mean(-1)
    return np.abs(y1 - y0) > threshold * (np.maximum(y0, y1) + 1e-2)


# ---------------------------------------------------------------- analysis (pure)
def _analyse_one(spec: AnimationSpec, ours: list, refs: list, masks: list, trail_mask, still: list | None,
                 cycles_noise_floor: float | None = None) -> dict:
    """Numbers of one technique's run (one noise draw). ``ours``/``refs``: per-frame images; ``masks[t]``: the
    pixels disoccluded at frame t (None at t = 0); ``trail_mask``: see the module doc;
    ``still``: the still-camera run's frames at the final pose (or None)."""
    n = len(ours)
    maps = [relmse_map(o, r) for o, r in zip(ours, refs)]
    rel = [float(m.mean()) for m in maps]
    diff = [None] + [frame_diff(ours[t], ours[t - 1]) for t in range(1, n)]
    cdiff = [None] + [frame_diff(refs[t], refs[t - 1]) for t in range(1, n)]
    dis = [None] + [masked_mean(maps[t], masks[t]) if masks[t] is not None and masks[t].any() else None
                    for t in range(1, n)]
    stop = spec.move
    moving = range(1, stop + 1)
    stab = float(np.mean([diff[t] for t in moving]))
    stab_c = float(np.mean([cdiff[t] for t in moving]))
    hold_fl = float(np.mean([diff[t] for t in range(stop + 1, n)])) if n > stop + 1 else None
    means = [float(np.mean(o[..., :3])) / max(float(np.mean(r[..., :3])), 1e-12) for o, r in zip(ours, refs)]
    out = {
        "relmse": rel,
        "frame_diff": diff,
        "cycles_frame_diff": cdiff,
        "disoccluded_relmse": dis,
        "disoccluded_pixels": [None] + [int(masks[t].sum()) if masks[t] is not None else 0 for t in range(1, n)],
        "mean_ratio": means,
        "relmse_moving": float(np.mean([rel[t] for t in moving])),
        "relmse_hold": float(np.mean(rel[stop + 1:])) if n > stop + 1 else None,
        "stability": stab,
        "cycles_stability": stab_c,
        "stability_ratio": stab / stab_c if stab_c > 0 else None,
        "hold_flicker": hold_fl,
        "cycles_noise_floor": cycles_noise_floor,
        "nonfinite_pixels": int(sum(int((~np.isfinite(o[..., :3])).any(-1).sum()) for o in ours)),
        "max_value": float(max(np.nanmax(np.where(np.isfinite(o[..., :3]), o[..., :3], 0.0)) for o in ours)),
    }
    trail = {"mask_pixels": int(trail_mask.sum()) if trail_mask is not None else 0,
             "k": int(min(spec.trail_k, spec.move)), "tolerance": RECOVERY_TOLERANCE}
    if trail_mask is not None and trail_mask.sum() > 0 and n > stop + 1:
        per = [masked_mean(maps[t], trail_mask) for t in range(stop, n)]  # index 0 = the stop frame
        trail["relmse_after_stop"] = per
        if still:
            sm = [masked_mean(relmse_map(s, refs[-1]), trail_mask) for s in still]
            trail["still_relmse"] = sm
            # paired (the still run is as long as the moving one): held frame t is compared
            # with the still run's frame t, rendered with the same seeds; else (a shorter still
            # run) with the mean of its last STILL_TAIL frames. See the module doc.
            paired = len(still) == n
            tail = float(np.mean(sm[-STILL_TAIL:]))
            lv = [float(v) for v in sm[stop:]] if paired else [tail] * len(per)
            trail["paired"] = paired
            trail["still_after_stop"] = lv
            trail["still_level"] = tail
            _trail_ratios(trail, per, lv)
    out["trail"] = trail
    return out


def _trail_ratios(trail: dict, per: list, lv: list):
    trail["ratio_after_stop"] = [p / v if v > 0 else None for p, v in zip(per, lv)]
    trail["recovered_after"] = next((k for k, (p, v) in enumerate(zip(per, lv)) if p <= RECOVERY_TOLERANCE * v),
                                    None)
    k8 = min(8, len(per) - 1)
    trail["ratio_at_8"] = per[k8] / lv[k8] if lv[k8] > 0 else None
    trail["ratio_at_frame"] = k8


def analyse(spec: AnimationSpec, ours: list, refs: list, masks: list, trail_mask, still: list | None,
            cycles_noise_floor: float | None = None, draws: list | None = None) -> dict:
    """Numbers of one technique's run. ``ours``/``refs``: per-frame images; ``masks[t]``: the
    pixels disoccluded at frame t (None at t = 0); ``trail_mask``: see the module doc;
    ``still``: the still-camera run's frames at the final pose (or None); ``draws``: the
    further noise draws as (ours, still) pairs. With draws, the per-frame lists are the first
    draw's; relMSE moving/held, the stability figure and the trail error (moving and still,
    per held frame) are means over all draws, and the trail ratios are ratios of those means."""
    first = _analyse_one(spec, ours, refs, masks, trail_mask, still, cycles_noise_floor)
    if not draws:
        first["draws"] = 1
        return first
    runs = [first] + [_analyse_one(spec, o, refs, masks, trail_mask, s, cycles_noise_floor) for o, s in draws]
    out = dict(first)
    out["draws"] = len(runs)
    for k in ("relmse_moving", "relmse_hold", "stability", "hold_flicker"):
        vals = [r[k] for r in runs]
        out[k] = None if any(v is None for v in vals) else float(np.mean(vals))
    out["stability_per_draw"] = [r["stability_ratio"] for r in runs]
    out["relmse_hold_per_draw"] = [r["relmse_hold"] for r in runs]
    out["stability_ratio"] = out["stability"] / out["cycles_stability"] if out["cycles_stability"] > 0 else None
    out["nonfinite_pixels"] = int(sum(r["nonfinite_pixels"] for r in runs))
    out["max_value"] = float(max(r["max_value"] for r in runs))
    trail = dict(first["trail"])
    if all("relmse_after_stop" in r["trail"] for r in runs):
        trail["relmse_after_stop"] = [float(v) for v in np.mean([r["trail"]["relmse_after_stop"] for r in runs], 0)]
    if all("still_after_stop" in r["trail"] for r in runs):
        lv = [float(v) for v in np.mean([r["trail"]["still_after_stop"] for r in runs], 0)]
        trail["still_after_stop"] = lv
        trail["still_level"] = float(np.mean([r["trail"]["still_level"] for r in runs]))
        trail["ratio_at_8_per_draw"] = [r["trail"]["ratio_at_8"] for r in runs]
        _trail_ratios(trail, trail["relmse_after_stop"], lv)
    out["trail"] = trail
    return out


# ---------------------------------------------------------------- Blender side (duck-typed)
class _Restore:
    """Remember the moved objects' transform channels (location, rotation in every mode,
    scale) and the current frame; put them back exactly on exit."""

    _CHANNELS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale")

    def __init__(self, scene, objects):
        self.scene = scene
        self.frame = int(scene.frame_current)
        self.saved = [(ob, ob.rotation_mode, [(c, tuple(getattr(ob, c))) for c in self._CHANNELS]) for ob in objects]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for ob, mode, chans in self.saved:
            for c, v in chans:
                setattr(ob, c, v)
            ob.rotation_mode = mode
        if int(self.scene.frame_current) != self.frame:
            self.scene.frame_set(self.frame)
        return False


def _world_matrix(reference, scene, ob) -> np.ndarray:
    """The object's evaluated camera/lamp-to-world matrix (rows), whatever the depsgraph state."""
    dg = reference.evaluated_depsgraph(scene)
    return np.array([list(r) for r in ob.evaluated_get(dg).matrix_world], np.float64)


def _pick_light(scene):
    lamps = [ob for ob in scene.objects if ob.type == "LIGHT" and not ob.hide_render]
    if not lamps:
        raise ValueError(f"--animation light: scene '{scene.name}' has no lamp to move")

    def power(ob):
        d = ob.data
        return float(d.energy) * (50.0 if d.type == "SUN" else 1.0)  # a sun's W/m^2 lights everything
    return max(lamps, key=power)


def _animated(ob) -> bool:
    ad = getattr(ob, "animation_data", None)
    return bool(ad and (ad.action is not None or len(ad.drivers)))


def _release(session, key):
    fut = session.release_session(key)
    if fut is not None:
        fut.result(timeout=120)


def cached_frame_reference(reference, scene, sd, spec: AnimationSpec, cache_dir=None, use_cache=True,
                           seed=None) -> tuple[np.ndarray, float, bool]:
    """(image, time_ms, from cache) of the Cycles 'full' reference of the scene as it is now
    (``sd`` is its export: its fingerprint keys the cache), ``spec.ref_spp`` spp, denoised with
    OpenImageDenoise when ``spec.ref_denoise``."""
    bpy = reference.bpy
    seed = spec.seed if seed is None else int(seed)
    bounces = dict(reference.KIND_BOUNCES["full"])
    key = _cache.reference_key(sd.fingerprint(), "full", spec.ref_spp, bounces, (sd.width, sd.height), seed,
                               bpy.app.version, denoise="oidn_albedo_normal" if spec.ref_denoise else "none")
    store = _cache.ReferenceCache(cache_dir or reference.default_cache_dir())
    if use_cache:
        hit = store.get(key)
        if hit is not None and hit[0].shape[:2] == (sd.height, sd.width):
            return hit[0], float(hit[1].get("time_ms", 0.0)), True
    img, ms = reference.render_cycles(scene, spec.ref_spp, "full", seed, width=sd.width, height=sd.height,
                                      denoise=spec.ref_denoise)
    store.put(key, img, {"spp": spec.ref_spp, "time_ms": ms, "kind": "full", "seed": seed,
                         "denoise": bool(spec.ref_denoise), "width": sd.width, "height": sd.height,
                         "scene": scene.name, "animation_frame": True})
    return img, ms, False


def run(scene, spec: AnimationSpec, techniques, *, reference, export, session, width, height,
        quality=None, cache_dir=None, use_cache=True, log=print, depth_technique="DIRECT") -> dict:
    """Render the animation with every technique in ``techniques`` and compare each frame with
    Cycles. Returns {"animation": {...numbers...}, "frames": {tech: [images]}, "refs": [images],
    "trail_mask": mask}; the first key is JSON-ready (results.json's ``animation``)."""
    cam = scene.camera
    if cam is None:
        raise ValueError(f"Scene '{scene.name}' has no camera: an animation needs one")
    reference.ensure_oiio()  # the reference cache reads and writes EXR through Blender's OpenImageIO
    qual = quality or {}

    def export_now():
        return export.export_scene(reference.evaluated_depsgraph(scene), width=width, height=height)

    def depth_of(sd, key):
        r = session.render(sd, depth_technique, 0, 1, keep_history=False, session=key)
        return np.asarray(r.aovs["Depth"])[..., 0]

    movers = [cam]
    lamp = None
    if spec.motion == "light":
        lamp = _pick_light(scene)
        movers.append(lamp)
    if spec.motion in ("orbit", "dolly", "pan") and _animated(cam):
        raise ValueError(f"the camera '{cam.name}' is animated: its keys would override the built-in "
                         f"'{spec.motion}' move; use --animation scene")
    if lamp is not None and _animated(lamp):
        raise ValueError(f"the lamp '{lamp.name}' is animated; use --animation scene")
    dkey = ("anim_depth", id(scene))
    t_start = time.perf_counter()
    with _Restore(scene, movers):
        f0 = int(scene.frame_start) if spec.motion == "scene" else int(scene.frame_current)
        if spec.motion == "scene":
            scene.frame_set(f0)
        m_cam0 = _world_matrix(reference, scene, cam)
        m_l0 = _world_matrix(reference, scene, lamp) if lamp is not None else None
        sd0 = export_now()
        d0 = depth_of(sd0, dkey)
        fg = d0[d0 < 1e9]
        distance = float(np.median(fg)) if fg.size else 3.0
        is_sun = lamp is not None and lamp.data.type == "SUN"
        light_amount = (SUN_DEFAULT_DEGREES if spec.amount_default else spec.amount) if is_sun else spec.amount

        def pose(i):
            s = spec.s(i)
            if spec.motion == "scene":
                scene.frame_set(f0 + min(i, spec.move))
            elif spec.motion == "light":
                m = light_matrix(m_l0, is_sun, s, light_amount, distance, m_cam0[:3, 0])
                lamp.matrix_world = type(lamp.matrix_world)(m.tolist())
            else:
                m = camera_matrix(m_cam0, spec.motion, s, spec.amount, distance)
                cam.matrix_world = type(cam.matrix_world)(m.tolist())

        # ---- scene state per frame, Cycles references, depth
        sds, refs, depths, ref_ms, cached = [], [], [], [], 0
        for i in range(spec.frames):
            if i <= spec.move:
                pose(i)
                sd = export_now()
                img, ms, hit = cached_frame_reference(reference, scene, sd, spec, cache_dir, use_cache)
                depth = d0 if i == 0 else depth_of(sd, dkey)
            # held frames: the same pose, the same reference
            sds.append(sd)
            refs.append(img)
            depths.append(depth)
            if i <= spec.move:
                ref_ms.append(ms)
                cached += int(hit)
            log(f"  frame {i:3d}: Cycles {'cached' if (i <= spec.move and hit) else f'{ms:.0f} ms'}")
        # Cycles' noise floor: frame 0 again with another seed
        pose(0)
        alt, _, _ = cached_frame_reference(reference, scene, export_now(), spec, cache_dir, use_cache,
                                           seed=spec.seed + 1)
        noise_floor = frame_diff(alt, refs[0])
        pose(spec.move)
    # the scene is restored from here on; sds hold every frame's state
    _release(session, dkey)
    masks = [None] + [disoccluded(sds[t - 1].camera, sds[t].camera, depths[t - 1], depths[t])
                      if t <= spec.move else np.zeros_like(depths[t], bool) for t in range(1, spec.frames)]
    k = min(spec.trail_k, spec.move)
    if spec.motion == "light":
        trail_mask = relit(refs[spec.move - k], refs[spec.move]) & (depths[spec.move] < 1e9)
        trail_kind = "relit"
    else:
        trail_mask = disoccluded(sds[spec.move - k].camera, sds[spec.move].camera, depths[spec.move - k],
                                 depths[spec.move])
        trail_kind = "disoccluded"

    results, frames_out, still_out = {}, {}, {}
    for tech in techniques:
        q = qual.get(tech)
        q = q if q is not None else 1
        key, skey = ("anim", tech, id(scene)), ("anim_still", tech, id(scene))
        runs, ms, warm = [], [], [None, None]

        def play(which, sd_of, draw):
            # draw > 0 runs in the same session from a camera cut + warm-up (how an F12
            # animation starts): the history restarts, the frame counter (the seed) runs on
            imgs = []
            for i in range(spec.frames):
                kw = {"camera_cut": True} if (draw > 0 and i == 0) else {}
                r = session.render(sd_of(i), tech, q, 1, keep_history=True,
                                   warmup=bool(spec.warmup and i == 0), session=key if which == 0 else skey, **kw)
                imgs.append(np.asarray(r.image, np.float32))
                if which == 0:
                    ms.append(float(r.frame_ms))
                if i == 0 and draw == 0:
                    warm[which] = int(getattr(r, "warmup_frames", 0) or 0)
            return imgs

        still_wanted = spec.still_run and spec.hold > 0
        try:
            for d in range(int(spec.draws)):
                ours = play(0, lambda i: sds[i], d)
                # the still run: as many frames as the moving one, warm-up included, so frame t
                # of both draws the same seeds (the session's frame counter): held frame t is paired
                still = play(1, lambda i: sds[-1], d) if still_wanted else None
                runs.append((ours, still))
        finally:
            _release(session, key)
            if still_wanted:
                _release(session, skey)
        ours, still = runs[0]
        a = analyse(spec, ours, refs, masks, trail_mask, still, noise_floor, draws=runs[1:])
        if still is not None:
            # equal warm-up lengths: the two runs' frame t share their seeds
            a["trail"]["warmup_frames"] = warm
            a["trail"]["same_seeds"] = warm[0] == warm[1]
        a["quality"] = q
        a["frame_ms"] = float(np.median(ms))
        results[tech] = a
        frames_out[tech] = ours
        still_out[tech] = still
        tr = a["trail"]
        log(f"  {tech}: relMSE moving {a['relmse_moving']:.4f}, held {a['relmse_hold'] or 0:.4f}; "
            f"stability {a['stability']:.4f} vs Cycles {a['cycles_stability']:.4f} "
            f"({(a['stability_ratio'] or float('nan')):.2f}x); trail {trail_kind} {tr['mask_pixels']} px, "
            f"+8 frames {tr.get('ratio_at_8', float('nan')) or float('nan'):.2f}x still level, "
            f"recovered after {tr.get('recovered_after')} frames")
    anim = {
        "motion": spec.motion, "amount": light_amount if spec.motion == "light" else spec.amount,
        "amount_unit": "degrees" if (spec.motion == "orbit" or (spec.motion == "light" and is_sun)) else
        ("frames of the scene" if spec.motion == "scene" else "x the distance to the viewed point"), "move_frames": spec.move, "hold_frames": spec.hold,
        "frames": spec.frames, "stop_frame": spec.move, "pivot_distance": distance,
        "lamp": lamp.name if lamp is not None else None,
        "resolution": [width, height], "warmup_first_frame": spec.warmup,
        "trail_kind": trail_kind, "trail_k": k, "trail_mask_pixels": int(trail_mask.sum()),
        "recovery_tolerance": RECOVERY_TOLERANCE, "still_tail_frames": STILL_TAIL, "draws": int(spec.draws),
        "trail_level": "the still-camera run's error on the same frame (same seeds), means over the draws",
        "cycles": {"spp": spec.ref_spp, "denoise": "OpenImageDenoise (albedo+normal)" if spec.ref_denoise else "none",
                   "seed": spec.seed, "frames_rendered": len(ref_ms) - cached, "frames_cached": cached,
                   "time_ms_median": float(np.median(ref_ms)) if ref_ms else None,
                   "frame_diff": results[techniques[0]]["cycles_frame_diff"] if techniques else None,
                   "stability": results[techniques[0]]["cycles_stability"] if techniques else None,
                   "noise_floor": noise_floor,
                   "measure": "mean |ref_t - ref_(t-1)| over pixels and RGB of the per-frame references, "
                              "moving frames only; noise_floor: mean |difference| of two renders of frame 0 "
                              "with seeds differing by 1 (the noise share of that figure)"},
        "techniques": results,
        "wall_s": time.perf_counter() - t_start,
    }
    return {"animation": anim, "frames": frames_out, "still": still_out, "refs": refs, "trail_mask": trail_mask,
            "masks": masks}


# ---------------------------------------------------------------- plot and report
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


def plot_png(anim: dict, path: str, title: str = "") -> str | None:
    """Three panels against frame index: relMSE, frame-to-frame difference (ours and
    Cycles'), error in the disoccluded pixels (per frame; the trail mask after the stop,
    dashed: the still-camera level). Returns the path, or None without matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception:  # noqa: BLE001
        return None
    techs = anim["techniques"]
    stop = anim["stop_frame"]
    fig, axs = plt.subplots(3, 1, figsize=(8.0, 9.0), dpi=100, sharex=True)
    x = list(range(anim["frames"]))
    for i, (t, a) in enumerate(techs.items()):
        c = _COLORS[i % len(_COLORS)]
        axs[0].plot(x, a["relmse"], "-o", ms=3, color=c, label=t)
        axs[1].plot(x[1:], a["frame_diff"][1:], "-o", ms=3, color=c, label=f"{t} ({a['stability']:.3g}, "
                    f"{(a['stability_ratio'] or float('nan')):.2f}x)")
        d = [(k, v) for k, v in enumerate(a["disoccluded_relmse"]) if v is not None]
        if d:
            axs[2].plot([k for k, _ in d], [v for _, v in d], "-o", ms=3, color=c, label=f"{t}: pixels new this frame")
        tr = a.get("trail") or {}
        if tr.get("relmse_after_stop"):
            xs = list(range(stop, stop + len(tr["relmse_after_stop"])))
            axs[2].plot(xs, tr["relmse_after_stop"], "-s", ms=3, color=c, alpha=0.6,
                        label=f"{t}: trail mask ({tr['mask_pixels']} px)")
            if tr.get("still_after_stop"):
                axs[2].plot(xs, tr["still_after_stop"], "--", lw=1, color=c, label=f"{t}: still camera, same frames")
    cy = anim["cycles"]
    if cy.get("frame_diff"):
        axs[1].plot(x[1:], cy["frame_diff"][1:], "-", color="black",
                    label=f"Cycles {cy['spp']} spp{' + OIDN' if anim['cycles']['denoise'] != 'none' else ''} "
                          f"({(cy['stability'] or 0):.3g})")
        axs[1].axhline(cy["noise_floor"], color="grey", ls=":", label=f"Cycles noise floor ({cy['noise_floor']:.3g})")
    for ax, yl in zip(axs, ("relMSE vs Cycles (frame t)", "mean |I(t) - I(t-1)|", "relMSE, disoccluded pixels")):
        ax.axvline(stop, color="#888", lw=1)
        ax.set_ylabel(yl, fontsize=9)
        ax.set_yscale("log")
        ax.grid(True, color="#ddd")
        ax.legend(fontsize=7, loc="best")
    axs[2].set_xlabel(f"frame (motion '{anim['motion']}' until frame {stop}, then still)")
    axs[0].set_title(title or "Per-frame comparison with Cycles", fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def strip(images: list, picks: list[int], view) -> np.ndarray:
    """One row of the frames ``picks`` (sRGB view), 2-pixel gaps; row 0 = bottom."""
    tiles = [view(images[i]) for i in picks]
    h, w = tiles[0].shape[:2]
    out = np.ones((h, len(tiles) * (w + 2) - 2, tiles[0].shape[2]), np.float32)
    for k, t in enumerate(tiles):
        out[:, k * (w + 2):k * (w + 2) + w] = t
    return out


def strip_frames(anim: dict) -> list[int]:
    """Frames worth looking at: start, mid-move, the stop, +1, +2, +4, +8 and the last."""
    stop, n = anim["stop_frame"], anim["frames"]
    pick = [0, stop // 2, stop, stop + 1, stop + 2, stop + 4, stop + 8, n - 1]
    return sorted({p for p in pick if 0 <= p < n})


def _fmt(v, f="{:.4g}"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "&ndash;"
    return f.format(v)


def report_html(anim: dict, images: dict | None = None) -> str:
    """The report's "Animation" section: the summary table, the plot and the frame strips
    (``images``: "animation:plot" and "animation:strip:<TECH>" / "animation:strip:cycles" PNGs)."""
    images = images or {}
    cy = anim["cycles"]
    p = ["<h2>Animation: per-frame comparison</h2>",
         f'<p class="meta">Motion <b>{html.escape(str(anim["motion"]))}</b> (amount {_fmt(anim["amount"], "{:g}")}) '
         f'for {anim["move_frames"]} frames after the start pose, then {anim["hold_frames"]} frames still; '
         f'{anim["resolution"][0]}&times;{anim["resolution"][1]} px. Cycles per frame: {cy["spp"]} spp, denoise '
         f'{html.escape(str(cy["denoise"]))}, seed {cy["seed"]}. Stability = mean |I(t)&minus;I(t&minus;1)| '
         f'over the moving frames, ours / Cycles&rsquo;; Cycles&rsquo; noise floor (two seeds, frame 0) '
         f'{_fmt(cy["noise_floor"])}. Trail: {html.escape(anim["trail_kind"])} pixels of the final pose '
         f'({anim["trail_mask_pixels"]} px, over the last {anim["trail_k"]} moving frames); their error after the '
         f'stop against a still camera&rsquo;s on the same frame (same seeds; {anim.get("draws", 1)} noise draw(s)); '
         f'&ldquo;recovered&rdquo; = within {anim["recovery_tolerance"]}&times;.</p>',
         '<table><tr><th class="l">technique</th><th>ms/frame</th><th>relMSE moving</th><th>relMSE held</th>'
         '<th>stability</th><th>Cycles</th><th>ratio</th><th>flicker held</th><th>trail +8 / still</th>'
         '<th>recovered after</th><th>mean/Cycles (last)</th><th>non-finite px</th></tr>']
    for t, a in anim["techniques"].items():
        tr = a.get("trail") or {}
        p.append(f'<tr><td class="l">{html.escape(t)}</td><td>{_fmt(a.get("frame_ms"), "{:.1f}")}</td>'
                 f'<td>{_fmt(a["relmse_moving"])}</td><td>{_fmt(a["relmse_hold"])}</td>'
                 f'<td>{_fmt(a["stability"])}</td><td>{_fmt(a["cycles_stability"])}</td>'
                 f'<td>{_fmt(a["stability_ratio"], "{:.2f}&times;")}</td><td>{_fmt(a["hold_flicker"])}</td>'
                 f'<td>{_fmt(tr.get("ratio_at_8"), "{:.2f}&times;")}</td>'
                 f'<td>{_fmt(tr.get("recovered_after"), "{} frames")}</td>'
                 f'<td>{_fmt(a["mean_ratio"][-1], "{:.3f}")}</td><td>{a["nonfinite_pixels"]}</td></tr>')
    p.append("</table>")

    def img(key, alt):
        png = images.get(key)
        if not png:
            return ""
        b64 = base64.b64encode(png).decode("ascii")
        return f'<img alt="{html.escape(alt)}" style="max-width:100%;image-rendering:pixelated" src="data:image/png;base64,{b64}"/>'
    if images.get("animation:plot"):
        p.append("<h3>Against frame index</h3>" + img("animation:plot", "per-frame plot"))
    picks = anim.get("strip_frames")
    if picks:
        p.append(f'<h3>Frames {", ".join(map(str, picks))}</h3>')
        for key in ["cycles"] + list(anim["techniques"]):
            if images.get("animation:strip:" + key):
                p.append(f"<p>{html.escape('Cycles' if key == 'cycles' else key)}</p>"
                         + img("animation:strip:" + key, key))
    return "\n".join(p)


def write_outputs(result: dict, out: str, *, imageio, metrics, title: str = "") -> dict:
    """Plot, frame strips and EXRs of the run into ``out``; returns the report images."""
    os.makedirs(out, exist_ok=True)
    anim = result["animation"]
    images = {}
    plot = plot_png(anim, os.path.join(out, "animation.png"), title)
    anim["plot"] = os.path.basename(plot) if plot else None
    if plot:
        with open(plot, "rb") as f:
            images["animation:plot"] = f.read()
    picks = strip_frames(anim)
    anim["strip_frames"] = picks
    seqs = {"cycles": result["refs"], **result["frames"]}
    anim["strips"] = {}
    for key, seq in seqs.items():
        s = strip(seq, picks, metrics.view_standard)
        name = f"strip_{key}.png"
        imageio.write_png(os.path.join(out, name), s)
        images["animation:strip:" + key] = imageio.png_bytes(s)
        anim["strips"][key] = name
    mask = result.get("trail_mask")
    if mask is not None:
        imageio.write_png(os.path.join(out, "trail_mask.png"), np.repeat(mask[..., None].astype(np.float32), 3, -1))
    return images
