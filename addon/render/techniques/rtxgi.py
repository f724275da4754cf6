"""RTXGI: DDGI with the production extensions (Majercik, Marrs, Spjut, McGuire 2021).

DDGI's chain (ddgi.py) plus, in ``probe_state`` and the shaders of ``passes/probes.py``:
32 fixed (unrotated) rays per probe used for relocation and classification only;
relocation (the SDK's three cases: more than ``backface_ratio`` of the fixed rays on back
faces: inside geometry, moved past the closest back face; a front face closer than
``min_frontface``: moved away along the farthest front-face direction; nothing near: back
towards the lattice point; the offset stays inside the 0.45-cell ellipsoid); classification (inactive, not traced beyond the fixed rays and
skipped by the lookup, when inside geometry or when no fixed ray meets a surface within the
probe's cell); an optional camera-following volume that scrolls by whole cells
(``probe_trace.follow_camera``); warm-up that ends when the probes' drift (mean signed
relative change of the stored irradiance per frame) is below ``converge_threshold``; and
glossy indirect light from the probes in the reflection direction
(``color += specular albedo × E(R)/π``). The outer probes sit half a cell inside the scene's
bounds (``margin`` -0.5); relocation moves the ones that still end up in geometry. Compared with Cycles "full".
SSR with the probes as its miss fallback: the id ``RTXGI_SSR`` (technique menu "RTXGI + SSR")
is RTXGI followed by SSR's passes (techniques/ssr.py ``ssr_passes``); the probe gather also
writes ``probes.glossy`` = DIRECT's shadowed world reflection + the probe glossy term (all
the glossy light already in ``color``), which SSR's composite takes as its ``fallback`` for
the share of the lobe it does not find on screen and as the term its result ``replaces``:
``color += ks·found + (1 − a)·glossy − glossy``. Without SSR the probes give every glossy
reflection (blurry); SSR alone falls back to the world reflection only (black indoors).
See docs/techniques/RTXGI.md. Parameters: DDGI's, plus
``probe_state.backface_ratio`` (0.25), ``min_frontface`` (0.2 cell), ``max_offset`` (0.45 cell),
``probe_trace.follow_camera`` (0/1), ``probe_update.converge_threshold``.
"""
from __future__ import annotations

import dataclasses

from ..framegraph import Effect
from ..passes.gbuffer import GBufferPass
from ..passes.probes import GLOSSY, PROBE_OUTPUTS, VolumeConfig, probe_chain
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

    config = RTXGI_CONFIG

    def passes(self, quality):
        chain = probe_chain(self.config, quality, probe_trace={"margin": -0.5})
        for p in chain:
            p.provides = RTXGI_PROVIDES
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), *chain]


@register
class RTXGIWithSSR(RTXGI):
    """RTXGI + SSR: SSR's reflections where found on screen, RTXGI's probe glossy light (and
    DIRECT's world reflection) as SSR's miss fallback."""

    id = "RTXGI_SSR"
    label = "RTXGI + SSR (probes as SSR's miss fallback)"
    description = ("RTXGI, with screen-space reflections where they are found on screen and the probes' "
                   "glossy light where SSR misses")
    cost_rank = 48
    config = dataclasses.replace(RTXGI_CONFIG, glossy_out=True)
    outputs = {**RTXGI.outputs, "GI_IndirectGlossy": "ssr_composite.effect"}

    def passes(self, quality):
        from .ssr import ssr_passes
        return [*super().passes(quality), *ssr_passes(quality, fallback=GLOSSY, replaces=(GLOSSY,))]
