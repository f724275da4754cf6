"""BVH builder invariants (numpy) and GPU traversal (shaders/lib/bvh.glsl) against a CPU
brute-force reference: closest hit, any hit, and no self-intersection at grazing angles."""
from __future__ import annotations

import numpy as np
import pytest

from gi_preview.render import bvh as B
from gi_preview.render.scene_data import Instance, Material, Mesh, SceneData


# ---------------------------------------------------------------- test geometry
def uv_sphere(n_lat=12, n_lon=16, r=1.0):
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon + 1)
    P = np.stack(np.meshgrid(th, ph, indexing="ij"), -1)
    xyz = np.stack([np.sin(P[..., 0]) * np.cos(P[..., 1]), np.sin(P[..., 0]) * np.sin(P[..., 1]),
                    np.cos(P[..., 0])], -1) * r
    tris = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b, c, d = xyz[i, j], xyz[i + 1, j], xyz[i + 1, j + 1], xyz[i, j + 1]
            if i != 0:
                tris.append([a, b, d])  # outward winding (CCW seen from outside)
            if i != n_lat - 1:
                tris.append([b, c, d])
    return np.asarray(tris, np.float32)


def box():
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [[v[a], v[b], v[c]], [v[a], v[c], v[d]]]
    return np.asarray(tris, np.float32)


def soup(n, rng):
    c = rng.uniform(-1, 1, (n, 1, 3))
    return (c + 0.25 * rng.standard_normal((n, 3, 3))).astype(np.float32)


def make_mesh(name, tris):
    T = tris.shape[0]
    pos = tris.reshape(-1, 3)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-30
    return Mesh(name, pos, np.repeat(n, 3, axis=0).astype(np.float32), np.zeros((3 * T, 2), np.float32),
                np.zeros(T, np.int32))


def trs(t, axis_angle=(0, 0, 1, 0.0), scale=(1, 1, 1)):
    x, y, z, a = axis_angle
    k = np.array([x, y, z], float)
    k /= np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    m = np.eye(4)
    m[:3, :3] = R @ np.diag(scale)
    m[:3, 3] = t
    return m.astype(np.float32)


def make_scene(rng=None):
    rng = rng or np.random.default_rng(7)
    meshes = [make_mesh("sphere", uv_sphere()), make_mesh("box", box()), make_mesh("soup", soup(300, rng))]
    insts = [
        Instance(0, trs((0, 0, 0)), "s0"),
        Instance(0, trs((2.5, 0.3, 0), (1, 1, 0, 0.7), (0.5, 1.5, 1.0)), "s1"),
        Instance(1, trs((-2.5, 0, 0.5), (0, 1, 1, 0.4), (1.0, 0.6, 0.8)), "b0"),
        Instance(1, trs((0, 3, 0), (1, 0, 0, 0.2), (3.0, 0.1, 3.0)), "floor"),
        Instance(2, trs((0, -3, 0)), "soup"),
        Instance(2, trs((0, -3, 2.5), (0, 0, 1, 1.0), (0.7, 0.7, 0.7)), "soup2"),
    ]
    return SceneData(meshes=meshes, instances=insts, materials=[Material("m")])


def world_triangles(scene):
    tris, inst_id, tri_id = [], [], []
    for k, inst in enumerate(scene.instances):
        p = scene.meshes[inst.mesh].positions.astype(np.float64)
        w = (np.c_[p, np.ones(len(p))] @ inst.matrix.astype(np.float64).T)[:, :3]
        T = len(p) // 3
        tris.append(w.reshape(T, 3, 3))
        inst_id.append(np.full(T, k))
        tri_id.append(np.arange(T))
    return np.concatenate(tris), np.concatenate(inst_id), np.concatenate(tri_id)


def brute_force(tris, o, d, tmin, tmax):
    """Möller-Trumbore in float64 over all triangles; returns (t, index, second best t)."""
    e1 = tris[:, 1] - tris[:, 0]
    e2 = tris[:, 2] - tris[:, 0]
    pv = np.cross(d[:, None, :], e2[None])
    det = np.einsum("tk,rtk->rt", e1, pv)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1), 0)
    tv = o[:, None, :] - tris[None, :, 0]
    u = np.einsum("rtk,rtk->rt", tv, pv) * inv
    qv = np.cross(tv, e1[None])
    v = np.einsum("rk,rtk->rt", d, qv) * inv
    t = np.einsum("tk,rtk->rt", e2, qv) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > tmin[:, None]) & (t < tmax[:, None])
    t = np.where(hit, t, np.inf)
    order = np.argsort(t, axis=1)[:, :2]
    rows = np.arange(len(o))
    return t[rows, order[:, 0]], order[:, 0], t[rows, order[:, 1]]


