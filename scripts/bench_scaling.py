#!/usr/bin/env python3
"""How each technique's frame time and memory grow with pixels, lights and triangles.

    .venv/bin/python scripts/bench_scaling.py [--techniques DIRECT,SVGF,RTXGI] [--quality 1]
        [--sizes 32,64,128,256,512] [--lights 1,10,100,1000,10000]
        [--triangles 1000,10000,100000,1000000] [--axis-size 64] [--samples 4] [--out DIR]

Output folder ``--out``: default ``out/bench/scaling/`` (``scaling.json``, ``scaling.md``,
``scaling.png``); the page docs/results/scaling.md is regenerated with ``--out docs/results``.

The scene is bench_viewport's closed 4 x 3 x 2.5 m room with one area light (a scene no
technique was tuned on). Three sweeps, each changing one thing:

* **pixels**: the room at ``--sizes`` (square images). The fixed part of a frame is the
  intercept of a least-squares line through ms/frame against pixels: the time a frame costs
  whatever the image size (shadow maps, probe and cache updates, voxelisation), reported with
  its share of the frame at 128 x 128;
* **lights**: ``--axis-size`` px, the room plus N small sphere lights (radius 3 cm) on a
  jittered grid under the ceiling, 100 W in all whatever N;
* **triangles**: ``--axis-size`` px, the room plus a wavy grid mesh of about T triangles on
  the floor (T = 2 n^2).

Per point: ms/frame is the mean completion-to-completion frame time of an F12 render of
``--samples`` frames (warm-up frames not counted), after a first render that pays the setup
(compiles, BVH, uploads); the memory is what the render session holds in GL objects after
the render (textures, buffers and render targets alive, counted from their sizes as moderngl
created them; the scene upload, the BVH and the process's shared BVH cache included, mip
levels not; every earlier session is released first). Every time is the OpenGL
device's that results.json names: on Mesa's llvmpipe (software OpenGL on the CPU), compare
them as ratios only.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

def add_lights(bpy, sc, n: int, seed: int = 3):
    """N sphere lights (3 cm) on a jittered grid under the room's ceiling, 100 W in all."""
    import numpy as np

    rng = np.random.default_rng(seed)
    k = max(1, math.ceil(math.sqrt(n)))
    objs = []
    for i in range(n):
        gx, gy = i % k, i // k
        ld = bpy.data.lights.new(f"scale_l{i}", "POINT")
        ld.energy = 100.0 / n
        ld.shadow_soft_size = 0.03
        ld.color = tuple(0.6 + 0.4 * rng.random(3))
        ob = bpy.data.objects.new(f"scale_l{i}", ld)
        ob.location = (-1.8 + 3.6 * (gx + rng.uniform(0.2, 0.8)) / k,
                       -1.3 + 2.6 * (gy + rng.uniform(0.2, 0.8)) / k, 2.1 + 0.3 * rng.random())
        sc.collection.objects.link(ob)
        objs.append(ob)
    return objs


def add_triangles(bpy, sc, t: int):
    """A wavy grid of about t triangles on the room's floor."""
    import numpy as np

    from bench_viewport import grid_mesh
    from gi_preview.blender.demo_scenes import make_principled

    n = max(1, round(math.sqrt(t / 2)))
    me = grid_mesh(bpy, np, n, half=0.9, amp=0.05, name=f"scale_grid{n}")
    me.materials.append(make_principled("scale_grid", (0.6, 0.6, 0.55)))
    ob = bpy.data.objects.new(f"scale_grid{n}", me)
    ob.location = (0.6, -0.6, 0.06)
    sc.collection.objects.link(ob)
    return [ob], 2 * n * n


