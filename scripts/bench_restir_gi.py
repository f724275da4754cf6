"""Benchmark of RESTIR_GI, writing ``<out>/results.json`` and PNGs (``--out``, default
``out/bench/restir_gi/``).

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_restir_gi.py [--res 64]
        [--frames 16] [--ref-spp 256] [--parts still,motion,demos,configs] [--out DIR]

Run from the repository root. A run adds its parts to an existing ``<out>/results.json``.

* still: cornell and sunlit_room, still camera, frame ``--frames`` as shown (not accumulated)
  and the accumulated mean of all frames, relMSE against Cycles full: RESTIR_GI (no filter),
  RESTIR_GI + SVGF, RESTIR_GI + ATROUS, SSDO, PT 1 spp, SVGF (PT 1 spp + SVGF); mean
  brightness against Cycles; ms/frame. Images: Cycles | SSDO | RESTIR_GI | RESTIR_GI+SVGF.
* configs: RESTIR_GI variants on both scenes (no reuse, temporal only, spatial only, 1/M,
  the temporal reservoirs as history instead of the spatial ones).
* motion: a camera dolly+pan over ``--motion-frames`` frames on cornell / sunlit_room;
  every frame against a Cycles reference of that frame: relMSE per frame (whole image and
  the pixels disoccluded in that frame, i.e. with no valid reprojection), and the temporal
  stability figure (mean absolute frame-to-frame difference of the shown images) against
  Cycles'. Ghost trail: the disoccluded region's error per frame after a disocclusion,
  against the still-camera level.
* demos: every built-in demo scene renders finitely (RESTIR_GI and RESTIR_GI + SVGF).
Run with the bpy module (tests' conftest style: addon linked as gi_preview on sys.path).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "out" / "bench" / "restir_gi"  # --out


def setup():
    sys.path.insert(0, str(REPO / "scripts"))
    from _checkout import setup_blender
    setup_blender()


def rel(x, ref):
    import numpy as np
    return float(np.mean((x[..., :3] - ref[..., :3]) ** 2 / (ref[..., :3] ** 2 + 1e-2)))


def tonemap(i):
    import numpy as np
    return np.clip(i[..., :3] / (1 + i[..., :3]) * 1.6, 0, 1) ** (1 / 2.2)


def png(imgs, path, gap=2):
    import numpy as np
    try:
        from PIL import Image
    except ImportError:
        return
    h = imgs[0].shape[0]
    cols = []
    for k, i in enumerate(imgs):
        if k:
            cols.append(np.ones((h, gap, 3)))
        cols.append(tonemap(i))
    row = np.concatenate(cols, 1)
    Image.fromarray((row[::-1] * 255).astype(np.uint8)).save(path)


def run(sd, tech, n, sess, props=None, denoiser="NONE", frame_cb=None):
    """``n`` frames of one session (first one a history cut), no warm-up. Returns the shown
    images, the results and the median frame ms."""
    import numpy as np
    from gi_preview.render import session as S
    S.render(sd, tech, 1, 1, session=sess, warmup=False, denoiser=denoiser)
    if props:
        S.set_pass_properties(sess, props)
    imgs, ms, res = [], [], []
    for f in range(n):
        scene = frame_cb(f) if frame_cb else sd
        r = S.render(scene, tech, 1, 1, keep_history=f > 0, warmup=False, session=sess, denoiser=denoiser)
        imgs.append(r.image[..., :3].copy())
        ms.append(r.frame_ms)
        res.append(r)
    S.release_session(sess).result(timeout=60)
    return imgs, res, float(np.median(ms[1:] if n > 1 else ms))


def still(a, results):
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender.export import export_scene
    from gi_preview.blender.reference import evaluated_depsgraph, get_reference
    out = {}
    for scene in a.scenes:
        sc = D.build_demo(scene, resolution=a.res)
        sd = export_scene(evaluated_depsgraph(sc))
        ref = get_reference(sc, "full", a.ref_spp).image[..., :3]
        rows, shots = {}, {}
        for label, tech, den in (("RESTIR_GI", "RESTIR_GI", "NONE"), ("RESTIR_GI+SVGF", "RESTIR_GI", "SVGF"),
                                 ("RESTIR_GI+ATROUS", "RESTIR_GI", "ATROUS"), ("SSDO", "SSDO", "NONE"),
                                 ("PT", "PT", "NONE"), ("SVGF", "SVGF", "NONE")):
            t0 = time.perf_counter()
            imgs, res, ms = run(sd, tech, a.frames, f"s_{scene}_{label}", denoiser=den)
            acc = np.mean(imgs, 0)
            rows[label] = {"ms": ms, "relmse_first": rel(imgs[0], ref), "relmse_last": rel(imgs[-1], ref),
                           "relmse_accumulated": rel(acc, ref), "mean_vs_cycles": float(imgs[-1].mean() / ref.mean()),
                           "mean_acc_vs_cycles": float(acc.mean() / ref.mean()),
                           "finite": bool(np.isfinite(np.asarray(imgs)).all()), "wall_s": time.perf_counter() - t0}
            shots[label] = imgs[-1]
            if tech == "RESTIR_GI" and den == "NONE":
                aov = res[-1].aovs
                for k in ("GI_ReservoirW", "GI_ReservoirM", "GI_IndirectDiffuse", "GI_IndirectGlossy"):
                    if k in aov:
                        rows[label]["aov_mean_" + k] = float(np.asarray(aov[k])[..., :3].mean())
                if "GI_ReservoirW" in aov and "GI_ReservoirM" in aov:
                    w = np.asarray(aov["GI_ReservoirW"])[..., :3]
                    m = np.asarray(aov["GI_ReservoirM"])[..., :3]
                    png([w / max(np.percentile(w, 99), 1e-6), m / max(m.max(), 1e-6)],
                        OUT / f"{scene}_debug_w_m.png")
                ind = sum(np.asarray(aov[k])[..., :3] for k in ("GI_IndirectDiffuse", "GI_IndirectGlossy") if k in aov)
                png([ind], OUT / f"{scene}_indirect.png")
            print(f"{scene} {label}: {json.dumps(rows[label])}", flush=True)
        png([ref, shots["SSDO"], shots["RESTIR_GI"], shots["RESTIR_GI+SVGF"], shots["SVGF"]],
            OUT / f"{scene}_cycles_ssdo_restirgi_restirgi_svgf_svgf.png")
        out[scene] = rows
        bpy.data.scenes.remove(sc)
    results["still"] = out


def configs(a, results):
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender.export import export_scene
    from gi_preview.blender.reference import evaluated_depsgraph, get_reference
    cfg = {"default": {}, "no_reuse": {"temporal": 0, "spatial": 0}, "temporal_only": {"spatial": 0},
           "spatial_only": {"temporal": 0}, "bias_1/M": {"bias_mode": 0},
           "history_temporal (paper)": {"feedback": 0}}
    out = {}
    for scene in a.scenes:
        sc = D.build_demo(scene, resolution=a.res)
        sd = export_scene(evaluated_depsgraph(sc))
        ref = get_reference(sc, "full", a.ref_spp).image[..., :3]
        rows = {}
        for name, props in cfg.items():
            imgs, _r, ms = run(sd, "RESTIR_GI", a.frames, f"c_{scene}_{name}", props={"restir_gi": props})
            acc = np.mean(imgs, 0)
            rows[name] = {"ms": ms, "relmse_first": rel(imgs[0], ref), "relmse_last": rel(imgs[-1], ref),
                          "relmse_accumulated": rel(acc, ref), "mean_acc_vs_cycles": float(acc.mean() / ref.mean())}
            print(f"{scene} {name}: {json.dumps(rows[name])}", flush=True)
        out[scene] = rows
        bpy.data.scenes.remove(sc)
    results["configs"] = out


def motion(a, results):
    """Moving camera through the per-frame comparison (addon/compare/animation.py, the engine
    of ``gi_compare.py --animation``): relMSE per frame, error of the disoccluded pixels, the
    ghost trail against a still camera, the stability figure against Cycles'."""
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender import export, reference
    from gi_preview.compare import animation as A
    from gi_preview.render import session as S
    class Shim:
        """session with "TECH+DENOISER" ids (RESTIR_GI+SVGF): the denoiser option of render()."""
        release_session = staticmethod(S.release_session)

        @staticmethod
        def render(sd, tech, *args, **kw):
            t, _, den = tech.partition("+")
            return S.render(sd, t, *args, denoiser=den or "NONE", **kw)

    out = {}
    techs = a.motion_techniques.split(",")
    for scene in a.scenes:
        for case in a.motions.split(","):
            mo, _, amount = case.partition("@")  # "pan@0.04": a slow pan (amount x the distance)
            try:
                amount = float(amount) if amount else None
            except ValueError:
                raise SystemExit(f"--motions: the amount after '@' must be a number (got {case!r})") from None
            sc = D.build_demo(scene, resolution=a.res)
            spec = A.AnimationSpec(motion=mo, move=a.motion_frames, hold=a.motion_hold, draws=a.motion_draws,
                                   amount=amount)
            mo = case.replace("@", "_")
            t0 = time.perf_counter()
            res = A.run(sc, spec, techs, reference=reference, export=export, session=Shim, width=a.res,
                        height=a.res, log=lambda m: print(m, flush=True))
            anim = res["animation"]
            A.plot_png(anim, str(OUT / f"motion_{scene}_{mo}.png"), f"{scene}: {mo}, {a.res} px")
            row = {"motion": mo, "amount": anim["amount"], "cycles": {k: anim["cycles"][k] for k in
                                                                       ("spp", "denoise", "stability", "noise_floor")},
                   "wall_s": time.perf_counter() - t0}
            for t, v in anim["techniques"].items():
                tr = v.get("trail") or {}
                row[t] = {k: v[k] for k in ("relmse", "disoccluded_relmse", "relmse_moving", "relmse_hold", "stability",
                                            "cycles_stability", "stability_ratio", "hold_flicker", "nonfinite_pixels",
                                            "max_value", "mean_ratio", "frame_ms")}
                row[t]["trail"] = tr
                print(f"{scene} {mo} {t}: stability {v['stability']:.4f} vs Cycles {v['cycles_stability']:.4f} "
                      f"({v['stability_ratio']:.2f}x); trail ratio at +8 {tr.get('ratio_at_8')}, recovered after "
                      f"{tr.get('recovered_after')}", flush=True)
                frames = res["frames"][t]
                picks = A.strip_frames(anim)
                png([res["refs"][i] for i in picks], OUT / f"motion_{scene}_{mo}_cycles.png")
                png([frames[i] for i in picks], OUT / f"motion_{scene}_{mo}_{t}.png")
            out[f"{scene}/{mo}"] = row
            bpy.data.scenes.remove(sc)
    results["motion"] = out


