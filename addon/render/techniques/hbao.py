"""HBAO: horizon-based ambient occlusion (Bavoil et al. 2008) in the cosine-weighted GTAO
form (Jimenez et al. 2016).

Passes: DIRECT's three → ``hbao`` (horizon search along ``directions`` screen directions
per pixel, ``steps`` samples per side, distance falloff over the last ``falloff`` of the
radius, GTAO's analytic cosine-weighted arc integral) → ``hbao_temporal`` → ``hbao_blur``
→ ``hbao_ambient_stats`` → ``hbao_composite``. The composite is the same as SSAO's
(``techniques/ssao.py``, docs/techniques/HBAO.md); the AO is the ``GI_AO`` AOV.

| parameter | range | meaning |
|---|---|---|
| directions | 1–32 | slice directions per pixel per frame |
| steps | 1–64 | horizon samples per side |
| radius | 0.01–100 | AO distance in scene units (Cycles' AO distance) |
| falloff | 0–1 | fraction of the radius over which occluders fade |
| bias | 0–1 | normal offset in scene units |
| scale | 0.25–1 | resolution scale of the AO pass |
| blur_radius | 0–8 | bilateral kernel radius (pixels) |
| max_history | 1–1024 | temporal frames averaged at most |
| ambient_bounces | 0–8 | bounces of the constant indirect term (0 = none: DIRECT only) |

Quality ladder (directions, steps, scale, blur): 0 = 2, 4, 0.5, 3; 1 = 4, 6, 1, 2; 2 = 6, 10, 1, 2;
3 = 8, 16, 1, 1.
"""
from __future__ import annotations

from ..framegraph import Param
from ..gpu_scene import set_uniform
from ..passes.gbuffer import GBufferPass
from ..passes.screen_space import ao_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass
from .ssao import AO_PROVIDES, BLUR, AOPass, _q


class HBAOPass(AOPass):
    name = "hbao"
    shader = "screen_space/hbao.comp"
    prefix = "hbao"
    params = (
        Param("directions", 4, 1, 32, "slice directions per pixel per frame"),
        Param("steps", 6, 1, 64, "horizon samples per side"),
        Param("radius", 1.0, 0.01, 100.0, "AO distance (scene units), as Cycles' AO distance"),
        Param("falloff", 0.1, 0.0, 1.0, "fraction of the radius over which occluders fade out"),
        Param("bias", 0.005, 0.0, 1.0, "normal offset (scene units)"),
        Param("scale", 1.0, 0.25, 1.0, "resolution scale"),
    )
    quality_ladder = ({"directions": 2, "steps": 4, "scale": 0.5}, {"directions": 4, "steps": 6, "scale": 1.0},
                      {"directions": 6, "steps": 10, "scale": 1.0}, {"directions": 8, "steps": 16, "scale": 1.0})

    def set_uniforms(self, prog):
        set_uniform(prog, "u_directions", int(self["directions"]))
        set_uniform(prog, "u_steps", int(self["steps"]))
        set_uniform(prog, "u_radius", float(self["radius"]))
        set_uniform(prog, "u_falloff", float(self["falloff"]))
        set_uniform(prog, "u_bias", float(self["bias"]))


@register
class HBAO(Technique):
    id = "HBAO"
    label = "HBAO (GTAO)"
    description = "Horizon-based AO, cosine-weighted (GTAO form), times a constant indirect ambient, added to DIRECT"
    family = "screen_space"
    reference = "one_bounce"
    cost_rank = 12
    outputs = {**DIRECT_OUTPUTS, "GI_AO": "hbao.aov", "GI_IndirectDiffuse": "hbao_composite.effect"}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *ao_chain("hbao", HBAOPass(quality, provides=AO_PROVIDES), quality, AO_PROVIDES,
                          blur=_q(quality, BLUR))]
