"""A self-contained HTML report of one comparison run (bpy-free, no OpenImageIO needed).

Everything is inline: images as base64 PNG data URIs (the caller encodes them, e.g. with
``imageio.png_bytes``), the chart as inline SVG, CSS and a small script (no libraries, no
network). One file that can be mailed or attached to a CI run.

Layout, top to bottom: the device (and whether its times are CPU-emulated), a sortable
summary table (one row per distinct result: techniques whose images are identical share a
row, with the reason), a flip / slide viewer per row against Cycles, the cost-vs-accuracy
chart, then every detail table collapsed in ``<details>``.

Opening the file with ``#selftest`` appended runs an in-page check (sorting, flipping and
sliding a viewer) and writes its outcome into ``<body data-selftest="ok">`` (or ``"fail: ..."``);
script errors are collected in ``data-errors``.
"""
from __future__ import annotations

import base64
import hashlib
import html
import math
import re
import struct

_BASELINE_LABELS = {"cycles": "Cycles", "cycles_denoised": "Cycles + OpenImageDenoise",
                    "eevee": "EEVEE (ray tracing)"}
_SUMMARY_BASELINES = (("cycles", "vs Cycles"), ("cycles_denoised", "vs Cycles + OIDN"), ("eevee", "vs EEVEE"))
_SOFTWARE_GL = ("llvmpipe", "softpipe", "swiftshader", "lavapipe", "swrast")
_VIEW_MIN_PX = 480  # small images are shown at an integer zoom of at least this width
_DASH = "&mdash;"


# ---------------------------------------------------------------- small helpers
def technique_label(e: dict) -> str:
    """The technique of a results entry as the render panel names it: "RESTIR_GI + SVGF"
    when a filter ends its frames."""
    d = str(e.get("denoiser") or "NONE")
    return str(e.get("technique")) + ("" if d == "NONE" else f" + {d}")


def entry_id(technique: str, quality, reference: str) -> str:
    """The key tying a results entry to its images: ``TECH_q<quality>_<reference>``."""
    return f"{technique}_q{quality}_{reference}"


def _eid(e: dict) -> str:
    return entry_id(e.get("technique"), e.get("quality"), e.get("reference"))


def _row_name(e: dict) -> str:
    return f"{technique_label(e)} q{e.get('quality')}"


def _esc(v) -> str:
    return html.escape(str(v))


def _num(v, fmt="{:.4g}") -> str:
    if v is None:
        return "&ndash;"
    if isinstance(v, float) and not math.isfinite(v):
        return "inf" if v > 0 else ("nan" if v != v else "-inf")
    try:
        return fmt.format(v)
    except (ValueError, TypeError):
        return html.escape(str(v))


def _sortval(v) -> str:
    """A data-v attribute value: finite numbers only (empty sorts last)."""
    return repr(float(v)) if isinstance(v, (int, float)) and math.isfinite(v) else ""


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _img(png: bytes | None, alt: str, cls: str = "") -> str:
    if not png:
        return f'<div class="missing">{_esc(alt)}: no image</div>'
    return f'<img class="{cls}" alt="{_esc(alt)}" title="{_esc(alt)}" src="{_data_uri(png)}"/>'


def _png_size(png: bytes | None) -> tuple[int, int] | None:
    if not png or png[:8] != b"\x89PNG\r\n\x1a\n" or len(png) < 24:
        return None
    return struct.unpack(">II", png[16:24])


def _bound(s: dict) -> str:
    """"&le; 1.2&times;" / "&ge; 3&times;" for a speed-up outside the baseline's curve, else "n/a"."""
    b = s.get("bound") or {}
    if b.get("at_most") is not None:
        return f'&le;&thinsp;{_num(b["at_most"], "{:.3g}")}&times;'
    if b.get("at_least") is not None:
        return f'&ge;&thinsp;{_num(b["at_least"], "{:.3g}")}&times;'
    return "n/a"


def _speedup(e: dict, baseline: str) -> dict | None:
    s = (e.get("speedups") or {}).get(baseline)
    if s is None and baseline == "cycles":
        s = e.get("speedup")
    return s


# ---------------------------------------------------------------- what the report derives
def device(results: dict) -> tuple[str, bool]:
    """(the GL renderer GI Preview ran on, whether it is a software rasterizer): from
    ``run.gl_renderer``, else parsed from the ``run.device`` sentence."""
    run = results.get("run") or {}
    name = run.get("gl_renderer")
    if not name:
        m = re.search(r"GI Preview on (.+?)(?:; |$)", str(run.get("device") or ""))
        name = m.group(1) if m else ""
    name = str(name or "")
    return name, any(s in name.lower() for s in _SOFTWARE_GL)


def _image_key(e: dict, images: dict):
    """What makes two results "the same image": the float image's hash when the run recorded
    it, else the PNG's; with the relMSE. None when neither is known."""
    h = e.get("image_sha256")
    if not h:
        png = (images.get(_eid(e)) or {}).get("ours")
        h = hashlib.sha256(png).hexdigest() if png else None
    return None if h is None else (h, e.get("relmse"))


def fold_identical(entries: list[dict], images: dict) -> list[list[dict]]:
    """Entries grouped by identical image (hash and relMSE), in first-seen order; each group
    ordered fastest first."""
    groups: dict = {}
    for i, e in enumerate(entries):
        key = _image_key(e, images)
        groups.setdefault(key if key is not None else ("entry", i), []).append(e)
    return [sorted(g, key=lambda e: (e.get("frame_ms") is None, e.get("frame_ms") or 0.0))
            for g in groups.values()]


