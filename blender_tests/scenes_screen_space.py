"""Reproduction scenes for the screen-space family, built in code.

* ``corridor``: a corridor with a near-mirror metal floor (roughness 0.05), a gold metal
  wall (roughness 0.3), a diffuse blue wall, a diffuse ceiling and a diffuse far wall, lit
  by two downward-facing area lights; a diffuse sphere on the floor; the near end is open
  to a dim sky. SSR's reflections of the walls and the ceiling in the floor and the gold
  wall. The ceiling is lit only by light coming back from below (here mostly a caustic:
  the mirror floor reflecting the lights, which only path tracing models).
* ``bounce_room``: a room whose diffuse floor is lit by downward area lights; the ceiling,
  the upper walls and the ceiling's corners are lit only by light bouncing off the floor.
  SSDO's bounce on a surface lit only indirectly.
* ``mirror_gradient``: a mirror floor (metal, roughness 0) in front of a diffuse wall lit
  from below by a strip of area light, so the wall carries a smooth vertical gradient;
  reflection continuity: the gradient's reflection must stay a gradient.

``masks(sd, pos)`` turns the G-buffer's material ids into boolean masks per surface
(``reflective``, ``ceiling``, ``floor``...), so errors can be measured on those surfaces.
Used by ``test_screen_space.py`` and ``scripts/bench_screen_space.py``.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from _helpers import build_named_scene

SCENES = ("corridor", "bounce_room", "mirror_gradient")


def _corridor(b, mp, mw):
    floor = mp(b.n("floor_mirror"), (0.9, 0.9, 0.9), 0.05, 1.0)
    gold = mp(b.n("wall_gold"), (1.0, 0.78, 0.34), 0.3, 1.0)
    blue = mp(b.n("wall_blue"), (0.12, 0.25, 0.75), 0.8, specular=0.3)
    ceil = mp(b.n("ceiling"), (0.8, 0.8, 0.8), 0.9, specular=0.2)
    back = mp(b.n("wall_back"), (0.75, 0.65, 0.5), 0.9, specular=0.2)
    x0, x1, y0, y1, h = -1.2, 1.2, -1.0, 7.0, 2.4
    b.room("corr", (x0, y0, 0.0), (x1, y1, h),
           {"floor": floor, "ceiling": ceil, "-x": gold, "+x": blue, "+y": back}, skip=("-y",))
    b.sphere("ball", 0.35, mp(b.n("ball"), (0.8, 0.15, 0.1), 0.5), (0.35, 3.2, 0.35), segments=24, rings=12)
    for i, y in enumerate((1.8, 4.8)):
        b.light(f"panel{i}", "AREA", (0.0, y, h - 0.02), size=0.7, energy=120.0, color=(1.0, 0.95, 0.85))
    b.camera((0.25, -0.6, 1.25), (-0.05, 6.0, 0.75), lens=22.0)
    b.scene.world = mw(b.n("sky"), (0.3, 0.4, 0.6), 0.3)


def _bounce_room(b, mp, mw):
    floor = mp(b.n("floor"), (0.8, 0.7, 0.55), 0.8, specular=0.2)
    ceil = mp(b.n("ceiling"), (0.8, 0.8, 0.8), 0.9, specular=0.2)
    wall = mp(b.n("wall"), (0.7, 0.72, 0.75), 0.9, specular=0.2)
    x0, x1, y0, y1, h = -2.0, 2.0, -2.5, 2.5, 2.4
    b.room("room", (x0, y0, 0.0), (x1, y1, h),
           {"floor": floor, "ceiling": ceil, "-x": wall, "+x": wall, "+y": wall, "-y": wall})
    # downward spots of light on the floor: the ceiling sees only what the floor sends back
    for i, (x, y) in enumerate(((-0.8, 0.6), (0.9, 1.2))):
        b.light(f"panel{i}", "AREA", (x, y, 1.6), size=0.5, energy=90.0, color=(1.0, 0.93, 0.8))
    b.box("block", (0.6, 0.6, 0.9), mp(b.n("block"), (0.3, 0.5, 0.7), 0.7), location=(0.2, 0.2, 0.45))
    b.camera((0.0, -2.3, 1.0), (0.0, 1.5, 1.45), lens=16.0)
    b.scene.world = mw(b.n("sky"), (0.0, 0.0, 0.0), 0.0)


def _mirror_gradient(b, mp, mw):
    floor = mp(b.n("floor_mirror"), (0.95, 0.95, 0.95), 0.0, 1.0)
    wall = mp(b.n("wall"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], floor)
    b.quad("wall", [(-3, 1.5, 0), (3, 1.5, 0), (3, 1.5, 3), (-3, 1.5, 3)], wall)
    # a wide strip of light low in front of the wall, facing it: irradiance falls smoothly
    # with height (a gradient), and no light reaches the mirror directly from above
    b.light("strip", "AREA", (0.0, 0.6, 0.02), rotation=(math.radians(90), 0, 0),
            shape="RECTANGLE", size=5.5, size_y=0.03, energy=60.0)
    b.camera((0.0, -2.6, 0.9), (0.0, 1.5, 0.45), lens=30.0)
    b.scene.world = mw(b.n("sky"), (0.0, 0.0, 0.0), 0.0)


_BUILDERS = {"corridor": _corridor, "bounce_room": _bounce_room, "mirror_gradient": _mirror_gradient}


def build(name: str, resolution: int = 64) -> bpy.types.Scene:
    """A new scene ``ss_<name>`` at ``resolution``² (the caller removes it)."""
    return build_named_scene(_BUILDERS, name, resolution, "ss", "screen-space test scene")


# surfaces per scene, by material-name suffix
SURFACES = {
    "corridor": {"reflective": ("floor_mirror", "wall_gold"), "floor": ("floor_mirror",),
                 "gold": ("wall_gold",), "ceiling": ("ceiling",)},
    "bounce_room": {"ceiling": ("ceiling",), "floor": ("floor",)},
    "mirror_gradient": {"reflective": ("floor_mirror",), "wall": ("wall",)},
}


def masks(name: str, sd, material_ids: np.ndarray) -> dict[str, np.ndarray]:
    """Boolean (H, W) masks of the surfaces of scene ``name`` from a G-buffer material-id
    image (``gbuffer.position`` channel w, < 0 = background)."""
    mids = np.rint(material_ids).astype(int)
    out = {}
    for key, suffixes in SURFACES[name].items():
        ids = [i for i, m in enumerate(sd.materials) if any(m.name.endswith("." + s) for s in suffixes)]
        if not ids:
            raise RuntimeError(f"{name}: no material for {key} {suffixes} in {[m.name for m in sd.materials]}")
        out[key] = np.isin(mids, ids) & (material_ids >= 0)
    return out


def material_ids(sd, session_key: str = "ss_mask"):
    """Render one unjittered frame of DIRECT and read the G-buffer's material ids (H, W)."""
    from gi_preview.render import session
    from gi_preview.render.gl import get_gl

    session.render(sd, "DIRECT", 0, 1, session=session_key)
    t = session._sessions[session_key].rc.resources["gbuffer.position"]
    w, h = t.size

    def read():
        return np.frombuffer(t.read(), np.float32).reshape(h, w, 4)[..., 3].copy()
    ids = get_gl().submit(read).result()
    session.release_session(session_key) if hasattr(session, "release_session") else None
    return ids


