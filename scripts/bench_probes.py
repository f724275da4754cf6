"""Probe family benchmark (IRRADIANCE_VOLUME, DDGI, RTXGI): the numbers of the probe pages.

Sections (``--only a,b``; each writes its own JSON into ``--out``, default
``out/bench/probes/``, so they can be run one at a time under the heavy-command lock):

* ``energy``: mean of the image over Cycles "full"'s on the closed white room (one lamp,
  albedo 0.8), the open world-lit furnace (sphere on a floor under a uniform white world)
  and the closed white furnace (every wall albedo 0.8 and emitting 1: exact answer 5
  everywhere) -> energy.json.
* ``leak``: the thin-wall two rooms, with lamp A on and off (lamp B always on): the light
  leaked into the dark room is ours(A on) - ours(A off), beside Cycles' same difference
  (about 0: the wall is closed); also the simpler "mean - Cycles mean" measure. Variants
  (bench-only technique ids) isolate what RTXGI's relocation and placement do: margin
  (-0.5 inner / +0.05 enclosing), relocation off, classification off; per variant the count
  of relocated and inactive probes -> leak.json.
* ``ladder``: quality ladder q0-q3 on cornell and sunlit_room against Cycles "full": relMSE,
  mean ratio, median frame ms, warm-up frames; DIRECT and SSDO beside -> ladder.json.
* ``compare``: scripts/gi_compare.py on cornell and sunlit_room (DIRECT, SSDO, DDGI, RTXGI
  at quality 1; baselines Cycles, Cycles + OIDN, EEVEE) -> compare_<scene>/ and
  speedups.json (equal-error speed-ups per baseline).
* ``dynamics``: cornell, viewport-style frames (history kept): 40 frames lit (not plotted),
  then frame 0 the lamp switched off (energy x 1e-4: an energy of 0 makes the scene unlit
  and the planner skips the probes), frame 30 the lamp back on, moved. Per frame the error
  against the Cycles reference of the current state (mean |ours - Cycles| over the lit
  reference's mean, and relMSE while lit), the settle frame of each switch, and per probe
  the irradiance before/after: the largest residual of a probe after 30 frames off (over
  its lit value), and after the move the largest per-probe difference to a freshly
  converged volume, beside the same statistic between two independent fresh volumes (the
  noise floor) -> dynamics.json, dynamics.png.
* ``ssr``: glossy_room (and the glossy_spheres demo): SSR, RTXGI, and RTXGI_SSR (SSR with
  RTXGI's probe glossy light as its miss fallback) against Cycles "full" -> ssr.json.

Run: flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_probes.py --only energy [--res 48] [--spp 256]
    [--out DIR]
Tables for the pages (from the JSON files in ``--out``): .venv/bin/python scripts/bench_probes.py --tables
The figure docs/results/probes/dynamics.png is regenerated with ``--only dynamics --out
docs/results/probes`` (then delete dynamics.json there, or link it: every file under
docs/results must be linked from a page).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "blender_tests"))
import conftest  # noqa: E402,F401  (hermetic Blender user folder, gi_preview on sys.path)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import scenes_probes  # noqa: E402
from gi_preview.blender import demo_scenes, reference  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.compare import metrics  # noqa: E402
from gi_preview.render import session, techniques  # noqa: E402
from gi_preview.render.gl import get_gl  # noqa: E402
from gi_preview.render.passes import probes as P  # noqa: E402

TECHS = ("IRRADIANCE_VOLUME", "DDGI", "RTXGI")
OUT = REPO / "out" / "bench" / "probes"  # default of --out


def log(*a):
    print(f"[bench_probes {time.strftime('%H:%M:%S')}]", *a, flush=True)


def export(sc):
    return export_scene(reference.evaluated_depsgraph(sc))


def build(name, res):
    if name in scenes_probes.SCENES:
        return scenes_probes.build(name, res)
    return demo_scenes.build_demo(name, resolution=res)


def probes_of(key):
    """Per-probe values of session ``key``'s last graph (see passes/probes.read_probes)."""
    def read():
        sess = session._sessions[key]
        vol = P.find_volume(sess._last_graph)
        return P.read_probes(sess.rc, vol)
    return get_gl().call(read)


