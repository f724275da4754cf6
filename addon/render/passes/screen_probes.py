"""Screen probes: radiance probes placed on the surfaces the camera sees, one per screen tile,
and the passes that trace, integrate, filter and gather them (GI10 after GI-1.0, Boissé et
al. 2023; SCREEN_PROBES after Lumen's final gather, with importance sampling and adaptive
probes). The shaders' ``screen_probes/common.glsl`` documents the storage and the ray
directions.

A ``ScreenProbes`` object (one probe set, its resources named under a prefix: ``sp`` for the
probes, ``spa`` for SCREEN_PROBES' adaptive set) is shared by the passes of one graph
(``screen_probe_chain``):

``ScreenProbePlacePass`` (``sp_place``, screen_probes/place.comp): keeps last frame's probe of
a tile when it reprojects onto the same surface (its SH history comes along), else spawns a
new one at a hashed pixel of the tile; a kept probe is refreshed (traced) once in ``refresh``
frames (a quarter of the probes per frame for 4) and every frame until it has
``spawn_traces`` traces (the spawn queue). ``ScreenProbeTracePass`` (``sp_trace``): the rays of
the probes that trace, ``res`` × ``res`` per probe over the hemisphere of its normal, hits
shaded with their direct light plus the world radiance cache's irradiance (passes/
radiance_cache.py) for the later bounces. ``ScreenProbeIntegratePass`` (``sp_integrate``): rays →
2-band SH and the irradiance at the probe's normal, blended with the probe's history
(``min_blend``, faster on luminance change; importance-sampled rays weighted by their pdf).
``ScreenProbeFilterPass`` (``sp_filter``): mean over the neighbours in the probe's plane.
``ScreenProbeGatherPass`` (``sp_gather``): per pixel, the 2×2 probes around it weighted by plane
and normal, then the adaptive probes, then the cache where they fail; ``color += kd E/π + ks E(R)/π``; render passes
GI_IndirectDiffuse, GI_IndirectGlossy and the debug views GI_ScreenProbes, GI_CacheOccupancy.

History: probes and their SH are graph-owned history, reset on a camera cut and a parameter
change; scene edits are followed by reprojection (a probe whose surface moved away is
replaced), the luminance-driven blend, and for 8 frames after a light, material or geometry
edit the short blending window of the F12 warm-up (radiance_cache.settling).
"""
from __future__ import annotations

import numpy as np

from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION
from .radiance_cache import ENTRIES, IRR as CACHE_IRR, RadianceCache, reset_settling, settling
from .screen_space import GBUFFER_BOUND, Units, bind_frame, bind_gbuffer, bind_world_light

COLOR = "color"
EFFECT, DIFFUSE, GLOSSY = "sp_gather.effect", "sp.diffuse", "sp.glossy"
VIEW_PROBES, VIEW_CACHE = "sp.view_probes", "sp.view_cache"
PREV = "@prev"
SP_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE})
SP_PROVIDES = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR})
_SH_UNI = ("u_sh_r", "u_sh_g", "u_sh_b", "u_sh_n")

SP_OUTPUTS = {"GI_IndirectDiffuse": DIFFUSE, "GI_IndirectGlossy": GLOSSY, "GI_ScreenProbes": VIEW_PROBES,
              "GI_CacheOccupancy": VIEW_CACHE}

PLACE_PARAMS = (
    Param("tile", 16, 4, 64, "pixels per probe tile side (one probe per tile; adaptive probes: half)"),
    Param("res", 8, 4, 16, "rays per probe side (res x res rays over the hemisphere)"),
    Param("refresh", 4, 1, 16, "a kept probe traces once in this many frames (4: a quarter per frame)"),
    Param("spawn_traces", 4, 1, 64, "a probe traces every frame until it has this many traces"),
    Param("plane_tol", 0.05, 0.001, 1.0, "plane distance a probe may have from a surface it serves (fraction of the view depth)"),
)


