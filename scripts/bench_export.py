"""Benchmark of the scene exporter (addon/blender/export.py): bpy depsgraph -> SceneData.

Run with the bpy module:  python scripts/bench_export.py [--quick] [--out DIR]

Builds, in fresh scenes, grid meshes of about 1e5, 1e6 and 4e6 triangles (with a UV map and
two materials, built with numpy + foreach_set, not from_pydata) and scenes with many
instances of one mesh (linked duplicates and a collection instance grid), times
``export_scene`` (median of 3 runs; 1 run where one run takes over 20 s), prints a table,
and writes ``export_benchmark.md`` and ``export_benchmark.json`` with machine info into
``--out`` (default ``out/bench/export/``; ``--quick``: ``export_benchmark_quick.*``). The page
docs/results/export_benchmark.md is regenerated with ``--out docs/results`` (then delete the
.json there, or link it: every file under docs/results must be linked from a page).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import import_checkout_package  # noqa: E402

import_checkout_package()
import bpy  # noqa: E402
import numpy as np  # noqa: E402

from gi_preview.blender.export import export_scene  # noqa: E402


def grid_mesh(name: str, n: int) -> bpy.types.Mesh:
    """An n x n quad grid (2 n^2 triangles) built with foreach_set only."""
    me = bpy.data.meshes.new(name)
    xs = np.linspace(-1.0, 1.0, n + 1, dtype=np.float32)
    x, y = np.meshgrid(xs, xs)
    z = 0.05 * np.sin(6 * x) * np.cos(6 * y)
    co = np.stack([x.ravel(), y.ravel(), z.ravel()], 1).astype(np.float32)
    me.vertices.add(len(co))
    me.vertices.foreach_set("co", co.ravel())
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    base = (j * (n + 1) + i).ravel()
    quads = np.stack([base, base + 1, base + n + 2, base + n + 1], 1).astype(np.int32)
    nf = len(quads)
    me.loops.add(4 * nf)
    me.loops.foreach_set("vertex_index", quads.ravel())
    me.polygons.add(nf)
    me.polygons.foreach_set("loop_start", np.arange(0, 4 * nf, 4, dtype=np.int32))
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", ((co[quads.ravel(), :2] + 1) / 2).ravel())
    me.polygons.foreach_set("material_index", (np.arange(nf) % 2).astype(np.int32))
    me.update()
    me.shade_smooth()
    return me


def new_scene(name: str) -> bpy.types.Scene:
    sc = bpy.data.scenes.new(name)
    sc.render.resolution_x = sc.render.resolution_y = 256
    cam = bpy.data.objects.new(name + ".cam", bpy.data.cameras.new(name + ".cam"))
    cam.location = (0, -6, 3)
    cam.rotation_euler = (1.1, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    light = bpy.data.objects.new(name + ".light", bpy.data.lights.new(name + ".light", "AREA"))
    light.location = (0, 0, 4)
    sc.collection.objects.link(light)
    return sc


def materials(name):
    out = []
    for k, col in enumerate(((0.8, 0.2, 0.2, 1), (0.2, 0.8, 0.2, 1))):
        m = bpy.data.materials.new(f"{name}.mat{k}")
        m.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = col
        out.append(m)
    return out


def case_single(n: int):
    sc = new_scene(f"grid{n}")
    me = grid_mesh(f"grid{n}", n)
    for m in materials(sc.name):
        me.materials.append(m)
    ob = bpy.data.objects.new(f"grid{n}", me)
    sc.collection.objects.link(ob)
    return sc, f"one mesh, {n}x{n} quad grid", 1


def case_linked(n: int, count: int):
    sc = new_scene(f"linked{count}")
    me = grid_mesh(f"tile{n}", n)
    for m in materials(sc.name):
        me.materials.append(m)
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        ob = bpy.data.objects.new(f"tile{k}", me)
        ob.location = (2.1 * (k % side), 2.1 * (k // side), 0)
        sc.collection.objects.link(ob)
    return sc, f"{count} linked duplicates of a {n}x{n} grid", count


def case_distinct(n: int, count: int):
    sc = new_scene(f"distinct{count}")
    mats = materials(sc.name)
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        me = grid_mesh(f"dtile{k}", n)
        for m in mats:
            me.materials.append(m)
        ob = bpy.data.objects.new(f"dtile{k}", me)
        ob.location = (2.1 * (k % side), 2.1 * (k // side), 0)
        sc.collection.objects.link(ob)
    return sc, f"{count} distinct meshes, each a {n}x{n} grid", count


def case_collection_instances(n: int, count: int):
    sc = new_scene(f"colinst{count}")
    me = grid_mesh(f"ctile{n}", n)
    for m in materials(sc.name):
        me.materials.append(m)
    col = bpy.data.collections.new(f"tilecol{count}")
    col.objects.link(bpy.data.objects.new(f"ctile{n}", me))
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        e = bpy.data.objects.new(f"inst{k}", None)
        e.instance_type = "COLLECTION"
        e.instance_collection = col
        e.location = (2.1 * (k % side), 2.1 * (k // side), 0)
        sc.collection.objects.link(e)
    return sc, f"{count} collection instances of a {n}x{n} grid", count


def depsgraph(sc):
    with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
        dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    return dg


def time_export(sc, runs=3):
    dg = depsgraph(sc)
    times = []
    sd = None
    for r in range(runs):
        sd = None
        t = time.perf_counter()
        sd = export_scene(dg)
        times.append(time.perf_counter() - t)
        if times[-1] > 20.0:
            break
    return times, sd


def cpu_model():
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only (smoke test)")
    ap.add_argument("--out", default=str(REPO / "out" / "bench" / "export"),
                    help="output folder (default: out/bench/export; the docs page: docs/results)")
    args = ap.parse_args(argv)
    if args.quick:
        cases = [lambda: case_single(50), lambda: case_linked(10, 50),
                 lambda: case_collection_instances(10, 50)]
    else:
        cases = [lambda: case_single(224), lambda: case_single(707), lambda: case_single(1414),
                 lambda: case_linked(22, 1000), lambda: case_collection_instances(22, 4000),
                 lambda: case_distinct(22, 1000)]
    rows = []
    print(f"{'case':48s} {'tris':>10s} {'meshes':>6s} {'inst':>6s} {'median s':>9s} {'uMtri/s':>7s} {'Mtri/s':>7s}")
    for make in cases:
        t0 = time.perf_counter()
        sc, label, _ = make()
        build_s = time.perf_counter() - t0
        times, sd = time_export(sc)
        med = statistics.median(times)
        unique = sum(m.triangle_count for m in sd.meshes)
        row = dict(case=label, triangles=sd.triangle_count, unique_triangles=unique,
                   meshes=len(sd.meshes), instances=len(sd.instances), runs=len(times),
                   times_s=[round(t, 4) for t in times], median_s=round(med, 4),
                   build_s=round(build_s, 2),
                   unique_mtris_per_s=round(unique / med / 1e6, 2) if med > 0 else None,
                   total_mtris_per_s=round(sd.triangle_count / med / 1e6, 1) if med > 0 else None)
        rows.append(row)
        print(f"{label:48s} {sd.triangle_count:>10d} {len(sd.meshes):>6d} {len(sd.instances):>6d} "
              f"{med:>9.3f} {row['unique_mtris_per_s']:>7} {row['total_mtris_per_s']:>7}", flush=True)
        del sd
        bpy.data.scenes.remove(sc)
        bpy.data.orphans_purge(do_recursive=True)
    info = dict(blender=bpy.app.version_string, python=platform.python_version(),
                numpy=np.__version__, cpu=cpu_model(), cpu_count=os.cpu_count(),
                platform=platform.platform(), date=time.strftime("%Y-%m-%d"),
                quick=args.quick)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "export_benchmark_quick" if args.quick else "export_benchmark"
    (out / f"{name}.json").write_text(json.dumps(dict(machine=info, results=rows), indent=2) + "\n")
    md = ["# Scene export benchmark", "",
          "`export_scene` (bpy depsgraph -> SceneData: triangulated per-corner positions, normals,",
          "UVs, material ids; instances; lights; camera), measured by `scripts/bench_export.py`.",
          "Time is the median of the runs listed (one run where a run exceeds 20 s); the depsgraph",
          "is evaluated before timing, so modifier evaluation is not included. Unique triangles",
          "are the ones copied into SceneData (instanced meshes are stored once); total counts",
          "every instance. The first run also pays for Blender's lazily computed caches (loop",
          "triangles, corner normals) of the evaluated meshes; later runs find them cached.", "",
          f"Machine: {info['cpu']}, {info['cpu_count']} CPUs (shared), Blender {info['blender']} "
          f"(PyPI bpy), Python {info['python']}, numpy {info['numpy']}, {info['date']}.", "",
          "| case | triangles | unique triangles | meshes | instances | runs | median (s) | "
          "first run (s) | unique Mtri/s | total Mtri/s |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        md.append(f"| {r['case']} | {r['triangles']:,} | {r['unique_triangles']:,} | {r['meshes']} | "
                  f"{r['instances']} | {r['runs']} | {r['median_s']:.3f} | {r['times_s'][0]:.3f} | "
                  f"{r['unique_mtris_per_s']} | {r['total_mtris_per_s']} |")
    (out / f"{name}.md").write_text("\n".join(md) + "\n")
    print("wrote", out / f"{name}.md", out / f"{name}.json")


if __name__ == "__main__":
    main()
