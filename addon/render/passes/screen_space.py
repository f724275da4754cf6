"""Passes shared by the screen-space family (SSAO, HBAO, SSDO, SSR).

* ``ScreenPass``: base of every screen-space compute pass: binds the frame's camera
  (the jittered view-projection the G-buffer was drawn with), the G-buffer and the scene
  buffers; ``scale`` runs a pass at a fraction of the resolution.
* ``HiZPass``: min device-depth pyramid (``ss.hiz``) for Hi-Z ray marching.
* ``TemporalPass``: reprojection with ``gbuffer.motion`` (reflections, given a hit-distance
  image: by the reflected point), disocclusion rejection by plane
  distance and normal, running mean capped at ``max_history``; its state (signal, position,
  normal) is history resources the graph double-buffers and clears on the events the
  pass declares.
* ``BilateralPass``: depth/normal-aware blur whose spatial extent shrinks with the
  temporal history length.
* ``AmbientStatsPass``: screen means (direct-lit radiance, diffuse albedo, enclosure) for
  the AO techniques' constant indirect term.
* ``CompositePass``: adds a technique's indirect light to ``color`` and writes its AO AOV.

Every pass takes ``provides`` so that the chain of one technique is planned (and skipped,
with the scene analysis' reason) as a whole. Shaders: ``shaders/screen_space/``.
"""
from __future__ import annotations

import math

import numpy as np

from ..framegraph import (ALL_EVENTS, CAMERA_CUT, PARAM_CHANGE, PREV, SHADER_IMAGE_ACCESS_BARRIER_BIT,
                          TEXTURE_FETCH_BARRIER_BIT, TEXTURE_UPDATE_BARRIER_BIT, Param, Pass, Res)
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, MOTION, NORMAL, POSITION

HIZ = "ss.hiz"
DIRECT_RADIANCE = "aov.direct"  # reflected direct light (no emission), written by direct_light
WORLD_SPEC = "aov.world_spec"  # DIRECT's world glossy term, replaced by SSR
COLOR = "color"


def camera_vectors(frame):
    inv = np.linalg.inv(np.asarray(frame.view, np.float64))
    pos = inv[:3, 3]
    fwd = -inv[:3, 2]
    return pos, fwd / max(np.linalg.norm(fwd), 1e-20)


def bind_frame(rc, prog, frame, size=None):
    """Camera, resolution, world and sample uniforms of lib/screen.glsl and common.glsl."""
    vp = (np.asarray(frame.proj, np.float64) @ np.asarray(frame.view, np.float64)).astype(np.float32)
    set_uniform(prog, "u_view_proj", vp)
    set_uniform(prog, "u_view", np.asarray(frame.view, np.float32))
    pos, fwd = camera_vectors(frame)
    set_uniform(prog, "u_camera_pos", tuple(float(x) for x in pos))
    set_uniform(prog, "u_camera_fwd", tuple(float(x) for x in fwd))
    cam = rc.scene.scene.camera
    set_uniform(prog, "u_ortho", 1 if cam is not None and cam.type == "ORTHO" else 0)
    set_uniform(prog, "u_near", float(cam.clip_start) if cam is not None else 1e-3)
    w, h = size or rc.size
    set_uniform(prog, "u_resolution", (float(w), float(h)))
    world = rc.scene.scene.world
    set_uniform(prog, "u_world", tuple(float(x) for x in (world.color if world is not None else (0, 0, 0))))
    set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)


def bind_world_light(scene, prog) -> None:
    """lib/bounce.glsl's u_world_light: 1 when the scene's world is not black."""
    world = scene.world
    set_uniform(prog, "u_world_light", 1 if world is not None and max(world.color) > 0 else 0)


class Units:
    """Hands out texture units (0 is the scene's texture array)."""

    def __init__(self, first: int = 1):
        self.next = first

    def tex(self, prog, uniform: str, tex):
        u = self.next
        self.next += 1
        tex.use(u)
        set_uniform(prog, uniform, u)
        return u


