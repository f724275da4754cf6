#!/usr/bin/env python3
"""Batch comparison of GI Preview techniques with Cycles.

Runs as
    blender -b scene.blend -P scripts/gi_compare.py -- [SCENE] ARGS
    python scripts/gi_compare.py SCENE ARGS            (with the PyPI ``bpy`` module)
where SCENE is a .blend path or a built-in demo scene name (cornell, glossy_spheres,
sunlit_room, emissive_panel, many_lights, courtyard_loft). Under ``blender -b file.blend`` SCENE may be left
out: the file's current scene is used.

ARGS
  --techniques A,B      technique ids (default: all available)
  --denoiser D          AUTO (default: each technique's own filter, as Blender's Technique
                        Default: SVGF for RESTIR_GI, none for the others), NONE, ATROUS or SVGF
  --quality LEVELS      e.g. 0,1,2 or all (default: all levels of each technique)
  --res N               width in pixels (height keeps the scene's aspect; demo scenes are square)
  --ref-spp N           Cycles reference samples (default 256)
  --frames N            timed renders per technique and quality, after a cold and a warm first
                        render (time_ms = their median wall time; default 3)
  --samples N           accumulation samples for techniques that converge (default 1)
  --ttq LIST            sample counts of each technique's time-to-quality curve (default
                        1,2,4,8,16; none to skip)
  --viewport-frames N   viewport redraws timed per technique (default 4)
  --cycles-curve LIST   Cycles spp list for its own error/time curve (default 1,2,4,...,ref-spp/4)
  --baselines LIST      what a user would pick instead, measured in the same run against the
                        'full' reference: any of cycles, cycles_denoised, eevee, or none
                        (default cycles,cycles_denoised,eevee; 'cycles' is always measured)
  --denoised-curve LIST spp list for Cycles + OpenImageDenoise (default: the Cycles list)
  --eevee-samples LIST  EEVEE sample counts (default 1,2,4,8); EEVEE's first render in a
                        process compiles its shaders (about 40 s on llvmpipe): reported as
                        setup, never as per-frame time
  --reference KIND      full | direct | one_bounce | ao | auto (default auto: each technique
                        against the reference it models, and also against full)
  --seed N              reference seed (default 0)
  --out DIR             output folder (default ./gi_compare_out)
  --cache DIR           reference cache folder (default: the user cache)
  --no-cache            always re-render the references
  --use-installed       use the installed extension even when run from a checkout
  --animation [MOTION]  per-frame comparison of an animation instead of a still (see
                        docs/COMPARISON.md, addon/compare/animation.py): MOTION is orbit
                        (default), dolly, pan, light, or scene (the file's own animation)
  --anim-frames N       moving frames after the start pose (12); --anim-hold N still frames
                        after the stop (10); --anim-amount X the size of the move (orbit 12
                        degrees, dolly/pan/light 0.15/0.12/0.15 x the viewed distance, a sun
                        30 degrees); --anim-ref-spp N Cycles spp per frame (256) and
                        --anim-ref-denoise on|off (on: OpenImageDenoise); --anim-draws N
                        independent noise draws of the run (1; the trail and stability figures
                        are their means); techniques default to SVGF,TAA and each technique's
                        default quality

Several scenes (names, .blend files, folders of .blend files) write one folder each under
DIR, plus index.html and summary.json; a rerun keeps what an earlier run finished:
  --workers N           on a local Dask cluster of N worker processes (127.0.0.1, one thread each)
  --scheduler ADDRESS   on a running Dask scheduler and its workers (see docs/COMPARISON.md)
  --retries N           with Dask: runs of a task that raises (2); --no-resume: run everything again
Without --workers or --scheduler nothing of Dask is imported.

Timing (docs/COMPARISON.md, "Cost"): a technique's ``time_ms`` is the wall time of one F12
render after setup: the per-render preparation (scene analysis, upload check, AUTO's plan),
the warm-up frames, ``samples`` accumulated frames and the read-back (``frames_ms`` is the
frames alone, ``frame_ms`` x samples). Its one-time setup (scene export, GPU upload, BVH
build, shader compilation, including the driver's compiles at first use) is measured twice:
``setup_ms`` cold (the driver's shader cache cannot serve it) and ``setup_warm_ms`` (it can).
Over several scenes, a (technique, quality, denoiser)'s cold compile is measured on the first
scene a process renders it for, and later scenes add that to their own export.
``viewport_frame_ms`` is one viewport redraw. ``time_to_quality``: the error after 1, 2, 4,
... samples against the wall time from the first frame (time_to_quality.svg). The baselines'
wall times are split the same way: ``wall = setup + per_sample x spp`` fitted over each
curve; each point's ``time_ms`` leaves the setup out (``wall_ms`` keeps the raw wall time).
Equal-error speed-ups are given against every baseline with ``time_ms`` (warm-up counted),
and with the frames alone as ``speedups_frames_only``.

Writes into DIR: per technique and quality ``<TECH>_q<Q>.exr`` (linear), ``.png`` (sRGB
"Standard" view), ``<TECH>_q<Q>_vs_<kind>_error.png`` (relMSE heat map); ``reference_<kind>``
EXR/PNG; ``results.json``; ``chart.svg`` (+ ``chart.png`` when matplotlib is importable,
one per extra reference kind as ``chart_<kind>``); ``report.html`` (self-contained).
"""
from __future__ import annotations

import argparse
import datetime
import hashlib
import importlib
import json
import math
import os
import secrets
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEMOS = ("cornell", "glossy_spheres", "sunlit_room", "emissive_panel", "many_lights", "courtyard_loft")
REF_KINDS = ("full", "direct", "one_bounce", "ao")
BASELINES = ("cycles", "cycles_denoised", "eevee")
# (technique, quality, denoiser) -> its cold setup as measured on the first scene of this process:
# {"renderer_ms", "first_render_ms", "renderer_setup_ms", "scene", "salt"}
_COLD_SETUP: dict = {}


def log(msg: str):
    print(f"[gi_compare {time.strftime('%H:%M:%S')}] {msg}", flush=True)


# ---------------------------------------------------------------- arguments
def _script_argv() -> tuple[list[str], bool]:
    """(our arguments, running inside the Blender binary?)."""
    argv = sys.argv
    in_blender = False
    try:
        import bpy
        in_blender = bool(bpy.app.binary_path) and os.path.basename(argv[0]) != os.path.basename(__file__)
    except ImportError:
        pass
    if "--" in argv:
        return argv[argv.index("--") + 1:], in_blender
    if in_blender:
        return [], True
    return argv[1:], False


