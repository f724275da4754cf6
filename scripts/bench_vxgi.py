#!/usr/bin/env python3
"""VXGI (voxel cone tracing) measured against Cycles: accuracy, leaks, stability, demo sweeps.

    cd /work/main && flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_vxgi.py
        [--accuracy] [--leak] [--stability] [--sweep] [--res 48] [--ref-spp 128] [--qualities 0,1,2,3]
        [--out docs/results/vxgi] [--images [--img-res 40] [--img-quality 0]]

* ``--audit``: energy audit (q0/q1 of --qualities): a white furnace in the voxel domain (a
  closed box whose voxels show a known radiance L must give E = pi L) and the Cornell box's
  indirect light per wall against Cycles' one-bounce / full indirect light, for the
  default and with each loss-related parameter changed.
* ``--accuracy``: cornell and sunlit_room, VXGI q0-q3 (multi-bounce on; off too at q0, q1) and DIRECT
  against Cycles "full" (the bounce-matched reference: VXGI with multi-bounce models every
  bounce): relMSE, mean over the reference's mean, frame and setup time.
* ``--leak``: two_rooms (scenes_raster3d: a zero-thickness wall between a lit room and the
  dark room the camera is in): the dark room's mean minus Cycles', over the lit room's
  Cycles mean, for the default and each mitigation (thicker voxelisation, opacity bias,
  both).
* ``--stability``: cornell, 60 frames with a moving light and a moving camera (history
  kept, one frame each, as the viewport), Cycles 64 spp per frame: finite, minimum, and the
  frame-to-frame mean |difference| of ours against Cycles' (the test_raster3d method).
* ``--sweep``: scripts/gi_compare.py on every demo scene, DIRECT and VXGI at q0-q3 against
  the reference each models and "full" (relMSE, FLIP, time per frame, setup time,
  equal-error speed-up against Cycles' curve), into ``<out>/<scene>/``; ``<out>/sweep.md``.
* ``--images``: docs/techniques/img/vxgi_cornell.png and vxgi_sunlit_room.png with the current
  defaults: Cycles full ``--ref-spp`` | VXGI ``--img-quality`` | per-pixel relMSE (viridis,
  log10 1e-4..1) | GI_VXGI_Voxels, ``--img-res`` px, each panel scaled 4x; relMSE and
  mean / Cycles' mean printed and written to ``<out>/images.json``. Not part of the default run.
With no section flag, --accuracy, --leak, --stability and --sweep run (--audit, --images only
when asked). Results: ``<out>/bench.json`` and ``<out>/bench.md``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEMOS = ("cornell", "glossy_spheres", "sunlit_room", "emissive_panel", "many_lights")


def _setup():
    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    import conftest  # noqa: F401  (hermetic Blender user folder, `import gi_preview`)


def _props(sess, props):
    from gi_preview.render import session

    session.set_pass_properties(sess, props)


def render_vxgi(sd, quality, samples, props=None, sess="bench_vxgi"):
    from gi_preview.render import session

    if props:  # set on the session's graph before its first frame
        session.set_pass_properties(sess, props, "VXGI", quality)
    r = session.render(sd, "VXGI", quality, samples, session=sess)
    fut = session.release_session(sess)  # asynchronous: wait, or the next set_pass_properties
    if fut is not None:                  # lands on this session and the next render gets defaults
        fut.result()
    return r


def accuracy(o, out):
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import metrics
    from gi_preview.render import session

    rows = []
    for scene in ("cornell", "sunlit_room"):
        sc = demo_scenes.build_demo(scene, resolution=o.res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref = reference.render_cycles(sc, o.ref_spp, "full")[0]
        one = reference.render_cycles(sc, o.ref_spp, "one_bounce")[0]
        d = session.render(sd, "DIRECT", 1, o.samples)
        rows.append({"scene": scene, "technique": "DIRECT", "quality": 1, "multi_bounce": None,
                     "relmse_full": metrics.relmse(d.image, ref), "relmse_one_bounce": metrics.relmse(d.image, one),
                     "mean_ratio_full": float(d.image[..., :3].mean() / ref[..., :3].mean()),
                     "frame_ms": d.frame_ms, "setup_ms": d.setup_ms})
        for q in o.qualities:
            for mb in ((True, False) if q <= 1 else (True,)):
                r = render_vxgi(sd, q, o.samples, None if mb else {"vxgi_inject": {"multi_bounce": False}})
                img = r.image
                rows.append({"scene": scene, "technique": "VXGI", "quality": q, "multi_bounce": mb,
                             "relmse_full": metrics.relmse(img, ref), "relmse_one_bounce": metrics.relmse(img, one),
                             "mean_ratio_full": float(img[..., :3].mean() / ref[..., :3].mean()),
                             "finite": bool(np.isfinite(img).all()), "min": float(img.min()),
                             "frame_ms": r.frame_ms, "setup_ms": r.setup_ms, "warmup_frames": r.warmup_frames,
                             "pass_ms": {k: round(v, 2) for k, v in r.pass_ms.items()}})
                print(json.dumps(rows[-1]), flush=True)
        bpy.data.scenes.remove(sc)
    return rows


WALLS = (("floor", 2, 1), ("ceiling", 2, -1), ("red (-x)", 0, 1), ("green (+x)", 0, -1), ("back (+y)", 1, -1))


def _per_wall(values, ref, normal):
    """Mean of values over ref's mean on each axis-aligned wall (by the shading normal);
    'boxes' = the rest."""
    import numpy as np

    out, rest = {}, np.ones(values.shape, bool)
    for name, ax, sg in WALLS:
        m = normal[..., ax] * sg > 0.98
        rest &= ~m
        if m.any():
            out[name] = float(values[m].mean() / max(ref[m].mean(), 1e-9))
    if rest.any():
        out["boxes"] = float(values[rest].mean() / max(ref[rest].mean(), 1e-9))
    return out


AUDIT_CONFIGS = (
    ("default", {}),
    ("edge opacity 0", {"vxgi_inject": {"edge_opacity": 0.0}}),
    ("edge opacity 0.3", {"vxgi_inject": {"edge_opacity": 0.3}}),
    ("footprint cap 1", {"vxgi_inject": {"footprint_cap": 1.0}, "vxgi_trace": {"footprint_cap": 1.0}}),
    ("footprint cap 0 (off)", {"vxgi_inject": {"footprint_cap": 0.0}, "vxgi_trace": {"footprint_cap": 0.0}}),
    ("normal offset 1.5", {"vxgi_inject": {"normal_offset": 1.5}, "vxgi_trace": {"normal_offset": 1.5}}),
    ("thickness 0", {"vxgi_voxelize": {"thickness": 0.0}}),
    ("opacity x2", {"vxgi_inject": {"opacity_scale": 2.0}, "vxgi_trace": {"opacity_scale": 2.0}}),
)


def _merge(a, b):
    out = {k: dict(v) for k, v in a.items()}
    for k, v in b.items():
        out.setdefault(k, {}).update(v)
    return out


def audit(o, out):
    """Energy audit. (1) White furnace in the voxel domain: a closed box whose voxels all
    show radiance L (``audit_radiance``), E / (pi L) at every pixel should be 1. (2) The
    Cornell box's indirect light per wall: VXGI's GI_IndirectDiffuse with multi-bounce off
    against Cycles' one_bounce - direct, on against full - direct."""
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene

    import scenes_raster3d

    rows = []
    fur = scenes_raster3d.build("furnace_box", o.res)
    sd_f = export_scene(reference.evaluated_depsgraph(fur))
    cb = demo_scenes.build_demo("cornell", resolution=o.res)
    sd_c = export_scene(reference.evaluated_depsgraph(cb))
    full = reference.render_cycles(cb, 256, "full")[0][..., :3].mean(axis=2)
    one = reference.render_cycles(cb, 256, "one_bounce")[0][..., :3].mean(axis=2)
    dire = reference.render_cycles(cb, 256, "direct")[0][..., :3].mean(axis=2)
    for q in (x for x in o.qualities if x <= 1):
        for label, props in AUDIT_CONFIGS:
            p = _merge({"vxgi_inject": {"audit_radiance": 1.0, "multi_bounce": False},
                        "vxgi_trace": {"audit_radiance": 1.0}}, props)
            r = render_vxgi(sd_f, q, 1, p)
            e = r.aovs["GI_IndirectDiffuse"][..., :3].mean(axis=2)
            row = {"quality": q, "config": label, "furnace_mean": float(e.mean()), "furnace_min": float(e.min()),
                   "furnace_p10": float(np.percentile(e, 10)),
                   "furnace_walls": _per_wall(e, np.ones_like(e), r.aovs["Normal"])}
            for mb, ref, key in ((False, one - dire, "one_bounce"), (True, full - dire, "full")):
                r = render_vxgi(sd_c, q, o.samples, _merge({"vxgi_inject": {"multi_bounce": mb}}, props))
                ind = r.aovs["GI_IndirectDiffuse"][..., :3].mean(axis=2)
                row[f"cornell_indirect_vs_{key}"] = float(ind.mean() / ref.mean())
                row[f"cornell_walls_vs_{key}"] = _per_wall(ind, ref, r.aovs["Normal"])
                if mb:
                    row["cornell_mean_vs_full"] = float(r.image[..., :3].mean() / full.mean())
            rows.append(row)
            print(json.dumps(row), flush=True)
    bpy.data.scenes.remove(fur)
    bpy.data.scenes.remove(cb)
    return rows


