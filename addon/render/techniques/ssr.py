"""SSR: screen-space reflections on a Hi-Z pyramid (McGuire & Mara 2014; Uludag 2014;
Stachowiak 2015).

Passes: DIRECT's three → ``ss_hiz`` (min device-depth pyramid, level 0 conservative over
each pixel's footprint) → ``ssr_trace`` (one GGX visible-normal sampled ray per pixel at
``scale``, Hi-Z traversal, level-0 hit test against the pixel's plane with ``thickness``
measured along its normal, edge fade, rays leaving the screen miss) → ``ssr_resolve`` (ratio
estimator over ``resolve_samples`` neighbouring rays, radius growing with roughness, the own
ray weighted in closed form so mirrors stay exact; a hit's radiance trusted for its diffuse
share and its glossy share near the camera direction; also the found hits' mean distance
``ssr.hit_dist``) → ``ssr_temporal`` (history reprojected by the reflected point, the virtual
image behind the mirror, where a hit was found) → ``ssr_composite``
(``color += spec_albedo * found + (1 - a) * fallback - replaced``; replaced is DIRECT's
shadowed world reflection ``aov.world_spec``; the fallback for the share ``1 - a`` not found on
screen — misses, untrusted hits — is ``ssr.fallback``: with ``miss_trace`` (on at every level)
``ssr_trace`` traces the same rays again through the scene's BVH (second dispatch,
``ssr_miss.comp``: direct light at the hit with one shadow ray, the world's light on it with one
visibility ray, the world where the ray escapes; ``miss_samples_moving`` of them while the camera
moves; with the distance of the light's image — the hit's, or for a glossy hit's highlight the
unfolded path to the light — for the reprojection) and ``ssr_resolve`` averages them over the
same neighbours, weighted by the share each left unfound; ``ssr_fallback_temporal`` (the shared
temporal pass) accumulates that fallback over frames — history reprojected by the virtual image
point at the miss rays' mean distance ``ssr.miss_dist``, clamped to the current 3x3
neighbourhood while the camera moves, 16 frames still / 4 moving; with ``miss_trace`` 0 it keeps
no history and passes ``aov.world_spec`` through unchanged. Surfaces rougher than
``max_roughness`` are not marched on screen; with ``rough_trace`` (on at every level) their GGX
ray is traced through the BVH like a miss, otherwise (and with ``miss_trace`` 0) they keep
``aov.world_spec``. ``ssr_passes`` lets
another technique pass its own fallback, which turns the miss trace off). Radiance at a hit is the
direct-lit colour without emission (one bounce; emitters' glossy reflection is DIRECT's).
All SSR passes provide INDIRECT_SPECULAR: the planner skips them, saying "no glossy
surface in view", on a scene without one. Compared with Cycles "one_bounce".
See docs/techniques/SSR.md.

| parameter | range | meaning |
|---|---|---|
| steps | 8–1024 | Hi-Z traversal iterations per ray |
| thickness | 0.001–10 | assumed thickness of surfaces, along their normal (scene units) |
| max_distance | 0.1–1000 | ray length (scene units) |
| max_roughness | 0–1 | rougher surfaces keep DIRECT's world reflection |
| edge_fade | 0–0.5 | screen fraction over which hits fade at the border |
| bias | 0–1 | ray origin offset along the geometric normal (scene units) |
| resolve_samples | 1–16 | neighbour rays reused per pixel |
| scale | 0.25–1 | resolution scale of the trace |
| miss_trace | 0/1 | trace the rays through the scene for the share not found on screen (1 at every level) |
| rough_trace | 0/1 | with miss_trace: surfaces rougher than max_roughness trace their GGX ray through the scene (1 at every level) |
| miss_samples | 1–16 | light samples per miss-trace hit, camera still |
| miss_samples_moving | 1–16 | the same while the camera moves (default 2: the fallback's history is short) |

Quality ladder (steps, resolve, scale, miss_trace, rough_trace): 0 = 32, 4, 1, 1, 1; 1 = 64, 6, 1, 1, 1;
2 = 128, 8, 1, 1, 1; 3 = 256, 12, 1, 1, 1. With ``miss_trace`` 0 the share not found on screen keeps DIRECT's
shadowed world reflection ``aov.world_spec``; see docs/techniques/SSR.md.
"""
from __future__ import annotations

from ..framegraph import SHADER_IMAGE_ACCESS_BARRIER_BIT, Effect, Param, Res
from ..gpu_scene import set_uniform
from ..passes.gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION, GBufferPass
from ..passes.screen_space import (DIRECT_RADIANCE, HIZ, WORLD_SPEC, CompositePass, HiZPass, ScreenPass, TemporalPass,
                                   Units, bind_frame, bind_gbuffer, scaled)
