"""Tests of addon/blender/export.py (bpy -> SceneData) and addon/blender/demo_scenes.py.

Every test builds its scene in code in a fresh scene and removes everything it created.
Light units are checked twice: against the formulas, and against tiny Cycles renders
(16x16 px, 64 spp, no bounces, box filter) of a Lambertian plane.
"""
import math
import os
import sys
import tempfile

if not any(os.path.isdir(os.path.join(p, "gi_preview")) for p in sys.path if p):
    # conftest.py normally does this; keep the file runnable on its own.
    _d = tempfile.mkdtemp(prefix="gi_preview_export_")
    os.symlink(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "addon"),
               os.path.join(_d, "gi_preview"))
    sys.path.insert(0, _d)

import bpy  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from bpy_extras.object_utils import world_to_camera_view  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

from gi_preview.blender import demo_scenes  # noqa: E402
from gi_preview.blender.demo_scenes import make_principled  # noqa: E402
from gi_preview.blender.export import DEFAULT_MATERIAL_NAME, export_scene  # noqa: E402
from gi_preview.render.scene_data import AreaShape, LightType, SceneError  # noqa: E402

_ID_COLLECTIONS = ("objects", "meshes", "materials", "lights", "cameras", "worlds", "images",
                   "collections", "curves", "node_groups", "scenes", "textures", "metaballs")


def _all_ids():
    # Blender keeps pointers to its own "Render Result" / "Viewer Node" images: removing them
    # leaves the render pipeline with a dangling image (a later render segfaults)
    return {(c, id_.as_pointer()): id_ for c in _ID_COLLECTIONS for id_ in getattr(bpy.data, c)
            if not (c == "images" and id_.name in ("Render Result", "Viewer Node"))}


@pytest.fixture
def scene():
    """A fresh scene with a camera at (0,-10,0) looking +Y; everything created is removed."""
    before = set(_all_ids())
    sc = bpy.data.scenes.new("export_test")
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 48, 100
    cd = bpy.data.cameras.new("cam")
    cam = bpy.data.objects.new("cam", cd)
    cam.location = (0, -10, 0)
    cam.rotation_euler = (math.pi / 2, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    yield sc
    new = [id_ for k, id_ in _all_ids().items() if k not in before]
    bpy.data.batch_remove(new)


def depsgraph(sc):
    with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
        dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    return dg


def export(sc, **kw):
    return export_scene(depsgraph(sc), **kw)


def add_mesh(sc, name, verts, faces, mats=(), location=(0, 0, 0), data=None):
    me = data
    if me is None:
        me = bpy.data.meshes.new(name)
        me.from_pydata(verts, [], faces)
        for m in mats:
            me.materials.append(m)
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    sc.collection.objects.link(ob)
    return ob


QUAD = ([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)])
CUBE = ([(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1),
         (-1, 1, 1)],
        [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)])


def instances_of(sd, object_name):
    return [i for i in sd.instances if i.object_name == object_name]


