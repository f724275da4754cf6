"""ReSTIR GI pass (Ouyang et al. 2021) on the shared ray tracer (lib/scene_rt.glsl);
shader ``shaders/restir_gi/restir_gi.comp`` (its header documents the sample, the target
function, the Jacobian and the stages).

``RestirGIPass`` adds indirect light to ``color`` (which DIRECT's passes wrote):

* stage 0: per pixel one BSDF-sampled secondary ray from the G-buffer point, its hit x_s,
  n_s and the radiance leaving x_s towards the pixel (next-event estimation at x_s plus a
  path continuation with Russian roulette, ``max_bounces`` as Cycles counts them; the
  emission of x_s and the world seen by that first ray are left to DIRECT); temporal reuse of
  last frame's final reservoir (reprojection through ``gbuffer.motion``, plane/normal tests,
  validation ray, reconnection Jacobian, M capped at ``m_cap``; a history sample older than
  ``max_age`` frames is not reused), then the boiling filter (``boiling_filter``: a reservoir
  far brighter than its 8x8 tile's mean is dropped);
* stage 1: spatial reuse over ``spatial`` neighbours in ``radius`` pixels (depth/normal
  tests, validation rays, Jacobian), bias correction ``bias_mode`` (0 = 1/M, 1 = the balance
  heuristic over the domains, Bitterli 2020 Alg. 6, with ray-traced visibility from each);
* stage 2: ``color += f L_o W`` split by lobe into ``restir_gi.diffuse`` /
  ``restir_gi.glossy`` (GI_IndirectDiffuse / GI_IndirectGlossy) and the debug views
  ``restir_gi.view_w`` (the reservoir's contribution weight W) and ``restir_gi.view_m``
  (its candidate count M).

Reservoirs are graph-owned history (``restir_gi.pos/nrm/rad`` and the visible point they were
made for, ``restir_gi.vpos/vnrm``; ``feedback`` 1 keeps the spatial reservoirs there, 0 the
temporal ones as in the paper, shading then reads ``restir_gi.tmp_*``), reset on a camera cut, a parameter change and scene edits
that change radiance or positions (geometry, transforms, materials, lights, textures).
"""
from __future__ import annotations

from ..barriers import SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT
from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, MOTION, NORMAL, POSITION
from .restir import bind_reuse_frame

COLOR = "color"
AOV_DIFFUSE, AOV_GLOSSY = "restir_gi.diffuse", "restir_gi.glossy"
VIEW_W, VIEW_M = "restir_gi.view_w", "restir_gi.view_m"
HISTORY = ("restir_gi.pos", "restir_gi.nrm", "restir_gi.rad", "restir_gi.vpos", "restir_gi.vnrm")
TMP = ("restir_gi.tmp_pos", "restir_gi.tmp_nrm", "restir_gi.tmp_rad")
BIAS_MODES = ("1/M", "balance heuristic (MIS) with ray-traced visibility")
# reservoirs hold positions and radiance: any edit of either invalidates them
RESTIR_GI_RESETS = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", "transforms", "materials", "lights", "textures"})

_TEX = (("u_gb_albedo", ALBEDO), ("u_gb_position", POSITION), ("u_gb_normal", NORMAL),
        ("u_gb_geonormal", GEONORMAL), ("u_gb_motion", MOTION))
_IN = ("u_in_pos", "u_in_nrm", "u_in_rad", "u_in_vpos", "u_in_vnrm")


