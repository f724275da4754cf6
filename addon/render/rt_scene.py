"""The scene ray-tracing component shared by every pass that traces rays (bpy-free; GL thread).

``SceneRT`` (one per ``GPUScene``, from ``gpu_scene.rt()``) owns the two-level BVH on the GPU
(``RtBuffers``: the SSBOs of ``shaders/lib/bvh.glsl``) and the light-selection table of
``shaders/lib/scene_rt.glsl`` (power CDF, mesh lights, world map tables, and the light tree
and light BVH of ``light_tree.py`` / ``shaders/lib/light_select.glsl``); with the GPUScene's material, light and emitter buffers and
texture array it is everything a compute pass needs to call ``scene_trace``,
``scene_occluded``, ``select_light``/``light_pdf``, ``shade_direct`` and
``bsdf_hit_light_mis``. Two graphs of a session share one SceneRT, hence one BVH. It rebuilds
the bottom levels only when mesh geometry changes and only the top level when instances move;
a pass uses it with::

    rt = rc.scene.rt()                         # brings it up to date with the GPUScene
    prog = rc.programs.compute("x/y.comp", rt.defines)
    rt.bind(prog)                              # scene buffers, textures, BVH, light table

Binding points default to ``RT_BINDINGS`` and are passed to shaders as the ``RT_BINDING_*``
defines (see :meth:`RtBuffers.defines`), so a technique that needs other binding points
changes them in one place.
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from .bvh import SceneBVH
from .light_tree import light_select_table
from .scene_data import LightType, SceneError
from .world_map import world_map_of

# What GL guarantees when the driver does not say (OpenGL 4.3: at least 2^27 bytes).
GL_MIN_SSBO_BLOCK = 1 << 27


def max_ssbo_bytes(ctx) -> int:
    """GL_MAX_SHADER_STORAGE_BLOCK_SIZE of the context (128 MiB on Mesa llvmpipe)."""
    try:
        v = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 0))
    except Exception:  # pragma: no cover - a context without info
        v = 0
    return v if v > 0 else GL_MIN_SSBO_BLOCK


def check_buffer_sizes(arrays: dict, limit: int, triangles: int) -> None:
    """Raise SceneError naming the limit when one BVH buffer exceeds the SSBO block size
    (a shader cannot address more; the driver would fail or read garbage)."""
    too_big = {k: a.nbytes for k, a in arrays.items() if a.nbytes > limit}
    if not too_big:
        return
    name, size = max(too_big.items(), key=lambda kv: kv[1])
    per_tri = max(max(arrays[k].nbytes for k in ("verts", "normals") if k in arrays) // max(triangles, 1), 1)
    raise SceneError(
        f"The scene has {triangles:,} triangles: its ray-tracing buffer '{name}' needs "
        f"{size / 2**20:.0f} MiB, more than this GPU driver allows in one shader storage block "
        f"(GL_MAX_SHADER_STORAGE_BLOCK_SIZE = {limit / 2**20:.0f} MiB, about "
        f"{limit // per_tri:,} triangles). Reduce the triangle count (lower Subdivision or "
        f"Decimate levels, hide objects from rendering) or use a rasterisation technique.")

RT_BINDINGS = {
    "nodes": 8,
    "tlas": 9,
    "verts": 10,
    "normals": 11,
    "tri_info": 12,
    "instances": 13,
    "material_map": 14,
    "light_select": 15,
    "colors": 16,
}
_DEFINE = {
    "nodes": "RT_BINDING_BLAS_NODES",
    "tlas": "RT_BINDING_TLAS_NODES",
    "verts": "RT_BINDING_VERTS",
    "normals": "RT_BINDING_NORMALS",
    "tri_info": "RT_BINDING_TRI_INFO",
    "instances": "RT_BINDING_INSTANCES",
    "material_map": "RT_BINDING_MATERIAL_MAP",
    "light_select": "RT_BINDING_LIGHT_SELECT",
    "colors": "RT_BINDING_COLORS",
}


class RtBuffers:
    """The BVH's SSBOs in one GL context."""

    def __init__(self, ctx, bvh: SceneBVH, bindings: dict | None = None):
        self.ctx = ctx
        self.bvh = bvh
        self.bindings = dict(RT_BINDINGS, **(bindings or {}))
        self.buffers = {}
        arrays = bvh.buffers()
        self.max_block_bytes = max_ssbo_bytes(ctx)
        check_buffer_sizes(arrays, self.max_block_bytes, int(arrays["tri_info"].shape[0]))
        for name, arr in arrays.items():
            self.buffers[name] = ctx.buffer(np.ascontiguousarray(arr).tobytes())

    @property
    def defines(self) -> dict:
        return {_DEFINE[k]: v for k, v in self.bindings.items()}

    def bind(self) -> None:
        for name, buf in self.buffers.items():
            buf.bind_to_storage_buffer(self.bindings[name])

    def update_instances(self, scene) -> None:
        """Instances moved: rebuild the TLAS on the CPU and re-upload only the TLAS and the
        instance records."""
        self.bvh.update_instances(scene)
        fresh = self.bvh.buffers()
        check_buffer_sizes(fresh, self.max_block_bytes, int(fresh["tri_info"].shape[0]))
        for name in ("tlas", "instances", "material_map"):
            data = np.ascontiguousarray(fresh[name]).tobytes()
            buf = self.buffers[name]
            if buf.size != len(data):
                buf.release()
                self.buffers[name] = self.ctx.buffer(data)
            else:
                buf.write(data)

    @property
    def nbytes(self) -> int:
        return sum(b.size for b in self.buffers.values())

    def release(self) -> None:
        for b in self.buffers.values():
            b.release()
        self.buffers.clear()


