"""Temporal correctness of instances and a viewport that never blocks.

* Instanced motion vectors: two collection instances of one mesh (one object name) moving
  differently between two frames; every pixel's G-buffer motion against the motion computed
  on the CPU from the two transforms and the camera.
* Incremental viewport updates from real ``depsgraph.updates``: moving an object re-reads
  no mesh and the GPU scene reports a ``transforms`` edit, not ``geometry``; editing a mesh
  re-reads that mesh only.
* Two Rendered viewports converge independently (own sessions), and a closed view frees
  its session.
* A viewport frame is served while an F12 render of many samples runs, within about one
  frame of each (measured and printed), and the F12 render goes on.
"""
from __future__ import annotations

import math
import statistics
import threading
import time

import bpy
import numpy as np
import pytest
from mathutils import Matrix

from gi_preview.blender import engine as engine_mod
from gi_preview.blender.demo_scenes import build_demo, make_principled
from gi_preview.blender.export import export_scene
from gi_preview.render import session
from gi_preview.render.gl import PRIORITY_NORMAL, get_gl
from gi_preview.render.gpu_scene import GPUScene

from test_engine import draw_until_idle, fake_gpu_modules, fake_view


def _depsgraph(sc):
    with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
        return bpy.context.evaluated_depsgraph_get()


def _read_resources(key, names):
    """Read G-buffer resources of session ``key`` on the GL thread (after the graph's barriers)."""
    def read():
        sess = session._sessions[key]
        sess.rc.barrier_external(list(names))
        return {n: session.Session._read(sess.rc.resources[n]) for n in names}
    return get_gl().call(read)