# ---------------------------------------------------------------- builder invariants
@pytest.mark.parametrize("n", [1, 2, 3, 7, 100, 5000, 20000])
def test_invariants_random(n):
    rng = np.random.default_rng(n)
    tris = soup(n, rng)
    lo, hi = B.triangle_bounds(tris.reshape(-1, 3))
    bvh = B.build_bvh(lo, hi)
    B.check_invariants(bvh, lo, hi)
    leaf = bvh.count[bvh.count > 0]
    assert leaf.max() <= B.MAX_LEAF
    assert bvh.depth <= B.MAX_DEPTH + 1


def test_invariants_degenerate():
    lo = np.zeros((257, 3), np.float32)
    hi = np.ones((257, 3), np.float32)  # identical boxes: SAH cannot split, median split must
    bvh = B.build_bvh(lo, hi)
    B.check_invariants(bvh, lo, hi)
    assert bvh.count[bvh.count > 0].max() <= B.MAX_LEAF
    # a flat mesh (zero extent on one axis) and a mesh with one far outlier
    tris = soup(2000, np.random.default_rng(3))
    tris[..., 2] = 0.0
    tris[0] += 1e4
    lo, hi = B.triangle_bounds(tris.reshape(-1, 3))
    B.check_invariants(B.build_bvh(lo, hi), lo, hi)


def test_scene_bvh_and_tlas_update():
    scene = make_scene()
    sb = B.SceneBVH.from_scene(scene)
    assert sb.triangle_count == sum(m.triangle_count for m in scene.meshes)
    blas_before = sb.blas_nodes.copy()
    tlas_before = sb.tlas_nodes.copy()
    scene.instances[0].matrix = trs((0, 0, 6))
    sb.update_instances(scene)
    assert np.array_equal(sb.blas_nodes, blas_before)  # moving an object touches only the TLAS
    assert not np.array_equal(sb.tlas_nodes, tlas_before)
    # TLAS leaves hold one instance each and cover all instances once
    cnt = sb.tlas_nodes[:, 7].view(np.int32)
    first = sb.tlas_nodes[:, 3].view(np.int32)
    assert sorted(first[cnt > 0].tolist()) == list(range(len(scene.instances)))


# ---------------------------------------------------------------- GPU traversal
SHADER = """
#include "lib/bvh.glsl"
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Rays { vec4 rays[]; };
layout(std430, binding = 1) writeonly buffer Hits { vec4 hits[]; };
uniform int u_count;
uniform int u_mode;  // 0: closest + any; 1: grazing secondary rays from the closest hit
void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec4 a = rays[2 * i], b = rays[2 * i + 1];
    RtHit h = rt_miss();
    bool hit = rt_trace_closest(a.xyz, b.xyz, a.w, b.w, h);
    if (u_mode == 0) {
        bool any = rt_trace_any(a.xyz, b.xyz, a.w, b.w);
        int tri = hit ? rt_surface(h).triangle : -1;
        hits[2 * i] = vec4(hit ? h.t : -1.0, intBitsToFloat(h.instance), intBitsToFloat(tri), any ? 1.0 : 0.0);
        hits[2 * i + 1] = vec4(h.bary, 0.0, 0.0);
        return;
    }
    hits[2 * i] = vec4(-1.0);
    hits[2 * i + 1] = vec4(-1.0);
    if (!hit) return;
    RtSurface s = rt_surface(h);
    vec3 n = dot(s.geo_normal, b.xyz) < 0.0 ? s.geo_normal : -s.geo_normal;  // side the ray came from
    vec3 tangent = normalize(cross(n, abs(n.x) < 0.9 ? vec3(1, 0, 0) : vec3(0, 1, 0)));
    float ang = 1e-4 * pow(100.0, fract(sin(float(i) * 12.9898) * 43758.5453));  // 1e-4 .. 1e-2 rad
    vec3 d = normalize(cos(ang) * tangent + sin(ang) * n);
    vec3 o = rt_offset_ray(s.position, n);
    RtHit h2 = rt_miss();
    bool hit2 = rt_trace_closest(o, d, 0.0, 1e30, h2);
    int tri2 = hit2 ? rt_surface(h2).triangle : -1;
    hits[2 * i] = vec4(hit2 ? h2.t : -1.0, intBitsToFloat(hit2 ? h2.instance : -1), intBitsToFloat(tri2), 0.0);
    hits[2 * i + 1] = vec4(intBitsToFloat(h.instance), intBitsToFloat(s.triangle), 0.0, 0.0);
}
"""


