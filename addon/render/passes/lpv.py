"""Cascaded light propagation volumes (Kaplanyan 2009; Kaplanyan & Dachsbacher 2010).

* ``LPVPass``: injects the RSM texels (``passes/rsm.py``: one VPL each, flux in W) into
  2-band SH intensity per cell (shifted half a cell along the VPL's normal), by rasterising
  one point per texel into a layered target with additive blending (a geometry shader
  picks the layer); then ``iterations`` propagation steps (``lpv_propagate.comp``: 6
  neighbours, 5 faces each, the faces' solid angles computed here), each added to the
  accumulated volume, with a memory barrier between dependent dispatches.
  Grids are TEX2D_ARRAY of ``grid`` x ``grid`` x (``grid`` · ``cascades``) layers, rgba32f,
  one per colour channel (4 SH coefficients): moderngl cannot attach a 3D texture to a
  framebuffer, and a 2D array can be (the lookup interpolates between layers itself).
  Cascades: cell size doubles per cascade; the coarsest covers the scene's bounds, the finer
  ones are centred ahead of the camera; every origin is snapped to its cell size, so a
  camera move never shifts the grid by a fraction of a cell (no popping). Each VPL goes to
  the finest cascade that contains it; the lookup adds the cascades.
* ``LPVLookupPass``: per pixel, trilinear SH lookup with a half-cell normal offset and
  dampening; rgb = E/π for the screen-space composite.
Geometry volume (``geometry_volume``): every RSM texel is also a surfel of known area
(rsm.frag stores it); its blocking potential area / cell² is added, unshifted, to the cell
containing it in every cascade (isotropic: the 2-band SH of |n·ω| is a constant), and
propagation scales the flux entering a cell by 1 - B. The G-buffer's pixels are added the
same way (footprint area), so surfaces no light sees still block.
"""
from __future__ import annotations

import math

import numpy as np

from ..framegraph import HOST, SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import NORMAL, POSITION
from .rsm import INDIRECT, RSM_FLUX, RSM_NRM, RSM_POS, RSM_VIEWS
from .screen_space import camera_vectors

LPV_R, LPV_G, LPV_B, LPV_GRID = "lpv.r", "lpv.g", "lpv.b", "lpv.grid"
MAX_CASCADES = 4


def face_solid_angles() -> tuple[float, float]:
    """Solid angles, seen from a source cell's centre (cell size 1), of the far face and of
    one side face of the neighbouring cell (numerical integration of the projected area)."""
    n = 200
    u = (np.arange(n) + 0.5) / n - 0.5
    a, b = np.meshgrid(u, u)
    # far face: plane z = 1.5, x, y in [-0.5, 0.5]
    r2 = a * a + b * b + 1.5 * 1.5
    front = float(np.sum(1.5 / r2 ** 1.5) / (n * n))
    # side face: plane x = 0.5, y in [-0.5, 0.5], z in [0.5, 1.5]
    z = b + 1.0
    r2 = 0.25 + a * a + z * z
    side = float(np.sum(0.5 / r2 ** 1.5) / (n * n))
    return front, side


OMEGA_FRONT, OMEGA_SIDE = face_solid_angles()


class LPVGrid:
    """Host resource: the cascades' origins (grid corner, cell size) of this frame."""

    def __init__(self, origins=(), grid=0):
        self.origins, self.grid = list(origins), grid

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
    """(corner, cell size) per cascade, snapped to the cell size (see module docstring)."""
    lo, hi = scene.world_bounds()
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    ext = float(np.max(hi - lo)) * 1.02 + 1e-3
    coarse = cell_size * 2 ** (cascades - 1) if cell_size > 0 else ext / (grid - 1)
    out = []
    cam, fwd = camera_vectors(frame)
    for c in range(cascades):
        cs = coarse / 2 ** (cascades - 1 - c)
        if c == cascades - 1:
            centre = 0.5 * (lo + hi)
        else:
            # ahead of the camera, clamped into the scene's box
            centre = np.clip(cam + fwd * (0.5 * grid * cs), lo, hi)
        corner = np.floor((centre - 0.5 * grid * cs) / cs) * cs
        out.append((corner.astype(np.float32), float(cs)))
    return out


