"""Cost vs accuracy: equal-error speed-up against Cycles' own curve, and the chart (bpy-free).

Cycles' curve is a list of ``(spp, time_ms, error)`` (or dicts with those keys): Cycles
rendered at 1, 2, 4, ... spp on the same machine in the same run, each measured against the
high-spp reference. A technique point is ``(technique, quality, time_ms, error)`` (or a dict).

Equal-error speed-up = Cycles' time to reach the technique's error / the technique's time.

* The curve is made monotone first: sorted by time, error replaced by the running minimum
  ("the best error Cycles had reached by this time"), and only the points where the error
  strictly drops are kept. Noise in the low-spp measurements therefore never makes the
  inverse ill-defined.
* Between two curve points, log(time) is interpolated linearly in log(error) (a power law
  error ~ time^-k is reproduced exactly).
* No extrapolation: an error above the curve's highest error (worse than Cycles' cheapest
  render) or below its lowest (better than the most expensive one measured) gives
  ``speedup = None`` with a ``reason``.
"""
from __future__ import annotations

import html
import math
import os

_PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
            "#17becf", "#bcbd22", "#7f7f7f"]


def _curve_tuples(curve, metric: str = "relmse") -> list[tuple[float, float, float]]:
    out = []
    for c in curve:
        if isinstance(c, dict):
            out.append((float(c["spp"]), float(c["time_ms"]), float(c.get("error", c.get(metric)))))
        else:
            out.append((float(c[0]), float(c[1]), float(c[2])))
    return out


def _point_dicts(points) -> list[dict]:
    out = []
    for p in points:
        if isinstance(p, dict):
            out.append(dict(p))
        else:
            out.append({"technique": p[0], "quality": p[1], "time_ms": p[2], "error": p[3]})
    return out


def _ok(x) -> bool:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x) and x > 0


def monotone_curve(curve, metric: str = "relmse") -> list[tuple[float, float, float]]:
    """Sorted by time; error = running minimum; only strictly decreasing points kept."""
    pts = sorted((c for c in _curve_tuples(curve, metric) if _ok(c[1]) and _ok(c[2])),
                 key=lambda c: (c[1], c[0]))
    out: list[tuple[float, float, float]] = []
    best = math.inf
    for spp, t, e in pts:
        if e < best:
            best = e
            out.append((spp, t, e))
    return out


def equal_error_speedup(error, time_ms, curve, metric: str = "relmse") -> dict:
    """{"speedup": float|None, "cycles_time_ms": float|None, "cycles_spp": float|None, "reason": str}."""
    res = {"speedup": None, "cycles_time_ms": None, "cycles_spp": None, "reason": ""}
    if not (isinstance(error, (int, float)) and math.isfinite(error)):
        res["reason"] = "technique error is not finite"
        return res
    if not _ok(time_ms):
        res["reason"] = "technique time is not a positive number"
        return res
    mono = monotone_curve(curve, metric)
    if not mono:
        res["reason"] = "Cycles curve is empty"
        return res
    e_hi, e_lo = mono[0][2], mono[-1][2]
    if error > e_hi:
        res["reason"] = (f"error above Cycles' curve (worse than Cycles at {mono[0][0]:g} spp, "
                         f"{e_hi:.4g}); no extrapolation")
        return res
    if error < e_lo:
        res["reason"] = (f"error below Cycles' curve (better than Cycles at {mono[-1][0]:g} spp, "
                         f"{e_lo:.4g}); no extrapolation")
        return res
    if error == e_hi or len(mono) == 1:
        t, spp = mono[0][1], mono[0][0]
    else:
        t = spp = None
        for (s0, t0, e0), (s1, t1, e1) in zip(mono, mono[1:]):
            if e0 >= error >= e1:
                f = (math.log(e0) - math.log(error)) / (math.log(e0) - math.log(e1))
                t = math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
                spp = math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0)))
                break
    res.update(speedup=t / float(time_ms), cycles_time_ms=t, cycles_spp=spp,
               reason="interpolated on Cycles' curve")
    return res


def speedups(points, curve, metric: str = "relmse") -> list[dict]:
    """For each technique point (dict with time_ms and error), its equal-error speed-up."""
    out = []
    for p in _point_dicts(points):
        s = equal_error_speedup(p.get("error"), p.get("time_ms"), curve, metric)
        out.append({"technique": p.get("technique"), "quality": p.get("quality"), **s})
    return out


# ---------------------------------------------------------------- chart
def _nice_decades(lo: float, hi: float) -> list[float]:
    a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    if a == b:
        b += 1
    return [10.0 ** k for k in range(a, b + 1)]