class ScreenProbes:
    """One set of screen probes shared by its passes: resource names under ``prefix``
    (``sp.pos``, ``sp.sh_r``, ...), the tile size, the ray count. ``importance``: rays drawn
    from the cosine and last frame's light (SCREEN_PROBES). ``coarse``: this set is the
    adaptive refinement of that one (tiles of half its size, probes only where its probes fail
    to interpolate)."""

    def __init__(self, cache: RadianceCache | None, prefix: str = "sp", *, importance: bool = False,
                 coarse: "ScreenProbes | None" = None):
        self.cache = cache
        self.prefix = prefix
        self.importance = bool(importance)
        self.coarse = coarse
        self.fine: "ScreenProbes | None" = None
        if coarse is not None:
            coarse.fine = self
        self.place_pass: "ScreenProbePlacePass | None" = None
        self.frame = 0
        self.pos, self.nrm, self.src, self.atlas = (f"{prefix}.{n}" for n in ("pos", "nrm", "src", "atlas"))
        # per probe: 2-band SH of radiance per colour channel, and the irradiance at its own normal
        self.sh = tuple(f"{prefix}.{n}" for n in ("sh_r", "sh_g", "sh_b", "irr"))
        self.filt = tuple(f"{prefix}.{n}" for n in ("filt_r", "filt_g", "filt_b", "filt_irr"))

    @property
    def tile(self) -> int:
        if self.coarse is not None:
            return max(4, self.coarse.tile // 2)
        return int(self.place_pass["tile"])

    @property
    def res(self) -> int:
        return int(self.place_pass["res"])

    def grid(self, rc) -> tuple[int, int]:
        t = self.tile
        return (-(-rc.width // t), -(-rc.height // t))

    def defines(self) -> dict:
        return {"SP_ADAPTIVE": 1} if self.coarse is not None else {}

    def bind(self, rc, prog, frame):
        bind_frame(rc, prog, frame)
        set_uniform(prog, "u_sp_tile", self.tile)
        set_uniform(prog, "u_sp_res", self.res)
        set_uniform(prog, "u_sp_grid", self.grid(rc))
        set_uniform(prog, "u_sp_frame", int(self.frame) & 0xFFFFFFFF)
        set_uniform(prog, "u_sp_plane_tol", float(self.place_pass["plane_tol"]))
        set_uniform(prog, "u_sp_importance", 1 if self.importance else 0)

    def bytes(self, size) -> int:
        pw, ph = (-(-int(size[0]) // self.tile), -(-int(size[1]) // self.tile))
        probes = pw * ph
        # pos, nrm and 4 SH/irradiance textures double-buffered, 4 filtered, src; the ray atlas
        return probes * (16 * (2 * 6 + 4) + 4) + probes * self.res ** 2 * 16


class _SPPass(Pass):
    kind = "compute"
    history_resets = SP_RESETS
    stage = ""

    def __init__(self, probes: ScreenProbes, quality=None, *, provides=SP_PROVIDES, **props):
        super().__init__(quality, **props)
        self.probes = probes
        self.provides = frozenset(provides)
        self.name = f"{probes.prefix}_{self.stage}"

    def reset_history(self):
        super().reset_history()
        reset_settling(self)

    def tiled(self, name, per_tile=1, **kw):
        return Res(name, tile=self.probes.tile, per_tile=per_tile, **kw)

    def program(self, rc, shader, frame, *, rt=False, defines=None):
        d = {**self.probes.defines(), **(defines or {})}
        if rt:
            r = rc.scene.rt()
            prog = rc.programs.compute(shader, {**r.defines, **d})
            r.bind(prog)
        else:
            prog = rc.programs.compute(shader, d)
            rc.scene.bind(prog)
        self.probes.bind(rc, prog, frame)
        return prog

    def groups(self, rc, per_tile=1):
        pw, ph = self.probes.grid(rc)
        return (pw * per_tile + 7) // 8, (ph * per_tile + 7) // 8


class ScreenProbePlacePass(_SPPass):
    stage = "place"
    params = PLACE_PARAMS
    quality_ladder = ({"tile": 32}, {"tile": 16}, {"tile": 12}, {"tile": 8, "res": 12})
    optional_reads = GBUFFER_BOUND

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        probes.place_pass = self
        sp = probes
        self.reads = (POSITION, NORMAL, GEONORMAL, sp.pos + PREV, sp.nrm + PREV)
        if sp.coarse is not None:
            self.reads += (sp.coarse.pos, sp.coarse.nrm)
        self.writes = (sp.pos, sp.nrm, sp.src)

    def resources(self):
        sp = self.probes
        return (self.tiled(sp.pos, history=True), self.tiled(sp.nrm, history=True),
                self.tiled(sp.src, components=1, dtype="i4", check="none"))

    def reset_history(self):
        super().reset_history()
        self.probes.frame = 0  # the probes start over: their refresh pattern and rays with them

    def execute(self, rc, frame):
        sp = self.probes
        sp.frame += 1
        prog = self.program(rc, "screen_probes/place.comp", frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        units.tex(prog, "u_prev_pos", rc.resources[sp.pos + PREV])
        units.tex(prog, "u_prev_nrm", rc.resources[sp.nrm + PREV])
        if sp.coarse is not None:
            units.tex(prog, "u_coarse_pos", rc.resources[sp.coarse.pos])
            units.tex(prog, "u_coarse_nrm", rc.resources[sp.coarse.nrm])
            set_uniform(prog, "u_coarse_tile", sp.coarse.tile)
            set_uniform(prog, "u_coarse_grid", sp.coarse.grid(rc))
            set_uniform(prog, "u_min_weight", float(sp.gather_pass["min_weight"]))
        set_uniform(prog, "u_history", 1 if self.history_valid else 0)
        # an F12 render's warm-up frames are thrown away: every probe traces in them, so the
        # accumulation starts from converged probes; the viewport keeps the refresh schedule
        set_uniform(prog, "u_sp_refresh", 1 if frame.warmup else int(self["refresh"]))
        set_uniform(prog, "u_sp_spawn_traces", float(self["spawn_traces"]))
        for b, n in enumerate((sp.pos, sp.nrm, sp.src)):
            rc.resources[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeTracePass(_SPPass):
    stage = "trace"

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        sp = probes
        self.reads = (sp.pos, sp.nrm)
        if sp.importance:
            self.reads += (sp.src,) + tuple(n + PREV for n in sp.sh[:3])
        self.writes = (sp.atlas,)
        if sp.cache is not None:
            self.reads = self.reads + (ENTRIES, CACHE_IRR)
            self.writes = self.writes + (ENTRIES,)

    def resources(self):
        return (self.tiled(self.probes.atlas, per_tile=self.probes.res, check="radiance"),)

    def execute(self, rc, frame):
        sp = self.probes
        prog = self.program(rc, "screen_probes/trace.comp", frame, rt=True)
        units = Units(1)
        units.tex(prog, "u_sp_pos", rc.resources[sp.pos])
        units.tex(prog, "u_sp_nrm", rc.resources[sp.nrm])
        if sp.importance:
            units.tex(prog, "u_sp_src", rc.resources[sp.src])
            for uni, n in zip(_SH_UNI[:3], sp.sh[:3]):
                units.tex(prog, "u_prev" + uni[1:], rc.resources[n + PREV])
        cache = sp.cache
        set_uniform(prog, "u_cache", 1 if cache is not None else 0)
        if cache is not None:
            cache.bind(rc, prog)
        bind_world_light(rc.scene.scene, prog)
        rc.resources[sp.atlas].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc, sp.res))


class ScreenProbeIntegratePass(_SPPass):
    stage = "integrate"
    params = (
        Param("min_blend", 0.05, 0.001, 1.0, "smallest weight of a trace (history at most 1 - this: GI-1.0's 0.95 cap)"),
        Param("warmup_blend", 0.5, 0.0, 1.0, "smallest weight of a trace during an F12 render's warm-up and for 8 frames "
              "after an edit of the lights, materials or geometry (a short window while the world cache's later bounces build up)"),
        Param("fast_blend", 0.5, 0.0, 1.0, "weight of a trace whose irradiance moved by more than change_threshold"),
        Param("change_threshold", 0.8, 0.0, 100.0, "relative luminance change that counts as the light changing"),
    )

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        sp = probes
        self.reads = (sp.pos, sp.nrm, sp.src, sp.atlas) + tuple(n + PREV for n in sp.sh)
        self.writes = sp.sh

    def resources(self):
        return tuple(self.tiled(n, history=True) for n in self.probes.sh)

    def execute(self, rc, frame):
        sp = self.probes
        prog = self.program(rc, "screen_probes/integrate.comp", frame)
        units = Units(1)
        res = rc.resources
        for uni, n in (("u_sp_pos", sp.pos), ("u_sp_nrm", sp.nrm), ("u_sp_src", sp.src), ("u_sp_atlas", sp.atlas)):
            units.tex(prog, uni, res[n])
        for uni, n in zip(_SH_UNI, sp.sh):
            units.tex(prog, "u_prev" + uni[1:], res[n + PREV])
        for k in ("fast_blend", "change_threshold"):
            set_uniform(prog, "u_sp_" + k, float(self[k]))
        blend = max(float(self["min_blend"]), float(self["warmup_blend"]) if settling(self, frame) else 0.0)
        set_uniform(prog, "u_sp_min_blend", blend)
        for b, n in enumerate(sp.sh):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeFilterPass(_SPPass):
    stage = "filter"
    params = (Param("radius", 1, 0, 3, "neighbour probes on each side the spatial filter averages (0: off)"),)

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        sp = probes
        self.reads = (sp.pos, sp.nrm) + sp.sh
        self.writes = sp.filt

    def resources(self):
        return tuple(self.tiled(n) for n in self.probes.filt)

    def execute(self, rc, frame):
        sp = self.probes
        prog = self.program(rc, "screen_probes/filter.comp", frame)
        units = Units(1)
        res = rc.resources
        for uni, n in (("u_sp_pos", sp.pos), ("u_sp_nrm", sp.nrm), *zip(_SH_UNI, sp.sh)):
            units.tex(prog, uni, res[n])
        set_uniform(prog, "u_radius", int(self["radius"]))
        for b, n in enumerate(sp.filt):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *self.groups(rc))


class ScreenProbeGatherPass(_SPPass):
    stage = "gather"
    params = (
        Param("min_weight", 0.05, 0.0, 1.0, "probe weight below which the adaptive probes, then the world cache, fill in"),
        Param("glossy", 1, 0, 1, "1: glossy indirect light from the probes in the mirror direction"),
        Param("debug_views", 1, 0, 1, "write the debug render passes (probe placement, cache occupancy)"),
    )
    optional_reads = GBUFFER_BOUND

    def __init__(self, probes, quality=None, **kw):
        super().__init__(probes, quality, **kw)
        probes.gather_pass = self
        sp = probes
        self.reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, sp.pos, sp.nrm) + sp.filt
        self.writes = (COLOR, EFFECT, DIFFUSE, GLOSSY, VIEW_PROBES, VIEW_CACHE)
        if sp.cache is not None:
            self.reads += (ENTRIES, CACHE_IRR)
            self.writes += (ENTRIES,)
        self.history_resets = frozenset()

    def add_fine(self, fine: ScreenProbes):
        fine.gather_pass = self
        self.reads += (fine.pos, fine.nrm) + fine.filt

    def resources(self):
        return tuple(Res(n, check="radiance") for n in (EFFECT, DIFFUSE, GLOSSY, VIEW_PROBES, VIEW_CACHE))

    def execute(self, rc, frame):
        sp = self.probes
        fine = sp.fine
        prog = self.program(rc, "screen_probes/gather.comp", frame, rt=True,
                            defines={"SP_ADAPTIVE": 1} if fine is not None else None)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        res = rc.resources
        for uni, n in (("u_sp_pos", sp.pos), ("u_sp_nrm", sp.nrm), *zip(_SH_UNI, sp.filt)):
            units.tex(prog, uni, res[n])
        if fine is not None:
            for uni, n in (("u_fine_pos", fine.pos), ("u_fine_nrm", fine.nrm),
                           *zip(("u_fine_sh_r", "u_fine_sh_g", "u_fine_sh_b", "u_fine_sh_n"), fine.filt)):
                units.tex(prog, uni, res[n])
            set_uniform(prog, "u_fine_tile", fine.tile)
            set_uniform(prog, "u_fine_grid", fine.grid(rc))
        cache = sp.cache
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


_CHAIN = (ScreenProbePlacePass, ScreenProbeTracePass, ScreenProbeIntegratePass, ScreenProbeFilterPass)


def screen_probe_chain(quality, cache: RadianceCache | None, *, importance: bool = False, adaptive: bool = False,
                       **params) -> list:
    """The passes of a screen-probe technique: place, trace, integrate and filter for the
    probes (and, with ``adaptive``, again for the adaptive set ``spa``, placed after the coarse
    probes), then one gather. ``params``: per pass name, a dict of properties."""
    sp = ScreenProbes(cache, "sp", importance=importance)
    passes = [k(sp, quality, **params.get(f"sp_{k.stage}", {})) for k in _CHAIN]
    gather = ScreenProbeGatherPass(sp, quality, **params.get("sp_gather", {}))
    if adaptive:
        fine = ScreenProbes(cache, "spa", importance=importance, coarse=sp)
        fine_passes = [k(fine, quality, **params.get(f"spa_{k.stage}", {})) for k in _CHAIN]
        passes += fine_passes
        gather.add_fine(fine)
    return passes + [gather]


def find_probes(graph, prefix: str = "sp") -> "ScreenProbes | None":
    for p in getattr(graph, "passes", ()):
        if isinstance(p, ScreenProbePlacePass) and p.probes.prefix == prefix:
            return p.probes
    return None


def read_screen_probes(rc, probes: ScreenProbes) -> dict:
    """Per-probe values for tests and benchmarks (GL thread, after the graph's barriers):
    ``state`` (PH, PW) 0 none / 1 kept / 2 refreshed / 3 new, ``traces``, ``positions``
    (PH, PW, 3), ``irradiance`` (PH, PW, 3) at each probe's normal (its history, unfiltered)."""
    names = [probes.pos, probes.nrm, *probes.sh]
    rc.barrier_external(names)

    def read(n):
        t = rc.resources[n]
        w, h = t.size
        return np.frombuffer(t.read(), np.float32).reshape(h, w, 4).copy()

    pos, nrm = read(probes.pos), read(probes.nrm)
    irr = read(probes.sh[3])[..., :3]
    return {"state": pos[..., 3].round().astype(int), "traces": nrm[..., 3].copy(), "positions": pos[..., :3],
            "irradiance": np.maximum(irr, 0.0)}
