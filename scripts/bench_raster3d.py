#!/usr/bin/env python3
"""3D-raster family (RSM, LPV; VXGI when registered) against Cycles: demo scenes, thin-wall
leak, stability.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_raster3d.py [--parts compare,leak,stability]
        [--scenes cornell,sunlit_room] [--techniques DIRECT,RSM,LPV] [--quality all]
        [--res 64] [--ref-spp 256] [--samples 8] [--baselines cycles,cycles_denoised,eevee]
        [--stability-frames 60] [--out docs/results/raster3d]
    (--parts summary: only rewrite summary.md from the folders present)

* ``compare``: scripts/gi_compare.py once per scene and technique (each quality level
  against the Cycles reference it models and against "full": relMSE, FLIP, SSIM, time per
  frame, setup time, equal-error speed-ups against the baselines' curves: Cycles, Cycles +
  OpenImageDenoise, EEVEE) into ``<out>/<scene>/<TECH>/``; the mean of each image over the
  mean of each reference is read back from the EXRs. Table in ``<out>/summary.md``.
* ``leak``: the thin-wall scene of blender_tests/scenes_raster3d.py (two rooms, a wall of
  zero thickness, the light in the left one, the camera in the right one): the dark room's
  mean minus Cycles' (one bounce), over the lit room's mean seen from inside it; LPV with
  and without its geometry volume. ``<out>/leak.json``.
* ``stability``: the Cornell box at 32 px, ``--stability-frames`` frames with the light and
  the camera moving every frame (viewport-like: history kept, 1 frame each): finite, the
  minimum value, and the mean absolute frame-to-frame difference against Cycles' (64 spp
  per frame, same poses). ``<out>/stability.json``.
The doc pages (docs/techniques/RSM.md, LPV.md) quote these numbers.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def _bpy_env():
    sys.path.insert(0, HERE)
    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    from _checkout import setup_blender

    setup_blender()


def _set_props(sess, props):
    from gi_preview.render import session as S
    from gi_preview.render.gl import get_gl

    get_gl().call(lambda: [g.set_properties(props) for _t, g in S._sessions[sess].graphs.values()])


def part_compare(o, rows):
    """One gi_compare run per scene and technique into ``<out>/<scene>/<TECH>/`` (a run per
    technique keeps each locked command short; the summary reads every folder present)."""
    for scene in o.scenes.split(","):
        for tech in o.techniques.split(","):
            out = os.path.join(o.out, scene, tech)
            cmd = [sys.executable, os.path.join(HERE, "gi_compare.py"), scene, "--techniques", tech,
                   "--quality", o.quality, "--res", str(o.res), "--ref-spp", str(o.ref_spp),
                   "--samples", str(o.samples), "--frames", str(o.frames), "--baselines", o.baselines,
                   "--out", out]
            print(" ".join(cmd), flush=True)
            subprocess.run(cmd, check=True)
    collect(o, rows)


def collect(o, rows):
    """Rows of every ``<out>/<scene>/<TECH>/results.json`` of the requested scenes, with the
    mean of each image over the mean of its reference read back from the EXRs."""
    from gi_preview.blender import reference
    from gi_preview.compare import imageio

    reference.ensure_oiio()
    for scene in o.scenes.split(","):
        base = os.path.join(o.out, scene)
        for tech in sorted(os.listdir(base)) if os.path.isdir(base) else ():
            out = os.path.join(base, tech)
            if not os.path.isfile(os.path.join(out, "results.json")):
                continue
            with open(os.path.join(out, "results.json")) as f:
                res = json.load(f)
            refs = {}
            for r in res.get("results", []):
                k = r.get("reference")
                if k not in refs:
                    refs[k] = imageio.read_exr(os.path.join(out, f"reference_{k}.exr"))[..., :3].mean()
                img = imageio.read_exr(os.path.join(out, r["files"]["exr"]))[..., :3]
                r["mean_ratio"] = float(img.mean() / max(refs[k], 1e-12))
                rows.append((scene, r))


def _speedup(r, b):
    sp = (r.get("speedups") or {}).get(b) or {}
    v = sp.get("speedup")
    if isinstance(v, (int, float)):
        return f"{v:.3g}"
    b = sp.get("bound") or {}
    if "at_most" in b:  # the technique's error is above the baseline's lowest-spp error
        return f"≤ {b['at_most']:.3g}"
    if "at_least" in b:  # below the baseline's highest-spp error
        return f"≥ {b['at_least']:.3g}"
    if not sp:
        return "–"
    return str(sp.get("reason", "")).replace("|", "/")


def write_summary(o, rows):
    bl = [b for b in o.baselines.split(",") if b and b != "none"] or ["cycles"]
    lines = ["# 3D-raster family vs Cycles (scripts/bench_raster3d.py)", "",
             f"Resolution {o.res}, Cycles {o.ref_spp} spp, {o.samples} accumulated frames, llvmpipe on 2 cores; "
             "per-scene details (images, error maps, baselines) in the scene folders. Mean = mean of the "
             "image over the mean of the reference. Speed-up: the baseline's time to reach the "
             "technique's error over the technique's time (setup apart); ≤ x: the technique's error is "
             "above the baseline's error at its fewest samples (x = the speed-up at that point, an upper "
             "bound), ≥ x: below the baseline's error at its most samples (a lower bound). The "
             "Cycles + OpenImageDenoise and EEVEE curves are measured against the full reference only.", "",
             "| scene | technique | q | reference | relMSE | FLIP | mean | ms/frame | setup ms | "
             + " | ".join(f"speed-up vs {b}" for b in bl) + " |",
             "|---|---|---|---|---|---|---|---|---|" + "---|" * len(bl)]
    for scene, r in rows:
        lines.append(f"| {scene} | {r.get('technique')} | {r.get('quality')} | {r.get('reference')} | "
                     f"{r.get('relmse', float('nan')):.4f} | {r.get('flip', float('nan')):.4f} | "
                     f"{r.get('mean_ratio', float('nan')):.3f} | {r.get('frame_ms', float('nan')):.1f} | "
                     f"{r.get('setup_ms', float('nan')):.0f} | " + " | ".join(_speedup(r, b) for b in bl) + " |")
    with open(os.path.join(o.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def part_leak(o):
    import bpy
    import numpy as np

    import scenes_raster3d
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    res = o.leak_res
    dark = scenes_raster3d.build("two_rooms", res)
    lit = scenes_raster3d.build("two_rooms", res, lit_camera=True)
    sd_dark = export_scene(reference.evaluated_depsgraph(dark))
    ref_dark = reference.render_cycles(dark, o.ref_spp, "one_bounce")[0][..., :3]
    ref_lit = reference.render_cycles(lit, o.ref_spp, "one_bounce")[0][..., :3]
    lit_level = float(ref_lit.mean())
    out = {"res": res, "ref_spp": o.ref_spp, "cycles_dark_mean": float(ref_dark.mean()),
           "cycles_lit_mean": lit_level, "runs": []}
    configs = [("DIRECT", {}, "DIRECT"), ("RSM", {}, "RSM")]
    if "LPV" in o.techniques.split(","):
        configs += [("LPV", {}, "LPV, geometry volume on"),
                    ("LPV", {"lpv": {"geometry_volume": False}}, "LPV, geometry volume off")]
    for q in (1,):
        for k, (tech, props, label) in enumerate(configs):
            sess = f"leak{k}"
            S.render(sd_dark, tech, q, 1, session=sess, warmup=False)
            if props:
                _set_props(sess, props)
            img = S.render(sd_dark, tech, q, o.samples, session=sess).image[..., :3]
            S.release_session(sess).result(timeout=60)
            leak = float(img.mean() - ref_dark.mean()) / lit_level
            out["runs"].append({"technique": tech, "quality": q, "label": label, "props": props,
                                "dark_mean": float(img.mean()), "leak": leak})
            print(f"two_rooms {label} q{q}: dark-room mean {img.mean():.4f} (Cycles {ref_dark.mean():.4f}), "
                  f"leak {leak:.4f} of the lit room's {lit_level:.4f}", flush=True)
    bpy.data.scenes.remove(dark)
    bpy.data.scenes.remove(lit)
    with open(os.path.join(o.out, "leak.json"), "w") as f:
        json.dump(out, f, indent=1)


def move(sc, k, n):
    """Pose k of n: the light sweeps across the ceiling and the camera dollies and rises."""
    light = next(ob for ob in sc.objects if ob.type == "LIGHT")
    cam = sc.camera
    if not hasattr(move, "base"):
        move.base = {}
    key = sc.name
    if key not in move.base:
        move.base[key] = (tuple(light.location), tuple(cam.location))
    (lx, ly, lz), (cx, cy, cz) = move.base[key]
    t = k / max(n - 1, 1)
    light.location = (lx - 0.3 + 0.6 * t, ly + 0.2 * math.sin(2 * math.pi * t), lz)
    cam.location = (cx + 0.3 * t, cy, cz + 0.2 * t)


def part_stability(o):
    import bpy
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    n = o.stability_frames
    sc = demo_scenes.build_demo("cornell", resolution=32)
    cyc = []
    for k in range(n):
        move(sc, k, n)
        cyc.append(reference.render_cycles(sc, 64, "one_bounce")[0][..., :3])
    d_cyc = [float(np.abs(a - b).mean()) for a, b in zip(cyc, cyc[1:])]
    out = {"frames": n, "res": 32, "cycles_spp": 64, "cycles": {"mean": float(np.mean(d_cyc)),
                                                              "max": float(np.max(d_cyc))}, "runs": []}
    for tech in [t for t in o.techniques.split(",") if t != "DIRECT"]:
        for q in (0, 1):
            ours, t0 = [], time.perf_counter()
            fin, mn = True, float("inf")
            for k in range(n):
                move(sc, k, n)
                sd = export_scene(reference.evaluated_depsgraph(sc))
                img = S.render(sd, tech, q, 1, keep_history=True, session="stab").image[..., :3]
                fin &= bool(np.isfinite(img).all())
                mn = min(mn, float(img.min()))
                ours.append(img)
            S.release_session("stab").result(timeout=60)
            d = [float(np.abs(a - b).mean()) for a, b in zip(ours, ours[1:])]
            r = {"technique": tech, "quality": q, "finite": fin, "min": mn, "mean": float(np.mean(d)),
                 "max": float(np.max(d)), "ratio_mean": float(np.mean(d) / np.mean(d_cyc)),
                 "wall_s": time.perf_counter() - t0}
            out["runs"].append(r)
            print(f"stability {tech} q{q}: finite {fin}, min {mn:.3g}, frame-to-frame mean {r['mean']:.4f} "
                  f"max {r['max']:.4f} vs Cycles mean {out['cycles']['mean']:.4f} max {out['cycles']['max']:.4f}",
                  flush=True)
    bpy.data.scenes.remove(sc)
    with open(os.path.join(o.out, "stability.json"), "w") as f:
        json.dump(out, f, indent=1)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--parts", default="compare,leak,stability")
    p.add_argument("--scenes", default="cornell,sunlit_room")
    p.add_argument("--techniques", default="DIRECT,RSM,LPV")
    p.add_argument("--quality", default="all")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--leak-res", type=int, default=48)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--samples", type=int, default=8)
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--baselines", default="cycles,cycles_denoised,eevee")
    p.add_argument("--stability-frames", type=int, default=60)
    p.add_argument("--out", default=os.path.join(REPO, "docs", "results", "raster3d"))
    o = p.parse_args(argv)
    os.makedirs(o.out, exist_ok=True)
    _bpy_env()
    parts = o.parts.split(",")
    if "compare" in parts or "summary" in parts:
        rows = []
        if "compare" in parts:
            part_compare(o, rows)
        else:
            collect(o, rows)
        write_summary(o, rows)
    if "leak" in parts:
        part_leak(o)
    if "stability" in parts:
        part_stability(o)


if __name__ == "__main__":
    main()
