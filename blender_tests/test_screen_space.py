"""The screen-space family (SSAO, HBAO, SSDO, SSR) against Cycles, on hard cases, in the
planner, and over time.

Tolerances (measured with scripts/bench_screen_space.py and this file, Blender 5.0.1,
llvmpipe; margins cover the Cycles reference's noise at the spp used here):

* AO vs Cycles' AO (reference kind "ao", distance 1 = the techniques' default radius) on
  the cornell demo at 48 px, 16 frames, Cycles 128 spp. Measured: HBAO relMSE ~0.07,
  FLIP ~0.13; SSAO relMSE ~0.07, FLIP ~0.14 (the remaining error is what screen space
  cannot see: the gap behind the tall box, the back faces). Thresholds: relMSE <= 0.12,
  FLIP <= 0.20, and the mean AO within 0.12 of Cycles' (ours is brighter, never darker).
* DIRECT lights with the world itself (shadowed by its world-light maps), so the
  techniques add only indirect light and SSR replaces DIRECT's world reflection; the ratios
  below are against that DIRECT.
* SSR on glossy_spheres vs Cycles "one_bounce": measured relMSE ~0.026 against DIRECT's
  ~0.045 (ratio ~0.58); asserted ratio <= 0.75.
* SSDO on cornell vs "one_bounce": measured 0.031 against DIRECT's 0.179 (ratio 0.18);
  asserted ratio <= 0.85. SSAO/HBAO there: ~0.080 / ~0.126 (ratios ~0.44 / ~0.69; the
  constant indirect term); <= 0.9.
* Hard cases: every technique's output is finite and at most 4x the brightest value of
  DIRECT's image (the scene's own maximum radiance: lights seen directly, emission,
  world); measured ratios <= ~1.5.
* Temporal: viewport-style (1 frame per render call, history kept), the GI_AO error
  against a 64-frame accumulation drops by more than half from frame 1 to frame 16
  (measured ~0.4x); after a camera move the history is dropped on >= 95 % of the pixels
  whose surface was hidden before (measured 100 % of 26) and kept on >= 80 % of
  those seen before (measured 99.9 %; no ghosting; the test says why images are not compared).

* The reproduction scenes (scenes_screen_space.py; 64 px, 16 frames, Cycles "one_bounce"
  256 spp; numbers from scripts/bench_screen_space.py --repro):
  corridor, SSR's screen part (miss_trace 0) masked to the mirror floor and the gold wall
  0.231, DIRECT's 0.455: asserted <= 0.32 and <= 0.7x DIRECT's, and the image's step across
  the hit/miss boundaries (found share jumping by > 0.25) 0.083 against Cycles' 0.120 on the
  same pixel pairs: asserted <= Cycles'; mirror_gradient, SSR on the mirror 0.071 (0.0085
  with the miss trace, the default; TV 0.043), the reflection's total variation 0.037
  against Cycles' 0.029: asserted relMSE <= 0.14 and TV <= 1.8x Cycles'; bounce_room, SSDO
  on the ceiling (lit only by the floor) 0.061 (0.112 if off-screen directions take the
  mean of the on-screen ones instead of a scene trace), mean 0.334 against Cycles' 0.444:
  asserted relMSE <= 0.107 and the mean within 30 %.
* SSR's miss trace under motion (corridor dolly, 48 px, one frame per call, vs a still
  32-frame render with the trace): fallback accumulated by ssr_fallback_temporal 0.086 (0.178
  with highlights reprojected by the hit point and one sample per hit), of one frame 0.173:
  asserted <= 0.25, <= 0.75x and <= 0.85x. The trace is SSR's default (miss_trace, rough_trace
  1 at every level); the corridor test asserts the default <= 0.2 (measured 0.116) and
  the screen part alone (miss_trace 0) against the bounds above, and the reflected-point
  reprojection test measures the screen part alone.

Images are written to blender_tests/_artifacts/screen_space/ when an assertion fails.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import bpy
import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.blender.demo_scenes import make_principled, make_world
from gi_preview.compare import metrics
from gi_preview.render import session
from _helpers import export as _export, dump_exr

import scenes_screen_space as repro

TECHS = ("SSAO", "HBAO", "SSDO", "SSR")
ARTIFACTS = Path(__file__).resolve().parent / "_artifacts" / "screen_space"


def _dump(name, **images):
    dump_exr(ARTIFACTS, name, **images)


def _ao3(res):
    ao = res.aovs["GI_AO"]
    return np.repeat(ao[..., :1], 3, axis=2) if ao.shape[2] == 1 else ao[..., :3]


@pytest.fixture(scope="module")
def cornell():
    sc = demo_scenes.build_demo("cornell", resolution=48)
    sd = _export(sc)
    refs = {k: reference.render_cycles(sc, 128, k)[0] for k in ("ao", "one_bounce")}
    yield sc, sd, refs
    bpy.data.scenes.remove(sc)


# ------------------------------------------------------------------ vs Cycles
@pytest.mark.parametrize("tech", ["SSAO", "HBAO"])
def test_ao_matches_cycles_ao(cornell, tech):
    sc, sd, refs = cornell
    res = session.render(sd, tech, 1, 16)
    ours, ref = _ao3(res), refs["ao"][..., :3]
    assert np.isfinite(ours).all()
    err = metrics.relmse(ours, ref)
    fl = metrics.flip(ours, ref)
    print(f"{tech} AO vs Cycles AO: relMSE {err:.4f} FLIP {fl:.4f} mean {ours.mean():.3f} vs {ref.mean():.3f}")
    if err > 0.12 or fl > 0.2:
        _dump(f"ao_{tech}", ours=ours, cycles=ref)
    assert err <= 0.12 and fl <= 0.20
    assert abs(ours.mean() - ref.mean()) <= 0.12
    assert ours.min() >= 0.0 and ours.max() <= 1.0 + 1e-5


def test_indirect_techniques_improve_on_direct_cornell(cornell):
    sc, sd, refs = cornell
    ref = refs["one_bounce"]
    direct = metrics.relmse(session.render(sd, "DIRECT", 1, 8).image, ref)
    for tech, ratio in (("SSDO", 0.85), ("SSAO", 0.9), ("HBAO", 0.9)):
        img = session.render(sd, tech, 1, 8).image
        err = metrics.relmse(img, ref)
        print(f"cornell {tech}: relMSE vs one_bounce {err:.4f} (DIRECT {direct:.4f})")
        if err > ratio * direct:
            _dump(f"cornell_{tech}", ours=img, cycles=ref)
        assert err <= ratio * direct, f"{tech}: {err:.4f} vs DIRECT {direct:.4f}"


def test_ssr_improves_on_direct_glossy_spheres():
    """SSR (defaults: the miss trace on) at the product's default 16 F12 frames against Cycles
    one_bounce at 512 spp (48 px). Measured 0.0255 vs DIRECT 0.0499 (0.51x; the screen part
    alone, miss_trace 0: 0.0292). At 8 frames against 128 spp the default scores
    0.78x DIRECT on this seed: the trace's one ray per pixel leaves seed-to-seed spread (over
    five seeds at 8 frames against 1024 spp the default averaged 0.0349 +- 0.0046, 0.0357 +- 0.0053
    with the F12 pass-through of its fallback, and the screen part 0.0396 +- 0.0038; seed 0, the
    tests', was the default's worst of the five), and the 128-spp
    reference is itself too noisy at 48 px (SSR.md)."""
    sc = demo_scenes.build_demo("glossy_spheres", resolution=48)
    try:
        sd = _export(sc)
        ref, _ = reference.render_cycles(sc, 512, "one_bounce")
        direct = metrics.relmse(session.render(sd, "DIRECT", 1, 16).image, ref)
        res = session.render(sd, "SSR", 1, 16)
        err = metrics.relmse(res.image, ref)
        print(f"glossy_spheres SSR relMSE vs one_bounce {err:.4f} (DIRECT {direct:.4f})")
        assert not res.skipped_passes or all(not s.name.startswith("ssr") for s in res.skipped_passes)
        if err > 0.75 * direct:
            _dump("glossy_spheres_SSR", ours=res.image, cycles=ref)
        assert err <= 0.75 * direct
    finally:
        bpy.data.scenes.remove(sc)


# ------------------------------------------------------------------ planner
def test_planner_skips_ssr_without_glossy_surfaces(cornell):
    sc, sd, refs = cornell
    res = session.render(sd, "SSR", 1, 1)
    skipped = {s.name: s.reason for s in res.skipped_passes}
    for name in ("ss_hiz", "ssr_trace", "ssr_resolve", "ssr_temporal", "ssr_fallback_temporal", "ssr_composite"):
        assert skipped.get(name) == "no glossy surface in view", skipped
    direct = session.render(sd, "DIRECT", 1, 1).image
    assert np.allclose(res.image, direct, atol=1e-4)  # nothing added, nothing broken


def test_planner_skips_ao_passes_when_nothing_emits_light():
    sc = bpy.data.scenes.new("ss_dark")
    try:
        sc.render.resolution_x = sc.render.resolution_y = 16
        sc.world = make_world("ss_dark_world", (0, 0, 0), 0.0)
        b = demo_scenes._Builder(sc, "ss_dark")
        b.quad("floor", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], make_principled("ss_dark_m"))
        b.camera((0, -4, 2), (0, 0, 0))
        sd = _export(sc)
        for tech in ("SSAO", "HBAO", "SSDO"):
            res = session.render(sd, tech, 1, 1)
            skipped = {s.name: s.reason for s in res.skipped_passes}
            p = tech.lower()
            for name in (p, f"{p}_temporal", f"{p}_blur", f"{p}_composite"):
                assert "nothing emits light" in skipped.get(name, ""), (tech, skipped)
            assert np.isfinite(res.image).all()
    finally:
        bpy.data.scenes.remove(sc)


# ------------------------------------------------------------------ hard cases
def _hard_scene(kind: str, floor_roughness: float):
    sc = bpy.data.scenes.new(f"ss_hard_{kind}_{floor_roughness}")
    sc.render.resolution_x = sc.render.resolution_y = 40
    sc.world = make_world(f"ss_hard_world_{kind}", (0.4, 0.5, 0.7), 0.5)
    b = demo_scenes._Builder(sc, f"ss_hard_{kind}_{floor_roughness}")
    floor = make_principled(b.n("floor"), (0.8, 0.8, 0.8), floor_roughness, metallic=1.0 if floor_roughness == 0 else 0.0)
    wall = make_principled(b.n("wall"), (0.7, 0.3, 0.2), 0.5)
    b.quad("floor", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)], floor)
    b.quad("wall", [(-3, 1.5, 0), (3, 1.5, 0), (3, 1.5, 3), (-3, 1.5, 3)], wall)
    # a thin object in front of the wall, and boxes at very different depths
    b.box("thin", (1.2, 0.01, 1.5), make_principled(b.n("thin"), (0.2, 0.6, 0.3), 0.3), location=(0.3, 1.3, 0.75))
    b.box("near", (0.3, 0.3, 0.3), wall, location=(-0.4, -1.5, 0.15))
    b.sphere("ball", 0.4, make_principled(b.n("ball"), (0.9, 0.9, 0.9), 0.1, 1.0), (0.8, 0.2, 0.4))
    b.light("sun", "SUN", (0, 0, 5), rotation=(math.radians(40), 0, math.radians(30)), energy=3.0)
    if kind == "grazing":
        b.camera((0.0, -5.0, 0.03), (0.0, 2.0, 0.05), lens=30.0)
    elif kind == "edge":  # an occluder cut by the screen edge, close to the camera
        b.box("edge_box", (0.6, 0.6, 1.2), wall, location=(-1.05, -2.0, 0.6))
        b.camera((0.0, -4.0, 1.0), (0.0, 0.5, 0.5), lens=35.0)
    else:  # depth discontinuities: a near box over a far wall, seen from above
        b.camera((1.5, -3.0, 2.5), (0.0, 0.8, 0.4), lens=30.0)
    return sc


@pytest.mark.parametrize("kind,rough", [("grazing", 0.0), ("grazing", 1.0), ("edge", 0.0), ("edge", 1.0),
                                        ("discontinuity", 0.0), ("discontinuity", 1.0)])
def test_hard_cases_finite_and_bounded(kind, rough):
    sc = _hard_scene(kind, rough)
    try:
        sd = _export(sc)
        base = session.render(sd, "DIRECT", 1, 2).image
        bound = 4.0 * max(float(base[..., :3].max()), float(np.max(sd.world.color)), 1e-3)
        for tech in TECHS:
            res = session.render(sd, tech, 1, 2)
            img = res.image[..., :3]
            print(f"{kind} rough={rough} {tech}: max {img.max():.3f} (bound {bound:.3f})")
            assert np.isfinite(img).all(), f"{tech}: non-finite pixels"
            assert img.min() >= 0.0 and img.max() <= bound, f"{tech}: out of bounds"
            for name, aov in res.aovs.items():
                assert np.isfinite(aov).all(), f"{tech}: non-finite AOV {name}"
            if "GI_AO" in res.aovs:
                ao = res.aovs["GI_AO"]
                assert ao.min() >= 0.0 and ao.max() <= 1.0 + 1e-5
    finally:
        bpy.data.scenes.remove(sc)


# ------------------------------------------------------------------ temporal
def test_temporal_converges_for_a_still_camera(cornell):
    sc, sd, refs = cornell
    conv = _ao3(session.render(sd, "SSAO", 1, 64))
    errs = {}
    for i in range(16):
        res = session.render(sd, "SSAO", 1, 1, keep_history=True, session="ss_viewport")
        if i + 1 in (1, 4, 16):
            errs[i + 1] = metrics.relmse(_ao3(res), conv)
    print("viewport SSAO error vs converged:", errs)
    assert errs[16] < 0.5 * errs[1] and errs[4] < errs[1]


def _ssr_variant(tech_id: str, **ssr_kw):
    """Register (under ``tech_id``) an SSR whose own passes are ``ssr_passes(quality, **ssr_kw)``
    after DIRECT's, as SSR.passes builds them: a test's variant of one SSR switch. The caller
    pops it from ``techniques.REGISTRY`` when done."""
    from gi_preview.render import techniques
    from gi_preview.render.passes.gbuffer import GBufferPass
    from gi_preview.render.passes.shadows import ShadowPass
    from gi_preview.render.techniques.direct import DirectLightPass
    from gi_preview.render.techniques.ssr import SSR, ssr_passes

    class Variant(SSR):
        id = tech_id

        def passes(self, quality):
            return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                    *ssr_passes(quality, **ssr_kw)]

    techniques.REGISTRY[tech_id] = Variant
    return Variant


def _dolly(sd, k: int, step=(0.0, 0.08, 0.0)):
    """A copy of the exported scene with the camera moved ``k`` steps of ``step`` metres."""
    moved = copy.deepcopy(sd)
    m = moved.camera.matrix_world.astype(np.float64).copy()
    m[:3, 3] += np.array(step) * k
    moved.camera.matrix_world = m.astype(moved.camera.matrix_world.dtype)
    return moved


def _dolly_errors(sd, runs: dict, mask, *, truth_key: str, truth_samples: int, at, steps: int = 9):
    """The camera dollies (``_dolly``, ``steps`` frames); each run ({session key: technique})
    renders viewport-style (one frame per call, history kept). At the frames ``at``, each
    run's image is checked finite and compared, masked, with a still SSR render of
    ``truth_samples`` frames (session ``truth_key``, configured by the caller). Returns
    ({session key: mean masked relMSE}, the last frame's scene)."""
    errs = {key: [] for key in runs}
    for k in range(steps):
        moved = _dolly(sd, k)
        imgs = {key: session.render(moved, t, 1, 1, keep_history=True, session=key).image
                for key, t in runs.items()}
        if k in at:
            truth = session.render(moved, "SSR", 1, truth_samples, session=truth_key).image
            for key, img in imgs.items():
                assert np.isfinite(img).all()
                errs[key].append(metrics.relmse(img, truth, mask=mask))
    return {key: float(np.mean(v)) for key, v in errs.items()}, moved


def _read_resource(key, name, comps):
    from gi_preview.render.gl import get_gl

    t = session._sessions[key].rc.resources[name]
    w, h = t.size

    def read():
        dt = np.float16 if t.dtype == "f2" else np.float32
        return np.frombuffer(t.read(), dt).reshape(h, w, t.components)[..., :comps].astype(np.float32)
    return get_gl().submit(read).result()


def test_temporal_rejects_disoccluded_history(cornell):
    """After a camera move, history survives exactly where the surface was visible before.

    Screen-space AO is view-dependent (measured: the converged HBAO of the old view,
    reprojected onto the same surface points, is ~0.04 darker on average than the new
    view's), so comparing images would measure that lag, not ghosting. This checks the
    rejection itself: the temporal history length after the move is 1 (history dropped)
    on pixels whose surface point was hidden or off screen at the old camera, and > 1 on
    pixels seen before."""
    sc, sd, refs = cornell
    for _ in range(8):  # build history at the first camera
        session.render(sd, "HBAO", 1, 1, keep_history=True, session="ss_move")
    old_pos = _read_resource("ss_move", "gbuffer.position", 4)
    moved = _dolly(sd, 1, step=(0.8, 0.0, -0.3))  # reveals what the boxes hid
    session.render(moved, "HBAO", 1, 1, keep_history=True, session="ss_move")
    new_pos = _read_resource("ss_move", "gbuffer.position", 4)
    length = _read_resource("ss_move", "hbao.temporal.len", 1)[..., 0]
    h, w = length.shape
    # which new pixels show a surface point that the old view saw: splat the old view's
    # points into the new view (the pixel they land in and its 8 neighbours)
    vp1 = moved.camera.projection.astype(np.float64) @ moved.camera.view.astype(np.float64)
    pts = old_pos[old_pos[..., 3] >= 0][:, :3]
    clip = np.concatenate([pts, np.ones((len(pts), 1))], -1) @ vp1.T
    front = clip[:, 3] > 1e-6
    pix = (clip[front, :2] / clip[front, 3:4] * 0.5 + 0.5) * np.array([w, h])
    # keep only old points that are visible in the new view (not behind a nearer surface)
    ix, iy = pix[:, 0].astype(int), pix[:, 1].astype(int)
    ok = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    ix, iy, p3 = ix[ok], iy[ok], pts[front][ok]
    vis = np.linalg.norm(new_pos[iy, ix, :3] - p3, axis=-1) < 0.1
    covered = np.zeros((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            covered[np.clip(iy[vis] + dy, 0, h - 1), np.clip(ix[vis] + dx, 0, w - 1)] = True
    hit = np.zeros((h, w), bool)
    hit[iy[vis], ix[vis]] = True
    geo = new_pos[..., 3] >= 0
    seen = geo & hit
    hidden = geo & ~covered
    frac_hidden_rejected = float((length[hidden] <= 1.0).mean())
    frac_seen_kept = float((length[seen] > 1.0).mean())
    print(f"camera move: {hidden.sum()} disoccluded px, {frac_hidden_rejected:.3f} rejected; "
          f"{seen.sum()} seen px, {frac_seen_kept:.3f} kept")
    assert hidden.sum() > 10 and seen.sum() > 200  # the move does reveal something
    assert frac_hidden_rejected >= 0.95
    assert frac_seen_kept >= 0.8


# ------------------------------------------------------------------ reproduction scenes
def _repro(name, spp=256):
    sc = repro.build(name, 64)
    sd = _export(sc)
    ref, _ = reference.render_cycles(sc, spp, "one_bounce")
    masks = repro.masks(name, sd, repro.material_ids(sd))
    return sc, sd, ref, masks


def test_ssr_corridor_reflections_of_walls():
    """A near-mirror metal floor and a glossy gold wall reflecting diffuse walls: the
    reflections must be found on screen (before the fixes they broke into speckles and
    bands and scored worse than DIRECT's world reflection)."""
    sc, sd, ref, masks = _repro("corridor")
    try:
        m = masks["reflective"]
        direct = metrics.relmse(session.render(sd, "DIRECT", 1, 16).image, ref, mask=m)
        # the screen part alone (miss_trace 0: the share not found falls back to DIRECT's
        # shadowed world reflection): measured 0.231 (seam 0.083 vs Cycles' 0.120 over 78 pairs)
        session.set_pass_properties("ss_corridor_screen", {"ssr_trace": {"miss_trace": 0}},
                                    technique="SSR", quality=1)
        scr = session.render(sd, "SSR", 1, 16, session="ss_corridor_screen")
        err_scr = metrics.relmse(scr.image, ref, mask=m)
        # no seam between found reflections and the fallback: across the pixel pairs where
        # the found share jumps by > 0.25 the image steps no more than Cycles' does there
        pairs = repro.seam_pairs(_read_resource("ss_corridor_screen", "ssr.temporal", 4)[..., 3], m)
        seam_scr, n_pairs = repro.seam_gradient(scr.image, pairs)
        seam_ref, _ = repro.seam_gradient(ref, pairs)
        # the default: the share not found on screen traced through the scene BVH (miss_trace
        # 1, rough_trace 1). Measured 0.116 (seam 0.097); the screen part alone (0.231) fails 0.2
        res = session.render(sd, "SSR", 1, 16, session="ss_corridor")
        err = metrics.relmse(res.image, ref, mask=m)
        seam, _ = repro.seam_gradient(res.image, pairs)
        print(f"corridor reflective relMSE: SSR {err:.4f} (screen part alone {err_scr:.4f}), DIRECT {direct:.4f}; "
              f"seam step {seam:.4f} (screen part {seam_scr:.4f}) vs Cycles {seam_ref:.4f} over {n_pairs} pairs")
        assert np.isfinite(res.image).all() and np.isfinite(scr.image).all()
        if err > 0.2 or err_scr > 0.32 or err_scr > 0.7 * direct:
            _dump("corridor_SSR", ours=res.image, screen_only=scr.image, cycles=ref)
        assert err_scr <= 0.32 and err_scr <= 0.7 * direct
        assert n_pairs >= 20 and seam_scr <= seam_ref
        assert err <= 0.2 and seam <= seam_ref
    finally:
        session.release_session("ss_corridor_screen")
        session.release_session("ss_corridor")
        bpy.data.scenes.remove(sc)


def test_ssr_mirror_reflects_a_gradient_as_a_gradient():
    """Reflection continuity: a smooth vertical gradient on a diffuse wall, seen in a
    mirror floor, stays smooth: the total variation of the mirror's pixels stays close to
    Cycles' (whose own variation includes its sampling noise)."""
    sc, sd, ref, masks = _repro("mirror_gradient")
    try:
        m = masks["reflective"]
        res = session.render(sd, "SSR", 1, 16)
        err = metrics.relmse(res.image, ref, mask=m)
        tv, tv_ref = repro.total_variation(res.image, m), repro.total_variation(ref, m)
        print(f"mirror_gradient: relMSE {err:.4f}, TV {tv:.4f} vs Cycles {tv_ref:.4f}")
        if err > 0.14 or tv > 1.8 * tv_ref:
            _dump("mirror_gradient_SSR", ours=res.image, cycles=ref)
        assert err <= 0.14
        assert tv <= 1.8 * tv_ref
        # the reflection is there (not DIRECT's black world reflection)
        lum = res.image[..., :3].mean(-1)
        assert lum[m].mean() >= 0.5 * ref[..., :3].mean(-1)[m].mean()
    finally:
        bpy.data.scenes.remove(sc)


def test_ssdo_ceiling_lit_only_by_the_floor():
    """A ceiling lit only by light bouncing off a diffuse floor: SSDO's bounce must reach
    it (directions that leave the screen are traced through the scene, not open) without
    large blotches. The acceptance is relMSE <= 0.107; measured 0.0191 with the traced
    off-screen radiance shrunk towards the on-screen mean (0.0712 without the shrinkage), so
    the bound is 0.04 to keep that gain."""
    sc, sd, ref, masks = _repro("bounce_room")
    try:
        m = masks["ceiling"]
        res = session.render(sd, "SSDO", 1, 16)
        err = metrics.relmse(res.image, ref, mask=m)
        ours, theirs = float(res.image[..., :3][m].mean()), float(ref[..., :3][m].mean())
        print(f"bounce_room ceiling: SSDO relMSE {err:.4f}, mean {ours:.3f} vs Cycles {theirs:.3f}")
        if err > 0.04:
            _dump("bounce_room_SSDO", ours=res.image, cycles=ref)
        assert err <= 0.04, f"bounce_room ceiling relMSE {err:.4f} (acceptance 0.107, measured 0.0191)"
        assert abs(ours - theirs) <= 0.3 * theirs
    finally:
        bpy.data.scenes.remove(sc)


def test_ssr_miss_fallback_is_a_composite_argument():
    """SSR's miss fallback is a constructor argument of its composite (probes
    or another technique provide it): ``color += ks found + (1 - a) fallback -
    replaced``. With DIRECT's reflected direct light as a stand-in fallback, the image
    differs from SSR's default (fallback = its own ``ssr.fallback``: the miss trace's, DIRECT's
    world reflection while ``miss_trace`` is off; replaced = DIRECT's world reflection) by
    exactly ``(1 - a) (fallback - ssr.fallback)`` per pixel, where ``a`` is the share found.
    The default is rendered with ``rough_trace`` 0 so that both graphs trace the same rays (with
    it, pixels rougher than ``max_roughness`` also store a ray, which enters their smooth
    neighbours' found share as a miss; the variant, without SSR's own miss trace, has no
    rough_trace)."""
    from gi_preview.render import techniques
    from gi_preview.render.passes.screen_space import DIRECT_RADIANCE, WORLD_SPEC
    from gi_preview.render.techniques.ssr import ssr_passes

    sc = repro.build("corridor", 40)
    SSRWithFallback = _ssr_variant("SSR_FALLBACK_TEST", fallback=DIRECT_RADIANCE, replaces=(WORLD_SPEC,))
    try:
        sd = _export(sc)
        session.set_pass_properties("ss_fb_base", {"ssr_trace": {"rough_trace": 0}}, technique="SSR", quality=1)
        base = session.render(sd, "SSR", 1, 1, session="ss_fb_base").image
        res = session.render(sd, SSRWithFallback.id, 1, 1, session="ss_fb")
        a = np.clip(_read_resource("ss_fb", "ssr.temporal", 4)[..., 3:4], 0.0, 1.0)
        ws = _read_resource("ss_fb_base", "ssr.fallback", 3)  # the default's own fallback
        fb = _read_resource("ss_fb", DIRECT_RADIANCE, 3)
        glossy = _read_resource("ss_fb", "gbuffer.position", 4)[..., 3] >= 0
        expect = (1.0 - a) * (fb - ws)
        diff = res.image[..., :3] - base[..., :3]
        err = np.abs(diff - expect)[glossy].max()
        missed = ((1.0 - a[..., 0]) * np.abs(fb - ws).mean(-1) > 1e-2) & glossy
        print(f"fallback: max |diff - (1-a)(fb-ws)| {err:.2e}; {missed.sum()} px take the fallback, "
              f"{int((a[..., 0] > 0.5).sum())} px found on screen")
        assert missed.sum() > 20 and (a[..., 0] > 0.5).sum() > 20  # both branches exercised
        assert err <= 1e-3 * max(1.0, float(np.abs(fb).max()))
        with pytest.raises(ValueError):
            ssr_passes(1, replaces=("a", "b", "c"))
    finally:
        techniques.REGISTRY.pop(SSRWithFallback.id, None)
        for k in ("ss_fb", "ss_fb_base"):
            session.release_session(k)
        bpy.data.scenes.remove(sc)


def test_ssr_reflections_reproject_by_the_reflected_point():
    """Under camera motion a reflection moves with the reflected point, not with the mirror:
    the camera dollies down the corridor, rendered viewport-style (one
    frame per call, history kept); the reflective surfaces are compared with a fresh render
    at the same camera (no history, no lag). SSR's temporal pass (reprojection by the
    virtual image point, hit distance behind the mirror) lags less than reprojection by the
    surface's motion. The screen part is measured alone (``miss_trace`` 0
    for all three renders: the miss trace's own fallback and its temporal pass are tested by
    test_ssr_miss_fallback_accumulates_over_time). Measured here (48 px, frames 6-9): 0.068 vs
    0.091 (ratio 0.75; deterministic); asserted <= 0.85x."""
    from gi_preview.render import techniques

    sc = repro.build("corridor", 48)
    SSRSurfaceMotion = _ssr_variant("SSR_SURFACE_MOTION_TEST", reproject_by_hit=False)
    keys = ("ss_mv_truth", "ss_mv_hit", "ss_mv_surf")
    try:
        sd = _export(sc)
        mask = repro.masks("corridor", sd, repro.material_ids(sd))["reflective"]
        for key, tech in zip(keys, ("SSR", "SSR", SSRSurfaceMotion.id)):
            session.set_pass_properties(key, {"ssr_trace": {"miss_trace": 0}}, technique=tech, quality=1)
        errs, _ = _dolly_errors(sd, {keys[1]: "SSR", keys[2]: SSRSurfaceMotion.id}, mask,
                                truth_key=keys[0], truth_samples=8, at=range(5, 9))
        e_hit, e_surf = errs[keys[1]], errs[keys[2]]
        print(f"reflection lag under motion (masked relMSE vs still render): by reflected point {e_hit:.4f}, "
              f"by surface {e_surf:.4f}")
        assert e_hit <= 0.85 * e_surf
    finally:
        techniques.REGISTRY.pop(SSRSurfaceMotion.id, None)
        for k in keys:
            session.release_session(k)
        bpy.data.scenes.remove(sc)


def _poison_history(key: str, names: tuple) -> None:
    """Fill session ``key``'s resources ``names`` with NaN (both dtypes the graph uses)."""
    from gi_preview.render.gl import get_gl

    def go():
        s = session._sessions[key]
        for n in names:
            tex = s.rc.resources[n]
            w, h = tex.size
            dt = np.float16 if tex.dtype == "f2" else np.float32
            tex.write(np.full((h, w, tex.components), np.nan, dt).tobytes())
        s.ctx.finish()
    get_gl().call(go)


def test_ssr_miss_fallback_accumulates_over_time():
    """SSR's miss trace (``miss_trace`` 1) traces one ray per pixel and frame; its fallback
    (``ssr.fallback``) is accumulated over frames by ``ssr_fallback_temporal`` (the shared
    TemporalPass: history reprojected by the virtual image point at the miss rays' distance,
    clamped to the current 3x3 neighbourhood while the camera moves, 4 frames while moving).
    The camera dollies down the corridor, one frame per call; frames 7 and 9 are compared,
    masked to the reflective surfaces, with a still 32-frame render of the same settings.
    Measured (48 px, deterministic): temporal 0.0858 vs the fallback of one frame (no temporal
    pass) 0.173, and vs 0.178 for a glossy hit's highlights reprojected by the hit point with
    one light sample per hit while moving (``SSR_MISS_HIT_PARALLAX``, ``miss_samples_moving``
    1); asserted <= 0.25, <= 0.75x the one-frame fallback and <= 0.85x the hit-point variant,
    which fail them. (The trace is the default; against Cycles under motion it is closer than
    the screen part alone, SSR.md.) A NaN history is dropped within one frame. An F12 render
    passes the fallback through (the session's accumulator averages it)."""
    from gi_preview.render import techniques
    from gi_preview.render.techniques.ssr import FALLBACK_TEMPORAL

    sc = repro.build("corridor", 48)
    SSROneFrameFallback = _ssr_variant("SSR_ONE_FRAME_FALLBACK_TEST", fallback_reproject="none")
    SSRHitParallax = _ssr_variant("SSR_HIT_PARALLAX_TEST", miss_defines={"SSR_MISS_HIT_PARALLAX": 1})
    variants = {"ss_mf_temporal": "SSR", "ss_mf_one": SSROneFrameFallback.id, "ss_mf_hitpar": SSRHitParallax.id}
    keys = ("ss_mf_truth", *variants)
    try:
        sd = _export(sc)
        mask = repro.masks("corridor", sd, repro.material_ids(sd))["reflective"]
        for key, tech in (("ss_mf_truth", "SSR"), *variants.items()):
            session.set_pass_properties(key, {"ssr_trace": {"miss_trace": 1}}, technique=tech, quality=1)
        # the hit-point variant: highlights reprojected by the hit, one sample while moving
        session.set_pass_properties("ss_mf_hitpar", {"ssr_trace": {"miss_samples_moving": 1}},
                                    technique=SSRHitParallax.id, quality=1)
        errs, moved = _dolly_errors(sd, variants, mask, truth_key="ss_mf_truth", truth_samples=32, at=(6, 8))
        e_t, e_one, e_hit = errs["ss_mf_temporal"], errs["ss_mf_one"], errs["ss_mf_hitpar"]
        print(f"miss fallback under motion (masked relMSE vs still 32 frames): temporal {e_t:.4f}, "
              f"one frame {e_one:.4f}, highlights by the hit point and one sample {e_hit:.4f}")
        assert e_t <= 0.25 and e_t <= 0.75 * e_one and e_t <= 0.85 * e_hit
        # an F12 render (a fresh accumulation: the 32-frame still truth) passes the fallback
        # through, so the session's accumulator takes the plain mean of the frames' fallbacks;
        # viewport frames (history kept) accumulate it here
        for key, passes_through in (("ss_mf_truth", True), ("ss_mf_temporal", False)):
            surf = _read_resource(key, "gbuffer.position", 4)[..., 3] >= 0.0
            out, raw = _read_resource(key, FALLBACK_TEMPORAL, 3)[surf], _read_resource(key, "ssr.fallback", 3)[surf]
            assert surf.sum() > 100 and np.allclose(out, raw, atol=1e-6) == passes_through, key
        # NaN in the fallback's history: gone within one frame
        hist = (FALLBACK_TEMPORAL, FALLBACK_TEMPORAL + ".pos", FALLBACK_TEMPORAL + ".nrm")
        _poison_history("ss_mf_temporal", hist + tuple(h + "@prev" for h in hist))
        img = session.render(moved, "SSR", 1, 1, keep_history=True, session="ss_mf_temporal").image
        assert np.isfinite(img).all()
        assert np.isfinite(_read_resource("ss_mf_temporal", FALLBACK_TEMPORAL, 4)).all()
    finally:
        techniques.REGISTRY.pop(SSROneFrameFallback.id, None)
        techniques.REGISTRY.pop(SSRHitParallax.id, None)
        for k in keys:
            session.release_session(k)
        bpy.data.scenes.remove(sc)
