"""Hard cases: small scenes built the way artists build them, each a known failure mode of
real-time GI. Used by ``test_hard_cases.py`` (a subset, in CI) and
``scripts/bench_hard_cases.py`` (every scene x every technique -> docs/results/hard_cases.md).

Each scene is a few objects, one material a surface, lit by lamps, emitters or a world:

* ``thin_wall``: two rooms in one closed white shell split by a 2 cm wall (no door); a bright
  lamp in room A, a dim one in room B, the camera in B. Light in B beyond its lamp is a leak.
* ``mirror``: a perfect mirror floor (metallic, roughness 0) under a coloured box, a white wall
  and a point lamp without radius.
* ``glass``: a glass sphere (transmission 1, IOR 1.45) on a floor, a lamp behind it.
* ``furnace``: a white diffuse sphere (albedo 1, no specular) in a uniform white world of
  radiance 1, no lamp. The sphere is convex, so it sees only the world: every pixel is 1.
* ``camera_inside``: the camera inside a closed box that holds a dim lamp; a bright lamp and a
  lit floor outside. Cycles sees the inside of the box lit by its lamp only.
* ``emissive_only``: a closed room lit only by an emissive panel (no lamp, black world).
* ``many_lights``: a floor and boxes under a 100 x 100 grid of 10,000 small coloured point lamps.
* ``tiny_scale``: a lit room 4 mm across (every length x 0.001, lamp power x 1e-6).
* ``huge_scale``: the same room 10 km across (every length x 2500, lamp power x 2500^2).
* ``hdri_sun``: an HDR world map (128 x 64, float) of a dim blue sky with one texel of sun
  10^5 x brighter than the sky, over a floor and boxes.
* ``animated``: a box that crosses the frame in 4 frames (1 m a frame), the camera panning
  0.3 m and the lamp moving 0.5 m a frame, rendered frame by frame with history kept; judged
  on its last frame.
* ``degenerate``: a floor and a box with zero-area triangles (three equal corners), collinear
  triangles and 1e-6-wide slivers among the faces, under a lamp.
* ``z_fighting``: two coincident planes of different colours (red and green) and a blue one
  1e-5 m above part of them, under a lamp. Cycles shadows each coincident plane by the other
  (a shadow ray skips only the surface it starts on), so its reference is rendered without
  the duplicate (``REFERENCE_HIDE``): the lit floor an artist expects.
* ``black``: objects, no lamp, no emitter, a black world: the image must be exactly black.
* ``bright_light``: a zero-size point lamp and a 10^6 W lamp, far away (irradiance normal).
* ``mirrored_instances``: a box and a sphere with negative scale (mirrored) beside the
  originals, under a lamp.
* ``missing_texture``: a floor whose Image Texture points at a file that does not exist
  (Cycles shows magenta).
"""
from __future__ import annotations

import math

import bpy
import numpy as np

import scenes_probes
from _helpers import build_named_scene

SCENES = ("thin_wall", "mirror", "glass", "furnace", "camera_inside", "emissive_only", "many_lights",
          "tiny_scale", "huge_scale", "hdri_sun", "animated", "degenerate", "z_fighting", "black",
          "bright_light", "mirrored_instances", "missing_texture", "million_triangles")

ANIMATED_FRAMES = (1, 2, 3, 4)
# objects (name prefixes) hidden from Cycles for a scene's reference (see z_fighting)
REFERENCE_HIDE = {"z_fighting": ("hard_z_fighting.plane_b",)}  # the frames ``animated`` is rendered at (history kept)


# ------------------------------------------------------------------ what a cell must meet
# the factor of Cycles' mean (for the technique's reference kind) a technique's mean must be within
TOLERANCE = 1.5
SCREEN_SPACE = ("SSAO", "HBAO", "SSDO", "SSR")  # DIRECT + a screen-space term: judged between bounds
SS_LOW, SS_HIGH = 1.25, 1.5  # >= Cycles direct / 1.25, <= Cycles one_bounce x 1.5
FURNACE_TOL = 0.10  # |mean - 1| <= 0.10
FURNACE_EXACT = 1.0


def kind_of(tech: str) -> str:
    return _techniques().get(tech).reference


