"""Measure AUTO's table: per demo scene, its effect shares and, per candidate of
``techniques/auto.py`` CANDIDATES, the relMSE against Cycles full and the ms/frame.

    /work/heavy .venv/bin/python scripts/sweep_auto.py [--size 32] [--frames 8] [--spp 256] [--repeats 3] [--out addon/render/auto_table.json]
    /work/heavy .venv/bin/python scripts/sweep_auto.py --candidates GI10,SCREEN_PROBES   # add new candidates' rows
    .venv/bin/python scripts/sweep_auto.py --compare   # fixed bundle vs AUTO's choice on scenes outside the table
    .venv/bin/python scripts/sweep_auto.py --loo       # leave-one-out check of AUTO's choice on the table

Writes ``addon/render/auto_table.json`` (the table AUTO reads). ms/frame: per render the mean
interval of the accumulated frames (``RenderResult.frame_ms``, Mesa llvmpipe here), the median
over ``--repeats`` renders (one render when the first takes over ``--slow-ms`` per frame: it
fits no budget a median of the single techniques sets, and a repeat only costs time); the
Cycles references come from the cache.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import import_checkout_package  # noqa: E402

import_checkout_package()
sys.path.insert(0, str(REPO / "blender_tests"))
import bpy  # noqa: E402,F401

from gi_preview.blender import demo_scenes, reference  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.compare import metrics  # noqa: E402
from gi_preview.render import session  # noqa: E402
from gi_preview.render.techniques import auto  # noqa: E402

DEMOS = ("cornell", "glossy_spheres", "sunlit_room", "emissive_panel", "many_lights", "courtyard_loft")


def render(sd, candidate: str | None, frames: int, quality: int, key: str, **auto_opts):
    opts = dict(auto_opts)
    if candidate:
        opts["candidate"] = candidate
    return session.render(sd, "AUTO", quality, frames, session=key, auto=opts)


def measure(sc, sd, ref, candidates, frames, quality, key, repeats=3, slow_ms=1000.0):
    rows, shares = [], None
    for c in candidates:
        t0 = time.perf_counter()
        res = render(sd, c, frames, quality, key, threshold=0.0)
        err = metrics.relmse(res.image, ref)
        shares = res.auto["shares"]
        times = [float(res.frame_ms)]
        while len(times) < max(1, repeats) and times[0] <= slow_ms:
            times.append(float(render(sd, c, frames, quality, key, threshold=0.0).frame_ms))
        ms = statistics.median(times)
        rows.append({"candidate": c, "relmse": round(float(err), 5), "ms": round(ms, 2)})
        print(f"  {c:18s} relMSE {err:.4f}  {ms:7.1f} ms/frame {[round(t) for t in times]} "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)
    return rows, shares


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--quality", type=int, default=1)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3, help="renders per candidate; ms/frame is their median")
    ap.add_argument("--slow-ms", type=float, default=1000.0, help="no repeat for a candidate slower than this")
    ap.add_argument("--scenes", nargs="*", default=list(DEMOS))
    ap.add_argument("--out", default=str(REPO / "addon" / "render" / "auto_table.json"))
    ap.add_argument("--candidates", default="",
                    help="measure only these candidates (comma-separated) and merge their rows into the table at --out")
    ap.add_argument("--compare", action="store_true",
                    help="fixed bundle vs AUTO's choice on scenes outside the table (scenes_probes, scenes_screen_space)")
    ap.add_argument("--loo", action="store_true",
                    help="leave-one-out: each table scene judged by AUTO's choice from the other scenes' rows")
    a = ap.parse_args()
    if a.loo:
        return loo(auto.load_table(a.out))
    if a.compare:
        return compare(a)
    table = {"width": a.size, "height": a.size, "frames": a.frames, "quality": a.quality, "reference": "full",
             "reference_spp": a.spp, "repeats": a.repeats, "device": "Mesa llvmpipe, 2 CPU cores", "scenes": {},
             "rows": []}
    only = [c for c in a.candidates.split(",") if c]
    if only:  # a new candidate: its rows join the table measured before (same settings)
        unknown = set(only) - set(auto.CANDIDATES)
        if unknown:
            raise SystemExit(f"unknown candidates {sorted(unknown)}")
        table = auto.load_table(a.out)
        table["rows"] = [r for r in table["rows"] if r["candidate"] not in only]
    for name in a.scenes:
        sc = demo_scenes.build_demo(name, resolution=a.size)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref = reference.get_reference(sc, "full", a.spp).image
        key = f"sweep_{name}"
        rows, sh = measure(sc, sd, ref, only or list(auto.CANDIDATES), a.frames, a.quality, key, a.repeats, a.slow_ms)
        print(name, {k: round(v, 3) for k, v in sh.items()}, flush=True)
        if not only:
            table["scenes"][name] = {"shares": {k: round(float(v), 5) for k, v in sh.items()}}
        for r in rows:
            table["rows"].append({"scene": name, **r})
        session.release_session(key)
        bpy.data.scenes.remove(sc)
        with open(a.out, "w", encoding="utf-8") as f:
            json.dump(table, f, indent=1)
    print("wrote", a.out)


def loo(table, factor: float = 1.25) -> int:
    """Each table scene left out in turn: AUTO chooses from the other scenes' rows at a budget
    equal to the median ms/frame of the left-out scene's single techniques; judged by the
    left-out scene's own rows (within ``factor`` of the best single technique that fits, not
    worse than DIRECT). Prints one line per scene; returns how many pass."""
    passed = 0
    for name, row in table["scenes"].items():
        rest = {**table, "scenes": {k: v for k, v in table["scenes"].items() if k != name},
                "rows": [r for r in table["rows"] if r["scene"] != name]}
        own = {r["candidate"]: (r["relmse"], r["ms"]) for r in table["rows"] if r["scene"] == name}
        singles = {c: v for c, v in own.items() if c not in auto.COMPOSITIONS}
        budget = statistics.median(v[1] for v in singles.values())
        fit = {c: v for c, v in singles.items() if v[1] <= budget}
        best = min(fit, key=lambda c: fit[c][0])
        plan = auto.choose(row["shares"], rest, table["width"], table["height"], budget_ms=budget)
        e = own[plan.candidate][0]
        ok = e <= factor * fit[best][0] and e <= own["DIRECT"][0]
        passed += ok
        print(f"{name:15s} class {plan.scene_class:15s} budget {budget:6.1f} ms: {plan.candidate:16s} {e:.4f} "
              f"| best fitting {best} {fit[best][0]:.4f} | DIRECT {own['DIRECT'][0]:.4f} | {'pass' if ok else 'FAIL'}")
    print(f"{passed} of {len(table['scenes'])} pass")
    return passed


def compare(a):
    import scenes_probes
    import scenes_screen_space

    builds = [("white_room", scenes_probes.build), ("doorway", scenes_probes.build),
              ("bounce_room", scenes_screen_space.build)]
    for name, build in builds:
        sc = build(name, a.size)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref = reference.get_reference(sc, "full", a.spp).image
        key = f"cmp_{name}"
        old = render(sd, auto.BUNDLE, a.frames, a.quality, key, threshold=0.0)
        new = render(sd, None, a.frames, a.quality, key)
        e_old, e_new = metrics.relmse(old.image, ref), metrics.relmse(new.image, ref)
        print(f"{name}: fixed bundle relMSE {e_old:.4f} ({old.frame_ms:.0f} ms/frame) | AUTO "
              f"{new.auto['candidate']} (class {new.auto['scene_class']}) relMSE {e_new:.4f} "
              f"({new.frame_ms:.0f} ms/frame) | shares "
              f"{ {k: round(v, 3) for k, v in new.auto['shares'].items() if v > 0} }", flush=True)
        session.release_session(key)


if __name__ == "__main__":
    main()
