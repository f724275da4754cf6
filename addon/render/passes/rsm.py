"""Reflective shadow maps (Dachsbacher & Stamminger 2005), shared by RSM and LPV.

* ``RSMPass`` (raster): one reflective shadow map per view of every shadow-casting light,
  tiled in 2D atlases (like the shadow atlas): ``rsm.position`` (world position, w = 1 where
  a surface was seen), ``rsm.normal`` (normal turned towards the light) and ``rsm.flux``
  (the flux the texel's surface patch reflects diffusely, in W, from Cycles' light units).
  Views: a spot light whose cone is at most 120 degrees gets one perspective view; point,
  wider spot and area lights get six 90-degree cube faces (tiles of the atlas, one draw per
  face; no paraboloids); a sun gets one orthographic view over the scene's bounds
  intersected with a box of ``sun_extent`` around the camera. The view matrices come from
  ``passes/shadows.py``'s helpers (perspective, ortho, look_at, CUBE_DIRS).
  Flux of a texel (radiometry in Cycles' units, see the page):
  point/spot ``Φ = ρ_d · I(ω) · dω`` with ``dω = t² cos³α`` the texel's solid angle (t the
  texel size on the unit image plane, α the angle to the view axis); area lights (from
  their centre) ``I(ω) = L_e A max(0, cos θ_L)``; sun ``Φ = ρ_d · E · A_texel``. ρ_d is the
  diffuse albedo of the Principled layer at the light's incidence (lib/albedo.glsl).
  The world light (its sky; a sun taken out of the map is a sun light above) gets
  ``world_directions`` orthographic views per frame along directions drawn by the map's
  luminance (world_map.world_light_directions, rotated every frame of an accumulation),
  each a sun of irradiance ``E = L(ω) / (K p(ω))``: their sum over the frames estimates the
  sky's irradiance integral, so the sky-lit surfaces become VPLs. Mesh lights are not
  injected (the planner reports it).
* ``RSMGatherPass`` (compute): one bounce of indirect diffuse from the VPLs. Samples are
  placed in a disk of radius ``radius`` (fraction of the map) around the receiver's
  projection by ξ1 (r = radius·ξ1) and weighted by ξ1² (the paper; normalised so that a
  constant flux sums exactly: 3πR²ξ1²/N with R in texels) or, with ``exact_weights``, by
  the exact inverse density 2πR²ξ1/N. Kernel
  ``Φ·max(0,⟨n_p,x−x_p⟩)·max(0,⟨n,x_p−x⟩)/max(‖x−x_p‖², d_min²)²``: the clamp ``min_distance``
  bounds the singularity and darkens contacts closer than d_min (bias, see the page).
  The pattern is shared by all pixels of a frame: window ``index`` of one R2 sequence, the
  frame's index in the current accumulation (accumulation converges to the full sum over
  the disk; a moving view or light keeps window 0, so the pattern's error does not jump
  from frame to frame). A sample's VPL is its nearest texel (a bilinear blend of 4 texels
  would move continuously with the light, but a blend across a depth edge is a VPL in mid-air:
  sun-lit room relMSE 0.0098 -> 0.0179). It runs at ``low_scale`` of the resolution,
  then ``RSMResolvePass`` interpolates the four nearest low-resolution samples where their
  normals and planes agree with the pixel's (at least three), and gathers again at full
  resolution where they do not (the paper's screen-space scheme).
* ``RSMDebugPass``: the flux atlas stretched over the frame (render pass GI_RSM_Flux).
* ``indirect_temporal``: the screen-space family's TemporalPass on the gathered signal
  (reprojected running mean over ``max_history`` frames, 8 by default, moving or not). Its
  history survives light and transform edits (a moving light is the common case; the
  8-frame window bounds the lag) and resets on camera cuts, parameter and geometry changes.
  It removes the frame-to-frame jitter of the VPL sample set (RSM) and of the cell
  quantisation (LPV) under a moving light or camera (measured on the pages).
* ``LightGatedGraph``: a FrameGraph whose indirect effects are skipped, with the reason,
  when no light casts shadows (the VPLs come only from shadow-casting lights).
Shaders: ``shaders/raster3d/``.
"""
from __future__ import annotations