def measure(techniques, quality, sizes, lights, triangles, axis_size, samples) -> dict:
    from _checkout import setup_blender

    setup_blender()
    import bpy
    import numpy as np

    import bench_viewport as bv
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session
    from gi_preview.render.gl import get_gl

    from check_growth import GLCensus

    gl_bytes = GLCensus().install()
    sc = bv._room_scene(bpy)
    out = {"techniques": techniques, "quality": quality, "samples": samples, "axis_size": axis_size,
           "pixels": {}, "lights": {}, "triangles": {}}

    def point(t, res):
        sc.render.resolution_x = sc.render.resolution_y = res
        sd = export_scene(reference.evaluated_depsgraph(sc))
        key = f"scaling_{t}"
        t0 = time.perf_counter()
        session.render(sd, t, quality, 1, session=key)
        setup_s = time.perf_counter() - t0
        r = session.render(sd, t, quality, samples, session=key)
        mem = get_gl().submit(gl_bytes.mb).result()
        done = session.release_session(key)
        if done is not None:
            done.result()  # the next point starts from the shared caches only
        ok = bool(np.isfinite(r.image).all())
        return {"ms": round(float(r.frame_ms), 2), "mem_mb": round(float(mem), 2), "first_render_s": round(setup_s, 2),
                "finite": ok}

    for t in techniques:
        for res in sizes:
            out["pixels"].setdefault(t, {})[str(res)] = p = point(t, res)
            print(f"{t} {res}px: {p['ms']} ms/frame, {p['mem_mb']} MB", flush=True)
        for n in lights:
            objs = add_lights(bpy, sc, n)
            out["lights"].setdefault(t, {})[str(n)] = p = point(t, axis_size)
            print(f"{t} {n} lights: {p['ms']} ms/frame, {p['mem_mb']} MB", flush=True)
            for ob in objs:
                bpy.data.lights.remove(ob.data)
        for tris in triangles:
            objs, real = add_triangles(bpy, sc, tris)
            out["triangles"].setdefault(t, {})[str(tris)] = p = point(t, axis_size)
            p["triangles"] = real
            print(f"{t} {real} triangles: {p['ms']} ms/frame, {p['mem_mb']} MB", flush=True)
            for ob in objs:
                me = ob.data
                bpy.data.objects.remove(ob)
                bpy.data.meshes.remove(me)
    out["run"] = {"gl_renderer": get_gl().info.get("GL_RENDERER"),
                  "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()}
    return out


def fixed_part(points: dict) -> tuple[float, float] | None:
    """(fixed ms, ms per pixel) from the two smallest sizes: the line through them, followed
    down to an image of no pixels (what a frame costs as the image shrinks)."""
    pts = sorted((int(k) ** 2, v["ms"]) for k, v in points.items())
    if len(pts) < 2:
        return None
    (x0, y0), (x1, y1) = pts[:2]
    b = (y1 - y0) / max(x1 - x0, 1)
    return float(y0 - b * x0), float(b)


def report(data: dict, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    techs = data["techniques"]
    lines = ["# Scaling: frame time and memory against pixels, lights and triangles", "",
             f"`python scripts/bench_scaling.py --techniques {','.join(techs)} --quality {data['quality']}` "
             f"on a closed one-area-light room built by the script (not a demo scene), quality "
             f"{data['quality']}; ms/frame = mean frame time of an F12 render of {data['samples']} frames after a "
             "first render that pays the setup; memory = the GL textures, buffers and render targets alive "
             "after the render (the session's, its scene upload and BVH, and the shared BVH cache; earlier "
             "sessions released). "
             f"Times are {data['run']['gl_renderer']} on {data['run']['cores']} CPU cores: "
             "software OpenGL, compare them as ratios only.", "",
             "## Pixels", "", "Fixed part: the line through the two smallest sizes' ms/frame against pixels, "
             "followed down to an image of no pixels: what a frame costs whatever the image size (0 where the "
             "line goes below 0); its share is of the 128 x 128 frame.", ""]
    sizes = list(next(iter(data["pixels"].values())).keys()) if data["pixels"] else []
    lines.append("| technique | " + " | ".join(f"{s}² ms" for s in sizes) + " | fixed ms | fixed share at 128² | "
                 + " | ".join(f"{s}² MB" for s in sizes) + " |")
    lines.append("|---|" + "---:|" * (2 * len(sizes) + 2))
    for t in techs:
        pts = data["pixels"].get(t, {})
        fp = fixed_part(pts)
        f128 = fp[0] + fp[1] * 128 * 128 if fp else None
        f128 = pts["128"]["ms"] if "128" in pts else f128
        share = f"{100 * max(fp[0], 0) / f128:.0f} %" if fp and f128 and f128 > 0 else ""
        lines.append(f"| {t} | " + " | ".join(f"{pts[s]['ms']:.1f}" for s in sizes) +
                     f" | {max(fp[0], 0):.1f} | {share} | " + " | ".join(f"{pts[s]['mem_mb']:.1f}" for s in sizes)
                     + " |")
    for axis, title, unit in (("lights", "Lights", "lights"), ("triangles", "Triangles", "triangles")):
        keys = list(next(iter(data[axis].values())).keys()) if data[axis] else []
        if not keys:
            continue
        lines += ["", f"## {title}", "", f"{data['axis_size']} x {data['axis_size']} px; the room plus N {unit}; "
                  "growth: the last column's time over the first's.", "",
                  "| technique | " + " | ".join(f"{int(k):,} ms" for k in keys) + " | growth | "
                  + " | ".join(f"{int(k):,} MB" for k in keys) + " |",
                  "|---|" + "---:|" * (2 * len(keys) + 1)]
        for t in techs:
            pts = data[axis].get(t, {})
            g = pts[keys[-1]]["ms"] / max(pts[keys[0]]["ms"], 1e-6)
            lines.append(f"| {t} | " + " | ".join(f"{pts[k]['ms']:.1f}" for k in keys) + f" | {g:.1f}x | "
                         + " | ".join(f"{pts[k]['mem_mb']:.1f}" for k in keys) + " |")
    bad = [f"{t} {axis} {k}" for axis in ("pixels", "lights", "triangles") for t, pts in data[axis].items()
           for k, v in pts.items() if not v["finite"]]
    lines += ["", "Every image finite." if not bad else f"Non-finite images: {', '.join(bad)}.", ""]
    (out / "scaling.md").write_text("\n".join(lines), encoding="utf-8")

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, axis, xlabel in zip(axes, ("pixels", "lights", "triangles"), ("pixels", "lights", "triangles")):
        for t in techs:
            pts = data[axis].get(t, {})
            if not pts:
                continue
            xs = [int(k) ** 2 if axis == "pixels" else (v.get("triangles") or int(k)) for k, v in pts.items()]
            ax.plot(xs, [v["ms"] for v in pts.values()], marker="o", label=t)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("ms / frame")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"ms per frame, quality {data['quality']} ({data['run']['gl_renderer']}: ratios only)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "scaling.png", dpi=90)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--techniques", default="DIRECT,SVGF,RTXGI")
    ap.add_argument("--quality", type=int, default=1)
    ap.add_argument("--sizes", default="32,64,128,256,512")
    ap.add_argument("--lights", default="1,10,100,1000,10000")
    ap.add_argument("--triangles", default="1000,10000,100000,1000000")
    ap.add_argument("--axis-size", type=int, default=64, help="image size of the lights and triangles sweeps")
    ap.add_argument("--samples", type=int, default=4, help="frames per timed render")
    ap.add_argument("--out", default=str(REPO / "out" / "bench" / "scaling"))
    ap.add_argument("--md-only", action="store_true", help="rewrite scaling.md and the chart from scaling.json")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.md_only:
        data = json.loads((out / "scaling.json").read_text(encoding="utf-8"))
    else:
        ints = lambda s: [int(float(x)) for x in s.split(",") if x]  # noqa: E731
        data = measure(a.techniques.split(","), a.quality, ints(a.sizes), ints(a.lights), ints(a.triangles),
                       a.axis_size, a.samples)
        (out / "scaling.json").write_text(json.dumps(data, indent=1), encoding="utf-8")
    report(data, out)
    print(out / "scaling.md")


if __name__ == "__main__":
    main()