def fold_reason(group: list[dict]) -> str:
    """Why a group's techniques render the same image, from their skipped passes:
    "AUTO q0 = SSDO q0 here: AUTO q0 skipped its indirect_specular passes (ssr_trace, ...): no glossy
    surface in view"."""
    names = " = ".join(_row_name(e) for e in group)
    notes = []
    for e in group:
        by_reason: dict = {}
        for s in e.get("skipped_passes") or []:
            r = by_reason.setdefault(str(s.get("reason")), ([], []))
            r[0].append(str(s.get("pass")))
            r[1].extend(str(x) for x in s.get("effects", []) if str(x) not in r[1])
        for reason, (passes, effects) in by_reason.items():
            what = f"its {', '.join(effects)} passes" if effects else "passes"
            notes.append(f"{_row_name(e)} skipped {what} ({', '.join(passes)}): {reason}")
    if not notes:
        eff = sorted({str(x) for e in group for x in e.get("effects") or []})
        notes.append("same passes run" + (f" ({', '.join(eff)})" if eff else ""))
    return f"{names} here: " + "; ".join(notes)


# ---------------------------------------------------------------- page parts
_CSS = """
body{font-family:system-ui,sans-serif;margin:24px;color:#222;max-width:1350px}
h1{font-size:22px;margin-bottom:4px} h2{font-size:17px;margin-top:28px;border-bottom:1px solid #ccc}
h3{font-size:14px;margin:18px 0 6px}
table{border-collapse:collapse;font-size:13px} th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0} td.l,th.l{text-align:left}
.meta{color:#555;font-size:13px}
.note{background:#fff4d6;border:1px solid #e0b84c;padding:6px 10px;font-size:13px;max-width:900px}
.row{display:flex;gap:12px;flex-wrap:wrap;align-items:flex-start}
.row figure{margin:0} figcaption{font-size:12px;color:#444;text-align:center}
img.px,.viewer img,img.thumb{image-rendering:pixelated}
img.px{width:300px;height:auto;border:1px solid #999}
img.thumb{width:64px;height:auto;display:block;border:1px solid #999}
.missing{width:300px;height:120px;border:1px dashed #aaa;color:#777;font-size:12px;padding:8px}
.legend{font-size:11px;color:#444} .legend img{width:300px;height:10px;display:block;border:1px solid #999}
.skipped{font-size:12px;color:#333} .warn{color:#a40} .same{font-size:12px;color:#555;font-weight:normal}
#summary th.sortable{cursor:pointer;user-select:none} #summary th.sortable:hover{background:#e4e4e4}
#summary th[aria-sort=ascending]::after{content:" \\25B2"} #summary th[aria-sort=descending]::after{content:" \\25BC"}
#summary td{vertical-align:middle} #summary td:not(.l){white-space:nowrap}
.viewers{display:flex;flex-wrap:wrap;gap:8px 28px;align-items:flex-start}
.viewer{margin:6px 0 18px;max-width:100%} .viewer h3{margin-top:6px}
.viewer .bar{font-size:13px;margin-bottom:6px;display:flex;gap:8px;align-items:center}
.viewer button{font-size:12px} .viewer button.on{background:#333;color:#fff}
.stage{position:relative;max-width:100%;border:1px solid #999;cursor:pointer;outline:none;touch-action:none}
.stage:focus{box-shadow:0 0 0 2px #48f}
.stage img{position:absolute;left:0;top:0;width:100%;height:100%;display:block}
.viewer[data-mode=flip][data-show=b] img.top{visibility:hidden}
.stage .divider{position:absolute;top:0;bottom:0;width:2px;margin-left:-1px;background:#fff;
  box-shadow:0 0 2px #000;display:none;pointer-events:none}
.viewer[data-mode=slide] .divider{display:block} .viewer[data-mode=slide] .stage{cursor:ew-resize}
.stage .tag{position:absolute;top:4px;font-size:11px;background:rgba(0,0,0,.6);color:#fff;padding:1px 5px;
  pointer-events:none}
.stage .tag.a{left:4px} .stage .tag.b{right:4px}
.viewer[data-mode=flip] .tag.b,.viewer[data-mode=flip][data-show=b] .tag.a{display:none}
.viewer[data-mode=flip][data-show=b] .tag.b{display:block}
details{margin:10px 0} summary{cursor:pointer;font-weight:600;font-size:15px;padding:4px 0}
"""

