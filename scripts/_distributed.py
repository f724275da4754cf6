"""scripts/gi_compare.py over several scenes on a Dask cluster (``--workers N`` or ``--scheduler ADDRESS``).

Imported only for those options, so a plain run never imports Dask. The work of each scene
is split into tasks:

* ``reference``: one Cycles reference per reference kind, through the reference cache
  (``--cache``: a shared folder when the workers run on several machines);
* ``curve``: Cycles' own error/time curve against that reference, and ``baseline``: each
  other baseline (Cycles + OpenImageDenoise, EEVEE) against the ``full`` reference. A curve
  is one task, not one per sample count, because its setup/per-sample fit and its untimed
  warm-up render need all its points timed in one process;
* ``render``: one technique at one quality level, measured against the references it needs.

The curves and renders depend on their scene's references, which reach them as images (the
task results), so a reference is rendered once per scene whatever the number of workers.
Every finished task is saved under ``<out>/<scene>/parts/<settings>/`` by the client; a rerun
with the same settings submits only the tasks whose part is missing (resume). When a scene's
tasks are all done, the client writes its results.json and report.html (the same rows as a
serial run of that scene), and at the end ``<out>/index.html`` and ``<out>/summary.json``.

A worker that dies mid-task has its task run again on another worker (the scheduler does
that up to ``distributed.scheduler.allowed-failures`` times, 3 by default); a task that
raises is retried ``--retries`` times; a scene whose task still fails is reported in the
summary with the error, and the other scenes go on.

The task functions travel by value (cloudpickle), so a worker needs only this checkout's
path (shared storage) and the project's venv, not this file on its ``sys.path``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import sys
import time
import uuid

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "gi_compare.py")


# ---------------------------------------------------------------- on the workers
def _import_bpy():
    """``import bpy`` in a worker. A worker process started by a client that had imported bpy
    inherits its ``sys.path``, which then holds Blender's own ``scripts/modules`` folders, whose
    inner ``bpy`` package would shadow the bpy module: they go until bpy puts them back."""
    if "bpy" in sys.modules:
        return
    inner = [p for p in sys.path if "/bpy/" in p.replace(os.sep, "/") and "/scripts" in p.replace(os.sep, "/")]
    sys.path[:] = [p for p in sys.path if p not in inner]
    import bpy  # noqa: F401
    sys.path += [p for p in inner if p not in sys.path]


def _script(path: str):
    """gi_compare.py as a module, loaded once per worker process (it keeps the worker's scenes)."""
    _import_bpy()
    mod = sys.modules.get("gi_compare_script")
    if mod is None or getattr(mod, "__file__", None) != path:
        import importlib.util
        spec = importlib.util.spec_from_file_location("gi_compare_script", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["gi_compare_script"] = mod
        spec.loader.exec_module(mod)
    return mod


def _runner(job: dict):
    """The worker's ``_Run`` of the job's scene, its scene loaded once per worker process: demo
    scenes are kept side by side; opening a .blend replaces every scene, so it starts afresh."""
    mod = _script(job["script"])
    mod.log = lambda msg: None  # the client prints one line per finished task instead
    scenes = mod.__dict__.setdefault("_WORKER_SCENES", {})
    spec = job["spec"]
    r = scenes.get(spec)
    if r is None:
        if spec.lower().endswith(".blend"):
            scenes.clear()
        opts = argparse.Namespace(**job["opts"])
        opts.scene, opts.out = spec, job["out"]
        r = mod._Run(opts)
        r.load_scene(quiet=True)
        scenes[spec] = r
    return r


def _ref_fields(ref) -> dict:
    import dataclasses
    return {f.name: getattr(ref, f.name) for f in dataclasses.fields(ref)}


def _run_task(step: str, job: dict, *args):
    """One task: ``step`` of ``_Run`` on the job's scene. Returns {"value", "seconds", "worker"}."""
    import socket
    t0 = time.perf_counter()
    try:
        r = _runner(job)
        if step == "reference":
            value = {"meta": r.scene_meta(), "ref": _ref_fields(r.get_reference(args[0]))}
        else:
            refs = {k: r.reference.Reference(**d["value"]["ref"]) for k, d in args[-1].items()}
            if step == "curve":
                value = r.cycles_curve(args[0], refs[args[0]])
            elif step == "baseline":
                value = r.baseline(args[0], refs["full"], args[1]["value"]["setup_ms"] if args[1] else None)
            elif step == "render":
                value = r.render_row(args[0], args[1], refs)
                r.gl.get_gl().call(r.session.release_all)
            else:
                raise ValueError(f"unknown step {step!r}")
    except SystemExit as exc:  # the script's one-line errors, as an exception Dask reports
        raise RuntimeError(str(exc.code)) from None
    return {"value": value, "seconds": time.perf_counter() - t0, "worker": f"{socket.gethostname()}:{os.getpid()}"}


# ---------------------------------------------------------------- on the client
def settings_key(mod, opts, spec: str) -> str:
    """A hash of the options that change a scene's results: a part saved under others is not reused."""
    d = {k: getattr(opts, k, None) for k in mod._RESULT_OPTIONS}
    d["scene"] = spec
    return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


class Parts:
    """The finished tasks of one scene: ``<name>.pkl`` files, written atomically."""

    def __init__(self, directory: str):
        self.directory = directory
        os.makedirs(directory, exist_ok=True)

    def _path(self, name):
        return os.path.join(self.directory, name + ".pkl")

    def get(self, name):
        try:
            with open(self._path(name), "rb") as f:
                return pickle.load(f)
        except (OSError, EOFError, pickle.UnpicklingError):
            return None

    def put(self, name, result):
        tmp = self._path(name) + f".{os.getpid()}.tmp"
        with open(tmp, "wb") as f:
            pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, self._path(name))


def _dashboard_address():
    import importlib.util
    return "127.0.0.1:0" if importlib.util.find_spec("bokeh") is not None else None


def start_cluster(workers: int):
    """A LocalCluster of ``workers`` processes, one thread each, on the loopback interface."""
    from distributed import LocalCluster
    return LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, host="127.0.0.1",
                        dashboard_address=_dashboard_address())


