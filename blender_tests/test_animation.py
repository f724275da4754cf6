"""Per-frame comparison of an animation with Cycles:
``scripts/gi_compare.py --animation`` and its logic in ``addon/compare/animation.py``.

* The disocclusion mask (depth + the two cameras) against a case with a known answer: a pan
  in front of a flat wall reveals exactly the columns that were off-screen.
* The per-frame analysis on synthetic sequences: the stability figure is the mean absolute
  frame difference, a lagging history shows up as a trail that recovers when it should.
* The trail's still level is paired: held frame t against the still run's frame t (same seeds);
  with several noise draws the ratio is that of the means.
* End to end on the Cornell box (32 px, a pan of 6 frames then 9 still frames, Cycles
  256 spp + OpenImageDenoise per frame, cached): results.json, the plot and the report are
  written, the scene is left as it was, and SVGF and TAA meet the acceptance bounds under a
  moving camera: the error in the pixels the pan disoccluded is back within 1.5x of the
  still-camera level 8 frames after the stop (no ghost trail), and the temporal stability
  figure is within 2x of Cycles'.
* TAA's ghost on the 48-px Cornell pan (12 moving frames, 3 noise draws), where a TAA without
  the history normal test leaves a lit ghost on the revealed side face: +8 frames within 1.3x
  of the still level (measured 1.07x; without the normal test 2.01x).
"""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gi_preview.compare import animation as A

REPO = Path(__file__).resolve().parent.parent


def _cam(pos, proj):
    m = np.eye(4)
    m[:3, 3] = pos  # looking down -Z, right = +X, up = +Y
    return SimpleNamespace(matrix_world=m, projection=proj, view=np.linalg.inv(m), position=np.asarray(pos, float),
                           forward=np.array([0.0, 0.0, -1.0]))


def _persp(fov_deg=60.0, near=0.1, far=100.0):
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    p = np.zeros((4, 4))
    p[0, 0] = p[1, 1] = f
    p[2, 2] = (far + near) / (near - far)
    p[2, 3] = 2 * far * near / (near - far)
    p[3, 2] = -1.0
    return p


def test_disocclusion_mask_pan_reveals_offscreen_columns():
    w = h = 40
    proj = _persp()
    depth = np.full((h, w), 4.0)  # a wall 4 m away
    c0 = _cam([0.0, 0.0, 0.0], proj)
    assert not A.disoccluded(c0, c0, depth, depth).any(), "no motion, nothing disoccluded"
    dx = 0.5
    c1 = _cam([dx, 0.0, 0.0], proj)
    m = A.disoccluded(c0, c1, depth, depth)
    # the wall point of pixel column x shifts by dx * f / depth * w / 2 pixels
    shift = dx * proj[0, 0] / 4.0 * w / 2
    cols = m.any(0)
    assert (m.all(0) == cols).all(), "whole columns"
    assert abs(cols.sum() - shift) <= 1.0, (cols.sum(), shift)
    assert cols[-1] and not cols[0], "the revealed columns are on the side the camera moved to"
    # a nearer occluder in pose 0 hides the wall behind it: those pixels count as disoccluded in pose 1
    d0 = depth.copy()
    d0[:, 10:14] = 1.0
    m2 = A.disoccluded(c0, c0, d0, depth)
    assert m2[:, 10:14].all() and m2.sum() == 4 * h
    # one-sided: a point whose pose-0 pixel centre saw something *farther* (the background just
    # past a silhouette, a grazing wall's far part) was not hidden; the two-sided test flagged
    # the green wall's whole front-edge column on the 48-px Cornell pan (48 of 91 trail pixels)
    d0 = depth.copy()
    d0[:, 20] = 1e10
    d0[:, 21] = 4.5
    assert not A.disoccluded(c0, c0, d0, depth).any()
    # background pixels are never in the mask
    bg = depth.copy()
    bg[:5] = 1e10
    assert not A.disoccluded(c0, c1, bg, bg)[:5].any()