OLD_EDGE = {"vxgi_inject": {"edge_opacity": 0.05, "footprint_cap": 0.0}, "vxgi_trace": {"footprint_cap": 0.0}}
LEAK_CONFIGS = (
    ("no mitigation (thickness 0, edge opacity 0.05, no footprint cap)",
     {"vxgi_voxelize": {"thickness": 0.0}, **OLD_EDGE}),
    ("thickness 1, edge opacity 0.05, no footprint cap", OLD_EDGE),
    ("thickness 0 (edge opacity 0.1, footprint cap 0.35)", {"vxgi_voxelize": {"thickness": 0.0}}),
    ("default (thickness 1, edge opacity 0.1, footprint cap 0.35)", {}),
    ("default, edge opacity 0.3", {"vxgi_inject": {"edge_opacity": 0.3}}),
    ("default, edge opacity 0", {"vxgi_inject": {"edge_opacity": 0.0}}),
    ("default, opacity x2", {"vxgi_inject": {"opacity_scale": 2.0}, "vxgi_trace": {"opacity_scale": 2.0}}),
    ("default, thickness 2", {"vxgi_voxelize": {"thickness": 2.0}}),
)


def leak(o, out):
    import bpy
    import numpy as np
    import scenes_raster3d
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene

    dark = scenes_raster3d.build("two_rooms", o.res)
    lit = scenes_raster3d.build("two_rooms", o.res, lit_camera=True)
    sd = export_scene(reference.evaluated_depsgraph(dark))
    ref_dark = reference.render_cycles(dark, o.ref_spp, "full")[0]
    lit_level = float(reference.render_cycles(lit, o.ref_spp, "full")[0][..., :3].mean())
    rows = []
    for q in (x for x in o.qualities if x <= 1):
        for label, props in LEAK_CONFIGS:
            r = render_vxgi(sd, q, o.samples, props)
            img = r.image
            rows.append({"quality": q, "config": label, "dark_mean": float(img[..., :3].mean()),
                         "cycles_dark_mean": float(ref_dark[..., :3].mean()), "lit_mean": lit_level,
                         "leak": float(img[..., :3].mean() - ref_dark[..., :3].mean()) / lit_level,
                         "finite": bool(np.isfinite(img).all())})
            print(json.dumps(rows[-1]), flush=True)
    bpy.data.scenes.remove(dark)
    bpy.data.scenes.remove(lit)
    return rows


