"""The hard-case matrix: every scene of blender_tests/hard_cases.py x every registered
technique, in validation mode 2 (every pass output checked for NaN/Inf and negative
radiance, and every GL access checked against the declared resources and the barriers issued).

Per cell (``judge``):

* ``finite``: every pixel of the image and of every AOV is finite, none negative;
* ``validator``: the render raised no validation or synchronisation error;
* ``ratio``: the image mean over Cycles' mean for the reference the technique models
  (``direct``, ``one_bounce`` or ``full``), within the technique's factor (``TOLERANCE``);
  screen-space techniques that add an ambient or screen-space term to DIRECT (SSAO, HBAO,
  SSDO, SSR) are judged on what they compute: at least Cycles' direct mean / 1.25 and at
  most 1.5 x Cycles' one-bounce mean;
* ``furnace``: the image mean against the exact answer 1 (every pixel of the white furnace
  is 1, whatever the bounce count: the sphere is convex), within 10 %;
* ``black``: the black scene gives exactly 0 everywhere.

Run (about 10 minutes on llvmpipe, 2 cores):
    flock /tmp/heavy.lock .venv/bin/python scripts/bench_hard_cases.py
Options: --res 32 --spp 64 (Cycles) --samples 4 (accumulated frames) --quality 0
    --scenes a,b --techs X,Y --json docs/results/hard_cases.json --md docs/results/hard_cases.md
    --md-only (rewrite the page from the JSON).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import traceback
from pathlib import Path

os.environ["GI_PREVIEW_VALIDATE"] = "2"

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "blender_tests"))
import conftest  # noqa: E402,F401  (hermetic Blender user folder, gi_preview on sys.path)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import hard_cases  # noqa: E402
from gi_preview.blender import reference  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.render import session, techniques  # noqa: E402

def log(*a):
    print(f"[bench_hard_cases {time.strftime('%H:%M:%S')}]", *a, flush=True)


def export(sc):
    return export_scene(reference.evaluated_depsgraph(sc))


def render_cell(scene: str, sc, sds, tech: str, quality: int, samples: int) -> dict:
    """Render one cell in validation mode; returns the image (or the error) and the time."""
    key = f"hard_{scene}_{tech}"
    t0 = time.perf_counter()
    out = {"error": None, "image": None}
    try:
        r = hard_cases.render(scene, sds, tech, quality, samples, key)
        out["image"] = r.image
        out["aovs_finite"] = all(bool(np.isfinite(a).all()) for a in r.aovs.values())
    except Exception as exc:  # noqa: BLE001  (every failure is a finding of the cell)
        out["error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:300]
        log(scene, tech, "raised", traceback.format_exc(limit=3))
    finally:
        fut = session.release_session(key)
        if fut is not None:
            fut.result()
    out["ms"] = 1000 * (time.perf_counter() - t0)
    return out


def run_scene(name, techs, a) -> dict:
    sc = hard_cases.build(name, a.res)
    try:
        t0 = time.perf_counter()
        sds = hard_cases.scene_data(name, sc)  # the animated scene ends on its last frame
        export_s = time.perf_counter() - t0
        kinds = {"direct", "one_bounce", "full"}
        refs, ref_ms = {}, {}
        for k in sorted(kinds):
            img, ms = hard_cases.render_reference(sc, name, a.spp, k)
            refs[k] = float(img[..., :3].mean())
            ref_ms[k] = ms
        row = {"scene": name, "cycles_mean": refs, "cycles_ms": ref_ms, "export_s": export_s, "cells": {}}
        log(name, "Cycles means", {k: round(v, 5) for k, v in refs.items()})
        for tech in techs:
            o = render_cell(name, sc, sds, tech, a.quality, a.samples)
            cell = {"ms": o["ms"], "error": o["error"]}
            if o["image"] is not None:
                img = o["image"][..., :3]
                cell["finite"] = bool(np.isfinite(img).all()) and o["aovs_finite"]
                cell["nonnegative"] = bool((img >= 0).all()) if cell["finite"] else False
                cell["mean"] = float(np.nan_to_num(img).mean())
                cell.update(hard_cases.judge(name, tech, np.nan_to_num(img), refs))
                cell["pass"] = cell["finite"] and cell["nonnegative"] and cell["ok"]
                if not cell["finite"]:
                    cell["why"] = "non-finite pixels"
                elif not cell["nonnegative"]:
                    cell["why"] = "negative pixels"
            else:
                cell.update({"finite": False, "pass": False, "why": o["error"], "value": None})
            log(name, tech, "PASS" if cell["pass"] else "FAIL", cell.get("value"), cell.get("why", ""),
                f"{cell['ms']:.0f} ms")
            row["cells"][tech] = cell
        return row
    finally:
        bpy.data.scenes.remove(sc)


def _fmt(cell) -> str:
    if cell.get("error"):
        return "FAIL (error)"
    v = cell.get("value")
    s = "-" if v is None else f"{v:.2f}" if abs(v) >= 0.01 or v == 0 else f"{v:.1e}"
    return f"{'pass' if cell['pass'] else '**FAIL**'} {s}"


READING_HEAD = """# Hard cases: every technique on scenes built to break it

