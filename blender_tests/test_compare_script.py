"""The batch comparison script end to end, and the Compare operator (bpy + GL)."""
import base64
import json
import math
import os
import re
import subprocess
import sys
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


@needs_renderer
def test_gi_compare_cornell(tmp_path):
    out = tmp_path / "out"
    env = dict(os.environ)
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")  # hermetic reference cache
    cmd = [sys.executable, str(SCRIPT), "cornell", "--techniques", "DIRECT", "--res", "64",
           "--ref-spp", "64", "--frames", "2", "--quality", "0,1", "--out", str(out)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert "[gi_compare" in p.stdout  # progress lines
    res = json.loads((out / "results.json").read_text())
    assert res["reference"]["spp"] == 64 and _finite(res["reference"]["time_ms"])
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
    d = {e["quality"]: e for e in entries if e["reference"] == "direct"}
    f = {e["quality"]: e for e in entries if e["reference"] == "full"}
    assert d[1]["relmse"] < f[1]["relmse"]  # the direct reference fits a direct-light technique better
    assert len(res["speedup"]) == len(entries)
    for name in ("DIRECT_q0.exr", "DIRECT_q0.png", "DIRECT_q1_vs_full_error.png", "reference_full.exr",
                 "chart.svg", "report.html"):
        assert (out / name).exists(), name
    html = (out / "report.html").read_text()
    imgs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(imgs) >= 1 + 2 * 3  # references + (ours, Cycles, error) per entry
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in imgs)
    assert "<svg" in html and "DIRECT q1" in html


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