# ------------------------------------------------------------------ geometry
def test_instances_transforms_dedup_array_and_collection_instance(scene):
    a = add_mesh(scene, "a", *CUBE, location=(1, 2, 3))
    b = add_mesh(scene, "b", None, None, data=a.data, location=(-4, 0, 0))
    b.rotation_euler = (0, 0, math.pi / 2)
    b.scale = (2, 2, 2)
    arr = add_mesh(scene, "arr", None, None, data=a.data)
    arr.modifiers.new("Array", "ARRAY").count = 3
    col = bpy.data.collections.new("col")
    inner = bpy.data.objects.new("inner", a.data)
    inner.location = (0, 0, 1)
    col.objects.link(inner)
    empty = bpy.data.objects.new("empty", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = col
    empty.location = (10, 0, 0)
    scene.collection.objects.link(empty)
    hidden = add_mesh(scene, "hidden", None, None, data=a.data)
    hidden.hide_render = True

    sd = export(scene)
    assert not instances_of(sd, "hidden")
    (ia,), (ib,), (iarr,), (iin,) = (instances_of(sd, n) for n in ("a", "b", "arr", "inner"))
    # a, b and the collection instance share one mesh; the array has its own
    assert ia.mesh == ib.mesh == iin.mesh != iarr.mesh
    assert len(sd.meshes) == 2
    assert sd.meshes[ia.mesh].triangle_count == 12
    assert sd.meshes[iarr.mesh].triangle_count == 36
    assert sd.triangle_count == 12 * 3 + 36
    np.testing.assert_allclose(ia.matrix, np.array(a.matrix_world), atol=1e-6)
    np.testing.assert_allclose(ib.matrix, np.array(b.matrix_world), atol=1e-6)
    np.testing.assert_allclose(iin.matrix[:3, 3], (10, 0, 1), atol=1e-6)
    lo, hi = sd.meshes[iarr.mesh].bounds()  # array offset 1 x width 2 -> x in [-1, 5]
    np.testing.assert_allclose(lo, (-1, -1, -1), atol=1e-6)
    np.testing.assert_allclose(hi, (5, 1, 1), atol=1e-6)
    m = sd.meshes[ia.mesh]
    assert m.positions.shape == (36, 3) and m.positions.dtype == np.float32
    assert m.normals.shape == (36, 3) and m.uvs.shape == (36, 2)
    assert m.material_ids.dtype == np.int32
    assert sd.materials[m.material_ids[0]].name == DEFAULT_MATERIAL_NAME
    assert sd.materials[m.material_ids[0]].base_color == pytest.approx((0.8, 0.8, 0.8))
    assert sd.materials[m.material_ids[0]].roughness == pytest.approx(0.5)


def test_geometry_nodes_instances_stored_once(scene):
    ob = add_mesh(scene, "gn", *QUAD)
    tree = bpy.data.node_groups.new("gn_tree", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n = tree.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    line = n.new("GeometryNodeMeshLine")
    line.inputs["Count"].default_value = 5
    cube = n.new("GeometryNodeMeshCube")
    inst = n.new("GeometryNodeInstanceOnPoints")
    tree.links.new(line.outputs["Mesh"], inst.inputs["Points"])
    tree.links.new(cube.outputs["Mesh"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], gout.inputs[0])
    ob.modifiers.new("GN", "NODES").node_group = tree
    sd = export(scene)
    insts = instances_of(sd, "gn")
    assert len(insts) == 5
    assert len({i.mesh for i in insts}) == 1
    assert sd.meshes[insts[0].mesh].triangle_count == 12
    xs = sorted(round(float(i.matrix[2, 3]), 4) for i in insts)  # Mesh Line offsets along Z
    assert xs == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_instance_ids_unique_and_stable(scene):
    """Every instance has its own id (two collection instances of one object, geometry-nodes
    instances, linked duplicates), and the ids survive moving things and changing frames."""
    a = add_mesh(scene, "a", *CUBE)
    add_mesh(scene, "b", None, None, data=a.data, location=(3, 0, 0))
    col = bpy.data.collections.new("col")
    col.objects.link(bpy.data.objects.new("inner", a.data))
    empties = []
    for k in range(2):
        e = bpy.data.objects.new(f"empty{k}", None)
        e.instance_type = "COLLECTION"
        e.instance_collection = col
        e.location = (0, 5 * k, 0)
        scene.collection.objects.link(e)
        empties.append(e)
    gn = add_mesh(scene, "gn", *QUAD)
    tree = bpy.data.node_groups.new("gn_ids", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    line = tree.nodes.new("GeometryNodeMeshLine")
    line.inputs["Count"].default_value = 3
    inst = tree.nodes.new("GeometryNodeInstanceOnPoints")
    tree.links.new(line.outputs["Mesh"], inst.inputs["Points"])
    tree.links.new(tree.nodes.new("GeometryNodeMeshCube").outputs["Mesh"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], tree.nodes.new("NodeGroupOutput").inputs[0])
    gn.modifiers.new("GN", "NODES").node_group = tree
    sd = export(scene)
    ids = [i.instance_id for i in sd.instances]
    assert len(ids) == len(set(ids)) == 2 + 2 + 3, ids
    assert sd.instance_ids() == ids
    inner = sorted(i.instance_id for i in instances_of(sd, "inner"))
    assert inner[0].startswith("empty0/inner/") and inner[1].startswith("empty1/inner/")
    assert {i.instance_id for i in instances_of(sd, "a")} == {"a"}
    by_id = {i.instance_id: i.matrix.copy() for i in sd.instances}
    empties[1].location.x += 1
    a.location.z += 1
    scene.frame_set(scene.frame_current + 1)
    sd2 = export(scene)
    assert [i.instance_id for i in sd2.instances] == ids
    moved = {i.instance_id for i in sd2.instances if not np.allclose(i.matrix, by_id[i.instance_id])}
    assert moved == {"a", inner[1]}, moved
    # instances built without ids (SceneData made in code) get unique ones too
    for i in sd2.instances:
        i.instance_id = ""
    gen = sd2.instance_ids()
    assert len(set(gen)) == len(gen) and gen[0] == f"{sd2.instances[0].object_name}#0"


def test_scene_exporter_reads_only_changed_meshes(scene):
    """SceneExporter with fake depsgraph.updates: a transform update reuses every Mesh object;
    a geometry update of a mesh shared by two objects reads it once; a deleted object's
    mesh leaves the cache."""
    import types

    from gi_preview.blender.export import SceneExporter

    a = add_mesh(scene, "a", *CUBE)
    b = add_mesh(scene, "b", None, None, data=a.data, location=(3, 0, 0))
    c = add_mesh(scene, "c", *QUAD, location=(0, 3, 0))
    ex = SceneExporter()
    sd1 = ex.export(depsgraph(scene))
    assert ex.last_stats == {"meshes_read": 2, "meshes_reused": 0}

    def upd(idb, geometry=False, transform=False):
        return types.SimpleNamespace(id=idb, is_updated_geometry=geometry, is_updated_transform=transform,
                                     is_updated_shading=False)

    c.location.x += 1
    sd2 = ex.export(depsgraph(scene), [upd(c, transform=True)])
    assert ex.last_stats == {"meshes_read": 0, "meshes_reused": 2}
    assert {id(m) for m in sd2.meshes} == {id(m) for m in sd1.meshes}
    assert not np.allclose(instances_of(sd2, "c")[0].matrix, instances_of(sd1, "c")[0].matrix)
    a.data.vertices[0].co.z += 0.5
    a.data.update()
    sd3 = ex.export(depsgraph(scene), [upd(a, geometry=True), upd(a.data, geometry=True)])
    assert ex.last_stats == {"meshes_read": 1, "meshes_reused": 1}
    ia, ib = instances_of(sd3, "a")[0], instances_of(sd3, "b")[0]
    assert ia.mesh == ib.mesh and np.isclose(sd3.meshes[ia.mesh].positions[:, 2], -0.5).any()  # the edit
    bpy.data.objects.remove(c)
    ex.export(depsgraph(scene), [])
    assert len(ex._meshes) == 1


def test_curve_and_text_come_through_once(scene):
    tx = bpy.data.curves.new("txt", "FONT")
    tx.body = "Hi"
    t = bpy.data.objects.new("text", tx)
    scene.collection.objects.link(t)
    cu = bpy.data.curves.new("cu", "CURVE")
    cu.bevel_depth = 0.1
    sp = cu.splines.new("POLY")
    sp.points.add(1)
    sp.points[1].co = (1, 1, 1, 1)
    c = bpy.data.objects.new("curve", cu)
    scene.collection.objects.link(c)
    sd = export(scene)
    for name, ob in (("text", t), ("curve", c)):
        insts = instances_of(sd, name)
        assert len(insts) == 1, name
        ev = ob.evaluated_get(depsgraph(scene))
        me = ev.to_mesh()
        me.calc_loop_triangles()
        expected = len(me.loop_triangles)
        ev.to_mesh_clear()
        assert sd.meshes[insts[0].mesh].triangle_count == expected > 0


def test_flat_smooth_custom_normals_and_uvs(scene):
    flat = add_mesh(scene, "flat", *CUBE)
    smooth_me = bpy.data.meshes.new("sphere")
    import bmesh
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=1.0, calc_uvs=True)
    bm.to_mesh(smooth_me)
    bm.free()
    smooth_me.shade_smooth()
    add_mesh(scene, "smooth", None, None, data=smooth_me)
    custom = add_mesh(scene, "custom", *QUAD, location=(5, 0, 0))
    custom.data.normals_split_custom_set_from_vertices([(1, 0, 0)] * 4)
    uvq = add_mesh(scene, "uvq", *QUAD, location=(0, 5, 0))
    uv = uvq.data.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", [0, 0, 1, 0, 1, 1, 0, 1])
    sd = export(scene)

    def mesh(name):
        return sd.meshes[instances_of(sd, name)[0].mesh]

    m = mesh("flat")
    p = m.positions.reshape(-1, 3, 3)
    face_n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    np.testing.assert_allclose(m.normals.reshape(-1, 3, 3), np.repeat(face_n[:, None], 3, 1),
                               atol=1e-5)
    assert np.all(m.uvs == 0)  # no UV map -> zeros
    m = mesh("smooth")
    radial = m.positions / np.linalg.norm(m.positions, axis=1, keepdims=True)
    np.testing.assert_allclose(m.normals, radial, atol=0.03)  # angle-weighted vertex normals
    # smooth: all corners at one position share one normal (flat shading would not)
    key = np.round(m.positions, 4)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    first = np.zeros((inv.max() + 1, 3), np.float32)
    first[inv] = m.normals
    np.testing.assert_allclose(m.normals, first[inv], atol=1e-6)
    assert m.uvs.max() > 0.9 and m.uvs.min() >= 0
    m = mesh("custom")
    np.testing.assert_allclose(m.normals, np.tile([1, 0, 0], (6, 1)), atol=1e-3)  # compressed
    m = mesh("uvq")
    # the UV of each corner is (x+1)/2, (y+1)/2 of its position
    np.testing.assert_allclose(m.uvs, (m.positions[:, :2] + 1) / 2, atol=1e-6)


# ------------------------------------------------------------------ materials
def _noise_into_roughness(mat):
    tree = mat.node_tree
    bsdf = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    noise = tree.nodes.new("ShaderNodeTexNoise")
    noise.name = "My Noise"
    tree.links.new(noise.outputs["Fac"], bsdf.inputs["Roughness"])


def test_materials_principled_slots_texture_and_fallback(scene):
    red = make_principled("red", (0.9, 0.1, 0.05), roughness=0.25, metallic=0.3,
                          emission=(1, 0.5, 0.25), emission_strength=2.0, specular=0.7, ior=1.45)
    bsdf = red.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Alpha"].default_value = 0.75
    bsdf.inputs["Specular Tint"].default_value = (0.5, 0.6, 0.7, 1)
    # textured: 2x2 sRGB image into Base Color
    img = bpy.data.images.new("tex", 2, 2, alpha=True)
    img.colorspace_settings.name = "sRGB"
    img.pixels.foreach_set(np.array([0.5, 0.5, 0.5, 1] * 3 + [1, 0, 0, 1], np.float32))
    tex_mat = make_principled("textured")
    tn = tex_mat.node_tree.nodes.new("ShaderNodeTexImage")
    tn.image = img
    tex_mat.node_tree.links.new(tn.outputs["Color"],
                                tex_mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    noisy = make_principled("Noisy", (0.2, 0.3, 0.4))
    noisy.diffuse_color = (0.1, 0.2, 0.3, 1)
    _noise_into_roughness(noisy)
    emit = demo_scenes.make_emission("emit", (1, 0.5, 0.25), 3.0)
    # one mesh with two triangles of different slots, a second with the others
    ob = add_mesh(scene, "two", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)],
                  [(0, 1, 2, 3), (1, 4, 5, 2)], mats=(red, tex_mat))
    ob.data.polygons[1].material_index = 1
    add_mesh(scene, "noisy", *QUAD, mats=(noisy,))
    add_mesh(scene, "emit", *QUAD, mats=(emit,))
    add_mesh(scene, "plain", *QUAD)
    sd = export(scene)

    by_name = {m.name: m for m in sd.materials}
    assert len(by_name) == len(sd.materials)  # deduplicated
    m = by_name["red"]
    assert m.exact and not m.warnings and m.support == "exact"
    assert m.base_color == pytest.approx((0.9, 0.1, 0.05), abs=1e-6)
    assert (m.metallic, m.roughness, m.ior, m.specular_ior_level, m.alpha) == pytest.approx(
        (0.3, 0.25, 1.45, 0.7, 0.75), abs=1e-6)
    assert m.specular_tint == pytest.approx((0.5, 0.6, 0.7), abs=1e-6)
    np.testing.assert_allclose(m.emission, (2, 1, 0.5), atol=1e-6)
    two = sd.meshes[instances_of(sd, "two")[0].mesh]
    names = [sd.materials[i].name for i in two.material_ids]
    assert names == ["red", "red", "textured", "textured"]

    m = by_name["textured"]
    assert m.exact and m.base_color_texture >= 0
    px = sd.textures[m.base_color_texture].pixels
    assert px.shape == (2, 2, 4) and px.dtype == np.float32
    lin = ((0.5 + 0.055) / 1.055) ** 2.4  # sRGB 0.5 -> linear 0.214
    np.testing.assert_allclose(px[0, 0], (lin, lin, lin, 1), atol=3e-3)  # 8-bit quantisation
    np.testing.assert_allclose(px[1, 1], (1, 0, 0, 1), atol=1e-6)

    # a procedural texture on Roughness: that input alone falls back to its own value
    m = by_name["Noisy"]
    assert not m.exact and m.support.startswith("unsupported:") and "'My Noise'" in m.support
    assert m.base_color == pytest.approx((0.2, 0.3, 0.4), abs=1e-6)
    (w,) = m.warnings
    assert "Material 'Noisy'" in w and "'My Noise'" in w and "ShaderNodeTexNoise" in w
    assert "'Roughness'" in w and "input's own value" in w
    assert w in sd.warnings

    m = by_name["emit"]
    assert m.exact and m.base_color == (0, 0, 0) and m.is_emissive
    np.testing.assert_allclose(m.emission, (3, 1.5, 0.75), atol=1e-6)
    plain = sd.materials[sd.meshes[instances_of(sd, "plain")[0].mesh].material_ids[0]]
    assert plain.name == DEFAULT_MATERIAL_NAME


def test_diffuse_and_unsupported_surface(scene):
    diff = bpy.data.materials.new("diff")
    t = diff.node_tree
    t.nodes.clear()
    out = t.nodes.new("ShaderNodeOutputMaterial")
    d = t.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (0.2, 0.4, 0.6, 1)
    t.links.new(d.outputs[0], out.inputs["Surface"])
    toon = bpy.data.materials.new("toon")
    t = toon.node_tree
    t.nodes.clear()
    out = t.nodes.new("ShaderNodeOutputMaterial")
    tn = t.nodes.new("ShaderNodeBsdfToon")
    t.links.new(tn.outputs[0], out.inputs["Surface"])
    add_mesh(scene, "d", *QUAD, mats=(diff,))
    add_mesh(scene, "t", *QUAD, mats=(toon,))
    sd = export(scene)
    by_name = {m.name: m for m in sd.materials}
    m = by_name["diff"]
    assert m.exact and m.base_color == pytest.approx((0.2, 0.4, 0.6))
    assert m.roughness == 1.0 and m.specular_ior_level == 0.0 and m.metallic == 0.0
    m = by_name["toon"]
    assert not m.exact and "ShaderNodeBsdfToon" in m.warnings[0] and "'toon'" in m.warnings[0]


# ------------------------------------------------------------------ lights
def add_light(sc, kind, location=(0, 0, 2), **props):
    ld = bpy.data.lights.new(kind.lower(), kind)
    for k, v in props.items():
        setattr(ld, k, v)
    ob = bpy.data.objects.new(kind.lower(), ld)
    ob.location = location
    sc.collection.objects.link(ob)
    return ob


def test_light_units(scene):
    add_light(scene, "POINT", energy=100.0, color=(1, 0.5, 0.25), shadow_soft_size=0.2,
              use_shadow=False)
    add_light(scene, "SPOT", energy=50.0, spot_size=1.0, spot_blend=0.3, exposure=1.0)
    add_light(scene, "SUN", energy=3.0, angle=0.1)
    area = add_light(scene, "AREA", energy=100.0, shape="RECTANGLE", size=0.5, size_y=0.25,
                     spread=1.0)
    area.scale = (2, 3, 1)
    add_light(scene, "AREA", energy=80.0, shape="DISK", size=0.5, normalize=False)
    temp = add_light(scene, "POINT", energy=10.0, use_temperature=True, temperature=3000.0)
    sd = export(scene)
    by = {(l.name, l.type): l for l in sd.lights}
    assert len(sd.lights) == 6
    p = by[("point", LightType.POINT)]
    np.testing.assert_allclose(p.color, np.array([1, 0.5, 0.25]) * 100 / (4 * math.pi), rtol=1e-6)
    assert p.radius == pytest.approx(0.2) and not p.cast_shadow and p.power == 100.0
    np.testing.assert_allclose(p.position, (0, 0, 2))
    s = by[("spot", LightType.SPOT)]
    np.testing.assert_allclose(s.color, [2 * 50 / (4 * math.pi)] * 3, rtol=1e-6)  # exposure 1 -> x2
    assert (s.spot_size, s.spot_blend) == pytest.approx((1.0, 0.3)) and s.cast_shadow
    np.testing.assert_allclose(s.direction, (0, 0, -1), atol=1e-6)
    u = by[("sun", LightType.SUN)]
    np.testing.assert_allclose(u.color, [3, 3, 3], rtol=1e-6)
    assert u.angle == pytest.approx(0.1)
    a = by[("area", LightType.AREA)]
    assert a.shape == AreaShape.RECTANGLE and a.size == pytest.approx((0.5, 0.25))
    assert a.spread == pytest.approx(1.0)
    world_area = 0.5 * 2 * 0.25 * 3
    assert a.area() == pytest.approx(world_area, rel=1e-6)
    np.testing.assert_allclose(a.color, [100 / (math.pi * world_area)] * 3, rtol=1e-5)
    d = by[("area.001", LightType.AREA)]
    assert d.shape == AreaShape.DISK and d.size == pytest.approx((0.5, 0.5))
    np.testing.assert_allclose(d.color, [80 / math.pi] * 3, rtol=1e-6)  # normalize=False
    t = by[("point.001", LightType.POINT)]
    tc = np.array(temp.data.temperature_color)
    assert abs(tc[0] - tc[2]) > 0.5  # 3000 K is reddish
    np.testing.assert_allclose(t.color, tc * 10 / (4 * math.pi), rtol=1e-5)


@pytest.fixture(scope="module")
def cycles():
    import addon_utils
    addon_utils.enable("cycles", default_set=True)
    return True


def _cycles_plane(sc, rho=0.8):
    """Lambertian plane (albedo rho) at z=0, ortho camera looking down at its centre."""
    mat = make_principled("lambert", (rho, rho, rho), roughness=1.0, specular=0.0)
    add_mesh(sc, "plane", [(-50, -50, 0), (50, -50, 0), (50, 50, 0), (-50, 50, 0)],
             [(0, 1, 2, 3)], mats=(mat,))
    cam = sc.camera
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 0.02
    cam.location = (0, 0, 5)
    cam.rotation_euler = (0, 0, 0)
    r = sc.render
    r.engine = "CYCLES"
    r.resolution_x = r.resolution_y = 16
    c = sc.cycles
    c.samples, c.use_adaptive_sampling, c.use_denoising = 64, False, False
    c.max_bounces, c.sample_clamp_direct, c.sample_clamp_indirect = 0, 0, 0
    c.pixel_filter_type, c.filter_width, c.seed, c.device = "BOX", 1.0, 0, "CPU"
    sc.world = demo_scenes.make_world("black", (0, 0, 0), 0.0)


def _render_mean(sc, tmp_path):
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = str(tmp_path / f"{sc.name}.exr")
    bpy.ops.render.render(write_still=True, scene=sc.name)
    im = bpy.data.images.load(sc.render.filepath)
    a = np.empty(len(im.pixels), np.float32)
    im.pixels.foreach_get(a)
    bpy.data.images.remove(im)
    return a.reshape(-1, 4)[:, :3].mean(axis=0)


def _square_irradiance(s, h, n=200):
    """Irradiance below the centre of an s x s square of unit radiance at height h."""
    xs = (np.arange(n) + 0.5) / n * s - s / 2
    x, y = np.meshgrid(xs, xs)
    return float(np.sum(h * h / (x * x + y * y + h * h) ** 2) * (s / n) ** 2)


@pytest.mark.parametrize("case", ["point", "spot", "sun", "area", "area_unnormalized",
                                  "world", "emission"])
def test_light_units_match_cycles(scene, cycles, tmp_path, case):
    rho, h = 0.8, 2.0
    _cycles_plane(scene, rho)
    if case == "point":
        add_light(scene, "POINT", (0, 0, h), energy=100.0, shadow_soft_size=0.0,
                  color=(1, 0.5, 0.25), exposure=0.5)
    elif case == "spot":
        add_light(scene, "SPOT", (0, 0, h), energy=100.0, shadow_soft_size=0.0, spot_size=1.5)
    elif case == "sun":
        sun = add_light(scene, "SUN", (0, 0, h), energy=3.0, angle=0.0)
        sun.rotation_euler = (math.radians(60), 0, 0)
    elif case in ("area", "area_unnormalized"):
        ob = add_light(scene, "AREA", (0, 0, h), energy=100.0, size=0.25,
                       normalize=case == "area")
        ob.scale = (2, 2, 1)
    elif case == "world":
        scene.world = demo_scenes.make_world("grey", (0.5, 0.25, 1.0), 2.0)
    elif case == "emission":
        plane = scene.objects["plane"]
        plane.data.materials[0] = demo_scenes.make_emission("em", (1, 0.5, 0.25), 3.0)
    sd = export(scene)
    if case in ("point", "spot"):
        (lt,) = sd.lights
        expected = rho / math.pi * lt.color / h ** 2
    elif case == "sun":
        (lt,) = sd.lights
        cos = float(-lt.direction[2])
        assert cos == pytest.approx(0.5, abs=1e-6)
        expected = rho / math.pi * lt.color * cos
    elif case.startswith("area"):
        (lt,) = sd.lights
        s = float(np.linalg.norm(lt.area_axes()[0]) * 2)
        expected = rho / math.pi * lt.color * _square_irradiance(s, h)
    elif case == "world":
        expected = rho * sd.world.color  # cosine-weighted hemisphere of uniform radiance
    else:
        (m,) = [m for m in sd.materials if m.is_emissive]
        expected = m.emission
    got = _render_mean(scene, tmp_path)
    print(case, "expected", expected, "cycles", got)
    np.testing.assert_allclose(got, expected, rtol=2e-3)


# ------------------------------------------------------------------ world
def test_world(scene):
    sd = export(scene)
    np.testing.assert_allclose(sd.world.color, 0)
    scene.world = demo_scenes.make_world("bg", (0.5, 0.25, 1.0), 2.0)
    sd = export(scene)
    assert sd.world.exact and not sd.world.warnings
    np.testing.assert_allclose(sd.world.color, (1, 0.5, 2), rtol=1e-6)
    sky = scene.world.node_tree.nodes.new("ShaderNodeTexSky")
    bg = scene.world.node_tree.nodes["Background"]
    scene.world.node_tree.links.new(sky.outputs["Color"], bg.inputs["Color"])
    scene.world.color = (0.1, 0.2, 0.3)
    sd = export(scene)  # any other tree: Cycles evaluates it into a map (test_world.py measures it)
    assert sd.world.exact and sd.world.map is not None and sd.world.source == "cycles"
    assert sd.world.map.ndim == 3 and sd.world.map.shape[2] == 3 and float(sd.world.map.max()) > 0
    # a world Cycles cannot evaluate falls back to the viewport colour, with the reason
    from gi_preview.blender import world_bake

    def broken(*a, **k):
        raise RuntimeError("Cycles could not evaluate world 'bg': out of memory")

    world_bake._memory.clear()
    old, world_bake._start = world_bake._start, broken
    cache = world_bake._cache_dir()
    moved = []
    try:
        for f in os.listdir(cache):  # no cached map either
            os.replace(os.path.join(cache, f), os.path.join(cache, f + ".aside"))
            moved.append(f)
        sd = export(scene)
    finally:
        world_bake._start = old
        for f in moved:
            os.replace(os.path.join(cache, f + ".aside"), os.path.join(cache, f))
    assert not sd.world.exact and sd.world.map is None
    np.testing.assert_allclose(sd.world.color, (0.1, 0.2, 0.3), rtol=1e-6)
    assert "out of memory" in sd.world.warnings[0] and sd.world.warnings[0] in sd.warnings


# ------------------------------------------------------------------ camera
def _project(cam, p):
    clip = cam.projection.astype(np.float64) @ cam.view.astype(np.float64) @ np.append(p, 1.0)
    return clip[:2] / clip[3] * 0.5 + 0.5, clip


POINTS = [(0.3, 1.0, 0.2), (-1.5, 3.0, 0.9), (2.0, -4.0, -1.0), (0.0, 0.0, 0.0)]


@pytest.mark.parametrize("setup", ["persp", "persp_shift_vertical_fit", "pixel_aspect", "ortho"])
def test_camera_projection_matches_blender(scene, setup):
    cam = scene.camera
    cam.location = (1, -8, 2)
    cam.rotation_euler = (math.radians(80), 0, math.radians(10))
    cd = cam.data
    r = scene.render
    if setup == "persp_shift_vertical_fit":
        cd.sensor_fit, cd.shift_x, cd.shift_y, cd.lens = "VERTICAL", 0.1, -0.2, 30.0
        r.resolution_x, r.resolution_y = 40, 80
    elif setup == "pixel_aspect":
        r.pixel_aspect_x, r.pixel_aspect_y = 2.0, 1.0
        cd.shift_x = -0.15
    elif setup == "ortho":
        cd.type, cd.ortho_scale, cd.shift_y = "ORTHO", 7.0, 0.1
        cd.clip_start, cd.clip_end = 0.5, 40.0
    sd = export(scene)
    c = sd.camera
    assert c.type == cd.type and (sd.width, sd.height) == (r.resolution_x, r.resolution_y)
    assert (c.clip_start, c.clip_end) == pytest.approx((cd.clip_start, cd.clip_end))
    np.testing.assert_allclose(c.matrix_world, np.array(cam.matrix_world), atol=1e-6)
    for p in POINTS:
        uv, clip = _project(c, np.array(p))
        ref = world_to_camera_view(scene, cam, Vector(p))
        np.testing.assert_allclose(uv, (ref.x, ref.y), atol=1e-5, err_msg=str(p))
        if setup == "ortho":
            assert clip[3] == pytest.approx(1.0)


def test_camera_override_and_resolution_args(scene):
    other = bpy.data.objects.new("other", bpy.data.cameras.new("other"))
    scene.collection.objects.link(other)
    scene.render.resolution_percentage = 50
    sd = export(scene)
    assert (sd.width, sd.height) == (32, 24) and sd.camera.name == "cam"
    sd = export(scene, width=20, height=10, camera=other)
    assert (sd.width, sd.height) == (20, 10) and sd.camera.name == "other"
    assert sd.camera.projection[0, 0] == pytest.approx(sd.camera.projection[1, 1] / 2, rel=1e-5)


def test_errors(scene):
    add_light(scene, "POINT")
    with pytest.raises(SceneError, match="too small"):
        export(scene, width=0, height=10)
    with pytest.raises(SceneError, match="too small"):
        export(scene, width=3, height=10)
    scene.camera.data.type = "PANO"
    with pytest.raises(SceneError, match="panoramic"):
        export(scene)
    scene.camera = None
    with pytest.raises(SceneError, match="Scene 'export_test.*' has no camera"):
        export(scene)


def test_empty_scene_is_not_an_error(scene):
    sd = export(scene)
    assert sd.meshes == [] and sd.instances == [] and sd.lights == []
    assert sd.camera is not None and sd.triangle_count == 0


def _snapshot(sc):
    snap = {"scene": (sc.camera.name, sc.render.resolution_x, sc.render.resolution_y,
                      sc.render.resolution_percentage, sc.frame_current, sc.render.engine)}
    for ob in sc.objects:
        snap[ob.name] = (tuple(map(tuple, ob.matrix_world)), ob.hide_render,
                         ob.data.name if ob.data else None,
                         len(ob.data.polygons) if ob.type == "MESH" else None,
                         len(ob.modifiers), tuple(s.name for s in ob.material_slots))
    for c in ("objects", "meshes", "materials", "lights", "images", "cameras", "worlds"):
        coll = getattr(bpy.data, c)
        snap[c] = (len(coll), sorted((i.name, i.users, i.is_dirty if hasattr(i, "is_dirty") else 0)
                                     for i in coll))
    for mat in bpy.data.materials:
        if mat.node_tree:
            snap["mat:" + mat.name] = tuple(
                (n.name, tuple(tuple(s.default_value) if hasattr(s.default_value, "__len__")
                               else s.default_value for s in n.inputs if hasattr(s, "default_value")))
                for n in mat.node_tree.nodes)
    return snap


def test_export_does_not_modify_scene(scene):
    sc = demo_scenes.build_demo("glossy_spheres", resolution=32)
    try:
        tx = bpy.data.curves.new("txt", "FONT")
        sc.collection.objects.link(bpy.data.objects.new("text", tx))
        (floor,) = [o for o in sc.objects if o.name.startswith("glossy_spheres.floor")]
        _noise_into_roughness(floor.data.materials[0])
        depsgraph(sc)  # evaluation itself updates matrix_world; snapshot after it
        before = _snapshot(sc)
        sd = export(sc)
        assert sd.triangle_count > 0 and sd.warnings
        assert _snapshot(sc) == before
    finally:
        bpy.data.scenes.remove(sc)


# ------------------------------------------------------------------ demo scenes
@pytest.mark.parametrize("name", [d[0] for d in demo_scenes.DEMO_SCENES])
def test_demo_scene_builds_and_exports(scene, name):
    current = bpy.context.scene
    n_scenes = len(bpy.data.scenes)
    sc = demo_scenes.build_demo(name, resolution=40)
    assert bpy.context.scene == current and len(bpy.data.scenes) == n_scenes + 1
    assert sc.name.startswith("GI Preview Demo: " + name)
    assert (sc.render.resolution_x, sc.render.resolution_y) == (40, 40)
    sd = export(sc)
    assert sd.camera is not None and 0 < sd.triangle_count < 50_000
    world_lit = sd.world is not None and float(np.max(sd.world.color)) > 0.0
    assert sd.lights or any(m.is_emissive for m in sd.materials) or world_lit
    assert all(m.exact for m in sd.materials) and not sd.warnings
    lo, hi = sd.world_bounds()
    assert np.all(hi > lo - 1e-6)
    # the camera sees the centre of the geometry
    uv, clip = _project(sd.camera, (lo + hi) / 2)
    assert clip[3] > 0 and np.all((uv > 0) & (uv < 1))
    if name == "many_lights":
        assert len(sd.lights) >= 24
    # the spheres' faces in one fixed order (bmesh makes them in an order that changes between
    # processes, and with it the BVH and the ray-traced images); boxes and walls are written
    # face by face
    for ob in sc.objects:
        if ob.type == "MESH" and len(ob.data.polygons) >= 64:
            faces = [tuple(sorted(p.vertices)) for p in ob.data.polygons]
            assert faces == sorted(faces), ob.name
    if name == "emissive_panel":
        assert not sd.lights and any(m.is_emissive for m in sd.materials)
    if name == "courtyard_loft":  # lit by the HDRI alone, evaluated exactly; textured floor
        assert world_lit and sd.world.exact and sd.world.source == "cycles"
        assert any(m.support == "exact" and "floor" in m.name for m in sd.materials)


def test_operator_and_menu(scene):
    """The add-on (registered once for the run by conftest) exposes the operator and menu."""
    n = len(bpy.data.scenes)
    window = bpy.context.window
    previous = bpy.context.scene
    try:
        assert bpy.ops.gi_preview.add_demo_scene(scene="cornell", resolution=32) == {"FINISHED"}
        assert len(bpy.data.scenes) == n + 1
        # the operator switches the window to the new scene
        assert bpy.context.scene.name.startswith("GI Preview Demo: cornell")
    finally:
        # restore it before the fixture deletes the new scene (a window left on a deleted
        # scene crashes Blender later)
        if window is not None:
            window.scene = previous
    assert demo_scenes.GIPREVIEW_OT_add_demo_scene.__doc__
    assert callable(demo_scenes.menu_func)
    assert demo_scenes.menu_func in bpy.types.VIEW3D_MT_add._dyn_ui_initialize()
    with pytest.raises(ValueError):
        demo_scenes.build_demo("nope")
