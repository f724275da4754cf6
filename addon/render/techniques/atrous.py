"""ATROUS: 1-spp path tracing + the edge-avoiding à-trous wavelet filter (Dammertz et al.
2010). See passes/filters.py (AtrousPass) and docs/techniques/ATROUS.md.

Parameters (pass ``atrous``): iterations 1–8, sigma_color, sigma_normal, sigma_position.
Quality ladder: iterations 3, 4, 5, 6. Compared with: the full Cycles reference."""
from __future__ import annotations

from ..passes.filters import AtrousPass
from . import register
from ._filtered import FilteredPT


@register
class ATROUS(FilteredPT):
    id = "ATROUS"
    label = "À-trous (PT 1 spp)"
    description = "1-spp path tracing filtered by the edge-avoiding à-trous wavelet (Dammertz 2010)"
    cost_rank = 300

    def filters(self, quality):
        return [AtrousPass(quality)]
