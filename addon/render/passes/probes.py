"""Probe volumes: the machinery IRRADIANCE_VOLUME, DDGI and RTXGI share (and later surfels,
screen probes and GI-1.0's world cache can reuse).

A ``ProbeVolume`` is one grid of probes shared by the passes of a graph:

* placement: fitted to the scene's bounds, *enclosing the surfaces* (the bounds grown by a
  small margin, so bounce hits on walls lie inside the volume; a volume fitted to the air of a
  room loses the multi-bounce light, see shared/TECHNIQUE_NOTES.md), with ``probes`` along
  the longest side and the other axes in proportion (cells close to cubes); or a fixed
  ``spacing``; or explicit ``probes_x/y/z``; or (RTXGI) ``follow_camera``: a volume of the
  same counts centred on the camera's cell that scrolls by whole cells (toroidal storage: a
  probe keeps its slot while it stays inside; slots that scroll in restart);
* storage (``shaders/probes/common.glsl``): irradiance atlas (bordered octahedral tiles,
  ``irr_size`` texels, float32 rgb + age), distance atlas (``dist_size`` texels, mean d and
  d^2, float32), state texture (relocation offset, active/inactive), all graph-owned history
  (``X@prev`` is last frame's); the per-frame ray texture (rays x probes).

Passes, in graph order:

``ProbeTracePass`` (``probe_trace``, probes/trace.comp): rays from every probe through the
shared ray tracer; hits shaded with direct light (shadow rays), the world's light at the
hit, and last frame's probe irradiance at the hit (infinite bounces). ``ProbeStatePass``
(``probe_state``, probes/state.comp): relocation and classification (RTXGI), else all active
on the lattice. ``ProbeUpdatePass`` (``probe_update``, probes/update.comp): blends the rays
into the atlases with hysteresis. ``ProbeGatherPass`` (``probe_gather``, probes/gather.comp):
``color += diffuse albedo x E / pi`` (RTXGI: + specular albedo x E(R) / pi), the
``GI_IndirectDiffuse`` effect image and the debug views.

History: the probes' state survives light, material, transform and geometry edits (they
follow a moving or switched light through hysteresis, with the fast response to large
changes); a camera cut (a fresh F12 render) and a parameter change reset it. Warm-up: the
update pass asks for ``warmup`` frames before an F12 render accumulates; with
``measure_convergence`` (RTXGI) the warm-up ends earlier once the stored irradiance drifts
by less than ``converge_threshold`` per frame: the mean over the texels of the signed relative
change, so the ray noise of single texels (which keeps their absolute change at 2-9 % per
frame) averages out and what remains is the light still building up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION
from .screen_space import GBUFFER_BOUND, Units, bind_frame, bind_gbuffer, bind_world_light

COLOR = "color"
IRR, DIST, STATE = "probes.irradiance", "probes.distance", "probes.state"
RAYS, CHANGE = "probes.rays", "probes.change"
GLOSSY = "probes.glossy"    # glossy light in colour (world reflection + probe glossy): SSR's fallback
WORLD_SPEC = "aov.world_spec"  # DIRECT's shadowed world reflection (techniques/direct.py)
EFFECT = "probe_gather.effect"
VIEW_IRR, VIEW_STATE, VIEW_ATLAS = "probes.view_irradiance", "probes.view_state", "probes.view_atlas"
PREV = "@prev"

# probe state survives scene edits (lights move, switch; objects move): hysteresis follows
PROBE_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE})
MAX_PROBES = 16384          # rows of the ray texture
MAX_TILES_PER_ROW = 1024    # cx * cy (distance atlas 16 texels/tile: 16384 px)
PROBE_PROVIDES = frozenset({Effect.INDIRECT_DIFFUSE})

# debug views / effect: AOV name -> resource (every probe technique returns these)
PROBE_OUTPUTS = {"GI_IndirectDiffuse": EFFECT, "GI_ProbeIrradiance": VIEW_IRR, "GI_ProbeState": VIEW_STATE,
                 "GI_ProbeAtlas": VIEW_ATLAS}


@dataclass(frozen=True)
class VolumeConfig:
    """What a technique's volume does (the papers' differences)."""

    visibility: bool = True     # DDGI: distance atlas, Chebyshev, biases, wrap weights
    relocate: bool = False      # RTXGI
    classify: bool = False      # RTXGI
    glossy: bool = False        # RTXGI: glossy indirect from the probes
    measure_convergence: bool = False  # RTXGI: warm-up ends on low variability
    fixed_rays: int = 0         # RTXGI: fixed (unrotated) rays for relocation/classification
    glossy_out: bool = False    # RTXGI_SSR: write GLOSSY (DIRECT's world reflection + probe glossy)

    def defines(self) -> dict:
        d = {}
        if self.visibility:
            d["PROBE_VISIBILITY"] = 1
        if self.relocate:
            d["PROBE_RELOCATE"] = 1
        if self.classify:
            d["PROBE_CLASSIFY"] = 1
        if self.glossy:
            d["PROBE_GLOSSY"] = 1
        return d

    def gather_defines(self) -> dict:
        return {**self.defines(), **({"PROBE_GLOSSY_OUT": 1} if self.glossy and self.glossy_out else {})}


GRID_PARAMS = (
    Param("probes", 8, 2, 64, "probes along the longest side of the scene's bounds (others in proportion)"),
    Param("spacing", 0.0, 0.0, 1e4, "probe spacing in scene units (0 = from `probes`)"),
    Param("probes_x", 0, 0, 64, "probes along x (0 = automatic)"),
    Param("probes_y", 0, 0, 64, "probes along y (0 = automatic)"),
    Param("probes_z", 0, 0, 64, "probes along z (0 = automatic)"),
    Param("margin", 0.05, -0.5, 1.0, "the volume grows past the scene bounds by this fraction of a cell (negative: shrinks)"),
    Param("rays", 128, 8, 1024, "rays per probe per frame"),
    Param("follow_camera", 0, 0, 1, "1: the volume is centred on the camera and scrolls with it"),
    Param("infinite_bounces", 1, 0, 1, "1: hits add last frame's probe irradiance (0: one bounce only)"),
)


def fit_counts(extent: np.ndarray, probes: int) -> np.ndarray:
    """Counts per axis for ``probes`` along the longest side, cells as close to cubes as the
    extent allows (at least 2 per axis)."""
    longest = float(max(extent.max(), 1e-6))
    cell = longest / max(probes - 1, 1)
    return np.clip(np.round(extent / cell).astype(int) + 1, 2, 64)


def limit_counts(counts: np.ndarray) -> np.ndarray:
    """Shrink counts (in proportion) until the ray texture and atlases fit GL limits."""
    counts = np.asarray(counts, int).copy()
    while int(np.prod(counts)) > MAX_PROBES or int(counts[0] * counts[1]) > MAX_TILES_PER_ROW:
        i = int(np.argmax(counts))
        counts[i] = max(2, counts[i] - 1)
    return counts


class ProbeVolume:
    """The grid shared by a graph's probe passes (host side of probes/common.glsl)."""

    def __init__(self, config: VolumeConfig, irr_size: int = 8, dist_size: int = 16):
        self.config = config
        self.irr_size, self.dist_size = int(irr_size), int(dist_size)
        self.counts = np.array([8, 8, 8])
        self.spacing = np.ones(3)
        self.anchor = np.zeros(3)
        self.cell0 = np.zeros(3, int)
        self.cell0_prev = np.zeros(3, int)
        self.key = None          # what the fitted grid was computed from
        self.reset = True        # this frame starts from nothing (every probe new)
        self.passes: list[Pass] = []
        self.grid_pass: Pass | None = None

    # ------------------------------------------------------------ placement
    def initial_counts(self, props: dict) -> np.ndarray:
        c = [int(props.get(k, 0)) for k in ("probes_x", "probes_y", "probes_z")]
        n = int(props.get("probes", 8))
        return limit_counts(np.array([x if x >= 2 else n for x in c]))

    def place(self, scene, props: dict, camera_pos=None) -> bool:
        """Compute the grid from the scene's bounds and the parameters. Returns True when the
        counts changed (the atlases must be reallocated)."""
        lo, hi = scene.world_bounds()
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        extent = np.maximum(hi - lo, 1e-4)
        spacing_p = float(props["spacing"])
        if spacing_p > 0:
            counts = np.clip(np.ceil(extent / spacing_p).astype(int) + 1, 2, 64)
        else:
            counts = fit_counts(extent, int(props["probes"]))
        for i, k in enumerate(("probes_x", "probes_y", "probes_z")):
            if int(props[k]) >= 2:
                counts[i] = int(props[k])
        counts = limit_counts(counts)
        follow = int(props["follow_camera"]) == 1
        if spacing_p > 0:
            spacing = np.full(3, spacing_p)
        else:
            # the grid encloses the surfaces: (counts - 1) cells span the bounds plus the margin
            m = float(props["margin"])
            spacing = np.maximum(extent / np.maximum(counts - 1 - 2 * m, 0.5), 1e-4)
        margin = float(props["margin"]) * spacing
        key = (tuple(np.round(lo, 6)), tuple(np.round(hi, 6)), tuple(counts), tuple(np.round(spacing, 6)), follow)
        changed_counts = tuple(counts) != tuple(self.counts)
        if key != self.key:
            if spacing_p > 0 and not follow:  # centre the fixed-spacing grid on the bounds
                span = (counts - 1) * spacing
                anchor = (lo + hi) * 0.5 - span * 0.5
            else:
                anchor = lo - margin
            moved = self.key is not None and (not np.allclose(anchor, self.anchor) or
                                              not np.allclose(spacing, self.spacing))
            self.anchor, self.spacing, self.counts = anchor, spacing, counts
            if moved or changed_counts:
                self.reset = True
            self.key = key
        self.cell0_prev = self.cell0.copy()
        if follow and camera_pos is not None:
            cam_cell = np.floor((np.asarray(camera_pos, np.float64) - self.anchor) / self.spacing).astype(int)
            self.cell0 = cam_cell - self.counts // 2
        else:
            self.cell0 = np.zeros(3, int)
        if self.reset:
            self.cell0_prev = self.cell0.copy()
        return changed_counts

    @property
    def probe_count(self) -> int:
        return int(np.prod(self.counts))

    def positions(self, state: np.ndarray | None = None) -> np.ndarray:
        """World positions of the probes in slot order (state: (N, 4) offsets, optional)."""
        n = self.probe_count
        idx = np.arange(n)
        cx, cy, cz = (int(c) for c in self.counts)
        s = np.stack([idx % cx, (idx // cx) % cy, idx // (cx * cy)], axis=1)
        cells = self.cell0 + np.mod(s - self.cell0, self.counts)
        pos = self.anchor + cells * self.spacing
        if state is not None:
            pos = pos + state[:, :3]
        return pos

    def atlas_size(self, tile: int) -> tuple[int, int]:
        cx, cy, cz = (int(c) for c in self.counts)
        return (cx * cy * tile, cz * tile)

    @property
    def state_size(self) -> tuple[int, int]:
        cx, cy, cz = (int(c) for c in self.counts)
        return (cx * cy, cz)

    def set_uniforms(self, prog):
        set_uniform(prog, "u_probe_anchor", tuple(float(x) for x in self.anchor))
        set_uniform(prog, "u_probe_spacing", tuple(float(x) for x in self.spacing))
        set_uniform(prog, "u_probe_counts", tuple(int(x) for x in self.counts))
        set_uniform(prog, "u_probe_cell0", tuple(int(x) for x in self.cell0))
        set_uniform(prog, "u_probe_cell0_prev", tuple(int(x) for x in self.cell0_prev))
        set_uniform(prog, "u_irr_size", self.irr_size)
        set_uniform(prog, "u_dist_size", self.dist_size)

    def set_ray_uniforms(self, prog, rays: int, rotation: np.ndarray):
        set_uniform(prog, "u_rays", int(rays))
        set_uniform(prog, "u_fixed_rays", int(self.config.fixed_rays))
        set_uniform(prog, "u_ray_rotation", np.asarray(rotation, np.float32))

    def reallocate(self, rc):
        """The counts changed: reallocate every probe resource of the graph and clear history."""
        for p in self.passes:
            for d in p.resources():
                rc.allocate(d, p.props)
                if d.history:
                    rc.clear_resource(d.name, d.clear)
                    rc.clear_resource(d.name + PREV, d.clear)


def find_volume(graph) -> "ProbeVolume | None":
    """The probe volume of a frame graph (None: not a probe technique)."""
    for p in getattr(graph, "passes", ()):
        if isinstance(p, ProbeTracePass):
            return p.volume
    return None


def read_probes(rc, volume: "ProbeVolume") -> dict:
    """Per-probe values for tests, benchmarks and the viewport overlay (GL thread; after the
    graph's barriers). Returns ``positions`` (N, 3) world (relocation included), ``state``
    (N,) 0 active / 1 inactive / -1 moved this frame, ``offset`` (N, 3), ``irradiance``
    (N, 3) mean E over each tile's interior texels (all directions), ``irradiance_tiles``
    (N, irr-2, irr-2, 3) the interior texels (octahedral layout, row = t.y - 1), ``irradiance_bordered``
    (N, irr, irr, 3) the whole tiles (row = t.y), in slot order."""
    rc.barrier_external([IRR, STATE])  # texture fetch + read-back after the passes' image stores
    cx, cy, cz = (int(c) for c in volume.counts)
    n, t = volume.probe_count, volume.irr_size

    def read(name, comps):
        tex = rc.resources[name]
        w, h = tex.size
        return np.frombuffer(tex.read(), np.float32).reshape(h, w, tex.components)[..., :comps].copy()

    st = read(STATE, 4).reshape(n, 4)  # texel (s.x + cx*s.y, s.z): row-major = slot index
    irr = read(IRR, 3).reshape(cz, t, cx * cy, t, 3).transpose(0, 2, 1, 3, 4).reshape(n, t, t, 3)
    inner = irr[:, 1:t - 1, 1:t - 1]
    return {"positions": volume.positions(st), "state": st[:, 3].copy(), "offset": st[:, :3].copy(),
            "irradiance": inner.mean(axis=(1, 2)), "irradiance_tiles": inner, "irradiance_bordered": irr,
            "spacing": volume.spacing.copy(),
            "counts": volume.counts.copy()}


def random_rotation(seed: int) -> np.ndarray:
    """A uniformly random rotation (Shoemake's quaternion method), reproducible from seed."""
    rng = np.random.default_rng(int(seed) & 0xFFFFFFFF)
    u1, u2, u3 = rng.random(3)
    q = np.array([math.sqrt(1 - u1) * math.sin(2 * math.pi * u2), math.sqrt(1 - u1) * math.cos(2 * math.pi * u2),
                  math.sqrt(u1) * math.sin(2 * math.pi * u3), math.sqrt(u1) * math.cos(2 * math.pi * u3)])
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]], np.float64)


