"""The batch comparison script end to end, and the Compare operator (bpy + GL)."""
import base64
import json
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "gi_compare.py"


def _have(path):
    return (REPO / path).exists()


needs_renderer = pytest.mark.skipif(
    not (_have("addon/render/session.py") and _have("addon/blender/demo_scenes.py")),
    reason="session.py / demo_scenes.py not there yet")


def _finite(v):
    return isinstance(v, (int, float)) and math.isfinite(v)


def _load_script():
    """scripts/gi_compare.py as a module (it is a script, not part of the package)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("gi_compare_script", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@needs_renderer
def test_gi_compare_cornell(tmp_path, monkeypatch, capsys):
    """The script's own entry point ``main()`` with a command line (argument parsing, the
    checkout's add-on, every baseline, the report), run in this process: the interpreter,
    Blender's start-up and the GL thread/context are shared with the other tests instead of
    paid again in a child process (EEVEE's first render of this scene, ~35 s on llvmpipe, is
    paid here either way). The script as a separate process is exercised by
    test_gi_compare_reports_missing_opengl."""
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # hermetic reference cache
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), "cornell", "--techniques", "DIRECT", "--res", "64",
                                      "--ref-spp", "64", "--frames", "2", "--quality", "0,1",
                                      "--eevee-samples", "1,2,4", "--ttq", "1,2,4",
                                      "--cache", str(tmp_path / "refs"), "--out", str(out)])
    _load_script().main()  # a failure raises (SystemExit for a usage or GL error)
    assert "[gi_compare" in capsys.readouterr().out  # progress lines
    res = json.loads((out / "results.json").read_text())
    assert res["reference"]["spp"] == 64 and _finite(res["reference"]["time_ms"])
    assert res["reference"]["cached"] is False  # rendered by this run
    assert res["reference"]["kind"] == "full"
    curve = res["cycles_curve"]
    assert [c["spp"] for c in curve] == [1, 2, 4, 8, 16]
    for c in curve:
        assert _finite(c["time_ms"]) and _finite(c["relmse"]) and _finite(c["flip"])
    entries = res["results"]
    # auto: DIRECT against the direct reference and against full, two quality levels
    assert {(e["quality"], e["reference"]) for e in entries} == {(0, "direct"), (0, "full"),
                                                                 (1, "direct"), (1, "full")}
    for e in entries:
        assert e["technique"] == "DIRECT"
        for k in ("time_ms", "relmse", "flip", "ssim"):
            assert _finite(e[k]), (k, e[k])
        assert e["nonfinite_pixels"] == 0
        assert isinstance(e["effects"], list) and isinstance(e["skipped_passes"], list)
        assert "speedup" in e["speedup"] and "reason" in e["speedup"]
        assert 0 <= e["relmse"] and 0 <= e["flip"] <= 1 and -1 <= e["ssim"] <= 1
    _check_setup_and_baselines(res, out)
    d = {e["quality"]: e for e in entries if e["reference"] == "direct"}
    f = {e["quality"]: e for e in entries if e["reference"] == "full"}
    assert d[1]["relmse"] < f[1]["relmse"]  # the direct reference fits a direct-light technique better
    assert len(res["speedup"]) == len(entries)
    for name in ("DIRECT_q0.exr", "DIRECT_q0.png", "DIRECT_q1_vs_full_error.png", "reference_full.exr",
                 "chart.svg", "time_to_quality.svg", "report.html"):
        assert (out / name).exists(), name
    html = (out / "report.html").read_text()
    imgs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(imgs) >= 1 + 2 * 3  # references + (ours, Cycles, error) per entry
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in imgs)
    assert "<svg" in html and "DIRECT q1" in html


def _check_setup_and_baselines(res, out):
    """The public contract of the results: setup_ms per row, baselines.{cycles, cycles_denoised,
    eevee} with {spp, time_ms, relmse, flip, ssim}, per-frame times without setup, and an
    equal-error speed-up (or its bound) against every baseline."""
    for e in res["results"]:
        assert _finite(e["setup_ms"]) and e["setup_ms"] > 0, e["setup_ms"]
        assert e["setup"]["export_ms"] > 0 and e["setup"]["renderer_ms"] >= 0
        assert e["setup_ms"] == pytest.approx(e["setup"]["export_ms"] + e["setup"]["renderer_ms"])
        # time_ms: one render after setup (warm-up and read-back counted), the frames within it
        c = e["cost"]
        assert e["time_ms"] == pytest.approx(c["render_ms"]) and e["setup_ms"] == pytest.approx(c["setup_cold_ms"])
        assert e["frames_ms"] == pytest.approx(e["frame_ms"] * e["samples"])
        assert e["frames_ms"] <= e["time_ms"] * 1.05, e
        # cold: the driver's shader cache cannot serve the programs (salted source), so the
        # first render compiles everything; warm: the same programs again from that cache
        assert c["first_render_cold_ms"] > c["first_render_warm_ms"], c
        assert e["setup_warm_ms"] < e["setup_ms"], c
        assert _finite(c["viewport_frame_ms"]) and c["viewport_frame_ms"] > 0, c
        ttq = e["time_to_quality"]
        assert [p["samples"] for p in ttq] == [1, 2, 4]
        assert all(b["time_ms"] > a["time_ms"] for a, b in zip(ttq, ttq[1:])), ttq
        assert all(_finite(p["relmse"]) for p in ttq)
        print(f"{e['technique']} q{e['quality']} vs {e['reference']}: {e['time_ms']:.1f} ms, "
              f"setup {e['setup_ms']:.0f} ms, relMSE {e['relmse']:.4g}")
    b = res["baselines"]
    assert set(b) == {"cycles", "cycles_denoised", "eevee"}
    assert [p["spp"] for p in b["cycles"]] == [1, 2, 4, 8, 16]
    assert [p["spp"] for p in b["cycles_denoised"]] == [1, 2, 4, 8, 16]
    assert [p["spp"] for p in b["eevee"]] == [1, 2, 4]
    assert b["cycles"] == res["cycles_curve"]  # the old top-level key stays, same numbers
    for name, pts in b.items():
        setup = res["baselines_setup"][name]
        assert _finite(setup["setup_ms"]) and setup["setup_ms"] >= 0
        for p in pts:
            for k in ("spp", "time_ms", "relmse", "flip", "ssim"):
                assert _finite(p[k]), (name, k, p)
            assert 0 < p["time_ms"] <= p["wall_ms"] * 1.5 + 1.0, (name, p)  # setup left out
            assert p["setup_ms"] == pytest.approx(setup["setup_ms"])
            print(f"{name} {p['spp']:>2} spp: {p['time_ms']:8.1f} ms/frame ({p['wall_ms']:.0f} ms wall), "
                  f"relMSE {p['relmse']:.4g}")
    # EEVEE compiles shaders in its first renders: measured, and kept out of every point
    assert res["baselines_setup"]["eevee"]["warmup_renders"] == 2
    # the denoiser does what it is for: at 16 spp far closer to the reference than plain Cycles
    assert b["cycles_denoised"][-1]["relmse"] < 0.5 * b["cycles"][-1]["relmse"]
    # EEVEE's ray-traced GI recovers indirect light that DIRECT (direct light only) lacks
    direct_full = min(e["relmse"] for e in res["results"] if e["reference"] == "full")
    assert b["eevee"][-1]["relmse"] < direct_full
    for e in res["results"]:
        sps = e["speedups"]
        assert set(sps) == ({"cycles", "cycles_denoised", "eevee"} if e["reference"] == "full" else {"cycles"})
        for name, s in sps.items():
            assert s["speedup"] is not None or s["bound"] or s["reason"], (name, s)
            if s["speedup"] is not None:
                assert s["speedup"] > 0
    assert {(s["baseline"]) for s in res["speedups"]} == {"cycles", "cycles_denoised", "eevee"}
    svg = (out / "chart.svg").read_text()
    for label in ("Cycles (spp)", "Cycles + OIDN (spp)", "EEVEE ray tracing (samples)"):
        assert label in svg
    html = (out / "report.html").read_text()
    assert "Equal-error speed-ups" in html and "vs EEVEE (ray tracing)" in html and "setup ms" in html
    assert (out / "baseline_eevee_4spp.png").exists()


GL_MISSING = "GI Preview needs OpenGL 4.9"


@needs_renderer
def test_gi_compare_reports_missing_opengl(tmp_path):
    """Without OpenGL 4.3 (here: 4.9 demanded) the batch script stops at once with the
    engine's message and the apt-get hint, exit status 2, no traceback, no Cycles work."""
    env = dict(os.environ, GI_PREVIEW_GL_REQUIRE="490", XDG_CACHE_HOME=str(tmp_path / "cache"))
    p = subprocess.run([sys.executable, str(SCRIPT), "cornell", "--techniques", "DIRECT", "--res", "16",
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 2, (p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    assert f"gi_compare: {GL_MISSING}" in p.stderr and "libegl1" in p.stderr, p.stderr[-2000:]
    assert "Traceback" not in p.stderr
    assert "Cycles reference" not in p.stdout  # failed before any Cycles render


@needs_renderer
def test_compare_operator_reports_missing_opengl(tmp_path):
    """The Compare with Cycles operator reports the missing OpenGL as its error."""
    code = textwrap.dedent(f"""
        import os, sys
        os.environ["GI_PREVIEW_GL_REQUIRE"] = "490"
        sys.path.insert(0, {str(Path(__import__("gi_preview").__file__).parent.parent)!r})
        import bpy, gi_preview
        gi_preview.register()
        from gi_preview.blender.demo_scenes import build_demo
        sc = build_demo("cornell", resolution=16)
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            try:
                bpy.ops.gi_preview.compare("EXEC_DEFAULT", ref_spp=4, use_cache=False)
                print("NO ERROR")
            except RuntimeError as exc:
                print("ERROR:", exc)
        print("ENGINE", sc.render.engine)
        print("ALIVE")
    """)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path), XDG_CACHE_HOME=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    text = out.stdout + out.stderr
    assert "ALIVE" in text, text[-2000:]
    assert f"Compare with Cycles failed: {GL_MISSING}" in text, text[-2000:]
    assert "libegl1" in text
    assert "ENGINE GI_PREVIEW" in text  # the scene's engine untouched


@needs_renderer
def test_compare_operator(tmp_path, monkeypatch):
    bpy = pytest.importorskip("bpy")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    import gi_preview
    from gi_preview.blender import compare_ops, demo_scenes
    from gi_preview.compare import imageio
    sc = demo_scenes.build_demo("cornell", resolution=32)
    try:
        with bpy.context.temp_override(scene=sc, view_layer=sc.view_layers[0]):
            r = bpy.ops.gi_preview.compare("EXEC_DEFAULT", ref_spp=8)
        assert r == {"FINISHED"}
        for name in (compare_ops.IMG_RESULT, compare_ops.IMG_CYCLES, compare_ops.IMG_ERROR,
                     compare_ops.IMG_SPLIT):
            img = bpy.data.images[name]
            assert tuple(img.size) == (32, 32)
        stored = compare_ops.load_results(sc)
        tech = sc.gi_preview_comparison.last_technique
        assert tech in stored and _finite(stored[tech]["relmse"]) and _finite(stored[tech]["flip"])
        # the panel's ms/frame and setup ms (export + GPU upload/BVH/compile), kept apart
        assert _finite(stored[tech]["ms_per_frame"]) and stored[tech]["ms_per_frame"] > 0
        assert _finite(stored[tech]["setup_ms"]) and stored[tech]["setup_ms"] > 0
        # render slots 1-3 hold GI Preview, Cycles and the error map (J flips between them)
        rr = bpy.data.images["Render Result"]
        assert [rr.render_slots[i].name for i in range(3)] == list(compare_ops.SLOT_LABELS)
        s = sc.render.image_settings
        s.media_type, s.file_format, s.color_depth = "IMAGE", "OPEN_EXR", "32"
        expected = [np.array(bpy.data.images[n].pixels[:], np.float32).reshape(32, 32, 4)
                    for n in (compare_ops.IMG_RESULT, compare_ops.IMG_CYCLES)]
        for i, exp in enumerate(expected):
            rr.render_slots.active_index = i
            path = str(tmp_path / f"slot{i}.exr")
            rr.save_render(path, scene=sc)
            got = imageio.read_exr(path)
            assert np.allclose(got[..., :3], exp[..., :3], atol=1e-3), f"slot {i + 1}"
        assert sc.render.engine == "GI_PREVIEW"
    finally:
        bpy.data.scenes.remove(sc)


def test_baseline_arguments():
    """--baselines / --eevee-samples / --denoised-curve: defaults, 'none', bad values."""
    mod = _load_script()
    a = mod.parse_args(["cornell"], scene_optional=False)
    assert a.baselines == ["cycles", "cycles_denoised", "eevee"]
    assert a.curve == [1, 2, 4, 8, 16, 32, 64] and a.denoised_curve == a.curve
    assert a.eevee_samples == [1, 2, 4, 8]
    a = mod.parse_args(["cornell", "--baselines", "none", "--ref-spp", "16"], scene_optional=False)
    assert a.baselines == ["cycles"] and a.curve == [1, 2, 4]
    a = mod.parse_args(["cornell", "--baselines", "eevee", "--eevee-samples", "4,1,4",
                        "--denoised-curve", "2,8"], scene_optional=False)
    assert a.baselines == ["cycles", "eevee"] and a.eevee_samples == [1, 4] and a.denoised_curve == [2, 8]
    for bad in (["--baselines", "eevee,unbiased"], ["--eevee-samples", "0,2"], ["--denoised-curve", "x"]):
        with pytest.raises(SystemExit):
            mod.parse_args(["cornell", *bad], scene_optional=False)
