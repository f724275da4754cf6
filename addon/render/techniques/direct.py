"""DIRECT: direct lighting and shadows only (no indirect light).

Passes: ``gbuffer`` (raster) → ``shadows`` (shadow atlas) → ``direct_light`` (compute).
Every light type in Cycles' units; diffuse terms are exact (cosine law, polygon
irradiance), glossy terms are Monte Carlo with MIS and converge over ``samples`` frames,
as do soft shadows (the shadow views move over the light's surface each frame) and
anti-aliasing (box-filter jitter). The world is the background and, like in Cycles'
"direct" reference, a light: uniform radiance times each lobe's albedo, shadowed by the
visibility of ``world_directions`` orthographic maps per frame (directions stratified on
the sphere, rotated every frame; a cosine-weighted ratio estimator, exact for unoccluded
points). No indirect light.

| parameter | range | meaning |
|---|---|---|
| shadow_resolution | 64–4096 | texels per cube face / cascade |
| cascades | 1–4 | sun cascades |
| glossy_samples | 1–16 | light+BSDF sample pairs per light per pixel per frame |
| mesh_exact_max | 0–256 | emissive meshes with at most this many triangles are integrated exactly |
| world_directions | 0–64 | world-light visibility maps per frame |

Quality ladder (shadow px, glossy samples, world directions): 0 = 256, 1, 4; 1 = 512, 2, 8;
2 = 1024, 4, 16; 3 = 2048, 8, 24.
Compared with: Cycles with all bounces off (direct light only).
"""
from __future__ import annotations

import numpy as np

from ..framegraph import Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from ..passes.gbuffer import ALBEDO, GEONORMAL, NORMAL, POSITION, GBufferPass
from ..passes.shadows import ATLAS, VIEWS, WORLD_RANGE, ShadowPass
from . import Technique, register

COLOR, AOV_DIRECT, AOV_EMIT, WORLD_SPEC = "color", "aov.direct", "aov.emit", "aov.world_spec"
# DIRECT's render passes; every technique built on DIRECT's passes returns them too
DIRECT_OUTPUTS = {"GI_Direct": AOV_DIRECT, "Emit": AOV_EMIT}


class DirectLightPass(Pass):
    name = "direct_light"
    provides = frozenset({Effect.DIRECT, Effect.EMISSION, Effect.ENVIRONMENT})
    always = True  # produces the colour every technique builds on
    reads = (ALBEDO, NORMAL, POSITION, GEONORMAL)
    optional_reads = (ATLAS, VIEWS, WORLD_RANGE)  # the shadow pass runs only if something casts shadows
    writes = (COLOR, AOV_DIRECT, AOV_EMIT, WORLD_SPEC)
    declared = tuple(Res(n, check="radiance") for n in writes)
    history_resets = frozenset()
    params = (
        Param("glossy_samples", 2, 1, 16, "light+BSDF sample pairs per light per pixel per frame"),
        Param("mesh_exact_max", 64, 0, 256, "emissive meshes up to this many triangles are integrated exactly"),
    )
    quality_ladder = ({"glossy_samples": 1}, {"glossy_samples": 2}, {"glossy_samples": 4}, {"glossy_samples": 8})

    def execute(self, rc, frame):
        prog = rc.programs.compute("direct/direct.comp")
        res = rc.resources
        rc.scene.bind(prog)
        for unit, (name, uni) in enumerate(((ALBEDO, "u_gb_albedo"), (NORMAL, "u_gb_normal"),
                                            (POSITION, "u_gb_position"), (GEONORMAL, "u_gb_geonormal")), start=1):
            res[name].use(unit)
            set_uniform(prog, uni, unit)
        if ATLAS in res and VIEWS in res:  # present when the shadow pass ran (now or before)
            res[ATLAS].use(5)
            res[VIEWS].bind_to_storage_buffer(3)
        set_uniform(prog, "u_shadow_atlas", 5)
        cam = rc.scene.scene.camera
        set_uniform(prog, "u_camera_pos", tuple(float(x) for x in cam.position))
        set_uniform(prog, "u_camera_dir", tuple(float(x) for x in cam.forward))
        set_uniform(prog, "u_ortho", 1 if cam.type == "ORTHO" else 0)
        set_uniform(prog, "u_world", tuple(float(x) for x in rc.scene.scene.world.color))
        set_uniform(prog, "u_sample", int(frame.sample) & 0xFFFFFFFF)
        set_uniform(prog, "u_glossy_samples", int(self["glossy_samples"]))
        set_uniform(prog, "u_mesh_exact_max", int(self["mesh_exact_max"]))
        wr = res.get(WORLD_RANGE)
        world_on = wr is not None and wr.count > 0 and float(max(rc.scene.scene.world.color)) > 0
        set_uniform(prog, "u_world_first", int(wr.first) if world_on else 0)
        set_uniform(prog, "u_world_count", int(wr.count) if world_on else 0)
        res[COLOR].bind_to_image(0, read=False, write=True)
        res[AOV_DIRECT].bind_to_image(1, read=False, write=True)
        res[AOV_EMIT].bind_to_image(2, read=False, write=True)
        res[WORLD_SPEC].bind_to_image(3, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


@register
class Direct(Technique):
    id = "DIRECT"
    label = "Direct light"
    description = "Direct light and shadows only: the baseline every GI technique adds to"
    family = "core"
    reference = "direct"
    cost_rank = 0
    outputs = DIRECT_OUTPUTS

    def passes(self, quality):
        return [GBufferPass(quality), ShadowPass(quality), DirectLightPass(quality)]
