"""Scenes for the probe family (IRRADIANCE_VOLUME, DDGI, RTXGI), built in code.

* ``white_room``: a closed room (4 x 4 x 3 m, every wall white diffuse, albedo 0.8, no
  specular) lit by one point lamp under the ceiling; the camera inside. Many bounces carry
  most of the light (the indirect is several times the direct): the energy check.
* ``furnace``: a white-furnace-like case: a diffuse sphere (albedo 0.8) on a diffuse floor
  (albedo 0.8) under a uniform white world (radiance 1), no lamp. What the probes add is the
  light bounced between the sphere and the floor; the rest is DIRECT's world light.
* ``furnace_room``: the closed white furnace: a closed room (4 x 4 x 3 m) whose every wall is
  diffuse with albedo 0.8 *and* emits radiance 1 (white), no lamp. The exact answer is the
  same radiance everywhere, Le / (1 - albedo) = 5 (Cycles "full" stops after its bounce limit:
  slightly less); DIRECT gives the emission seen (1) and one bounce of it (0.8), the probes
  must carry the rest (3.2: 64 % of the image).
* ``probe_in_box``: a room (4 x 4 x 3 m, one lamp) with a solid 1.6 m cube in the middle
  whose inside holds probes of every automatic grid the tests use (stability: a probe inside
  geometry; RTXGI relocates it or makes it inactive).
* ``glossy_room``: a room open towards the camera with a glossy metal floor (roughness 0.2),
  coloured diffuse walls and a wall behind the camera (off screen), one lamp: SSR finds the
  far walls on screen; the reflections of the walls behind the camera and of what leaves the
  screen need the miss fallback (RTXGI's probe glossy light, technique RTXGI_SSR).
* ``two_rooms``: two rooms side by side in one closed shell, split by a thin wall (2 cm,
  a closed box, no door); a bright lamp in room A, a dim one in room B; the camera in room B
  looks at the wall. Cycles shows room B lit by its dim lamp only: anything more is light
  leaked through the wall by probe interpolation.
* ``doorway``: the same shell split by a 10 cm wall with a door (1 m wide, 2 m high); one
  lamp in room A, none in room B, where the camera looks at the door. Room B gets the lamp's
  light only through the door (a patch on its floor) and what bounces from there: transport
  around a corner.
* ``behind_camera``: a closed room (4 x 6 x 3 m, white, one red wall) whose only light is an
  area lamp behind the camera facing away from it, onto the wall behind the camera: nothing
  the camera sees is lit directly or shows the lit wall. The screen-space limit (the light
  comes from off screen): SSDO finds no bounce; world-space rays (probes, screen probes with
  their world cache) must.

Used by ``test_probes.py`` and ``scripts/bench_probes.py``.
"""
from __future__ import annotations

import math

import bpy

from _helpers import build_named_scene

SCENES = ("white_room", "furnace", "furnace_room", "two_rooms", "probe_in_box", "glossy_room", "doorway",
          "behind_camera")


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


def _furnace_room(b, mp, mw):
    glow = mp(b.n("glow"), (0.8, 0.8, 0.8), 1.0, specular=0.0, emission=(1.0, 1.0, 1.0), emission_strength=1.0)
    b.room("room", (-2, -2, 0), (2, 2, 3), {k: glow for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.camera((0, -1.9, 1.5), (0, 1.0, 1.0), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _probe_in_box(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 1.0, specular=0.0)
    b.room("room", (-2, -2, 0), (2, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.box("block", (1.6, 1.6, 1.6), red, location=(0.0, 0.3, 1.0))
    b.light("lamp", "POINT", (1.2, -1.0, 2.6), energy=300.0, shadow_soft_size=0.0)
    b.camera((0, -1.9, 1.5), (0, 1.0, 1.0), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _glossy_room(b, mp, mw):
    floor = mp(b.n("floor"), (0.9, 0.9, 0.9), 0.2, metallic=1.0)
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    red = mp(b.n("red"), (0.75, 0.1, 0.08), 1.0, specular=0.0)
    green = mp(b.n("green"), (0.12, 0.6, 0.15), 1.0, specular=0.0)
    blue = mp(b.n("blue"), (0.1, 0.2, 0.75), 1.0, specular=0.0)
    b.room("room", (-1.5, -3, 0), (1.5, 3, 2.5),
           {"floor": floor, "ceiling": white, "-x": red, "+x": green, "+y": white, "-y": blue})
    b.box("block", (0.6, 0.6, 0.9), white, location=(0.4, 1.2, 0.45))
    b.light("lamp", "POINT", (0.0, 0.5, 2.2), energy=300.0, shadow_soft_size=0.1)
    b.camera((0, -2.6, 1.6), (0, 1.5, 0.4), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _two_rooms(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    # shell: x in [-4, 4], y in [-2, 2], z in [0, 3]; thin wall at x = 0
    b.room("shell", (-4, -2, 0), (4, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.box("wall", (0.02, 4.0, 3.0), white, location=(0.0, 0.0, 1.5))
    b.light("lamp_a", "POINT", (-1.0, 0.0, 1.5), energy=2000.0, shadow_soft_size=0.0)
    b.light("lamp_b", "POINT", (3.0, -1.0, 2.5), energy=20.0, shadow_soft_size=0.0)
    b.camera((3.8, -1.8, 1.6), (0.0, 0.6, 1.2), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _doorway(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.room("shell", (-4, -2, 0), (4, 2, 3), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    # the dividing wall at x = 0, 10 cm thick, with a door y in [-0.5, 0.5], z in [0, 2]
    b.box("wall_s", (0.1, 1.5, 3.0), white, location=(0.0, -1.25, 1.5))
    b.box("wall_n", (0.1, 1.5, 3.0), white, location=(0.0, 1.25, 1.5))
    b.box("lintel", (0.1, 1.0, 1.0), white, location=(0.0, 0.0, 2.5))
    b.light("lamp_a", "POINT", (-2.0, 0.6, 2.2), energy=1000.0, shadow_soft_size=0.0)
    b.camera((3.8, -1.8, 1.6), (0.0, 0.3, 1.0), lens=24.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _behind_camera(b, mp, mw):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    red = mp(b.n("red"), (0.7, 0.1, 0.08), 1.0, specular=0.0)
    b.room("room", (-2, -3, 0), (2, 3, 3), {**{k: white for k in ("floor", "ceiling", "-x", "+y")}, "+x": red,
                                            "-y": white})
    b.box("block", (0.8, 0.8, 0.8), white, location=(0.6, 1.6, 0.4))
    # an area light behind the camera facing away from it: it lights the wall behind the camera
    # (never on screen); everything the camera sees is lit by that wall's bounce
    b.light("lamp", "AREA", (0.0, -1.8, 1.8), rotation=(-math.pi / 2, 0.0, 0.0), energy=400.0, size=1.0)
    b.camera((0.0, -1.2, 1.5), (0.0, 3.0, 1.0), lens=28.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


_BUILD = {"white_room": _white_room, "furnace": _furnace, "furnace_room": _furnace_room, "two_rooms": _two_rooms,
          "probe_in_box": _probe_in_box, "glossy_room": _glossy_room, "doorway": _doorway,
          "behind_camera": _behind_camera}


def build(name: str, resolution: int = 48) -> bpy.types.Scene:
    """A new scene ``probes_<name>`` at ``resolution``² (the caller removes it)."""
    return build_named_scene(_BUILD, name, resolution, "probes", "probe scene")
