"""ReSTIR passes (shaders/restir/). ``RestirDIPass``: Bitterli et al. 2020 on the shared ray
tracer (lib/scene_rt.glsl): RIS over light candidates drawn by power and BSDF candidates
(MIS'd candidate pdfs), visibility reuse, temporal reuse (reprojection through
``gbuffer.motion``, M cap), spatial reuse (depth/normal tests), a bias-correction mode, and
final visibility (a hidden sample is kept with W = 0). Reservoirs are graph-owned history
textures (``restir.y``/``meta``/``le`` and the surface they were made for, ``restir.pos``/
``nrm``). Render passes: ``restir.direct`` (direct light), ``restir.emit`` (emission seen),
debug views ``restir.dbg_w`` (the reservoir's W) and ``restir.dbg_m`` (its M).
See the header of shaders/restir/restir_di.comp for the sample space, the stages and the
bias modes.
"""
from __future__ import annotations

import numpy as np

from ..barriers import SHADER_IMAGE_ACCESS_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT
from ..framegraph import CAMERA_CUT, LIGHT_SET, PARAM_CHANGE, Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from .gbuffer import ALBEDO, EMISSION, GEONORMAL, MOTION, NORMAL, POSITION
from .screen_space import camera_vectors

COLOR = "color"
AOV_DIRECT, AOV_EMIT, DBG_W, DBG_M = "restir.direct", "restir.emit", "restir.dbg_w", "restir.dbg_m"
BIAS_MODES = ("1/M", "MIS-normalised", "ray-traced visibility")
_HIST = ("restir.y", "restir.meta", "restir.le")
_TMP = ("restir.tmp_y", "restir.tmp_meta", "restir.tmp_le")



def bind_reuse_frame(prog, frame, history_valid: bool):
    """The per-frame uniforms of the ReSTIR passes (DI and GI): camera position, sample index
    and seed, and ``u_reset`` (1 when the reservoir history cannot be reused)."""
    pos, _ = camera_vectors(frame)
    set_uniform(prog, "u_camera_pos", tuple(float(x) for x in pos))
    set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)
    set_uniform(prog, "u_seed", int(frame.seed) & 0xFFFFFFFF)
    set_uniform(prog, "u_reset", 0 if (history_valid and not frame.camera_cut) else 1)

