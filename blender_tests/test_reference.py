"""Cycles references: fair settings fully restored, cache hits and misses, kinds (bpy)."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gi_preview.blender import reference as R  # noqa: E402
from gi_preview.compare import cache as C  # noqa: E402


def _mesh_obj(scene, name, verts, faces, mat):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    return ob


def _material(name, color):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    return m


@pytest.fixture
def scene():
    """A floor, a red wall lit by a spot that only hits the wall: the floor near the wall
    is lit by the wall's bounce light only (direct != full)."""
    sc = bpy.data.scenes.new("gi_ref_test")
    sc.render.resolution_x = 32
    sc.render.resolution_y = 32
    sc.render.resolution_percentage = 100
    white = _material("ref_white", (0.8, 0.8, 0.8))
    red = _material("ref_red", (0.9, 0.1, 0.1))
    _mesh_obj(sc, "floor", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2, 3)], white)
    _mesh_obj(sc, "wall", [(-2, 1, 0), (2, 1, 0), (2, 1, 2), (-2, 1, 2)], [(0, 1, 2, 3)], red)
    ld = bpy.data.lights.new("ref_sun", "SUN")
    ld.energy = 3.0
    lo = bpy.data.objects.new("ref_sun", ld)
    # sun from -Y towards +Y, grazing: lights the wall's front, floor in the wall's "shadow"?
    # keep it simple: sun hits the wall straight on and the floor at a grazing angle
    lo.rotation_euler = (np.radians(85), 0, 0)
    sc.collection.objects.link(lo)
    cd = bpy.data.cameras.new("ref_cam")
    co = bpy.data.objects.new("ref_cam", cd)
    co.location = (0, -4, 2.0)
    co.rotation_euler = (np.radians(70), 0, 0)
    sc.collection.objects.link(co)
    sc.camera = co
    # non-default user settings the reference must not disturb
    sc.render.engine = "BLENDER_EEVEE"
    sc.render.image_settings.file_format = "PNG"
    sc.render.image_settings.color_depth = "8"  # EXR has no 8: must be recorded before the switch
    sc.render.film_transparent = True
    sc.view_settings.exposure = 0.5
    sc["test_red_material"] = red.name
    yield sc
    ids = [ob for ob in sc.collection.objects] + [ob.data for ob in sc.collection.objects] + [white, red]
    bpy.data.batch_remove(ids)
    bpy.data.scenes.remove(sc)


def _paths(scene, kind):
    p = [path for path, _ in R.fair_settings(scene, kind, 4)]
    p += [f'view_layers["{vl.name}"].material_override' for vl in scene.view_layers]
    p += [f'view_layers["{vl.name}"].use_pass_ambient_occlusion' for vl in scene.view_layers]
    return p


def _snapshot(scene, paths):
    return {p: R.get_path(scene, p) for p in paths}


def test_settings_guard_plain_objects():
    from types import SimpleNamespace as NS
    root = NS(a=NS(b=1, c="x"), items={"k": NS(v=2.0)})
    g = R.SettingsGuard(root)
    with pytest.raises(KeyError):
        with g:
            g.set("a.b", 5)
            g.set('items["k"].v', 3.0)
            assert root.a.b == 5 and root.items["k"].v == 3.0
            raise KeyError("boom")
    assert root.a.b == 1 and root.items["k"].v == 2.0
    assert g.touched == ["a.b", 'items["k"].v']


@pytest.mark.parametrize("kind", ["full", "ao"])
def test_render_restores_every_setting(scene, kind):
    paths = _paths(scene, kind)
    before = _snapshot(scene, paths)
    n_mat, n_img = len(bpy.data.materials), set(bpy.data.images.keys())
    log = []
    img, ms = R.render_cycles(scene, 4, kind, guard_log=log)
    assert img.shape == (32, 32, 4) and img.dtype == np.float32 and np.isfinite(img).all()
    assert ms > 0
    assert set(log) <= set(paths), set(log) - set(paths)
    after = _snapshot(scene, paths)
    assert after == before, {k: (before[k], after[k]) for k in paths if before[k] != after[k]}
    assert len(bpy.data.materials) == n_mat
    assert set(bpy.data.images.keys()) <= n_img | {"Render Result"}
    if kind == "ao":
        assert img[..., :3].min() >= -1e-3 and img[..., :3].max() <= 1.0 + 1e-3
        assert img[..., 0].std() > 0.01  # corner occlusion shows up


def test_restored_after_injected_exception(scene, monkeypatch):
    paths = _paths(scene, "ao")
    before = _snapshot(scene, paths)
    n_mat = len(bpy.data.materials)
    seen = {}

    def boom(sc):
        seen["engine"] = sc.render.engine
        seen["filter"] = sc.cycles.pixel_filter_type
        raise RuntimeError("injected failure mid-render")

    monkeypatch.setattr(R, "_run_render", boom)
    with pytest.raises(RuntimeError, match="injected"):
        R.render_cycles(scene, 4, "ao")
    assert seen == {"engine": "CYCLES", "filter": "BOX"}  # the settings were applied...
    assert _snapshot(scene, paths) == before  # ...and all put back
    assert len(bpy.data.materials) == n_mat


