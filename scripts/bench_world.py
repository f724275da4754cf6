#!/usr/bin/env python3
"""Every technique under worlds as artists build them, against Cycles.

    .venv/bin/python scripts/bench_world.py [--scenes hdri:forest,pavilion:courtyard,sky:MULTIPLE_SCATTERING]
        [--techniques PT,DIRECT,...] [--res 48] [--ref-spp 512] [--samples 16] [--pt-samples 64]
        [--denoiser AUTO|NONE|ATROUS|SVGF] [--set PASS.PARAM=VALUE ...] [--out DIR]

Output folder ``--out``: default ``out/bench/world/``. The documentation's world results
(docs/results/world/, linked from its README.md) are regenerated on purpose with

    .venv/bin/python scripts/bench_world.py --scenes all --res 40 --ref-spp 512 --samples 16 \
        --pt-samples 64 --out docs/results/world

(about 12 minutes on 2 cores; then delete docs/results/world/results.json, which no page
links, and update the numbers README.md quotes).

Scenes (``blender_tests/scenes_world.py``): ``hdri:NAME`` (one of the eight HDRIs Blender
ships, through an Environment Texture rotated by a Mapping node), ``pavilion:NAME`` (the same
under a roof and beside a wall, so part of it sees the world only around a corner),
``sky:TYPE`` (a Sky Texture of that type), ``gradient`` (a procedural world), ``demo:NAME`` (a
demo scene of addon/blender/demo_scenes.py) and
``room:bsdf`` (blender_tests/scenes_real.py: glass, mixes, transparency and translucency in a
room lit by an area light; every technique is measured there the same way). ``all`` =
the eight HDRIs, the four sky types, the gradient and the pavilion under courtyard.

For every scene: the world's evaluation time (Cycles, once; cached afterwards), the Cycles
references "full" and "direct", and for every technique an F12-style render of
``--samples`` frames (PT ``--pt-samples``), each with the filter ``--denoiser`` names (default
AUTO, the panel's Technique Default: RESTIR_GI ends in SVGF, the others unfiltered): relMSE
against full (DIRECT also against direct), the image mean over Cycles' and the median frame
time. summary.md marks in bold each cell worse than DIRECT's against full (DIRECT has no
indirect light, so a technique above it makes the image worse than having none). Times are those of this
machine's OpenGL (llvmpipe on a machine without a GPU): compare them as ratios.

Writes ``<out>/results.json``, ``<out>/summary.md`` (with the command that made it) and per
scene ``<out>/<scene>.png``: one row per technique, ours | Cycles | error (|ours - Cycles| x 4),
tone-mapped.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
ALL = ("hdri:city,hdri:courtyard,hdri:forest,hdri:interior,hdri:night,hdri:studio,hdri:sunrise,hdri:sunset,"
       "sky:SINGLE_SCATTERING,sky:MULTIPLE_SCATTERING,sky:PREETHAM,sky:HOSEK_WILKIE,gradient,pavilion:courtyard")


def log(msg):
    print(f"[bench_world {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def build(spec: str, res: int):
    import scenes_world as SW

    kind, _, arg = spec.partition(":")
    if kind == "hdri":
        return SW.hdri_scene(arg or "forest", res=res)
    if kind == "pavilion":
        return SW.hdri_scene(arg or "courtyard", res=res, roof=True)
    if kind == "sky":
        return SW.sky_scene(arg or None, res=res)
    if kind == "gradient":
        return SW.gradient_scene(res=res)
    if kind == "demo":
        from gi_preview.blender.demo_scenes import build_demo

        return build_demo(arg, resolution=res)
    if kind == "room" and arg in ("", "bsdf"):
        import tempfile

        import scenes_real

        return scenes_real.bsdf_room(tempfile.mkdtemp(prefix="gi_bsdf_room_"), resolution=res)
    raise SystemExit(f"bench_world: unknown scene {spec!r} (hdri:NAME, pavilion:NAME, sky:TYPE, gradient, room:bsdf)")


def tonemap(img):
    import numpy as np

    x = np.clip(img[..., :3] / (1.0 + img[..., :3]), 0, 1) ** (1 / 2.2)
    return x


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", default="hdri:forest,pavilion:courtyard,sky:MULTIPLE_SCATTERING")
    p.add_argument("--techniques", default="")
    p.add_argument("--res", type=int, default=48)
    p.add_argument("--ref-spp", type=int, default=512)
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--pt-samples", type=int, default=64)
    p.add_argument("--denoiser", default="AUTO", choices=("AUTO", "NONE", "ATROUS", "SVGF"),
                   help="the filter after each technique (AUTO: the technique's default, as the panel's default)")
    p.add_argument("--set", action="append", default=[], metavar="PASS.PARAM=VALUE",
                   help="a pass parameter for every technique that has the pass (repeatable)")
    p.add_argument("--out", default=os.path.join(REPO, "out", "bench", "world"),
                   help="output folder (default: out/bench/world; the docs' results: docs/results/world)")
    a = p.parse_args(argv)
    params: dict = {}
    for item in a.set:
        key, _, value = item.partition("=")
        pass_name, _, param = key.partition(".")
        if not (pass_name and param and value):
            raise SystemExit(f"bench_world: --set {item!r}: expected PASS.PARAM=VALUE")
        params.setdefault(pass_name, {})[param] = float(value)

    sys.path.insert(0, HERE)
    sys.path.insert(0, os.path.join(REPO, "blender_tests"))
    from _checkout import setup_blender

    setup_blender()
    import numpy as np

    from gi_preview.blender import reference as R
    from gi_preview.blender.export import export_scene
    from gi_preview.compare import imageio, metrics
    from gi_preview.render import session, techniques

    R.ensure_oiio()
    techs = [t for t in a.techniques.split(",") if t] or [t.id for t in techniques.available()]
    scenes = (ALL if a.scenes == "all" else a.scenes).split(",")
    os.makedirs(a.out, exist_ok=True)
    results = {"res": a.res, "ref_spp": a.ref_spp, "samples": a.samples, "pt_samples": a.pt_samples,
               "denoiser": a.denoiser, "device": None, "scenes": {}}
    for spec in scenes:
        sc = build(spec, a.res)
        t0 = time.perf_counter()
        data = export_scene(R.evaluated_depsgraph(sc))
        export_ms = (time.perf_counter() - t0) * 1e3
        refs = {k: R.get_reference(sc, k, a.ref_spp) for k in ("full", "direct")}
        full = refs["full"].image[..., :3]
        row = {"world": data.world.source, "world_exact": data.world.exact, "export_ms": round(export_ms, 1),
               "cycles_full_ms": refs["full"].time_ms, "techniques": {}}
        log(f"{spec}: export {export_ms:.0f} ms (world: {data.world.source}), Cycles full {refs['full'].time_ms:.0f} ms")
        strip = []
        for tech in techs:
            n = a.pt_samples if tech == "PT" else a.samples
            try:
                r = session.render(data, tech, 1, n, denoiser=a.denoiser, params=params or None)
            except Exception as exc:  # noqa: BLE001 - one technique failing is a row, not the end
                row["techniques"][tech] = {"error": repr(exc)}
                log(f"  {tech}: error {exc!r}")
                continue
            if results["device"] is None:
                from gi_preview.render.gl import get_gl

                info = getattr(get_gl(), "info", {}) or {}
                results["device"] = f"{info.get('GL_RENDERER')} | {info.get('GL_VERSION')}"
            img = r.image[..., :3]
            rec = {"relmse_full": round(metrics.relmse(img, full), 5),
                   "mean_ratio": round(float(img.mean() / max(full.mean(), 1e-12)), 4),
                   "finite": bool(np.isfinite(img).all()), "frame_ms": round(r.frame_ms, 2), "samples": n}
            if tech == "DIRECT":
                rec["relmse_direct"] = round(metrics.relmse(img, refs["direct"].image[..., :3]), 5)
            row["techniques"][tech] = rec
            log(f"  {tech}: relMSE {rec['relmse_full']:.4f} mean {rec['mean_ratio']:.3f} {rec['frame_ms']:.1f} ms/frame")
            strip.append(np.concatenate([tonemap(img), tonemap(full), np.clip(np.abs(img - full) * 4.0, 0, 1) ** (1 / 2.2)],
                                        axis=1))
        if strip:
            imageio.write_png(os.path.join(a.out, f"{spec.replace(':', '_')}.png"),
                              np.concatenate(strip[::-1], axis=0))
        results["scenes"][spec] = row
        bpy_remove_scene(sc)
    with open(os.path.join(a.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    write_summary(results, techs, os.path.join(a.out, "summary.md"), command_line(a))
    log(f"wrote {a.out}")


def bpy_remove_scene(sc):
    import bpy

    bpy.data.scenes.remove(sc)


def command_line(a) -> str:
    """The command that makes this run's results (for summary.md)."""
    out = os.path.abspath(a.out)
    rel = os.path.relpath(out, REPO)
    args = [f"--scenes {a.scenes}"] + ([f"--techniques {a.techniques}"] if a.techniques else []) + [
        f"--res {a.res}", f"--ref-spp {a.ref_spp}", f"--samples {a.samples}", f"--pt-samples {a.pt_samples}",
        *([f"--denoiser {a.denoiser}"] if a.denoiser != "AUTO" else []), *[f"--set {x}" for x in a.set],
        f"--out {out if rel.startswith('..') else rel}"]
    return ".venv/bin/python scripts/bench_world.py " + " ".join(args)


