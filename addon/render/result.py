"""What one render of GI Preview returns: a linear image, AOVs, timings and the plan."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SkippedPass:
    """A pass the planner did not run, and why (machine-readable and for the stats line)."""

    name: str
    effects: list[str]
    reason: str

    def as_dict(self) -> dict:
        return {"pass": self.name, "effects": list(self.effects), "reason": self.reason}


@dataclass
class RenderResult:
    """One rendered image (possibly accumulated over ``samples`` frames).

    image: (H, W, 4) float32 linear scene-referred RGBA, row 0 = bottom row (Blender's order).
    aovs: render-pass name -> (H, W, C) float32, same orientation ("Depth", "Normal",
          "DiffCol", "Emit", and one per effect a technique provides, e.g. "GI_AO").
    pass_ms: per pass, GPU time of the last frame in milliseconds (timer queries).
    frame_ms: mean time of one accumulated frame in milliseconds, completion to completion
              (frames overlap: the CPU records one while the GPU runs the previous), without
              one-time setup (shader compiles, BVH builds) that happened in a frame.
    total_ms: the call's wall time, ~ setup_ms + prep_ms + warmup_ms + frame_ms x samples +
              the read-back.
    """

    image: np.ndarray
    aovs: dict[str, np.ndarray] = field(default_factory=dict)
    technique: str = "DIRECT"
    quality: int = 1
    samples: int = 1
    pass_ms: dict[str, float] = field(default_factory=dict)
    frame_ms: float = 0.0
    total_ms: float = 0.0
    effects: list[str] = field(default_factory=list)
    skipped_passes: list[SkippedPass] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    cancelled: bool = False
    setup_ms: float = 0.0  # one-time work of this call: upload, BVH, allocation, shader compiles
    prep_ms: float = 0.0  # per-call work before the first frame: scene analysis, upload check, AUTO's plan
    warmup_frames: int = 0  # frames run (not accumulated) for the technique's state to converge
    warmup_ms: float = 0.0  # wall time of those frames, to the last one's completion
    history_resets: list[str] = field(default_factory=list)  # passes whose history this call reset
    pass_order: list[str] = field(default_factory=list)  # the planned passes in execution order
    auto: dict = field(default_factory=dict)  # AUTO's plan: shares, chosen members, predictions (else empty)

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    def stats_line(self) -> str:
        skipped = ", ".join(f"{s.name} ({s.reason})" for s in self.skipped_passes) or "none"
        return (f"GI Preview {self.technique} q{self.quality} | {self.samples} spp | "
                f"{self.frame_ms:.1f} ms/frame"
                + (f" | warm-up {self.warmup_frames} frames, {self.warmup_ms:.0f} ms" if self.warmup_frames else "")
                + f" | skipped: {skipped}")
