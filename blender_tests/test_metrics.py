"""Metrics, heat map and the equal-error speed-up (bpy-free)."""
import math
import os
import sys
import tempfile

import numpy as np
import pytest

try:
    import gi_preview  # noqa: F401  (conftest puts the package on sys.path)
except ImportError:  # running this file without the conftest
    _d = tempfile.mkdtemp(prefix="gi_preview_pkg_")
    os.symlink(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "addon"),
               os.path.join(_d, "gi_preview"))
    sys.path.insert(0, _d)

from gi_preview.compare import metrics, sweep  # noqa: E402


def _img(h=32, w=40, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.random((h, w, 4)) * 2.0).astype(np.float32)


def test_identical_is_zero():
    a = _img()
    r = metrics.compare(a, a.copy())
    assert r["relmse"] == 0.0
    assert r["flip"] == pytest.approx(0.0, abs=1e-7)
    assert r["ssim"] == pytest.approx(1.0, abs=1e-9)
    assert r["psnr"] == math.inf
    assert r["nonfinite_pixels"] == 0


def test_known_relmse():
    ref = np.full((16, 16, 3), 0.5, np.float32)
    test = ref * 1.1
    expected = (0.05 ** 2) / (0.25 + 1e-2)
    assert metrics.relmse(test, ref) == pytest.approx(expected, rel=1e-5)
    # alpha is ignored
    ref4 = np.concatenate([ref, np.zeros((16, 16, 1), np.float32)], axis=2)
    test4 = np.concatenate([test, np.ones((16, 16, 1), np.float32)], axis=2)
    assert metrics.relmse(test4, ref4) == pytest.approx(expected, rel=1e-5)


def test_mask_restricts_pixels():
    ref = np.full((8, 8, 3), 1.0, np.float32)
    test = ref.copy()
    test[:4] = 2.0
    mask = np.zeros((8, 8), bool)
    mask[4:] = True
    assert metrics.relmse(test, ref, mask=mask) == 0.0
    assert metrics.relmse(test, ref, mask=~mask) == pytest.approx(1.0 / 1.01)


def test_flip_equals_package():
    import flip_evaluator
    ref = _img(seed=1)
    test = ref * np.float32(1.2) + np.float32(0.05)
    _, mean_hdr, _ = flip_evaluator.evaluate(ref[:, :, :3].copy(), test[:, :, :3].copy(), "HDR",
                                             inputsRGB=False, applyMagma=False, computeMeanError=True)
    assert metrics.flip(test, ref) == pytest.approx(mean_hdr, rel=1e-5)
    lt, lr = metrics.view_standard(test).astype(np.float32), metrics.view_standard(ref).astype(np.float32)
    _, mean_ldr, _ = flip_evaluator.evaluate(lr, lt, "LDR", inputsRGB=True, applyMagma=False,
                                             computeMeanError=True)
    assert metrics.flip(test, ref, mode="LDR") == pytest.approx(mean_ldr, rel=1e-5)


def test_nonfinite_counted_and_excluded():
    ref = np.full((16, 16, 3), 0.5, np.float32)
    test = ref * 1.1
    test[0, 0, 0] = np.nan
    test[3, 5, 2] = np.inf
    test[7, 7, 1] = -np.inf
    r = metrics.compare(test, ref)
    assert r["nonfinite_pixels"] == 3
    assert r["valid_pixels"] == 256 - 3
    assert r["relmse"] == pytest.approx((0.05 ** 2) / 0.26, rel=1e-5)
    for k in ("flip", "flip_ldr", "ssim", "psnr"):
        assert math.isfinite(r[k]), k
    assert np.isnan(metrics.relmse_map(test, ref)[0, 0])


def test_ssim_drops_with_noise_and_psnr_known():
    ref = np.full((32, 32, 3), 0.18, np.float32)
    ref[:, 16:] = 0.5
    assert metrics.ssim(ref, ref) == pytest.approx(1.0)
    noisy = ref + np.random.default_rng(3).normal(0, 0.05, ref.shape).astype(np.float32)
    assert metrics.ssim(noisy, ref) < 0.95
    # PSNR on LDR-mapped values: a uniform offset of d in encoded space -> 20 log10(1/d)
    a = np.full((8, 8, 3), 0.2, np.float32)
    b = np.full((8, 8, 3), 0.3, np.float32)
    d = float(metrics.srgb_oetf(np.array(0.3)) - metrics.srgb_oetf(np.array(0.2)))
    assert metrics.psnr(a, b) == pytest.approx(20 * math.log10(1 / d), rel=1e-6)


def test_ssim_small_image():
    a = _img(6, 7)
    assert metrics.ssim(a, a) == pytest.approx(1.0)


