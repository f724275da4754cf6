"""Any world node tree as an equirectangular radiance map, evaluated by Cycles itself.

A world that is not one uniform colour (an Environment Texture, a Sky Texture, gradients,
mixes, anything Cycles can render) is rendered once by Cycles, alone, through an
equirectangular panoramic camera oriented so that the image is in the convention of
Blender's Environment Texture (``render/world_map.py``). Each pixel is the mean radiance
over its solid-angle footprint (box pixel filter, ``spp`` samples). The result is cached by
a hash of the node tree (every node's settings and links) and its images, in memory and on
disk beside the Cycles references, so an unchanged world is never evaluated twice.

Cycles runs in a child process: a render cannot start from inside another render (F12 calls
the exporter from ``RenderEngine.render``), and the user's file is never touched. The world
and what it uses are written with ``bpy.data.libraries.write`` into a temporary .blend, the
child appends the world into an empty file and renders it:

* with Blender itself (``bpy.app.binary_path``): ``blender -b --factory-startup -P world_bake.py -- ARGS``;
* with the PyPI ``bpy`` module: ``python world_bake.py ARGS``.

What Cycles evaluates this way is the world as camera rays see it: a tree that shows a
different colour to camera rays than to light (Light Path "Is Camera Ray") is baked as the
camera sees it, and the exporter says so.
"""
from __future__ import annotations

import hashlib
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

DEFAULT_SIZE = (1024, 512)
MAX_WIDTH = 2048
DEFAULT_SPP = 16
SUN_SPP = 1024  # the window around a bright peak (a sun disc) is rendered again with this many
TIMEOUT_S = 600
_memory: dict[str, object] = {}  # key -> (H, W, 3) float32 map


# ------------------------------------------------------------------ parent side (bpy)
def _value(v):
    if isinstance(v, (str, bool, int)) or v is None:
        return v
    if isinstance(v, float):
        return round(v, 7)
    try:
        return tuple(round(float(x), 7) for x in v)
    except (TypeError, ValueError):
        return repr(v)


def _image_key(img) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(f"{img.name_full}|{img.source}|{tuple(img.size)}|{img.colorspace_settings.name}|"
             f"{img.alpha_mode}".encode())
    path = bpy_abspath(img.filepath) if img.filepath else ""
    if img.packed_file is None and path and os.path.isfile(path) and not img.is_dirty:
        st = os.stat(path)
        h.update(f"{path}|{st.st_size}|{st.st_mtime_ns}".encode())
    else:  # packed, generated or edited in Blender: the pixels themselves
        import numpy as np

        w, hgt = int(img.size[0]), int(img.size[1])
        if w > 0 and hgt > 0:
            px = np.empty(w * hgt * 4, np.float32)
            img.pixels.foreach_get(px)
            h.update(px.tobytes())
    return h.hexdigest()


def bpy_abspath(path: str) -> str:
    import bpy

    return os.path.normpath(bpy.path.abspath(path))


def _tree_items(tree, seen: set) -> list:
    """A stable description of a node tree (node settings, unlinked inputs, links, images,
    node groups recursively)."""
    out = []
    if tree is None or tree.name_full in seen:
        return out
    seen.add(tree.name_full)
    skip = {"rna_type", "location", "location_absolute", "width", "height", "dimensions", "select",
            "show_options", "show_preview", "show_texture", "hide", "label", "color", "use_custom_color",
            "parent", "inputs", "outputs", "internals", "type", "bl_idname", "bl_label", "bl_description",
            "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min", "bl_width_max",
            "bl_height_default", "bl_height_min", "bl_height_max", "is_active_output", "warning_propagation",
            "color_tag"}
    for node in sorted(tree.nodes, key=lambda n: n.name):
        item = [node.bl_idname, node.name, node.mute]
        for prop in node.bl_rna.properties:
            pid = prop.identifier
            if pid in skip:
                continue
            try:
                v = getattr(node, pid)
            except AttributeError:
                continue
            if prop.type == "POINTER":
                if v is None:
                    item.append((pid, None))
                elif pid == "image" or v.__class__.__name__ == "Image":
                    item.append((pid, _image_key(v)))
                elif pid == "node_tree":
                    item.append((pid, _tree_items(v, seen)))
                elif hasattr(v, "bl_rna"):
                    sub = []
                    for sp in v.bl_rna.properties:
                        if sp.type in ("BOOLEAN", "INT", "FLOAT", "STRING", "ENUM"):
                            try:
                                sub.append((sp.identifier, _value(getattr(v, sp.identifier))))
                            except (AttributeError, TypeError):
                                pass
                    item.append((pid, sub))
                continue
            if prop.type == "COLLECTION":
                continue
            try:
                item.append((pid, _value(v)))
            except Exception:  # noqa: BLE001 - a property that does not read as a value
                pass
        for sock in node.inputs:
            if not sock.is_linked and hasattr(sock, "default_value"):
                item.append((sock.identifier, _value(sock.default_value)))
        out.append(item)
    for lk in tree.links:
        out.append(("link", lk.from_node.name, lk.from_socket.identifier, lk.to_node.name,
                    lk.to_socket.identifier, lk.is_muted, lk.is_valid))
    return out


