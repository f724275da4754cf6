"""The world as a light: an equirectangular radiance map, its sampling tables and its
prefiltered forms. bpy-free; the exporter fills ``SceneData.world.map`` and every pass reads
the world through ``shaders/lib/world.glsl``.

Map convention (Blender's Environment Texture and Cycles' equirectangular camera): pixel
``map[row, col]``, row 0 at the bottom (elevation -90 deg), ``u = (col + 0.5) / W``,
``v = (row + 0.5) / H``; direction ``d`` has azimuth ``atan2(d.y, d.x) = pi (1 - 2u)`` and
elevation ``asin(d.z) = pi (v - 0.5)`` (+X at the map's centre, +Y a quarter to the left).

What the world provides, each computed once per map:

* ``mean``: the solid-angle mean radiance (what passes that treat the world as uniform use);
* ``irradiance_map``: the irradiance ``E(n)`` on a small equirectangular grid
  (``IRRADIANCE_SIZE``), the map's radiance integrated against the clamped cosine around each
  texel's direction (exact up to the source's binning, ``IRRADIANCE_SOURCE`` blocks of the map;
  not spherical harmonics, whose order-2 ringing reads 1.24x the irradiance of an upward floor
  and 2.1x that of a downward face under Blender's studio HDRI);
* a piecewise-constant sampling density over a grid of at most ``SAMPLE_GRID`` cells,
  proportional to luminance x cos(elevation) (the solid angle of a cell), stored as a
  marginal CDF over rows and one conditional CDF per row: ``sample`` / ``pdf`` below and
  ``world_sample`` / ``world_pdf`` in ``lib/scene_rt.glsl`` read the same tables, so
  importance sampling and its MIS weights agree on the CPU and the GPU;
* the map itself with mipmaps on the GPU (``world_glossy``: a roughness-dependent level).
"""
from __future__ import annotations

import math

import numpy as np

SAMPLE_GRID = (512, 256)  # at most W x H cells in the sampling tables
MAX_MAP_WIDTH = 4096
# A cell's density never falls below this fraction of the mean density: bilinear lookups
# reach half a texel into dark cells, which must then still be sampled.
DENSITY_FLOOR = 1e-3
WORLD_TEXTURE_UNIT = 31  # fixed texture unit of u_world_map (scene buffers use unit 0, passes 1..)
WORLD_IRRADIANCE_UNIT = 29  # fixed texture unit of u_world_irr
# W x H texels of the irradiance map (bilinear: E is smooth). Its rows run from pole to pole
# (row i at elevation pi (i / (H - 1) - 0.5)), so that a floor's or a ceiling's irradiance is
# a texel, not an extrapolation.
IRRADIANCE_SIZE = (64, 33)
IRRADIANCE_SOURCE = (128, 64)  # blocks of the map the irradiance integrates over


