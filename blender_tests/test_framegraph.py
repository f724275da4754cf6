"""The frame graph: planning (topological order, unproduced reads, cycles), typed
resources, memory barriers (checked on the graph's barrier log), history owned by the
graph (double-buffered, reset per declared event), warm-up before F12 accumulation,
layered raster targets, and GI_PREVIEW_VALIDATE.

Passes here are small compute/raster programs written for the test, so every claim is
checked on real GL objects, not on mocks; the scene-level tests use the built-in Cornell
box at 24 px.
"""
from __future__ import annotations

import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.blender.export import export_scene
from gi_preview.render import framegraph as fg
from gi_preview.render import session, techniques
from gi_preview.render.framegraph import Effect, FrameGraph, FrameState, Param, Pass, PlanError, RenderContext, Res
from gi_preview.render.gl import get_gl
from gi_preview.render.shaders import ProgramCache


# ---------------------------------------------------------------- planning (no GL)
class P(Pass):
    def __init__(self, name, reads=(), writes=(), provides=(), always=False, optional=()):
        self.name, self.reads, self.writes = name, tuple(reads), tuple(writes)
        self.provides, self.always, self.optional_reads = frozenset(provides), always, tuple(optional)
        super().__init__()

    def execute(self, rc, frame):
        pass


def test_order_is_topological_whatever_the_declaration_order():
    g = FrameGraph([P("resolve", reads=("b", "gb"), writes=("color",), always=True),
                    P("filter", reads=("a",), writes=("b",)),
                    P("gbuffer", writes=("gb",), always=True),
                    P("trace", reads=("gb",), writes=("a",))])
    g.plan(set())
    assert g.order.index("gbuffer") < g.order.index("trace") < g.order.index("filter") < g.order.index("resolve")
    assert set(g.order) == {"resolve", "filter", "gbuffer", "trace"}  # producers pulled in


def test_multi_writer_resource_keeps_declaration_order_of_versions():
    # color: written by direct, then read-modify-written by two composites; a reader of the
    # first version (the bounce pass) must run before the composite that changes it
    g = FrameGraph([P("direct", writes=("color", "radiance"), always=True),
                    P("bounce", reads=("radiance",), writes=("bounce",), provides={Effect.INDIRECT_DIFFUSE}),
                    P("composite_a", reads=("color", "bounce"), writes=("color",), provides={Effect.INDIRECT_DIFFUSE}),
                    P("probe_color", reads=("color",), writes=("seen",), provides={Effect.AO}),
                    P("composite_b", reads=("color", "seen"), writes=("color",), provides={Effect.AO})])
    g.plan({Effect.INDIRECT_DIFFUSE, Effect.AO})
    o = g.order
    assert o.index("direct") < o.index("composite_a") < o.index("probe_color") < o.index("composite_b")
    # a composite that is not needed is not pulled in by a later reader of color
    g.plan({Effect.AO})
    assert "composite_a" not in g.order and "bounce" not in g.order
    assert [s.name for s in g._plan.skipped] == ["bounce", "composite_a"]


def test_plan_tells_each_pass_who_reads_its_output():
    """A producer may ask the planned readers of what it writes what they can do without it
    (the shadow pass leaves lights to rays only where every reader of its maps traces them):
    ``consumers`` holds the planned readers, optional reads included, and nothing skipped."""
    g = FrameGraph([P("gbuffer", writes=("gb",), always=True),
                    P("shadows", writes=("atlas",), always=True),
                    P("light", reads=("gb",), optional=("atlas",), writes=("color",), always=True),
                    P("inject", reads=("gb", "atlas"), writes=("vox",), provides={Effect.INDIRECT_DIFFUSE})])
    g.plan({Effect.INDIRECT_DIFFUSE})
    names = lambda p: sorted(c.name for c in g.find(p).consumers)  # noqa: E731
    assert names("shadows") == ["inject", "light"] and names("gbuffer") == ["inject", "light"]
    assert names("light") == [] and names("inject") == []
    g.plan(set())  # the inject pass is not needed: it is no consumer any more
    assert names("shadows") == ["light"]


