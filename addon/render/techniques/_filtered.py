"""Shared shape of the filter technique ids (ATROUS, SVGF, TAA): the papers' own setup, the
shared path tracer at 1 sample per pixel per frame followed by the filter."""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from .pt import AOV_DIRECT, AOV_IND_DIFFUSE, AOV_IND_GLOSSY, PathTracePass
from . import Technique


class FilteredPT(Technique):
    family = "ray tracing"
    reference = "full"
    converges = True
    outputs = {"GI_Direct": AOV_DIRECT, "GI_IndirectDiffuse": AOV_IND_DIFFUSE, "GI_IndirectGlossy": AOV_IND_GLOSSY}

    def filters(self, quality) -> list:
        raise NotImplementedError

    def passes(self, quality):
        return [GBufferPass(quality), PathTracePass(None, spp_per_frame=1), *self.filters(quality)]