def _fmt(v: float) -> str:
    if v >= 1000 or v < 0.01:
        return f"1e{int(round(math.log10(v)))}"
    return f"{v:g}"


def chart_svg(points, curve, *, metric: str = "relMSE", title: str = "",
              width: int = 720, height: int = 480) -> str:
    """A log-log chart (x: time per frame in ms, y: error) as an SVG string, written by hand.

    Cycles' curve is a line with its spp labelled; each technique point is a marker labelled
    "TECH qN"; points of one technique are joined along its quality ladder."""
    pts = [p for p in _point_dicts(points) if _ok(p.get("time_ms")) and _ok(p.get("error"))]
    cur = [c for c in _curve_tuples(curve, metric.lower()) if _ok(c[1]) and _ok(c[2])]
    xs = [p["time_ms"] for p in pts] + [c[1] for c in cur]
    ys = [p["error"] for p in pts] + [c[2] for c in cur]
    ml, mr, mt, mb = 70, 150, 40, 55
    pw, ph = width - ml - mr, height - mt - mb
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">',
             f'<rect width="{width}" height="{height}" fill="white"/>']
    ttl = title or f"Cost vs accuracy ({metric} against the Cycles reference)"
    parts.append(f'<text x="{ml}" y="22" font-size="14" font-weight="bold">{html.escape(ttl)}</text>')
    if not xs:
        parts.append(f'<text x="{ml}" y="{mt + 20}">no finite data</text></svg>')
        return "\n".join(parts)
    xd = _nice_decades(min(xs), max(xs))
    yd = _nice_decades(min(ys), max(ys))
    lx0, lx1 = math.log10(xd[0]), math.log10(xd[-1])
    ly0, ly1 = math.log10(yd[0]), math.log10(yd[-1])

    def X(v):
        return ml + (math.log10(v) - lx0) / (lx1 - lx0) * pw

    def Y(v):
        return mt + ph - (math.log10(v) - ly0) / (ly1 - ly0) * ph

    # grid and axes
    for v in xd:
        x = X(v)
        parts.append(f'<line x1="{x:.1f}" y1="{mt}" x2="{x:.1f}" y2="{mt + ph}" stroke="#ddd"/>')
        parts.append(f'<text x="{x:.1f}" y="{mt + ph + 16}" text-anchor="middle">{_fmt(v)}</text>')
    for v in yd:
        y = Y(v)
        parts.append(f'<line x1="{ml}" y1="{y:.1f}" x2="{ml + pw}" y2="{y:.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{ml - 6}" y="{y + 4:.1f}" text-anchor="end">{_fmt(v)}</text>')
    parts.append(f'<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>')
    parts.append(f'<text x="{ml + pw / 2:.1f}" y="{height - 12}" text-anchor="middle">'
                 f'time per frame (ms, log scale)</text>')
    parts.append(f'<text x="16" y="{mt + ph / 2:.1f}" text-anchor="middle" '
                 f'transform="rotate(-90 16 {mt + ph / 2:.1f})">{html.escape(metric)} (log scale)</text>')
    # Cycles curve
    cur.sort(key=lambda c: c[1])
    if cur:
        d = " ".join(f"{'M' if i == 0 else 'L'}{X(c[1]):.1f},{Y(c[2]):.1f}" for i, c in enumerate(cur))
        parts.append(f'<path d="{d}" fill="none" stroke="#444" stroke-width="2"/>')
        for c in cur:
            parts.append(f'<circle cx="{X(c[1]):.1f}" cy="{Y(c[2]):.1f}" r="3" fill="#444"/>')
            parts.append(f'<text x="{X(c[1]) + 5:.1f}" y="{Y(c[2]) - 5:.1f}" fill="#444" '
                         f'font-size="9">{c[0]:g}</text>')
    # technique points
    techs = []
    for p in pts:
        if p["technique"] not in techs:
            techs.append(p["technique"])
    placed: list[tuple[float, float, float, float]] = []  # label boxes, to avoid overlaps

    def free(bx):
        return all(bx[0] >= o[2] or bx[2] <= o[0] or bx[1] >= o[3] or bx[3] <= o[1] for o in placed)

    markers = []
    for i, tech in enumerate(techs):
        col = _PALETTE[i % len(_PALETTE)]
        tp = sorted((p for p in pts if p["technique"] == tech), key=lambda p: (p.get("quality") or 0))
        if len(tp) > 1:
            d = " ".join(f"{'M' if j == 0 else 'L'}{X(p['time_ms']):.1f},{Y(p['error']):.1f}"
                         for j, p in enumerate(tp))
            parts.append(f'<path d="{d}" fill="none" stroke="{col}" stroke-dasharray="4 3"/>')
        for p in tp:
            x, y = X(p["time_ms"]), Y(p["error"])
            parts.append(f'<rect x="{x - 4:.1f}" y="{y - 4:.1f}" width="8" height="8" fill="{col}"/>')
            placed.append((x - 4, y - 4, x + 4, y + 4))
            markers.append((x, y, col, f"{tech} q{p.get('quality')}" if p.get("quality") is not None
                            else str(tech)))
    for x, y, col, label in markers:
        lw = 6.2 * len(label)
        for dx, dy in ((7, 4), (7, 16), (7, -8), (-7 - lw, 4), (7, 28), (-7 - lw, 16), (-7 - lw, -8),
                       (7, -20), (-7 - lw, 28), (-7 - lw, -20)):
            bx = (x + dx, y + dy - 10, x + dx + lw, y + dy + 2)
            if free(bx):
                break
        placed.append(bx)
        parts.append(f'<text x="{bx[0]:.1f}" y="{bx[3] - 2:.1f}" fill="{col}">{html.escape(label)}</text>')
    # legend
    lx, ly = ml + pw + 14, mt + 10
    parts.append(f'<line x1="{lx}" y1="{ly}" x2="{lx + 22}" y2="{ly}" stroke="#444" stroke-width="2"/>')
    parts.append(f'<text x="{lx + 28}" y="{ly + 4}">Cycles (spp)</text>')
    for i, tech in enumerate(techs):
        y = ly + 18 * (i + 1)
        col = _PALETTE[i % len(_PALETTE)]
        parts.append(f'<rect x="{lx + 7}" y="{y - 4}" width="8" height="8" fill="{col}"/>')
        parts.append(f'<text x="{lx + 28}" y="{y + 4}">{html.escape(str(tech))}</text>')
    parts.append("</svg>")
    return "\n".join(parts)


