"""Screen probes: radiance probes placed on the surfaces the camera sees, one per screen tile,
and the passes that trace, integrate, filter and gather them (GI10 after GI-1.0, Boissé et
al. 2023; SCREEN_PROBES after Lumen's final gather can share them). The shaders'
``screen_probes/common.glsl`` documents the storage and the ray directions.

A ``ScreenProbes`` object is shared by the passes of one graph (``screen_probe_chain``):

``ScreenProbePlacePass`` (``sp_place``, screen_probes/place.comp): keeps last frame's probe of
a tile when it reprojects onto the same surface (its SH history comes along), else spawns a
new one at a hashed pixel of the tile; a kept probe is refreshed (traced) once in ``refresh``
frames (a quarter of the probes per frame for 4) and every frame until it has
``spawn_traces`` traces (the spawn queue). ``ScreenProbeTracePass`` (``sp_trace``): the rays of
the probes that trace, ``res`` × ``res`` per probe over the hemisphere of its normal, hits
shaded with their direct light plus the world radiance cache's irradiance (passes/
radiance_cache.py) for the later bounces. ``ScreenProbeIntegratePass`` (``sp_integrate``): rays →
2-band SH, blended with the probe's history (``min_blend``, faster on luminance change).
``ScreenProbeFilterPass`` (``sp_filter``): mean over the neighbours in the probe's plane.
``ScreenProbeGatherPass`` (``sp_gather``): per pixel, the 2×2 probes around it weighted by plane
and normal, the cache where they fail; ``color += kd E/π + ks E(R)/π``; render passes
GI_IndirectDiffuse, GI_IndirectGlossy and the debug views GI_ScreenProbes, GI_CacheOccupancy.

History: probes and their SH are graph-owned history, reset on a camera cut and a parameter
change; scene edits are followed by reprojection (a probe whose surface moved away is
replaced) and the luminance-driven blend.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION
from .radiance_cache import ENTRIES, IRR as CACHE_IRR, RadianceCache, settling
from .screen_space import GBUFFER_BOUND, Units, bind_frame, bind_gbuffer

COLOR = "color"
POS, NRM, SRC = "sp.pos", "sp.nrm", "sp.src"
# per probe: 2-band SH of radiance per colour channel, and the irradiance at its own normal
SH = ("sp.sh_r", "sp.sh_g", "sp.sh_b", "sp.irr")
FILT = ("sp.filt_r", "sp.filt_g", "sp.filt_b", "sp.filt_irr")
_SH_UNI = ("u_sh_r", "u_sh_g", "u_sh_b", "u_sh_n")
ATLAS = "sp.atlas"
EFFECT, DIFFUSE, GLOSSY = "sp_gather.effect", "sp.diffuse", "sp.glossy"
VIEW_PROBES, VIEW_CACHE = "sp.view_probes", "sp.view_cache"
PREV = "@prev"
SP_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE})
SP_PROVIDES = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR})

SP_OUTPUTS = {"GI_IndirectDiffuse": DIFFUSE, "GI_IndirectGlossy": GLOSSY, "GI_ScreenProbes": VIEW_PROBES,
              "GI_CacheOccupancy": VIEW_CACHE}

PLACE_PARAMS = (
    Param("tile", 16, 4, 64, "pixels per probe tile side (one probe per tile)"),
    Param("res", 8, 4, 16, "rays per probe side (res x res rays over the hemisphere)"),
    Param("refresh", 4, 1, 16, "a kept probe traces once in this many frames (4: a quarter per frame)"),
    Param("spawn_traces", 4, 1, 64, "a probe traces every frame until it has this many traces"),
    Param("plane_tol", 0.05, 0.001, 1.0, "plane distance a probe may have from a surface it serves (fraction of the view depth)"),
)


class ScreenProbes:
    """Shared state of a graph's screen-probe passes."""

    def __init__(self, cache: RadianceCache | None):
        self.cache = cache
        self.place_pass: "ScreenProbePlacePass | None" = None
        self.frame = 0

    @property
    def tile(self) -> int:
        return int(self.place_pass["tile"])

    @property
    def res(self) -> int:
        return int(self.place_pass["res"])

    def grid(self, rc) -> tuple[int, int]:
        t = self.tile
        return (-(-rc.width // t), -(-rc.height // t))

    def bind(self, rc, prog, frame):
        bind_frame(rc, prog, frame)
        set_uniform(prog, "u_sp_tile", self.tile)
        set_uniform(prog, "u_sp_res", self.res)
        set_uniform(prog, "u_sp_grid", self.grid(rc))
        set_uniform(prog, "u_sp_frame", int(self.frame) & 0xFFFFFFFF)
        set_uniform(prog, "u_sp_plane_tol", float(self.place_pass["plane_tol"]))

    def bytes(self, size) -> int:
        pw, ph = (-(-int(size[0]) // self.tile), -(-int(size[1]) // self.tile))
        probes = pw * ph
        return probes * 16 * (2 * 2 + 2 * 3 + 3 + 1) + probes * 4 + probes * self.res ** 2 * 16


class _SPPass(Pass):
    kind = "compute"
    history_resets = SP_RESETS

    def __init__(self, probes: ScreenProbes, quality=None, *, provides=SP_PROVIDES, **props):
        super().__init__(quality, **props)
        self.probes = probes
        self.provides = frozenset(provides)

    def tiled(self, name, per_tile=1, **kw):
        return Res(name, tile=self.probes.tile, per_tile=per_tile, **kw)

    def program(self, rc, shader, frame, *, rt=False):
        if rt:
            r = rc.scene.rt()
            prog = rc.programs.compute(shader, r.defines)
            r.bind(prog)
        else:
            prog = rc.programs.compute(shader)
            rc.scene.bind(prog)
        self.probes.bind(rc, prog, frame)
        return prog

    def groups(self, rc, per_tile=1):
        pw, ph = self.probes.grid(rc)
        return (pw * per_tile + 7) // 8, (ph * per_tile + 7) // 8


class ScreenProbePlacePass(_SPPass):
    name = "sp_place"
    params = PLACE_PARAMS
    quality_ladder = ({"tile": 32}, {"tile": 16}, {"tile": 12}, {"tile": 8, "res": 12})
    reads = (POSITION, NORMAL, GEONORMAL, POS + PREV, NRM + PREV)
    optional_reads = GBUFFER_BOUND
    writes = (POS, NRM, SRC)

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        probes.place_pass = self

    def resources(self):
        return (self.tiled(POS, history=True), self.tiled(NRM, history=True),
                self.tiled(SRC, components=1, dtype="i4", check="none"))

    def execute(self, rc, frame):
        self.probes.frame += 1
        prog = self.program(rc, "screen_probes/place.comp", frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        units.tex(prog, "u_prev_pos", rc.resources[POS + PREV])
        units.tex(prog, "u_prev_nrm", rc.resources[NRM + PREV])
        set_uniform(prog, "u_history", 1 if self.history_valid else 0)
        # an F12 render's warm-up frames are thrown away: every probe traces in them, so the
        # accumulation starts from converged probes; the viewport keeps the refresh schedule
        set_uniform(prog, "u_sp_refresh", 1 if frame.warmup else int(self["refresh"]))
        set_uniform(prog, "u_sp_spawn_traces", float(self["spawn_traces"]))
        for b, n in enumerate((POS, NRM, SRC)):
            rc.resources[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeTracePass(_SPPass):
    name = "sp_trace"
    reads = (POS, NRM)

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        self.writes = (ATLAS,)
        if probes.cache is not None:
            self.reads = self.reads + (ENTRIES, CACHE_IRR)
            self.writes = self.writes + (ENTRIES,)

    def resources(self):
        return (self.tiled(ATLAS, per_tile=self.probes.res, check="radiance"),)

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_probes/trace.comp", frame, rt=True)
        units = Units(1)
        units.tex(prog, "u_sp_pos", rc.resources[POS])
        units.tex(prog, "u_sp_nrm", rc.resources[NRM])
        cache = self.probes.cache
        set_uniform(prog, "u_cache", 1 if cache is not None else 0)
        if cache is not None:
            cache.bind(rc, prog)
        world = rc.scene.scene.world
        set_uniform(prog, "u_world_light", 1 if world is not None and max(world.color) > 0 else 0)
        rc.resources[ATLAS].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc, self.probes.res))


class ScreenProbeIntegratePass(_SPPass):
    name = "sp_integrate"
    params = (
        Param("min_blend", 0.05, 0.001, 1.0, "smallest weight of a trace (history at most 1 - this: GI-1.0's 0.95 cap)"),
        Param("warmup_blend", 0.5, 0.0, 1.0, "smallest weight of a trace during an F12 render's warm-up and for 8 frames "
              "after an edit of the lights, materials or geometry (a short window "
              "while the world cache's later bounces build up)"),
        Param("fast_blend", 0.5, 0.0, 1.0, "weight of a trace whose irradiance moved by more than change_threshold"),
        Param("change_threshold", 0.8, 0.0, 100.0, "relative luminance change that counts as the light changing"),
    )
    reads = (POS, NRM, SRC, ATLAS) + tuple(n + PREV for n in SH)
    writes = SH

    def resources(self):
        return tuple(self.tiled(n, history=True) for n in SH)

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_probes/integrate.comp", frame)
        units = Units(1)
        res = rc.resources
        for uni, n in (("u_sp_pos", POS), ("u_sp_nrm", NRM), ("u_sp_src", SRC), ("u_sp_atlas", ATLAS)):
            units.tex(prog, uni, res[n])
        for uni, n in zip(_SH_UNI, SH):
            units.tex(prog, "u_prev" + uni[1:], res[n + PREV])
        for k in ("fast_blend", "change_threshold"):
            set_uniform(prog, "u_sp_" + k, float(self[k]))
        blend = max(float(self["min_blend"]), float(self["warmup_blend"]) if settling(self, frame) else 0.0)
        set_uniform(prog, "u_sp_min_blend", blend)
        for b, n in enumerate(SH):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeFilterPass(_SPPass):
    name = "sp_filter"
    params = (Param("radius", 1, 0, 3, "neighbour probes on each side the spatial filter averages (0: off)"),)
    reads = (POS, NRM) + SH
    writes = FILT

    def resources(self):
        return tuple(self.tiled(n) for n in FILT)

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_probes/filter.comp", frame)
        units = Units(1)
        res = rc.resources
        for uni, n in (("u_sp_pos", POS), ("u_sp_nrm", NRM), *zip(_SH_UNI, SH)):
            units.tex(prog, uni, res[n])
        set_uniform(prog, "u_radius", int(self["radius"]))
        for b, n in enumerate(FILT):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeGatherPass(_SPPass):
    name = "sp_gather"
    params = (
        Param("min_weight", 0.05, 0.0, 1.0, "probe weight below which the world cache fills in (interpolation failed)"),
        Param("glossy", 1, 0, 1, "1: glossy indirect light from the probes in the mirror direction"),
        Param("debug_views", 1, 0, 1, "write the debug render passes (probe placement, cache occupancy)"),
    )
    optional_reads = GBUFFER_BOUND

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        self.reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, POS, NRM) + FILT
        self.writes = (COLOR, EFFECT, DIFFUSE, GLOSSY, VIEW_PROBES, VIEW_CACHE)
        if probes.cache is not None:
            self.reads += (ENTRIES, CACHE_IRR)
            self.writes += (ENTRIES,)
        self.history_resets = frozenset()

    def resources(self):
        return tuple(Res(n, check="radiance") for n in (EFFECT, DIFFUSE, GLOSSY, VIEW_PROBES, VIEW_CACHE))

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_probes/gather.comp", frame, rt=True)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        res = rc.resources
        for uni, n in (("u_sp_pos", POS), ("u_sp_nrm", NRM), *zip(_SH_UNI, FILT)):
            units.tex(prog, uni, res[n])
        cache = self.probes.cache
        set_uniform(prog, "u_cache", 1 if cache is not None else 0)
        if cache is not None:
            cache.bind(rc, prog)
        set_uniform(prog, "u_min_weight", float(self["min_weight"]))
        set_uniform(prog, "u_glossy", int(self["glossy"]))
        debug = int(self["debug_views"]) == 1
        set_uniform(prog, "u_debug", 1 if debug else 0)
        res[COLOR].bind_to_image(0, read=True, write=True)
        for b, n in enumerate((EFFECT, DIFFUSE, GLOSSY, VIEW_PROBES, VIEW_CACHE), start=1):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
        if not debug:
            for n in (VIEW_PROBES, VIEW_CACHE):
                rc.clear_resource(n)


def screen_probe_chain(quality, cache: RadianceCache | None, **params) -> list:
    """The five passes of a screen-probe technique sharing one ``ScreenProbes``. ``params``:
    per pass name, a dict of properties."""
    sp = ScreenProbes(cache)
    kinds = (ScreenProbePlacePass, ScreenProbeTracePass, ScreenProbeIntegratePass, ScreenProbeFilterPass,
             ScreenProbeGatherPass)
    return [k(sp, quality, **params.get(k.name, {})) for k in kinds]


def read_screen_probes(rc, probes: ScreenProbes) -> dict:
    """Per-probe values for tests and benchmarks (GL thread, after the graph's barriers):
    ``state`` (PH, PW) 0 none / 1 kept / 2 refreshed / 3 new, ``traces``, ``positions``
    (PH, PW, 3), ``irradiance`` (PH, PW, 3) at each probe's normal (its history, unfiltered)."""
    names = [POS, NRM, *SH]
    rc.barrier_external(names)

    def read(n):
        t = rc.resources[n]
        w, h = t.size
        return np.frombuffer(t.read(), np.float32).reshape(h, w, 4).copy()

    pos, nrm = read(POS), read(NRM)
    irr = read(SH[3])[..., :3]
    return {"state": pos[..., 3].round().astype(int), "traces": nrm[..., 3].copy(), "positions": pos[..., :3],
            "irradiance": np.maximum(irr, 0.0)}