# what bind_gbuffer binds: a pass that calls it lists these in optional_reads
GBUFFER_BOUND = (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION)


def bind_gbuffer(rc, prog, units: Units):
    res = rc.resources
    for name, uni in zip(GBUFFER_BOUND, ("u_gb_albedo", "u_gb_normal", "u_gb_position", "u_gb_geonormal",
                                         "u_gb_motion")):
        if name in res:
            units.tex(prog, uni, res[name])


def scaled(size, scale: float) -> tuple[int, int]:
    return (max(1, int(math.ceil(size[0] * scale))), max(1, int(math.ceil(size[1] * scale))))


class ScreenPass(Pass):
    """A compute pass of the family. ``provides`` is given per technique."""

    optional_reads = GBUFFER_BOUND  # bind_gbuffer

    def __init__(self, quality=None, *, provides=frozenset(), name=None, **props):
        super().__init__(quality, **props)
        self.provides = frozenset(provides)
        if name:
            self.name = name

    def program(self, rc, shader: str, defines=None):
        prog = rc.programs.compute(shader, defines)
        rc.scene.bind(prog)
        return prog

    @staticmethod
    def groups(size, local=8):
        return (size[0] + local - 1) // local, (size[1] + local - 1) // local

    @staticmethod
    def run(rc, prog, size=None):
        """Dispatch over ``size`` (default: the frame). The graph issues the barriers
        between this pass and the next; a pass whose own dispatches depend on each other
        calls ``rc.ctx.memory_barrier`` between them."""
        gx, gy = ScreenPass.groups(size or rc.size)
        rc.dispatch(prog, gx, gy)


# ---------------------------------------------------------------- Hi-Z
class HiZPass(ScreenPass):
    """Min pyramid of device depth: level 0 the nearest depth over each pixel's footprint
    (its G-buffer plane at the pixel corners), then 2x2 (3x3 at odd edges)."""

    name = "ss_hiz"
    reads = (POSITION, GEONORMAL)
    writes = (HIZ,)
    declared = (Res(HIZ, components=1, dtype="f4", levels=0),)
    history_resets = frozenset()

    def compile(self, rc):
        w, h = rc.size
        self.levels = int(math.floor(math.log2(max(w, h)))) + 1

    def execute(self, rc, frame):
        tex = rc.resources[HIZ]
        init = rc.programs.compute("screen_space/hiz.comp", {"HIZ_INIT": 1})
        bind_frame(rc, init, frame)
        rc.resources[POSITION].use(1)
        set_uniform(init, "u_gb_position", 1)
        rc.resources[GEONORMAL].use(2)
        set_uniform(init, "u_gb_geonormal", 2)
        tex.bind_to_image(1, read=False, write=True, level=0)
        self.run(rc, init)
        red = rc.programs.compute("screen_space/hiz.comp")
        w, h = rc.size
        for lv in range(1, self.levels):
            lw, lh = max(1, w >> lv), max(1, h >> lv)
            rc.ctx.memory_barrier(SHADER_IMAGE_ACCESS_BARRIER_BIT)  # level lv-1 stored by the last dispatch
            tex.bind_to_image(0, read=True, write=False, level=lv - 1)
            tex.bind_to_image(1, read=False, write=True, level=lv)
            self.run(rc, red, (lw, lh))


