"""The world-space radiance cache: a spatial hash grid of indirect irradiance (after the world
cache of GI-1.0, Boissé et al. 2023), shared by the techniques that need light from beyond
the screen and the later bounces without tracing paths (GI10 and SCREEN_PROBES).

Storage (``shaders/radiance_cache/common.glsl`` documents the layout): ``buckets`` buckets of
16 entries (GI-1.0: 4096 × 16); an entry is a cell of a grid whose side grows with the
distance to the camera (powers of two of ``cell_min`` × the scene's size, ``cell_scale`` per
unit of distance) and one of six normal directions. ``radiance_cache.entries`` (keys, ages,
the point each entry traces from) is state the cache keeps across frames;
``radiance_cache.irradiance`` (rgb + sample count per entry) is graph-owned history, so the
update reads last frame's values and every other pass this frame's.

``RadianceCacheUpdatePass`` (``radiance_cache``) runs first in a frame: every used entry
traces ``rays`` cosine rays and blends E = π · mean(L) in; entries unused for ``max_age``
frames are freed (LRU). Lookups anywhere (the screen probes' hits, the gather's fallback,
the update's own hits) request the cells they miss. Capacity is fixed: the cache cannot grow
past ``buckets`` × 16 entries; a full bucket answers "no entry" until one of its entries ages out.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import BUFFER, CAMERA_CUT, PARAM_CHANGE, Param, Pass, Res
from ..gpu_scene import set_uniform
from .screen_space import bind_world_light, camera_vectors

ENTRIES, IRR = "radiance_cache.entries", "radiance_cache.irradiance"
BUCKET = 16                 # entries per bucket (radiance_cache/common.glsl RC_BUCKET)
ENTRY_BYTES = 48            # uvec4 key + vec4 pos + vec4 nrm
BINDING_ENTRIES, BINDING_IRR, BINDING_IRR_OUT = 18, 19, 20
CACHE_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE})  # light and scene edits: blended through

CACHE_PARAMS = (
    Param("buckets", 4096, 64, 65536, "hash buckets of 16 entries each (capacity = 16 x buckets)"),
    Param("cell_min", 1.0 / 256.0, 1e-4, 0.25, "smallest cell side, as a fraction of the scene's largest extent"),
    Param("cell_scale", 0.02, 0.0, 1.0, "cell side per unit of distance to the camera (0: all cells cell_min)"),
    Param("rays", 4, 1, 64, "rays per used entry per frame"),
    Param("max_age", 50, 1, 10000, "frames an entry is kept without being used (LRU eviction)"),
    Param("min_blend", 0.05, 0.001, 1.0, "smallest weight of a frame's estimate (history at most 1 - this)"),
    Param("warmup_blend", 0.8, 0.0, 1.0, "smallest weight of a frame's estimate during an F12 render's warm-up and for 8 frames after "
          "an edit of the lights, materials or geometry (a short window: the "
          "later bounces build up over frames, and a long mean would keep the early, darker estimates)"),
    Param("fast_blend", 0.25, 0.0, 1.0, "weight of a frame's estimate when the luminance changed by more than change_threshold"),
    Param("change_threshold", 0.8, 0.0, 100.0, "relative luminance change that counts as the light changing"),
)


# scene edits that change the light a cache holds
LIGHT_EDITS = frozenset({"geometry", "transforms", "materials", "lights", "textures"})
SETTLE_FRAMES = 8


def settling(p: Pass, frame) -> bool:
    """True in an F12 render's warm-up frames and in the SETTLE_FRAMES frames after a scene
    edit that changes the light (``p`` counts them): the blend of a cache then uses its short
    warm-up window, so that a light switched off or moved is followed within a few frames
    even where the cache's own later bounces would keep the old light alive (a decay of one
    bounce per frame is a relative change below any threshold that noise does not cross)."""
    if frame.scene_edits & LIGHT_EDITS:
        p._settle = SETTLE_FRAMES
    left = int(getattr(p, "_settle", 0))
    p._settle = max(0, left - 1)
    return bool(frame.warmup) or left > 0


def reset_settling(p: Pass) -> None:
    """Forget ``p``'s settle window (its history reset): a render that starts over settles
    as the last one did."""
    p._settle = 0


class RadianceCache:
    """Host side of radiance_cache/common.glsl, shared by the update pass and the readers."""

    def __init__(self):
        self.update_pass: "RadianceCacheUpdatePass | None" = None
        self.frame = 0
        self.cell_min = 1e-2
        self.camera = np.zeros(3)
        self.enabled = True

    @property
    def props(self) -> dict:
        return self.update_pass.props

    @property
    def capacity(self) -> int:
        return int(self.props["buckets"]) * BUCKET

    def bytes(self) -> int:
        return self.capacity * (ENTRY_BYTES + 2 * 16)

    def bind(self, rc, prog, *, prev: bool = False):
        """Uniforms and buffers of a program that looks the cache up (``prev``: bind last
        frame's irradiance, as the update does)."""
        set_uniform(prog, "u_rc_buckets", int(self.props["buckets"]))
        set_uniform(prog, "u_rc_cell_min", float(self.cell_min))
        set_uniform(prog, "u_rc_cell_scale", float(self.props["cell_scale"]))
        set_uniform(prog, "u_rc_camera", tuple(float(x) for x in self.camera))
        set_uniform(prog, "u_rc_frame", int(self.frame) & 0xFFFFFFFF)
        rc.resources[ENTRIES].bind_to_storage_buffer(BINDING_ENTRIES)
        rc.resources[IRR + ("@prev" if prev else "")].bind_to_storage_buffer(BINDING_IRR)


class RadianceCacheUpdatePass(Pass):
    """Traces from every used cache entry and blends the result in; frees unused entries."""

    name = "radiance_cache"
    kind = "compute"
    history_resets = CACHE_RESETS
    params = CACHE_PARAMS
    quality_ladder = ({"rays": 2, "buckets": 2048}, {"rays": 4}, {"rays": 4, "buckets": 8192},
                      {"rays": 8, "buckets": 16384})

    def __init__(self, cache: RadianceCache, quality=None, *, provides=frozenset(), **props):
        super().__init__(quality, **props)
        self.cache = cache
        cache.update_pass = self
        self.provides = frozenset(provides)
        # the entries are the cache's own state across frames: the update, first in a frame,
        # reads and writes them after last frame's lookups (ordered by the graph as writes)
        self.reads = (IRR + "@prev",)
        self.writes = (ENTRIES, IRR)

    def resources(self):
        n = int(self["buckets"]) * BUCKET
        return (Res(ENTRIES, kind=BUFFER, size=n * ENTRY_BYTES, check="none"),
                Res(IRR, kind=BUFFER, size=n * 16, history=True, check="radiance"))

    def reset_history(self):
        super().reset_history()
        self._clear_entries = True
        # the entries go with the counter their ages are kept in: a render that starts over
        # (F12) then draws the same random numbers as the last one did
        self.cache.frame = 0
        reset_settling(self)

    def execute(self, rc, frame):
        cache = self.cache
        if getattr(self, "_clear_entries", True):
            rc.clear_resource(ENTRIES, by=self.name)
            self._clear_entries = False
        lo, hi = rc.scene.scene.world_bounds()
        extent = float(np.max(np.asarray(hi, np.float64) - np.asarray(lo, np.float64)))
        cache.cell_min = max(extent, 1e-6) * float(self["cell_min"])
        cache.camera = camera_vectors(frame)[0]
        cache.frame += 1
        rt = rc.scene.rt()
        prog = rc.programs.compute("radiance_cache/update.comp", rt.defines)
        rt.bind(prog)
        cache.bind(rc, prog, prev=True)
        rc.resources[IRR].bind_to_storage_buffer(BINDING_IRR_OUT)
        set_uniform(prog, "u_rc_rays", int(self["rays"]))
        set_uniform(prog, "u_rc_max_age", int(self["max_age"]))
        for k in ("fast_blend", "change_threshold"):
            set_uniform(prog, "u_rc_" + k, float(self[k]))
        blend = max(float(self["min_blend"]), float(self["warmup_blend"]) if settling(self, frame) else 0.0)
        set_uniform(prog, "u_rc_min_blend", blend)
        set_uniform(prog, "u_seed", int(frame.sample) & 0xFFFFFFFF)
        bind_world_light(rc.scene.scene, prog)
        rc.dispatch(prog, (cache.capacity + 63) // 64)


def read_cache(rc, cache: RadianceCache) -> dict:
    """Occupancy of the cache for tests, benchmarks and the docs (GL thread, after the
    graph's barriers): ``capacity``, ``used`` (entries with a key), ``filled`` (with samples),
    ``levels`` (entries per distance level), ``bytes``."""
    rc.barrier_external([ENTRIES, IRR])
    keys = np.frombuffer(rc.resources[ENTRIES].read(), np.uint32).reshape(-1, 12)
    irr = np.frombuffer(rc.resources[IRR].read(), np.float32).reshape(-1, 4)
    used = keys[:, 0] != 0
    levels = np.bincount(keys[used, 3].astype(np.int64), minlength=1) if used.any() else np.zeros(1, int)
    return {"capacity": int(keys.shape[0]), "used": int(used.sum()), "filled": int((used & (irr[:, 3] > 0)).sum()),
            "levels": levels.tolist(), "bytes": cache.bytes(), "frame": int(cache.frame)}