import math

import numpy as np

from ..framegraph import CAMERA_CUT, HOST, PARAM_CHANGE, Effect, FrameGraph, Param, Pass, Res
from ..gpu_scene import set_uniform
from ..scene_data import LightType
from ..world_map import world_light_directions
from .gbuffer import GEONORMAL, NORMAL, POSITION
from .screen_space import GBUFFER_BOUND, TemporalPass, Units, bind_frame, bind_gbuffer, scaled
from .shadows import CUBE_DIRS, look_at, ortho, perspective, world_view

RSM_POS, RSM_NRM, RSM_FLUX, RSM_VIEWS = "rsm.position", "rsm.normal", "rsm.flux", "rsm.views"
MAX_RSM_VIEWS = 24  # matches RSM_MAX_VIEWS in shaders/raster3d/rsm_common.glsl
INDIRECT = frozenset({Effect.INDIRECT_DIFFUSE})


def shadow_lights(scene) -> list[int]:
    """Indices of the lights that cast shadows and emit (RSM/LPV/VXGI inject only these)."""
    return [i for i, L in enumerate(scene.lights) if L.cast_shadow and float(np.max(L.color)) > 0.0]


class LightGatedGraph(FrameGraph):
    """Skips the passes of the given effects, with a reason, when no light casts shadows.

    ``compile`` runs before ``plan`` in the session, so the graph sees the scene there."""

    gated = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR, Effect.AO})
    _scene = None

    def compile(self, rc, force: bool = False):
        self._scene = rc.scene.scene if rc.scene is not None else None
        return super().compile(rc, force)

    def plan(self, needed, reasons=None):
        reasons = dict(reasons or {})
        sc = self._scene
        if sc is not None and not shadow_lights(sc) and not world_injected(sc, self.passes):
            world_on = sc.world is not None and float(np.max(sc.world.color)) > 0.0
            lights_on = any(float(np.max(L.color)) > 0 for L in sc.lights)
            if world_on and not lights_on:
                why = "open sky only, and the RSM's world directions are 0: the world light is not injected"
            else:
                why = "no light casts shadows (the injected light comes from shadow-casting lights and the world)"
            needed = set(needed) - self.gated
            for e in self.gated:
                reasons[e] = why
        return super().plan(needed, reasons)


def world_injected(scene, passes) -> bool:
    """Does an RSM pass among ``passes`` inject the world light of ``scene``?"""
    if scene.world is None or float(np.max(scene.world.color)) <= 0.0:
        return False
    return any(isinstance(p, RSMPass) and int(p.props.get("world_directions", 0)) > 0 for p in passes)


class RSMViews:
    """This frame's RSM views (a host resource): per view the view-projection, origin,
    whether it is orthographic, the forward axis, the texel size (tangent-plane units for
    perspective views, world units for orthographic), the light index, and the atlas rect."""

    def __init__(self, views=(), cols=1, res=1):
        self.views, self.cols, self.res = list(views), cols, res

    def release(self):
        pass

    def uniforms(self, prog, atlas_size):
        n = len(self.views)
        vp = np.zeros((MAX_RSM_VIEWS, 4, 4), np.float32)
        org = np.zeros((MAX_RSM_VIEWS, 4), np.float32)
        fwd = np.zeros((MAX_RSM_VIEWS, 4), np.float32)
        rect = np.zeros((MAX_RSM_VIEWS, 4), np.float32)
        for i, v in enumerate(self.views):
            vp[i] = v["vp"].T  # column-major
            org[i, :3], org[i, 3] = v["origin"], v["ortho"]
            fwd[i, :3], fwd[i, 3] = v["fwd"], v["texel"]
            x0, y0 = (i % self.cols) * self.res, (i // self.cols) * self.res
            rect[i] = (x0, y0, self.res, self.res)
        set_uniform(prog, "u_rsm_count", n)
        for name, arr in (("u_rsm_vp", vp), ("u_rsm_origin", org), ("u_rsm_fwd", fwd), ("u_rsm_rect", rect)):
            if name in prog:
                prog[name].write(arr.tobytes())


def rsm_views(scene, res: int, sun_extent: float, max_views: int = MAX_RSM_VIEWS) -> list[dict]:
    """The views of the shadow-casting lights (see the module docstring), at most
    ``max_views``: whole lights only, suns first, then by power (largest first; ties keep
    the scene's order), so a scene with more lights than the atlas holds injects its
    brightest ones (``RSMPass.notes`` says how many)."""
    lo, hi = scene.world_bounds()
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    center = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(hi - lo)) * 0.5, 1e-3)
    order = sorted(shadow_lights(scene), key=lambda i: (scene.lights[i].type != LightType.SUN,
                                                        -float(scene.lights[i].power)))
    out = []
    for li in order:
        lv = _light_views(scene.lights[li], li, res, sun_extent, scene.camera, lo, hi, center, radius)
        if len(out) + len(lv) <= max_views:  # whole lights; a light with fewer views may still fit
            out += lv
    return out


