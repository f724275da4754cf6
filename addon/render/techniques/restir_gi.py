"""RESTIR_GI: indirect light by spatiotemporal path resampling (Ouyang et al. 2021), added
to DIRECT's direct light.

Passes: ``gbuffer`` → ``shadows`` → ``direct_light`` (DIRECT: every light, emitter and the
world as direct light) → ``restir_gi`` (passes/restir_gi.py, shaders/restir_gi/restir_gi.comp):
one secondary path sample per pixel per frame (hit point, normal, radiance leaving it from
next-event estimation there plus a short path continuation), temporal reuse (M cap),
spatial reuse with depth/normal tests and the reconnection Jacobian, validation rays, bias
correction 1/M or MIS; ``color += f L_o W``. Effects: indirect diffuse and glossy. The
filters of ``scene.gi_preview.denoiser`` (ATROUS, SVGF) and ``use_taa`` follow it as they
follow PT; with the denoiser's default "AUTO" (Technique Default) RESTIR_GI ends in SVGF
(``default_denoiser``), "NONE" shows it unfiltered. Compared with Cycles "full".
Docs: docs/techniques/RESTIR_GI.md.

| parameter (pass ``restir_gi``) | range | meaning |
|---|---|---|
| temporal | 0–1 | temporal reuse |
| spatial | 0–16 | spatial neighbours |
| radius | 1–64 | spatial radius (pixels) |
| m_cap | 1–500 | temporal M cap |
| bias_mode | 0–1 | 0 = 1/M, 1 = balance heuristic (MIS) with ray-traced visibility |
| jacobian_max | 1–1000 | reuse refused beyond this Jacobian (or below its inverse) |
| max_bounces | 1–64 | Cycles' Max Bounces of the secondary path |
| rr_start | 1–64 | Russian roulette after this many bounces |
| feedback | 0–1 | next frame's history: 1 = spatial reservoirs (RTXDI), 0 = temporal ones (the paper) |

Quality ladder (spatial, radius): 0 = 2, 8 px (and 3 bounces); 1 = 4, 12; 2 = 6, 16;
3 = 8, 24 (M cap 30). Warm-up: 8 frames before an F12 render accumulates.
Render passes: GI_Direct, Emit (DIRECT), GI_IndirectDiffuse, GI_IndirectGlossy, and the
debug views GI_ReservoirW (contribution weight W) and GI_ReservoirM (candidate count M).
"""
from __future__ import annotations


from ..passes.gbuffer import GBufferPass
from ..passes.restir_gi import AOV_DIFFUSE, AOV_GLOSSY, VIEW_M, VIEW_W, RestirGIPass
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


@register
class RESTIR_GI(Technique):
    id = "RESTIR_GI"
    label = "ReSTIR GI"
    description = "Indirect light by spatiotemporal resampling of secondary path samples (Ouyang 2021), over DIRECT"
    family = "ray tracing"
    reference = "full"
    cost_rank = 400
    warmup_frames = 8
    # one resampled path sample per pixel flickers 5-10x more than Cycles 256 spp + OIDN frame to
    # frame (docs/techniques/RESTIR_GI.md); like production ReSTIR GI it is meant to end in a
    # denoiser: scene.gi_preview.denoiser "AUTO" (the default) picks SVGF, "NONE" shows it raw
    default_denoiser = "SVGF"
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectDiffuse": AOV_DIFFUSE, "GI_IndirectGlossy": AOV_GLOSSY,
               "GI_ReservoirW": VIEW_W, "GI_ReservoirM": VIEW_M}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), RestirGIPass(quality)]
