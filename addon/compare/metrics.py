"""Image metrics for comparing a GI Preview frame with a Cycles reference (bpy-free).

All inputs are linear scene-referred images, (H, W, C) with C = 1, 3 or 4 (alpha is
ignored), in the same orientation. The reference is always the second argument.

Metrics
-------
* ``relmse``: relative MSE ``(a - b)^2 / (b^2 + 1e-2)``, averaged over valid pixels and the
  three RGB channels, on linear HDR values. Pixels where either image is non-finite
  (NaN/Inf in any RGB channel) are *excluded* and counted separately
  (``nonfinite_pixels``); they never turn a mean into NaN.
* ``flip``: mean FLIP error (NVIDIA FLIP, package ``flip-evaluator``), HDR-FLIP on the
  linear images (negative and non-finite values set to 0 first, masked/non-finite pixels
  left out of the mean). ``flip_ldr``: LDR-FLIP on the images after the view transform.
* ``ssim``: SSIM on the luminance (Rec.709 weights) of the view-transformed (LDR, sRGB
  encoded) images, Gaussian window 11x11, sigma 1.5, K1 = 0.01, K2 = 0.03, L = 1, computed
  over the "valid" region (windows fully inside the image), like Wang et al. 2004.
* ``psnr``: PSNR in dB of the view-transformed RGB images (peak 1.0).

The view transform
------------------
``view_standard(img, exposure=0)`` is Blender's "Standard" view transform reduced to what
matters for a metric: scale by ``2**exposure``, apply the sRGB OETF (piecewise: 12.92 x below
0.0031308, ``1.055 x^(1/2.4) - 0.055`` above), clamp to [0, 1]. No look, no curve, no
dithering. LDR metrics (SSIM, PSNR, LDR-FLIP) use it unless another function is passed as
``view=``.
"""
from __future__ import annotations

import math

import numpy as np

EPS_RELMSE = 1e-2
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float64)


# ---------------------------------------------------------------- helpers
def _rgb(img) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"expected an (H, W, C) image, got shape {a.shape}")
    c = a.shape[2]
    if c == 1:
        a = np.repeat(a, 3, axis=2)
    elif c == 2:
        a = np.concatenate([a, a[:, :, :1]], axis=2)
    else:
        a = a[:, :, :3]
    return a.astype(np.float64, copy=False)


def _check_same(test: np.ndarray, ref: np.ndarray):
    if test.shape[:2] != ref.shape[:2]:
        raise ValueError(f"image sizes differ: test {test.shape[:2]} vs reference {ref.shape[:2]}")


def finite_mask(img) -> np.ndarray:
    """(H, W) bool: True where all RGB channels are finite."""
    return np.all(np.isfinite(_rgb(img)), axis=2)


def nonfinite_count(img) -> int:
    """Number of pixels with a NaN or Inf in any RGB channel."""
    return int((~finite_mask(img)).sum())


def _valid(test, ref, mask) -> np.ndarray:
    v = finite_mask(test) & finite_mask(ref)
    if mask is not None:
        m = np.asarray(mask)
        if m.ndim == 3:
            m = m[:, :, 0]
        if m.shape != v.shape:
            raise ValueError(f"mask shape {m.shape} does not match image {v.shape}")
        v &= m.astype(bool)
    return v


def _clean(a: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(a), a, 0.0)


