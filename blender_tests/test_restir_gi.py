"""RESTIR_GI (issue 11, Ouyang et al. 2021) against Cycles full (256 spp, 40 px, cached).

* Cornell box and sun-lit room, still camera, the frame shown after 16 frames: RESTIR_GI +
  SVGF has a lower relMSE than SSDO (the issue's acceptance), and RESTIR_GI's own
  accumulated mean is within 15 % of Cycles' (the indirect light is not lost or doubled).
* Reuse works: the single frame shown after 12 frames with temporal + spatial reuse has a
  lower relMSE than the same pass with reuse off (one path sample per pixel, no resampling).
* The effect AOVs GI_IndirectDiffuse / GI_IndirectGlossy and the debug views GI_ReservoirW /
  GI_ReservoirM are returned, finite and non-negative; the image is DIRECT's plus them.
* NaN written into every history texture is gone from image and history after one frame.
* 200 frames of a moving camera stay finite and bounded (test_stability's bound).
Images go to blender_tests/_artifacts/restir_gi/ for a person to look at.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("moderngl")

from gi_preview.blender import demo_scenes as D  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.blender.reference import evaluated_depsgraph, get_reference  # noqa: E402
from gi_preview.render import session  # noqa: E402
from gi_preview.render.gl import get_gl  # noqa: E402

RES = 40
REF_SPP = 256
ART = Path(__file__).resolve().parent / "_artifacts" / "restir_gi"


def relmse(a, b) -> float:
    return float(np.mean((a[..., :3] - b[..., :3]) ** 2 / (b[..., :3] ** 2 + 1e-2)))


def save_png(imgs, name):
    try:
        from PIL import Image
    except ImportError:
        return
    ART.mkdir(parents=True, exist_ok=True)
    row = np.concatenate([np.clip(i[..., :3] / (1 + i[..., :3]) * 1.6, 0, 1) ** (1 / 2.2) for i in imgs], 1)
    Image.fromarray((row[::-1] * 255).astype(np.uint8)).resize((row.shape[1] * 4, row.shape[0] * 4)).save(ART / name)


def build(name, res=RES):
    sc = D.build_demo(name, resolution=res)
    return sc, export_scene(evaluated_depsgraph(sc))


def frames(sd, tech, n, sess, **kw):
    """The results after each of ``n`` viewport-style frames (history kept, no warm-up)."""
    return [session.render(sd, tech, 1, 1, keep_history=True, warmup=False, session=sess, **kw) for _ in range(n)]


def release(sess):
    session.release_session(sess).result(timeout=60)


def set_props(sess, props):
    session.set_pass_properties(sess, {"restir_gi": props})


@pytest.fixture(scope="module", params=["cornell", "sunlit_room"])
def scene(request):
    sc, sd = build(request.param)
    ref = get_reference(sc, "full", REF_SPP).image[..., :3]
    yield request.param, sc, sd, ref
    bpy.data.scenes.remove(sc)


def test_restir_gi_svgf_beats_ssdo(scene):
    name, sc, sd, ref = scene
    try:
        rg = frames(sd, "RESTIR_GI", 16, "rg_" + name)
        rgs = frames(sd, "RESTIR_GI", 16, "rgs_" + name, denoiser="SVGF")
        ssdo = frames(sd, "SSDO", 16, "ssdo_" + name)
    finally:
        for s in ("rg_", "rgs_", "ssdo_"):
            release(s + name)
    img, imgs, imso = rg[-1].image[..., :3], rgs[-1].image[..., :3], ssdo[-1].image[..., :3]
    acc = np.mean([r.image[..., :3] for r in rg], 0)
    e_rg, e_rgs, e_ssdo = relmse(img, ref), relmse(imgs, ref), relmse(imso, ref)
    save_png([ref, imso, img, imgs], f"{name}_cycles_ssdo_restirgi_restirgi_svgf.png")
    print(f"\n{name} {RES}px, frame shown after 16: relMSE vs Cycles full RESTIR_GI {e_rg:.4f}, "
          f"RESTIR_GI+SVGF {e_rgs:.4f}, SSDO {e_ssdo:.4f} ({e_ssdo / e_rgs:.2f}x); mean of 16 RESTIR_GI frames "
          f"{acc.mean() / ref.mean():.3f} of Cycles")
    assert np.isfinite(img).all() and np.isfinite(imgs).all()
    assert e_rgs < e_ssdo, f"RESTIR_GI+SVGF {e_rgs:.4f} does not beat SSDO {e_ssdo:.4f}"
    assert abs(acc.mean() / ref.mean() - 1.0) < 0.15, f"mean {acc.mean() / ref.mean():.3f} of Cycles"


@pytest.mark.parametrize("scene", ["cornell"], indirect=True)  # Cornell box only (test time budget)
def test_reuse_lowers_error_cornell(scene):
    name, sc, sd, ref = scene
    try:
        on = [relmse(r.image, ref) for r in frames(sd, "RESTIR_GI", 12, "reuse_on")[-4:]]
        session.render(sd, "RESTIR_GI", 1, 1, warmup=False, session="reuse_off")
        set_props("reuse_off", {"temporal": 0, "spatial": 0})
        off = [relmse(r.image, ref) for r in frames(sd, "RESTIR_GI", 12, "reuse_off")[-4:]]
    finally:
        release("reuse_on"), release("reuse_off")
    e_on, e_off = float(np.mean(on)), float(np.mean(off))
    print(f"\ncornell: relMSE of single frames with reuse {e_on:.4f}, without {e_off:.4f} ({e_off / e_on:.2f}x)")
    assert e_on < 0.7 * e_off, f"reuse {e_on:.4f} vs none {e_off:.4f}"


@pytest.mark.parametrize("scene", ["cornell"], indirect=True)  # Cornell box only (test time budget)
def test_aovs_and_debug_views(scene):
    name, sc, sd, ref = scene
    try:
        r = frames(sd, "RESTIR_GI", 3, "aov")[-1]
        d = session.render(sd, "DIRECT", 1, 1, warmup=False, session="aov_direct")
    finally:
        release("aov"), release("aov_direct")
    for k in ("GI_IndirectDiffuse", "GI_IndirectGlossy", "GI_ReservoirW", "GI_ReservoirM", "GI_Direct"):
        assert k in r.aovs, f"missing render pass {k}"
        a = np.asarray(r.aovs[k])[..., :3]
        assert np.isfinite(a).all() and a.min() >= 0.0, k
    ind = np.asarray(r.aovs["GI_IndirectDiffuse"])[..., :3] + np.asarray(r.aovs["GI_IndirectGlossy"])[..., :3]
    assert ind.mean() > 0.05 * r.image[..., :3].mean(), "no indirect light in the Cornell box"
    m = np.asarray(r.aovs["GI_ReservoirM"])[..., 0]
    fg = r.aovs["Depth"][..., 0] < 1e9
    # after 3 frames with temporal and spatial reuse, M is well above the one fresh sample
    assert np.median(m[fg]) > 2.0, f"median M {np.median(m[fg]):.2f}"
    # the image is DIRECT's (its own estimator, deterministic diffuse) plus the indirect light
    diff = np.abs(r.image[..., :3] - ind - d.image[..., :3]).mean() / d.image[..., :3].mean()
    print(f"\nindirect share {ind.mean() / r.image[..., :3].mean():.3f}; median M {np.median(m[fg]):.1f}; "
          f"|image - indirect - DIRECT| / DIRECT {diff:.3f}")
    assert diff < 0.15


def _history_names(sess):
    def get():
        s = session._sessions[sess]
        return [h + sfx for _t, g in s.graphs.values() for p in g.passes for h in p.history for sfx in ("", "@prev")
                if p.name == "restir_gi"]
    return get_gl().call(get)


def test_nan_in_history_gone_within_one_frame():
    sc, sd = build("cornell", 24)
    sess = "rg_nan"
    try:
        frames(sd, "RESTIR_GI", 3, sess)
        names = _history_names(sess)
        assert len(names) == 10, names

        def poison():
            s = session._sessions[sess]
            for n in names:
                t = s.rc.resources[n]
                t.write(np.full((t.size[1], t.size[0], t.components), np.nan, np.float32).tobytes())
            s.ctx.finish()
        get_gl().call(poison)
        img = frames(sd, "RESTIR_GI", 1, sess)[-1].image
        assert np.isfinite(img).all(), f"{int((~np.isfinite(img)).sum())} non-finite values after NaN history"

        def check():
            s = session._sessions[sess]
            s.ctx.memory_barrier()
            return [n for n in names if not n.endswith("@prev")
                    and not np.isfinite(np.frombuffer(s.rc.resources[n].read(), np.float32)).all()]
        bad = get_gl().call(check)
        assert not bad, f"history still holds NaN after one frame: {bad}"
    finally:
        release(sess)
        bpy.data.scenes.remove(sc)


def _inject_bright_sample(sess, scale: float = 1e4):
    """Multiplies the radiance of the history reservoir at the image centre by ``scale`` (a
    valid sample, so reuse takes it): a rare, very bright sample, the seed of boiling."""
    def go():
        s = session._sessions[sess]
        s.ctx.memory_barrier()
        for n in ("restir_gi.rad", "restir_gi.rad@prev"):
            t = s.rc.resources[n]
            w, h = t.size
            a = np.frombuffer(t.read(), np.float32).reshape(h, w, 4).copy()
            ys, xs = np.nonzero(a[..., 3] > 0.5)
            k = int(np.argmin((ys - h / 2) ** 2 + (xs - w / 2) ** 2))
            a[ys[k], xs[k], :3] *= scale
            t.write(a.tobytes())
        s.ctx.finish()
    get_gl().call(go)


def test_boiling_filter_drops_a_rare_bright_sample():
    """A reservoir made 10^4x brighter than its neighbours (valid, so temporal and spatial reuse
    take it) is dropped by the boiling filter in the next frame: the indirect light stays
    within 20x its level before. With the filter off the same sample spreads over its
    neighbours (the check is able to fail)."""
    sc, sd = build("cornell", 24)
    peaks = {}
    try:
        for strength in (0.2, 0.0):
            sess = f"rg_boil_{strength}"
            try:
                frames(sd, "RESTIR_GI", 1, sess, denoiser="NONE")
                set_props(sess, {"boiling_filter": strength})
                before = frames(sd, "RESTIR_GI", 4, sess, denoiser="NONE")[-1].aovs["GI_IndirectDiffuse"]
                _inject_bright_sample(sess)
                after = frames(sd, "RESTIR_GI", 1, sess, denoiser="NONE")[-1].aovs["GI_IndirectDiffuse"]
                assert np.isfinite(after).all()
                peaks[strength] = float(after.max()) / max(float(before.max()), 1e-9)
            finally:
                release(sess)
    finally:
        bpy.data.scenes.remove(sc)
    print(f"\nbright sample injected: indirect peak / before {peaks[0.2]:.1f}x with the filter, "
          f"{peaks[0.0]:.1f}x without")
    assert peaks[0.2] < 20.0, peaks
    assert peaks[0.0] > 100.0, peaks


def test_200_frame_animation_finite_and_bounded():
    sc, sd = build("cornell", 16)
    sess = "rg_anim"
    try:
        b = float(max([np.max(m.emission) for m in sd.materials] + [1.0] +
                      [float(np.max(L.color)) * 1e4 for L in sd.lights])) * 100.0
        cam0 = sd.camera.matrix_world.copy()
        peak = 0.0
        for f in range(200):
            m = cam0.copy()
            a = 0.4 * math.sin(f * 0.07)
            m[:3, 3] = cam0[:3, 3] + cam0[:3, 0] * a  # pan back and forth
            sdf = dataclasses.replace(sd, camera=dataclasses.replace(sd.camera, matrix_world=m.astype(np.float32)))
            img = session.render(sdf, "RESTIR_GI", 1, 1, keep_history=f > 0, warmup=False, session=sess,
                                 denoiser="SVGF" if f >= 100 else "NONE").image
            assert np.isfinite(img).all(), f"frame {f}: non-finite"
            peak = max(peak, float(img[..., :3].max()))
            assert peak <= b, f"frame {f}: {peak} above the bound {b}"
        print(f"\n200 frames: peak {peak:.3f} (bound {b:.1f})")
    finally:
        release(sess)
        bpy.data.scenes.remove(sc)


def _moved(sd, dx=0.0, yaw_deg=0.0):
    """``sd`` with its camera moved sideways by ``dx`` (its own x axis) and turned by ``yaw_deg``
    about the world z axis through the camera."""
    m = sd.camera.matrix_world.astype(np.float64).copy()
    m[:3, 3] += m[:3, 0] * dx
    a = math.radians(yaw_deg)
    rz = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    m[:3, :3] = rz @ m[:3, :3]
    return dataclasses.replace(sd, camera=dataclasses.replace(sd.camera, matrix_world=m.astype(np.float32)))


def test_reprojection_keeps_surfaces_and_drops_disoccluded_pixels():
    """Temporal reuse after a camera move (48 px Cornell box, spatial reuse off, so the final
    reservoir's candidate count M is 1 exactly when last frame's reservoir was refused):
    * a pure rotation disoccludes nothing (no parallax): every pixel whose point was on screen
      keeps its history, edges included (the nearest previous pixel of an edge pixel may lie on
      the neighbouring face; the other pixels of the bilinear footprint are tried);
    * a sideways move: the pixels whose surface was hidden behind something at least 20 %
      nearer, or off-screen, start from a fresh sample instead of inheriting a reservoir made
      for another surface (the start of a ghost trail)."""
    from gi_preview.compare import animation as A
    sc, sd = build("cornell", 48)
    out = {}
    try:
        for label, dx, yaw in (("rotation", 0.0, 10.0), ("sideways", 1.5, 0.0)):
            sess = "rg_repro_" + label
            try:
                session.render(sd, "RESTIR_GI", 1, 1, warmup=False, session=sess)
                set_props(sess, {"spatial": 0})
                r0 = frames(sd, "RESTIR_GI", 4, sess)[-1]
                sd1 = _moved(sd, dx=dx, yaw_deg=yaw)
                r1 = session.render(sd1, "RESTIR_GI", 1, 1, keep_history=True, warmup=False, session=sess)
            finally:
                release(sess)
            d0, d1 = r0.aovs["Depth"][..., 0], r1.aovs["Depth"][..., 0]
            m = np.asarray(r1.aovs["GI_ReservoirM"])[..., 0]
            offscreen = A.disoccluded(sd.camera, sd1.camera, d0, d1, rel_tol=1e9)  # no depth test
            hidden = A.disoccluded(sd.camera, sd1.camera, d0, d1, rel_tol=0.2)
            out[label] = (m, d1, offscreen, hidden)
    finally:
        bpy.data.scenes.remove(sc)
    m, d1, offscreen, _h = out["rotation"]
    seen = (d1 < 1e9) & ~offscreen
    kept = float(np.mean(m[seen] > 1.0))
    m, d1, _o, hidden = out["sideways"]
    fresh = float(np.mean(m[hidden] <= 1.0))
    print(f"\nrotation: {kept:.4f} of {int(seen.sum())} px keep their reservoir; sideways: {fresh:.3f} of "
          f"{int(hidden.sum())} disoccluded px start fresh")
    assert kept >= 0.99, f"rotation: only {kept:.4f} of the pixels seen last frame kept their reservoir"
    assert hidden.sum() >= 20, "the move must disocclude something"
    assert fresh >= 0.85, f"only {fresh:.3f} of the disoccluded pixels dropped last frame's reservoir"


def test_technique_default_filter_and_motion_as_shipped():
    """scene.gi_preview.denoiser defaults to "AUTO" (Technique Default): RESTIR_GI then ends in
    SVGF, PT stays unfiltered. As shipped, under a camera pan on the Cornell box (32 px, 6
    moving frames then 9 still, each frame against Cycles 256 spp + OIDN, cached), RESTIR_GI
    meets the issue's motion acceptance: temporal stability within 2x of Cycles', and the error
    of the disoccluded pixels back within 1.5x of a still camera's 8 frames after the stop (the
    still camera's error on that same frame, drawn with the same seeds: animation.py)."""
    from gi_preview.blender import export, reference
    from gi_preview.blender.engine import _filter_options
    from gi_preview.compare import animation as A
    from gi_preview.render import techniques
    sc = D.build_demo("cornell", resolution=32)
    try:
        opts = _filter_options(sc)
        assert opts["denoiser"] == "AUTO", opts
        assert techniques.resolve_denoiser("RESTIR_GI", opts["denoiser"]) == "SVGF"
        assert techniques.resolve_denoiser("PT", opts["denoiser"]) == "NONE"
        assert techniques.resolve_denoiser("RESTIR_GI", "NONE") == "NONE"
        sd = export_scene(evaluated_depsgraph(sc))
        try:
            r = session.render(sd, "RESTIR_GI", 1, 1, warmup=False, session="rg_auto", **opts)
            p = session.render(sd, "PT", 1, 1, warmup=False, session="rg_auto", **opts)
        finally:
            release("rg_auto")
        assert r.pass_order[-1] == "svgf", r.pass_order
        assert "svgf" not in p.pass_order, p.pass_order

        class Shipped:  # the engine's call: the scene's filter options
            release_session = staticmethod(session.release_session)

            @staticmethod
            def render(sd_, tech, *args, **kw):
                return session.render(sd_, tech, *args, **opts, **kw)

        res = A.run(sc, A.AnimationSpec(motion="pan", move=6, hold=9), ["RESTIR_GI"], reference=reference,
                    export=export, session=Shipped, width=32, height=32, log=lambda _m: None)
    finally:
        bpy.data.scenes.remove(sc)
    a = res["animation"]["techniques"]["RESTIR_GI"]
    tr = a["trail"]
    print(f"\nRESTIR_GI as shipped (SVGF), cornell pan 32 px: stability {a['stability']:.4f} vs Cycles "
          f"{a['cycles_stability']:.4f} ({a['stability_ratio']:.2f}x); trail {tr['mask_pixels']} px, +8 frames "
          f"{tr['ratio_at_8']:.2f}x the still level (paired {tr['paired']}, same seeds {tr['same_seeds']}), "
          f"recovered after {tr['recovered_after']}")
    assert a["nonfinite_pixels"] == 0
    assert tr["mask_pixels"] >= 15, "the pan must disocclude something"
    assert a["stability_ratio"] <= 2.0, f"stability {a['stability_ratio']:.2f}x Cycles'"
    assert tr["paired"], "the still run must be as long as the moving one (frame-by-frame still level)"
    assert tr["ratio_at_8"] <= A.RECOVERY_TOLERANCE, f"ghost trail: {tr['ratio_at_8']:.2f}x the still level"