def parse_args(argv: list[str], scene_optional: bool):
    p = argparse.ArgumentParser(prog="gi_compare.py", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenes", nargs="*" if scene_optional else "+", metavar="SCENE",
                   help=".blend path, demo scene name (" + ", ".join(DEMOS) + ") or a folder of .blend "
                        "files; several scenes write one folder each under --out and an index.html")
    p.add_argument("--techniques", default="")
    p.add_argument("--denoiser", default="AUTO", type=str.upper, choices=("AUTO", "NONE", "ATROUS", "SVGF"),
                   help="filter that ends each technique's frames, as the render panel's Denoiser: AUTO "
                        "(default) = each technique's own default, as in Blender (SVGF for RESTIR_GI, none "
                        "for the others); NONE shows every technique raw")
    p.add_argument("--quality", default="all")
    p.add_argument("--res", type=int, default=None)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--samples", type=int, default=1)
    p.add_argument("--ttq", default="1,2,4,8,16",
                   help="sample counts of each technique's time-to-quality curve, or none")
    p.add_argument("--viewport-frames", type=int, default=4,
                   help="viewport redraws timed per technique (one frame each, analysis and read-back included)")
    p.add_argument("--cycles-curve", default="")
    p.add_argument("--baselines", default="cycles,cycles_denoised,eevee")
    p.add_argument("--denoised-curve", default="")
    p.add_argument("--eevee-samples", default="1,2,4,8")
    p.add_argument("--reference", default="auto", choices=REF_KINDS + ("auto",))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="gi_compare_out")
    p.add_argument("--cache", default=None)
    p.add_argument("--no-cache", action="store_true")
    p.add_argument("--use-installed", action="store_true")
    p.add_argument("--animation", nargs="?", const="orbit", default=None,
                   choices=("orbit", "dolly", "pan", "light", "scene"))
    p.add_argument("--anim-frames", type=int, default=12)
    p.add_argument("--anim-hold", type=int, default=10)
    p.add_argument("--anim-amount", type=float, default=None)
    p.add_argument("--anim-ref-spp", type=int, default=256)
    p.add_argument("--anim-ref-denoise", choices=("on", "off"), default="on")
    p.add_argument("--anim-draws", type=int, default=1)
    p.add_argument("--workers", type=int, default=None,
                   help="run on a local Dask cluster of N worker processes (one thread each)")
    p.add_argument("--scheduler", default=None, help="run on the Dask scheduler at ADDRESS (tcp://host:8786)")
    p.add_argument("--retries", type=int, default=2,
                   help="with Dask: how often a task that raises is run again (a worker that dies "
                        "mid-task has its task rescheduled in any case)")
    p.add_argument("--no-resume", action="store_true",
                   help="with several scenes or Dask: run every task again, even those a previous run finished")
    a = p.parse_args(argv)
    a.scene = a.scenes[0] if len(a.scenes) == 1 else None
    a.distributed = a.workers is not None or a.scheduler is not None
    if a.workers is not None and a.scheduler is not None:
        p.error("--workers and --scheduler exclude each other")
    if a.workers is not None and a.workers < 1:
        p.error("--workers must be >= 1")
    if a.animation and (a.distributed or len(a.scenes) > 1):
        p.error("--animation compares one scene on this machine (no --workers/--scheduler)")
    if a.ref_spp < 1 or a.frames < 1 or a.samples < 1:
        p.error("--ref-spp, --frames and --samples must be >= 1")
    def spp_list(text, name):
        try:
            v = sorted({int(x) for x in text.split(",") if x.strip()})
        except ValueError:
            p.error(f"{name} must be a comma-separated list of sample counts, got {text!r}")
        if not v or v[0] < 1:
            p.error(f"{name} must hold sample counts >= 1, got {text!r}")
        return v
    a.ttq = [] if a.ttq.strip().lower() in ("", "none", "0") else spp_list(a.ttq, "--ttq")
    if a.viewport_frames < 0:
        p.error("--viewport-frames must be >= 0")
    if a.cycles_curve:
        a.curve = spp_list(a.cycles_curve, "--cycles-curve")
    else:
        a.curve, s = [], 1
        while s <= max(1, a.ref_spp // 4):
            a.curve.append(s)
            s *= 2
    a.denoised_curve = spp_list(a.denoised_curve, "--denoised-curve") if a.denoised_curve else list(a.curve)
    a.eevee_samples = spp_list(a.eevee_samples, "--eevee-samples")
    names = [b.strip() for b in a.baselines.split(",") if b.strip() and b.strip() != "none"]
    bad = [b for b in names if b not in BASELINES]
    if bad:
        p.error(f"--baselines: unknown {', '.join(bad)}; choose from {', '.join(BASELINES)} or none")
    a.baselines = ["cycles"] + [b for b in BASELINES[1:] if b in names]
    return a


# ---------------------------------------------------------------- finding the add-on
def find_addon(use_installed: bool):
    """The gi_preview package: the checkout's ``addon/`` (via a symlink package in a temp
    dir) when run from a checkout, else the installed extension (``bl_ext.*.gi_preview``)."""
    checkout = os.path.join(REPO, "addon")
    if not use_installed and os.path.isdir(os.path.join(checkout, "compare")):
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from _checkout import import_checkout_package

        return import_checkout_package()
    import bpy
    for name in bpy.context.preferences.addons.keys():
        if name.endswith(".gi_preview") or name == "gi_preview":
            return importlib.import_module(name)
    import addon_utils
    for mod in addon_utils.modules():
        if mod.__name__.endswith(".gi_preview"):
            addon_utils.enable(mod.__name__, default_set=False)
            return importlib.import_module(mod.__name__)
    raise SystemExit("gi_compare: GI Preview not found: run from a checkout or install the extension")


# ---------------------------------------------------------------- helpers
def _finite(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None if v != v else (1e308 if v > 0 else -1e308)
    return v


def _clean_json(o):
    if isinstance(o, dict):
        return {str(k): _clean_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean_json(v) for v in o]
    if isinstance(o, float):
        return _finite(o)
    if hasattr(o, "item") and not isinstance(o, (str, bytes)):
        try:
            return _clean_json(o.item())
        except (ValueError, TypeError):
            pass
    return o


_ID_COLLECTIONS = ("scenes", "objects", "meshes", "materials", "lights", "cameras", "worlds", "images",
                   "node_groups", "collections", "textures", "curves")


def _data_ids(bpy) -> dict:
    return {(attr, idb.name_full): idb for attr in _ID_COLLECTIONS for idb in getattr(bpy.data, attr)}


def _load_scene(bpy, name_or_path: str | None, demo_scenes):
    if name_or_path is None:
        return bpy.context.scene
    if name_or_path.lower().endswith(".blend"):
        if not os.path.exists(name_or_path):
            raise SystemExit(f"gi_compare: no such file {name_or_path}")
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(name_or_path))
        return bpy.context.scene
    if name_or_path in DEMOS or demo_scenes is not None:
        return demo_scenes.build_demo(name_or_path)
    raise SystemExit(f"gi_compare: {name_or_path!r} is neither a .blend nor a demo scene ({', '.join(DEMOS)})")


def expand_scenes(items) -> list[dict]:
    """The scenes of the command line as [{"label", "spec", "error"}]: a folder gives its .blend
    files (sorted); ``label`` names the scene's output folder (the demo name or the file's stem,
    made unique); ``error`` is set for a missing file or an unknown name (the sweep goes on)."""
    found = []
    for it in items:
        if os.path.isdir(it):
            blends = sorted(f for f in os.listdir(it) if f.lower().endswith(".blend"))
            if not blends:
                found.append((os.path.basename(os.path.normpath(it)), os.path.abspath(it),
                              f"no .blend files in the folder {it}"))
            found += [(os.path.splitext(f)[0], os.path.abspath(os.path.join(it, f)), None) for f in blends]
        elif it.lower().endswith(".blend"):
            err = None if os.path.isfile(it) else f"gi_compare: no such file {it}"
            found.append((os.path.splitext(os.path.basename(it))[0], os.path.abspath(it), err))
        else:
            err = None if it in DEMOS else \
                f"gi_compare: {it!r} is neither a .blend nor a demo scene ({', '.join(DEMOS)})"
            found.append((it, it, err))
    out, seen = [], {}
    for label, spec, err in found:
        label = "".join(c if c.isalnum() or c in "-_." else "_" for c in label) or "scene"
        n = seen[label] = seen.get(label, 0) + 1
        out.append({"label": label if n == 1 else f"{label}_{n}", "spec": spec, "error": err})
    return out


def write_index(opts, rows: list[dict], *, wall_s: float, workers: int | None = None, tasks_run=(),
                tasks_skipped: int = 0, log=log) -> dict:
    """``<out>/summary.json`` and ``<out>/index.html`` over the scenes of a sweep. ``rows``:
    [{"label", "scene", "error", "report", "results", "summary" (the scene's results dict)}]."""
    pkg = find_addon(opts.use_installed)
    report = importlib.import_module(pkg.__name__ + ".compare.report")
    out = os.path.abspath(opts.out)
    scenes = []
    for r in rows:
        res = r.get("summary") or {}
        primary = res.get("baselines_reference") or "full"
        scenes.append({
            "label": r["label"], "scene": r["scene"], "name": res.get("scene"), "error": r.get("error"),
            "report": r.get("report"), "results": r.get("results"),
            "resolution": res.get("resolution"), "reference": primary,
            "reference_ms": (res.get("reference") or {}).get("time_ms"),
            "reference_spp": (res.get("reference") or {}).get("spp"),
            "rows": [{"technique": e["technique"], "quality": e["quality"], "denoiser": e.get("denoiser"),
                      "relmse": e["relmse"], "flip": e["flip"], "time_ms": e["time_ms"],
                      "speedup": (e.get("speedup") or {}).get("speedup")}
                     for e in res.get("entries", []) if e["reference"] == primary]})
    summary = _clean_json({
        "date": datetime.datetime.now().isoformat(timespec="seconds"), "wall_s": wall_s,
        "workers": workers, "mode": "dask" if workers else "serial",
        "settings": {k: getattr(opts, k, None) for k in ("techniques", "quality", "res", "ref_spp", "frames",
                                                           "samples", "reference", "seed")},
        "scenes": scenes, "failed": [s["label"] for s in scenes if s["error"]],
        "tasks_run": list(tasks_run), "tasks_skipped": tasks_skipped})
    with open(os.path.join(out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    report.write_index(os.path.join(out, "index.html"), summary)
    ok = len(scenes) - len(summary["failed"])
    log(f"{ok} of {len(scenes)} scene(s) compared in {wall_s:.1f} s; wrote {os.path.join(out, 'index.html')}")
    for s in scenes:
        if s["error"]:
            log(f"  {s['label']}: FAILED: {s['error']}")
    return summary


def run_scenes(opts, scenes: list[dict]) -> dict:
    """Several scenes on this machine, one after another: ``<out>/<label>/`` per scene (a
    scene's results are kept when a rerun finds its results.json with the same settings), then
    the index."""
    import copy
    t0 = time.perf_counter()
    rows = []
    for sc in scenes:
        row = {"label": sc["label"], "scene": sc["spec"], "error": sc["error"], "report": None, "results": None}
        rows.append(row)
        if row["error"]:
            log(f"{sc['label']}: {row['error']}")
            continue
        o = copy.copy(opts)
        o.scene, o.out = sc["spec"], os.path.join(opts.out, sc["label"])
        done = os.path.join(o.out, "results.json")
        key = os.path.join(o.out, "settings.json")
        settings = json.dumps({k: getattr(opts, k, None) for k in _RESULT_OPTIONS}, sort_keys=True, default=str)
        try:
            if not opts.no_resume and os.path.exists(done) and os.path.exists(key) \
                    and open(key, encoding="utf-8").read() == settings:
                log(f"{sc['label']}: results.json already there with these settings; skipped")
                with open(done, encoding="utf-8") as f:
                    row["summary"] = json.load(f)
            else:
                row["summary"] = run(o)
                with open(key, "w", encoding="utf-8") as f:
                    f.write(settings)
            row["report"] = os.path.join(sc["label"], "report.html")
            row["results"] = os.path.join(sc["label"], "results.json")
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - one scene's failure is reported, not fatal
            row["error"] = str(exc.code) if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}"
            log(f"{sc['label']}: FAILED: {row['error']}")
    return write_index(opts, rows, wall_s=time.perf_counter() - t0)


_RESULT_OPTIONS = ("techniques", "denoiser", "quality", "res", "ref_spp", "frames", "samples", "ttq", "curve",
                   "baselines", "denoised_curve", "eevee_samples", "reference", "seed", "no_cache")


def _resolution(scene, res):
    r = scene.render
    w = int(r.resolution_x * r.resolution_percentage / 100)
    h = int(r.resolution_y * r.resolution_percentage / 100)
    if res:
        h = max(4, int(round(res * h / max(1, w))))
        w = int(res)
    return w, h


# ---------------------------------------------------------------- the run
class _Run:
    """What every step of a comparison needs: the package's modules, the plan (technique,
    quality) and the reference kinds; after :meth:`load_scene` also the scene, its export and
    its resolution. The serial run uses one; a distributed run makes one per task (the steps
    below are the tasks)."""

    def __init__(self, opts, *, pkg=None, session=None):
        self.opts = opts
        self.pkg = pkg or find_addon(opts.use_installed)
        pn = self.pkg.__name__
        for name, path in (("reference", "blender.reference"), ("export", "blender.export"),
                           ("metrics", "compare.metrics"), ("sweep", "compare.sweep"),
                           ("report", "compare.report"), ("imageio", "compare.imageio"),
                           ("techniques", "render.techniques")):
            setattr(self, name, importlib.import_module(f"{pn}.{path}"))
        self.session = session or importlib.import_module(pn + ".render.session")
        self.out = os.path.abspath(opts.out)
        self.scene = None
        self.curves, self.baselines = {}, {}

    # ---- techniques, quality levels and reference kinds (no scene needed)
    def make_plan(self, quiet: bool = False):
        opts = self.opts
        self.infos = infos = {t.id: t for t in self.session.available_techniques()}
        wanted = [t.strip() for t in opts.techniques.split(",") if t.strip()] or list(infos)
        unknown = [t for t in wanted if t not in infos]
        if unknown:
            raise SystemExit(f"gi_compare: unknown technique(s) {', '.join(unknown)}; available: {', '.join(infos)}")
        plan = []
        for t in wanted:
            levels = list(infos[t].quality_levels)
            if opts.quality != "all":
                req = [int(q) for q in opts.quality.split(",") if q.strip()]
                missing = [q for q in req if q not in levels]
                if missing and not quiet:
                    log(f"{t}: quality level(s) {missing} not in its ladder {levels}; skipped")
                levels = [q for q in req if q in levels]
            plan += [(t, q) for q in levels]
        if not plan:
            raise SystemExit("gi_compare: nothing to render (check --techniques/--quality)")
        self.plan = plan
        self.kinds = []
        for t, _ in plan:
            for k in self.kinds_for(t):
                if k not in self.kinds:
                    self.kinds.append(k)
        self.primary = "full" if "full" in self.kinds else self.kinds[0]
        return plan

    def kinds_for(self, tech):
        if self.opts.reference != "auto":
            return [self.opts.reference]
        k = getattr(self.infos[tech], "reference", "full") or "full"
        return [k] if k == "full" else [k, "full"]

    # ---- the scene, OpenGL and the export
    built_demo: list = []  # the datablocks of a demo scene this run built

    def release_scene(self):
        """Remove the demo scene this run built and its datablocks (a scene given or loaded from
        a file stays)."""
        if self.built_demo:
            import bpy
            alive = []
            for idb in self.built_demo:
                try:
                    idb.name  # noqa: B018 - raises ReferenceError once removed
                    alive.append(idb)
                except ReferenceError:
                    pass
            bpy.data.batch_remove(alive)
            self.scene, self.built_demo = None, []

    def load_scene(self, scene=None, quiet: bool = False):
        import bpy

        opts = self.opts
        self.reference.ensure_oiio()
        if scene is None:
            demo = None
            if opts.scene and not opts.scene.lower().endswith(".blend"):
                demo = importlib.import_module(self.pkg.__name__ + ".blender.demo_scenes")
            before = _data_ids(bpy) if demo is not None else None
            scene = _load_scene(bpy, opts.scene, demo)
            # a demo scene built for this run is removed with every datablock it made when the
            # run ends (release_scene), so each run in one process builds the same scene, with
            # the same names (and so the same reference)
            if demo is not None:
                self.built_demo = [idb for key, idb in _data_ids(bpy).items() if key not in before]
        self.scene = scene
        os.makedirs(self.out, exist_ok=True)
        self.w, self.h = w, h = _resolution(scene, opts.res)
        say = (lambda m: None) if quiet else log
        say(f"scene '{scene.name}' at {w}x{h}, output {self.out}")
        # OpenGL 4.3 first: without it nothing of ours can render, so fail before any Cycles work
        self.gl = importlib.import_module(self.pkg.__name__ + ".render.gl")
        self.gl_info = dict(self.gl.get_gl().info)
        say(f"OpenGL: {self.gl_info.get('GL_RENDERER')} ({self.gl_info.get('GL_VERSION')})")
        self.make_plan(quiet=quiet)
        # export once (the fingerprint keys the reference cache); its time is setup
        t0 = time.perf_counter()
        dg = self.reference.evaluated_depsgraph(scene)
        self.sd = self.export.export_scene(dg, width=w, height=h)
        self.export_ms = (time.perf_counter() - t0) * 1e3
        self.fp = self.sd.fingerprint()
        say(f"exported the scene in {self.export_ms:.0f} ms")
        support = importlib.import_module(self.pkg.__name__ + ".render.support").scene_support(self.sd)
        self.support = support
        say(support["summary"])
        for kind in ("materials", "lights"):
            for name, e in support[kind].items():
                if e["status"] != "exact":
                    say(f"  {kind[:-1]} '{name}': {e['status']}: {e['detail']}")
        if support["world"]["status"] != "exact" or support["world"]["detail"] != "uniform colour":
            say(f"  world: {support['world']['status']}: {support['world']['detail']}")
        return scene

    def scene_meta(self) -> dict:
        """What the results need of the scene, without the scene (plain data)."""
        import bpy
        return {"scene": self.scene.name, "w": self.w, "h": self.h, "fp": self.fp, "export_ms": self.export_ms,
                "support": self.support, "gl_info": self.gl_info, "blender": bpy.app.version_string}

    # ---- Cycles: a reference, its curve, the other baselines
    def get_reference(self, k):
        opts = self.opts
        log(f"Cycles reference '{k}' at {opts.ref_spp} spp ...")
        r = self.reference.get_reference(self.scene, k, opts.ref_spp, seed=opts.seed, width=self.w, height=self.h,
                                         fingerprint=self.fp, cache_dir=opts.cache, use_cache=not opts.no_cache)
        log(f"  {'from cache' if r.cached else 'rendered'}: {r.time_ms:.0f} ms")
        self.imageio.write_exr(os.path.join(self.out, f"reference_{k}.exr"), r.image)
        self.imageio.write_png(os.path.join(self.out, f"reference_{k}.png"), self.metrics.view_standard(r.image))
        return r

    def _progress(self, name):
        return lambda i, n, spp, ms: log(f"  {name} {spp:>5} spp: {ms:8.0f} ms wall ({i}/{n})")

    def cycles_curve(self, k, ref) -> dict:
        log(f"Cycles curve '{k}' at {self.opts.curve} spp ...")
        bc = self.reference.baseline_curve(self.scene, "cycles", self.opts.curve, ref, seed=self.opts.seed + 1,
                                           progress=self._progress("Cycles"))
        log(f"  setup {bc['setup_ms']:.0f} ms + {bc['per_sample_ms']:.2f} ms/spp")
        return bc

    def baseline(self, name, ref, cyc_setup) -> dict:
        spps = self.opts.denoised_curve if name == "cycles_denoised" else self.opts.eevee_samples
        log(f"{self.reference.BASELINE_LABELS[name]} at {spps} samples (untimed warm-up first) ...")
        bc = self.reference.baseline_curve(self.scene, name, spps, ref, seed=self.opts.seed + 1,
                                           setup_ms=cyc_setup if name == "cycles_denoised" else None,
                                           progress=self._progress(name))
        extra = bc["first_render_extra_ms"]
        log(f"  setup {bc['setup_ms']:.0f} ms + {bc['per_sample_ms']:.2f} ms/sample"
            + (f"; first render +{extra:.0f} ms (warm-up)" if extra is not None else ""))
        return bc

    def baseline_names(self) -> list[str]:
        """The baselines besides Cycles that this run measures (they need the 'full' reference)."""
        return list(self.opts.baselines[1:]) if self.primary == "full" else []

    def set_curves(self, curves: dict, baselines: dict):
        """``curves``: {kind: Cycles curve}; ``baselines``: {name: curve} (all from baseline_curve)."""
        self.curves, self.baselines = curves, baselines

    def baseline_curves_for(self, k):
        """{baseline name: [(spp, time_ms, relmse)]} for entries measured against kind k."""
        if k != self.primary:
            return {"cycles": [(c["spp"], c["time_ms"], c["relmse"]) for c in self.curves[k]["points"]]}
        return {b: [(c["spp"], c["time_ms"], c["relmse"]) for c in bc["points"]] for b, bc in self.baselines.items()}

    def speedups(self, e, time_key: str = "time_ms") -> dict:
        return {b: self.sweep.equal_error_speedup(e["relmse"], e[time_key], cur,
                                                  name=self.reference.BASELINE_LABELS[b])
                for b, cur in self.baseline_curves_for(e["reference"]).items()}

    def time_to_quality(self, kw: dict, refs: dict, tech: str) -> dict:
        """{reference kind: [{"samples", "time_ms", "relmse"}]}: the error after each sample
        count of ``--ttq`` against the wall time from the first frame (a fresh render's prep
        and warm-up, then the accumulation continued to the next count; no setup, as in the
        baselines' curves). What an artist waits for to see that quality."""
        out = {k: [] for k in self.kinds_for(tech)}
        t_acc, done = 0.0, 0
        for n in self.opts.ttq:
            if n <= done:
                continue
            extra = {} if done == 0 else {"keep_history": True, "continue_accumulation": True}
            t0 = time.perf_counter()
            r = self.session.render(self.sd, **{**kw, "samples": n - done, **extra})
            t_acc += (time.perf_counter() - t0) * 1e3
            done = n
            for k in out:
                out[k].append({"samples": n, "time_ms": t_acc,
                               "relmse": float(self.metrics.relmse(r.image, refs[k].image))})
        return out

    # ---- one technique at one quality level: the rows (one per reference kind) and report images
    def render_row(self, tech, q, refs, i=0, n=1):
        import numpy as np

        opts, session, metrics, imageio = self.opts, self.session, self.metrics, self.imageio
        out, sd = self.out, self.sd
        denoiser = self.techniques.resolve_denoiser(tech, opts.denoiser)
        log(f"[{i + 1}/{n}] {tech} q{q}{'' if denoiser == 'NONE' else ' + ' + denoiser}: "
            f"{opts.frames} render(s) of {opts.samples} sample(s) ...")
        # Every row starts from fresh GPU sessions, so it pays and reports its own setup, whatever
        # rows ran before: (1) cold: a new session whose programs the driver's shader cache
        # cannot serve (a new salt in their source: as on a first start after installing the
        # add-on or a driver); (2) warm: a new session again, the driver's cache now holding the
        # programs (a later start of Blender); (3) the timed renders in that session (a repeated
        # F12: prep + warm-up frames + accumulated frames + read-back, no setup). A setup is the
        # excess of (1) or (2) over (3)'s median, plus the scene export. (1) compiles the same
        # programs for every scene, so a sweep pays it once per process and technique: a later
        # scene skips (1), reuses the first scene's salt for (2), and counts the compile
        # measured on that first scene.
        gl_call = self.gl.get_gl().call
        shaders = importlib.import_module(self.pkg.__name__ + ".render.shaders")
        kw = dict(technique=tech, quality=q, denoiser=denoiser)
        known = _COLD_SETUP.get((tech, q, denoiser))

        def timed(**extra):
            t0 = time.perf_counter()
            r = session.render(sd, **{**kw, "samples": opts.samples, **extra})
            return r, (time.perf_counter() - t0) * 1e3

        gl_call(session.release_all)
        salt = known["salt"] if known else secrets.randbits(30)
        shaders.set_driver_cache_salt(salt)
        try:
            if known is None:
                cold, cold_ms = timed()
                gl_call(session.release_all)
            warm, warm_ms = timed()
            runs = [timed() for _ in range(opts.frames)]
            ttq = self.time_to_quality(kw, refs, tech) if opts.ttq else {}
            # the viewport: one frame per redraw, continuing the accumulation; its wall time per
            # call is what a redraw costs (analysis, upload check, the frame, the read-back)
            vp_ms = [timed(samples=1, keep_history=True, continue_accumulation=True)[1]
                     for _ in range(opts.viewport_frames)]
        finally:
            shaders.set_driver_cache_salt(None)
        results = [r for r, _ in runs]
        res = results[-1]
        render_ms = statistics.median(ms for _, ms in runs)
        frame_ms = statistics.median(float(r.frame_ms) for r in results)
        total_ms = statistics.median(float(r.total_ms) for r in results)
        n_samples = max(1, int(getattr(res, "samples", opts.samples) or 1))
        # time_ms: what one render costs after setup (warm-up and read-back counted); the
        # frames alone (frame_ms x samples) are kept as frames_ms
        time_ms = render_ms
        frames_ms = frame_ms * n_samples
        if known is None:
            known = _COLD_SETUP[(tech, q, denoiser)] = {
                "renderer_ms": max(0.0, cold_ms - render_ms), "first_render_ms": cold_ms, "salt": salt,
                "renderer_setup_ms": float(getattr(cold, "setup_ms", 0.0) or 0.0),
                "scene": os.path.basename(str(opts.scene or self.scene.name))}
            source = "cold first render's wall time minus a timed render's"
        else:
            cold_ms = render_ms + known["renderer_ms"]
            source = (f"the compile measured on {known['scene']} (its cold first render's wall time "
                      f"minus a timed render's) plus this scene's export")
        setup_ms = self.export_ms + known["renderer_ms"]
        setup_warm_ms = self.export_ms + max(0.0, warm_ms - render_ms)
        cost = {"setup_cold_ms": setup_ms, "setup_warm_ms": setup_warm_ms, "export_ms": self.export_ms,
                "first_render_cold_ms": cold_ms, "first_render_warm_ms": warm_ms,
                "renderer_setup_ms": known["renderer_setup_ms"], "cold_measured_on": known["scene"],
                "warmup_frames": int(statistics.median(int(r.warmup_frames) for r in results)),
                "warmup_ms": statistics.median(float(r.warmup_ms) for r in results),
                "prep_ms": statistics.median(float(r.prep_ms) for r in results),
                "render_ms": render_ms, "frames_ms": frames_ms,
                "viewport_frame_ms": statistics.median(vp_ms) if vp_ms else None}
        img = np.asarray(res.image, np.float32)
        base = f"{tech}_q{q}"
        imageio.write_exr(os.path.join(out, base + ".exr"), img)
        imageio.write_png(os.path.join(out, base + ".png"), metrics.view_standard(img))
        ours_png = imageio.png_bytes(metrics.view_standard(img))
        image_sha256 = hashlib.sha256(np.ascontiguousarray(img).tobytes()).hexdigest()  # identical images fold
        # per-effect error: an effect pass against the Cycles reference of just that effect,
        # when this run rendered it (direct light: GI_Direct + Emit vs 'direct'; AO: GI_AO vs 'ao')
        aovs = getattr(res, "aovs", {}) or {}
        test_aovs, ref_aovs = {}, {}
        if "GI_Direct" in aovs and "direct" in refs:
            test_aovs["direct"] = aovs["GI_Direct"] + aovs.get("Emit", 0.0)
            ref_aovs["direct"] = refs["direct"].image[..., :3]
        if "GI_AO" in aovs and "ao" in refs:
            test_aovs["ao"] = aovs["GI_AO"]
            ref_aovs["ao"] = refs["ao"].image[..., :3]
        entries, images = [], {}
        for k in self.kinds_for(tech):
            ref = refs[k]
            m = metrics.compare(img, ref.image, test_aovs=test_aovs, ref_aovs=ref_aovs)
            heat, legend = metrics.heatmap(img, ref.image)
            epath = os.path.join(out, f"{base}_vs_{k}_error.png")
            imageio.write_png(epath, heat)
            e = {"technique": tech, "quality": q, "denoiser": denoiser, "reference": k, "time_ms": time_ms,
                 "frame_ms": frame_ms, "frames_ms": frames_ms, "total_ms": total_ms,
                 "samples": int(getattr(res, "samples", 1)), "setup_ms": setup_ms, "setup_warm_ms": setup_warm_ms,
                 "warmup_frames": cost["warmup_frames"], "warmup_ms": cost["warmup_ms"],
                 "viewport_frame_ms": cost["viewport_frame_ms"], "cost": cost,
                 "setup": {"export_ms": self.export_ms, "renderer_ms": setup_ms - self.export_ms,
                           "first_render_ms": cold_ms,
                           "source": source},
                 "time_to_quality": ttq.get(k, []),
                 "relmse": m["relmse"], "flip": m["flip"], "flip_ldr": m["flip_ldr"], "ssim": m["ssim"],
                 "psnr": m["psnr"], "nonfinite_pixels": m["nonfinite_pixels"],
                 "image_sha256": image_sha256,
                 "effects": list(getattr(res, "effects", []) or []),
                 "skipped_passes": [s.as_dict() if hasattr(s, "as_dict") else dict(s)
                                    for s in (getattr(res, "skipped_passes", []) or [])],
                 "effect_errors": m.get("effects", {}),
                 "warnings": list(getattr(res, "warnings", []) or []),
                 "speedup": None,
                 "speedups": None,
                 "files": {"exr": base + ".exr", "png": base + ".png", "error_png": os.path.basename(epath)}}
            entries.append(e)
            images[self.report.entry_id(tech, q, k)] = {
                "ours": ours_png, "cycles": imageio.png_bytes(metrics.view_standard(ref.image)),
                "error": imageio.png_bytes(heat)}
            line = (f"  vs {k}: {time_ms:.1f} ms/render ({cost['warmup_frames']} warm-up frames "
                    f"{cost['warmup_ms']:.0f} ms + {n_samples} x {frame_ms:.1f} ms; setup cold {setup_ms:.0f} / "
                    f"warm {setup_warm_ms:.0f} ms)  relMSE {m['relmse']:.4g}  FLIP {m['flip']:.4g}  "
                    f"SSIM {m['ssim']:.4f}")
            if self.baselines:  # the curves are known: the speed-ups now
                sps = e["speedups"] = self.speedups(e)
                e["speedup"] = sps["cycles"]
                e["speedups_frames_only"] = self.speedups(e, "frames_ms")
                line += "  speed-up: " + "  ".join(f"{b} {self.sweep.speedup_text(v, plain=True)}"
                                                   for b, v in sps.items())
            log(line)
        return entries, images

    # ---- results.json, the charts and report.html
    def finish(self, meta: dict, refs: dict, entries: list, images: dict) -> dict:
        """``meta``: :meth:`scene_meta`; ``refs``: {kind: Reference}; ``entries``/``images``:
        the rows and images of :meth:`render_row`, in plan order. Curves from :meth:`set_curves`."""
        import numpy as np

        opts, metrics, imageio, report, sweep = self.opts, self.metrics, self.imageio, self.report, self.sweep
        out, primary, kinds = self.out, self.primary, self.kinds
        os.makedirs(out, exist_ok=True)
        w, h, name = meta["w"], meta["h"], meta["scene"]
        for e in entries:
            if e["speedups"] is None:
                e["speedups"] = self.speedups(e)
                e["speedup"] = e["speedups"]["cycles"]
                e["speedups_frames_only"] = self.speedups(e, "frames_ms")

        def strip(points):
            return [{k: v for k, v in c.items() if k != "image"} for c in points]
        curves = {k: strip(bc["points"]) for k, bc in self.curves.items()}
        curve_info = {k: {key: v for key, v in bc.items() if key != "points"} for k, bc in self.curves.items()}
        baselines = {b: strip(bc["points"]) for b, bc in self.baselines.items()}
        baseline_info = {b: {key: v for key, v in bc.items() if key != "points"} for b, bc in self.baselines.items()}
        baseline_images = {b: bc["points"][-1]["image"] for b, bc in self.baselines.items()}
        if primary != "full" and len(opts.baselines) > 1:
            log(f"baselines {', '.join(opts.baselines[1:])} need the 'full' reference (--reference "
                f"{opts.reference}): not measured")
        # ---- chart(s): the primary one carries every baseline
        charts = {}
        for k in kinds:
            pts = [{"technique": e["technique"], "quality": e["quality"], "time_ms": e["time_ms"],
                    "error": e["relmse"]} for e in entries if e["reference"] == k]
            base = os.path.join(out, "chart" if k == primary else f"chart_{k}")
            labels = {"cycles": "Cycles (spp)", "cycles_denoised": "Cycles + OIDN (spp)",
                      "eevee": "EEVEE ray tracing (samples)"}
            cur = {labels[b]: c for b, c in self.baseline_curves_for(k).items()}
            c = sweep.write_chart(pts, cur, base, metric="relMSE",
                                  title=f"{name}: cost vs accuracy against Cycles '{k}' ({opts.ref_spp} spp)")
            charts[k] = c
            if c["png"] is None and k == primary:
                log("matplotlib is not importable: chart written as SVG only")
        # time to quality: each technique's error against wall time from its first frame
        ttq_series = {f"{e['technique']} q{e['quality']}" + (f" + {e['denoiser']}" if e.get("denoiser") not in
                                                              (None, "NONE") else ""):
                      [(c["samples"], c["time_ms"], c["relmse"])
                                                          for c in e.get("time_to_quality") or []]
                      for e in entries if e["reference"] == primary and e.get("time_to_quality")}
        if ttq_series:
            labels = {"cycles": "Cycles (spp)", "cycles_denoised": "Cycles + OIDN (spp)",
                      "eevee": "EEVEE ray tracing (samples)"}
            charts["time_to_quality"] = sweep.write_chart(
                [], {labels[b]: c for b, c in self.baseline_curves_for(primary).items()},
                os.path.join(out, "time_to_quality"), metric="relMSE", series=ttq_series,
                xlabel="wall time from the first frame (ms, log scale; setup left out)",
                title=f"{name}: time to quality against Cycles '{primary}' (samples labelled)")

        gl_info = meta["gl_info"]
        speedups = [{"technique": e["technique"], "quality": e["quality"], "reference": e["reference"],
                     "baseline": b, **v} for e in entries for b, v in e["speedups"].items()]
        results = {
            "scene": name, "resolution": [w, h], "fingerprint": meta["fp"],
            "run": {"date": datetime.datetime.now().isoformat(timespec="seconds"),
                    "blender": meta["blender"], "frames": opts.frames, "samples": opts.samples,
                    "ref_spp": opts.ref_spp, "reference_mode": opts.reference, "resolution": f"{w}x{h}",
                    "device": "GI Preview on {} ({}); Cycles on the CPU; EEVEE on Blender's own OpenGL context".format(
                        gl_info.get("GL_RENDERER"), gl_info.get("GL_VERSION")),
                    "gl_renderer": gl_info.get("GL_RENDERER"), "gl_version": gl_info.get("GL_VERSION"),
                    "baselines": ",".join(baselines)},
            "reference": {**refs[primary].info()},
            "references": {k: r.info() for k, r in refs.items()},
            "reference_settings": getattr(self.reference, "FAIR_SETTINGS_SUMMARY", ""),
            "export_ms": meta["export_ms"],
            "scene_support": meta["support"],
            "baselines": baselines,
            "baselines_reference": primary,
            "baselines_setup": baseline_info,
            "cycles_curve": curves[primary],
            "cycles_curves": curves,
            "cycles_curves_setup": curve_info,
            "entries": entries,
            "results": entries,
            "speedup": [{"technique": e["technique"], "quality": e["quality"], "reference": e["reference"],
                         **e["speedup"]} for e in entries],
            "speedups": speedups,
            "charts": {k: {"svg": os.path.basename(c["svg"]), "png": c["png"] and os.path.basename(c["png"])}
                       for k, c in charts.items()},
        }
        results = _clean_json(results)
        with open(os.path.join(out, "results.json"), "w", encoding="utf-8") as f:
            json.dump(results, f, indent=1)
        for k, r in refs.items():
            images[f"reference:{k}"] = imageio.png_bytes(metrics.view_standard(r.image))
        for b, img in baseline_images.items():
            spp = baselines[b][-1]["spp"]
            images[f"baseline:{b}"] = imageio.png_bytes(metrics.view_standard(img))
            imageio.write_png(os.path.join(out, f"baseline_{b}_{spp}spp.png"), metrics.view_standard(img))
        chart_html = "\n".join(charts[k]["svg_text"] for k in ([primary] + [k for k in kinds if k != primary]))
        if "time_to_quality" in charts:
            chart_html += ("\n<h3>Time to quality</h3><p class=\"meta\">Error against the wall time from the "
                           "first frame: warm-up and accumulation counted, setup left out on every side. "
                           "Each technique's points are its sample counts; the baselines' are their spp.</p>\n"
                           + charts["time_to_quality"]["svg_text"])
        _, legend = metrics.heatmap(np.zeros((1, 1, 3)), np.zeros((1, 1, 3)))
        report.write_html(os.path.join(out, "report.html"),
                          title=f"GI Preview vs Cycles: {name} ({w}x{h})", results=results,
                          images=images, chart_svg=chart_html,
                          colorbar_png=imageio.png_bytes(metrics.colorbar(256, 10)), legend=legend)
        log(f"wrote {os.path.join(out, 'results.json')} and report.html")
        return results


def run(opts, *, pkg=None, session=None, scene=None) -> dict:
    r = _Run(opts, pkg=pkg, session=session)
    r.load_scene(scene)
    refs, curves, baselines = {}, {}, {}
    for k in r.kinds:
        refs[k] = r.get_reference(k)
        curves[k] = r.cycles_curve(k, refs[k])
        if k == r.primary:
            baselines["cycles"] = curves[k]
    # the other baselines, against the primary reference
    for name in r.baseline_names():
        baselines[name] = r.baseline(name, refs[r.primary], baselines["cycles"]["setup_ms"])
    r.set_curves(curves, baselines)
    entries, images = [], {}
    for i, (tech, q) in enumerate(r.plan):
        e, im = r.render_row(tech, q, refs, i, len(r.plan))
        entries += e
        images.update(im)
    r.gl.get_gl().call(r.session.release_all)
    try:
        return r.finish(r.scene_meta(), refs, entries, images)
    finally:
        r.release_scene()


# ---------------------------------------------------------------- --animation
def run_animation(opts, *, pkg=None, session=None, scene=None) -> dict:
    """``--animation``: every frame against a Cycles reference of that frame (the logic is
    ``compare/animation.py``); writes results.json (``animation``), animation.png, the frame
    strips and report.html into ``--out``."""
    import bpy

    pkg = pkg or find_addon(opts.use_installed)
    pn = pkg.__name__
    mods = {m: importlib.import_module(f"{pn}.{p}") for m, p in (
        ("reference", "blender.reference"), ("export", "blender.export"), ("metrics", "compare.metrics"),
        ("report", "compare.report"), ("imageio", "compare.imageio"), ("animation", "compare.animation"))}
    A = mods["animation"]
    mods["reference"].ensure_oiio()
    session = session or importlib.import_module(pn + ".render.session")
    if scene is None:
        demo = importlib.import_module(pn + ".blender.demo_scenes") if opts.scene and not \
            opts.scene.lower().endswith(".blend") else None
        scene = _load_scene(bpy, opts.scene, demo)
    out = os.path.abspath(opts.out)
    os.makedirs(out, exist_ok=True)
    w, h = _resolution(scene, opts.res)
    infos = {t.id: t for t in session.available_techniques()}
    wanted = [t.strip() for t in opts.techniques.split(",") if t.strip()] or ["SVGF", "TAA"]
    unknown = [t for t in wanted if t not in infos]
    if unknown:
        raise SystemExit(f"gi_compare: unknown technique(s) {', '.join(unknown)}; available: {', '.join(infos)}")
    quality = {}
    if opts.quality != "all":
        q = [int(x) for x in opts.quality.split(",") if x.strip()]
        quality = {t: q[0] for t in wanted if q and q[0] in infos[t].quality_levels}
    quality = {t: quality.get(t, infos[t].default_quality) for t in wanted}
    spec = A.AnimationSpec(motion=opts.animation, move=opts.anim_frames, hold=opts.anim_hold,
                           amount=opts.anim_amount, ref_spp=opts.anim_ref_spp,
                           ref_denoise=opts.anim_ref_denoise == "on", seed=opts.seed,
                           draws=getattr(opts, "anim_draws", 1))
    log(f"animation '{spec.motion}' of scene '{scene.name}' at {w}x{h}: {spec.move} moving + {spec.hold} still "
        f"frames; Cycles {spec.ref_spp} spp{' + OIDN' if spec.ref_denoise else ''} per frame; {', '.join(wanted)}")
    res = A.run(scene, spec, wanted, reference=mods["reference"], export=mods["export"], session=session,
                width=w, height=h, quality=quality, cache_dir=opts.cache, use_cache=not opts.no_cache, log=log)
    gl_info = importlib.import_module(pn + ".render.gl").get_gl().info
    images = A.write_outputs(res, out, imageio=mods["imageio"], metrics=mods["metrics"],
                             title=f"{scene.name}: {spec.motion}, {w}x{h}")
    results = _clean_json({"scene": scene.name, "resolution": [w, h], "mode": "animation",
                           "run": {"date": datetime.datetime.now().isoformat(timespec="seconds"),
                                   "blender": bpy.app.version_string, "animation": spec.motion,
                                   "resolution": f"{w}x{h}", "ref_spp": spec.ref_spp,
                                   "ref_denoise": opts.anim_ref_denoise, "gl_renderer": gl_info.get("GL_RENDERER"),
                                   "gl_version": gl_info.get("GL_VERSION")},
                           "reference_settings": getattr(mods["reference"], "FAIR_SETTINGS_SUMMARY", ""),
                           "entries": [], "animation": res["animation"]})
    with open(os.path.join(out, "results.json"), "w", encoding="utf-8") as f:
        json.dump(results, f, indent=1)
    mods["report"].write_html(os.path.join(out, "report.html"),
                              title=f"GI Preview vs Cycles per frame: {scene.name} ({spec.motion}, {w}x{h})",
                              results=results, images=images)
    log(f"wrote {os.path.join(out, 'results.json')}, animation.png and report.html")
    return results


def main():
    argv, in_blender = _script_argv()
    opts = parse_args(argv, scene_optional=in_blender)
    try:
        import bpy  # noqa: F401
    except ImportError:
        raise SystemExit("gi_compare: needs Blender (blender -b -P) or the bpy module (pip install bpy)")
    try:
        if opts.distributed:
            sys.path.insert(0, HERE)
            import _distributed  # Dask is imported only here

            summary = _distributed.run(opts, expand_scenes(opts.scenes), log=log)
            if summary["failed"] and len(summary["failed"]) == len(summary["scenes"]):
                raise SystemExit(1)
        elif len(opts.scenes) > 1 or (opts.scenes and os.path.isdir(opts.scenes[0])):
            summary = run_scenes(opts, expand_scenes(opts.scenes))
            if summary["failed"] and len(summary["failed"]) == len(summary["scenes"]):
                raise SystemExit(1)
        else:
            run_animation(opts) if opts.animation else run(opts)
    except Exception as exc:  # GLUnavailableError: one clear line, not a traceback
        if type(exc).__name__ != "GLUnavailableError":
            raise
        print(f"gi_compare: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