@pytest.fixture(scope="module")
def gl(tmp_path_factory):
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as exc:  # pragma: no cover - machine without EGL/GL 4.3
        pytest.skip(f"no OpenGL 4.3 context: {exc}")
    from gi_preview.render.shaders import ShaderLibrary, shader_roots
    d = tmp_path_factory.mktemp("bvh_shader")
    (d / "test_bvh.comp").write_text(SHADER)
    src = ShaderLibrary([d] + shader_roots()).compose("test_bvh.comp")
    try:
        prog = ctx.compute_shader(src.text)
    except Exception as exc:
        raise AssertionError(src.explain(str(exc))) from None
    yield ctx, prog
    ctx.release()


def gpu_trace(gl, scene, o, d, tmin, tmax, mode=0):
    from gi_preview.render.rt_scene import RtBuffers
    ctx, prog = gl
    sb = B.SceneBVH.from_scene(scene)
    rt = RtBuffers(ctx, sb)
    rt.bind()
    n = len(o)
    rays = np.zeros((n, 2, 4), np.float32)
    rays[:, 0, :3] = o
    rays[:, 0, 3] = tmin
    rays[:, 1, :3] = d
    rays[:, 1, 3] = tmax
    rbuf = ctx.buffer(rays.tobytes())
    hbuf = ctx.buffer(reserve=n * 32)
    rbuf.bind_to_storage_buffer(0)
    hbuf.bind_to_storage_buffer(1)
    prog["u_count"] = n
    prog["u_mode"] = mode
    prog.run((n + 63) // 64)
    out = np.frombuffer(hbuf.read(), np.float32).reshape(n, 2, 4).copy()
    rbuf.release()
    hbuf.release()
    rt.release()
    return out


def random_rays(scene, n, rng):
    tris, _, _ = world_triangles(scene)
    o = rng.uniform(-5, 5, (n, 3))
    # half the rays aimed at random triangle points, half random directions
    k = rng.integers(0, len(tris), n)
    u = rng.random((n, 2))
    u = np.where(u.sum(1, keepdims=True) > 1, 1 - u, u)
    target = tris[k, 0] + u[:, :1] * (tris[k, 1] - tris[k, 0]) + u[:, 1:] * (tris[k, 2] - tris[k, 0])
    d = target - o
    d[n // 2:] = rng.standard_normal((n - n // 2, 3))
    d *= rng.uniform(0.3, 3.0, (n, 1))  # unnormalised directions must work too
    return o, d


def test_gpu_closest_and_any_hit(gl):
    rng = np.random.default_rng(11)
    scene = make_scene(rng)
    n = 1024
    o, d = random_rays(scene, n, rng)
    tmin = np.zeros(n)
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.2, 1.0, n), 1e30)  # some short rays
    out = gpu_trace(gl, scene, o, d, tmin, tmax)
    t_gpu = out[:, 0, 0]
    inst_gpu = out[:, 0, 1].view(np.int32)
    tri_gpu = out[:, 0, 2].view(np.int32)
    any_gpu = out[:, 0, 3] > 0.5
    tris, inst_id, tri_id = world_triangles(scene)
    t_ref, idx, t2 = brute_force(tris, o, d, tmin, tmax)
    hit_ref = np.isfinite(t_ref)
    # ambiguous rays (grazing an edge: two hits within 1e-4, or a hit within 1e-4 of tmax) are
    # left out of the identity check, not of the distance check
    with np.errstate(invalid="ignore"):
        clear = (np.abs(t2 - t_ref) > 1e-4) & (np.abs(t_ref - tmax) > 1e-4)
    hit_gpu = t_gpu >= 0
    assert hit_ref.sum() > n // 3
    mism = np.flatnonzero((hit_gpu != hit_ref) & clear)
    assert mism.size == 0, f"hit/miss differs for {mism.size} rays, e.g. {mism[:5]}"
    both = hit_gpu & hit_ref
    err = np.abs(t_gpu[both] - t_ref[both]) / np.maximum(1.0, np.abs(t_ref[both]))
    assert err.max() < 1e-4, f"closest t differs by {err.max()}"
    sel = both & clear
    assert np.all(inst_gpu[sel] == inst_id[idx[sel]])
    assert np.all(tri_gpu[sel] == tri_id[idx[sel]])
    assert np.all(any_gpu[clear] == hit_ref[clear]), "any-hit disagrees with closest hit"


