"""The Render Properties of GI Preview: panels and their parents, the grouped technique menu,
Quality as named levels over the stored integer, the technique settings (shown only for
their technique, reaching the passes' parameters, the defaults leaving the render
unchanged), the comparison table's references and the grouped stats line.

Panels are drawn into a recording layout (no window is needed); renders are 24x24."""
from __future__ import annotations

from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from gi_preview.blender import engine as engine_mod
from gi_preview.blender import properties, ui
from gi_preview.render import session, techniques
from gi_preview.render.result import SkippedPass


class FakeLayout:
    """Records what a panel draws: ``props`` (property identifiers), ``labels``, ``operators``."""

    def __init__(self, root=None):
        self.root = root or self
        if root is None:
            self.props, self.labels, self.operators = [], [], []
        self.use_property_split = self.use_property_decorate = False

    def _child(self, *a, **k):
        return FakeLayout(self.root)

    column = row = box = split = grid_flow = _child

    def prop(self, data, prop, **k):
        assert prop in data.bl_rna.properties, prop
        self.root.props.append(prop)

    def label(self, text="", **k):
        self.root.labels.append(text)

    def operator(self, idname, **k):
        op = SimpleNamespace(idname=idname)
        self.root.operators.append(op)
        return op

    def separator(self, **k):
        pass


def draw(panel, scene):
    layout = FakeLayout()
    ctx = SimpleNamespace(scene=scene, engine="GI_PREVIEW")
    if not panel.poll(ctx):
        return None
    fake = SimpleNamespace(layout=layout, split_layout=lambda: layout)
    if hasattr(panel, "draw_header"):
        panel.draw_header(fake, ctx)
    panel.draw(fake, ctx)
    return layout


@pytest.fixture
def scene():
    sc = bpy.data.scenes.new("ui_test")
    yield sc
    bpy.data.scenes.remove(sc)


def test_panels_registered_with_their_parents():
    parents = {
        "GIPREVIEW_RENDER_PT_technique": None,
        "GIPREVIEW_RENDER_PT_technique_settings": "GIPREVIEW_RENDER_PT_technique",
        "GIPREVIEW_RENDER_PT_sampling": "GIPREVIEW_RENDER_PT_technique",
        "GIPREVIEW_RENDER_PT_denoising": "GIPREVIEW_RENDER_PT_sampling",
        "GIPREVIEW_RENDER_PT_compare": "GIPREVIEW_RENDER_PT_technique",
        "GIPREVIEW_RENDER_PT_last": "GIPREVIEW_RENDER_PT_technique",
    }
    for name, parent in parents.items():
        cls = getattr(bpy.types, name)
        assert getattr(cls, "bl_parent_id", "") == (parent or ""), name
        assert cls.bl_context == "render" and "GI_PREVIEW" in cls.COMPAT_ENGINES
    assert {c.__name__ for c in ui.classes} == set(parents)


def test_technique_menu_grouped_by_family():
    items = properties.technique_items()
    headings = [i[1] for i in items if i is not None and i[0] == ""]
    assert "Probes" in headings and "Screen Space" in headings and items.count(None) == len(headings) - 1
    enum = {i.identifier: i for i in bpy.types.Scene.bl_rna.properties["gi_preview"].fixed_type
            .properties["technique"].enum_items}
    assert set(enum) == {i.id for i in techniques.available()}  # headings are not items
    for tid, it in enum.items():
        assert len(it.name) <= 26 and "\n" not in it.description and it.value == properties.enum_value(tid)


def test_quality_named_levels_over_the_stored_integer(scene):
    s = scene.gi_preview
    assert s.quality_preset == "MEDIUM" and s.quality == 1
    # what a file saved with the integer property holds: an integer ID property "quality"
    s["quality"] = 2
    assert s.quality_preset == "HIGH" and engine_mod._settings(scene)[1] == 2
    s.quality_preset = "ULTRA"
    assert s.quality == 3 and s["quality"] == 3
    s.quality = 0  # scripts setting the integer keep working
    assert s.quality_preset == "DRAFT"
    assert "quality_preset" not in s.keys()  # a view of "quality": nothing more is saved


