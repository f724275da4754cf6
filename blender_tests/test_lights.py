"""The light tree and light BVH (render/light_tree.py, shaders/lib/light_select.glsl).

Scene: a floor, an emissive box (a mesh light) and 90 lights of every type at random places
and orientations (points with and without a radius, spots, square/rectangle/disk area lights,
two suns), powers spread over three decades. Probed by blender_tests/shaders/light_probe.comp at 2048
random shading points (half with a normal, half without) and directions.

Criteria: the selection probabilities of all lights sum to 1 (GPU, 1e-4; float64 reference of
the table, 1e-9); light_pdf of the light select_light picked equals the probability the sampler
returned (1e-5 relative: the same products); the GPU's light_pdf equals the float64
reimplementation (light_tree.table_pdf) to 1e-4 relative on >= 99.5 % of the queries (float32
at a cone's edge may flip a node's culling; measured: all within 2.3e-5); the histogram of 2^16 selections at one
shading point matches light_pdf (chi-square); the light BVH finds exactly the lights (count
and radiance) a loop over every light finds.
"""
from __future__ import annotations

import numpy as np
import pytest

from gi_preview.render.scene_data import AreaShape, Instance, Light, LightType, Material, Mesh, SceneData

N_QUERIES = 2048


def _frame(rng, pos):
    z = rng.normal(size=3)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.3, 0.5, 0.8])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4, dtype=np.float32)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, pos
    return m


def build_scene() -> SceneData:
    rng = np.random.default_rng(5)
    floor = np.array([[-6, -6, 0], [6, -6, 0], [6, 6, 0], [-6, -6, 0], [6, 6, 0], [-6, 6, 0]], np.float32)
    nf = np.tile([0, 0, 1], (6, 1)).astype(np.float32)
    box = np.array([[0, 0, 1], [0.5, 0, 1], [0.5, 0.5, 1.2], [0, 0, 1], [0.5, 0.5, 1.2], [0, 0.5, 1.2]], np.float32)
    meshes = [Mesh("floor", floor, nf, np.zeros((6, 2), np.float32), np.zeros(2, np.int32)),
              Mesh("panel", box, np.tile([0, 0, -1], (6, 1)).astype(np.float32), np.zeros((6, 2), np.float32),
                   np.zeros(2, np.int32))]
    m = np.eye(4, dtype=np.float32)
    m[:3, 3] = (1.0, -2.0, 0.5)
    instances = [Instance(0, np.eye(4, dtype=np.float32), "floor"), Instance(1, m, "panel", material_map=np.array([1], np.int32))]
    mats = [Material("grey", base_color=(0.5, 0.5, 0.5)),
            Material("glow", base_color=(0, 0, 0), emission_color=(1.0, 0.75, 0.5), emission_strength=4.0)]
    lights = []
    for k in range(90):
        pos = rng.uniform([-5, -5, 0.2], [5, 5, 4])
        col = rng.uniform(0.2, 1.0, 3).astype(np.float32) * np.float32(10 ** rng.uniform(-1, 2))
        kind = k % 6
        if kind in (0, 1):
            L = Light(f"p{k}", LightType.POINT, _frame(rng, pos), col, radius=0.0 if kind == 0 else 0.1)
        elif kind == 2:
            L = Light(f"s{k}", LightType.SPOT, _frame(rng, pos), col, radius=0.05, spot_size=rng.uniform(0.3, 2.5),
                      spot_blend=0.2)
        else:
            shape = (AreaShape.SQUARE, AreaShape.RECTANGLE, AreaShape.DISK)[kind - 3]
            L = Light(f"a{k}", LightType.AREA, _frame(rng, pos), col, shape=shape, size=(0.4, 0.8))
        L.power = float(col.mean() * (4 * np.pi if L.type != LightType.AREA else np.pi * L.area()))
        lights.append(L)
    for k, ang in enumerate((0.0, 0.1)):
        sun = Light(f"sun{k}", LightType.SUN, _frame(rng, (0, 0, 10)), np.array([1.0, 0.9, 0.8], np.float32),
                    angle=ang)
        sun.power = 0.9
        lights.append(sun)
    return SceneData(meshes=meshes, instances=instances, materials=mats, lights=lights, width=8, height=8)