def demos(a, results):
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender.export import export_scene
    from gi_preview.blender.reference import evaluated_depsgraph
    out = {}
    for name, _l, _d in D.DEMO_SCENES:
        sc = D.build_demo(name, resolution=min(a.res, 48))
        sd = export_scene(evaluated_depsgraph(sc))
        for den in ("NONE", "SVGF"):
            imgs, _r, ms = run(sd, "RESTIR_GI", 4, f"d_{name}_{den}", denoiser=den)
            arr = np.asarray(imgs)
            out[f"{name}/{den}"] = {"finite": bool(np.isfinite(arr).all()), "min": float(arr.min()),
                                    "max": float(arr.max()), "ms": ms}
            print(name, den, out[f"{name}/{den}"], flush=True)
        bpy.data.scenes.remove(sc)
    results["demos"] = out


def main():
    global OUT
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--scenes", default="cornell,sunlit_room")
    ap.add_argument("--parts", default="still,configs,demos")
    ap.add_argument("--motion-frames", type=int, default=12)
    ap.add_argument("--motion-hold", type=int, default=10)
    ap.add_argument("--motions", default="orbit,pan", help="motions, each optionally with an amount: pan@0.04")
    ap.add_argument("--motion-techniques", default="RESTIR_GI,RESTIR_GI+SVGF,SVGF")
    ap.add_argument("--motion-draws", type=int, default=1,
                    help="independent noise draws per motion run (trail and stability: means; see animation.py)")
    ap.add_argument("--out", default=str(OUT), help="output folder: results.json and the PNGs "
                    "(default: out/bench/restir_gi)")
    a = ap.parse_args()
    a.scenes = a.scenes.split(",")
    OUT = Path(a.out)
    setup()
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / "results.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    results.update({"res": a.res, "frames": a.frames, "ref_spp": a.ref_spp})
    for part in a.parts.split(","):
        globals()[part](a, results)
        path.write_text(json.dumps(results, indent=1))
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