# ---------------------------------------------------------------- temporal
class TemporalPass(ScreenPass):
    """Shared temporal accumulation: ``source`` (any resolution) -> ``output`` (full).

    History (double-buffered by the graph): ``output`` (the running mean), ``output.pos``
    (world position, w = history length) and ``output.nrm``, read back as ``@prev``.
    ``resets``: the events that invalidate it (default: all; an AO signal, which does not
    depend on lights or materials, keeps its history across light and material edits).
    ``f12_pass_through``: in a fresh accumulation (F12: ``frame.keeps_history`` False) output
    each frame's signal unaccumulated, so the session's accumulator takes its plain mean
    instead of an average of running means (which weighs the first frames most); viewport and
    animation frames accumulate as usual. SSR's miss-trace fallback uses it (SSR.md)."""

    params = (
        Param("max_history", 32, 1, 1024, "frames averaged at most while the camera is still"),
        Param("max_history_moving", 8, 1, 1024, "frames averaged at most while the camera moves"),
    )

    def __init__(self, quality=None, *, source: str, output: str, background=(1.0, 1.0, 1.0, 1.0),
                 resets=ALL_EVENTS, hit_distance: str | None = None, clamp: bool = False,
                 f12_pass_through: bool = False, **kw):
        super().__init__(quality, **kw)
        self.f12_pass_through = f12_pass_through
        self.clamp = clamp  # neighbourhood clamp of the history while the camera moves (temporal.comp HISTORY_CLAMP)
        self.source, self.output = source, output
        self.hit_distance = hit_distance  # reflections: reproject by the reflected point (temporal.comp)
        self.len_name = output + ".len"
        self.pos_name, self.nrm_name = output + ".pos", output + ".nrm"
        self.reads = (source, POSITION, NORMAL, MOTION, output + PREV, self.pos_name + PREV, self.nrm_name + PREV) + (
            (hit_distance,) if hit_distance else ())
        self.writes = (output, self.len_name, self.pos_name, self.nrm_name)
        self.declared = (Res(output, history=True, check="radiance"), Res(self.pos_name, history=True),
                         Res(self.nrm_name, dtype="f2", history=True),
                         Res(self.len_name, components=1, check="radiance"))
        self.history_resets = frozenset(resets)
        self.background = tuple(float(x) for x in background)
        self.prev_vp = None

    def execute(self, rc, frame):
        defines = {**({"REFLECTION_REPROJECT": 1} if self.hit_distance else {}),
                   **({"HISTORY_CLAMP": 1} if self.clamp else {})}
        prog = rc.programs.compute("screen_space/temporal.comp", defines or None)
        bind_frame(rc, prog, frame)
        units = Units(1)
        res = rc.resources
        if self.hit_distance:
            units.tex(prog, "u_hit_dist", res[self.hit_distance])
            set_uniform(prog, "u_prev_view_proj", np.asarray(frame.prev_view_proj, np.float32))
        units.tex(prog, "u_current", res[self.source])
        units.tex(prog, "u_hist", res[self.output + PREV])
        units.tex(prog, "u_hist_pos", res[self.pos_name + PREV])
        units.tex(prog, "u_hist_nrm", res[self.nrm_name + PREV])
        bind_gbuffer(rc, prog, units)
        vp = (np.asarray(frame.proj_unjittered if frame.proj_unjittered is not None else frame.proj, np.float64)
              @ np.asarray(frame.view, np.float64))
        moving = self.prev_vp is not None and not np.allclose(vp, self.prev_vp, atol=1e-6)
        self.prev_vp = vp
        fresh = self.f12_pass_through and not frame.keeps_history
        set_uniform(prog, "u_reset", 0 if self.history_valid and not fresh else 1)
        set_uniform(prog, "u_max_history", float(self["max_history_moving"] if moving else self["max_history"]))
        if self.clamp:
            set_uniform(prog, "u_clamp", 1 if moving else 0)
        set_uniform(prog, "u_background", self.background)
        res[self.output].bind_to_image(0, read=False, write=True)
        res[self.len_name].bind_to_image(1, read=False, write=True)
        res[self.pos_name].bind_to_image(2, read=False, write=True)
        res[self.nrm_name].bind_to_image(3, read=False, write=True)
        self.run(rc, prog)

    def reset_history(self):
        super().reset_history()
        self.prev_vp = None