def run_probe(sd, queries):
    from gi_preview.render.gl import get_gl
    from gi_preview.render.gpu_scene import GPUScene, set_uniform
    from _shaders import probe_programs

    gl = get_gl()

    def job():
        ctx = gl.ctx
        gs = GPUScene(ctx)
        programs = probe_programs(ctx)
        try:
            gs.update(sd)
            rt = gs.rt()
            prog = programs.compute("light_probe.comp", rt.defines)
            rt.bind(prog)
            n = len(queries)
            qbuf = ctx.buffer(np.ascontiguousarray(queries, np.float32).tobytes())
            obuf = ctx.buffer(reserve=n * 3 * 16)
            qbuf.bind_to_storage_buffer(4)
            obuf.bind_to_storage_buffer(5)
            set_uniform(prog, "u_count", n)
            prog.run((n + 63) // 64)
            ctx.memory_barrier()
            out = np.frombuffer(obuf.read(), np.float32).reshape(n, 3, 4).copy()
            table = np.frombuffer(rt._select_buf.read(), np.float32).copy()
            qbuf.release()
            obuf.release()
            return out, table, rt.light_tree_offset, gs.light_count, gs.light_array.copy()
        finally:
            programs.release()
            gs.release()

    return gl.submit(job).result()


def _queries(rng, n, p_fixed=None):
    q = np.zeros((n, 3, 4), np.float32)
    q[:, 0, :3] = rng.uniform([-6, -6, 0], [6, 6, 4.5], (n, 3)) if p_fixed is None else p_fixed
    q[:, 0, 3] = rng.random(n)
    nn = rng.normal(size=(n, 3))
    q[:, 1, :3] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
    q[:, 1, 3] = (np.arange(n) % 2) if p_fixed is None else 1.0
    dd = rng.normal(size=(n, 3))
    q[:, 2, :3] = dd / np.linalg.norm(dd, axis=1, keepdims=True)
    return q


@pytest.fixture(scope="module")
def probe():
    pytest.importorskip("moderngl")
    sd = build_scene()
    rng = np.random.default_rng(17)
    q = _queries(rng, N_QUERIES)
    hist_p = np.array([0.5, -1.0, 1.0], np.float32)
    qh = _queries(rng, 1 << 16, hist_p)
    qh[:, 1, :3] = (0.0, 0.0, 1.0)
    out, table, off, count, arr = run_probe(sd, np.concatenate([q, qh]))
    return sd, q, out[:N_QUERIES], qh, out[N_QUERIES:], table, off, count, arr


def test_probabilities_sum_to_one(probe):
    from gi_preview.render import light_tree

    sd, q, out, _, _, table, off, count, _ = probe
    assert count == len(sd.lights) + 1  # the emissive panel is a mesh light
    assert np.allclose(out[:, 0, 3], 1.0, atol=1e-4), out[:, 0, 3].min()
    flat = table[count:2 * count].astype(np.float64)
    for k in range(0, N_QUERIES, 97):
        nrm = q[k, 1, :3] if q[k, 1, 3] > 0.5 else None
        s = sum(light_tree.table_pdf(table, off, i, flat[i], q[k, 0, :3], nrm) for i in range(count))
        assert abs(s - 1.0) < 1e-6, (k, s)


def test_light_pdf_matches_sampler_and_reference(probe):
    from gi_preview.render import light_tree

    sd, q, out, _, _, table, off, count, _ = probe
    i = out[:, 0, 0].astype(int)
    assert np.all((i >= 0) & (i < count))
    prob, pdf = out[:, 0, 1], out[:, 0, 2]
    assert np.all(prob > 0.0)
    assert np.allclose(pdf, prob, rtol=1e-5, atol=0.0)
    flat = table[count:2 * count].astype(np.float64)
    ref = np.array([light_tree.table_pdf(table, off, i[k], flat[i[k]], q[k, 0, :3],
                                         q[k, 1, :3] if q[k, 1, 3] > 0.5 else None) for k in range(N_QUERIES)])
    ok = np.abs(pdf - ref) <= 1e-4 * ref + 1e-12
    assert ok.mean() >= 0.995, (ok.mean(), np.abs(pdf / ref - 1).max())


def test_selection_histogram(probe):
    from gi_preview.render import light_tree

    sd, _, _, qh, out, table, off, count, _ = probe
    i = out[:, 0, 0].astype(int)
    flat = table[count:2 * count].astype(np.float64)
    p = np.array([light_tree.table_pdf(table, off, k, flat[k], qh[0, 0, :3], qh[0, 1, :3]) for k in range(count)])
    assert abs(p.sum() - 1.0) < 1e-6
    obs = np.bincount(i, minlength=count)
    exp = p * len(i)
    assert np.all(obs[exp == 0] == 0)  # a light the tree gives no probability is never picked
    big = exp >= 5
    chi2 = float(((obs[big] - exp[big]) ** 2 / exp[big]).sum())
    dof = int(big.sum()) - 1
    assert chi2 < dof + 5 * np.sqrt(2 * dof), (chi2, dof)


def test_light_bvh_finds_what_the_loop_finds(probe):
    _, _, out, _, _, _, _, _, _ = probe
    assert np.array_equal(out[:, 1, 3], out[:, 2, 3])
    assert out[:, 1, 3].sum() > 20  # the rays do cross lights
    assert np.allclose(out[:, 1, :3], out[:, 2, :3], rtol=1e-6, atol=0.0)