from ..passes.shadows import ShadowPass
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass

SSR_PROVIDES = frozenset({Effect.INDIRECT_SPECULAR})
RAY0, RAY1, RESOLVED, HIT_DIST = "ssr.ray0", "ssr.ray1", "ssr.raw", "ssr.hit_dist"
MISS, FALLBACK, MISS_DIST = "ssr.miss", "ssr.fallback", "ssr.miss_dist"
FALLBACK_TEMPORAL = "ssr.fallback_temporal"


class SSRTracePass(ScreenPass):
    name = "ssr_trace"
    params = (
        Param("steps", 64, 8, 1024, "Hi-Z traversal iterations per ray"),
        Param("thickness", 0.15, 0.001, 10.0, "assumed thickness of surfaces, along their normal (scene units)"),
        Param("max_distance", 20.0, 0.1, 1000.0, "ray length (scene units)"),
        Param("max_roughness", 0.7, 0.0, 1.0, "rougher surfaces use the fallback"),
        Param("edge_fade", 0.08, 0.0, 0.5, "screen fraction over which hits fade at the border"),
        Param("bias", 0.005, 0.0, 1.0, "ray origin offset along the geometric normal"),
        Param("scale", 1.0, 0.25, 1.0, "resolution scale of the trace"),
        Param("miss_trace", 1, 0, 1, "trace every ray through the scene too, for the share not found on screen "
              "(SSR's own fallback; 0 = DIRECT's shadowed world reflection)"),
        Param("rough_trace", 1, 0, 1, "surfaces rougher than max_roughness take their whole glossy lobe from the "
              "miss trace (with miss_trace; 0 = DIRECT's shadowed world reflection)"),
        Param("miss_samples", 1, 1, 16, "light samples at each miss-trace hit while the camera is still"),
        Param("miss_samples_moving", 2, 1, 16, "light samples at each miss-trace hit while the camera moves "
              "(the fallback's history is short then)"),
    )
    # q0 traces at full resolution: at half resolution (measured, glossy_spheres 96 px) the
    # reflections of the curved spheres lost detail (relMSE 0.0274 vs 0.0229), for ~1 ms
    # miss_trace and rough_trace on at every level: F12 renders improve every column measured
    # (sunlit_room q1 vs full 0.07582 off -> 0.07451; glossy_spheres q1 vs one_bounce
    # 0.0191 -> 0.0094), and under camera motion against
    # Cycles (corridor frames 4-12) 0.2879 off -> 0.1652 with the trace
    quality_ladder = tuple({"steps": n, "scale": 1.0, "miss_trace": 1, "rough_trace": 1} for n in (32, 64, 128, 256))
    reads = (ALBEDO, NORMAL, POSITION, GEONORMAL, HIZ)
    writes = (RAY0, RAY1)
    declared = (Res(RAY0, scale="scale"), Res(RAY1, scale="scale"))
    history_resets = frozenset()
    miss_defines: dict = {}  # extra defines of ssr_miss.comp (benches: SSR_MISS_NO_MIS, ...)

    def __init__(self, quality=None, *, miss: bool = False, **kw):
        """miss: also write ``ssr.miss`` (ssr_miss.comp: the rays traced through the scene
        when ``miss_trace`` is on, zeros when off) for the resolve's fallback. Without it
        (a technique passing its own fallback, RTXGI) the pass is the screen trace only."""
        super().__init__(quality, **kw)
        self.miss = miss
        if miss:
            self.writes = self.writes + (MISS,)
            self.declared = self.declared + (Res(MISS, dtype="f2", scale="scale", check="radiance"),)

    def size(self, rc):
        return scaled(rc.size, float(self["scale"]))

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_space/ssr_trace.comp")
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        hiz = rc.resources[HIZ]
        units.tex(prog, "u_hiz", hiz)
        set_uniform(prog, "u_hiz_levels", _levels(rc.size))
        for k, u in (("steps", "u_steps"),):
            set_uniform(prog, u, int(self[k]))
        for k, u in (("thickness", "u_thickness"), ("max_distance", "u_max_distance"),
                     ("max_roughness", "u_max_roughness"), ("edge_fade", "u_edge_fade"), ("bias", "u_bias")):
            set_uniform(prog, u, float(self[k]))
        set_uniform(prog, "u_rough_trace", self.rough_on())
        size = self.size(rc)
        rc.resources[RAY0].bind_to_image(0, read=False, write=True)
        rc.resources[RAY1].bind_to_image(1, read=False, write=True)
        self.run(rc, prog, size)
        if self.miss:
            self._miss(rc, frame, size)

    def rough_on(self) -> int:
        """1 where surfaces rougher than ``max_roughness`` draw a ray for the miss trace only:
        ``rough_trace`` and ``miss_trace`` on and SSR's own fallback (``miss``)."""
        return int(self.miss and int(self["miss_trace"]) > 0 and int(self["rough_trace"]) > 0)

    def _miss(self, rc, frame, size):
        """Second dispatch: the rays just stored, traced through the scene's BVH."""
        on = int(self["miss_trace"]) > 0
        if on:
            rt = rc.scene.rt()
            prog = rc.programs.compute("screen_space/ssr_miss.comp", {**rt.defines, **self.miss_defines})
            rt.bind(prog)
        else:
            prog = self.program(rc, "screen_space/ssr_miss.comp", {"SSR_MISS_OFF": 1})
        bind_frame(rc, prog, frame)
        bind_gbuffer(rc, prog, Units(1))
        # the rays were stored by the dispatch above: visible to this one's image loads
        rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT)
        rc.resources[RAY0].bind_to_image(0, read=True, write=False)
        rc.resources[RAY1].bind_to_image(1, read=True, write=False)
        rc.resources[MISS].bind_to_image(2, read=False, write=True)
        moving = frame.camera_changed and not frame.camera_cut  # a moving viewport: history capped short
        set_uniform(prog, "u_shade_samples", int(self["miss_samples_moving" if moving else "miss_samples"]))
        self.run(rc, prog, size)


