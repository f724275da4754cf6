"""Long viewport runs keep their GL objects and memory bounded (scripts/check_growth.py).

A technique that created a texture, buffer or framebuffer per frame, or per camera move or
scene edit, without releasing it would grow without end in the viewport. Criterion: once every
kind of edit has happened once, the number of live moderngl objects never exceeds its count
at that frame while the camera orbits every frame and the light edits and object moves
repeat. Techniques with history, probes or reservoirs run here at 16 px for 48 frames;
VXGI and LPV (about 1 s per frame here) and every other technique run for 200 frames in the
script (docs/results/growth.md). A mutant that leaks one texture per frame is caught.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import bpy
import pytest

from gi_preview.blender import demo_scenes, export, reference
from gi_preview.render import session

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "check_growth.py"
spec = importlib.util.spec_from_file_location("check_growth", SCRIPT)
growth = importlib.util.module_from_spec(spec)
spec.loader.exec_module(growth)

# the light changes every 10 frames and a box moves every 15; from frame 32 on (after the
# first edit of each kind, whose one-time allocations are not growth) nothing may grow
FRAMES, SETTLE, LIGHT_EVERY, MOVE_EVERY = 48, 32, 10, 15


@pytest.fixture
def census():
    c = growth.GLCensus().install()
    yield c
    c.remove()


def _run(tech, census):
    sc = demo_scenes.build_demo("cornell", resolution=16)
    try:
        return growth.run_technique(tech, sc, FRAMES, 16, SETTLE, census, session=session, export=export,
                                    reference=reference, light_every=LIGHT_EVERY, move_every=MOVE_EVERY)
    finally:
        bpy.data.scenes.remove(sc)


@pytest.mark.parametrize("tech", ["DIRECT", "SVGF", "RTXGI", "RESTIR_GI", "TAA"])
def test_live_gl_objects_stay_bounded(tech, census):
    r = _run(tech, census)
    assert r["live_objects_at_settle"] > 0  # the census sees the session's objects
    assert r["live_objects_max_after"] <= r["live_objects_at_settle"], (
        tech, r["counts"][SETTLE:], census.by_kind())


def test_a_leak_of_one_texture_per_frame_is_caught(census, monkeypatch):
    from gi_preview.render import framegraph
    real = framegraph.FrameGraph.execute
    leaked = []

    def leaky(self, rc, frame, **kw):
        leaked.append(rc.ctx.texture((1, 1), 4))  # never released
        return real(self, rc, frame, **kw)
    monkeypatch.setattr(framegraph.FrameGraph, "execute", leaky)
    r = _run("DIRECT", census)
    assert r["live_objects_max_after"] > r["live_objects_at_settle"]
    for t in leaked:
        t.release()
