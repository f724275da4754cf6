"""Surfel GI: irradiance cached on surface elements spawned where the screen is poorly covered
(SURFEL, after EA SEED's GIBS, Halen, Brinck, Heitz et al. 2021, in the shape of its public
take in WickedEngine). ``shaders/surfels/common.glsl`` documents the storage.

Passes, each frame: ``surfel_prepare`` (after a reset: the pool emptied; then every live
surfel's world position from its instance's transform, the grid's counts cleared),
``surfel_grid`` (each surfel listed in the cells its sphere overlaps), ``surfel_spawn`` (one
candidate per screen tile: a surfel where coverage is low), ``surfel_update`` (rays from every
live surfel, the estimator, the depth moments; unseen surfels recycled), ``surfel_gather``
(per pixel: ``color += kd E / π``, the debug views), ``surfel_glossy`` (per glossy pixel: rays
from its GGX lobe, each hit shaded by its direct light and the surfels there; skipped by the
planner when no glossy surface is in view).

Buffers: ``surfels.pool`` (free stack + surfels, state across frames, emptied on a reset),
``surfels.cells`` (the grid, rebuilt every frame), ``surfels.state`` (irradiance estimator and
depth moments, graph-owned history). The pool's size is fixed (``capacity``): surfel counts
cannot run away; a full pool spawns nothing until unseen surfels are recycled.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import BUFFER, CAMERA_CUT, PARAM_CHANGE, SHADER_STORAGE_BARRIER_BIT, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION
from .radiance_cache import reset_settling, settling
from .screen_space import (GBUFFER_BOUND, WORLD_SPEC, Units, bind_frame, bind_gbuffer, bind_world_light,
                           camera_vectors)
from .shadows import WORLD_RANGE, world_light_range

COLOR = "color"
POOL, CELLS, STATE = "surfels.pool", "surfels.cells", "surfels.state"
EFFECT, VIEW_SURFELS, VIEW_COVERAGE = "surfel_gather.effect", "surfels.view", "surfels.view_coverage"
GLOSSY = "surfel_glossy.effect"
PREV = "@prev"
GRID, CASCADES, CELL_CAP, STATE_VEC4 = 16, 4, 32, 11   # surfels/common.glsl
SURFEL_BYTES = 80
BINDING_POOL, BINDING_CELLS, BINDING_STATE, BINDING_STATE_OUT = 18, 19, 20, 21
# a geometry or light-set edit changes which instances there are (surfels hold instance ids)
SURFEL_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", "light_set"})
SURFEL_PROVIDES = frozenset({Effect.INDIRECT_DIFFUSE})
SURFEL_OUTPUTS = {"GI_IndirectDiffuse": EFFECT, "GI_IndirectGlossy": GLOSSY, "GI_Surfels": VIEW_SURFELS,
                  "GI_SurfelCoverage": VIEW_COVERAGE}

SURFEL_PARAMS = (
    Param("capacity", 16384, 256, 262144, "surfels in the pool (fixed: counts cannot grow past it)"),
    Param("tile", 16, 4, 64, "screen tile (pixels) that spawns at most one surfel per frame"),
    Param("radius_px", 6.0, 1.0, 64.0, "a new surfel's radius, in pixels at its depth"),
    Param("coverage", 1.0, 0.0, 16.0, "summed surfel weight below which a pixel is uncovered"),
    Param("spawn_chance", 0.5, 0.0, 1.0, "chance per frame that an uncovered tile spawns"),
    Param("rays", 4, 1, 64, "rays per surfel per frame"),
    Param("ray_spawn_chance", 0.05, 0.0, 1.0, "chance that a surfel's ray meeting an uncovered surface spawns a surfel there"),
    Param("max_age", 60, 1, 10000, "frames a surfel survives unused by any pixel or surfel ray (then recycled)"),
    Param("mean_blend", 0.08, 0.001, 1.0, "smallest weight of a frame in the mean (the short window)"),
    Param("var_blend", 0.04, 0.001, 1.0, "smallest weight of a frame in the variance"),
    Param("warmup_blend", 0.5, 0.0, 1.0, "smallest weight of a frame in the mean during an F12 warm-up and after light edits"),
    Param("moment_blend", 0.2, 0.0, 1.0, "weight of a frame's ray distances in the depth moments"),
    Param("normal_power", 2.0, 0.0, 16.0, "exponent of the normals' agreement in a surfel's weight"),
    Param("cell_scale", 1.1, 0.1, 16.0, "cell size factor: 1 = the coarsest cascade just reaches the scene's farthest corner from the camera"),
)


class SurfelSet:
    """Host side of surfels/common.glsl, shared by the passes of one graph."""

    def __init__(self):
        self.owner: "SurfelPreparePass | None" = None
        self.frame = 0
        self.cell = 1.0
        self.center = np.zeros(3)

    @property
    def props(self) -> dict:
        return self.owner.props

    @property
    def capacity(self) -> int:
        return (int(self.props["capacity"]) + 3) // 4 * 4

    def defines(self) -> dict:
        return {"SF_CAPACITY": self.capacity}

    def pool_bytes(self) -> int:
        return 16 + 4 * self.capacity + SURFEL_BYTES * self.capacity

    def cells_bytes(self) -> int:
        n = GRID ** 3 * CASCADES
        return 4 * n * (1 + CELL_CAP)

    def state_bytes(self) -> int:
        return 16 * STATE_VEC4 * self.capacity

    def bytes(self) -> int:
        return self.pool_bytes() + self.cells_bytes() + 2 * self.state_bytes()

    def bind(self, rc, prog, *, state: str | None = STATE):
        set_uniform(prog, "u_sf_cell", float(self.cell))
        set_uniform(prog, "u_sf_center", tuple(float(x) for x in self.center))
        set_uniform(prog, "u_sf_frame", int(self.frame) & 0xFFFFFFFF)
        set_uniform(prog, "u_sf_normal_power", float(self.props["normal_power"]))
        rc.resources[POOL].bind_to_storage_buffer(BINDING_POOL)
        rc.resources[CELLS].bind_to_storage_buffer(BINDING_CELLS)
        if state is not None:
            rc.resources[state].bind_to_storage_buffer(BINDING_STATE)


class _SurfelPass(Pass):
    kind = "compute"
    history_resets = SURFEL_RESETS

    def __init__(self, surfels: SurfelSet, quality=None, **props):
        super().__init__(quality, **props)
        self.surfels = surfels
        self.provides = SURFEL_PROVIDES

    def reset_history(self):
        super().reset_history()
        reset_settling(self)

    def program(self, rc, shader, *, rt=False):
        d = self.surfels.defines()
        if rt:
            r = rc.scene.rt()
            prog = rc.programs.compute(shader, {**r.defines, **d})
            r.bind(prog)
        else:
            prog = rc.programs.compute(shader, d)
            rc.scene.bind(prog)
        return prog


class SurfelPreparePass(_SurfelPass):
    name = "surfel_prepare"
    params = SURFEL_PARAMS
    quality_ladder = ({"capacity": 4096, "rays": 2, "radius_px": 8.0}, {"capacity": 16384},
                      {"capacity": 32768, "rays": 8, "radius_px": 5.0}, {"capacity": 65536, "rays": 16, "radius_px": 4.0})

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        surfels.owner = self
        self.reads = ()
        self.writes = (POOL, CELLS)
        self._empty = True

    def resources(self):
        sf = self.surfels
        return (Res(POOL, kind=BUFFER, size=sf.pool_bytes(), check="none"),
                Res(CELLS, kind=BUFFER, size=sf.cells_bytes(), check="none"))

    def reset_history(self):
        super().reset_history()
        self._empty = True
        self.surfels.frame = 0  # the pool empties: ages and spawn seeds start over with it

    def execute(self, rc, frame):
        sf = self.surfels
        lo, hi = (np.asarray(v, np.float64) for v in rc.scene.scene.world_bounds())
        cam = camera_vectors(frame)[0]
        # the coarsest cascade reaches the farthest corner of the scene from the camera
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        reach = float(np.max(np.linalg.norm(corners - cam, axis=1)))
        sf.cell = max(reach, 1e-6) / (0.5 * GRID * 2 ** (CASCADES - 1)) * float(self["cell_scale"])
        snap = sf.cell * 2 ** (CASCADES - 1)
        sf.center = np.floor(cam / snap) * snap
        sf.frame += 1
        rt = rc.scene.rt()
        prog = rc.programs.compute("surfels/prepare.comp", {**rt.defines, **sf.defines()})
        rt.bind(prog)
        sf.bind(rc, prog, state=None)
        n = max(sf.capacity, GRID ** 3 * CASCADES)
        set_uniform(prog, "u_sf_max_age", int(self["max_age"]))
        if self._empty:
            set_uniform(prog, "u_stage", 0)
            rc.dispatch(prog, (sf.capacity + 63) // 64)
            rc.ctx.memory_barrier(SHADER_STORAGE_BARRIER_BIT)  # in-pass: the next stage reads the emptied pool
            self._empty = False
        set_uniform(prog, "u_stage", 1)
        rc.dispatch(prog, (n + 63) // 64)


class SurfelGridPass(_SurfelPass):
    name = "surfel_grid"

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        self.reads = (POOL,)
        self.writes = (CELLS,)

    def execute(self, rc, frame):
        sf = self.surfels
        prog = self.program(rc, "surfels/grid.comp")
        sf.bind(rc, prog, state=None)
        rc.dispatch(prog, (sf.capacity + 63) // 64)


class SurfelSpawnPass(_SurfelPass):
    name = "surfel_spawn"
    optional_reads = GBUFFER_BOUND

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        self.reads = (POSITION, NORMAL, GEONORMAL, CELLS, STATE + PREV)
        self.writes = (POOL,)

    def execute(self, rc, frame):
        sf = self.surfels
        p = sf.props
        prog = self.program(rc, "surfels/spawn.comp", rt=True)
        bind_frame(rc, prog, frame)
        sf.bind(rc, prog, state=STATE + PREV)
        bind_gbuffer(rc, prog, Units(1))
        tile = int(p["tile"])
        set_uniform(prog, "u_sf_tile", tile)
        set_uniform(prog, "u_sf_coverage", float(p["coverage"]))
        set_uniform(prog, "u_sf_spawn_chance", 1.0 if frame.warmup else float(p["spawn_chance"]))
        set_uniform(prog, "u_sf_radius_px", float(p["radius_px"]))
        tx, ty = -(-rc.width // tile), -(-rc.height // tile)
        rc.dispatch(prog, (tx + 7) // 8, (ty + 7) // 8)


class SurfelUpdatePass(_SurfelPass):
    name = "surfel_update"

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        self.reads = (CELLS, STATE + PREV)
        self.writes = (POOL, STATE)

    def resources(self):
        return (Res(STATE, kind=BUFFER, size=self.surfels.state_bytes(), history=True, check="finite"),)

    def execute(self, rc, frame):
        sf = self.surfels
        p = sf.props
        prog = self.program(rc, "surfels/update.comp", rt=True)
        sf.bind(rc, prog, state=STATE + PREV)
        rc.resources[STATE].bind_to_storage_buffer(BINDING_STATE_OUT)
        set_uniform(prog, "u_sf_rays", int(p["rays"]))
        set_uniform(prog, "u_sf_max_age", int(p["max_age"]))
        mean = max(float(p["mean_blend"]), float(p["warmup_blend"]) if settling(self, frame) else 0.0)
        set_uniform(prog, "u_sf_mean_blend", mean)
        set_uniform(prog, "u_sf_var_blend", float(p["var_blend"]))
        set_uniform(prog, "u_sf_moment_blend", float(p["moment_blend"]))
        # F12 warm-up frames are thrown away: surfels spawn freely in them (screen and rays)
        set_uniform(prog, "u_sf_ray_spawn_chance", max(float(p["ray_spawn_chance"]), 0.5 if frame.warmup else 0.0))
        set_uniform(prog, "u_sf_radius_px", float(p["radius_px"]))
        bind_frame(rc, prog, frame)
        set_uniform(prog, "u_seed", int(frame.sample) & 0xFFFFFFFF)
        bind_world_light(rc.scene.scene, prog)
        rc.dispatch(prog, (sf.capacity + 63) // 64)


class SurfelGatherPass(_SurfelPass):
    name = "surfel_gather"
    params = (Param("debug_views", 1, 0, 1, "write the debug render passes (surfels, coverage)"),)
    optional_reads = GBUFFER_BOUND

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        self.reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, CELLS, STATE)
        self.writes = (COLOR, POOL, EFFECT, VIEW_SURFELS, VIEW_COVERAGE)
        self.history_resets = frozenset()

    def resources(self):
        return tuple(Res(n, check="radiance") for n in (EFFECT, VIEW_SURFELS, VIEW_COVERAGE))

    def execute(self, rc, frame):
        sf = self.surfels
        prog = self.program(rc, "surfels/gather.comp")
        bind_frame(rc, prog, frame)
        sf.bind(rc, prog)
        bind_gbuffer(rc, prog, Units(1))
        debug = int(self["debug_views"]) == 1
        set_uniform(prog, "u_debug", 1 if debug else 0)
        res = rc.resources
        res[COLOR].bind_to_image(0, read=True, write=True)
        for b, n in enumerate((EFFECT, VIEW_SURFELS, VIEW_COVERAGE), start=1):
            res[n].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
        if not debug:
            for n in (VIEW_SURFELS, VIEW_COVERAGE):
                rc.clear_resource(n)


class SurfelGlossyPass(_SurfelPass):
    """Glossy indirect light: a surfel holds irradiance only, so each glossy pixel traces its
    lobe (surfels/glossy.comp); a hit is lit by its direct light and the surfels there."""
    name = "surfel_glossy"
    params = (Param("glossy_rays", 1, 0, 16, "rays from each glossy pixel's lobe per frame (0: no glossy "
                                                  "indirect light)"),)
    quality_ladder = ({"glossy_rays": 1}, {"glossy_rays": 1}, {"glossy_rays": 2}, {"glossy_rays": 4})

    def __init__(self, surfels, quality=None, **kw):
        super().__init__(surfels, quality, **kw)
        self.provides = frozenset({Effect.INDIRECT_SPECULAR})
        self.reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, CELLS, STATE, WORLD_SPEC)
        self.optional_reads = GBUFFER_BOUND + (WORLD_RANGE,)
        self.writes = (COLOR, POOL, GLOSSY)
        self.history_resets = frozenset()

    def resources(self):
        return (Res(GLOSSY, check="radiance"),)

    def execute(self, rc, frame):
        rays = int(self["glossy_rays"])
        if rays <= 0:
            rc.clear_resource(GLOSSY)
            return
        sf = self.surfels
        prog = self.program(rc, "surfels/glossy.comp", rt=True)
        bind_frame(rc, prog, frame)
        sf.bind(rc, prog)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        units.tex(prog, "u_world_spec", rc.resources[WORLD_SPEC])
        set_uniform(prog, "u_world_refl", 1 if world_light_range(rc)[1] > 0 else 0)
        set_uniform(prog, "u_sf_glossy_rays", rays)
        bind_world_light(rc.scene.scene, prog)
        rc.resources[COLOR].bind_to_image(0, read=True, write=True)
        rc.resources[GLOSSY].bind_to_image(1, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


def surfel_chain(quality, **params) -> list:
    sf = SurfelSet()
    kinds = (SurfelPreparePass, SurfelGridPass, SurfelSpawnPass, SurfelUpdatePass, SurfelGatherPass,
             SurfelGlossyPass)
    return [k(sf, quality, **params.get(k.name, {})) for k in kinds]


def read_surfels(rc, surfels: SurfelSet) -> dict:
    """The pool for tests and benchmarks (GL thread, after the graph's barriers): ``capacity``,
    ``live``, ``free`` (the stack's count), ``bytes``, and per live surfel ``index``,
    ``instance``, ``made`` (the frame it was spawned), ``world`` (N, 3) positions as of this
    frame's prepare (or spawn)."""
    rc.barrier_external([POOL])
    raw = np.frombuffer(rc.resources[POOL].read(), np.uint32)
    cap = surfels.capacity
    free = int(raw[0])
    recs = raw[4 + cap:4 + cap + cap * (SURFEL_BYTES // 4)].reshape(cap, SURFEL_BYTES // 4)
    alive = recs[:, 8] != 0  # info.x
    world = recs[:, 12:15].view(np.float32)
    return {"capacity": cap, "live": int(alive.sum()), "free": free, "bytes": surfels.bytes(),
            "frame": int(surfels.frame), "index": np.nonzero(alive)[0], "instance": recs[alive, 8].astype(int) - 1,
            "made": recs[alive, 10].astype(np.int64), "world": world[alive].copy()}