def test_heatmap_shape_and_range():
    ref = _img(20, 30, seed=2)
    test = ref.copy()
    test[5:10] *= 3.0
    test[0, 0] = np.nan
    img, legend = metrics.heatmap(test, ref)
    assert img.shape == (20, 30, 3) and img.dtype == np.float32
    assert img.min() >= 0.0 and img.max() <= 1.0
    assert tuple(img[0, 0]) == metrics.NONFINITE_COLOR
    assert legend["vmin"] < legend["vmax"] and legend["scale"] == "log10"
    # zero error -> the low end of the map, large error -> the high end
    assert np.allclose(img[15, 15], metrics.colormap(0.0))
    assert img[7, 7].sum() > img[15, 15].sum()
    bar = metrics.colorbar(64, 4)
    assert bar.shape == (4, 64, 3)


def test_effects_per_aov():
    ref = _img(seed=4)
    t_aovs = {"GI_AO": np.full((32, 40, 1), 0.5, np.float32), "Only_test": ref}
    r_aovs = {"GI_AO": np.full((32, 40, 1), 0.5, np.float32)}
    r = metrics.compare(ref, ref, test_aovs=t_aovs, ref_aovs=r_aovs, with_flip=False)
    assert list(r["effects"]) == ["GI_AO"]
    assert r["effects"]["GI_AO"]["relmse"] == 0.0


def test_size_mismatch_raises():
    with pytest.raises(ValueError):
        metrics.relmse(_img(8, 8), _img(8, 9))


# ---------------------------------------------------------------- sweep
def _cycles_curve():
    # error = 1/spp (ideal Monte Carlo), time = 10 ms * spp
    return [(spp, 10.0 * spp, 1.0 / spp) for spp in (1, 2, 4, 8, 16, 32)]


def test_speedup_on_synthetic_curve():
    s = sweep.equal_error_speedup(0.25, 2.0, _cycles_curve())
    # Cycles reaches error 0.25 at 4 spp = 40 ms -> 40 / 2 = 20x
    assert s["cycles_time_ms"] == pytest.approx(40.0, rel=1e-9)
    assert s["speedup"] == pytest.approx(20.0, rel=1e-9)
    # between points: log-log interpolation, error 1/6 -> 60 ms (exact for a power law)
    s = sweep.equal_error_speedup(1.0 / 6.0, 3.0, _cycles_curve())
    assert s["cycles_time_ms"] == pytest.approx(60.0, rel=1e-9)
    assert s["speedup"] == pytest.approx(20.0, rel=1e-9)


def test_speedup_outside_curve_is_none():
    below = sweep.equal_error_speedup(1e-3, 1.0, _cycles_curve())
    assert below["speedup"] is None and "below" in below["reason"]
    above = sweep.equal_error_speedup(5.0, 1.0, _cycles_curve())
    assert above["speedup"] is None and "above" in above["reason"]
    bad = sweep.equal_error_speedup(float("nan"), 1.0, _cycles_curve())
    assert bad["speedup"] is None
    # bounds: Cycles at 1 spp (10 ms) is already better -> at most 10/1 = 10x;
    # better than 32 spp (320 ms) -> at least 320/1 = 320x
    assert above["bound"] == {"at_most": pytest.approx(10.0)}
    assert below["bound"] == {"at_least": pytest.approx(320.0)}


def test_speedup_non_monotone_curve():
    # a noisy curve: error rises from 4 to 8 spp; monotone-ized (running minimum)
    curve = [(1, 10, 1.0), (2, 20, 0.5), (4, 40, 0.2), (8, 80, 0.3), (16, 160, 0.1)]
    mono = sweep.monotone_curve(curve)
    errs = [e for _, _, e in mono]
    assert all(a >= b for a, b in zip(errs, errs[1:]))
    s = sweep.equal_error_speedup(0.2, 4.0, curve)
    assert s["cycles_time_ms"] == pytest.approx(40.0)
    assert s["speedup"] == pytest.approx(10.0)


def test_chart_svg(tmp_path):
    points = [{"technique": "DIRECT", "quality": 0, "time_ms": 2.0, "error": 0.25},
              {"technique": "DIRECT", "quality": 1, "time_ms": 4.0, "error": 0.1}]
    svg = sweep.chart_svg(points, _cycles_curve(), metric="relMSE")
    assert svg.startswith("<svg") and "DIRECT q0" in svg and "Cycles" in svg
    path = sweep.write_chart(points, _cycles_curve(), str(tmp_path / "chart"), metric="relMSE")
    assert os.path.exists(path["svg"])


# ---------------------------------------------------------------- setup vs per-frame time
def test_fit_setup_recovers_setup_and_per_sample():
    pts = [(s, 150.0 + 12.5 * s) for s in (1, 2, 4, 8, 16)]
    f = sweep.fit_setup(pts)
    assert f["ok"] and f["n"] == 5
    assert f["setup_ms"] == pytest.approx(150.0, rel=1e-9)
    assert f["per_sample_ms"] == pytest.approx(12.5, rel=1e-9)
    assert f["max_rel_residual"] < 1e-9


