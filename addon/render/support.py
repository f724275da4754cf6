"""What GI Preview renders of a scene, exactly or not: the scene support report.

``scene_support(scene) -> dict`` classifies every material, the world and every light the
exporter saw as ``exact``, ``approximated`` (with how) or ``unsupported`` (with the node or
setting named), from what the exporter recorded (``Material.exact`` and its warnings,
``World``, the export's warnings about lights). The panel shows its ``summary`` line,
``gi_compare.py`` prints it before rendering and writes it into results.json as
``scene_support``.
"""
from __future__ import annotations

from .scene_data import SceneData

EXACT, APPROX, UNSUPPORTED = "exact", "approximated", "unsupported"
_FALLBACK = "using the viewport colour"


def _material_entry(m) -> dict:
    if m.exact:
        return {"status": EXACT, "detail": ""}
    detail = "; ".join(m.warnings) or "not understood exactly"
    status = UNSUPPORTED if any(_FALLBACK in w for w in m.warnings) else APPROX
    own = getattr(m, "support", "")
    if own:
        status, _, how = own.partition(":")
        detail = how.strip() or detail
    return {"status": status.strip(), "detail": detail}


def _world_entry(scene: SceneData) -> dict:
    w = scene.world
    if not w.exact:
        status = UNSUPPORTED if any(_FALLBACK in x for x in w.warnings) else APPROX
        return {"status": status, "detail": "; ".join(w.warnings)}
    if w.map is None:
        return {"status": EXACT, "detail": "uniform colour"}
    h, wd = w.map.shape[:2]
    how = f"evaluated by Cycles into a {wd}x{h} map"
    if w.sun_light:
        return {"status": APPROX, "detail": f"{how}; its sun is the sun light '{w.sun_light}' "
                                            "(a uniform disc of the same direction, size and irradiance)"}
    return {"status": EXACT, "detail": how}


def scene_support(scene: SceneData) -> dict:
    mats = {}
    for m in scene.materials:
        mats[m.name] = _material_entry(m)
    lights = {L.name: {"status": EXACT, "detail": ""} for L in scene.lights}
    for msg in scene.warnings:
        if msg.startswith("Light '"):
            name = msg[len("Light '"):].split("'", 1)[0]
            skipped = "skipped" in msg
            lights[name] = {"status": UNSUPPORTED if skipped else APPROX, "detail": msg}
    world = _world_entry(scene)
    n = len(mats)
    exact = sum(1 for e in mats.values() if e["status"] == EXACT)
    parts = [f"{exact} of {n} materials exact"]
    for status in (APPROX, UNSUPPORTED):
        names = [k for k, e in mats.items() if e["status"] == status]
        if names:
            shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
            parts.append(f"{len(names)} {status}: {shown}")
    parts.append(f"world {world['status']}")
    nl = len(lights)
    le = sum(1 for e in lights.values() if e["status"] == EXACT)
    if nl:
        parts.append(f"{le} of {nl} lights exact")
    return {"summary": "Scene: " + "; ".join(parts), "materials": mats, "world": world, "lights": lights,
            "counts": {"materials": n, "materials_exact": exact, "lights": nl, "lights_exact": le}}