def stability(o, out, frames=60):
    """60 frames, moving light and camera, one frame each with history kept (as the viewport
    and an animation after its first frame); the first frame needs no warm-up (the injection
    converges within a reset frame). DIRECT runs the same frames in the same run: its steps
    are the G-buffer's own (edges at 32 px), the floor under any technique built on it."""
    import bpy
    import numpy as np
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session

    q = o.stability_quality
    sc = demo_scenes.build_demo("cornell", resolution=32)
    light = next(ob for ob in sc.objects if ob.type == "LIGHT")
    cam = sc.camera
    l0, c0 = light.location.copy(), cam.location.copy()
    ours, direct, cyc, mins, finite, ms = [], [], [], [], True, []
    for k in range(frames):
        s = k / 10.0  # the 6-frame test's path, 10 times finer
        light.location.x = l0.x - 0.3 + 0.12 * s
        light.location.y = l0.y + 0.1 * math.sin(s)
        cam.location.x = c0.x + 0.05 * s
        cam.location.z = 1.0 + 0.02 * s
        sd = export_scene(reference.evaluated_depsgraph(sc))
        r = session.render(sd, "VXGI", q, 1, keep_history=True, session="bench_vxgi_motion")
        img = r.image[..., :3]
        finite &= bool(np.isfinite(img).all())
        mins.append(float(img.min()))
        ms.append(r.frame_ms)
        ours.append(img)
        direct.append(session.render(sd, "DIRECT", q, 1, keep_history=True, session="bench_vxgi_direct").image[..., :3])
        cyc.append(reference.render_cycles(sc, 64, "full")[0][..., :3])
    session.release_session("bench_vxgi_motion")
    session.release_session("bench_vxgi_direct")
    bpy.data.scenes.remove(sc)

    def steps(seq):
        return [float(np.abs(a - b).mean()) for a, b in zip(seq, seq[1:])]
    d_ours, d_dir, d_cyc = steps(ours), steps(direct), steps(cyc)
    row = {"frames": frames, "quality": q, "finite": finite, "min": min(mins), "ours_max_diff": max(d_ours),
           "ours_mean_diff": float(np.mean(d_ours)), "cycles_max_diff": max(d_cyc),
           "cycles_mean_diff": float(np.mean(d_cyc)), "direct_max_diff": max(d_dir),
           "direct_mean_diff": float(np.mean(d_dir)), "first_step": d_ours[0], "cycles_first_step": d_cyc[0],
           "ours_max_after_first": max(d_ours[1:]),
           "above_cycles_max": int(sum(d > max(d_cyc) for d in d_ours)),
           "direct_above_cycles_max": int(sum(d > max(d_cyc) for d in d_dir)),
           "argmax": int(np.argmax(d_ours)), "direct_argmax": int(np.argmax(d_dir)),
           "frame_ms_median": float(np.median(ms)),
           "ours_diffs": [round(x, 5) for x in d_ours], "direct_diffs": [round(x, 5) for x in d_dir],
           "cycles_diffs": [round(x, 5) for x in d_cyc]}
    print(json.dumps(row), flush=True)
    return row


