"""RESTIR_DI: direct light by spatiotemporal reservoir resampling (Bitterli et al. 2020).

Passes: ``gbuffer`` → ``restir_di`` (passes/restir.py, shaders/restir/restir_di.comp). Per
pixel per frame: RIS over ``candidates`` light samples drawn by power from the shared sampler
(select_light / sample_light: every light type, emissive triangles) and ``bsdf_candidates``
BSDF samples (emissive triangles, the world, and area/sphere/sun lights while the scene has at
most ``bsdf_light_max`` of them), weighted with MIS'd candidate pdfs; visibility reuse;
temporal reuse (reprojected, M capped at ``m_cap`` x the candidates); spatial reuse over
``spatial`` neighbours (depth/normal tests) within ``radius`` x the image's larger side (at
least ``radius_min`` px); bias correction ``bias_mode`` (0 = 1/M, 1 = MIS-normalised
(pairwise MIS), 2 = ray-traced visibility); every spatial input shaded by its MIS weight
(``shade_all``); final visibility (a hidden kept sample gets W = 0). Samples are points on
lights (or directions), so reuse needs no Jacobian. Compared with Cycles "direct".
Render passes: GI_Direct, Emit, and the debug views GI_ReservoirW and GI_ReservoirM.
Docs and measurements: docs/techniques/RESTIR_DI.md.

Quality ladder (candidates, spatial): 8/4, 32/8, 64/8, 64/16.
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.restir import AOV_DIRECT, AOV_EMIT, DBG_M, DBG_W, RestirDIPass
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
    # render passes: direct light, emission, and the debug views (the reservoir's W and M)
    outputs = {"GI_Direct": AOV_DIRECT, "Emit": AOV_EMIT, "GI_ReservoirW": DBG_W, "GI_ReservoirM": DBG_M}

    def passes(self, quality):
        return [GBufferPass(quality), RestirDIPass(quality)]
