"""RSM: reflective shadow maps (Dachsbacher & Stamminger 2005), one diffuse bounce added to DIRECT.

Passes: DIRECT's (gbuffer, light_cull, shadows, direct_light) → ``rsm`` (raster: position,
normal and reflected flux of every shadow-casting light's views, in Cycles' units) →
``rsm_gather`` (the paper's disk of VPL samples at low resolution) → ``rsm_resolve``
(interpolate, or gather again where the four low-resolution samples disagree with the
pixel) → ``rsm_temporal`` (reprojected running mean over 8 frames: ``max_history``) →
``rsm_composite`` (``color += albedo_d · E/π``, the screen-space family's
composite) → ``rsm_debug`` (GI_RSM_Flux). No visibility between VPL and receiver.
Compared with Cycles "one_bounce". See passes/rsm.py and docs/techniques/RSM.md.

| parameter | range | meaning |
|---|---|---|
| rsm_resolution | 16–1024 | texels per side of one RSM view |
| sun_extent | 0–1e5 | sun RSM: half size of the region around the camera (0 = the whole scene) |
| vpl_samples | 4–1024 | VPL samples per RSM view per pixel per frame |
| radius | 0.05–1.5 | sampling disk radius, fraction of the RSM side |
| min_distance | 0–10 | distance clamp d_min of the kernel (scene units) |
| exact_weights | bool | exact inverse-density weights (2ξ1) instead of the paper's ξ1² |
| low_scale | 0.125–1 | resolution of the first gather |
| normal_tolerance, plane_tolerance | | when interpolation is accepted |

Quality ladder (RSM px, VPL samples, low scale): 0 = 64, 32, 1/4; 1 = 128, 64, 1/4;
2 = 256, 128, 1/2; 3 = 512, 256, 1/2.
"""
from __future__ import annotations

from ..framegraph import Effect
from ..passes.gbuffer import GBufferPass
from ..passes.light_cull import LightCullPass
from ..passes.rsm import (INDIRECT, LightGatedGraph, RSMDebugPass, RSMGatherPass, RSMPass,
                          RSMResolvePass, indirect_temporal)
from ..passes.screen_space import CompositePass
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


def rsm_passes(quality) -> list:
    gather = RSMGatherPass(quality)
    return [RSMPass(quality), gather, RSMResolvePass(quality, gather=gather)]


@register
class RSM(Technique):
    id = "RSM"
    label = "RSM"
    description = "Reflective shadow maps: one diffuse bounce from the lights' VPLs (no visibility), added to DIRECT"
    family = "raster3d"
    reference = "one_bounce"
    cost_rank = 20
    graph_class = LightGatedGraph  # skips the injected-light passes without shadow-casting lights
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectDiffuse": "rsm_composite.effect",
               "GI_RSM_Flux": "rsm.debug_flux", "GI_RSM_Regather": "rsm.regather"}

    def passes(self, quality):
        return [GBufferPass(quality), LightCullPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *rsm_passes(quality),
                indirect_temporal(quality, name="rsm_temporal", source="rsm.raw", output="rsm.temporal"),
                CompositePass(quality, name="rsm_composite", mode="SSDO", signal="rsm.temporal",
                              ao_output="rsm.vis", provides=INDIRECT),
                RSMDebugPass(quality)]



__all__ = ["RSM", "rsm_passes", "Effect"]
