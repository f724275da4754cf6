#!/usr/bin/env python3
"""One strip figure from a ``gi_compare.py`` output folder: each chosen technique's image
with its relMSE against the Cycles reference and its time, then the reference itself with
its samples and time; with ``--errors`` a second row of error maps.

    .venv/bin/python scripts/make_figure.py out/demo --techniques DIRECT,RTXGI,RESTIR_GI,PT \\
        --out out/demo/strip.jpg [--errors] [--reference full]

Only numpy and matplotlib; the times are the ones gi_compare measured (its results.json
names the OpenGL renderer they come from, and the caption repeats it).
"""
from __future__ import annotations

import argparse
import json
import os


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", help="a gi_compare.py --out folder (results.json and PNGs)")
    ap.add_argument("--techniques", default="", help="comma-separated, in order (default: every entry)")
    ap.add_argument("--reference", default="full", help="which Cycles reference the numbers are against")
    ap.add_argument("--errors", action="store_true", help="add a row of error maps")
    ap.add_argument("--out", default=None, help="image to write (.jpg or .png; default <folder>/strip.jpg)")
    ap.add_argument("--dpi", type=int, default=100)
    a = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    with open(os.path.join(a.folder, "results.json"), encoding="utf-8") as f:
        res = json.load(f)
    entries = [e for e in res["entries"] if e["reference"] == a.reference]
    want = [t for t in a.techniques.split(",") if t]
    if want:
        by = {e["technique"]: e for e in entries}
        missing = [t for t in want if t not in by]
        if missing:
            raise SystemExit(f"make_figure: {', '.join(missing)} not in {a.folder}/results.json")
        entries = [by[t] for t in want]
    ref = (res.get("references") or {}).get(a.reference) or res["reference"]
    cols = len(entries) + 1
    rows = 2 if a.errors else 1
    first = mpimg.imread(os.path.join(a.folder, entries[0]["files"]["png"]))
    h, w = first.shape[:2]
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 2.4 * w / h, rows * 2.4 + 0.5), squeeze=False)

    def show(ax, path, title):
        ax.imshow(mpimg.imread(path))
        ax.set_title(title, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])

    for i, e in enumerate(entries):
        d = e.get("denoiser") or "NONE"
        name = e["technique"] + ("" if d == "NONE" else f" + {d}")
        show(axes[0][i], os.path.join(a.folder, e["files"]["png"]),
             f"{name}\nrelMSE {e['relmse']:.3f} · {e['time_ms']:.0f} ms")
        if a.errors:
            show(axes[1][i], os.path.join(a.folder, e["files"]["error_png"]), "error")
    show(axes[0][-1], os.path.join(a.folder, f"reference_{a.reference}.png"),
         f"Cycles {ref.get('spp')} spp\n{ref.get('time_ms', 0):.0f} ms (CPU)")
    if a.errors:
        axes[1][-1].axis("off")
    device = (res.get("run") or {}).get("device", "")
    import textwrap

    caption = textwrap.fill(f"{res.get('scene', '')}, {res['resolution'][0]}×{res['resolution'][1]} px. "
                            f"Times: {device}", width=int(cols * 2.4 * w / h * 14))
    lines = caption.count("\n") + 1
    fig.text(0.5, 0.01, caption, ha="center", va="bottom", fontsize=6.5)
    fig.tight_layout(rect=(0, 0.03 * lines + 0.01, 1, 1), h_pad=1.5)
    out = a.out or os.path.join(a.folder, "strip.jpg")
    kw = {"pil_kwargs": {"quality": 88}} if out.lower().endswith((".jpg", ".jpeg")) else {}
    fig.savefig(out, dpi=a.dpi, **kw)
    print(out)


if __name__ == "__main__":
    main()