def _instanced_scene(res=96):
    sc = bpy.data.scenes.new("instances")
    sc.render.engine = "GI_PREVIEW"
    sc.render.resolution_x, sc.render.resolution_y = res, res * 3 // 4
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.location = (0, -7, 1.5)
    cam.rotation_euler = (math.radians(80), 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.rotation_euler = (0.4, 0.3, 0)
    sc.collection.objects.link(sun)
    me = bpy.data.meshes.new("cube")
    v = [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    f = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    me.from_pydata(v, [], f)
    me.materials.append(make_principled("grey", (0.6, 0.6, 0.6)))
    src_coll = bpy.data.collections.new("src")
    src = bpy.data.objects.new("src_cube", me)
    src_coll.objects.link(src)  # not in the scene: only its instances render
    empties = []
    for i, x in enumerate((-1.5, 1.5)):
        e = bpy.data.objects.new(f"E{i}", None)
        e.instance_type = "COLLECTION"
        e.instance_collection = src_coll
        e.location = (x, 0, 0.5)
        sc.collection.objects.link(e)
        empties.append(e)
    return sc, empties


def _project(vp, pts, size):
    """World points -> pixel coordinates (as gbuffer.frag: (ndc * 0.5 + 0.5) * resolution)."""
    h = np.concatenate([pts, np.ones((len(pts), 1))], axis=1) @ vp.T
    ndc = h[:, :2] / h[:, 3:4]
    return (ndc * 0.5 + 0.5) * np.array(size, np.float64)


def test_instanced_motion_vectors():
    """Two instances of one object (same name, one mesh) move differently between two frames
    of one session (keep_history): the G-buffer's motion at every covered pixel equals the
    CPU motion from that instance's previous and current transforms and the camera."""
    sc, (e0, e1) = _instanced_scene()
    try:
        d1 = export_scene(_depsgraph(sc))
        ids1 = sorted(i.instance_id for i in d1.instances)
        assert {i.object_name for i in d1.instances} == {"src_cube"}  # one object name for both
        assert len(ids1) == 2 and ids1[0] != ids1[1] and ids1[0].startswith("E0/src_cube")
        key = "motion_test"
        session.render(d1, "DIRECT", 0, 1, keep_history=True, session=key)
        e0.location.x += 0.3  # to the right
        e1.location.z -= 0.25  # down, and turning about Z
        e1.rotation_euler.z = math.radians(20)
        d2 = export_scene(_depsgraph(sc))
        assert sorted(i.instance_id for i in d2.instances) == ids1  # stable across frames
        res = session.render(d2, "DIRECT", 0, 1, keep_history=True, session=key)
        rs = _read_resources(key, ["gbuffer.motion", "gbuffer.position"])
        motion, pos = rs["gbuffer.motion"][..., :2], rs["gbuffer.position"]
        H, W = pos.shape[:2]
        cam = d2.camera
        vp = cam.projection.astype(np.float64) @ cam.view.astype(np.float64)
        prev_m = {i.instance_id: i.matrix.astype(np.float64) for i in d1.instances}
        fg = pos[..., 3] >= 0
        P = pos[..., :3].astype(np.float64)
        errs, meds = {}, {}
        for inst in d2.instances:
            M = inst.matrix.astype(np.float64)
            Minv = np.linalg.inv(M)
            local = P @ Minv[:3, :3].T + Minv[:3, 3]
            mask = fg & (np.abs(local) <= 0.5 + 1e-3).all(axis=2)
            assert mask.sum() > 100, f"{inst.instance_id}: only {mask.sum()} pixels"
            pts = P[mask]
            prev_world = local[mask] @ prev_m[inst.instance_id][:3, :3].T + prev_m[inst.instance_id][:3, 3]
            expected = _project(vp, pts, (W, H)) - _project(vp, prev_world, (W, H))
            got = motion[mask].astype(np.float64)
            err = np.abs(got - expected)
            errs[inst.instance_id] = (float(err.max()), float(err.mean()))
            meds[inst.instance_id] = np.median(expected, axis=0)
            # the instance really moved on screen by more than a pixel
            assert np.linalg.norm(meds[inst.instance_id]) > 1.0, (inst.instance_id, meds[inst.instance_id])
            # half-float storage: ~0.01 px at these magnitudes
            assert err.max() < 0.05, (inst.instance_id, errs[inst.instance_id])
        a, b = list(meds)
        assert np.linalg.norm(meds[a] - meds[b]) > 1.0  # they moved differently
        print("instanced motion error (max, mean px):", errs, "median motion:",
              {k: v.round(2).tolist() for k, v in meds.items()})
        # a third frame with nothing moved: no motion anywhere
        session.render(d2, "DIRECT", 0, 1, keep_history=True, session=key)
        still = _read_resources(key, ["gbuffer.motion"])["gbuffer.motion"][..., :2]
        assert np.abs(still[fg]).max() < 1e-3
    finally:
        session.release_session("motion_test").result(timeout=30)
        bpy.data.scenes.remove(sc)


def test_viewport_updates_are_incremental(monkeypatch):
    """With real depsgraph.updates (Blender's update handler calls view_update as the
    viewport does): moving an object re-reads no mesh and the GPU scene reports only a
    'transforms' edit; editing one mesh re-reads that mesh only."""
    fake_gpu_modules(monkeypatch)
    sc = build_demo("cornell", resolution=32)
    ctx, eng = fake_view(sc, _depsgraph(sc))
    log = []

    def handler(scene, depsgraph):
        if scene == sc:
            engine_mod.view_update(eng, ctx, depsgraph)
            log.append(dict(eng._viewport.last_update))

    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        engine_mod.view_update(eng, ctx, _depsgraph(sc))
        first = eng._viewport.last_update
        n_meshes = len(eng._viewport.data.meshes)
        assert first["full"] and first["meshes_read"] == n_meshes
        draw_until_idle(eng, ctx, _depsgraph(sc), max_draws=2)
        box = next(o for o in sc.objects if o.name.split(".")[1:2] == ["tall_box"])
        meshes_before = list(eng._viewport.data.meshes)
        box.location.x += 0.1
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            bpy.context.view_layer.update()
        assert log and not log[-1]["full"]
        assert log[-1]["meshes_read"] == 0 and log[-1]["meshes_reused"] == n_meshes, log[-1]
        assert all(a is b for a, b in zip(eng._viewport.data.meshes, meshes_before))
        # the GPU scene sees a transform edit, not a geometry edit, and uploads no mesh
        before = eng._viewport.data
        box.location.x += 0.1
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            bpy.context.view_layer.update()
        after = eng._viewport.data
        assert after is not before and log[-1]["meshes_read"] == 0

        def gpu_changes():
            gs = GPUScene(get_gl().ctx)
            try:
                gs.update(before)
                vbos = dict(gs._vbos)
                return gs.update(after), vbos == gs._vbos
            finally:
                gs.release()

        changes, same_buffers = get_gl().call(gpu_changes)
        assert changes["transforms"] and not changes["geometry"], changes
        assert same_buffers
        # editing one mesh: that mesh only is read again
        box.data.vertices[0].co.z += 0.05
        box.data.update()
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            bpy.context.view_layer.update()
        assert log[-1]["meshes_read"] == 1 and log[-1]["meshes_reused"] == n_meshes - 1, log[-1]
        print("view_update after a move:", log[-3], "after a mesh edit:", log[-1])
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
        eng._viewport.free()
        bpy.data.scenes.remove(sc)


def test_two_viewports_converge_independently(monkeypatch):
    """Two Rendered 3D views with different views each reach viewport_samples (with one
    shared session they reset each other's accumulation forever), and closing one frees
    its session."""
    fake_gpu_modules(monkeypatch)
    sc = build_demo("cornell", resolution=32)
    views = []
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.viewport_samples = 4
        sc.gi_preview.viewport_scale = 0.5
        dg = _depsgraph(sc)
        v0 = sc.camera.matrix_world.inverted()
        views = [fake_view(sc, dg, 64, 48, v0), fake_view(sc, dg, 56, 40, Matrix.Translation((0.3, 0, 0)) @ v0)]
        for ctx, eng in views:
            engine_mod.view_update(eng, ctx, dg)
        for _ in range(12):  # interleaved redraws, as two views on screen get
            for ctx, eng in views:
                engine_mod.view_draw(eng, ctx, dg)
            for ctx, eng in views:
                if eng._viewport.future is not None:
                    eng._viewport.future.result(timeout=60)
        counts = [eng._viewport.count for _, eng in views]
        assert counts == [4, 4], counts
        keys = [eng._viewport.session_key for _, eng in views]
        assert keys[0] != keys[1] and set(keys) <= set(session.session_keys())
        views[0][1]._viewport.free()
        assert session.release_session(keys[0]).result(timeout=30) is False  # runs after free()'s release
        live = session.session_keys()
        assert keys[0] not in live and keys[1] in live
        print("two viewports converged:", counts)
    finally:
        for _, eng in views:
            eng._viewport.free()
        bpy.data.scenes.remove(sc)


@pytest.mark.serial  # a latency bound: not beside another test process
def test_viewport_frame_during_f12_render():
    """An F12 render of many samples runs on the GL thread; viewport frames submitted
    meanwhile come back within about one frame of each (they run before the F12 render's
    next frame), and the F12 render keeps going."""
    sc = build_demo("cornell", resolution=96)
    try:
        data = export_scene(_depsgraph(sc))
        # warm: compile shaders, upload the scene, measure one frame of each
        warm = session.render(data, "DIRECT", 1, 4, session="final")
        f12_frame_s = warm.total_ms / 4 / 1e3
        vp_times = []
        for _ in range(3):
            t0 = time.perf_counter()
            session.submit_render(data, "DIRECT", 1, 1, keep_history=True, continue_accumulation=True,
                                  session="vp_during_f12").result(timeout=60)
            vp_times.append(time.perf_counter() - t0)
        vp_frame_s = statistics.median(vp_times)
        stop = threading.Event()
        f12 = session.submit_render(data, "DIRECT", 1, 100000, cancel=stop, session="final",
                                    priority=PRIORITY_NORMAL)
        t_wait = time.perf_counter()
        while f12.progress == 0.0 and time.perf_counter() - t_wait < 60:
            time.sleep(0.01)
        latencies = []
        for _ in range(8):
            t0 = time.perf_counter()
            r = session.submit_render(data, "DIRECT", 1, 1, keep_history=True, continue_accumulation=True,
                                      session="vp_during_f12").result(timeout=60)
            latencies.append(time.perf_counter() - t0)
            assert np.isfinite(r.image).all()
            time.sleep(0.02)
        assert not f12.done(), "the F12 render should still be running"
        p_mid = f12.progress
        time.sleep(0.3)
        assert f12.progress > p_mid  # F12 frames go on between viewport frames
        stop.set()
        res = f12.result(timeout=60)
        assert res.cancelled and res.samples > 8
        bound = vp_frame_s + f12_frame_s
        print(f"viewport latency during F12: median {statistics.median(latencies) * 1e3:.0f} ms, "
              f"max {max(latencies) * 1e3:.0f} ms; one viewport frame {vp_frame_s * 1e3:.0f} ms, "
              f"one F12 frame {f12_frame_s * 1e3:.0f} ms; F12 accumulated {res.samples} frames")
        # at most the F12 frame in progress plus its own frame (generous margin: shared CPU)
        assert max(latencies) < 2.0 * bound + 0.25, (latencies, bound)
    finally:
        for k in ("vp_during_f12",):
            session.release_session(k)
        bpy.data.scenes.remove(sc)


def test_scene_edits_reset_history_as_declared():
    """Between two frames of one session: moving an object is a 'transforms' edit (not
    'geometry'); the shadow pass, which declares transforms/lights/geometry, is reset by a
    move and a light edit but not by a material edit."""
    sc = build_demo("cornell", resolution=32)
    key = "edits_test"
    try:
        def frame():
            return session.render(export_scene(_depsgraph(sc)), "DIRECT", 0, 1, keep_history=True, session=key)

        def last_events():
            def read():
                # the graphs dict is keyed (technique, quality, ...): take DIRECT q0's
                (_, graph), = [g for k, g in session._sessions[key].graphs.items() if k[:2] == ("DIRECT", 0)]
                return list(graph.history_log)
            return get_gl().call(read)

        frame()
        n0 = len(last_events())
        assert frame().history_resets == []  # nothing changed
        box = next(o for o in sc.objects if o.name.split(".")[1:2] == ["tall_box"])
        box.location.x += 0.05
        res = frame()
        log = last_events()[n0:]
        assert "shadows" in res.history_resets
        assert {tuple(e["events"]) for e in log} == {("transforms",)}, log
        mat = box.material_slots[0].material
        mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.6, 0.2, 1)
        res = frame()
        assert "shadows" not in res.history_resets  # a material edit does not touch shadow maps
        light = next(o for o in sc.objects if o.type == "LIGHT")
        light.data.energy *= 1.5
        res = frame()
        assert "shadows" in res.history_resets
        assert {tuple(e["events"]) for e in last_events()[-len(res.history_resets):]} == {("lights",)}
    finally:
        session.release_session(key).result(timeout=30)
        bpy.data.scenes.remove(sc)


def test_gl_thread_schedules_steps_by_priority_and_session():
    """Generator jobs run one step at a time: interactive jobs first, round robin within a
    priority, jobs of one key in submission order; an exception ends only its own job."""
    from gi_preview.render.gl import PRIORITY_INTERACTIVE

    gl = get_gl()
    log = []
    gate = threading.Event()

    def steps(name, n, fail=False):
        for i in range(n):
            log.append(f"{name}{i}")
            yield
        if fail:
            raise ValueError(f"{name} failed")
        return name

    blocker = gl.submit(gate.wait, 30)  # holds the thread while the jobs below queue up
    a = gl.submit_job(steps, ("A", 3), key="k")
    b = gl.submit_job(steps, ("B", 2), key="k")  # same key as A: waits for A to end
    c = gl.submit_job(steps, ("C", 2), priority=PRIORITY_INTERACTIVE)
    d = gl.submit_job(steps, ("D", 2), {"fail": True})
    gate.set()
    assert blocker.result(timeout=30) is True
    assert [f.result(timeout=30) for f in (a, b, c)] == ["A", "B", "C"]
    with pytest.raises(ValueError, match="D failed"):
        d.result(timeout=30)
    assert log == ["C0", "C1", "A0", "D0", "A1", "D1", "A2", "B0", "B1"], log
    assert gl.call(lambda: 42) == 42  # the thread lives on


def test_shutdown_during_a_long_render():
    """Unregistering (gl.shutdown) while an F12-style render runs: the render ends between two
    frames with a clear GLUnavailableError, sessions are freed, and a new GL thread renders."""
    from gi_preview.render import gl as glmod

    sc = build_demo("cornell", resolution=32)
    try:
        data = export_scene(_depsgraph(sc))
        fut = session.submit_render(data, "DIRECT", 0, 100000, session="final", priority=PRIORITY_NORMAL)
        t0 = time.perf_counter()
        while fut.progress == 0.0 and time.perf_counter() - t0 < 60:
            time.sleep(0.01)
        glmod.shutdown()
        with pytest.raises(glmod.GLUnavailableError, match="stopped"):
            fut.result(timeout=30)
        assert session._sessions == {}
        res = session.render(data, "DIRECT", 0, 1)  # a fresh GL thread
        assert np.isfinite(res.image).all() and res.image[..., :3].mean() > 1e-3
    finally:
        bpy.data.scenes.remove(sc)
