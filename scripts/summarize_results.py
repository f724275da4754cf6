"""Markdown table of one or more gi_compare runs (results.json), for the docs pages.

    python scripts/summarize_results.py docs/results/direct/*/results.json > docs/results/direct/summary.md

Columns: scene, technique, quality, reference, samples, ms per frame, time of the
accumulated image, relMSE, FLIP, SSIM, and the equal-error speed-up against Cycles' curve
measured in the same run (on llvmpipe: a ratio, not a GPU timing).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def fmt(v, f="{:.4g}"):
    if v is None:
        return "–"
    try:
        return f.format(v)
    except (TypeError, ValueError):
        return str(v)


def main(paths: list[str]) -> str:
    rows = ["| scene | technique | q | reference | samples | ms/frame | ms total | relMSE | FLIP | SSIM | "
            "equal-error speed-up |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for p in paths:
        d = json.loads(Path(p).read_text())
        scene = d.get("scene", {})
        name = scene.get("name", Path(p).parent.name) if isinstance(scene, dict) else str(scene)
        for e in d["entries"]:
            sp = (e.get("speedup") or {}).get("speedup")
            rows.append(f"| {name} | {e['technique']} | {e['quality']} | {e['reference']} | {e['samples']} | "
                        f"{fmt(e['frame_ms'], '{:.1f}')} | {fmt(e['time_ms'], '{:.0f}')} | {fmt(e['relmse'])} | "
                        f"{fmt(e['flip'], '{:.3f}')} | {fmt(e['ssim'], '{:.4f}')} | "
                        f"{fmt(sp, '{:.3g}×') if sp is not None else 'n/a'} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    sys.stdout.write(main(sys.argv[1:]))