def world_key(world, size: tuple[int, int], spp: int) -> str:
    import bpy

    desc = repr((_tree_items(world.node_tree, set()), tuple(size), int(spp), SUN_SPP, tuple(bpy.app.version), "v2"))
    return hashlib.sha256(desc.encode()).hexdigest()[:32]


def uses_light_path(world) -> bool:
    """Does the tree read the Light Path node (a world that differs for camera rays)?"""
    return any(n.bl_idname == "ShaderNodeLightPath" for n in world.node_tree.nodes)


def map_size(world) -> tuple[int, int]:
    """The map's resolution: the largest environment image's width (at most MAX_WIDTH) x half."""
    w = 0
    for n in world.node_tree.nodes:
        if n.bl_idname == "ShaderNodeTexEnvironment" and n.image is not None:
            w = max(w, int(n.image.size[0]))
    if w <= 0:
        return DEFAULT_SIZE
    w = max(256, min(MAX_WIDTH, 1 << int(math.ceil(math.log2(w)))))
    return w, w // 2


def _cache_dir() -> str:
    from .reference import default_cache_dir

    d = os.path.join(default_cache_dir(), "worlds")
    os.makedirs(d, exist_ok=True)
    return d


class _Job:
    """One child process evaluating a world (its temporary folder, log and output)."""

    def __init__(self, world, size, spp, out_path):
        import bpy

        self.world_name = world.name
        self.out_path = out_path
        self.tmp = tempfile.mkdtemp(prefix="gi_preview_world_")
        lib = os.path.join(self.tmp, "world.blend")
        bpy.data.libraries.write(lib, {world}, path_remap="ABSOLUTE", fake_user=True)
        self.exr = os.path.join(self.tmp, "world.exr")
        args = ["--child", "--blend", lib, "--world", world.name, "--out", self.exr,
                "--width", str(size[0]), "--height", str(size[1]), "--spp", str(int(spp))]
        script = os.path.abspath(__file__)
        if bpy.app.binary_path:
            cmd = [bpy.app.binary_path, "-b", "--factory-startup", "-noaudio", "-P", script, "--"] + args
        else:
            cmd = [sys.executable, script] + args
        self.log_path = os.path.join(self.tmp, "log.txt")
        self._log = open(self.log_path, "w")
        self.started = time.monotonic()
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    def done(self) -> bool:
        return self.proc.poll() is not None

    def wait(self) -> None:
        try:
            self.proc.wait(timeout=max(1.0, TIMEOUT_S - (time.monotonic() - self.started)))
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def result(self):
        """The map (after ``done``); raises RuntimeError with the child's last lines."""
        import numpy as np

        from ..compare.imageio import read_exr

        try:
            self._log.close()
            if self.proc.returncode != 0 or not os.path.isfile(self.exr):
                with open(self.log_path, errors="replace") as f:
                    tail = [ln for ln in f.read().strip().splitlines() if ln.strip()][-6:]
                raise RuntimeError(f"Cycles could not evaluate world '{self.world_name}': " + " | ".join(tail))
            px = np.ascontiguousarray(read_exr(self.exr)[..., :3], np.float32)
            try:
                shutil.copyfile(self.exr, self.out_path + ".part")
                os.replace(self.out_path + ".part", self.out_path)
            except OSError:
                pass
            return px
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)


_jobs: dict[str, _Job] = {}


def bake_world(world, *, size: tuple[int, int] | None = None, spp: int = DEFAULT_SPP,
               cache_dir: str | None = None, wait: bool = True):
    """The world's radiance map (H, W, 3) float32, row 0 at the bottom (cached). Raises
    RuntimeError with Cycles' message when the child fails. With ``wait=False`` (the
    viewport) a world not yet evaluated returns None at once: the child runs on, and when it
    ends the world is tagged for an update, so the next export finds the map."""
    import numpy as np

    from ..compare.imageio import read_exr

    size = tuple(size) if size is not None else map_size(world)
    key = world_key(world, size, spp)
    hit = _memory.get(key)
    if hit is not None:
        return hit
    folder = cache_dir or _cache_dir()
    path = os.path.join(folder, f"{key}.exr")
    if os.path.isfile(path):
        try:
            px = np.ascontiguousarray(read_exr(path)[..., :3], np.float32)
            _memory[key] = px
            return px
        except Exception:  # noqa: BLE001 - a damaged cache file: bake again
            pass
    job = _jobs.get(key)
    if job is None:
        job = _jobs[key] = _start(world, size, spp, path)
    if wait:
        job.wait()
    elif not job.done():
        _watch()
        return None
    del _jobs[key]
    px = job.result()
    while len(_memory) >= 8:
        _memory.pop(next(iter(_memory)))
    _memory[key] = px
    return px