# ------------------------------------------------------------ bench-only variants
def register_variants():
    """Technique ids for the leak study (not in the add-on): placement and RTXGI features."""
    from gi_preview.render.passes.gbuffer import GBufferPass
    from gi_preview.render.passes.shadows import ShadowPass
    from gi_preview.render.techniques.direct import DirectLightPass
    from gi_preview.render.techniques.rtxgi import RTXGI, RTXGI_CONFIG
    from gi_preview.render.techniques.ddgi import DDGI, DDGI_CONFIG

    def variant(tid, base, config, **trace):
        cls = type(tid, (base,), {"id": tid, "passes": lambda self, q: [
            GBufferPass(q), ShadowPass(q), DirectLightPass(q), *P.probe_chain(config, q, probe_trace=trace)]})
        techniques.REGISTRY[tid] = cls

    import dataclasses
    variant("DDGI_INNER", DDGI, DDGI_CONFIG, margin=-0.5)
    variant("RTXGI_ENCLOSING", RTXGI, RTXGI_CONFIG, margin=0.05)
    variant("RTXGI_NO_RELOCATION", RTXGI, dataclasses.replace(RTXGI_CONFIG, relocate=False), margin=-0.5)
    variant("RTXGI_NO_CLASSIFY", RTXGI, dataclasses.replace(RTXGI_CONFIG, classify=False), margin=-0.5)
    variant("RTXGI_ENCLOSING_NO_RELOCATION", RTXGI, dataclasses.replace(RTXGI_CONFIG, relocate=False), margin=0.05)


# ------------------------------------------------------------ sections
def energy(res, spp, samples):
    out = []
    for name in ("white_room", "furnace", "furnace_room"):
        sc = build(name, res)
        sd = export(sc)
        ref, ms = reference.render_cycles(sc, spp, "full")
        rm = float(ref[..., :3].mean())
        row = {"scene": name, "cycles_mean": rm, "cycles_ms": ms, "techniques": {}}
        for tech in ("DIRECT",) + TECHS:
            r = session.render(sd, tech, 1, samples)
            img = r.image[..., :3]
            row["techniques"][tech] = {"mean": float(img.mean()), "ratio": float(img.mean() / rm),
                                       "relmse": metrics.relmse(r.image, ref), "warmup_frames": r.warmup_frames,
                                       "finite": bool(np.isfinite(img).all())}
        log(name, json.dumps(row))
        out.append(row)
        bpy.data.scenes.remove(sc)
    return out


def leak(res, spp, samples):
    register_variants()
    sc = build("two_rooms", res)
    lamp_a = next(o for o in sc.objects if o.type == "LIGHT" and "lamp_a" in o.name)
    e_a = lamp_a.data.energy
    ref_on = reference.render_cycles(sc, spp, "full")[0]
    sd_on = export(sc)
    lamp_a.data.energy = e_a * 1e-6
    ref_off = reference.render_cycles(sc, spp, "full")[0]
    sd_off = export(sc)
    lamp_a.data.energy = e_a
    out = {"cycles_mean_on": float(ref_on[..., :3].mean()), "cycles_mean_off": float(ref_off[..., :3].mean()),
           "cycles_leak": float(ref_on[..., :3].mean() - ref_off[..., :3].mean()), "techniques": {}}
    for tech in TECHS + ("DDGI_INNER", "RTXGI_ENCLOSING", "RTXGI_NO_RELOCATION", "RTXGI_NO_CLASSIFY",
                         "RTXGI_ENCLOSING_NO_RELOCATION"):
        key = f"leak_{tech}"
        on = session.render(sd_on, tech, 1, samples, session=key)
        pr = probes_of(key)
        off = session.render(sd_off, tech, 1, samples, session=key + "_off")
        session.release_session(key)
        session.release_session(key + "_off")
        m_on, m_off = float(on.image[..., :3].mean()), float(off.image[..., :3].mean())
        moved = np.linalg.norm(pr["offset"], axis=1) > 1e-6
        row = {"mean_on": m_on, "mean_off": m_off, "leak": m_on - m_off,
               "minus_cycles": m_on - out["cycles_mean_on"], "relmse_on": metrics.relmse(on.image, ref_on),
               "probes": int(len(pr["state"])), "relocated": int(moved.sum()),
               "inactive": int((pr["state"] > 0.5).sum()), "counts": [int(c) for c in pr["counts"]],
               "spacing": [float(s) for s in pr["spacing"]]}
        # probes whose position is within half a cell of the thin wall (x = 0) or outside the shell
        pos = pr["positions"]
        row["near_wall"] = int((np.abs(pos[:, 0]) < 0.5 * pr["spacing"][0]).sum())
        row["outside_shell"] = int(((np.abs(pos[:, 0]) > 4) | (np.abs(pos[:, 1]) > 2) | (pos[:, 2] < 0)
                                    | (pos[:, 2] > 3)).sum())
        log(tech, json.dumps(row))
        out["techniques"][tech] = row
    bpy.data.scenes.remove(sc)
    return out


