"""AUTO: one graph holding the cheapest passes that can cover every effect, planned per scene.

The graph is DIRECT's passes, then SSDO's (ambient occlusion, one diffuse bounce from
on-screen senders), then SSR's (glossy reflections), merged by pass name (the
G-buffer, shadow and direct-light passes are shared). The planner runs only the passes
whose effects the scene calls for: a scene with no glossy surface in view skips the SSR
passes ("no glossy surface in view"), an unlit scene skips the SSDO passes, a scene whose
lights cast no shadow skips the shadow pass — each reported with its reason. DIRECT lights
with the world (shadowed); SSDO adds one diffuse bounce; SSR replaces DIRECT's world
reflection by what the reflected rays find on screen.

Quality: the same level for every member technique. Compared with: Cycles "one_bounce"
(and "full"). Screen-space limits apply (see SSDO.md, SSR.md).
"""
from __future__ import annotations

from . import Technique, get, register

MEMBERS = ("DIRECT", "SSDO", "SSR")


def merge_passes(groups: list[list]) -> list:
    """Concatenate pass lists, keeping the first pass of each name (shared passes)."""
    out, seen = [], set()
    for passes in groups:
        for p in passes:
            if p.name not in seen:
                seen.add(p.name)
                out.append(p)
    return out


@register
class Auto(Technique):
    id = "AUTO"
    label = "Auto"
    description = ("The planner runs the cheapest passes that cover what the scene needs: direct light, "
                   "SSDO for ambient light and one diffuse bounce, SSR for glossy reflections")
    family = "auto"
    reference = "one_bounce"
    cost_rank = 50

    @classmethod
    def _members(cls):
        return [get(t) for t in MEMBERS if t != cls.id]

    @property
    def outputs(self):  # noqa: D401 - union of the members' AOVs
        out = {}
        for m in self._members():
            out.update(m.outputs)
        return out

    def passes(self, quality):
        groups = [m().passes(quality) for m in self._members()]
        return merge_passes(groups)
