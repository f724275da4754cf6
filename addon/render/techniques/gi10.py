"""GI10: two-level radiance caching after AMD's GI-1.0 (Boissé, Guillaume, Le Bras, Sarkar,
Wimmer 2023): screen probes for the detail near the camera, a hash-grid world cache for the
later bounces and what the probes cannot interpolate, added to DIRECT's direct light.

Passes: ``gbuffer`` → ``shadows`` → ``direct_light`` (DIRECT) → ``radiance_cache``
(passes/radiance_cache.py: every used cell traces a few rays, blends, ages out) → ``sp_place``
(last frame's probes reprojected onto this frame's surfaces, a quarter refreshed per frame,
new probes spawned where none reprojects) → ``sp_trace`` (res² rays per tracing probe, hits
shaded with their direct light plus the cache) → ``sp_integrate`` (SH, temporal blend driven
by luminance change) → ``sp_filter`` (spatial) → ``sp_gather`` (per pixel; the cache where
the probes fail). Compared with Cycles "full". Docs: docs/techniques/GI10.md.

Parameters: ``sp_place`` tile (16 px), res (8: 64 rays per probe), refresh (4), spawn_traces
(4), plane_tol; ``sp_integrate`` min_blend (0.05), fast_blend, change_threshold;
``sp_filter`` radius (1); ``sp_gather`` min_weight, glossy, debug_views; ``radiance_cache``
buckets (4096 × 16 entries), cell_min (1/256 of the scene), cell_scale (0.02 per unit of
distance), rays (4), max_age (50 frames), min_blend, fast_blend, change_threshold.
Quality ladder: tiles of 32, 16, 12 and 8 px (8 with 12×12 rays at 3); cache rays 2, 4, 4, 8.
Warm-up: 16 frames before an F12 render accumulates (each probe traced at least 4 + 3 times).
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.radiance_cache import RadianceCache, RadianceCacheUpdatePass
from ..passes.screen_probes import SP_OUTPUTS, SP_PROVIDES, screen_probe_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


@register
class GI10(Technique):
    id = "GI10"
    label = "GI-1.0 (screen probes + hash-grid cache)"
    description = ("Screen probes reprojected frame to frame, a quarter refreshed per frame, over a "
                   "hash-grid world radiance cache (AMD GI-1.0), added to DIRECT")
    family = "radiance cache"
    reference = "full"
    cost_rank = 60
    warmup_frames = 16
    outputs = {**DIRECT_OUTPUTS, **SP_OUTPUTS}

    def passes(self, quality):
        cache = RadianceCache()
        upd = RadianceCacheUpdatePass(cache, quality, provides=SP_PROVIDES)
        chain = screen_probe_chain(quality, cache)
        upd.warmup_frames = self.warmup_frames
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), upd, *chain]