def test_cancel_before_render(scene):
    before = _snapshot(scene, _paths(scene, "full"))
    with pytest.raises(R.ReferenceCancelled):
        R.render_cycles(scene, 4, "full", cancel=lambda: True)
    assert _snapshot(scene, _paths(scene, "full")) == before


def test_renders_a_scene_that_is_not_the_context_scene_at_its_own_frame(scene):
    """The reference of a scene other than the window's is rendered at that scene's frame and
    leaves the frame alone (Blender's operator, given only the scene's name, renders at the
    context scene's frame and moves the scene there). The sun is keyed off at frame 1 and on
    from frame 4."""
    assert bpy.context.scene != scene and bpy.context.scene.frame_current != 4
    sun = scene.objects["ref_sun"].data
    sun.energy = 0.0
    sun.keyframe_insert("energy", frame=1)
    sun.energy = 3.0
    sun.keyframe_insert("energy", frame=4)
    action = sun.animation_data.action
    try:
        for fc in getattr(action, "fcurves", None) or [c for lay in action.layers for s in lay.strips
                                                       for b in s.channelbags for c in b.fcurves]:
            for k in fc.keyframe_points:
                k.interpolation = "CONSTANT"
        scene.frame_set(4)
        lit, _ = R.render_cycles(scene, 4, "direct")
        assert scene.frame_current == 4 and scene.objects["ref_sun"].data.energy == 3.0
        scene.frame_set(1)
        dark, _ = R.render_cycles(scene, 4, "direct")
        assert scene.frame_current == 1
    finally:
        sun.animation_data_clear()
        bpy.data.actions.remove(action)
    assert float(dark[..., :3].max()) == 0.0
    assert float(lit[..., :3].mean()) > 0.05


def test_cache_hit_and_invalidation(scene, tmp_path):
    r1 = R.get_reference(scene, "full", 16, cache_dir=str(tmp_path))
    assert not r1.cached and r1.image.shape == (32, 32, 4)
    r2 = R.get_reference(scene, "full", 16, cache_dir=str(tmp_path))
    assert r2.cached and r2.key == r1.key
    assert r2.time_ms == pytest.approx(r1.time_ms)  # the stored render time, not the load time
    np.testing.assert_array_equal(r2.image, r1.image)
    # a material change invalidates the entry
    bpy.data.materials[scene["test_red_material"]].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = \
        (0.1, 0.9, 0.1, 1.0)
    r3 = R.get_reference(scene, "full", 16, cache_dir=str(tmp_path))
    assert not r3.cached and r3.key != r1.key
    # other spp -> other key
    assert R.get_reference(scene, "full", 8, cache_dir=str(tmp_path)).key != r3.key


def test_direct_differs_from_full(scene, tmp_path):
    d = R.get_reference(scene, "direct", 16, cache_dir=str(tmp_path)).image
    f = R.get_reference(scene, "full", 16, cache_dir=str(tmp_path)).image
    o = R.get_reference(scene, "one_bounce", 16, cache_dir=str(tmp_path)).image
    md, mo, mf = (float(x[..., :3].mean()) for x in (d, o, f))
    assert mf > md * 1.05, (md, mf)
    assert md < mo <= mf * 1.02, (md, mo, mf)


def test_cache_roundtrip(tmp_path):
    R.ensure_oiio()
    store = C.ReferenceCache(str(tmp_path))
    img = np.random.default_rng(0).random((6, 9, 4)).astype(np.float32)
    img[0, :, 0] = 5.0  # bottom row marker survives the flip on write/read
    key = C.reference_key("fp", "full", 16, {"max_bounces": 12}, (9, 6), 0, (5, 0, 1))
    assert store.get(key) is None
    store.put(key, img, {"spp": 16, "time_ms": 12.5, "kind": "full"})
    got, meta = store.get(key)
    np.testing.assert_array_equal(got, img)
    assert meta["spp"] == 16 and meta["time_ms"] == 12.5 and "created" in meta
    assert os.path.exists(os.path.join(str(tmp_path), key + ".exr"))
    keys = {C.reference_key("fp", "full", 16, {"max_bounces": 12}, (9, 6), 0, (5, 0, 1)),
            C.reference_key("fp2", "full", 16, {"max_bounces": 12}, (9, 6), 0, (5, 0, 1)),
            C.reference_key("fp", "direct", 16, {"max_bounces": 12}, (9, 6), 0, (5, 0, 1)),
            C.reference_key("fp", "full", 16, {"max_bounces": 1}, (9, 6), 0, (5, 0, 1)),
            C.reference_key("fp", "full", 16, {"max_bounces": 12}, (9, 7), 0, (5, 0, 1)),
            C.reference_key("fp", "full", 16, {"max_bounces": 12}, (9, 6), 1, (5, 0, 1)),
            C.reference_key("fp", "full", 16, {"max_bounces": 12}, (9, 6), 0, (5, 0, 2))}
    assert len(keys) == 7


