"""Hard cases stay numerically stable: every technique, on scenes built to break shading.

Each case is rendered with every registered technique (a few frames, small images) and
must give finite pixels (no NaN/Inf), no negative values, and no pixel brighter than a
bound derived from the scene (the largest radiance anything in it can send to the camera,
times a safety factor for glossy concentration), so a firefly or an overflow fails.

Cases: degenerate triangles (zero area, collinear), a zero-size area light, a light inside
an object, the camera inside an object, mirror (roughness 0) and fully rough floors under
a point light, an extremely bright emitter (1e6), a huge and a tiny scene scale, and
back-facing / flipped normals.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from gi_preview.blender.demo_scenes import make_emission, make_principled, make_world
from gi_preview.blender.export import export_scene
from gi_preview.render import session, techniques

RES = 32
TECHNIQUES = sorted(i.id for i in techniques.available())


def _mesh(sc, name, verts, faces, mat, location=(0, 0, 0), scale=1.0):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(scale * c for c in v) for v in verts], [], faces)
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    ob.location = tuple(scale * c for c in location)
    sc.collection.objects.link(ob)
    return ob


def _box(sc, name, mat, location, size, scale=1.0):
    s = size / 2
    v = [(-s, -s, -s), (s, -s, -s), (s, s, -s), (-s, s, -s), (-s, -s, s), (s, -s, s), (s, s, s), (-s, s, s)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return _mesh(sc, name, v, f, mat, location, scale)


def _scene(case: str):
    sc = bpy.data.scenes.new(f"hard_{case}")
    sc.render.resolution_x = sc.render.resolution_y = RES
    sc.world = make_world(f"w_{case}", (0.05, 0.05, 0.08), 1.0)
    scale = {"huge_scale": 1000.0, "tiny_scale": 0.001}.get(case, 1.0)
    rough = 0.0 if case == "mirror_floor" else (1.0 if case == "rough_floor" else 0.5)
    floor = make_principled(f"floor_{case}", (0.6, 0.6, 0.6), roughness=rough, metallic=1.0 if case == "mirror_floor" else 0.0)
    _mesh(sc, "floor", [(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], [(0, 1, 2, 3)], floor, scale=scale)
    _box(sc, "box", make_principled(f"box_{case}", (0.8, 0.3, 0.2), 0.3), (0.5, 0.5, 0.5), 1.0, scale)
    bound = 0.0  # the largest radiance a surface can reflect or emit (before the safety factor)

    def light(kind, loc, energy, **kw):
        ld = bpy.data.lights.new(f"L_{case}", kind)
        ld.energy = energy
        for k, v in kw.items():
            setattr(ld, k, v)
        ob = bpy.data.objects.new(f"L_{case}", ld)
        ob.location = tuple(scale * c for c in loc)
        sc.collection.objects.link(ob)
        return ob

    if case == "degenerate_triangles":
        mat = make_principled(f"deg_{case}", (0.5, 0.5, 0.5))
        _mesh(sc, "degenerate", [(0, 0, 1), (0, 0, 1), (0, 0, 1), (1, 0, 1), (2, 0, 1), (3, 0, 1)],
              [(0, 1, 2), (3, 4, 5)], mat)
        light("POINT", (0, -2, 3), 300.0)
    elif case == "zero_size_area_light":
        light("AREA", (0, 0, 3), 300.0, size=0.0, size_y=0.0, shape="RECTANGLE")
        light("POINT", (1, -2, 3), 100.0)
    elif case == "light_inside_object":
        light("POINT", (0.5, 0.5, 0.5), 1000.0, shadow_soft_size=0.05)
        light("SUN", (0, 0, 5), 2.0)
    elif case == "camera_inside_object":
        light("POINT", (0, -2, 3), 300.0)
    elif case in ("mirror_floor", "rough_floor"):
        light("POINT", (0, -1, 2), 300.0, shadow_soft_size=0.0)
        light("AREA", (-1, 0, 2), 200.0, size=0.5)
    elif case == "bright_emitter":
        em = make_emission(f"em_{case}", (1, 1, 1), 1e6)
        _mesh(sc, "emitter", [(-.2, -.2, 0), (.2, -.2, 0), (.2, .2, 0), (-.2, .2, 0)], [(0, 1, 2, 3)], em,
              location=(-1, 0, 1.5))
        bound = 1e6
    elif case in ("huge_scale", "tiny_scale"):
        light("SUN", (0, 0, 5), 3.0, angle=math.radians(1))
        light("POINT", (0, -2, 3), 300.0 * scale * scale, shadow_soft_size=0.1 * scale)
    elif case == "flipped_normals":
        for ob in sc.objects:
            if ob.type == "MESH":
                ob.data.flip_normals()
        light("POINT", (0, -2, 3), 300.0)
    cam = bpy.data.objects.new(f"cam_{case}", bpy.data.cameras.new(f"cam_{case}"))
    if case == "camera_inside_object":
        cam.location = (0.5, 0.5, 0.5)
        cam.rotation_euler = (math.radians(80), 0, 0)
    else:
        cam.location = (0, -6 * scale, 3 * scale)
        cam.rotation_euler = (math.radians(65), 0, 0)
    cam.data.clip_start = 0.01 * scale
    cam.data.clip_end = 100 * scale
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc, bound


CASES = ["degenerate_triangles", "zero_size_area_light", "light_inside_object", "camera_inside_object",
         "mirror_floor", "rough_floor", "bright_emitter", "huge_scale", "tiny_scale", "flipped_normals"]


def _radiance_bound(sd) -> float:
    """An upper bound on what a pixel can show: emitters and the world directly, and the
    irradiance a 1 m^2 patch can get from each light at the closest distance any geometry
    reaches (floored at 1 cm) reflected by a white Lambertian surface — times 100 for the
    concentration of glossy lobes and sample noise."""
    b = float(np.max(sd.world.color)) if sd.world is not None else 0.0
    for m in sd.materials:
        b = max(b, float(np.max(m.emission)))
    for L in sd.lights:
        b = max(b, float(np.max(L.color)) * 1e4)  # intensity / (1 cm)^2 * (1/pi) ~ generous
    return 100.0 * max(b, 1.0)


@pytest.fixture(autouse=True)
def validate_passes(monkeypatch):
    """Every pass output is checked for NaN, Inf and negative radiance as it is written
    (framegraph's GI_PREVIEW_VALIDATE): a bad value fails the test naming pass and resource."""
    monkeypatch.setenv("GI_PREVIEW_VALIDATE", "1")


@pytest.mark.parametrize("case", CASES)
def test_hard_case_is_finite_and_bounded(case):
    sc, _ = _scene(case)
    try:
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        sd = export_scene(dg)
        bound = _radiance_bound(sd)
        for tech in TECHNIQUES:
            res = session.render(sd, tech, 0, 2)
            img = res.image[..., :3]
            assert np.isfinite(img).all(), f"{case}/{tech}: {int((~np.isfinite(img)).sum())} non-finite values"
            assert img.min() >= 0.0, f"{case}/{tech}: negative radiance {img.min()}"
            assert img.max() <= bound, f"{case}/{tech}: pixel {img.max():.3g} above the bound {bound:.3g}"
            for name, aov in res.aovs.items():
                assert np.isfinite(aov).all(), f"{case}/{tech}: AOV {name} not finite"
    finally:
        bpy.data.scenes.remove(sc)
