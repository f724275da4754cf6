"""Many-lights benchmark: DIRECT's (and PT's) time per frame against the number of lights,
with Cycles on the same scene in the same run.

Run with the bpy module (one process per checkout; ``--repo`` measures another checkout,
e.g. one without light culling, with this same script and scene):

    .venv/bin/python scripts/bench_lights.py --repo /tmp/gi_before --label before
    .venv/bin/python scripts/bench_lights.py --label after

The scene (built here, so both checkouts see the same one): a 16 m x 16 m grey floor with a
sphere, two pillars and a metal ball, lit by N point lights (radius 0.05 m, many colours) on
a jittered grid over the floor at 0.25-1.2 m, total power 768 W whatever N (768/N W each),
a dark world; camera as in the many_lights demo. For each N in ``--counts``:

* Cycles direct-light reference (``--ref-spp``, fair settings) and Cycles direct at
  ``--samples`` spp (time, relMSE against the reference);
* DIRECT at ``--quality`` accumulating ``--samples`` frames: median ms per frame (after a
  warm-up render that compiles shaders and builds what it builds), total ms, relMSE against
  the reference (all pixels);
* PT at quality 0 (1 spp per frame), ``--samples`` frames: ms per frame; Cycles full at
  ``--samples`` spp: time (the ratio PT / Cycles at equal samples).

A render whose warm-up frame is slower than ``--frame-budget`` seconds accumulates fewer
frames (at least 2): its median frame time is still measured, its relMSE is then noisier
(the table says how many frames it ran).

``--set PASS.PARAM=VALUE`` (repeatable) overrides a pass parameter in every render, e.g.
``--set shadows.max_shadow_maps=16`` (the shadow-map budget). Besides relMSE over all pixels
each row has it without the 0.1 % worst pixels (``*_relmse_trim``): on this scene a glossy
metal ball's sub-pixel highlights of the 5 cm lights can put most of an image's relMSE in
one or two pixels.

``--techniques PT,RESTIR_DI`` measures only those techniques: ms/frame and relMSE at
``--samples`` frames against Cycles at ``--ref-spp`` (PT: full light transport, the others:
direct light), on the scene with ``--kinds mix`` (points, 5 cm spheres and 25 cm area
lights facing down in turn) and ``--world forest`` (a bundled HDRI, dimmed); ``--ref-cache``
keeps the references for the other checkout's run. The light-tree numbers in
docs/results/light_tree.md:

    .venv/bin/python scripts/bench_lights.py --repo /tmp/gi_before --label before \
        --techniques PT,RESTIR_DI --kinds mix --world forest --counts 10,100,1000,10000 \
        --res 64 --ref-spp 128 --ref-cache /tmp/refs --name light_tree --out docs/results
    .venv/bin/python scripts/bench_lights.py --label after (same options)

Output folder ``--out``: default ``out/bench/lights/`` (the pages docs/results/many_lights.md
and light_tree.md are regenerated with ``--out docs/results``; then delete the .json files
there, or link them: every file under docs/results must be linked from a page). Writes
``<out>/many_lights_<label>.json``; the ``after`` run also writes ``<out>/many_lights.md`` and
``many_lights.json`` with the before numbers side by side when ``many_lights_before.json``
exists. With ``--techniques``: ``<out>/<name>_<label>.json``, and ``<out>/<name>.md`` when
``<name>_before.json`` exists.
"""
from __future__ import annotations

import argparse
import colorsys
import importlib
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def import_addon(repo: Path):
    d = tempfile.mkdtemp(prefix="gi_preview_pkg_")
    os.symlink(repo / "addon", os.path.join(d, "gi_preview"), target_is_directory=True)
    sys.path.insert(0, d)
    return importlib.import_module("gi_preview")