def test_analysis_stability_and_trail_synthetic():
    spec = A.AnimationSpec(motion="pan", move=4, hold=10)
    rng = np.random.default_rng(1)
    h = w = 16
    n = spec.frames
    refs = [np.full((h, w, 4), 0.5 + 0.05 * min(t, spec.move), np.float32) for t in range(n)]
    mask = np.zeros((h, w), bool)
    mask[:, :4] = True
    # ours: the reference plus noise, and in the mask a ghost that halves every frame after the stop
    ours = []
    for t in range(n):
        o = refs[t] + rng.normal(0, 0.01, refs[t].shape).astype(np.float32)
        if t >= spec.move:
            o[mask] += 0.8 * 0.5 ** (t - spec.move)
        ours.append(o)
    still = [refs[-1] + rng.normal(0, 0.01, refs[-1].shape).astype(np.float32) for _ in range(spec.hold + 1)]
    masks = [None] + [mask.copy() for _ in range(1, n)]
    a = A.analyse(spec, ours, refs, masks, mask, still, cycles_noise_floor=0.0)
    diffs = [float(np.mean(np.abs(ours[t][..., :3] - ours[t - 1][..., :3]))) for t in range(1, spec.move + 1)]
    assert a["stability"] == pytest.approx(np.mean(diffs))
    assert a["cycles_stability"] == pytest.approx(0.05)
    assert a["stability_ratio"] == pytest.approx(a["stability"] / 0.05)
    tr = a["trail"]
    assert tr["mask_pixels"] == mask.sum()
    # the ghost's relMSE falls as 0.8^2 * 4^-k / (0.7^2 + 0.01); the noise level is ~1e-4
    assert tr["ratio_after_stop"][0] > 100
    assert 4 <= tr["recovered_after"] <= 8, tr["relmse_after_stop"]
    assert tr["ratio_at_8"] < A.RECOVERY_TOLERANCE
    assert a["nonfinite_pixels"] == 0
    assert not tr["paired"], "a still run shorter than the moving one: the mean of its last frames"
    assert tr["still_after_stop"] == [pytest.approx(tr["still_level"])] * (spec.hold + 1)
    with pytest.raises(ValueError, match="unknown animation motion 'spin'"):
        A.AnimationSpec(motion="spin")
    with pytest.raises(ValueError, match="noise draw"):
        A.AnimationSpec(motion="pan", draws=0)


def test_trail_still_level_is_paired_by_frame_and_draws_average():
    """Held frame t is compared with the still run's frame t: when both share the frame's noise
    (the same seeds) and the history carries nothing from the move, the ratio is 1 whatever
    that noise is; a ghost shows on top of it. Draws: ratio of the means, not mean of ratios."""
    spec = A.AnimationSpec(motion="pan", move=4, hold=10)
    n, h, w = spec.frames, 12, 12
    refs = [np.full((h, w, 4), 0.5, np.float32) for _ in range(n)]
    mask = np.zeros((h, w), bool)
    mask[:, :3] = True
    masks = [None] + [mask.copy() for _ in range(1, n)]

    def draw(seed, ghost):
        rng = np.random.default_rng(seed)
        # the frame's noise, shared by both runs; its size changes from frame to frame
        noise = [rng.normal(0, 0.02 * (1 + t % 3), refs[0].shape).astype(np.float32) for t in range(n)]
        still = [refs[t] + noise[t] for t in range(n)]
        ours = [refs[t] + noise[t] for t in range(n)]
        for t in range(spec.move, n):
            ours[t][mask] += ghost * 0.5 ** (t - spec.move)
        return ours, still

    ours, still = draw(1, 0.0)
    tr = A.analyse(spec, ours, refs, masks, mask, still)["trail"]
    assert tr["paired"] and tr["ratio_after_stop"] == [pytest.approx(1.0)] * (spec.hold + 1)
    assert tr["recovered_after"] == 0 and tr["ratio_at_8"] == pytest.approx(1.0)
    ours, still = draw(1, 0.8)
    tr = A.analyse(spec, ours, refs, masks, mask, still)["trail"]
    assert tr["ratio_after_stop"][0] > 10 and tr["ratio_at_8"] < 1.2 and 2 <= tr["recovered_after"] <= 8
    # three draws: the figures are the means over draws, the ratio is mean trail / mean still
    runs = [draw(s, 0.8) for s in (2, 3, 4)]
    a = A.analyse(spec, *runs[0][:1], refs, masks, mask, runs[0][1], draws=runs[1:])
    one = [A.analyse(spec, o, refs, masks, mask, st) for o, st in runs]
    per = np.mean([r["trail"]["relmse_after_stop"] for r in one], 0)
    lv = np.mean([r["trail"]["still_after_stop"] for r in one], 0)
    assert a["draws"] == 3
    assert a["trail"]["ratio_at_8"] == pytest.approx(per[8] / lv[8])
    assert a["trail"]["ratio_at_8_per_draw"] == [pytest.approx(r["trail"]["ratio_at_8"]) for r in one]
    assert a["stability"] == pytest.approx(np.mean([r["stability"] for r in one]))
    assert a["relmse"] == one[0]["relmse"], "per-frame lists are the first draw's"


