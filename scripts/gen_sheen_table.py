"""Measure the directional albedo of Cycles' Principled sheen and write addon/render/sheen_table.py.

Cycles' sheen is the microfiber model of Zeltner et al. 2022 (an LTC fit); GI Preview shades a
Charlie sheen lobe (lib/brdf.glsl sheen_eval) scaled to Cycles' albedo. The albedo
``SHEEN_ALBEDO[rough*32 + mu]`` (rough, mu = i/31) is measured here by rendering with Cycles a
unit sphere seen by an orthographic camera under a uniform white world, black base colour,
no specular, Sheen Weight 1 and white tint: the pixel at normalised radius rho is the albedo at
mu = sqrt(1 - rho^2). Run with the bpy module: ``.venv/bin/python scripts/gen_sheen_table.py``
(about a minute).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np

RES = 160
SPP = 64
ROUGH = [i / 15 for i in range(16)]


def render(rough: float) -> np.ndarray:
    sc = bpy.data.scenes.new(f"sheen_{rough:.3f}")
    sc.render.engine = "CYCLES"
    sc.cycles.samples = SPP
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 4
    sc.render.resolution_x = sc.render.resolution_y = RES
    sc.render.filter_size = 0.01
    sc.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("w")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 1.0
    sc.world = world
    mat = bpy.data.materials.new("m")
    mat.use_nodes = True
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0, 0, 0, 1)
    p.inputs["Specular IOR Level"].default_value = 0.0
    p.inputs["Sheen Weight"].default_value = 1.0
    p.inputs["Sheen Roughness"].default_value = rough
    p.inputs["Sheen Tint"].default_value = (1, 1, 1, 1)
    me = bpy.data.meshes.new("s")
    import bmesh
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=256, v_segments=128, radius=1.0)
    bm.to_mesh(me)
    bm.free()
    me.shade_smooth()
    me.materials.append(mat)
    ob = bpy.data.objects.new("s", me)
    sc.collection.objects.link(ob)
    cd = bpy.data.cameras.new("c")
    cd.type = "ORTHO"
    cd.ortho_scale = 2.0
    cam = bpy.data.objects.new("c", cd)
    cam.location = (0, -5, 0)
    cam.rotation_euler = (np.pi / 2, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    out = Path(tempfile.mkdtemp()) / "a.exr"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.filepath = str(out)
    bpy.ops.render.render(write_still=True, scene=sc.name)
    im = bpy.data.images.load(str(out))
    px = np.array(im.pixels[:], np.float32).reshape(RES, RES, -1)[..., 0]
    return px


def albedo_curve(px: np.ndarray) -> np.ndarray:
    c = (np.arange(RES) + 0.5) / RES * 2 - 1
    X, Y = np.meshgrid(c, c)
    rho2 = X * X + Y * Y
    inside = rho2 < 0.97  # away from the silhouette's pixel blend
    mu = np.sqrt(np.clip(1 - rho2[inside], 0, 1))
    val = px[inside]
    out = np.zeros(32)
    for j in range(32):
        m = j / 31
        sel = np.abs(mu - m) < 0.5 / 31
        if sel.sum() < 8:  # grazing: extrapolate from the nearest bins below
            out[j] = np.nan
        else:
            out[j] = float(val[sel].mean())
    good = ~np.isnan(out)
    out[~good] = np.interp(np.flatnonzero(~good), np.flatnonzero(good), out[good])
    return out


def main():
    curves = np.array([albedo_curve(render(r)) for r in ROUGH])  # [16 rough][32 mu]
    rr = np.arange(32) / 31
    table = np.array([[np.interp(r, ROUGH, curves[:, j]) for j in range(32)] for r in rr])
    items = [f"{v:.5f}" for v in table.ravel()]
    lines = [", ".join(items[i:i + 16]) for i in range(0, len(items), 16)]
    text = ('"""Directional albedo of Cycles\' Principled sheen, MEASURED by scripts/gen_sheen_table.py\n'
            "(do not edit): SHEEN_ALBEDO[rough*32 + mu], rough and mu = i/31.\n"
            '"""\n\nSHEEN_ALBEDO = (\n    ' + ",\n    ".join(lines) + ",\n)\n")
    path = Path(__file__).resolve().parent.parent / "addon" / "render" / "sheen_table.py"
    path.write_text(text)
    print(f"wrote {path}; albedo at mu=1: {table[::8, 31]}, mu=0.3: {table[::8, 9]}")


if __name__ == "__main__":
    main()