def test_fit_setup_noisy_and_clamped():
    # +-5 % noise: setup and per-sample within 20 % of the truth
    rng = np.random.default_rng(3)
    pts = [(s, (300.0 + 40.0 * s) * (1 + 0.05 * rng.uniform(-1, 1))) for s in (1, 2, 4, 8, 16, 32)]
    f = sweep.fit_setup(pts)
    assert f["ok"]
    assert f["setup_ms"] == pytest.approx(300.0, rel=0.2)
    assert f["per_sample_ms"] == pytest.approx(40.0, rel=0.2)
    # pure per-sample cost (no setup): the intercept is clamped at 0, never negative
    f = sweep.fit_setup([(1, 9.0), (2, 21.0), (4, 40.0), (8, 82.0)])
    assert f["ok"] and f["setup_ms"] >= 0.0 and f["per_sample_ms"] == pytest.approx(10.0, rel=0.1)
    # the setup never exceeds the cheapest render
    f = sweep.fit_setup([(1, 100.0), (2, 100.5), (4, 101.0)])
    assert 0.0 <= f["setup_ms"] <= 100.0


def test_fit_setup_degenerate():
    one = sweep.fit_setup([(4, 100.0)])
    assert not one["ok"] and one["setup_ms"] == 0.0 and one["per_sample_ms"] == pytest.approx(25.0)
    flat = sweep.fit_setup([(1, 100.0), (2, 90.0), (4, 80.0)])  # times fall with spp: no split
    assert not flat["ok"] and flat["setup_ms"] == 0.0 and "grow" in flat["reason"]
    assert not sweep.fit_setup([])["ok"]


def test_speedup_names_the_baseline():
    s = sweep.equal_error_speedup(5.0, 1.0, _cycles_curve(), name="EEVEE (ray tracing)")
    assert s["speedup"] is None and "EEVEE (ray tracing)" in s["reason"]
    s = sweep.equal_error_speedup(0.25, 2.0, _cycles_curve(), name="EEVEE (ray tracing)")
    assert s["speedup"] == pytest.approx(20.0) and "EEVEE" in s["reason"]


def test_chart_every_baseline(tmp_path):
    points = [{"technique": "SSDO", "quality": 1, "time_ms": 3.0, "error": 0.2}]
    curves = {"Cycles (spp)": _cycles_curve(),
              "Cycles + OIDN (spp)": [(1, 30.0, 0.3), (4, 60.0, 0.05)],
              "EEVEE ray tracing (samples)": [(1, 400.0, 0.4), (8, 900.0, 0.2)]}
    svg = sweep.chart_svg(points, curves)
    for label in curves:
        assert label in svg
    # three curves: three stroked paths with three different styles (solid, dashed, dotted)
    assert svg.count('stroke-width="2"') >= 3
    assert 'stroke-dasharray="7 3"' in svg and 'stroke-dasharray="2 3"' in svg
    out = sweep.write_chart(points, curves, str(tmp_path / "c"))
    assert os.path.exists(out["svg"])


def test_report_speedup_table_per_baseline():
    from gi_preview.compare import report
    sp = {"cycles": {"speedup": 2.0, "cycles_spp": 4.0, "reason": "interpolated"},
          "cycles_denoised": {"speedup": None, "reason": "error above Cycles + OpenImageDenoise's curve",
                              "bound": {"at_most": 0.75}},
          "eevee": {"speedup": 0.5, "cycles_spp": 2.0, "reason": "interpolated"}}
    results = {"reference": {"kind": "full", "spp": 64},
               "entries": [{"technique": "SSDO", "quality": 1, "reference": "full", "time_ms": 5.0,
                            "setup_ms": 1234.0, "setup_warm_ms": 56.0, "relmse": 0.1, "speedup": sp["cycles"],
                            "speedups": sp}],
               "baselines": {"cycles": [{"spp": 1, "time_ms": 1.0, "wall_ms": 2.0, "relmse": 0.5}],
                             "cycles_denoised": [{"spp": 1, "time_ms": 3.0, "wall_ms": 4.0, "relmse": 0.05}],
                             "eevee": [{"spp": 1, "time_ms": 5.0, "wall_ms": 9.0, "relmse": 0.2}]},
               "baselines_setup": {"eevee": {"setup_ms": 4.0, "per_sample_ms": 5.0, "first_render_extra_ms": 30000}}}
    h = report.build_html(title="t", results=results)
    assert "Equal-error speed-ups" in h
    for label in ("vs Cycles<", "vs Cycles + OpenImageDenoise", "vs EEVEE (ray tracing)"):
        assert label in h, label
    assert "2&times;" in h and "0.5&times;" in h and "&le;&thinsp;0.75&times;" in h
    assert ">1234 / 56<" in h  # the setup column: cold / warm
    assert "first render +30000 ms" in h
