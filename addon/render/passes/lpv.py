"""Cascaded light propagation volumes (Kaplanyan 2009; Kaplanyan & Dachsbacher 2010).

* ``LPVPass``:
  1. **Cascades** (``cascade_origins``): ``cascades`` grids of ``grid``³ cells, the cell size
     doubling per cascade. The coarsest covers the scene's bounds (``cell_size`` = 0) or is
     centred ahead of the camera; each finer one is centred ahead of the camera and clamped
     inside the next coarser one's membership box (nested). Every corner is snapped to its
     cell size, so a camera move shifts a grid by whole cells only (no popping).
  2. **Injection** (raster, additive blending into a layered target, one point per RSM
     texel, ``lpv_inject.geom`` picks ``gl_Layer``; after the geometry volume, step 3): each
     VPL of flux Φ is the Lambertian intensity ``Φ/π·max(0, n·ω)`` projected on 2-band SH
     at its position **shifted ``inject_offset`` (1) cell along n**, splatted trilinearly
     over the cell centres around that point in front of its surface, each centre's weight
     cut by the geometry volume's transmittance between the point and it (a VPL next to a
     thin wall does not splat through it; the weights are renormalised).
     ``trilinear_injection`` False: the one cell containing the point (a VPL moving with
     its light then steps between cells: flicker). Per cascade c two
     volumes (slabs): ``A_c`` with every VPL inside c's membership box ``M_c`` (the grid
     shrunk by one cell), and the ring ``R_c`` (c ≥ 1) with the VPLs inside ``M_c`` but not
     ``M_{c-1}``. The lookup adds ``A_f + Σ_{c>f} R_c`` (f the finest cascade at the point),
     which counts every VPL once and lets light of the near VPLs leave the fine cascade
     (each slab propagates alone). ``soft_cascades``: a VPL's share in ``A_c`` ramps from 0
     at ``M_c``'s border to 1 two cells inside and ``R_c`` takes the difference to
     ``A_{c-1}``'s share, so a cascade following the camera hands VPLs over gradually.
  3. **Geometry volume** (``geometry_volume``, fuzzy occlusion): every RSM texel and every
     G-buffer pixel is a surfel of known area A and normal n; ``A·|n_a| / cell²`` is added to
     channel a of the *staggered* cell between the two cell centres the surfel lies
     between along axis a (one slab per cascade; surfels wider than a cell are split). The
     flux crossing between two cells is scaled by ``1 − B`` of that face, so a wall thinner
     than a cell blocks wherever it lies in the cells.
  4. **Propagation** (``ceil(iteration_scale · grid)`` compute steps, a memory barrier
     between dependent dispatches): each cell gathers from its 6 neighbours the flux
     through its 5 other faces, ``Ω_face · I(ω_face)``, re-emitted as a cosine lobe around the
     face normal; the faces' solid angles (far 0.4007 sr, side 0.4234 sr) are integrated in
     ``face_solid_angles``. Every step is added to the accumulated volume.
  The volume is recomputed only when the scene (GPUScene.version), the camera's view, the
  parameters, the RSM views (their matrices and resolution) or the frame size changed: frames that differ only by the sub-pixel jitter
  (F12 accumulation, a still viewport) reuse it.
  Grids are TEX2D_ARRAY of ``grid`` x ``grid`` x (``grid`` · slabs) layers, rgba32f, one per
  colour channel (4 SH coefficients): moderngl cannot attach a 3D texture to a framebuffer,
  a 2D array it can.
* ``LPVLookupPass``: per pixel, the irradiance from the cascades (``lpv_lookup.comp``:
  trilinear over the cell centres in front of the surface, weighted by the geometry
  volume, normal offset ``normal_offset`` (0.25) cell, dampening); ``lpv.raw`` rgb = E/π for the screen-space
  composite, ``lpv.cascade`` = the cascade used (GI_LPV_Cascade).
* ``LPVDebugPass``: a horizontal slice of one cascade's volume (GI_LPV_Slice).
"""
from __future__ import annotations

import math

import numpy as np