@pytest.mark.parametrize("tid", sorted(i.id for i in techniques.available()))
def test_settings_shown_only_for_their_technique(scene, tid):
    s = scene.gi_preview
    s.technique = tid
    s.denoiser, s.use_taa = "NONE", False
    own = [st.prop for st in properties.technique_settings(tid)]
    layout = draw(ui.GIPREVIEW_RENDER_PT_technique_settings, scene)
    drawn = [] if layout is None else layout.props
    probes = techniques.get(tid).family == "probes"
    assert drawn == own + (["show_probes"] if probes else [])
    assert own, f"{tid} shows no setting"
    # the filters' settings appear in Denoising only when that filter ends the graph
    assert draw(ui.GIPREVIEW_RENDER_PT_denoising, scene).props == ["denoiser", "use_taa"]
    # every setting shown sets a parameter one of the technique's passes declares
    passes = {p.name: {d.name for d in p.params} for p in techniques.get(tid)().passes(1)}
    for st in properties.technique_settings(tid):
        assert any(param in passes.get(name, ()) for name, param in st.targets), (tid, st.prop)


def test_filter_settings_in_denoising(scene):
    s = scene.gi_preview
    s.technique = "DDGI"
    s.use_taa = True
    s.denoiser = "SVGF"
    props = draw(ui.GIPREVIEW_RENDER_PT_denoising, scene).props
    assert props == ["denoiser", "use_taa", "svgf_history", "taa_history"]
    s.svgf_history, s.taa_history = 12, 20
    assert properties.pass_overrides(s, "DDGI") == {"svgf": {"max_history": 12}, "taa": {"max_history": 20}}
    from gi_preview.render.passes.filters import with_filters
    graph_passes = {p.name: {d.name for d in p.params}
                    for p in with_filters(techniques.get("DDGI")().passes(1), "SVGF", True, 1)}
    assert "max_history" in graph_passes["svgf"] and "max_history" in graph_passes["taa"]
    s.use_taa, s.denoiser = False, "NONE"
    assert properties.pass_overrides(s, "DDGI") == {}


def test_defaults_override_nothing(scene):
    s = scene.gi_preview
    for tid in (i.id for i in techniques.available()):
        assert properties.pass_overrides(s, tid) == {}, tid


def _probe_scene():
    from scenes_probes import build

    return build("white_room", resolution=24)


def test_probe_spacing_reaches_the_probe_grid():
    """DDGI's Probe Spacing becomes probe_trace.spacing and changes the probe lattice; set
    back to 0 the pass returns to its quality level's grid."""
    from _helpers import export

    sc = _probe_scene()
    key = "ui_probe_spacing"
    try:
        s = sc.gi_preview
        s.technique, s.quality = "DDGI", 0
        data = export(sc)
        gkey = ("DDGI", 0, "NONE", False)

        def grid():
            def read():
                p = session._sessions[key].graphs[gkey][1].find("probe_trace")
                return p.props["spacing"], tuple(int(c) for c in p.volume.counts)
            from gi_preview.render.gl import get_gl
            return get_gl().call(read)

        session.render(data, "DDGI", 0, 1, session=key, warmup=False, params=engine_mod._pass_params(sc, "DDGI"))
        spacing0, counts0 = grid()
        s.probe_spacing = 0.5
        params = engine_mod._pass_params(sc, "DDGI")
        assert params == {"probe_trace": {"spacing": 0.5}}
        session.render(data, "DDGI", 0, 1, session=key, warmup=False, params=params)
        spacing1, counts1 = grid()
        assert spacing0 == 0.0 and spacing1 == 0.5
        assert counts1 != counts0 and max(counts1) > max(counts0), (counts0, counts1)
        s.probe_spacing = 0.0
        session.render(data, "DDGI", 0, 1, session=key, warmup=False, params=engine_mod._pass_params(sc, "DDGI"))
        assert grid() == (spacing0, counts0)
    finally:
        session.release_session(key).result(timeout=60)
        bpy.data.scenes.remove(sc)


def test_default_settings_leave_the_render_bit_identical():
    """Settings at 0 ("the Quality level's value") render exactly what a render without
    settings renders, pixel for pixel."""
    from _helpers import export

    sc = _probe_scene()
    try:
        s = sc.gi_preview
        s.technique, s.quality = "DDGI", 0
        data = export(sc)
        a = session.render(data, "DDGI", 0, 2, session="ui_bits_a", warmup=False)
        params = engine_mod._pass_params(sc, "DDGI")
        assert params == {}
        b = session.render(data, "DDGI", 0, 2, session="ui_bits_b", warmup=False, params=params)
        assert np.array_equal(a.image, b.image)
        s.probe_rays = 8  # and a setting that is not 0 does change it
        c = session.render(data, "DDGI", 0, 2, session="ui_bits_b", warmup=False,
                           params=engine_mod._pass_params(sc, "DDGI"))
        assert not np.array_equal(a.image, c.image)
    finally:
        for k in ("ui_bits_a", "ui_bits_b"):
            session.release_session(k).result(timeout=60)
        bpy.data.scenes.remove(sc)


