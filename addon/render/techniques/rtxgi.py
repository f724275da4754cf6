"""RTXGI: DDGI with the production extensions (Majercik, Marrs, Spjut, McGuire 2021).

DDGI's chain (ddgi.py) plus, in ``probe_state`` and the shaders of ``passes/probes.py``:
32 fixed (unrotated) rays per probe used for relocation and classification only;
relocation (more than ``backface_ratio`` of the fixed rays on back faces: inside geometry,
moved past the closest back face; too close to a front face: moved away; never more than
0.45 of a cell per axis); classification (inactive, not traced beyond the fixed rays and
skipped by the lookup, when inside geometry or when no fixed ray meets a surface within the
probe's cell); an optional camera-following volume that scrolls by whole cells
(``probe_trace.follow_camera``); warm-up that ends when the probes' variability (mean
relative change of the stored irradiance per frame) is below ``converge_threshold``; and
glossy indirect light from the probes in the reflection direction
(``color += specular albedo × E(R)/π``). The outer probes sit half a cell inside the scene's
bounds (``margin`` -0.5); relocation moves the ones that still end up in geometry. Compared with Cycles "full".
See docs/techniques/RTXGI.md. Parameters: DDGI's, plus
``probe_state.backface_ratio`` (0.25), ``min_frontface`` (0.2 cell), ``max_offset`` (0.45 cell),
``probe_trace.follow_camera`` (0/1), ``probe_update.converge_threshold``.
"""
from __future__ import annotations

from ..framegraph import Effect
from ..passes.gbuffer import GBufferPass
from ..passes.probes import PROBE_OUTPUTS, VolumeConfig, probe_chain
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass

RTXGI_CONFIG = VolumeConfig(visibility=True, relocate=True, classify=True, glossy=True,
                            measure_convergence=True, fixed_rays=32)
RTXGI_PROVIDES = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR})


@register
class RTXGI(Technique):
    id = "RTXGI"
    label = "RTXGI (DDGI + relocation, classification)"
    description = ("DDGI with probe relocation, classification, a scrolling volume, convergence by "
                   "variability and glossy indirect from the probes, added to DIRECT")
    family = "probes"
    reference = "full"
    cost_rank = 45
    outputs = {**DIRECT_OUTPUTS, **PROBE_OUTPUTS}

    def passes(self, quality):
        chain = probe_chain(RTXGI_CONFIG, quality, probe_trace={"margin": -0.5})
        for p in chain:
            p.provides = RTXGI_PROVIDES
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), *chain]