def ladder(res, spp, samples, scenes):
    rows = []
    for name in scenes:
        sc = build(name, res)
        sd = export(sc)
        ref, ref_ms = reference.render_cycles(sc, spp, "full")
        for tech, levels in [("DIRECT", (1,)), ("SSDO", (1,))] + [(t, (0, 1, 2, 3)) for t in TECHS]:
            for q in levels:
                r = session.render(sd, tech, q, samples)
                row = {"scene": name, "technique": tech, "quality": q, "relmse": metrics.relmse(r.image, ref),
                       "mean_ratio": float(r.image[..., :3].mean() / ref[..., :3].mean()),
                       "frame_ms": r.frame_ms, "warmup_frames": r.warmup_frames, "cycles_ms": ref_ms}
                log(json.dumps(row))
                rows.append(row)
        bpy.data.scenes.remove(sc)
    return rows


def compare(res, spp, scenes):
    """gi_compare.py per scene (its own process), then the speed-ups gathered."""
    out = {}
    for name in scenes:
        d = OUT / f"compare_{name}"
        cmd = [sys.executable, str(REPO / "scripts" / "gi_compare.py"), name, "--techniques",
               "DIRECT,SSDO,DDGI,RTXGI", "--quality", "1", "--res", str(res), "--ref-spp", str(spp),
               "--frames", "3", "--samples", "4", "--reference", "full", "--out", str(d)]
        log(" ".join(cmd))
        subprocess.run(cmd, check=True, cwd=REPO)
        data = json.loads((d / "results.json").read_text())
        # gi_compare's time_ms is frame_ms x samples: an F12 render's warm-up frames (probes
        # converging before accumulation) are not in it; measured here and added as a second
        # speed-up (the warm-up paid once per F12 render; a viewport pays it over its frames)
        sc = build(name, res)
        sd = export(sc)
        warm = {t: session.render(sd, t, 1, 1).warmup_frames for t in ("DDGI", "RTXGI")}
        bpy.data.scenes.remove(sc)
        rows = []
        for e in data["entries"]:
            row = {k: e.get(k) for k in ("technique", "quality", "relmse", "time_ms", "frame_ms", "samples",
                                         "setup_ms")}
            row["warmup_frames"] = warm.get(e["technique"], 0)
            t_incl = e["frame_ms"] * (e["samples"] + row["warmup_frames"])
            row["time_ms_with_warmup"] = t_incl
            row["speedups"] = {}
            for b, v in e["speedups"].items():
                bt = v.get("cycles_time_ms")
                row["speedups"][b] = {"speedup": v.get("speedup"), "bound": v.get("bound"),
                                      "baseline_time_ms": bt, "reason": v.get("reason"),
                                      "speedup_with_warmup": (bt / t_incl) if bt else None,
                                      "bound_with_warmup": ({k2: x * e["time_ms"] / t_incl for k2, x in
                                                             v["bound"].items() if x is not None}
                                                            if v.get("bound") else None)}
            log(name, json.dumps(row))
            rows.append(row)
        out[name] = {"entries": rows, "raw": str(d.relative_to(REPO) / "results.json")}
    return out


def _settle(errs, floor, tol=0.1):
    """First index from which every error stays within floor * (1 + tol) + 1e-4."""
    lim = floor * (1 + tol) + 1e-4
    for i in range(len(errs)):
        if all(e <= lim for e in errs[i:]):
            return i
    return len(errs)


