"""Benchmark of the issue-11 techniques (RESTIR_DI and the filters), writing
docs/results/restir/results.json and PNGs (Cycles | ours) for a person to look at.

    cd /work/main && flock /tmp/gi_heavy.lock .venv/bin/python scripts/bench_restir.py [--res 64] [--frames 16]

* many_lights: RESTIR_DI (defaults; temporal on; each bias mode) against light sampling by
  power at equal time per frame: relMSE vs Cycles direct after 1 frame and after N
  accumulated frames, mean brightness, ms/frame.
* cornell, sunlit_room: PT 1 spp, ATROUS, SVGF, TAA: relMSE vs Cycles full of the frame shown
  after N still frames.
Run with the bpy module (tests' conftest style: addon linked as gi_preview on sys.path).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "docs" / "results" / "restir"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=256)
    a = ap.parse_args()
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp())
    pkg = Path(tempfile.mkdtemp())
    (pkg / "gi_preview").symlink_to(REPO / "addon", target_is_directory=True)
    sys.path.insert(0, str(pkg))
    import numpy as np
    import bpy  # noqa: F401
    import gi_preview
    gi_preview.register()
    from gi_preview.blender import demo_scenes as D
    from gi_preview.blender.export import export_scene
    from gi_preview.blender.reference import evaluated_depsgraph, get_reference
    from gi_preview.render import session as S
    from gi_preview.render.gl import get_gl

    def rel(x, ref):
        return float(np.mean((x[..., :3] - ref) ** 2 / (ref ** 2 + 1e-2)))

    def png(imgs, name):
        try:
            from PIL import Image
        except ImportError:
            return
        row = np.concatenate([np.clip(i[..., :3] / (1 + i[..., :3]) * 1.6, 0, 1) ** (1 / 2.2) for i in imgs], 1)
        Image.fromarray((row[::-1] * 255).astype(np.uint8)).save(OUT / name)

    def run(sd, tech, props, n, sess):
        S.render(sd, tech, 1, 1, session=sess, warmup=False)
        if props:
            get_gl().call(lambda: [g.set_properties(props) for _t, g in S._sessions[sess].graphs.values()])
        imgs, ms = [], []
        for f in range(n):
            r = S.render(sd, tech, 1, 1, keep_history=f > 0, warmup=False, session=sess)
            imgs.append(r.image[..., :3])
            ms.append(r.frame_ms)
        S.release_session(sess).result(timeout=60)
        return imgs, float(np.median(ms[1:] if n > 1 else ms))

    OUT.mkdir(parents=True, exist_ok=True)
    results = {"res": a.res, "frames": a.frames, "ref_spp": a.ref_spp, "restir_di": {}, "filters": {}}
    sc = D.build_demo("many_lights", resolution=a.res)
    sd = export_scene(evaluated_depsgraph(sc))
    ref = get_reference(sc, "direct", a.ref_spp).image[..., :3]
    configs = {"default": {}, "temporal": {"restir_di": {"temporal": 1}},
               "bias_1/M": {"restir_di": {"bias_mode": 0}}, "bias_raytraced": {"restir_di": {"bias_mode": 2}}}
    rows = {}
    for name, props in configs.items():
        imgs, ms = run(sd, "RESTIR_DI", props, a.frames, "b_" + name)
        acc = np.mean(imgs, 0)
        rows[name] = {"ms": ms, "relmse_1": rel(imgs[0], ref), "relmse_acc": rel(acc, ref),
                      "mean_vs_cycles": float(acc.mean() / ref.mean())}
        if name == "default":
            png([ref, imgs[0], acc], "many_lights_cycles_restir1_restir_acc.png")
    _i, ms1 = run(sd, "RESTIR_DI", {"restir_di": {"baseline_spp": 1}}, 4, "b_base1")
    spp = max(1, int(round(rows["default"]["ms"] / max(ms1, 1e-3))))
    imgs, bms = run(sd, "RESTIR_DI", {"restir_di": {"baseline_spp": spp}}, a.frames, "b_base")
    acc = np.mean(imgs, 0)
    rows["light_sampling_equal_time"] = {"spp": spp, "ms": bms, "relmse_1": rel(imgs[0], ref),
                                         "relmse_acc": rel(acc, ref), "mean_vs_cycles": float(acc.mean() / ref.mean())}
    png([ref, imgs[0], acc], "many_lights_cycles_base1_base_acc.png")
    results["restir_di"] = rows
    bpy.data.scenes.remove(sc)
    for scene in ("cornell", "sunlit_room"):
        sc = D.build_demo(scene, resolution=a.res)
        sd = export_scene(evaluated_depsgraph(sc))
        ref = get_reference(sc, "full", a.ref_spp).image[..., :3]
        r, shots = {}, [ref]
        for tech in ("PT", "ATROUS", "SVGF", "TAA"):
            imgs, ms = run(sd, tech, {}, a.frames, "f_" + tech)
            r[tech] = {"ms": ms, "relmse_first": rel(imgs[0], ref), "relmse_last": rel(imgs[-1], ref),
                       "mean_vs_cycles": float(imgs[-1].mean() / ref.mean())}
            shots.append(imgs[-1])
        png(shots, f"{scene}_cycles_pt_atrous_svgf_taa.png")
        results["filters"][scene] = r
        bpy.data.scenes.remove(sc)
    (OUT / "results.json").write_text(json.dumps(results, indent=1))
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
