"""Per-tile light culling for DIRECT with many lights (``shaders/direct/light_cull.comp``).

Every light gets a range of influence: a sphere around it outside which its diffuse
contribution to a white surface facing it falls below ``L_min``, where ``L_min`` is
``cull_fraction`` times the radiance all lights together would give such a surface at the
scene's radius ``D`` (``sum(I) / (pi D^2)``). So ``R_i = D sqrt(I_i / (f sum I)) + extent_i``
(I = peak radiant intensity in W/sr: point/spot intensity, area ``Le A``, mesh ``Le_max A``;
extent = the light's own size). Suns (and the world) reach everywhere. A scene with fewer
than ``MIN_CULL_LIGHTS`` (32) lights culls nothing.

Each 16x16 pixel tile lists the lights whose sphere meets the world-space box of its
G-buffer points. Culling does not drop light: ``direct.comp`` estimates the lights a tile
does not list with light samples chosen by power (unbiased, a little noise that
accumulates away). The culling is a cost/noise trade-off, not a bias.

The result (``LightCull``, a host object in ``rc.resources["direct.light_cull"]``) also
feeds the shadow pass's budget: the lights that matter most in view get shadow maps. The
tile bounds are a history resource: the budget reads last frame's (``direct.tile_bounds@prev``)
so that nothing is read back in the middle of a frame; where there is no last frame (the
first frame, a camera cut, a scene edit) it ranks lights by intensity / squared distance.
"""
from __future__ import annotations

import numpy as np

from ..barriers import BUFFER_UPDATE_BARRIER_BIT
from ..framegraph import BUFFER, HOST, PREV, Param, Pass, Res
from ..gpu_scene import LIGHT_MESH, set_uniform
from ..scene_data import LightType
from .gbuffer import POSITION

TILE_LIGHTS, TILE_BOUNDS, LIGHT_CULL = "direct.tile_lights", "direct.tile_bounds", "direct.light_cull"
TILE = 16  # pixels per tile side (light_cull.comp's work group)
MAX_TILE_LIST_BYTES = 64 << 20  # the tile lists' buffer: capacity per tile shrinks to fit
BIND_RANGES, BIND_TILE_LIGHTS, BIND_TILE_BOUNDS = 4, 6, 7
# Below this many lights nothing is culled: every tile lists every light. Culling pays when
# the per-pixel loop is long; with a few lights the far-light samples' noise (a glossy
# highlight of a light outside a tile's diffuse range, divided by its selection probability)
# costs more than the loop saves (16 lights, 96², 16 frames: relMSE 0.0089 culled, 0.0024 for
# the code before culling, which shaded every light at every pixel).
MIN_CULL_LIGHTS = 32


def light_ranges(gpu_scene, cull_fraction: float) -> dict:
    """Ranges of influence of every light of the GPU scene (see the module docstring).

    Returns ``ranges`` (n, 4) float32 (centre xyz, radius; -1 = everywhere), ``intensity``
    (n,) peak W/sr, ``extent`` (n,) the light's own radius, ``partial`` (True when some light
    does not reach the whole scene, i.e. a tile may leave it out) and ``l_min``."""
    arr = gpu_scene.light_array
    n = int(gpu_scene.light_count)
    scene = gpu_scene.scene
    lo, hi = scene.world_bounds()
    D = max(float(np.linalg.norm(hi - lo)) * 0.5, 1e-3)
    ranges = np.zeros((max(n, 1), 4), np.float32)
    intensity = np.zeros(max(n, 1), np.float64)
    extent = np.zeros(max(n, 1), np.float64)
    groups = gpu_scene.emitters.groups if gpu_scene.emitters else []
    n_mesh0 = n - len(groups)
    for i in range(n):
        r = arr[i]
        typ = int(round(float(r[3])))
        cmax = float(np.max(r[8:11]))
        ranges[i, :3] = r[0:3]
        if typ in (int(LightType.POINT), int(LightType.SPOT)):
            intensity[i], extent[i] = cmax, float(r[7])
        elif typ == int(LightType.AREA):
            intensity[i] = cmax * float(r[19])
            extent[i] = float(np.linalg.norm(r[12:15]) + np.linalg.norm(r[16:19]))
        elif typ == LIGHT_MESH:
            intensity[i] = cmax * float(r[27])
            g = groups[i - n_mesh0]
            tri = np.asarray(g["triangles"], np.float64).reshape(-1, 3)
            extent[i] = float(np.max(np.linalg.norm(tri - r[0:3].astype(np.float64), axis=1))) if tri.size else 0.0
        else:  # sun
            intensity[i] = np.inf
    finite = np.isfinite(intensity[:n])
    total = float(intensity[:n][finite].sum())
    f = float(cull_fraction)
    partial = False
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    few = n < MIN_CULL_LIGHTS  # shading them all costs less than the noise of leaving some out
    for i in range(n):
        if not finite[i] or f <= 0 or total <= 0 or few:
            ranges[i, 3] = -1.0
            continue
        R = D * np.sqrt(intensity[i] / (f * total)) + extent[i]
        ranges[i, 3] = R
        far = float(np.max(np.linalg.norm(corners - ranges[i, :3].astype(np.float64), axis=1)))
        partial |= R < far
    l_min = f * total / (np.pi * D * D) if total > 0 else 0.0
    return {"ranges": ranges, "intensity": intensity[:n], "extent": extent[:n], "partial": bool(partial),
            "l_min": l_min, "scene_radius": D, "fraction": f}


