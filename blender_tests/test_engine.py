"""The GI_PREVIEW engine end to end through Blender's own render operator.

F12-style renders of every demo scene (finite, non-black), a 3-frame animation, bad
inputs (empty scene, no camera, too small a resolution, unsupported node, OpenGL
unavailable) giving clear errors, cancellation, and the scene's settings unchanged.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import bpy
import numpy as np
import pytest

import gi_preview
from gi_preview.blender import engine as engine_mod
from gi_preview.blender.demo_scenes import DEMO_SCENES, build_demo, make_principled
from gi_preview.compare import imageio
from gi_preview.render import session

REPO = Path(__file__).resolve().parent.parent


def render_to_array(scene, tmp_path, name="f12", after_render=None) -> np.ndarray:
    """F12 through bpy.ops.render.render, saved as a float EXR and read back."""
    bpy.ops.render.render(scene=scene.name)
    if after_render is not None:
        after_render()
    path = str(tmp_path / f"{name}.exr")
    s = scene.render.image_settings
    s.media_type = "IMAGE"
    s.file_format = "OPEN_EXR"
    s.color_depth = "32"
    bpy.data.images["Render Result"].save_render(path, scene=scene)
    return imageio.read_exr(path)


def settings_snapshot(scene) -> dict:
    snap = {}
    for owner, prefix in ((scene.render, "render"), (scene.gi_preview, "gi_preview"),
                          (scene.view_settings, "view"), (scene.display_settings, "display"),
                          (scene.render.image_settings, "image")):
        for p in owner.bl_rna.properties:
            if p.identifier in ("rna_type",) or p.type in ("POINTER", "COLLECTION"):
                continue
            v = getattr(owner, p.identifier)
            snap[f"{prefix}.{p.identifier}"] = tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v
    snap["frame"] = scene.frame_current
    snap["camera"] = scene.camera.name if scene.camera else None
    snap["objects"] = sorted((o.name, tuple(round(x, 6) for x in o.matrix_world.col[3])) for o in scene.objects)
    return snap


@pytest.mark.parametrize("demo", [d[0] for d in DEMO_SCENES])
def test_f12_every_demo_scene(demo, tmp_path):
    sc = build_demo(demo, resolution=64)
    try:
        assert sc.render.engine == "GI_PREVIEW"
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 4
        before = settings_snapshot(sc)
        snaps = []
        img = render_to_array(sc, tmp_path, after_render=lambda: snaps.append(settings_snapshot(sc)))
        assert img.shape == (64, 64, 4)
        assert np.isfinite(img).all()
        lum = img[..., :3].mean(axis=2)
        assert lum.mean() > 1e-3, f"{demo}: black image"
        assert (lum > 1e-3).mean() > 0.02, f"{demo}: almost all black"
        info = engine_mod.last_render
        assert info["scene"] == sc.name and info["samples"] == 4
        assert {"Combined", "Depth", "Normal", "DiffCol", "Emit", "GI_Direct"} <= set(info["passes"])
        after = snaps[0]
        changed = {k: (before[k], after[k]) for k in before if before[k] != after.get(k)}
        assert not changed, f"render changed scene settings: {changed}"
    finally:
        bpy.data.scenes.remove(sc)


def test_skipped_passes_reported(tmp_path):
    """A scene whose only light casts no shadow: the shadow pass is skipped, with its reason."""
    sc = _new_scene("noshadow")
    _add_plane(sc)
    light = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    light.data.use_shadow = False
    sc.collection.objects.link(light)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 1
        render_to_array(sc, tmp_path)
        skipped = {s["pass"]: s["reason"] for s in engine_mod.last_render["skipped_passes"]}
        assert skipped == {"shadows": "world is black; no light casts shadows"}
    finally:
        bpy.data.scenes.remove(sc)


def test_animation_three_frames(tmp_path):
    sc = build_demo("glossy_spheres", resolution=48)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 2
        mover = next(o for o in sc.objects if o.type == "MESH" and "sphere" in o.name.lower())
        z0 = mover.location.z
        for f, dz in ((1, 0.0), (3, 1.0)):
            mover.location.z = z0 + dz
            mover.keyframe_insert("location", frame=f)
        sc.frame_start, sc.frame_end = 1, 3
        sc.render.filepath = str(tmp_path / "anim_")
        s = sc.render.image_settings
        s.media_type = "IMAGE"
        s.file_format = "OPEN_EXR"
        s.color_depth = "32"
        frame_before = sc.frame_current
        bpy.ops.render.render(animation=True, scene=sc.name)
        files = sorted(tmp_path.glob("anim_*.exr"))
        assert len(files) == 3, files
        imgs = [imageio.read_exr(str(f)) for f in files]
        for im in imgs:
            assert np.isfinite(im).all() and im[..., :3].mean() > 1e-3
        # the sphere moves: consecutive frames differ
        assert np.abs(imgs[0] - imgs[1]).mean() > 1e-4 and np.abs(imgs[1] - imgs[2]).mean() > 1e-4
        assert sc.frame_current == frame_before
    finally:
        bpy.data.scenes.remove(sc)


def test_animation_warms_up_only_its_first_frame(tmp_path):
    """A technique with converging state (DDGI's probes) warms up on the animation's first
    frame (a camera cut) and carries its state into the next frames instead of restarting."""
    sc = build_demo("cornell", resolution=24)
    seen = []

    def record(scene, *_):
        seen.append(dict(engine_mod.last_render))

    try:
        sc.gi_preview.technique = "DDGI"
        sc.gi_preview.quality = 0
        sc.gi_preview.samples = 1
        sc.frame_start, sc.frame_end = 1, 3
        sc.render.filepath = str(tmp_path / "warm_")
        bpy.app.handlers.render_post.append(record)
        bpy.ops.render.render(animation=True, scene=sc.name)
    finally:
        if record in bpy.app.handlers.render_post:
            bpy.app.handlers.render_post.remove(record)
        bpy.data.scenes.remove(sc)
    assert [r["frame"] for r in seen] == [1, 2, 3]
    assert seen[0]["warmup_frames"] > 0
    assert [r["warmup_frames"] for r in seen[1:]] == [0, 0]
    assert all(not any(p.startswith("probe") for p in r["history_resets"]) for r in seen[1:]), seen


def _new_scene(name, with_camera=True, res=32):
    sc = bpy.data.scenes.new(name)
    sc.render.engine = "GI_PREVIEW"
    sc.render.resolution_x = sc.render.resolution_y = res
    if with_camera:
        cam = bpy.data.objects.new(f"{name}_cam", bpy.data.cameras.new(f"{name}_cam"))
        cam.location = (0, -5, 1)
        cam.rotation_euler = (math.radians(85), 0, 0)
        sc.collection.objects.link(cam)
        sc.camera = cam
    return sc


def _add_plane(sc, mat=None):
    me = bpy.data.meshes.new("plane")
    me.from_pydata([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [], [(0, 1, 2, 3)])
    if mat:
        me.materials.append(mat)
    ob = bpy.data.objects.new("plane", me)
    sc.collection.objects.link(ob)
    return ob


def test_empty_scene_clear_error():
    sc = _new_scene("empty")
    try:
        with pytest.raises(RuntimeError, match="is empty: no visible mesh"):
            bpy.ops.render.render(scene=sc.name)
    finally:
        bpy.data.scenes.remove(sc)


def test_no_camera_clear_error():
    sc = _new_scene("nocam", with_camera=False)
    _add_plane(sc)
    try:
        with pytest.raises(RuntimeError, match="(?i)no camera"):
            bpy.ops.render.render(scene=sc.name)
    finally:
        bpy.data.scenes.remove(sc)


def test_too_small_resolution_clear_error():
    sc = _new_scene("tiny", res=64)
    _add_plane(sc)
    sc.render.resolution_percentage = 5  # 64 * 5% = 3 px
    try:
        with pytest.raises(RuntimeError, match="too small"):
            bpy.ops.render.render(scene=sc.name)
    finally:
        bpy.data.scenes.remove(sc)


def test_unsupported_node_warns_and_renders(tmp_path):
    sc = _new_scene("unsupported")
    mat = make_principled("noisy", (0.2, 0.5, 0.8))
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(noise.outputs["Fac"], nt.nodes["Principled BSDF"].inputs["Roughness"])
    _add_plane(sc, mat)
    light = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sc.collection.objects.link(light)
    try:
        img = render_to_array(sc, tmp_path)
        assert np.isfinite(img).all() and img[..., :3].mean() > 1e-3
        warnings = " ".join(engine_mod.last_render["warnings"])
        assert "noisy" in warnings and "Noise Texture" in warnings
    finally:
        bpy.data.scenes.remove(sc)


def test_opengl_unavailable_clear_error(tmp_path):
    """With OpenGL 4.6 demanded (llvmpipe has 4.5; a GPU driver may have it, then skip)."""
    code = textwrap.dedent(f"""
        import os, sys
        os.environ["GI_PREVIEW_GL_REQUIRE"] = "490"
        sys.path.insert(0, {str(Path(gi_preview.__file__).parent.parent)!r})
        import bpy, gi_preview
        gi_preview.register()
        from gi_preview.blender.demo_scenes import build_demo
        sc = build_demo("cornell", resolution=16)
        try:
            bpy.ops.render.render(scene=sc.name)
            print("NO ERROR")
        except RuntimeError as exc:
            print("ERROR:", exc)
        print("ALIVE")
    """)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    text = out.stdout + out.stderr
    assert "ALIVE" in text, text[-2000:]
    assert "ERROR: Error: GI Preview needs OpenGL 4.9" in text, text[-2000:]
    assert "libegl1" in text


@pytest.mark.serial  # a wall-time bound: not beside another test process
def test_cancel_within_a_second():
    """Cancelling stops the accumulation between frames: far fewer frames than asked."""
    sc = build_demo("many_lights", resolution=64)
    try:
        from gi_preview.blender.export import export_scene

        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        data = export_scene(dg)
        session.render(data, "DIRECT", 1, 1)  # warm up (shader compile)
        flag = {"stop_at": None}

        def cancel():
            if flag["stop_at"] is None:
                flag["stop_at"] = time.perf_counter()
            return True

        t0 = time.perf_counter()
        res = session.render(data, "DIRECT", 1, 100000, cancel=cancel)
        elapsed = time.perf_counter() - t0
        assert res.cancelled
        assert res.samples < 100000
        assert np.isfinite(res.image).all()
        print(f"cancelled after {res.samples} frames, {elapsed:.2f} s")
        assert elapsed < 5.0  # the cancel flag is honoured at the next frame boundary
    finally:
        bpy.data.scenes.remove(sc)


def test_cancel_event_from_another_thread():
    sc = build_demo("cornell", resolution=64)
    try:
        from gi_preview.blender.export import export_scene

        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        data = export_scene(dg)
        ev = threading.Event()
        threading.Timer(0.3, ev.set).start()
        res = session.render(data, "DIRECT", 1, 100000, cancel=ev)
        assert res.cancelled and 0 < res.samples < 100000
    finally:
        bpy.data.scenes.remove(sc)


def test_blender_panels_show_for_the_engine():
    """Dimensions, output, colour management, light, material, world, camera panels."""
    from gi_preview.blender import ui

    for name in ("RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_frame_range", "RENDER_PT_color_management",
                 "DATA_PT_EEVEE_light", "DATA_PT_spot", "EEVEE_MATERIAL_PT_surface", "EEVEE_WORLD_PT_surface",
                 "DATA_PT_lens", "DATA_PT_camera", "VIEWLAYER_PT_layer_passes"):
        assert "GI_PREVIEW" in getattr(bpy.types, name).COMPAT_ENGINES, name
    for name in ui.EXTRA_PANELS:
        assert hasattr(bpy.types, name), f"{name} does not exist in this Blender"
    assert "GI_PREVIEW" in ui.GIPREVIEW_RENDER_PT_technique.COMPAT_ENGINES


def test_settings_contract():
    """scene.gi_preview: every registered technique id plus AUTO, samples, quality."""
    sc = bpy.data.scenes.new("contract")
    try:
        s = sc.gi_preview
        ids = {i.identifier for i in s.bl_rna.properties["technique"].enum_items}
        assert {"AUTO", "DIRECT", "PT"} <= ids
        s.technique = "DIRECT"
        s.samples = 7
        s.quality = 3
        assert (s.technique, s.samples, s.quality) == ("DIRECT", 7, 3)
        with pytest.raises(TypeError):
            s.technique = "NOT_A_TECHNIQUE"
    finally:
        bpy.data.scenes.remove(sc)


def test_saved_enum_values_stay_stable():
    """A .blend stores an enum as its item's integer value: the values must not depend on the
    menu's order, or registering a new technique (or filter) would change what saved files
    read. Files from before the Technique Default filter stored NONE/ATROUS/SVGF as 0/1/2."""
    from gi_preview.blender.properties import enum_value

    sc = bpy.data.scenes.new("enum_values")
    try:
        s = sc.gi_preview
        den = {i.identifier: i.value for i in s.bl_rna.properties["denoiser"].enum_items}
        assert {k: den[k] for k in ("NONE", "ATROUS", "SVGF")} == {"NONE": 0, "ATROUS": 1, "SVGF": 2}, den
        assert s.denoiser == "AUTO" and len(set(den.values())) == len(den)
        tech = {i.identifier: i.value for i in s.bl_rna.properties["technique"].enum_items}
        assert all(v == enum_value(k) for k, v in tech.items()), tech
        assert len(set(tech.values())) == len(tech), "two technique ids share a stored value"
        s.denoiser = "SVGF"
        s.technique = "PT"
        assert (s["denoiser"], s["technique"]) == (2, enum_value("PT"))
        # a value no item has (a file saved with positional numbers) renders with AUTO, not an error
        s["technique"] = 5
        assert engine_mod._settings(sc)[0] == "AUTO"
    finally:
        bpy.data.scenes.remove(sc)


def test_mesh_too_large_for_the_gpu_clear_error(monkeypatch):
    """A scene whose vertex data exceeds what GI Preview uploads gets a clear error naming
    the size, and nothing crashes (the limit is lowered here instead of building 2 GiB)."""
    from gi_preview.render import gpu_scene

    monkeypatch.setattr(gpu_scene, "MAX_VERTEX_BYTES", 1024)
    sc = build_demo("cornell", resolution=32)
    try:
        sc.gi_preview.technique = "DIRECT"
        with pytest.raises(RuntimeError, match="GiB of vertex data.*reduce the triangle count"):
            bpy.ops.render.render(scene=sc.name)
    finally:
        bpy.data.scenes.remove(sc)
    monkeypatch.undo()
    # the renderer is still usable afterwards
    sc = build_demo("cornell", resolution=32)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 1
        bpy.ops.render.render(scene=sc.name)
        assert engine_mod.last_render["scene"] == sc.name
    finally:
        bpy.data.scenes.remove(sc)


def test_spot_light_uses_one_perspective_view():
    from gi_preview.render.passes import shadows

    sc = build_demo("cornell", resolution=32)
    try:
        for ob in list(sc.objects):
            if ob.type == "LIGHT":
                bpy.data.objects.remove(ob)
        spot = bpy.data.objects.new("spot", bpy.data.lights.new("spot", "SPOT"))
        spot.data.spot_size = math.radians(60)
        spot.data.energy = 200
        spot.location = (0, 0, 1.9)
        sc.collection.objects.link(spot)
        from gi_preview.blender.export import export_scene

        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        data = export_scene(dg)
        res = session.render(data, "DIRECT", 1, 1)
        assert np.isfinite(res.image).all() and res.image[..., :3].mean() > 1e-3
        sess = session._sessions["final"]
        (_, graph), = [g for k, g in sess.graphs.items() if k[:2] == ("DIRECT", 1)]
        views = graph.find("shadows")._last_views
        spot_idx = [i for i, L in enumerate(data.lights) if L.name == "spot"][0]
        assert sum(1 for v in views if v[0] == spot_idx) == 1
    finally:
        bpy.data.scenes.remove(sc)


def test_shadow_tiles_keep_still_views(monkeypatch):
    """A light without size keeps its shadow tiles across frames while the area light's moving
    origins are redrawn; the image is the same as when every tile is redrawn every frame, and
    cube faces behind the one-sided area light are never drawn."""
    from gi_preview.blender.export import export_scene
    from gi_preview.render.passes import shadows

    sc = build_demo("cornell", resolution=32)
    try:
        pt = bpy.data.objects.new("point", bpy.data.lights.new("point", "POINT"))
        pt.data.energy = 20
        pt.data.shadow_soft_size = 0.0
        pt.location = (0.4, -0.3, 1.2)
        sc.collection.objects.link(pt)
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            data = export_scene(bpy.context.evaluated_depsgraph_get())
        point = [i for i, L in enumerate(data.lights) if L.name == "point"][0]
        area = [i for i, L in enumerate(data.lights) if L.type.name == "AREA"]
        assert area, "the cornell box is lit by an area light"

        # the maps themselves: a 32-px image would otherwise leave the area light to rays
        session.set_pass_properties("final", {"shadows": {"ray_cost_texels": 0.0}}, "DIRECT", 1)
        kept = session.render(data, "DIRECT", 1, 4)
        sess = session._sessions["final"]
        (_, graph), = [g for k, g in sess.graphs.items() if k[:2] == ("DIRECT", 1)]
        sp = graph.find("shadows")
        views = sp._last_views
        n_point = sum(1 for v in views if v[0] == point)
        n_area = sum(1 for v in views if v[0] in area)
        assert n_point == 6 and n_area >= 6
        # frame 4 drew only area-light faces, and not the ones that look behind the light
        assert 0 < sp.tiles_drawn < n_area

        execute = shadows.ShadowPass.execute

        def redraw_all(self, rc, frame):
            self._tile_views = {}
            return execute(self, rc, frame)

        monkeypatch.setattr(shadows.ShadowPass, "execute", redraw_all)
        redrawn = session.render(data, "DIRECT", 1, 4)
        assert np.isfinite(kept.image).all()
        np.testing.assert_allclose(kept.image[..., :3], redrawn.image[..., :3], rtol=1e-5, atol=1e-6)
    finally:
        session.release_session("final")
        bpy.data.scenes.remove(sc)


def test_lights_with_size_are_ray_traced_where_rays_cost_less():
    """The Cornell box's area light at 32 px: its moving shadow views would draw 2 x 6 faces of
    512^2 texels every frame, far more than 32^2 pixels x 4 rays x 8. So DIRECT traces its
    shadows: no view of it in the atlas and nothing drawn after the first frame of a still
    scene. The rays are unbiased: the tall box's sides, which see half the light below their
    horizon, were 35 % too dark when a ray to a point behind the horizon counted as shadow
    (image mean 0.976 of Cycles'). Measured (16 frames, Cycles 256 spp direct): relMSE rays
    0.0028, maps 0.0027; mean rays 1.000, maps 0.996. Asserted: the rays' mean within 1 %,
    their error within 1.3x the maps'."""
    from gi_preview.blender import reference
    from gi_preview.compare import metrics

    sc = build_demo("cornell", resolution=32)
    try:
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            data = bpy.context.evaluated_depsgraph_get()
            from gi_preview.blender.export import export_scene
            data = export_scene(data)
        area = [i for i, L in enumerate(data.lights) if L.type.name == "AREA"]
        ref = reference.render_cycles(sc, 256, "direct")[0][..., :3]
        err = {}
        for label, cost in (("rays", None), ("maps", 0.0)):
            key = f"shadow_{label}"
            if cost is not None:
                session.set_pass_properties(key, {"shadows": {"ray_cost_texels": cost}}, "DIRECT", 1)
            res = session.render(data, "DIRECT", 1, 16, session=key)
            (_, graph), = [g for k, g in session._sessions[key].graphs.items() if k[:2] == ("DIRECT", 1)]
            sp = graph.find("shadows")
            traced = sorted(sp.selection.traced)
            views_of_area = sum(1 for v in sp._last_views if v[0] in area)
            if label == "rays":
                assert traced == area and views_of_area == 0 and sp.tiles_drawn == 0
                assert not any("shadow maps (budget" in w for w in res.warnings), res.warnings
            else:
                assert traced == [] and views_of_area >= 6
            img = res.image[..., :3]
            assert np.isfinite(img).all() and img.min() >= 0.0
            err[label] = (metrics.relmse(img, ref), float(img.mean() / ref.mean()))
            session.release_session(key)
        print(f"cornell 32 px, DIRECT 16 frames vs Cycles direct: relMSE / mean ratio rays "
              f"{err['rays'][0]:.4f} / {err['rays'][1]:.3f}, maps {err['maps'][0]:.4f} / {err['maps'][1]:.3f}")
        assert abs(err["rays"][1] - 1.0) < 0.01
        assert err["rays"][0] < 1.3 * err["maps"][0]
    finally:
        bpy.data.scenes.remove(sc)


def test_shadow_maps_are_kept_where_a_reader_cannot_trace():
    """VXGI injects light into voxels through the shadow maps and traces no shadow rays: a
    light left to rays would light its voxels unshadowed, so its graph keeps every map
    whatever the image size; DIRECT's graph may trace them."""
    from gi_preview.render import techniques
    from gi_preview.render.framegraph import Effect

    for tech, can in (("VXGI", False), ("DIRECT", True)):
        g = techniques.get(tech)().build(1)
        g.plan(set(Effect))
        sp = g.find("shadows")
        assert sp.consumers, tech
        rays = [c.shadow_rays_per_pixel() if hasattr(c, "shadow_rays_per_pixel") else 0 for c in sp.consumers]
        assert (min(rays) > 0) == can, (tech, [c.name for c in sp.consumers], rays)
        if not can:
            assert sp._trace_rays(None) == 0


def fake_gpu_modules(monkeypatch):
    """Stand-ins for Blender's ``gpu`` and ``gpu_extras.presets`` (they draw nothing headless)
    that record texture uploads and draws."""
    import types

    rec = {"uploads": [], "draws": []}
    fake_gpu = types.ModuleType("gpu")
    fake_gpu.types = types.SimpleNamespace(
        Buffer=lambda fmt, n, data: np.asarray(data, np.float32).copy(),
        GPUTexture=lambda size, format, data: rec["uploads"].append((size, format, data)) or ("tex", size))
    fake_gpu.state = types.SimpleNamespace(blend_set=lambda mode: None)
    fake_extras = types.ModuleType("gpu_extras")
    fake_presets = types.ModuleType("gpu_extras.presets")
    fake_presets.draw_texture_2d = lambda tex, pos, w, h: rec["draws"].append((tex, w, h))
    monkeypatch.setitem(sys.modules, "gpu", fake_gpu)
    monkeypatch.setitem(sys.modules, "gpu_extras", fake_extras)
    monkeypatch.setitem(sys.modules, "gpu_extras.presets", fake_presets)
    return rec


def fake_view(sc, dg, width=80, height=60, view=None):
    """A (context, engine) pair standing in for one Rendered 3D view: region size, the
    RegionView3D's matrices, and an engine that records redraw requests."""
    import types

    cam = sc.camera
    view = cam.matrix_world.inverted() if view is None else view
    proj = cam.calc_matrix_camera(dg, x=width, y=height)
    rv3d = types.SimpleNamespace(view_matrix=view, window_matrix=proj, is_perspective=True)
    ctx = types.SimpleNamespace(region=types.SimpleNamespace(width=width, height=height), region_data=rv3d,
                                scene=sc)
    redraws = []
    eng = types.SimpleNamespace(_viewport=engine_mod.ViewportState(), update_stats=lambda a, b: None,
                                tag_redraw=lambda: redraws.append(time.perf_counter()),
                                bind_display_space_shader=lambda s: None,
                                unbind_display_space_shader=lambda: None)
    eng.redraws = redraws
    return ctx, eng


def draw_until_idle(eng, ctx, dg, max_draws=50):
    """Call view_draw as Blender would on each redraw: view_draw never blocks; between draws
    wait for the frame in flight (Blender redraws when the engine tags it)."""
    n = 0
    for n in range(1, max_draws + 1):
        t0 = time.perf_counter()
        engine_mod.view_draw(eng, ctx, dg)
        eng.draw_ms = max(getattr(eng, "draw_ms", 0.0), (time.perf_counter() - t0) * 1e3)
        fut = eng._viewport.future
        if fut is None:
            break
        fut.result(timeout=120)
    return n


def test_viewport_progressive_with_fake_gpu(monkeypatch):
    """view_update/view_draw logic without a window: Blender's gpu module is replaced by a
    recorder (it draws nothing headless). Checks the region camera, progressive accumulation
    up to viewport_samples (view_draw never waits: each finished frame tags a redraw, the
    next draw shows it and submits the next), restart on a view change, and the finite,
    clamped texture data handed to Blender."""
    from mathutils import Matrix

    rec = fake_gpu_modules(monkeypatch)
    sc = build_demo("cornell", resolution=32)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.viewport_samples = 3
        sc.gi_preview.viewport_scale = 0.5
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        ctx, eng = fake_view(sc, dg)
        engine_mod.view_update(eng, ctx, dg)
        assert eng._viewport.data is not None and eng._viewport.error is None
        draws = draw_until_idle(eng, ctx, dg)
        assert eng._viewport.count == 3
        # 1st draw submits (nothing to show yet), then one draw per finished frame
        assert draws == 4 and len(rec["uploads"]) == 3 and len(rec["draws"]) == 3
        assert len(eng.redraws) == 3  # every finished frame asked for a redraw
        for _ in range(3):  # converged: drawing again submits nothing and uploads nothing
            engine_mod.view_draw(eng, ctx, dg)
        assert eng._viewport.future is None and len(rec["uploads"]) == 3
        size, fmt, data = rec["uploads"][-1]
        assert size == (40, 30) and fmt == "RGBA16F"
        assert np.isfinite(data).all() and data.max() <= 65504 and data[0::4].mean() > 1e-3
        # the region camera is the view we gave
        rv3d = ctx.region_data
        c = engine_mod._region_camera(ctx)
        assert np.allclose(c.view, np.array(rv3d.view_matrix), atol=1e-5)
        # moving the view restarts the accumulation
        rv3d.view_matrix = Matrix.Translation((0.1, 0, 0)) @ rv3d.view_matrix
        engine_mod.view_draw(eng, ctx, dg)
        assert eng._viewport.count == 0 and eng._viewport.future is not None
        eng._viewport.future.result(timeout=60)
        engine_mod.view_draw(eng, ctx, dg)
        assert eng._viewport.count == 1
        print(f"longest view_draw call {eng.draw_ms:.2f} ms")
    finally:
        eng._viewport.free()
        bpy.data.scenes.remove(sc)


@pytest.mark.parametrize("demo,ssr_runs", [("cornell", False), ("glossy_spheres", True)])
def test_auto_runs_only_the_passes_the_scene_needs(demo, ssr_runs):
    """AUTO's DIRECT + SSDO + SSR candidate: passes in one graph; the planner skips SSR where
    the measured indirect glossy share is below the threshold, and says why with the number."""
    sc = build_demo(demo, resolution=32)
    try:
        from gi_preview.blender.export import export_scene

        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        res = session.render(export_scene(dg), "AUTO", 0, 2, auto={"candidate": "DIRECT+SSDO+SSR"})
        assert np.isfinite(res.image).all()
        skipped = {s.name: s.reason for s in res.skipped_passes}
        ssr = {n for n in res.pass_ms if n.startswith("ssr")}
        if ssr_runs:
            assert ssr and not any(n.startswith("ssr") for n in skipped)
            assert "indirect_specular" in res.effects
        else:
            assert not ssr
            assert {n for n in skipped if n.startswith("ssr")} and all(
                r.startswith("indirect glossy: ") and r.endswith(" % of the image -> skipped")
                for n, r in skipped.items() if n.startswith("ssr"))
        assert "ssdo" in res.pass_ms and "indirect_diffuse" in res.effects
    finally:
        bpy.data.scenes.remove(sc)


def test_switching_techniques_and_sizes_in_one_session():
    """Graphs share a session's resources: rendering A at one size, B at another, then A
    again at the second size must give images of the right size (a stale-size regression)."""
    sc = build_demo("cornell", resolution=32)
    try:
        from gi_preview.blender.export import export_scene

        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        small = export_scene(dg)
        large = export_scene(dg, width=48, height=40)
        for data, tech in ((small, "AUTO"), (large, "DIRECT"), (small, "AUTO"), (large, "SSAO"), (small, "DIRECT"),
                           (large, "PT"), (small, "PT")):
            res = session.render(data, tech, 0, 2, session="switching")
            assert res.image.shape == (data.height, data.width, 4), (tech, data.width)
            for name, aov in res.aovs.items():
                assert aov.shape[:2] == (data.height, data.width), (tech, name)
            assert np.isfinite(res.image).all() and res.image[..., :3].mean() > 1e-3
    finally:
        bpy.data.scenes.remove(sc)


def test_pass_properties_after_release_reach_the_fresh_session():
    """``release_session`` is queued at background priority; a ``set_pass_properties`` on the
    same key called after it must run after it (the session's own job order), so the values
    land on the fresh session and not on the one being freed (a bench once lost its settings
    this way: its next row rendered with the defaults)."""
    from gi_preview.render.gl import get_gl

    gl = get_gl()
    key = "props_after_release"
    session.set_pass_properties(key, {"direct_light": {"glossy_samples": 3}}, technique="DIRECT", quality=0)
    gate = threading.Event()
    blocker = gl.submit_job(lambda: gate.wait(30))  # holds the GL thread so both calls queue up
    try:
        released = session.release_session(key)
        setter = threading.Thread(target=session.set_pass_properties,
                                  args=(key, {"direct_light": {"glossy_samples": 5}}),
                                  kwargs={"technique": "DIRECT", "quality": 0})
        setter.start()
        time.sleep(0.3)  # the setter's job is queued behind the release
    finally:
        gate.set()
    setter.join(30)
    blocker.result(timeout=30)
    assert released.result(timeout=30) is True
    props = gl.call(lambda: [g.get_properties()["direct_light"]["glossy_samples"]
                             for _t, g in session._sessions[key].graphs.values()])
    assert props == [5], props
    session.release_session(key).result(timeout=30)