def chart_png(points, curve, path: str, *, metric: str = "relMSE", title: str = "") -> str | None:
    """The same chart through matplotlib (Agg); returns the path, or None if matplotlib is
    not importable."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception:  # noqa: BLE001 - any import problem means "no PNG"
        return None
    pts = [p for p in _point_dicts(points) if _ok(p.get("time_ms")) and _ok(p.get("error"))]
    cur = sorted((c for c in _curve_tuples(curve, metric.lower()) if _ok(c[1]) and _ok(c[2])),
                 key=lambda c: c[1])
    fig, ax = plt.subplots(figsize=(7.2, 4.8), dpi=100)
    if cur:
        ax.plot([c[1] for c in cur], [c[2] for c in cur], "-o", color="#444", ms=3, label="Cycles (spp)")
        for c in cur:
            ax.annotate(f"{c[0]:g}", (c[1], c[2]), textcoords="offset points", xytext=(4, 4),
                        fontsize=7, color="#444")
    techs = []
    for p in pts:
        if p["technique"] not in techs:
            techs.append(p["technique"])
    for i, tech in enumerate(techs):
        col = _PALETTE[i % len(_PALETTE)]
        tp = sorted((p for p in pts if p["technique"] == tech), key=lambda p: (p.get("quality") or 0))
        ax.plot([p["time_ms"] for p in tp], [p["error"] for p in tp], "s--", color=col, label=str(tech))
        for j, p in enumerate(tp):
            ax.annotate(f"{tech} q{p.get('quality')}", (p["time_ms"], p["error"]),
                        textcoords="offset points", xytext=((6, -3), (6, -13), (6, 7), (-62, -3))[j % 4],
                        fontsize=8, color=col)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per frame (ms, log scale)")
    ax.set_ylabel(f"{metric} (log scale)")
    ax.set_title(title or f"Cost vs accuracy ({metric} against the Cycles reference)", fontsize=11)
    ax.grid(True, which="major", color="#ddd")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_chart(points, curve, path_base: str, *, metric: str = "relMSE", title: str = "") -> dict:
    """Write ``path_base + '.svg'`` always and ``path_base + '.png'`` when matplotlib is
    importable. Returns {"svg": path, "png": path or None, "svg_text": str}."""
    d = os.path.dirname(os.path.abspath(path_base))
    os.makedirs(d, exist_ok=True)
    svg = chart_svg(points, curve, metric=metric, title=title)
    with open(path_base + ".svg", "w", encoding="utf-8") as f:
        f.write(svg)
    png = chart_png(points, curve, path_base + ".png", metric=metric, title=title)
    return {"svg": path_base + ".svg", "png": png, "svg_text": svg}