def run(opts, scenes: list[dict], *, client=None, log=print) -> dict:
    """Compare every scene of ``scenes`` ([{"label", "spec", "error"}], see gi_compare.expand_scenes)
    on ``client`` (or a cluster made from ``opts.workers`` / ``opts.scheduler``). Returns the
    summary (also written to ``<out>/summary.json``)."""
    import cloudpickle
    from distributed import Client, as_completed

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    mod = _script(SCRIPT) if "gi_compare_script" not in sys.modules else sys.modules["gi_compare_script"]
    out = os.path.abspath(opts.out)
    os.makedirs(out, exist_ok=True)
    plan_run = mod._Run(opts)
    plan = plan_run.make_plan()
    kinds, primary = plan_run.kinds, plan_run.primary
    baseline_names = plan_run.baseline_names()

    cluster = None
    own_client = client is None
    if client is None:
        if getattr(opts, "scheduler", None):
            client = Client(opts.scheduler)
        else:
            cluster = start_cluster(opts.workers)
            client = Client(cluster)
    t_start = time.perf_counter()
    try:
        n_workers = len(client.scheduler_info(n_workers=-1).get("workers", {}))
    except TypeError:  # older distributed: no n_workers argument
        n_workers = len(client.scheduler_info().get("workers", {}))
    link = client.dashboard_link if (cluster is None or cluster.dashboard_link) else None
    log(f"Dask scheduler {client.scheduler.address}, {n_workers} worker(s); dashboard: "
        + (link or "off (install bokeh for Dask's dashboard)"))
    opts_d = {k: v for k, v in vars(opts).items() if k not in ("scenes",)}
    token = uuid.uuid4().hex[:6]
    retries = max(0, int(getattr(opts, "retries", 2)))
    state = {}  # label -> scene state
    futures = {}  # future -> (label, part name)
    done_now = []
    skipped = 0

    for sc in scenes:
        label = sc["label"]
        st = state[label] = {"label": label, "spec": sc["spec"], "error": sc.get("error"), "results": {},
                             "out": os.path.join(out, label), "tasks": []}
        if st["error"]:
            log(f"{label}: {st['error']}")
            continue
        parts = st["parts"] = Parts(os.path.join(st["out"], "parts",
                                                 "fresh" if getattr(opts, "no_resume", False) else
                                                 settings_key(mod, opts, sc["spec"])))
        job = {"script": SCRIPT, "opts": opts_d, "spec": sc["spec"], "out": st["out"]}

        def task(name, step, *args, _st=st, _parts=parts, _job=job, _label=label):
            """The saved result of ``name``, or a future for it."""
            have = None if getattr(opts, "no_resume", False) else _parts.get(name)
            if have is not None:
                nonlocal skipped
                skipped += 1
                _st["results"][name] = have
                return have
            f = client.submit(_run_task, step, _job, *args, key=f"{name}-{_label}-{token}", retries=retries,
                              pure=False)
            futures[f] = (_label, name)
            return f

        refs = {k: task(f"reference_{k}", "reference", k) for k in kinds}
        curves = {k: task(f"curve_{k}", "curve", k, {k: refs[k]}) for k in kinds}
        for b in baseline_names:
            task(f"baseline_{b}", "baseline", b, curves[primary] if b == "cycles_denoised" else None,
                 {"full": refs["full"]})
        for tech, q in plan:
            task(f"render_{tech}_q{q}", "render", tech, q, {k: refs[k] for k in plan_run.kinds_for(tech)})

    n_total = len(futures)
    log(f"{n_total} task(s) submitted, {skipped} already done (saved in <scene>/parts/)")
    n_done = 0
    for f in as_completed(list(futures)):
        label, name = futures.pop(f)
        st = state[label]
        n_done += 1
        if f.status not in ("finished", "error", "cancelled"):
            # a result held by a worker that died is "lost": the scheduler computes it again
            try:
                f.result()
            except Exception:  # noqa: BLE001 - reported below from the future's status
                pass
        if f.status == "finished":
            res = f.result()
            st["parts"].put(name, res)
            st["results"][name] = res
            done_now.append({"scene": label, "task": name, "seconds": res["seconds"], "worker": res["worker"]})
            log(f"[{n_done}/{n_total}] {label}: {name} done in {res['seconds']:.1f} s on {res['worker']}")
        else:
            try:
                exc = f.exception()
                err = f"{type(exc).__name__}: {exc}" if exc is not None else f"task {f.status}"
            except Exception as e:  # noqa: BLE001 - a cancelled future has no exception to fetch
                err = f"{type(e).__name__}: {e}"
            if not st["error"] or (name.startswith("reference_") and not st["error"].startswith("reference_")):
                st["error"] = f"{name}: {err}"  # the reference's error, not its dependents' copies
            log(f"[{n_done}/{n_total}] {label}: {name} FAILED: {err}")
        f.release()

    # ---- per scene: results.json and report.html, as the serial run writes them
    rows = []
    for sc in scenes:
        st = state[sc["label"]]
        row = {"label": st["label"], "scene": st["spec"], "error": st["error"], "report": None, "results": None}
        if not st["error"]:
            try:
                row.update(_finish(mod, opts, st, plan, kinds, baseline_names))
            except Exception as exc:  # noqa: BLE001 - one scene's failure is reported, not fatal
                row["error"] = f"results: {type(exc).__name__}: {exc}"
        rows.append(row)
    wall = time.perf_counter() - t_start
    summary = mod.write_index(opts, rows, wall_s=wall, workers=n_workers, tasks_run=done_now, tasks_skipped=skipped,
                              log=log)
    if own_client:
        client.close()
        if cluster is not None:
            cluster.close()
    return summary


def _finish(mod, opts, st, plan, kinds, baseline_names) -> dict:
    res = st["results"]
    o = argparse.Namespace(**vars(opts))
    o.scene, o.out = st["spec"], st["out"]
    r = mod._Run(o)
    r.make_plan(quiet=True)
    r.reference.ensure_oiio()
    refs = {k: r.reference.Reference(**res[f"reference_{k}"]["value"]["ref"]) for k in kinds}
    meta = res[f"reference_{kinds[0]}"]["value"]["meta"]
    curves = {k: res[f"curve_{k}"]["value"] for k in kinds}
    baselines = {"cycles": curves[r.primary]}
    baselines.update({b: res[f"baseline_{b}"]["value"] for b in baseline_names})
    r.set_curves(curves, baselines)
    entries, images = [], {}
    for tech, q in plan:
        e, im = res[f"render_{tech}_q{q}"]["value"]
        entries += e
        images.update(im)
    results = r.finish(meta, refs, entries, images)
    return {"report": os.path.join(st["label"], "report.html"), "results": os.path.join(st["label"], "results.json"),
            "summary": results}