def directions(width: int, height: int) -> np.ndarray:
    """Unit directions of the pixel centres of a W x H map, (H, W, 3), row 0 at the bottom."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    az = np.pi * (1.0 - 2.0 * u)
    el = np.pi * (v - 0.5)
    ce = np.cos(el)[:, None]
    return np.stack([ce * np.cos(az)[None, :], ce * np.sin(az)[None, :],
                     np.repeat(np.sin(el)[:, None], width, axis=1)], axis=-1)


def direction_to_uv(d: np.ndarray) -> np.ndarray:
    """(..., 3) directions -> (..., 2) map coordinates (u, v) in [0, 1]."""
    d = np.asarray(d, np.float64)
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-30)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi)
    v = 0.5 + np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi
    return np.stack([u % 1.0, v], axis=-1)


def uv_to_direction(uv: np.ndarray) -> np.ndarray:
    uv = np.asarray(uv, np.float64)
    az = np.pi * (1.0 - 2.0 * uv[..., 0])
    el = np.pi * (uv[..., 1] - 0.5)
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def pixel_solid_angles(width: int, height: int) -> np.ndarray:
    """(H, 1) exact solid angle of one pixel of each row."""
    e0 = np.pi * (np.arange(height) / height - 0.5)
    e1 = np.pi * ((np.arange(height) + 1) / height - 0.5)
    return ((np.sin(e1) - np.sin(e0)) * (2.0 * np.pi / width))[:, None]


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722


def _dilate(a: np.ndarray) -> np.ndarray:
    """3x3 maximum (u wraps around, v is clamped)."""
    m = np.maximum(a, np.maximum(np.roll(a, 1, axis=1), np.roll(a, -1, axis=1)))
    out = m.copy()
    out[1:] = np.maximum(out[1:], m[:-1])
    out[:-1] = np.maximum(out[:-1], m[1:])
    return out


def _block_mean(a: np.ndarray, h: int, w: int) -> np.ndarray:
    """Mean of a (H, W) array over an h x w grid of equal blocks (H, W multiples of h, w)."""
    H, W = a.shape
    return a.reshape(h, H // h, w, W // w).mean(axis=(1, 3))


def _edges(n: int, blocks: int) -> np.ndarray:
    """Start indices of ``blocks`` near-equal runs of ``n`` items (at most n runs)."""
    return np.unique(np.linspace(0, n, min(blocks, n) + 1).astype(np.int64)[:-1])


def irradiance_map(px: np.ndarray) -> np.ndarray:
    """E(n) (IRRADIANCE_SIZE[1], IRRADIANCE_SIZE[0], 3) at the texels' directions (columns as
    the map's, rows from pole to pole: ``irradiance_uv``) of a radiance map (H, W, 3): the map
    binned into IRRADIANCE_SOURCE blocks (radiance x solid angle summed, so a small bright light
    keeps its power whatever the map's size), each block a point source at its luminous
    centroid, against max(cos, 0)."""
    H, W = px.shape[:2]
    w = px.astype(np.float64) * pixel_solid_angles(W, H)[..., None]
    rb, cb = _edges(H, IRRADIANCE_SOURCE[1]), _edges(W, IRRADIANCE_SOURCE[0])

    def blocks(a):
        return np.add.reduceat(np.add.reduceat(a, rb, axis=0), cb, axis=1)

    power = blocks(w)  # (gh, gw, 3)
    # each block's direction: its luminous centroid (a small bright light inside it stays where
    # it is), the block's centre where it is black
    v = (rb + np.append(rb[1:], H)) * 0.5 / H
    u = (cb + np.append(cb[1:], W)) * 0.5 / W
    centre = uv_to_direction(np.stack(np.broadcast_arrays(u[None, :], v[:, None]), axis=-1))
    lum = _luminance(w)[..., None]
    pull = blocks(directions(W, H) * lum)
    norm = np.linalg.norm(pull, axis=-1, keepdims=True)
    src = np.where(norm > 1e-30, pull / np.maximum(norm, 1e-30), centre)
    iw, ih = IRRADIANCE_SIZE
    tu, tv = (np.arange(iw) + 0.5) / iw, np.arange(ih) / (ih - 1)
    dst = uv_to_direction(np.stack(np.broadcast_arrays(tu[None, :], tv[:, None]), axis=-1))
    cos = np.maximum(dst.reshape(-1, 3).astype(np.float32) @ src.reshape(-1, 3).T.astype(np.float32), 0.0)
    return (cos @ power.reshape(-1, 3).astype(np.float32)).reshape(ih, iw, 3)


def irradiance_uv(uv: np.ndarray) -> np.ndarray:
    """The irradiance map's texture coordinates of map coordinates uv (..., 2): rows from pole
    to pole (as ``world_irradiance`` in lib/world.glsl)."""
    h = IRRADIANCE_SIZE[1]
    return np.stack([uv[..., 0], (uv[..., 1] * (h - 1) + 0.5) / h], axis=-1)


def bilinear_equirect(table: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """A (h, w, C) equirectangular table at uv (..., 2) as the GPU filters it (texel centres at
    (i + 0.5) / size, u wraps, v clamps to the edge rows)."""
    h, w = table.shape[:2]
    x = uv[..., 0] * w - 0.5
    y = np.clip(uv[..., 1] * h - 0.5, 0.0, h - 1)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    y1 = np.minimum(y0 + 1, h - 1)
    c0, c1 = x0 % w, (x0 + 1) % w
    top = table[y0, c0] * (1 - fx) + table[y0, c1] * fx
    bot = table[y1, c0] * (1 - fx) + table[y1, c1] * fx
    return top * (1 - fy) + bot * fy


class WorldMap:
    """Tables derived from one equirectangular radiance map (H, W, 3), row 0 at the bottom."""

    def __init__(self, pixels: np.ndarray):
        px = np.ascontiguousarray(np.asarray(pixels, np.float32)[..., :3])
        px = np.where(np.isfinite(px), np.maximum(px, 0.0), 0.0).astype(np.float32)
        self.pixels = px
        H, W = px.shape[:2]
        self.width, self.height = W, H
        sa = pixel_solid_angles(W, H)
        self.mean = (px * sa[..., None]).sum(axis=(0, 1)) / (4.0 * np.pi)
        self.irradiance_map = irradiance_map(px)
        # sampling grid: a divisor grid of the map no larger than SAMPLE_GRID
        gw = W
        while gw > SAMPLE_GRID[0] and gw % 2 == 0:
            gw //= 2
        gh = H
        while gh > SAMPLE_GRID[1] and gh % 2 == 0:
            gh //= 2
        # the density follows the luminance dilated by one texel: a bilinear lookup reaches
        # half a texel into the next cell, so a dark cell beside a bright texel must not have
        # a density far below the radiance it returns (fireflies: L / pdf)
        lum = _block_mean(_dilate(_luminance(px.astype(np.float64))), gh, gw)
        cell_sa = pixel_solid_angles(gw, gh)
        weight = lum * cell_sa
        total = weight.sum()
        if total <= 0.0:
            weight = np.broadcast_to(cell_sa, (gh, gw)).copy()
            total = weight.sum()
        weight = weight + DENSITY_FLOOR * total / weight.size
        row = weight.sum(axis=1)
        self.grid = (gw, gh)
        self.marginal = np.cumsum(row) / row.sum()
        self.marginal[-1] = 1.0
        cond = np.cumsum(weight, axis=1) / row[:, None]
        cond[:, -1] = 1.0
        self.conditional = cond
        self._p = weight / weight.sum()  # probability of each cell

    # ------------------------------------------------------------------ tables
    def table(self) -> np.ndarray:
        """The flat float32 table the shaders read: marginal CDF (gh), then gh conditional
        CDFs of gw entries each."""
        return np.concatenate([self.marginal, self.conditional.ravel()]).astype(np.float32)

    def power_weight(self, radius: float) -> float:
        """Selection weight against lights (rt_scene.light_selection's units: a sun's
        irradiance x the scene's cross-section): the world's irradiance at normal incidence
        (pi x mean radiance, in luminance) over a disk of the scene's radius."""
        return float(np.pi * _luminance(self.mean) * np.pi * radius * radius)

    # ------------------------------------------------------------------ CPU sampling
    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Directions (N, 3) and their solid-angle pdfs for uniform numbers u (N, 2), by the
        same tables and arithmetic as ``world_sample`` in lib/scene_rt.glsl."""
        u = np.asarray(u, np.float64).reshape(-1, 2)
        gw, gh = self.grid
        r = np.minimum(np.searchsorted(self.marginal, u[:, 0], side="right"), gh - 1)
        r0 = np.where(r > 0, self.marginal[np.maximum(r - 1, 0)], 0.0)
        fy = (u[:, 0] - r0) / np.maximum(self.marginal[r] - r0, 1e-30)
        c = np.array([min(int(np.searchsorted(self.conditional[ri], ui, side="right")), gw - 1)
                      for ri, ui in zip(r, u[:, 1])], np.int64)
        c0 = np.where(c > 0, self.conditional[r, np.maximum(c - 1, 0)], 0.0)
        fx = (u[:, 1] - c0) / np.maximum(self.conditional[r, c] - c0, 1e-30)
        # a thousandth of a cell inside it, as world_sample keeps it (world_pdf finds the cell again)
        uv = np.stack([(c + np.clip(fx, 1e-3, 1 - 1e-3)) / gw, (r + np.clip(fy, 1e-3, 1 - 1e-3)) / gh], axis=-1)
        d = uv_to_direction(uv)
        return d, self.pdf(d)

    def pdf(self, d: np.ndarray) -> np.ndarray:
        """Solid-angle pdf of directions (N, 3) under ``sample``."""
        gw, gh = self.grid
        uv = direction_to_uv(d)
        c = np.clip((uv[..., 0] * gw).astype(np.int64), 0, gw - 1)
        r = np.clip((uv[..., 1] * gh).astype(np.int64), 0, gh - 1)
        el = np.pi * (uv[..., 1] - 0.5)
        return self._p[r, c] * gw * gh / (2.0 * np.pi * np.pi * np.maximum(np.cos(el), 1e-6))

    def radiance(self, d: np.ndarray) -> np.ndarray:
        """Nearest-texel radiance along directions (N, 3) (tests and host-side estimates)."""
        uv = direction_to_uv(d)
        c = np.clip((uv[..., 0] * self.width).astype(np.int64), 0, self.width - 1)
        r = np.clip((uv[..., 1] * self.height).astype(np.int64), 0, self.height - 1)
        return self.pixels[r, c]

    def irradiance(self, n: np.ndarray) -> np.ndarray:
        """Irradiance E(n) (N, 3) from the irradiance map, filtered as world_irradiance in GLSL."""
        uv = irradiance_uv(direction_to_uv(np.asarray(n, np.float64)))
        return bilinear_equirect(self.irradiance_map.astype(np.float64), uv)


# A compact, bright region carrying at least this share of the map's light is a sun.
SUN_MIN_SHARE = 0.2
SUN_MAX_SOLID_ANGLE = 0.003  # sr (a disc of about 3.5 degrees across)


def extract_sun(pixels: np.ndarray):
    """Split a map into a sun and the rest: the connected region around the brightest texel
    whose luminance exceeds both 5 % of that peak and 50x the map's median, when it is
    compact (under SUN_MAX_SOLID_ANGLE) and carries at least SUN_MIN_SHARE of the map's
    light. Returns ``(sun, residual)``: ``sun`` is None or a dict with ``direction`` (unit,
    towards the sun), ``irradiance`` (RGB, W/m^2 at normal incidence: the region's radiance
    integrated over its solid angle), ``angle`` (the angular diameter of a disc of the same
    solid angle), ``share``; ``residual`` is the map with the region filled by the median of
    the texels around it (the sky next to the sun)."""
    px = np.asarray(pixels, np.float32)[..., :3]
    H, W = px.shape[:2]
    lum = _luminance(px.astype(np.float64))
    sa = np.broadcast_to(pixel_solid_angles(W, H), (H, W))
    total = float((lum * sa).sum())
    if total <= 0.0:
        return None, px
    r, c = np.unravel_index(int(np.argmax(lum)), lum.shape)
    peak = float(lum[r, c])
    bright = lum > max(0.05 * peak, 50.0 * float(np.median(lum)))
    region = np.zeros_like(bright)
    region[r, c] = True
    for _ in range(64):  # grow through bright texels (u wraps around)
        grown = region.copy()
        grown[1:] |= region[:-1]
        grown[:-1] |= region[1:]
        grown |= np.roll(region, 1, axis=1) | np.roll(region, -1, axis=1)
        grown &= bright
        if (grown == region).all():
            break
        region = grown
    omega = float(sa[region].sum())
    share = float((lum * sa)[region].sum()) / total
    if omega > SUN_MAX_SOLID_ANGLE or share < SUN_MIN_SHARE:
        return None, px
    w = (px * sa[..., None])[region].astype(np.float64)  # radiance x solid angle per texel
    irradiance = w.sum(axis=0)
    dirs = directions(W, H)[region]
    d = (dirs * _luminance(w)[:, None]).sum(axis=0)
    d /= max(float(np.linalg.norm(d)), 1e-30)
    ring = region.copy()
    for _ in range(3):
        g = ring.copy()
        g[1:] |= ring[:-1]
        g[:-1] |= ring[1:]
        g |= np.roll(ring, 1, axis=1) | np.roll(ring, -1, axis=1)
        ring = g
    ring &= ~region
    residual = px.copy()
    residual[region] = np.median(px[ring], axis=0) if ring.any() else 0.0
    angle = 2.0 * math.acos(max(-1.0, 1.0 - omega / (2.0 * math.pi)))
    return {"direction": d, "irradiance": irradiance, "angle": angle, "share": share,
            "solid_angle": omega}, residual


_MAPS: dict[int, tuple[np.ndarray, WorldMap]] = {}


def world_map_of(world) -> WorldMap | None:
    """The WorldMap of a ``scene_data.World``; None for a uniform world. Cached per map
    array (the exporter hands back the same array while the world does not change)."""
    px = getattr(world, "map", None)
    if px is None:
        return None
    hit = _MAPS.get(id(px))
    if hit is not None and hit[0] is px:
        return hit[1]
    wm = WorldMap(px)
    while len(_MAPS) >= 4:
        _MAPS.pop(next(iter(_MAPS)))
    _MAPS[id(px)] = (px, wm)
    return wm


def halton(i: int, b: int) -> float:
    """The radical inverse of ``i`` in base ``b`` (the Halton sequence)."""
    f, r = 1.0, 0.0
    while i > 0:
        f /= b
        r += f * (i % b)
        i //= b
    return r


def world_light_directions(world, k: int, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``k`` directions towards the world light for frame ``index`` of an accumulation:
    stratified in one coordinate and rotated by a Halton offset per frame, drawn by the map's
    luminance (a uniform world: uniformly on the sphere). Returns the directions (k, 3)
    pointing at the sky, their radiance (k, 3) and solid-angle pdfs (k,), so that
    ``L / (k · pdf)`` summed over them estimates the world's irradiance integral. The shadow
    maps of the world light (DIRECT) and its reflective shadow maps (RSM, LPV) draw their
    directions here."""
    jx, jy = halton(index + 1, 2), halton(index + 1, 3)
    us = np.array([[(i + jx) / k, (i * 0.61803398875 + jy) % 1.0] for i in range(k)]).reshape(-1, 2)
    wm = world_map_of(world)
    if wm is not None:
        omegas, pdf = wm.sample(us)
        return omegas, np.asarray(wm.radiance(omegas), np.float64), np.asarray(pdf, np.float64)
    z = 1.0 - 2.0 * us[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    omegas = np.stack([r * np.cos(2 * np.pi * us[:, 1]), r * np.sin(2 * np.pi * us[:, 1]), z], axis=-1)
    color = np.broadcast_to(np.asarray(world.color, np.float64)[:3], (len(omegas), 3))
    return omegas, np.array(color), np.full(len(omegas), 1.0 / (4.0 * np.pi))


class WorldGPU:
    """The world's GPU resources of one GL context: the map texture (mipmapped, RGBA32F) and
    the uniforms of lib/world.glsl. The sampling tables travel in the ray tracer's light
    table (rt_scene.light_table)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.texture = None
        self.irr_texture = None
        self._key = None
        self.map: WorldMap | None = None

    def update(self, world) -> bool:
        """Upload ``world``'s map if it changed; True when anything changed."""
        wm = world_map_of(world)
        key = None if wm is None else (id(wm.pixels), wm.pixels.shape)
        if key == self._key and self.texture is not None:
            return False
        import moderngl

        self._release_textures()

        def upload(rgb, mipmaps):
            data = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=-1)
            h, w = data.shape[:2]
            tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(data, np.float32).tobytes(), dtype="f4")
            if mipmaps:
                tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR if mipmaps else moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = True
            tex.repeat_y = False
            return tex

        # without a map, black stand-ins shaped like a map (a mip chain) and like the irradiance
        # table: a driver that specialises a program on the bound textures' sizes and levels
        # (Mesa's llvmpipe) then compiles it once for worlds with and without a map
        self.texture = upload(np.zeros((2, 4, 3), np.float32) if wm is None else wm.pixels, True)
        no_irr = np.zeros((IRRADIANCE_SIZE[1], IRRADIANCE_SIZE[0], 3), np.float32)
        self.irr_texture = upload(no_irr if wm is None else wm.irradiance_map, False)
        self._key = key
        self.map = wm
        return True

    def bind(self, prog, world, film_transparent: bool = False) -> None:
        from .gpu_scene import set_uniform

        wm = self.map
        set_uniform(prog, "u_film_transparent", 1 if film_transparent else 0)
        self.texture.use(WORLD_TEXTURE_UNIT)
        set_uniform(prog, "u_world_map", WORLD_TEXTURE_UNIT)
        set_uniform(prog, "u_world_mode", 0 if wm is None else 1)
        mean = wm.mean if wm is not None else np.asarray(world.color, np.float64)
        set_uniform(prog, "u_world_color", tuple(float(x) for x in mean))
        if wm is not None:
            set_uniform(prog, "u_world_lods", float(math.floor(math.log2(max(wm.width, wm.height)))))
            set_uniform(prog, "u_world_grid", tuple(int(x) for x in wm.grid))
        self.irr_texture.use(WORLD_IRRADIANCE_UNIT)
        set_uniform(prog, "u_world_irr", WORLD_IRRADIANCE_UNIT)

    def _release_textures(self) -> None:
        for t in (self.texture, self.irr_texture):
            if t is not None:
                t.release()
        self.texture = self.irr_texture = None

    def release(self) -> None:
        self._release_textures()
        self._key = None
        self.map = None
