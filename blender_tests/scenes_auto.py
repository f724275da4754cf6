"""Scenes for AUTO's acceptance, built in code as an artist would build them (not tuned to
AUTO's table; no AUTO setting was chosen while looking at them).

* ``metal_corridor``: a corridor (2.4 x 8 x 2.6 m) whose side walls are brushed metal
  (Principled metallic 1, roughness 0.25, steel and copper), with a mirror floor (metallic 1,
  roughness 0.02), a white diffuse ceiling and a diffuse end wall, a diffuse crate and a
  chrome ball; lit by two ceiling lamps (point, 10 cm radius). The camera stands at one end,
  looking down the corridor.
* ``around_corner``: a closed flat of two rooms (6 x 4 x 2.8 m in all) joined by a doorway
  (0.9 x 2.1 m) in a 12 cm wall. The side room holds every light (a ceiling area lamp and a
  table lamp); the camera's room has none and looks at a sofa, a shelf and the doorway
  at an angle: what it sees is lit through the door and by bounces (mostly indirect).
* ``party_room``: a closed room (7 x 7 x 3 m) lit only by 144 small coloured lights: a string
  of 96 small sphere lights (point, 3 cm radius) along the walls under the ceiling, 40
  small point lights hanging over a table, 8 small square area lamps on the ceiling;
  light-grey walls, a wooden floor, a table and a glossy vase.

Used by ``scripts/bench_auto.py`` and ``test_auto.py``.
"""
from __future__ import annotations

import colorsys
import math

import bpy
import numpy as np

from _helpers import build_named_scene

SCENES = ("metal_corridor", "around_corner", "party_room")


def _metal_corridor(b, mp, mw):
    steel = mp(b.n("steel"), (0.75, 0.76, 0.78), 0.25, metallic=1.0)
    copper = mp(b.n("copper"), (0.95, 0.64, 0.54), 0.3, metallic=1.0)
    mirror = mp(b.n("mirror"), (0.92, 0.92, 0.92), 0.02, metallic=1.0)
    ceiling = mp(b.n("ceiling"), (0.8, 0.8, 0.8), 0.9, specular=0.3)
    end = mp(b.n("end"), (0.2, 0.35, 0.6), 0.7)
    crate = mp(b.n("crate"), (0.7, 0.45, 0.2), 0.6)
    chrome = mp(b.n("chrome"), (0.95, 0.95, 0.95), 0.05, metallic=1.0)
    b.room("corridor", (-1.2, -4.0, 0.0), (1.2, 4.0, 2.6),
           {"floor": mirror, "ceiling": ceiling, "-x": steel, "+x": copper, "-y": end, "+y": end})
    b.box("crate", (0.7, 0.7, 0.7), crate, location=(0.45, 1.6, 0.35), rotation=(0, 0, math.radians(20)))
    b.sphere("ball", 0.3, chrome, location=(-0.5, 0.4, 0.3), segments=24, rings=12)
    b.light("lamp_near", "POINT", (0.0, -1.2, 2.35), energy=120.0, shadow_soft_size=0.1, color=(1.0, 0.92, 0.8))
    b.light("lamp_far", "POINT", (0.0, 2.4, 2.35), energy=120.0, shadow_soft_size=0.1, color=(0.85, 0.9, 1.0))
    b.camera((0.3, -3.8, 1.5), (0.0, 2.0, 0.9), lens=22.0)
    b.scene.world = mw(b.n("world"), (0.0, 0.0, 0.0), 0.0)


