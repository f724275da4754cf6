"""IRRADIANCE_VOLUME: the irradiance volume (Greger, Shirley, Hubbard, Greenberg 1998),
updated every frame by ray tracing.

The probe chain of ``passes/probes.py`` without visibility: irradiance per probe as an
octahedral map (8×8 texels with borders, float32), trilinear interpolation between the eight
surrounding probes, no distance test, no surface bias, no wrap weights. This is the baseline
that shows light leaks: a probe on the lit side of a thin wall lights the dark side. The
rays, shading, hysteresis and infinite bounces are DDGI's (same code), so the leak is the
only difference measured. (The distance atlas is still updated; the lookup ignores it.) The volume's outer probes sit half a
cell inside the scene's bounds (``margin`` -0.5): without visibility, probes outside the walls
would darken every surface near a wall.
Parameters and quality ladder: as DDGI (see ddgi.py). Compared with Cycles "full".
See docs/techniques/IRRADIANCE_VOLUME.md.
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.probes import PROBE_OUTPUTS, VolumeConfig, probe_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass

IV_CONFIG = VolumeConfig(visibility=False)


@register
class IrradianceVolume(Technique):
    id = "IRRADIANCE_VOLUME"
    label = "Irradiance volume"
    description = "Irradiance probes on a grid, trilinear, no visibility (the leak baseline), added to DIRECT"
    family = "probes"
    reference = "full"
    cost_rank = 35
    outputs = {**DIRECT_OUTPUTS, **PROBE_OUTPUTS}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality),
                *probe_chain(IV_CONFIG, quality, probe_trace={"margin": -0.5})]
