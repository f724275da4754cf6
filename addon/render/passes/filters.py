"""Denoising filters any noisy technique's graph can end with (shaders/filters/).

* ``AtrousPass`` (Dammertz et al. 2010, "Edge-avoiding À-Trous wavelet transform for fast
  global illumination filtering"): the colour is demodulated by the G-buffer albedo, filtered
  by ``iterations`` à-trous steps (5x5 B3 taps spaced 1, 2, 4, ... pixels) with colour,
  normal and position edge-stopping weights (the colour sigma halves each step, as in the
  paper), and remodulated. No temporal state.
* ``SVGFPass`` (Schied et al. 2017, "Spatiotemporal variance-guided filtering"): demodulated
  illumination reprojected through ``gbuffer.motion`` with a history length, temporal
  luminance moments (spatial estimate while the history is shorter than 4 frames),
  variance-guided à-trous, and remodulation. The history is the temporal integration, not
  the first à-trous iteration the paper feeds back (that loses light on heavy-tailed input:
  sun-lit room 0.86 of Cycles vs 0.965).
* Emission (the G-buffer surface's material emission) bypasses demodulation in ATROUS and
  SVGF: illumination = (colour - emission) / albedo, colour = filtered x albedo + emission.
* ``TAAPass`` (Karis 2014): reprojected history (rejected by geometry), per-pixel history
  length, YCoCg variance clip widened by the temporal sigma, linear exponential blend of a
  reconstruction-filtered current frame (same-surface binomial, 5x5 while the history is
  young, else 3x3; the clip box spans the same window).
  The camera jitter is the session's R2 sequence (frame 0 at the pixel centre), which the
  G-buffer and every pass already use; TAA does not add its own (Halton) jitter: two jitter
  sequences would disagree, and R2 is the better-distributed 2D sequence.

History is graph-owned (``Res(..., history=True)``, read as ``name@prev``); every history
read is checked for finiteness, so a NaN injected into history is gone within one frame.
``with_filters(passes, denoiser, taa)`` appends the filters (and a G-buffer if the graph
has none) to a technique's passes: the session does this for ``scene.gi_preview.denoiser``
and ``scene.gi_preview.use_taa``.
"""
from __future__ import annotations

from ..barriers import SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT
from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, EMISSION, GEONORMAL, MOTION, NORMAL, POSITION, GBufferPass
from .screen_space import Units, bind_frame

COLOR = "color"
DENOISERS = ("NONE", "ATROUS", "SVGF")

# filtered illumination depends on lights/materials/geometry: those edits restart it;
# camera and object motion are followed by reprojection (gbuffer.motion)
FILTER_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", "materials", "lights", "textures"})


# A temporal filter's history through a light edit (TAA and SVGF; see _set_history_uniforms)
LIGHT_HISTORY = Param("light_history", 2, 0, 1024, "a light edit caps the history length at this (0: restarts the "
                      "history)")


