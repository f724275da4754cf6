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
