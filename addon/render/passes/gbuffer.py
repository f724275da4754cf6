"""G-buffer: rasterises every instance once per frame (jittered for anti-aliasing).

Writes ``gbuffer.albedo`` (base colour, w = specular IOR level), ``gbuffer.normal`` (shading
normal, normal-mapped, w = roughness), ``gbuffer.position`` (world position, w = material id,
-1 = background), ``gbuffer.geonormal`` (geometric normal, w = metallic), ``gbuffer.motion``
(pixels, current minus previous), ``gbuffer.emission`` (emitted radiance) and
``gbuffer.depth`` (depth attachment): every material input textures can drive, sampled
once per pixel (``lib/textures.glsl``), so readers build the surface with ``gbuffer_surface``
(``lib/brdf.glsl``) without sampling textures again.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import DEPTH as DEPTH_KIND
from ..framegraph import Pass, Res
from ..gpu_scene import set_uniform

ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, DEPTH = (
    "gbuffer.albedo", "gbuffer.normal", "gbuffer.position", "gbuffer.geonormal", "gbuffer.motion", "gbuffer.depth")
EMISSION = "gbuffer.emission"


class GBufferPass(Pass):
    name = "gbuffer"
    kind = "raster"
    always = True
    writes = (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, EMISSION, DEPTH)
    declared = (Res(ALBEDO, components=4, dtype="f2"), Res(NORMAL, components=4, dtype="f2"),
                Res(POSITION, components=4, dtype="f4"), Res(GEONORMAL, components=4, dtype="f2"),
                Res(MOTION, components=4, dtype="f2"), Res(EMISSION, components=4, dtype="f2"),
                Res(DEPTH, kind=DEPTH_KIND, check="none"))
    history_resets = frozenset()  # no state across frames

    def compile(self, rc):
        if getattr(self, "fbo", None) is not None:
            self.fbo.release()
        self.fbo = rc.ctx.framebuffer(
            color_attachments=[rc.resources[n] for n in (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, EMISSION)],
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
        set_uniform(prog, "u_alpha_seed", int((frame.sample * 2654435761 + frame.seed * 40503) & 0x7FFFFFFF))
        rc.scene.bind(prog)
        rc.scene.draw(prog, prev=True)
        ctx.disable(moderngl.DEPTH_TEST)

    def release(self):
        if getattr(self, "fbo", None) is not None:
            self.fbo.release()
            self.fbo = None
