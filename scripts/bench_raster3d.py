#!/usr/bin/env python3
"""3D-raster family (RSM, LPV; VXGI when registered) against Cycles: demo scenes, thin-wall
leak, stability, lag.

    flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_raster3d.py [--parts compare,leak,stability,lag]
        [--scenes cornell,sunlit_room] [--techniques DIRECT,RSM,LPV] [--quality all]
        [--res 64] [--ref-spp 256] [--samples 8] [--baselines cycles,cycles_denoised,eevee]
        [--stability-frames 60] [--stability-quality 0,1,2,3] [--label L] [--set PASS.PARAM=V]
        [--out DIR]   (default out/bench/raster3d)
    .venv/bin/python scripts/bench_raster3d.py --lock-chunk 20 ...   (no outer flock: the script
        takes /tmp/gi_heavy.lock itself and gives it up every 20 frames, see ``HeavyLock``)
    (--parts summary: only rewrite summary.md from the folders present)

* ``compare``: scripts/gi_compare.py once per scene and technique (each quality level
  against the Cycles reference it models and against "full": relMSE, FLIP, SSIM, time per
  frame, setup time, equal-error speed-ups against the baselines' curves: Cycles, Cycles +
  OpenImageDenoise, EEVEE) into ``<out>/<scene>/<TECH>/``; the mean of each image over the
  mean of each reference is read back from the EXRs. Table in ``<out>/summary.md``.
  VXGI (models "full") is measured against "one_bounce" too (``BOTH_REFS``), its quality
  subsets go to ``<TECH>_q<levels>/``; with ``--lock-chunk`` the lock is given up between
  renders once held ``HOLD_S`` seconds (VXGI q2/q3 rows take minutes).
* ``leak``: the thin-wall scene of blender_tests/scenes_raster3d.py (two rooms, a wall of
  zero thickness, the light in the left one, the camera in the right one): the dark room's
  mean minus Cycles' (one bounce), over the lit room's mean seen from inside it; LPV with
  and without its geometry volume.
  ``<out>/leak.json``.
* ``stability``: the Cornell box at 32 px, ``--stability-frames`` frames with the light and
  the camera moving every frame (viewport-like: history kept, 1 frame each): finite, the
  minimum value, and the mean absolute frame-to-frame difference against Cycles' (64 spp
  per frame, same poses), the largest single step and where it falls, the indirect pass's
  own change per frame and its second difference in time (flicker), ms per frame.
  ``--stability-quality``, ``--label`` and ``--set PASS.PARAM=V`` name and configure a run;
  runs are merged into ``<out>/stability.json`` by (technique, quality, label). Cycles'
  frames are cached in ``--cache`` (the poses are deterministic). ``--stability-first F``
  (screening) renders only the first F poses of the same path and prints, saves nothing.
  ``--stability-samples S`` (S > 1) renders each pose as an F12 animation frame does
  (addon/blender/engine.py ``final_render`` with ``is_animation``: history kept, S jittered
  frames accumulated, anti-aliased edges); label "F12 animation, S samples".
* ``variant``: a ``--set`` variant against the default on the demo scenes (relMSE vs the
  cached one_bounce reference, mean ratio), ``<out>/variants.json``.
* ``testmotion``: test_raster3d's six moves started at offsets 0/3/6 (whole image and
  without the G-buffer-edge pixels), ``<out>/testmotion.json``.
* ``lag``: how many frames the bounce of a moved light takes to follow (camera still, the
  light moved 0.6 m in one step; the share of the way from the old indirect image to the
  new one per frame, 50 % / 90 % frames). ``<out>/lag.json``.
The doc pages (docs/techniques/RSM.md, LPV.md) quote these numbers. Output folder ``--out``:
default ``out/bench/raster3d/``; the table docs/results/raster3d/summary.md is regenerated with
``--out docs/results/raster3d`` (then keep only summary.md there: every file under
docs/results must be linked from a page).
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


class HeavyLock:
    """The shared heavy-command lock (/tmp/gi_heavy.lock) taken by the script itself, for
    runs longer than one lock turn (LPV q3: about 8 s per moving frame, 60 frames): the
    process keeps its GL state (the technique's history) while it waits, and holds the lock
    only while it renders. ``turn()`` gives it up for a moment every ``chunk`` frames so the
    other waiting commands get their turn; the frames themselves are timed one by one, so
    the pauses do not enter any measured time. ``chunk`` 0: no locking (the caller holds
    the lock, e.g. ``flock /tmp/gi_heavy.lock ...``; taking it again here would deadlock)."""

    def __init__(self, chunk: int, path: str = "/tmp/gi_heavy.lock"):
        self.chunk, self.path, self.fd, self.count = int(chunk), path, None, 0

    def acquire(self):
        if self.chunk <= 0 or self.fd is not None:
            return
        import fcntl

        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        t0 = time.perf_counter()
        fcntl.flock(self.fd, fcntl.LOCK_EX)
        self.count = 0
        self.t_acquired = time.perf_counter()
        print(f"[lock] acquired after {time.perf_counter() - t0:.0f} s", flush=True)

    def release(self):
        if self.fd is None:
            return
        import fcntl

        fcntl.flock(self.fd, fcntl.LOCK_UN)
        os.close(self.fd)
        self.fd = None

    def frame(self, last: bool = False):
        """Count one frame; every ``chunk`` frames give the lock up and wait for it again
        (not after the ``last`` frame of a run: the rest is a few numpy lines)."""
        if self.chunk <= 0 or last:
            return
        self.count += 1
        if self.count >= self.chunk:
            self.release()
            time.sleep(3.0)  # let a waiting command take it (flock is not fair)
            self.acquire()


    def turn_after(self, seconds: float):
        """Give the lock up for a moment (and wait for it again) once it has been held for
        ``seconds`` (compare rows of very different lengths: VXGI q1 cornell ~40 s, q3
        many_lights minutes)."""
        if self.chunk <= 0 or self.fd is None or time.perf_counter() - self.t_acquired < seconds:
            return
        self.release()
        time.sleep(3.0)
        self.acquire()


LOCK = HeavyLock(0)


def _bpy_env():
    sys.path.insert(0, HERE)
    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    from _checkout import setup_blender

    setup_blender()


def _set_props(sess, props):
    from gi_preview.render import session as S

    S.set_pass_properties(sess, props)


def part_compare(o, rows):
    """One gi_compare run per scene and technique into ``<out>/<scene>/<TECH>/`` (a run per
    technique keeps each locked command short; the summary reads every folder present)."""
    for scene in o.scenes.split(","):
        for tech in o.techniques.split(","):
            # a subset of the levels (a scene too slow for one locked command) gets its own
            # folder; the summary reads every folder of the scene
            sub = tech if o.quality == "all" else f"{tech}_q{o.quality.replace(',', '')}"
            out = os.path.join(o.out, scene, sub)
            cmd = [sys.executable, os.path.join(HERE, "gi_compare.py"), scene, "--techniques", tech,
                   "--quality", o.quality, "--res", str(o.res), "--ref-spp", str(o.ref_spp),
                   "--samples", str(o.samples), "--frames", str(o.frames), "--baselines", o.baselines,
                   "--out", out]
            if tech in BOTH_REFS:
                # a technique that models "full" (VXGI) measured against one_bounce too, as the
                # issue's table asks: gi_compare in-process with a shim, lock turns between rows
                cmd = [sys.executable, os.path.abspath(__file__), BOTH_REFS_FLAG,
                       str(LOCK.chunk)] + cmd[2:]
                print(" ".join(cmd), flush=True)
                LOCK.release()  # the child takes it (with --lock-chunk) or runs under the caller's
                subprocess.run(cmd, check=True)
                continue
            LOCK.acquire()  # (again, after a BOTH_REFS child; the summary needs no lock)
            print(" ".join(cmd), flush=True)
            subprocess.run(cmd, check=True)
    # the summary lists every scene folder present, so one scene can be re-run alone
    present = sorted(d for d in os.listdir(o.out) if os.path.isdir(os.path.join(o.out, d)))
    collect(o, rows, present)


# techniques that model Cycles' "full" (gi_compare --reference auto measures them only
# against it) but whose demo table also wants the one-bounce columns, to sit beside RSM and LPV
BOTH_REFS = ("VXGI",)
BOTH_REFS_FLAG = "--gi-compare-one-bounce-too"
HOLD_S = 150.0  # lock turns of the BOTH_REFS child: after the render that passes this hold


def gi_compare_one_bounce_too(chunk: int, argv: list[str]):
    """``gi_compare.run(argv)`` for a technique in ``BOTH_REFS``, against Cycles' one_bounce
    reference as well as "full" (the primary, which carries the Cycles + OIDN and EEVEE
    curves): the session module is wrapped so the technique reports ``reference =
    "one_bounce"`` to gi_compare's reference choice only (the renders are the technique's own).
    ``chunk`` > 0: take /tmp/gi_heavy.lock here and give it up after a render or a session
    release once held ``HOLD_S`` seconds (gi_compare releases every session before each row;
    setup and frame times are the RenderResult's own, so the pauses enter no measured time):
    a VXGI q3 render of many_lights costs minutes (docs/techniques/VXGI.md)."""
    import importlib

    LOCK.chunk = int(chunk)
    LOCK.acquire()
    _bpy_env()
    import gi_compare as G

    opts = G.parse_args(argv, scene_optional=False)
    pkg = G.find_addon(opts.use_installed)
    S = importlib.import_module(pkg.__name__ + ".render.session")

    class _Info:
        reference = "one_bounce"

        def __init__(self, t):
            self._t = t

        def __getattr__(self, k):
            return getattr(self._t, k)

    class _Session:
        def __getattr__(self, k):
            return getattr(S, k)

        def available_techniques(self):
            return [_Info(t) if t.id in BOTH_REFS else t for t in S.available_techniques()]

        def release_all(self):  # called (on the GL thread) before every row and at the end
            S.release_all()
            LOCK.turn_after(HOLD_S)
            waits.append([])

        def render(self, *a, **kw):  # a row's warm-up and timed renders (the times are the
            r = S.render(*a, **kw)   # RenderResult's own: no pause enters them)
            t0 = time.perf_counter()
            LOCK.turn_after(HOLD_S)
            waits[-1].append((time.perf_counter() - t0) * 1e3)
            return r

    waits: list[list[float]] = []
    G.run(opts, pkg=pkg, session=_Session())
    LOCK.release()
    # gi_compare's setup.first_render_ms is the warm-up render's wall time around our render():
    # take out the lock turn that followed it (rows in plan order, one release before each)
    path = os.path.join(opts.out, "results.json")
    with open(path) as f:
        res = json.load(f)
    rows = sorted({(e["technique"], e["quality"]) for e in res.get("results", [])},
                  key=[(e["technique"], e["quality"]) for e in res["results"]].index)
    for e in res.get("results", []) + (res.get("entries") if isinstance(res.get("entries"), list) else []):
        w = waits[rows.index((e["technique"], e["quality"]))] if len(waits) > len(rows) else []
        st = e.get("setup") or {}
        if w and "first_render_ms" in st:
            st["lock_wait_ms"] = w[0]
            st["first_render_ms"] -= w[0]
    with open(path, "w") as f:
        json.dump(res, f, indent=1)


def collect(o, rows, scenes=None):
    """Rows of every ``<out>/<scene>/<TECH>/results.json`` of the given scenes (default: the
    requested ones), with the mean of each image over the mean of its reference read back
    from the EXRs."""
    from gi_preview.blender import reference
    from gi_preview.compare import imageio

    reference.ensure_oiio()
    for scene in scenes or o.scenes.split(","):
        base = os.path.join(o.out, scene)
        for tech in sorted(os.listdir(base)) if os.path.isdir(base) else ():
            out = os.path.join(base, tech)
            if not os.path.isfile(os.path.join(out, "results.json")):
                continue
            with open(os.path.join(out, "results.json")) as f:
                res = json.load(f)
            refs = {}
            for r in res.get("results", []):
                k = r.get("reference")
                if k not in refs:
                    refs[k] = imageio.read_exr(os.path.join(out, f"reference_{k}.exr"))[..., :3].mean()
                img = imageio.read_exr(os.path.join(out, r["files"]["exr"]))[..., :3]
                r["mean_ratio"] = float(img.mean() / max(refs[k], 1e-12))
                rows.append((scene, r))


def _speedup(r, b):
    sp = (r.get("speedups") or {}).get(b) or {}
    v = sp.get("speedup")
    if isinstance(v, (int, float)):
        return f"{v:.3g}"
    b = sp.get("bound") or {}
    if "at_most" in b:  # the technique's error is above the baseline's lowest-spp error
        return f"≤ {b['at_most']:.3g}"
    if "at_least" in b:  # below the baseline's highest-spp error
        return f"≥ {b['at_least']:.3g}"
    if not sp:
        return "–"
    return str(sp.get("reason", "")).replace("|", "/")


def write_summary(o, rows):
    bl = [b for b in o.baselines.split(",") if b and b != "none"] or ["cycles"]
    lines = ["# 3D-raster family vs Cycles (scripts/bench_raster3d.py)", "",
             f"Resolution {o.res}, Cycles {o.ref_spp} spp, {o.samples} accumulated frames, llvmpipe on 2 cores; "
             "per-scene details (images, error maps, baselines) in the scene folders. Mean = mean of the "
             "image over the mean of the reference. Speed-up: the baseline's time to reach the "
             "technique's error over the technique's time (setup apart); ≤ x: the technique's error is "
             "above the baseline's error at its fewest samples (x = the speed-up at that point, an upper "
             "bound), ≥ x: below the baseline's error at its most samples (a lower bound). The "
             "Cycles + OpenImageDenoise and EEVEE curves are measured against the full reference only.", "",
             "| scene | technique | q | reference | relMSE | FLIP | mean | ms/frame | setup ms | "
             + " | ".join(f"speed-up vs {b}" for b in bl) + " |",
             "|---|---|---|---|---|---|---|---|---|" + "---|" * len(bl)]
    for scene, r in rows:
        lines.append(f"| {scene} | {r.get('technique')} | {r.get('quality')} | {r.get('reference')} | "
                     f"{r.get('relmse', float('nan')):.4f} | {r.get('flip', float('nan')):.4f} | "
                     f"{r.get('mean_ratio', float('nan')):.3f} | {r.get('frame_ms', float('nan')):.1f} | "
                     f"{r.get('setup_ms', float('nan')):.0f} | " + " | ".join(_speedup(r, b) for b in bl) + " |")
    with open(os.path.join(o.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def part_leak(o):
    import bpy
    import numpy as np

    import scenes_raster3d
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    res = o.leak_res
    dark = scenes_raster3d.build("two_rooms", res)
    lit = scenes_raster3d.build("two_rooms", res, lit_camera=True)
    sd_dark = export_scene(reference.evaluated_depsgraph(dark))
    ref_dark = reference.render_cycles(dark, o.ref_spp, "one_bounce")[0][..., :3]
    ref_lit = reference.render_cycles(lit, o.ref_spp, "one_bounce")[0][..., :3]
    lit_level = float(ref_lit.mean())
    out = {"res": res, "ref_spp": o.ref_spp, "cycles_dark_mean": float(ref_dark.mean()),
           "cycles_lit_mean": lit_level, "runs": []}
    configs = [("DIRECT", {}, "DIRECT"), ("RSM", {}, "RSM")]
    if "LPV" in o.techniques.split(","):
        configs += [("LPV", {}, "LPV, geometry volume on"),
                    ("LPV", {"lpv": {"geometry_volume": False}}, "LPV, geometry volume off"),
                    ("LPV", {"lpv": {"splat_blocking": False}}, "LPV, trilinear splat not blocked (diagnosis)"),
                    ("LPV", {"lpv": {"trilinear_injection": False}}, "LPV, nearest-cell injection")]
    for q in (1,):
        for k, (tech, props, label) in enumerate(configs):
            sess = f"leak{k}"
            S.render(sd_dark, tech, q, 1, session=sess, warmup=False)
            if props:
                _set_props(sess, props)
            img = S.render(sd_dark, tech, q, o.samples, session=sess).image[..., :3]
            S.release_session(sess).result(timeout=60)
            leak = float(img.mean() - ref_dark.mean()) / lit_level
            out["runs"].append({"technique": tech, "quality": q, "label": label, "props": props,
                                "dark_mean": float(img.mean()), "leak": leak})
            print(f"two_rooms {label} q{q}: dark-room mean {img.mean():.4f} (Cycles {ref_dark.mean():.4f}), "
                  f"leak {leak:.4f} of the lit room's {lit_level:.4f}", flush=True)
    bpy.data.scenes.remove(dark)
    bpy.data.scenes.remove(lit)
    with open(os.path.join(o.out, "leak.json"), "w") as f:
        json.dump(out, f, indent=1)


def move(sc, k, n):
    """Pose k of n: the light sweeps across the ceiling and the camera dollies and rises."""
    light = next(ob for ob in sc.objects if ob.type == "LIGHT")
    cam = sc.camera
    if not hasattr(move, "base"):
        move.base = {}
    key = sc.name
    if key not in move.base:
        move.base[key] = (tuple(light.location), tuple(cam.location))
    (lx, ly, lz), (cx, cy, cz) = move.base[key]
    t = k / max(n - 1, 1)
    light.location = (lx - 0.3 + 0.6 * t, ly + 0.2 * math.sin(2 * math.pi * t), lz)
    cam.location = (cx + 0.3 * t, cy, cz + 0.2 * t)


def _overrides(o) -> dict:
    """``--set PASS.PARAM=VALUE`` (repeatable) as FrameGraph.set_properties' dict."""
    props = {}
    for item in o.set or ():
        key, val = item.split("=", 1)
        pname, param = key.split(".", 1)
        v = {"true": True, "false": False}.get(val.lower(), None)
        if v is None:
            v = float(val) if any(c in val for c in ".e") else int(val)
        props.setdefault(pname, {})[param] = v
    return props


def _merge_runs(path, head, runs, key=("technique", "quality", "label")):
    """Write ``head`` + runs into ``path``, keeping the runs of an earlier file whose key is
    not re-measured now (the parts can be run in several short locked commands)."""
    old = []
    if os.path.isfile(path):
        with open(path) as f:
            old = json.load(f).get("runs", [])
    new_keys = {tuple(r.get(k) for k in key) for r in runs}
    out = dict(head)
    out["runs"] = [r for r in old if tuple(r.get(k) for k in key) not in new_keys] + runs
    out["runs"].sort(key=lambda r: (str(r.get("scene", "")), str(r.get("technique")), str(r.get("label")),
                                    r.get("quality", 0)))
    with open(path, "w") as f:
        json.dump(out, f, indent=1)


def _cycles_motion(o, sc, n):
    """Cycles at 64 spp on the n poses, ``--stability-ref`` bounces (one_bounce: what RSM and
    LPV model; full: VXGI with multi-bounce), cached: the poses are deterministic."""
    import numpy as np

    from gi_preview.blender import reference

    mode = o.stability_ref
    tag = "" if mode == "one_bounce" else f"_{mode}"
    path = os.path.join(o.cache, f"stability_cycles_cornell_{n}f_32px_64spp{tag}.npy")
    if os.path.isfile(path):
        return list(np.load(path))
    cyc = []
    for k in range(n):
        move(sc, k, n)
        cyc.append(reference.render_cycles(sc, 64, mode)[0][..., :3])
    os.makedirs(o.cache, exist_ok=True)
    np.save(path, np.stack(cyc))
    return cyc


def part_stability(o):
    """60 moving frames (viewport-like: history kept, one frame per pose) per technique and
    quality level; per run the frame-to-frame mean |diff| per frame, its mean and max, the
    frame of the max, and the ratios to Cycles' (mean to mean, max to max)."""
    import bpy
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    n = o.stability_frames
    sc = demo_scenes.build_demo("cornell", resolution=32)
    cyc = _cycles_motion(o, sc, n)
    if o.stability_first:  # screening: the first F of the n poses (same path, fewer frames)
        cyc = cyc[: o.stability_first]
    d_cyc = [float(np.abs(a - b).mean()) for a, b in zip(cyc, cyc[1:])]
    head = {"frames": n, "res": 32, "cycles_spp": 64, "cycles_ref": o.stability_ref, "first": o.stability_first or n,
            "cycles": {"mean": float(np.mean(d_cyc)), "max": float(np.max(d_cyc)),
                       "diffs": [round(x, 6) for x in d_cyc]}}
    props = _overrides(o)
    spp = max(1, o.stability_samples)
    label = o.label or ("default" if spp == 1 else f"F12 animation, {spp} samples")
    head["samples"] = spp
    runs = []
    for tech in o.techniques.split(","):  # DIRECT too: what the direct light alone changes
        for q in [int(x) for x in o.stability_quality.split(",")]:
            ours, ind, gbs, ms, t0 = [], [], [], [], time.perf_counter()
            fin, mn = True, float("inf")
            nk = o.stability_first or n
            for k in range(nk):
                move(sc, k, n)
                sd = export_scene(reference.evaluated_depsgraph(sc))
                if k == 0 and props:
                    S.render(sd, tech, q, 1, keep_history=True, session="stab")
                    _set_props("stab", props)
                # samples > 1: an F12 animation frame (engine.final_render with is_animation:
                # history kept, `samples` jittered frames accumulated per pose, anti-aliased)
                res = S.render(sd, tech, q, spp, keep_history=True, session="stab", warmup=(k == 0 and spp > 1))
                LOCK.frame(last=k == nk - 1)
                img = res.image[..., :3]
                fin &= bool(np.isfinite(img).all())
                mn = min(mn, float(img.min()))
                ours.append(img)
                ms.append(res.frame_ms)
                if "GI_IndirectDiffuse" in res.aovs:
                    ind.append(res.aovs["GI_IndirectDiffuse"][..., :3])
                gbs.append(np.concatenate([res.aovs["Normal"][..., :3], res.aovs["DiffCol"][..., :3]], -1))
            S.release_session("stab").result(timeout=60)
            # where the steps come from, per frame: the pixels whose G-buffer surface changed
            # (normal or diffuse colour: an edge crossed the pixel centre) against the rest,
            # ours and Cycles' on the same pixels; and the direct part against the indirect one
            edge = [np.abs(a - b).max(-1) > 0.05 for a, b in zip(gbs, gbs[1:])]
            d_in = [float(np.abs(a - b).mean(-1)[~e].mean()) for a, b, e in zip(ours, ours[1:], edge)]
            c_in = [float(np.abs(a - b).mean(-1)[~e].mean()) for a, b, e in zip(cyc, cyc[1:], edge)]
            d_dir = ([float(np.abs((a - ia) - (b - ib)).mean()) for a, b, ia, ib in zip(ours, ours[1:], ind, ind[1:])]
                     if ind else [])
            d = [float(np.abs(a - b).mean()) for a, b in zip(ours, ours[1:])]
            # the indirect pass alone: its change per frame and its second difference in time
            # (flicker: a smooth change has none)
            ind_d = [float(np.abs(a - b).mean()) for a, b in zip(ind, ind[1:])]
            ind_d2 = [float(np.abs(a - 2 * b + c).mean()) for a, b, c in zip(ind, ind[1:], ind[2:])]
            r = {"technique": tech, "quality": q, "label": label, "props": props, "samples": spp,
                 "finite": fin, "min": mn, "mean": float(np.mean(d)), "max": float(np.max(d)),
                 "max_at": int(np.argmax(d)) + 1, "ratio_mean": float(np.mean(d) / np.mean(d_cyc)),
                 "ratio_max": float(np.max(d) / np.max(d_cyc)),
                 "ratio_mean_after8": float(np.mean(d[8:]) / np.mean(d_cyc[8:])),
                 "ratio_max_after8": float(np.max(d[8:]) / np.max(d_cyc[8:])),
                 "indirect_change": float(np.mean(ind_d)) if ind_d else None,
                 "indirect_flicker": float(np.mean(ind_d2)) if ind_d2 else None,
                 "frame_ms": float(np.median(ms)), "wall_s": time.perf_counter() - t0,
                 "ratio_mean_no_edges": float(np.mean(d_in) / np.mean(c_in)),
                 "ratio_max_no_edges": float(np.max(d_in) / np.max(c_in)),
                 "max_no_edges_at": int(np.argmax(d_in)) + 1,
                 "diffs": [round(x, 6) for x in d],
                 "edge_px": [int(e.sum()) for e in edge],
                 "diffs_no_edges": [round(x, 6) for x in d_in],
                 "cycles_diffs_no_edges": [round(x, 6) for x in c_in],
                 "direct_part_diffs": [round(x, 6) for x in d_dir],
                 "indirect_diffs": [round(x, 6) for x in ind_d]}
            runs.append(r)
            print(f"stability {tech} q{q} [{r['label']}]: finite {fin}, min {mn:.3g}, frame-to-frame mean "
                  f"{r['mean']:.4f} ({r['ratio_mean']:.3f}x) max {r['max']:.4f} ({r['ratio_max']:.2f}x, frame "
                  f"{r['max_at']}); after frame 8 {r['ratio_mean_after8']:.3f}x / {r['ratio_max_after8']:.2f}x; "
                  f"indirect change {r['indirect_change'] or 0:.4f} flicker {r['indirect_flicker'] or 0:.4f}; "
                  f"without the G-buffer-edge pixels {r['ratio_mean_no_edges']:.3f}x / {r['ratio_max_no_edges']:.2f}x "
                  f"(frame {r['max_no_edges_at']}); "
                  f"Cycles mean {head['cycles']['mean']:.4f} max {head['cycles']['max']:.4f}; {r['frame_ms']:.0f} ms/frame, "
                  f"{r['wall_s']:.0f} s",
                  flush=True)
    bpy.data.scenes.remove(sc)
    if o.stability_first:  # screening runs are printed only (stability.json holds full runs)
        return
    name = "stability.json" if o.stability_ref == "one_bounce" else f"stability_{o.stability_ref}.json"
    _merge_runs(os.path.join(o.out, name), head, runs)


def part_lag(o):
    """How many frames the bounce of a moved light takes to follow: the Cornell box at 32 px,
    camera still, the light held at pose A for ``hold`` frames, then moved in one step to
    pose B (0.6 m across the ceiling) and held (viewport-like frames, history kept). Per
    frame after the step, the share of the way from A's indirect image to B's that the
    GI_IndirectDiffuse pass has gone: ``<I_t - T_A, T_B - T_A> / |T_B - T_A|²`` with T_A, T_B
    fresh 16-frame renders of each pose (noise is mostly orthogonal to the step). Lag =
    the first frame after the step at which the share reaches 0.5 / 0.9."""
    import bpy
    import numpy as np

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    sc = demo_scenes.build_demo("cornell", resolution=32)
    light = next(ob for ob in sc.objects if ob.type == "LIGHT")
    base = tuple(light.location)
    poses = [(base[0] - 0.3, base[1], base[2]), (base[0] + 0.3, base[1], base[2])]
    hold, after = 12, o.lag_frames
    props = _overrides(o)
    runs = []

    def ind(res):
        return res.aovs["GI_IndirectDiffuse"][..., :3].astype(np.float64)

    for tech in [t for t in o.techniques.split(",") if t != "DIRECT"]:
        for q in [int(x) for x in o.stability_quality.split(",")]:
            targets = []
            for p in poses:
                light.location = p
                sd = export_scene(reference.evaluated_depsgraph(sc))
                if props:
                    S.render(sd, tech, q, 1, session="lagref", warmup=False)
                    _set_props("lagref", props)
                targets.append(ind(S.render(sd, tech, q, 16, session="lagref")))
                S.release_session("lagref").result(timeout=60)
            ta, tb = targets
            step = tb - ta
            share = []
            for k in range(hold + after):
                light.location = poses[0] if k < hold else poses[1]
                sd = export_scene(reference.evaluated_depsgraph(sc))
                if k == 0 and props:
                    S.render(sd, tech, q, 1, keep_history=True, session="lag")
                    _set_props("lag", props)
                img = ind(S.render(sd, tech, q, 1, keep_history=True, session="lag"))
                LOCK.frame(last=k == hold + after - 1)
                if k >= hold:
                    share.append(float(np.sum((img - ta) * step) / max(np.sum(step * step), 1e-20)))
            S.release_session("lag").result(timeout=60)

            def first(th):
                return next((i + 1 for i, s in enumerate(share) if s >= th), None)

            r = {"technique": tech, "quality": q, "label": o.label or "default", "props": props,
                 "lag50": first(0.5), "lag90": first(0.9), "share": [round(s, 4) for s in share]}
            runs.append(r)
            print(f"lag {tech} q{q} [{r['label']}]: 50 % after {r['lag50']} frames, 90 % after {r['lag90']}; "
                  f"share {np.round(share[:20], 2)}", flush=True)
    bpy.data.scenes.remove(sc)
    _merge_runs(os.path.join(o.out, "lag.json"), {"res": 32, "hold": hold, "after": after,
                                                   "step_m": 0.6}, runs)


def part_variant(o):
    """One parameter variant (``--set``, named ``--label``) of each technique on each demo
    scene at ``--res``, ``--samples`` accumulated frames, against the scene's cached Cycles
    one_bounce reference (``<out>/<scene>/<TECH>/reference_one_bounce.exr``, written by the
    compare part): relMSE and mean ratio, default and variant rendered in the same run.
    Merged into ``<out>/variants.json`` by (scene, technique, quality, label)."""
    import bpy

    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import imageio, metrics
    from gi_preview.render import session as S

    reference.ensure_oiio()
    props = _overrides(o)
    qs = [int(x) for x in (o.stability_quality if o.quality == "all" else o.quality).split(",")]
    runs = []
    for scene in o.scenes.split(","):
        sc = demo_scenes.build_demo(scene, resolution=o.res)
        sd = export_scene(reference.evaluated_depsgraph(sc))
        for tech in o.techniques.split(","):
            ref = imageio.read_exr(os.path.join(o.out, scene, tech, "reference_one_bounce.exr"))[..., :3]
            for q in qs:
                for label, pr in (("default", {}), (o.label or "variant", props)):
                    S.render(sd, tech, q, 1, session="variant", warmup=False)
                    if pr:
                        _set_props("variant", pr)
                    img = S.render(sd, tech, q, o.samples, session="variant").image[..., :3]
                    S.release_session("variant").result(timeout=60)
                    r = {"scene": scene, "technique": tech, "quality": q, "label": label, "props": pr,
                         "relmse": float(metrics.relmse(img, ref)), "mean_ratio": float(img.mean() / ref.mean())}
                    runs.append(r)
                    print(f"{scene} {tech} q{q} [{label}]: relMSE vs one_bounce {r['relmse']:.4f}, "
                          f"mean {r['mean_ratio']:.3f}", flush=True)
        bpy.data.scenes.remove(sc)
    _merge_runs(os.path.join(o.out, "variants.json"), {"res": o.res, "samples": o.samples}, runs,
                key=("scene", "technique", "quality", "label"))


def part_testmotion(o):
    """test_raster3d's six large moves (scenes_raster3d.move_light_and_camera, 32 px, q1,
    Cycles 64 spp) started at offsets 0, 3 and 6: whole-image and interior (no
    G-buffer-edge pixels) frame-to-frame ratios to Cycles', to judge the test's guard.
    ``<out>/testmotion.json``."""
    import bpy
    import numpy as np

    import scenes_raster3d
    from gi_preview.blender import demo_scenes, reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session as S

    techs = [t for t in o.techniques.split(",") if t != "DIRECT"]
    runs = []
    for off in (0, 3, 6):
        sc = demo_scenes.build_demo("cornell", resolution=32)
        cyc, ours, gbs = [], {t: [] for t in techs}, {t: [] for t in techs}
        for k in range(6):
            scenes_raster3d.move_light_and_camera(sc, k + off)
            sd = export_scene(reference.evaluated_depsgraph(sc))
            cyc.append(reference.render_cycles(sc, 64, "one_bounce")[0][..., :3])
            for i, tech in enumerate(techs):
                res = S.render(sd, tech, 1, 1, keep_history=True, session=f"tm{i}")
                ours[tech].append(res.image[..., :3])
                gbs[tech].append(np.concatenate([res.aovs["Normal"][..., :3], res.aovs["DiffCol"][..., :3]], -1))
        for i, tech in enumerate(techs):
            S.release_session(f"tm{i}").result(timeout=60)
            im, g = ours[tech], gbs[tech]
            edge = [np.abs(a - b).max(-1) > 0.05 for a, b in zip(g, g[1:])]
            d = [float(np.abs(a - b).mean()) for a, b in zip(im, im[1:])]
            dc = [float(np.abs(a - b).mean()) for a, b in zip(cyc, cyc[1:])]
            di = [float(np.abs(a - b).mean(-1)[~e].mean()) for a, b, e in zip(im, im[1:], edge)]
            ci = [float(np.abs(a - b).mean(-1)[~e].mean()) for a, b, e in zip(cyc, cyc[1:], edge)]
            r = {"technique": tech, "quality": 1, "label": f"offset {off}", "offset": off,
                 "ratio_mean": float(np.mean(d) / np.mean(dc)), "ratio_max": float(max(d) / max(dc)),
                 "ratio_mean_no_edges": float(np.mean(di) / np.mean(ci)),
                 "ratio_max_no_edges": float(max(di) / max(ci)), "edge_px": [int(e.sum()) for e in edge]}
            runs.append(r)
            print(f"test motion offset {off} {tech}: {r['ratio_mean']:.3f}x / max {r['ratio_max']:.2f}x; without the "
                  f"G-buffer-edge pixels {r['ratio_mean_no_edges']:.3f}x / {r['ratio_max_no_edges']:.2f}x; "
                  f"edge px {r['edge_px']}", flush=True)
        bpy.data.scenes.remove(sc)
    _merge_runs(os.path.join(o.out, "testmotion.json"), {"res": 32, "cycles_spp": 64, "moves": 6}, runs)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == [BOTH_REFS_FLAG]:
        return gi_compare_one_bounce_too(int(argv[1]), argv[2:])
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--parts", default="compare,leak,stability")
    p.add_argument("--scenes", default="cornell,sunlit_room")
    p.add_argument("--techniques", default="DIRECT,RSM,LPV")
    p.add_argument("--quality", default="all")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--leak-res", type=int, default=48)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--samples", type=int, default=8)
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--baselines", default="cycles,cycles_denoised,eevee")
    p.add_argument("--stability-frames", type=int, default=60)
    p.add_argument("--stability-quality", default="0,1,2,3", help="quality levels of the stability and lag parts")
    p.add_argument("--stability-samples", type=int, default=1,
                   help="frames accumulated per pose (1: the viewport's one frame; S > 1: an F12 animation "
                        "frame, S jittered frames, anti-aliased); the label defaults to 'F12 animation, S samples'")
    p.add_argument("--stability-ref", default="one_bounce", choices=("one_bounce", "full"),
                   help="Cycles' bounces for the stability part (full for VXGI with multi-bounce); runs against "
                        "full are merged into stability_full.json")
    p.add_argument("--stability-first", type=int, default=0,
                   help="screening: render only the first F of the --stability-frames poses (printed, not saved)")
    p.add_argument("--lag-frames", type=int, default=30, help="frames after the light's step (lag part)")
    p.add_argument("--set", action="append", help="PASS.PARAM=VALUE override (stability, lag; repeatable)")
    p.add_argument("--label", default="", help="name of this configuration in stability.json / lag.json")
    p.add_argument("--cache", default=os.path.join("/tmp", "gi_bench_raster3d_cache"),
                   help="folder for the Cycles frames of the stability part (deterministic poses)")
    p.add_argument("--out", default=os.path.join(REPO, "out", "bench", "raster3d"),
                   help="output folder (default: out/bench/raster3d; the docs table: docs/results/raster3d)")
    p.add_argument("--lock-chunk", type=int, default=0,
                   help="take /tmp/gi_heavy.lock here and give it up every N moving frames "
                        "(stability, lag; compare of VXGI: every N rows; run WITHOUT an outer flock); "
                        "0: the caller holds it")
    o = p.parse_args(argv)
    os.makedirs(o.out, exist_ok=True)
    LOCK.chunk = o.lock_chunk
    parts = o.parts.split(",")
    if parts != ["compare"]:  # compare takes the lock per run itself (part_compare)
        LOCK.acquire()
    _bpy_env()
    if "compare" in parts or "summary" in parts:
        rows = []
        if "compare" in parts:
            part_compare(o, rows)
        else:
            collect(o, rows)
        write_summary(o, rows)
    if "leak" in parts:
        part_leak(o)
    if "stability" in parts:
        part_stability(o)
    if "lag" in parts:
        part_lag(o)
    if "variant" in parts:
        part_variant(o)
    if "testmotion" in parts:
        part_testmotion(o)


if __name__ == "__main__":
    main()
