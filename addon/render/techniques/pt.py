"""PT: reference path tracer on a software two-level BVH (compute shaders).

One pass, ``path_trace`` (``shaders/pt/pt.comp``): camera rays with box-filter jitter over
the pixel; the Principled subset of ``lib/brdf.glsl`` (the same code DIRECT shades with):
Lambert diffuse under a dielectric GGX layer, metals, visible-normal GGX sampling; next-event
estimation for every light type (point/sphere, spot, sun with angle, area rectangle/disk/
ellipse, emissive triangles chosen by power) combined with BSDF sampling by MIS with the
power heuristic (Veach & Guibas 1995); world colour as background and light; Russian
roulette; bounce limits with Cycles' meaning (max total, diffuse, glossy, transmission). Each frame writes
the mean of ``spp_per_frame`` samples; the renderer accumulates frames (progressive), and
any change of scene or parameter restarts the accumulation there. Rays, materials, light
selection, next-event estimation and the MIS of BSDF rays hitting lights come from the shared
ray-tracing component (``render/rt_scene.py`` SceneRT, ``shaders/lib/scene_rt.glsl``), owned
by the session's GPUScene: its BVH (``render/bvh.py``) is rebuilt only when mesh geometry
changes, moving objects rebuilds the top level only, and every graph of the session shares it.

| parameter | range | meaning |
|---|---|---|
| spp_per_frame | 1–64 | samples per pixel traced in one frame |
| max_bounces | 0–64 | Cycles' Max Bounces (total) |
| diffuse_bounces | 0–64 | Cycles' Diffuse bounces |
| glossy_bounces | 0–64 | Cycles' Glossy bounces |
| transmission_bounces | 0–64 | Cycles' Transmission bounces (refraction, translucency) |
| rr_start | 0–64 | Russian roulette starts after this many bounces |
| tile | 16–1024 | pixels per side of one dispatch (keeps a dispatch short on slow GPUs) |
| pixel_sequence | 0–2 | in-pixel position of the camera ray: 0 white noise per sample; 1 Halton(2,3) indexed by the frame counter (``frame.sample`` x spp + k) with a per-pixel Cranley-Patterson rotation; 2 (default) Halton where the frames form one fresh accumulation (F12, offline renders: ``frame.keeps_history`` False), white noise where history is kept (viewport, animation: TAA under motion measured worse with Halton, docs/techniques/TAA.md) |

Quality ladder: spp_per_frame 1, 2, 4, 8. Compared with: the full Cycles reference.
AOVs: ``GI_Direct`` (paths with one scattering), ``GI_IndirectDiffuse`` /
``GI_IndirectGlossy`` (longer paths, by the lobe of their first scattering).
"""
from __future__ import annotations

import time

import numpy as np

from ..framegraph import Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
# the BVH, light selection and their checks live in the shared component (rt_scene.SceneRT);
# re-exported here for scripts that import them from this module
from ..rt_scene import check_triangle_budget, geometry_key, light_selection  # noqa: F401
from . import Technique, register

COLOR = "color"
AOV_DIRECT, AOV_IND_DIFFUSE, AOV_IND_GLOSSY = "aov.pt_direct", "aov.pt_indirect_diffuse", "aov.pt_indirect_glossy"