_JS = r"""
(function () {
  "use strict";
  var body = document.body;
  window.addEventListener("error", function (ev) {
    body.setAttribute("data-errors", (body.getAttribute("data-errors") || "") + ev.message + "\n");
  });

  // ---- sortable summary table
  function cellKey(row, col, numeric) {
    var td = row.cells[col];
    var v = td.getAttribute("data-v");
    if (!numeric) return (v !== null ? v : td.textContent).trim().toLowerCase();
    return v === null || v === "" ? null : parseFloat(v);
  }
  function sortBy(table, th) {
    var col = th.cellIndex, numeric = th.getAttribute("data-sort") === "num";
    var asc = th.getAttribute("aria-sort") !== "ascending";
    var ths = table.tHead.rows[0].cells;
    for (var i = 0; i < ths.length; i++) ths[i].removeAttribute("aria-sort");
    th.setAttribute("aria-sort", asc ? "ascending" : "descending");
    var tb = table.tBodies[0], rows = Array.prototype.slice.call(tb.rows);
    rows.sort(function (a, b) {
      var x = cellKey(a, col, numeric), y = cellKey(b, col, numeric);
      if (x === null || y === null) return (x === null) - (y === null);  // missing values last
      return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
    });
    rows.forEach(function (r) { tb.appendChild(r); });
  }
  var summary = document.getElementById("summary");
  if (summary) {
    Array.prototype.forEach.call(summary.querySelectorAll("th.sortable"), function (th) {
      th.addEventListener("click", function () { sortBy(summary, th); });
    });
  }

  // ---- flip / slide viewers (a: technique over b: Cycles)
  function setMode(v, mode) {
    v.setAttribute("data-mode", mode);
    v.querySelector("button.flip").classList.toggle("on", mode === "flip");
    v.querySelector("button.slide").classList.toggle("on", mode === "slide");
    setSplit(v, mode === "slide" ? parseFloat(v.getAttribute("data-split") || "0.5") : 1);
  }
  function setSplit(v, f) {
    f = Math.min(1, Math.max(0, f));
    if (v.getAttribute("data-mode") === "slide") v.setAttribute("data-split", String(f));
    var pct = (100 * f).toFixed(2);
    v.querySelector("img.top").style.clipPath = "inset(0 " + (100 - pct) + "% 0 0)";
    v.querySelector(".divider").style.left = pct + "%";
  }
  function flip(v) {
    v.setAttribute("data-show", v.getAttribute("data-show") === "a" ? "b" : "a");
    var label = v.querySelector(".showing");
    label.textContent = v.querySelector(v.getAttribute("data-show") === "a" ? ".tag.a" : ".tag.b").textContent;
  }
  function splitAt(v, ev) {
    var r = v.querySelector(".stage").getBoundingClientRect();
    setSplit(v, (ev.clientX - r.left) / r.width);
  }
  Array.prototype.forEach.call(document.querySelectorAll(".viewer"), function (v) {
    var stage = v.querySelector(".stage"), dragging = false;
    v.querySelector("button.flip").addEventListener("click", function () { setMode(v, "flip"); });
    v.querySelector("button.slide").addEventListener("click", function () { setMode(v, "slide"); });
    stage.addEventListener("click", function () { if (v.getAttribute("data-mode") === "flip") flip(v); });
    stage.addEventListener("pointerdown", function (ev) {
      if (v.getAttribute("data-mode") !== "slide") return;
      dragging = true;
      if (stage.setPointerCapture && ev.pointerId !== undefined) {
        try { stage.setPointerCapture(ev.pointerId); } catch (e) { /* synthetic pointer */ }
      }
      splitAt(v, ev);
    });
    stage.addEventListener("pointermove", function (ev) { if (dragging) splitAt(v, ev); });
    stage.addEventListener("pointerup", function () { dragging = false; });
    stage.addEventListener("pointercancel", function () { dragging = false; });
    stage.addEventListener("keydown", function (ev) {
      var slide = v.getAttribute("data-mode") === "slide";
      if (!slide && (ev.key === " " || ev.key === "f" || ev.key === "Enter")) { flip(v); ev.preventDefault(); }
      else if (slide && (ev.key === "ArrowLeft" || ev.key === "ArrowRight")) {
        setSplit(v, parseFloat(v.getAttribute("data-split")) + (ev.key === "ArrowLeft" ? -0.05 : 0.05));
        ev.preventDefault();
      }
    });
    setMode(v, "flip");
  });

  // ---- #selftest: exercise the page and record the outcome on <body>
  function shownSrc(v, fx) {  // the source of the image visible at fraction fx of the stage's width
    var top = v.querySelector("img.top"), cs = getComputedStyle(top);
    var covered = v.getAttribute("data-mode") === "slide" ? fx < parseFloat(v.getAttribute("data-split"))
      : cs.visibility !== "hidden" && cs.display !== "none";
    return covered ? top.src : v.querySelector("img.base").src;
  }
  function selftest() {
    var fails = [];
    if (summary) {
      var rows = summary.tBodies[0].rows.length;
      body.setAttribute("data-summary-rows", String(rows));
      var th = summary.querySelector("th[data-key=relmse]");
      var col = th.cellIndex, seq = function () {
        return Array.prototype.map.call(summary.tBodies[0].rows, function (r) { return cellKey(r, col, true); })
          .filter(function (x) { return x !== null; });
      };
      th.click();
      var up = seq();
      for (var i = 1; i < up.length; i++) if (up[i - 1] > up[i]) fails.push("relMSE not ascending");
      th.click();
      var down = seq();
      for (var j = 1; j < down.length; j++) if (down[j - 1] < down[j]) fails.push("relMSE not descending");
      if (th.getAttribute("aria-sort") !== "descending") fails.push("sort state not shown");
    } else {
      fails.push("no summary table");
    }
    var v = document.querySelector(".viewer");
    if (!v) {
      fails.push("no viewer");
    } else {
      var stage = v.querySelector(".stage");
      var s0 = shownSrc(v, 0.5);
      stage.click();
      var s1 = shownSrc(v, 0.5);
      if (s0 === s1) fails.push("flip did not change the displayed image");
      stage.click();
      if (shownSrc(v, 0.5) !== s0) fails.push("second flip did not restore the image");
      v.querySelector("button.slide").click();
      var r = stage.getBoundingClientRect();
      var opts = {clientX: r.left + 0.1 * r.width, clientY: r.top + 1, bubbles: true};
      stage.dispatchEvent(new PointerEvent("pointerdown", opts));
      stage.dispatchEvent(new PointerEvent("pointerup", opts));
      var f = parseFloat(v.getAttribute("data-split"));
      if (!(Math.abs(f - 0.1) < 0.02)) fails.push("slide did not move the divider (split " + f + ")");
      if (shownSrc(v, 0.05) !== s0 || shownSrc(v, 0.5) === s0) fails.push("slide did not split the images");
      v.querySelector("button.flip").click();
    }
    body.setAttribute("data-selftest", fails.length ? "fail: " + fails.join("; ") : "ok");
  }
  if (location.hash === "#selftest") selftest();
})();
"""