def judge(scene: str, tech: str, img: np.ndarray, refs: dict) -> dict:
    """The checks of one cell that depend on the image (finite and validator are the caller's).
    Returns {"ratio": ..., "ok": bool, "why": str}."""
    rgb = img[..., :3]
    mean = float(rgb.mean())
    if scene == "black":
        mx = float(np.abs(rgb).max())
        return {"value": mx, "what": "max", "ok": mx == 0.0, "why": "" if mx == 0.0 else f"max {mx:.3g}, not black"}
    if scene == "furnace":
        err = mean - FURNACE_EXACT
        ok = abs(err) <= FURNACE_TOL
        return {"value": mean, "what": "mean (exact 1)", "ok": ok,
                "why": "" if ok else f"mean {mean:.3f}, exact 1 +- {FURNACE_TOL}"}
    if tech in SCREEN_SPACE:
        lo = refs["direct"] / SS_LOW
        hi = refs["one_bounce"] * SS_HIGH
        r = mean / max(refs["one_bounce"], 1e-12)
        ok = lo <= mean <= hi
        why = "" if ok else (f"mean {mean:.4g} below Cycles direct {refs['direct']:.4g} / {SS_LOW}" if mean < lo
                             else f"mean {mean:.4g} above Cycles one-bounce {refs['one_bounce']:.4g} x {SS_HIGH}")
        return {"value": r, "what": "ratio to one_bounce", "ok": ok, "why": why}
    kind = kind_of(tech)
    r = mean / max(refs[kind], 1e-12)
    ok = 1 / TOLERANCE <= r <= TOLERANCE
    return {"value": r, "what": f"ratio to {kind}", "ok": ok,
            "why": "" if ok else f"mean {r:.2f}x Cycles {kind}, outside 1/{TOLERANCE}..{TOLERANCE}"}



def scene_data(name: str, sc) -> list:
    """The SceneData to render: one, or for ``animated`` one per frame of ANIMATED_FRAMES (the
    scene is left on its last frame, which the references render)."""
    from gi_preview.blender import reference
    from gi_preview.blender.export import export_scene
    if name != "animated":
        return [export_scene(reference.evaluated_depsgraph(sc))]
    sds = []
    for f in ANIMATED_FRAMES:
        sc.frame_set(f)
        sds.append(export_scene(reference.evaluated_depsgraph(sc)))
    return sds


def render(name: str, sds: list, tech: str, quality: int, samples: int, key: str):
    """A cell's render (session ``key``): ``samples`` frames; for ``animated`` one frame per
    SceneData with history kept, the last accumulating ``samples``. Returns the RenderResult."""
    from gi_preview.render import session
    r = None
    for i, sd in enumerate(sds):
        last = i == len(sds) - 1
        r = session.render(sd, tech, quality, samples if last else 1, keep_history=i > 0, session=key)
    return r


def _techniques():
    from gi_preview.render import techniques
    return techniques


# ------------------------------------------------------------------ scenes
def _lit_room(b, mp, mw):
    """A room open towards the camera: floor, back and side walls, a box, a lamp."""
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 0.6)
    b.room("room", (-2, -2, 0), (2, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "+y")},
           skip=("-y",))
    b.box("box", (0.8, 0.8, 0.8), red, location=(0.3, 0.4, 0.4))
    b.light("lamp", "POINT", (-0.5, -0.5, 2.4), energy=300.0, shadow_soft_size=0.1)
    b.camera((0, -3.5, 1.6), (0, 0.5, 0.8), lens=28.0)
    b.scene.world = mw(b.n("world"), (0.02, 0.02, 0.03), 1.0)


