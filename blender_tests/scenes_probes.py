"""Scenes for the probe family (issue 12: IRRADIANCE_VOLUME, DDGI, RTXGI), built in code.

* ``white_room``: a closed room (4 x 4 x 3 m, every wall white diffuse, albedo 0.8, no
  specular) lit by one point lamp under the ceiling; the camera inside. Many bounces carry
  most of the light (the indirect is several times the direct): the energy check.
* ``furnace``: a white-furnace-like case: a diffuse sphere (albedo 0.8) on a diffuse floor
  (albedo 0.8) under a uniform white world (radiance 1), no lamp. What the probes add is the
  light bounced between the sphere and the floor; the rest is DIRECT's world light.
* ``two_rooms``: two rooms side by side in one closed shell, split by a thin wall (2 cm,
  a closed box, no door); a bright lamp in room A, a dim one in room B; the camera in room B
  looks at the wall. Cycles shows room B lit by its dim lamp only: anything more is light
  leaked through the wall by probe interpolation.

Used by ``test_probes.py`` and ``scripts/bench_probes.py``.
"""
from __future__ import annotations

import bpy

SCENES = ("white_room", "furnace", "two_rooms")


def _helpers():
    from gi_preview.blender import demo_scenes
    return demo_scenes._Builder, demo_scenes.make_principled, demo_scenes.make_world


def _white_room(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.room("room", (-2, -2, 0), (2, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.light("lamp", "POINT", (0.5, 0.8, 2.5), energy=300.0, shadow_soft_size=0.0)
    b.camera((0, -1.9, 1.5), (0, 1.0, 1.0), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _furnace(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], white)
    b.sphere("ball", 0.8, white, location=(0, 0, 0.8), segments=24, rings=12)
    b.camera((0, -4.0, 2.0), (0, 0, 0.6), lens=35.0)
    b.scene.world = mw(b.n("world"), (1.0, 1.0, 1.0), 1.0)


def _two_rooms(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    # shell: x in [-4, 4], y in [-2, 2], z in [0, 3]; thin wall at x = 0
    b.room("shell", (-4, -2, 0), (4, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.box("wall", (0.02, 4.0, 3.0), white, location=(0.0, 0.0, 1.5))
    b.light("lamp_a", "POINT", (-1.0, 0.0, 1.5), energy=2000.0, shadow_soft_size=0.0)
    b.light("lamp_b", "POINT", (3.0, -1.0, 2.5), energy=20.0, shadow_soft_size=0.0)
    b.camera((3.8, -1.8, 1.6), (0.0, 0.6, 1.2), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


_BUILD = {"white_room": _white_room, "furnace": _furnace, "two_rooms": _two_rooms}


def build(name: str, resolution: int = 48) -> bpy.types.Scene:
    """A new scene ``probes_<name>`` at ``resolution``² (the caller removes it)."""
    if name not in _BUILD:
        raise ValueError(f"unknown probe scene {name!r}; choose one of {', '.join(SCENES)}")
    Builder, mp, mw = _helpers()
    sc = bpy.data.scenes.new(f"probes_{name}")
    sc.render.resolution_x = sc.render.resolution_y = int(resolution)
    sc.render.resolution_percentage = 100
    _BUILD[name](Builder(sc, f"probes_{name}"), mp, mw)
    return sc