def dynamics(res, spp, techs):
    sc = build("cornell", res)
    lamp = next(o for o in sc.objects if o.type == "LIGHT")
    energy, loc = lamp.data.energy, tuple(lamp.location)
    moved_loc = (loc[0] + 0.5, loc[1] + 0.3, loc[2] - 0.6)
    states = {"lit": (energy, loc), "off": (energy * 1e-4, loc), "moved": (energy, moved_loc)}
    refs, sds = {}, {}
    for st, (e, l) in states.items():
        lamp.data.energy, lamp.location = e, l
        refs[st] = reference.render_cycles(sc, spp, "full")[0]
        sds[st] = export(sc)
    norm = float(refs["lit"][..., :3].mean())
    out = {"frames": "0-29 lamp off (x1e-4), 30-59 lamp on and moved by (0.5, 0.3, -0.6); 40 lit frames before",
           "norm_mean_lit_cycles": norm, "techniques": {}}
    for tech in techs:
        key = f"dyn_{tech}"

        def frame(st):
            return session.render(sds[st], tech, 1, 1, keep_history=True, session=key).image

        for _ in range(40):
            frame("lit")
        is_probe = tech in TECHS
        pr_lit = probes_of(key) if is_probe else None
        errs = []
        pr_off = None
        for i in range(60):
            st = "off" if i < 30 else "moved"
            img = frame(st)
            errs.append({"frame": i, "state": st,
                         "mae_rel": float(np.abs(img[..., :3] - refs[st][..., :3]).mean() / norm),
                         "relmse": metrics.relmse(img, refs[st]) if st != "off" else None})
            if i == 29 and is_probe:
                pr_off = probes_of(key)
        row = {"errors": errs}
        mae = [e["mae_rel"] for e in errs]
        row["settle_off"] = _settle(mae[:30], float(np.mean(mae[25:30])))
        row["settle_moved"] = _settle(mae[30:], float(np.mean(mae[55:60])))
        if is_probe:
            pr_dyn = probes_of(key)
            session.release_session(key)
            act = (pr_lit["state"] < 0.5) & (pr_off["state"] < 0.5)
            lum = lambda e: e @ np.array([0.2126, 0.7152, 0.0722])  # noqa: E731
            l_lit, l_off = lum(pr_lit["irradiance"]), lum(pr_off["irradiance"])
            floor = 0.01 * float(l_lit[act].mean())
            resid = l_off[act] / np.maximum(l_lit[act], floor)
            row["off_residual_max"] = float(resid.max())
            row["off_residual_mean"] = float(resid.mean())
            row["off_min_irradiance"] = float(l_off[act].min())  # stuck dark is not possible off; kept for the record
            # a freshly converged volume of the moved state (F12 warm-up), and a second
            # independent one (viewport-style, other seeds) for the noise floor
            session.render(sds["moved"], tech, 1, 1, session=key + "_fresh")
            pr_f = probes_of(key + "_fresh")
            for _ in range(64):
                session.render(sds["moved"], tech, 1, 1, keep_history=True, session=key + "_fresh2")
            pr_f2 = probes_of(key + "_fresh2")
            for k in ("_fresh", "_fresh2"):
                session.release_session(key + k)
            act2 = (pr_dyn["state"] < 0.5) & (pr_f["state"] < 0.5) & (pr_f2["state"] < 0.5)
            lf, ld, lf2 = lum(pr_f["irradiance"]), lum(pr_dyn["irradiance"]), lum(pr_f2["irradiance"])
            fl = 0.05 * float(lf[act2].mean())
            d_dyn = (ld[act2] - lf[act2]) / np.maximum(lf[act2], fl)
            d_noise = (lf2[act2] - lf[act2]) / np.maximum(lf[act2], fl)
            row.update(moved_probe_diff_max=float(np.abs(d_dyn).max()), moved_probe_diff_p95=float(
                np.percentile(np.abs(d_dyn), 95)), moved_probe_diff_min=float(d_dyn.min()),
                moved_probe_diff_signed_max=float(d_dyn.max()),
                noise_probe_diff_max=float(np.abs(d_noise).max()),
                noise_probe_diff_p95=float(np.percentile(np.abs(d_noise), 95)), probes=int(act2.sum()))
        else:
            session.release_session(key)
        log(tech, json.dumps({k: v for k, v in row.items() if k != "errors"}))
        log(tech, "mae_rel per frame", [round(x, 4) for x in mae])
        out["techniques"][tech] = row
    bpy.data.scenes.remove(sc)
    return out


def plot_dynamics(dyn):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib missing: no plot")
        return
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    for tech, row in dyn["techniques"].items():
        ax.plot([e["mae_rel"] for e in row["errors"]], label=tech, lw=1.2)
    ax.axvline(30, color="grey", lw=0.6)
    ax.set_xlabel("frame (0-29 lamp switched off, 30-59 back on and moved)")
    ax.set_ylabel("mean |ours - Cycles| / lit mean")
    ax.set_yscale("log")
    ax.set_title("cornell, viewport-style frames against Cycles full of each state")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "dynamics.png", dpi=100)


def ssr(res, spp, samples):
    out = []
    for name in ("glossy_room", "glossy_spheres"):
        sc = build(name, res)
        sd = export(sc)
        ref = reference.render_cycles(sc, spp, "full")[0]
        row = {"scene": name, "techniques": {}}
        for tech in ("DIRECT", "SSR", "RTXGI", "RTXGI_SSR"):
            r = session.render(sd, tech, 1, samples)
            row["techniques"][tech] = {"relmse": metrics.relmse(r.image, ref),
                                       "mean_ratio": float(r.image[..., :3].mean() / ref[..., :3].mean()),
                                       "frame_ms": r.frame_ms}
        log(json.dumps(row))
        out.append(row)
        bpy.data.scenes.remove(sc)
    return out


