"""Synchronisation owned by the frame graph, checked by sync validation (sync_check).

Tiny passes written for the test, each broken in one way the validation must name (a write
of an undeclared resource, a read after an image store with the graph's barrier removed, a
framebuffer draw in a pass declared ``kind="compute"``), next to the correct version that
must run clean; then every registered technique renders a few frames at 20 px on two demo scenes with the
validation on and no finding.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.blender.export import export_scene
from gi_preview.render import barriers, session, sync_check, techniques
from gi_preview.render.framegraph import FrameGraph, FrameState, Pass, RenderContext, Res
from gi_preview.render.gl import get_gl
from gi_preview.render.shaders import ProgramCache

FILL_SRC = """#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_x;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_x)))) return;
    imageStore(o_x, p, vec4(1.0 + float(p.x), float(p.y), 0.0, 1.0));
}
"""
DOUBLE_SRC = """#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_y;
uniform sampler2D u_x;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_y)))) return;
    imageStore(o_y, p, 2.0 * texelFetch(u_x, p, 0));
}
"""


@pytest.fixture
def validating():
    sync_check.enable(True)
    sync_check.VALIDATOR.take()
    yield
    sync_check.VALIDATOR.take()
    sync_check.enable(False)


def _prog(rc, src):
    progs = rc.__dict__.setdefault("_test_programs", {})
    if src not in progs:
        progs[src] = rc.ctx.compute_shader(src)
    return progs[src]


class Fill(Pass):
    """x = (1 + px, py, 0, 1) by image store."""

    name = "fill"
    writes = ("x",)
    declared = (Res("x"),)
    always = True

    def execute(self, rc, frame):
        rc.resources["x"].bind_to_image(0, read=False, write=True)
        rc.dispatch(_prog(rc, FILL_SRC), *rc.groups(8))


class Double(Pass):
    """y = 2 x: x by texture fetch, y by image store."""

    name = "double"
    reads = ("x",)
    writes = ("y",)
    declared = (Res("y"),)
    always = True

    def execute(self, rc, frame):
        prog = _prog(rc, DOUBLE_SRC)
        rc.resources["x"].use(1)
        prog["u_x"].value = 1
        rc.resources["y"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


class Sneaky(Double):
    """Double that also stores into ``z``, which it does not declare."""

    name = "sneaky"
    writes = ("y",)

    def execute(self, rc, frame):
        super().execute(rc, frame)
        rc.resources["z"].bind_to_image(0, read=False, write=True)
        rc.dispatch(_prog(rc, FILL_SRC), *rc.groups(8))


class Other(Pass):
    name = "other"
    writes = ("z",)
    declared = (Res("z"),)
    always = True

    def execute(self, rc, frame):
        rc.resources["z"].bind_to_image(0, read=False, write=True)
        rc.dispatch(_prog(rc, FILL_SRC), *rc.groups(8))


def _raster(kind_):
    class Raster(Pass):
        """x cleared to 3 through a framebuffer."""

        name = "raster"
        kind = kind_
        writes = ("x",)
        declared = (Res("x"),)
        always = True

        def compile(self, rc):
            self.fbo = rc.ctx.framebuffer(color_attachments=[rc.resources["x"]])

        def execute(self, rc, frame):
            self.fbo.use()
            self.fbo.clear(3.0, 0.0, 0.0, 1.0)
    return Raster()


def _mixed(kind_, write_access):
    class Mixed(Pass):
        """Clears ``v`` through a framebuffer, then adds to it by image store (LPV's pattern:
        next frame's clear comes after this frame's image stores)."""

        name = "mixed"
        kind = kind_
        writes = ("v",)
        declared = (Res("v"),)
        always = True

        def compile(self, rc):
            self.fbo = rc.ctx.framebuffer(color_attachments=[rc.resources["v"]])

        def execute(self, rc, frame):
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0)
            rc.resources["v"].bind_to_image(0, read=False, write=True)
            rc.dispatch(_prog(rc, FILL_SRC), *rc.groups(8))
    m = Mixed()
    m.write_access = write_access
    return m


def _frames(passes, n=2, derive=True, size=(11, 7)):
    """Run ``passes`` for ``n`` frames; returns (sync findings, y or None)."""
    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, size)
        g = FrameGraph(passes)
        g.derive_barriers = derive
        g.plan(set())
        g.compile(rc)
        found = []
        try:
            for _ in range(n):
                try:
                    g.execute(rc, FrameState(), timers=False)
                except sync_check.SyncError as exc:
                    found.extend(str(exc).splitlines())
            y = None
            if "y" in rc.resources:
                y = np.frombuffer(rc.read_back("y"), np.float32).reshape(size[1], size[0], 4).copy()
            found.extend(sync_check.VALIDATOR.take())
        finally:
            rc.resources.release()
        return found, y
    return get_gl().call(job)


def test_correct_passes_run_clean(validating):
    found, y = _frames([Fill(), Double()])
    assert found == []
    assert np.allclose(y[..., 0], 2.0 * (1.0 + np.arange(11))[None, :])


def test_write_of_undeclared_resource_is_named(validating):
    found, _ = _frames([Fill(), Other(), Sneaky()])
    assert any("pass 'sneaky' uses 'z'" in f and "does not declare it" in f for f in found), found
    found, _ = _frames([Fill(), Other(), Double()])
    assert found == []


def test_read_after_image_store_without_barrier_is_named(validating):
    found, _ = _frames([Fill(), Double()], derive=False)
    assert any("pass 'double' accesses 'x' by texture fetch after 'fill' wrote it by image store" in f
               and "TEXTURE_FETCH" in f for f in found), found
    found, _ = _frames([Fill(), Double()], derive=True)
    assert found == []


def test_raster_pass_declared_compute_is_named(validating):
    found, _ = _frames([_raster("compute"), Double()])
    assert any("pass 'raster' writes 'x' by framebuffer draw but declares image store (kind='compute')" in f
               for f in found), found
    found, y = _frames([_raster("raster"), Double()])
    assert found == []
    assert np.allclose(y[..., 0], 6.0)


def test_mixed_pass_gets_the_framebuffer_barrier_next_frame(validating):
    # declared compute: its framebuffer clear is undeclared and next frame's clear, after this
    # frame's image stores, gets no FRAMEBUFFER barrier
    found, _ = _frames([_mixed("compute", {})], derive=True)
    assert any("pass 'mixed' writes 'v' by framebuffer draw" in f for f in found), found
    found, _ = _frames([_mixed("compute", {})], derive=False)
    assert any("pass 'mixed' accesses 'v' by framebuffer draw after 'mixed' wrote it by image store" in f
               for f in found), found
    found, _ = _frames([_mixed("mixed", {"v": ("framebuffer", "image")})], n=3)
    assert found == []


def test_private_object_across_frames_is_followed(validating):
    """A pass-owned texture (no resource name) cleared through a framebuffer after the last
    frame's image stores: reported until the texture is declared, then the graph orders it."""
    class Private(Pass):
        name = "private"
        writes = ("y",)
        declared = (Res("y"),)
        always = True

        def compile(self, rc):
            self.tex = rc.ctx.texture(rc.size, 4, dtype="f4")
            self.fbo = rc.ctx.framebuffer(color_attachments=[self.tex])

        def execute(self, rc, frame):
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0)
            self.tex.bind_to_image(0, read=False, write=True)
            rc.dispatch(_prog(rc, FILL_SRC), *rc.groups(8))
            rc.ctx.memory_barrier(barriers.TEXTURE_FETCH_BARRIER_BIT)  # in-pass: the copy fetches it
            prog = _prog(rc, DOUBLE_SRC)
            self.tex.use(1)
            prog["u_x"].value = 1
            rc.resources["y"].bind_to_image(0, read=False, write=True)
            rc.dispatch(prog, *rc.groups(8))

    class Declared(Private):
        kind = "mixed"
        writes = ("y", "private.tex")
        declared = (Res("y"), Res("private.tex", managed=False))
        write_access = {"y": "image", "private.tex": ("framebuffer", "image")}

        def execute(self, rc, frame):
            rc.resources["private.tex"] = self.tex
            super().execute(rc, frame)

    found, _ = _frames([Private()])
    assert any("pass 'private' accesses '<unnamed texture of pass private>' by framebuffer draw after 'private' "
               "wrote it by image store, with no FRAMEBUFFER barrier" in f for f in found), found
    found, y = _frames([Declared()], n=3)
    assert found == []
    assert np.allclose(y[..., 0], 2.0 * (1.0 + np.arange(11))[None, :])