def _speedup_cell(s: dict | None) -> tuple[str, float | None, str]:
    """(html, sort value, tooltip) of one speed-up."""
    if not s:
        return _DASH, None, "not measured"
    if s.get("speedup") is not None:
        return _num(s["speedup"], "{:.3g}&times;"), s["speedup"], s.get("reason", "")
    b = s.get("bound") or {}
    v = b.get("at_most", b.get("at_least"))
    if v is not None:
        return _bound(s), v, s.get("reason", "")
    return _DASH, None, s.get("reason", "")


def _member_cell(group: list[dict], texts: list[str], sortv, title: str = "", cls: str = "") -> str:
    """One summary cell of a (possibly folded) row: one value, or each member's when they differ."""
    if len(set(texts)) <= 1:
        body = texts[0] if texts else _DASH
    else:
        body = "<br>".join(f'{t} <span class="meta">({_esc(e.get("technique"))})</span>'
                           for e, t in zip(group, texts))
    t = f' title="{_esc(title)}"' if title else ""
    c = f' class="{cls}"' if cls else ""
    return f'<td{c} data-v="{_sortval(sortv)}"{t}>{body}</td>'


def _summary(groups: list[list[dict]], images: dict, ref_kind: str) -> list[str]:
    def render_text(e):
        n, w = e.get("samples") or 1, e.get("warmup_frames") or 0
        what = f"{n} sample{'s' if n != 1 else ''}" + (f" + {w} warm-up" if w else "")
        return f'{_num(e.get("time_ms"), "{:.1f}")} <span class="meta">({what})</span>'
    p = ["<h2>Summary</h2>",
         f'<p class="meta">One row per distinct result, against Cycles &lsquo;{_esc(ref_kind)}&rsquo;; '
         'click a column header to sort. relMSE: lower is closer to Cycles. Speed-up: the baseline&rsquo;s '
         'time to reach the same relMSE / the technique&rsquo;s time (&gt; 1: the technique is faster at equal '
         'error; &le;/&ge;: a bound, the error lies outside the baseline&rsquo;s measured curve; '
         f'{_DASH}: not measured). Hover a cell for its reason. Click a thumbnail to open its viewer.</p>',
         '<table id="summary"><thead><tr><th class="l">image</th>'
         '<th class="l sortable" data-sort="text" data-key="technique">technique</th>'
         '<th class="sortable" data-sort="num" data-key="relmse">relMSE</th>'
         '<th class="sortable" data-sort="num" data-key="ms">ms/frame</th>'
         + '<th class="sortable" data-sort="num" data-key="ms_render" title="one F12 render after setup: '
           'warm-up frames, accumulated frames and read-back">ms (render)</th>'
         + "".join(f'<th class="sortable" data-sort="num" data-key="{b}">{label}</th>'
                   for b, label in _SUMMARY_BASELINES)
         + "</tr></thead><tbody>"]
    for i, g in enumerate(groups):
        e0 = g[0]
        names = " = ".join(_esc(_row_name(e)) for e in g)
        same = f'<br><span class="same">{_esc(fold_reason(g))}</span>' if len(g) > 1 else ""
        thumb = _img((images.get(_eid(e0)) or {}).get("ours"), _row_name(e0), "thumb")
        cells = [f'<td class="l"><a href="#view-{i}">{thumb}</a></td>',
                 f'<td class="l" data-v="{_esc(_row_name(e0))}"><b>{names}</b>{same}</td>',
                 _member_cell(g, [_num(e.get("relmse")) for e in g], e0.get("relmse")),
                 _member_cell(g, [_num(e.get("frame_ms"), "{:.2f}") for e in g], e0.get("frame_ms"))]
        cells.append(_member_cell(g, [render_text(e) for e in g], e0.get("time_ms")))
        for b, _ in _SUMMARY_BASELINES:
            sp = [_speedup_cell(_speedup(e, b)) for e in g]
            cells.append(_member_cell(g, [s[0] for s in sp], sp[0][1], title=sp[0][2]))
        p.append(f'<tr id="row-{i}">' + "".join(cells) + "</tr>")
    p.append("</tbody></table>")
    return p


def _viewers(groups: list[list[dict]], images: dict, ref_kind: str) -> list[str]:
    ref_png = images.get(f"reference:{ref_kind}")
    p = ["<h2>Images: technique vs Cycles</h2>",
         '<p class="meta"><b>Flip</b>: click the image (or press F / space) to switch between the technique and '
         f'Cycles &lsquo;{_esc(ref_kind)}&rsquo;. <b>Slide</b>: drag across the image (or use the arrow keys): '
         'technique on the left, Cycles on the right. Small images are enlarged with square pixels.</p>']
    p.append('<div class="viewers">')
    for i, g in enumerate(groups):
        e0 = g[0]
        im = images.get(_eid(e0)) or {}
        ours, cyc = im.get("ours"), im.get("cycles") or ref_png
        name = " = ".join(_row_name(e) for e in g)
        head = (f'<h3>{_esc(name)} &mdash; relMSE {_num(e0.get("relmse"))}, '
                f'{_num(e0.get("frame_ms"), "{:.2f}")} ms/frame</h3>')
        if not (ours and cyc):
            p.append(f'<div id="view-{i}">{head}<div class="missing">{_esc(name)}: no image</div></div>')
            continue
        w, h = _png_size(ours) or _png_size(cyc) or (256, 256)
        zoom = max(1, math.ceil(_VIEW_MIN_PX / w)) if w < _VIEW_MIN_PX else 1
        cyc_name = f"Cycles {ref_kind}"
        p.append(f'<div class="viewer" id="view-{i}" data-mode="flip" data-show="a" data-split="0.5">{head}'
                 f'<div class="bar"><button type="button" class="flip">Flip</button>'
                 f'<button type="button" class="slide">Slide</button>'
                 f'<span class="meta">{w}&times;{h} px{f", shown &times;{zoom}" if zoom > 1 else ""}; '
                 f'showing: <b class="showing">{_esc(name)}</b></span></div>'
                 f'<div class="stage" tabindex="0" style="width:{w * zoom}px;aspect-ratio:{w}/{h}">'
                 f'<img class="base" alt="{_esc(cyc_name)}" src="{_data_uri(cyc)}"/>'
                 f'<img class="top" alt="{_esc(name)}" src="{_data_uri(ours)}"/>'
                 f'<div class="divider"></div><span class="tag a">{_esc(name)}</span>'
                 f'<span class="tag b">{_esc(cyc_name)}</span></div></div>')
    p.append("</div>")
    return p


