"""A self-contained HTML report of one comparison run (bpy-free, no OpenImageIO needed).

Everything is inline: images as base64 PNG data URIs (the caller encodes them, e.g. with
``imageio.png_bytes``), the chart as inline SVG, CSS in a <style> block. One file that can be
mailed or attached to a CI run.
"""
from __future__ import annotations

import base64
import html
import math


_BASELINE_LABELS = {"cycles": "Cycles", "cycles_denoised": "Cycles + OpenImageDenoise",
                    "eevee": "EEVEE (ray tracing)"}


def _bound(s: dict) -> str:
    """"&le; 1.2&times;" / "&ge; 3&times;" for a speed-up outside the baseline's curve, else "n/a"."""
    b = s.get("bound") or {}
    if b.get("at_most") is not None:
        return f'&le;&thinsp;{_num(b["at_most"], "{:.3g}")}&times;'
    if b.get("at_least") is not None:
        return f'&ge;&thinsp;{_num(b["at_least"], "{:.3g}")}&times;'
    return "n/a"


def technique_label(e: dict) -> str:
    """The technique of a results entry as the render panel names it: "RESTIR_GI + SVGF"
    when a filter ends its frames."""
    d = str(e.get("denoiser") or "NONE")
    return str(e.get("technique")) + ("" if d == "NONE" else f" + {d}")


def entry_id(technique: str, quality, reference: str) -> str:
    """The key tying a results entry to its images: ``TECH_q<quality>_<reference>``."""
    return f"{technique}_q{quality}_{reference}"


def _img(png: bytes | None, alt: str, cls: str = "") -> str:
    if not png:
        return f'<div class="missing">{html.escape(alt)}: no image</div>'
    b64 = base64.b64encode(png).decode("ascii")
    return f'<img class="{cls}" alt="{html.escape(alt)}" title="{html.escape(alt)}" src="data:image/png;base64,{b64}"/>'


def _num(v, fmt="{:.4g}") -> str:
    if v is None:
        return "&ndash;"
    if isinstance(v, float) and not math.isfinite(v):
        return "inf" if v > 0 else ("nan" if v != v else "-inf")
    try:
        return fmt.format(v)
    except (ValueError, TypeError):
        return html.escape(str(v))


_CSS = """
body{font-family:system-ui,sans-serif;margin:24px;color:#222;max-width:1350px}
h1{font-size:22px;margin-bottom:4px} h2{font-size:17px;margin-top:28px;border-bottom:1px solid #ccc}
h3{font-size:14px;margin:18px 0 6px}
table{border-collapse:collapse;font-size:13px} th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0} td.l,th.l{text-align:left}
.meta{color:#555;font-size:13px}
.row{display:flex;gap:12px;flex-wrap:wrap;align-items:flex-start}
.row figure{margin:0} figcaption{font-size:12px;color:#444;text-align:center}
img.px{image-rendering:pixelated;width:300px;height:auto;border:1px solid #999}
.missing{width:300px;height:120px;border:1px dashed #aaa;color:#777;font-size:12px;padding:8px}
.legend{font-size:11px;color:#444} .legend img{width:300px;height:10px;display:block;border:1px solid #999}
.skipped{font-size:12px;color:#333} .warn{color:#a40}
"""