def test_clear_resource_is_ordered_and_recorded(validating):
    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (8, 8))
        g = FrameGraph([Fill(), Double()])
        g.plan(set())
        g.compile(rc)
        try:
            g.execute(rc, FrameState(), timers=False)
            rc.clear_resource("x", (5.0, 0.0, 0.0, 0.0))
            rec = list(rc.sync["x"])
            g.execute(rc, FrameState(), timers=False)
            return rec, sync_check.VALIDATOR.take()
        finally:
            rc.resources.release()
    rec, found = get_gl().call(job)
    assert rec[:2] == ["graph", "upload"]
    assert found == []


def test_clear_behind_the_graphs_back_is_named(validating):
    """A history texture cleared with its own framebuffer after an image store (not through
    rc.clear_resource): no FRAMEBUFFER barrier, and the graph's record would be stale."""
    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (8, 8))
        g = FrameGraph([Fill(), Double()])
        g.plan(set())
        g.compile(rc)
        try:
            g.execute(rc, FrameState(), timers=False)
            fbo = ctx.framebuffer(color_attachments=[rc.resources["x"]])
            fbo.clear(5.0, 0.0, 0.0, 0.0)
            fbo.release()
            return sync_check.VALIDATOR.take()
        finally:
            rc.resources.release()
    found = get_gl().call(job)
    assert any("'<outside the passes>' accesses 'x' by framebuffer draw after 'fill' wrote it by image store" in f
               for f in found), found