def _device(results: dict) -> list[str]:
    name, software = device(results)
    run = results.get("run") or {}
    p = [f'<p><b>Device</b>: GI Preview on <b>{_esc(name or "unknown GL renderer")}</b>'
         + (f' (OpenGL {_esc(run["gl_version"])})' if run.get("gl_version") else "")
         + "; Cycles on the CPU; EEVEE on Blender&rsquo;s own OpenGL context.</p>"]
    if software:
        p.append(f'<p class="note"><b>CPU-emulated times.</b> {_esc(name.split()[0])} is a software '
                 'rasterizer: GI Preview&rsquo;s GPU work ran on the CPU, so its ms/frame are CPU times, not GPU '
                 'times, and the speed-ups compare CPU with CPU. On a real GPU the techniques run far faster.</p>')
    return p


def _metrics_table(entries: list[dict]) -> list[str]:
    p = ["<details><summary>All metrics</summary>",
         '<p class="meta">relMSE = mean (a&minus;b)&sup2;/(b&sup2;+0.01) on linear HDR; FLIP = HDR-FLIP mean; '
         'SSIM and PSNR on the sRGB "Standard" view. Lower is better except SSIM and PSNR. '
         'ms/frame: median time of one accumulated frame; warm-up: the frames (and their ms) a render runs '
         'before it accumulates; ms (render): one F12 render after setup, warm-up, accumulated frames and '
         'read-back included, the time the chart and the speed-up use; viewport ms: one viewport redraw; setup '
         'ms: one-time work (export, GPU upload, BVH, shader compilation), cold (empty shader cache) / warm '
         '(the driver&rsquo;s shader cache filled), never part of the per-render time. Speed-up = Cycles time to '
         'reach the same relMSE / technique time, both without setup (same machine, same run).</p>',
         '<table><tr><th class="l">technique</th><th>quality</th><th class="l">reference</th>'
         '<th>ms/frame</th><th>frames</th><th>warm-up</th><th>ms (render)</th><th>viewport ms</th>'
         '<th>setup ms cold / warm</th><th>relMSE</th><th>FLIP</th>'
         '<th>SSIM</th><th>PSNR (dB)</th><th>non-finite px</th><th>equal-error speed-up</th></tr>']
    for e in entries:
        s = e.get("speedup") or {}
        sp = _num(s.get("speedup"), "{:.3g}&times;") if s.get("speedup") is not None else \
            f'<span title="{_esc(s.get("reason", ""))}">n/a</span>'
        nf = e.get("nonfinite_pixels", 0)
        nf_s = f'<span class="warn">{nf}</span>' if nf else "0"
        p.append(f'<tr><td class="l">{_esc(technique_label(e))}</td><td>{_num(e.get("quality"), "{}")}</td>'
                 f'<td class="l">{_esc(e.get("reference"))}</td><td>{_num(e.get("frame_ms"), "{:.2f}")}</td>'
                 f'<td>{_num(e.get("samples"), "{}")}</td>'
                 f'<td>{_num(e.get("warmup_frames"), "{}")}'
                 f'{" (" + _num(e.get("warmup_ms"), "{:.0f}") + " ms)" if e.get("warmup_frames") else ""}</td>'
                 f'<td>{_num(e.get("time_ms"), "{:.1f}")}</td><td>{_num(e.get("viewport_frame_ms"), "{:.1f}")}</td>'
                 f'<td>{_num(e.get("setup_ms"), "{:.0f}")} / {_num(e.get("setup_warm_ms"), "{:.0f}")}</td>'
                 f'<td>{_num(e.get("relmse"))}</td>'
                 f'<td>{_num(e.get("flip"))}</td><td>{_num(e.get("ssim"), "{:.4f}")}</td>'
                 f'<td>{_num(e.get("psnr"), "{:.2f}")}</td><td>{nf_s}</td><td>{sp}</td></tr>')
    p.append("</table>")
    reasons = [(e, (e.get("speedup") or {}).get("reason")) for e in entries
               if (e.get("speedup") or {}).get("speedup") is None and (e.get("speedup") or {}).get("reason")]
    if reasons:
        p.append('<ul class="skipped">' + "".join(
            f"<li>{_esc(technique_label(e))} q{e.get('quality')} vs {_esc(e.get('reference'))}: "
            f"no speed-up: {_esc(r)}</li>" for e, r in reasons) + "</ul>")
    p.append("</details>")
    return p


