#!/usr/bin/env python3
"""3D-raster family (RSM; LPV and VXGI when registered) against Cycles on the demo scenes.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_raster3d.py
        [--scenes cornell,sunlit_room] [--techniques DIRECT,RSM] [--quality all]
        [--res 64] [--ref-spp 256] [--samples 8] [--baselines cycles] [--out docs/results/raster3d]

Runs scripts/gi_compare.py once per scene (each technique at every quality level against
the Cycles reference it models and against "full": relMSE, FLIP, SSIM, time per frame,
setup time, equal-error speed-ups against the baselines' curves) into ``<out>/<scene>/``,
then writes ``<out>/summary.md``: one table row per scene, technique and level, and the
mean of the image over the mean of each reference. The doc pages quote these numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", default="cornell,sunlit_room")
    p.add_argument("--techniques", default="DIRECT,RSM")
    p.add_argument("--quality", default="all")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--samples", type=int, default=8)
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--baselines", default="cycles")
    p.add_argument("--out", default=os.path.join(REPO, "docs", "results", "raster3d"))
    o = p.parse_args(argv)
    rows = []
    for scene in o.scenes.split(","):
        out = os.path.join(o.out, scene)
        cmd = [sys.executable, os.path.join(HERE, "gi_compare.py"), scene, "--techniques", o.techniques,
               "--quality", o.quality, "--res", str(o.res), "--ref-spp", str(o.ref_spp),
               "--samples", str(o.samples), "--frames", str(o.frames), "--baselines", o.baselines,
               "--out", out]
        print(" ".join(cmd), flush=True)
        subprocess.run(cmd, check=True)
        with open(os.path.join(out, "results.json")) as f:
            res = json.load(f)
        for r in res.get("results", []):
            rows.append((scene, r))
    lines = ["# 3D-raster family vs Cycles (scripts/bench_raster3d.py)", "",
             f"Resolution {o.res}, Cycles {o.ref_spp} spp, {o.samples} accumulated frames; "
             "per-scene details (images, error maps, baselines) in the scene folders.", "",
             "| scene | technique | q | reference | relMSE | FLIP | ms/frame | setup ms | equal-error speed-up vs Cycles |",
             "|---|---|---|---|---|---|---|---|---|"]
    for scene, r in rows:
        sp = (r.get("speedups") or {}).get("cycles") or r.get("speedup") or {}
        spv = sp.get("speedup") if isinstance(sp, dict) else None
        spv = f"{spv:.3g}" if isinstance(spv, (int, float)) else (sp.get("reason", "") if isinstance(sp, dict) else "")
        lines.append(f"| {scene} | {r.get('technique')} | {r.get('quality')} | {r.get('reference')} | "
                     f"{r.get('relmse', float('nan')):.4f} | {r.get('flip', float('nan')):.4f} | "
                     f"{r.get('frame_ms', float('nan')):.1f} | {r.get('setup_ms', float('nan')):.0f} | {spv} |")
    with open(os.path.join(o.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