class LPVPass(Pass):
    name = "lpv"
    provides = INDIRECT
    reads = (RSM_POS, RSM_NRM, RSM_FLUX, RSM_VIEWS, POSITION, NORMAL)
    writes = (LPV_R, LPV_G, LPV_B, LPV_GRID)
    declared = (Res(LPV_R, managed=False, check="finite"), Res(LPV_G, managed=False, check="finite"),
                Res(LPV_B, managed=False, check="finite"), Res(LPV_GRID, kind=HOST, managed=False, check="none"))
    history_resets = frozenset()
    params = (
        Param("grid", 24, 8, 64, "cells per side of one cascade"),
        Param("cascades", 3, 1, MAX_CASCADES, "nested cascades (cell size doubles)"),
        Param("cell_size", 0.0, 0.0, 100.0, "finest cell size (0 = the coarsest cascade covers the scene)"),
        Param("geometry_volume", True, doc="fuzzy occlusion by the RSM surfels during propagation"),
        Param("iteration_scale", 0.5, 0.05, 4.0, "propagation steps per cell of the grid side (steps = ceil(scale x grid))"),
    )
    quality_ladder = ({"grid": 16, "cascades": 2}, {"grid": 24, "cascades": 3}, {"grid": 32, "cascades": 3},
                      {"grid": 48, "cascades": 3})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.tex = None
        self.fbo = self.gv = self.gv_fbo = None
        self.vao = self.gv_vao = self.gb_vao = None

    def _ensure(self, rc, size):
        import moderngl

        if self.tex is not None and self.tex["acc"][0].size == size:
            return
        self.release()
        self.tex = {}
        self.gv = rc.ctx.texture_array(size, 4, dtype="f4")
        self.gv.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.gv_fbo = rc.ctx.framebuffer(color_attachments=[self.gv])
        for k in ("acc", "a", "b"):
            ts = [rc.ctx.texture_array(size, 4, dtype="f4") for _ in range(3)]
            for t in ts:
                t.filter = (moderngl.LINEAR, moderngl.LINEAR)
                t.repeat_x = t.repeat_y = False
            self.tex[k] = ts
        self.fbo = rc.ctx.framebuffer(color_attachments=self.tex["a"])

    def execute(self, rc, frame):
        import moderngl

        G, C = int(self["grid"]), int(self["cascades"])
        self._ensure(rc, (G, G, G * C))
        grid = LPVGrid(cascade_origins(rc.scene.scene, frame, G, C, float(self["cell_size"])), G)
        ctx = rc.ctx
        # injection: one point per RSM texel, additive
        prog = rc.programs.program("raster3d/lpv_inject.vert", "raster3d/lpv_inject.frag",
                                   geometry="raster3d/lpv_inject.geom")
        res = rc.resources
        atlas = res[RSM_POS]
        for u, (name, uni) in enumerate(((RSM_POS, "u_rsm_pos"), (RSM_NRM, "u_rsm_nrm"), (RSM_FLUX, "u_rsm_flux")),
                                        start=1):
            res[name].use(u)
            set_uniform(prog, uni, u)
        set_uniform(prog, "u_atlas_w", int(atlas.size[0]))
        grid.uniforms(prog)
        if self.vao is None:
            self.vao = ctx.vertex_array(prog, [])
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.viewport = (0, 0, G, G)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        self.vao.render(mode=moderngl.POINTS, vertices=int(atlas.size[0] * atlas.size[1]))
        if self["geometry_volume"]:
            gvp = rc.programs.program("raster3d/lpv_inject.vert", "raster3d/lpv_inject.frag",
                                      {"LPV_GV": 1}, geometry="raster3d/lpv_inject.geom")
            for u, (name, uni) in enumerate(((RSM_POS, "u_rsm_pos"), (RSM_NRM, "u_rsm_nrm"),
                                             (RSM_FLUX, "u_rsm_flux")), start=1):
                set_uniform(gvp, uni, u)
            set_uniform(gvp, "u_atlas_w", int(atlas.size[0]))
            grid.uniforms(gvp)
            if self.gv_vao is None:
                self.gv_vao = ctx.vertex_array(gvp, [])
            self.gv_fbo.use()
            self.gv_fbo.clear(0.0, 0.0, 0.0, 0.0)
            for c in range(C):
                set_uniform(gvp, "u_only_cascade", c)
                self.gv_vao.render(mode=moderngl.POINTS, vertices=int(atlas.size[0] * atlas.size[1]))
            # the camera's surfels too (what the lights do not see still blocks)
            gbp = rc.programs.program("raster3d/lpv_inject.vert", "raster3d/lpv_inject.frag",
                                      {"LPV_GV": 1, "LPV_GV_GBUFFER": 1}, geometry="raster3d/lpv_inject.geom")
            res[POSITION].use(1)
            res[NORMAL].use(2)
            set_uniform(gbp, "u_rsm_pos", 1)
            set_uniform(gbp, "u_rsm_nrm", 2)
            set_uniform(gbp, "u_atlas_w", int(rc.width))
            grid.uniforms(gbp)
            cam, _ = camera_vectors(frame)
            set_uniform(gbp, "u_camera_pos", tuple(float(x) for x in cam))
            set_uniform(gbp, "u_pixel_size", float(2.0 / (abs(float(frame.proj[1][1])) * rc.height)))
            if self.gb_vao is None:
                self.gb_vao = ctx.vertex_array(gbp, [])
            for c in range(C):
                set_uniform(gbp, "u_only_cascade", c)
                self.gb_vao.render(mode=moderngl.POINTS, vertices=int(rc.width * rc.height))
        ctx.disable(moderngl.BLEND)
        prop = rc.programs.compute("raster3d/lpv_propagate.comp")
        set_uniform(prop, "u_grid", G)
        set_uniform(prop, "u_cascades", C)
        set_uniform(prop, "u_omega_front", OMEGA_FRONT)
        set_uniform(prop, "u_omega_side", OMEGA_SIDE)
        self.gv.use(4)
        set_uniform(prop, "u_gv", 4)
        set_uniform(prop, "u_use_gv", 1 if self["geometry_volume"] else 0)
        copy = rc.programs.compute("raster3d/lpv_propagate.comp", {"LPV_COPY": 1})
        set_uniform(copy, "u_grid", G)
        set_uniform(copy, "u_cascades", C)
        groups = ((G + 3) // 4, (G + 3) // 4, (G * C + 3) // 4)
        barrier = SHADER_IMAGE_ACCESS_BARRIER_BIT | TEXTURE_FETCH_BARRIER_BIT
        # injected -> accumulated (framebuffer writes are visible to later commands)
        for i in range(3):
            self.tex["a"][i].use(1 + i)
            set_uniform(copy, ("u_src_r", "u_src_g", "u_src_b")[i], 1 + i)
            self.tex["acc"][i].bind_to_image(3 + i, read=True, write=True)
        rc.dispatch(copy, *groups)
        iters = max(1, int(math.ceil(float(self["iteration_scale"]) * G)))
        src, dst = self.tex["a"], self.tex["b"]
        for _ in range(iters):
            ctx.memory_barrier(barrier)  # the previous step's stores before this step reads them
            for i in range(3):
                src[i].use(1 + i)
                set_uniform(prop, ("u_src_r", "u_src_g", "u_src_b")[i], 1 + i)
                dst[i].bind_to_image(i, read=False, write=True)
                self.tex["acc"][i].bind_to_image(3 + i, read=True, write=True)
            rc.dispatch(prop, *groups)
            src, dst = dst, src
        res[LPV_R], res[LPV_G], res[LPV_B] = self.tex["acc"]
        res[LPV_GRID] = grid

    def release(self):
        for ts in (self.tex or {}).values():
            for t in ts:
                t.release()
        for o in (self.fbo, self.vao, self.gv_fbo, self.gv, self.gv_vao, self.gb_vao):
            if o is not None:
                o.release()
        self.tex = self.fbo = self.vao = self.gv = self.gv_fbo = self.gv_vao = self.gb_vao = None


class LPVLookupPass(Pass):
    name = "lpv_lookup"
    provides = INDIRECT
    reads = (POSITION, NORMAL, LPV_R, LPV_G, LPV_B, LPV_GRID)
    writes = ("lpv.raw",)
    declared = (Res("lpv.raw", check="radiance"),)
    history_resets = frozenset()
    params = (Param("dampening", 0.5, 0.0, 1.0, "scale of light flowing away along the normal (self-illumination)"),)

    def execute(self, rc, frame):
        prog = rc.programs.compute("raster3d/lpv_lookup.comp")
        res = rc.resources
        for u, (name, uni) in enumerate(((POSITION, "u_gb_position"), (NORMAL, "u_gb_normal"), (LPV_R, "u_lpv_r"),
                                         (LPV_G, "u_lpv_g"), (LPV_B, "u_lpv_b")), start=1):
            res[name].use(u)
            set_uniform(prog, uni, u)
        res[LPV_GRID].uniforms(prog)
        set_uniform(prog, "u_dampening", float(self["dampening"]))
        res["lpv.raw"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))
