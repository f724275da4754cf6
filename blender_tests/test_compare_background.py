"""Compare with Cycles in the background: the reference in a child process, Esc within 1 s.

* ``reference_worker.save_copy`` leaves the user's file path and unsaved-changes flag alone.
* A reference rendered by the child process equals the one rendered in this process with
  the same fair settings and seed, and lands in the reference cache.
* ``CompareJob`` (the modal operator's work) runs to the end with GI Preview on the GL
  thread and Cycles in the child, storing the metrics and images; cancelled while Cycles
  renders, it kills the child within a second (measured, printed) and changes nothing in
  the scene.
"""
from __future__ import annotations

import os
import time
import types

import bpy
import numpy as np
import pytest

from gi_preview.blender import compare_ops, reference as R, reference_worker as W
from gi_preview.blender.demo_scenes import build_demo
from gi_preview.blender.export import export_scene


def _dg(sc):
    with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
        return bpy.context.evaluated_depsgraph_get()


def _fake_operator(ref_spp, use_cache=False):
    """The operator's properties and step builder, without Blender's operator machinery."""
    op = types.SimpleNamespace(reference="AUTO", ref_spp=ref_spp, use_cache=use_cache, _state=None)
    op._make_steps = lambda ctx: compare_ops.GIPREVIEW_OT_compare._make_steps(op, ctx)
    return op


def test_save_copy_keeps_file_path_and_dirty_state(tmp_path):
    sc = build_demo("cornell", resolution=16)
    try:
        path, dirty = bpy.data.filepath, bpy.data.is_dirty
        out = str(tmp_path / "copy.blend")
        W.save_copy(out)
        assert os.path.getsize(out) > 1000
        assert (bpy.data.filepath, bpy.data.is_dirty) == (path, dirty)
    finally:
        bpy.data.scenes.remove(sc)


def test_child_reference_equals_in_process(tmp_path):
    sc = build_demo("cornell", resolution=24)
    try:
        fp = export_scene(_dg(sc)).fingerprint()
        proc = W.launch(sc, "direct", 8, width=24, height=24, fingerprint=fp, cache_dir=str(tmp_path))
        t0 = time.perf_counter()
        ref = None
        while ref is None and time.perf_counter() - t0 < 180:
            ref = proc.poll()
            time.sleep(0.05)
        assert ref is not None, "the reference process did not finish"
        assert not os.path.exists(proc.tmpdir)
        img, _ = R.render_cycles(sc, 8, "direct", R.DEFAULT_SEED, width=24, height=24)
        assert ref.image.shape == img.shape == (24, 24, 4)
        assert np.isfinite(ref.image).all() and ref.image[..., :3].mean() > 1e-3
        diff = float(np.abs(ref.image - img).max())
        print(f"child vs in-process Cycles: max |diff| {diff:.2e}, child wall {(time.perf_counter() - t0):.1f} s")
        assert diff < 1e-4
        hit = W.cached_reference(sc, "direct", 8, width=24, height=24, fingerprint=fp, cache_dir=str(tmp_path))
        assert hit is not None and hit.cached and np.array_equal(hit.image, ref.image)
    finally:
        bpy.data.scenes.remove(sc)


def test_compare_job_runs_in_the_background():
    sc = build_demo("cornell", resolution=24)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 2
        ctx = types.SimpleNamespace(scene=sc, view_layer=sc.view_layers[0])
        job = compare_ops.CompareJob(_fake_operator(4), ctx)
        t0 = time.perf_counter()
        job.start()
        start_ms = (time.perf_counter() - t0) * 1e3
        assert job.ref_proc is not None and job.ref_proc.running
        polls = 0
        while not job.poll():
            polls += 1
            assert time.perf_counter() - t0 < 180
            time.sleep(0.05)
        job.finish()
        e = compare_ops.load_results(sc)["DIRECT"]
        assert e["ref_spp"] == 4 and np.isfinite(e["relmse"]) and not e["ref_cached"]
        for name in (compare_ops.IMG_RESULT, compare_ops.IMG_CYCLES, compare_ops.IMG_ERROR):
            assert bpy.data.images.get(name) is not None
        print(f"start() returned in {start_ms:.0f} ms; {polls} polls while rendering")
    finally:
        bpy.data.scenes.remove(sc)


