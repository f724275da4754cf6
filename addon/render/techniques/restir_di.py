"""RESTIR_DI: direct light by spatiotemporal reservoir resampling (Bitterli et al. 2020).

Passes: ``gbuffer`` → ``restir_di`` (passes/restir.py, shaders/restir/restir_di.comp): per
pixel RIS over ``candidates`` light samples drawn by power from the shared sampler
(select_light / sample_light: every light type and emissive triangles), visibility reuse,
temporal reuse (M capped at ``m_cap`` x candidates), spatial reuse over ``spatial``
neighbours in ``radius`` pixels, bias correction ``bias_mode`` (0 = 1/M, 1 = MIS-normalised,
2 = ray-traced visibility); one shadow ray for the shading. 1 sample per pixel per frame.
Compared with Cycles "direct". Docs: docs/techniques/RESTIR_DI.md.

Quality ladder (candidates, spatial): 8/4, 32/8, 64/8, 64/16. Temporal reuse is implemented
(``temporal=1``) but off by default: measured on many_lights it darkens the image (0.89 of
the unbiased baseline's mean) and correlates frames so that 16 accumulated frames gain little;
until that is found, spatial-only reuse is the default (unbiased mean, 4-5x lower relMSE).
Not yet: BSDF-sampled candidates (glossy highlights of large lights rely on light samples).
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.restir import RestirDIPass
from . import Technique, register


@register
class RESTIR_DI(Technique):
    id = "RESTIR_DI"
    label = "ReSTIR DI"
    description = "Direct light of many lights by spatiotemporal reservoir resampling (Bitterli 2020)"
    family = "ray tracing"
    reference = "direct"
    cost_rank = 200
    warmup_frames = 4
    outputs = {}

    def passes(self, quality):
        return [GBufferPass(quality), RestirDIPass(quality)]