def _fmt_speedup(v, key="speedup", bkey="bound"):
    if v.get(key) is not None:
        return f"{v[key]:.3g}×"
    b = v.get(bkey) or {}
    if b.get("at_most") is not None:
        return f"≤{b['at_most']:.3g}×"
    if b.get("at_least") is not None:
        return f"≥{b['at_least']:.3g}×"
    return "n/a"


def tables():
    """Markdown tables of the JSON results present (for the docs pages)."""
    def load(name):
        f = OUT / f"{name}.json"
        return json.loads(f.read_text())["data"] if f.exists() else None

    sp = load("speedups")
    if sp:
        print("| scene | technique | relMSE | ms/frame | warm-up | Cycles | Cycles + OIDN | EEVEE |")
        print("|---|---|---|---|---|---|---|---|")
        for scene, d in sp.items():
            for e in d["entries"]:
                cells = []
                for b in ("cycles", "cycles_denoised", "eevee"):
                    v = (e.get("speedups") or {}).get(b)
                    if not v:
                        cells.append("–")
                        continue
                    t = _fmt_speedup(v)
                    if e["warmup_frames"]:
                        t += f" ({_fmt_speedup(v, 'speedup_with_warmup', 'bound_with_warmup')} with warm-up)"
                    cells.append(t)
                print(f"| {scene} | {e['technique']} | {e['relmse']:.4f} | {e['frame_ms']:.0f} | {e['warmup_frames']} | "
                      + " | ".join(cells) + " |")
    dyn = load("dynamics")
    if dyn:
        print("\n| technique | settle after off (frames) | settle after move | error at frame 29 | at 59 | "
              "probe residual off (max) | moved probe diff max / p95 | noise floor max / p95 |")
        print("|---|---|---|---|---|---|---|---|")
        for t, r in dyn["techniques"].items():
            e = [x["mae_rel"] for x in r["errors"]]
            pr = (f"{r['off_residual_max']:.4f} | {r['moved_probe_diff_max']:.3f} / {r['moved_probe_diff_p95']:.3f} | "
                  f"{r['noise_probe_diff_max']:.3f} / {r['noise_probe_diff_p95']:.3f}") if "off_residual_max" in r else "– | – | –"
            print(f"| {t} | {r['settle_off']} | {r['settle_moved']} | {e[29]:.4f} | {e[59]:.4f} | {pr} |")
    ss = load("ssr")
    if ss:
        print("\n| scene | DIRECT | SSR | RTXGI | RTXGI_SSR |")
        print("|---|---|---|---|---|")
        for row in ss:
            t = row["techniques"]
            print(f"| {row['scene']} | " + " | ".join(f"{t[k]['relmse']:.4f}" for k in ("DIRECT", "SSR", "RTXGI", "RTXGI_SSR"))
                  + " |")


def main():
    global OUT
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--scenes", default="cornell,sunlit_room")
    ap.add_argument("--only", default="energy,leak,ladder,compare,dynamics,ssr")
    ap.add_argument("--tables", action="store_true", help="print the markdown tables of the stored results")
    ap.add_argument("--out", default=str(OUT), help="output folder (default: out/bench/probes)")
    a = ap.parse_args()
    OUT = Path(a.out)
    if a.tables:
        tables()
        return
    OUT.mkdir(parents=True, exist_ok=True)
    only = a.only.split(",")
    meta = {"res": a.res, "spp": a.spp, "samples": a.samples, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}

    def write(name, data):
        (OUT / f"{name}.json").write_text(json.dumps({"settings": meta, "data": data}, indent=1))

    if "energy" in only:
        write("energy", energy(a.res, a.spp, a.samples))
    if "leak" in only:
        write("leak", leak(a.res, a.spp, a.samples))
    if "ladder" in only:
        write("ladder", ladder(a.res, a.spp, a.samples, a.scenes.split(",")))
    if "compare" in only:
        write("speedups", compare(a.res, a.spp, a.scenes.split(",")))
    if "dynamics" in only:
        dyn = dynamics(a.res, a.spp, ("DIRECT",) + TECHS)
        write("dynamics", dyn)
        plot_dynamics(dyn)
    if "ssr" in only:
        write("ssr", ssr(a.res, a.spp, a.samples))


if __name__ == "__main__":
    main()
