"""Long viewport runs: do GL objects or process memory grow with the number of frames?

    .venv/bin/python scripts/check_growth.py [--frames 200] [--size 32] [--techniques all]
                                             [--out out/bench/growth]

Every technique (but AUTO, which runs the same members) renders ``--frames`` viewport frames
of the ``cornell`` demo scene (history kept, one frame per call, as the viewport redraws)
while the camera orbits a little every frame; every 50th frame the light's strength changes
and every 75th a box moves, so the edit paths run too. Per frame it records the GL objects
alive (moderngl textures, buffers, framebuffers, programs, queries, ... created and not yet
released, counted by wrapping their constructors and ``release``) and the process's resident
memory. A technique passes when the live objects after frame ``--settle`` (default 80, after
the first edit of each kind, whose one-time allocations are not growth) never exceed their
count at that frame while the edits repeat, and the resident memory grows by less than
``--rss-mb`` (default 64 MB) from there to the end. Writes ``growth.json`` and ``growth.md``; the exit
status is 1 when a technique fails. On llvmpipe the GPU's memory is the process's memory, so
RSS covers both.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

_KINDS = ("texture", "texture3d", "texture_array", "texture_cube", "depth_texture", "buffer", "framebuffer",
          "renderbuffer", "depth_renderbuffer", "program", "compute_shader", "vertex_array", "query", "sampler",
          "simple_vertex_array")


_BYTES = {"f1": 1, "u1": 1, "i1": 1, "nu1": 1, "ni1": 1, "f2": 2, "u2": 2, "i2": 2, "nu2": 2, "ni2": 2,
          "f4": 4, "u4": 4, "i4": 4}


def gl_object_bytes(kind: str, obj) -> int:
    """The bytes of a moderngl texture, buffer or render target as created (mip levels not
    counted); 0 for the other kinds."""
    if kind == "buffer":
        return int(obj.size)
    if kind in ("depth_texture", "depth_renderbuffer"):
        w, h = obj.size
        return int(w * h * 4)
    if kind not in ("texture", "texture3d", "texture_array", "texture_cube", "renderbuffer"):
        return 0
    per = int(getattr(obj, "components", 4)) * _BYTES.get(str(getattr(obj, "dtype", "f1")), 4)
    return int(math.prod(obj.size) * per * (6 if kind == "texture_cube" else 1))


class GLCensus:
    """Counts the moderngl objects created and not released (by wrapping the Context's
    constructors and each object's ``release``), and their bytes. ``install()`` / ``remove()``."""

    def __init__(self):
        self.live: dict[int, str] = {}
        self.bytes: dict[int, int] = {}
        self.created = 0
        self._saved = []

    def install(self):
        import moderngl

        census = self

        def wrap_ctor(name, fn):
            def ctor(ctx, *a, **kw):
                obj = fn(ctx, *a, **kw)
                census.created += 1
                census.live[id(obj)] = name
                census.bytes[id(obj)] = gl_object_bytes(name, obj)
                cls = type(obj)
                if not getattr(cls, "_gi_census_wrapped", False):
                    rel = cls.release

                    def release(self, *ra, **rkw):
                        census.live.pop(id(self), None)
                        census.bytes.pop(id(self), None)
                        return rel(self, *ra, **rkw)
                    census._saved.append((cls, "release", rel))
                    cls.release = release
                    cls._gi_census_wrapped = True
                return obj
            return ctor

        for name in _KINDS:
            fn = getattr(moderngl.Context, name, None)
            if fn is None:
                continue
            self._saved.append((moderngl.Context, name, fn))
            setattr(moderngl.Context, name, wrap_ctor(name, fn))
        return self

    def remove(self):
        for cls, name, fn in reversed(self._saved):
            setattr(cls, name, fn)
            if name == "release":
                cls._gi_census_wrapped = False
        self._saved.clear()

    def count(self) -> int:
        return len(self.live)

    def mb(self) -> float:
        """MiB of the live textures, buffers and render targets."""
        return sum(self.bytes.values()) / 2**20

    def by_kind(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for k in self.live.values():
            out[k] = out.get(k, 0) + 1
        return out


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def orbit_frames(scene, frames: int, degrees_per_frame: float = 0.5, light_every: int = 50, move_every: int = 75):
    """Yield (frame index, edited) after moving the scene's camera about the origin; every
    ``light_every``-th frame the first light's strength changes, every ``move_every``-th a box
    moves."""
    import mathutils

    cam = scene.camera
    base = cam.matrix_world.copy()
    light = next((o for o in scene.objects if o.type == "LIGHT"), None)
    mover = next((o for o in scene.objects if o.type == "MESH" and "box" in o.name.lower()), None)
    for i in range(frames):
        rot = mathutils.Matrix.Rotation(math.radians(degrees_per_frame * ((i % 40) - 20)), 4, "Z")
        cam.matrix_world = rot @ base
        edited = False
        if light is not None and i and i % light_every == 0:
            light.data.energy *= 1.05
            edited = True
        if mover is not None and i and i % move_every == 0:
            mover.location.x += 0.01
            edited = True
        yield i, edited


def run_technique(tech: str, scene, frames: int, size: int, settle: int, census: GLCensus, *, session, export,
                  reference, light_every: int = 50, move_every: int = 75) -> dict:
    key = ("growth", tech)
    counts, mems = [], []
    try:
        for i, _edited in orbit_frames(scene, frames, light_every=light_every, move_every=move_every):
            sd = export.export_scene(reference.evaluated_depsgraph(scene), width=size, height=size)
            res = session.render(sd, tech, 1, 1, session=key, keep_history=True, continue_accumulation=True)
            if not all(math.isfinite(float(v)) for v in (res.image.min(), res.image.max())):
                raise AssertionError(f"{tech}: non-finite pixels at frame {i}")
            counts.append(census.count())
            mems.append(rss_mb())
    finally:
        f = session.release_session(key)
        if f is not None:
            f.result()
    return summarize({"technique": tech, "frames": frames, "counts": counts,
                      "rss_mb": [round(m, 1) for m in mems]}, settle)


def summarize(row: dict, settle: int) -> dict:
    """The figures of one technique's run (``counts`` and ``rss_mb`` per frame) from frame
    ``settle`` on."""
    counts, mems = row["counts"], row["rss_mb"]
    s = min(settle, len(counts) - 1)
    return {**row, "settle": s, "live_objects_at_settle": counts[s],
            "live_objects_max_after": max(counts[s:]), "live_objects_end": counts[-1],
            "rss_mb_at_settle": round(mems[s], 1), "rss_mb_end": round(mems[-1], 1),
            "rss_growth_mb": round(mems[-1] - mems[s], 1),
            "live_objects_at_frame": {i: c for i, c in enumerate(counts) if i and c != counts[i - 1]}}


def write(rows: list, a):
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "growth.json"), "w", encoding="utf-8") as f:
        json.dump({"frames": a.frames, "size": a.size, "settle": a.settle, "rss_limit_mb": a.rss_mb,
                   "rows": rows}, f, indent=1)
    lines = [f"# GL objects and memory over {a.frames} viewport frames", "",
             f"`scripts/check_growth.py --frames {a.frames} --size {a.size}`: the cornell scene, {a.size} px, one "
             "frame per call as the viewport redraws, the camera orbiting every frame, the light's strength "
             "changed every 50 frames and a box moved every 75 (Mesa llvmpipe; the resident memory covers the "
             f"emulated GPU's too). Nothing may grow from frame {a.settle} on, after the first edit of each "
             "kind, while the edits repeat.", "",
             f"| technique | live GL objects at frame {a.settle} | max after | changes (frame: count) | "
             f"RSS at frame {a.settle} (MB) | RSS growth to the end (MB) | |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        ch = ", ".join(f"{k}: {v}" for k, v in r["live_objects_at_frame"].items()) or "none"
        lines.append(f"| {r['technique']} | {r['live_objects_at_settle']} | {r['live_objects_max_after']} | {ch} | "
                     f"{r['rss_mb_at_settle']} | {r['rss_growth_mb']:+.1f} | {'ok' if r['ok'] else 'grows'} |")
    with open(os.path.join(a.out, "growth.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


def verdict(r: dict, rss_limit: float) -> dict:
    r["ok"] = r["live_objects_max_after"] <= r["live_objects_at_settle"] and r["rss_growth_mb"] < rss_limit
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--settle", type=int, default=80,
                    help="frame from which nothing may grow (after the first light edit and the first move)")
    ap.add_argument("--rss-mb", type=float, default=64.0)
    ap.add_argument("--techniques", default="all")
    ap.add_argument("--out", default="out/bench/growth")
    ap.add_argument("--resummarize", metavar="JSON", help="rewrite growth.json/.md of an earlier run with --settle")
    a = ap.parse_args(argv)
    if a.resummarize:
        with open(a.resummarize, encoding="utf-8") as f:
            old = json.load(f)
        a.frames, a.size = old["frames"], old["size"]
        rows = [verdict(summarize({k: r[k] for k in ("technique", "frames", "counts", "rss_mb", "seconds")}, a.settle),
                        a.rss_mb) for r in old["rows"]]
        write(rows, a)
        return 0 if all(r["ok"] for r in rows) else 1
    from _checkout import import_checkout_package

    pkg = import_checkout_package()
    import bpy  # noqa: F401

    pkg.register()
    from gi_preview.blender import demo_scenes, export, reference
    from gi_preview.render import session, techniques

    ids = [t.id for t in techniques.available() if t.id != "AUTO"]
    if a.techniques != "all":
        ids = [t for t in a.techniques.split(",") if t]
    census = GLCensus().install()
    rows = []
    try:
        for tech in ids:
            sc = demo_scenes.build_demo("cornell", resolution=a.size)
            t0 = time.perf_counter()
            r = run_technique(tech, sc, a.frames, a.size, a.settle, census, session=session, export=export,
                              reference=reference)
            bpy.data.scenes.remove(sc)
            verdict(r, a.rss_mb)
            r["seconds"] = round(time.perf_counter() - t0, 1)
            rows.append(r)
            print(f"{tech:18s} live GL objects {r['live_objects_at_settle']} at frame {a.settle} -> max "
                  f"{r['live_objects_max_after']}, end {r['live_objects_end']}; RSS {r['rss_mb_at_settle']} -> "
                  f"{r['rss_mb_end']} MB ({r['rss_growth_mb']:+.1f}); {'ok' if r['ok'] else 'GROWS'} "
                  f"({r['seconds']} s)", flush=True)
    finally:
        census.remove()
    write(rows, a)
    print("wrote", os.path.join(a.out, "growth.md"))
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
