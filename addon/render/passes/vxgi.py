"""Voxel cone tracing (Crassin, Neyret, Sainz, Green, Eisemann 2011), the passes of VXGI.

* ``VoxelizePass`` (raster): the whole scene into ``cascades`` grids of
  ``resolution``³ voxels centred on the camera. Each cascade's voxels are twice the size
  of the previous one's; the coarsest covers the scene's bounds, the finer ones are
  centred on the camera and clamped into the scene's box; corners are snapped to 4 voxels
  of their cascade (a camera move shifts a grid by whole voxels, and mip levels 0-2 keep
  their cells; a moving cascade is read at those levels only and wider footprints go to the
  next cascade, so a snap does not shift the texels a cone reads: the coarsest cascade never
  moves). Conservative voxelisation by geometry-shader dominant-axis projection of
  each triangle, enlarged by half a pixel (plus ``thickness`` voxels) per edge, then an
  exact triangle/box overlap test for every voxel of the fragment's column
  (``shaders/vxgi/voxelize.*``). Chosen over a compute voxeliser because llvmpipe's
  rasteriser spreads the work of large triangles over its threads, where a thread per
  triangle would leave one thread walking a whole wall. Each overlapping triangle adds its
  diffuse albedo, normal (the mesh's orientation) and the voxel centre's distance to its
  plane to the voxel's record of its orientation bucket (dominant axis and sign of the
  normal; ``vxgi.voxels``, an SSBO of VX_REC words per voxel, float atomics by
  compare-and-swap): surfaces of one voxel at an angle or facing apart stay apart.
* ``VoxelInjectPass`` (compute): per voxel and orientation bucket → direct light from every
  light in Cycles' units on both sides of the voxel's surface, shadowed by the shadow maps
  (the shadow atlas; suns through their RSM view, which covers the whole scene while the
  atlas' sun cascades cover only the camera's frustum), optionally plus last frame's
  indirect irradiance and sky light gathered by six cones per side through the history
  volume (``multi_bounce``); after a history reset, ``reset_bounces`` runs within the frame, each
  gathering from the previous run's volume, so the first frame is converged (no warm-up
  frames); the direct light is computed by the first of those runs only (stored per voxel
  list entry, loaded by the others). Many lights (``light_cull``, from ``MIN_CULL_LIGHTS``
  lights on): each voxel shades exactly the lights whose range of influence
  (``light_cull.light_ranges``, DIRECT's) holds its centre, the others by ``cull_samples``
  power-sampled lights (unbiased). Writes level 0 of ``vxgi.radiance``: six directional volumes
  (the radiance each voxel emits towards ±x, ±y, ±z: the surface side facing that way;
  a dilated voxel shows only the side it lies on; opacity at least ``edge_opacity``),
  then builds the anisotropic mips (``shaders/vxgi/mip.comp``, front-to-back compositing of
  the two children along each direction, as in the paper).
* ``VoxelTracePass`` (compute): per pixel, six diffuse cones (weights integrating the
  cosine lobe) and one specular cone (aperture from roughness) through the volume; adds
  ``albedo_d·E/π + albedo_s·L_spec`` to DIRECT's colour; writes the effect AOVs and AO.
* ``VoxelDebugPass``: the volume at mip ``mip`` as the camera sees it (GI_VXGI_Voxels).

Radiometry: voxels hold outgoing radiance of Lambertian surfaces (W/m²/sr) from
irradiance in Cycles' units; no gamma, no bounce scale. Emission is not voxelised: every
emissive instance is a mesh light that lights the voxels, and DIRECT draws the emitters.
"""
from __future__ import annotations

import math

import numpy as np

from ..barriers import BUFFER_UPDATE_BARRIER_BIT
from ..framegraph import (BUFFER, CAMERA_CUT, HOST, PARAM_CHANGE,
                          SHADER_IMAGE_ACCESS_BARRIER_BIT, SHADER_STORAGE_BARRIER_BIT, TEX3D,
                          TEXTURE_FETCH_BARRIER_BIT, TEXTURE_UPDATE_BARRIER_BIT, Effect, Param, Pass, Res)
from ..gpu_scene import set_uniform
from ..rt_scene import light_selection
from .gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION
from .light_cull import light_ranges
from .rsm import RSM_POS, RSM_VIEWS, LightGatedGraph, MAX_RSM_VIEWS, shadow_lights
from .screen_space import COLOR, GBUFFER_BOUND, Units, bind_frame, bind_gbuffer, camera_vectors
from .shadows import ATLAS, VIEWS