def test_unproduced_read_names_the_pass_and_resource():
    g = FrameGraph([P("gbuffer", writes=("gb",), always=True), P("ssao", reads=("gb", "hiz"), writes=("ao",))])
    with pytest.raises(PlanError, match=r"pass 'ssao' reads 'hiz', which no pass"):
        g.plan(set())
    g2 = FrameGraph([P("t", reads=("x@prev",), writes=("x",), always=True)])
    with pytest.raises(PlanError, match=r"pass 't' reads 'x@prev'.*not a history resource"):
        g2.plan(set())


def test_cycle_names_the_passes():
    g = FrameGraph([P("a", reads=("y",), writes=("x",), always=True), P("b", reads=("x",), writes=("y",))])
    with pytest.raises(PlanError, match=r"'a', 'b' depend on each other in a cycle"):
        g.plan(set())


def test_declaration_must_be_written_and_consistent():
    class D(P):
        declared = (Res("x", dtype="f2"),)
    with pytest.raises(PlanError, match="declares resource 'x' but does not list it in writes"):
        FrameGraph([D("d", writes=("y",))])

    class E(P):
        declared = (Res("x", dtype="f4"),)
    with pytest.raises(PlanError, match="declared differently"):
        FrameGraph([D("d", writes=("x",)), E("e", writes=("x",))])