def build_html(*, title: str, results: dict, images: dict | None = None, chart_svg: str = "",
               colorbar_png: bytes | None = None, legend: dict | None = None) -> str:
    """The report as one HTML string.

    results: the results.json dict (``scene``, ``reference``, ``references``, ``entries``,
      ``cycles_curve``, ``speedup``...). Each entry: technique, quality, reference, time_ms,
      relmse, flip, ssim, psnr, nonfinite_pixels, effects, skipped_passes, speedup (dict).
    images: {entry_id(...): {"ours": png, "cycles": png, "error": png}} plus optional
      {"reference:<kind>": png} for the Cycles images shown at the top and
      {"baseline:<name>": png} for each baseline's image at its largest sample count.
    results["baselines"]: {name: [{spp, time_ms, wall_ms, relmse, flip, ssim}]} and
      entries' "speedups": {name: {speedup, cycles_spp, reason}} give the speed-up table.
    """
    images = images or {}
    legend = legend or {}
    entries = results.get("entries", [])
    p = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
         f"<style>{_CSS}</style></head><body>", f"<h1>{html.escape(title)}</h1>"]
    meta = results.get("run", {})
    if meta:
        p.append('<p class="meta">' + " &middot; ".join(
            f"{html.escape(str(k))}: {html.escape(str(v))}" for k, v in meta.items()) + "</p>")

    # ---- references
    p.append("<h2>Cycles references</h2>")
    refs = results.get("references") or ({results["reference"]["kind"]: results["reference"]}
                                         if results.get("reference") else {})
    p.append('<table><tr><th class="l">kind</th><th>spp</th><th>time (ms)</th><th class="l">bounces</th>'
             '<th>seed</th><th class="l">from cache</th><th class="l">Blender</th></tr>')
    for kind, r in refs.items():
        b = r.get("bounces", {})
        bstr = ", ".join(f"{k}={v}" for k, v in b.items()) if isinstance(b, dict) else str(b)
        p.append(f'<tr><td class="l">{html.escape(kind)}</td><td>{_num(r.get("spp"), "{}")}</td>'
                 f'<td>{_num(r.get("time_ms"), "{:.0f}")}</td><td class="l">{html.escape(bstr)}</td>'
                 f'<td>{_num(r.get("seed"), "{}")}</td><td class="l">{"yes" if r.get("cached") else "no"}</td>'
                 f'<td class="l">{html.escape(str(r.get("blender_version", "")))}</td></tr>')
    p.append("</table>")
    settings = results.get("reference_settings")
    if settings:
        p.append('<p class="meta">Reference settings: ' + html.escape(settings) + "</p>")
    ref_imgs = [(k[len("reference:"):], v) for k, v in images.items() if k.startswith("reference:")]
    base_imgs = [(k[len("baseline:"):], v) for k, v in images.items() if k.startswith("baseline:")]
    if ref_imgs or base_imgs:
        p.append('<div class="row">')
        for kind, png in ref_imgs:
            p.append(f"<figure>{_img(png, 'Cycles ' + kind, 'px')}<figcaption>Cycles, {html.escape(kind)}"
                     "</figcaption></figure>")
        for name, png in base_imgs:
            pts = (results.get("baselines") or {}).get(name) or [{}]
            cap = f"{_BASELINE_LABELS.get(name, name)}, {_num(pts[-1].get('spp'), '{}')} spp"
            p.append(f"<figure>{_img(png, cap, 'px')}<figcaption>{html.escape(cap)}</figcaption></figure>")
        p.append("</div>")

    # ---- metrics table
    p.append("<h2>Metrics</h2>")
    p.append('<p class="meta">relMSE = mean (a&minus;b)&sup2;/(b&sup2;+0.01) on linear HDR; FLIP = HDR-FLIP mean; '
             'SSIM and PSNR on the sRGB "Standard" view. Lower is better except SSIM and PSNR. '
             'ms/frame: median time of one frame; ms (image): the accumulated image (frames &times; ms/frame), the time '
             'the chart and the speed-up use; setup ms: one-time scene setup (export, GPU upload, BVH, shader '
             'compilation), never part of the per-frame time. Speed-up = Cycles time to reach the same relMSE / '
             'technique time, both without setup (same machine, same run); against the other baselines below.</p>')
    p.append('<table><tr><th class="l">technique</th><th>quality</th><th class="l">reference</th>'
             '<th>ms/frame</th><th>frames</th><th>ms (image)</th><th>setup ms</th><th>relMSE</th><th>FLIP</th>'
             '<th>SSIM</th><th>PSNR (dB)</th><th>non-finite px</th><th>equal-error speed-up</th></tr>')
    for e in entries:
        s = e.get("speedup") or {}
        sp = _num(s.get("speedup"), "{:.3g}&times;") if s.get("speedup") is not None else \
            f'<span title="{html.escape(s.get("reason", ""))}">n/a</span>'
        nf = e.get("nonfinite_pixels", 0)
        nf_s = f'<span class="warn">{nf}</span>' if nf else "0"
        p.append(f'<tr><td class="l">{html.escape(technique_label(e))}</td><td>{_num(e.get("quality"), "{}")}</td>'
                 f'<td class="l">{html.escape(str(e.get("reference")))}</td><td>{_num(e.get("frame_ms"), "{:.2f}")}</td>'
                 f'<td>{_num(e.get("samples"), "{}")}</td><td>{_num(e.get("time_ms"), "{:.1f}")}</td>'
                 f'<td>{_num(e.get("setup_ms"), "{:.0f}")}</td><td>{_num(e.get("relmse"))}</td><td>{_num(e.get("flip"))}</td><td>{_num(e.get("ssim"), "{:.4f}")}</td>'
                 f'<td>{_num(e.get("psnr"), "{:.2f}")}</td><td>{nf_s}</td><td>{sp}</td></tr>')
    p.append("</table>")
    reasons = [(e, (e.get("speedup") or {}).get("reason")) for e in entries
               if (e.get("speedup") or {}).get("speedup") is None and (e.get("speedup") or {}).get("reason")]
    if reasons:
        p.append('<ul class="skipped">' + "".join(
            f"<li>{html.escape(technique_label(e))} q{e.get('quality')} vs {html.escape(str(e.get('reference')))}: "
            f"no speed-up: {html.escape(r)}</li>" for e, r in reasons) + "</ul>")

    # ---- equal-error speed-ups against every baseline
    baselines = results.get("baselines") or {}
    with_sp = [e for e in entries if e.get("speedups")]
    names = [b for b in baselines if any(b in e["speedups"] for e in with_sp)]
    if with_sp and names:
        ref_kind = (results.get("reference") or {}).get("kind", "full")
        p.append("<h2>Equal-error speed-ups</h2>")
        p.append(f'<p class="meta">Each baseline&rsquo;s per-frame time to reach the technique&rsquo;s relMSE '
                 f'against Cycles &lsquo;{html.escape(str(ref_kind))}&rsquo;, divided by the technique&rsquo;s '
                 'time; one-time setup left out on both sides. &gt; 1: the technique is faster at equal error. '
                 '&le;/&ge;: the technique&rsquo;s error lies outside the baseline&rsquo;s measured curve, so only a '
                 'bound is known (&le;: the baseline&rsquo;s cheapest render is already more accurate; &ge;: the '
                 'technique beats its most expensive one); hover for the reason. No extrapolation.</p>')
        p.append('<table><tr><th class="l">technique</th><th>quality</th><th>ms (image)</th><th>relMSE</th>'
                 + "".join(f"<th>vs {html.escape(_BASELINE_LABELS.get(b, b))}</th>" for b in names) + "</tr>")
        for e in with_sp:
            if e.get("reference") != ref_kind:
                continue
            cells = []
            for b in names:
                s = (e.get("speedups") or {}).get(b) or {}
                if s.get("speedup") is not None:
                    cells.append(f'<td title="{html.escape(s.get("reason", ""))}">{_num(s["speedup"], "{:.3g}&times;")}'
                                 f' <span class="meta">({_num(s.get("cycles_spp"), "{:.2g}")} spp)</span></td>')
                else:
                    cells.append(f'<td><span title="{html.escape(s.get("reason", ""))}">{_bound(s)}</span></td>')
            p.append(f'<tr><td class="l">{html.escape(technique_label(e))}</td><td>{_num(e.get("quality"), "{}")}</td>'
                     f'<td>{_num(e.get("time_ms"), "{:.1f}")}</td><td>{_num(e.get("relmse"))}</td>{"".join(cells)}</tr>')
        p.append("</table>")

    # ---- chart
    if chart_svg:
        p.append("<h2>Cost vs accuracy</h2>")
        p.append(chart_svg)

    # ---- baseline curves
    setup = results.get("baselines_setup") or {}
    if baselines:
        p.append("<h3>Baselines: what a user would pick instead</h3>")
        p.append('<p class="meta">Each baseline rendered at 1, 2, 4, &hellip; samples in the same run. Wall times are '
                 'fitted as setup + per-sample &times; spp; <i>ms/frame</i> leaves the setup out (scene sync and BVH '
                 'for Cycles, per-render set-up for EEVEE), <i>wall ms</i> is the measured render call. The first '
                 'render of each (Cycles&rsquo; kernels, the denoiser, EEVEE&rsquo;s shader compilation) is an '
                 'untimed warm-up.</p>')
        for b, pts in baselines.items():
            info = setup.get(b) or {}
            extra = info.get("first_render_extra_ms")
            p.append(f"<p><b>{html.escape(_BASELINE_LABELS.get(b, b))}</b>: setup {_num(info.get('setup_ms'), '{:.0f}')} ms, "
                     f"{_num(info.get('per_sample_ms'), '{:.3g}')} ms per sample"
                     + (f", first render +{_num(extra, '{:.0f}')} ms" if extra is not None else "") + "</p>")
            p.append('<table><tr><th>spp</th><th>ms/frame</th><th>wall ms</th><th>relMSE</th><th>FLIP</th>'
                     '<th>SSIM</th></tr>')
            for c in pts:
                p.append(f'<tr><td>{_num(c.get("spp"), "{}")}</td><td>{_num(c.get("time_ms"), "{:.1f}")}</td>'
                         f'<td>{_num(c.get("wall_ms"), "{:.0f}")}</td><td>{_num(c.get("relmse"))}</td>'
                         f'<td>{_num(c.get("flip"))}</td><td>{_num(c.get("ssim"), "{:.4f}")}</td></tr>')
            p.append("</table>")
    curve = results.get("cycles_curve") or []
    if curve and not baselines:
        p.append("<h3>Cycles' own curve</h3>")
        p.append('<table><tr><th>spp</th><th>time (ms)</th><th>relMSE</th><th>FLIP</th></tr>')
        for c in curve:
            p.append(f'<tr><td>{_num(c.get("spp"), "{}")}</td><td>{_num(c.get("time_ms"), "{:.0f}")}</td>'
                     f'<td>{_num(c.get("relmse"))}</td><td>{_num(c.get("flip"))}</td></tr>')
        p.append("</table>")

    # ---- per-frame comparison of an animation (gi_compare.py --animation)
    if results.get("animation"):
        from .animation import report_html
        p.append(report_html(results["animation"], images))

    # ---- per technique images
    p.append("<h2>Images</h2>")
    if colorbar_png:
        lo, hi = legend.get("vmin"), legend.get("vmax")
        p.append(f'<div class="legend">Error map: per-pixel relMSE, {html.escape(str(legend.get("scale", "log10")))} scale, '
                 f'{html.escape(str(legend.get("colormap", "viridis")))}, from {_num(lo)} (left) to {_num(hi)} (right); '
                 f'magenta = non-finite pixel.{_img(colorbar_png, "legend")}</div>')
    for e in entries:
        eid = entry_id(e.get("technique"), e.get("quality"), e.get("reference"))
        im = images.get(eid, {})
        p.append(f"<h3>{html.escape(str(e.get('technique')))} q{e.get('quality')} vs Cycles "
                 f"{html.escape(str(e.get('reference')))} &mdash; relMSE {_num(e.get('relmse'))}, "
                 f"FLIP {_num(e.get('flip'))}, {_num(e.get('time_ms'), '{:.2f}')} ms</h3>")
        p.append('<div class="row">')
        for k, cap in (("ours", "GI Preview"), ("cycles", "Cycles"), ("error", "error (relMSE)")):
            p.append(f"<figure>{_img(im.get(k), cap + ' ' + eid, 'px')}<figcaption>{cap}</figcaption></figure>")
        p.append("</div>")
        eff = e.get("effects") or []
        sk = e.get("skipped_passes") or []
        p.append('<div class="skipped">effects: ' + (html.escape(", ".join(map(str, eff))) or "none"))
        if sk:
            p.append("<br>skipped passes: <ul>" + "".join(
                f"<li>{html.escape(str(s.get('pass')))} ({html.escape(', '.join(map(str, s.get('effects', []))))}): "
                f"{html.escape(str(s.get('reason')))}</li>" for s in sk) + "</ul>")
        else:
            p.append("<br>skipped passes: none")
        ef = e.get("effect_errors") or {}
        if ef:
            p.append("<br>per-effect relMSE: " + ", ".join(
                f"{html.escape(k)} {_num(v.get('relmse'))}" for k, v in ef.items()))
        if e.get("warnings"):
            p.append('<br><span class="warn">warnings: ' + html.escape("; ".join(e["warnings"])) + "</span>")
        p.append("</div>")
    p.append("</body></html>")
    return "\n".join(p)


def write_html(path: str, **kwargs) -> str:
    with open(path, "w", encoding="utf-8") as f:
        f.write(build_html(**kwargs))
    return path
