"""SSAO: screen-space ambient occlusion (Mittring 2007; Shanmugam & Orikan 2007).

Passes: ``gbuffer`` → ``shadows`` → ``direct_light`` (DIRECT) → ``ssao`` (normal-oriented
hemisphere kernel, per-pixel rotation, range check; at ``scale`` of the resolution) →
``ssao_temporal`` (shared reprojection + disocclusion rejection) → ``ssao_blur``
(depth/normal-aware bilateral) → ``ssao_ambient_stats`` → ``ssao_composite``.

What is added to DIRECT (docs/techniques/SSAO.md): the survey's "ambient term times AO",
with a physical ambient: ``albedo_d * AO * L_amb``, where ``L_amb`` is a constant indirect
estimate from the screen means (radiosity's ambient term: mean direct-lit radiance x mean
enclosure within the AO radius x a geometric series over ``ambient_bounces``). DIRECT
already lights with the world (shadowed by its world-light maps), so no world term is
added here. The AO itself is the ``GI_AO`` AOV, comparable with Cycles' AO at distance
``radius`` (reference kind "ao").

| parameter | range | meaning |
|---|---|---|
| samples | 1–64 | kernel directions per pixel per frame |
| points | 1–16 | kernel points per direction (1 = the classic kernel, which under-occludes) |
| radius | 0.01–100 | AO distance in scene units (Cycles' AO distance) |
| bias | 0–1 | depth bias / normal offset in scene units |
| scale | 0.25–1 | resolution scale of the AO pass |
| blur_radius | 0–8 | bilateral kernel radius (pixels) |
| max_history | 1–1024 | temporal frames averaged at most |
| ambient_bounces | 0–8 | bounces of the constant indirect term (0 = none: DIRECT only) |

Quality ladder (samples, points, scale, blur): 0 = 4, 2, 0.5, 3; 1 = 8, 3, 1, 2; 2 = 16, 4, 1, 2;
3 = 32, 6, 1, 1.
"""
from __future__ import annotations

from ..framegraph import Effect, Param, Res
from ..gpu_scene import set_uniform
from ..passes.gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION, GBufferPass
from ..passes.screen_space import ScreenPass, Units, ao_chain, bind_frame, bind_gbuffer, scaled
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass

AO_PROVIDES = frozenset({Effect.AO, Effect.INDIRECT_DIFFUSE})
BLUR = ({"blur_radius": 3}, {"blur_radius": 2}, {"blur_radius": 2}, {"blur_radius": 1})


class AOPass(ScreenPass):
    """Raw AO at ``scale`` of the resolution into ``<prefix>.raw`` (rgba16f, rgb = AO)."""

    shader = ""
    prefix = ""

    def __init__(self, quality=None, **kw):
        super().__init__(quality, **kw)
        self.reads = (ALBEDO, NORMAL, POSITION, GEONORMAL)
        self.writes = (f"{self.prefix}.raw",)
        self.declared = (Res(self.writes[0], dtype="f2", scale="scale", check="radiance"),)
        self.history_resets = frozenset()

    def out_size(self, rc):
        return scaled(rc.size, float(self["scale"]))

    def set_uniforms(self, prog):
        raise NotImplementedError

    def execute(self, rc, frame):
        prog = self.program(rc, self.shader)
        bind_frame(rc, prog, frame)
        bind_gbuffer(rc, prog, Units(1))
        self.set_uniforms(prog)
        size = self.out_size(rc)
        rc.resources[self.writes[0]].bind_to_image(0, read=False, write=True)
        self.run(rc, prog, size)


class SSAOPass(AOPass):
    name = "ssao"
    shader = "screen_space/ssao.comp"
    prefix = "ssao"
    params = (
        Param("samples", 8, 1, 64, "kernel directions per pixel per frame"),
        Param("points", 3, 1, 16, "kernel points per direction (1 = classic one-point kernel)"),
        Param("radius", 1.0, 0.01, 100.0, "AO distance (scene units), as Cycles' AO distance"),
        Param("bias", 0.01, 0.0, 1.0, "depth bias and normal offset (scene units)"),
        Param("scale", 1.0, 0.25, 1.0, "resolution scale"),
    )
    quality_ladder = ({"samples": 4, "points": 2, "scale": 0.5}, {"samples": 8, "points": 3, "scale": 1.0},
                      {"samples": 16, "points": 4, "scale": 1.0}, {"samples": 32, "points": 6, "scale": 1.0})

    def set_uniforms(self, prog):
        set_uniform(prog, "u_samples", int(self["samples"]))
        set_uniform(prog, "u_points", int(self["points"]))
        set_uniform(prog, "u_radius", float(self["radius"]))
        set_uniform(prog, "u_bias", float(self["bias"]))


def _q(quality, table):
    return table[max(0, min(int(quality), len(table) - 1))]


@register
class SSAO(Technique):
    id = "SSAO"
    label = "SSAO"
    description = "Screen-space ambient occlusion times a constant indirect ambient term, added to DIRECT"
    family = "screen_space"
    reference = "one_bounce"
    cost_rank = 10
    outputs = {**DIRECT_OUTPUTS, "GI_AO": "ssao.aov", "GI_IndirectDiffuse": "ssao_composite.effect"}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *ao_chain("ssao", SSAOPass(quality, provides=AO_PROVIDES), quality, AO_PROVIDES,
                          blur=_q(quality, BLUR))]
