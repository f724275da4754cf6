"""SVGF: 1-spp path tracing + spatiotemporal variance-guided filtering (Schied et al. 2017).
See passes/filters.py (SVGFPass) and docs/techniques/SVGF.md.

Parameters (pass ``svgf``): iterations 1–8, max_history, sigma_luminance, sigma_normal,
sigma_depth, edge_history, light_history. Debug render passes: GI_SVGF_Variance (luminance variance of the
integrated signal), GI_SVGF_History (history length / max_history). Quality ladder: iterations 3, 4, 5, 6. Warm-up: 8 frames before an F12 render
accumulates (the temporal history fills). Compared with: the full Cycles reference."""
from __future__ import annotations

from ..passes.filters import SVGFPass
from . import register
from ._filtered import FilteredPT


@register
class SVGF(FilteredPT):
    id = "SVGF"
    label = "SVGF (PT 1 spp)"
    description = "1-spp path tracing filtered by spatiotemporal variance-guided filtering (Schied 2017)"
    cost_rank = 310
    warmup_frames = 8
    # debug views as render passes: the variance handed to the à-trous, the history length
    outputs = {**FilteredPT.outputs, "GI_SVGF_Variance": "svgf.dbg_var", "GI_SVGF_History": "svgf.dbg_len"}

    def filters(self, quality):
        return [SVGFPass(quality)]
