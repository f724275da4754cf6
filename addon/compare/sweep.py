"""Cost vs accuracy: equal-error speed-ups against the baselines' curves, setup vs per-frame
time, and the chart (bpy-free).

A baseline's curve is a list of ``(spp, time_ms, error)`` (or dicts with those keys): the
baseline (Cycles, Cycles + OpenImageDenoise, EEVEE) rendered at 1, 2, 4, ... samples on the
same machine in the same run, each measured against the high-spp Cycles reference, with
``time_ms`` the per-frame time without one-time setup (:func:`fit_setup`). A technique
point is ``(technique, quality, time_ms, error)`` (or a dict), its time also without setup.

Equal-error speed-up = the baseline's time to reach the technique's error / the technique's
time. The rules below say "Cycles" for any baseline.

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


def speedup_text(s: dict | None, *, plain: bool = False) -> str:
    """An equal-error speed-up entry as text: "2.3×", "≤0.8×" / "≥12×" when the technique's
    error lies outside the baseline's curve (a bound), or "n/a". ``plain``: ASCII ("x", "<=",
    ">=") for consoles and logs."""
    s = s or {}
    times, le, ge = ("x", "<=", ">=") if plain else ("×", "≤", "≥")
    if s.get("speedup") is not None:
        return f"{s['speedup']:.3g}{times}"
    b = s.get("bound") or {}
    if b.get("at_most") is not None:
        return f"{le}{b['at_most']:.3g}{times}"
    if b.get("at_least") is not None:
        return f"{ge}{b['at_least']:.3g}{times}"
    return "n/a"


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


def equal_error_speedup(error, time_ms, curve, metric: str = "relmse", name: str = "Cycles") -> dict:
    """{"speedup": float|None, "cycles_time_ms": float|None, "cycles_spp": float|None, "reason": str}.

    ``curve`` may be any baseline's curve (Cycles, denoised Cycles, EEVEE); ``name`` is used
    in the reasons. ``cycles_time_ms``/``cycles_spp`` are the baseline's interpolated time
    and samples at the technique's error (the key names predate the other baselines).

    Outside the curve there is no number, but a bound (``bound``: ``{"at_most": x}`` or
    ``{"at_least": x}``): a technique worse than the baseline's cheapest point is at most
    (that point's time / the technique's time) faster, since the baseline gets a lower error
    in that time; one better than its most expensive point is at least (that time / the
    technique's time) faster."""
    res = {"speedup": None, "cycles_time_ms": None, "cycles_spp": None, "reason": "", "bound": None}
    if not (isinstance(error, (int, float)) and math.isfinite(error)):
        res["reason"] = "technique error is not finite"
        return res
    if not _ok(time_ms):
        res["reason"] = "technique time is not a positive number"
        return res
    mono = monotone_curve(curve, metric)
    if not mono:
        res["reason"] = f"{name} curve is empty"
        return res
    e_hi, e_lo = mono[0][2], mono[-1][2]
    if error > e_hi:
        res["reason"] = (f"error above {name}'s curve (worse than {name} at {mono[0][0]:g} spp, "
                         f"{e_hi:.4g}); no extrapolation")
        res["bound"] = {"at_most": mono[0][1] / float(time_ms)}
        return res
    if error < e_lo:
        res["reason"] = (f"error below {name}'s curve (better than {name} at {mono[-1][0]:g} spp, "
                         f"{e_lo:.4g}); no extrapolation")
        res["bound"] = {"at_least": mono[-1][1] / float(time_ms)}
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
               reason=f"interpolated on {name}'s curve")
    return res


def speedups(points, curve, metric: str = "relmse") -> list[dict]:
    """For each technique point (dict with time_ms and error), its equal-error speed-up."""
    out = []
    for p in _point_dicts(points):
        s = equal_error_speedup(p.get("error"), p.get("time_ms"), curve, metric)
        out.append({"technique": p.get("technique"), "quality": p.get("quality"), **s})
    return out


