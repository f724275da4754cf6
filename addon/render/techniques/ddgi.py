"""DDGI: dynamic diffuse global illumination (Majercik, Guertin, Nowrouzezahrai, McGuire 2019).

Passes: DIRECT's three (G-buffer, shadows, direct light: every direct term, emission and the
world, exact) → the probe chain of ``passes/probes.py``: ``probe_trace`` (rays per probe
through the shared ray tracer, rotated randomly every frame; hits shaded with direct light,
the world's light and last frame's probe irradiance: infinite bounces) → ``probe_state``
(all probes active on the lattice) → ``probe_update`` (octahedral irradiance 8×8 and
distance/distance² 16×16 float32 atlases with one-texel borders, hysteresis with fast
response to large changes) → ``probe_gather`` (Chebyshev visibility, normal and view bias,
wrap-shading weights; ``color += diffuse albedo × E/π``). Compared with Cycles "full".
See docs/techniques/DDGI.md.

| pass.parameter | range | meaning |
|---|---|---|
| probe_trace.probes | 2–64 | probes along the longest side of the scene's bounds |
| probe_trace.spacing | 0–1e4 | fixed probe spacing (0 = from `probes`) |
| probe_trace.probes_x/y/z | 0–64 | explicit counts (0 = automatic) |
| probe_trace.rays | 8–1024 | rays per probe per frame |
| probe_update.hysteresis | 0–0.999 | stored value's weight per frame |
| probe_update.change_threshold | 0–1 | relative change that drops hysteresis to a quarter |
| probe_update.normal_bias / view_bias | 0–1 | surface bias, fraction of a cell |
| probe_update.warmup | 0–1024 | F12 warm-up frames |

Quality ladder (probes along the longest side, rays): 0 = 6, 64; 1 = 8, 128; 2 = 10, 192; 3 = 12, 256.
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.probes import PROBE_OUTPUTS, VolumeConfig, probe_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass

DDGI_CONFIG = VolumeConfig(visibility=True)


@register
class DDGI(Technique):
    id = "DDGI"
    label = "DDGI"
    description = "Dynamic diffuse GI: ray-traced irradiance probes with visibility (Chebyshev), added to DIRECT"
    family = "probes"
    reference = "full"
    cost_rank = 40
    warmup_frames = 0  # the probe_update pass declares it (parameter `warmup`)
    outputs = {**DIRECT_OUTPUTS, **PROBE_OUTPUTS}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *probe_chain(DDGI_CONFIG, quality)]
