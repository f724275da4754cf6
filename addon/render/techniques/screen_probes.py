"""SCREEN_PROBES: Lumen's final gather (Wright, Narkowicz and Kelly, SIGGRAPH 2022), added to
DIRECT's direct light: radiance probes placed on the screen every 16 pixels, refined where
they cannot interpolate, every probe traced every frame with importance-sampled rays, and a
world-space radiance cache for the later bounces and what the probes miss.

Passes: ``gbuffer`` → ``shadows`` → ``direct_light`` (DIRECT) → ``radiance_cache`` (the world
cache GI10 uses too: passes/radiance_cache.py) → ``sp_place`` (one probe per 16-pixel tile,
kept where last frame's reprojects) → ``sp_trace`` (8 × 8 rays per probe every frame, drawn by
the cosine and last frame's light of the probe: Lumen's BRDF × lighting importance sampling,
with a quarter spread uniformly) → ``sp_integrate`` → ``sp_filter`` → ``spa_place`` (adaptive
refinement: probes on 8-pixel tiles placed only where the 16-pixel probes fail to interpolate)
→ ``spa_trace`` → ``spa_integrate`` → ``spa_filter`` → ``sp_gather`` (per pixel: the probes,
then the adaptive probes, then the world cache). Compared with Cycles "full". Docs:
docs/techniques/SCREEN_PROBES.md.

What it shares with GI10 and how it differs: the same probe passes and world cache
(passes/screen_probes.py); GI10 refreshes a quarter of its probes per frame with one ray per
stratum, SCREEN_PROBES traces every probe every frame with importance-sampled rays and adds
the adaptive probes. Lumen's world cache is a clipmap of world-space probes; here it is the
shared hash grid (cells sized by distance, the same job: light from beyond the probes' reach
and the later bounces). Parameters: those of GI10's passes (``sp_*``, ``radiance_cache``) plus
the adaptive set's ``spa_*`` (its tile is half of ``sp_place`` tile).
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.radiance_cache import RadianceCache, RadianceCacheUpdatePass
from ..passes.screen_probes import SP_OUTPUTS, SP_PROVIDES, screen_probe_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


@register
class SCREEN_PROBES(Technique):
    id = "SCREEN_PROBES"
    label = "Screen probes (Lumen final gather)"
    description = ("Radiance probes on the screen every 16 px, refined where they fail, importance-sampled "
                   "every frame, over a world radiance cache (Lumen), added to DIRECT")
    family = "radiance cache"
    reference = "full"
    cost_rank = 70
    warmup_frames = 16
    outputs = {**DIRECT_OUTPUTS, **SP_OUTPUTS}

    def passes(self, quality):
        cache = RadianceCache()
        upd = RadianceCacheUpdatePass(cache, quality, provides=SP_PROVIDES)
        upd.warmup_frames = self.warmup_frames
        every = {"refresh": 1}
        chain = screen_probe_chain(quality, cache, importance=True, adaptive=True,
                                   sp_place=every, spa_place=every)
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), upd, *chain]