def _levels(size) -> int:
    import math

    return int(math.floor(math.log2(max(size)))) + 1


class SSRResolvePass(ScreenPass):
    name = "ssr_resolve"
    params = (
        Param("resolve_samples", 6, 1, 16, "neighbour rays reused per pixel"),
        Param("max_roughness", 0.7, 0.0, 1.0, "rougher surfaces use the fallback"),
    )
    quality_ladder = ({"resolve_samples": 4}, {"resolve_samples": 6}, {"resolve_samples": 8},
                      {"resolve_samples": 12})
    reads = (RAY0, RAY1, DIRECT_RADIANCE, ALBEDO, NORMAL, POSITION, GEONORMAL)
    writes = (RESOLVED, HIT_DIST)
    declared = (Res(RESOLVED, dtype="f2", check="radiance"), Res(HIT_DIST, components=1, check="radiance"))
    history_resets = frozenset()

    def __init__(self, quality=None, *, miss: bool = False, trace: "SSRTracePass | None" = None, **kw):
        """miss: also write ``ssr.fallback`` from ``ssr.miss`` (see ssr_resolve.comp, SSR_MISS).
        trace: the trace pass whose ``rough_trace`` switch this resolve follows."""
        super().__init__(quality, **kw)
        self.miss = miss
        self.trace = trace
        if miss:
            self.reads = self.reads + (MISS, WORLD_SPEC)
            self.writes = self.writes + (FALLBACK, MISS_DIST)
            self.declared = self.declared + (Res(FALLBACK, check="radiance"),
                                             Res(MISS_DIST, components=1, check="radiance"))

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_space/ssr_resolve.comp", {"SSR_MISS": 1} if self.miss else None)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        res = rc.resources
        if self.miss:
            units.tex(prog, "u_miss", res[MISS])
            units.tex(prog, "u_world_spec", res[WORLD_SPEC])
            res[FALLBACK].bind_to_image(2, read=False, write=True)
            res[MISS_DIST].bind_to_image(3, read=False, write=True)
        units.tex(prog, "u_ray0", res[RAY0])
        units.tex(prog, "u_ray1", res[RAY1])
        units.tex(prog, "u_radiance", res[DIRECT_RADIANCE])
        set_uniform(prog, "u_resolve_samples", int(self["resolve_samples"]))
        set_uniform(prog, "u_max_roughness", float(self["max_roughness"]))
        set_uniform(prog, "u_rough_trace", self.trace.rough_on() if self.miss and self.trace is not None else 0)
        rc.resources[RESOLVED].bind_to_image(0, read=False, write=True)
        rc.resources[HIT_DIST].bind_to_image(1, read=False, write=True)
        self.run(rc, prog)


