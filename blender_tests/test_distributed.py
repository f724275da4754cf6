"""scripts/gi_compare.py over several scenes on a Dask cluster (scripts/_distributed.py).

One 2-worker LocalCluster (127.0.0.1, one thread per worker) serves the tests; scenes are
tiny (16 px, 8-spp references, Cycles' curve at 1 and 2 spp, DIRECT and SSDO at q0), so the
cost is mostly Dask and Blender starting in the worker processes."""
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

# its workers are processes of their own, timed out by heartbeats: not beside another test process
pytestmark = pytest.mark.serial

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "gi_compare.py"
SCENES = ["cornell", "glossy_spheres", "sunlit_room"]
ARGS = ["--techniques", "DIRECT,SSDO", "--quality", "0", "--res", "16", "--ref-spp", "8", "--frames", "1",
        "--baselines", "none", "--cycles-curve", "1,2", "--reference", "full"]


def _script():
    spec = importlib.util.spec_from_file_location("gi_compare_script", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["gi_compare_script"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def gc():
    pytest.importorskip("bpy")
    mod = _script()
    sys.path.insert(0, str(REPO / "scripts"))
    import _distributed
    mod.dist = _distributed
    return mod


@pytest.fixture(scope="module")
def client(gc):
    from distributed import Client
    cluster = gc.dist.start_cluster(2)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


def _opts(gc, scenes, out, cache, *extra):
    return gc.parse_args([*scenes, *ARGS, "--out", str(out), "--cache", str(cache), *extra], scene_optional=False)


@pytest.fixture(scope="module")
def sweeps(gc, client, tmp_path_factory):
    """The same three scenes serially (this process) and on the 2-worker cluster, each with its
    own empty reference cache, so both render their references."""
    tmp = tmp_path_factory.mktemp("dist")
    o = _opts(gc, SCENES, tmp / "serial", tmp / "cache_serial")
    serial = gc.run_scenes(o, gc.expand_scenes(o.scenes))
    o = _opts(gc, SCENES, tmp / "dask", tmp / "cache_dask", "--workers", "2")
    dask = gc.dist.run(o, gc.expand_scenes(o.scenes), client=client)
    return tmp, serial, dask


def _rows(results):
    return {(e["technique"], e["quality"], e["reference"]): e for e in results["entries"]}


def test_two_workers_give_the_serial_rows(gc, sweeps):
    tmp, serial, dask = sweeps
    gc.find_addon(False)
    from gi_preview.blender import reference
    from gi_preview.compare import imageio
    reference.ensure_oiio()
    assert serial["failed"] == [] and dask["failed"] == []
    assert dask["workers"] == 2
    # every task ran once: a reference and a curve per scene, a render per technique
    assert sorted(t["task"] for t in dask["tasks_run"]) == sorted(
        n for _ in SCENES for n in ("reference_full", "curve_full", "render_DIRECT_q0", "render_SSDO_q0"))
    assert len({t["worker"] for t in dask["tasks_run"]}) == 2  # both workers took work
    exact = []
    for name in SCENES:
        s = json.loads((tmp / "serial" / name / "results.json").read_text())
        d = json.loads((tmp / "dask" / name / "results.json").read_text())
        assert s["scene"] == d["scene"] and d["reference"]["cached"] is False
        a = imageio.read_exr(str(tmp / "serial" / name / "reference_full.exr"))
        b = imageio.read_exr(str(tmp / "dask" / name / "reference_full.exr"))
        if s["fingerprint"] == d["fingerprint"]:  # the same exported scene and seed: the same Cycles image
            assert np.array_equal(a, b), name
            exact.append(name)
        else:  # a demo built after others in a process can differ in its datablock names, so in Cycles' noise
            assert abs(a[..., :3].mean() - b[..., :3].mean()) < 0.02 * a[..., :3].mean(), name
        rs, rd = _rows(s), _rows(d)
        assert set(rs) == set(rd) == {("DIRECT", 0, "full"), ("SSDO", 0, "full")}
        for k in rs:
            assert set(rs[k]) == set(rd[k])
            for m in ("relmse", "flip", "ssim", "psnr"):
                assert rd[k][m] == pytest.approx(rs[k][m], rel=1e-4), (name, k, m)
            assert rd[k]["nonfinite_pixels"] == rs[k]["nonfinite_pixels"] == 0
            assert rd[k]["speedups"].keys() == rs[k]["speedups"].keys() == {"cycles"}
        assert [c["spp"] for c in d["cycles_curve"]] == [1, 2]
        assert (tmp / "dask" / name / "report.html").exists()
    assert "cornell" in exact  # built first in both processes: the identical scene, the identical reference
    # one process compiles a technique once: the serial sweep measures its cold setup on the first
    # scene and later scenes count that compile plus their own export
    first = _rows(json.loads((tmp / "serial" / SCENES[0] / "results.json").read_text()))
    for name in SCENES[1:]:
        for k, e in _rows(json.loads((tmp / "serial" / name / "results.json").read_text())).items():
            assert e["cost"]["cold_measured_on"] == SCENES[0] != name, (name, k)
            assert e["setup"]["renderer_ms"] == pytest.approx(first[k]["setup"]["renderer_ms"]), (name, k)
            assert e["setup_ms"] == pytest.approx(e["setup"]["export_ms"] + first[k]["setup"]["renderer_ms"])
    assert all(e["cost"]["cold_measured_on"] == SCENES[0] for e in first.values())
    index = (tmp / "dask" / "index.html").read_text()
    for name in SCENES:
        assert f"href='{name}/report.html'" in index
    assert "<svg" in index and "relMSE across scenes" in index


def test_rerun_skips_finished_work(gc, client, sweeps):
    from distributed import get_task_stream
    tmp, _, first = sweeps
    o = _opts(gc, SCENES, tmp / "dask", tmp / "cache_dask", "--workers", "2")
    with get_task_stream(client) as ts:
        again = gc.dist.run(o, gc.expand_scenes(o.scenes), client=client)
    assert again["failed"] == []
    assert again["tasks_run"] == [] and again["tasks_skipped"] == 4 * len(SCENES)
    assert ts.data == []  # nothing ran on the workers
    d = json.loads((tmp / "dask" / "cornell" / "results.json").read_text())
    assert _rows(d)[("DIRECT", 0, "full")]["relmse"] == first["scenes"][0]["rows"][0]["relmse"]
    # one render's saved result removed: only that task runs again
    parts = list((tmp / "dask" / "glossy_spheres" / "parts").glob("*/render_SSDO_q0.pkl"))
    assert len(parts) == 1
    parts[0].unlink()
    with get_task_stream(client) as ts:
        third = gc.dist.run(o, gc.expand_scenes(o.scenes), client=client)
    assert [(t["scene"], t["task"]) for t in third["tasks_run"]] == [("glossy_spheres", "render_SSDO_q0")]
    assert len(ts.data) == 1
    # --no-resume runs every task again; the references then come from the reference cache
    o = _opts(gc, SCENES[:1], tmp / "dask", tmp / "cache_dask", "--workers", "2", "--no-resume")
    fourth = gc.dist.run(o, gc.expand_scenes(o.scenes), client=client)
    assert len(fourth["tasks_run"]) == 4
    assert json.loads((tmp / "dask" / "cornell" / "results.json").read_text())["reference"]["cached"] is True


def test_a_dead_worker_and_a_failing_scene_do_not_stop_the_sweep(gc, client, tmp_path):
    """A worker process exits while it runs a render task: the scheduler runs the task again on
    a worker that lives (the nanny restarts the dead one). A missing .blend and a file that is
    no .blend fail their own scenes only, each with its error in the summary."""
    from distributed.diagnostics.plugin import WorkerPlugin
    marker = tmp_path / "died"

    class DieOnce(WorkerPlugin):
        name = "die-once"

        def transition(self, key, start, finish, **kw):
            k = key if isinstance(key, str) else str(key)
            if finish == "executing" and k.startswith("render_") and not os.path.exists(marker):
                with open(marker, "w") as f:
                    f.write(f"{os.getpid()} {k}")
                os._exit(1)

    bad = tmp_path / "broken.blend"
    bad.write_bytes(b"not a blend file")
    client.register_plugin(DieOnce())
    try:
        o = _opts(gc, ["cornell", str(tmp_path / "missing.blend"), str(bad), "sunlit_room"], tmp_path / "out",
                  tmp_path / "cache", "--workers", "2", "--retries", "1")
        summary = gc.dist.run(o, gc.expand_scenes(o.scenes), client=client)
    finally:
        client.unregister_worker_plugin("die-once")
    pid, key = marker.read_text().split()
    status = {s["label"]: s["error"] for s in summary["scenes"]}
    assert status["cornell"] is None and status["sunlit_room"] is None
    assert "no such file" in status["missing"]
    assert status["broken"] and status["broken"].startswith("reference_full:")
    assert sorted(summary["failed"]) == ["broken", "missing"]
    # the killed task finished on another (or the restarted) worker process
    killed = [t for t in summary["tasks_run"] if key.startswith(f"{t['task']}-{t['scene']}-")]
    assert len(killed) == 1 and not killed[0]["worker"].endswith(f":{pid}")
    for name in ("cornell", "sunlit_room"):
        res = json.loads((tmp_path / "out" / name / "results.json").read_text())
        assert set(_rows(res)) == {("DIRECT", 0, "full"), ("SSDO", 0, "full")}
    index = (tmp_path / "out" / "index.html").read_text()
    assert "failed: gi_compare: no such file" in index and "href='cornell/report.html'" in index


def test_scene_arguments(gc, tmp_path):
    """Folders give their .blend files; labels are made unique; unknown names and missing files
    are errors of their own scene; --workers and --scheduler exclude each other."""
    d = tmp_path / "blends"
    d.mkdir()
    for n in ("b.blend", "a.blend", "notes.txt"):
        (d / n).write_bytes(b"")
    got = gc.expand_scenes([str(d), "cornell", "cornell", "nosuchdemo", str(tmp_path / "x.blend")])
    assert [g["label"] for g in got] == ["a", "b", "cornell", "cornell_2", "nosuchdemo", "x"]
    assert [g["error"] is None for g in got] == [True, True, True, True, False, False]
    a = gc.parse_args(["cornell", "sunlit_room", "--workers", "3"], scene_optional=False)
    assert a.scenes == ["cornell", "sunlit_room"] and a.scene is None and a.distributed and a.workers == 3
    a = gc.parse_args(["cornell"], scene_optional=False)
    assert a.scene == "cornell" and not a.distributed
    with pytest.raises(SystemExit):
        gc.parse_args(["cornell", "--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"], scene_optional=False)


def test_plain_run_never_imports_dask(tmp_path):
    """Without --workers or --scheduler the script runs as before, in one process, without Dask."""
    import subprocess
    code = ("import runpy, sys; sys.argv = [sys.argv[0], 'cornell', '--techniques', 'DIRECT', '--quality', '0', "
            f"'--res', '8', '--ref-spp', '2', '--frames', '1', '--baselines', 'none', '--cycles-curve', '1', "
            f"'--out', {str(tmp_path / 'out')!r}, '--cache', {str(tmp_path / 'c')!r}]; "
            f"runpy.run_path({str(SCRIPT)!r}, run_name='__main__'); "
            "print('DASK', sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       env=dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "xdg")))
    assert p.returncode == 0, p.stderr[-2000:]
    assert "DASK []" in p.stdout, p.stdout[-500:]
    assert (tmp_path / "out" / "results.json").exists() and not (tmp_path / "out" / "index.html").exists()