def world_views(scene, k: int, index: int, res: int) -> list[dict]:
    """``k`` orthographic views of the world light for frame ``index`` (module docstring):
    each covers the scene's bounds, looks along the light's travel and carries ``e``, the
    irradiance its texels receive at normal incidence."""
    if k <= 0 or scene.world is None or float(np.max(scene.world.color)) <= 0.0:
        return []
    lo, hi = (np.asarray(v, np.float64) for v in scene.world_bounds())
    center = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(hi - lo)) * 0.5, 1e-3)
    omegas, L, pdf = world_light_directions(scene.world, k, index)
    out = []
    for omega, l, p in zip(omegas, L, pdf):
        if not p > 0.0:
            continue
        d = -np.asarray(omega, np.float64)  # the direction light travels
        vp, eye = world_view(center, radius, d)
        out.append({"vp": vp, "origin": eye, "ortho": 1.0, "fwd": d, "texel": 2.0 * radius * 1.02 / res,
                    "light": -1, "e": np.asarray(l, np.float64) / (k * float(p))})
    return out


def _light_views(L, li, res, sun_extent, cam, lo, hi, center, radius) -> list[dict]:
    """The RSM views of light ``L`` (index ``li``): see the module docstring."""
    if L.type == LightType.SUN:
        d = L.direction.astype(np.float64)
        c, r = center, radius
        if sun_extent > 0 and cam is not None and radius > sun_extent:
            # over the camera's region: the scene box clipped to a box around the camera
            cp = np.asarray(cam.position, np.float64)
            blo, bhi = np.maximum(lo, cp - sun_extent), np.minimum(hi, cp + sun_extent)
            if np.all(bhi > blo):
                c, r = 0.5 * (blo + bhi), max(float(np.linalg.norm(bhi - blo)) * 0.5, 1e-3)
        eye = c - d * (2.0 * radius + r)
        vp = ortho(r, 0.0, 4.0 * radius + 2.0 * r) @ look_at(eye, d, (0, 0, 1))
        return [{"vp": vp, "origin": eye, "ortho": 1.0, "fwd": d, "texel": 2.0 * r / res, "light": li}]
    origin = np.asarray(L.position, np.float64)
    far = float(np.linalg.norm(origin - center)) + radius * 1.01 + 1e-3
    near = max(far * 1e-4, min(1e-3, far * 1e-3))  # 1 mm, or a thousandth of a smaller scene
    if L.type == LightType.SPOT and L.spot_size <= math.radians(120.0):
        fov = min(math.radians(150.0), L.spot_size * 1.02 + math.radians(1.0))
        d = L.direction.astype(np.float64)
        vp = perspective(fov, near, far) @ look_at(origin, d, (0, 0, 1))
        return [{"vp": vp, "origin": origin, "ortho": 0.0, "fwd": d / np.linalg.norm(d),
                 "texel": 2.0 * math.tan(fov / 2) / res, "light": li}]
    fov = math.radians(90.0)  # exact cube: every direction in exactly one face
    out = []
    for fwd, up in CUBE_DIRS:
        if L.type == LightType.AREA and float(np.dot(fwd, L.direction)) < -0.99:
            continue  # a one-sided area light emits nothing into the face behind it
        vp = perspective(fov, near, far) @ look_at(origin, fwd, up)
        out.append({"vp": vp, "origin": origin, "ortho": 0.0, "fwd": np.asarray(fwd, np.float64),
                    "texel": 2.0 / res, "light": li})
    return out


