"""Probe family benchmark (IRRADIANCE_VOLUME, DDGI, RTXGI): heavier numbers than the tests.

1. Quality ladder q0-q3 on the cornell and sunlit_room demos against Cycles "full":
   relMSE, mean ratio, median frame ms, warm-up frames; DIRECT and SSDO as baselines.
2. Dynamics on cornell over 60 viewport-style frames (history kept): the lamp on (frames
   0-19), switched off (20-39), switched on again moved (40-59); relMSE against the Cycles
   reference of each state per frame, plotted.

Writes docs/results/probes/{ladder.json, dynamics.json, dynamics.png}.
Run: flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_probes.py [--res 48] [--spp 256]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "blender_tests"))
import conftest  # noqa: E402,F401  (hermetic Blender user folder, gi_preview on sys.path)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from gi_preview.blender import demo_scenes, reference  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.compare import metrics  # noqa: E402
from gi_preview.render import session  # noqa: E402

TECHS = ("IRRADIANCE_VOLUME", "DDGI", "RTXGI")
OUT = REPO / "docs" / "results" / "probes"


def ladder(res, spp, scenes):
    rows = []
    for name in scenes:
        sc = demo_scenes.build_demo(name, resolution=res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref, ref_ms = reference.render_cycles(sc, spp, "full")
        for tech, levels in [("DIRECT", (1,)), ("SSDO", (1,))] + [(t, (0, 1, 2, 3)) for t in TECHS]:
            for q in levels:
                r = session.render(sd, tech, q, 8)
                row = {"scene": name, "technique": tech, "quality": q, "relmse": metrics.relmse(r.image, ref),
                       "mean_ratio": float(r.image[..., :3].mean() / ref[..., :3].mean()),
                       "frame_ms": r.frame_ms, "warmup_frames": r.warmup_frames, "cycles_ms": ref_ms}
                print(row, flush=True)
                rows.append(row)
        bpy.data.scenes.remove(sc)
    return rows


def dynamics(res, spp, techs):
    sc = demo_scenes.build_demo("cornell", resolution=res)
    lamp = next(o for o in sc.objects if o.type == "LIGHT")
    energy, loc = lamp.data.energy, tuple(lamp.location)
    states = [("on", energy, loc), ("off", 0.0, loc), ("moved", energy, (loc[0] + 0.5, loc[1] + 0.3, loc[2] - 0.6))]
    refs = {}
    for st, e, l in states:
        lamp.data.energy, lamp.location = e, l
        refs[st] = reference.render_cycles(sc, spp, "full")[0]
    out = {}
    for tech in techs:
        errs = []
        for st, e, l in states:
            lamp.data.energy, lamp.location = e, l
            sd = export_scene(reference.evaluated_depsgraph(sc))
            for _ in range(20):
                img = session.render(sd, tech, 1, 1, keep_history=True, session=f"dyn_{tech}").image
                errs.append({"state": st, "relmse": metrics.relmse(img, refs[st]),
                             "mean_abs": float(np.abs(img[..., :3] - refs[st][..., :3]).mean())})
        session.release_session(f"dyn_{tech}")
        out[tech] = errs
        print(tech, [round(e["mean_abs"], 4) for e in errs], flush=True)
    bpy.data.scenes.remove(sc)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--scenes", default="cornell,sunlit_room")
    ap.add_argument("--skip-ladder", action="store_true")
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    if not a.skip_ladder:
        (OUT / "ladder.json").write_text(json.dumps(ladder(a.res, a.spp, a.scenes.split(",")), indent=1))
    dyn = dynamics(a.res, a.spp, ("DIRECT",) + TECHS)
    (OUT / "dynamics.json").write_text(json.dumps(dyn, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for tech, errs in dyn.items():
            ax.plot([e["mean_abs"] for e in errs], label=tech)
        for x in (20, 40):
            ax.axvline(x, color="grey", lw=0.5)
        ax.set_xlabel("frame (0-19 lamp on, 20-39 off, 40-59 on and moved)")
        ax.set_ylabel("mean |ours - Cycles|")
        ax.set_yscale("log")
        ax.legend()
        fig.tight_layout()
        fig.savefig(OUT / "dynamics.png", dpi=100)
    except ImportError:
        print("matplotlib missing: no plot")


if __name__ == "__main__":
    main()
