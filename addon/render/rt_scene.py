"""GPU side of the two-level BVH: uploads ``bvh.SceneBVH`` into the SSBOs of
``shaders/lib/bvh.glsl`` and binds them (bpy-free; runs on the GL thread).

Binding points default to ``RT_BINDINGS`` and are passed to shaders as the ``RT_BINDING_*``
defines of bvh.glsl (see :meth:`RtBuffers.defines`), so a technique that needs other
binding points changes them in one place.
"""
from __future__ import annotations

import numpy as np

from .bvh import SceneBVH

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
        for name, arr in bvh.buffers().items():
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
