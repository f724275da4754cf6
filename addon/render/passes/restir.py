"""ReSTIR passes (shaders/restir/). ``RestirDIPass``: Bitterli et al. 2020 on the shared ray
tracer (lib/scene_rt.glsl): RIS over light candidates drawn by power, visibility reuse,
temporal reuse (reprojection through ``gbuffer.motion``, M cap), spatial reuse (depth/normal
tests) and a bias-correction mode; reservoirs are graph-owned history textures
(``restir.u``/``restir.meta`` and the surface they were made for, ``restir.pos``/``nrm``).
See the header of shaders/restir/restir_di.comp for the sample space and the stages.
"""
from __future__ import annotations

import numpy as np

from ..framegraph import CAMERA_CUT, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, GEONORMAL, MOTION, NORMAL, POSITION

COLOR = "color"
BIAS_MODES = ("1/M", "MIS-normalised", "ray-traced visibility")


class RestirDIPass(Pass):
    name = "restir_di"
    kind = "compute"
    provides = frozenset({Effect.DIRECT, Effect.SHADOWS, Effect.EMISSION})
    always = True
    reads = (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, "restir.u@prev", "restir.meta@prev", "restir.pos@prev",
             "restir.nrm@prev")
    writes = (COLOR, "restir.u", "restir.meta", "restir.pos", "restir.nrm", "restir.tmp_u", "restir.tmp_meta")
    declared = (Res(COLOR, check="radiance"),
                Res("restir.u", history=True), Res("restir.meta", history=True),
                Res("restir.pos", history=True, clear=(0.0, 0.0, 0.0, -1.0)), Res("restir.nrm", history=True),
                Res("restir.tmp_u"), Res("restir.tmp_meta"))
    # reservoirs hold light samples: a light or geometry edit invalidates them; camera and
    # object motion are followed by reprojection
    history_resets = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", "lights", "materials"})
    warmup_frames = 4
    params = (
        Param("candidates", 32, 1, 256, "RIS light candidates per pixel per frame"),
        Param("temporal", 0, 0, 1, "temporal reuse (off by default: see docs/techniques/RESTIR_DI.md, measured darkening)"),
        Param("spatial", 8, 0, 16, "spatial neighbours"),
        Param("radius", 16.0, 1.0, 64.0, "spatial radius (pixels)"),
        Param("m_cap", 20.0, 1.0, 100.0, "temporal M cap, in multiples of the candidates"),
        Param("bias_mode", 1, 0, 2, "bias correction: 0 = 1/M, 1 = MIS-normalised, 2 = ray-traced visibility"),
        Param("baseline_spp", 0, 0, 256, "> 0: light sampling by power with this many samples, no reuse"),
    )
    quality_ladder = ({"candidates": 8, "spatial": 4}, {"candidates": 32, "spatial": 8},
                      {"candidates": 64, "spatial": 8}, {"candidates": 64, "spatial": 16})

    def execute(self, rc, frame):
        rt = rc.scene.rt()
        res = rc.resources
        prog = rc.programs.compute("restir/restir_di.comp", rt.defines)
        rt.bind(prog)
        inv = np.linalg.inv(np.asarray(frame.view, np.float64))
        set_uniform(prog, "u_camera_pos", tuple(float(x) for x in inv[:3, 3]))
        set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)
        set_uniform(prog, "u_seed", int(frame.seed) & 0xFFFFFFFF)
        set_uniform(prog, "u_reset", 0 if (self.history_valid and not frame.camera_cut) else 1)
        for k in ("candidates", "temporal", "spatial", "bias_mode", "baseline_spp"):
            set_uniform(prog, "u_" + k, int(self[k]))
        set_uniform(prog, "u_radius", float(self["radius"]))
        set_uniform(prog, "u_m_cap", float(self["m_cap"]))
        unit = 1
        for uni, name in (("u_gb_albedo", ALBEDO), ("u_gb_position", POSITION), ("u_gb_normal", NORMAL),
                          ("u_gb_geonormal", GEONORMAL), ("u_gb_motion", MOTION),
                          ("u_prev_pos", "restir.pos@prev"), ("u_prev_nrm", "restir.nrm@prev")):
            res[name].use(unit)
            set_uniform(prog, uni, unit)
            unit += 1
        u_in, m_in = unit, unit + 1
        set_uniform(prog, "u_in_u", u_in)
        set_uniform(prog, "u_in_meta", m_in)
        gx, gy = rc.groups(8)
        if int(self["baseline_spp"]) == 0:
            # stage 0: candidates, visibility reuse, temporal reuse -> tmp
            set_uniform(prog, "u_stage", 0)
            res["restir.u@prev"].use(u_in)
            res["restir.meta@prev"].use(m_in)
            for b, name in enumerate(("restir.tmp_u", "restir.tmp_meta", COLOR, "restir.pos", "restir.nrm")):
                res[name].bind_to_image(b, read=False, write=True)
            rc.dispatch(prog, gx, gy)
            rc.ctx.memory_barrier(0x0008 | 0x0020)  # stage 1 fetches the neighbours' reservoirs
        # stage 1: spatial reuse, shading, reservoirs for the next frame
        set_uniform(prog, "u_stage", 1)
        res["restir.tmp_u"].use(u_in)
        res["restir.tmp_meta"].use(m_in)
        for b, name in enumerate(("restir.u", "restir.meta", COLOR, "restir.pos", "restir.nrm")):
            res[name].bind_to_image(b, read=False, write=True)
        rc.dispatch(prog, gx, gy)
