"""Measured effect shares: how much of what the camera sees each effect is.

A small path-traced image of the scene's camera (the shared path tracer, ``pt.comp`` with
``PT_SHARES``: ``ShareTracePass``) split by light path:

* ``environment``: the world seen directly (camera rays that miss);
* ``emission``: emissive surfaces seen directly;
* ``direct``: light reaching the camera after one scattering (lights, emitters, world);
* ``indirect_diffuse`` / ``indirect_glossy`` / ``transmission``: longer paths, by the lobe of
  their first scattering (Cycles' Diffuse / Glossy / Transmission Indirect passes).

A share is the effect's luminance summed over the image divided by the image's; the shares
add up to 1. Defaults: 32 pixels along the longer side, 4 frames of 4 samples (1-bounce noise
at this size stays below a percentage point on the demo scenes). ``SharesCache`` keeps one
estimate per scene version (``GPUScene.version``), camera (view and projection) and size, so
a viewport that redraws an unchanged scene does not trace again.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .framegraph import FrameGraph, FrameState, Res, RenderContext
from .techniques.pt import AOV_DIRECT, AOV_IND_DIFFUSE, AOV_IND_GLOSSY, COLOR, PathTracePass

AOV_EMISSION, AOV_ENVIRONMENT, AOV_IND_TRANSMISSION = "aov.share_emission", "aov.share_environment", \
    "aov.share_transmission"
EFFECTS = ("direct", "indirect_diffuse", "indirect_glossy", "transmission", "emission", "environment")
LABELS = {"direct": "direct", "indirect_diffuse": "indirect diffuse", "indirect_glossy": "indirect glossy",
          "transmission": "transmission", "emission": "emission", "environment": "environment"}
LUMA = np.array([0.2126, 0.7152, 0.0722])


class ShareTracePass(PathTracePass):
    """The path tracer with the three extra light-path outputs (``PT_SHARES``)."""

    name = "share_trace"
    writes = (COLOR, AOV_DIRECT, AOV_IND_DIFFUSE, AOV_IND_GLOSSY, AOV_EMISSION, AOV_ENVIRONMENT, AOV_IND_TRANSMISSION)
    declared = tuple(Res(n, check="radiance") for n in writes)

    def shader_defines(self, rt) -> dict:
        return {**rt.defines, "PT_SHARES": 1}


@dataclass
class EffectShares:
    shares: dict  # effect -> fraction of the image's luminance (sum 1)
    size: tuple  # (w, h) traced
    samples: int
    time_ms: float
    total: float = 0.0  # mean luminance of the traced image
    images: dict = field(default_factory=dict, repr=False)  # effect -> (H, W, 3), when asked for

    def percent(self, effect: str) -> float:
        return 100.0 * float(self.shares.get(effect, 0.0))

    def as_dict(self) -> dict:
        return {"shares": {k: round(float(v), 5) for k, v in self.shares.items()}, "size": list(self.size),
                "samples": self.samples, "time_ms": round(self.time_ms, 2)}


def small_size(width: int, height: int, longest: int = 32) -> tuple[int, int]:
    """The estimate's size: ``longest`` pixels along the longer side, the aspect kept."""
    s = min(1.0, float(longest) / max(width, height, 1))
    return max(4, int(round(width * s))), max(4, int(round(height * s)))


def shares_from_images(img: dict) -> tuple[dict, float]:
    """Shares from the per-path images (keys: color, direct, ind_diffuse, ind_glossy,
    emission, environment, transmission), each (H, W, 3)."""
    lum = {k: float(np.sum(np.asarray(v, np.float64)[..., :3] @ LUMA)) for k, v in img.items()}
    parts = {
        "environment": lum["environment"],
        "emission": lum["emission"],
        "direct": max(0.0, lum["direct"] - lum["emission"] - lum["environment"]),
        "indirect_diffuse": lum["ind_diffuse"],
        "indirect_glossy": max(0.0, lum["ind_glossy"] - lum["transmission"]),
        "transmission": lum["transmission"],
    }
    tot = sum(parts.values())
    if tot <= 0.0:
        return {e: 0.0 for e in EFFECTS}, 0.0
    n = max(1, int(np.prod(np.asarray(img["color"]).shape[:2])))
    return {e: parts[e] / tot for e in EFFECTS}, tot / n


