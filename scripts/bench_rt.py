"""Ray-tracing benchmark: BVH build, ray throughput, and PT vs Cycles time to equal error.

Run with the bpy module:  .venv/bin/python scripts/bench_rt.py [--quick] [--out DIR]

1. BVH build (CPU, numpy; ``bvh.build_blas``) for triangle soups of 1e5, 1e6 and 4e6
   triangles (a displaced sphere, so the triangles are small, coherent and overlapping like a
   scanned mesh): wall time and node count.
2. Ray throughput of ``shaders/lib/bvh.glsl`` (``shaders/pt/raybench.comp``) on the Cornell
   demo scene and on the Cornell box with a 1e6-triangle displaced sphere in it: primary rays
   (closest hit, one per pixel of a 256 x 256 camera), shadow rays (any hit, from every primary
   hit to a point under the ceiling) and diffuse-bounce rays (closest hit, cosine-distributed
   from every primary hit). Median of 5 dispatches, each synchronised (ctx.finish).
3. PT against Cycles on the same machine in the same run, on the Cornell demo scene at
   128 x 128: a Cycles reference at high spp (fair settings, cached on disk), then PT at
   1, 2, 4, ... spp and Cycles at 1, 2, 4, ... spp (another seed, never cached), each timed
   and measured (relMSE against the reference, ``compare.metrics``). The time each needs to
   reach a given relMSE is interpolated log-log between neighbouring points; the ratio
   PT time / Cycles time is quoted per target. PT's time is its tracing time plus its BVH
   build (Cycles' includes its sync and BVH build).

Writes ``rt_benchmark.md`` and ``rt_benchmark.json`` (with machine and GL info) into ``--out``,
default ``out/bench/rt/``. The page docs/results/rt_benchmark.md is regenerated with
``--out docs/results`` (then delete the .json there, or link it: every file under
docs/results must be linked from a page).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import import_checkout_package  # noqa: E402

import_checkout_package()
import bpy  # noqa: E402,F401
import moderngl  # noqa: E402
import numpy as np  # noqa: E402

from gi_preview.blender import demo_scenes as D  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.blender.reference import evaluated_depsgraph, get_reference, render_cycles  # noqa: E402
from gi_preview.compare import metrics as M  # noqa: E402
from gi_preview.render import bvh as B  # noqa: E402
from gi_preview.render.gpu_scene import set_uniform  # noqa: E402
from gi_preview.render.rt_scene import RtBuffers  # noqa: E402
from gi_preview.render.scene_data import Instance, Mesh  # noqa: E402
from gi_preview.render.shaders import ProgramCache  # noqa: E402
from gi_preview.render.techniques.pt import render_offline  # noqa: E402


# ---------------------------------------------------------------- geometry
def displaced_sphere(n_tris: int, radius: float = 1.0, seed: int = 0) -> np.ndarray:
    """(3T, 3) float32 triangle soup of a UV sphere with ~n_tris triangles, radially displaced."""
    n_lat = max(4, int(round(np.sqrt(n_tris / 4))))
    n_lon = max(8, int(round(n_tris / (2 * n_lat))))
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    r = radius * (1 + 0.05 * np.sin(9 * T) * np.cos(7 * P))
    xyz = np.stack([r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T)], -1).astype(np.float32)
    a, b = xyz[:-1, :-1], xyz[1:, :-1]
    c, d = xyz[1:, 1:], xyz[:-1, 1:]
    t1 = np.stack([a, b, d], 2).reshape(-1, 3, 3)
    t2 = np.stack([b, c, d], 2).reshape(-1, 3, 3)
    return np.concatenate([t1, t2]).reshape(-1, 3)


def soup_mesh(name: str, pos: np.ndarray, material: int = 0) -> Mesh:
    tri = pos.reshape(-1, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-30
    T = tri.shape[0]
    return Mesh(name, pos.astype(np.float32), np.repeat(n, 3, axis=0).astype(np.float32),
                np.zeros((3 * T, 2), np.float32), np.full(T, material, np.int32))


# ---------------------------------------------------------------- 1. BVH build
def bench_build(sizes) -> list[dict]:
    out = []
    for n in sizes:
        pos = displaced_sphere(n)
        t0 = time.perf_counter()
        b = B.build_blas(pos)
        dt = time.perf_counter() - t0
        tris = pos.shape[0] // 3
        out.append({"triangles": tris, "build_s": dt, "nodes": b.node_count,
                    "mtris_per_s": tris / dt / 1e6})
        print(f"  build {tris:>9,} triangles: {dt:7.2f} s ({tris / dt / 1e6:.2f} M tris/s), {b.node_count:,} nodes",
              flush=True)
        del b, pos
    return out


# ---------------------------------------------------------------- 2. rays/s
def bench_rays(ctx, programs, sd, label: str, size: int = 256, reps: int = 5) -> dict:
    t0 = time.perf_counter()
    sbvh = B.SceneBVH.from_scene(sd)
    build_s = time.perf_counter() - t0
    rt = RtBuffers(ctx, sbvh)
    prog = programs.compute("pt/raybench.comp", rt.defines)
    n = size * size
    hp = ctx.buffer(reserve=n * 16)
    hn = ctx.buffer(reserve=n * 16)
    cs = ctx.buffer(reserve=16)
    cam = sd.camera
    proj = np.asarray(cam.projection, np.float64).copy()
    lo, hi = sd.world_bounds()
    light = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - 0.05 * (hi[2] - lo[2])], np.float32)
    rt.bind()
    hp.bind_to_storage_buffer(0)
    hn.bind_to_storage_buffer(1)
    cs.bind_to_storage_buffer(2)
    set_uniform(prog, "u_cam_to_world", np.asarray(cam.matrix_world, np.float32))
    set_uniform(prog, "u_inv_proj", np.linalg.inv(proj).astype(np.float32))
    set_uniform(prog, "u_size", (size, size))
    set_uniform(prog, "u_light", tuple(float(x) for x in light))
    res = {"scene": label, "triangles": int(sbvh.triangle_count), "bvh_build_s": build_s, "rays_per_kind": n}
    groups = ((size + 7) // 8, (size + 7) // 8)
    for mode, kind in ((0, "primary"), (1, "shadow"), (2, "diffuse")):
        set_uniform(prog, "u_mode", mode)
        times = []
        for r in range(reps + 1):
            set_uniform(prog, "u_seed", r)
            cs.write(np.zeros(4, np.uint32).tobytes())
            ctx.finish()
            t = time.perf_counter()
            prog.run(*groups, 1)
            ctx.finish()
            if r > 0:  # the first is a warm-up
                times.append(time.perf_counter() - t)
            if mode == 0:
                hits = np.frombuffer(hp.read(), np.float32).reshape(-1, 4)[:, 3]
                active = int((hits > 0.5).sum())
        rays = n if mode == 0 else active
        med = statistics.median(times)
        res[kind] = {"rays": rays, "median_ms": med * 1e3, "mrays_per_s": rays / med / 1e6}
        print(f"  {label:<28} {kind:<8} {rays:>7,} rays {med * 1e3:8.1f} ms  {rays / med / 1e6:6.2f} Mrays/s",
              flush=True)
    for b in (hp, hn, cs):
        b.release()
    rt.release()
    return res


def cornell_with_sphere(sd, n_tris: int):
    """The exported Cornell box plus a displaced sphere of n_tris triangles (bpy-free)."""
    pos = displaced_sphere(n_tris, radius=0.45)
    mat = 0 if sd.materials else -1
    sd.meshes.append(soup_mesh("dense_sphere", pos, mat))
    m = np.eye(4, dtype=np.float32)
    lo, hi = sd.world_bounds()
    m[:3, 3] = [(lo[0] + hi[0]) / 2 - 0.3, (lo[1] + hi[1]) / 2 - 0.2, lo[2] + 0.5]
    sd.instances.append(Instance(len(sd.meshes) - 1, m, "dense_sphere"))
    return sd


# ---------------------------------------------------------------- 3. PT vs Cycles
def interp_time(curve: list[dict], target: float) -> float | None:
    """Time (ms) to reach relMSE <= target, log-log interpolation between measured points."""
    pts = sorted(curve, key=lambda c: c["time_ms"])
    for a, b in zip(pts, pts[1:]):
        if a["relmse"] <= target:
            return a["time_ms"]
        if b["relmse"] <= target < a["relmse"]:
            la, lb = np.log(a["relmse"]), np.log(b["relmse"])
            f = (np.log(target) - la) / (lb - la)
            return float(np.exp(np.log(a["time_ms"]) + f * (np.log(b["time_ms"]) - np.log(a["time_ms"]))))
    if pts and pts[-1]["relmse"] <= target:
        return pts[-1]["time_ms"]
    return None


def bench_pt_vs_cycles(ctx, res: int, ref_spp: int, max_spp: int) -> dict:
    scene = D.build_demo("cornell", resolution=res)
    dg = evaluated_depsgraph(scene)
    sd = export_scene(dg)
    ref = get_reference(scene, "full", ref_spp, depsgraph=dg)
    print(f"  Cycles reference {ref_spp} spp: {ref.time_ms / 1e3:.1f} s{' (cached)' if ref.cached else ''}", flush=True)
    spps = [2 ** k for k in range(int(np.log2(max_spp)) + 1)]
    pt_curve, cy_curve = [], []
    programs = ProgramCache(ctx)
    for spp in spps:
        per = min(spp, 16)
        r = render_offline(ctx, sd, spp // per, spp_per_frame=per, seed=7, programs=programs)
        img = r["frames"].mean(axis=0)
        m = M.compare(img, ref.image[..., :3], with_flip=False)
        t = r["time_ms"] + r["bvh_ms"]
        pt_curve.append({"spp": spp, "time_ms": t, "trace_ms": r["time_ms"], "bvh_ms": r["bvh_ms"],
                         "relmse": float(m["relmse"])})
        print(f"  PT     {spp:>5} spp {t:9.1f} ms  relMSE {m['relmse']:.4g}", flush=True)
    for spp in spps:
        img, ms = render_cycles(scene, spp, "full", seed=11)
        m = M.compare(img[..., :3], ref.image[..., :3], with_flip=False)
        cy_curve.append({"spp": spp, "time_ms": ms, "relmse": float(m["relmse"])})
        print(f"  Cycles {spp:>5} spp {ms:9.1f} ms  relMSE {m['relmse']:.4g}", flush=True)
    bpy.data.scenes.remove(scene)
    lo = max(min(c["relmse"] for c in pt_curve), min(c["relmse"] for c in cy_curve))
    hi = min(pt_curve[0]["relmse"], cy_curve[0]["relmse"])
    targets = [float(x) for x in np.geomspace(hi, lo * 1.05, 5)] if hi > lo else []
    rows = []
    for tgt in targets:
        tp, tc = interp_time(pt_curve, tgt), interp_time(cy_curve, tgt)
        rows.append({"relmse": tgt, "pt_ms": tp, "cycles_ms": tc,
                     "ratio_pt_over_cycles": (tp / tc) if tp and tc else None})
    return {"resolution": res, "reference_spp": ref_spp, "reference_ms": ref.time_ms, "pt": pt_curve,
            "cycles": cy_curve, "equal_error": rows}


# ---------------------------------------------------------------- report
def write_report(out_dir: Path, data: dict):
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "rt_benchmark.json").write_text(json.dumps(data, indent=2))
    L = ["# Ray-tracing benchmark (PT)", "",
         f"Machine: {data['machine']['cpu']} ({data['machine']['cores']} cores), GL renderer "
         f"`{data['machine']['gl_renderer']}`, Blender {data['machine']['blender']}. "
         f"Generated by `scripts/bench_rt.py` on {data['date']}. Shared machine: expect +-20 % between runs.", "",
         "## BVH build (CPU, numpy binned SAH, one BLAS)", "",
         "| triangles | build (s) | M triangles/s | nodes |", "|---:|---:|---:|---:|"]
    for b in data["build"]:
        L.append(f"| {b['triangles']:,} | {b['build_s']:.2f} | {b['mtris_per_s']:.2f} | {b['nodes']:,} |")
    L += ["", "## Ray throughput (lib/bvh.glsl on the GL device; 256 x 256 camera)", "",
          "| scene | triangles | BVH build (s) | primary Mrays/s | shadow Mrays/s | diffuse Mrays/s |",
          "|---|---:|---:|---:|---:|---:|"]
    for r in data["rays"]:
        L.append(f"| {r['scene']} | {r['triangles']:,} | {r['bvh_build_s']:.2f} | {r['primary']['mrays_per_s']:.2f} | "
                 f"{r['shadow']['mrays_per_s']:.2f} | {r['diffuse']['mrays_per_s']:.2f} |")
    pc = data["pt_vs_cycles"]
    L += ["", f"## PT vs Cycles: time to equal relMSE (Cornell demo, {pc['resolution']}^2, full GI, 12 bounces)", "",
          f"Reference: Cycles {pc['reference_spp']} spp (fair settings). PT time = tracing + BVH build; "
          "Cycles time = its render call (sync + BVH + tracing). Both on this machine in the same run.", "",
          "| spp | PT ms | PT relMSE | Cycles ms | Cycles relMSE |", "|---:|---:|---:|---:|---:|"]
    for p, c in zip(pc["pt"], pc["cycles"]):
        L.append(f"| {p['spp']} | {p['time_ms']:.0f} | {p['relmse']:.4g} | {c['time_ms']:.0f} | {c['relmse']:.4g} |")
    L += ["", "| target relMSE | PT ms | Cycles ms | PT / Cycles |", "|---:|---:|---:|---:|"]
    for r in pc["equal_error"]:
        f = (lambda v: f"{v:.0f}" if v else "n/a")
        ratio = f"{r['ratio_pt_over_cycles']:.1f}x" if r["ratio_pt_over_cycles"] else "n/a"
        L.append(f"| {r['relmse']:.4g} | {f(r['pt_ms'])} | {f(r['cycles_ms'])} | {ratio} |")
    L += ["", "Notes: the GL device here is Mesa llvmpipe (software rasteriser, compute shaders on the "
          "CPU, shared with Cycles' CPU threads' machine), so PT's rays/s measure the BVH code on a "
          "CPU through LLVM, not a GPU. Cycles uses Embree and hand-vectorised kernels on the same cores.", ""]
    (out_dir / "rt_benchmark.md").write_text("\n".join(L))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--out", default=str(REPO / "out" / "bench" / "rt"),
                    help="output folder (default: out/bench/rt; the docs page: docs/results)")
    a = ap.parse_args()
    ctx = moderngl.create_standalone_context(backend="egl", require=430)
    programs = ProgramCache(ctx)
    data = {"date": time.strftime("%Y-%m-%d %H:%M"),
            "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                        "gl_renderer": ctx.info.get("GL_RENDERER"), "blender": bpy.app.version_string,
                        "python": platform.python_version()}}
    print("BVH build:", flush=True)
    data["build"] = bench_build([10_000, 100_000] if a.quick else [100_000, 1_000_000, 4_000_000])
    print("Rays:", flush=True)
    scene = D.build_demo("cornell", resolution=64)
    sd = export_scene(evaluated_depsgraph(scene))
    bpy.data.scenes.remove(scene)
    data["rays"] = [bench_rays(ctx, programs, sd, "Cornell demo")]
    big = cornell_with_sphere(sd, 20_000 if a.quick else 1_000_000)
    data["rays"].append(bench_rays(ctx, programs, big, f"Cornell + {big.meshes[-1].triangle_count / 1e6:.1f} M-tri sphere"))
    print("PT vs Cycles:", flush=True)
    data["pt_vs_cycles"] = bench_pt_vs_cycles(ctx, 64 if a.quick else 128, 256 if a.quick else 2048,
                                              16 if a.quick else 256)
    write_report(Path(a.out), data)
    print(f"wrote {a.out}/rt_benchmark.md and .json")


if __name__ == "__main__":
    main()
