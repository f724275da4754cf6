"""Scenes built the way artists' assets arrive: texture-set materials through glTF.

``gltf_texture_set(folder, resolution)`` makes images in numpy and saves them as PNG in
``folder``, builds Principled materials from them as an artist would (base colour image;
metallic-roughness image through Separate Color, G -> Roughness, B -> Metallic; a
tangent-space normal map through Normal Map; an emissive image on Emission Color with
strength 1; a leaf whose alpha is clipped), exports the objects with
``bpy.ops.export_scene.gltf`` to a .glb, removes everything and imports the .glb back, so
the materials rendered are the glTF importer's own node setups. A camera, an area light, a
sun and a uniform grey world are added after the import. Returns the new scene.

Objects (metres, Z up): a 4 x 4 m ground tiled with the texture set ("Tiles": base-colour
checker, roughness 0.15 -> 0.85 along u, metallic stripes along v, an egg-crate normal map
whose upper half in v also tilts towards +v, so a flipped green channel shows),
an upright emissive panel ("Screen": a colour gradient with a dark frame) at the back, and an
upright leaf ("Leaf": an ellipse with two round holes, alpha-clipped) in front, which casts a
shadow with holes on the ground.
"""
from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np

N = 64  # image size (every image of the set has the same size, as a texture set does)


def _grid(n=N):
    # texel centres; row 0 = v near 0 (Blender's image order)
    v, u = np.mgrid[0:n, 0:n]
    return (u + 0.5) / n, (v + 0.5) / n