class _FilterPass(Pass):
    kind = "compute"
    provides = frozenset()
    always = True

    def _run(self, rc, prog):
        rc.dispatch(prog, *rc.groups(8))

    def _set_history_uniforms(self, prog, frame):
        """u_reset and u_len_cap of a temporal filter that keeps its history through a light
        edit (``lights`` not in its ``history_resets``): a light edit caps the history length at
        ``light_history`` (0: restarts the history, as a reset would)."""
        light_edit = "lights" in frame.scene_edits
        light_reset = light_edit and int(self["light_history"]) <= 0
        set_uniform(prog, "u_reset", 0 if (self.history_valid and not frame.camera_cut and not light_reset) else 1)
        set_uniform(prog, "u_len_cap", float(self["light_history"]) if light_edit and not light_reset else 1e9)

    def _atrous(self, rc, frame, src, dst_a, dst_b, iterations, mode, sigma_c, sigma_n, sigma_p,
                halve_sigma=False):
        """Run ``iterations`` à-trous steps from ``src`` ping-ponging between two textures
        (``halve_sigma``: the colour sigma halves each step). Returns the name of the texture
        holding the result."""
        res = rc.resources
        prog = rc.programs.compute("filters/atrous.comp")
        bind_frame(rc, prog, frame)
        cur = src
        outs = (dst_a, dst_b)
        for it in range(int(iterations)):
            dst = outs[it % 2]
            units = Units(1)
            units.tex(prog, "u_in", res[cur])
            units.tex(prog, "u_gb_position", res[POSITION])
            units.tex(prog, "u_gb_normal", res[NORMAL])
            set_uniform(prog, "u_step", 1 << it)
            set_uniform(prog, "u_mode", int(mode))
            set_uniform(prog, "u_sigma_c", float(sigma_c) * (0.5 ** it if halve_sigma else 1.0))
            set_uniform(prog, "u_sigma_n", float(sigma_n))
            set_uniform(prog, "u_sigma_p", float(sigma_p))
            res[dst].bind_to_image(0, read=False, write=True)
            self._run(rc, prog)
            rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the next step fetches this one's stores
            cur = dst
        return cur

    def _copy(self, rc, src, dst, keep_alpha=False):
        res = rc.resources
        if keep_alpha:  # a straight texture copy keeps the variance channel
            prog = rc.programs.compute("filters/copy.comp", {"KEEP_ALPHA": 1})
        else:
            prog = rc.programs.compute("filters/copy.comp")
        res[src].use(1)
        set_uniform(prog, "u_in", 1)
        res[dst].bind_to_image(0, read=False, write=True)
        self._run(rc, prog)
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the filter steps after the copy read its stores

    def _modulate(self, rc, frame, src, dst, demod: bool):
        res = rc.resources
        prog = rc.programs.compute("filters/modulate.comp")
        bind_frame(rc, prog, frame)  # the camera: the albedo is the one seen from it
        units = Units(1)
        units.tex(prog, "u_in", res[src])
        units.tex(prog, "u_gb_albedo", res[ALBEDO])
        units.tex(prog, "u_gb_position", res[POSITION])
        units.tex(prog, "u_gb_normal", res[NORMAL])
        units.tex(prog, "u_gb_geonormal", res[GEONORMAL])
        units.tex(prog, "u_gb_emission", res[EMISSION])  # the emission that bypasses demodulation
        set_uniform(prog, "u_demod", 1 if demod else 0)
        res[dst].bind_to_image(0, read=False, write=True)
        self._run(rc, prog)
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the filter steps read the (de)modulated image


class AtrousPass(_FilterPass):
    """Edge-avoiding à-trous wavelet filter of ``color`` (no temporal state)."""

    name = "atrous"
    reads = (COLOR, ALBEDO, NORMAL, GEONORMAL, POSITION, EMISSION)
    writes = (COLOR, "atrous.a", "atrous.b")
    declared = (Res(COLOR, check="radiance"), Res("atrous.a", check="radiance"), Res("atrous.b", check="radiance"))
    history_resets = frozenset()
    params = (
        Param("iterations", 5, 1, 8, "à-trous steps (kernel spacing 1, 2, 4, ... pixels)"),
        Param("sigma_color", 0.8, 1e-3, 10.0, "colour sigma of the first step (tone-mapped units; halved per step)"),
        Param("sigma_normal", 0.3, 1e-3, 2.0, "normal sigma (|n - n'|)"),
        Param("sigma_position", 1.0, 1e-3, 100.0, "tangent-plane distance sigma (pixel footprints per pixel of tap distance)"),
    )
    quality_ladder = ({"iterations": 3}, {"iterations": 4}, {"iterations": 5}, {"iterations": 6})

    def execute(self, rc, frame):
        self._modulate(rc, frame, COLOR, "atrous.a", demod=True)
        prog_src = "atrous.a"
        out = self._atrous(rc, frame, prog_src, "atrous.b", "atrous.a", self["iterations"], 0,
                           self["sigma_color"], self["sigma_normal"], self["sigma_position"], halve_sigma=True)
        self._modulate(rc, frame, out, COLOR, demod=False)


