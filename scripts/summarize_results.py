"""Markdown tables of one or more gi_compare runs (results.json), for the docs pages.

    python scripts/summarize_results.py out/bench/direct/*/results.json > out/bench/direct/summary.md

First table, per technique, quality and reference: samples, ms per frame, time of the
accumulated image, one-time setup (export, GPU upload, BVH, shader compilation; never in
the per-frame time), relMSE, FLIP, SSIM, and the equal-error speed-up against each baseline
measured in the same run (Cycles, Cycles + OpenImageDenoise, EEVEE; on llvmpipe: ratios,
not GPU timings; "≤x"/"≥x" where the technique's error is outside the baseline's curve).
Second table: the baselines' own curves (spp, ms per frame without setup, wall ms, errors)
and their setup.
"""
from __future__ import annotations

import importlib
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import import_checkout_package  # noqa: E402

import_checkout_package()
speedup_text = importlib.import_module("gi_preview.compare.sweep").speedup_text

BASELINES = ("cycles", "cycles_denoised", "eevee")
LABELS = {"cycles": "Cycles", "cycles_denoised": "Cycles + OIDN", "eevee": "EEVEE"}


def fmt(v, f="{:.4g}"):
    if v is None:
        return "–"
    try:
        return f.format(v)
    except (TypeError, ValueError):
        return str(v)


def main(paths: list[str]) -> str:
    runs = [(p, json.loads(Path(p).read_text())) for p in paths]
    names = [b for b in BASELINES if any(b in (d.get("baselines") or {}) for _, d in runs)] or ["cycles"]
    head = ("| scene | technique | q | reference | samples | ms/frame | ms total | setup ms | relMSE | FLIP | SSIM | "
            + " | ".join(f"speed-up vs {LABELS[b]}" for b in names) + " |")
    rows = [head, "|" + "---|" * (11 + len(names))]
    for p, d in runs:
        scene = d.get("scene", {})
        name = scene.get("name", Path(p).parent.name) if isinstance(scene, dict) else str(scene)
        for e in d["entries"]:
            sps = e.get("speedups") or {"cycles": e.get("speedup")}
            cells = " | ".join(speedup_text(sps.get(b)) if b in sps else "–" for b in names)
            rows.append(f"| {name} | {e['technique']} | {e['quality']} | {e['reference']} | {e['samples']} | "
                        f"{fmt(e['frame_ms'], '{:.1f}')} | {fmt(e['time_ms'], '{:.0f}')} | "
                        f"{fmt(e.get('setup_ms'), '{:.0f}')} | {fmt(e['relmse'])} | "
                        f"{fmt(e['flip'], '{:.3f}')} | {fmt(e['ssim'], '{:.4f}')} | {cells} |")
    out = "\n".join(rows) + "\n"
    brows = ["| scene | baseline | spp | ms/frame | wall ms | relMSE | FLIP | SSIM |", "|---|---|---|---|---|---|---|---|"]
    notes = []
    for p, d in runs:
        scene = d.get("scene", {})
        name = scene.get("name", Path(p).parent.name) if isinstance(scene, dict) else str(scene)
        for b, pts in (d.get("baselines") or {}).items():
            info = (d.get("baselines_setup") or {}).get(b) or {}
            extra = info.get("first_render_extra_ms")
            notes.append(f"- {name}, {LABELS.get(b, b)}: setup {fmt(info.get('setup_ms'), '{:.0f}')} ms, "
                         f"{fmt(info.get('per_sample_ms'), '{:.3g}')} ms per sample"
                         + (f", first render(s) +{extra:.0f} ms (warm-up, not timed)" if extra is not None else ""))
            for c in pts:
                brows.append(f"| {name} | {LABELS.get(b, b)} | {c['spp']} | {fmt(c['time_ms'], '{:.1f}')} | "
                             f"{fmt(c.get('wall_ms'), '{:.0f}')} | {fmt(c['relmse'])} | {fmt(c.get('flip'), '{:.3f}')} | "
                             f"{fmt(c.get('ssim'), '{:.4f}')} |")
    if len(brows) > 2:
        out += "\nBaselines (ms/frame = wall time minus the fitted one-time setup):\n\n" + "\n".join(brows) + "\n\n"
        out += "\n".join(notes) + "\n"
    return out


if __name__ == "__main__":
    sys.stdout.write(main(sys.argv[1:]))