def _denoiser_words(d: str) -> str:
    if d == "AUTO":
        return "the panel's default does (Technique Default: RESTIR_GI through SVGF, the rest unfiltered)"
    return "nothing (the raw estimators)" if d == "NONE" else f"{d} after every technique"


def write_summary(results, techs, path, command="scripts/bench_world.py"):
    scenes = list(results["scenes"])
    lines = [f"# Techniques under HDRI, sky and procedural worlds, against Cycles", "",
             f"{results['res']}×{results['res']} px; Cycles references at {results['ref_spp']} spp (box filter, "
             f"no denoising); every technique accumulates {results['samples']} frames (PT {results['pt_samples']}), "
             f"filtered as {_denoiser_words(results.get('denoiser', 'NONE'))}. "
             f"relMSE against Cycles full (DIRECT: also against Cycles direct, in brackets); the second figure "
             f"is the image mean over Cycles'. **Bold**: worse than DIRECT against full. Frame times are those of "
             f"`{results.get('device') or 'this machine'}`: compare them as ratios, not as milliseconds.", "",
             f"Made by `{command}`. Per scene, `<scene>.png` shows one row "
             "per technique (in the order of the table, top to bottom): ours | Cycles | error ×4.", ""]
    lines.append("| technique | " + " | ".join(scenes) + " |")
    lines.append("|---|" + "---|" * len(scenes))
    worse = []
    for t in techs:
        cells = []
        for s in scenes:
            recs = results["scenes"][s]["techniques"]
            rec = recs.get(t)
            if rec is None:
                cells.append("—")
            elif "error" in rec:
                cells.append("error")
            else:
                extra = f" ({rec['relmse_direct']:.3f})" if "relmse_direct" in rec else ""
                cell = f"{rec['relmse_full']:.3f}{extra} / {rec['mean_ratio']:.2f}"
                base = recs.get("DIRECT", {}).get("relmse_full")
                if t != "DIRECT" and base is not None and rec["relmse_full"] > base:
                    worse.append(f"{t} on {s} ({rec['relmse_full']:.4f} > {base:.4f})")
                    cell = f"**{cell}**"
                cells.append(cell)
        lines.append(f"| {t} | " + " | ".join(cells) + " |")
    n_cells = sum(1 for s in scenes for t, r in results["scenes"][s]["techniques"].items()
                  if t != "DIRECT" and "error" not in r)
    lines += ["", f"Worse than DIRECT against full: {len(worse)} of {n_cells} cells"
              + (": " + "; ".join(worse) + "." if worse else ".")]
    lines += ["", "Export time includes evaluating the world with Cycles unless its map was already cached "
              "(on this machine a first evaluation takes 5–8 s).", "",
              "| scene | world | export (ms) | Cycles full (ms) |", "|---|---|---|---|"]
    for s in scenes:
        r = results["scenes"][s]
        lines.append(f"| {s} | {r['world']} | {r['export_ms']:.0f} | {r['cycles_full_ms']:.0f} |")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