class RestirGIPass(Pass):
    name = "restir_gi"
    kind = "compute"
    provides = frozenset({Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR})
    reads = (COLOR, ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION) + tuple(n + "@prev" for n in HISTORY)
    writes = (COLOR, *HISTORY, *TMP, AOV_DIFFUSE, AOV_GLOSSY, VIEW_W, VIEW_M)
    declared = (Res(COLOR, check="radiance"),
                Res("restir_gi.pos", history=True), Res("restir_gi.nrm", history=True),
                Res("restir_gi.rad", history=True, check="radiance"),
                Res("restir_gi.vpos", history=True, clear=(0.0, 0.0, 0.0, -1.0)),
                Res("restir_gi.vnrm", history=True),
                *(Res(n) for n in TMP),
                Res(AOV_DIFFUSE, check="radiance"), Res(AOV_GLOSSY, check="radiance"),
                Res(VIEW_W, check="radiance"), Res(VIEW_M, check="radiance"))
    history_resets = RESTIR_GI_RESETS
    warmup_frames = 8
    params = (
        Param("temporal", 1, 0, 1, "temporal reuse"),
        Param("spatial", 4, 0, 16, "spatial neighbours"),
        Param("radius", 12.0, 1.0, 64.0, "spatial radius (pixels)"),
        Param("m_cap", 20.0, 1.0, 500.0, "temporal M cap (candidates kept from history)"),
        Param("bias_mode", 1, 0, 1, "bias correction: 0 = 1/M, 1 = balance heuristic over the domains with ray-traced visibility"),
        Param("jacobian_max", 10.0, 1.0, 1000.0, "reuse refused when the reconnection Jacobian is above this or below its inverse"),
        Param("max_bounces", 12, 1, 64, "Cycles' Max Bounces (total) of the secondary path"),
        Param("rr_start", 3, 1, 64, "Russian roulette after this many bounces"),
        Param("feedback", 1, 0, 1, "next frame's history: 1 = the spatial reservoirs (RTXDI), 0 = the temporal ones (the paper)"),
        Param("max_age", 30.0, 0.0, 1000.0, "a history reservoir whose sample was traced more than this many frames ago is not reused (0 = no cap)"),
        Param("boiling_filter", 0.2, 0.0, 1.0, "boiling filter strength: after temporal reuse, reservoirs brighter than (10 / strength - 9) x their 8x8 tile's mean are dropped (0 = off)"),
    )
    quality_ladder = ({"spatial": 2, "radius": 8.0, "max_bounces": 3}, {"spatial": 4, "radius": 12.0},
                      {"spatial": 6, "radius": 16.0}, {"spatial": 8, "radius": 24.0, "m_cap": 30.0})

    def execute(self, rc, frame):
        rt = rc.scene.rt()
        res = rc.resources
        prog = rc.programs.compute("restir_gi/restir_gi.comp", rt.defines)
        rt.bind(prog)
        bind_reuse_frame(prog, frame, self.history_valid)
        for k in ("temporal", "spatial", "bias_mode", "max_bounces", "rr_start"):
            set_uniform(prog, "u_" + k, int(self[k]))
        for k in ("radius", "m_cap", "jacobian_max", "max_age"):
            set_uniform(prog, "u_" + k, float(self[k]))
        set_uniform(prog, "u_boiling", float(self["boiling_filter"]))
        unit = 1
        for uni, name in _TEX:
            res[name].use(unit)
            set_uniform(prog, uni, unit)
            unit += 1
        in_units = {}
        for uni in _IN:
            in_units[uni] = unit
            set_uniform(prog, uni, unit)
            unit += 1

        def inputs(names):
            for uni, name in zip(_IN, names):
                res[name].use(in_units[uni])

        gx, gy = rc.groups(8)
        barrier = TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT  # in-pass: the next stage fetches or loads this one's stores
        # feedback 1: stage 0 -> tmp, stage 1 -> history (the spatial result is next frame's
        # history); feedback 0: stage 0 -> history, stage 1 -> tmp (the temporal result is)
        fb = int(self["feedback"]) == 1
        temporal_out = TMP if fb else HISTORY[:3]
        spatial_out = HISTORY[:3] if fb else TMP
        vis = HISTORY[3:]  # both stages write the same visible point
        # stage 0: fresh sample + temporal reuse
        set_uniform(prog, "u_stage", 0)
        inputs([n + "@prev" for n in HISTORY])
        for b, name in enumerate(temporal_out + vis):
            res[name].bind_to_image(b, read=b == 0, write=True)
        rc.dispatch(prog, gx, gy)
        rc.ctx.memory_barrier(barrier)
        # stage 1: spatial reuse
        set_uniform(prog, "u_stage", 1)
        inputs(temporal_out + ("restir_gi.vpos@prev", "restir_gi.vnrm@prev"))  # vpos/vnrm unused here
        for b, name in enumerate(spatial_out + vis):
            res[name].bind_to_image(b, read=b == 0, write=True)
        rc.dispatch(prog, gx, gy)
        rc.ctx.memory_barrier(barrier)
        # stage 2: shading from the spatial reservoirs, effect images, debug views
        set_uniform(prog, "u_stage", 2)
        inputs(spatial_out + vis)
        for b, name in enumerate((COLOR, AOV_DIFFUSE, AOV_GLOSSY, VIEW_W, VIEW_M)):
            res[name].bind_to_image(b, read=b == 0, write=True)
        rc.dispatch(prog, gx, gy)
