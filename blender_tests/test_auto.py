"""AUTO: measured effect shares against Cycles' light-path passes, the skip threshold with
its number in the reason, and the frame budget choosing between the table's candidates.

Small: 24 px demo scenes, Cycles at 64 spp, the shares at 24 px and 16 spp.
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from gi_preview.blender import demo_scenes, reference
from gi_preview.compare import metrics
from gi_preview.render import effect_shares, session
from gi_preview.render.gl import get_gl
from gi_preview.render.techniques import auto
from _helpers import export as _export

SIZE = 24


def _view_layer_state(sc):
    vl = sc.view_layers[0]
    return ({p: getattr(vl, p) for p in reference._PASS_PROPS.values()}, sc.compositing_node_group,
            sc.render.use_compositing, sc.render.engine, len(bpy.data.node_groups))


@pytest.mark.parametrize("demo", ["cornell", "glossy_spheres", "emissive_panel"])
def test_shares_match_cycles_light_passes(demo):
    """Every effect's share within 5 percentage points of Cycles' passes; the user's scene
    (pass switches, compositor, engine) is left as it was."""
    sc = demo_scenes.build_demo(demo, resolution=SIZE)
    try:
        sd = _export(sc)
        gl = get_gl()
        est = gl.call(lambda: effect_shares.estimate_offline(gl.ctx, sd, longest=SIZE))
        before = _view_layer_state(sc)
        cyc = reference.cycles_effect_shares(sc, 64)
        assert _view_layer_state(sc) == before
        assert abs(sum(est.shares.values()) - 1.0) < 1e-6
        for e in effect_shares.EFFECTS:
            assert abs(est.shares[e] - cyc[e]) < 0.05, (demo, e, est.shares, cyc)
    finally:
        bpy.data.scenes.remove(sc)


def test_threshold_skips_with_the_share_in_the_reason_and_the_estimate_is_cached():
    """Cornell has no glossy surface: indirect glossy is 0.0 % -> skipped, said with the
    number; a second render of the unchanged scene and camera does not estimate again."""
    sc = demo_scenes.build_demo("cornell", resolution=SIZE)
    try:
        sd = _export(sc)
        key = "auto_threshold"
        res = session.render(sd, "AUTO", 0, 1, session=key, auto={"candidate": auto.BUNDLE})
        reasons = {s.name: s.reason for s in res.skipped_passes}
        ssr = [r for n, r in reasons.items() if n.startswith("ssr")]
        assert ssr and all(r == "indirect glossy: 0.0 % of the image -> skipped" for r in ssr), reasons
        assert res.auto["members"] == list(auto.CANDIDATES[auto.BUNDLE][0])
        assert res.auto["shares"]["indirect_diffuse"] > 0.3
        n = get_gl().call(lambda: session._get_session(key)._shares.estimates)
        session.render(sd, "AUTO", 0, 1, session=key, auto={"candidate": auto.BUNDLE}, keep_history=True,
                       continue_accumulation=True)
        assert get_gl().call(lambda: session._get_session(key)._shares.estimates) == n
        session.release_session(key)
    finally:
        bpy.data.scenes.remove(sc)


def test_budget_picks_cheap_or_accurate_from_the_table():
    """On every demo scene class of the table: a 1 ms budget picks the cheapest candidate
    (nothing fits), an unlimited one the lowest relMSE; the chosen members are reported."""
    table = auto.load_table()
    assert table is not None and table["rows"]
    for name, row in table["scenes"].items():
        shares = row["shares"]
        cheap = auto.choose(shares, table, table["width"], table["height"], budget_ms=1.0)
        best = auto.choose(shares, table, table["width"], table["height"], budget_ms=0.0)
        assert cheap.scene_class == best.scene_class == name
        cands = best.considered
        assert cheap.candidate == min(cands, key=lambda c: cands[c][1])
        assert best.candidate == min(cands, key=lambda c: (cands[c][0], cands[c][1]))
        assert cheap.predicted_ms <= best.predicted_ms and best.predicted_relmse <= cheap.predicted_relmse
        assert cheap.members == auto.CANDIDATES[cheap.candidate][0]
        mid = auto.choose(shares, table, table["width"], table["height"], target_error=best.predicted_relmse)
        assert mid.predicted_relmse <= best.predicted_relmse + 1e-12


def test_budget_in_a_render_reports_the_chosen_members():
    """A render with a tiny budget runs the cheap path, with an unlimited budget the accurate
    one; RenderResult.auto names the members and the image is finite."""
    sc = demo_scenes.build_demo("sunlit_room", resolution=SIZE)
    try:
        sd = _export(sc)
        key = "auto_budget"
        tiny = session.render(sd, "AUTO", 0, 1, session=key, auto={"budget_ms": 0.001})
        big = session.render(sd, "AUTO", 0, 1, session=key, auto={"budget_ms": 0.0})
        session.release_session(key)
        for r in (tiny, big):
            assert r.auto["members"] == list(auto.CANDIDATES[r.auto["candidate"]][0])
            assert np.isfinite(r.image).all()
        assert tiny.auto["predicted_ms"] <= big.auto["predicted_ms"]
        assert big.auto["predicted_relmse"] <= tiny.auto["predicted_relmse"]
        assert tiny.auto["candidate"] != big.auto["candidate"]
    finally:
        bpy.data.scenes.remove(sc)


def test_budget_settings_shown_only_for_auto():
    """Frame Budget, Target Error and Skip Below are in the Technique panel for AUTO only, and
    reach the render as ``auto=`` options."""
    from gi_preview.blender import properties, ui
    from test_ui import draw

    sc = bpy.data.scenes.new("auto_ui")
    try:
        s = sc.gi_preview
        s.technique = "AUTO"
        s.auto_frame_budget = 40.0
        props = draw(ui.GIPREVIEW_RENDER_PT_technique, sc).props
        assert {"auto_frame_budget", "auto_target_error", "auto_threshold"} <= set(props)
        assert properties.auto_options(s, "AUTO") == {"auto": {"budget_ms": 40.0, "target_error": 0.0,
                                                               "threshold": 0.01}}
        s.technique = "SSDO"
        props = draw(ui.GIPREVIEW_RENDER_PT_technique, sc).props
        assert not {"auto_frame_budget", "auto_target_error", "auto_threshold"} & set(props)
        assert properties.auto_options(s, "SSDO") == {}
    finally:
        bpy.data.scenes.remove(sc)


def test_every_single_technique_is_a_candidate_and_restir_gi_keeps_its_filter():
    """AUTO can choose any single technique (a budget never lacks one that fits); RESTIR_GI is
    composed with its default SVGF, exactly the graph RESTIR_GI renders with by default; RSM,
    LPV and VXGI keep their own graph type (they gate on shadow-casting lights)."""
    from gi_preview.render import techniques

    ids = {t.id for t in techniques.available()} - {"AUTO"}
    covered = {auto.split_member(m)[0] for members, _d, _g in auto.CANDIDATES.values() for m in members}
    assert ids <= covered, ids - covered
    rg = auto.Auto(auto.CANDIDATES["RESTIR_GI+SVGF"][0])
    want = techniques.get("RESTIR_GI")().build(1, techniques.resolve_denoiser("RESTIR_GI", "AUTO"))
    assert [p.name for p in rg.passes(1)] == [p.name for p in want.passes]
    assert any(p.name.startswith("svgf") for p in rg.passes(1))
    for t in ("RSM", "LPV", "VXGI"):
        assert auto.Auto((t,)).graph_class is techniques.get(t).graph_class
    assert auto.Auto(("DIRECT", "SSR")).graph_class is techniques.get("DIRECT").graph_class


def test_budget_on_a_scene_outside_the_table_fits_and_beats_direct(monkeypatch):
    """A closed room lit around a corner (not in the table; most of what the camera sees is
    indirect): at a budget equal to the median predicted cost of the candidates AUTO picks one
    predicted to fit and is better than DIRECT against Cycles full. The frame time it measured
    is printed, not asserted (llvmpipe's times; speed is the benchmarks' business). Re-planning
    from measured frames is off here: it depends on how busy the machine is (two test workers
    share the cores), and the re-planning tests below cover it."""
    import statistics

    import scenes_auto

    monkeypatch.setattr(auto, "REPLAN_FACTOR", float("inf"))

    sc = scenes_auto.build("around_corner", SIZE)
    try:
        sd = _export(sc)
        ref = reference.get_reference(sc, "full", 64).image
        key = "auto_new_scene"
        free = session.render(sd, "AUTO", 1, 1, session=key, auto={"budget_ms": 0.0})
        budget = statistics.median(v[1] for v in free.auto["considered"].values())
        res = session.render(sd, "AUTO", 1, 4, session=key, auto={"budget_ms": budget})
        direct = session.render(sd, "DIRECT", 1, 4, session=key)
        session.release_session(key)
        assert res.auto["scene_class"] in auto.load_table()["scenes"]
        assert res.auto["predicted_ms"] <= budget
        print(f"AUTO on around_corner: {res.auto['candidate']}, predicted {res.auto['predicted_ms']:.1f} ms, "
              f"measured {res.frame_ms:.1f} ms (llvmpipe), budget {budget:.1f} ms")
        e_auto, e_direct = metrics.relmse(res.image, ref), metrics.relmse(direct.image, ref)
        assert e_auto < e_direct, (res.auto["candidate"], e_auto, e_direct)
    finally:
        bpy.data.scenes.remove(sc)


def test_budget_floor_runs_direct_when_everything_that_fits_is_worse():
    """A table where the only candidate under the budget is predicted worse than DIRECT and
    DIRECT is predicted 10 % over: AUTO runs DIRECT (within DIRECT_SLACK), says so in its
    notes; at a budget DIRECT misses by more, the cheap candidate; a better one that fits wins."""
    shares = {"direct": 0.9, "indirect_diffuse": 0.05, "indirect_glossy": 0.05}
    table = {"width": 32, "height": 32, "scenes": {"s": {"shares": shares}},
             "rows": [{"scene": "s", "candidate": "DIRECT", "relmse": 0.05, "ms": 110.0},
                      {"scene": "s", "candidate": "RESTIR_DI", "relmse": 0.06, "ms": 20.0},
                      {"scene": "s", "candidate": "RTXGI", "relmse": 0.02, "ms": 300.0}]}
    p = auto.choose(shares, table, 32, 32, budget_ms=100.0)
    assert p.candidate == "DIRECT" and any("worse than DIRECT" in n for n in p.notes), p.notes
    assert auto.choose(shares, table, 32, 32, budget_ms=100.0 / auto.DIRECT_SLACK).candidate == "RESTIR_DI"
    assert auto.choose(shares, table, 32, 32, budget_ms=300.0).candidate == "RTXGI"
    assert auto.choose(shares, table, 32, 32, budget_ms=0.0).candidate == "RTXGI"


@pytest.fixture
def mispredicted_cornell(monkeypatch, request):
    """The Cornell box with a table that predicts RTXGI at 1 ms and DIRECT at a tenth of that,
    and a budget of 0.6x RTXGI's measured ms/frame: (scene data, session key, budget)."""
    shares = {"direct": 0.5, "indirect_diffuse": 0.5, "indirect_glossy": 0.0}
    table = {"width": SIZE, "height": SIZE, "scenes": {"s": {"shares": shares}},
             "rows": [{"scene": "s", "candidate": "RTXGI", "relmse": 0.01, "ms": 1.0},
                      {"scene": "s", "candidate": "DIRECT", "relmse": 0.2, "ms": 0.1}]}
    monkeypatch.setattr(auto, "load_table", lambda *a, **k: table)
    sc = demo_scenes.build_demo("cornell", resolution=SIZE)
    key = "auto_replan_" + request.node.name
    try:
        sd = _export(sc)
        rtxgi = session.render(sd, "AUTO", 0, 6, session=key, auto={"candidate": "RTXGI"})
        yield sd, key, 0.6 * rtxgi.frame_ms
    finally:
        session.release_session(key)
        bpy.data.scenes.remove(sc)


