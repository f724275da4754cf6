"""G-buffer: rasterises every instance once per frame (jittered for anti-aliasing).

Writes ``gbuffer.albedo`` (base colour, textured), ``gbuffer.normal`` (shading normal,
w = roughness), ``gbuffer.position`` (world position, w = material id, -1 = background),
``gbuffer.geonormal`` (geometric normal, w = metallic), ``gbuffer.motion`` (pixels, current
minus previous) and ``gbuffer.depth`` (depth attachment).
"""
from __future__ import annotations

import numpy as np

from ..framegraph import Pass
from ..gpu_scene import set_uniform

ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, DEPTH = (
    "gbuffer.albedo", "gbuffer.normal", "gbuffer.position", "gbuffer.geonormal", "gbuffer.motion", "gbuffer.depth")


class GBufferPass(Pass):
    name = "gbuffer"
    always = True
    writes = (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, DEPTH)

    def compile(self, rc):
        size = rc.size
        rc.texture(ALBEDO, 4, "f2")
        rc.texture(NORMAL, 4, "f2")
        rc.texture(POSITION, 4, "f4")
        rc.texture(GEONORMAL, 4, "f2")
        rc.texture(MOTION, 4, "f2")
        old = rc.resources.get(DEPTH)
        if old is not None:
            old.release()
        rc.resources[DEPTH] = rc.ctx.depth_texture(size)
        if getattr(self, "fbo", None) is not None:
            self.fbo.release()
        self.fbo = rc.ctx.framebuffer(
            color_attachments=[rc.resources[n] for n in (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION)],
            depth_attachment=rc.resources[DEPTH])

    def execute(self, rc, frame):
        import moderngl

        ctx = rc.ctx
        prog = rc.programs.program("raster/gbuffer.vert", "raster/gbuffer.frag")
        self.fbo.use()
        ctx.viewport = (0, 0, rc.width, rc.height)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        # w = -1 in every attachment marks background (position.w is the material id)
        self.fbo.clear(0.0, 0.0, 0.0, -1.0, depth=1.0)
        view_proj = (frame.proj @ frame.view).astype(np.float32)
        nojit = (frame.proj_unjittered @ frame.view).astype(np.float32)
        set_uniform(prog, "u_view_proj", view_proj)
        set_uniform(prog, "u_view_proj_nojit", nojit)
        set_uniform(prog, "u_prev_view_proj", frame.prev_view_proj if frame.prev_view_proj is not None else nojit)
        set_uniform(prog, "u_camera_pos", np.linalg.inv(frame.view)[:3, 3].astype(np.float32))
        set_uniform(prog, "u_resolution", (float(rc.width), float(rc.height)))
        rc.scene.bind(prog)
        rc.scene.draw(prog, prev=True)
        ctx.disable(moderngl.DEPTH_TEST)

    def release(self):
        if getattr(self, "fbo", None) is not None:
            self.fbo.release()
            self.fbo = None