class ShareTracer:
    """A one-pass graph of ``ShareTracePass`` on its own small render context (the GPU
    scene, its BVH and the program cache are the caller's)."""

    def __init__(self, ctx, programs, gpu_scene):
        self.ctx, self.programs, self.gpu_scene = ctx, programs, gpu_scene
        self.rc = None
        self.graph = None
        self.p = None

    def estimate(self, scene, *, longest: int = 32, spp: int = 4, frames: int = 4, seed: int = 7,
                 keep_images: bool = False) -> EffectShares:
        """Trace ``scene`` (SceneData, already uploaded to the GPU scene) at ``small_size``."""
        size = small_size(scene.width, scene.height, longest)
        if self.rc is None:
            self.rc = RenderContext(self.ctx, self.programs, self.gpu_scene, size)
            self.p = ShareTracePass(None, spp_per_frame=spp, pixel_sequence=1)
            self.graph = FrameGraph([self.p])
            self.graph.plan(set(self.p.provides))
        self.rc.size = size
        self.p.set_properties({"spp_per_frame": spp})
        self.graph.compile(self.rc)
        w, h = size
        keys = {COLOR: "color", AOV_DIRECT: "direct", AOV_IND_DIFFUSE: "ind_diffuse", AOV_IND_GLOSSY: "ind_glossy",
                AOV_EMISSION: "emission", AOV_ENVIRONMENT: "environment", AOV_IND_TRANSMISSION: "transmission"}
        acc = {k: np.zeros((h, w, 3), np.float64) for k in keys.values()}
        t0 = time.perf_counter()
        for f in range(max(1, int(frames))):
            self.graph.execute(self.rc, FrameState(index=f, sample=f, seed=seed), timers=False)
            for res, k in keys.items():
                acc[k] += np.frombuffer(self.rc.read_back(res), np.float32).reshape(h, w, 4)[..., :3]
        self.ctx.finish()
        ms = (time.perf_counter() - t0) * 1e3
        for k in acc:
            acc[k] /= max(1, int(frames))
        shares, total = shares_from_images(acc)
        return EffectShares(shares, size, spp * max(1, int(frames)), ms, total, acc if keep_images else {})

    def release(self):
        if self.p is not None:
            self.p.release()
        if self.rc is not None:
            self.rc.resources.release()
        self.rc = self.graph = self.p = None


class SharesCache:
    """One estimate per (scene version, camera, size, settings)."""

    def __init__(self, ctx, programs, gpu_scene):
        self.tracer = ShareTracer(ctx, programs, gpu_scene)
        self.key = None
        self.value: EffectShares | None = None
        self.estimates = 0  # how many times it traced (tests: the viewport reuses the estimate)

    def get(self, scene, **kw) -> EffectShares:
        cam = scene.camera
        key = (self.tracer.gpu_scene.version, np.asarray(cam.view, np.float32).tobytes(),
               np.asarray(cam.projection, np.float32).tobytes(), small_size(scene.width, scene.height,
                                                                             kw.get("longest", 32)),
               tuple(sorted(kw.items())))
        if key != self.key or self.value is None:
            self.value = self.tracer.estimate(scene, **kw)
            self.key = key
            self.estimates += 1
        return self.value

    def release(self):
        self.tracer.release()


def estimate_offline(ctx, scene, **kw) -> EffectShares:
    """Shares of ``scene`` (SceneData) on ``ctx`` without a session (scripts, tests)."""
    from .gpu_scene import GPUScene
    from .shaders import ProgramCache

    gs = GPUScene(ctx)
    gs.update(scene)
    tracer = ShareTracer(ctx, ProgramCache(ctx), gs)
    try:
        return tracer.estimate(scene, **kw)
    finally:
        tracer.release()
        gs.release()


__all__ = ["EFFECTS", "LABELS", "EffectShares", "SharesCache", "ShareTracer", "estimate_offline",
           "shares_from_images", "small_size"]