# ---------------------------------------------------------------- bilateral blur
class BilateralPass(ScreenPass):
    params = (
        Param("blur_radius", 2, 0, 8, "kernel radius in pixels (0 = off)"),
        Param("normal_power", 16.0, 0.0, 128.0, "normal edge sharpness"),
        Param("depth_sigma", 1.0, 0.05, 16.0, "depth edge tolerance in pixels of plane distance"),
    )

    def __init__(self, quality=None, *, source: str, output: str, length: str, **kw):
        super().__init__(quality, **kw)
        self.source, self.output, self.length = source, output, length
        self.reads = (source, length, POSITION, NORMAL)
        self.writes = (output,)
        self.declared = (Res(output, check="radiance"),)
        self.history_resets = frozenset()

    def execute(self, rc, frame):
        prog = rc.programs.compute("screen_space/bilateral.comp")
        bind_frame(rc, prog, frame)
        units = Units(1)
        res = rc.resources
        units.tex(prog, "u_src", res[self.source])
        units.tex(prog, "u_len", res[self.length])
        bind_gbuffer(rc, prog, units)
        set_uniform(prog, "u_radius_px", int(self["blur_radius"]))
        set_uniform(prog, "u_normal_power", float(self["normal_power"]))
        set_uniform(prog, "u_depth_sigma", float(self["depth_sigma"]))
        res[self.output].bind_to_image(0, read=False, write=True)
        self.run(rc, prog)


# ---------------------------------------------------------------- ambient statistics
STATS0, STATS1 = "ss.stats0", "ss.stats1"


class AmbientStatsPass(ScreenPass):
    """Screen means for the constant indirect term (reduced with the GL mipmap chain)."""

    name = "ss_ambient_stats"

    def __init__(self, quality=None, *, ao: str, **kw):
        super().__init__(quality, **kw)
        self.ao = ao
        self.reads = (ao, DIRECT_RADIANCE, ALBEDO, NORMAL, POSITION)
        self.writes = (STATS0, STATS1)
        self.declared = (Res(STATS0, levels=0, check="radiance"), Res(STATS1, levels=0, check="radiance"))
        # level 0 by image store, the other levels by glGenerateMipmap
        self.write_access = {STATS0: ("image", "upload"), STATS1: ("image", "upload")}
        self.history_resets = frozenset()

    def execute(self, rc, frame):
        prog = self.program(rc, "screen_space/stats.comp")
        bind_frame(rc, prog, frame)
        units = Units(1)
        units.tex(prog, "u_radiance", rc.resources[DIRECT_RADIANCE])
        units.tex(prog, "u_ao", rc.resources[self.ao])
        bind_gbuffer(rc, prog, units)
        tex = (rc.resources[STATS0], rc.resources[STATS1])
        tex[0].bind_to_image(0, read=False, write=True)
        tex[1].bind_to_image(1, read=False, write=True)
        self.run(rc, prog)
        # in-pass: the mip build reads the level 0 just stored; later fetches and image loads of it
        rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | TEXTURE_UPDATE_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)
        for t in tex:
            t.build_mipmaps()


# ---------------------------------------------------------------- composite
MAX_REPLACED = 2


