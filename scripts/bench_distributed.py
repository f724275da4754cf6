#!/usr/bin/env python3
"""Wall time of scripts/gi_compare.py over the six demo scenes: serially in one process, on a
1-worker and on a 2-worker Dask LocalCluster (each run in a fresh process with an empty
reference cache), and the scaling to expect on N machines, from the task durations of the
1-worker run and the dependencies (a scene's curves and renders wait for its reference).

    python scripts/bench_distributed.py --out docs/results/distributed   (writes .md and .json)
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = ["cornell", "glossy_spheres", "sunlit_room", "emissive_panel", "many_lights", "courtyard_loft"]
ARGS = ["--techniques", "DIRECT,SSDO,SVGF", "--quality", "0", "--res", "32", "--ref-spp", "64", "--frames", "2",
        "--baselines", "none", "--cycles-curve", "1,2,4,8,16", "--reference", "full"]


def timed_run(extra, tmp, name):
    out, cache = os.path.join(tmp, name), os.path.join(tmp, name + "_cache")
    cmd = [sys.executable, os.path.join(HERE, "gi_compare.py"), *SCENES, *ARGS, "--out", out, "--cache", cache, *extra]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{name} failed:\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}")
    with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
        return wall, json.load(f)


def simulate(tasks: list[dict], n: int) -> float:
    """Makespan of a greedy list schedule on n workers: references first (longest first), each
    other task as soon as its scene's reference is done and a worker is free."""
    free = [0.0] * n
    ref_done = {}
    for t in sorted((t for t in tasks if t["task"].startswith("reference_")), key=lambda t: -t["seconds"]):
        i = min(range(n), key=lambda k: free[k])
        free[i] += t["seconds"]
        ref_done[t["scene"]] = free[i]
    rest = sorted((t for t in tasks if not t["task"].startswith("reference_")),
                  key=lambda t: (ref_done[t["scene"]], -t["seconds"]))
    for t in rest:
        i = min(range(n), key=lambda k: free[k])
        free[i] = max(free[i], ref_done[t["scene"]]) + t["seconds"]
    return max(free)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="docs/results/distributed")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_distributed_")
    try:
        serial_s, _ = timed_run([], tmp, "serial")
        one_s, one = timed_run(["--workers", "1"], tmp, "workers1")
        two_s, two = timed_run(["--workers", "2"], tmp, "workers2")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    tasks = one["tasks_run"]
    total = sum(t["seconds"] for t in tasks)
    refs = {t["scene"]: t["seconds"] for t in tasks if t["task"].startswith("reference_")}
    crit = max(refs[s] + max(t["seconds"] for t in tasks if t["scene"] == s and not t["task"].startswith("reference_"))
               for s in refs)
    scaling = [{"machines": n, "predicted_s": simulate(tasks, n), "bound_s": max(crit, total / n),
                "speedup": total / simulate(tasks, n)} for n in (1, 2, 4, 8, 16)]
    res = {"scenes": SCENES, "args": ARGS, "wall_s": {"serial": serial_s, "workers_1": one_s, "workers_2": two_s},
           "ratio_serial_over_2_workers": serial_s / two_s, "ratio_serial_over_1_worker": serial_s / one_s,
           "tasks": tasks, "task_total_s": total, "reference_s": refs, "critical_path_s": crit, "scaling": scaling,
           "cores": os.cpu_count()}
    with open(a.out + ".json", "w", encoding="utf-8") as f:
        json.dump(res, f, indent=1)
    kinds = {}
    for t in tasks:
        k = t["task"].split("_")[0]
        kinds.setdefault(k, []).append(t["seconds"])
    lines = [
        "# Batch comparison on Dask: serial against 2 workers",
        "",
        f"`scripts/gi_compare.py` over the six demo scenes ({', '.join(SCENES)}) with "
        f"`{' '.join(ARGS)}`, each run in a fresh process with an empty reference cache, on this "
        f"machine ({os.cpu_count()} CPU cores, Mesa llvmpipe). Made by `scripts/bench_distributed.py` "
        "([numbers](distributed.json)).",
        "",
        "| run | wall (s) | serial / run |",
        "|---|---:|---:|",
        f"| one process (no Dask) | {serial_s:.1f} | 1.00 |",
        f"| `--workers 1` | {one_s:.1f} | {serial_s / one_s:.2f} |",
        f"| `--workers 2` | {two_s:.1f} | {serial_s / two_s:.2f} |",
        "",
        f"Two workers against one: {one_s / two_s:.2f}x. On {os.cpu_count()} cores two workers gain little: "
        "Cycles already renders on every core, and llvmpipe rasterises on several threads, so two "
        "workers mostly share the same cores. The wall times include starting the cluster and Blender "
        "in each worker. The one-process run is slower than the 1-worker run, which also runs one "
        "task at a time; that gap is not parallelism and is not explained by these measurements.",
        "",
        "## Expected scaling on N machines",
        "",
        f"From the {len(tasks)} task durations of the 1-worker run (sum {total:.1f} s; per task kind, "
        "the mean: " + ", ".join(f"{k} {sum(v) / len(v):.2f} s" for k, v in sorted(kinds.items())) + "). "
        f"A scene's curve and renders wait for its reference: the critical path is the longest "
        f"reference plus its longest dependent task, {crit:.2f} s. 'predicted' is a greedy schedule "
        "of the measured tasks (references first) on N one-worker machines; 'bound' is "
        "max(critical path, total / N). Start-up and transfer times are left out.",
        "",
        "| machines | predicted (s) | bound (s) | speed-up |",
        "|---:|---:|---:|---:|",
    ] + [f"| {s['machines']} | {s['predicted_s']:.2f} | {s['bound_s']:.2f} | {s['speedup']:.2f} |" for s in scaling] + [
        "",
        "At this size the tasks last well under a second and the sweep stops scaling once every "
        "machine holds one scene's reference: more scenes, larger images or more reference samples "
        "lengthen the references and the renders alike, and the table scales with them.",
        ""]
    with open(a.out + ".md", "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
