#!/usr/bin/env python3
"""Screen-space family (SSAO, HBAO, SSDO, SSR) and AUTO against Cycles on the demo scenes.

    .venv/bin/python scripts/bench_screen_space.py [--scenes cornell,glossy_spheres]
        [--techniques SSAO,HBAO,SSDO,SSR,AUTO] [--quality 0,1,2,3] [--res 96] [--ref-spp 256]
        [--samples 16] [--curve 1,2,4,8,16,32,64] [--out DIR] [--cache DIR]

Every output goes into ``--out``, default ``out/bench/screen_space/`` (images and JSON alike;
the pages' figures in docs/techniques/img are picked from there by hand).

For every scene: Cycles references "ao" (AO node, distance 1 = the AO techniques' default
radius), "direct", "one_bounce" and "full", plus Cycles' own error-vs-time curve against
"one_bounce" and against "ao". For every technique and quality level: an F12-style render
accumulating ``--samples`` frames (time = median frame time, i.e. the cost of one real-time
frame, and time x samples for the accumulated image). Measured:

* AO techniques (SSAO, HBAO; SSDO's visibility too): the ``GI_AO`` AOV vs Cycles "ao"
  (relMSE, FLIP, SSIM) and the equal-error speed-up against Cycles' AO curve;
* every technique (and DIRECT as the baseline): Combined vs "one_bounce" and "full";
  SSR/SSDO and the AO techniques' equal-error speed-up against Cycles' one_bounce curve;
* AUTO (DIRECT + SSDO + SSR planned per scene) the same way, with the passes the planner
  skipped and why (``skipped_passes``).

``--repro corridor,bounce_room,mirror_gradient`` instead measures the family's reproduction
scenes (``blender_tests/scenes_screen_space.py``: reflections in a corridor, light bounced
onto a ceiling, a reflected gradient) at ``--res`` (64 in the pages) against Cycles
"one_bounce": relMSE over the whole image and masked to each named surface (the
reflective floor and gold wall, the indirectly lit ceiling), and the total variation of
the reflections (ours vs Cycles'), and for SSR/AUTO the seam between found reflections and
the miss fallback (the mean luminance step across pixel pairs where SSR's found share
jumps by more than 0.25, ours vs Cycles' on the same pairs), into
``<out>/screen_space_repro.json`` and ``<out>/repro_<scene>_*.png``.

``--motion corridor`` measures SSR's temporal reprojection under camera motion (reflection
lag: reprojection by the reflected point vs by the surface; ``<out>/screen_space_motion.json``).
``--seeds`` writes ``<out>/screen_space_seeds.json``, ``--same-run`` ``<out>/screen_space_same_run.json``
and ``.md`` (with ``--profile``: ``<out>/screen_space_profile.json``).

Writes ``<out>/<scene>_<TECH>_q<Q>.png`` (ours), ``<scene>_cycles_<kind>.png``,
``<scene>_<TECH>_q<Q>_vs_<kind>_error.png`` (relMSE heat map), the AO images, and
``<out>/screen_space_results.json``. The doc pages quote these numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def _import_pkg():
    sys.path.insert(0, HERE)
    from _checkout import import_checkout_package

    import_checkout_package()


def log(msg):
    print(f"[bench_ss {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", default="cornell,glossy_spheres,sunlit_room")
    p.add_argument("--techniques", default="SSAO,HBAO,SSDO,SSR,AUTO")
    p.add_argument("--quality", default="1")
    p.add_argument("--res", type=int, default=96)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--curve", default="1,2,4,8,16,32,64")
    p.add_argument("--out", default=os.path.join(REPO, "out", "bench", "screen_space"),
                   help="output folder: images and JSON (default: out/bench/screen_space)")
    p.add_argument("--cache", default=None)
    p.add_argument("--repro", default="", help="the reproduction scenes (scenes_screen_space.py) instead of the demo scenes")
    p.add_argument("--motion", default="", help="reflection lag under camera motion on these reproduction scenes")
    p.add_argument("--motion-cycles", type=int, default=0, help="with --motion: also compare every frame with "
                   "Cycles one_bounce at this many spp at that frame's camera (error against the truth, not lag alone)")
    p.add_argument("--motion-miss", type=int, default=0, help="with --motion: also SSR with miss_trace 1, its "
                   "fallback accumulated (ssr_fallback_temporal) and of one frame (no temporal pass), each "
                   "against a still render with miss_trace 1 of this many frames (e.g. 64)")
    p.add_argument("--tables", default="", help="print the pages' tables of TECH from <out>/screen_space_results.json")
    p.add_argument("--before", default="", help="with --tables: an earlier results JSON, shown beside")
    p.add_argument("--seeds", default="", help="run-to-run noise: offsets added to every frame's seed "
                   "(e.g. 0,1000,2000); relMSE vs one_bounce per offset for --scenes/--techniques/--quality")
    p.add_argument("--same-run", default="", help="a commit (or a tree with addon/ and shaders/) timed against "
                   "this working tree in one run, renders interleaved (see same_run)")
    p.add_argument("--profile", action="store_true", help="with --same-run: per-pass CPU times (ctx.finish() "
                   "around every pass, median over the accumulated frames) instead of the GL timer queries, "
                   "which llvmpipe answers only for rasterised work (compute passes read 0.0 ms)")
    p.add_argument("--repeats", type=int, default=1, help="with --same-run: render every technique/level this "
                   "many times per tree (alternating), entries keep every repeat")
    p.add_argument("--thin-wall", action="store_true", help="DIRECT's dark-room mean in two_rooms "
                   "(scenes_raster3d, 32 px, q0 and q1, 2 frames): the shadow maps' thin-wall leak")
    p.add_argument("--worker", default="", help=argparse.SUPPRESS)  # same_run's child: a tree to render with
    opts = p.parse_args(argv)
    if opts.worker:
        return worker(opts.worker)
    if opts.same_run:
        _import_pkg()
        return same_run(opts)
    if opts.tables:
        print(tables(opts.tables, os.path.join(opts.out, "screen_space_results.json"), opts.before))
        return None
    _import_pkg()
    if opts.thin_wall:
        return thin_wall()
    if opts.repro:
        return repro(opts)
    if opts.motion:
        return motion(opts)
    if opts.seeds:
        return seeds(opts)
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import imageio, metrics, sweep
    from gi_preview.render import session

    reference.ensure_oiio()
    os.makedirs(opts.out, exist_ok=True)
    techs = [t for t in opts.techniques.split(",") if t]
    levels = [int(q) for q in opts.quality.split(",") if q]
    curve_spp = [int(s) for s in opts.curve.split(",") if s]
    out = {"res": opts.res, "ref_spp": opts.ref_spp, "samples": opts.samples, "scenes": {}}
    jpath = os.path.join(opts.out, "screen_space_results.json")
    if os.path.exists(jpath):
        with open(jpath) as f:
            old = json.load(f)
        if old.get("res") == opts.res:
            out["scenes"] = old.get("scenes", {})

    def png(name, img):
        imageio.write_png(os.path.join(opts.out, name), metrics.view_standard(img))

    for scene_name in [s for s in opts.scenes.split(",") if s]:
        sc = demo_scenes.build_demo(scene_name, resolution=opts.res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        refs, curves = {}, {}
        for kind in ("ao", "direct", "one_bounce", "full"):
            r = reference.get_reference(sc, kind, opts.ref_spp, cache_dir=opts.cache)
            refs[kind] = r
            png(f"{scene_name}_cycles_{kind}.png", r.image)
            log(f"{scene_name}: Cycles {kind} {r.ref_spp if hasattr(r, 'ref_spp') else r.spp} spp "
                f"{r.time_ms:.0f} ms{' (cached)' if r.cached else ''}")
        for kind in ("ao", "one_bounce"):
            cur = reference.cycles_curve(sc, curve_spp, refs[kind])
            curves[kind] = [{"spp": c["spp"], "time_ms": c["time_ms"], "relmse": c["relmse"], "flip": c["flip"]}
                            for c in cur]
            log(f"{scene_name}: Cycles {kind} curve " + ", ".join(
                f"{c['spp']}spp {c['time_ms']:.0f}ms relMSE {c['relmse']:.4f}" for c in curves[kind]))
        # a run of some techniques keeps the other techniques' entries of an earlier run
        entry = {"references": {k: {"spp": r.spp, "time_ms": r.time_ms} for k, r in refs.items()},
                 "cycles_curves": curves, "techniques": dict(out["scenes"].get(scene_name, {}).get("techniques", {}))}
        for tech in ["DIRECT"] + techs:
            for q in (levels if tech != "DIRECT" else [1]):
                session.render(sd, tech, q, 1)  # warm-up: shader compilation, uploads
                t0 = time.perf_counter()
                res = session.render(sd, tech, q, opts.samples)
                wall = (time.perf_counter() - t0) * 1e3
                img = res.image
                base = f"{scene_name}_{tech}_q{q}"
                png(base + ".png", img)
                e = {"frame_ms": res.frame_ms, "accumulated_ms": wall, "samples": res.samples,
                     "nonfinite": int((~np.isfinite(img)).sum()),
                     "skipped_passes": [s.as_dict() for s in res.skipped_passes],
                     "pass_ms": res.pass_ms}
                for kind in ("one_bounce", "full", "direct"):
                    m = metrics.compare(img, refs[kind].image)
                    e[f"vs_{kind}"] = {k: m[k] for k in ("relmse", "flip", "ssim")}
                    if kind != "direct":
                        heat, _ = metrics.heatmap(img, refs[kind].image)
                        imageio.write_png(os.path.join(opts.out, f"{base}_vs_{kind}_error.png"), heat)
                sp = sweep.equal_error_speedup(e["vs_one_bounce"]["relmse"], res.frame_ms * res.samples,
                                               [(c["spp"], c["time_ms"], c["relmse"]) for c in curves["one_bounce"]])
                e["speedup_vs_one_bounce"] = sp
                ind = res.aovs.get("GI_IndirectDiffuse")
                if ind is not None:  # isolated bright pixels of the bounce (SSDO page: the sun-lit room)
                    e["speckles"] = speckles(ind)
                    e["speckles_cycles"] = speckles(refs["one_bounce"].image[..., :3] - refs["direct"].image[..., :3])
                ao = res.aovs.get("GI_AO")
                if ao is not None:
                    ao3 = np.repeat(ao[..., :1], 3, axis=2) if ao.shape[2] == 1 else ao[..., :3]
                    ref_ao = refs["ao"].image[..., :3]
                    m = metrics.compare(ao3, ref_ao)
                    e["ao_vs_cycles"] = {k: m[k] for k in ("relmse", "flip", "ssim")}
                    e["ao_mean"], e["ao_ref_mean"] = float(ao3.mean()), float(ref_ao.mean())
                    e["speedup_ao"] = sweep.equal_error_speedup(
                        m["relmse"], res.frame_ms * res.samples,
                        [(c["spp"], c["time_ms"], c["relmse"]) for c in curves["ao"]])
                    imageio.write_png(os.path.join(opts.out, base + "_ao.png"), np.clip(ao3, 0, 1))
                    heat, _ = metrics.heatmap(ao3, ref_ao)
                    imageio.write_png(os.path.join(opts.out, base + "_ao_error.png"), heat)
                entry["techniques"][f"{tech}_q{q}"] = e
                msg = (f"{scene_name} {tech} q{q}: {res.frame_ms:.1f} ms/frame; vs one_bounce relMSE "
                       f"{e['vs_one_bounce']['relmse']:.4f} FLIP {e['vs_one_bounce']['flip']:.4f}; vs full "
                       f"{e['vs_full']['relmse']:.4f}")
                if "speckles" in e:
                    msg += f"; bounce speckles {e['speckles']} (Cycles {e['speckles_cycles']})"
                if "ao_vs_cycles" in e:
                    msg += (f"; AO relMSE {e['ao_vs_cycles']['relmse']:.4f} FLIP {e['ao_vs_cycles']['flip']:.4f} "
                            f"(mean {e['ao_mean']:.3f} vs {e['ao_ref_mean']:.3f})")
                log(msg)
        imageio.write_png(os.path.join(opts.out, f"{scene_name}_cycles_ao.png"),
                          np.clip(refs["ao"].image[..., :3], 0, 1))
        out["scenes"][scene_name] = entry
        import bpy

        bpy.data.scenes.remove(sc)
        with open(jpath, "w") as f:
            json.dump(out, f, indent=1, default=float)
    log(f"wrote {jpath}")
    return out


def speckles(img, k: float = 3.0, floor: float = 0.01, r: int = 3) -> int:
    """Speckles of a bounce image: pixels whose luminance exceeds ``k`` x the median of their
    (2r+1)^2 neighbourhood and that median by more than ``floor`` (docs/techniques/SSDO.md)."""
    import numpy as np
    from numpy.lib.stride_tricks import sliding_window_view

    x = np.asarray(img, np.float64)[..., :3]
    lum = 0.2126 * x[..., 0] + 0.7152 * x[..., 1] + 0.0722 * x[..., 2]
    med = np.median(sliding_window_view(np.pad(lum, r, mode="edge"), (2 * r + 1, 2 * r + 1)), axis=(-1, -2))
    return int(((lum > k * med) & (lum - med > floor)).sum())


def tables(tech: str, path: str, before: str = "") -> str:
    """The Markdown results table of one technique (with DIRECT's row per scene); with
    ``before``, that earlier run's ms/frame, relMSE vs one_bounce and speed-up vs one_bounce
    each in a "(before)" column beside the current one."""
    with open(path) as f:
        cur = json.load(f)
    old = {}
    if before:
        with open(before) as f:
            old = json.load(f)["scenes"]

    def sp(x):
        v = (x or {}).get("speedup")
        return "n/a" if v is None else f"{v:.2g}×"

    ao = tech != "SSR"
    b = ["(before)"] if old else []
    head = ["scene", "q", "ms/frame", *b, "relMSE vs one_bounce", *b, "FLIP vs one_bounce", "relMSE vs full",
            "speed-up (one_bounce)", *b]
    if ao:
        head += ["AO relMSE", "AO FLIP", "AO mean (Cycles)", "speed-up (AO)"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene, entry in cur["scenes"].items():
        for key in ["DIRECT_q1"] + sorted(k for k in entry["techniques"] if k.startswith(tech + "_q")):
            e = entry["techniques"].get(key)
            if e is None:
                continue
            q = "DIRECT" if key.startswith("DIRECT") else key.split("_q")[-1]
            o = old.get(scene, {}).get("techniques", {}).get(key)
            r = [scene, q, f"{e['frame_ms']:.1f}"]
            if old:
                r.append(f"{o['frame_ms']:.1f}" if o else "–")
            r.append(f"{e['vs_one_bounce']['relmse']:.4g}")
            if old:
                r.append(f"{o['vs_one_bounce']['relmse']:.4g}" if o else "–")
            r += [f"{e['vs_one_bounce']['flip']:.4g}", f"{e['vs_full']['relmse']:.4g}", sp(e.get("speedup_vs_one_bounce"))]
            if old:
                r.append(sp(o.get("speedup_vs_one_bounce")) if o else "–")
            if ao:
                if "ao_vs_cycles" in e and q != "DIRECT":
                    r += [f"{e['ao_vs_cycles']['relmse']:.4g}", f"{e['ao_vs_cycles']['flip']:.4g}",
                          f"{e['ao_mean']:.3f} ({e['ao_ref_mean']:.3f})", sp(e.get("speedup_ao"))]
                else:
                    r += [""] * 4
            rows.append("| " + " | ".join(r) + " |")
    return "\n".join(rows)


def repro(opts):
    """The reproduction scenes: masked errors and reflection total variation."""
    import numpy as np
    import bpy

    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    import scenes_screen_space as S
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import imageio, metrics
    from gi_preview.render import session

    reference.ensure_oiio()
    os.makedirs(opts.out, exist_ok=True)
    techs = ["DIRECT"] + [t for t in opts.techniques.split(",") if t]
    out = {"res": opts.res, "ref_spp": opts.ref_spp, "samples": opts.samples, "scenes": {}}
    path = os.path.join(opts.out, "screen_space_repro.json")
    if os.path.exists(path):  # a run of some scenes or techniques keeps the others of an earlier run
        with open(path) as f:
            old = json.load(f)
        if old.get("res") == opts.res:
            out["scenes"] = old.get("scenes", {})

    def png(name, img):
        imageio.write_png(os.path.join(opts.out, name), metrics.view_standard(img))

    for name in [s for s in opts.repro.split(",") if s]:
        sc = S.build(name, opts.res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref, ref_ms = reference.render_cycles(sc, opts.ref_spp, "one_bounce")
        png(f"repro_{name}_cycles_one_bounce.png", ref)
        masks = S.masks(name, sd, S.material_ids(sd))
        entry = {"cycles_ms": ref_ms, "pixels": {k: int(m.sum()) for k, m in masks.items()},
                 "techniques": dict(out["scenes"].get(name, {}).get("techniques", {}))}
        for k, m in masks.items():
            entry.setdefault("cycles_tv", {})[k] = S.total_variation(ref, m)
        for tech in techs:
            key = f"repro_{name}_{tech}"
            res = session.render(sd, tech, 1, opts.samples, session=key)
            img = res.image
            png(f"repro_{name}_{tech}.png", img)
            heat, _ = metrics.heatmap(img, ref)
            imageio.write_png(os.path.join(opts.out, f"repro_{name}_{tech}_error.png"), heat)
            e = {"relmse": metrics.relmse(img, ref), "frame_ms": res.frame_ms,
                 "nonfinite": int((~np.isfinite(img)).sum()),
                 "skipped": [x.name for x in res.skipped_passes]}
            for k, m in masks.items():
                e[f"relmse_{k}"] = metrics.relmse(img, ref, mask=m)
                e[f"tv_{k}"] = S.total_variation(img, m)
            if tech in ("SSR", "AUTO") and "reflective" in masks:
                # the seam between found reflections and the fallback: the image's gradient
                # across the hit/miss boundaries (SSR's found share jumps by > 0.25), ours vs Cycles'
                found = S.read_resource(key, "ssr.temporal", 4)[..., 3]
                pairs = S.seam_pairs(found, masks["reflective"])
                e["seam_grad"], e["seam_pairs"] = S.seam_gradient(img, pairs)
                e["seam_grad_cycles"], _ = S.seam_gradient(ref, pairs)
            session.release_session(key)
            entry["techniques"][tech] = e
            # ours | Cycles | error side by side: the pages' "paths it cannot represent" figures
            side = np.concatenate([metrics.view_standard(img), metrics.view_standard(ref),
                                   np.asarray(heat, np.float64)[..., :3] / (255.0 if heat.dtype == np.uint8 else 1.0)],
                                  axis=1)
            imageio.write_png(os.path.join(opts.out, f"repro_{name}_{tech}_side.png"), side)
            log(f"{name} {tech}: " + ", ".join(f"{k} {v:.4f}" for k, v in e.items() if isinstance(v, float)))
        out["scenes"][name] = entry
        bpy.data.scenes.remove(sc)
    with open(path, "w") as f:
        json.dump(out, f, indent=1, default=float)
    log(f"wrote {path}")
    return out


def motion(opts):
    """SSR's temporal reprojection under camera motion: the camera dollies along the
    corridor (``STEP`` scene units per frame, 12 frames), rendered viewport-style (one frame
    per call, history kept) with the history reprojected by the reflected point (SSR's
    default) and by the reflecting surface's motion (``reproject_by_hit=False``); each frame is
    compared, masked to the reflective surfaces, with a fresh 16-frame render of SSR at that
    camera (no history, so no lag). Writes ``<out>/screen_space_motion.json`` and
    ``<out>/motion_<scene>_<variant>.png`` (the last frame)."""
    import copy

    import numpy as np

    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    import scenes_screen_space as S
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import imageio, metrics
    from gi_preview.render import session, techniques
    from gi_preview.render.passes.gbuffer import GBufferPass
    from gi_preview.render.passes.shadows import ShadowPass
    from gi_preview.render.techniques.direct import DirectLightPass
    from gi_preview.render.techniques.ssr import SSR, ssr_passes

    class SSRSurfaceMotion(SSR):
        id = "SSR_SURFACE_MOTION"

        def passes(self, q):
            return [GBufferPass(q), ShadowPass(q), DirectLightPass(q), *ssr_passes(q, reproject_by_hit=False)]

    techniques.REGISTRY[SSRSurfaceMotion.id] = SSRSurfaceMotion
    reference.ensure_oiio()
    os.makedirs(opts.out, exist_ok=True)
    step = np.array([0.0, 0.08, 0.0])
    frames = 12
    out = {"res": opts.res, "frames": frames, "step": step.tolist(), "scenes": {}}
    class SSRMissOneFrame(SSR):
        id = "SSR_MISS_ONE_FRAME"

        def passes(self, q):
            return [GBufferPass(q), ShadowPass(q), DirectLightPass(q), *ssr_passes(q, fallback_reproject="none")]

    variants = {"reflected_point": "SSR", "surface_motion": SSRSurfaceMotion.id}
    miss_variants = {}
    if opts.motion_miss:
        techniques.REGISTRY[SSRMissOneFrame.id] = SSRMissOneFrame
        miss_variants = {"miss_temporal": "SSR", "miss_one_frame": SSRMissOneFrame.id}
        out["miss_truth_frames"] = opts.motion_miss
    for name in [s for s in opts.motion.split(",") if s]:
        sc = S.build(name, opts.res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        mask = S.masks(name, sd, S.material_ids(sd))["reflective"]
        errs = {v: [] for v in (*variants, *miss_variants)}
        errs_cyc = {v: [] for v in (*variants, *miss_variants)}
        for key, tech in (("motion_truth_miss", "SSR"), *(("motion_" + v, t) for v, t in miss_variants.items())):
            if miss_variants:
                session.set_pass_properties(key, {"ssr_trace": {"miss_trace": 1}}, technique=tech, quality=1)
        for k in range(frames):
            moved = copy.deepcopy(sd)
            m = moved.camera.matrix_world.astype(np.float64).copy()
            m[:3, 3] += step * k
            moved.camera.matrix_world = m.astype(moved.camera.matrix_world.dtype)
            truth = session.render(moved, "SSR", 1, 16, session="motion_truth").image
            cyc = None
            if opts.motion_cycles:  # Cycles one_bounce (the repro's reference) at this camera
                loc0 = tuple(sc.camera.location)
                sc.camera.location = tuple(float(a + b) for a, b in zip(loc0, step * k))
                cyc = reference.render_cycles(sc, opts.motion_cycles, "one_bounce")[0]
                sc.camera.location = loc0
            for v, tech in variants.items():
                img = session.render(moved, tech, 1, 1, keep_history=True, session="motion_" + v).image
                errs[v].append(metrics.relmse(img, truth, mask=mask))
                if cyc is not None:
                    errs_cyc[v].append(metrics.relmse(img, cyc, mask=mask))
                if k == frames - 1:
                    imageio.write_png(os.path.join(opts.out, f"motion_{name}_{v}.png"), metrics.view_standard(img))
            if miss_variants:
                truth_m = session.render(moved, "SSR", 1, opts.motion_miss, session="motion_truth_miss").image
            for v, tech in miss_variants.items():
                img = session.render(moved, tech, 1, 1, keep_history=True, session="motion_" + v).image
                errs[v].append(metrics.relmse(img, truth_m, mask=mask))
                if cyc is not None:
                    errs_cyc[v].append(metrics.relmse(img, cyc, mask=mask))
                if k == frames - 1:
                    imageio.write_png(os.path.join(opts.out, f"motion_{name}_{v}.png"), metrics.view_standard(img))
            if k == frames - 1:
                imageio.write_png(os.path.join(opts.out, f"motion_{name}_still16.png"), metrics.view_standard(truth))
                if miss_variants:
                    imageio.write_png(os.path.join(opts.out, f"motion_{name}_miss_still{opts.motion_miss}.png"),
                                      metrics.view_standard(truth_m))
        for key in ["motion_truth", "motion_truth_miss"] + ["motion_" + v for v in (*variants, *miss_variants)]:
            session.release_session(key)
        entry = {v: {"per_frame": e, "mean_frames_4_12": float(np.mean(e[3:]))} for v, e in errs.items()}
        for v, e in errs_cyc.items():
            if e:
                entry[v].update(vs_cycles_per_frame=e, vs_cycles_mean_frames_4_12=float(np.mean(e[3:])))
        out["scenes"][name] = entry
        log(f"{name}: reflection error vs a still render, frames 4-12: " + ", ".join(
            f"{v} {entry[v]['mean_frames_4_12']:.4f}" for v in entry))
        if opts.motion_cycles:
            log(f"{name}: reflection error vs Cycles one_bounce ({opts.motion_cycles} spp) at each frame's camera, "
                "frames 4-12: " + ", ".join(f"{v} {entry[v]['vs_cycles_mean_frames_4_12']:.4f}" for v in entry))
        bpy_scene_remove(sc)
    techniques.REGISTRY.pop(SSRSurfaceMotion.id, None)
    techniques.REGISTRY.pop(SSRMissOneFrame.id, None)
    os.makedirs(opts.out, exist_ok=True)
    path = os.path.join(opts.out, "screen_space_motion.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1, default=float)
    log(f"wrote {path}")
    return out


def seeds(opts):
    """Run-to-run noise of the demo numbers: the same F12 render (``--samples`` frames) with
    every frame's seed shifted by each offset of ``--seeds`` (the seed the benchmark uses is
    offset 0), relMSE vs Cycles one_bounce at ``--ref-spp``; prints mean/std per technique
    and level (an earlier checkout can be measured the same way: ``git archive COMMIT``,
    then this script from there). Writes ``<out>/screen_space_seeds.json``."""
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import metrics
    from gi_preview.render import session as S

    reference.ensure_oiio()
    offsets = [int(x) for x in opts.seeds.split(",") if x]
    out = {"res": opts.res, "ref_spp": opts.ref_spp, "samples": opts.samples, "offsets": offsets, "scenes": {}}
    orig = S.FrameState
    try:
        for scene_name in [s for s in opts.scenes.split(",") if s]:
            sc = demo_scenes.build_demo(scene_name, resolution=opts.res)
            sd = export_scene(reference.evaluated_depsgraph(sc))
            ref = reference.get_reference(sc, "one_bounce", opts.ref_spp, cache_dir=opts.cache).image
            entry = out["scenes"].setdefault(scene_name, {})
            for tech in [t for t in opts.techniques.split(",") if t]:
                for q in [int(x) for x in opts.quality.split(",") if x]:
                    vals = []
                    for off in offsets:
                        def shifted(off=off, **kw):
                            kw["sample"] += off
                            kw["seed"] += off
                            return orig(**kw)

                        S.FrameState = shifted
                        S.render(sd, tech, q, 1)
                        vals.append(metrics.relmse(S.render(sd, tech, q, opts.samples).image, ref))
                    entry[f"{tech}_q{q}"] = {"relmse": vals, "mean": float(np.mean(vals)),
                                             "std": float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0}
                    log(f"{scene_name} {tech} q{q}: relMSE per seed offset " + ", ".join(f"{v:.5f}" for v in vals)
                        + f"; mean {np.mean(vals):.5f} std {entry[f'{tech}_q{q}']['std']:.5f}")
            import bpy

            bpy.data.scenes.remove(sc)
    finally:
        S.FrameState = orig
    os.makedirs(opts.out, exist_ok=True)
    path = os.path.join(opts.out, "screen_space_seeds.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1, default=float)
    log(f"wrote {path}")
    return out


SAME_RUN_JSON = "screen_space_same_run.json"  # in --out
PROFILE_JSON = "screen_space_profile.json"


def thin_wall():
    """two_rooms (blender_tests/scenes_raster3d.py): a point light in the left room, the camera
    in the right room behind a zero-thickness wall, where Cycles' direct render is black.
    Prints DIRECT's mean there at q1 and q0 (what shaders/lib/shadows.glsl's nearest-texel
    test is for; test_direct_vs_cycles asserts q1)."""
    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    import scenes_raster3d
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session

    sc = scenes_raster3d.build("two_rooms", 32)
    sd = export_scene(reference.evaluated_depsgraph(sc))
    out = {f"q{q}": float(session.render(sd, "DIRECT", q, 2).image[..., :3].mean()) for q in (1, 0)}
    log("two_rooms DIRECT dark-room mean: " + ", ".join(f"{k} {v:.5f}" for k, v in out.items()))
    return out


def worker(tree: str):
    """same_run's child process: renders with the add-on of ``tree`` (``<tree>/addon`` imported
    as ``gi_preview``, its shaders from ``<tree>/shaders``). Reads one JSON command per line on
    stdin ({"scene", "res"} builds a demo scene; {"tech", "q", "samples", "npy"} renders it
    F12-style after a 1-frame warm-up and saves the image), answers one line starting "@@"."""
    import tempfile

    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="gi_preview_user_"))
    d = tempfile.mkdtemp(prefix="gi_preview_pkg_")
    os.symlink(os.path.join(os.path.abspath(tree), "addon"), os.path.join(d, "gi_preview"), target_is_directory=True)
    sys.path.insert(0, d)
    import importlib

    importlib.import_module("gi_preview")
    import bpy
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session

    sc = sd = None
    frames: list = []

    def reply(obj):
        sys.stdout.write("@@" + json.dumps(obj, default=float) + "\n")
        sys.stdout.flush()

    reply({"ready": tree})
    for line in sys.stdin:
        cmd = json.loads(line)
        if "scene" in cmd:
            if sc is not None:
                bpy.data.scenes.remove(sc)
            sc = demo_scenes.build_demo(cmd["scene"], resolution=int(cmd["res"]))
            sd = export_scene(reference.evaluated_depsgraph(sc))
            reply({"scene": cmd["scene"]})
        elif "tech" in cmd:
            if cmd.get("profile"):
                install_pass_profiler(frames)
            session.render(sd, cmd["tech"], int(cmd["q"]), 1)  # warm-up: shader compilation, uploads
            frames.clear()
            t0 = time.perf_counter()
            res = session.render(sd, cmd["tech"], int(cmd["q"]), int(cmd["samples"]))
            wall = (time.perf_counter() - t0) * 1e3
            np.save(cmd["npy"], np.asarray(res.image, np.float32))
            r = {"frame_ms": res.frame_ms, "accumulated_ms": wall, "samples": res.samples,
                 "pass_ms": res.pass_ms, "load1": os.getloadavg()[0]}
            if cmd.get("profile"):
                r["pass_ms"] = profile_medians(frames)
                r["pass_ms_timer"] = res.pass_ms
            reply(r)
        else:
            break


def install_pass_profiler(frames: list):
    """Per-pass CPU times that mean something on llvmpipe: its GL timer queries time only
    rasterised work (a compute-only pass reads 0.0 ms, a pass with draws gets part of its
    cost), so ``RenderResult.pass_ms`` cannot profile compute passes. Wraps
    ``FrameGraph.execute`` (in this process) so every pass runs between two ``ctx.finish()``
    and is timed with ``perf_counter``; each frame's ``{pass: ms}`` is appended to ``frames``.
    The finishes serialise the frame, so use it for where the time goes, not for frame times."""
    from gi_preview.render import framegraph

    G = framegraph.FrameGraph
    if getattr(G.execute, "_profiled", False):
        G.execute._frames = frames
        return
    orig = G.execute

    def execute(self, rc, frame, *, timers=True):
        times = {}
        for p in self._plan.active:
            if not getattr(p.execute, "_profiled", False):
                inner = p.execute

                def timed(rc_, frame_, _inner=inner, _name=p.name):
                    rc_.ctx.finish()
                    t0 = time.perf_counter()
                    _inner(rc_, frame_)
                    rc_.ctx.finish()
                    execute._times[_name] = (time.perf_counter() - t0) * 1e3

                timed._profiled = True
                p.execute = timed
        execute._times = times
        orig(self, rc, frame, timers=False)
        execute._frames.append(dict(times))
        return dict(times)

    execute._profiled = True
    execute._frames = frames
    G.execute = execute


def profile_medians(frames: list) -> dict:
    """Median ms per pass over the profiled frames (``install_pass_profiler``)."""
    names = {k for f in frames for k in f}
    return {k: round(statistics.median(f.get(k, 0.0) for f in frames), 3) for k in sorted(names)}


class _Worker:
    def __init__(self, tree, label):
        import subprocess

        self.label = label
        self.p = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker", tree],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        self.read()

    def read(self):
        for line in self.p.stdout:
            if line.startswith("@@"):
                return json.loads(line[2:])
        raise RuntimeError(f"the {self.label} worker ended (exit {self.p.wait()})")

    def ask(self, **cmd):
        self.p.stdin.write(json.dumps(cmd) + "\n")
        self.p.stdin.flush()
        return self.read()

    def close(self):
        try:
            self.p.stdin.write(json.dumps({"quit": 1}) + "\n")
            self.p.stdin.close()
        except OSError:
            pass
        self.p.wait(timeout=60)


def same_run(opts):
    """A fair timing of an earlier checkout against this working tree: both render in the SAME
    run, each in its own child process (its own GL context), alternating render by render
    (order swapped every other technique/level so a drifting machine load hits both alike):
    per demo scene, DIRECT q1 and every ``--techniques`` x ``--quality``, F12-style with
    ``--samples`` frames after a 1-frame warm-up. Cycles' one_bounce error-vs-time curve is
    re-timed in the same run (``--curve`` spp) for the equal-error speed-ups; the reference is
    the cached ``--ref-spp`` one_bounce render. Both trees' images are measured with this
    tree's metrics. ``--same-run`` takes a commit (exported with ``git archive``) or a folder.
    Writes ``<out>/screen_space_same_run.json`` (a run of some scenes keeps the others)
    and ``<out>/screen_space_same_run.md`` (the tables)."""
    import subprocess
    import tempfile

    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.compare import metrics, sweep

    reference.ensure_oiio()
    before = opts.same_run
    if not os.path.isdir(before):
        commit = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", before], check=True,
                                capture_output=True, text=True).stdout.strip()
        before = tempfile.mkdtemp(prefix=f"ss_before_{commit}_")
        subprocess.run(f"git -C {REPO} archive {commit} | tar -x -C {before}", shell=True, check=True)
    else:
        commit = os.path.basename(os.path.normpath(before))
    head = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    dirty = [ln[3:] for ln in subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--", "addon", "shaders"],
                                             capture_output=True, text=True).stdout.splitlines()]
    out = {"res": opts.res, "ref_spp": opts.ref_spp, "samples": opts.samples, "scenes": {}}
    os.makedirs(opts.out, exist_ok=True)
    same_run_json = os.path.join(opts.out, SAME_RUN_JSON)
    json_path = os.path.join(opts.out, PROFILE_JSON) if opts.profile else same_run_json  # profiled: own file
    if os.path.exists(json_path):
        with open(json_path) as f:
            old = json.load(f)
        if old.get("res") == opts.res and old.get("samples") == opts.samples:
            out["scenes"] = old.get("scenes", {})
    npy = tempfile.mkdtemp(prefix="ss_same_run_")
    workers = {"before": _Worker(before, "before"), "current": _Worker(REPO, "current")}
    techs = ["DIRECT"] + [t for t in opts.techniques.split(",") if t]
    levels = [int(q) for q in opts.quality.split(",") if q]
    curve_spp = [int(x) for x in opts.curve.split(",") if x]
    try:
        for scene_name in [s for s in opts.scenes.split(",") if s]:
            sc = demo_scenes.build_demo(scene_name, resolution=opts.res)
            ref = reference.get_reference(sc, "one_bounce", opts.ref_spp, cache_dir=opts.cache)
            for w in workers.values():
                w.ask(scene=scene_name, res=opts.res)
            # a run of some techniques keeps the scene's other techniques (each entry carries the
            # speed-ups computed with the Cycles curve of its own run)
            entry = {"when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "before": commit,
                     "current": head + (" + uncommitted edits" if dirty else ""), "uncommitted": dirty,
                     "techniques": dict(out["scenes"].get(scene_name, {}).get("techniques", {}))}
            t_c = time.perf_counter()
            curve = [{"spp": c["spp"], "time_ms": c["time_ms"], "relmse": c["relmse"]}
                     for c in reference.cycles_curve(sc, curve_spp, ref)]
            entry["cycles_curve"] = curve
            log(f"{scene_name}: Cycles one_bounce curve ({time.perf_counter() - t_c:.0f} s) " + ", ".join(
                f"{c['spp']}spp {c['time_ms']:.0f}ms {c['relmse']:.4f}" for c in curve))
            k = 0
            for tech in techs:
                for q in (levels if tech != "DIRECT" else [1]):
                    reps = []
                    for rep in range(max(1, opts.repeats)):
                        order = ("before", "current") if k % 2 == 0 else ("current", "before")
                        k += 1
                        e = {}
                        for side in order:
                            path = os.path.join(npy, f"{scene_name}_{tech}_{q}_{side}.npy")
                            r = workers[side].ask(tech=tech, q=q, samples=opts.samples, npy=path,
                                                  profile=bool(opts.profile))
                            img = np.load(path)
                            rel = metrics.relmse(img, ref.image)
                            sp = sweep.equal_error_speedup(rel, r["frame_ms"] * r["samples"],
                                                           [(c["spp"], c["time_ms"], c["relmse"]) for c in curve])
                            e[side] = {**r, "relmse": rel, "nonfinite": int((~np.isfinite(img)).sum()),
                                       "speedup": sp["speedup"], "speedup_bound": sp["bound"]}
                        reps.append(e)
                        b, c = e["before"], e["current"]
                        log(f"{scene_name} {tech} q{q}{f' repeat {rep + 1}' if opts.repeats > 1 else ''}: ms/frame "
                            f"{b['frame_ms']:.1f} -> {c['frame_ms']:.1f}, relMSE {b['relmse']:.5f} -> "
                            f"{c['relmse']:.5f}, speed-up {b['speedup']} -> {c['speedup']}")
                        if opts.profile:
                            names = list(dict.fromkeys([*b["pass_ms"], *c["pass_ms"]]))
                            log("  per pass ms (before -> now): " + ", ".join(
                                f"{n} {b['pass_ms'].get(n, 0.0):.1f}->{c['pass_ms'].get(n, 0.0):.1f}" for n in names))
                    if len(reps) == 1:
                        e = reps[0]
                    else:  # the repeat with the median frame time per tree; every repeat kept
                        e = {}
                        for side in ("before", "current"):
                            srt = sorted(reps, key=lambda x: x[side]["frame_ms"])
                            e[side] = srt[len(srt) // 2][side]
                        e["repeats"] = [{side: {kk: x[side][kk] for kk in ("frame_ms", "speedup", "speedup_bound",
                                                                             "relmse")} for side in ("before", "current")}
                                        for x in reps]
                    e["when"] = time.strftime("%H:%M UTC", time.gmtime())
                    entry["techniques"][f"{tech}_q{q}"] = e
            out["scenes"][scene_name] = entry
            import bpy

            bpy.data.scenes.remove(sc)
            with open(json_path, "w") as f:
                json.dump(out, f, indent=1, default=float)
    finally:
        for w in workers.values():
            w.close()
    if opts.profile:
        log(f"wrote {json_path}")
        return out
    md = same_run_tables(out)
    with open(os.path.splitext(same_run_json)[0] + ".md", "w") as f:
        f.write(md)
    log(f"wrote {same_run_json} and its .md")
    return out


def same_run_tables(out) -> str:
    """Markdown of a same_run JSON: per scene, ms/frame, relMSE vs one_bounce and equal-error
    speed-up against Cycles one_bounce (the curve timed in that run), before -> current."""
    def sp(x):
        if x.get("speedup") is not None:
            return f"{x['speedup']:.2g}×"
        bd = x.get("speedup_bound") or {}
        return (f"≤{bd['at_most']:.2g}×" if "at_most" in bd else f"≥{bd['at_least']:.2g}×" if "at_least" in bd
                else "n/a")

    lines = ["# Screen-space family: two trees timed in the same run (before -> current)", "",
             f"{out['res']} px, {out['samples']} accumulated frames (ms/frame = median frame), relMSE vs Cycles "
             f"one_bounce at {out['ref_spp']} spp; speed-up = Cycles' time to the same relMSE (its one_bounce curve "
             "timed in the same run) / the technique's accumulated time. Both trees render in one run, alternating "
             "render by render (scripts/bench_screen_space.py --same-run). ≤x: worse than Cycles' cheapest point.", ""]
    for scene, e in out["scenes"].items():
        lines += [f"## {scene} ({e['when']}; before = {e['before']}, current = {e['current']})", "",
                  "| technique | q | ms/frame before | now | ratio | relMSE before | now | speed-up before | now |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for key, x in e["techniques"].items():
            b, c = x["before"], x["current"]
            tech, q = key.rsplit("_q", 1)
            lines.append(f"| {tech} | {q} | {b['frame_ms']:.1f} | {c['frame_ms']:.1f} | "
                         f"{c['frame_ms'] / b['frame_ms']:.2f} | {b['relmse']:.5f} | {c['relmse']:.5f} | "
                         f"{sp(b)} | {sp(c)} |")
        lines.append("")
    return "\n".join(lines)


def bpy_scene_remove(sc):
    import bpy

    bpy.data.scenes.remove(sc)


if __name__ == "__main__":
    main()