class PathTracePass(Pass):
    name = "path_trace"
    provides = frozenset({Effect.DIRECT, Effect.SHADOWS, Effect.EMISSION, Effect.ENVIRONMENT,
                          Effect.INDIRECT_DIFFUSE, Effect.INDIRECT_SPECULAR})
    always = True
    reads = ()
    writes = (COLOR, AOV_DIRECT, AOV_IND_DIFFUSE, AOV_IND_GLOSSY)
    declared = tuple(Res(n, check="radiance") for n in writes)
    history_resets = frozenset()
    params = (
        Param("spp_per_frame", 1, 1, 64, "samples per pixel traced in one frame"),
        Param("max_bounces", 12, 0, 64, "Cycles' Max Bounces (total)"),
        Param("diffuse_bounces", 12, 0, 64, "Cycles' Diffuse bounces"),
        Param("glossy_bounces", 12, 0, 64, "Cycles' Glossy bounces"),
        Param("transmission_bounces", 12, 0, 64, "Cycles' Transmission bounces"),
        Param("rr_start", 3, 0, 64, "Russian roulette after this many bounces"),
        Param("tile", 128, 16, 1024, "pixels per side of one dispatch"),
        Param("pixel_sequence", 2, 0, 2, "in-pixel camera-ray position: 0 white noise, 1 Halton(2,3) over the "
              "frame counter, rotated per pixel, 2 Halton in a fresh accumulation (F12), white noise where "
              "history is kept (viewport, animation)"),
    )
    quality_ladder = ({"spp_per_frame": 1}, {"spp_per_frame": 2}, {"spp_per_frame": 4}, {"spp_per_frame": 8})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.bvh_ms = 0.0

    def shader_defines(self, rt) -> dict:
        """The defines ``pt.comp`` is compiled with (the shared ray tracer's bindings)."""
        return rt.defines

    def execute(self, rc, frame):
        rt = rc.scene.rt()  # the session's shared BVH (rebuilt there only when geometry changes)
        self.bvh_ms = rt.bvh_ms
        scene = rc.scene.scene
        cam = scene.camera
        prog = rc.programs.compute("pt/pt.comp", self.shader_defines(rt))
        rt.bind(prog)
        set_uniform(prog, "u_cam_to_world", np.asarray(cam.matrix_world, np.float32))
        set_uniform(prog, "u_inv_proj", np.linalg.inv(np.asarray(cam.projection, np.float64)).astype(np.float32))
        set_uniform(prog, "u_ortho", 1 if cam.type == "ORTHO" else 0)
        set_uniform(prog, "u_clip_start", float(cam.clip_start))
        set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)
        set_uniform(prog, "u_seed", int(frame.seed) & 0xFFFFFFFF)
        set_uniform(prog, "u_spp", int(self["spp_per_frame"]))
        set_uniform(prog, "u_max_bounces", int(self["max_bounces"]))
        set_uniform(prog, "u_max_diffuse", int(self["diffuse_bounces"]))
        set_uniform(prog, "u_max_glossy", int(self["glossy_bounces"]))
        set_uniform(prog, "u_max_transmission", int(self["transmission_bounces"]))
        set_uniform(prog, "u_rr_start", int(self["rr_start"]))
        seq = int(self["pixel_sequence"])
        set_uniform(prog, "u_pixel_sequence", int(not frame.keeps_history) if seq == 2 else seq)
        res = rc.resources
        for unit, name in enumerate(self.writes):
            res[name].bind_to_image(unit, read=False, write=True)
        tile = int(self["tile"])
        for y in range(0, rc.height, tile):
            for x in range(0, rc.width, tile):
                set_uniform(prog, "u_offset", (x, y))
                rc.dispatch(prog, (min(tile, rc.width - x) + 7) // 8, (min(tile, rc.height - y) + 7) // 8)


def render_offline(ctx, scene, frames: int, *, spp_per_frame: int = 4, seed: int = 0, programs=None,
                   gpu_scene=None, **props) -> dict:
    """Render ``scene`` (SceneData) with PT outside the renderer: ``frames`` frames of
    ``spp_per_frame`` samples each, on ``ctx`` (the caller's GL thread). Returns a dict with
    ``frames`` (F, H, W, 3) per-frame means of colour, ``aovs`` (name -> (H, W, 3) mean),
    ``time_ms`` (wall time of tracing, synchronised) and ``bvh_ms``. Row 0 = bottom row."""
    from ..framegraph import FrameGraph, FrameState, RenderContext
    from ..gpu_scene import GPUScene
    from ..shaders import ProgramCache

    own_scene = gpu_scene is None
    gs = gpu_scene or GPUScene(ctx)
    gs.update(scene)
    programs = programs or ProgramCache(ctx)
    rc = RenderContext(ctx, programs, gs, (scene.width, scene.height))
    p = PathTracePass(None, spp_per_frame=spp_per_frame, **props)
    # a one-pass graph: it orders each frame's image stores after the last frame's read-backs
    # and stores, and the read-backs after the stores
    graph = FrameGraph([p])
    graph.plan(set(p.provides))
    graph.compile(rc)
    out = np.zeros((frames, scene.height, scene.width, 3), np.float32)
    aovs = {n: np.zeros((scene.height, scene.width, 3), np.float64) for n in p.writes[1:]}
    graph.execute(rc, FrameState(index=0, sample=0, seed=seed), timers=False)  # warm-up: BVH, compile
    ctx.finish()
    bvh_ms = p.bvh_ms
    t0 = time.perf_counter()
    for f in range(frames):
        graph.execute(rc, FrameState(index=f, sample=f, seed=seed), timers=False)
        img = np.frombuffer(rc.read_back(COLOR), np.float32).reshape(scene.height, scene.width, 4)
        out[f] = img[..., :3]
        for n in aovs:
            aovs[n] += np.frombuffer(rc.read_back(n), np.float32).reshape(scene.height, scene.width, 4)[..., :3]
    ctx.finish()
    dt = (time.perf_counter() - t0) * 1e3
    for n in aovs:
        aovs[n] /= max(frames, 1)
    p.release()
    rc.resources.release()
    if own_scene:
        gs.release()
    return {"frames": out, "aovs": aovs, "time_ms": dt, "bvh_ms": bvh_ms}


@register
class PT(Technique):
    id = "PT"
    label = "Path tracing"
    description = "Reference path tracer on a software BVH: every effect, converges to Cycles"
    family = "ray tracing"
    reference = "full"
    cost_rank = 1000
    outputs = {"GI_Direct": AOV_DIRECT, "GI_IndirectDiffuse": AOV_IND_DIFFUSE, "GI_IndirectGlossy": AOV_IND_GLOSSY}

    def passes(self, quality):
        return [PathTracePass(quality)]
