"""SSDO: screen-space directional occlusion with one indirect bounce (Ritschel et al. 2009).

Passes: DIRECT's three → ``ssdo`` (hemisphere point samples around the normal; blocked
directions receive the direct-lit radiance ``aov.direct`` of the pixel that blocks them
when it faces the receiver, weighted by how far that radiance toward the camera stands for
the radiance sent to the receiver (its diffuse share; its glossy share only near the camera
direction); directions open within the radius are marched further and a surface met there
sends too; directions whose sample or march leaves the screen are traced through the scene
with the shared ray tracer, one per tile of ``world_tile``² pixels and frame (the tracer
rotates per frame; its radiance stands for the tile's pixels that face alike, shrunk towards
the mean of each pixel's known on-screen directions by the share of them it knows), the hit
sending its direct light toward the receiver (lib/scene_rt.glsl); with ``world_rays`` 0 they are
unknown and the bounce is the mean over the known ones); ``sender_samples`` sender pixels per
receiver are also picked in proportion to their flux (importance sampling of bright senders such
as a sun patch, combined with the directions by multiple importance sampling) → ``ssdo_temporal`` → ``ssdo_blur`` →
``ssdo_composite``
(``color += albedo_d * bounce``; DIRECT already lights with the world, shadowed by its
world-light maps). The fraction of directions that stay open is the ``GI_AO`` AOV.
Compared with Cycles "one_bounce" (and "full"). See docs/techniques/SSDO.md.

| parameter | range | meaning |
|---|---|---|
| samples | 1–64 | hemisphere samples per pixel per frame |
| radius | 0.01–100 | sample radius in scene units |
| bias | 0–1 | depth bias / normal offset in scene units |
| scale | 0.25–1 | resolution scale of the SSDO pass |
| far_points | 0–32 | far-field march points past the radius (0 = the radius only) |
| far_distance | 0–1e4 | far-field march length (0 = the scene's bounding diagonal) |
| world_rays | 0–1 | trace off-screen directions through the scene (0: mean of the on-screen ones) |
| world_tile | 1–8 | pixels per side of the tile that shares one traced direction per frame (1, 2, 4 or 8) |
| sender_samples | 0–8 | senders picked per pixel and frame in proportion to their flux (MIS; 0 = off) |
| blur_radius | 0–8 | bilateral kernel radius (pixels) |
| max_history | 1–1024 | temporal frames averaged at most |

Quality ladder (samples, radius, scale, world_rays, world_tile, blur): 0 = 4, 1.0, 0.5, 0, -, 3;
1 = 8, 1.5, 1, 1, 8, 2; 2 = 16, 2.0, 1, 1, 4, 2; 3 = 32, 2.5, 1, 1, 2, 1; sender_samples 2 at
q1-q3 and 0 at q0. The flux pyramid is built at the pass's own resolution (q0: blocks of 2x2
G-buffer pixels), but at q0 one sender still costs more than its lower error buys: sun-lit room
q0 equal-error speed-up 0.55/0.49/0.56x -> 0.53/0.47/0.36x in a same run against HEAD (cornell
0.21/0.22/0.22x -> 0.28/0.25/0.23x, relMSE 0.042 -> 0.030); docs/techniques/SSDO.md.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT, Effect, Param, Res
from ..gpu_scene import set_uniform
from ..passes.gbuffer import GBufferPass
from ..passes.screen_space import DIRECT_RADIANCE, Units, ao_chain, bind_frame, bind_gbuffer
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass
from .ssao import BLUR, AOPass, _q

SSDO_PROVIDES = frozenset({Effect.AO, Effect.INDIRECT_DIFFUSE})
FAR_PARAMS = (
    Param("far_points", 6, 0, 32, "far-field march points past the radius (0 = radius only)"),
    Param("far_distance", 0.0, 0.0, 1e4, "far-field march length (0 = the scene's bounding diagonal)"),
)


class SSDOPass(AOPass):
    name = "ssdo"
    shader = "screen_space/ssdo.comp"
    prefix = "ssdo"
    params = (
        Param("samples", 8, 1, 64, "hemisphere samples per pixel per frame"),
        Param("radius", 1.5, 0.01, 100.0, "sample radius (scene units)"),
        Param("bias", 0.01, 0.0, 1.0, "depth bias and normal offset (scene units)"),
        Param("scale", 1.0, 0.25, 1.0, "resolution scale"),
        *FAR_PARAMS,
        Param("world_rays", 1, 0, 1, "trace off-screen directions through the scene (1) or not (0: they take "
              "the mean of the on-screen ones)"),
        Param("world_tile", 4, 1, 8, "pixels per side of the tile that shares one traced direction per frame "
              "(rounded down to 1, 2, 4 or 8)"),
        Param("sender_samples", 2, 0, 8, "senders picked per pixel and frame in proportion to their flux "
              "(importance sampling of bright senders, combined with the directions by MIS; 0 = off)"),
    )
    quality_ladder = ({"samples": 4, "radius": 1.0, "scale": 0.5, "world_rays": 0, "sender_samples": 0},
                      {"samples": 8, "radius": 1.5, "scale": 1.0, "world_rays": 1, "world_tile": 8},
                      {"samples": 16, "radius": 2.0, "scale": 1.0, "world_rays": 1, "world_tile": 4},
                      {"samples": 32, "radius": 2.5, "scale": 1.0, "world_rays": 1, "world_tile": 2})

    def __init__(self, quality=None, **kw):
        super().__init__(quality, **kw)
        self.reads = self.reads + (DIRECT_RADIANCE,)
        # per-pixel half of the senders' view trust (ssdo_trust.comp), written by this pass's
        # first dispatch at full resolution and read by the main one
        self.trust = f"{self.prefix}.trust"
        # world_rays: per tile the tracer's ray (origin + pixel, direction) and the radiance it
        # brought back (ssdo_trace.comp), per pixel the counts ssdo_resolve.comp needs; tile
        # images are indexed by tile and sized like the output (a tile grid is never larger)
        self.ray_o, self.ray_d = f"{self.prefix}.ray_o", f"{self.prefix}.ray_d"
        self.tile_l, self.part = f"{self.prefix}.tile_l", f"{self.prefix}.part"
        # sender_samples: the senders' flux pyramid (power-of-two, allocated here: ssdo_flux.comp)
        self.flux = f"{self.prefix}.flux"
        self._flux_tex = None
        self.writes = self.writes + (self.trust, self.ray_o, self.ray_d, self.tile_l, self.part, self.flux)
        self.declared = self.declared + (
            Res(self.trust, components=2, dtype="f2"),
            Res(self.ray_o, scale="scale"), Res(self.ray_d, scale="scale"),
            Res(self.tile_l, dtype="f2", scale="scale", check="radiance"),
            Res(self.part, components=2, dtype="f2", scale="scale"),
            Res(self.flux, components=2, managed=False, check="none"))

    def execute(self, rc, frame):
        """Four dispatches, each depending on the previous one's image writes (barriers
        between them): the senders' trust (full resolution), with sender_samples the senders'
        flux pyramid (``_flux``), the screen-space samples (with
        world_rays, also the tiles' rays and each pixel's counts), then with world_rays the
        tiles' rays through the scene and the resolve. Cost, sunlit_room 96 px q1 on
        llvmpipe: see docs/techniques/SSDO.md (timing)."""
        res = rc.resources
        tprog = self.program(rc, "screen_space/ssdo_trust.comp")
        bind_frame(rc, tprog, frame)
        bind_gbuffer(rc, tprog, Units(1))
        res[self.trust].bind_to_image(1, read=False, write=True)
        self.run(rc, tprog)
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT)  # in-pass: the sampling dispatch fetches the trust

        senders = int(self["sender_samples"])
        if senders > 0:
            flux, top = self._flux(rc, frame)
        world_rays = int(self["world_rays"])
        defines = {**({"SSDO_WORLD": 1} if world_rays > 0 else {}), **({"SSDO_SENDERS": 1} if senders > 0 else {})}
        prog = self.program(rc, self.shader, defines or None)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        units.tex(prog, "u_radiance", res[DIRECT_RADIANCE])
        units.tex(prog, "u_trust", res[self.trust])
        if senders > 0:
            units.tex(prog, "u_flux", flux)
            set_uniform(prog, "u_flux_top", top)
            set_uniform(prog, "u_sender_samples", senders)
        self.set_uniforms(prog)
        far = float(self["far_distance"])
        if far <= 0.0:
            lo, hi = rc.scene.scene.world_bounds()
            far = max(float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))), 1e-3)
        set_uniform(prog, "u_far_distance", far)
        set_uniform(prog, "u_far_points", int(self["far_points"]))
        size = self.out_size(rc)
        out = res[self.writes[0]]
        out.bind_to_image(0, read=False, write=True)
        if world_rays <= 0:
            self.run(rc, prog, size)
            return
        tile = int(self["world_tile"])
        tile = 8 if tile >= 8 else 4 if tile >= 4 else 2 if tile >= 2 else 1
        set_uniform(prog, "u_world_tile", tile)
        res[self.ray_o].bind_to_image(1, read=False, write=True)
        res[self.ray_d].bind_to_image(2, read=False, write=True)
        res[self.part].bind_to_image(4, read=False, write=True)
        self.run(rc, prog, size)
        rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the trace loads the stored rays

        # the tiles' rays through the scene, side by side (shared ray tracer)
        rt = rc.scene.rt()
        trace = rc.programs.compute("screen_space/ssdo_trace.comp", rt.defines)
        rt.bind(trace)
        set_uniform(trace, "u_sample", int(frame.sample) & 0xFFFFFFFF)
        gx, gy = self.groups(size)
        tiles = (gx * 8 // tile, gy * 8 // tile)
        set_uniform(trace, "u_tiles", tiles)
        set_uniform(trace, "u_world_distance", far)
        res[self.ray_o].bind_to_image(1, read=True, write=False)
        res[self.ray_d].bind_to_image(2, read=True, write=False)
        res[self.tile_l].bind_to_image(3, read=False, write=True)
        self.run(rc, trace, tiles)
        rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the resolve loads the tiles' light

        resolve = self.program(rc, "screen_space/ssdo_resolve.comp")
        bind_frame(rc, resolve, frame)
        bind_gbuffer(rc, resolve, Units(1))
        set_uniform(resolve, "u_samples", int(self["samples"]))
        set_uniform(resolve, "u_world_tile", tile)
        out.bind_to_image(0, read=True, write=True)
        res[self.ray_o].bind_to_image(1, read=True, write=False)
        res[self.tile_l].bind_to_image(3, read=True, write=False)
        res[self.part].bind_to_image(4, read=True, write=False)
        self.run(rc, resolve, size)

    def _flux(self, rc, frame):
        """The senders' flux pyramid: level 0 at the pass's own resolution (ssdo_flux.comp:
        per texel the flux of its block of G-buffer pixels, 1 at full resolution, 2x2 at q0's
        half) in a power-of-two image, then each level the sum of its children
        (ssdo_flux_reduce.comp). Returns (texture, coarsest level)."""
        import moderngl

        w, h = self.out_size(rc)  # level 0 at the pass's resolution (q0: half), blocks of pixels
        pw, ph = 1 << max(0, (w - 1).bit_length()), 1 << max(0, (h - 1).bit_length())
        levels = max(pw, ph).bit_length()
        tex = self._flux_tex
        if tex is None or tuple(tex.size) != (pw, ph):
            if tex is not None:
                tex.release()
            tex = rc.ctx.texture((pw, ph), 2, dtype="f4")
            tex.build_mipmaps(0, levels - 1)
            tex.filter = (moderngl.NEAREST_MIPMAP_NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
            self._flux_tex = tex
        rc.resources[self.flux] = tex
        fprog = self.program(rc, "screen_space/ssdo_flux.comp")
        bind_frame(rc, fprog, frame)
        units = Units(1)
        bind_gbuffer(rc, fprog, units)
        units.tex(fprog, "u_radiance", rc.resources[DIRECT_RADIANCE])
        units.tex(fprog, "u_trust", rc.resources[self.trust])
        set_uniform(fprog, "u_out_size", (w, h))
        tex.bind_to_image(0, read=False, write=True, level=0)
        self.run(rc, fprog, (pw, ph))
        red = rc.programs.compute("screen_space/ssdo_flux_reduce.comp")
        for lv in range(1, levels):
            rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT)  # level lv-1 stored by the last dispatch
            tex.bind_to_image(0, read=True, write=False, level=lv - 1)
            tex.bind_to_image(1, read=False, write=True, level=lv)
            self.run(rc, red, (max(1, pw >> lv), max(1, ph >> lv)))
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT)  # in-pass: the gather fetches the flux mips
        return tex, levels - 1

    def release(self):
        if self._flux_tex is not None:
            self._flux_tex.release()
            self._flux_tex = None
        super().release()

    def set_uniforms(self, prog):
        set_uniform(prog, "u_samples", int(self["samples"]))
        set_uniform(prog, "u_radius", float(self["radius"]))
        set_uniform(prog, "u_bias", float(self["bias"]))


@register
class SSDO(Technique):
    id = "SSDO"
    label = "SSDO"
    description = "Screen-space directional occlusion: one diffuse bounce from on-screen pixels, added to DIRECT"
    family = "screen_space"
    reference = "one_bounce"
    cost_rank = 15
    outputs = {**DIRECT_OUTPUTS, "GI_AO": "ssdo.aov", "GI_IndirectDiffuse": "ssdo_composite.effect"}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *ao_chain("ssdo", SSDOPass(quality, provides=SSDO_PROVIDES), quality, SSDO_PROVIDES,
                          mode="SSDO", blur=_q(quality, BLUR))]