def build_scene(n: int, res: int, kinds: str = "point", world: str = "dark"):
    import bpy
    import numpy as np

    sc = bpy.data.scenes.new(f"bench_lights_{n}")
    sc.render.resolution_x = sc.render.resolution_y = res
    sc.render.resolution_percentage = 100

    def mat(name, color, rough, metal=0.0):
        m = bpy.data.materials.new(name)
        m.use_nodes = True
        bsdf = m.node_tree.nodes.get("Principled BSDF")
        bsdf.inputs["Base Color"].default_value = (*color, 1.0)
        bsdf.inputs["Roughness"].default_value = rough
        bsdf.inputs["Metallic"].default_value = metal
        return m

    def mesh(name, verts, faces, m, loc=(0, 0, 0), smooth=False):
        me = bpy.data.meshes.new(name)
        me.from_pydata(verts, [], faces)
        me.materials.append(m)
        if smooth:
            me.shade_smooth()
        ob = bpy.data.objects.new(name, me)
        ob.location = loc
        sc.collection.objects.link(ob)

    def box(name, size, m, loc):
        sx, sy, sz = (s / 2 for s in size)
        v = [(-sx, -sy, -sz), (sx, -sy, -sz), (sx, sy, -sz), (-sx, sy, -sz),
             (-sx, -sy, sz), (sx, -sy, sz), (sx, sy, sz), (-sx, sy, sz)]
        f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        mesh(name, v, f, m, loc)

    def sphere(name, r, m, loc, seg=32, rings=16):
        verts, faces = [], []
        for i in range(rings + 1):
            th = math.pi * i / rings
            for j in range(seg):
                ph = 2 * math.pi * j / seg
                verts.append((r * math.sin(th) * math.cos(ph), r * math.sin(th) * math.sin(ph), r * math.cos(th)))
        for i in range(rings):
            for j in range(seg):
                a, b = i * seg + j, i * seg + (j + 1) % seg
                faces.append((a, b, b + seg, a + seg))
        mesh(name, verts, faces, m, loc, smooth=True)

    grey = mat("bl_grey", (0.7, 0.7, 0.7), 0.5)
    mesh("bl_floor", [(-8, -8, 0), (8, -8, 0), (8, 8, 0), (-8, 8, 0)], [(0, 1, 2, 3)], mat("bl_floor", (0.6, 0.6, 0.6), 0.4))
    sphere("bl_ball", 0.8, grey, (0, 0, 0.8))
    box("bl_pillar_a", (0.6, 0.6, 2.0), grey, (2.2, 1.0, 1.0))
    box("bl_pillar_b", (0.6, 0.6, 1.2), grey, (-2.0, 1.8, 0.6))
    sphere("bl_metal", 0.4, mat("bl_metal", (0.9, 0.9, 0.9), 0.15, 1.0), (-1.2, -1.6, 0.4))
    rng = np.random.default_rng(11)
    g = int(math.ceil(math.sqrt(n)))
    for i in range(n):
        gx, gy = i % g, i // g
        x = -7.5 + 15.0 * (gx + 0.2 + 0.6 * rng.random()) / g
        y = -7.5 + 15.0 * (gy + 0.2 + 0.6 * rng.random()) / g
        z = 0.25 + 0.95 * rng.random()
        hue = float(rng.random())
        kind = "sphere" if kinds == "point" else ("point", "sphere", "area")[i % 3]
        ld = bpy.data.lights.new(f"bl_{kind}_{i}", "AREA" if kind == "area" else "POINT")
        ld.energy = 768.0 / n
        ld.color = colorsys.hsv_to_rgb(hue, 0.75, 1.0)
        if kind == "area":
            ld.size = 0.25  # a square facing down
        else:
            ld.shadow_soft_size = 0.05 if kind == "sphere" else 0.0
        ob = bpy.data.objects.new(f"bl_{kind}_{i}", ld)
        ob.location = (x, y, z)
        sc.collection.objects.link(ob)
    cd = bpy.data.cameras.new("bl_cam")
    cd.lens = 30.0
    cd.clip_start = 0.05
    cam = bpy.data.objects.new("bl_cam", cd)
    cam.location = (0, -7.5, 4.5)
    from mathutils import Vector
    cam.rotation_euler = (Vector((0, 0, 0.5)) - Vector(cam.location)).to_track_quat("-Z", "Y").to_euler()
    sc.collection.objects.link(cam)
    sc.camera = cam
    w = bpy.data.worlds.new("bl_world")
    w.use_nodes = True
    bg = w.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.02, 0.02, 0.03, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    if world != "dark":  # a bundled HDRI (Blender's studiolights/world/<name>.exr), dimmed
        env = w.node_tree.nodes.new("ShaderNodeTexEnvironment")
        path = os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), f"{world}.exr")
        env.image = bpy.data.images.load(path, check_existing=True)
        w.node_tree.links.new(env.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = 0.05
    sc.world = w
    return sc


def relmse(a, b):
    import numpy as np
    a = a[..., :3].astype(np.float64)
    b = b[..., :3].astype(np.float64)
    return float(np.mean((a - b) ** 2 / (b * b + 1e-2)))


def relmse_trimmed(a, b, drop: float = 0.001):
    """relMSE without the ``drop`` fraction of worst pixels (at least one): a sub-pixel glint
    (a small light's highlight on a glossy metal) can carry most of an image's relMSE by
    itself, and which render gets the unlucky sample is chance."""
    import numpy as np
    a = a[..., :3].astype(np.float64)
    b = b[..., :3].astype(np.float64)
    e = np.sort(((a - b) ** 2 / (b * b + 1e-2)).mean(axis=2).ravel())
    k = max(1, int(round(drop * e.size)))
    return float(e[:-k].mean())


def time_technique(session, sd, tech, quality, samples, frame_budget):
    """Warm-up render (compile, BVH), then ``samples`` frames (fewer when one frame is slower
    than frame_budget s). Returns (image, frame_ms median, total_ms, frames, result)."""
    t0 = time.perf_counter()
    session.render(sd, tech, quality, 1)
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    session.render(sd, tech, quality, 1)
    one = time.perf_counter() - t0
    frames = samples if one <= frame_budget else max(2, min(samples, int(frame_budget * samples / one)))
    t0 = time.perf_counter()
    r = session.render(sd, tech, quality, frames)
    total = (time.perf_counter() - t0) * 1e3
    return r.image, float(r.frame_ms), total, frames, r, warm


def run_techniques(args, n, bpy, np, reference, export_scene, session) -> dict:
    """``--techniques``: each technique's ms/frame and relMSE at ``--samples`` frames against
    a Cycles reference at ``--ref-spp`` (PT: full light transport; DIRECT and RESTIR_DI:
    direct light), on a fresh scene."""
    sc = build_scene(n, args.res, args.kinds, args.world)
    try:
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        dg.update()
        sd = export_scene(dg)
        refs = {}
        row = {"lights": n, "ref_spp": args.ref_spp}
        for tech in args.techniques.split(","):
            kind = "full" if tech == "PT" else "direct"
            if kind not in refs:
                cpath = (Path(args.ref_cache) / f"{args.kinds}_{args.world}_{n}_{args.res}_{args.ref_spp}_{kind}.npy"
                         if args.ref_cache else None)
                if cpath is not None and cpath.exists():  # the same scene in a before/after pair
                    refs[kind] = np.load(cpath)
                else:
                    refs[kind], row[f"cycles_{kind}_ref_ms"] = reference.render_cycles(sc, args.ref_spp, kind)
                    if cpath is not None:
                        cpath.parent.mkdir(parents=True, exist_ok=True)
                        np.save(cpath, refs[kind])
            ref = refs[kind]
            q = 0 if tech == "PT" else args.quality
            img, fms, tot, frames, r, warm = time_technique(session, sd, tech, q, args.samples, args.frame_budget)
            t = tech.lower()
            row.update({f"{t}_frame_ms": fms, f"{t}_frames": frames, f"{t}_relmse": relmse(img, ref),
                        f"{t}_relmse_trim": relmse_trimmed(img, ref), f"{t}_nonfinite": int((~np.isfinite(img)).sum())})
            print(f"[{args.label}] N={n}: {tech} {fms:.0f} ms/frame x{frames} relMSE {row[t + '_relmse']:.4f} "
                  f"(trimmed {row[t + '_relmse_trim']:.4f})", flush=True)
        return row
    finally:
        bpy.data.scenes.remove(sc)


def run_count(args, n, bpy, np, reference, export_scene, session) -> dict:
    """Everything measured for one light count (Cycles, DIRECT, PT) on a fresh scene."""
    if args.techniques:
        return run_techniques(args, n, bpy, np, reference, export_scene, session)
    sc = build_scene(n, args.res)
    try:
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        dg.update()
        sd = export_scene(dg)
        ref, ref_ms = reference.render_cycles(sc, args.ref_spp, "direct")
        cyc, cyc_ms = reference.render_cycles(sc, args.samples, "direct", seed=4321)
        row = {"lights": n, "cycles_direct_ref_spp": args.ref_spp, "cycles_direct_ref_ms": ref_ms,
               "cycles_direct_spp": args.samples, "cycles_direct_ms": cyc_ms,
               "cycles_direct_relmse": relmse(cyc, ref), "cycles_direct_relmse_trim": relmse_trimmed(cyc, ref)}
        img, fms, tot, frames, r, warm = time_technique(session, sd, "DIRECT", args.quality, args.samples,
                                                        args.frame_budget)
        row.update({"direct_frame_ms": fms, "direct_total_ms": tot, "direct_frames": frames,
                    "direct_first_render_s": warm, "direct_relmse": relmse(img, ref),
                    "direct_relmse_trim": relmse_trimmed(img, ref),
                    "direct_nonfinite": int((~np.isfinite(img)).sum()),
                    "direct_pass_ms": {k: float(v) for k, v in r.pass_ms.items()},
                    "direct_warnings": list(getattr(r, "warnings", []))})
        print(f"[{args.label}] N={n}: DIRECT {fms:.0f} ms/frame x{frames} relMSE {row['direct_relmse']:.4f} "
              f"(without the 0.1 % worst pixels {row['direct_relmse_trim']:.5f}) | "
              f"Cycles direct {args.samples} spp {cyc_ms:.0f} ms relMSE {row['cycles_direct_relmse']:.4f} "
              f"({row['cycles_direct_relmse_trim']:.5f}) "
              f"| passes {row['direct_pass_ms']}", flush=True)
        if not args.no_pt:
            full, full_ms = reference.render_cycles(sc, args.samples, "full", seed=4321)
            img, fms, tot, frames, r, warm = time_technique(session, sd, "PT", 0, args.samples, args.frame_budget)
            row.update({"pt_frame_ms": fms, "pt_total_ms": tot, "pt_frames": frames,
                        "cycles_full_spp": args.samples, "cycles_full_ms": full_ms,
                        "pt_nonfinite": int((~np.isfinite(img)).sum())})
            print(f"[{args.label}] N={n}: PT {fms:.0f} ms/frame x{frames} | Cycles full {args.samples} spp "
                  f"{full_ms:.0f} ms", flush=True)
        return row
    finally:
        bpy.data.scenes.remove(sc)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repo", default=str(REPO), help="checkout whose add-on is measured")
    ap.add_argument("--label", default="after")
    ap.add_argument("--counts", default="1,4,16,64,256,1024")
    ap.add_argument("--res", type=int, default=96)
    ap.add_argument("--samples", type=int, default=16, help="frames DIRECT/PT accumulate (the F12 default)")
    ap.add_argument("--quality", type=int, default=1)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--frame-budget", type=float, default=3.0,
                    help="s: a technique slower than this per frame runs fewer frames")
    ap.add_argument("--no-pt", action="store_true")
    ap.add_argument("--out", default=str(REPO / "out" / "bench" / "lights"),
                    help="output folder (default: out/bench/lights; the docs pages: docs/results)")
    ap.add_argument("--set", action="append", default=[], metavar="PASS.PARAM=VALUE",
                    help="override a pass parameter for every render (e.g. shadows.max_shadow_maps=16); repeatable")
    ap.add_argument("--techniques", default="",
                    help="e.g. PT,RESTIR_DI: only these, each with relMSE at --samples frames against Cycles "
                         "(PT: full, others: direct) at --ref-spp; writes <out>/<--name>_<label>.json/.md")
    ap.add_argument("--kinds", default="point", choices=("point", "mix"),
                    help="point: 5 cm sphere lights; mix: points, 5 cm spheres and 25 cm area lights in turn")
    ap.add_argument("--world", default="dark", help="dark, or a bundled HDRI name (forest, city, ...)")
    ap.add_argument("--ref-cache", default=None, help="folder keeping the Cycles references between runs")
    ap.add_argument("--name", default="many_lights", help="result file prefix (with --techniques)")
    ap.add_argument("--before-label", default="the scheme without culling (every light shadow-mapped, every light "
                    "shaded at every pixel)", help="what the before checkout is, for many_lights.md")
    ap.add_argument("--lock", default=None,
                    help="a file to flock around each light count's renders (shared machines: others run between)")
    args = ap.parse_args(argv)

    import_addon(Path(args.repo).resolve())
    import bpy
    if hasattr(bpy.utils, "expose_bundled_modules"):
        bpy.utils.expose_bundled_modules()  # OpenImageIO (world maps are baked through EXR)
    import numpy as np
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session
    from gi_preview.render.gl import get_gl

    overrides = parse_overrides(args.set)
    if overrides:
        from gi_preview.render import framegraph
        orig_init = framegraph.Pass.__init__

        def init(self, quality=None, **props):
            orig_init(self, quality, **props)
            if self.name in overrides:
                self.set_properties(overrides[self.name])
        framegraph.Pass.__init__ = init
    counts = [int(c) for c in args.counts.split(",")]
    rows = []
    import contextlib
    import fcntl

    @contextlib.contextmanager
    def heavy():
        if not args.lock:
            yield
            return
        with open(args.lock, "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    for n in counts:
        with heavy():
            rows.append(run_count(args, n, bpy, np, reference, export_scene, session))
    gl = get_gl()
    info = {"label": args.label, "repo": str(Path(args.repo).resolve()), "res": args.res, "samples": args.samples,
            "quality": args.quality, "overrides": overrides, "before_label": args.before_label,
            "machine": f"{platform.machine()} ({os.cpu_count()} cores)",
            "gl": getattr(gl, "info", {}), "blender": bpy.app.version_string,
            "date": time.strftime("%Y-%m-%d %H:%M"), "rows": rows}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.techniques:
        info.update({"techniques": args.techniques, "kinds": args.kinds, "world": args.world,
                     "ref_spp": args.ref_spp})
        (out / f"{args.name}_{args.label}.json").write_text(json.dumps(info, indent=1))
        before_p = out / f"{args.name}_before.json"
        if args.label != "before" and before_p.exists():
            (out / f"{args.name}.md").write_text(report_techniques(info, json.loads(before_p.read_text())))
    else:
        (out / f"many_lights_{args.label}.json").write_text(json.dumps(info, indent=1))
    if args.label == "after" and not args.techniques:
        before_p = out / "many_lights_before.json"
        before = json.loads(before_p.read_text()) if before_p.exists() else None
        (out / "many_lights.json").write_text(json.dumps({"after": info, "before": before}, indent=1))
        (out / "many_lights.md").write_text(report(info, before))
    session_release = getattr(session, "shutdown", None)
    if session_release:
        session_release()


def parse_overrides(items) -> dict:
    """``["shadows.max_shadow_maps=16", ...]`` -> ``{"shadows": {"max_shadow_maps": 16.0}}``."""
    out: dict = {}
    for it in items:
        key, sep, val = it.partition("=")
        pass_name, dot, param = key.partition(".")
        if not (sep and dot and pass_name and param):
            raise SystemExit(f"bench_lights: --set wants PASS.PARAM=VALUE, got {it!r}")
        out.setdefault(pass_name, {})[param] = float(val)
    return out


def report_techniques(after: dict, before: dict) -> str:
    """Before/after table of a --techniques run: ms/frame, the ratio to the 100-light row,
    relMSE at equal frames."""
    techs = after["techniques"].split(",")
    b = {r["lights"]: r for r in before.get("rows", [])}
    L = [f"# {', '.join(techs)} against the number of lights", "",
         f"Generated by `scripts/bench_lights.py --techniques {after['techniques']} --kinds {after['kinds']} "
         f"--world {after['world']}`: {after['res']} x {after['res']} px, {after['samples']} frames (1 spp each; "
         f"DIRECT/RESTIR_DI quality {after['quality']}), relMSE against Cycles at {after['ref_spp']} spp (PT: full "
         f"light transport, others: direct light), {after['machine']}, GL `{after['gl'].get('GL_RENDERER', '?')}`. "
         f"`before` = {before.get('repo', '?')} measured by the same script. ms/frame = median over the frames "
         "after a warm-up render; shared machine: expect +-20 % between runs.", ""]
    head = "| lights |" + "".join(f" {t} before ms | {t} ms | {t} before relMSE | {t} relMSE |" for t in techs)
    L += [head, "|---:|" + "---:|" * (4 * len(techs))]
    for r in after["rows"]:
        o = b.get(r["lights"], {})
        cells = []
        for t in (x.lower() for x in techs):
            cells += [f"{o[t + '_frame_ms']:.0f}" if t + "_frame_ms" in o else "-", f"{r[t + '_frame_ms']:.0f}",
                      f"{o[t + '_relmse']:.4f}" if t + "_relmse" in o else "-", f"{r[t + '_relmse']:.4f}"]
        L.append(f"| {r['lights']} | " + " | ".join(cells) + " |")
    rows = {r["lights"]: r for r in after["rows"]}
    lo, hi = min(rows), max(rows)
    for t in (x.lower() for x in techs):
        ra = rows[hi][t + "_frame_ms"] / rows[lo][t + "_frame_ms"]
        rb = (b[hi][t + "_frame_ms"] / b[lo][t + "_frame_ms"]) if hi in b and lo in b else float("nan")
        L.append(f"\n{t.upper()}: {hi} vs {lo} lights: x{ra:.2f} ms/frame (before x{rb:.2f}).")
    return "\n".join(L) + "\n"


def report(after: dict, before: dict | None) -> str:
    b = {r["lights"]: r for r in (before or {}).get("rows", [])}
    L = ["# DIRECT and PT against the number of lights", "",
         f"Generated by `scripts/bench_lights.py` on {after['date']}: {after['res']} x {after['res']} px, "
         f"DIRECT quality {after['quality']} accumulating {after['samples']} frames, PT quality 0 (1 spp per "
         f"frame), {after['machine']}, GL `{after['gl'].get('GL_RENDERER', '?')}`, Blender {after['blender']}. "
         "Shared machine: expect +-20 % between runs. Scene: a 16 m floor with a sphere, two pillars and a metal "
         "ball under N point lights (radius 5 cm, many colours, 768 W in total whatever N), built by the script.",
         "",
         f"`before` = {after.get('before_label') or 'the checkout given to --repo'}, measured by "
         "the same script with `--repo`. relMSE against Cycles direct at "
         f"{after['rows'][0]['cycles_direct_ref_spp'] if after['rows'] else '?'} spp, all pixels. "
         "ms/frame = median over the accumulated frames, after a warm-up render (shader compiles, BVH builds "
         "excluded). Cycles ms = its render call at the same number of samples.", "",
         "| lights | DIRECT before ms/frame | DIRECT ms/frame | speed-up | DIRECT before relMSE | DIRECT relMSE "
         "| Cycles direct ms (spp) | Cycles direct relMSE | DIRECT total / Cycles | PT ms/frame | Cycles full ms "
         "| PT total / Cycles |",
         "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in after["rows"]:
        o = b.get(r["lights"])
        bf = f"{o['direct_frame_ms']:.0f} (x{o['direct_frames']})" if o else "-"
        sp = f"{o['direct_frame_ms'] / r['direct_frame_ms']:.1f}x" if o else "-"
        br = f"{o['direct_relmse']:.4f}" if o else "-"
        ratio = r["direct_frame_ms"] * after["samples"] / max(r["cycles_direct_ms"], 1e-9)
        pt = f"{r['pt_frame_ms']:.0f}" if "pt_frame_ms" in r else "-"
        cf = f"{r['cycles_full_ms']:.0f}" if "cycles_full_ms" in r else "-"
        ptr = (f"{r['pt_frame_ms'] * after['samples'] / max(r['cycles_full_ms'], 1e-9):.2f}"
               if "pt_frame_ms" in r else "-")
        L.append(f"| {r['lights']} | {bf} | {r['direct_frame_ms']:.0f} (x{r['direct_frames']}) | {sp} | {br} | "
                 f"{r['direct_relmse']:.4f} | {r['cycles_direct_ms']:.0f} ({r['cycles_direct_spp']}) | "
                 f"{r['cycles_direct_relmse']:.4f} | {ratio:.2f} | {pt} | {cf} | {ptr} |")
    L += ["", "DIRECT's pass times (ms, last frame) and what it reported approximating:", ""]
    for r in after["rows"]:
        L.append(f"- {r['lights']} lights: {r['direct_pass_ms']}; " + ("; ".join(r.get("direct_warnings") or [])
                                                                        or "nothing approximated"))
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
