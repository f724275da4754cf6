"""DIRECT: direct lighting and shadows only (no indirect light).

Passes: ``gbuffer`` (raster) → ``shadows`` (shadow atlas) → ``direct_light`` (compute).
Every light type in Cycles' units; diffuse terms are exact (cosine law, polygon
irradiance), glossy terms are Monte Carlo with MIS and converge over ``samples`` frames,
as do soft shadows (the shadow views move over the light's surface each frame, or, where
that costs more than rays, shadow rays to points on the light: passes/shadows.py) and
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
| rt_shadow_rays | 0–8 | shadow rays per pixel per frame for lights without a shadow map |
| ray_cost_texels | 0–1e6 | lights with size are ray-traced where their moving maps cost more texels than this x the rays |

Quality ladder (shadow px, glossy samples, world directions, shadow rays): 0 = 256, 1, 4, 4;
1 = 512, 2, 8, 4; 2 = 1024, 4, 16, 8; 3 = 2048, 8, 24, 8.
Compared with: Cycles with all bounces off (direct light only).
"""
from __future__ import annotations

import numpy as np

from ..barriers import SHADER_STORAGE_BARRIER_BIT
from ..framegraph import Effect, Param, Pass, Res
from ..gpu_scene import set_uniform
from ..passes.gbuffer import ALBEDO, EMISSION, GEONORMAL, NORMAL, POSITION, GBufferPass
from ..passes.light_cull import (BIND_TILE_LIGHTS, LIGHT_CULL, TILE, TILE_LIGHTS, LightCuller,
                                  LightCullPass)
from ..passes.shadows import ATLAS, SHADOW_SELECTION, VIEWS, WORLD_RANGE, ShadowPass, world_light_range
from ..scene_data import SceneError
from . import Technique, register

COLOR, AOV_DIRECT, AOV_EMIT, WORLD_SPEC = "color", "aov.direct", "aov.emit", "aov.world_spec"
# DIRECT's render passes; every technique built on DIRECT's passes returns them too
DIRECT_OUTPUTS = {"GI_Direct": AOV_DIRECT, "Emit": AOV_EMIT}