VOXELS, GRID, RADIANCE = "vxgi.voxels", "vxgi.grid", "vxgi.radiance"
# the occupied-voxel list (count + indices, appended by the voxelisation), the injection's
# light-culling table and its direct-light store (a reset frame's runs share it)
VX_LIST, VX_CULL, VX_DIRECT = "vxgi.list", "vxgi.cull", "vxgi.direct"
DIFFUSE, GLOSSY, AO, DEBUG = "vxgi.diffuse", "vxgi.glossy", "vxgi.ao", "vxgi.debug"
VX_REC = 1 + 6 * 8  # words per voxel record: bucket mask + 6 orientation buckets (shaders/vxgi/common.glsl)
MAX_CASCADES = 4
SNAP = 4  # voxels: the cascades' corners move in steps of this many of their voxels
# mip levels a cascade that follows the camera is read at: those whose texels the SNAP-voxel
# steps keep in place (levels 0-2); wider footprints read the next cascade. Otherwise a snap
# shifts the coarser mips' texels by a fraction and the indirect light steps
MOVING_LEVELS = int(math.log2(SNAP)) + 1
BINDING_RECORDS = 5
BINDING_LIST = 4
BINDING_CULL = 6    # inject.comp's light culling table
BINDING_DIRECT = 7  # inject.comp's direct irradiance of a reset frame
DIRECT_FLOATS = 6 * 6  # per voxel list entry: (Ep.rgb, Em.rgb) of each of the 6 orientation buckets
MAX_DIRECT_BYTES = 96 << 20  # below llvmpipe's 128 MiB storage block; entries past it compute every run
GI = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR, Effect.AO})


def mip_levels(n: int) -> int:
    """Mip levels usable inside one cascade: halvings while n stays divisible by 2."""
    levels = 1
    while n % 2 == 0 and n > 1:
        n //= 2
        levels += 1
    return levels


class VoxelGrid:
    """Host resource: this frame's cascades, (corner, voxel size) each, finest first."""

    def __init__(self, origins=(), n: int = 0, moving_levels: int = 0):
        self.origins, self.n = list(origins), int(n)
        # mip levels the cascades that follow the camera (all but the coarsest) may be read at
        # (0: all of them); see MOVING_LEVELS
        self.moving_levels = int(moving_levels)

    @property
    def cascades(self) -> int:
        return len(self.origins)

    @property
    def levels(self) -> int:
        return mip_levels(self.n)

    def release(self):
        pass

    def array(self) -> np.ndarray:
        arr = np.zeros((MAX_CASCADES, 4), np.float32)
        for i, (o, vs) in enumerate(self.origins):
            arr[i, :3], arr[i, 3] = o, vs
        return arr

    def uniforms(self, prog, origin_uniform: str = "u_vx_origin"):
        if origin_uniform in prog:
            prog[origin_uniform].write(self.array().tobytes())
        set_uniform(prog, "u_vx_n", self.n)
        set_uniform(prog, "u_vx_cascades", self.cascades)
        set_uniform(prog, "u_vx_levels", self.levels)
        ml = self.levels if self.moving_levels <= 0 else min(self.levels, self.moving_levels)
        set_uniform(prog, "u_vx_moving_levels", ml)

    def extent(self) -> float:
        """Side of the coarsest cascade (world units)."""
        return self.n * self.origins[-1][1] if self.origins else 0.0


def voxel_cascades(scene, frame, n: int, cascades: int, voxel_size: float, snap: int = 4):
    """(corner, voxel size) per cascade, finest first (see the module docstring)."""
    lo, hi = scene.world_bounds()
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    ext = float(np.max(hi - lo)) * 1.02 + 1e-3
    # the coarsest holds the scene with a margin of a snap step on each side
    coarse = voxel_size * 2 ** (cascades - 1) if voxel_size > 0 else ext / max(n - 2 * snap, 1)
    cam, _ = camera_vectors(frame)
    centre_scene = 0.5 * (lo + hi)
    out = []
    for c in range(cascades):
        vs = coarse / 2 ** (cascades - 1 - c)
        side = n * vs
        if c == cascades - 1:
            centre = centre_scene
        else:
            centre = np.empty(3)
            for k in range(3):
                a, b = lo[k] + 0.5 * side, hi[k] - 0.5 * side
                centre[k] = np.clip(cam[k], a, b) if a <= b else centre_scene[k]
        step = vs * snap
        corner = np.floor((centre - 0.5 * side) / step) * step
        out.append((corner.astype(np.float32), float(vs)))
    return out