def test_gpu_no_self_intersection_at_grazing_angles(gl):
    """Secondary rays leaving convex objects within 1e-4..1e-2 rad of the tangent plane,
    from offset origins, must never hit the instance they leave (a convex surface cannot be
    seen from its own outside)."""
    rng = np.random.default_rng(5)
    scene = make_scene(rng)
    scene.instances = scene.instances[:4]  # spheres and boxes: convex
    o = rng.uniform(-6, 6, (4096, 3))
    # keep origins outside every object (inside a convex object the ray rightly hits it again)
    for inst in scene.instances:
        local = (np.c_[o, np.ones(len(o))] @ np.linalg.inv(inst.matrix.astype(np.float64)).T)[:, :3]
        o = o[np.abs(local).max(axis=1) > 1.05]
    n = len(o)
    targets = np.array([inst.matrix[:3, 3] for inst in scene.instances])[rng.integers(0, 4, n)]
    d = targets + rng.uniform(-0.8, 0.8, (n, 3)) - o
    out = gpu_trace(gl, scene, o, d, np.zeros(n), np.full(n, 1e30), mode=1)
    src_inst = out[:, 1, 0].view(np.int32)
    valid = out[:, 1, 0] != -1.0
    hit_inst = out[:, 0, 1].view(np.int32)
    assert valid.sum() > n // 2
    same = valid & (hit_inst == src_inst)
    assert same.sum() == 0, f"{same.sum()} of {valid.sum()} grazing rays re-hit their own object"


def test_blas_cache_shares_builds_and_rebuilds_only_edited_meshes():
    """Per-mesh BLAS come from the process-wide cache: a second export of the same scene (another
    session, or the same one after an edit elsewhere) builds no BLAS and gives the same node
    arrays; editing one mesh's positions rebuilds that mesh only; a UV edit rebuilds none."""
    from gi_preview.render.bvh import BLAS_CACHE

    BLAS_CACHE.clear()
    h0, m0 = BLAS_CACHE.hits, BLAS_CACHE.misses
    SceneBVH = B.SceneBVH
    a = SceneBVH.from_scene(make_scene())
    assert (BLAS_CACHE.hits - h0, BLAS_CACHE.misses - m0) == (0, 3)
    b = SceneBVH.from_scene(make_scene())  # new Mesh objects with the same content
    assert (BLAS_CACHE.hits - h0, BLAS_CACHE.misses - m0) == (3, 3)
    assert np.array_equal(a.blas_nodes, b.blas_nodes) and np.array_equal(a.tlas_nodes, b.tlas_nodes)

    sc = make_scene()
    box_mesh = sc.meshes[1]
    sc.meshes[1] = make_mesh("box", box() * 1.5)
    c = SceneBVH.from_scene(sc)
    assert (BLAS_CACHE.hits - h0, BLAS_CACHE.misses - m0) == (5, 4)
    assert not np.array_equal(a.blas_nodes, c.blas_nodes)
    sc.meshes[1] = Mesh(box_mesh.name, box_mesh.positions, box_mesh.normals, box_mesh.uvs + 0.25,
                        box_mesh.material_ids)
    d = SceneBVH.from_scene(sc)
    assert (BLAS_CACHE.hits - h0, BLAS_CACHE.misses - m0) == (8, 4)
    assert np.array_equal(a.blas_nodes, d.blas_nodes)

    small = type(BLAS_CACHE)(max_triangles=box().shape[0])  # holds one box, evicts the oldest
    small.get(make_mesh("x", box()), box().reshape(-1, 3))
    small.get(make_mesh("y", box() * 2), (box() * 2).reshape(-1, 3))
    small.get(make_mesh("x", box()), box().reshape(-1, 3))
    assert (small.hits, small.misses) == (0, 3)