class CompositePass(ScreenPass):
    """color += the technique's indirect light (see composite.comp for each mode).

    SSR mode, miss fallback: ``fallback`` names the resource holding the
    glossy light (radiance already multiplied by the specular albedo, the units added to
    ``color``) that stands for the share ``1 - a`` of the lobe SSR did not find on screen;
    ``replaces`` names the glossy terms ``color`` already contains which SSR's result
    (found share + fallback share) replaces in full (at most ``MAX_REPLACED``). The pass
    adds ``ks * found + (1 - a) * fallback - sum(replaces)``. Default: DIRECT's shadowed
    world reflection for both, i.e. ``ks * found - a * aov.world_spec`` (SSR's own chain passes
    its miss trace ``ssr.fallback`` instead, see techniques/ssr.py). Another technique
    (probes) passes its own glossy resource as ``fallback`` and lists what of its own it
    already added to ``color`` in ``replaces``."""

    params = (
        Param("ambient_bounces", 1, 0, 8, "AO modes: bounces of the constant indirect term (0 = none)"),
    )

    def __init__(self, quality=None, *, mode: str, signal: str, ao_output: str | None = None,
                 fallback: str = WORLD_SPEC, replaces: tuple[str, ...] | None = None, **kw):
        super().__init__(quality, **kw)
        self.mode, self.signal, self.ao_output = mode, signal, ao_output
        self.fallback = fallback
        self.replaces = tuple((WORLD_SPEC,) if replaces is None else replaces)
        if len(self.replaces) > MAX_REPLACED:
            raise ValueError(f"CompositePass: at most {MAX_REPLACED} replaced terms, got {self.replaces}")
        reads = [signal, COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL]
        if mode == "AO":
            reads += [STATS0, STATS1]
        if mode == "SSR":
            reads += [fallback] + [r for r in self.replaces if r != fallback]
        self.reads = tuple(reads)
        self.effect_output = f"{self.name}.effect"  # what this pass adds: the effect's render pass
        self.writes = (COLOR, self.effect_output) + ((ao_output,) if ao_output else ())
        # SSR's effect replaces DIRECT's world reflection: a signed difference
        self.declared = (Res(self.effect_output, check="finite" if mode == "SSR" else "radiance"),) + (
            (Res(ao_output, check="radiance"),) if ao_output else ())
        self.history_resets = frozenset()

    def execute(self, rc, frame):
        defines = {f"MODE_{self.mode}": 1}
        if self.mode == "SSR":
            defines["N_REPLACED"] = len(self.replaces)
        prog = self.program(rc, "screen_space/composite.comp", defines)
        bind_frame(rc, prog, frame)
        units = Units(1)
        res = rc.resources
        units.tex(prog, "u_signal", res[self.signal])
        if self.mode == "AO":
            units.tex(prog, "u_stats0", res[STATS0])
            units.tex(prog, "u_stats1", res[STATS1])
            set_uniform(prog, "u_stats_lod", float(int(math.floor(math.log2(max(rc.size))))))
            set_uniform(prog, "u_ambient_bounces", int(self["ambient_bounces"]))
        if self.mode == "SSR":
            units.tex(prog, "u_fallback", res[self.fallback])
            for i, r in enumerate(self.replaces):
                units.tex(prog, f"u_replaced{i}", res[r])
        bind_gbuffer(rc, prog, units)
        res[COLOR].bind_to_image(0, read=True, write=True)
        if self.ao_output:
            res[self.ao_output].bind_to_image(1, read=False, write=True)
        res[self.effect_output].bind_to_image(2, read=False, write=True)
        self.run(rc, prog)


# ---------------------------------------------------------------- chains
def ao_chain(prefix: str, raw_pass: Pass, quality, provides, *, mode: str = "AO", blur=None,
             temporal=None, composite=None) -> list:
    """raw (any scale) -> temporal -> bilateral -> [ambient stats] -> composite.

    Resources: ``<prefix>.raw`` (raw_pass writes it), ``<prefix>.temporal``, ``<prefix>.ao``
    (filtered signal), ``<prefix>.aov`` (the AO effect image, background 1)."""
    bg = (1.0, 1.0, 1.0, 1.0) if mode == "AO" else (0.0, 0.0, 0.0, 1.0)
    # occlusion depends on geometry and the view only; a bounce depends on lights and materials too
    resets = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", "transforms"}) if mode == "AO" else ALL_EVENTS
    chain = [raw_pass,
             TemporalPass(quality, name=f"{prefix}_temporal", source=f"{prefix}.raw",
                          output=f"{prefix}.temporal", background=bg, provides=provides, resets=resets,
                          **(temporal or {})),
             BilateralPass(quality, name=f"{prefix}_blur", source=f"{prefix}.temporal", output=f"{prefix}.ao",
                           length=f"{prefix}.temporal.len", provides=provides, **(blur or {}))]
    if mode == "AO":
        chain.append(AmbientStatsPass(quality, name=f"{prefix}_ambient_stats", ao=f"{prefix}.ao",
                                      provides=provides))
    chain.append(CompositePass(quality, name=f"{prefix}_composite", mode=mode, signal=f"{prefix}.ao",
                               ao_output=f"{prefix}.aov", provides=provides, **(composite or {})))
    return chain