def test_compare_cancel_within_a_second():
    """Esc while Cycles renders a reference of 100k samples: the child is gone within 1 s."""
    sc = build_demo("cornell", resolution=64)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 100000
        engine_before = sc.render.engine
        cycles_samples = sc.cycles.samples
        ctx = types.SimpleNamespace(scene=sc, view_layer=sc.view_layers[0])
        job = compare_ops.CompareJob(_fake_operator(100000), ctx)
        job.start()
        proc = job.ref_proc
        t0 = time.perf_counter()
        while proc.progress == 0.0 and time.perf_counter() - t0 < 120:  # Cycles is sampling
            assert not job.poll()
            time.sleep(0.05)
        assert proc.progress > 0.0 and proc.running, proc.lines[-5:]
        t_cancel = time.perf_counter()
        kill_ms = job.cancel()  # what the modal operator does on Esc
        assert proc.proc.poll() is not None  # the Cycles process is gone when cancel() returns
        job.future.exception(timeout=10)  # our render stops at its next frame
        total_s = time.perf_counter() - t_cancel
        print(f"cancel latency: Cycles process gone after {kill_ms:.0f} ms, GI Preview render stopped "
              f"after {total_s * 1e3:.0f} ms (Cycles was at {proc.progress * 100000:.0f} samples)")
        assert kill_ms < 1000.0 and total_s < 1.0
        assert not os.path.exists(proc.tmpdir)
        assert job.future.done()
        assert sc.render.engine == engine_before and sc.cycles.samples == cycles_samples
    finally:
        bpy.data.scenes.remove(sc)


def test_modal_operator_escape_within_a_second():
    """The operator's own modal(): timer events poll the job (progress shown), Esc returns
    CANCELLED with the Cycles process gone, within a second of the key press (measured)."""
    sc = build_demo("cornell", resolution=64)
    try:
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.samples = 100000
        reports, progress, status = [], [], []
        wm = types.SimpleNamespace(progress_update=progress.append, progress_end=lambda: None,
                                   event_timer_remove=lambda t: None)
        ctx = types.SimpleNamespace(scene=sc, view_layer=sc.view_layers[0], window_manager=wm,
                                    workspace=types.SimpleNamespace(status_text_set=status.append), screen=None)
        op = _fake_operator(100000)
        op._timer = object()
        op.report = lambda kind, msg: reports.append((kind, msg))
        op._finish = lambda c: compare_ops.GIPREVIEW_OT_compare._finish(op, c)
        op._job = compare_ops.CompareJob(op, ctx)
        op._job.start()
        modal = compare_ops.GIPREVIEW_OT_compare.modal
        timer, esc = types.SimpleNamespace(type="TIMER"), types.SimpleNamespace(type="ESC")
        t0 = time.perf_counter()
        while op._job.ref_proc.progress == 0.0 and time.perf_counter() - t0 < 120:
            assert modal(op, ctx, timer) == {"RUNNING_MODAL"}
            time.sleep(0.1)
        assert modal(op, ctx, timer) == {"RUNNING_MODAL"}
        assert progress and "Esc to cancel" in status[-1]
        assert modal(op, ctx, types.SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}
        t_esc = time.perf_counter()
        assert modal(op, ctx, esc) == {"CANCELLED"}
        esc_ms = (time.perf_counter() - t_esc) * 1e3
        assert op._job.ref_proc.proc.poll() is not None
        print(f"Esc -> operator cancelled, Cycles process gone: {esc_ms:.0f} ms")
        assert esc_ms < 1000.0
        assert reports[-1][0] == {"WARNING"} and "cancelled" in reports[-1][1]
        assert status[-1] is None  # status bar cleared
        op._job.future.exception(timeout=10)
    finally:
        bpy.data.scenes.remove(sc)