def _around_corner(b, mp, mw):
    plaster = mp(b.n("plaster"), (0.82, 0.8, 0.76), 0.9, specular=0.3)
    floor = mp(b.n("floor"), (0.45, 0.3, 0.18), 0.5)
    sofa = mp(b.n("sofa"), (0.2, 0.3, 0.55), 0.9, specular=0.2)
    shelf = mp(b.n("shelf"), (0.55, 0.4, 0.25), 0.6)
    rug = mp(b.n("rug"), (0.6, 0.15, 0.1), 1.0, specular=0.1)
    # the flat: x in [-3, 3], y in [-2, 2], z in [0, 2.8]; the side room is x < 0
    walls = {k: plaster for k in ("ceiling", "-x", "+x", "-y", "+y")}
    walls["floor"] = floor
    b.room("flat", (-3.0, -2.0, 0.0), (3.0, 2.0, 2.8), walls)
    # the wall at x = 0 (12 cm) with a doorway y in [0.6, 1.5], z in [0, 2.1]
    b.box("wall_a", (0.12, 2.6, 2.8), plaster, location=(0.0, -0.7, 1.4))
    b.box("wall_b", (0.12, 0.5, 2.8), plaster, location=(0.0, 1.75, 1.4))
    b.box("lintel", (0.12, 0.9, 0.7), plaster, location=(0.0, 1.05, 2.45))
    # the side room: a ceiling area lamp and a table lamp
    area = b.light("ceiling_lamp", "AREA", (-1.6, 0.3, 2.75), energy=500.0, color=(1.0, 0.95, 0.85))
    area.data.size = 0.6
    b.box("side_table", (0.5, 0.5, 0.6), shelf, location=(-2.5, 1.4, 0.3))
    b.light("table_lamp", "POINT", (-2.5, 1.4, 0.9), energy=60.0, shadow_soft_size=0.1, color=(1.0, 0.8, 0.55))
    # the camera's room: sofa, shelf, rug
    b.box("sofa_seat", (0.9, 2.0, 0.45), sofa, location=(2.45, -0.6, 0.225))
    b.box("sofa_back", (0.2, 2.0, 0.5), sofa, location=(2.85, -0.6, 0.7))
    b.box("shelf", (1.2, 0.35, 1.8), shelf, location=(1.2, -1.8, 0.9))
    b.quad("rug", [(0.8, -1.2, 0.005), (2.0, -1.2, 0.005), (2.0, 0.6, 0.005), (0.8, 0.6, 0.005)], rug)
    b.camera((2.8, 1.8, 1.6), (0.2, -0.3, 0.9), lens=20.0)
    b.scene.world = mw(b.n("world"), (0.0, 0.0, 0.0), 0.0)


def _party_room(b, mp, mw):
    walls = mp(b.n("walls"), (0.7, 0.7, 0.68), 0.8, specular=0.3)
    wood = mp(b.n("wood"), (0.5, 0.33, 0.2), 0.4)
    table = mp(b.n("table"), (0.35, 0.22, 0.14), 0.35)
    vase = mp(b.n("vase"), (0.1, 0.5, 0.45), 0.1)
    mats = {k: walls for k in ("ceiling", "-x", "+x", "-y", "+y")}
    mats["floor"] = wood
    b.room("room", (-3.5, -3.5, 0.0), (3.5, 3.5, 3.0), mats)
    b.box("table", (2.0, 1.0, 0.75), table, location=(0.0, 0.5, 0.375))
    b.sphere("vase", 0.2, vase, location=(0.3, 0.6, 0.95), segments=20, rings=10)
    b.box("bench", (1.6, 0.4, 0.45), wood, location=(0.0, -0.5, 0.225))
    rng = np.random.default_rng(11)
    # a string of sphere lights along the walls, 15 cm under the ceiling
    n_string = 96
    for i in range(n_string):
        t = 4.0 * i / n_string  # around the four walls
        side, f = int(t), t - int(t)
        x, y = {0: (-3.3 + 6.6 * f, -3.3), 1: (3.3, -3.3 + 6.6 * f), 2: (3.3 - 6.6 * f, 3.3),
                3: (-3.3, 3.3 - 6.6 * f)}[side]
        z = 2.85 - 0.12 * abs(math.sin(math.pi * 4 * f))
        rgb = colorsys.hsv_to_rgb(float(rng.random()), 0.8, 1.0)
        b.light(f"bulb_{i:03d}", "POINT", (x, y, z), energy=1.5, color=rgb, shadow_soft_size=0.03)
    # small lights hanging over the table
    for i in range(40):
        x, y = -1.2 + 2.4 * rng.random(), -0.2 + 1.4 * rng.random()
        z = 1.6 + 0.9 * rng.random()
        rgb = colorsys.hsv_to_rgb(float(rng.random()), 0.6, 1.0)
        b.light(f"hang_{i:02d}", "POINT", (x, y, z), energy=0.8, color=rgb, shadow_soft_size=0.02)
    # small square area lamps on the ceiling
    for i in range(8):
        ang = 2.0 * math.pi * i / 8
        ob = b.light(f"panel_{i}", "AREA", (2.2 * math.cos(ang), 2.2 * math.sin(ang), 2.98), energy=8.0,
                     color=colorsys.hsv_to_rgb(i / 8.0, 0.5, 1.0))
        ob.data.size = 0.15
    b.camera((2.6, -3.2, 1.7), (-0.3, 0.6, 0.8), lens=20.0)
    b.scene.world = mw(b.n("world"), (0.0, 0.0, 0.0), 0.0)


_BUILD = {"metal_corridor": _metal_corridor, "around_corner": _around_corner, "party_room": _party_room}


def build(name: str, resolution: int = 32) -> bpy.types.Scene:
    """A new scene ``auto_<name>`` at ``resolution``² (the caller removes it)."""
    return build_named_scene(_BUILD, name, resolution, "auto", "AUTO scene")
