"""Viewport and F12 benchmark of two checkouts: ``--before`` (e.g. one whose viewport waits
for F12 renders) against ``--after`` (default: this checkout, the non-blocking viewport).

Run with the bpy module (each checkout is measured in a child process of its own):

    git worktree add /tmp/gi_before COMMIT         # the checkout to compare against
    python scripts/bench_viewport.py --before /tmp/gi_before [--out DIR]

``--fps`` measures something else: viewport frames per second of DIRECT, SVGF, RTXGI and AUTO
at 64 x 64, 128 x 128 and 256 x 256 on a closed one-light room built here (not a demo scene),
for both checkouts, and writes ``viewport_fps.md`` / ``.json``:

    python scripts/bench_viewport.py --fps --before /tmp/gi_before --out docs/results

or measure one checkout at a time (``--measure CHECKOUT --json FILE``) and write the report
from the two files (``--report BEFORE.json AFTER.json``). Writes ``viewport_benchmark.md`` and
``.json`` into ``--out``, default ``out/bench/viewport/`` (the page
docs/results/viewport_benchmark.md is regenerated with ``--out docs/results``; then delete the
.json there, or link it: every file under docs/results must be linked from a page).

Scenes: the ``cornell`` demo scene and a 10^6-triangle scene (a 708 x 708 quad grid built
with numpy + foreach_set, a small cube to move, a sun). Both rendered with DIRECT, q1.
The viewport is driven through the engine's own ``view_update``/``view_draw`` with a
recording stand-in for Blender's ``gpu`` module (headless), a 320 x 240 region, scale 1.

Measured per scene and checkout:

* ``viewport_frame_ms``: wall time per accumulated viewport frame (16 frames from the first
  ``view_draw`` to the 16th image handed to Blender, divided by 16);
* ``view_draw_max_ms``: the longest single ``view_draw`` call, i.e. how long Blender's main
  thread is blocked (before: a whole frame; after: submitting and uploading only);
* ``f12_frame_ms``: an F12 render (``bpy.ops.render.render``) of 16 samples at 320 x 240,
  its total time divided by 16 (``engine.last_render``), after a warm-up render;
* ``viewport_during_f12_ms``: an F12-style render of many samples runs on another thread
  (as Blender's render job does) while the viewport asks for frames; the time from a
  ``view_draw`` that submits a frame until that frame is ready (before: ``view_draw``
  itself waits, for the whole F12 render);
* ``move_view_update_ms`` / ``move_first_frame_ms``: one object moved (its ``location``),
  the depsgraph update handler calls ``view_update`` with the real ``depsgraph.updates``
  (before: a full export; after: matrices only), then the time until the first frame of
  the moved scene is ready (the GPU scene update included: before, every mesh is hashed
  again); ``full_export_ms``: ``export_scene`` of the whole scene, for comparison.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import types
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
W, H = 320, 240
FRAMES = 16


# ------------------------------------------------------------------ child: one checkout
def _import_checkout(checkout: str):
    d = tempfile.mkdtemp(prefix="gi_preview_bench_pkg_")
    os.symlink(os.path.join(checkout, "addon"), os.path.join(d, "gi_preview"), target_is_directory=True)
    sys.path.insert(0, d)
    import gi_preview

    return gi_preview


def _fake_gpu(rec):
    fake_gpu = types.ModuleType("gpu")
    fake_gpu.types = types.SimpleNamespace(
        Buffer=lambda fmt, n, data: data,
        GPUTexture=lambda size, format, data: rec.append(time.perf_counter()) or ("tex", size))
    fake_gpu.state = types.SimpleNamespace(blend_set=lambda mode: None)
    extras = types.ModuleType("gpu_extras")
    presets = types.ModuleType("gpu_extras.presets")
    presets.draw_texture_2d = lambda tex, pos, w, h: None
    sys.modules.update({"gpu": fake_gpu, "gpu_extras": extras, "gpu_extras.presets": presets})


def grid_mesh(bpy, np, n: int, half: float = 3.0, amp: float = 0.1, name: str = "grid"):
    """A wavy n x n quad grid (2 n^2 triangles) of side 2 half, built with foreach_set
    (fast at 10^6 triangles); no material."""
    me = bpy.data.meshes.new(name)
    xs = np.linspace(-half, half, n + 1, dtype=np.float32)
    x, y = np.meshgrid(xs, xs)
    z = amp * np.sin(4 * x / half * 3.0) * np.cos(4 * y / half * 3.0)
    co = np.stack([x.ravel(), y.ravel(), z.ravel()], 1).astype(np.float32)
    me.vertices.add(len(co))
    me.vertices.foreach_set("co", co.ravel())
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    base = (j * (n + 1) + i).ravel()
    quads = np.stack([base, base + 1, base + n + 2, base + n + 1], 1).astype(np.int32)
    nf = len(quads)
    me.loops.add(4 * nf)
    me.loops.foreach_set("vertex_index", quads.ravel())
    me.polygons.add(nf)
    me.polygons.foreach_set("loop_start", np.arange(0, 4 * nf, 4, dtype=np.int32))
    me.update()
    return me


def _grid_scene(bpy, np, n=708):
    """~10^6 triangles (2 n^2) in one grid mesh, a cube to move, a sun, a camera."""
    from gi_preview.blender.demo_scenes import make_principled

    sc = bpy.data.scenes.new("grid1m")
    sc.render.engine = "GI_PREVIEW"
    me = grid_mesh(bpy, np, n)
    me.materials.append(make_principled("grid", (0.7, 0.7, 0.7)))
    sc.collection.objects.link(bpy.data.objects.new("grid", me))
    cm = bpy.data.meshes.new("cube")
    v = [(a, b, c) for a in (-0.3, 0.3) for b in (-0.3, 0.3) for c in (0, 0.6)]
    cm.from_pydata(v, [], [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)])
    cm.materials.append(make_principled("cube", (0.8, 0.2, 0.2)))
    cube = bpy.data.objects.new("mover", cm)
    sc.collection.objects.link(cube)
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.rotation_euler = (0.5, 0.2, 0)
    sun.data.energy = 3
    sc.collection.objects.link(sun)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.location = (0, -6, 3.5)
    cam.rotation_euler = (1.0, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc


def measure(checkout: str) -> dict:
    _import_checkout(checkout)
    import bpy
    import numpy as np

    import gi_preview
    from gi_preview.blender import engine as E
    from gi_preview.blender.demo_scenes import build_demo
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session

    gi_preview.register()
    uploads = []
    _fake_gpu(uploads)
    out = {"checkout": checkout, "scenes": {}}
    try:
        out["commit"] = subprocess.run(["git", "-C", checkout, "rev-parse", "--short", "HEAD"], capture_output=True,
                                       text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        pass

    def dg_of(sc):
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            return bpy.context.evaluated_depsgraph_get()

    for name in ("cornell", "grid1m"):
        sc = build_demo("cornell", resolution=W) if name == "cornell" else _grid_scene(bpy, np)
        sc.render.resolution_x, sc.render.resolution_y = W, H
        sc.gi_preview.technique = "DIRECT"
        sc.gi_preview.quality = 1
        sc.gi_preview.viewport_scale = 1.0
        sc.gi_preview.viewport_samples = 10000
        dg = dg_of(sc)
        r = {}
        full = []
        for _ in range(3):
            t0 = time.perf_counter()
            data = export_scene(dg)
            full.append((time.perf_counter() - t0) * 1e3)
        r["triangles"] = int(data.triangle_count)
        r["full_export_ms"] = statistics.median(full)
        # ---------------- viewport
        view = sc.camera.matrix_world.inverted()
        proj = sc.camera.calc_matrix_camera(dg, x=W, y=H)
        rv3d = types.SimpleNamespace(view_matrix=view, window_matrix=proj, is_perspective=True)
        ctx = types.SimpleNamespace(region=types.SimpleNamespace(width=W, height=H), region_data=rv3d, scene=sc)
        eng = types.SimpleNamespace(_viewport=E.ViewportState(), update_stats=lambda a, b: None,
                                    tag_redraw=lambda: None, bind_display_space_shader=lambda s: None,
                                    unbind_display_space_shader=lambda: None)
        st = eng._viewport
        E.view_update(eng, ctx, dg)

        def frames(n, draw_max=None):
            """Draw until n more images were handed to Blender; returns (wall s, max draw ms)."""
            target = len(uploads) + n
            longest = 0.0
            t0 = time.perf_counter()
            while len(uploads) < target:
                t = time.perf_counter()
                E.view_draw(eng, ctx, dg)
                longest = max(longest, (time.perf_counter() - t) * 1e3)
                fut = getattr(st, "future", None)
                if fut is not None:
                    fut.result()
            return time.perf_counter() - t0, longest

        frames(3)  # warm: shaders, upload
        wall, longest = frames(FRAMES)
        r["viewport_frame_ms"] = wall / FRAMES * 1e3
        r["view_draw_max_ms"] = longest
        # ---------------- move one object (real depsgraph.updates through the update handler)
        mover = next(o for o in sc.objects if o.type == "MESH" and ("mover" in o.name or "tall_box" in o.name))
        ups = []

        def handler(scene, depsgraph):
            if scene == sc:
                t = time.perf_counter()
                E.view_update(eng, ctx, depsgraph)
                ups.append((time.perf_counter() - t) * 1e3)

        bpy.app.handlers.depsgraph_update_post.append(handler)
        move_upd, move_first = [], []
        for k in range(3):
            mover.location.x += 0.05
            with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
                bpy.context.view_layer.update()
            move_upd.append(ups[-1])
            t0 = time.perf_counter()
            frames(1)
            move_first.append((time.perf_counter() - t0) * 1e3)
        bpy.app.handlers.depsgraph_update_post.remove(handler)
        r["move_view_update_ms"] = statistics.median(move_upd)
        r["move_first_frame_ms"] = statistics.median(move_first)
        r["move_meshes_read"] = getattr(st, "last_update", {}).get("meshes_read", "all (full export)")
        # ---------------- F12
        bpy.ops.render.render(scene=sc.name)  # warm-up
        sc.gi_preview.samples = FRAMES
        bpy.ops.render.render(scene=sc.name)
        info = E.last_render
        r["f12_frame_ms"] = info["total_ms"] / FRAMES
        r["f12_median_gpu_frame_ms"] = info["frame_ms"]
        # ---------------- a viewport frame while an F12 render runs
        f12_frames = max(20, int(6000 / max(r["f12_frame_ms"], 1.0)))  # ~6 s of F12
        data = export_scene(dg)
        done = threading.Event()
        f12_res = {}

        def f12():
            f12_res["res"] = session.render(data, "DIRECT", 1, f12_frames, session="final")
            f12_res["end"] = time.perf_counter()
            done.set()

        th = threading.Thread(target=f12)
        t_f12 = time.perf_counter()
        th.start()
        time.sleep(1.0)
        lat = []
        while not done.is_set() and len(lat) < 5:
            t0 = time.perf_counter()  # the view's next accumulated frame
            n0 = len(uploads)
            while len(uploads) == n0:
                E.view_draw(eng, ctx, dg)
                fut = getattr(st, "future", None)
                if fut is not None:
                    fut.result()
            lat.append((time.perf_counter() - t0) * 1e3)
        th.join()
        r["f12_frames_during"] = f12_frames
        r["f12_total_ms_during"] = (f12_res["end"] - t_f12) * 1e3
        r["viewport_during_f12_ms"] = statistics.median(lat)
        r["viewport_during_f12_max_ms"] = max(lat)
        if hasattr(st, "free"):
            st.free()
        bpy.data.scenes.remove(sc)
        out["scenes"][name] = r
        print(name, json.dumps(r), flush=True)
    from gi_preview.render.gl import get_gl

    out["gl_renderer"] = get_gl().info.get("GL_RENDERER")
    return out


def _room_scene(bpy):
    """A closed 4 x 3 x 2.5 m room (white walls, one red wall, a box), one area light in a
    corner under the ceiling, the camera inside: a scene no technique was tuned on."""
    sc = bpy.data.scenes.new("fps_room")
    mats = {}
    for name, col in (("white", (0.75, 0.75, 0.75)), ("red", (0.7, 0.1, 0.08)), ("box", (0.3, 0.5, 0.7))):
        m = bpy.data.materials.new(f"fps_{name}")
        m.diffuse_color = (*col, 1.0)
        bsdf = m.node_tree.nodes.get("Principled BSDF") if m.node_tree else None
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = (*col, 1.0)
            bsdf.inputs["Roughness"].default_value = 0.8
        mats[name] = m

    def box(name, lo, hi, side_mat, other_mat, inward):
        """An axis-aligned box; its +x face (index 3) gets side_mat, the others other_mat."""
        me = bpy.data.meshes.new(name)
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1),
             (x0, y1, z1)]
        f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        me.from_pydata(v, [], [tuple(reversed(q)) for q in f] if inward else f)
        me.materials.append(mats[other_mat])
        me.materials.append(mats[side_mat])
        for poly in me.polygons:
            poly.material_index = 1 if poly.index == 3 else 0
        sc.collection.objects.link(bpy.data.objects.new(name, me))

    box("fps_room", (-2, -1.5, 0), (2, 1.5, 2.5), "red", "white", True)
    box("fps_box", (-0.4, -0.2, 0), (0.4, 0.6, 0.9), "box", "box", False)
    ld = bpy.data.lights.new("fps_light", "AREA")
    ld.energy, ld.size = 150.0, 0.5
    light = bpy.data.objects.new("fps_light", ld)
    light.location = (1.5, 1.0, 2.4)
    sc.collection.objects.link(light)
    cd = bpy.data.cameras.new("fps_cam")
    cd.lens = 18.0
    cam = bpy.data.objects.new("fps_cam", cd)
    cam.location = (-1.8, -1.3, 1.4)
    cam.rotation_euler = (1.3, 0.0, -0.95)
    sc.collection.objects.link(cam)
    sc.camera = cam
    w = bpy.data.worlds.new("fps_world")
    w.color = (0, 0, 0)
    sc.world = w
    return sc


FPS_TECHNIQUES = ("DIRECT", "SVGF", "RTXGI", "AUTO")
FPS_SIZES = (64, 128, 256)


def measure_fps(checkout: str, frames: int = 12) -> dict:
    """Viewport frames per second for FPS_TECHNIQUES x FPS_SIZES (quality 1) on _room_scene:
    ``frames`` accumulated viewport frames after 3 warm-up frames (shaders, uploads, probe
    start), wall time from the first view_draw to the last image handed to Blender."""
    _import_checkout(checkout)
    import bpy

    import gi_preview
    from gi_preview.blender import engine as E

    gi_preview.register()
    uploads = []
    _fake_gpu(uploads)
    out = {"checkout": checkout, "fps": {}}
    sc = _room_scene(bpy)
    with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
        dg = bpy.context.evaluated_depsgraph_get()
    for tech in FPS_TECHNIQUES:
        for size in FPS_SIZES:
            sc.render.resolution_x = sc.render.resolution_y = size
            sc.gi_preview.technique = tech
            sc.gi_preview.quality = 1
            sc.gi_preview.viewport_scale = 1.0
            sc.gi_preview.viewport_samples = 10000
            view = sc.camera.matrix_world.inverted()
            proj = sc.camera.calc_matrix_camera(dg, x=size, y=size)
            rv3d = types.SimpleNamespace(view_matrix=view, window_matrix=proj, is_perspective=True)
            ctx = types.SimpleNamespace(region=types.SimpleNamespace(width=size, height=size), region_data=rv3d,
                                        scene=sc)
            eng = types.SimpleNamespace(_viewport=E.ViewportState(), update_stats=lambda a, b: None,
                                        tag_redraw=lambda: None, bind_display_space_shader=lambda s: None,
                                        unbind_display_space_shader=lambda: None)
            st = eng._viewport
            E.view_update(eng, ctx, dg)

            def draw(n):
                target = len(uploads) + n
                t0 = time.perf_counter()
                while len(uploads) < target:
                    E.view_draw(eng, ctx, dg)
                    fut = getattr(st, "future", None)
                    if fut is not None:
                        fut.result()
                return time.perf_counter() - t0

            draw(3)
            n = frames if size < 256 else max(4, frames // 2)
            wall = draw(n)
            out["fps"][f"{tech}@{size}"] = n / wall
            print(tech, size, f"{n / wall:.2f} fps", flush=True)
            if hasattr(st, "free"):
                st.free()
    from gi_preview.render.gl import get_gl

    out["gl_renderer"] = get_gl().info.get("GL_RENDERER")
    return out


def report_fps(before: dict, after: dict, out_dir: Path, before_label: str, after_label: str):
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "viewport_fps.json").write_text(json.dumps({"before": before, "after": after,
                                                            "machine": platform.platform(),
                                                            "cpus": os.cpu_count()}, indent=1))
    lines = ["# Viewport frames per second: before / after", "",
             f"`python scripts/bench_viewport.py --fps --before CHECKOUT` (before = {before_label}, after = "
             f"{after_label}; the numbers are in viewport_fps.json). A closed one-light room built by the script "
             f"(not a demo scene), quality 1, the viewport driven through the engine's view_draw; frames per "
             f"second over {12} accumulated frames (6 at 256 x 256) after 3 warm-up frames. "
             f"{after.get('gl_renderer')} on {os.cpu_count()} CPU cores: these are software-OpenGL rates, "
             "compare them as ratios only.", "",
             "| technique | size | before fps | after fps | after / before |", "|---|---:|---:|---:|---:|"]
    for key, a in after["fps"].items():
        tech, size = key.split("@")
        b = before["fps"].get(key)
        ratio = f"{a / b:.2f}x" if b else "-"
        lines.append(f"| {tech} | {size} x {size} | {b:.2f} | {a:.2f} | {ratio} |" if b else
                     f"| {tech} | {size} x {size} | - | {a:.2f} | - |")
    (out_dir / "viewport_fps.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


# ------------------------------------------------------------------ parent: both, report
def _run_child(checkout: str, fps: bool = False) -> dict:
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        path = f.name
    env = dict(os.environ, BLENDER_USER_RESOURCES=tempfile.mkdtemp(prefix="gi_bench_user_"))
    subprocess.run([sys.executable, __file__, "--measure", checkout, "--json", path] + (["--fps"] if fps else []),
                   check=True, env=env)
    with open(path) as f:
        return json.load(f)


ROWS = [
    ("viewport_frame_ms", "viewport: wall time per accumulated frame (ms)"),
    ("view_draw_max_ms", "viewport: longest view_draw call = main thread blocked (ms)"),
    ("f12_frame_ms", "F12: total time / samples (ms per frame)"),
    ("viewport_during_f12_ms", "viewport frame while an F12 render runs: median wait (ms)"),
    ("viewport_during_f12_max_ms", "... longest wait (ms)"),
    ("f12_total_ms_during", "... the F12 render's total time (ms)"),
    ("full_export_ms", "full export_scene (ms)"),
    ("move_view_update_ms", "move one object: view_update (ms)"),
    ("move_first_frame_ms", "move one object: until the moved frame is ready (ms)"),
    ("move_meshes_read", "move one object: meshes read again"),
]


def report(before: dict, after: dict, out_dir: Path, before_label: str = "the --before checkout",
           after_label: str = "the --after checkout"):
    def commit(res):
        if res.get("commit"):
            return res["commit"]
        try:
            return subprocess.run(["git", "-C", res["checkout"], "rev-parse", "--short", "HEAD"], capture_output=True,
                                  text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError, KeyError):
            return "?"

    for res in (before, after):
        res["commit"] = commit(res)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "viewport_benchmark.json").write_text(json.dumps({"before": before, "after": after,
                                                                  "machine": platform.platform(),
                                                                  "cpus": os.cpu_count()}, indent=1))

    def fmt(v):
        return f"{v:.1f}" if isinstance(v, float) else str(v)

    lines = ["# Viewport and F12 benchmark: before / after the non-blocking viewport", "",
             f"`python scripts/bench_viewport.py --before /tmp/gi_before` (before = {before_label}, "
             f"after = {after_label}; the checkouts' commits are in viewport_benchmark.json). "
             f"{W} x {H}, DIRECT q1, {FRAMES} frames; "
             f"{after.get('gl_renderer')} on {os.cpu_count()} CPU cores ({platform.machine()}); "
             "absolute milliseconds are llvmpipe's, the ratios are the point.", ""]
    for scene in after["scenes"]:
        b, a = before["scenes"][scene], after["scenes"][scene]
        lines += [f"## {scene} ({a['triangles']:,} triangles)", "", "| measure | before | after |",
                  "|---|---:|---:|"]
        for key, label in ROWS:
            lines.append(f"| {label} | {fmt(b.get(key, '-'))} | {fmt(a.get(key, '-'))} |")
        one = a["f12_frame_ms"] + a["viewport_frame_ms"]
        lines += ["", f"Reading: during F12 a viewport frame waited {a['viewport_during_f12_ms']:.0f} ms (median), "
                      f"about one F12 frame plus its own frame ({one:.0f} ms), against "
                      f"{b['viewport_during_f12_ms']:.0f} ms before (the rest of the whole F12 render). "
                      f"Blender's main thread is blocked {a['view_draw_max_ms']:.1f} ms per view_draw at most "
                      f"(before: {b['view_draw_max_ms']:.0f} ms, a whole frame). Moving one object: view_update "
                      f"{a['move_view_update_ms']:.1f} ms against {b['move_view_update_ms']:.0f} ms, no mesh read "
                      f"again; the frame after it costs what any frame costs (rendering dominates on llvmpipe). "
                      f"The F12 render's total grows by the viewport frames served in between.", ""]
    lines += ["How each number is taken: see the docstring of `scripts/bench_viewport.py`. Per-frame render "
              "times (viewport frame, F12 frame) are not what this benchmark is about: they differ between the "
              "two checkouts by whatever else differs between them and by run-to-run noise on a shared "
              "2-core machine.", ""]
    (out_dir / "viewport_benchmark.md").write_text("\n".join(lines))
    print("\n".join(lines))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", help="checkout to compare against (a git worktree)")
    ap.add_argument("--after", default=str(REPO), help="checkout measured as 'after' (default: this one)")
    ap.add_argument("--before-label", default="a viewport that waits for F12 renders",
                    help="what the before checkout is, for the report")
    ap.add_argument("--after-label", default="the non-blocking viewport", help="what the after checkout is")
    ap.add_argument("--out", default=str(REPO / "out" / "bench" / "viewport"),
                    help="output folder (default: out/bench/viewport; the docs page: docs/results)")
    ap.add_argument("--measure", help="measure one checkout (child mode)")
    ap.add_argument("--json", help="child mode: write the numbers here")
    ap.add_argument("--fps", action="store_true",
                    help="measure viewport frames per second of DIRECT, SVGF, RTXGI, AUTO at 64/128/256 px")
    ap.add_argument("--report", nargs=2, metavar=("BEFORE_JSON", "AFTER_JSON"),
                    help="write the report from two saved --measure outputs")
    args = ap.parse_args()
    if args.report and args.fps:
        report_fps(json.loads(Path(args.report[0]).read_text()), json.loads(Path(args.report[1]).read_text()),
                   Path(args.out), args.before_label, args.after_label)
        return
    if args.report:
        report(json.loads(Path(args.report[0]).read_text()), json.loads(Path(args.report[1]).read_text()),
               Path(args.out), args.before_label, args.after_label)
        return
    if args.measure:
        res = measure_fps(args.measure) if args.fps else measure(args.measure)
        if args.json:
            Path(args.json).write_text(json.dumps(res))
        return
    if not args.before:
        ap.error("--before CHECKOUT is required (git worktree add /tmp/gi_before COMMIT)")
    before = _run_child(args.before, args.fps)
    after = _run_child(args.after, args.fps)
    if args.fps:
        report_fps(before, after, Path(args.out), args.before_label, args.after_label)
        return
    report(before, after, Path(args.out), args.before_label, args.after_label)


if __name__ == "__main__":
    main()