def _floor_and_boxes(b, mp, mw, lamp=True):
    grey = mp(b.n("grey"), (0.6, 0.6, 0.6), 0.8, specular=0.3)
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 0.5)
    blue = mp(b.n("blue"), (0.1, 0.2, 0.7), 0.3)
    b.quad("floor", [(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], grey)
    b.box("box", (1.0, 1.0, 1.0), red, location=(-0.6, 0.3, 0.5))
    b.sphere("ball", 0.5, blue, location=(0.8, -0.2, 0.5), segments=16, rings=8)
    if lamp:
        b.light("lamp", "POINT", (1.0, -1.5, 3.0), energy=400.0, shadow_soft_size=0.2)
    b.camera((0, -5.0, 2.5), (0, 0, 0.5), lens=35.0)


def _thin_wall(b, mp, mw):
    scenes_probes._two_rooms(b, mp, mw)


def _mirror(b, mp, mw):
    mirror = mp(b.n("mirror"), (0.9, 0.9, 0.9), 0.0, metallic=1.0)
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 0.8)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], mirror)
    b.quad("back", [(-3, 3, 0), (3, 3, 0), (3, 3, 3), (-3, 3, 3)], white)
    b.box("box", (0.8, 0.8, 0.8), red, location=(0.0, 0.8, 0.6))
    # a point lamp without radius: no path can reach it through the mirror, so the wall gets no
    # reflective caustic (which Cycles finds as fireflies and no technique here models)
    b.light("lamp", "POINT", (-1.0, -0.5, 2.5), energy=400.0, shadow_soft_size=0.0)
    b.camera((0, -4.0, 1.5), (0, 0.5, 0.5), lens=35.0)
    b.scene.world = mw(b.n("world"), (0.05, 0.05, 0.08), 1.0)


def _glass(b, mp, mw):
    glass = bpy.data.materials.new(b.n("glass"))
    nt = glass.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (1, 1, 1, 1)
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    bsdf.inputs["IOR"].default_value = 1.45
    checker = mp(b.n("floor"), (0.6, 0.6, 0.6), 0.8)
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], checker)
    b.quad("back", [(-3, 2, 0), (3, 2, 0), (3, 2, 3), (-3, 2, 3)], white)
    b.sphere("ball", 0.7, glass, location=(0, 0, 0.7), segments=24, rings=12)
    b.light("lamp", "POINT", (1.0, 1.0, 2.5), energy=400.0, shadow_soft_size=0.1)
    b.camera((0, -4.0, 1.4), (0, 0, 0.6), lens=35.0)
    b.scene.world = mw(b.n("world"), (0.05, 0.05, 0.08), 1.0)


def _furnace(b, mp, mw):
    white = mp(b.n("white"), (1.0, 1.0, 1.0), 1.0, specular=0.0)
    b.sphere("ball", 1.0, white, segments=24, rings=12)
    b.camera((0, -4.0, 0.0), (0, 0, 0), lens=50.0)
    b.scene.world = mw(b.n("world"), (1.0, 1.0, 1.0), 1.0)


