"""Built-in demo scenes, built in code (no .blend files shipped).

``build_demo(name, *, resolution=256) -> bpy.types.Scene`` creates a NEW scene called
"GI Preview Demo: <name>" (the current scene is not touched). ``DEMO_SCENES`` lists the
ids for an enum. ``GIPREVIEW_OT_add_demo_scene`` / ``menu_func`` expose them in
View3D > Add; this module does not register anything itself (see ``classes``).

Triangle counts stay small (UV spheres of 32x16 segments, no subdivision modifiers).
"""
from __future__ import annotations

import colorsys
import math

import bmesh
import bpy
import numpy as np

DEMO_SCENES: tuple[tuple[str, str, str], ...] = (
    ("cornell", "Cornell Box",
     "Classic Cornell box: red and green walls, two white boxes, an area light at the ceiling"),
    ("glossy_spheres", "Glossy Spheres",
     "Spheres of increasing roughness, dielectric and metallic, on a floor under an area "
     "light and a sky-coloured world"),
    ("sunlit_room", "Sunlit Room",
     "A closed room with a window; the sun shines in, everything else is indirect light"),
    ("emissive_panel", "Emissive Panel",
     "A room lit only by an emissive mesh panel (no lamps, black world)"),
    ("many_lights", "Many Lights",
     "A floor and a few objects lit by 256 small point lights of many colours and three "
     "emissive strips"),
    ("courtyard_loft", "Courtyard Loft",
     "An open-fronted loft lit only by Blender's bundled courtyard HDRI: a texture-set floor "
     "(colour and roughness images), a glossy ball and a block; most of the back of the room "
     "sees the sky only by bounced light"),
)
_IDS = tuple(d[0] for d in DEMO_SCENES)
SCENE_PREFIX = "GI Preview Demo: "


# ------------------------------------------------------------------ material helpers
def make_principled(name, color=(0.8, 0.8, 0.8), roughness=0.5, metallic=0.0, *,
                    emission=(0.0, 0.0, 0.0), emission_strength=0.0, specular=0.5,
                    ior=1.5) -> bpy.types.Material:
    """A new material whose surface is one Principled BSDF with the given unlinked values."""
    mat = bpy.data.materials.new(name)
    tree = _fresh_tree(mat)
    nodes, links = tree.nodes, tree.links
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.location = (-300, 0)
    inp = bsdf.inputs
    inp["Base Color"].default_value = (*color[:3], 1.0)
    inp["Roughness"].default_value = roughness
    inp["Metallic"].default_value = metallic
    inp["Specular IOR Level"].default_value = specular
    inp["IOR"].default_value = ior
    inp["Emission Color"].default_value = (*emission[:3], 1.0)
    inp["Emission Strength"].default_value = emission_strength
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    mat.diffuse_color = (*color[:3], 1.0)
    mat.roughness = roughness
    mat.metallic = metallic
    return mat


def make_emission(name, color=(1.0, 1.0, 1.0), strength=1.0) -> bpy.types.Material:
    """A new material whose surface is an Emission shader (radiance = colour * strength)."""
    mat = bpy.data.materials.new(name)
    tree = _fresh_tree(mat)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    em = tree.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*color[:3], 1.0)
    em.inputs["Strength"].default_value = strength
    tree.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color[:3], 1.0)
    return mat


def _fresh_tree(idblock):
    if idblock.node_tree is None and hasattr(idblock, "use_nodes"):
        idblock.use_nodes = True  # Blender < 5 creates the tree on demand
    tree = idblock.node_tree
    tree.nodes.clear()
    return tree


def make_world(name, color=(0.0, 0.0, 0.0), strength=1.0) -> bpy.types.World:
    """A world whose surface is one Background node (radiance = colour * strength)."""
    wo = bpy.data.worlds.new(name)
    tree = _fresh_tree(wo)
    out = tree.nodes.new("ShaderNodeOutputWorld")
    bg = tree.nodes.new("ShaderNodeBackground")
    bg.inputs["Color"].default_value = (*color[:3], 1.0)
    bg.inputs["Strength"].default_value = strength
    tree.links.new(bg.outputs["Background"], out.inputs["Surface"])
    wo.color = color[:3]
    return wo