def test_compare_table_names_each_rows_reference(scene):
    import json

    scene.gi_preview_comparison.results_json = json.dumps({
        "DDGI": {"quality": 1, "reference": "full", "ref_spp": 256, "relmse": 0.01},
        "SSAO": {"quality": 1, "reference": "ao", "ref_spp": 64, "relmse": 0.02}})
    scene.gi_preview.compare_reference, scene.gi_preview.compare_samples = "FULL", 512
    layout = draw(ui.GIPREVIEW_RENDER_PT_compare, scene)
    assert layout.props == ["compare_reference", "compare_samples"]
    op = layout.operators[0]
    assert (op.reference, op.ref_spp) == ("FULL", 512)
    labels = layout.labels
    assert "Reference" in labels
    assert labels[labels.index("DDGI q1") + 1] == "Full 256"
    assert labels[labels.index("SSAO q1") + 1] == "AO 64"


def test_stats_line_groups_skipped_passes_by_effect():
    res = SimpleNamespace(technique="AUTO", quality=1, samples=4, frame_ms=2.0, skipped_passes=[
        SkippedPass("ssr_trace", ["glossy"], "no glossy surface in view"),
        SkippedPass("ssr_resolve", ["glossy"], "no glossy surface in view"),
        SkippedPass("shadows", ["shadows"], "no light casts shadows")])
    text = engine_mod.stats_text(res, 16)
    assert "glossy: no glossy surface in view; shadows: no light casts shadows" in text
    assert "ssr_trace" not in text and "4/16 samples" in text and "(Medium)" in text


# settings that resize a pass's resources: changed between two frames of one session (as in
# the viewport), the next frame renders with them
RESIZING = (("VXGI", "voxel_resolution", 16), ("VXGI", "voxel_cascades", 1), ("LPV", "lpv_cells", 8),
            ("LPV", "lpv_cascades", 1), ("RSM", "rsm_resolution", 32), ("DDGI", "probe_count", 3),
            ("DIRECT", "shadow_resolution", 64))


@pytest.mark.parametrize("tid,prop,value", RESIZING)
def test_resizing_setting_changes_mid_session(tid, prop, value):
    from _helpers import export

    sc = _probe_scene()
    key = f"ui_resize_{prop}"
    try:
        s = sc.gi_preview
        s.technique, s.quality = tid, 0
        data = export(sc)
        session.render(data, tid, 0, 1, session=key, keep_history=True, warmup=False,
                       params=engine_mod._pass_params(sc, tid))
        setattr(s, prop, value)
        params = engine_mod._pass_params(sc, tid)
        res = session.render(data, tid, 0, 1, session=key, keep_history=True, continue_accumulation=True,
                             warmup=False, params=params)
        assert np.isfinite(res.image).all() and res.image[..., :3].max() > 0
        assert res.samples == 1  # the accumulation starts again (the graph's state is rebuilt)
        (pass_name, param), = [t for t in properties.SETTINGS_BY_PROP[prop].targets if t[0] in params]
        from gi_preview.render.gl import get_gl
        got = get_gl().call(lambda: session._sessions[key].graphs[(tid, 0, "NONE", False)][1]
                            .find(pass_name).props[param])
        assert got == value
    finally:
        session.release_session(key).result(timeout=60)
        bpy.data.scenes.remove(sc)


def test_viewport_restarts_when_a_setting_changes(monkeypatch):
    """A converged Rendered view starts accumulating again when a technique setting changes,
    and its next frame renders with the new pass parameter."""
    from gi_preview.blender.demo_scenes import build_demo
    from gi_preview.render.gl import get_gl
    from test_engine import draw_until_idle, fake_gpu_modules, fake_view

    fake_gpu_modules(monkeypatch)
    sc = build_demo("cornell", resolution=24)
    eng = None
    try:
        s = sc.gi_preview
        s.technique, s.quality, s.viewport_samples = "SSAO", 0, 2
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            dg = bpy.context.evaluated_depsgraph_get()
        ctx, eng = fake_view(sc, dg, width=32, height=24)
        engine_mod.view_update(eng, ctx, dg)
        draw_until_idle(eng, ctx, dg)
        assert eng._viewport.count == 2
        s.ao_distance = 0.25
        engine_mod.view_draw(eng, ctx, dg)
        assert eng._viewport.count == 0 and eng._viewport.future is not None
        draw_until_idle(eng, ctx, dg)
        assert eng._viewport.count == 2
        key = eng._viewport.session_key
        radius = get_gl().call(lambda: session._sessions[key].graphs[("SSAO", 0, "NONE", False)][1]
                               .find("ssao").props["radius"])
        assert radius == 0.25
    finally:
        if eng is not None:
            eng._viewport.free()
        bpy.data.scenes.remove(sc)