Each scene of `blender_tests/hard_cases.py` rendered with every technique at {res}x{res} px,
quality {quality}, {samples} accumulated frames (after the technique's warm-up), in validation
mode 2 (`GI_PREVIEW_VALIDATE=2`: every pass output checked for NaN/Inf and negative radiance,
and every GL access checked against what the pass declares and the barriers issued), against
Cycles at {spp} samples per pixel with the bounce limits of the reference the technique models.

**What a cell shows.** `pass`/`FAIL` and the figure judged:

* most scenes: the image mean over Cycles' mean for the technique's reference (`direct` for
  DIRECT and RESTIR_DI, `one_bounce` for RSM and LPV, `full` for the rest); a pass is within
  {tol}x either way;
* SSAO, HBAO, SSDO, SSR (DIRECT plus a screen-space term): the mean over Cycles' one-bounce
  mean; a pass is at least Cycles' direct mean / {ss_low} and at most {ss_high}x Cycles'
  one-bounce mean;
* `furnace`: the image mean, whose exact value is 1 for every technique (a white convex
  sphere in a white world of radiance 1 reflects exactly what it receives); a pass is
  within {ftol};
* `black`: the largest pixel value, which must be exactly 0.

Every cell must also be finite and non-negative (image and AOVs) and raise no validation or
synchronisation error; `FAIL (error)` names the error below.

Result: **{n_pass} of {n_cells} cells pass**. Whole matrix {total_min:.1f} min on llvmpipe
(Mesa's software rasteriser, 2 cores), Cycles references included.

Reproduce: `.venv/bin/python scripts/bench_hard_cases.py` (writes this page and
[hard_cases.json](hard_cases.json)). The CI part is `blender_tests/test_hard_cases.py`: a subset
of these cells, with the failing ones listed as known failures.

"""

SCENE_NOTES = {
    "thin_wall": "two rooms split by a 2 cm wall, camera in the dim room: leaks show as a high ratio",
    "mirror": "perfect mirror floor (metallic, roughness 0), point lamp without radius",
    "glass": "glass sphere (transmission 1, IOR 1.45)",
    "furnace": "white sphere (albedo 1) in a white world: exact mean 1",
    "camera_inside": "camera inside a closed box with a dim lamp; a bright lamp outside",
    "emissive_only": "closed room lit only by an emissive panel",
    "many_lights": "10,000 point lamps",
    "tiny_scale": "a room 4 mm across",
    "huge_scale": "a room 10 km across",
    "hdri_sun": "HDR world with one texel of sun 1e5x the sky",
    "animated": "a box crossing the frame at 1 m a frame, camera and lamp moving, history kept over 4 frames",
    "degenerate": "zero-area, collinear and 1e-6 m sliver triangles",
    "z_fighting": "two coincident planes, a third 1e-5 m above (Cycles: without the duplicate)",
    "black": "no lamp, no emitter, black world: must be exactly 0",
    "bright_light": "a zero-size lamp and a 1e6 W lamp far away",
    "mirrored_instances": "negative-scale (mirrored) copies of a box and a sphere",
    "missing_texture": "an Image Texture whose file does not exist (Cycles: magenta)",
    "million_triangles": "a lit room around a sphere of a million triangles",
}


def write_md(data: dict, path: Path, readings: dict):
    rows = data["rows"]
    techs = data["settings"]["techniques"]
    cells = [c for r in rows for c in r["cells"].values()]
    s = data["settings"]
    head = READING_HEAD.format(res=s["res"], quality=s["quality"], samples=s["samples"], spp=s["spp"], tol=hard_cases.TOLERANCE,
                               ss_low=hard_cases.SS_LOW, ss_high=hard_cases.SS_HIGH, ftol=hard_cases.FURNACE_TOL,
                               n_pass=sum(c["pass"] for c in cells), n_cells=len(cells),
                               total_min=data["total_s"] / 60)
    lines = [head, "## Scenes\n", "| scene | what | Cycles mean (direct / one bounce / full) |", "|---|---|---|"]
    for r in rows:
        m = r["cycles_mean"]
        lines.append(f"| {r['scene']} | {SCENE_NOTES.get(r['scene'], '')} | "
                     f"{m['direct']:.4g} / {m['one_bounce']:.4g} / {m['full']:.4g} |")
    lines += ["", "## The matrix\n", "| scene | " + " | ".join(techs) + " |", "|---" * (len(techs) + 1) + "|"]
    for r in rows:
        lines.append(f"| {r['scene']} | " + " | ".join(_fmt(r["cells"][t]) if t in r["cells"] else "" for t in techs)
                     + " |")
    lines += ["", "## Failing cells: what fails and why\n"]
    fails = [(r["scene"], t, r["cells"][t]) for r in rows for t in techs if t in r["cells"] and not r["cells"][t]["pass"]]
    if not fails:
        lines.append("None.")
    for scene, tech, c in fails:
        reading = readings.get(f"{scene}/{tech}") or readings.get(f"{scene}/*") or readings.get(f"*/{tech}") or ""
        lines.append(f"* **{scene} / {tech}**: {c.get('why') or 'fails'}. {reading}".rstrip())
    if readings.get("_notes"):
        lines += ["", "## Notes on passing cells\n"] + [f"* {n}" for n in readings["_notes"]]
    path.write_text("\n".join(lines) + "\n")


def load_readings() -> dict:
    """The user-facing explanation of each known failing cell (scripts/hard_cases_readings.json)."""
    p = REPO / "scripts" / "hard_cases_readings.json"
    return json.loads(p.read_text()) if p.exists() else {}


def merge_rows(old: dict, new: dict) -> dict:
    """``old`` with the rows of ``new`` put in place of the rows of the same scenes (in the
    order of hard_cases.SCENES); the total time is the sum of the rows' times, a row measured
    before rows recorded their time counting as an equal share of the old total."""
    if old["settings"] != new["settings"]:
        raise SystemExit(f"--merge: the JSON was measured with other settings: {old['settings']}")
    share = old["total_s"] / max(1, len(old["rows"]))
    by_scene = {r["scene"]: r for r in old["rows"]}
    by_scene.update({r["scene"]: r for r in new["rows"]})
    rows = [by_scene[n] for n in hard_cases.SCENES if n in by_scene]
    return {**old, "rows": rows, "total_s": sum(r.get("s", share) for r in rows)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--quality", type=int, default=0)
    ap.add_argument("--scenes", default=",".join(hard_cases.SCENES))
    ap.add_argument("--techs", default="")
    ap.add_argument("--json", default=str(REPO / "docs" / "results" / "hard_cases.json"))
    ap.add_argument("--md", default=str(REPO / "docs" / "results" / "hard_cases.md"))
    ap.add_argument("--md-only", action="store_true", help="rewrite the page from the JSON")
    ap.add_argument("--merge", action="store_true",
                    help="replace only the rows of --scenes in the existing JSON (same settings required)")
    a = ap.parse_args()
    if a.md_only:
        write_md(json.loads(Path(a.json).read_text()), Path(a.md), load_readings())
        return
    import gi_preview
    gi_preview.register()
    techs = a.techs.split(",") if a.techs else [i.id for i in techniques.available()]
    t0 = time.perf_counter()
    rows = []
    for name in a.scenes.split(","):
        t_row = time.perf_counter()
        rows.append(run_scene(name, techs, a))
        rows[-1]["s"] = time.perf_counter() - t_row
    data = {"settings": {"res": a.res, "spp": a.spp, "samples": a.samples, "quality": a.quality, "techniques": techs,
                         "validate": 2, "device": "llvmpipe (Mesa, CPU), 2 cores"},
            "total_s": time.perf_counter() - t0, "rows": rows}
    if a.merge:
        data = merge_rows(json.loads(Path(a.json).read_text()), data)
    Path(a.json).write_text(json.dumps(data, indent=1))
    write_md(data, Path(a.md), load_readings())
    cells = [c for r in data["rows"] for c in r["cells"].values()]
    log(f"{sum(c['pass'] for c in cells)}/{len(cells)} cells pass; the matrix took {data['total_s']:.0f} s")


if __name__ == "__main__":
    main()
