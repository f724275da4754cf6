"""SURFEL: surfel GI after EA SEED's GIBS (Halen, Brinck, Heitz et al. 2021), added to DIRECT's
direct light: irradiance cached on surface elements spawned where the screen is poorly
covered, kept in object space (they move with their objects), traced a few rays each frame,
integrated by a multiscale mean estimator, with depth-moment visibility, recycled when unseen.

Passes: ``gbuffer`` → ``shadows`` → ``direct_light`` (DIRECT) → ``surfel_prepare`` →
``surfel_grid`` → ``surfel_spawn`` → ``surfel_update`` → ``surfel_gather`` → ``surfel_glossy``
(passes/surfels.py). Compared with Cycles "full". A surfel holds irradiance, not directional
light, so glossy indirect light is traced: each glossy pixel sends ``glossy_rays`` rays
through its GGX lobe, lit at the hit by its direct light and the surfels there; the share of
those rays that escape also replaces DIRECT's shadow-map estimate of the world reflection's
visibility. Docs: docs/techniques/SURFEL.md.
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.shadows import ShadowPass
from ..passes.surfels import SURFEL_OUTPUTS, surfel_chain
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


@register
class SURFEL(Technique):
    id = "SURFEL"
    label = "Surfel GI (GIBS)"
    description = ("Irradiance cached on surfels spawned where the screen is poorly covered, moving with "
                   "their objects, with depth-moment visibility (EA SEED GIBS), added to DIRECT")
    family = "radiance cache"
    reference = "full"
    cost_rank = 65
    warmup_frames = 24
    outputs = {**DIRECT_OUTPUTS, **SURFEL_OUTPUTS}

    def passes(self, quality):
        chain = surfel_chain(quality)
        for p in chain:
            p.warmup_frames = self.warmup_frames
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), *chain]