def images() -> dict[str, tuple[np.ndarray, bool]]:
    """name -> (RGBA float image in [0, 1], non-colour?) of the texture set."""
    u, v = _grid()
    out = {}
    bc = np.ones((N, N, 4))
    check = ((np.floor(u * 4) + np.floor(v * 4)) % 2).astype(float)
    bc[..., 0] = 0.75 * check + 0.2 * (1 - check)
    bc[..., 1] = 0.55 * check + 0.35 * (1 - check)
    bc[..., 2] = 0.3 * check + 0.6 * (1 - check)
    out["tiles_base"] = (bc, False)
    mr = np.ones((N, N, 4))
    mr[..., 0] = 1.0  # occlusion (unused)
    mr[..., 1] = 0.15 + 0.7 * u  # roughness
    mr[..., 2] = (np.floor(v * 4) % 2 == 1).astype(float)  # metallic stripes
    out["tiles_mr"] = (mr, True)
    # tangent-space normal of the egg-crate height h = a sin(2 pi k u) sin(2 pi k v):
    # n ~ (-dh/du, -dh/dv, 1) (green = +v, Blender's and glTF's convention)
    k, s = 3, 0.8  # s = a 2 pi k, the largest slope
    du = s * np.cos(2 * math.pi * k * u) * np.sin(2 * math.pi * k * v)
    dv = s * np.sin(2 * math.pi * k * u) * np.cos(2 * math.pi * k * v) + 0.4 * (v > 0.5)
    n = np.stack([-du, -dv, np.ones_like(du)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    nm = np.ones((N, N, 4))
    nm[..., :3] = 0.5 * n + 0.5
    out["tiles_normal"] = (nm, True)
    em = np.ones((N, N, 4))
    frame = ((u > 0.08) & (u < 0.92) & (v > 0.1) & (v < 0.9)).astype(float)
    em[..., 0] = frame * (0.2 + 0.8 * u)
    em[..., 1] = frame * 0.5 * v
    em[..., 2] = frame * (1.0 - u)
    out["screen_emit"] = (em, False)
    lf = np.ones((N, N, 4))
    lf[..., 0], lf[..., 1], lf[..., 2] = 0.15 + 0.2 * v, 0.55, 0.1
    inside = ((u - 0.5) ** 2 / 0.2 + (v - 0.5) ** 2 / 0.22) < 1.0
    holes = (((u - 0.4) ** 2 + (v - 0.62) ** 2) < 0.012) | (((u - 0.62) ** 2 + (v - 0.35) ** 2) < 0.01)
    lf[..., 3] = (inside & ~holes).astype(float)
    out["leaf"] = (lf, False)
    return out


def _save(name: str, px: np.ndarray, non_color: bool, folder: Path):
    h, w = px.shape[:2]
    im = bpy.data.images.new(name, w, h, alpha=True)
    if non_color:
        im.colorspace_settings.name = "Non-Color"
    im.pixels.foreach_set(np.ascontiguousarray(px, np.float32).ravel())
    im.filepath_raw = str(folder / f"{name}.png")
    im.file_format = "PNG"
    im.save()
    return im


def _quad(sc, name, corners, uvs, mat):
    me = bpy.data.meshes.new(name)
    me.from_pydata(corners, [], [(0, 1, 2, 3)])
    layer = me.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", np.asarray(uvs, np.float32).ravel())
    me.materials.append(mat)
    me.update()
    ob = bpy.data.objects.new(name, me)
    sc.collection.objects.link(ob)
    return ob


def _material(name):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    return mat, nt, bsdf


def _tex(nt, im):
    t = nt.nodes.new("ShaderNodeTexImage")
    t.image = im
    return t


def _author(sc, folder: Path):
    ims = {k: _save(k, px, nc, folder) for k, (px, nc) in images().items()}
    tiles, nt, b = _material("Tiles")
    nt.links.new(_tex(nt, ims["tiles_base"]).outputs["Color"], b.inputs["Base Color"])
    sep = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(_tex(nt, ims["tiles_mr"]).outputs["Color"], sep.inputs["Color"])
    nt.links.new(sep.outputs["Green"], b.inputs["Roughness"])
    nt.links.new(sep.outputs["Blue"], b.inputs["Metallic"])
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nt.links.new(_tex(nt, ims["tiles_normal"]).outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], b.inputs["Normal"])
    screen, nt, b = _material("Screen")
    b.inputs["Base Color"].default_value = (0.05, 0.05, 0.05, 1)
    b.inputs["Roughness"].default_value = 0.6
    nt.links.new(_tex(nt, ims["screen_emit"]).outputs["Color"], b.inputs["Emission Color"])
    b.inputs["Emission Strength"].default_value = 1.0
    leaf, nt, b = _material("Leaf")
    b.inputs["Roughness"].default_value = 0.7
    t = _tex(nt, ims["leaf"])
    nt.links.new(t.outputs["Color"], b.inputs["Base Color"])
    clip = nt.nodes.new("ShaderNodeMath")
    clip.operation = "ROUND"  # read by the glTF exporter as alphaMode MASK, cutoff 0.5
    nt.links.new(t.outputs["Alpha"], clip.inputs[0])
    nt.links.new(clip.outputs[0], b.inputs["Alpha"])
    _quad(sc, "Ground", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 0), (2, 0), (2, 2), (0, 2)], tiles)
    _quad(sc, "Screen", [(-1.2, 1.3, 0.2), (1.2, 1.3, 0.2), (1.2, 1.3, 1.5), (-1.2, 1.3, 1.5)],
          [(0, 0), (1, 0), (1, 1), (0, 1)], screen)
    _quad(sc, "Leaf", [(-0.5, -0.2, 0.05), (0.5, -0.2, 0.05), (0.5, 0.1, 1.15), (-0.5, 0.1, 1.15)],
          [(0, 0), (1, 0), (1, 1), (0, 1)], leaf)