class ProbePass(Pass):
    """A pass of the probe chain: shares the graph's ProbeVolume."""

    history_resets = PROBE_RESETS

    def __init__(self, volume: ProbeVolume, quality=None, *, provides=PROBE_PROVIDES, **props):
        super().__init__(quality, **props)
        self.volume = volume
        self.provides = frozenset(provides)
        volume.passes.append(self)

    def bind_probe_textures(self, rc, prog, units: Units, *, prev: bool):
        sfx = PREV if prev else ""
        res = rc.resources
        units.tex(prog, "u_probe_irr", res[IRR + sfx])
        units.tex(prog, "u_probe_dist", res[DIST + sfx])
        units.tex(prog, "u_probe_state", res[STATE + sfx])


class ProbeTracePass(ProbePass):
    """Rays from every probe (see module docstring); owns the grid parameters."""

    name = "probe_trace"
    params = GRID_PARAMS
    quality_ladder = ({"probes": 6, "rays": 64}, {"probes": 8, "rays": 128},
                      {"probes": 10, "rays": 192}, {"probes": 12, "rays": 256})

    def __init__(self, volume, quality=None, **kw):
        super().__init__(volume, quality, **kw)
        volume.grid_pass = self
        self.reads = (IRR + PREV, DIST + PREV, STATE + PREV)
        self.writes = (RAYS,)

    def resources(self):
        n = self.volume.probe_count
        return (Res(RAYS, size=(int(self["rays"]), n), check="finite"),)

    def compile(self, rc):
        self.volume.counts = self.volume.initial_counts(self.props)
        self.volume.key = None  # placed again from the scene at the next frame (counts included)

    def reset_history(self):
        super().reset_history()
        self.volume.reset = True

    def execute(self, rc, frame):
        vol = self.volume
        scene = rc.scene.scene
        cam = getattr(scene, "camera", None)
        cam_pos = np.asarray(cam.position, np.float64) if cam is not None else None
        if vol.place(scene, self.props, cam_pos):
            vol.reallocate(rc)
            vol.reset = True
        if vol.reset:  # nothing stored yet: last frame's probes are not read
            for n in (IRR, DIST, STATE):
                rc.clear_resource(n + PREV)
        rt = rc.scene.rt()
        prog = rc.programs.compute("probes/trace.comp", {**rt.defines, **vol.config.defines()})
        rt.bind(prog)
        vol.set_uniforms(prog)
        self.rotation = random_rotation(0x5EED0000 + int(frame.sample))
        vol.set_ray_uniforms(prog, int(self["rays"]), self.rotation)
        units = Units(1)
        self.bind_probe_textures(rc, prog, units, prev=True)
        upd = vol.update_pass
        set_uniform(prog, "u_normal_bias", upd.normal_bias())
        set_uniform(prog, "u_view_bias", upd.view_bias())
        set_uniform(prog, "u_seed", int(frame.sample) & 0xFFFFFFFF)
        set_uniform(prog, "u_bounce", 0 if vol.reset or not int(self["infinite_bounces"]) else 1)
        bind_world_light(scene, prog)
        rc.resources[RAYS].bind_to_image(0, read=False, write=True)
        rays = int(self["rays"])
        rc.dispatch(prog, (rays + 31) // 32, vol.probe_count, 1)


class ProbeStatePass(ProbePass):
    """Relocation and classification (RTXGI); a plain lattice otherwise."""

    name = "probe_state"
    params = (
        Param("backface_ratio", 0.25, 0.0, 1.0, "fixed rays hitting back faces above which a probe is inside geometry"),
        Param("min_frontface", 0.2, 0.0, 1.0, "closest front face a probe keeps (fraction of a cell)"),
        Param("max_offset", 0.45, 0.0, 0.45, "largest relocation (fraction of a cell: the offset stays inside that ellipsoid)"),
    )

    def __init__(self, volume, quality=None, **kw):
        super().__init__(volume, quality, **kw)
        self.reads = (RAYS, STATE + PREV)
        self.writes = (STATE,)

    def resources(self):
        return (Res(STATE, size=self.volume.state_size, history=True, check="finite"),)

    def execute(self, rc, frame):
        vol = self.volume
        prog = rc.programs.compute("probes/state.comp", vol.config.defines())
        vol.set_uniforms(prog)
        vol.set_ray_uniforms(prog, int(vol.grid_pass["rays"]), vol.grid_pass.rotation)
        units = Units(1)
        units.tex(prog, "u_ray_tex", rc.resources[RAYS])
        units.tex(prog, "u_prev_state", rc.resources[STATE + PREV])
        set_uniform(prog, "u_backface_ratio", float(self["backface_ratio"]))
        set_uniform(prog, "u_min_frontface", float(self["min_frontface"]) * float(vol.spacing.min()))
        set_uniform(prog, "u_max_offset", float(self["max_offset"]))
        set_uniform(prog, "u_reset", 1 if vol.reset else 0)
        rc.resources[STATE].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, (vol.probe_count + 63) // 64)


class ProbeUpdatePass(ProbePass):
    """Blends the rays into the irradiance and distance atlases (hysteresis)."""

    name = "probe_update"
    params = (
        Param("hysteresis", 0.95, 0.0, 0.999, "weight of the stored value per frame (steady state)"),
        Param("change_threshold", 0.8, 0.0, 1.0,
              "relative luminance change above which hysteresis drops to a quarter (fast response)"),
        Param("ramp", 16.0, 0.0, 1e4, "warm-up: hysteresis <= age / (age + ramp) after a reset"),
        Param("normal_bias", 0.3, 0.0, 1.0, "surface bias along the normal (fraction of the smallest cell side)"),
        Param("view_bias", 0.3, 0.0, 1.0, "surface bias towards the viewer (fraction of the smallest cell side)"),
        Param("warmup", 32, 0, 1024, "frames an F12 render runs before accumulating"),
        Param("converge_threshold", 0.004, 0.0, 1.0,
              "warm-up ends when the probes' mean signed relative change per frame falls below this (measured volumes)"),
    )

    quality_ladder = ({"warmup": 16}, {"warmup": 32}, {"warmup": 48}, {"warmup": 64})

    def __init__(self, volume, quality=None, **kw):
        super().__init__(volume, quality, **kw)
        volume.update_pass = self
        self.reads = (RAYS, STATE, STATE + PREV, IRR + PREV, DIST + PREV)
        self.writes = (IRR, DIST, CHANGE)
        self.variability = None
        self._frames = 0

    @property
    def warmup_frames(self):
        return int(self["warmup"])

    warmup_alone = True  # the probes' rays do not read the image: warm-up frames run the probe passes only

    def normal_bias(self) -> float:
        return float(self["normal_bias"]) * float(self.volume.spacing.min())

    def view_bias(self) -> float:
        return float(self["view_bias"]) * float(self.volume.spacing.min())

    def resources(self):
        v = self.volume
        return (Res(IRR, size=v.atlas_size(v.irr_size), filter_linear=True, history=True, check="radiance"),
                Res(DIST, components=2, size=v.atlas_size(v.dist_size), filter_linear=True, history=True,
                    check="radiance"),
                Res(CHANGE, components=1, size=v.atlas_size(v.irr_size), check="finite"))

    def reset_history(self):
        super().reset_history()
        self._frames = 0
        self.variability = None

    def execute(self, rc, frame):
        vol = self.volume
        res = rc.resources
        rays = int(vol.grid_pass["rays"])
        max_dist = 1.5 * float(np.linalg.norm(vol.spacing))
        for which, out, prev, tile, stats in (("UPDATE_IRRADIANCE", IRR, IRR + PREV, vol.irr_size, True),
                                               ("UPDATE_DISTANCE", DIST, DIST + PREV, vol.dist_size, False)):
            defs = {which: 1, **({"PROBE_STATS": 1} if stats else {})}
            prog = rc.programs.compute("probes/update.comp", defs)
            vol.set_uniforms(prog)
            vol.set_ray_uniforms(prog, rays, vol.grid_pass.rotation)
            units = Units(1)
            units.tex(prog, "u_prev", res[prev])
            units.tex(prog, "u_ray_tex", res[RAYS])
            units.tex(prog, "u_state", res[STATE])
            units.tex(prog, "u_state_prev", res[STATE + PREV])
            set_uniform(prog, "u_hysteresis", float(self["hysteresis"]))
            set_uniform(prog, "u_change_threshold", float(self["change_threshold"]))
            set_uniform(prog, "u_ramp", float(self["ramp"]))
            set_uniform(prog, "u_max_distance", max_dist)
            set_uniform(prog, "u_reset", 1 if vol.reset else 0)
            res[out].bind_to_image(0, read=False, write=True)
            if stats:
                res[CHANGE].bind_to_image(1, read=False, write=True)
            w, h = vol.atlas_size(tile)
            rc.dispatch(prog, (w + 7) // 8, (h + 7) // 8)
        self._frames += 1
        vol.reset = False

    def converged(self, rc):
        """RTXGI: the mean relative change of the stored irradiance per frame (variability)."""
        if not self.volume.config.measure_convergence:
            return None
        if self._frames < 8:
            return False
        rc.barrier_external([CHANGE])
        a = np.frombuffer(rc.resources[CHANGE].read(), np.float32)
        self.variability = abs(float(a.mean())) if a.size else 0.0
        return self.variability < float(self["converge_threshold"])


class ProbeGatherPass(ProbePass):
    """color += the probes' indirect light; effect image and debug views."""

    name = "probe_gather"
    params = (
        Param("debug_views", 1, 0, 1, "write the probe debug render passes (spheres, state, atlas)"),
        Param("sphere_radius", 0.08, 0.01, 0.5, "debug spheres' radius (fraction of the smallest cell side)"),
    )

    def __init__(self, volume, quality=None, **kw):
        super().__init__(volume, quality, **kw)
        self.reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, IRR, DIST, STATE)
        self.optional_reads = GBUFFER_BOUND  # bind_gbuffer
        self.writes = (COLOR, EFFECT, VIEW_IRR, VIEW_STATE, VIEW_ATLAS)
        self.declared = (Res(EFFECT, check="radiance"), Res(VIEW_IRR, check="radiance"),
                         Res(VIEW_STATE, check="radiance"), Res(VIEW_ATLAS, check="radiance"))
        self.glossy_out = volume.config.glossy and volume.config.glossy_out
        if self.glossy_out:
            self.reads += (WORLD_SPEC,)
            self.writes += (GLOSSY,)
            self.declared += (Res(GLOSSY, check="radiance"),)
        self.history_resets = frozenset()

    def execute(self, rc, frame):
        vol = self.volume
        prog = rc.programs.compute("probes/gather.comp", vol.config.gather_defines())
        rc.scene.bind(prog)
        bind_frame(rc, prog, frame)
        vol.set_uniforms(prog)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        self.bind_probe_textures(rc, prog, units, prev=False)
        upd = vol.update_pass
        set_uniform(prog, "u_normal_bias", upd.normal_bias())
        set_uniform(prog, "u_view_bias", upd.view_bias())
        debug = int(self["debug_views"]) == 1 and vol.probe_count <= 4096
        set_uniform(prog, "u_debug", 1 if debug else 0)
        set_uniform(prog, "u_sphere_radius", float(self["sphere_radius"]) * float(vol.spacing.min()))
        res = rc.resources
        res[COLOR].bind_to_image(0, read=True, write=True)
        for unit, n in enumerate((EFFECT, VIEW_IRR, VIEW_STATE, VIEW_ATLAS), start=1):
            res[n].bind_to_image(unit, read=False, write=True)
        if self.glossy_out:
            units.tex(prog, "u_world_spec", res[WORLD_SPEC])
            res[GLOSSY].bind_to_image(5, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
        if not debug:
            for n in (VIEW_IRR, VIEW_STATE, VIEW_ATLAS):
                rc.clear_resource(n)


def probe_chain(config: VolumeConfig, quality, **params) -> list:
    """The four passes of a probe technique sharing one volume. ``params``: per pass name,
    a dict of properties (e.g. ``{"probe_trace": {"probes": 6}}``)."""
    vol = ProbeVolume(config)
    passes = [ProbeTracePass(vol, quality, **params.get("probe_trace", {})),
              ProbeStatePass(vol, quality, **params.get("probe_state", {})),
              ProbeUpdatePass(vol, quality, **params.get("probe_update", {})),
              ProbeGatherPass(vol, quality, **params.get("probe_gather", {}))]
    return passes