class SSRFallbackTemporalPass(TemporalPass):
    """The shared temporal accumulation (``TemporalPass``) of SSR's own fallback
    ``ssr.fallback``: the miss trace's one ray per pixel and frame, averaged over frames like
    the found share (``ssr_temporal``). While ``trace``'s ``miss_trace`` is 0 it keeps no
    history (every frame a reset: the output is this frame's ``aov.world_spec`` unchanged),
    and it restarts when ``miss_trace`` is switched. It is built with ``f12_pass_through``: in an
    F12 render the session's accumulator takes the plain mean of the frames' fallbacks
    (glossy_spheres q1, 96 px, 16 frames, five seeds: relMSE vs one_bounce 0.0157 +- 0.0024 ->
    0.0130 +- 0.0012; SSR.md)."""

    def __init__(self, quality=None, *, trace: SSRTracePass, **kw):
        super().__init__(quality, **kw)
        self.trace = trace
        self._was_on = None

    def execute(self, rc, frame):
        on = int(self.trace["miss_trace"]) > 0
        valid = self.history_valid
        if not on or on != self._was_on:
            self.history_valid = False
        self._was_on = on
        try:
            super().execute(rc, frame)
        finally:
            self.history_valid = valid

    def reset_history(self):
        super().reset_history()
        self._was_on = None


@register
class SSR(Technique):
    id = "SSR"
    label = "SSR (Hi-Z)"
    description = "Screen-space glossy reflections: Hi-Z ray marching, GGX importance sampling, ratio resolve"
    family = "screen_space"
    reference = "one_bounce"
    cost_rank = 20
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectGlossy": "ssr_composite.effect"}

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality), *ssr_passes(quality)]


def ssr_passes(quality, *, provides=SSR_PROVIDES, fallback: str = WORLD_SPEC,
               replaces: tuple[str, ...] | None = None, reproject_by_hit: bool = True,
               fallback_reproject: str = "miss", fallback_clamp: bool = True, miss_defines: dict | None = None) -> list:
    """SSR's own passes (Hi-Z, trace, resolve, temporal, composite), to follow DIRECT's.

    ``fallback``/``replaces`` go to the composite (see ``CompositePass``): the glossy light
    used for the share of the lobe not found on screen and the glossy terms already in
    ``color`` that SSR's result replaces (default ``(aov.world_spec,)``). Left at their
    defaults, the fallback is SSR's own miss trace ``ssr.fallback`` (``miss_trace``; off:
    DIRECT's shadowed world reflection ``aov.world_spec``). A probe technique passes its probe
    glossy resource as ``fallback`` (written before ``ssr_composite`` runs); then no miss
    trace runs.
    ``reproject_by_hit``: the temporal pass follows the reflected point (default) instead of
    the reflecting surface (kept for measuring the difference).
    ``fallback_reproject``: how SSR's own fallback's temporal pass (``ssr_fallback_temporal``)
    reprojects its history: ``"miss"`` by the virtual image point at the miss rays' mean
    distance (``ssr.miss_dist``, default), ``"surface"`` by the surface's motion, ``"none"``:
    no temporal pass (the fallback of one frame; kept for measuring the difference).
    ``fallback_clamp``: that pass clamps its history to the 3x3 neighbourhood of the current
    fallback while the camera moves (temporal.comp HISTORY_CLAMP).
    ``miss_defines``: extra defines of ``ssr_miss.comp`` (tests and benches, e.g.
    ``{"SSR_MISS_HIT_PARALLAX": 1}``: reproject a glossy hit's highlights by the hit point)."""
    p = provides
    # SSR's own fallback (the miss trace) only where the caller keeps the default one
    own = fallback == WORLD_SPEC and replaces is None
    trace = SSRTracePass(quality, provides=p, miss=own)
    if miss_defines:
        trace.miss_defines = dict(miss_defines)
    resolve = SSRResolvePass(quality, provides=p, max_roughness=trace["max_roughness"], miss=own, trace=trace)
    if fallback_reproject not in ("miss", "surface", "none"):
        raise ValueError(f"ssr_passes: fallback_reproject must be 'miss', 'surface' or 'none', got {fallback_reproject!r}")
    passes = [HiZPass(quality, provides=p), trace, resolve,
              TemporalPass(quality, name="ssr_temporal", source=RESOLVED, output="ssr.temporal",
                           background=(0.0, 0.0, 0.0, 1.0), provides=p, max_history=16,
                           hit_distance=HIT_DIST if reproject_by_hit else None)]
    if own and fallback_reproject == "none":
        fallback = FALLBACK
    elif own:
        fallback = FALLBACK_TEMPORAL
        passes.append(SSRFallbackTemporalPass(quality, name="ssr_fallback_temporal", trace=trace, source=FALLBACK,
                                              output=FALLBACK_TEMPORAL, background=(0.0, 0.0, 0.0, 1.0),
                                              provides=p, max_history=16, max_history_moving=4,
                                              clamp=fallback_clamp, f12_pass_through=True,
                                              hit_distance=MISS_DIST if fallback_reproject == "miss" else None))
    return passes + [CompositePass(quality, name="ssr_composite", mode="SSR", signal="ssr.temporal", provides=p,
                                   fallback=fallback, replaces=replaces)]