def test_barrier_bits_follow_writer_and_reader():
    rb = barriers.required_bits
    assert rb("image", "texture", False) == barriers.TEXTURE_FETCH_BARRIER_BIT
    assert rb("image", "framebuffer", False) == barriers.FRAMEBUFFER_BARRIER_BIT
    assert rb("image", "upload", False) == barriers.TEXTURE_UPDATE_BARRIER_BIT
    assert rb("storage", "indirect", True) == barriers.COMMAND_BARRIER_BIT
    assert rb("storage", "readback", True) == barriers.BUFFER_UPDATE_BARRIER_BIT
    assert rb("storage", "vertex", True) == barriers.VERTEX_ATTRIB_ARRAY_BARRIER_BIT
    assert rb("framebuffer", "texture", False) == 0 and rb("upload", "image", False) == 0


# ---------------------------------------------------------------- every technique
@pytest.fixture(scope="module", params=["cornell", "sunlit_room"])
def demo_sd(request):
    """An area-lit box, and a sun-lit room with a world (sky paths, world rays)."""
    import bpy

    sc = demo_scenes.build_demo(request.param, resolution=20)
    sd = export_scene(reference.evaluated_depsgraph(sc))
    yield sd
    bpy.data.scenes.remove(sc)


def _technique_ids():
    return [t.id for t in techniques.available()]


@pytest.mark.parametrize("tech", _technique_ids())
def test_technique_renders_without_sync_findings(demo_sd, tech, validating):
    key = f"test_sync_{tech}"
    moved = copy.deepcopy(demo_sd)
    moved.camera.matrix_world = moved.camera.matrix_world.copy()
    moved.camera.matrix_world[0, 3] += 0.05
    try:
        session.render(demo_sd, tech, 0, 2, session=key)
        # frames keeping history from a moved camera: what a pass caches while the view is
        # still is recomputed, after last frame's writes
        session.render(moved, tech, 0, 1, keep_history=True, session=key)
        session.render(demo_sd, tech, 0, 1, keep_history=True, session=key)
    finally:
        fut = session.release_session(key)
        if fut is not None:
            fut.result()
    assert get_gl().call(sync_check.VALIDATOR.take) == []


def test_validate_level_2_turns_on_both_checks(monkeypatch):
    """GI_PREVIEW_VALIDATE=2 runs the sync validation and keeps level 1's NaN/Inf checks;
    level 1 is the value checks alone."""
    from gi_preview.render import framegraph

    monkeypatch.delenv("GI_PREVIEW_VALIDATE_SYNC", raising=False)
    monkeypatch.setenv("GI_PREVIEW_VALIDATE", "2")
    assert sync_check.enabled() and framegraph.validate_enabled()
    monkeypatch.setenv("GI_PREVIEW_VALIDATE", "1")
    assert framegraph.validate_enabled() and not sync_check.enabled()