# ---------------------------------------------------------------- setup vs per-frame time
def fit_setup(points) -> dict:
    """Split a renderer's wall times into one-time setup and per-sample cost.

    ``points``: ``(spp, wall_ms)`` pairs of one renderer at several sample counts. Fits
    ``wall = setup + per_sample * spp`` by least squares on *relative* residuals (weights
    1/wall², so the 1-spp render counts as much as the 64-spp one), with
    ``0 <= setup <= min(wall)`` and ``per_sample > 0``. Returns ``{"setup_ms",
    "per_sample_ms", "ok", "n", "max_rel_residual", "reason"}``; ``ok`` is False (setup 0,
    per_sample the median wall/spp) when fewer than two distinct sample counts are given
    or the times do not grow with spp.
    """
    pts = [(float(s), float(t)) for s, t in points if _ok(s) and _ok(t)]
    out = {"setup_ms": 0.0, "per_sample_ms": None, "ok": False, "n": len(pts), "max_rel_residual": None,
           "reason": ""}
    if pts:
        r = sorted(t / s for s, t in pts)
        out["per_sample_ms"] = r[len(r) // 2]
    if len({s for s, _ in pts}) < 2:
        out["reason"] = "fewer than two sample counts: no setup/per-sample split"
        return out
    w = [1.0 / (t * t) for _, t in pts]
    sw = sum(w)
    sws = sum(wi * s for wi, (s, _) in zip(w, pts))
    swss = sum(wi * s * s for wi, (s, _) in zip(w, pts))
    swt = sum(wi * t for wi, (_, t) in zip(w, pts))
    swst = sum(wi * s * t for wi, (s, t) in zip(w, pts))
    det = sw * swss - sws * sws
    a = (swss * swt - sws * swst) / det
    if (sw * swst - sws * swt) / det <= 0.0:  # unconstrained slope: times fall with spp
        out["reason"] = "render times do not grow with the sample count"
        return out
    t_min = min(t for _, t in pts)
    if a < 0.0 or a > t_min:
        a = min(max(a, 0.0), t_min)
    b = (swst - a * sws) / swss  # best per-sample cost for that setup
    if not (b > 0.0 and math.isfinite(b)):
        out["reason"] = "render times do not grow with the sample count"
        return out
    res = max(abs(a + b * s - t) / t for s, t in pts)
    out.update(setup_ms=a, per_sample_ms=b, ok=True, max_rel_residual=res,
               reason="wall = setup + per_sample x spp, relative least squares")
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


# baseline curve styles: (colour, SVG dash, SVG marker, matplotlib format)
_CURVE_STYLES = [("#444444", "", "circle", "-o"), ("#111111", "7 3", "triangle", "--^"),
                 ("#888888", "2 3", "diamond", ":D"), ("#555555", "10 3 2 3", "square", "-.s")]


_CHAR_W = 6.2  # approximate width of an 11 px sans-serif character, for label boxes


def _segment_hits_box(sg, bx) -> bool:
    """Whether the line segment (x0, y0, x1, y1) crosses the box (x0, y0, x1, y1) (Liang-Barsky)."""
    x0, y0, x1, y1 = sg
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0 - bx[0]), (dx, bx[2] - x0), (-dy, y0 - bx[1]), (dy, bx[3] - y0)):
        if p == 0:
            if q < 0:
                return False
        elif p < 0:
            t0 = max(t0, q / p)
        else:
            t1 = min(t1, q / p)
        if t0 > t1:
            return False
    return True


def _curve_sets(curve, metric: str) -> list[tuple[str, list[tuple[float, float, float]]]]:
    """``curve`` as [(label, finite tuples sorted by time)]: a list is one curve labelled
    "Cycles (spp)"; a dict maps legend labels to curves (one per baseline)."""
    items = curve.items() if isinstance(curve, dict) else [("Cycles (spp)", curve)]
    out = []
    for label, c in items:
        cur = sorted((t for t in _curve_tuples(c or [], metric) if _ok(t[1]) and _ok(t[2])), key=lambda t: t[1])
        out.append((str(label), cur))
    return out


