"""Scene analysis: which effects does this scene call for, and why not the others.

The planner (``FrameGraph.plan``) runs only passes that provide a needed effect; the
reasons here are what the render stats and ``results.json`` say about each skipped pass.
"Visible" means an instance whose world bounding box intersects the camera frustum.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .framegraph import Effect
from .scene_data import LightType, SceneData


@dataclass
class SceneAnalysis:
    needed: set = field(default_factory=set)
    reasons: dict = field(default_factory=dict)  # Effect -> why it is not needed
    facts: dict = field(default_factory=dict)  # what was found (for stats and tests)

    def as_dict(self) -> dict:
        return {
            "needed": sorted(e.value for e in self.needed),
            "not_needed": {e.value: r for e, r in self.reasons.items()},
            "facts": self.facts,
        }


def _frustum_visible(scene: SceneData) -> list[bool]:
    """Per instance: does its world AABB touch the camera frustum (clip-space test)."""
    cam = scene.camera
    if cam is None:
        return [True] * len(scene.instances)
    vp = cam.projection.astype(np.float64) @ cam.view.astype(np.float64)
    out = []
    for inst in scene.instances:
        lo, hi = scene.meshes[inst.mesh].bounds()
        c = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        clip = c @ (vp @ inst.matrix.astype(np.float64)).T
        w = clip[:, 3:4]
        # outside if all corners are beyond the same plane
        outside = (np.all(clip[:, 0] > w[:, 0]) or np.all(clip[:, 0] < -w[:, 0]) or
                   np.all(clip[:, 1] > w[:, 0]) or np.all(clip[:, 1] < -w[:, 0]) or
                   np.all(clip[:, 2] > w[:, 0]) or np.all(clip[:, 2] < -w[:, 0]))
        out.append(not outside)
    return out


def analyse(scene: SceneData) -> SceneAnalysis:
    a = SceneAnalysis()
    visible = _frustum_visible(scene)
    mats_all = set()
    mats_vis = set()
    for inst, vis in zip(scene.instances, visible):
        ids = scene.meshes[inst.mesh].material_ids
        if inst.material_map is not None and ids.size:
            ids = np.asarray(inst.material_map)[np.clip(ids, 0, len(inst.material_map) - 1)]
        u = set(int(i) for i in np.unique(ids)) if ids.size else set()
        mats_all |= u
        if vis:
            mats_vis |= u
    def mat(i):
        return scene.materials[i] if 0 <= i < len(scene.materials) else None

    glossy_vis = sorted({mat(i).name for i in mats_vis if mat(i) is not None and mat(i).is_glossy})
    emissive = sorted({mat(i).name for i in mats_all if mat(i) is not None and mat(i).is_emissive})
    world_on = float(np.max(scene.world.color)) > 0.0 if scene.world is not None else False
    lights_on = [L for L in scene.lights if float(np.max(L.color)) > 0.0]
    shadowing = [L for L in lights_on if L.cast_shadow]
    has_geometry = any(scene.meshes[i.mesh].triangle_count for i in scene.instances)
    any_light = bool(lights_on) or bool(emissive) or world_on
    a.facts = {
        "instances": len(scene.instances),
        "visible_instances": int(sum(visible)),
        "triangles": scene.triangle_count,
        "lights": {t.name: sum(1 for L in lights_on if L.type == t) for t in LightType},
        "emissive_materials": emissive,
        "glossy_materials_in_view": glossy_vis,
        "world_light": world_on,
        "sun": any(L.type == LightType.SUN for L in lights_on),
    }

    def need(effect, cond, reason):
        if cond:
            a.needed.add(effect)
        else:
            a.reasons[effect] = reason

    need(Effect.DIRECT, bool(lights_on) and has_geometry,
         "no light with non-zero strength" if has_geometry else "no geometry")
    need(Effect.SHADOWS, (bool(shadowing) or bool(emissive)) and has_geometry, "no light casts shadows")
    need(Effect.EMISSION, bool(emissive), "no emissive material")
    need(Effect.ENVIRONMENT, world_on, "world is black")
    need(Effect.INDIRECT_DIFFUSE, any_light and has_geometry,
         "nothing emits light" if has_geometry else "no geometry")
    need(Effect.INDIRECT_SPECULAR, bool(glossy_vis) and any_light,
         "no glossy surface in view" if any_light else "nothing emits light")
    need(Effect.AO, any_light and has_geometry, "nothing to occlude" if not has_geometry else "nothing emits light")
    return a
