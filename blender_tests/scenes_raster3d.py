"""Reproduction scenes for the 3D-raster family (RSM, LPV, VXGI), built in code.

* ``two_rooms``: two closed 2 x 2 x 2 m rooms side by side (x in [-2, 0] and [0, 2]) that
  share one wall of zero thickness at x = 0 (thinner than any RSM texel, LPV cell or voxel).
  A point light (200 W, warm) hangs in the left room near the shared wall; the camera
  stands in the right room looking at the shared wall. In Cycles the right room is black:
  whatever a technique shows there is light leaking through the wall. ``lit_camera``
  moves the camera into the left room (the lit level the leak is compared with).

* ``furnace_box``: a closed 2 m box (all six walls white, 0.8), a point light (so that the
  planner keeps the injected-light passes) and a camera inside looking at a corner region:
  VXGI's energy audit (every voxel side shows one radiance; the cones must return E = pi L).

``build(name, resolution)`` returns a new ``bpy`` scene (the caller removes it).
"""
from __future__ import annotations

import math

import bpy

SCENES = ("two_rooms", "furnace_box")


def _two_rooms(b, mp, mw, lit_camera=False):
    white = mp(b.n("white"), (0.75, 0.75, 0.75), 1.0, specular=0.0)
    warm = mp(b.n("warm"), (0.8, 0.55, 0.35), 1.0, specular=0.0)
    b.room("left", (-2, -1, 0), (0, 1, 2), {"floor": white, "ceiling": white, "-x": warm, "-y": white,
                                            "+y": white}, skip=("+x",))
    b.room("right", (0, -1, 0), (2, 1, 2), {"floor": white, "ceiling": white, "+x": white, "-y": white,
                                           "+y": white}, skip=("-x",))
    # the shared wall: one quad, zero thickness, both sides white
    b.quad("shared_wall", [(0, -1, 0), (0, 1, 0), (0, 1, 2), (0, -1, 2)], white)
    b.light("lamp", "POINT", (-0.4, 0.0, 1.2), energy=200.0, shadow_soft_size=0.0, color=(1.0, 0.9, 0.75))
    if lit_camera:
        b.camera((-1.9, -0.9, 1.7), (-0.3, 0.3, 0.6), lens=16.0)
    else:
        b.camera((1.9, 0.0, 1.0), (0.0, 0.0, 1.0), lens=16.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def _furnace_box(b, mp, mw, lit_camera=False):
    white = mp(b.n("white"), (0.8, 0.8, 0.8), 1.0, specular=0.0)
    b.room("box", (-1, -1, 0), (1, 1, 2), {k: white for k in ("floor", "ceiling", "-x", "+x", "-y", "+y")})
    b.light("lamp", "POINT", (0, 0, 1.5), energy=10.0)
    b.camera((0.0, -0.9, 1.0), (0.0, 0.0, 1.0), lens=18.0)
    b.scene.world = mw(b.n("world"), (0, 0, 0), 0.0)


def build(name: str, resolution: int = 48, *, lit_camera: bool = False):
    from gi_preview.blender import demo_scenes

    if name not in SCENES:
        raise ValueError(f"unknown raster3d scene {name!r}; choose one of {', '.join(SCENES)}")
    sc = bpy.data.scenes.new(f"raster3d_{name}{'_lit' if lit_camera else ''}")
    r = sc.render
    r.resolution_x = r.resolution_y = int(resolution)
    r.resolution_percentage = 100
    sc.frame_current = 1
    b = demo_scenes._Builder(sc, f"r3d_{name}{'_lit' if lit_camera else ''}")
    {"two_rooms": _two_rooms, "furnace_box": _furnace_box}[name](
        b, demo_scenes.make_principled, demo_scenes.make_world, lit_camera=lit_camera)
    return sc


def move_light_and_camera(sc, k: int) -> None:
    """Frame ``k`` of the stability tests' motion: the scene's first light and its camera
    move a little every frame (test_raster3d and test_vxgi flicker tests)."""
    light = next(o for o in sc.objects if o.type == "LIGHT")
    cam = sc.camera
    light.location.x = -0.3 + 0.12 * k
    light.location.y = 0.1 * math.sin(k)
    cam.location.x = 0.05 * k
    cam.location.z = 1.0 + 0.02 * k


__all__ = ["SCENES", "build", "move_light_and_camera", "math"]