def test_a_candidate_measured_over_the_budget_is_replaced_in_the_same_render(mispredicted_cornell):
    """At that budget AUTO starts RTXGI, measures it over the budget, keeps the scene's cost
    factor and finishes the render with DIRECT (the samples asked for, a finite image); the
    next render of the scene plans DIRECT from the start."""
    sd, key, budget = mispredicted_cornell
    res = session.render(sd, "AUTO", 0, 6, session=key, auto={"budget_ms": budget})
    assert res.auto["candidate"] == "DIRECT", res.auto["notes"]
    assert any(n.startswith("re-planned: RTXGI") for n in res.auto["notes"]), res.auto["notes"]
    assert res.samples == 6 and np.isfinite(res.image).all()
    again = session.render(sd, "AUTO", 0, 2, session=key, auto={"budget_ms": budget})
    assert again.auto["candidate"] == "DIRECT"
    assert any(n.startswith("predicted costs x") for n in again.auto["notes"]), again.auto["notes"]
    assert not any(n.startswith("re-planned") for n in again.auto["notes"])


def test_viewport_redraws_over_the_budget_plan_again(mispredicted_cornell):
    """The viewport renders one frame per redraw, so no render has frames of its own to
    measure: the session keeps the latest four frames of the candidate, and once they measure
    over the budget the next redraw runs the candidate the cost factor gives."""
    sd, key, budget_ms = mispredicted_cornell
    budget = {"budget_ms": budget_ms}
    seen = []
    for _ in range(8):
        r = session.render(sd, "AUTO", 0, 1, session=key, keep_history=True, continue_accumulation=True,
                           auto=budget)
        assert np.isfinite(r.image).all()
        seen.append(r.auto["candidate"])
    assert seen[:3] == ["RTXGI"] * 3 and seen[-1] == "DIRECT", seen
    # an artist's edit (a light moved) keeps the measured factor: no return to RTXGI
    sd.lights[0].matrix = sd.lights[0].matrix.copy()
    sd.lights[0].matrix[0, 3] += 0.05
    r = session.render(sd, "AUTO", 0, 1, session=key, keep_history=True, auto=budget)
    assert r.auto["candidate"] == "DIRECT"
    assert any(n.startswith("predicted costs x") for n in r.auto["notes"]), r.auto["notes"]