# ---------------------------------------------------------------- end to end (bpy, GL, Cycles)
def _gi_compare():
    spec = importlib.util.spec_from_file_location("gi_compare_anim", REPO / "scripts" / "gi_compare.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_animation_compare_cornell_svgf_taa(tmp_path):
    bpy = pytest.importorskip("bpy")
    pytest.importorskip("moderngl")
    import gi_preview
    from gi_preview.blender import demo_scenes as D
    from gi_preview.render import session

    gc = _gi_compare()
    sc = D.build_demo("cornell", resolution=32)
    try:
        chans = ("location", "rotation_euler", "scale")
        cam_before = [tuple(getattr(sc.camera, c)) for c in chans]
        frame_before = sc.frame_current
        opts = gc.parse_args(["cornell", "--animation", "pan", "--techniques", "SVGF,TAA", "--res", "32",
                              "--anim-frames", "6", "--anim-hold", "9",
                              "--out", str(tmp_path)], scene_optional=False)
        res = gc.run_animation(opts, pkg=gi_preview, session=session, scene=sc)
        # the scene is as it was
        assert [tuple(getattr(sc.camera, c)) for c in chans] == cam_before
        assert sc.frame_current == frame_before
        on_disk = json.loads((tmp_path / "results.json").read_text())
        anim = on_disk["animation"]
        assert anim["frames"] == 16 and anim["stop_frame"] == 6
        assert anim["cycles"]["spp"] == 256 and "OpenImageDenoise" in anim["cycles"]["denoise"]
        assert (tmp_path / "animation.png").stat().st_size > 5000
        assert (tmp_path / "strip_SVGF.png").exists() and (tmp_path / "strip_cycles.png").exists()
        html = (tmp_path / "report.html").read_text()
        assert "Animation: per-frame comparison" in html and "data:image/png;base64" in html
        cy = anim["cycles"]
        assert cy["stability"] > 0 and cy["noise_floor"] < 0.5 * cy["stability"], \
            f"Cycles' frame difference {cy['stability']:.4f} must measure the motion, not its noise ({cy['noise_floor']:.4f})"
        assert anim["trail_mask_pixels"] >= 15, "the pan must disocclude something"
        for tech in ("SVGF", "TAA"):
            a = anim["techniques"][tech]
            tr = a["trail"]
            print(f"{tech}: relMSE per frame {', '.join(f'{e:.3f}' for e in a['relmse'])}; stability "
                  f"{a['stability']:.4f} vs Cycles {a['cycles_stability']:.4f} ({a['stability_ratio']:.2f}x, noise "
                  f"floor {cy['noise_floor']:.4f}); trail ({tr['mask_pixels']} px) after the stop "
                  f"{', '.join(f'{e:.3f}' for e in tr['relmse_after_stop'])} vs still {tr['still_level']:.4f}: "
                  f"+8 {tr['ratio_at_8']:.2f}x, recovered after {tr['recovered_after']}; mean/Cycles last "
                  f"{a['mean_ratio'][-1]:.3f}")
        for tech in ("SVGF", "TAA"):
            a = anim["techniques"][tech]
            tr = a["trail"]
            assert len(a["relmse"]) == 16 and a["nonfinite_pixels"] == 0
            assert all(np.isfinite(a["relmse"]))
            assert a["stability_ratio"] <= 2.0, f"{tech}: stability {a['stability_ratio']:.2f}x Cycles'"
            # paired: the still run is as long as the moving one and drew the same seeds
            assert tr["paired"] and tr["same_seeds"] and len(tr["still_relmse"]) == 16
            # the recovery criterion. Measured (paired, this draw): SVGF 1.28x, TAA 1.30x; over 12
            # seed offsets TAA 0.77-1.53x (mean 1.14), SVGF 0.85-2.56x (ratio of means 1.23, flat
            # after the stop: the revealed pixels' shorter history, not a decaying ghost). At this
            # size a TAA without the history normal test measures 1.49x here and 1.18x as a
            # ratio of 12 seeds' means: its ghost has faded by +8; the 48-px test below sees it.
            assert tr["ratio_at_8"] <= A.RECOVERY_TOLERANCE, f"{tech}: ghost trail, {tr['ratio_at_8']:.2f}x still level"
        assert res["animation"]["techniques"]["TAA"]["stability"] == pytest.approx(
            anim["techniques"]["TAA"]["stability"])
    finally:
        bpy.data.scenes.remove(sc)


def test_taa_pan_ghost_trail_48px():
    """The Cornell pan at 48 px (12 moving frames, 8 held, 3 noise draws): the pan reveals the
    short box's right side face at a grazing angle; a TAA without the history normal test keeps
    the lit front face's history there (its plane test accepts texels near the edge) and
    measures 2.01x the still level 8 frames after the stop (4.96x at the stop; 1.48-1.80x over
    groups of 3 seeds). With the history normal test under motion: 1.07x (1.06-1.11x over groups of 3 seeds;
    single draws 0.95-1.42x). Bound 1.3: between the two, three single-draw sd above this one."""
    pytest.importorskip("bpy")
    pytest.importorskip("moderngl")
    import bpy
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender import export, reference
    from gi_preview.render import session

    sc = D.build_demo("cornell", resolution=48)
    try:
        res = A.run(sc, A.AnimationSpec(motion="pan", move=12, hold=8, draws=3), ["TAA"], reference=reference,
                    export=export, session=session, width=48, height=48, log=lambda _m: None)
    finally:
        bpy.data.scenes.remove(sc)
    a = res["animation"]["techniques"]["TAA"]
    tr = a["trail"]
    print(f"\nTAA cornell pan 48 px, 3 draws: trail {tr['mask_pixels']} px, +8 {tr['ratio_at_8']:.2f}x (draws "
          f"{', '.join(f'{x:.2f}' for x in tr['ratio_at_8_per_draw'])}); after the stop "
          f"{', '.join(f'{x:.2f}' for x in tr['ratio_after_stop'])}; stability {a['stability_ratio']:.2f}x")
    assert a["draws"] == 3 and a["nonfinite_pixels"] == 0
    assert tr["same_seeds"] and tr["mask_pixels"] >= 30
    assert a["stability_ratio"] <= 2.0
    assert tr["ratio_at_8"] <= 1.3, f"ghost trail: {tr['ratio_at_8']:.2f}x the still level 8 frames after the stop"