from ..framegraph import HOST, SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import NORMAL, POSITION
from .rsm import INDIRECT, RSM_FLUX, RSM_NRM, RSM_POS, RSM_VIEWS
from .screen_space import camera_vectors

LPV_R, LPV_G, LPV_B, LPV_GV, LPV_GRID = "lpv.r", "lpv.g", "lpv.b", "lpv.gv", "lpv.grid"
LPV_GVD = "lpv.gv_depth"  # per axis: blocking x the blockers' position (cell units)
# the pass's own SH volumes (r, g, b): the injected light (then a propagation ping-pong
# buffer) and the other ping-pong buffer; kept across frames, so declared for the graph's
# barriers (next frame's framebuffer clear comes after this frame's image stores)
LPV_INJECT = ("lpv.inject.r", "lpv.inject.g", "lpv.inject.b")
LPV_STEP = ("lpv.step.r", "lpv.step.g", "lpv.step.b")
MAX_CASCADES = 4


def face_solid_angles(n: int = 400) -> tuple[float, float]:
    """Solid angles, seen from a source cell's centre (cell size 1), of the far face and of
    one side face of the neighbouring cell (midpoint integration of dA·cosθ/r²)."""
    u = (np.arange(n) + 0.5) / n - 0.5
    a, b = np.meshgrid(u, u)
    r2 = a * a + b * b + 1.5 * 1.5  # far face: plane z = 1.5
    front = float(np.sum(1.5 / r2 ** 1.5) / (n * n))
    z = b + 1.0  # side face: plane x = 0.5, y in [-0.5, 0.5], z in [0.5, 1.5]
    r2 = 0.25 + a * a + z * z
    side = float(np.sum(0.5 / r2 ** 1.5) / (n * n))
    return front, side


OMEGA_FRONT, OMEGA_SIDE = face_solid_angles()


def slab_steps(iteration_scale: float, grid: int, cascades: int) -> list[int]:
    """Propagation steps per slab (A_0..A_{C-1}, R_1..R_{C-1}): ``iteration_scale · grid``
    cells of the coarsest cascade, i.e. the same distance in every cascade (twice the steps
    per finer cascade), so a fine cascade's light reaches as far as a coarse one's."""
    base = max(1, int(math.ceil(iteration_scale * grid)))
    per_c = [base * 2 ** (cascades - 1 - c) for c in range(cascades)]
    return per_c + per_c[1:]


class LPVGrid:
    """Host resource: this frame's cascades, (corner, cell size) each."""

    def __init__(self, origins=(), grid=0):
        self.origins, self.grid = list(origins), grid

    @property
    def slabs(self) -> int:
        return max(1, 2 * len(self.origins) - 1)

    def release(self):
        pass

    def uniforms(self, prog):
        arr = np.zeros((MAX_CASCADES, 4), np.float32)
        for i, (o, cs) in enumerate(self.origins):
            arr[i, :3], arr[i, 3] = o, cs
        if "u_lpv_origin" in prog:
            prog["u_lpv_origin"].write(arr.tobytes())
        set_uniform(prog, "u_grid", int(self.grid))
        set_uniform(prog, "u_cascades", len(self.origins))


def cascade_origins(scene, frame, grid: int, cascades: int, cell_size: float):
    """(corner, cell size) per cascade, finest first (see the module docstring)."""
    lo, hi = scene.world_bounds()
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    ext = float(np.max(hi - lo)) * 1.02 + 1e-3
    cam, fwd = camera_vectors(frame)
    # the coarsest cascade's membership box (grid - 2 cells) covers the scene after snapping
    coarse = cell_size * 2 ** (cascades - 1) if cell_size > 0 else ext / max(grid - 4, 1)
    out = []
    for c in range(cascades - 1, -1, -1):
        cs = coarse / 2 ** (cascades - 1 - c)
        if c == cascades - 1 and cell_size <= 0:
            centre = 0.5 * (lo + hi)
        else:  # ahead of the camera, inside the scene's box
            centre = np.clip(cam + fwd * (0.4 * grid * cs), lo, hi)
        corner = np.floor((centre - 0.5 * grid * cs) / cs) * cs
        if out:  # nested: inside the next coarser cascade's membership box
            po, pcs = out[-1]
            corner = np.clip(corner, po + pcs, po + (grid - 1) * pcs - grid * cs)
        out.append((corner, float(cs)))
    out.reverse()
    return [(o.astype(np.float32), cs) for o, cs in out]