def _speedup_table(results: dict, entries: list[dict], ref_kind: str) -> list[str]:
    baselines = results.get("baselines") or {}
    with_sp = [e for e in entries if e.get("speedups") and e.get("reference") == ref_kind]
    names = [b for b in baselines if any(b in e["speedups"] for e in with_sp)]
    if not (with_sp and names):
        return []
    p = ["<details><summary>Equal-error speed-ups</summary>",
         f'<p class="meta">Each baseline&rsquo;s per-frame time to reach the technique&rsquo;s relMSE against '
         f'Cycles &lsquo;{_esc(ref_kind)}&rsquo;, divided by the technique&rsquo;s time per render (its warm-up frames '
         'counted); one-time setup left out on both sides. &gt; 1: the technique is faster at equal error. &le;/&ge;: the technique&rsquo;s error '
         'lies outside the baseline&rsquo;s measured curve, so only a bound is known (&le;: the baseline&rsquo;s '
         'cheapest render is already more accurate; &ge;: the technique beats its most expensive one); hover for '
         'the reason. No extrapolation.</p>',
         '<table><tr><th class="l">technique</th><th>quality</th><th>ms (render)</th><th>relMSE</th>'
         + "".join(f"<th>vs {_esc(_BASELINE_LABELS.get(b, b))}</th>" for b in names) + "</tr>"]
    for e in with_sp:
        cells = []
        for b in names:
            s = e["speedups"].get(b) or {}
            if s.get("speedup") is not None:
                cells.append(f'<td title="{_esc(s.get("reason", ""))}">{_num(s["speedup"], "{:.3g}&times;")}'
                             f' <span class="meta">({_num(s.get("cycles_spp"), "{:.2g}")} spp)</span></td>')
            else:
                cells.append(f'<td><span title="{_esc(s.get("reason", ""))}">{_bound(s)}</span></td>')
        p.append(f'<tr><td class="l">{_esc(technique_label(e))}</td><td>{_num(e.get("quality"), "{}")}</td>'
                 f'<td>{_num(e.get("time_ms"), "{:.1f}")}</td><td>{_num(e.get("relmse"))}</td>{"".join(cells)}</tr>')
    p.append("</table></details>")
    return p


def _baselines(results: dict, images: dict) -> list[str]:
    baselines = results.get("baselines") or {}
    setup = results.get("baselines_setup") or {}
    curve = results.get("cycles_curve") or []
    if not (baselines or curve):
        return []
    p = ["<details><summary>Baselines: what a user would pick instead</summary>"]
    base_imgs = [(k[len("baseline:"):], v) for k, v in images.items() if k.startswith("baseline:")]
    if base_imgs:
        p.append('<div class="row">')
        for name, png in base_imgs:
            pts = baselines.get(name) or [{}]
            cap = f"{_BASELINE_LABELS.get(name, name)}, {_num(pts[-1].get('spp'), '{}')} spp"
            p.append(f"<figure>{_img(png, cap, 'px')}<figcaption>{_esc(cap)}</figcaption></figure>")
        p.append("</div>")
    if baselines:
        p.append('<p class="meta">Each baseline rendered at 1, 2, 4, &hellip; samples in the same run. Wall times '
                 'are fitted as setup + per-sample &times; spp; <i>ms/frame</i> leaves the setup out (scene sync and '
                 'BVH for Cycles, per-render set-up for EEVEE), <i>wall ms</i> is the measured render call. The '
                 'first render of each (Cycles&rsquo; kernels, the denoiser, EEVEE&rsquo;s shader compilation) is an '
                 'untimed warm-up.</p>')
    for b, pts in baselines.items():
        info = setup.get(b) or {}
        extra = info.get("first_render_extra_ms")
        p.append(f"<p><b>{_esc(_BASELINE_LABELS.get(b, b))}</b>: setup {_num(info.get('setup_ms'), '{:.0f}')} ms, "
                 f"{_num(info.get('per_sample_ms'), '{:.3g}')} ms per sample"
                 + (f", first render +{_num(extra, '{:.0f}')} ms" if extra is not None else "") + "</p>")
        p.append('<table><tr><th>spp</th><th>ms/frame</th><th>wall ms</th><th>relMSE</th><th>FLIP</th>'
                 '<th>SSIM</th></tr>')
        for c in pts:
            p.append(f'<tr><td>{_num(c.get("spp"), "{}")}</td><td>{_num(c.get("time_ms"), "{:.1f}")}</td>'
                     f'<td>{_num(c.get("wall_ms"), "{:.0f}")}</td><td>{_num(c.get("relmse"))}</td>'
                     f'<td>{_num(c.get("flip"))}</td><td>{_num(c.get("ssim"), "{:.4f}")}</td></tr>')
        p.append("</table>")
    if curve and not baselines:
        p.append("<h3>Cycles' own curve</h3>")
        p.append('<table><tr><th>spp</th><th>time (ms)</th><th>relMSE</th><th>FLIP</th></tr>')
        for c in curve:
            p.append(f'<tr><td>{_num(c.get("spp"), "{}")}</td><td>{_num(c.get("time_ms"), "{:.0f}")}</td>'
                     f'<td>{_num(c.get("relmse"))}</td><td>{_num(c.get("flip"))}</td></tr>')
        p.append("</table>")
    p.append("</details>")
    return p


def _references(results: dict, images: dict) -> list[str]:
    refs = results.get("references") or ({results["reference"]["kind"]: results["reference"]}
                                         if results.get("reference") else {})
    ref_imgs = [(k[len("reference:"):], v) for k, v in images.items() if k.startswith("reference:")]
    if not (refs or ref_imgs):
        return []
    p = ["<details><summary>Cycles references: settings and bounces</summary>",
         '<table><tr><th class="l">kind</th><th>spp</th><th>time (ms)</th><th class="l">bounces</th>'
         '<th>seed</th><th class="l">from cache</th><th class="l">Blender</th></tr>']
    for kind, r in refs.items():
        b = r.get("bounces", {})
        bstr = ", ".join(f"{k}={v}" for k, v in b.items()) if isinstance(b, dict) else str(b)
        p.append(f'<tr><td class="l">{_esc(kind)}</td><td>{_num(r.get("spp"), "{}")}</td>'
                 f'<td>{_num(r.get("time_ms"), "{:.0f}")}</td><td class="l">{_esc(bstr)}</td>'
                 f'<td>{_num(r.get("seed"), "{}")}</td><td class="l">{"yes" if r.get("cached") else "no"}</td>'
                 f'<td class="l">{_esc(r.get("blender_version", ""))}</td></tr>')
    p.append("</table>")
    if results.get("reference_settings"):
        p.append('<p class="meta">Reference settings: ' + _esc(results["reference_settings"]) + "</p>")
    if ref_imgs:
        p.append('<div class="row">' + "".join(
            f"<figure>{_img(png, 'Cycles ' + kind, 'px')}<figcaption>Cycles, {_esc(kind)}</figcaption></figure>"
            for kind, png in ref_imgs) + "</div>")
    p.append("</details>")
    return p


