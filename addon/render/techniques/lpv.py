"""LPV: cascaded light propagation volumes (Kaplanyan 2009; Kaplanyan & Dachsbacher 2010).

Passes: DIRECT's → ``rsm`` (passes/rsm.py: the VPLs) → ``lpv`` (injection into 2-band SH
per cell, propagation; passes/lpv.py) → ``lpv_lookup`` (trilinear SH lookup with a
normal offset and dampening) → ``lpv_composite`` (``color += albedo_d · E/π``).
One diffuse bounce; compared with Cycles "one_bounce". See docs/techniques/LPV.md.

| parameter | range | meaning |
|---|---|---|
| rsm_resolution | 16–1024 | texels per side of one RSM view (the VPLs) |
| grid | 8–64 | cells per side of a cascade |
| cascades | 1–4 | nested cascades, cell size doubling |
| cell_size | 0–100 | finest cell size (0 = the coarsest cascade covers the scene) |
| iteration_scale | 0.05–4 | propagation steps per cell of the grid side (0.5: 12 steps at 24 cells) |
| dampening | 0–1 | scale of light flowing away along the normal |

**Experimental, not registered unless GI_PREVIEW_EXPERIMENTAL=1**: on the sun-lit room the
light of the sun-lit exterior (roof, outer walls) still leaks into the room through the
fuzzy geometry volume (mean 2.1x Cycles' one bounce; see docs/techniques/LPV.md), so it
stays out of the technique menu, AUTO and the hard-case tests until that is fixed.

Quality ladder (RSM px, grid, cascades): 0 = 64, 16, 2; 1 = 128, 24, 3; 2 = 256, 32, 3;
3 = 512, 48, 3.
"""
from __future__ import annotations

import os

from ..passes.gbuffer import GBufferPass
from ..passes.light_cull import LightCullPass
from ..passes.lpv import LPVLookupPass, LPVPass
from ..passes.rsm import INDIRECT, LightGatedGraph, RSMPass
from ..passes.screen_space import CompositePass
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


class LPV(Technique):
    id = "LPV"
    label = "LPV"
    description = "Cascaded light propagation volumes: RSM VPLs in SH cells, propagated; one diffuse bounce added to DIRECT"
    family = "raster3d"
    reference = "one_bounce"
    cost_rank = 25
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectDiffuse": "lpv_composite.effect"}

    def passes(self, quality):
        return [GBufferPass(quality), LightCullPass(quality), ShadowPass(quality), DirectLightPass(quality),
                RSMPass(quality), LPVPass(quality), LPVLookupPass(quality),
                CompositePass(quality, name="lpv_composite", mode="SSDO", signal="lpv.raw",
                              ao_output="lpv.vis", provides=INDIRECT)]

    def build(self, quality):
        return LightGatedGraph(self.passes(quality))


if os.environ.get("GI_PREVIEW_EXPERIMENTAL") == "1":
    register(LPV)