def chart_svg(points, curve, *, metric: str = "relMSE", title: str = "",
              width: int = 720, height: int = 480, series: dict | None = None,
              xlabel: str = "time per render (ms, log scale)") -> str:
    """A log-log chart (x: time per frame in ms, y: error) as an SVG string, written by hand.

    ``curve``: Cycles' curve, or a dict {legend label: curve} with one curve per baseline
    (Cycles, Cycles + OpenImageDenoise, EEVEE), each a line in its own dash and marker with
    its spp labelled; each technique point is a marker labelled "TECH qN"; points of one
    technique are joined along its quality ladder. ``series``: more curves in the same form as
    ``curve``'s dict, drawn in colour (a technique's time-to-quality curve, its sample counts
    labelled)."""
    pts = [p for p in _point_dicts(points) if _ok(p.get("time_ms")) and _ok(p.get("error"))]
    sets = _curve_sets(curve, metric.lower())
    colour_sets = _curve_sets(series, metric.lower()) if series else []
    xs = [p["time_ms"] for p in pts] + [c[1] for _, cur in sets + colour_sets for c in cur]
    ys = [p["error"] for p in pts] + [c[2] for _, cur in sets + colour_sets for c in cur]
    techs = []
    for p in pts:
        if p["technique"] not in techs:
            techs.append(p["technique"])
    longest = max([len(label) for label, _ in sets + colour_sets] + [len(str(t)) + 6 for t in techs] + [10])
    ml, mr, mt, mb = 70, max(150, 40 + int(_CHAR_W * longest)), 40, 55
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
                 f'{html.escape(xlabel)}</text>')
    parts.append(f'<text x="16" y="{mt + ph / 2:.1f}" text-anchor="middle" '
                 f'transform="rotate(-90 16 {mt + ph / 2:.1f})">{html.escape(metric)} (log scale)</text>')
    # baseline curves
    def marker(kind, x, y, col):
        if kind == "triangle":
            return (f'<path d="M{x:.1f},{y - 4:.1f} L{x + 4:.1f},{y + 3:.1f} L{x - 4:.1f},{y + 3:.1f} Z" '
                    f'fill="{col}"/>')
        if kind == "diamond":
            return (f'<path d="M{x:.1f},{y - 4:.1f} L{x + 4:.1f},{y:.1f} L{x:.1f},{y + 4:.1f} '
                    f'L{x - 4:.1f},{y:.1f} Z" fill="{col}"/>')
        if kind == "square":
            return f'<rect x="{x - 3:.1f}" y="{y - 3:.1f}" width="6" height="6" fill="{col}"/>'
        return f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="{col}"/>'

    # every label is placed where it overlaps no marker, no line and no other label, inside
    # the plot; a technique label that finds no such place is left to the legend
    boxes: list[tuple[float, float, float, float]] = []
    segments: list[tuple[float, float, float, float]] = []
    curve_labels = []
    for k, (label, cur) in enumerate(sets):
        col, dash, mk, _ = _CURVE_STYLES[k % len(_CURVE_STYLES)]
        if not cur:
            continue
        xy = [(X(c[1]), Y(c[2])) for c in cur]
        d = " ".join(f"{'M' if i == 0 else 'L'}{x:.1f},{y:.1f}" for i, (x, y) in enumerate(xy))
        da = f' stroke-dasharray="{dash}"' if dash else ""
        parts.append(f'<path d="{d}" fill="none" stroke="{col}" stroke-width="2"{da}/>')
        segments += [(*a, *b) for a, b in zip(xy, xy[1:])]
        for c, (x, y) in zip(cur, xy):
            parts.append(marker(mk, x, y, col))
            boxes.append((x - 4, y - 4, x + 4, y + 4))
            curve_labels.append((x, y, col, f"{c[0]:g}"))
    for k, (label, cur) in enumerate(colour_sets):
        col = _PALETTE[k % len(_PALETTE)]
        if not cur:
            continue
        xy = [(X(c[1]), Y(c[2])) for c in cur]
        d = " ".join(f"{'M' if i == 0 else 'L'}{x:.1f},{y:.1f}" for i, (x, y) in enumerate(xy))
        parts.append(f'<path d="{d}" fill="none" stroke="{col}" stroke-width="1.5"/>')
        segments += [(*a, *b) for a, b in zip(xy, xy[1:])]
        for c, (x, y) in zip(cur, xy):
            parts.append(marker("circle", x, y, col))
            boxes.append((x - 4, y - 4, x + 4, y + 4))
            curve_labels.append((x, y, col, f"{c[0]:g}"))
    markers = []
    for i, tech in enumerate(techs):
        col = _PALETTE[i % len(_PALETTE)]
        tp = sorted((p for p in pts if p["technique"] == tech), key=lambda p: (p.get("quality") or 0))
        xy = [(X(p["time_ms"]), Y(p["error"])) for p in tp]
        if len(tp) > 1:
            d = " ".join(f"{'M' if j == 0 else 'L'}{x:.1f},{y:.1f}" for j, (x, y) in enumerate(xy))
            parts.append(f'<path d="{d}" fill="none" stroke="{col}" stroke-dasharray="4 3"/>')
            segments += [(*a, *b) for a, b in zip(xy, xy[1:])]
        for p, (x, y) in zip(tp, xy):
            parts.append(f'<rect x="{x - 4:.1f}" y="{y - 4:.1f}" width="8" height="8" fill="{col}"/>')
            boxes.append((x - 4, y - 4, x + 4, y + 4))
            name = f"{tech} q{p.get('quality')}" if p.get("quality") is not None else str(tech)
            same = next((m for m in markers if abs(m[0] - x) < 1 and abs(m[1] - y) < 1), None)
            if same is None:
                markers.append([x, y, col, name, [(tech, p.get("quality"))]])
            else:  # the same point (identical results): one label naming both
                same[2], same[3] = "#333333", same[3] + " = " + name
                same[4].append((tech, p.get("quality")))
    plot = (ml, mt, ml + pw, mt + ph)

    def fits(bx):
        return (plot[0] <= bx[0] and bx[2] <= plot[2] and plot[1] <= bx[1] and bx[3] <= plot[3]
                and all(bx[0] >= o[2] or bx[2] <= o[0] or bx[1] >= o[3] or bx[3] <= o[1] for o in boxes)
                and not any(_segment_hits_box(sg, bx) for sg in segments))

    for x, y, col, text in curve_labels:
        lw = 5.5 * len(text)
        for dx, dy in ((5, -5), (5, 11), (-5 - lw, -5), (-5 - lw, 11), (6, 3), (-6 - lw, 3)):
            bx = (x + dx, y + dy - 8, x + dx + lw, y + dy + 1)
            if fits(bx):
                boxes.append(bx)
                parts.append(f'<text x="{bx[0]:.1f}" y="{bx[3] - 1:.1f}" fill="{col}" font-size="9">'
                             f'{html.escape(text)}</text>')
                break
    unlabelled: dict = {}
    for x, y, col, label, members in markers:
        lw = _CHAR_W * len(label)
        for dx, dy in ((7, 4), (7, 16), (7, -8), (-7 - lw, 4), (7, 28), (-7 - lw, 16), (-7 - lw, -8),
                       (7, -20), (-7 - lw, 28), (-7 - lw, -20), (-lw / 2, -10), (-lw / 2, 22)):
            bx = (x + dx, y + dy - 10, x + dx + lw, y + dy + 2)
            if fits(bx):
                boxes.append(bx)
                parts.append(f'<text x="{bx[0]:.1f}" y="{bx[3] - 2:.1f}" fill="{col}">{html.escape(label)}</text>')
                break
        else:
            for tech, q in members:
                unlabelled.setdefault(tech, []).append(q)
    # legend
    lx, ly = ml + pw + 14, mt + 10
    for k, (label, _) in enumerate(sets):
        col, dash, mk, _ = _CURVE_STYLES[k % len(_CURVE_STYLES)]
        y = ly + 18 * k
        da = f' stroke-dasharray="{dash}"' if dash else ""
        parts.append(f'<line x1="{lx}" y1="{y}" x2="{lx + 22}" y2="{y}" stroke="{col}" stroke-width="2"{da}/>')
        parts.append(marker(mk, lx + 11, y, col))
        parts.append(f'<text x="{lx + 28}" y="{y + 4}">{html.escape(label)}</text>')
    for k, (label, _) in enumerate(colour_sets):
        col = _PALETTE[k % len(_PALETTE)]
        y = ly + 18 * (len(sets) + k)
        parts.append(f'<line x1="{lx}" y1="{y}" x2="{lx + 22}" y2="{y}" stroke="{col}" stroke-width="1.5"/>')
        parts.append(marker("circle", lx + 11, y, col))
        parts.append(f'<text x="{lx + 28}" y="{y + 4}">{html.escape(label)}</text>')
    ly += 18 * (len(sets) + len(colour_sets) - 1)
    for i, tech in enumerate(techs):
        y = ly + 18 * (i + 1)
        col = _PALETTE[i % len(_PALETTE)]
        qs = [q for q in unlabelled.get(tech, []) if q is not None]
        text = str(tech) + (" (" + ", ".join(f"q{q}" for q in qs) + ")" if qs else "")
        parts.append(f'<rect x="{lx + 7}" y="{y - 4}" width="8" height="8" fill="{col}"/>')
        parts.append(f'<text x="{lx + 28}" y="{y + 4}">{html.escape(text)}</text>')
    parts.append("</svg>")
    return "\n".join(parts)


