"""Images and F12 timings of two checkouts, for changes to the frame loop that must not
change what is rendered.

Measure each checkout in a process of its own, then compare:

    python scripts/check_frame_loop.py --measure CHECKOUT --out before.npz
    python scripts/check_frame_loop.py --measure . --out after.npz
    python scripts/check_frame_loop.py --report before.npz after.npz

``--measure`` renders every registered technique (but AUTO) on the ``cornell`` demo scene at
``--size`` pixels (default 32) and ``--samples`` samples (default 4), F12-style (fresh
session, warm-up, deterministic seeds), and times F12 renders of DIRECT, SVGF and RTXGI at
64 x 64 and 8 samples (``--repeats`` each, default 3; the minimum total time and the mean
frame time are kept). ``--report`` prints, per technique, the largest absolute difference
and the relative mean squared difference of the two images (0 = bit-identical), and the
timing ratios after / before.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

TIMED = ("DIRECT", "SVGF", "RTXGI")


def _import_checkout(checkout: str):
    d = tempfile.mkdtemp(prefix="gi_preview_check_pkg_")
    os.symlink(os.path.join(os.path.abspath(checkout), "addon"), os.path.join(d, "gi_preview"),
               target_is_directory=True)
    sys.path.insert(0, d)
    import gi_preview

    return gi_preview


def measure(checkout: str, out: str, size: int, samples: int, repeats: int, only=None):
    gi_preview = _import_checkout(checkout)
    import bpy  # noqa: F401
    import numpy as np

    from gi_preview.blender import reference
    from gi_preview.blender.demo_scenes import build_demo
    from gi_preview.blender.export import export_scene
    from gi_preview.render import session, techniques

    gi_preview.register()
    images, timings = {}, {}
    sc = build_demo("cornell", resolution=size)
    sd = export_scene(reference.evaluated_depsgraph(sc))
    ids = [t.id for t in techniques.available() if t.id != "AUTO"]
    if only:
        ids = [t for t in ids if t in only]
    for k, tid in enumerate(ids):
        t0 = time.perf_counter()
        res = session.render(sd, tid, 1, samples, session=("check", tid))
        images[tid] = res.image
        session.release_session(("check", tid)).result()
        print(f"{tid:20s} {(time.perf_counter() - t0):6.1f} s  mean {float(res.image[..., :3].mean()):.5f}",
              flush=True)
    sc64 = build_demo("cornell", resolution=64)
    sd64 = export_scene(reference.evaluated_depsgraph(sc64))
    for tid in TIMED:
        if only and tid not in only:
            continue
        tot, fr, passes = [], [], None
        for r in range(repeats):
            key = ("check_t", tid, r)
            t0 = time.perf_counter()
            res = session.render(sd64, tid, 1, 8, session=key)
            tot.append((time.perf_counter() - t0) * 1e3)
            fr.append(res.frame_ms)
            passes = res.pass_ms
            session.release_session(key).result()
        timings[tid] = {"total_ms": min(tot), "total_all": tot, "frame_ms": float(np.mean(fr)), "frame_all": fr,
                        "pass_ms": passes}
        print(f"{tid:8s} F12 64px 8spp: total {min(tot):.0f} ms (all {[round(t) for t in tot]}), "
              f"frame {np.mean(fr):.1f} ms", flush=True)
    np.savez_compressed(out, **{f"img_{k}": v for k, v in images.items()},
                        timings=np.array(json.dumps(timings)))


def report(before: str, after: str):
    import numpy as np

    a, b = np.load(before), np.load(after)
    print(f"{'technique':20s} {'max |diff|':>12s} {'relMSE':>10s} {'mean before':>12s} {'mean after':>11s}")
    for k in sorted(x for x in a.files if x.startswith("img_")):
        if k not in b.files:
            print(f"{k[4:]:20s} missing after")
            continue
        x, y = a[k][..., :3].astype(np.float64), b[k][..., :3].astype(np.float64)
        d = np.abs(x - y)
        rel = float(np.mean((x - y) ** 2 / (x ** 2 + 1e-2)))
        print(f"{k[4:]:20s} {d.max():12.3g} {rel:10.3g} {x.mean():12.5f} {y.mean():11.5f}")
    ta, tb = json.loads(str(a["timings"])), json.loads(str(b["timings"]))
    for tid in TIMED:
        if tid in ta and tid in tb:
            print(f"{tid:8s} F12 total {ta[tid]['total_ms']:.0f} -> {tb[tid]['total_ms']:.0f} ms "
                  f"({tb[tid]['total_ms'] / ta[tid]['total_ms']:.2f}x), frame {ta[tid]['frame_ms']:.1f} -> "
                  f"{tb[tid]['frame_ms']:.1f} ms ({tb[tid]['frame_ms'] / ta[tid]['frame_ms']:.2f}x)")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--measure", metavar="CHECKOUT")
    p.add_argument("--out", default="frame_loop.npz")
    p.add_argument("--size", type=int, default=32)
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--only", nargs="*", help="technique ids (default: all)")
    p.add_argument("--report", nargs=2, metavar=("BEFORE", "AFTER"))
    a = p.parse_args()
    if a.report:
        report(*a.report)
    elif a.measure:
        measure(a.measure, a.out, a.size, a.samples, a.repeats, a.only)
        os._exit(0)  # the GL thread is a daemon; leave without waiting for it
    else:
        p.error("--measure or --report")


if __name__ == "__main__":
    main()
