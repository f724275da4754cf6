"""Generate addon/render/brdf_tables.py: the GGX albedo tables Cycles' Principled BSDF uses,
recomputed here by deterministic quadrature (same definitions, same grids, same lookup).

Cycles (4.x/5.x, ``bsdf_microfacet.h``) keeps three tables that change the Principled result:

* ``ggx_E[rough][mu]`` (32 x 32): directional albedo of single-scattering GGX with F = 1,
  rough = sqrt(alpha) = i/31, mu = cos(N, V) = j/31. Used for multiple-scattering energy
  preservation: the lobe is scaled by ``1 + Fms (1 - E) / E``.
* ``ggx_Eavg[rough]`` (32): the cosine-weighted average of E over mu (Kulla & Conty 2017).
* ``ggx_gen_schlick_ior_s[z][mu][rough]`` (16 x 16 x 16): the Fresnel blend factor
  s = int s_F f cos / int f cos of the dielectric specular layer, with
  s_F = (F_dielectric(cos_HV, eta) - F0(eta)) / (1 - F0(eta)); z = sqrt((eta-1)/(eta+1)).
  The layer's albedo, which darkens the diffuse under it, is
  ``E (1 + Fms (1-E)/E) * mix(f0, 1, s)``.

* ``ggx_glass_E[z][mu][rough]`` and ``ggx_glass_inv_E`` (16 x 16 x 16): the directional
  albedo of single-scattering GGX glass (reflection F + refraction 1 - F with the exact
  dielectric Fresnel, no tint) entering a medium of IOR eta (``inv``: leaving it, 1 / eta),
  z = sqrt((eta-1)/(eta+1)). Multiscatter GGX glass (Glass BSDF, Principled transmission) is
  scaled by 1 / E.

Quadrature: visible-normal samples (Heitz 2018) on a stratified N x N grid; the weight of
each sample with F = 1 is G2/G1 (the estimator of the albedo). Deterministic, converged to
~1e-4. Run: ``.venv/bin/python scripts/gen_brdf_tables.py`` (a few seconds).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

N = 192  # samples per dimension of the VNDF grid
_LAST_H = [None]  # the half vectors of the last vndf_samples call (glass_albedo reads them)


def _lambda(c, a2):
    c = np.clip(c, 1e-7, 1.0)
    return 0.5 * (np.sqrt(1.0 + a2 * np.maximum(1.0 / (c * c) - 1.0, 0.0)) - 1.0)


def fresnel_dielectric(c, eta):
    c = np.abs(c)
    g = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g, 0.0))
    A = (g - c) / (g + c)
    B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * A * A * (1.0 + B * B)


def vndf_samples(mu: float, alpha: float):
    """cos(V,H) and the F=1 weight G2/G1 for an N x N stratified grid of VNDF samples."""
    mu = max(mu, 1e-4)
    V = np.array([np.sqrt(max(0.0, 1.0 - mu * mu)), 0.0, mu])
    u1 = (np.arange(N) + 0.5) / N
    U1, U2 = np.meshgrid(u1, u1, indexing="ij")
    Vh = np.array([alpha * V[0], alpha * V[1], V[2]])
    Vh /= np.linalg.norm(Vh)
    lensq = Vh[0] ** 2 + Vh[1] ** 2
    T1 = np.array([-Vh[1], Vh[0], 0.0]) / np.sqrt(lensq) if lensq > 1e-12 else np.array([1.0, 0, 0])
    T2 = np.cross(Vh, T1)
    r = np.sqrt(U1)
    phi = 2 * np.pi * U2
    t1 = r * np.cos(phi)
    t2 = r * np.sin(phi)
    s = 0.5 * (1.0 + Vh[2])
    t2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - t1 * t1)) + s * t2
    Nh = t1[..., None] * T1 + t2[..., None] * T2 + np.sqrt(np.maximum(0.0, 1 - t1 * t1 - t2 * t2))[..., None] * Vh
    H = np.stack([alpha * Nh[..., 0], alpha * Nh[..., 1], np.maximum(0.0, Nh[..., 2])], -1)
    H /= np.linalg.norm(H, axis=-1, keepdims=True)
    _LAST_H[0] = H
    VoH = H @ V
    L = 2 * VoH[..., None] * H - V
    NoL = L[..., 2]
    a2 = alpha * alpha
    lv = _lambda(mu, a2)
    w = np.where(NoL > 0, (1.0 + lv) / (1.0 + lv + _lambda(NoL, a2)), 0.0)
    return VoH, w


def glass_albedo(mu, rough, eta):
    """Single-scattering albedo of GGX glass of relative IOR eta seen from mu (F = 1 tints)."""
    alpha = rough * rough
    if alpha < 1e-6:
        return 1.0
    mu = max(mu, 1e-4)
    V = np.array([np.sqrt(max(0.0, 1.0 - mu * mu)), 0.0, mu])
    VoH, _ = vndf_samples(mu, alpha)  # reflection weights are recomputed below
    H = _LAST_H[0]
    F = fresnel_dielectric(VoH, eta)
    F = np.where(eta * eta - 1.0 + VoH * VoH <= 0.0, 1.0, F)  # total internal reflection
    a2 = alpha * alpha
    lv = _lambda(mu, a2)
    Lr = 2 * VoH[..., None] * H - V
    wr = np.where(Lr[..., 2] > 0, (1.0 + lv) / (1.0 + lv + _lambda(Lr[..., 2], a2)), 0.0)
    # refraction of -V about H with 1/eta (GLSL refract)
    k = 1.0 - (1.0 / eta) ** 2 * (1.0 - VoH * VoH)
    Lt = (-V / eta) + ((VoH / eta) - np.sqrt(np.maximum(k, 0.0)))[..., None] * H
    ct = -Lt[..., 2]
    wt = np.where((ct > 0) & (k > 0), (1.0 + lv) / (1.0 + lv + _lambda(ct, a2)), 0.0)
    return float((F * wr + (1.0 - F) * wt).mean())


def albedo(mu, rough):
    alpha = rough * rough
    if alpha < 1e-6:
        return 1.0
    _, w = vndf_samples(mu, alpha)
    return float(w.mean())


def schlick_s(mu, rough, eta):
    alpha = max(rough * rough, 1e-6)
    f0 = ((eta - 1) / (eta + 1)) ** 2
    if alpha < 1e-6:
        c = np.array([max(mu, 1e-4)])
        w = np.ones(1)
    else:
        c, w = vndf_samples(mu, alpha)
    sF = np.clip((fresnel_dielectric(c, eta) - f0) / (1 - f0), 0, 1)
    tot = w.sum()
    return float((sF * w).sum() / tot) if tot > 0 else 0.0


def sheen_alpha(rough: float) -> float:
    return min(max(rough * rough, 0.01), 1.0)


def sheen_albedo(mu: float, rough: float) -> float:
    """Directional albedo of the sheen approximation of lib/brdf.glsl (Charlie D of Estevez &
    Kulla 2017 with alpha = the sheen roughness, Neubelt & Pettineo's visibility):
    the integral of f cos over the hemisphere, by a 256 x 512 midpoint grid in (cos, phi)."""
    mu = max(mu, 1e-4)
    a = sheen_alpha(rough)
    V = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    c = (np.arange(256) + 0.5) / 256
    p = (np.arange(512) + 0.5) / 512 * 2 * np.pi
    C, P = np.meshgrid(c, p, indexing="ij")
    S = np.sqrt(1 - C * C)
    L = np.stack([S * np.cos(P), S * np.sin(P), C], -1)
    H = L + V
    H /= np.linalg.norm(H, axis=-1, keepdims=True)
    sin_h = np.sqrt(np.maximum(1 - H[..., 2] ** 2, 0.0))
    D = (2 + 1 / a) * sin_h ** (1 / a) / (2 * np.pi)
    vis = 1.0 / (4 * (C + mu - C * mu))
    f = D * vis * C
    return float(f.mean() * 2 * np.pi)


def build():
    E = np.array([[albedo(j / 31, i / 31) for j in range(32)] for i in range(32)])  # [rough][mu]
    xg, wg = np.polynomial.legendre.leggauss(48)
    mus = 0.5 * (xg + 1)
    Eavg = np.array([float(np.sum(0.5 * wg * 2 * mus * np.array([albedo(m, i / 31) for m in mus])))
                     for i in range(32)])
    S = np.zeros((16, 16, 16))  # [z][mu][rough]
    for k in range(16):
        z = min(k / 15, 0.999)
        eta = (1 + z * z) / (1 - z * z)
        for j in range(16):
            for i in range(16):
                S[k, j, i] = schlick_s(j / 15, i / 15, max(eta, 1.0 + 1e-4))
    G = np.zeros((2, 16, 16, 16))  # [inv][z][mu][rough]
    for k in range(16):
        z = min(k / 15, 0.999)
        eta = max((1 + z * z) / (1 - z * z), 1.0 + 1e-4)
        for j in range(16):
            for i in range(16):
                G[0, k, j, i] = glass_albedo(j / 15, i / 15, eta)
                G[1, k, j, i] = glass_albedo(j / 15, i / 15, 1.0 / eta)
    return E, Eavg, S, G


def _fmt(v) -> str:
    """Five decimals without trailing zeros, always with a point (1. 0.98045 0.)."""
    t = f"{v:.5f}".rstrip("0").rstrip(".")
    return t if "." in t else t + "."


def py_array(name, a):
    items = [_fmt(float(v)) for v in np.ravel(a)]
    lines = [", ".join(items[i:i + 16]) for i in range(0, len(items), 16)]
    return f"{name} = (\n    " + ",\n    ".join(lines) + ",\n)\n"


def main():
    E, Eavg, S, G = build()
    SH = np.array([[sheen_albedo(j / 31, i / 31) for j in range(32)] for i in range(32)])  # [rough][mu]
    out = Path(__file__).resolve().parent.parent / "addon" / "render" / "brdf_tables.py"
    text = ('"""GGX albedo tables with Cycles\' definitions and grids. GENERATED by\n'
            "scripts/gen_brdf_tables.py (do not edit; its docstring says what they are).\n\n"
            "GGX_E[rough*32 + mu] (rough, mu = i/31), GGX_EAVG[rough],\n"
            "GGX_SCHLICK_S[(z*16 + mu)*16 + rough] (rough, mu, z = i/15),\n"
            "GGX_GLASS_E / GGX_GLASS_INV_E[(z*16 + mu)*16 + rough] (entering / leaving glass),\n"
            "SHEEN_E[rough*32 + mu]: albedo of the sheen approximation (lib/brdf.glsl sheen_eval).\n"
            "The shaders read them from one texture (shaders.brdf_lut; lib/brdf_tables.glsl).\n"
            '"""\n\n'
            + py_array("GGX_E", E) + "\n" + py_array("GGX_EAVG", Eavg) + "\n" + py_array("GGX_SCHLICK_S", S)
            + "\n" + py_array("GGX_GLASS_E", G[0]) + "\n" + py_array("GGX_GLASS_INV_E", G[1])
            + "\n" + py_array("SHEEN_E", SH))
    out.write_text(text)
    print(f"wrote {out} ({len(text)} bytes); E[r=0.3,mu=0.9]~{E[9, 28]:.4f} Eavg[r=0.6]~{Eavg[19]:.4f}")


if __name__ == "__main__":
    main()