# ---------------------------------------------------------------------------- SceneRT
VERT_BYTES_PER_TRIANGLE = 96  # bvh.glsl: three corners of two vec4 (normal + uv.x, tangent) per triangle (the largest buffer)


def geometry_key(scene) -> str:
    """Content hash of the meshes (what the BLAS depend on). Each mesh's own content hash is
    computed once and cached on the Mesh object (``_gi_key``, shared with GPUScene): the
    exporter hands back the same Mesh object while its geometry is unchanged, so moving an
    object hashes no vertex data."""
    from .gpu_scene import _mesh_key

    h = hashlib.blake2b(digest_size=16)
    for m in scene.meshes:
        key = getattr(m, "_gi_key", None)
        if key is None:
            key = _mesh_key(m, None)
            m._gi_key = key
        h.update(key.encode())
    return h.hexdigest()


def instance_key(scene) -> str:
    """Hash of the instances (transforms, meshes, material maps): what the TLAS depends on."""
    return hashlib.blake2b(b"".join(np.ascontiguousarray(i.matrix, np.float32).tobytes()
                                    + str(i.mesh).encode()
                                    + (b"" if i.material_map is None else np.asarray(i.material_map).tobytes())
                                    for i in scene.instances), digest_size=16).hexdigest()


def _selection_weights(scene, light_array: np.ndarray, count: int) -> tuple[np.ndarray, float]:
    """Unnormalised selection weights of the lights (power; suns: irradiance x the scene's
    cross-section) and the scene radius they use."""
    n = int(count)
    lo, hi = scene.world_bounds()
    radius = max(float(np.linalg.norm(hi - lo)) * 0.5, 1e-3)
    if n == 0:
        return np.zeros(0), radius
    typ = np.rint(light_array[:n, 3]).astype(int)
    w = np.maximum(light_array[:n, 11].astype(np.float64), 0.0)
    w = np.where(typ == int(LightType.SUN), w * np.pi * radius * radius, w)
    return w, radius


def light_selection(scene, light_array: np.ndarray, count: int) -> np.ndarray:
    """Selection probabilities among the lights proportional to power (suns: irradiance x
    the scene's cross-section), as [cdf..., prob...] (the first 2n floats of scene_rt.glsl's
    table)."""
    n = int(count)
    if n == 0:
        return np.zeros(2, np.float32)
    w, _ = _selection_weights(scene, light_array, count)
    if w.sum() <= 0:
        w[:] = 1.0
    prob = w / w.sum()
    cdf = np.cumsum(prob)
    cdf[-1] = 1.0
    return np.concatenate([cdf, prob]).astype(np.float32)