# ---------------------------------------------------------------- GL passes written for these tests
FILL_SRC = """#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_x;
uniform float u_value;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_x)))) return;
    imageStore(o_x, p, vec4(u_value + float(p.x), float(p.y), 0.0, 1.0));
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
EMA_SRC = """#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_state;
uniform sampler2D u_prev;
uniform float u_target;
uniform float u_hysteresis;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_state)))) return;
    vec4 prev = texelFetch(u_prev, p, 0);
    imageStore(o_state, p, vec4(mix(vec3(u_target), prev.rgb, u_hysteresis), prev.a + 1.0));
}
"""


def _prog(rc, src):
    key = ("test", src)
    progs = rc.__dict__.setdefault("_test_programs", {})
    if key not in progs:
        progs[key] = rc.ctx.compute_shader(src)
    return progs[key]


class FillPass(Pass):
    name = "fill"
    writes = ("x",)
    declared = (Res("x"),)
    always = True
    params = (Param("value", 1.0, 0.0, 100.0),)

    def execute(self, rc, frame):
        prog = _prog(rc, FILL_SRC)
        prog["u_value"].value = float(self["value"])
        rc.resources["x"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


class DoublePass(Pass):
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


def _run_gl(fn):
    return get_gl().call(fn)


def test_barrier_between_image_store_writer_and_later_reader():
    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (19, 13))
        g = FrameGraph([DoublePass(), FillPass()])  # declared out of order on purpose
        g.plan(set())
        g.compile(rc)
        logs = []
        for _ in range(2):
            g.execute(rc, FrameState(), timers=False)
            logs.append(list(g.barrier_log))
        rc.barrier_external(["y"])
        y = np.frombuffer(rc.resources["y"].read(), np.float32).reshape(13, 19, 4)
        out = (g.order, logs, y.copy())
        rc.resources.release()
        return out

    order, logs, y = _run_gl(job)
    assert order == ["fill", "double"]
    first, second = logs
    # frame 1: nothing before the first write of fresh resources; image store -> texel fetch
    assert [b["before"] for b in first] == ["double"]
    assert first[0]["resources"] == ["x"]
    assert {"TEXTURE_FETCH", "SHADER_IMAGE_ACCESS"} <= set(first[0]["names"])
    # frame 2: fill's image store must wait for last frame's fetch of x (write after read), and
    # double's store into y after the external read-back
    assert [b["before"] for b in second] == ["fill", "double"]
    assert "SHADER_IMAGE_ACCESS" in second[0]["names"] and second[0]["resources"] == ["x"]
    xs = np.arange(19, dtype=np.float32)[None, :] + 1.0
    ys = np.arange(13, dtype=np.float32)[:, None]
    assert np.allclose(y[..., 0], 2 * xs) and np.allclose(y[..., 1], 2 * ys)


def test_no_barrier_after_coherent_framebuffer_writes():
    class Raster(Pass):
        name = "raster"
        kind = "raster"
        writes = ("x",)
        declared = (Res("x"),)
        always = True

        def compile(self, rc):
            self.fbo = rc.ctx.framebuffer(color_attachments=[rc.resources["x"]])

        def execute(self, rc, frame):
            self.fbo.use()
            self.fbo.clear(3.0, 0.0, 0.0, 1.0)

    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (8, 8))
        g = FrameGraph([Raster(), DoublePass()])
        g.plan(set())
        g.compile(rc)
        g.execute(rc, FrameState(), timers=False)
        log = list(g.barrier_log)
        rc.barrier_external(["y"])
        y = np.frombuffer(rc.resources["y"].read(), np.float32).reshape(8, 8, 4)[..., 0].copy()
        rc.resources.release()
        return log, y

    log, y = _run_gl(job)
    assert log == []
    assert np.allclose(y, 6.0)


def test_typed_resources_are_allocated_and_resized():
    class Typed(Pass):
        name = "typed"
        writes = ("half", "vol", "arr", "buf", "hist")
        params = (Param("scale", 0.5, 0.25, 1.0),)
        declared = (Res("half", dtype="f2", scale="scale"), Res("vol", kind=fg.TEX3D, components=1, size=(4, 5, 6)),
                    Res("arr", kind=fg.TEX2D_ARRAY, size=(8, 8, 6)), Res("buf", kind=fg.BUFFER, size=256),
                    Res("hist", history=True))
        always = True

        def execute(self, rc, frame):
            pass

    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (30, 20))
        p = Typed()
        g = FrameGraph([p])
        g.plan(set())
        g.compile(rc)
        r = rc.resources
        first = (r["half"].size, r["half"].dtype, r["vol"].size, r["vol"].components, r["arr"].size,
                 r["buf"].size, r["hist"].size, "hist@prev" in r, r["hist"] is not r["hist@prev"])
        old_hist = r["hist"]
        g.execute(rc, FrameState(), timers=False)
        swapped = r["hist@prev"] is old_hist
        p.set_properties({"scale": 1.0})
        g.compile(rc)
        resized = r["half"].size
        rc.size = (10, 10)
        g.compile(rc)
        out = first, swapped, resized, r["half"].size, r["hist"].size
        rc.resources.release()
        return out

    first, swapped, resized, small, hist_small = _run_gl(job)
    assert first == ((15, 10), "f2", (4, 5, 6), 1, (8, 8, 6), 256, (30, 20), True, True)
    assert swapped  # this frame's write target became last frame's value
    assert resized == (30, 20) and small == (10, 10) and hist_small == (10, 10)


LAYER_VS = """#version 430
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""
LAYER_GS = """#version 430
layout(triangles) in;
layout(triangle_strip, max_vertices = 6) out;
out float g_value;
void main() {
    for (int layer = 0; layer < 2; ++layer) {
        for (int i = 0; i < 3; ++i) {
            gl_Layer = layer;
            g_value = float(layer + 1) * 10.0;
            gl_Position = gl_in[i].gl_Position;
            EmitVertex();
        }
        EndPrimitive();
    }
}
"""
LAYER_FS = """#version 430
in float g_value;
out vec4 f_color;
void main() { f_color = vec4(g_value, 0.0, 0.0, 1.0); }
"""