class VXGIGraph(LightGatedGraph):
    """LightGatedGraph (skips, with the reason, when no light casts shadows), except that
    an emissive mesh is a light too (it lights the voxels through its shadow-atlas cube), and
    so is the world: the voxels gather it through their cones (sky light that reaches a
    surface and bounces on)."""

    def plan(self, needed, reasons=None):
        sc = self._scene
        world_lit = sc is not None and sc.world is not None and float(np.max(sc.world.color)) > 0.0
        if sc is not None and not shadow_lights(sc) and (world_lit or any(m.is_emissive for m in sc.materials)):
            from ..framegraph import FrameGraph

            return FrameGraph.plan(self, needed, reasons)
        return super().plan(needed, reasons)


class VoxelizePass(Pass):
    name = "vxgi_voxelize"
    kind = "raster"
    provides = GI
    writes = (VOXELS, GRID, VX_LIST)
    declared = (Res(VOXELS, kind=BUFFER, managed=False, check="none"),
                Res(GRID, kind=HOST, managed=False, check="none"),
                Res(VX_LIST, kind=BUFFER, dtype="u4", managed=False, check="none"))
    # records and list by shader-storage stores from the fragment shader; the list's count
    # is reset by an upload first
    write_access = {VOXELS: "storage", VX_LIST: ("upload", "storage")}
    history_resets = frozenset()
    params = (
        Param("resolution", 64, 8, 256, "voxels per side of one cascade (a multiple of 8 keeps 4 mip levels)"),
        Param("cascades", 2, 1, MAX_CASCADES, "cascades centred on the camera (voxel size doubles)"),
        Param("voxel_size", 0.0, 0.0, 100.0, "finest voxel size (0 = the coarsest cascade holds the scene)"),
        Param("thickness", 1.0, 0.0, 2.0, "voxelisation dilation in voxels (thicker walls against leaks)"),
    )
    quality_ladder = ({"resolution": 32}, {"resolution": 48}, {"resolution": 64}, {"resolution": 96})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.buf = self.list = None
        self.fbo = None
        self.grid = VoxelGrid()
        self._key = None  # what the records hold (scene versions, cascades, thickness)
        self.revoxelised = False  # the last frame voxelised the scene (False: kept the records)

    def _ensure(self, rc, n: int, cascades: int) -> bool:
        """Buffers for n^3 x cascades voxels; True when they were (re)allocated (zero records)."""
        size = n * n * n * cascades * VX_REC * 4
        fresh = self.buf is None or self.buf.size != size
        if fresh:
            for o in (self.buf, self.list):
                if o is not None:
                    o.release()
            self.buf = rc.ctx.buffer(reserve=size)
            self.buf.clear()  # the injection clears the records it reads; this is the start
            self.list = rc.ctx.buffer(reserve=4 * (1 + n * n * n * cascades))
        if self.fbo is None or tuple(self.fbo.size) != (n, n):
            if self.fbo is not None:
                self.fbo.release()
            self.fbo = rc.empty_framebuffer((n, n))
        return fresh

    def execute(self, rc, frame):
        import moderngl

        n, C = int(self["resolution"]), int(self["cascades"])
        fresh = self._ensure(rc, n, C)
        grid = VoxelGrid(voxel_cascades(rc.scene.scene, frame, n, C, float(self["voxel_size"]), snap=SNAP), n,
                         MOVING_LEVELS)
        gs = rc.scene
        v = gs.versions
        key = (id(gs), v["geometry"], v["transforms"], v["materials"], v["textures"], grid.array().tobytes(),
               grid.moving_levels, float(self["thickness"]))
        rc.resources[VOXELS] = self.buf
        rc.resources[VX_LIST] = self.list
        if not fresh and key == self._key:
            # nothing the voxels hold changed (surfaces, their albedo, the cascades' placement):
            # the records and the list of occupied voxels stay as they are
            self.revoxelised = False
            rc.resources[GRID] = self.grid
            return
        self.grid = grid
        rc.resources[GRID] = grid
        self.buf.bind_to_storage_buffer(BINDING_RECORDS)
        self.list.bind_to_storage_buffer(BINDING_LIST)
        if not fresh:  # zero the records the last voxelisation wrote (a new buffer is zero)
            clear = rc.programs.compute("vxgi/clear.comp")
            rc.dispatch(clear, (n * n * n * C + 255) // 256)
            # in-pass: the clear's storage writes and list reads -> the list's reset upload and
            # the voxelisation's atomics on the records
            rc.ctx.memory_barrier(BUFFER_UPDATE_BARRIER_BIT | SHADER_STORAGE_BARRIER_BIT)
        # the list of occupied voxels starts empty (the graph orders it after last frame's stores)
        self.list.write(np.zeros(1, np.uint32).tobytes())
        prog = rc.programs.program("vxgi/voxelize.vert", "vxgi/voxelize.frag", geometry="vxgi/voxelize.geom")
        gs.bind(prog)
        grid.uniforms(prog)
        set_uniform(prog, "u_thickness", float(self["thickness"]))
        ctx = rc.ctx
        self.fbo.use()
        ctx.viewport = (0, 0, n, n)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        for c in range(C):
            set_uniform(prog, "u_cascade", c)
            gs.draw(prog)
        self._key = key
        self.revoxelised = True

    def reset_history(self):
        super().reset_history()
        self._key = None  # a parameter change or a camera cut voxelises again

    def release(self):
        for o in (self.buf, self.list, self.fbo):
            if o is not None:
                o.release()
        self.buf = self.list = self.fbo = None
        self._key = None


def radiance_decl(n: int, cascades: int) -> Res:
    return Res(RADIANCE, kind=TEX3D, components=4, dtype="f2", size=(n, n, n * cascades * 6),
               levels=mip_levels(n), filter_linear=True, history=True, check="radiance")


CONE_PARAMS = (
    Param("step", 0.5, 0.1, 2.0, "cone step, fraction of the cone diameter"),
    Param("normal_offset", 3.0, 0.0, 6.0, "cones start this many voxels off the surface"),
    Param("max_distance", 0.0, 0.0, 1e4, "cone length (0 = the coarsest cascade's side)"),
    Param("opacity_scale", 1.0, 1.0, 4.0, "opacity bias: voxel opacity x this (against leaks)"),
    Param("side_angle", 60.0, 20.0, 70.0, "angle of the five side cones from the normal (degrees)"),
    Param("footprint_cap", 0.35, 0.0, 4.0, "diffuse cones' footprint diameter <= this x the sample's height "
          "over the receiver's plane (0 = off): coarse mips never reach back over the receiver's own surface"),
    Param("box_ramp", 0.5, 0.0, 1.0, "each directional face is read as a box along its own axis (a one-voxel "
          "wall stops a cone wherever it lies in a texel): width (in texels) of a linear ramp across each texel "
          "boundary along the face's axis (0 = a hard box, whose value jumps when a cone sample crosses a "
          "boundary as the camera or receiver moves; 1 = the trilinear tent). 0.5 against 0: q1 60-frame "
          "largest step 1.37x -> 1.30x Cycles', mean 0.95x -> 0.88x (q0: largest 1.23x -> 1.46x, mean 0.93x -> "
          "0.87x); Cornell q2 one-bounce 0.925 -> 0.928"),
    Param("audit_radiance", 0.0, 0.0, 1e3, "energy audit (tests): > 0 = both sides of every voxelised surface "
          "show this radiance (no lights, no bounce) and GI_IndirectDiffuse holds E/pi (albedo 1); 0 = off"),
)


class VoxelInjectPass(Pass):
    name = "vxgi_inject"
    provides = GI
    reads = (VOXELS, VX_LIST, GRID, RSM_POS, RSM_VIEWS, RADIANCE + "@prev")
    optional_reads = (ATLAS, VIEWS)
    # a history reset ping-pongs the injection runs through the @prev twin (see execute); each
    # run clears level 0 by upload, then stores the occupied voxels. The last run clears the
    # voxel records it read (shader-storage stores) for the next frame's voxelisation.
    writes = (RADIANCE, RADIANCE + "@prev", VOXELS, VX_CULL, VX_DIRECT)
    write_access = {RADIANCE: ("upload", "image"), RADIANCE + "@prev": ("upload", "image"), VOXELS: "storage",
                    VX_CULL: "upload", VX_DIRECT: "storage"}
    # the list's count is read back (a reset frame sizes the direct store), then read by the shader
    read_access = {VX_LIST: ("readback", "storage")}
    history_resets = frozenset({CAMERA_CUT, PARAM_CHANGE})
    params = CONE_PARAMS + (
        Param("multi_bounce", True, doc="inject last frame's indirect irradiance (and sky light) into the voxels"),
        Param("shadow_offset", 0.5, 0.0, 4.0, "shadow lookups start this many voxels off the voxel's surface"),
        Param("mesh_exact_max", 64, 0, 256, "emissive meshes up to this many triangles are integrated exactly"),
        Param("edge_opacity", 0.1, 0.0, 1.0, "smallest level-0 opacity of an occupied voxel towards any "
              "direction (the opacity towards a direction is the surface's projected coverage |n.D|: an "
              "edge-on surface shows black at this opacity; against leaks)"),
        Param("reset_bounces", 6, 1, 16, "injection runs within the frame after a history reset (first frame, "
              "camera cut, parameter change), one bounce more each: the volume starts converged instead of "
              "building up one bounce per frame (1 = that build-up)"),
        Param("light_cull", True, doc="many lights (at least light_cull.MIN_CULL_LIGHTS): a voxel shades exactly "
              "the lights whose range of influence holds its centre (suns always), the others by cull_samples "
              "lights chosen by power (unbiased; off = every light at every voxel)"),
        Param("cull_fraction", 0.05, 0.0, 1.0, "ranges of influence (light_cull.light_ranges, as DIRECT's): where "
              "a light's radiance falls below this fraction of all lights' at the scene's radius"),
        Param("cull_samples", 4, 0, 32, "light samples per orientation bucket per frame for the lights out of a "
              "voxel's range (0 = they are left out: biased dark)"),
    )
    # the voxels' own gather (multi-bounce, sky) steps a whole cone diameter: it runs for
    # every occupied voxel, and later bounces carry less of the image
    quality_ladder = ({"step": 1.0, "reset_bounces": 6}, {"step": 1.0, "reset_bounces": 6},
                      {"step": 1.0, "reset_bounces": 8}, {"step": 1.0, "reset_bounces": 8})

    def __init__(self, quality=None, *, voxelize: VoxelizePass, **props):
        super().__init__(quality, **props)
        self.voxelize = voxelize
        self.prev_grid = None
        self.zeros = None  # a zero-filled buffer of level 0's size: clears it by a texture upload
        self.reset_runs = 0  # injection runs in the last frame (> 1: a reset frame that converged in-frame)
        self.cull_buf = self.direct_buf = None
        self._cull_key = None
        self.cull_info: dict = {}  # light_ranges() of the scene (+ "active": culling on this frame)
        self.direct_entries = 0  # voxel list entries the direct store held in the last frame (0: not used)
        self.occupied = 0        # occupied voxels read back in the last reset frame

    def _cull_table(self, rc) -> bool:
        """Uploads inject.comp's culling table (ranges + a power cdf over the lights that have a
        range) when the lights change; True when some light is culled somewhere."""
        gs = rc.scene
        f = float(self["cull_fraction"]) if self["light_cull"] else 0.0
        key = (gs.version, id(gs.scene), f)
        if key != self._cull_key:
            n = int(gs.light_count)
            info = light_ranges(gs, f)
            ranges = info["ranges"][:max(n, 1)]
            prob = np.zeros(max(n, 1), np.float64)
            if n:
                prob[:n] = light_selection(gs.scene, gs.light_array, n)[n:2 * n]
                prob[:n][ranges[:n, 3] < 0] = 0.0  # listed everywhere: never sampled
            tot = float(prob.sum())
            prob = prob / tot if tot > 0 else prob
            cdf = np.cumsum(prob)
            if tot > 0:
                cdf[np.nonzero(prob)[0][-1]:] = 1.0
            table = np.concatenate([ranges.reshape(-1), cdf, prob]).astype(np.float32)
            if self.cull_buf is None or self.cull_buf.size != table.nbytes:
                if self.cull_buf is not None:
                    self.cull_buf.release()
                self.cull_buf = rc.ctx.buffer(reserve=table.nbytes)
            self.cull_buf.write(table.tobytes())
            self.cull_info = dict(info, active=bool(info["partial"] and tot > 0))
            self._cull_key = key
        return bool(self.cull_info["active"])

    def _direct_store(self, rc) -> int:
        """A reset frame's direct-light store, sized to this frame's occupied voxels (read back:
        a reset frame runs the injection several times anyway); returns its capacity in entries."""
        # the graph ordered the read-back after the voxelisation's list appends (read_access)
        count = int(np.frombuffer(rc.resources[VX_LIST].read(size=4), np.uint32)[0])
        self.occupied = count
        entry = DIRECT_FLOATS * 4
        cap = min(max(count, 1), MAX_DIRECT_BYTES // entry)
        if self.direct_buf is None or self.direct_buf.size < cap * entry:
            if self.direct_buf is not None:
                self.direct_buf.release()
            grow = min(max(cap + cap // 4, 1024), MAX_DIRECT_BYTES // entry)
            self.direct_buf = rc.ctx.buffer(reserve=grow * entry)
        return min(count, self.direct_buf.size // entry)

    def resources(self):
        v = self.voxelize
        return (radiance_decl(int(v["resolution"]), int(v["cascades"])),
                Res(VX_CULL, kind=BUFFER, managed=False, check="none"),
                Res(VX_DIRECT, kind=BUFFER, managed=False, check="none"))

    def reset_history(self):
        super().reset_history()
        self.prev_grid = None

    def execute(self, rc, frame):
        res = rc.resources
        grid: VoxelGrid = res[GRID]
        scene = rc.scene.scene
        n, C = grid.n, grid.cascades
        prog = rc.programs.compute("vxgi/inject.comp")
        rc.scene.bind(prog)
        prev = self.prev_grid if (self.history_valid and self.prev_grid is not None
                                  and self.prev_grid.n == n and self.prev_grid.cascades == C) else None
        if "u_cur_origin" in prog:
            prog["u_cur_origin"].write(grid.array().tobytes())
        units = Units(1)
        unit_volume = units.next  # the volume the cones gather from (last frame's, or the last iteration's)
        units.next += 1
        set_uniform(prog, "u_vx_radiance", unit_volume)
        if ATLAS in res and VIEWS in res:
            res[ATLAS].use(units.next)
            set_uniform(prog, "u_shadow_atlas", units.next)
            units.next += 1
            res[VIEWS].bind_to_storage_buffer(3)
        views = res[RSM_VIEWS]
        units.tex(prog, "u_rsm_pos", res[RSM_POS])
        views.uniforms(prog, res[RSM_POS].size)
        li = np.full(MAX_RSM_VIEWS, -1, np.int32)
        for i, v in enumerate(views.views[:MAX_RSM_VIEWS]):
            li[i] = int(v["light"])
        if "u_rsm_light" in prog:
            prog["u_rsm_light"].write(li.tobytes())
        world = np.asarray(scene.world.color if scene.world is not None else (0, 0, 0), np.float64)
        multi, world_lit = bool(self["multi_bounce"]), float(world.max()) > 0.0
        set_uniform(prog, "u_vx_opacity_scale", float(self["opacity_scale"]))
        set_uniform(prog, "u_shadow_offset", float(self["shadow_offset"]))
        set_uniform(prog, "u_normal_offset", float(self["normal_offset"]))
        set_uniform(prog, "u_step", float(self["step"]))
        set_uniform(prog, "u_mesh_exact_max", int(self["mesh_exact_max"]))
        set_uniform(prog, "u_edge_opacity", float(self["edge_opacity"]))
        set_uniform(prog, "u_vx_cap", float(self["footprint_cap"]))
        set_uniform(prog, "u_vx_side_angle", float(np.radians(self["side_angle"])))
        set_uniform(prog, "u_audit", float(self["audit_radiance"]))
        set_uniform(prog, "u_vx_box_ramp", float(self["box_ramp"]))
        set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)
        res[VOXELS].bind_to_storage_buffer(BINDING_RECORDS)
        res[VX_LIST].bind_to_storage_buffer(BINDING_LIST)
        cull = self._cull_table(rc)
        if self.cull_buf is not None:
            res[VX_CULL] = self.cull_buf
        set_uniform(prog, "u_cull", 1 if cull else 0)
        set_uniform(prog, "u_cull_samples", int(self["cull_samples"]))
        self.cull_buf.bind_to_storage_buffer(BINDING_CULL)
        nbytes = n * n * n * C * 6 * 8
        if self.zeros is None or self.zeros.size != nbytes:
            if self.zeros is not None:
                self.zeros.release()
            self.zeros = rc.ctx.buffer(reserve=nbytes)
            self.zeros.clear()
        cur, other = res[RADIANCE], res[RADIANCE + "@prev"]
        # After a history reset (first frame, camera cut, parameter change) there is no last
        # frame to gather from: run the injection `reset_bounces` times within this frame, each
        # run gathering one bounce more from the volume the previous run wrote (ping-pong
        # between this frame's volume and its @prev twin, whose content is not needed on a
        # reset; the last run writes this frame's). The first frame is then as converged as
        # as many warm-up frames would make it, for the viewport and every path alike, and the
        # pass needs no warm-up frames.
        gathers = multi or world_lit
        runs = 1 if (prev is not None or not gathers) else max(1, int(self["reset_bounces"]))
        if not multi:
            runs = min(runs, 2)  # sky light only: one gather is all there is
        # the direct light does not change between the runs: the first stores it, the others load it
        cap = self._direct_store(rc) if runs > 1 else 0
        self.direct_entries = cap
        if self.direct_buf is None:
            self.direct_buf = rc.ctx.buffer(reserve=DIRECT_FLOATS * 4)
        res[VX_DIRECT] = self.direct_buf
        self.direct_buf.bind_to_storage_buffer(BINDING_DIRECT)
        set_uniform(prog, "u_direct_capacity", int(cap))
        for k in range(runs):
            dst = cur if (runs - 1 - k) % 2 == 0 else other
            src = other if dst is cur else cur
            if prev is not None:  # a normal frame: last frame's volume on its own grid
                prev.uniforms(prog)
                src_tex, gather = res[RADIANCE + "@prev"], True
            else:
                grid.uniforms(prog)
                src_tex, gather = src, k > 0
            src_tex.use(unit_volume)
            set_uniform(prog, "u_bounce", 1 if (multi and gather) else 0)
            set_uniform(prog, "u_gather", 1 if (gathers and gather) else 0)
            md = float(self["max_distance"])
            set_uniform(prog, "u_max_distance", md if md > 0 else float((prev or grid).extent()))
            set_uniform(prog, "u_direct_mode", 0 if runs == 1 else (1 if k == 0 else 2))
            if k > 0:  # the previous run's level 0 (image stores) -> its mips -> this run's sampler;
                # its record and direct-light stores -> this run's reads
                rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT | TEXTURE_FETCH_BARRIER_BIT
                                      | SHADER_STORAGE_BARRIER_BIT)
                build_mips(rc, src, grid)
                rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT | TEXTURE_FETCH_BARRIER_BIT)
            # clear level 0 (what was stored in it two frames ago), then write the occupied voxels;
            # the first run's upload is ordered by the graph (write_access), a later run's here
            if k > 0:
                rc.ctx.memory_barrier(TEXTURE_UPDATE_BARRIER_BIT)  # in-pass: after the run two back stored it
            dst.write(self.zeros)
            dst.bind_to_image(0, read=False, write=True, level=0)
            rc.dispatch(prog, (n * n * n * C + 255) // 256)
        self.reset_runs = runs
        self.prev_grid = grid
        self.history_valid = True

    def release(self):
        for attr in ("zeros", "cull_buf", "direct_buf"):
            b = getattr(self, attr)
            if b is not None:
                b.release()
                setattr(self, attr, None)
        self._cull_key = None


class VoxelMipPass(Pass):
    """The anisotropic mips of ``vxgi.radiance`` (shaders/vxgi/mip.comp), level by level;
    each level reads the one below, which the previous dispatch stored (own barriers)."""

    name = "vxgi_mips"
    provides = GI
    reads = (RADIANCE, GRID)
    writes = (RADIANCE,)
    history_resets = frozenset()

    def execute(self, rc, frame):
        build_mips(rc, rc.resources[RADIANCE], rc.resources[GRID])


def build_mips(rc, tex, grid: VoxelGrid):
    """Levels 1.. of ``tex`` from its level 0 (shaders/vxgi/mip.comp), level by level; each
    level reads the one below, which the previous dispatch stored (own barriers). The caller
    orders level 0's writes before this (the graph's barrier, or the injection's own)."""
    n, C = grid.n, grid.cascades
    mip = rc.programs.compute("vxgi/mip.comp")
    set_uniform(mip, "u_cascades", C)
    for k in range(grid.levels - 1):
        if k > 0:  # in-pass: level k was stored by the last dispatch
            rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT | TEXTURE_FETCH_BARRIER_BIT)
        nd = n >> (k + 1)
        tex.bind_to_image(0, read=False, write=True, level=k + 1)
        tex.bind_to_image(1, read=True, write=False, level=k)
        set_uniform(mip, "u_n_dst", nd)
        rc.dispatch(mip, (nd + 3) // 4, (nd + 3) // 4, (nd * 6 * C + 3) // 4)


class VoxelTracePass(Pass):
    name = "vxgi_trace"
    provides = GI
    reads = (RADIANCE, GRID, COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL)
    optional_reads = GBUFFER_BOUND  # bind_gbuffer
    writes = (COLOR, DIFFUSE, GLOSSY, AO)
    declared = (Res(DIFFUSE, check="radiance"), Res(GLOSSY, check="radiance"), Res(AO, check="radiance"))
    history_resets = frozenset()
    params = CONE_PARAMS + (
        Param("specular", True, doc="trace the specular cone (indirect glossy)"),
        Param("min_aperture", 0.05, 0.005, 0.577, "smallest tan(half aperture) of the specular cone"),
    )

    def __init__(self, quality=None, *, inject: VoxelInjectPass, **props):
        super().__init__(quality, **props)
        self.inject = inject

    def execute(self, rc, frame):
        res = rc.resources
        prog = rc.programs.compute("vxgi/trace.comp")
        rc.scene.bind(prog)
        bind_frame(rc, prog, frame)
        units = Units(1)
        bind_gbuffer(rc, prog, units)
        grid: VoxelGrid = res[GRID]
        grid.uniforms(prog)
        units.tex(prog, "u_vx_radiance", res[RADIANCE])
        set_uniform(prog, "u_vx_opacity_scale", float(self["opacity_scale"]))
        set_uniform(prog, "u_normal_offset", float(self["normal_offset"]))
        set_uniform(prog, "u_step", float(self["step"]))
        md = float(self["max_distance"])
        set_uniform(prog, "u_max_distance", md if md > 0 else float(grid.extent()))
        set_uniform(prog, "u_min_tan", float(self["min_aperture"]))
        set_uniform(prog, "u_vx_side_angle", float(np.radians(self["side_angle"])))
        set_uniform(prog, "u_specular", 1 if self["specular"] else 0)
        set_uniform(prog, "u_vx_cap", float(self["footprint_cap"]))
        set_uniform(prog, "u_audit", float(self["audit_radiance"]))
        set_uniform(prog, "u_vx_box_ramp", float(self["box_ramp"]))
        res[COLOR].bind_to_image(0, read=True, write=True)
        res[DIFFUSE].bind_to_image(1, read=False, write=True)
        res[GLOSSY].bind_to_image(2, read=False, write=True)
        res[AO].bind_to_image(3, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


class VoxelDebugPass(Pass):
    """GI_VXGI_Voxels: the radiance volume at mip ``mip`` ray-marched from the camera."""

    name = "vxgi_debug"
    provides = GI
    reads = (RADIANCE, GRID)
    writes = (DEBUG,)
    declared = (Res(DEBUG, check="radiance"),)
    history_resets = frozenset()
    params = (Param("mip", 0, 0, 8, "mip level shown by GI_VXGI_Voxels"),)

    def execute(self, rc, frame):
        res = rc.resources
        prog = rc.programs.compute("vxgi/debug.comp")
        grid: VoxelGrid = res[GRID]
        grid.uniforms(prog)
        units = Units(1)
        units.tex(prog, "u_vx_radiance", res[RADIANCE])
        set_uniform(prog, "u_vx_opacity_scale", 1.0)
        set_uniform(prog, "u_mip", float(min(int(self["mip"]), grid.levels - 1)))
        vp = np.asarray(frame.proj, np.float64) @ np.asarray(frame.view, np.float64)
        set_uniform(prog, "u_inv_view_proj", np.linalg.inv(vp).astype(np.float32))
        cam, _ = camera_vectors(frame)
        set_uniform(prog, "u_camera_pos", tuple(float(x) for x in cam))
        c = rc.scene.scene.camera
        set_uniform(prog, "u_ortho", 1 if c is not None and c.type == "ORTHO" else 0)
        res[DEBUG].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


__all__ = ["VoxelizePass", "VoxelInjectPass", "VoxelMipPass", "VoxelTracePass", "VoxelDebugPass", "VXGIGraph", "VoxelGrid",
           "voxel_cascades", "mip_levels", "math"]