def _camera_inside(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    grey = mp(b.n("grey"), (0.5, 0.5, 0.5), 1.0, specular=0.0)
    b.quad("floor", [(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], grey)
    b.box("shell", (1.2, 1.2, 1.2), white, location=(0, 0, 1.0))  # closed: the camera is inside
    b.light("lamp_in", "POINT", (0.2, 0.2, 1.3), energy=5.0, shadow_soft_size=0.0)
    b.light("lamp_out", "POINT", (2.0, -2.0, 3.0), energy=3000.0, shadow_soft_size=0.1)
    b.camera((0, -0.4, 1.0), (0, 1.0, 0.9), lens=18.0)
    b.scene.world = mw(b.n("world"), (0.3, 0.3, 0.35), 1.0)


def _emissive_only(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    glow = mp(b.n("glow"), (0.8, 0.8, 0.8), 1.0, specular=0.0, emission=(1.0, 0.9, 0.7), emission_strength=20.0)
    b.room("room", (-2, -2, 0), (2, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.quad("panel", [(-0.5, -0.5, 2.95), (-0.5, 0.5, 2.95), (0.5, 0.5, 2.95), (0.5, -0.5, 2.95)], glow)
    b.box("box", (0.8, 0.8, 0.8), white, location=(0.5, 0.5, 0.4))
    b.camera((0, -1.9, 1.5), (0, 1.0, 1.0), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _many_lights(b, mp, mw):
    _floor_and_boxes(b, mp, mw, lamp=False)
    rng = np.random.default_rng(7)
    nx, ny = 100, 100
    for i in range(nx):
        for j in range(ny):
            col = tuple(float(c) for c in 0.3 + 0.7 * rng.random(3))
            b.light(f"lamp_{i}_{j}", "POINT", (-4 + 8 * (i + 0.5) / nx, -4 + 8 * (j + 0.5) / ny, 2.5),
                    energy=0.1, color=col, shadow_soft_size=0.02)
    b.scene.world = mw(b.n("world"), (0.0, 0.0, 0.0), 0.0)


def _rescale(sc, s: float):
    """Every length in the scene times ``s``: object locations and scales, lamp sizes, lamp
    power times s^2 (the same irradiance), camera clipping."""
    for ob in sc.objects:
        ob.location = tuple(s * c for c in ob.location)
        if ob.type == "MESH":
            ob.scale = tuple(s * c for c in ob.scale)
        elif ob.type == "LIGHT":
            ld = ob.data
            if ld.type != "SUN":
                ld.energy *= s * s
                ld.shadow_soft_size *= s
            if ld.type == "AREA":
                ld.size *= s
                ld.size_y *= s
        elif ob.type == "CAMERA":
            ob.data.clip_start *= s
            ob.data.clip_end *= s


def _tiny_scale(b, mp, mw):
    _lit_room(b, mp, mw)
    _rescale(b.scene, 0.001)


def _huge_scale(b, mp, mw):
    _lit_room(b, mp, mw)
    _rescale(b.scene, 2500.0)


def _hdri_sun(b, mp, mw):
    _floor_and_boxes(b, mp, mw, lamp=False)
    w, h = 128, 64
    px = np.zeros((h, w, 4), np.float32)
    v = (np.arange(h) + 0.5) / h  # 0 = bottom (straight down), 1 = straight up
    sky = np.where(v[:, None] > 0.5, 1.0, 0.3)[..., None] * np.array([0.03, 0.04, 0.06], np.float32)
    px[..., :3] = sky
    px[..., 3] = 1.0
    sun_row, sun_col = int(0.75 * h), int(0.6 * w)  # 45 degrees up
    px[sun_row, sun_col, :3] = 1e5 * 0.04
    im = bpy.data.images.new(b.n("sky_hdr"), w, h, alpha=True, float_buffer=True)
    im.pixels.foreach_set(px.ravel())
    im.pack()
    wo = bpy.data.worlds.new(b.n("world"))
    b.scene.world = wo
    nt = wo.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = im
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])


def _animated(b, mp, mw):
    _lit_room(b, mp, mw)
    blue = mp(b.n("blue"), (0.1, 0.2, 0.7), 0.4)
    mover = b.box("mover", (0.6, 0.6, 0.6), blue, location=(-1.5, -0.8, 1.0))
    f0, f1 = ANIMATED_FRAMES[0], ANIMATED_FRAMES[-1]
    cam = b.scene.camera
    lamp = next(o for o in b.scene.objects if o.type == "LIGHT")
    # (object, axis, value at f0, change per frame): the box 1 m a frame, the camera 0.3 m, the lamp 0.5 m
    moves = ((mover, 0, -1.5, 1.0), (cam, 0, cam.location.x - 0.45, 0.3), (lamp, 1, lamp.location.y - 0.75, 0.5))
    for ob, axis, v0, dv in moves:
        for f in (f0, f1):
            ob.location[axis] = v0 + dv * (f - f0)
            ob.keyframe_insert("location", frame=f)
        for fc in _fcurves(ob):
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
    b.scene.frame_start, b.scene.frame_end = f0, f1
    b.scene.frame_set(f1)


def _fcurves(ob):
    act = ob.animation_data.action
    if hasattr(act, "fcurves"):
        return act.fcurves
    return [fc for layer in act.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]


def _degenerate(b, mp, mw):
    _floor_and_boxes(b, mp, mw)
    grey = mp(b.n("deg"), (0.5, 0.5, 0.5), 0.5)
    verts = [(0, 0, 1), (0, 0, 1), (0, 0, 1),  # zero area: three equal corners
             (1, 0, 1), (2, 0, 1), (3, 0, 1),  # collinear
             (-2, 0, 0.2), (-1, 0, 0.2), (-1.5, 1e-6, 0.2),  # a 1e-6 m sliver
             (-2, -1, 0.5), (2, -1, 0.5), (2, -1 + 1e-7, 0.5 + 1e-7)]  # a long sliver
    b.mesh("degenerate", verts, [(0, 1, 2), (3, 4, 5), (6, 7, 8), (9, 10, 11)], grey)
    b.scene.world = mw(b.n("world"), (0.03, 0.03, 0.04), 1.0)


def _z_fighting(b, mp, mw):
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 1.0, specular=0.0)
    green = mp(b.n("green"), (0.1, 0.6, 0.12), 1.0, specular=0.0)
    blue = mp(b.n("blue"), (0.1, 0.2, 0.7), 1.0, specular=0.0)
    b.quad("plane_a", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], red)
    b.quad("plane_b", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], green)
    b.quad("plane_c", [(-1, -1, 1e-5), (1, -1, 1e-5), (1, 1, 1e-5), (-1, 1, 1e-5)], blue)
    b.light("lamp", "POINT", (0.5, -1.0, 3.0), energy=400.0, shadow_soft_size=0.2)
    b.camera((0, -5.0, 3.0), (0, 0, 0), lens=35.0)
    b.scene.world = mw(b.n("world"), (0.03, 0.03, 0.04), 1.0)


def _black(b, mp, mw):
    _floor_and_boxes(b, mp, mw, lamp=False)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _bright_light(b, mp, mw):
    _floor_and_boxes(b, mp, mw, lamp=False)
    b.light("point_zero", "POINT", (1.0, -1.5, 3.0), energy=300.0, shadow_soft_size=0.0)
    b.light("huge", "POINT", (-300.0, -200.0, 400.0), energy=1e6, shadow_soft_size=1.0)
    b.scene.world = mw(b.n("world"), (0.02, 0.02, 0.03), 1.0)


def _mirrored_instances(b, mp, mw):
    _floor_and_boxes(b, mp, mw)
    for ob in [o for o in b.scene.objects if o.type == "MESH" and ("box" in o.name or "ball" in o.name)]:
        cp = ob.copy()
        cp.name = ob.name + ".mirrored"
        cp.location = (ob.location.x, ob.location.y + 1.8, ob.location.z)
        cp.scale = (-1.0, 1.0, 1.0)
        b.scene.collection.objects.link(cp)
    b.scene.world = mw(b.n("world"), (0.03, 0.03, 0.04), 1.0)


MISSING_PATH = "//textures/this_file_does_not_exist.png"


def _missing_texture(b, mp, mw):
    _floor_and_boxes(b, mp, mw)
    floor = next(o for o in b.scene.objects if o.name.startswith(b.n("floor")))
    mat = bpy.data.materials.new(b.n("textured"))
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    im = bpy.data.images.new(b.n("missing"), 8, 8)  # the artist's file was moved away: no pixels
    im.source = "FILE"
    im.filepath = MISSING_PATH
    tex.image = im
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    floor.data.materials.clear()
    floor.data.materials.append(mat)
    b.scene.world = mw(b.n("world"), (0.03, 0.03, 0.04), 1.0)


def _million_triangles(b, mp, mw):
    """The lit room around a sphere of about a million triangles (1000 x 500 segments)."""
    _lit_room(b, mp, mw)
    grey = mp(b.n("dense"), (0.6, 0.6, 0.55), 0.4)
    b.sphere("dense", 0.45, grey, location=(-0.6, -0.2, 0.45), segments=1000, rings=500)


_BUILD = {"thin_wall": _thin_wall, "mirror": _mirror, "glass": _glass, "furnace": _furnace,
          "camera_inside": _camera_inside, "emissive_only": _emissive_only, "many_lights": _many_lights,
          "tiny_scale": _tiny_scale, "huge_scale": _huge_scale, "hdri_sun": _hdri_sun, "animated": _animated,
          "degenerate": _degenerate, "z_fighting": _z_fighting, "black": _black, "bright_light": _bright_light,
          "mirrored_instances": _mirrored_instances, "missing_texture": _missing_texture,
          "million_triangles": _million_triangles}


def render_reference(sc, name: str, spp: int, kind: str):
    """Cycles' reference of hard case ``name`` (``reference.render_cycles``), with the objects of
    ``REFERENCE_HIDE`` hidden from it. Returns (image, ms)."""
    from gi_preview.blender import reference
    hide = [o for o in sc.objects if any(o.name.startswith(p) for p in REFERENCE_HIDE.get(name, ()))]
    for o in hide:
        o.hide_render = True
    try:
        return reference.render_cycles(sc, spp, kind)
    finally:
        for o in hide:
            o.hide_render = False


def build(name: str, resolution: int = 40) -> bpy.types.Scene:
    """A new scene ``hard_<name>`` at ``resolution``² (the caller removes it)."""
    return build_named_scene(_BUILD, name, resolution, "hard", "hard case")