def _start(world, size, spp, out_path) -> _Job:
    return _Job(world, size, spp, out_path)


def pending() -> list[str]:
    """Names of the worlds being evaluated now."""
    return [j.world_name for j in _jobs.values() if not j.done()]


def _watch() -> None:
    import bpy

    if not bpy.app.timers.is_registered(_poll):
        bpy.app.timers.register(_poll, first_interval=0.25)


def _poll():
    """Timer: tag the world of every finished evaluation for an update (the viewport then
    exports again and picks the map up); runs while evaluations are under way."""
    import bpy

    for job in list(_jobs.values()):
        if job.done() and not getattr(job, "tagged", False):
            job.tagged = True
            wo = bpy.data.worlds.get(job.world_name)
            if wo is not None:
                wo.update_tag()
    return 0.25 if any(not getattr(j, "tagged", False) for j in _jobs.values()) else None


# ------------------------------------------------------------------ child side
def _child(argv):
    import argparse

    import bpy

    ap = argparse.ArgumentParser()
    ap.add_argument("--child", action="store_true")
    ap.add_argument("--blend", required=True)
    ap.add_argument("--world", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--width", type=int, required=True)
    ap.add_argument("--height", type=int, required=True)
    ap.add_argument("--spp", type=int, required=True)
    a = ap.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with bpy.data.libraries.load(a.blend, link=False) as (src, dst):
        dst.worlds = [a.world]
    world = dst.worlds[0]
    sc = bpy.context.scene
    sc.world = world
    cam = bpy.data.cameras.new("GI Preview world camera")
    cam.type = "PANO"
    cam.panorama_type = "EQUIRECTANGULAR"
    ob = bpy.data.objects.new("GI Preview world camera", cam)
    sc.collection.objects.link(ob)
    sc.camera = ob
    # Looking along +X with +Z up: +X lands at the image's centre, +Y a quarter to the left,
    # as Blender's Environment Texture maps it.
    ob.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
    r = sc.render
    r.engine = "CYCLES"
    c = sc.cycles
    c.device = "CPU"
    c.samples = a.spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.seed = 1
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    for vl in sc.view_layers:
        vl.cycles.use_denoising = False
    r.film_transparent = False
    r.resolution_x, r.resolution_y, r.resolution_percentage = a.width, a.height, 100
    r.use_compositing = False
    r.use_sequencer = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGB"
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    r.filepath = a.out
    bpy.ops.render.render(write_still=True)
    _refine_peak(a, sc)


def _read_pixels(path):
    """(H, W, 4) float32, row 0 at the bottom."""
    import bpy
    import numpy as np

    bpy.utils.expose_bundled_modules()
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(path)
    px = np.asarray(inp.read_image(format="float"), np.float32)
    inp.close()
    if px.shape[2] == 3:
        px = np.concatenate([px, np.ones(px.shape[:2] + (1,), np.float32)], axis=2)
    return np.ascontiguousarray(px[::-1])


def _refine_peak(a, sc):
    """A small, very bright source (a sun disc) covers a few texels partially, so 16 samples
    per texel leave its energy noisy (about 7 % for a default sky's sun): render the window
    around the brightest texel again at SUN_SPP samples and splice it in."""
    import bpy
    import numpy as np

    px = _read_pixels(a.out)
    h, w = px.shape[:2]
    lum = px[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    y, x = np.unravel_index(int(np.argmax(lum)), lum.shape)
    if not lum[y, x] > 50.0 * max(float(np.median(lum)), 1e-12):
        return
    half = max(8, w // 64)
    x0, x1 = max(0, x - half), min(w, x + half + 1)
    y0, y1 = max(0, y - half), min(h, y + half + 1)
    r = sc.render
    r.use_border = True
    r.use_crop_to_border = False
    r.border_min_x, r.border_max_x = x0 / w, x1 / w
    r.border_min_y, r.border_max_y = y0 / h, y1 / h  # Blender's rows count from the bottom, as pixels do
    sc.cycles.samples = SUN_SPP
    sun_path = a.out + ".peak.exr"
    r.filepath = sun_path
    bpy.ops.render.render(write_still=True)
    win = _read_pixels(sun_path)
    # whole texels inside the window (its edge texels may be rendered only in part)
    px[y0 + 1:y1 - 1, x0 + 1:x1 - 1] = win[y0 + 1:y1 - 1, x0 + 1:x1 - 1]
    bpy.utils.expose_bundled_modules()
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(a.out)
    spec = oiio.ImageSpec(w, h, 4, "float")
    out.open(a.out, spec)
    out.write_image(np.ascontiguousarray(px[::-1]))  # files store the top row first
    out.close()


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if "--child" in argv:
        _child(argv)