# ---------------------------------------------------------------- baselines
def _baseline_paths(scene):
    """Every path a baseline may touch: the reference's, the denoiser's and EEVEE's."""
    p = _paths(scene, "full")
    p += [path for path, _ in R.denoise_settings(scene)]
    p += [path for path, _ in R.eevee_settings(scene, 1)]
    return sorted(set(p))


def test_denoised_baseline_restores_and_denoises(scene, tmp_path):
    """Cycles + OpenImageDenoise: settings put back, and at 2 spp it is much closer to a
    converged reference than plain Cycles at 2 spp (what the denoiser is for)."""
    scene.cycles.denoiser = "OPENIMAGEDENOISE"
    scene.cycles.denoising_input_passes = "RGB"  # a user setting the baseline must restore
    paths = _baseline_paths(scene)
    before = _snapshot(scene, paths)
    log = []
    den, ms = R.render_cycles(scene, 2, "full", seed=5, denoise=True, guard_log=log)
    assert set(log) <= set(paths)
    assert {"cycles.use_denoising", "cycles.denoising_input_passes"} <= set(log)
    assert _snapshot(scene, paths) == before
    assert den.shape == (32, 32, 4) and np.isfinite(den).all() and ms > 0
    plain, _ = R.render_cycles(scene, 2, "full", seed=5)
    ref = R.get_reference(scene, "full", 256, cache_dir=str(tmp_path))
    from gi_preview.compare import metrics as M
    e_den, e_plain = M.relmse(den, ref.image), M.relmse(plain, ref.image)
    print(f"relMSE at 2 spp: denoised {e_den:.4g}, plain {e_plain:.4g}")
    assert e_den < 0.5 * e_plain, (e_den, e_plain)
    with pytest.raises(ValueError, match="ao"):
        R.render_cycles(scene, 2, "ao", denoise=True)


def test_eevee_baseline_restores_settings(scene):
    """EEVEE with ray tracing: the engine, samples and ray-tracing options are the scene's
    again afterwards (the fixture's engine is EEVEE with ray tracing off), and the image is
    finite and lit like Cycles' (mean within a factor 2: EEVEE approximates the bounce)."""
    scene.eevee.use_raytracing = False
    scene.eevee.taa_render_samples = 7
    paths = _baseline_paths(scene)
    before = _snapshot(scene, paths)
    log = []
    img, ms = R.render_eevee(scene, 2, guard_log=log)
    assert {"render.engine", "eevee.use_raytracing", "eevee.taa_render_samples"} <= set(log)
    assert set(log) <= set(paths)
    after = _snapshot(scene, paths)
    assert after == before, {k: (before[k], after[k]) for k in paths if before[k] != after[k]}
    assert scene.render.engine == "BLENDER_EEVEE" and not scene.eevee.use_raytracing
    assert scene.eevee.taa_render_samples == 7
    assert img.shape == (32, 32, 4) and np.isfinite(img).all() and ms > 0
    cyc, _ = R.render_cycles(scene, 64, "full")
    m_e, m_c = float(img[..., :3].mean()), float(cyc[..., :3].mean())
    print(f"mean radiance: EEVEE {m_e:.4g}, Cycles {m_c:.4g}")
    assert 0.5 * m_c < m_e < 2.0 * m_c


def test_baseline_curve_splits_setup(scene, tmp_path):
    """The Cycles curve's wall times are split into setup + per-sample; every point's
    time_ms is the wall time without the setup, errors fall with spp."""
    ref = R.get_reference(scene, "full", 128, cache_dir=str(tmp_path))
    bc = R.baseline_curve(scene, "cycles", [1, 4, 16], ref)
    pts = bc["points"]
    assert [p["spp"] for p in pts] == [1, 4, 16]
    assert bc["warmup_renders"] == 1 and bc["warmup_ms"] > 0
    assert 0.0 <= bc["setup_ms"] <= min(p["wall_ms"] for p in pts)
    for p in pts:
        assert p["setup_ms"] == bc["setup_ms"]
        assert 0 < p["time_ms"] <= p["wall_ms"] * 1.5
        if bc["fit"]["ok"]:
            assert p["time_ms"] == pytest.approx(bc["per_sample_ms"] * p["spp"])
    assert pts[0]["relmse"] > pts[-1]["relmse"]
    # the denoised curve keeps the denoiser's fixed cost in time_ms: the setup passed in
    # (Cycles' own) is what is subtracted
    dn = R.baseline_curve(scene, "cycles_denoised", [1, 2], ref, setup_ms=bc["setup_ms"])
    assert dn["setup_ms"] == pytest.approx(min(bc["setup_ms"], min(p["wall_ms"] for p in dn["points"])))
    with pytest.raises(ValueError, match="full"):
        R.render_baseline(scene, "eevee", 1, kind="direct")
    with pytest.raises(ValueError, match="unknown baseline"):
        R.render_baseline(scene, "unbiased", 1)