def world_selection(scene, light_array: np.ndarray, count: int) -> float:
    """Probability that next-event estimation picks the world map rather than a light: the
    world's share of the selection weights (0 for a uniform world, which BSDF rays find)."""
    wm = world_map_of(scene.world)
    if wm is None:
        return 0.0
    w, radius = _selection_weights(scene, light_array, count)
    ww = wm.power_weight(radius)
    if ww <= 0.0:
        return 0.0
    total = float(w.sum()) + ww
    return float(np.clip(ww / total, 0.05, 1.0)) if int(count) > 0 else 1.0


def light_table(scene, light_array: np.ndarray, count: int, emitter_groups) -> np.ndarray:
    """scene_rt.glsl's RtLightSelect buffer: [cdf (n), prob (n), mesh light per instance,
    the world map's sampling tables (map worlds), the light tree and light BVH
    (light_tree.light_select_table, at light_tree_offset)]."""
    sel = light_selection(scene, light_array, count)
    inst = np.full(max(len(scene.instances), 1), -1.0, np.float32)
    first_mesh_light = int(count) - len(emitter_groups)
    for gi, g in enumerate(emitter_groups):
        inst[int(g["instance"])] = first_mesh_light + gi
    if int(count) == 0:
        sel = np.zeros(0, np.float32)
    parts = [sel, inst]
    wm = world_map_of(scene.world)
    if wm is not None:
        parts.append(wm.table())
    if int(count) > 0:
        w, _ = _selection_weights(scene, light_array, count)
        if w.sum() <= 0:
            w[:] = 1.0
        off = sum(len(x) for x in parts)
        parts.append(light_select_table(w, light_array, count, emitter_groups, off))
    return np.concatenate(parts).astype(np.float32)


def light_tree_offset(scene, count: int) -> int:
    """Where the light tree's header starts in light_table's buffer (-1: no lights)."""
    if int(count) <= 0:
        return -1
    wm = world_map_of(scene.world)
    return world_table_offset(scene, count) + (wm.grid[1] * (1 + wm.grid[0]) if wm is not None else 0)


def world_table_offset(scene, count: int) -> int:
    """Where the world's tables start in light_table's buffer."""
    return (2 * int(count) if int(count) else 0) + max(len(scene.instances), 1)


def check_triangle_budget(scene, limit: int) -> None:
    """Refuse, with a SceneError naming the limit, a scene whose BVH vertex buffer would exceed
    the GL context's GL_MAX_SHADER_STORAGE_BLOCK_SIZE (128 MiB on llvmpipe: ~1.4 M triangles),
    before spending time building it. RtBuffers checks every buffer again after the build."""
    tris = sum(scene.meshes[i].triangle_count for i in sorted({inst.mesh for inst in scene.instances}))
    need = tris * VERT_BYTES_PER_TRIANGLE
    if need > limit:
        raise SceneError(
            f"Ray tracing cannot hold this scene: its {tris:,} triangles need {need / 2**20:.0f} MiB of "
            f"vertex data in one shader storage block, more than this GPU driver allows "
            f"(GL_MAX_SHADER_STORAGE_BLOCK_SIZE = {limit / 2**20:.0f} MiB, about "
            f"{limit // VERT_BYTES_PER_TRIANGLE:,} triangles). Reduce the triangle count (lower "
            f"Subdivision or Decimate levels, hide objects from rendering) or pick a rasterisation "
            f"technique.")