class LPVPass(Pass):
    """Injection and propagation (see the module docstring)."""

    name = "lpv"
    # raster (the geometry volume and the injection: additive point draws after a framebuffer
    # clear) and compute (the geometry rays, the copy and the propagation: image stores)
    kind = "mixed"
    provides = INDIRECT
    reads = (RSM_POS, RSM_NRM, RSM_FLUX, RSM_VIEWS, POSITION, NORMAL)
    writes = (LPV_R, LPV_G, LPV_B, LPV_GV, LPV_GVD, LPV_GRID) + LPV_INJECT + LPV_STEP
    # sizes follow the grid and cascade parameters: the pass allocates the volumes itself
    declared = (Res(LPV_R, managed=False, check="finite"), Res(LPV_G, managed=False, check="finite"),
                Res(LPV_B, managed=False, check="finite"), Res(LPV_GV, managed=False, check="finite"),
                Res(LPV_GVD, managed=False, check="finite"),
                Res(LPV_GRID, kind=HOST, managed=False, check="none")) + tuple(
        Res(n, managed=False, check="finite") for n in LPV_INJECT + LPV_STEP)
    write_access = {**{n: "image" for n in (LPV_R, LPV_G, LPV_B) + LPV_STEP},
                    **{n: ("framebuffer", "image") for n in (LPV_GV, LPV_GVD) + LPV_INJECT}}
    history_resets = frozenset()
    params = (
        Param("grid", 24, 8, 64, "cells per side of one cascade"),
        Param("cascades", 3, 1, MAX_CASCADES, "nested cascades (cell size doubles)"),
        Param("cell_size", 0.0, 0.0, 100.0, "finest cell size (0 = the coarsest cascade covers the scene)"),
        Param("geometry_volume", True, doc="fuzzy occlusion by the RSM and G-buffer surfels during propagation"),
        Param("iteration_scale", 0.5, 0.05, 4.0, "propagation steps per cell of the grid side (steps = ceil(scale x grid))"),
        Param("inject_scale", 1.0, 0.0, 1.0, "weight of the injected (unpropagated) light in the result"),
        Param("flux_normalize", True, doc="scale each propagated cell so the clamped SH lobe carries its own flux (no energy gain per step)"),
        Param("trilinear_injection", True, doc="splat each VPL over the 8 cells around it (in front of its surface, weights cut by the geometry volume: splat_blocking); False: the one cell containing it (a VPL moving with its light steps between cells)"),
        Param("inject_offset", 1.0, 0.0, 2.0, "a VPL is injected at its position plus this many cells along its normal (0.5 lets a surface's own light light it at fine levels)"),
        Param("splat_blocking", True, doc="the trilinear splat's weights through the geometry volume (False: it crosses thin walls sideways, two_rooms leak 0.0000 -> 0.0055 at 48 px)"),
        Param("soft_cascades", True, doc="a VPL's share in a cascade ramps over 2 cells at its border (False: in or out, a moving cascade pops)"),
    )
    quality_ladder = ({"grid": 16, "cascades": 2}, {"grid": 24, "cascades": 3}, {"grid": 32, "cascades": 3},
                      {"grid": 40, "cascades": 3})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.tex = None
        self.fbo = self.gv = self.gvd = self.gv_fbo = None
        self.vao = self.gv_vao = self.gb_vao = None
        self._vao_prog = None
        self.iterations = 0
        self.grid = None
        self._key = None  # what the current volume was computed from (scene version, view, params)

    def _ensure(self, rc, size, gv_size):
        import moderngl

        if self.tex is not None and self.tex["acc"][0].size == size and self.gv.size == gv_size:
            return
        self.release()
        self.tex = {}
        self.gv = rc.ctx.texture_array(gv_size, 4, dtype="f4")
        self.gvd = rc.ctx.texture_array(gv_size, 4, dtype="f4")
        for t in (self.gv, self.gvd):
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.gv_fbo = rc.ctx.framebuffer(color_attachments=[self.gv, self.gvd])
        for k in ("acc", "a", "b"):
            ts = [rc.ctx.texture_array(size, 4, dtype="f4") for _ in range(3)]
            for t in ts:
                t.filter = (moderngl.NEAREST, moderngl.NEAREST)
                t.repeat_x = t.repeat_y = False
            self.tex[k] = ts
        self.fbo = rc.ctx.framebuffer(color_attachments=self.tex["a"])

    def _inject_program(self, rc, defines, atlas_w, grid):
        prog = rc.programs.program("raster3d/lpv_inject.vert", "raster3d/lpv_inject.frag", defines,
                                   geometry="raster3d/lpv_inject.geom")
        for u, uni in enumerate(("u_rsm_pos", "u_rsm_nrm", "u_rsm_flux"), start=1):
            set_uniform(prog, uni, u)
        set_uniform(prog, "u_atlas_w", int(atlas_w))
        grid.uniforms(prog)
        return prog

    def execute(self, rc, frame):
        import moderngl

        G, C = int(self["grid"]), int(self["cascades"])
        views = rc.resources[RSM_VIEWS]
        key = (id(rc.scene), getattr(rc.scene, "version", None), np.asarray(frame.view, np.float64).tobytes(),
               repr(self.get_properties()), rc.width, rc.height, views.res,
               tuple(np.asarray(v["vp"], np.float64).tobytes() for v in views.views))
        if self.tex is not None and key == self._key:
            # nothing the volume depends on changed (an accumulating F12 render, a still
            # viewport): the last frame's volume is this frame's; only the jitter differs
            self._publish(rc)
            return
        grid = LPVGrid(cascade_origins(rc.scene.scene, frame, G, C, float(self["cell_size"])), G)
        S = grid.slabs
        self._ensure(rc, (G, G, G * S), (G, G, G * C))
        ctx = rc.ctx
        res = rc.resources
        atlas = res[RSM_POS]
        n_vpl = int(atlas.size[0] * atlas.size[1])
        for u, name in enumerate((RSM_POS, RSM_NRM, RSM_FLUX), start=1):
            res[name].use(u)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        # the geometry volume first (the trilinear injection's weights read it): one point per
        # RSM texel and per G-buffer pixel, additive
        use_gv = bool(self["geometry_volume"])
        self.gv_fbo.use()
        self.gv_fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.viewport = (0, 0, G, G)
        if use_gv:
            gvp = self._inject_program(rc, {"LPV_GV": 1}, atlas.size[0], grid)
            if self.gv_vao is None:
                self.gv_vao = ctx.vertex_array(gvp, [])
            for c in range(C):
                set_uniform(gvp, "u_only_cascade", c)
                self.gv_vao.render(mode=moderngl.POINTS, vertices=n_vpl)
            # the camera's surfels too (what the lights do not see still blocks)
            gbp = self._inject_program(rc, {"LPV_GV": 1, "LPV_GV_GBUFFER": 1}, rc.width, grid)
            res[POSITION].use(1)
            res[NORMAL].use(2)
            cam, _ = camera_vectors(frame)
            set_uniform(gbp, "u_camera_pos", tuple(float(x) for x in cam))
            set_uniform(gbp, "u_pixel_size", float(2.0 / (abs(float(frame.proj[1][1])) * rc.height)))
            if self.gb_vao is None:
                self.gb_vao = ctx.vertex_array(gbp, [])
            for c in range(C):
                set_uniform(gbp, "u_only_cascade", c)
                self.gb_vao.render(mode=moderngl.POINTS, vertices=int(rc.width * rc.height))
        ctx.disable(moderngl.BLEND)
        # light injection: one point per RSM texel, additive (framebuffer writes of the geometry
        # volume are visible to this draw's texel fetches)
        defs = {**({} if self["trilinear_injection"] else {"LPV_SPLAT_NEAREST": 1}),
                **({} if self["soft_cascades"] else {"LPV_HARD_CASCADES": 1})}
        prog = self._inject_program(rc, defs or None, atlas.size[0], grid)
        if self.vao is None or self._vao_prog is not prog:
            if self.vao is not None:
                self.vao.release()
            self.vao = ctx.vertex_array(prog, [])
            self._vao_prog = prog
        set_uniform(prog, "u_inject_offset", float(self["inject_offset"]))
        if self["trilinear_injection"]:  # the splat's weights through the blockers (units 4, 5)
            self.gv.use(4)
            self.gvd.use(5)
            set_uniform(prog, "u_gv", 4)
            set_uniform(prog, "u_gvd", 5)
            set_uniform(prog, "u_use_gv", 1 if use_gv and self["splat_blocking"] else 0)
        for u, name in enumerate((RSM_POS, RSM_NRM, RSM_FLUX), start=1):
            res[name].use(u)  # the G-buffer surfels' pass bound units 1-2 to the G-buffer
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.viewport = (0, 0, G, G)
        self.vao.render(mode=moderngl.POINTS, vertices=n_vpl)
        ctx.disable(moderngl.BLEND)
        prop = rc.programs.compute("raster3d/lpv_propagate.comp")
        grid.uniforms(prop)
        set_uniform(prop, "u_slabs", S)
        set_uniform(prop, "u_omega_front", OMEGA_FRONT)
        set_uniform(prop, "u_omega_side", OMEGA_SIDE)
        self.gv.use(4)
        set_uniform(prop, "u_gv", 4)
        set_uniform(prop, "u_use_gv", 1 if use_gv else 0)
        set_uniform(prop, "u_normalize", 1 if self["flux_normalize"] else 0)
        copy = rc.programs.compute("raster3d/lpv_propagate.comp", {"LPV_COPY": 1})
        grid.uniforms(copy)
        set_uniform(copy, "u_slabs", S)
        set_uniform(copy, "u_copy_scale", float(self["inject_scale"]))
        groups = ((G + 3) // 4, (G + 3) // 4, (G * S + 3) // 4)
        barrier = SHADER_IMAGE_ACCESS_BARRIER_BIT | TEXTURE_FETCH_BARRIER_BIT
        # injected -> accumulated (framebuffer writes are visible to later commands)
        for i in range(3):
            self.tex["a"][i].use(1 + i)
            set_uniform(copy, ("u_src_r", "u_src_g", "u_src_b")[i], 1 + i)
            self.tex["acc"][i].bind_to_image(3 + i, read=True, write=True)
        rc.dispatch(copy, *groups)
        steps = slab_steps(float(self["iteration_scale"]), G, C)
        self.iterations = max(steps)
        src, dst = self.tex["a"], self.tex["b"]
        for k in range(self.iterations):
            ctx.memory_barrier(barrier)  # the previous step's stores before this step reads them
            for i in range(3):
                src[i].use(1 + i)
                set_uniform(prop, ("u_src_r", "u_src_g", "u_src_b")[i], 1 + i)
                dst[i].bind_to_image(i, read=False, write=True)
                self.tex["acc"][i].bind_to_image(3 + i, read=True, write=True)
            for slab, n in enumerate(steps):
                if k < n:
                    set_uniform(prop, "u_slab", slab)
                    rc.dispatch(prop, groups[0], groups[1], (G + 3) // 4)
            src, dst = dst, src
        self.grid = grid
        self._key = key
        self._publish(rc)

    def _publish(self, rc):
        res = rc.resources
        res[LPV_R], res[LPV_G], res[LPV_B] = self.tex["acc"]
        res[LPV_GV] = self.gv
        res[LPV_GVD] = self.gvd
        res[LPV_GRID] = self.grid
        for names, k in ((LPV_INJECT, "a"), (LPV_STEP, "b")):
            for n, t in zip(names, self.tex[k]):
                res[n] = t

    def release(self):
        for ts in (self.tex or {}).values():
            for t in ts:
                t.release()
        for o in (self.fbo, self.vao, self.gv_fbo, self.gv, self.gvd, self.gv_vao, self.gb_vao):
            if o is not None:
                o.release()
        self.tex = self.fbo = self.vao = self.gv = self.gvd = self.gv_fbo = self.gv_vao = self.gb_vao = None
        self._vao_prog = None
        self._key = None


def _bind_volume(rc, prog, first_unit: int):
    res = rc.resources
    for u, (name, uni) in enumerate(((LPV_R, "u_lpv_r"), (LPV_G, "u_lpv_g"), (LPV_B, "u_lpv_b")),
                                    start=first_unit):
        res[name].use(u)
        set_uniform(prog, uni, u)
    res[LPV_GRID].uniforms(prog)


class LPVLookupPass(Pass):
    """Per-pixel irradiance from the cascades (``lpv.raw`` rgb = E/π; ``lpv.cascade``)."""

    name = "lpv_lookup"
    provides = INDIRECT
    reads = (POSITION, NORMAL, LPV_R, LPV_G, LPV_B, LPV_GV, LPV_GVD, LPV_GRID)
    writes = ("lpv.raw", "lpv.cascade")
    declared = (Res("lpv.raw", check="radiance"), Res("lpv.cascade", dtype="f2", check="radiance"))
    history_resets = frozenset()
    params = (Param("dampening", 0.0, 0.0, 1.0, "scale of light flowing away along the normal (self-illumination; q3: 0.25)"),
              Param("normal_offset", 0.25, 0.0, 2.0, "lookup point offset along the normal, in cells of the cascade read"))
    # q3's grid (40) is the finest: a surface's own injected light sits nearest its lookup and
    # follows its direct light's change, the per-frame change 60 moving frames showed (1.004x
    # Cycles' mean step with 0; 0.25 takes 0.052 off the first 20 poses, docs/techniques/LPV.md).
    # q0-q2 keep 0 (they meet the stability bar without it; it darkens the
    # Cornell box's mean).
    quality_ladder = ({"dampening": 0.0}, {"dampening": 0.0}, {"dampening": 0.0}, {"dampening": 0.25})

    def __init__(self, quality=None, *, lpv: LPVPass | None = None, **kw):
        super().__init__(quality, **kw)
        self.lpv = lpv

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/lpv_lookup.comp")
        res = rc.resources
        res[POSITION].use(1)
        set_uniform(prog, "u_gb_position", 1)
        res[NORMAL].use(2)
        set_uniform(prog, "u_gb_normal", 2)
        _bind_volume(rc, prog, 3)
        res[LPV_GV].use(6)
        set_uniform(prog, "u_gv", 6)
        res[LPV_GVD].use(7)
        set_uniform(prog, "u_gvd", 7)
        set_uniform(prog, "u_use_gv", 1 if (self.lpv is None or self.lpv["geometry_volume"]) else 0)
        set_uniform(prog, "u_dampening", float(self["dampening"]))
        set_uniform(prog, "u_normal_offset", float(self["normal_offset"]))
        res["lpv.raw"].bind_to_image(0, read=False, write=True)
        res["lpv.cascade"].bind_to_image(1, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


class LPVDebugPass(Pass):
    """GI_LPV_Slice: a horizontal slice of one cascade's accumulated volume (mean radiance
    per cell) stretched over the frame; ``debug_cascade`` and ``debug_height`` pick it."""

    name = "lpv_debug"
    provides = INDIRECT
    reads = (LPV_R, LPV_G, LPV_B, LPV_GRID)
    writes = ("lpv.debug_slice",)
    declared = (Res("lpv.debug_slice", check="radiance"),)
    history_resets = frozenset()
    params = (Param("debug_cascade", MAX_CASCADES - 1, 0, MAX_CASCADES - 1,
                    "GI_LPV_Slice: the cascade shown (clamped to the coarsest; default: the coarsest)"),
              Param("debug_height", 0.5, 0.0, 1.0, "GI_LPV_Slice: height of the slice, fraction of the grid"))

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/lpv_debug.comp")
        _bind_volume(rc, prog, 1)
        set_uniform(prog, "u_debug_cascade", int(self["debug_cascade"]))
        set_uniform(prog, "u_debug_height", float(self["debug_height"]))
        rc.resources["lpv.debug_slice"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