class RSMPass(Pass):
    """Renders the reflective shadow maps of every shadow-casting light (see module doc)."""

    name = "rsm"
    kind = "raster"
    provides = INDIRECT
    writes = (RSM_POS, RSM_NRM, RSM_FLUX, RSM_VIEWS)
    declared = (Res(RSM_POS, managed=False, check="finite"), Res(RSM_NRM, managed=False, check="finite"),
                Res(RSM_FLUX, managed=False, check="radiance"),
                Res(RSM_VIEWS, kind=HOST, managed=False, check="none"))
    history_resets = frozenset()
    params = (
        Param("rsm_resolution", 128, 16, 1024, "texels per side of one RSM view"),
        Param("sun_extent", 0.0, 0.0, 1e5, "sun RSM: half size of the region around the camera (0 = whole scene)"),
        Param("world_directions", 4, 0, MAX_RSM_VIEWS, "world light: orthographic views per frame along directions drawn "
              "by the map's luminance (0 = the sky adds no bounce)"),
    )
    quality_ladder = ({"rsm_resolution": 64, "world_directions": 2}, {"rsm_resolution": 128},
                      {"rsm_resolution": 256, "world_directions": 8}, {"rsm_resolution": 512, "world_directions": 8})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.tex = None
        self.fbo = self.depth = None
        self.views = RSMViews()
        self.notes: list[str] = []  # what this frame left out (the session reports it)

    def _ensure(self, rc, n: int, res: int):
        import moderngl

        cols = max(1, math.ceil(math.sqrt(max(n, 1))))
        rows = max(1, math.ceil(max(n, 1) / cols))
        size = (cols * res, rows * res)
        if self.tex is None or self.tex[0].size != size:
            self.release()
            self.tex = [rc.ctx.texture(size, 4, dtype=dt) for dt in ("f4", "f2", "f4")]
            for t in self.tex:
                t.filter = (moderngl.NEAREST, moderngl.NEAREST)
                t.repeat_x = t.repeat_y = False
            self.depth = rc.ctx.depth_texture(size)
            self.fbo = rc.ctx.framebuffer(color_attachments=self.tex, depth_attachment=self.depth)
        for name, t in zip((RSM_POS, RSM_NRM, RSM_FLUX), self.tex):
            rc.resources[name] = t
        return cols

    def execute(self, rc, frame):
        import moderngl

        scene = rc.scene.scene
        res = int(self["rsm_resolution"])
        views = rsm_views(scene, res, float(self["sun_extent"]))
        n_lights, n_in = len(shadow_lights(scene)), len({v["light"] for v in views})
        self.notes = ([f"RSM: {n_in} of {n_lights} shadow-casting lights injected (atlas of {MAX_RSM_VIEWS} views, "
                       "brightest first); the others add no bounce"] if n_in < n_lights else [])
        k_world = int(self.props.get("world_directions", 0)) if world_injected(scene, (self,)) else 0
        wv = world_views(scene, min(k_world, MAX_RSM_VIEWS - len(views)), frame.index, res)
        if len(wv) < k_world:
            self.notes.append(f"RSM: {len(wv)} of {k_world} world directions fit in the atlas of {MAX_RSM_VIEWS} views")
        views += wv
        cols = self._ensure(rc, len(views), res)
        self.views = RSMViews(views, cols, res)
        rc.resources[RSM_VIEWS] = self.views
        ctx = rc.ctx
        prog = rc.programs.program("raster3d/rsm.vert", "raster3d/rsm.frag")
        rc.scene.bind(prog)
        set_uniform(prog, "u_alpha_seed", int((frame.sample * 2654435761 + frame.seed * 40503 + 29) & 0x7FFFFFFF))
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        for i, v in enumerate(views):
            ctx.viewport = ((i % cols) * res, (i // cols) * res, res, res)
            set_uniform(prog, "u_view_proj", v["vp"].astype(np.float32))
            set_uniform(prog, "u_origin", tuple(float(x) for x in v["origin"]))
            set_uniform(prog, "u_fwd", tuple(float(x) for x in v["fwd"]))
            set_uniform(prog, "u_ortho", int(v["ortho"]))
            set_uniform(prog, "u_texel", float(v["texel"]))
            set_uniform(prog, "u_light", int(v["light"]))
            set_uniform(prog, "u_world_e", tuple(float(x) for x in v.get("e", (0.0, 0.0, 0.0))))
            rc.scene.draw(prog)
        ctx.disable(moderngl.DEPTH_TEST)

    def release(self):
        for o in (self.fbo, *(self.tex or ()), self.depth):
            if o is not None:
                o.release()
        self.fbo = self.depth = None
        self.tex = None


GATHER_PARAMS = (
    Param("vpl_samples", 64, 4, 1024, "VPL samples per RSM view per pixel per frame"),
    Param("radius", 1.0, 0.05, 1.5, "sampling disk radius, fraction of the RSM side (1.42 = whole map)"),
    Param("min_distance", 0.1, 0.0, 10.0, "distance clamp d_min of the 1/d^4 kernel (scene units)"),
    Param("exact_weights", True, doc="weight samples by the exact inverse density 2ξ1 (default; False = the paper's ξ1², biased dark: cornell 0.81-0.86x)"),
)


def bind_rsm(rc, prog, units: Units, gather: Pass):
    res = rc.resources
    units.tex(prog, "u_rsm_pos", res[RSM_POS])
    units.tex(prog, "u_rsm_nrm", res[RSM_NRM])
    units.tex(prog, "u_rsm_flux", res[RSM_FLUX])
    res[RSM_VIEWS].uniforms(prog, res[RSM_POS].size)
    set_uniform(prog, "u_vpl_samples", int(gather["vpl_samples"]))
    set_uniform(prog, "u_disk_radius", float(gather["radius"]))
    set_uniform(prog, "u_min_distance", float(gather["min_distance"]))
    set_uniform(prog, "u_exact_weights", 1 if gather["exact_weights"] else 0)


def bind_pattern(prog, frame):
    """The VPL pattern's index: the frame's index within the current accumulation, so an
    accumulation (F12, a still viewport) walks consecutive windows of one R2 sequence
    (rsm_common.glsl) and converges, while a moving view or light (each frame a new
    accumulation) keeps window 0: the pattern's structured error does not change from frame
    to frame. Walking the windows by the frame's sample counter instead (the temporal pass
    then averages 8 of them) flickers more: 60 moving frames, q0, 1.24x Cycles' frame-to-frame
    change against 1.08x with window 0 (the 8-frame running mean leaves an eighth of each new
    window's error as flicker; without the temporal pass a new pattern every frame measures
    5.3x)."""
    set_uniform(prog, "u_pattern", int(frame.index) & 0xFFFFFFFF)


class RSMGatherPass(Pass):
    """Low-resolution gather (``rsm.low``, rgb = E/π, the incident irradiance over π)."""

    name = "rsm_gather"
    provides = INDIRECT
    reads = (POSITION, NORMAL, GEONORMAL, RSM_POS, RSM_NRM, RSM_FLUX, RSM_VIEWS)
    optional_reads = GBUFFER_BOUND  # bind_gbuffer
    writes = ("rsm.low",)
    declared = (Res("rsm.low", scale="low_scale", check="radiance"),)
    history_resets = frozenset()
    params = GATHER_PARAMS + (
        Param("low_scale", 0.25, 0.125, 1.0, "resolution scale of the first gather"),
        Param("normal_tolerance", 0.9, 0.0, 1.0, "interpolation: min cosine between normals"),
        Param("plane_tolerance", 0.02, 0.0, 1.0, "interpolation: max plane distance, fraction of view depth"),
    )
    # q0 32 samples (was 16): 60 moving frames measured 1.06x Cycles' frame-to-frame change with
    # 16, 0.99x with 32 (docs/techniques/RSM.md, Stability)
    quality_ladder = ({"vpl_samples": 32, "low_scale": 0.25}, {"vpl_samples": 64, "low_scale": 0.25},
                      {"vpl_samples": 128, "low_scale": 0.5}, {"vpl_samples": 256, "low_scale": 0.5})

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/rsm_gather.comp", {"RSM_LOW": 1})
        rc.scene.bind(prog)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        bind_rsm(rc, prog, units, self)
        bind_pattern(prog, frame)
        size = scaled(rc.size, float(self["low_scale"]))
        set_uniform(prog, "u_low_size", size)
        rc.resources["rsm.low"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, (size[0] + 7) // 8, (size[1] + 7) // 8)


class RSMResolvePass(Pass):
    """Full resolution: interpolate ``rsm.low`` where it is valid, gather again elsewhere.
    Writes ``rsm.raw`` (rgb = E/π, a = 1) and ``rsm.regather`` (1 where gathered again)."""

    name = "rsm_resolve"
    provides = INDIRECT
    reads = RSMGatherPass.reads + ("rsm.low",)
    optional_reads = GBUFFER_BOUND  # bind_gbuffer
    writes = ("rsm.raw", "rsm.regather")
    declared = (Res("rsm.raw", check="radiance"), Res("rsm.regather", dtype="f2", check="radiance"))
    history_resets = frozenset()

    def __init__(self, quality=None, *, gather: RSMGatherPass, **kw):
        super().__init__(quality, **kw)
        self.gather = gather

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/rsm_gather.comp", {"RSM_RESOLVE": 1})
        rc.scene.bind(prog)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        bind_rsm(rc, prog, units, self.gather)
        bind_pattern(prog, frame)
        units.tex(prog, "u_low", rc.resources["rsm.low"])
        g = self.gather
        set_uniform(prog, "u_low_size", scaled(rc.size, float(g["low_scale"])))
        set_uniform(prog, "u_low_scale", float(g["low_scale"]))
        set_uniform(prog, "u_normal_tol", float(g["normal_tolerance"]))
        set_uniform(prog, "u_plane_tol", float(g["plane_tolerance"]))
        rc.resources["rsm.raw"].bind_to_image(0, read=False, write=True)
        rc.resources["rsm.regather"].bind_to_image(1, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


TEMPORAL_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry"})


def indirect_temporal(quality, *, name: str, source: str, output: str, frames: int = 8) -> TemporalPass:
    """Reprojected running mean of an indirect signal over ``frames`` frames (module doc)."""
    return TemporalPass(quality, name=name, source=source, output=output, background=(0.0, 0.0, 0.0, 1.0),
                        resets=TEMPORAL_RESETS, provides=INDIRECT, max_history=frames,
                        max_history_moving=frames)


class RSMDebugPass(Pass):
    """The flux atlas stretched over the frame (GI_RSM_Flux): what every light's RSM sees,
    as flux per texel times the texels of one view (W: the view's flux if uniform)."""

    name = "rsm_debug"
    provides = INDIRECT
    reads = (RSM_FLUX, RSM_VIEWS)
    writes = ("rsm.debug_flux",)
    declared = (Res("rsm.debug_flux", check="radiance"),)
    history_resets = frozenset()

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/rsm_debug.comp")
        rc.resources[RSM_FLUX].use(1)
        set_uniform(prog, "u_rsm_flux", 1)
        views = rc.resources[RSM_VIEWS]
        set_uniform(prog, "u_scale", float(views.res * views.res))
        rc.resources["rsm.debug_flux"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