IMG_DIR = os.path.join(REPO, "docs", "techniques", "img")


def _panel(img, scale=4):
    """(H, W, 3) display-encoded float, bottom-up -> top-down uint8, scaled by nearest neighbour."""
    from gi_preview.compare.imageio import to_uint8

    a = to_uint8(img[..., :3])
    return a.repeat(scale, axis=0).repeat(scale, axis=1)


def images(o, out):
    """Side-by-side images of cornell and sunlit_room for docs/techniques/VXGI.md."""
    import bpy
    import numpy as np
    from PIL import Image, ImageDraw
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import metrics

    rows = []
    for scene in ("cornell", "sunlit_room"):
        sc = demo_scenes.build_demo(scene, resolution=o.img_res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        ref = reference.render_cycles(sc, o.ref_spp, "full")[0]
        r = render_vxgi(sd, o.img_quality, o.samples)
        img = r.image
        heat, _legend = metrics.heatmap(img, ref, vmin=1e-4, vmax=1.0, log=True)
        vox = r.aovs["GI_VXGI_Voxels"]
        panels = [(f"Cycles full {o.ref_spp} spp", metrics.view_standard(ref)),
                  (f"VXGI q{o.img_quality} now", metrics.view_standard(img)),
                  ("relMSE, log 1e-4 to 1", heat),
                  ("GI_VXGI_Voxels", metrics.view_standard(vox))]
        tiles = [_panel(p) for _l, p in panels]
        h, w = tiles[0].shape[:2]
        strip = np.zeros((h + 14, w * len(tiles), 3), np.uint8)
        for k, t in enumerate(tiles):
            strip[14:, k * w:(k + 1) * w] = t
        pil = Image.fromarray(strip)
        d = ImageDraw.Draw(pil)
        for k, (label, _p) in enumerate(panels):
            d.text((k * w + 2, 1), label, fill=(255, 255, 255))
        path = os.path.join(IMG_DIR, f"vxgi_{scene}.png")
        pil.save(path)
        row = {"scene": scene, "quality": o.img_quality, "res": o.img_res, "ref_spp": o.ref_spp,
               "relmse_full": metrics.relmse(img, ref),
               "mean_ratio_full": float(img[..., :3].mean() / ref[..., :3].mean()),
               "finite": bool(np.isfinite(img).all()), "png": os.path.relpath(path, REPO)}
        ours, cyc, n = img[..., :3].mean(axis=2), ref[..., :3].mean(axis=2), r.aovs["Normal"][..., :3]
        for ax in range(3):  # mean / Cycles' mean over the surfaces facing each axis direction
            for sg, name in ((1, "+"), (-1, "-")):
                m = n[..., ax] * sg > 0.98
                if m.sum() >= 20:
                    row[f"mean_ratio_normal_{name}{'xyz'[ax]}"] = float(ours[m].mean() / max(cyc[m].mean(), 1e-9))
        h = img.shape[0]  # rows are bottom-up
        row["mean_ratio_top_quarter"] = float(ours[3 * h // 4:].mean() / cyc[3 * h // 4:].mean())
        row["mean_ratio_bottom_quarter"] = float(ours[:h // 4].mean() / cyc[:h // 4].mean())
        rows.append(row)
        print(json.dumps(row), flush=True)
        bpy.data.scenes.remove(sc)
    with open(os.path.join(out, "images.json"), "w") as f:
        json.dump(rows, f, indent=1)
    return rows


def sweep(o, out):
    rows = []
    env = dict(os.environ)
    for scene in o.scenes.split(","):
        dst = os.path.join(out, scene)
        cmd = [sys.executable, os.path.join(HERE, "gi_compare.py"), scene, "--techniques", "DIRECT,VXGI",
               "--quality", ",".join(map(str, o.qualities)), "--res", str(o.sweep_res), "--ref-spp", str(o.sweep_ref_spp),
               "--samples", str(o.samples), "--frames", "2", "--baselines", "cycles", "--out", dst]
        print(" ".join(cmd), flush=True)
        subprocess.run(cmd, check=True, env=env)
        with open(os.path.join(dst, "results.json")) as f:
            res = json.load(f)
        for r in res.get("results", []):
            rows.append({"scene": scene, **{k: r.get(k) for k in (
                "technique", "quality", "reference", "relmse", "flip", "time_ms", "frame_ms", "setup_ms",
                "nonfinite_pixels", "speedups", "speedup", "errors")}})
    return rows


def _f(x, fmt=".4f"):
    return format(x, fmt) if isinstance(x, (int, float)) and x is not None else str(x)


def write_md(path, data, o):
    L = ["# VXGI against Cycles (scripts/bench_vxgi.py)", "",
         f"Resolution {o.res} px (sweep {o.sweep_res}), Cycles {o.ref_spp} spp, {o.samples} accumulated "
         f"frames after each quality level's warm-up; llvmpipe, 2 cores.", ""]
    if "audit" in data:
        L += ["## Energy audit", "",
              "Furnace: a closed 2 m box whose voxels all show radiance L (`audit_radiance`): E / (pi L), ideal 1. "
              "Cornell: VXGI's GI_IndirectDiffuse over Cycles' (256 spp) indirect light, multi-bounce off vs "
              "one_bounce - direct, on vs full - direct; per wall in bench.json.", "",
              "| q | configuration | furnace mean | furnace p10 | Cornell indirect, one-bounce | Cornell indirect, full | Cornell image / full |",
              "|---|---|---|---|---|---|---|"]
        for r in data["audit"]:
            L.append(f"| {r['quality']} | {r['config']} | {_f(r['furnace_mean'], '.3f')} | {_f(r['furnace_p10'], '.3f')} | "
                     f"{_f(r['cornell_indirect_vs_one_bounce'], '.3f')} | {_f(r['cornell_indirect_vs_full'], '.3f')} | "
                     f"{_f(r['cornell_mean_vs_full'], '.3f')} |")
        L.append("")
    if "accuracy" in data:
        L += ["## Accuracy against Cycles 'full'", "",
              "| scene | technique | q | multi-bounce | relMSE full | relMSE one-bounce | mean / full | ms/frame | setup ms |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in data["accuracy"]:
            L.append(f"| {r['scene']} | {r['technique']} | {r['quality']} | {r['multi_bounce']} | "
                     f"{_f(r['relmse_full'])} | {_f(r['relmse_one_bounce'])} | {_f(r['mean_ratio_full'], '.3f')} | "
                     f"{_f(r['frame_ms'], '.0f')} | {_f(r['setup_ms'], '.0f')} |")
        L.append("")
    if "leak" in data:
        L += ["## Light leak into the dark room (two_rooms, zero-thickness wall)", "",
              "leak = (dark-room mean - Cycles' dark-room mean) / Cycles' lit-room mean", "",
              "| q | configuration | dark-room mean | Cycles | leak |", "|---|---|---|---|---|"]
        for r in data["leak"]:
            L.append(f"| {r['quality']} | {r['config']} | {_f(r['dark_mean'])} | {_f(r['cycles_dark_mean'])} | "
                     f"{_f(r['leak'])} |")
        L.append("")
    for key in sorted(k for k in data if k.startswith("stability")):
        s = data[key]
        q = s.get("quality", 1)
        L += [f"## Stability: 60 frames, moving light and camera (cornell, 32 px, q{q})", "",
              f"finite: {s['finite']}, minimum {s['min']:.3g}; frame-to-frame mean |diff|: ours max "
              f"{s['ours_max_diff']:.4f} (mean {s['ours_mean_diff']:.4f}), Cycles 64 spp max "
              f"{s['cycles_max_diff']:.4f} (mean {s['cycles_mean_diff']:.4f}); median frame "
              f"{s['frame_ms_median']:.0f} ms."]
        if "direct_max_diff" in s:
            L += [f"First step {s['first_step']:.4f} (Cycles {s['cycles_first_step']:.4f}); largest after it "
                  f"{s['ours_max_after_first']:.4f}; {s['above_cycles_max']} of {s['frames'] - 1} steps above Cycles' "
                  f"largest. DIRECT in the same run: max {s['direct_max_diff']:.4f} (mean {s['direct_mean_diff']:.4f}), "
                  f"{s['direct_above_cycles_max']} steps above Cycles' largest."]
        L.append("")
    if "sweep" in data:
        L += ["## Demo scenes (scripts/gi_compare.py)", "",
              "| scene | technique | q | reference | relMSE | FLIP | ms/frame | setup ms | speed-up vs Cycles |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in data["sweep"]:
            sp = (r.get("speedups") or {}).get("cycles") or r.get("speedup") or {}
            spv = sp.get("speedup") if isinstance(sp, dict) else None
            spv = f"{spv:.3g}" if isinstance(spv, (int, float)) else (sp.get("reason", "") if isinstance(sp, dict) else "")
            L.append(f"| {r['scene']} | {r['technique']} | {r['quality']} | {r['reference']} | {_f(r['relmse'])} | "
                     f"{_f(r['flip'])} | {_f(r.get('frame_ms') or r.get('time_ms'), '.0f')} | "
                     f"{_f(r['setup_ms'], '.0f')} | {spv} |")
    with open(path, "w") as f:
        f.write("\n".join(L) + "\n")
    print("\n".join(L))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for s in ("audit", "accuracy", "leak", "stability", "sweep"):
        p.add_argument(f"--{s}", action="store_true")
    p.add_argument("--images", action="store_true", help="regenerate docs/techniques/img/vxgi_{cornell,sunlit_room}.png")
    p.add_argument("--img-res", type=int, default=40)
    p.add_argument("--img-quality", type=int, default=0)
    p.add_argument("--res", type=int, default=48)
    p.add_argument("--stability-quality", type=int, default=1, help="quality level of --stability")
    p.add_argument("--qualities", default="0,1,2,3", help="quality levels of --accuracy and --sweep (--leak: those <= 1)")
    p.add_argument("--ref-spp", type=int, default=128)
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--scenes", default=",".join(DEMOS))
    p.add_argument("--sweep-res", type=int, default=48)
    p.add_argument("--sweep-ref-spp", type=int, default=128)
    p.add_argument("--out", default=os.path.join(REPO, "docs", "results", "vxgi"))
    o = p.parse_args(argv)
    o.qualities = [int(x) for x in o.qualities.split(",")]
    chosen_explicit = any(getattr(o, s) for s in ("audit", "accuracy", "leak", "stability", "sweep"))
    chosen = [s for s in ("audit", "accuracy", "leak", "stability", "sweep") if getattr(o, s)] or [
        "accuracy", "leak", "stability", "sweep"]
    os.makedirs(o.out, exist_ok=True)
    path = os.path.join(o.out, "bench.json")
    data = {}
    if os.path.exists(path):
        with open(path) as f:
            data = json.load(f)
    _setup()
    if o.images:
        images(o, o.out)
        if not chosen_explicit:
            return
    t0 = time.time()
    for s in chosen:
        key = s if s != "stability" or o.stability_quality == 1 else f"stability_q{o.stability_quality}"
        data[key] = {"audit": audit, "accuracy": accuracy, "leak": leak, "stability": stability, "sweep": sweep}[s](o, o.out)
        with open(path, "w") as f:
            json.dump(data, f, indent=1)
    data["settings"] = {"res": o.res, "ref_spp": o.ref_spp, "samples": o.samples, "sweep_res": o.sweep_res,
                        "sweep_ref_spp": o.sweep_ref_spp, "wall_s": round(time.time() - t0, 1)}
    with open(path, "w") as f:
        json.dump(data, f, indent=1)
    write_md(os.path.join(o.out, "bench.md"), data, o)


if __name__ == "__main__":
    main()