def gltf_texture_set(folder, resolution: int = 64, name: str = "gltf_texture_set"):
    """The scene described in the module docstring; ``folder`` receives the PNGs and the .glb."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    glb = folder / f"{name}.glb"
    author = bpy.data.scenes.new(f"{name}_author")
    win = bpy.context.window
    old_scene = win.scene if win is not None else None
    try:
        if win is not None:
            win.scene = author
        _author(author, folder)
        with bpy.context.temp_override(scene=author, view_layer=author.view_layers[0]):
            bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB", use_active_scene=True)
        # clear what was authored: objects, meshes, materials, images
        made = [o for o in author.objects]
        data = [o.data for o in made]
        mats = {m for d in data for m in d.materials if m is not None}
        imgs = {n.image for m in mats for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeTexImage"}
        bpy.data.batch_remove(made + data + list(mats) + list(imgs))
        bpy.data.scenes.remove(author)
        sc = bpy.data.scenes.new(name)
        if win is not None:
            win.scene = sc
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0],
                                       collection=sc.collection):
            bpy.ops.import_scene.gltf(filepath=str(glb))
    finally:
        if win is not None and old_scene is not None and old_scene.name in bpy.data.scenes:
            win.scene = old_scene
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    cam = bpy.data.cameras.new(f"{name}.cam")
    cam.lens = 32
    cob = bpy.data.objects.new(f"{name}.cam", cam)
    cob.location = (0.0, -3.6, 2.2)
    look = np.array([0.0, 0.3, 0.45]) - np.array(cob.location)
    cob.rotation_euler = (math.atan2(math.hypot(look[0], look[1]), -look[2]), 0.0,
                          math.atan2(look[0], look[1]) * -1.0)
    sc.collection.objects.link(cob)
    sc.camera = cob
    area = bpy.data.lights.new(f"{name}.key", "AREA")
    area.size = 1.0
    area.energy = 250.0
    aob = bpy.data.objects.new(f"{name}.key", area)
    aob.location = (0.8, -1.6, 2.6)
    aob.rotation_euler = (math.radians(35), 0.0, math.radians(25))
    sc.collection.objects.link(aob)
    sun = bpy.data.lights.new(f"{name}.sun", "SUN")
    sun.energy = 2.0
    sun.angle = math.radians(3)
    sob = bpy.data.objects.new(f"{name}.sun", sun)
    sob.rotation_euler = (math.radians(30), 0.0, math.radians(-20))
    sc.collection.objects.link(sob)
    world = bpy.data.worlds.new(f"{name}.world")
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    sc.world = world
    return sc


# ------------------------------------------------------------------ BSDFs beyond the Principled
def _shader_material(name, build):
    """A material whose node tree ``build(nodes, links) -> output socket`` makes."""
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(build(nt.nodes, nt.links), out.inputs["Surface"])
    return mat


def _bsdf(nodes, kind, **inputs):
    n = nodes.new(kind)
    for k, v in inputs.items():
        if k == "distribution":
            n.distribution = v
            continue
        n.inputs[k].default_value = (*v, 1.0) if isinstance(v, tuple) and len(v) == 3 else v
    return n


def bsdf_room(folder, resolution: int = 48, name: str = "bsdf_room"):
    """A small room (open behind the camera, a uniform grey world beyond) lit by an area
    light near the ceiling, holding the everyday BSDFs: a smooth glass sphere (Principled,
    Transmission Weight 1, IOR 1.45) and a rough one (Glass BSDF, roughness 0.3) in front of a
    checkered floor, a Mix Shader sphere (Diffuse + Glossy, factor 0.4), a sphere mixing
    Diffuse and a metal Principled by a striped texture, an Add Shader box (Diffuse + Glossy),
    a leaf card cut out by a Transparent BSDF mixed in by the leaf's alpha, and a
    Translucent panel lit from behind. Images are saved as PNG in ``folder``."""
    from gi_preview.blender import demo_scenes as D

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sc = bpy.data.scenes.new(name)
    b = D._Builder(sc, name)
    n = 64
    u, v = _grid(n)
    check = np.ones((n, n, 4))
    c = ((np.floor(u * 8) + np.floor(v * 8)) % 2)[..., None]
    check[..., :3] = c * np.array([0.75, 0.72, 0.65]) + (1 - c) * np.array([0.12, 0.14, 0.2])
    stripes = np.ones((n, n, 4))
    stripes[..., :3] = (np.floor(u * 6) % 2 == 1)[..., None].astype(float)
    ims = {k: _save(f"{name}_{k}", px, nc, folder) for k, (px, nc) in
           {"check": (check, False), "stripes": (stripes, True), "leaf": (images()["leaf"][0], False)}.items()}

    floor_m = _shader_material(b.n("floor"), lambda N, L: _floor(N, L, ims["check"]))
    white = D.make_principled(b.n("white"), (0.7, 0.7, 0.7), 0.8)
    red = D.make_principled(b.n("red"), (0.6, 0.12, 0.08), 1.0, specular=0.0)
    floor = b.room("room", (-2, -2.8, 0), (2, 2, 2.5), {"floor": floor_m, "ceiling": white, "+y": white,
                                                         "-x": red, "+x": white}, skip=("-y",))["floor"]
    me = floor.data  # floor UVs over [0, 1] (the builder's planar UVs are in metres)
    uv = np.empty(2 * len(me.loops), np.float32)
    me.uv_layers[0].data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    uv = (uv - [-2.0, -2.8]) / [4.0, 4.8]
    me.uv_layers[0].data.foreach_set("uv", uv.ravel())

    def principled_glass(N, L):
        p = _bsdf(N, "ShaderNodeBsdfPrincipled", **{"Base Color": (1.0, 1.0, 1.0), "Roughness": 0.0,
                                                     "IOR": 1.45, "Transmission Weight": 1.0})
        return p.outputs[0]

    glass_s = _shader_material(b.n("glass_smooth"), principled_glass)
    glass_r = _shader_material(b.n("glass_rough"), lambda N, L: _bsdf(
        N, "ShaderNodeBsdfGlass", Color=(0.9, 0.95, 1.0), Roughness=0.3, IOR=1.5).outputs[0])

    def mix_const(N, L):
        m = N.new("ShaderNodeMixShader")
        m.inputs[0].default_value = 0.4
        L.new(_bsdf(N, "ShaderNodeBsdfDiffuse", Color=(0.75, 0.25, 0.1)).outputs[0], m.inputs[1])
        L.new(_bsdf(N, "ShaderNodeBsdfGlossy", Color=(0.9, 0.9, 0.9), Roughness=0.2).outputs[0], m.inputs[2])
        return m.outputs[0]

    def mix_tex(N, L):
        m = N.new("ShaderNodeMixShader")
        t = N.new("ShaderNodeTexImage")
        t.image = ims["stripes"]
        L.new(t.outputs["Color"], m.inputs[0])
        L.new(_bsdf(N, "ShaderNodeBsdfDiffuse", Color=(0.15, 0.3, 0.7)).outputs[0], m.inputs[1])
        L.new(_bsdf(N, "ShaderNodeBsdfPrincipled", **{"Base Color": (0.95, 0.75, 0.35), "Metallic": 1.0,
                                                       "Roughness": 0.3}).outputs[0], m.inputs[2])
        return m.outputs[0]

    def add(N, L):
        a = N.new("ShaderNodeAddShader")
        L.new(_bsdf(N, "ShaderNodeBsdfDiffuse", Color=(0.2, 0.45, 0.15)).outputs[0], a.inputs[0])
        L.new(_bsdf(N, "ShaderNodeBsdfGlossy", Color=(0.3, 0.3, 0.3), Roughness=0.3).outputs[0], a.inputs[1])
        return a.outputs[0]

    def leaf(N, L):
        m = N.new("ShaderNodeMixShader")
        t = N.new("ShaderNodeTexImage")
        t.image = ims["leaf"]
        L.new(t.outputs["Alpha"], m.inputs[0])
        L.new(_bsdf(N, "ShaderNodeBsdfTransparent", Color=(1.0, 1.0, 1.0)).outputs[0], m.inputs[1])
        d = _bsdf(N, "ShaderNodeBsdfDiffuse")
        L.new(t.outputs["Color"], d.inputs["Color"])
        L.new(d.outputs[0], m.inputs[2])
        return m.outputs[0]

    translucent = _shader_material(b.n("translucent"), lambda N, L: _bsdf(
        N, "ShaderNodeBsdfTranslucent", Color=(0.9, 0.75, 0.5)).outputs[0])
    b.sphere("glass_smooth", 0.42, glass_s, location=(-0.75, 0.1, 0.42), segments=48, rings=24)
    b.sphere("glass_rough", 0.38, glass_r, location=(0.3, 0.55, 0.38), segments=48, rings=24)
    b.sphere("mix", 0.33, _shader_material(b.n("mix"), mix_const), location=(1.15, 0.0, 0.33))
    b.sphere("mix_tex", 0.25, _shader_material(b.n("mix_tex"), mix_tex), location=(0.35, -0.55, 0.25))
    b.box("add", (0.4, 0.4, 0.4), _shader_material(b.n("add"), add), location=(-0.2, -0.75, 0.2),
          rotation=(0, 0, 0.5))
    card = b.quad("leaf", [(-0.5, 0, 0), (0.5, 0, 0), (0.5, 0, 1.1), (-0.5, 0, 1.1)],
                  _shader_material(b.n("leaf"), leaf), location=(-1.35, 1.2, 0.05), rotation=(0, 0, 0.3))
    me = card.data
    me.uv_layers[0].data.foreach_set("uv", np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32).ravel())
    b.quad("panel", [(-0.45, 0, 0), (0.45, 0, 0), (0.45, 0, 1.2), (-0.45, 0, 1.2)], translucent,
           location=(1.3, 1.2, 0.0), rotation=(0, 0, -0.4))
    b.light("key", "AREA", (0.6, 1.6, 2.3), rotation=(math.radians(25), 0, math.radians(180)),
            energy=120.0, size=1.0)
    b.camera((0.0, -2.75, 1.2), (0.05, 0.3, 0.45), lens=24)
    sc.world = D.make_world(b.n("world"), (0.25, 0.25, 0.25), 1.0)
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    return sc


def _floor(nodes, links, image):
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Roughness"].default_value = 0.5
    t = nodes.new("ShaderNodeTexImage")
    t.image = image
    links.new(t.outputs["Color"], p.inputs["Base Color"])
    return p.outputs[0]


# ------------------------------------------------------------------ everyday Principled setups
def _uv_quad(b, name, corners, mat):
    ob = b.quad(name, corners, mat)
    ob.data.uv_layers[0].data.foreach_set("uv", np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32).ravel())
    return ob


def bump_floor(folder, resolution: int = 40, name: str = "bump_floor"):
    """Two 2 x 2 m floor tiles under a grazing sun (15 degrees above the horizon) and a dim
    grey world, seen from above at 45 degrees (the tiles fill the frame). Left ("bump_image"): a Bump node on a
    Non-Color egg-crate height image (6 x 6 bumps over the tile), Distance 0.05. Right
    ("bump_graph"): a Bump node (Strength 0.8, Distance 0.02, Invert) on a value graph over
    UV (sin(40 * (u + 0.5 v)) through Vector Math Dot and Math), its Normal fed by a
    tangent-space Normal Map of a constant tilt. Both Principled, grey, roughness 0.4."""
    from gi_preview.blender import demo_scenes as D

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sc = bpy.data.scenes.new(name)
    b = D._Builder(sc, name)
    n = 64
    u, v = _grid(n)
    h = np.ones((n, n, 4))
    h[..., :3] = (0.5 + 0.5 * np.sin(2 * np.pi * 6 * u) * np.sin(2 * np.pi * 6 * v))[..., None]
    im = _save(f"{name}_height", h, True, folder)

    def image_bump(N, L):
        p = _bsdf(N, "ShaderNodeBsdfPrincipled", **{"Base Color": (0.7, 0.7, 0.7), "Roughness": 0.4})
        t = N.new("ShaderNodeTexImage")
        t.image = im
        bump = N.new("ShaderNodeBump")
        bump.inputs["Distance"].default_value = 0.05
        L.new(t.outputs["Color"], bump.inputs["Height"])
        L.new(bump.outputs["Normal"], p.inputs["Normal"])
        return p.outputs[0]

    def graph_bump(N, L):
        p = _bsdf(N, "ShaderNodeBsdfPrincipled", **{"Base Color": (0.6, 0.65, 0.7), "Roughness": 0.4})
        tc = N.new("ShaderNodeTexCoord")
        dot = N.new("ShaderNodeVectorMath")
        dot.operation = "DOT_PRODUCT"
        dot.inputs[1].default_value = (1.0, 0.5, 0.0)
        L.new(tc.outputs["UV"], dot.inputs[0])
        mul = N.new("ShaderNodeMath")
        mul.operation = "MULTIPLY"
        mul.inputs[1].default_value = 40.0
        L.new(dot.outputs["Value"], mul.inputs[0])
        sin = N.new("ShaderNodeMath")
        sin.operation = "SINE"
        L.new(mul.outputs[0], sin.inputs[0])
        nm = N.new("ShaderNodeNormalMap")
        nm.inputs["Color"].default_value = (0.62, 0.5, 0.92, 1.0)
        bump = N.new("ShaderNodeBump")
        bump.invert = True
        bump.inputs["Strength"].default_value = 0.8
        bump.inputs["Distance"].default_value = 0.02
        L.new(sin.outputs[0], bump.inputs["Height"])
        L.new(nm.outputs["Normal"], bump.inputs["Normal"])
        L.new(bump.outputs["Normal"], p.inputs["Normal"])
        return p.outputs[0]

    _uv_quad(b, "tile_image", [(-2, -1, 0), (0, -1, 0), (0, 1, 0), (-2, 1, 0)],
             _shader_material(b.n("bump_image"), image_bump))
    _uv_quad(b, "tile_graph", [(0, -1, 0), (2, -1, 0), (2, 1, 0), (0, 1, 0)],
             _shader_material(b.n("bump_graph"), graph_bump))
    b.light("sun", "SUN", (0, 0, 3), rotation=(math.radians(75), 0, math.radians(30)), energy=4.0,
            angle=math.radians(2))
    b.camera((0.0, -2.1, 2.1), (0.0, 0.05, 0.0), lens=24)
    sc.world = D.make_world(b.n("world"), (0.05, 0.05, 0.05), 1.0)
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    return sc


def color_attribute_scene(folder=None, resolution: int = 40, name: str = "color_attr"):
    """Vertex colours on Base Color: a 2 x 2 m floor grid (8 x 8 quads) whose point-domain float
    colour attribute "Col" (a hue sweep over x, darker towards +y) is read by a Color
    Attribute node naming it, and a cube whose corner-domain byte colour attribute "Paint"
    (one colour per face) is read by an Attribute node; both Principled, roughness 0.5, under a
    sun and a grey world."""
    from gi_preview.blender import demo_scenes as D

    sc = bpy.data.scenes.new(name)
    b = D._Builder(sc, name)

    def principled_from(node_kind, attr):
        def build(N, L):
            p = _bsdf(N, "ShaderNodeBsdfPrincipled", Roughness=0.5)
            a = N.new(node_kind)
            if node_kind == "ShaderNodeVertexColor":
                a.layer_name = attr
            else:
                a.attribute_name = attr
            L.new(a.outputs["Color"], p.inputs["Base Color"])
            return p.outputs[0]
        return build

    n = 8
    xs = np.linspace(-1, 1, n + 1)
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    floor = b.mesh("floor", verts, faces, _shader_material(b.n("floor_mat"),
                                                         principled_from("ShaderNodeVertexColor", "Col")))
    ca = floor.data.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
    P = np.array(verts)
    t = (P[:, 0] + 1) / 2
    col = np.stack([0.9 * (1 - t) + 0.05, 0.8 * np.sin(np.pi * t) + 0.05, 0.9 * t + 0.05, np.ones_like(t)], 1)
    col[:, :3] *= (1.0 - 0.6 * (P[:, 1] + 1) / 2)[:, None]
    ca.data.foreach_set("color", col.astype(np.float32).ravel())
    cube = b.box("cube", (0.7, 0.7, 0.7), _shader_material(b.n("cube_mat"),
                                                          principled_from("ShaderNodeAttribute", "Paint")),
                 location=(0.2, 0.2, 0.35), rotation=(0, 0, 0.4))
    pa = cube.data.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    face_cols = [(0.9, 0.2, 0.1), (0.1, 0.7, 0.2), (0.1, 0.3, 0.9), (0.9, 0.8, 0.1), (0.8, 0.1, 0.8), (0.1, 0.8, 0.8)]
    cc = np.array([(*face_cols[k // 4], 1.0) for k in range(24)], np.float32)
    pa.data.foreach_set("color", cc.ravel())
    b.light("sun", "SUN", (0, 0, 3), rotation=(math.radians(35), 0, math.radians(-30)), energy=3.0,
            angle=math.radians(3))
    b.camera((0.0, -2.3, 2.2), (0.0, 0.1, 0.1), lens=30)
    sc.world = D.make_world(b.n("world"), (0.3, 0.3, 0.3), 1.0)
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    return sc


def principled_layers_scene(folder=None, resolution: int = 40, name: str = "principled_layers",
                            layer: str = "coat"):
    """Three spheres on a grey floor under a sun, a small area light and a grey world, each a
    Principled BSDF with a layer on top as artists set it: ``layer="coat"``: a red plastic
    with a clear coat (Weight 1, Roughness 0.05, IOR 1.5), a gold metal with a rough blue-tinted
    coat (Weight 0.8, Roughness 0.3, IOR 1.6, Tint (0.5, 0.7, 1)) and a white diffuse with a
    half coat (Weight 0.5, Roughness 0.1); ``layer="sheen"``: a dark blue cloth (Sheen Weight
    1, Roughness 0.5, white tint), a red cloth (Sheen 1, Roughness 0.2, pink tint) and a
    grey one (Sheen 0.6, Roughness 0.9)."""
    from gi_preview.blender import demo_scenes as D

    sc = bpy.data.scenes.new(name)
    b = D._Builder(sc, name)
    if layer == "coat":
        specs = [({"Base Color": (0.6, 0.05, 0.03), "Roughness": 0.5, "Coat Weight": 1.0, "Coat Roughness": 0.05,
                   "Coat IOR": 1.5}),
                 ({"Base Color": (0.9, 0.7, 0.3), "Metallic": 1.0, "Roughness": 0.25, "Coat Weight": 0.8,
                   "Coat Roughness": 0.3, "Coat IOR": 1.6, "Coat Tint": (0.5, 0.7, 1.0)}),
                 ({"Base Color": (0.8, 0.8, 0.8), "Roughness": 0.9, "Coat Weight": 0.5, "Coat Roughness": 0.1})]
    else:
        specs = [({"Base Color": (0.03, 0.05, 0.2), "Roughness": 0.8, "Sheen Weight": 1.0, "Sheen Roughness": 0.5}),
                 ({"Base Color": (0.4, 0.02, 0.03), "Roughness": 0.7, "Sheen Weight": 1.0, "Sheen Roughness": 0.2,
                   "Sheen Tint": (1.0, 0.6, 0.7)}),
                 ({"Base Color": (0.3, 0.3, 0.3), "Roughness": 0.9, "Sheen Weight": 0.6, "Sheen Roughness": 0.9})]
    for k, spec in enumerate(specs):
        mat = _shader_material(b.n(f"{layer}{k}"), lambda N, L, spec=spec: _bsdf(
            N, "ShaderNodeBsdfPrincipled", **spec).outputs[0])
        b.sphere(f"ball{k}", 0.42, mat, location=(-1.0 + 1.0 * k, 0.0, 0.42), segments=48, rings=24)
    floor = D.make_principled(b.n("floor"), (0.5, 0.5, 0.5), 0.6)
    b.quad("floor", [(-3, -2, 0), (3, -2, 0), (3, 3, 0), (-3, 3, 0)], floor)
    b.light("sun", "SUN", (0, 0, 3), rotation=(math.radians(50), 0, math.radians(-35)), energy=2.5,
            angle=math.radians(4))
    b.light("key", "AREA", (1.2, -1.5, 2.0), rotation=(math.radians(40), 0, math.radians(35)), energy=60.0,
            size=0.6)
    b.camera((0.0, -2.6, 0.9), (0.0, 0.0, 0.42), lens=38)
    sc.world = D.make_world(b.n("world"), (0.35, 0.35, 0.35), 1.0)
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    return sc
