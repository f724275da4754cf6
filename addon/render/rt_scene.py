"""GPU side of the two-level BVH: uploads ``bvh.SceneBVH`` into the SSBOs of
``shaders/lib/bvh.glsl`` and binds them (bpy-free; runs on the GL thread).

Binding points default to ``RT_BINDINGS`` and are passed to shaders as the ``RT_BINDING_*``
defines of bvh.glsl (see :meth:`RtBuffers.defines`), so a technique that needs other
binding points changes them in one place.
"""
from __future__ import annotations

import numpy as np

from .bvh import SceneBVH
from .scene_data import SceneError

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
    per_tri = max(arrays["verts"].nbytes // max(triangles, 1), 1)
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
}
_DEFINE = {
    "nodes": "RT_BINDING_BLAS_NODES",
    "tlas": "RT_BINDING_TLAS_NODES",
    "verts": "RT_BINDING_VERTS",
    "normals": "RT_BINDING_NORMALS",
    "tri_info": "RT_BINDING_TRI_INFO",
    "instances": "RT_BINDING_INSTANCES",
    "material_map": "RT_BINDING_MATERIAL_MAP",
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
