"""TAA: 1-spp path tracing + temporal anti-aliasing (Karis 2014): reprojection through the
G-buffer motion, YCoCg neighbourhood clip, exponential history. The camera jitter is the
session's R2 sequence (see passes/filters.py). Docs: docs/techniques/TAA.md.

Parameters (pass ``taa``): alpha (least current-frame weight), gamma (box width in sigmas),
max_history, input_filter/radius/young (same-surface binomial of the current frame, 5x5 by
default), history_filter (Catmull-Rom history), history_normal/normal_motion/history_fallback (under
motion a history tap must face like the pixel; 3x3 same-surface fallback), turned_history/thin_neff/thin_radius
(edge-on faces revealed by a slow pan), light_history (a light edit caps the history length instead of restarting
it). Debug render pass GI_TAA_History (R: history length / max_history, G: share of the history moved by the clip).
Quality ladder: alpha 0.2, 0.1, 0.1 (gamma 1), 0.05 (gamma 1). Warm-up: 8 frames."""
from __future__ import annotations

from ..passes.filters import TAAPass
from . import register
from ._filtered import FilteredPT


@register
class TAA(FilteredPT):
    id = "TAA"
    label = "TAA (PT 1 spp)"
    description = "1-spp path tracing with temporal anti-aliasing (Karis 2014)"
    cost_rank = 305
    warmup_frames = 8
    # debug view as a render pass: R = history length / max_history, G = share of the history clipped
    outputs = {**FilteredPT.outputs, "GI_TAA_History": "taa.debug"}

    def filters(self, quality):
        return [TAAPass(quality)]