def total_variation(img: np.ndarray, mask: np.ndarray, axis: int | None = None) -> float:
    """Mean absolute difference of luminance between neighbouring pixels that both lie in
    ``mask`` (along ``axis``: 0 = vertical, 1 = horizontal, None = both)."""
    lum = img[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    diffs = []
    for ax in ((0, 1) if axis is None else (axis,)):
        d = np.abs(np.diff(lum, axis=ax))
        m = mask[1:, :] & mask[:-1, :] if ax == 0 else mask[:, 1:] & mask[:, :-1]
        diffs.append(d[m])
    d = np.concatenate(diffs)
    return float(d.mean()) if d.size else 0.0


def read_resource(session_key: str, name: str, comps: int) -> np.ndarray:
    """A frame-graph resource of session ``session_key`` after its last render, (H, W, comps)."""
    from gi_preview.render import session
    from gi_preview.render.gl import get_gl

    t = session._sessions[session_key].rc.resources[name]
    w, h = t.size

    def read():
        dt = np.float16 if t.dtype == "f2" else np.float32
        return np.frombuffer(t.read(), dt).reshape(h, w, t.components)[..., :comps].astype(np.float32)
    return get_gl().submit(read).result()


def seam_pairs(found: np.ndarray, mask: np.ndarray, jump: float = 0.25) -> list:
    """Neighbouring pixel pairs (both in ``mask``) across which SSR's found share ``found``
    (H, W) changes by more than ``jump``: the hit/miss boundaries. Returns [(a_idx, b_idx)]
    as pairs of index tuples for vertical and horizontal neighbours."""
    out = []
    for ax in (0, 1):
        a = found[1:, :] if ax == 0 else found[:, 1:]
        b = found[:-1, :] if ax == 0 else found[:, :-1]
        ma = mask[1:, :] & mask[:-1, :] if ax == 0 else mask[:, 1:] & mask[:, :-1]
        sel = ma & (np.abs(a - b) > jump)
        ys, xs = np.nonzero(sel)
        if ax == 0:
            out.append(((ys + 1, xs), (ys, xs)))
        else:
            out.append(((ys, xs + 1), (ys, xs)))
    return out


def seam_gradient(img: np.ndarray, pairs: list) -> tuple[float, int]:
    """Mean absolute luminance difference of ``img`` over the pixel pairs of ``seam_pairs``
    (the image's gradient across hit/miss boundaries) and the number of pairs."""
    lum = img[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    d = np.concatenate([np.abs(lum[a] - lum[b]) for a, b in pairs]) if pairs else np.zeros(0)
    return (float(d.mean()) if d.size else 0.0), int(d.size)