def test_layered_raster_target():
    """A raster pass renders both layers of a 2D array in one draw (gl_Layer from a geometry
    shader), as cube-map and voxelisation passes do."""

    class Layered(Pass):
        name = "layered"
        kind = "raster"
        writes = ("layers",)
        declared = (Res("layers", kind=fg.TEX2D_ARRAY, size=(4, 4, 2)),)
        always = True

        def execute(self, rc, frame):
            prog = rc.ctx.program(vertex_shader=LAYER_VS, geometry_shader=LAYER_GS, fragment_shader=LAYER_FS)
            vbo = rc.ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
            vao = rc.ctx.vertex_array(prog, [(vbo, "2f", "in_pos")])
            fbo = rc.layered_framebuffer(["layers"])
            fbo.use()
            rc.ctx.viewport = (0, 0, 4, 4)
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            vao.render()
            for o in (fbo, vao, vbo, prog):
                o.release()

    def job():
        ctx = get_gl().ctx
        rc = RenderContext(ctx, ProgramCache(ctx), None, (4, 4))
        g = FrameGraph([Layered()])
        g.plan(set())
        g.compile(rc)
        g.execute(rc, FrameState(), timers=False)
        data = np.frombuffer(rc.resources["layers"].read(), np.float32).reshape(2, 4, 4, 4)[..., 0].copy()
        rc.resources.release()
        return data

    data = _run_gl(job)
    assert np.allclose(data[0], 10.0) and np.allclose(data[1], 20.0)


# ---------------------------------------------------------------- scene-level: history, warm-up, validation
@pytest.fixture(scope="module")
def cornell_sd():
    import bpy

    sc = demo_scenes.build_demo("cornell", resolution=24)
    sd = export_scene(reference.evaluated_depsgraph(sc))
    yield sd
    bpy.data.scenes.remove(sc)


