"""LPV: cascaded light propagation volumes (Kaplanyan 2009; Kaplanyan & Dachsbacher 2010).

Passes: DIRECT's → ``rsm`` (passes/rsm.py: the VPLs) → ``lpv`` (cascades, injection into
2-band SH per cell, geometry volume, propagation; passes/lpv.py) → ``lpv_lookup``
(trilinear SH lookup with a normal offset, occlusion-aware weights, dampening) →
``lpv_temporal`` (reprojected running mean over 12 frames) → ``lpv_composite``
(``color += albedo_d · E/π``) → ``rsm_debug`` (GI_RSM_Flux) and ``lpv_debug`` (GI_LPV_Slice). One diffuse bounce; compared with Cycles "one_bounce".
See docs/techniques/LPV.md.

| parameter | range | meaning |
|---|---|---|
| rsm_resolution | 16–1024 | texels per side of one RSM view (the VPLs) |
| grid | 8–64 | cells per side of a cascade |
| cascades | 1–4 | nested cascades, cell size doubling |
| cell_size | 0–100 | finest cell size (0 = the coarsest cascade covers the scene) |
| geometry_volume | bool | fuzzy occlusion by the RSM and G-buffer surfels |
| trilinear_injection | bool | splat each VPL over its 8 cells (default on; off: the one cell, steps as the light moves) |
| splat_blocking | bool | the splat's weights through the geometry volume (off: it leaks through thin walls) |
| inject_offset | 0–2 | cells along the VPL's normal where it is injected (default 1) |
| soft_cascades | bool | a VPL's share in a cascade ramps over 2 cells at its border |
| iteration_scale | 0.05–4 | propagation steps per cell of the grid side |
| inject_scale | 0–1 | weight of the unpropagated injected light in the result |
| dampening | 0–1 | scale of light flowing away along the normal (0; q3 0.25) |
| normal_offset | 0–2 | cells along the surface normal where the lookup reads (default 0.25) |
| debug_cascade, debug_height | | the slice GI_LPV_Slice shows |

Quality ladder (RSM px, grid, cascades): 0 = 64, 16, 2; 1 = 128, 24, 3; 2 = 256, 32, 3;
3 = 512, 40, 3 with the lookup's dampening 0.25 (its finest grid's self-illumination).
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.light_cull import LightCullPass
from ..passes.lpv import LPVDebugPass, LPVLookupPass, LPVPass
from ..passes.rsm import INDIRECT, LightGatedGraph, RSMDebugPass, RSMPass, indirect_temporal
from ..passes.screen_space import CompositePass
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


@register
class LPV(Technique):
    id = "LPV"
    label = "LPV"
    description = "Cascaded light propagation volumes: RSM VPLs in SH cells, propagated; one diffuse bounce added to DIRECT"
    family = "raster3d"
    reference = "one_bounce"
    cost_rank = 25
    graph_class = LightGatedGraph  # skips the injected-light passes without shadow-casting lights
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectDiffuse": "lpv_composite.effect", "GI_RSM_Flux": "rsm.debug_flux",
               "GI_LPV_Slice": "lpv.debug_slice", "GI_LPV_Cascade": "lpv.cascade"}

    def passes(self, quality):
        lpv = LPVPass(quality)
        return [GBufferPass(quality), LightCullPass(quality), ShadowPass(quality), DirectLightPass(quality),
                # the sky's RSM views off by default: under open sky the sky-lit ground lights
                # itself through the volume (city HDRI, 40 px: mean 1.22 of Cycles', relMSE
                # 0.057 against DIRECT's 0.0125; lookup dampening 0.5: 1.11, 0.021); Sky
                # Directions turns them on (interiors lit through openings: see LPV.md)
                RSMPass(quality, world_directions=0), lpv, LPVLookupPass(quality, lpv=lpv),
                # 12 frames (RSM: 8): 60 moving frames at q1 measured 1.00x Cycles' frame-to-frame
                # change with 8, 0.977x with 12; the bounce of a moved light follows 90 % within
                # about 26 frames instead of 19 (docs/techniques/LPV.md, Stability)
                indirect_temporal(quality, name="lpv_temporal", source="lpv.raw", output="lpv.temporal", frames=12),
                CompositePass(quality, name="lpv_composite", mode="SSDO", signal="lpv.temporal",
                              ao_output="lpv.vis", provides=INDIRECT),
                RSMDebugPass(quality), LPVDebugPass(quality)]



__all__ = ["LPV"]
