"""SSDO: screen-space directional occlusion with one indirect bounce (Ritschel et al. 2009).

Passes: DIRECT's three → ``ssdo`` (hemisphere point samples around the normal; unblocked
directions see the world, blocked ones receive the direct-lit radiance ``aov.direct`` of
the pixel that blocks them when it faces the receiver) → ``ssdo_temporal`` → ``ssdo_blur``
→ ``ssdo_composite`` (``color += albedo_d * (bounce + world * visibility) + spec_albedo *
world * visibility``). The directional visibility is the ``GI_AO`` AOV. Compared with Cycles
"one_bounce" (and "full"). See docs/techniques/SSDO.md.

| parameter | range | meaning |
|---|---|---|
| samples | 1–64 | hemisphere samples per pixel per frame |
| radius | 0.01–100 | sample radius in scene units |
| bias | 0–1 | depth bias / normal offset in scene units |
| scale | 0.25–1 | resolution scale of the SSDO pass |

Quality ladder (samples, radius, scale): 0 = 4, 1.0, 0.5; 1 = 8, 1.5, 1; 2 = 16, 2.0, 1; 3 = 32, 2.5, 1.
"""
from __future__ import annotations

from ..framegraph import Effect, Param
from ..gpu_scene import set_uniform
from ..passes.gbuffer import GBufferPass
from ..passes.screen_space import DIRECT_RADIANCE, Units, ao_chain, bind_frame, bind_gbuffer
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DirectLightPass
from .ssao import FAR_PARAMS, BLUR, AOPass, _q

SSDO_PROVIDES = frozenset({Effect.AO, Effect.INDIRECT_DIFFUSE})


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
    )
    quality_ladder = ({"samples": 4, "radius": 1.0, "scale": 0.5}, {"samples": 8, "radius": 1.5, "scale": 1.0},
                      {"samples": 16, "radius": 2.0, "scale": 1.0}, {"samples": 32, "radius": 2.5, "scale": 1.0})

    def __init__(self, quality=None, **kw):
        super().__init__(quality, **kw)
        self.reads = self.reads + (DIRECT_RADIANCE,)

    def execute(self, rc, frame):
        prog = self.program(rc, self.shader)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        units.tex(prog, "u_radiance", rc.resources[DIRECT_RADIANCE])
        self.set_uniforms(prog)
        self.set_far(rc, prog)
        size = self.out_size(rc)
        rc.texture(self.writes[0], 4, "f2", size=size).bind_to_image(0, read=False, write=True)
        self.run(rc, prog, size)

    def set_uniforms(self, prog):
        set_uniform(prog, "u_samples", int(self["samples"]))
        set_uniform(prog, "u_radius", float(self["radius"]))
        set_uniform(prog, "u_bias", float(self["bias"]))


@register
class SSDO(Technique):
    id = "SSDO"
    label = "SSDO"
    description = "Screen-space directional occlusion of the world light plus one bounce from on-screen pixels"
    family = "screen_space"
    reference = "one_bounce"
    cost_rank = 15
    outputs = {"GI_AO": "ssdo.aov", "GI_Direct": "aov.direct"}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *ao_chain("ssdo", SSDOPass(quality, provides=SSDO_PROVIDES), quality, SSDO_PROVIDES,
                          mode="SSDO", blur=_q(quality, BLUR))]