class SVGFPass(_FilterPass):
    """Spatiotemporal variance-guided filtering of ``color``."""

    name = "svgf"
    reads = (COLOR, ALBEDO, NORMAL, GEONORMAL, POSITION, MOTION, EMISSION, "svgf.illum@prev", "svgf.moments@prev", "svgf.pos@prev",
             "svgf.nrm@prev")
    writes = (COLOR, "svgf.illum", "svgf.moments", "svgf.pos", "svgf.nrm", "svgf.a", "svgf.b", "svgf.dbg_var",
              "svgf.dbg_len")
    declared = (Res(COLOR, check="radiance"),
                Res("svgf.illum", history=True, check="radiance"),
                Res("svgf.moments", history=True, check="finite"),
                Res("svgf.pos", history=True, check="finite"),
                Res("svgf.nrm", history=True, check="finite"),
                Res("svgf.a", check="radiance"), Res("svgf.b", check="radiance"),
                Res("svgf.dbg_var", check="radiance"), Res("svgf.dbg_len", check="radiance"))
    history_resets = FILTER_RESETS - {"lights"}  # light_history decides (below)
    params = (
        Param("iterations", 5, 1, 8, "variance-guided à-trous steps"),
        Param("max_history", 32, 1, 1024, "history length cap (alpha = 1 / length, at least 1/max_history)"),
        Param("sigma_luminance", 4.0, 0.1, 100.0, "luminance edge-stopping (times the standard deviation)"),
        Param("sigma_normal", 128.0, 1.0, 1024.0, "normal exponent"),
        Param("sigma_depth", 1.0, 1e-3, 100.0, "tangent-plane distance sigma (pixel footprints per pixel of tap distance)"),
        # edge_history 8 (against 0): Cornell slow pan trail 1.59x -> 1.44x the still level (8 draws, paired
        # -0.13 +- 0.02), every case's stability +0.01..0.09 (all < 2x), moving relMSE +5 %. docs/techniques/SVGF.md
        Param("edge_history", 8.0, 0.0, 1024.0, "history length cap at geometric-edge pixels (a 3x3 neighbour on "
              "another surface) while the reprojection moves: their coverage changes (0: off)"),
        # light_history 2 (against a restart): the moving sun's held relMSE 0.039 -> 0.019, flicker
        # 1.58x -> 0.92x Cycles', trail 2.63x -> 1.90x (16 paired draws); the price is a 2-frame lag while the
        # light moves (relMSE moving: median equal, mean +18 %). As TAA's. docs/techniques/SVGF.md
        LIGHT_HISTORY,
        # moments_alpha 0.2 (the paper's; against the colour's 1/32): held relMSE 0.0281/0.0065/0.0134/0.0478
        # -> 0.0266/0.0064/0.0134/0.0462 on cornell:pan, sunlit_room:pan, sunlit_room:light, cornell:orbit
        # (48 px, 2 draws), trails 1.18/1.62/1.25/1.43x -> 1.20/1.24/1.23/1.35x the still level
        Param("moments_alpha", 0.2, 0.0, 1.0, "least weight of the current frame in the luminance moments the "
              "variance comes from (they follow changes faster than the colour)"),
    )
    quality_ladder = ({"iterations": 3}, {"iterations": 4}, {"iterations": 5}, {"iterations": 6})

    def execute(self, rc, frame):
        res = rc.resources
        prog = rc.programs.compute("filters/svgf_temporal.comp")
        bind_frame(rc, prog, frame)
        units = Units(1)
        for uni, name in (("u_color", COLOR), ("u_gb_albedo", ALBEDO), ("u_gb_position", POSITION),
                          ("u_gb_emission", EMISSION),
                          ("u_gb_normal", NORMAL), ("u_gb_geonormal", GEONORMAL), ("u_gb_motion", MOTION),
                          ("u_hist_illum", "svgf.illum@prev"),
                          ("u_hist_moments", "svgf.moments@prev"), ("u_hist_pos", "svgf.pos@prev"),
                          ("u_hist_nrm", "svgf.nrm@prev")):
            units.tex(prog, uni, res[name])
        self._set_history_uniforms(prog, frame)
        set_uniform(prog, "u_max_history", float(self["max_history"]))
        set_uniform(prog, "u_edge_len", float(self["edge_history"]))
        set_uniform(prog, "u_moments_alpha", float(self["moments_alpha"]))
        for unit, name in enumerate(("svgf.a", "svgf.moments", "svgf.pos", "svgf.nrm", "svgf.dbg_var", "svgf.dbg_len")):
            res[name].bind_to_image(unit, read=False, write=True)
        self._run(rc, prog)
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the copy and the wavelet steps read the temporal result
        # the temporal integration (with its variance) is next frame's history
        self._copy(rc, "svgf.a", "svgf.illum", keep_alpha=True)
        out = self._atrous(rc, frame, "svgf.a", "svgf.b", "svgf.a", int(self["iterations"]), 1,
                           self["sigma_luminance"], self["sigma_normal"], self["sigma_depth"])
        self._modulate(rc, frame, out, COLOR, demod=False)