# ------------------------------------------------------------------ geometry helpers
class _Builder:
    def __init__(self, scene: bpy.types.Scene, prefix: str):
        self.scene = scene
        self.prefix = prefix

    def n(self, name: str) -> str:
        return f"{self.prefix}.{name}"

    def obj(self, name, data, location=(0, 0, 0), rotation=(0, 0, 0), scale=(1, 1, 1)):
        ob = bpy.data.objects.new(self.n(name), data)
        ob.location = location
        ob.rotation_euler = rotation
        ob.scale = scale
        self.scene.collection.objects.link(ob)
        return ob

    def mesh(self, name, verts, faces, material, location=(0, 0, 0), rotation=(0, 0, 0),
             scale=(1, 1, 1)):
        me = bpy.data.meshes.new(self.n(name))
        me.from_pydata(verts, [], faces)
        uv = me.uv_layers.new(name="UVMap")
        # planar UVs from X/Y (enough for demos)
        co = np.empty(3 * len(me.vertices), np.float32)
        me.vertices.foreach_get("co", co)
        cv = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("vertex_index", cv)
        uv.data.foreach_set("uv", np.ascontiguousarray(co.reshape(-1, 3)[cv][:, :2]).ravel())
        me.update()
        if material is not None:
            me.materials.append(material)
        return self.obj(name, me, location, rotation, scale)

    def quad(self, name, corners, material, **kw):
        return self.mesh(name, corners, [(0, 1, 2, 3)], material, **kw)

    def box(self, name, size, material, location=(0, 0, 0), rotation=(0, 0, 0)):
        sx, sy, sz = (s / 2 for s in size)
        v = [(-sx, -sy, -sz), (sx, -sy, -sz), (sx, sy, -sz), (-sx, sy, -sz),
             (-sx, -sy, sz), (sx, -sy, sz), (sx, sy, sz), (-sx, sy, sz)]
        f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        return self.mesh(name, v, f, material, location, rotation)

    def sphere(self, name, radius, material, location=(0, 0, 0), segments=32, rings=16):
        me = bpy.data.meshes.new(self.n(name))
        bm = bmesh.new()
        bm.loops.layers.uv.new("UVMap")
        bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius,
                                  calc_uvs=True)
        # bmesh makes the sphere's faces in an order that changes from process to process (the
        # vertices keep theirs): sorted by their vertices, the exported triangles, and so the
        # BVH and every ray-traced image, are the same in every process
        bm.faces.index_update()
        rank = {f.index: r for r, f in enumerate(sorted(bm.faces, key=lambda f: sorted(v.index for v in f.verts)))}
        bm.faces.sort(key=lambda f: rank[f.index])
        bm.to_mesh(me)
        bm.free()
        me.shade_smooth()
        if material is not None:
            me.materials.append(material)
        return self.obj(name, me, location)

    def room(self, name, lo, hi, materials, skip=()):
        """An axis-aligned room seen from inside; faces: floor, ceiling, -x, +x, -y, +y."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        faces = {
            "floor": [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
            "ceiling": [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)],
            "-x": [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
            "+x": [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],
            "-y": [(x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)],
            "+y": [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)],
        }
        return {k: self.quad(f"{name}.{k}", c, materials[k]) for k, c in faces.items()
                if k not in skip}

    def light(self, name, kind, location, rotation=(0, 0, 0), **props):
        ld = bpy.data.lights.new(self.n(name), kind)
        for k, val in props.items():
            setattr(ld, k, val)
        return self.obj(name, ld, location, rotation)

    def camera(self, location, look_at, lens=35.0, sensor=36.0):
        cd = bpy.data.cameras.new(self.n("Camera"))
        cd.lens = lens
        cd.sensor_width = sensor
        cd.clip_start = 0.05
        cd.clip_end = 200.0
        ob = self.obj("Camera", cd, location)
        _look_at(ob, look_at)
        self.scene.camera = ob
        return ob


def _look_at(ob, target):
    from mathutils import Vector
    d = Vector(target) - Vector(ob.location)
    ob.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


# ------------------------------------------------------------------ scenes
def _cornell(b: _Builder):
    white = make_principled(b.n("white"), (0.73, 0.73, 0.73), 1.0, specular=0.0)
    red = make_principled(b.n("red"), (0.63, 0.065, 0.05), 1.0, specular=0.0)
    green = make_principled(b.n("green"), (0.14, 0.45, 0.091), 1.0, specular=0.0)
    b.room("box", (-1, -1, 0), (1, 1, 2),
           {"floor": white, "ceiling": white, "+y": white, "-x": red, "+x": green}, skip=("-y",))
    b.box("tall_box", (0.6, 0.6, 1.2), white, location=(-0.33, 0.3, 0.6),
          rotation=(0, 0, math.radians(15)))
    b.box("short_box", (0.6, 0.6, 0.6), white, location=(0.35, -0.3, 0.3),
          rotation=(0, 0, math.radians(-18)))
    b.light("ceiling_light", "AREA", (0, 0, 1.98), size=0.5, energy=40.0,
            color=(1.0, 0.85, 0.65))
    b.camera((0, -3.8, 1.0), (0, 0, 1.0), lens=50.0)
    b.scene.world = make_world(b.n("world"), (0, 0, 0), 0.0)


def _glossy_spheres(b: _Builder):
    floor = make_principled(b.n("floor"), (0.5, 0.5, 0.5), 0.6)
    b.quad("floor", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)], floor)
    for i, rough in enumerate((0.05, 0.2, 0.4, 0.6, 0.9)):
        x = (i - 2) * 1.0
        diel = make_principled(b.n(f"dielectric_r{rough}"), (0.8, 0.1, 0.1), rough)
        metal = make_principled(b.n(f"metal_r{rough}"), (0.95, 0.75, 0.35), rough, 1.0)
        b.sphere(f"dielectric_{i}", 0.4, diel, (x, 0.6, 0.4))
        b.sphere(f"metal_{i}", 0.4, metal, (x, -0.6, 0.4))
    b.light("key", "AREA", (1.5, -2.0, 4.0), rotation=(math.radians(30), 0, math.radians(35)),
            size=1.5, energy=400.0)
    b.light("fill", "POINT", (-3.0, 1.0, 2.5), energy=150.0, shadow_soft_size=0.1,
            color=(0.8, 0.9, 1.0))
    b.camera((0, -5.5, 2.6), (0, 0, 0.35), lens=40.0)
    b.scene.world = make_world(b.n("sky"), (0.35, 0.5, 0.8), 0.3)


def _sunlit_room(b: _Builder):
    wall = make_principled(b.n("wall"), (0.75, 0.72, 0.68), 0.9, specular=0.2)
    floor = make_principled(b.n("floor"), (0.45, 0.3, 0.2), 0.5)
    x0, x1, y0, y1, h = -2.0, 2.0, -2.0, 2.0, 2.5
    b.room("room", (x0, y0, 0), (x1, y1, h),
           {"floor": floor, "ceiling": wall, "-x": wall, "-y": wall, "+y": wall},
           skip=("+x",))
    # +x wall with a window opening (y in [-0.6, 0.6], z in [0.8, 1.9]), four quads
    wy0, wy1, wz0, wz1 = -0.6, 0.6, 0.8, 1.9
    verts = [(x1, y0, 0), (x1, y1, 0), (x1, y1, h), (x1, y0, h),
             (x1, wy0, wz0), (x1, wy1, wz0), (x1, wy1, wz1), (x1, wy0, wz1)]
    faces = [(0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]
    b.mesh("room.window_wall", verts, faces, wall)
    table = make_principled(b.n("table"), (0.2, 0.35, 0.6), 0.3)
    b.box("block", (0.8, 0.8, 0.8), table, location=(-0.5, 0.6, 0.4),
          rotation=(0, 0, math.radians(20)))
    b.sphere("ball", 0.35, make_principled(b.n("ball"), (0.8, 0.8, 0.8), 0.2), (0.4, -0.8, 0.35))
    # sun from +x, 35 degrees above the horizon, shining in through the window
    b.light("sun", "SUN", (4, 0, 4), rotation=(0, math.radians(55), math.radians(10)),
            energy=8.0, angle=math.radians(0.53), color=(1.0, 0.95, 0.85))
    b.camera((-1.8, -1.7, 1.4), (0.5, 0.3, 0.8), lens=18.0)
    b.scene.world = make_world(b.n("sky"), (0.3, 0.45, 0.8), 0.2)


def _emissive_panel(b: _Builder):
    wall = make_principled(b.n("wall"), (0.7, 0.7, 0.7), 0.8, specular=0.2)
    blue = make_principled(b.n("blue"), (0.1, 0.2, 0.7), 0.8, specular=0.2)
    b.room("room", (-2, -2, 0), (2, 2, 2.5),
           {"floor": wall, "ceiling": wall, "-x": blue, "+x": wall, "-y": wall, "+y": wall})
    panel = make_emission(b.n("panel"), (1.0, 0.9, 0.75), 8.0)
    s = 0.6
    b.quad("panel", [(-s, -s, 2.49), (-s, s, 2.49), (s, s, 2.49), (s, -s, 2.49)], panel)
    b.box("box", (0.9, 0.9, 0.9), make_principled(b.n("box"), (0.8, 0.5, 0.2), 0.5),
          location=(0.6, 0.6, 0.45), rotation=(0, 0, math.radians(30)))
    b.sphere("ball", 0.45, make_principled(b.n("ball"), (0.9, 0.9, 0.9), 0.15),
             (-0.7, -0.3, 0.45))
    b.camera((1.7, -1.8, 1.5), (-0.2, 0.3, 0.8), lens=18.0)
    b.scene.world = make_world(b.n("black"), (0, 0, 0), 0.0)


MANY_LIGHTS_COUNT = 256


def _many_lights(b: _Builder):
    """256 small point lights of many colours on a jittered 16 x 16 grid over the floor
    (heights 0.25-1.2 m) plus three emissive strips (mesh lights): DIRECT's many-light path
    (tile culling, shadow-map budget, ray-traced shadows) and light sampling in every
    ray-tracing technique."""
    floor = make_principled(b.n("floor"), (0.6, 0.6, 0.6), 0.4)
    b.quad("floor", [(-8, -8, 0), (8, -8, 0), (8, 8, 0), (-8, 8, 0)], floor)
    grey = make_principled(b.n("grey"), (0.7, 0.7, 0.7), 0.5)
    b.sphere("ball", 0.8, grey, (0, 0, 0.8))
    b.box("pillar_a", (0.6, 0.6, 2.0), grey, location=(2.2, 1.0, 1.0))
    b.box("pillar_b", (0.6, 0.6, 1.2), grey, location=(-2.0, 1.8, 0.6),
          rotation=(0, 0, math.radians(30)))
    b.sphere("small", 0.4, make_principled(b.n("metal"), (0.9, 0.9, 0.9), 0.15, 1.0),
             (-1.2, -1.6, 0.4))
    for k, (x, hue) in enumerate(((-4.5, 0.0), (0.0, 0.35), (4.5, 0.6))):
        rgb = colorsys.hsv_to_rgb(hue, 0.7, 1.0)
        strip = make_emission(b.n(f"strip_{k}"), rgb, 6.0)
        b.box(f"strip_{k}", (0.12, 7.0, 0.06), strip, location=(x, 3.5, 0.03))
    rng = np.random.default_rng(7)
    n = 16
    for i in range(MANY_LIGHTS_COUNT):
        gx, gy = i % n, i // n
        x = -7.5 + 15.0 * (gx + 0.2 + 0.6 * rng.random()) / n
        y = -7.5 + 15.0 * (gy + 0.2 + 0.6 * rng.random()) / n
        z = 0.25 + 0.95 * rng.random()
        rgb = colorsys.hsv_to_rgb(float(rng.random()), 0.75, 1.0)
        b.light(f"point_{i:03d}", "POINT", (x, y, z), energy=3.0, color=rgb, shadow_soft_size=0.05)
    b.camera((0, -7.5, 4.5), (0, 0, 0.5), lens=30.0)
    b.scene.world = make_world(b.n("night"), (0.02, 0.02, 0.03), 1.0)


def _checker_image(name: str, size: int = 128, tiles: int = 2):
    """A packed sRGB image: warm light and dark checker tiles in RGB, and a roughness map in
    the alpha-free G channel of a second image (the layout of a texture set)."""
    u = (np.arange(size) + 0.5) / size
    uu, vv = np.meshgrid(u, u)
    check = ((np.floor(uu * tiles) + np.floor(vv * tiles)) % 2)[..., None]
    col = np.where(check > 0, (0.70, 0.62, 0.50), (0.16, 0.12, 0.10))
    rough = 0.25 + 0.55 * check[..., 0]
    images = []
    for suffix, rgb, colorspace in (("color", col, "sRGB"),
                                    ("roughness", np.stack([rough] * 3, -1), "Non-Color")):
        img = bpy.data.images.new(f"{name}.{suffix}", size, size, alpha=True)
        img.colorspace_settings.name = colorspace
        px = np.concatenate([rgb, np.ones((size, size, 1))], -1).astype(np.float32)
        img.pixels.foreach_set(px.ravel())
        img.pack()
        images.append(img)
    return images


def _textured_floor(b: _Builder):
    m = make_principled(b.n("floor"), (0.5, 0.5, 0.5), 0.5)
    nt = m.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    col_img, rough_img = _checker_image(b.n("floor"))
    for img, socket in ((col_img, "Base Color"), (rough_img, None)):  # the UVs are in metres:
        t = nt.nodes.new("ShaderNodeTexImage")                         # one repeat per metre
        t.image = img
        if socket is not None:
            nt.links.new(t.outputs["Color"], bsdf.inputs[socket])
        else:
            sep = nt.nodes.new("ShaderNodeSeparateColor")
            nt.links.new(t.outputs["Color"], sep.inputs["Color"])
            nt.links.new(sep.outputs["Green"], bsdf.inputs["Roughness"])
    return m


def _courtyard_loft(b: _Builder):
    wall = make_principled(b.n("plaster"), (0.78, 0.75, 0.70), 0.9, specular=0.3)
    x0, x1, y0, y1, h = -2.5, 2.5, -2.0, 2.5, 2.6
    # open towards -y (the camera's side): the sky comes in through the whole front
    b.room("loft", (x0, y0, 0), (x1, y1, h), {"floor": _textured_floor(b), "ceiling": wall, "-x": wall,
                                              "+x": wall, "+y": wall}, skip=("-y",))
    b.box("block", (0.9, 0.9, 0.9), make_principled(b.n("terracotta"), (0.62, 0.28, 0.16), 0.7),
          location=(-1.0, 1.2, 0.45), rotation=(0, 0, math.radians(25)))
    b.sphere("ball", 0.45, make_principled(b.n("lacquer"), (0.15, 0.3, 0.65), 0.12), (0.9, 0.6, 0.45))
    b.camera((0.3, -3.6, 1.3), (0.0, 1.2, 0.9), lens=24.0)
    wo = bpy.data.worlds.new(b.n("courtyard"))
    _fresh_tree(wo)
    nt = wo.node_tree
    out = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    import os
    path = os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), "courtyard.exr")
    env.image = bpy.data.images.load(path, check_existing=True)
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(200.0))
    tc = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
    nt.links.new(mp.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    b.scene.world = wo


_BUILDERS = {"cornell": _cornell, "glossy_spheres": _glossy_spheres,
             "sunlit_room": _sunlit_room, "emissive_panel": _emissive_panel,
             "many_lights": _many_lights, "courtyard_loft": _courtyard_loft}


def _engine_registered(idname: str) -> bool:
    items = bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items
    if idname in items.keys():
        return True
    return any(getattr(c, "bl_idname", None) == idname for c in bpy.types.RenderEngine.__subclasses__())


def build_demo(name: str, *, resolution: int = 256) -> bpy.types.Scene:
    """Build the demo scene ``name`` (one of ``DEMO_SCENES``' ids) as a new scene."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown demo scene {name!r}; choose one of {', '.join(_IDS)}")
    scene = bpy.data.scenes.new(SCENE_PREFIX + name)
    r = scene.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    scene.frame_current = 1
    _BUILDERS[name](_Builder(scene, f"{name}"))
    if _engine_registered("GI_PREVIEW"):
        try:
            r.engine = "GI_PREVIEW"
        except TypeError:
            pass
    return scene


# ------------------------------------------------------------------ operator and menu
class GIPREVIEW_OT_add_demo_scene(bpy.types.Operator):
    """Add a new scene with a GI Preview demo setup (lights, materials, camera) and switch to it"""

    bl_idname = "gi_preview.add_demo_scene"
    bl_label = "Add GI Preview Demo Scene"
    bl_options = {"REGISTER", "UNDO"}

    scene: bpy.props.EnumProperty(name="Scene", items=[(i, l, d) for i, l, d in DEMO_SCENES],
                                  default="cornell")
    resolution: bpy.props.IntProperty(name="Resolution", default=256, min=4, max=8192,
                                      description="Square render resolution of the new scene")

    def execute(self, context):
        sc = build_demo(self.scene, resolution=self.resolution)
        window = getattr(context, "window", None)
        if window is not None:
            window.scene = sc
        self.report({"INFO"}, f"Added scene '{sc.name}'")
        return {"FINISHED"}


class GIPREVIEW_MT_add_demo_scene(bpy.types.Menu):
    """GI Preview's built-in demo scenes"""

    bl_idname = "GIPREVIEW_MT_add_demo_scene"
    bl_label = "GI Preview Demo Scene"

    def draw(self, context):
        for ident, label, _desc in DEMO_SCENES:
            self.layout.operator(GIPREVIEW_OT_add_demo_scene.bl_idname, text=label).scene = ident


def menu_func(self, context):
    """Append to ``VIEW3D_MT_add``: the "GI Preview Demo Scene" submenu."""
    self.layout.menu(GIPREVIEW_MT_add_demo_scene.bl_idname, icon="SCENE_DATA")


classes = (GIPREVIEW_OT_add_demo_scene, GIPREVIEW_MT_add_demo_scene)