def _entry_details(entries: list[dict], images: dict, colorbar_png: bytes | None, legend: dict) -> list[str]:
    if not entries:
        return []
    p = ["<details><summary>Per result: error maps, effects and skipped passes</summary>"]
    if colorbar_png:
        lo, hi = legend.get("vmin"), legend.get("vmax")
        p.append(f'<div class="legend">Error map: per-pixel relMSE, {_esc(legend.get("scale", "log10"))} scale, '
                 f'{_esc(legend.get("colormap", "viridis"))}, from {_num(lo)} (left) to {_num(hi)} (right); '
                 f'magenta = non-finite pixel.{_img(colorbar_png, "legend")}</div>')
    for e in entries:
        eid = _eid(e)
        im = images.get(eid, {})
        p.append(f"<h3>{_esc(_row_name(e))} vs Cycles {_esc(e.get('reference'))} &mdash; relMSE "
                 f"{_num(e.get('relmse'))}, FLIP {_num(e.get('flip'))}, {_num(e.get('time_ms'), '{:.2f}')} ms</h3>")
        if im.get("error"):
            p.append(f"<figure>{_img(im['error'], 'error (relMSE) ' + eid, 'px')}"
                     "<figcaption>error (relMSE)</figcaption></figure>")
        eff = e.get("effects") or []
        sk = e.get("skipped_passes") or []
        p.append('<div class="skipped">effects: ' + (_esc(", ".join(map(str, eff))) or "none"))
        if sk:
            p.append("<br>skipped passes: <ul>" + "".join(
                f"<li>{_esc(s.get('pass'))} ({_esc(', '.join(map(str, s.get('effects', []))))}): "
                f"{_esc(s.get('reason'))}</li>" for s in sk) + "</ul>")
        else:
            p.append("<br>skipped passes: none")
        ef = e.get("effect_errors") or {}
        if ef:
            p.append("<br>per-effect relMSE: " + ", ".join(
                f"{_esc(k)} {_num(v.get('relmse'))}" for k, v in ef.items()))
        if e.get("warnings"):
            p.append('<br><span class="warn">warnings: ' + _esc("; ".join(e["warnings"])) + "</span>")
        p.append("</div>")
    p.append("</details>")
    return p


def _run_settings(results: dict) -> list[str]:
    meta = results.get("run") or {}
    if not meta:
        return []
    return ["<details><summary>Run settings</summary><table>"
            + "".join(f'<tr><th class="l">{_esc(k)}</th><td class="l">{_esc(v)}</td></tr>' for k, v in meta.items())
            + "</table></details>"]


# ---------------------------------------------------------------- the page
def build_html(*, title: str, results: dict, images: dict | None = None, chart_svg: str = "",
               colorbar_png: bytes | None = None, legend: dict | None = None) -> str:
    """The report as one HTML string.

    results: the results.json dict (``scene``, ``reference``, ``references``, ``entries``,
      ``cycles_curve``, ``run``...). Each entry: technique, quality, reference, frame_ms, time_ms,
      relmse, flip, ssim, psnr, nonfinite_pixels, effects, skipped_passes, image_sha256 (optional),
      speedup and speedups ({baseline: {speedup, cycles_spp, reason, bound}}).
      ``run.gl_renderer`` names the device (else it is read from ``run.device``).
    images: {entry_id(...): {"ours": png, "cycles": png, "error": png}} plus optional
      {"reference:<kind>": png} for each Cycles reference and {"baseline:<name>": png} for each
      baseline's image at its largest sample count.
    """
    images = images or {}
    entries = results.get("entries", [])
    ref_kind = (results.get("baselines_reference") or (results.get("reference") or {}).get("kind")
                or "full")
    main = [e for e in entries if e.get("reference") == ref_kind] or entries
    groups = fold_identical(main, images)
    p = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_esc(title)}</title>",
         f"<style>{_CSS}</style></head><body>", f"<h1>{_esc(title)}</h1>"]
    p += _device(results)
    if main:
        p += _summary(groups, images, ref_kind)
        p += _viewers(groups, images, ref_kind)
    if chart_svg:
        p += ["<h2>Cost vs accuracy</h2>", chart_svg]
    if results.get("animation"):
        from .animation import report_html
        p.append(report_html(results["animation"], images))
    details = ((_metrics_table(entries) if entries else []) + _speedup_table(results, entries, ref_kind)
               + _entry_details(entries, images, colorbar_png, legend or {}) + _baselines(results, images)
               + _references(results, images) + _run_settings(results))
    if details:
        p += ["<h2>Details</h2>"] + details
    p += [f"<script>{_JS}</script>", "</body></html>"]
    return "\n".join(p)


def write_html(path: str, **kwargs) -> str:
    with open(path, "w", encoding="utf-8") as f:
        f.write(build_html(**kwargs))
    return path


