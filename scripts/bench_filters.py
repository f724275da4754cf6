#!/usr/bin/env python3
"""Per-frame numbers of the filters (ATROUS, SVGF, TAA over 1-spp PT) under motion, with
``gi_compare.py --animation`` (addon/compare/animation.py), on the demo scenes.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_filters.py [--tag after] \
        [--cases cornell:pan,sunlit_room:pan,sunlit_room:light,cornell:orbit] [--res 48] \
        [--techniques PT,ATROUS,SVGF,TAA] [--out DIR] [--case-out DIR]

The summary of the run goes to ``<out>/animation_<tag>.json`` and ``.md`` (``--out``, default
``out/bench/filters/``; a table per case: relMSE moving/held, stability vs Cycles', trail
recovery, brightness of the last held frame against Cycles). Each case writes a full
comparison folder ``<case-out>/animation_<scene>_<motion>/`` (results.json, animation.png,
frame strips, report.html; ``--case-out``, default ``out/bench/filters/cases/`` whatever
``--out`` is). The tables the SVGF and TAA pages link are regenerated with
``--out docs/results/filters`` (then delete the .json there, or link it: every file under
docs/results must be linked from a page).
Cycles per frame: 256 spp + OpenImageDenoise (cached), 12 moving + 10 still frames.

``--draws N`` repeats each run with N independent noise draws (``AnimationSpec.draws``): the
trail ratio is then the mean trail error over the mean still-camera error on the same held
frame, the stability figure the mean over draws (per-draw values in the JSON). A case may give
the motion's amount after an ``@`` (``cornell:pan@0.04``: a slow pan; the summary reports the
pan's speed in pixels per frame at the viewed distance). ``--taa-set k=v,...`` overrides TAA
parameters for the whole run (e.g. ``history_normal=-1,history_fallback=0``: TAA without its
history normal test and without its fallback tap); ``--svgf-set k=v,...`` does the same for
SVGF. ``--pt-set k=v,...`` sets path-tracer parameter defaults for every technique (e.g.
``pixel_sequence=1``: Halton in-pixel positions).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tag", default="after")
    ap.add_argument("--cases", default="cornell:pan,sunlit_room:pan,sunlit_room:light,cornell:orbit")
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--techniques", default="PT,ATROUS,SVGF,TAA")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--hold", type=int, default=10)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--out", default=os.path.join(REPO, "out", "bench", "filters"),
                    help="folder of the summary animation_<tag>.json/.md (default: out/bench/filters)")
    ap.add_argument("--case-out", default=os.path.join(REPO, "out", "bench", "filters", "cases"),
                    help="folder of the per-case comparison folders (default: out/bench/filters/cases)")
    ap.add_argument("--draws", type=int, default=1, help="independent noise draws per run (trail/stability: means)")
    ap.add_argument("--taa-set", default="", help="TAA parameter overrides k=v,... for every quality level")
    ap.add_argument("--svgf-set", default="", help="SVGF parameter overrides k=v,... for every quality level")
    ap.add_argument("--pt-set", default="", help="path-tracer (PathTracePass) parameter defaults k=v,... for every technique")
    a = ap.parse_args()
    import gi_compare as gc
    pkg = gc.find_addon(False)
    import importlib
    session = importlib.import_module(pkg.__name__ + ".render.session")
    demo = importlib.import_module(pkg.__name__ + ".blender.demo_scenes")
    import bpy
    filters = importlib.import_module(pkg.__name__ + ".render.passes.filters")
    overrides = {}
    for opt, cls in (("taa_set", filters.TAAPass), ("svgf_set", filters.SVGFPass)):
        names = {p.name for p in cls.params}
        kv = {}
        for item in (x.strip() for x in getattr(a, opt).split(",")):
            if not item:
                continue
            k, eq, v = item.partition("=")
            if not eq or k not in names:
                ap.error(f"--{opt.replace('_', '-')} {item!r}: expected k=v with k one of {sorted(names)}")
            try:
                kv[k] = float(v)
            except ValueError:
                ap.error(f"--{opt.replace('_', '-')} {item!r}: {v!r} is not a number")
        if kv:
            cls.quality_ladder = tuple(dict(d, **kv) for d in cls.quality_ladder)
        overrides[opt] = kv
    pt_set = {k: float(v) for k, v in (kv.split("=") for kv in a.pt_set.split(",") if kv.strip())}
    ptm = importlib.import_module(pkg.__name__ + ".render.techniques.pt")
    if pt_set:
        import dataclasses
        ptm.PathTracePass.params = tuple(dataclasses.replace(p, default=type(p.default)(pt_set[p.name]))
                                         if p.name in pt_set else p for p in ptm.PathTracePass.params)
    summary = {"date": time.strftime("%Y-%m-%d %H:%M"), "res": a.res, "ref_spp": a.ref_spp, "draws": a.draws,
               "taa_set": overrides["taa_set"], "svgf_set": overrides["svgf_set"], "pt_set": pt_set, "cases": {}}
    for case in a.cases.split(","):
        scene_name, motion = case.split(":")
        motion, _, amount = motion.partition("@")
        out = os.path.join(a.case_out, f"animation_{scene_name}_{motion}" + (f"_{amount}" if amount else ""))
        opts = gc.parse_args([scene_name, "--animation", motion, "--techniques", a.techniques, "--res", str(a.res),
                              "--anim-frames", str(a.frames), "--anim-hold", str(a.hold),
                              "--anim-ref-spp", str(a.ref_spp), "--anim-draws", str(a.draws), "--out", out]
                             + (["--anim-amount", amount] if amount else []), scene_optional=False)
        sc = demo.build_demo(scene_name, resolution=a.res)
        cam = sc.camera.data
        # a pan's speed in pixels per frame at the viewed distance: amount / move x focal x width / 2
        px_frame = (float(amount or 0.12) / a.frames * a.res / 2.0 / math.tan(cam.angle_x / 2.0)
                    if motion == "pan" and cam.type == "PERSP" else None)
        try:
            t0 = time.perf_counter()
            res = gc.run_animation(opts, pkg=pkg, session=session, scene=sc)
            anim = res["animation"]
            anim["bench_wall_s"] = time.perf_counter() - t0
        finally:
            bpy.data.scenes.remove(sc)
        summary["cases"][case] = {
            "cycles": anim["cycles"], "trail_mask_pixels": anim["trail_mask_pixels"], "trail_kind": anim["trail_kind"],
            "pan_px_per_frame": px_frame, "draws": anim.get("draws", 1),
            "techniques": {t: {k: v[k] for k in ("relmse_moving", "relmse_hold", "stability", "cycles_stability",
                                                  "stability_ratio", "hold_flicker", "frame_ms", "nonfinite_pixels")}
                           | {"trail_ratio_at_8": v["trail"].get("ratio_at_8"),
                              "recovered_after": v["trail"].get("recovered_after"),
                              "trail_ratio_per_draw": v["trail"].get("ratio_at_8_per_draw"),
                              "trail_ratio_after_stop": v["trail"].get("ratio_after_stop"),
                              "stability_per_draw": v.get("stability_per_draw"),
                              "relmse_hold_per_draw": v.get("relmse_hold_per_draw"),
                              "mean_ratio_last": v["mean_ratio"][-1],
                              "mean_ratio_hold": sum(v["mean_ratio"][anim["stop_frame"] + 1:])
                              / max(1, len(v["mean_ratio"][anim["stop_frame"] + 1:]))}
                           for t, v in anim["techniques"].items()}}
    d = a.out
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, f"animation_{a.tag}.json"), "w") as f:
        json.dump(gc._clean_json(summary), f, indent=1)
    lines = [f"# Filters under motion ({a.tag}, {summary['date']}, {a.res} px, Cycles {a.ref_spp} spp + OIDN per frame)", "",
             "Made by `scripts/bench_filters.py --tag " + a.tag + (f" --draws {a.draws}" if a.draws > 1 else "")
             + (f" --taa-set {a.taa_set}" if a.taa_set else "") + (f" --svgf-set {a.svgf_set}" if a.svgf_set else "") + (f" --pt-set {a.pt_set}" if a.pt_set else "") + "`. Stability = mean |frame difference| over the moving "
             "frames, ours / Cycles'. Trail: error in the pixels disoccluded (relit, for a light move) over the last 8 "
             "moving frames, 8 frames after the stop, over a still camera's error on the same frame (same seeds); "
             "recovered = first held frame within 1.5x. Brightness = mean of the image / Cycles' (held frames). "
             f"Noise draws per run: {a.draws} (stability and trail: means over the draws; min-max of the single "
             "draws in brackets).", ""]
    fmt = lambda v, f="{:.3f}": "–" if v is None else f.format(v)  # noqa: E731
    for case, c in summary["cases"].items():
        speed = f"; {c['pan_px_per_frame']:.2f} px/frame" if c.get("pan_px_per_frame") else ""
        lines += [f"## {case} (Cycles stability {fmt(c['cycles']['stability'], '{:.4f}')}, noise floor "
                  f"{fmt(c['cycles']['noise_floor'], '{:.4f}')}; trail mask {c['trail_mask_pixels']} px, {c['trail_kind']}"
                  f"{speed})", "",
                  "| technique | relMSE moving | relMSE held | stability | ratio | trail +8 / still | recovered after | brightness held | ms/frame |",
                  "|---|---|---|---|---|---|---|---|---|"]
        def spread4(vals):
            vals = [x for x in (vals or []) if x is not None]
            return f" ({min(vals):.4f}-{max(vals):.4f})" if len(vals) > 1 else ""

        def spread(vals):
            vals = [x for x in (vals or []) if x is not None]
            return f" ({min(vals):.2f}-{max(vals):.2f})" if len(vals) > 1 else ""
        for t, v in c["techniques"].items():
            lines.append(f"| {t} | {fmt(v['relmse_moving'], '{:.4f}')} | {fmt(v['relmse_hold'], '{:.4f}')}{spread4(v.get('relmse_hold_per_draw'))} | "
                         f"{fmt(v['stability'], '{:.4f}')} | {fmt(v['stability_ratio'], '{:.2f}x')}"
                         f"{spread(v.get('stability_per_draw'))} | "
                         f"{fmt(v['trail_ratio_at_8'], '{:.2f}x')}{spread(v.get('trail_ratio_per_draw'))} | "
                         f"{fmt(v['recovered_after'], '{}')} | "
                         f"{fmt(v['mean_ratio_hold'])} | {fmt(v['frame_ms'], '{:.1f}')} |")
        lines.append("")
    with open(os.path.join(d, f"animation_{a.tag}.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