class RestirDIPass(Pass):
    name = "restir_di"
    kind = "compute"
    provides = frozenset({Effect.DIRECT, Effect.SHADOWS, Effect.EMISSION, Effect.ENVIRONMENT})
    always = True
    reads = (ALBEDO, NORMAL, POSITION, GEONORMAL, MOTION, EMISSION, *(h + "@prev" for h in _HIST), "restir.pos@prev",
             "restir.nrm@prev")
    writes = (COLOR, AOV_DIRECT, AOV_EMIT, DBG_W, DBG_M, *_HIST, "restir.pos", "restir.nrm", *_TMP)
    declared = (Res(COLOR, check="radiance"), Res(AOV_DIRECT, check="radiance"), Res(AOV_EMIT, check="radiance"),
                Res(DBG_W), Res(DBG_M),
                *(Res(h, history=True) for h in _HIST),
                Res("restir.pos", history=True, clear=(0.0, 0.0, 0.0, -1.0)), Res("restir.nrm", history=True),
                *(Res(t) for t in _TMP))
    # reservoirs hold light-relative samples (restir_di.comp): they follow a light that moves or
    # changes; a change of which lights there are (LIGHT_SET), geometry or materials invalidates
    # them; camera and object motion are followed by reprojection
    history_resets = frozenset({CAMERA_CUT, PARAM_CHANGE, "geometry", LIGHT_SET, "materials"})
    warmup_frames = 4
    params = (
        Param("candidates", 32, 0, 256, "RIS light candidates (by power) per pixel per frame"),
        Param("bsdf_candidates", 1, 0, 8, "RIS BSDF candidates per pixel per frame (world light, large lights)"),
        Param("bsdf_glossy", 8, 0, 32, "BSDF candidates on glossy pixels (they also test every area/sphere/sun "
              "light there): small lights' highlights, which light sampling by power rarely finds"),
        Param("glossy_roughness", 0.3, 0.0, 1.0, "glossy pixels: roughness below this, mostly specular"),
        Param("temporal", 2, 0, 2, "temporal reuse: 0 off, 1 on, 2 = on except for frames 2.. of a still "
              "accumulation (F12, still viewport), whose mean converges faster from independent frames"),
        Param("spatial", 8, 0, 16, "spatial neighbours"),
        Param("radius", 0.03, 0.0, 0.25, "spatial radius, a fraction of the image's larger side (30 px at 1080p)"),
        Param("radius_min", 2.0, 1.0, 64.0, "smallest spatial radius (pixels)"),
        Param("shade_all", 1, 0, 1, "shade every spatial input by its MIS weight (1 shadow ray each) instead of only the kept one"),
        Param("m_cap", 20.0, 1.0, 100.0, "temporal M cap, in multiples of this frame's candidates"),
        Param("bias_mode", 2, 0, 2, "bias correction: 0 = 1/M, 1 = MIS-normalised, 2 = ray-traced visibility"),
        Param("baseline_spp", 0, 0, 256, "> 0: the shared next-event estimator with this many samples, no reuse"),
        Param("bsdf_light_max", 16, 0, 1024,
              "BSDF candidates test area/sphere/sun-disk lights when the scene has at most this many"),
        Param("baseline_bsdf", 1, 0, 2, "baseline: 0 = light samples only, 1 = plus a BSDF ray for the world light, "
              "2 = light samples MIS'd with BSDF rays (PT's estimator)"),
    )
    quality_ladder = ({"candidates": 8, "spatial": 4}, {"candidates": 32, "spatial": 8},
                      {"candidates": 64, "spatial": 8}, {"candidates": 64, "spatial": 16})

    @staticmethod
    def _analytic_lights(rc) -> int:
        """Lights a BSDF ray can hit other than emissive triangles: area lights, and point,
        spot and sun lights with a size (gpu_scene.pack_lights rows: type at 3, size at 7)."""
        arr = getattr(rc.scene, "light_array", None)
        n = int(getattr(rc.scene, "light_count", 0))
        if arr is None or n == 0:
            return 0
        a = np.asarray(arr, np.float32).reshape(-1, 28)[:n]
        t, size = np.rint(a[:, 3]).astype(int), a[:, 7]
        return int(np.count_nonzero((t == 3) | ((t <= 2) & (size > 1e-6))))

    def execute(self, rc, frame):
        rt = rc.scene.rt()
        res = rc.resources
        gx, gy = rc.groups(8)
        baseline = int(self["baseline_spp"]) > 0
        analytic = int(self._analytic_lights(rc) <= int(self["bsdf_light_max"]))
        for stage in ((2,) if baseline else (0, 1)):
            prog = rc.programs.compute("restir/restir_di.comp", {**rt.defines, "RESTIR_STAGE": str(stage)})
            rt.bind(prog)
            rc.scene.light_prev_buf.bind_to_storage_buffer(17)  # restir_di.comp: lights_prev
            bind_reuse_frame(prog, frame, self.history_valid)
            set_uniform(prog, "u_light_cands", int(self["candidates"]))
            t = int(self["temporal"])
            set_uniform(prog, "u_temporal", int(t == 1 or (t == 2 and int(frame.index) == 0)))
            set_uniform(prog, "u_lights_edited", int(bool({"lights", "transforms"} & set(frame.scene_edits))))
            for k in ("bsdf_cands", "spatial", "shade_all", "bias_mode", "baseline_spp", "baseline_bsdf"):
                set_uniform(prog, "u_" + k, int(self["bsdf_candidates" if k == "bsdf_cands" else k]))
            set_uniform(prog, "u_bsdf_analytic", analytic)
            set_uniform(prog, "u_bsdf_glossy", int(self["bsdf_glossy"]))
            set_uniform(prog, "u_glossy_rough", float(self["glossy_roughness"]))
            set_uniform(prog, "u_radius", float(self["radius"]))
            set_uniform(prog, "u_radius_min", float(self["radius_min"]))
            set_uniform(prog, "u_m_cap", float(self["m_cap"]))
            src = [h + "@prev" for h in _HIST] if stage == 0 else list(_TMP)
            unit = 1
            for uni, name in (("u_gb_albedo", ALBEDO), ("u_gb_position", POSITION), ("u_gb_normal", NORMAL),
                              ("u_gb_geonormal", GEONORMAL), ("u_gb_motion", MOTION), ("u_gb_emission", EMISSION),
                              ("u_prev_pos", "restir.pos@prev"), ("u_prev_nrm", "restir.nrm@prev"),
                              ("u_in_y", src[0]), ("u_in_meta", src[1]), ("u_in_le", src[2])):
                res[name].use(unit)
                set_uniform(prog, uni, unit)
                unit += 1
            if stage == 0:
                images = (*_TMP, "restir.pos", "restir.nrm", AOV_EMIT)
            elif stage == 1:
                images = (*_HIST, COLOR, AOV_DIRECT, DBG_W, DBG_M)
            else:
                images = (None, None, None, COLOR, AOV_DIRECT, AOV_EMIT)
            for b, name in enumerate(images):
                if name is not None:
                    res[name].bind_to_image(b, read=False, write=True)
            rc.dispatch(prog, gx, gy)
            if stage == 0:
                # in-pass: stage 1 fetches the neighbours' reservoirs stage 0 stored
                rc.ctx.memory_barrier(TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT)