def chart_png(points, curve, path: str, *, metric: str = "relMSE", title: str = "", series: dict | None = None,
              xlabel: str = "time per render (ms, log scale)") -> str | None:
    """The same chart through matplotlib (Agg); returns the path, or None if matplotlib is
    not importable."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception:  # noqa: BLE001 - any import problem means "no PNG"
        return None
    pts = [p for p in _point_dicts(points) if _ok(p.get("time_ms")) and _ok(p.get("error"))]
    sets = _curve_sets(curve, metric.lower())
    fig, ax = plt.subplots(figsize=(8.0, 4.8), dpi=100)
    for k, (label, cur) in enumerate(sets):
        col, _, _, fmt = _CURVE_STYLES[k % len(_CURVE_STYLES)]
        if not cur:
            continue
        ax.plot([c[1] for c in cur], [c[2] for c in cur], fmt, color=col, ms=4, label=label)
        for c in cur:
            ax.annotate(f"{c[0]:g}", (c[1], c[2]), textcoords="offset points", xytext=(4, 4),
                        fontsize=7, color=col)
    for k, (label, cur) in enumerate(_curve_sets(series, metric.lower()) if series else []):
        col = _PALETTE[k % len(_PALETTE)]
        if not cur:
            continue
        ax.plot([c[1] for c in cur], [c[2] for c in cur], "-o", color=col, ms=4, lw=1.5, label=label)
        for c in cur:
            ax.annotate(f"{c[0]:g}", (c[1], c[2]), textcoords="offset points", xytext=(4, 4),
                        fontsize=7, color=col)
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
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{metric} (log scale)")
    ax.set_title(title or f"Cost vs accuracy ({metric} against the Cycles reference)", fontsize=11)
    ax.grid(True, which="major", color="#ddd")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_chart(points, curve, path_base: str, *, metric: str = "relMSE", title: str = "",
                series: dict | None = None, xlabel: str = "time per render (ms, log scale)") -> dict:
    """Write ``path_base + '.svg'`` always and ``path_base + '.png'`` when matplotlib is
    importable. Returns {"svg": path, "png": path or None, "svg_text": str}."""
    d = os.path.dirname(os.path.abspath(path_base))
    os.makedirs(d, exist_ok=True)
    svg = chart_svg(points, curve, metric=metric, title=title, series=series, xlabel=xlabel)
    with open(path_base + ".svg", "w", encoding="utf-8") as f:
        f.write(svg)
    png = chart_png(points, curve, path_base + ".png", metric=metric, title=title, series=series, xlabel=xlabel)
    return {"svg": path_base + ".svg", "png": png, "svg_text": svg}
