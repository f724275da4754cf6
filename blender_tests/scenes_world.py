"""Scenes lit by worlds the way artists light them: one of Blender's bundled HDRIs through an
Environment Texture (with a Mapping rotation and a strength), a Sky Texture, and a
procedural gradient. None is tuned for a technique: a ground plane, a diffuse and a glossy
sphere, a metal box and a camera, lit by the world alone (the pavilion adds a roof, so that
part of the scene sees the world only around a corner)."""
from __future__ import annotations

import math
import os

import bpy

SKY_TYPES = ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING", "PREETHAM", "HOSEK_WILKIE")
HDRIS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")


def hdri_path(name: str) -> str:
    return os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), f"{name}.exr")


def _material(name, color, roughness=0.5, metallic=0.0):
    m = bpy.data.materials.new(name)
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    return m


def _add(sc, ob, mat):
    sc.collection.objects.link(ob)
    ob.data.materials.append(mat)
    return ob


def _mesh_object(name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    return bpy.data.objects.new(name, me)


def _uv_sphere(name, radius, center, segments=24, rings=12):
    verts, faces = [], []
    for i in range(rings + 1):
        th = math.pi * i / rings
        for j in range(segments):
            ph = 2 * math.pi * j / segments
            verts.append((center[0] + radius * math.sin(th) * math.cos(ph),
                          center[1] + radius * math.sin(th) * math.sin(ph),
                          center[2] + radius * math.cos(th)))
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            faces.append((a, b, b + segments, a + segments))
    ob = _mesh_object(name, verts, faces)
    for p in ob.data.polygons:
        p.use_smooth = True
    return ob


def _box(name, lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return _mesh_object(name, v, f)


def _objects(sc, roof: bool):
    _add(sc, _mesh_object("Ground", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)], [(0, 1, 2, 3)]),
         _material("Ground", (0.55, 0.5, 0.45), 0.8))
    _add(sc, _uv_sphere("Diffuse ball", 0.6, (-0.9, 0.3, 0.6)), _material("Clay", (0.75, 0.75, 0.75), 0.9))
    _add(sc, _uv_sphere("Glossy ball", 0.5, (0.7, -0.4, 0.5)), _material("Glossy", (0.8, 0.3, 0.2), 0.15))
    _add(sc, _box("Metal box", (0.3, 0.8, 0.0), (1.1, 1.6, 0.8)), _material("Metal", (0.9, 0.8, 0.6), 0.3, 1.0))
    if roof:
        _add(sc, _box("Roof", (-2.2, -1.2, 2.2), (2.2, 2.6, 2.35)), _material("Roof", (0.7, 0.7, 0.7), 0.7))
        _add(sc, _box("Back wall", (-2.2, 2.45, 0.0), (2.2, 2.6, 2.2)), _material("Wall", (0.7, 0.7, 0.7), 0.7))


def _camera(sc, res: int):
    cam = bpy.data.cameras.new("Camera")
    cam.lens = 32
    ob = bpy.data.objects.new("Camera", cam)
    sc.collection.objects.link(ob)
    ob.location = (0.0, -5.2, 1.7)
    ob.rotation_euler = (math.radians(78), 0.0, 0.0)
    sc.camera = ob
    sc.render.resolution_x = sc.render.resolution_y = res
    sc.render.resolution_percentage = 100


def hdri_scene(name: str = "forest", *, res: int = 48, rotation_deg: float = 30.0, strength: float = 1.0,
               roof: bool = False):
    """The objects under a bundled HDRI (Environment Texture <- Mapping (Z rotation) <- Texture
    Coordinate Generated), Background strength ``strength``."""
    sc = bpy.data.scenes.new(f"HDRI {name}")
    wo = bpy.data.worlds.new(f"HDRI {name}")
    sc.world = wo
    nt = wo.node_tree
    bg = nt.nodes["Background"]
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri_path(name), check_existing=True)
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rotation_deg))
    tc = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
    nt.links.new(mp.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    _objects(sc, roof)
    _camera(sc, res)
    return sc


def sky_scene(sky_type: str | None = None, *, res: int = 48, sun_elevation_deg: float = 35.0,
              strength: float = 0.1):
    """The objects under a Sky Texture (Blender's default sky type unless ``sky_type``), with
    its sun, Background strength ``strength`` (a physical sky is bright: artists scale it)."""
    sc = bpy.data.scenes.new("Sky")
    wo = bpy.data.worlds.new("Sky")
    sc.world = wo
    nt = wo.node_tree
    bg = nt.nodes["Background"]
    sky = nt.nodes.new("ShaderNodeTexSky")
    if sky_type is not None:
        sky.sky_type = sky_type
    if hasattr(sky, "sun_elevation"):
        sky.sun_elevation = math.radians(sun_elevation_deg)
    if hasattr(sky, "sun_rotation"):
        sky.sun_rotation = math.radians(60.0)
    nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    _objects(sc, roof=True)
    _camera(sc, res)
    return sc


def gradient_scene(*, res: int = 48):
    """A procedural world: a Gradient Texture over the direction through a Color Ramp (blue
    above, warm below), a node tree no fast path reads: Cycles evaluates it."""
    sc = bpy.data.scenes.new("Gradient world")
    wo = bpy.data.worlds.new("Gradient")
    sc.world = wo
    nt = wo.node_tree
    bg = nt.nodes["Background"]
    tc = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position = 0.4
    ramp.color_ramp.elements[0].color = (0.5, 0.35, 0.2, 1.0)
    ramp.color_ramp.elements[1].position = 0.7
    ramp.color_ramp.elements[1].color = (0.3, 0.5, 1.0, 1.0)
    mp = nt.nodes.new("ShaderNodeMapRange")
    mp.inputs["From Min"].default_value = -1.0
    nt.links.new(tc.outputs["Generated"], sep.inputs["Vector"])
    nt.links.new(sep.outputs["Z"], mp.inputs["Value"])
    nt.links.new(mp.outputs["Result"], ramp.inputs["Fac"])
    nt.links.new(ramp.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.5
    _objects(sc, roof=False)
    _camera(sc, res)
    return sc