class DirectLightPass(Pass):
    name = "direct_light"
    provides = frozenset({Effect.DIRECT, Effect.EMISSION, Effect.ENVIRONMENT})
    always = True  # produces the colour every technique builds on
    reads = (ALBEDO, NORMAL, POSITION, GEONORMAL, EMISSION)
    # the shadow pass runs only if something casts shadows; graphs without the light_cull
    # pass (techniques built on DIRECT's passes) get their tile lists culled here, inline
    optional_reads = (ATLAS, VIEWS, WORLD_RANGE, SHADOW_SELECTION, TILE_LIGHTS, LIGHT_CULL)
    writes = (COLOR, AOV_DIRECT, AOV_EMIT, WORLD_SPEC)
    declared = tuple(Res(n, check="radiance") for n in writes)
    history_resets = frozenset()
    params = (
        Param("glossy_samples", 2, 1, 16, "light+BSDF sample pairs per light per pixel per frame"),
        Param("mesh_exact_max", 64, 0, 256, "emissive meshes up to this many triangles are integrated exactly"),
        Param("rt_shadow_rays", 4, 0, 8,
              "shadow rays per pixel per frame: for each light with size left to rays by the shadow pass, and "
              "shared by the lights over the shadow-map budget (chosen by contribution)"),
        Param("far_samples", 4, 0, 8, "lights outside a tile's list: light samples per pixel per frame"),
        Param("cull_fraction", 0.05, 0.0, 1.0, "light culling when the graph has no light_cull pass (see light_cull.py)"),
    )
    quality_ladder = ({"glossy_samples": 1, "rt_shadow_rays": 4}, {"glossy_samples": 2, "rt_shadow_rays": 4},
                      {"glossy_samples": 4, "rt_shadow_rays": 8}, {"glossy_samples": 8, "rt_shadow_rays": 8})

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self._culler = None  # inline culling (graphs without the light_cull pass)
        self.notes: list[str] = []  # what this frame approximated (stats)
        self.rt_used = False

    def shadow_rays_per_pixel(self) -> int:
        """Shadow rays per pixel per frame traced for each light with size that the shadow
        pass leaves to rays (where they cost less than its maps), and shared by the lights
        over the budget."""
        return int(self["rt_shadow_rays"])

    def _cull(self, rc, frame):
        cull = rc.resources.get(LIGHT_CULL)
        if cull is not None and cull.frame is frame:
            return cull
        if self._culler is None:
            self._culler = LightCuller()
        return self._culler.run(rc, frame, float(self["cull_fraction"]))

    def execute(self, rc, frame):
        res = rc.resources
        cull = self._cull(rc, frame)
        sel = res.get(SHADOW_SELECTION)
        sel = sel if sel is not None and sel.frame is frame else None
        unmapped = list(sel.unmapped) if sel is not None else []
        far = cull.info["partial"] and int(self["far_samples"]) > 0
        notes = []
        rt = None
        if (unmapped and int(self["rt_shadow_rays"]) > 0) or far:
            try:
                rt = rc.scene.rt()  # the session's shared ray-tracing component
            except SceneError as exc:
                notes.append(f"no ray tracing ({exc}): lights without a shadow map are unshadowed, "
                             f"lights outside a tile's range are left out")
        if rt is not None:
            prog = rc.programs.compute("direct/direct.comp", {**rt.defines, "DIRECT_RT": 1})
            rt.bind(prog)
        else:
            prog = rc.programs.compute("direct/direct.comp")
            rc.scene.bind(prog)
        self.rt_used = rt is not None
        n = int(rc.scene.light_count)
        if sel is not None and (sel.mapped or unmapped):
            how = (f"ray-traced shadows ({int(self['rt_shadow_rays'])} rays/pixel/frame, lights chosen by "
                   f"contribution)" if rt is not None and int(self["rt_shadow_rays"]) > 0 else "no shadows")
            # lights with size left to rays because rays cost less (sel.traced) approximate
            # nothing: only the lights over the budget are worth a note
            over = len(unmapped) - len(sel.traced)
            if over > 0:
                notes.append(f"{len(sel.mapped)} of {len(sel.mapped) + over} shadow-casting lights have "
                             f"shadow maps (budget {sel.budget}); the other {over}: {how}")
        if cull.info["partial"]:
            how = (f"estimated with {int(self['far_samples'])} light sample(s)/pixel/frame (unbiased)"
                   if rt is not None and int(self["far_samples"]) > 0 else "left out (biased dark)")
            notes.append(f"{n} lights culled per {TILE}px tile beyond {cull.info['l_min']:.3g} W/m2/sr "
                         f"(cull_fraction {cull.info.get('fraction', 0):g}); lights outside a tile's range {how}")
        self.notes = notes
        cull.tile_lights.bind_to_storage_buffer(BIND_TILE_LIGHTS)
        set_uniform(prog, "u_tile_capacity", int(cull.capacity))
        set_uniform(prog, "u_tiles_x", int(cull.tiles_x))
        set_uniform(prog, "u_tile_size", TILE)
        set_uniform(prog, "u_rt_shadow_rays", int(self["rt_shadow_rays"]) if rt is not None else 0)
        set_uniform(prog, "u_far_samples", int(self["far_samples"]) if rt is not None else 0)
        for unit, (name, uni) in enumerate(((ALBEDO, "u_gb_albedo"), (NORMAL, "u_gb_normal"),
                                            (POSITION, "u_gb_position"), (GEONORMAL, "u_gb_geonormal")), start=1):
            res[name].use(unit)
            set_uniform(prog, uni, unit)
        res[EMISSION].use(6)
        set_uniform(prog, "u_gb_emission", 6)
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
        first, count = world_light_range(rc)
        set_uniform(prog, "u_world_first", first)
        set_uniform(prog, "u_world_count", count)
        res[COLOR].bind_to_image(0, read=False, write=True)
        res[AOV_DIRECT].bind_to_image(1, read=False, write=True)
        res[AOV_EMIT].bind_to_image(2, read=False, write=True)
        res[WORLD_SPEC].bind_to_image(3, read=False, write=True)
        if rc.resources.get(LIGHT_CULL) is not cull:
            # culled inline by this pass: its SSBO stores before this dispatch reads them
            # (the graph places the barrier after the light_cull pass)
            rc.ctx.memory_barrier(SHADER_STORAGE_BARRIER_BIT)
        rc.dispatch(prog, *rc.groups(8))

    def release(self):
        if self._culler is not None:
            self._culler.release()
            self._culler = None


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
        return [GBufferPass(quality), LightCullPass(quality), ShadowPass(quality), DirectLightPass(quality)]
