#!/usr/bin/env python3
"""VXGI (voxel cone tracing) measured against Cycles: accuracy, leaks, stability, demo sweeps.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_vxgi.py     (from the repository root)
        [--accuracy] [--leak] [--stability] [--sweep] [--res 48] [--ref-spp 128] [--qualities 0,1,2,3]
        [--out DIR] [--images [--img-res 40] [--img-quality 0] [--img-out DIR]]

Output folder ``--out``: default ``out/bench/vxgi/``.

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
  frame-to-frame mean |difference| of ours against Cycles' (the test_raster3d method), each
  step also without its G-buffer-edge pixels and for the indirect AOVs alone. Cycles' frames
  cached in ``--cache``; ``--lock-chunk N`` (no outer flock) for q2/q3; ``--stability-first F``,
  ``--stability-set PASS.PARAM=V --label L``, ``--stability-save FILE.npz`` (see stability()).
* ``--sweep``: scripts/gi_compare.py on every demo scene, DIRECT and VXGI at q0-q3 against
  the reference each models and "full" (relMSE, FLIP, time per frame, setup time,
  equal-error speed-up against Cycles' curve), into ``<out>/<scene>/``; ``<out>/sweep.md``.
* ``--images``: ``<img-out>/vxgi_cornell.png`` and ``vxgi_sunlit_room.png`` (``--img-out``,
  default the ``--out`` folder) with the current defaults: Cycles full ``--ref-spp`` | VXGI ``--img-quality`` | per-pixel relMSE (viridis,
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


NO_EDGE_MITIGATION = {"vxgi_inject": {"edge_opacity": 0.05, "footprint_cap": 0.0}, "vxgi_trace": {"footprint_cap": 0.0}}
LEAK_CONFIGS = (
    ("no mitigation (thickness 0, edge opacity 0.05, no footprint cap)",
     {"vxgi_voxelize": {"thickness": 0.0}, **NO_EDGE_MITIGATION}),
    ("thickness 1, edge opacity 0.05, no footprint cap", NO_EDGE_MITIGATION),
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


def _stability_poses(sc, frames):
    """The --stability path (deterministic): the light sweeps 0.71 m along x and sways in y,
    the camera dollies 0.3 m and rises 0.12 m over 60 frames. Yields (k, scene data)."""
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene

    light = next(ob for ob in sc.objects if ob.type == "LIGHT")
    cam = sc.camera
    l0, c0 = light.location.copy(), cam.location.copy()
    try:
        for k in range(frames):
            s = k / 10.0  # the 6-frame test's path, 10 times finer
            light.location.x = l0.x - 0.3 + 0.12 * s
            light.location.y = l0.y + 0.1 * math.sin(s)
            cam.location.x = c0.x + 0.05 * s
            cam.location.z = 1.0 + 0.02 * s
            yield k, export_scene(reference.evaluated_depsgraph(sc))
    finally:
        light.location, cam.location = l0, c0


def _stability_cycles(o, sc, frames, lock):
    """Cycles "full" 64 spp on the --stability poses, cached in ``--cache`` (the poses and
    Cycles' seed are deterministic)."""
    import numpy as np
    from gi_preview.blender import reference

    path = os.path.join(o.cache, f"vxgi_stability_cycles_full_{frames}f_32px_64spp.npy")
    if os.path.isfile(path):
        return list(np.load(path))
    cyc = []
    for k, _sd in _stability_poses(sc, frames):
        cyc.append(reference.render_cycles(sc, 64, "full")[0][..., :3].copy())
        lock.frame(last=k == frames - 1)
    os.makedirs(o.cache, exist_ok=True)
    np.save(path, np.stack(cyc))
    return cyc


def _steps(seq, mask=None):
    """Frame-to-frame mean |difference| (over the pixels where ``mask`` is False, per step)."""
    import numpy as np

    if mask is None:
        return [float(np.abs(a - b).mean()) for a, b in zip(seq, seq[1:])]
    return [float(np.abs(a - b).mean(-1)[~m].mean()) for a, b, m in zip(seq, seq[1:], mask)]


def stability(o, out, frames=60):
    """60 frames, moving light and camera, one frame each with history kept (as the viewport
    and an animation after its first frame); the first frame needs no warm-up (the injection
    converges within a reset frame). DIRECT runs the same frames in the same run: its steps
    are the G-buffer's own (edges at 32 px), the floor under any technique built on it.

    Each step is also split by pixel: the G-buffer-edge pixels of that step (normal or diffuse
    colour changed by > 0.05: an edge crossed the pixel centre, bench_raster3d's mask) against
    the rest, ours, DIRECT's and Cycles' on the same pixels; and VXGI's indirect light alone
    (GI_IndirectDiffuse + GI_IndirectGlossy) stepping. ``--stability-first F`` renders only the
    first F poses (screening; the row is printed and written under a ``_first`` key);
    ``--stability-set PASS.PARAM=V`` changes a parameter (key gets ``--label``).
    ``--lock-chunk N``: the script takes /tmp/gi_heavy.lock itself, gives it up every N frames
    (run without an outer flock). Cycles' frames are cached in ``--cache``."""
    import bpy
    import numpy as np
    from bench_raster3d import HeavyLock, _overrides
    from gi_preview.blender import demo_scenes
    from gi_preview.render import session

    lock = o.heavy_lock if getattr(o, "heavy_lock", None) is not None else HeavyLock(o.lock_chunk)
    lock.acquire()
    q = o.stability_quality
    nk = o.stability_first or frames
    sc = demo_scenes.build_demo("cornell", resolution=32)
    cyc = _stability_cycles(o, sc, frames, lock)[:nk]
    props = _overrides(argparse.Namespace(set=o.stability_set))
    if props:
        session.set_pass_properties("bench_vxgi_motion", props, "VXGI", q)
    ours, ind, direct, gbs, mins, finite, ms = [], [], [], [], [], True, []
    t0 = time.time()
    for k, sd in _stability_poses(sc, nk):
        r = session.render(sd, "VXGI", q, 1, keep_history=True, session="bench_vxgi_motion")
        img = r.image[..., :3].copy()
        finite &= bool(np.isfinite(img).all())
        mins.append(float(img.min()))
        ms.append(r.frame_ms)
        ours.append(img)
        ind.append((r.aovs["GI_IndirectDiffuse"][..., :3] + r.aovs["GI_IndirectGlossy"][..., :3]).copy())
        gbs.append(np.concatenate([r.aovs["Normal"][..., :3], r.aovs["DiffCol"][..., :3]], -1).copy())
        direct.append(session.render(sd, "DIRECT", q, 1, keep_history=True,
                                     session="bench_vxgi_direct").image[..., :3].copy())
        lock.frame(last=k == nk - 1)
    wall = time.time() - t0
    for name in ("bench_vxgi_motion", "bench_vxgi_direct"):
        fut = session.release_session(name)
        if fut is not None:
            fut.result()
    lock.release()
    bpy.data.scenes.remove(sc)
    if o.stability_save:
        np.savez_compressed(o.stability_save, ours=np.stack(ours), indirect=np.stack(ind), direct=np.stack(direct),
                            gbuffer=np.stack(gbs), cycles=np.stack(cyc))

    edge = [np.abs(a - b).max(-1) > 0.05 for a, b in zip(gbs, gbs[1:])]
    d_ours, d_dir, d_cyc, d_ind = _steps(ours), _steps(direct), _steps(cyc), _steps(ind)
    e_ours, e_dir, e_cyc = _steps(ours, edge), _steps(direct, edge), _steps(cyc, edge)
    cmax, cmean = max(d_cyc), float(np.mean(d_cyc))
    am = int(np.argmax(d_ours))  # step am: frame am -> am + 1
    # the largest step's share on its edge pixels (sum of |diff| there over the whole sum)
    a, b, e = ours[am], ours[am + 1], edge[am]
    tot = np.abs(a - b).mean(-1)
    row = {"frames": nk, "quality": q, "label": o.label or "default", "props": props, "finite": finite,
           "min": min(mins), "ours_max_diff": max(d_ours),
           "ours_mean_diff": float(np.mean(d_ours)), "cycles_max_diff": cmax,
           "cycles_mean_diff": cmean, "direct_max_diff": max(d_dir),
           "direct_mean_diff": float(np.mean(d_dir)), "first_step": d_ours[0], "cycles_first_step": d_cyc[0],
           "ours_max_after_first": max(d_ours[1:]),
           "ratio_mean": float(np.mean(d_ours)) / cmean, "ratio_max": max(d_ours) / cmax,
           "above_cycles_max": int(sum(d > cmax for d in d_ours)),
           "above_steps": [i for i, d in enumerate(d_ours) if d > cmax],
           "direct_above_cycles_max": int(sum(d > cmax for d in d_dir)),
           "argmax": am, "direct_argmax": int(np.argmax(d_dir)),
           "at_argmax": {"ours_x": d_ours[am] / cmax, "direct_x": d_dir[am] / cmax, "cycles_x": d_cyc[am] / cmax,
                         "indirect": d_ind[am], "indirect_mean": float(np.mean(d_ind)),
                         "edge_px": int(e.sum()), "edge_share": float(tot[e].sum() / max(tot.sum(), 1e-12)),
                         "no_edges_ours": e_ours[am], "no_edges_direct": e_dir[am], "no_edges_cycles": e_cyc[am]},
           "ratio_mean_no_edges": float(np.mean(e_ours) / np.mean(e_cyc)),
           "ratio_max_no_edges": float(max(e_ours) / max(e_cyc)), "max_no_edges_at": int(np.argmax(e_ours)),
           "direct_ratio_max_no_edges": float(max(e_dir) / max(e_cyc)),
           "indirect_mean_diff": float(np.mean(d_ind)), "indirect_max_diff": max(d_ind),
           "indirect_argmax": int(np.argmax(d_ind)),
           "frame_ms_median": float(np.median(ms)), "wall_s": round(wall, 1),
           "ours_diffs": [round(x, 5) for x in d_ours], "direct_diffs": [round(x, 5) for x in d_dir],
           "cycles_diffs": [round(x, 5) for x in d_cyc], "indirect_diffs": [round(x, 5) for x in d_ind],
           "ours_diffs_no_edges": [round(x, 5) for x in e_ours], "direct_diffs_no_edges": [round(x, 5) for x in e_dir],
           "cycles_diffs_no_edges": [round(x, 5) for x in e_cyc], "edge_px": [int(x.sum()) for x in edge]}
    print(json.dumps({k: v for k, v in row.items() if not k.endswith(("diffs", "no_edges", "edge_px"))}), flush=True)
    print(f"stability VXGI q{q} [{row['label']}] {nk} frames: finite {finite}, min {row['min']:.3g}, mean step "
          f"{row['ratio_mean']:.3f}x Cycles', largest {row['ratio_max']:.3f}x (step {am}; DIRECT there "
          f"{row['at_argmax']['direct_x']:.3f}x, edge share {row['at_argmax']['edge_share']:.2f}), "
          f"{row['above_cycles_max']} above; without edge pixels {row['ratio_mean_no_edges']:.3f}x / "
          f"{row['ratio_max_no_edges']:.3f}x (step {row['max_no_edges_at']}; DIRECT {row['direct_ratio_max_no_edges']:.3f}x); "
          f"{row['frame_ms_median']:.0f} ms/frame", flush=True)
    return row


def _panel(img, scale=4):
    """(H, W, 3) display-encoded float, bottom-up -> top-down uint8, scaled by nearest neighbour."""
    from gi_preview.compare.imageio import to_uint8

    a = to_uint8(img[..., :3])
    return a.repeat(scale, axis=0).repeat(scale, axis=1)


def images(o, out):
    """Side-by-side images of cornell and sunlit_room (the kind docs/techniques/VXGI.md shows)."""
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
        os.makedirs(o.img_out or out, exist_ok=True)
        path = os.path.join(o.img_out or out, f"vxgi_{scene}.png")
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
    p.add_argument("--images", action="store_true", help="write vxgi_{cornell,sunlit_room}.png into --img-out")
    p.add_argument("--img-out", default="", help="folder of the --images figures (default: --out)")
    p.add_argument("--img-res", type=int, default=40)
    p.add_argument("--img-quality", type=int, default=0)
    p.add_argument("--res", type=int, default=48)
    p.add_argument("--stability-quality", type=int, default=1, help="quality level of --stability")
    p.add_argument("--stability-first", type=int, default=0, help="--stability: only the first F poses (screening)")
    p.add_argument("--stability-set", action="append", help="--stability: PASS.PARAM=VALUE (repeatable)")
    p.add_argument("--stability-save", default="", help="--stability: write the frames into this .npz")
    p.add_argument("--label", default="", help="--stability: name of the --stability-set configuration")
    p.add_argument("--lock-chunk", type=int, default=0, help="--stability: take /tmp/gi_heavy.lock in the "
                   "script and give it up every N frames (run WITHOUT an outer flock); 0: the caller holds it")
    p.add_argument("--cache", default="/tmp/gi_bench_vxgi_cache", help="--stability: Cycles' frames")
    p.add_argument("--qualities", default="0,1,2,3", help="quality levels of --accuracy and --sweep (--leak: those <= 1)")
    p.add_argument("--ref-spp", type=int, default=128)
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--scenes", default=",".join(DEMOS))
    p.add_argument("--sweep-res", type=int, default=48)
    p.add_argument("--sweep-ref-spp", type=int, default=128)
    p.add_argument("--out", default=os.path.join(REPO, "out", "bench", "vxgi"),
                   help="output folder (default: out/bench/vxgi)")
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
    if o.lock_chunk:  # take the lock before Blender's import (the heavy part of the start)
        sys.path.insert(0, HERE)
        from bench_raster3d import HeavyLock

        o.heavy_lock = HeavyLock(o.lock_chunk)
        o.heavy_lock.acquire()
    _setup()
    if o.images:
        images(o, o.out)
        if not chosen_explicit:
            return
    t0 = time.time()
    for s in chosen:
        key = s if s != "stability" or o.stability_quality == 1 else f"stability_q{o.stability_quality}"
        if s == "stability" and (o.label or o.stability_first):
            key = f"stability_q{o.stability_quality}" + (f"_{o.label}" if o.label else "") + (
                f"_first{o.stability_first}" if o.stability_first else "")
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