# ---------------------------------------------------------------- index of a sweep over scenes
def _index_chart(scenes: list[dict], width: int = 760, height: int = 360) -> str:
    """relMSE (log) of every technique and quality level per scene, as an inline SVG: one column
    per scene, one colour per technique label."""
    ok = [s for s in scenes if not s.get("error") and s.get("rows")]
    labels = []
    for s in ok:
        for r in s["rows"]:
            name = _row_name(r)
            if name not in labels:
                labels.append(name)
    vals = [r["relmse"] for s in ok for r in s["rows"] if isinstance(r.get("relmse"), (int, float))
            and math.isfinite(r["relmse"]) and r["relmse"] > 0]
    if not vals:
        return ""
    palette = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
               "#bcbd22", "#7f7f7f"]
    lo, hi = math.floor(math.log10(min(vals))), math.ceil(math.log10(max(vals)))
    hi = hi if hi > lo else lo + 1
    ml, mr, mt, mb = 64, 190, 20, 70
    pw, ph = width - ml - mr, height - mt - mb

    def y(v):
        return mt + ph - (math.log10(v) - lo) / (hi - lo) * ph

    p = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" '
         f'font-size="11" id="scene-chart"><rect width="{width}" height="{height}" fill="white"/>']
    for d in range(lo, hi + 1):
        yy = y(10.0 ** d)
        p.append(f'<line x1="{ml}" y1="{yy:.1f}" x2="{ml + pw}" y2="{yy:.1f}" stroke="#ddd"/>'
                 f'<text x="{ml - 6}" y="{yy + 4:.1f}" text-anchor="end">1e{d}</text>')
    p.append(f'<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>')
    p.append(f'<text x="14" y="{mt + ph / 2:.1f}" text-anchor="middle" transform="rotate(-90 14 {mt + ph / 2:.1f})">'
             f'relMSE against Cycles (log scale)</text>')
    step = pw / max(1, len(ok))
    for i, s in enumerate(ok):
        cx = ml + step * (i + 0.5)
        p.append(f'<text x="{cx:.1f}" y="{mt + ph + 14}" text-anchor="end" '
                 f'transform="rotate(-30 {cx:.1f} {mt + ph + 14})">{_esc(s["label"])}</text>')
        n = len(s["rows"])
        for j, r in enumerate(s["rows"]):
            v = r.get("relmse")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                continue
            x = cx + (j - (n - 1) / 2) * min(8.0, step * 0.8 / max(1, n))
            col = palette[labels.index(_row_name(r)) % len(palette)]
            p.append(f'<circle cx="{x:.1f}" cy="{y(v):.1f}" r="4" fill="{col}"><title>{_esc(s["label"])}: '
                     f'{_esc(_row_name(r))} relMSE {v:.4g}</title></circle>')
    for k, name in enumerate(labels):
        ly = mt + 10 + 16 * k
        p.append(f'<circle cx="{ml + pw + 16}" cy="{ly}" r="4" fill="{palette[k % len(palette)]}"/>'
                 f'<text x="{ml + pw + 26}" y="{ly + 4}">{_esc(name)}</text>')
    p.append("</svg>")
    return "\n".join(p)


def build_index(summary: dict) -> str:
    """The index page of a sweep over scenes (``summary.json``'s dict): a table with one row per
    scene (its report, reference time, and relMSE and ms/frame of every technique and quality
    level against Cycles; a failed scene shows its error) and a chart of relMSE across scenes."""
    scenes = summary.get("scenes", [])
    cols = []
    for s in scenes:
        for r in s.get("rows") or []:
            name = _row_name(r)
            if name not in cols:
                cols.append(name)
    n_fail = len(summary.get("failed") or [])
    wall = summary.get("wall_s")
    how = (f"{summary['workers']} Dask worker(s)" if summary.get("workers") else "one process")
    title = f"GI Preview vs Cycles: {len(scenes)} scene(s)"
    p = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_esc(title)}</title>",
         f"<style>{_CSS}</style></head><body>", f"<h1>{_esc(title)}</h1>",
         f"<p class='meta'>{len(scenes) - n_fail} compared, {n_fail} failed; {_esc(how)}"
         + (f", {wall:.1f} s wall" if isinstance(wall, (int, float)) else "")
         + f"; {len(summary.get('tasks_run') or [])} task(s) run, {summary.get('tasks_skipped', 0)} reused "
           "from an earlier run. Each cell: relMSE against Cycles / ms per frame.</p>"]
    p.append("<table id='scenes'><thead><tr><th class='l'>scene</th><th class='l'>status</th>"
             "<th>size</th><th>Cycles ref ms (spp)</th>"
             + "".join(f"<th>{_esc(c)}</th>" for c in cols) + "</tr></thead><tbody>")
    for s in scenes:
        name = _esc(s["label"])
        link = f"<a href='{_esc(s['report'])}'>{name}</a>" if s.get("report") and not s.get("error") else name
        if s.get("error"):
            p.append(f"<tr class='failed' data-scene='{name}'><td class='l'>{link}</td>"
                     f"<td class='l warn' colspan='{3 + len(cols)}'>failed: {_esc(s['error'])}</td></tr>")
            continue
        res = s.get("resolution") or []
        by = {_row_name(r): r for r in s.get("rows") or []}
        cells = []
        for c in cols:
            r = by.get(c)
            cells.append(f"<td data-v='{_sortval(r['relmse'])}'>{_num(r['relmse'])} / {_num(r['time_ms'], '{:.3g}')}"
                         "</td>" if r else f"<td>{_DASH}</td>")
        p.append(f"<tr data-scene='{name}'><td class='l'>{link}</td><td class='l'>ok</td>"
                 f"<td>{'x'.join(str(v) for v in res) or _DASH}</td>"
                 f"<td>{_num(s.get('reference_ms'), '{:.0f}')} ({_esc(s.get('reference_spp'))})</td>"
                 + "".join(cells) + "</tr>")
    p.append("</tbody></table>")
    chart = _index_chart(scenes)
    if chart:
        p += ["<h2>relMSE across scenes</h2>", chart]
    p.append("</body></html>")
    return "\n".join(p)


def write_index(path: str, summary: dict) -> str:
    with open(path, "w", encoding="utf-8") as f:
        f.write(build_index(summary))
    return path