class LightCull:
    """One frame's culling: buffers on the GPU plus what the host needs (ranges, sizes).
    ``frame`` is the FrameState it was computed for (readers check they see this frame's)."""

    def __init__(self):
        self.frame = None
        self.tiles_x = self.tiles_y = 0
        self.capacity = 0
        self.info: dict = {}
        self.tile_lights = None
        self.tile_bounds = None

    @property
    def n_tiles(self) -> int:
        return self.tiles_x * self.tiles_y

    def release(self):
        pass  # the buffers belong to the LightCuller


class LightCuller:
    """Runs light_cull.comp; owns its buffers (tile lists, tile bounds, ranges)."""

    def __init__(self):
        self.tile_lights = self.tile_bounds = self.range_buf = None
        self._range_key = None

    def _buffer(self, ctx, attr: str, nbytes: int):
        buf = getattr(self, attr)
        if buf is None or buf.size != nbytes:
            if buf is not None:
                buf.release()
            buf = ctx.buffer(reserve=max(16, nbytes))
            setattr(self, attr, buf)
        return buf

    def run(self, rc, frame, cull_fraction: float, position_tex=None, bounds=None) -> LightCull:
        """Cull this frame's tiles; ``bounds``: a callable ``bounds(nbytes)`` giving the buffer
        the tile bounds go to (default: the culler's own)."""
        gs = rc.scene
        n = int(gs.light_count)
        key = (gs.version, id(gs.scene), float(cull_fraction))
        if key != self._range_key:
            self.info = light_ranges(gs, cull_fraction)
            data = self.info["ranges"].tobytes()
            self._buffer(rc.ctx, "range_buf", len(data)).write(data)
            self._range_key = key
        tx, ty = (rc.width + TILE - 1) // TILE, (rc.height + TILE - 1) // TILE
        tiles = tx * ty
        cap = max(1, min(max(n, 1), MAX_TILE_LIST_BYTES // (4 * tiles) - 1))
        tl = self._buffer(rc.ctx, "tile_lights", tiles * (cap + 1) * 4)
        tb = bounds(tiles * 32) if bounds is not None else self._buffer(rc.ctx, "tile_bounds", tiles * 32)
        prog = rc.programs.compute("direct/light_cull.comp")
        gs.bind(prog)
        tex = position_tex if position_tex is not None else rc.resources[POSITION]
        tex.use(1)
        set_uniform(prog, "u_gb_position", 1)
        set_uniform(prog, "u_capacity", int(cap))
        self.range_buf.bind_to_storage_buffer(BIND_RANGES)
        tl.bind_to_storage_buffer(BIND_TILE_LIGHTS)
        tb.bind_to_storage_buffer(BIND_TILE_BOUNDS)
        rc.dispatch(prog, tx, ty)
        out = LightCull()
        out.frame, out.tiles_x, out.tiles_y, out.capacity = frame, tx, ty, cap
        out.info, out.tile_lights, out.tile_bounds = self.info, tl, tb
        return out

    def release(self):
        for attr in ("tile_lights", "tile_bounds", "range_buf"):
            b = getattr(self, attr)
            if b is not None:
                b.release()
                setattr(self, attr, None)
        self._range_key = None


def read_tile_bounds(ctx, cull: LightCull) -> np.ndarray:
    """(tiles, 2, 4) float32: (min.xyz, pixels with geometry), (max.xyz, lights in range).
    Issues the barrier that makes the shader's stores visible to the read-back."""
    ctx.memory_barrier(BUFFER_UPDATE_BARRIER_BIT)  # the cull shader's stores, before glGetBufferSubData
    return np.frombuffer(cull.tile_bounds.read(size=cull.n_tiles * 32), np.float32).reshape(-1, 2, 4)


def tile_stats(ctx, cull: LightCull) -> dict:
    """Lights per tile over the tiles that hold geometry (for stats, benchmarks and tests)."""
    tb = read_tile_bounds(ctx, cull)
    geo = tb[:, 0, 3] > 0
    n_in = tb[geo, 1, 3]
    return {"tiles": int(cull.n_tiles), "tiles_with_geometry": int(geo.sum()),
            "mean_lights_per_tile": float(n_in.mean()) if n_in.size else 0.0,
            "max_lights_per_tile": int(n_in.max()) if n_in.size else 0,
            "capacity": int(cull.capacity), "tiles_over_capacity": int((n_in > cull.capacity).sum())}


def light_scores(ctx, cull: LightCull, indices) -> np.ndarray:
    """Estimated contribution of lights ``indices`` to the visible pixels: for each tile with
    geometry, pixels x I / d^2 from the light to the nearest point of the tile's box (d at
    least the light's size and 1 % of the scene radius); lights outside a tile's range add 0."""
    return scores_from_bounds(read_tile_bounds(ctx, cull), cull.info, indices)


def scores_from_bounds(tb: np.ndarray, info: dict, indices) -> np.ndarray | None:
    """:func:`light_scores` from tile bounds ``tb`` ((tiles, 2, 4), read_tile_bounds' layout)
    and the ranges ``info`` (light_ranges); None when no tile holds geometry (bounds never
    written, or cleared)."""
    idx = np.asarray(list(indices), int)
    geo = tb[:, 0, 3] > 0
    if not geo.any():
        return None
    if idx.size == 0:
        return np.zeros(0)
    lo, hi, npx = tb[geo, 0, :3].astype(np.float64), tb[geo, 1, :3].astype(np.float64), tb[geo, 0, 3].astype(np.float64)
    D = info["scene_radius"]
    out = np.zeros(idx.size)
    if info["ranges"].shape[0] <= int(idx.max()):
        return None  # bounds of another light set
    for s in range(0, idx.size, 128):
        part = idx[s:s + 128]
        c = info["ranges"][part, :3].astype(np.float64)
        R = info["ranges"][part, 3].astype(np.float64)
        q = np.clip(c[:, None, :], lo[None], hi[None])
        d2 = np.sum((c[:, None, :] - q) ** 2, axis=2)
        floor = np.maximum(info["extent"][part] ** 2, (0.01 * D) ** 2)[:, None]
        inside = (R[:, None] < 0) | (d2 <= R[:, None] ** 2)
        I = info["intensity"][part][:, None]
        out[s:s + 128] = np.sum(np.where(inside, npx[None] * I / np.maximum(d2, floor), 0.0), axis=1)
    return out


class LightCullPass(Pass):
    """Per-tile light lists of this frame; the tile bounds are kept for the next frame's
    shadow budget (``direct.tile_bounds@prev``)."""

    name = "light_cull"
    always = True  # DIRECT's lighting needs it (DirectLightPass culls inline in graphs without it)
    reads = (POSITION,)
    writes = (TILE_LIGHTS, TILE_BOUNDS, LIGHT_CULL)
    # sizes depend on the light count and the frame: the pass allocates them (managed=False);
    # the tile bounds are double-buffered by the graph (history) for the next frame's budget
    declared = (Res(TILE_LIGHTS, kind=BUFFER, dtype="i4", managed=False, check="none"),
                Res(TILE_BOUNDS, kind=BUFFER, managed=False, check="none", history=True),
                Res(LIGHT_CULL, kind=HOST, managed=False, check="none"))
    # last frame's bounds describe another view or scene after these (the graph clears them:
    # a cleared buffer holds no tile with geometry, and the budget ranks by distance)
    history_resets = frozenset({"camera_cut", "geometry", "transforms", "lights", "param_change"})
    params = (
        Param("cull_fraction", 0.05, 0.0, 1.0,
              "range of influence: where a light's radiance falls below this fraction of all lights' (0 = no culling)"),
    )

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.culler = LightCuller()
        self.last: LightCull | None = None

    def _bounds(self, rc, nbytes: int):
        """This frame's tile-bounds buffer (the graph swapped last frame's to ``@prev``); both
        made, zeroed, when missing or of another size (zero: no tile holds geometry)."""
        for n in (TILE_BOUNDS + PREV, TILE_BOUNDS):
            b = rc.resources.get(n)
            if b is None or b.size != nbytes:
                if b is not None:
                    b.release()
                rc.resources[n] = rc.ctx.buffer(data=bytes(nbytes))
                rc.sync.pop(n, None)
        return rc.resources[TILE_BOUNDS]

    def execute(self, rc, frame):
        cull = self.culler.run(rc, frame, float(self["cull_fraction"]), bounds=lambda nb: self._bounds(rc, nb))
        rc.resources[TILE_LIGHTS] = cull.tile_lights
        rc.resources[TILE_BOUNDS] = cull.tile_bounds
        rc.resources[LIGHT_CULL] = cull
        self.last = cull

    def release(self):
        self.culler.release()