class TAAPass(_FilterPass):
    """Temporal anti-aliasing of ``color`` (after any denoiser): geometric history rejection,
    per-pixel history length, variance clipping widened by the temporal sigma, linear blend
    (see shaders/filters/taa.comp)."""

    name = "taa"
    reads = (COLOR, MOTION, POSITION, NORMAL, "taa.history@prev", "taa.aux@prev", "taa.pos@prev")
    writes = (COLOR, "taa.history", "taa.aux", "taa.pos", "taa.debug")
    declared = (Res(COLOR, check="radiance"),
                Res("taa.history", history=True, check="radiance"),
                Res("taa.aux", history=True, check="finite"),
                Res("taa.pos", history=True, check="finite"),
                Res("taa.debug", check="radiance"))
    # A light edit does not restart the history (a restart left one filtered 1-spp frame per
    # frame of a moving sun: flicker 3.5x Cycles'); it caps the history length at
    # light_history (2: the current frame weighs >= 1/3), so the relit region follows within a
    # few frames (without the cap it lagged 3.4x the still level 8 frames after the stop).
    # Numbers: docs/techniques/TAA.md.
    history_resets = FILTER_RESETS - {"lights"}
    params = (
        Param("alpha", 0.1, 0.01, 1.0, "least weight of the current frame (1/history length until then)"),
        Param("gamma", 1.25, 0.25, 4.0, "clip box: window mean ± gamma x max(spatial, temporal sigma)"),
        Param("max_history", 32, 1, 1024, "history length cap (debug view: length / max_history)"),
        Param("input_filter", 1, 0, 1, "1: blend the same-surface binomial of this frame's samples (Karis' "
              "reconstruction filter, see radius/young); 0: the pixel's own sample"),
        Param("radius", 2, 1, 2, "input filter radius once the history is older than young (1: 3x3, 2: 5x5)"),
        Param("young", 8.0, 0.0, 1024.0, "history length up to which the input filter is 5x5 whatever radius"),
        Param("history_filter", 1, 0, 1, "history resampling: 1 Catmull-Rom (4x4 taps, where all are on the "
              "pixel's surface; else bilinear), 0 bilinear"),
        Param("history_normal", 0.9, -1.0, 1.0, "a history texel is kept only if its normal . the pixel's normal "
              "exceeds this (-1: off)"),
        # 0.5: a sub-pixel move keeps the plane test only (the still pixel's rule), so a slow pan does not
        # drop the edge pixels' anti-aliased history (sun-lit pan at 0.08 px/frame: held relMSE 0.0253 ->
        # 0.0239); the Cornell pan's grazing face (0.67 px/frame) keeps the normal test. docs/techniques/TAA.md
        Param("normal_motion", 0.5, 0.0, 100.0, "history_normal applies where the reprojection moves by more "
              "than this (pixels)"),
        # turned_history + thin_neff: a slow pan reveals a face edge-on, one pixel wide, whose
        # history is the neighbouring wall's (the plane test passes near their common edge): cap that history
        # and give the young, thin face a wider same-surface input. Cornell pan at 0.22 px/frame, 16 paired
        # draws: trail 1.78x -> 1.38x the still level; stability costs 1.65x -> 1.72x (sun-lit pan).
        Param("turned_history", 1.0, 0.0, 1024.0, "history length cap where a move below normal_motion keeps "
              "history texels whose normal fails history_normal (0: off)"),
        Param("thin_neff", 6.0, 0.0, 25.0, "thin surfaces: where the 5x5 same-surface binomial has fewer effective "
              "samples than this, a young history's input is the same-surface mean of a wider box (0: off)"),
        Param("thin_radius", 4, 2, 8, "thin surfaces: radius of that box"),
        Param("history_fallback", 1, 0, 1, "1: where no bilinear history tap is on the pixel's surface, the "
              "same-surface texels of the 3x3 around the reprojected point"),
        LIGHT_HISTORY,
    )
    quality_ladder = ({"alpha": 0.2}, {"alpha": 0.1}, {"alpha": 0.1, "gamma": 1.0}, {"alpha": 0.05, "gamma": 1.0})

    def execute(self, rc, frame):
        res = rc.resources
        prog = rc.programs.compute("filters/taa.comp")
        bind_frame(rc, prog, frame)
        units = Units(1)
        for uni, name in (("u_color", COLOR), ("u_hist", "taa.history@prev"), ("u_hist_aux", "taa.aux@prev"),
                          ("u_hist_pos", "taa.pos@prev"), ("u_gb_motion", MOTION), ("u_gb_position", POSITION),
                          ("u_gb_normal", NORMAL)):
            units.tex(prog, uni, res[name])
        self._set_history_uniforms(prog, frame)  # light edits: restart or cap the history length
        set_uniform(prog, "u_alpha", float(self["alpha"]))
        set_uniform(prog, "u_gamma", float(self["gamma"]))
        set_uniform(prog, "u_max_history", float(self["max_history"]))
        set_uniform(prog, "u_input_filter", int(self["input_filter"]))
        world = rc.scene.scene.world
        set_uniform(prog, "u_background_filter", 0 if getattr(world, "map", None) is not None else 1)
        set_uniform(prog, "u_young", float(self["young"]))
        set_uniform(prog, "u_history_filter", int(self["history_filter"]))
        set_uniform(prog, "u_radius", int(self["radius"]))
        set_uniform(prog, "u_hist_normal", float(self["history_normal"]))
        set_uniform(prog, "u_hist_fallback", int(self["history_fallback"]))
        set_uniform(prog, "u_normal_motion", float(self["normal_motion"]))
        set_uniform(prog, "u_turned_len", float(self["turned_history"]))
        set_uniform(prog, "u_thin_neff", float(self["thin_neff"]))
        set_uniform(prog, "u_thin_radius", int(self["thin_radius"]))
        for unit, name in enumerate(("taa.history", "taa.aux", "taa.pos", "taa.debug")):
            res[name].bind_to_image(unit, read=False, write=True)
        self._run(rc, prog)
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)  # in-pass: the copy fetches the history just stored
        self._copy(rc, "taa.history", COLOR)


def filter_passes(denoiser: str = "NONE", taa: bool = False, quality=None) -> list:
    """The filter passes for a denoiser id (``NONE``, ``ATROUS``, ``SVGF``) and TAA."""
    d = (denoiser or "NONE").upper()
    if d not in DENOISERS:
        raise ValueError(f"unknown GI Preview denoiser '{denoiser}' (choose one of {', '.join(DENOISERS)})")
    out = []
    if d == "ATROUS":
        out.append(AtrousPass(quality))
    elif d == "SVGF":
        out.append(SVGFPass(quality))
    if taa:
        out.append(TAAPass(quality))
    return out


def with_filters(passes: list, denoiser: str = "NONE", taa: bool = False, quality=None) -> list:
    """``passes`` followed by the requested filters (a filter already in the graph is not
    added twice); a G-buffer pass goes first when no pass of the graph writes one."""
    names = {p.name for p in passes}
    extra = [f for f in filter_passes(denoiser, taa, quality) if f.name not in names]
    if not extra:
        return list(passes)
    out = list(passes)
    if not any(POSITION in p.writes for p in passes):
        out.insert(0, GBufferPass(quality))
    return out + extra
