"""Benchmark of RESTIR_DI on the many-light demo scene, writing ``<out>/results.json`` and PNGs
for a person to look at (and, with --filters, the filters ATROUS/SVGF/TAA on cornell and
sunlit_room).

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_restir.py [--res 64] [--frames 16] [--cold 8]
        [--filters] [--out DIR] [--img-out DIR]

Run from the repository root. ``--out``: default ``out/bench/restir/`` (results.json,
``<scene>_cycles_pt_atrous_svgf_taa.png``); ``--img-out``: the figures
restir_di_many_lights.png and restir_di_debug_w_m_direct.png, default the ``--out`` folder
(docs/techniques/img holds the pages' figures, as JPEG).

many_lights (256 coloured point lights + 3 emissive strips), against Cycles direct-only:

* equal time per frame. The baseline is light sampling by power without reuse (RESTIR_DI's
  pass with ``baseline_spp`` > 0: the shared select_light/sample_light, one shadow ray per
  sample, plus one BSDF ray per sample for the world light that light sampling does not
  cover). Its frame time is measured at 1, 8 and 32 spp on this machine and fitted as
  ``a + b spp``; it then runs with the spp whose fitted time equals RESTIR_DI's measured
  median frame time (each configuration gets its own equal-time baseline).
* "after 1 frame": the mean relMSE of ``--cold`` frames rendered from a cold start (history
  cut before each); "after 16 still frames": the 16th of 16 frames rendered one per call with
  history (temporal reuse on: what a real-time view shows), and 16 frames accumulated by the
  session (what F12 and the still viewport show; temporal = 2 reuses only in the first).
  The baseline's frames are independent: its "1 frame" stands for any single frame.
* every bias mode's mean brightness / Cycles, temporal reuse on and off, shading the kept
  sample only, and the debug views (W, M) as images.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "out" / "bench" / "restir"  # default of --out

CONFIGS = {
    "default (ray-traced visibility, temporal auto)": {},
    "temporal always on": {"temporal": 1},
    "temporal off": {"temporal": 0},
    "bias 1/M": {"bias_mode": 0},
    "bias MIS-normalised": {"bias_mode": 1},
    "shade the kept sample only": {"shade_all": 0},
    "no BSDF candidates": {"bsdf_candidates": 0},
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--cold", type=int, default=8, help="cold-start frames averaged for 'after 1 frame'")
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--only", default="", help="';'-separated config names (default: all)")
    ap.add_argument("--filters", action="store_true", help="also the filters on cornell / sunlit_room")
    ap.add_argument("--out", default=str(OUT), help="output folder (default: out/bench/restir)")
    ap.add_argument("--img-out", default=None, help="folder of the RESTIR_DI figures (default: --out)")
    a = ap.parse_args()
    out_dir = Path(a.out)
    IMG = Path(a.img_out) if a.img_out else out_dir
    sys.path.insert(0, str(REPO / "scripts"))
    from _checkout import setup_blender
    setup_blender()
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender.export import export_scene
    from gi_preview.blender.reference import evaluated_depsgraph, get_reference
    from gi_preview.render import session as S

    def rel(x, ref):
        return float(np.mean((x[..., :3] - ref) ** 2 / (ref ** 2 + 1e-2)))

    def tonemap(i):
        return np.clip(i[..., :3] / (1 + i[..., :3]) * 1.6, 0, 1) ** (1 / 2.2)

    def png(imgs, path, scale=3):
        try:
            from PIL import Image
        except ImportError:
            return
        row = np.concatenate(imgs, 1)
        im = Image.fromarray((row[::-1] * 255).astype(np.uint8))
        im.resize((im.width * scale, im.height * scale), Image.NEAREST).save(path)

    def run(sd, tech, props, n, sess, *, cold=False, aovs=False):
        """n frames in a fresh session: history kept (cut before every frame when cold)."""
        S.render(sd, tech, 1, 1, session=sess, warmup=False)
        if props:
            S.set_pass_properties(sess, props)
        imgs, ms, last = [], [], None
        for f in range(n):
            r = S.render(sd, tech, 1, 1, keep_history=True, camera_cut=(f == 0 or cold), warmup=False, session=sess)
            imgs.append(r.image[..., :3])
            ms.append(r.frame_ms)
            last = r
        S.release_session(sess).result(timeout=60)
        return imgs, float(np.median(ms[1:] if n > 1 else ms)), (last.aovs if aovs else None)

    def accumulate(sd, props, n, sess):
        """A fresh render of n frames accumulated by the session (F12 without warm-up)."""
        S.render(sd, "RESTIR_DI", 1, 1, session=sess, warmup=False)
        S.set_pass_properties(sess, props)
        r = S.render(sd, "RESTIR_DI", 1, n, warmup=False, session=sess)
        S.release_session(sess).result(timeout=60)
        return r.image[..., :3]

    out_dir.mkdir(parents=True, exist_ok=True)
    IMG.mkdir(parents=True, exist_ok=True)
    out_path = out_dir / "results.json"
    results = json.loads(out_path.read_text()) if out_path.exists() else {}
    results.update({"res": a.res, "frames": a.frames, "cold_frames": a.cold, "ref_spp": a.ref_spp})
    sc = D.build_demo("many_lights", resolution=a.res)
    sd = export_scene(evaluated_depsgraph(sc))
    ref = get_reference(sc, "direct", a.ref_spp).image[..., :3]

    # the baseline's cost per sample on this machine: ms = a + b spp
    cal = {}
    for spp in (1, 8, 32):
        _i, ms, _ = run(sd, "RESTIR_DI", {"restir_di": {"baseline_spp": spp}}, 6, f"cal{spp}", cold=True)
        cal[spp] = ms
    xs = np.array(sorted(cal)); ys = np.array([cal[s] for s in xs])
    b, a0 = np.polyfit(xs, ys, 1)
    rows = {"_baseline_calibration": {"ms_at_spp": {str(k): v for k, v in cal.items()}, "fixed_ms": float(a0),
                                      "ms_per_spp": float(b)}}
    print(f"baseline: {a0:.1f} ms + {b:.2f} ms/spp ({cal})", flush=True)
    base_cache = {}

    def baseline(spp):
        if spp not in base_cache:
            cold, bms, _ = run(sd, "RESTIR_DI", {"restir_di": {"baseline_spp": spp}}, a.cold, f"bc{spp}", cold=True)
            imgs = cold
            acc = accumulate(sd, {"restir_di": {"baseline_spp": spp}}, a.frames, f"b{spp}")
            base_cache[spp] = {"spp": spp, "ms": bms, "relmse_1": float(np.mean([rel(i, ref) for i in cold])),
                               "relmse_16_accumulated": rel(acc, ref), "relmse_16th_frame": rel(imgs[-1], ref),
                               "mean_vs_cycles": float(acc.mean() / ref.mean()), "_imgs": (cold[0], acc)}
        return base_cache[spp]

    only = [s.strip() for s in a.only.split(";") if s.strip()]
    for name, props in CONFIGS.items():
        if only and name not in only:
            continue
        p = {"restir_di": props}
        cold, ms_c, _ = run(sd, "RESTIR_DI", p, a.cold, "c_" + name, cold=True)
        imgs, ms, aov = run(sd, "RESTIR_DI", p, a.frames, "r_" + name, aovs=True)
        acc = accumulate(sd, p, a.frames, "a_" + name)
        spp = max(1, int(round((ms - a0) / b)))
        base = baseline(spp)
        row = {"ms": ms, "ms_cold": ms_c, "relmse_1": float(np.mean([rel(i, ref) for i in cold])),
               "relmse_16_accumulated": rel(acc, ref), "relmse_16th_frame": rel(imgs[-1], ref),
               "mean_vs_cycles": float(np.mean(imgs) / ref.mean()),  # the 16 frames with history
               "mean_accumulated_vs_cycles": float(acc.mean() / ref.mean()),
               "mean_16th_frame_vs_cycles": float(imgs[-1].mean() / ref.mean()),
               "baseline": {k: v for k, v in base.items() if not k.startswith("_")}}
        row["gain_1"] = base["relmse_1"] / row["relmse_1"]
        row["gain_16_accumulated"] = base["relmse_16_accumulated"] / row["relmse_16_accumulated"]
        row["gain_16th_frame"] = base["relmse_1"] / row["relmse_16th_frame"]
        rows[name] = row
        print(f"{name}: {ms:.1f} ms, relMSE 1 frame {row['relmse_1']:.4f} (baseline {spp} spp {base['relmse_1']:.4f}, "
              f"{row['gain_1']:.2f}x), 16 accumulated {row['relmse_16_accumulated']:.4f} "
              f"({base['relmse_16_accumulated']:.4f}, {row['gain_16_accumulated']:.2f}x), 16th frame "
              f"{row['relmse_16th_frame']:.4f}; mean/Cycles {row['mean_vs_cycles']:.3f}", flush=True)
        if not props:
            bc, bacc = base["_imgs"]
            png([tonemap(ref), tonemap(cold[0]), tonemap(acc), tonemap(bc), tonemap(bacc)],
                IMG / "restir_di_many_lights.png")
            w = aov.get("GI_ReservoirW")
            m = aov.get("GI_ReservoirM")
            if w is not None and m is not None:
                wl = np.log1p(np.maximum(w[..., :1], 0.0))
                png([np.repeat(wl / max(wl.max(), 1e-9), 3, -1), np.repeat(m[..., :1] / max(m.max(), 1e-9), 3, -1),
                     tonemap(aov["GI_Direct"])], IMG / "restir_di_debug_w_m_direct.png")
    results["restir_di"] = {**results.get("restir_di", {}), **rows} if only else rows
    bpy.data.scenes.remove(sc)
    if a.filters:
        results["filters"] = {}
        for scene in ("cornell", "sunlit_room"):
            sc = D.build_demo(scene, resolution=a.res)
            sd = export_scene(evaluated_depsgraph(sc))
            ref = get_reference(sc, "full", a.ref_spp).image[..., :3]
            r, shots = {}, [tonemap(ref)]
            for tech in ("PT", "ATROUS", "SVGF", "TAA"):
                imgs, ms, _ = run(sd, tech, {}, a.frames, "f_" + tech)
                r[tech] = {"ms": ms, "relmse_first": rel(imgs[0], ref), "relmse_last": rel(imgs[-1], ref),
                           "mean_vs_cycles": float(imgs[-1].mean() / ref.mean())}
                shots.append(tonemap(imgs[-1]))
            png(shots, out_dir / f"{scene}_cycles_pt_atrous_svgf_taa.png", scale=1)
            results["filters"][scene] = r
            bpy.data.scenes.remove(sc)
    out_path.write_text(json.dumps(results, indent=1))
    print(json.dumps(results.get("restir_di", {}), indent=1))


if __name__ == "__main__":
    main()
