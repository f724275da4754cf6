#!/usr/bin/env python3
"""Per-frame numbers of the filters (ATROUS, SVGF, TAA over 1-spp PT) under motion, with
``gi_compare.py --animation`` (addon/compare/animation.py), on the demo scenes.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_filters.py [--tag after] \
        [--cases cornell:pan,sunlit_room:pan,sunlit_room:light,cornell:orbit] [--res 48] \
        [--techniques PT,ATROUS,SVGF,TAA]

Each case writes a full comparison folder docs/results/animation_<scene>_<motion>/
(results.json, animation.png, frame strips, report.html); the summary of the run goes to
docs/results/filters/animation_<tag>.json and .md (a table per case: relMSE moving/held,
stability vs Cycles', trail recovery, brightness of the last held frame against Cycles).
Cycles per frame: 256 spp + OpenImageDenoise (cached), 12 moving + 10 still frames.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tag", default="after")
    ap.add_argument("--cases", default="cornell:pan,sunlit_room:pan,sunlit_room:light,cornell:orbit")
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--techniques", default="PT,ATROUS,SVGF,TAA")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--hold", type=int, default=10)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--no-docs", action="store_true", help="write the case folders under /tmp instead of docs/results")
    a = ap.parse_args()
    import gi_compare as gc
    pkg = gc.find_addon(False)
    import importlib
    session = importlib.import_module(pkg.__name__ + ".render.session")
    demo = importlib.import_module(pkg.__name__ + ".blender.demo_scenes")
    import bpy
    summary = {"date": time.strftime("%Y-%m-%d %H:%M"), "res": a.res, "ref_spp": a.ref_spp, "cases": {}}
    for case in a.cases.split(","):
        scene_name, motion = case.split(":")
        out = os.path.join("/tmp" if a.no_docs else os.path.join(REPO, "docs", "results"),
                           f"animation_{scene_name}_{motion}")
        opts = gc.parse_args([scene_name, "--animation", motion, "--techniques", a.techniques, "--res", str(a.res),
                              "--anim-frames", str(a.frames), "--anim-hold", str(a.hold),
                              "--anim-ref-spp", str(a.ref_spp), "--out", out], scene_optional=False)
        sc = demo.build_demo(scene_name, resolution=a.res)
        try:
            t0 = time.perf_counter()
            res = gc.run_animation(opts, pkg=pkg, session=session, scene=sc)
            anim = res["animation"]
            anim["bench_wall_s"] = time.perf_counter() - t0
        finally:
            bpy.data.scenes.remove(sc)
        summary["cases"][case] = {
            "cycles": anim["cycles"], "trail_mask_pixels": anim["trail_mask_pixels"], "trail_kind": anim["trail_kind"],
            "techniques": {t: {k: v[k] for k in ("relmse_moving", "relmse_hold", "stability", "cycles_stability",
                                                  "stability_ratio", "hold_flicker", "frame_ms", "nonfinite_pixels")}
                           | {"trail_ratio_at_8": v["trail"].get("ratio_at_8"),
                              "recovered_after": v["trail"].get("recovered_after"),
                              "mean_ratio_last": v["mean_ratio"][-1],
                              "mean_ratio_hold": sum(v["mean_ratio"][anim["stop_frame"] + 1:])
                              / max(1, len(v["mean_ratio"][anim["stop_frame"] + 1:]))}
                           for t, v in anim["techniques"].items()}}
    d = os.path.join(REPO, "docs", "results", "filters")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, f"animation_{a.tag}.json"), "w") as f:
        json.dump(gc._clean_json(summary), f, indent=1)
    lines = [f"# Filters under motion ({a.tag}, {summary['date']}, {a.res} px, Cycles {a.ref_spp} spp + OIDN per frame)", "",
             "Made by `scripts/bench_filters.py --tag " + a.tag + "`. Stability = mean |frame difference| over the moving "
             "frames, ours / Cycles'. Trail: error in the pixels disoccluded (relit, for a light move) over the last 8 "
             "moving frames, 8 frames after the stop, over a still camera's level; recovered = first held frame within "
             "1.5x. Brightness = mean of the image / Cycles' (held frames).", ""]
    fmt = lambda v, f="{:.3f}": "–" if v is None else f.format(v)  # noqa: E731
    for case, c in summary["cases"].items():
        lines += [f"## {case} (Cycles stability {fmt(c['cycles']['stability'], '{:.4f}')}, noise floor "
                  f"{fmt(c['cycles']['noise_floor'], '{:.4f}')}; trail mask {c['trail_mask_pixels']} px, {c['trail_kind']})", "",
                  "| technique | relMSE moving | relMSE held | stability | ratio | trail +8 / still | recovered after | brightness held | ms/frame |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for t, v in c["techniques"].items():
            lines.append(f"| {t} | {fmt(v['relmse_moving'], '{:.4f}')} | {fmt(v['relmse_hold'], '{:.4f}')} | "
                         f"{fmt(v['stability'], '{:.4f}')} | {fmt(v['stability_ratio'], '{:.2f}x')} | "
                         f"{fmt(v['trail_ratio_at_8'], '{:.2f}x')} | {fmt(v['recovered_after'], '{}')} | "
                         f"{fmt(v['mean_ratio_hold'])} | {fmt(v['frame_ms'], '{:.1f}')} |")
        lines.append("")
    with open(os.path.join(d, f"animation_{a.tag}.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