class EmaPass(Pass):
    """State that converges over frames: state = target + hysteresis^n (0 - target)."""

    name = "ema"
    reads = ("ema.state@prev",)
    writes = ("ema.state",)
    declared = (Res("ema.state", history=True, check="radiance"),)
    provides = frozenset({Effect.INDIRECT_DIFFUSE})
    always = True
    params = (Param("hysteresis", 0.5, 0.0, 0.999), Param("target", 1.0, 0.0, 10.0))

    def execute(self, rc, frame):
        prog = _prog(rc, EMA_SRC)
        rc.resources["ema.state@prev"].use(1)
        prog["u_prev"].value = 1
        prog["u_target"].value = float(self["target"])
        prog["u_hysteresis"].value = float(self["hysteresis"])
        rc.resources["ema.state"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


class ShowPass(Pass):
    name = "show"
    reads = ("ema.state",)
    writes = ("color",)
    declared = (Res("color", check="radiance"),)
    always = True

    def execute(self, rc, frame):
        prog = _prog(rc, DOUBLE_SRC)
        rc.resources["ema.state"].use(1)
        prog["u_x"].value = 1
        rc.resources["color"].bind_to_image(0, read=False, write=True)
        rc.dispatch(prog, *rc.groups(8))


@pytest.fixture
def stateful_technique():
    made = []

    def make(tid, warmup=0, measured=False):
        class Ema(EmaPass):
            warmup_frames = warmup

            def converged(self, rc):
                if not measured:
                    return None
                rc.barrier_external(["ema.state"])
                s = np.frombuffer(rc.resources["ema.state"].read(), np.float32)
                return bool(np.all(np.abs(s[0::4] - 1.0) < 1e-3))

        class Tech(techniques.Technique):
            id = tid
            label = tid
            reference = "full"

            def passes(self, quality):
                return [Ema(), ShowPass()]

        techniques.register(Tech)
        made.append(tid)
        return Tech

    yield make
    for tid in made:
        techniques.REGISTRY.pop(tid, None)


def test_f12_warms_up_state_before_accumulating(cornell_sd, stateful_technique):
    stateful_technique("TEST_EMA_COLD", warmup=0)
    stateful_technique("TEST_EMA_WARM", warmup=24)
    stateful_technique("TEST_EMA_MEASURED", warmup=200, measured=True)
    cold = session.render(cornell_sd, "TEST_EMA_COLD", 0, 4, session="test_warmup")
    warm = session.render(cornell_sd, "TEST_EMA_WARM", 0, 4, session="test_warmup")
    measured = session.render(cornell_sd, "TEST_EMA_MEASURED", 0, 4, session="test_warmup")
    # shown value = 2 * state; cold: the mean of the first four frames of 1 - 0.5^n
    expect_cold = 2 * np.mean([1 - 0.5 ** n for n in range(1, 5)])
    assert cold.warmup_frames == 0
    assert np.allclose(cold.image[..., 0], expect_cold, atol=1e-5)
    assert warm.warmup_frames == 24 and warm.samples == 4
    assert np.allclose(warm.image[..., 0], 2.0, atol=1e-5)  # what the viewport shows once settled
    # measured convergence stops the warm-up as soon as the state is within 1e-3 (n = 10)
    assert measured.warmup_frames == 10, measured.warmup_frames
    assert np.allclose(measured.image[..., 0], 2.0, atol=3e-3)
    # the viewport (history kept, progressive) never warms up
    vp = session.render(cornell_sd, "TEST_EMA_WARM", 0, 1, keep_history=True, session="test_warmup_vp")
    assert vp.warmup_frames == 0


def _len_texture(key, name):
    def job():
        rc = session._sessions[key].rc
        rc.barrier_external([name])
        t = rc.resources[name]
        return np.frombuffer(t.read(), np.float32).reshape(t.size[1], t.size[0], -1)[..., 0].copy()

    return get_gl().call(job)


def test_light_edit_resets_declared_history_only(cornell_sd):
    import copy

    sd = copy.deepcopy(cornell_sd)
    for tech, key in (("SSDO", "test_hist_ssdo"), ("SSAO", "test_hist_ssao")):
        for _ in range(4):
            res = session.render(sd, tech, 0, 1, keep_history=True, session=key)
        temporal = f"{tech.lower()}_temporal"
        assert res.history_resets == []
        lit = _len_texture(key, f"{tech.lower()}.temporal.len")
        geo = sd.instances  # noqa: F841 - unchanged
        assert lit.max() >= 4  # four frames of history on the surfaces
    # a light edit: SSDO's bounce depends on light, its history is reset; SSAO's AO is not
    sd.lights[0].color = np.asarray(sd.lights[0].color, np.float32) * 2.0
    r_ssdo = session.render(sd, "SSDO", 0, 1, keep_history=True, session="test_hist_ssdo")
    r_ssao = session.render(sd, "SSAO", 0, 1, keep_history=True, session="test_hist_ssao")
    assert "ssdo_temporal" in r_ssdo.history_resets
    assert "ssao_temporal" not in r_ssao.history_resets
    assert _len_texture("test_hist_ssdo", "ssdo.temporal.len").max() == 1  # restarted
    assert _len_texture("test_hist_ssao", "ssao.temporal.len").max() >= 5  # kept
    # a parameter change resets only the pass whose parameter changed
    def bump():
        tech, graph = session._sessions["test_hist_ssao"]._graph("SSAO", 0)
        graph.find("ssao_blur").set_properties({"blur_radius": 1})
        graph.find("ssao_temporal").set_properties({"max_history": 16})
    get_gl().call(bump)
    r = session.render(sd, "SSAO", 0, 1, keep_history=True, session="test_hist_ssao")
    assert r.history_resets == ["ssao_temporal"]


def test_validate_names_the_pass_and_resource(cornell_sd, stateful_technique, monkeypatch):
    class Tech(techniques.Technique):
        id = "TEST_NAN"
        label = "nan"

        def passes(self, quality):
            return [EmaPass(target=1.0), NanPass(), ShowPass()]

    class NanPass(Pass):
        name = "nan_maker"
        reads = ("ema.state",)
        writes = ("bad",)
        declared = (Res("bad", check="radiance"),)
        always = True

        def execute(self, rc, frame):
            w, h = rc.size
            a = np.zeros((h, w, 4), np.float32)
            a[3, 5, 1] = np.nan
            rc.resources["bad"].write(a.tobytes())

    techniques.register(Tech)
    try:
        monkeypatch.delenv("GI_PREVIEW_VALIDATE", raising=False)
        session.render(cornell_sd, "TEST_NAN", 0, 1, session="test_validate")  # off: not checked
        monkeypatch.setenv("GI_PREVIEW_VALIDATE", "1")
        with pytest.raises(fg.ValidationError, match=r"pass 'nan_maker' wrote NaN/Inf .* into 'bad' at texel \(5, 3\) channel 1"):
            session.render(cornell_sd, "TEST_NAN", 0, 1, session="test_validate")
    finally:
        techniques.REGISTRY.pop("TEST_NAN", None)