class SceneRT:
    """The scene ray-tracing component of one GPUScene (see the module docstring).

    Stats (for benchmarks and tests): ``bvh_ms`` (the last BVH work, build or refit),
    ``blas_builds`` and ``tlas_builds`` (how often each level was rebuilt since creation)."""

    def __init__(self, gpu_scene, bindings: dict | None = None):
        self.gpu_scene = gpu_scene
        self.ctx = gpu_scene.ctx
        self.bindings = dict(RT_BINDINGS, **(bindings or {}))
        self.buffers: RtBuffers | None = None
        self._select_buf = None
        self.world_select = 0.0
        self.light_tree_offset = -1
        self._geo_key = self._inst_key = self._light_key = None
        self._version = None
        self._scene = None
        self.bvh_ms = 0.0
        self.blas_builds = 0
        self.tlas_builds = 0

    def update(self) -> "SceneRT":
        """Bring the BVH and the light table up to date with the GPUScene (cheap when unchanged)."""
        gs = self.gpu_scene
        scene = gs.scene
        if scene is None:
            raise SceneError("the GPU scene is empty: update it with a scene before tracing rays")
        if self.buffers is not None and self._version == gs.version and self._scene is scene:
            return self
        key = geometry_key(scene)
        inst_key = instance_key(scene)
        if self.buffers is None or key != self._geo_key:
            check_triangle_budget(scene, max_ssbo_bytes(self.ctx))  # before a long BVH build
            t0 = time.perf_counter()
            if self.buffers is not None:
                self.buffers.release()
                self.buffers = None
            self.buffers = RtBuffers(self.ctx, SceneBVH.from_scene(scene), self.bindings)
            self._geo_key, self._inst_key = key, inst_key
            self.bvh_ms = (time.perf_counter() - t0) * 1e3
            gs.setup_ms = getattr(gs, "setup_ms", 0.0) + self.bvh_ms  # one-time work (session stats)
            self.blas_builds += 1
            self.tlas_builds += 1
        elif inst_key != self._inst_key:
            t0 = time.perf_counter()
            self.buffers.update_instances(scene)  # objects moved: top level only
            self._inst_key = inst_key
            self.bvh_ms = (time.perf_counter() - t0) * 1e3
            gs.setup_ms = getattr(gs, "setup_ms", 0.0) + self.bvh_ms
            self.tlas_builds += 1
        table = light_table(scene, gs.light_array, gs.light_count, gs.emitters.groups if gs.emitters else [])
        data = table.tobytes()
        if self._select_buf is None or self._select_buf.size != len(data):
            if self._select_buf is not None:
                self._select_buf.release()
            self._select_buf = self.ctx.buffer(data)
        else:
            self._select_buf.write(data)
        self.world_select = world_selection(scene, gs.light_array, gs.light_count)
        self.light_tree_offset = light_tree_offset(scene, gs.light_count)
        self._version, self._scene = gs.version, scene
        return self

    @property
    def defines(self) -> dict:
        """The binding-point defines of bvh.glsl / scene_rt.glsl for ``programs.compute``, and
        ``RT_SCENE_ALPHA`` when some material has holes (rays then test alpha at every
        candidate hit; without holes the traversal skips that code)."""
        from .gpu_scene import has_alpha

        out = {_DEFINE[k]: v for k, v in self.bindings.items()}
        scene = self.gpu_scene.scene
        if scene is not None and has_alpha(scene):
            out["RT_SCENE_ALPHA"] = 1
        return out

    def bind(self, prog, texture_unit: int = 0) -> None:
        """Bind everything scene_rt.glsl reads: the GPUScene's buffers and texture array, the
        BVH, the light table, and the uniforms (light/material counts, world radiance)."""
        from .gpu_scene import set_uniform

        if self.buffers is None:
            self.update()
        gs = self.gpu_scene
        gs.bind(prog, texture_unit)
        self.buffers.bind()
        self._select_buf.bind_to_storage_buffer(self.bindings["light_select"])
        scene = gs.scene
        wm = world_map_of(scene.world)
        set_uniform(prog, "u_world_select", self.world_select)
        set_uniform(prog, "u_world_table", world_table_offset(scene, gs.light_count))
        set_uniform(prog, "u_world_grid", tuple(int(x) for x in (wm.grid if wm is not None else (1, 1))))
        set_uniform(prog, "u_light_tree", self.light_tree_offset)
        # u_alpha_test (GPUScene.bind): rays test alpha only when some material has holes

    @property
    def nbytes(self) -> int:
        return (self.buffers.nbytes if self.buffers else 0) + (self._select_buf.size if self._select_buf else 0)

    def release(self) -> None:
        if self.buffers is not None:
            self.buffers.release()
            self.buffers = None
        if self._select_buf is not None:
            self._select_buf.release()
            self._select_buf = None
        self._geo_key = self._inst_key = self._version = self._scene = None