# ---------------------------------------------------------------- view transform
def srgb_oetf(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (linear -> encoded), for x >= 0."""
    x = np.maximum(x, 0.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def view_standard(img, exposure: float = 0.0) -> np.ndarray:
    """Blender's "Standard" view (sRGB OETF) with exposure, clamped to [0, 1]; RGB float64.

    Non-finite values become 0."""
    a = _clean(_rgb(img)) * (2.0 ** exposure)
    return np.clip(srgb_oetf(a), 0.0, 1.0)


# ---------------------------------------------------------------- relMSE
def relmse_map(test, ref) -> np.ndarray:
    """(H, W) per-pixel relMSE (mean over RGB); NaN where either pixel is non-finite."""
    t, r = _rgb(test), _rgb(ref)
    _check_same(t, r)
    with np.errstate(invalid="ignore", over="ignore"):
        m = np.mean((t - r) ** 2 / (r * r + EPS_RELMSE), axis=2)
    m[~(finite_mask(t) & finite_mask(r))] = np.nan
    return m


def relmse(test, ref, mask=None) -> float:
    """Mean relMSE over valid pixels and RGB channels (NaN if no pixel is valid)."""
    m = relmse_map(test, ref)
    v = _valid(test, ref, mask)
    if not v.any():
        return float("nan")
    return float(np.mean(m[v]))


# ---------------------------------------------------------------- PSNR
def psnr(test, ref, mask=None, view=view_standard) -> float:
    """PSNR (dB) of the view-transformed images, peak 1.0; inf when identical."""
    t, r = view(test), view(ref)
    _check_same(t, r)
    v = _valid(test, ref, mask)
    if not v.any():
        return float("nan")
    mse = float(np.mean((t[v] - r[v]) ** 2))
    if mse <= 0.0:
        return float("inf")
    return 10.0 * math.log10(1.0 / mse)


# ---------------------------------------------------------------- SSIM
def _gauss_kernel(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    k = np.exp(-(x * x) / (2.0 * sigma * sigma))
    return k / k.sum()


def _filter_valid(img: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Separable 'valid' convolution of a 2-D image with a 1-D symmetric kernel."""
    n = k.shape[0]
    h, w = img.shape
    tmp = np.zeros((h, w - n + 1))
    for i in range(n):
        tmp += k[i] * img[:, i:i + w - n + 1]
    out = np.zeros((h - n + 1, w - n + 1))
    for i in range(n):
        out += k[i] * tmp[i:i + h - n + 1, :]
    return out


def ssim_map(test, ref, view=view_standard, window: int = 11, sigma: float = 1.5) -> np.ndarray:
    """SSIM map on luminance of the view-transformed images, valid region only.

    Shape (H - window + 1, W - window + 1); for images smaller than the window the window
    shrinks to the largest odd size that fits."""
    yt = view(test) @ LUMA
    yr = view(ref) @ LUMA
    _check_same(yt, yr)
    window = min(window, yt.shape[0] - (1 - yt.shape[0] % 2), yt.shape[1] - (1 - yt.shape[1] % 2))
    window = max(window, 1)
    k = _gauss_kernel(window, sigma)
    c1 = (0.01 * 1.0) ** 2
    c2 = (0.03 * 1.0) ** 2
    mu_t = _filter_valid(yt, k)
    mu_r = _filter_valid(yr, k)
    s_tt = _filter_valid(yt * yt, k) - mu_t * mu_t
    s_rr = _filter_valid(yr * yr, k) - mu_r * mu_r
    s_tr = _filter_valid(yt * yr, k) - mu_t * mu_r
    num = (2 * mu_t * mu_r + c1) * (2 * s_tr + c2)
    den = (mu_t ** 2 + mu_r ** 2 + c1) * (s_tt + s_rr + c2)
    return num / den


def ssim(test, ref, mask=None, view=view_standard) -> float:
    """Mean SSIM; windows whose centre pixel is masked out or non-finite are left out."""
    m = ssim_map(test, ref, view=view)
    v = _valid(test, ref, mask)
    oy = (v.shape[0] - m.shape[0]) // 2
    ox = (v.shape[1] - m.shape[1]) // 2
    vc = v[oy:oy + m.shape[0], ox:ox + m.shape[1]]
    if not vc.any():
        return float("nan")
    return float(np.mean(m[vc]))


# ---------------------------------------------------------------- FLIP
def _flip_module():
    try:
        import flip_evaluator  # noqa: WPS433 (lazy: heavy, optional)
    except ImportError as e:  # pragma: no cover - depends on the install
        raise ImportError("FLIP needs the 'flip-evaluator' package (pip install flip-evaluator)") from e
    return flip_evaluator


def flip_map(test, ref, mode: str = "HDR", view=view_standard) -> np.ndarray:
    """(H, W) FLIP error map. HDR: linear inputs (non-finite -> 0, negatives -> 0).
    LDR: the view-transformed images (already sRGB encoded)."""
    fe = _flip_module()
    if mode.upper() == "HDR":
        t = np.maximum(_clean(_rgb(test)), 0.0).astype(np.float32)
        r = np.maximum(_clean(_rgb(ref)), 0.0).astype(np.float32)
        emap, _, _ = fe.evaluate(np.ascontiguousarray(r), np.ascontiguousarray(t), "HDR",
                                 inputsRGB=False, applyMagma=False, computeMeanError=False)
    elif mode.upper() == "LDR":
        t = view(test).astype(np.float32)
        r = view(ref).astype(np.float32)
        emap, _, _ = fe.evaluate(np.ascontiguousarray(r), np.ascontiguousarray(t), "LDR",
                                 inputsRGB=True, applyMagma=False, computeMeanError=False)
    else:
        raise ValueError(f"FLIP mode must be 'HDR' or 'LDR', not {mode!r}")
    emap = np.asarray(emap)
    if emap.ndim == 3:
        emap = emap[:, :, 0]
    return emap.astype(np.float64)


def flip(test, ref, mask=None, mode: str = "HDR", view=view_standard) -> float:
    """Mean FLIP error over valid pixels (equals the package's own mean when all are valid)."""
    _check_same(_rgb(test), _rgb(ref))
    v = _valid(test, ref, mask)
    if not v.any():
        return float("nan")
    return float(np.mean(flip_map(test, ref, mode, view)[v]))


# ---------------------------------------------------------------- heat map
# Viridis (matplotlib's perceptually uniform map), 17 samples, linear interpolation between.
_VIRIDIS = np.array([
    [0.267004, 0.004874, 0.329415], [0.282623, 0.140926, 0.457517],
    [0.253935, 0.265254, 0.529983], [0.206756, 0.371758, 0.553117],
    [0.163625, 0.471133, 0.558148], [0.127568, 0.566949, 0.550556],
    [0.134692, 0.658636, 0.517649], [0.266941, 0.748751, 0.440573],
    [0.477504, 0.821444, 0.318195], [0.741388, 0.873449, 0.149561],
    [0.993248, 0.906157, 0.143936],
], np.float64)
NONFINITE_COLOR = (1.0, 0.0, 1.0)  # magenta: not in viridis


def colormap(t: np.ndarray) -> np.ndarray:
    """Viridis for t in [0, 1] (clamped); returns (..., 3) float in [0, 1] (sRGB encoded)."""
    t = np.clip(np.nan_to_num(np.asarray(t, np.float64), nan=0.0), 0.0, 1.0)
    x = t * (len(_VIRIDIS) - 1)
    i = np.minimum(np.floor(x).astype(int), len(_VIRIDIS) - 2)
    f = (x - i)[..., None]
    return _VIRIDIS[i] * (1.0 - f) + _VIRIDIS[i + 1] * f


def heatmap(test, ref, *, vmin: float = 1e-4, vmax: float = 1.0, log: bool = True):
    """Per-pixel relMSE through viridis.

    Returns ``(image, legend)``: image (H, W, 3) float32 in [0, 1], *display-encoded*
    (write it to PNG as is, do not apply a view transform), same orientation as the inputs;
    non-finite pixels are magenta. legend = {"metric": "relmse", "vmin", "vmax",
    "scale": "log10"|"linear", "colormap": "viridis", "nonfinite_color"}.
    """
    m = relmse_map(test, ref)
    bad = ~np.isfinite(m)
    if log:
        lo, hi = math.log10(vmin), math.log10(vmax)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (np.log10(np.maximum(np.nan_to_num(m, nan=vmin), vmin)) - lo) / (hi - lo)
    else:
        t = (np.nan_to_num(m, nan=vmin) - vmin) / (vmax - vmin)
    img = colormap(t)
    img[bad] = NONFINITE_COLOR
    legend = {"metric": "relmse", "vmin": vmin, "vmax": vmax, "scale": "log10" if log else "linear",
              "colormap": "viridis", "nonfinite_color": list(NONFINITE_COLOR)}
    return img.astype(np.float32), legend


def colorbar(width: int = 256, height: int = 12) -> np.ndarray:
    """A horizontal legend strip (height, width, 3) float32, low values on the left."""
    t = np.linspace(0.0, 1.0, width)
    return np.repeat(colormap(t)[None, :, :], height, axis=0).astype(np.float32)


# ---------------------------------------------------------------- all together
def _aov_pair(t, r):
    t = np.asarray(t)
    r = np.asarray(r)
    if t.ndim == 2:
        t = t[:, :, None]
    if r.ndim == 2:
        r = r[:, :, None]
    c = min(t.shape[2], r.shape[2], 3)
    return t[:, :, :c], r[:, :, :c]


def compare(test, ref, *, mask=None, test_aovs: dict | None = None, ref_aovs: dict | None = None,
            with_flip: bool = True, view=view_standard) -> dict:
    """All metrics of ``test`` against ``ref``.

    Returns a dict with: relmse, flip (HDR), flip_ldr, ssim, psnr, nonfinite_pixels (test),
    ref_nonfinite_pixels, valid_pixels, pixels, and ``effects``: {aov name: {relmse, ssim,
    nonfinite_pixels}} for each AOV present in both ``test_aovs`` and ``ref_aovs``.
    FLIP values are None (with ``flip_error``) when flip-evaluator is missing or
    ``with_flip`` is False.
    """
    t, r = _rgb(test), _rgb(ref)
    _check_same(t, r)
    v = _valid(t, r, mask)
    out = {
        "relmse": relmse(t, r, mask),
        "ssim": ssim(t, r, mask, view=view),
        "psnr": psnr(t, r, mask, view=view),
        "nonfinite_pixels": nonfinite_count(t),
        "ref_nonfinite_pixels": nonfinite_count(r),
        "valid_pixels": int(v.sum()),
        "pixels": int(v.size),
        "flip": None,
        "flip_ldr": None,
    }
    if with_flip:
        try:
            out["flip"] = flip(t, r, mask, "HDR")
            out["flip_ldr"] = flip(t, r, mask, "LDR", view=view)
        except ImportError as e:
            out["flip_error"] = str(e)
    effects = {}
    for name in sorted(set(test_aovs or {}) & set(ref_aovs or {})):
        ta, ra = _aov_pair(test_aovs[name], ref_aovs[name])
        if ta.shape[:2] != ra.shape[:2]:
            continue
        effects[name] = {"relmse": relmse(ta, ra, mask), "ssim": ssim(ta, ra, mask, view=view),
                         "nonfinite_pixels": nonfinite_count(ta)}
    out["effects"] = effects
    return out
