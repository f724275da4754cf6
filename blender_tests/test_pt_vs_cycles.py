"""PT agrees with Cycles: a statistical per-pixel test on small images (Mitsuba-style).

For every scene: PT renders K independent batches (different seeds per sample); their
spread gives each pixel's standard error. The Cycles reference (4096 spp, fair settings:
box filter 1 px, no denoise, no clamps, blur_glossy 0, no adaptive sampling, fixed seed,
bounces as PT's: 12/12/12) is cached on disk by scene hash. Its own noise is estimated
from PT's per-sample variance scaled by the sample counts (the two estimators sample the
same integrand). Pass: (1) the fraction of pixels whose luminance fails a two-sided t-test
at alpha = 0.01 with Šidák correction over the image is <= 1 %, and (2) the mean relMSE
is below the pair's noise floor (the relMSE expected from the two images' variances alone,
times 1.5 for the uncertainty of a K-batch variance estimate). Images (PT, Cycles, error)
are written to blender_tests/_artifacts/pt_vs_cycles/ for a person to look at.

Also: a 256x256 Cornell box at 64 spp has no NaN/Inf and no pixel above 50x the median.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
moderngl = pytest.importorskip("moderngl")

from gi_preview.blender import demo_scenes as D  # noqa: E402
from gi_preview.blender.export import export_scene  # noqa: E402
from gi_preview.blender.reference import evaluated_depsgraph, get_reference  # noqa: E402
from gi_preview.render.techniques.pt import render_offline  # noqa: E402

RES = int(os.environ.get("GI_PT_TEST_RES", 48))
BATCHES = int(os.environ.get("GI_PT_TEST_BATCHES", 32))
SPP_PER_BATCH = int(os.environ.get("GI_PT_TEST_SPP", 8))
REF_SPP = int(os.environ.get("GI_PT_TEST_REF_SPP", 4096))
ALPHA = 0.01
MAX_FAIL_FRACTION = 0.01
NOISE_FLOOR_FACTOR = 1.5
ART = Path(__file__).resolve().parent / "_artifacts"
LUMA = np.array([0.2126, 0.7152, 0.0722])


# ---------------------------------------------------------------- statistics (numpy only)
def normal_quantile(p: float) -> float:
    """z with P(Z > z) = p, by bisection on erfc."""
    lo, hi = 0.0, 40.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 0.5 * math.erfc(mid / math.sqrt(2)) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def t_quantile(p: float, dof: int) -> float:
    """Student-t upper quantile (Cornish-Fisher expansion around the normal quantile)."""
    z = normal_quantile(p)
    v = float(dof)
    return (z + (z ** 3 + z) / (4 * v) + (5 * z ** 5 + 16 * z ** 3 + 3 * z) / (96 * v ** 2)
            + (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / (384 * v ** 3))


def compare(batches: np.ndarray, ref: np.ndarray, spp_per_batch: int, ref_spp: int) -> dict:
    """batches (K, H, W, 3) batch means, ref (H, W, 3)."""
    K = batches.shape[0]
    mean = batches.mean(axis=0)
    var_batch = batches.var(axis=0, ddof=1)  # variance of one batch mean
    se2_pt = var_batch / K
    se2_ref = var_batch * spp_per_batch / ref_spp  # per-sample variance / ref spp
    # luminance per pixel, t-test with Šidák correction over the pixels
    lb = batches @ LUMA
    lm = lb.mean(axis=0)
    lse2 = lb.var(axis=0, ddof=1) / K + lb.var(axis=0, ddof=1) * spp_per_batch / ref_spp
    lr = ref @ LUMA
    n = lm.size
    p_pixel = 1.0 - (1.0 - ALPHA) ** (1.0 / n)
    tcrit = t_quantile(p_pixel / 2.0, K - 1)
    diff = np.abs(lm - lr)
    se = np.sqrt(lse2)
    fail = np.where(se > 0, diff > tcrit * se, diff > 1e-5 * (1 + np.abs(lr)))
    relmse = float(np.mean((mean - ref) ** 2 / (ref ** 2 + 1e-2)))
    floor = float(np.mean((se2_pt + se2_ref) / (ref ** 2 + 1e-2)))
    return {"fail_fraction": float(fail.mean()), "fail_map": fail, "tcrit": tcrit, "relmse": relmse,
            "noise_floor": floor, "mean_pt": mean, "z": np.where(se > 0, (lm - lr) / np.maximum(se, 1e-30), 0.0),
            "mean_ratio": float((mean @ LUMA).mean() / max((ref @ LUMA).mean(), 1e-12))}


# ---------------------------------------------------------------- scenes
def _room(b, color=(0.7, 0.7, 0.7), rough=0.8, specular=0.5):
    white = D.make_principled(b.n("white"), color, rough, specular=specular)
    red = D.make_principled(b.n("red"), (0.6, 0.1, 0.08), 1.0, specular=0.0)
    b.room("room", (-1.5, -1.5, 0), (1.5, 1.5, 2.5), {"floor": white, "ceiling": white, "+y": white,
                                                        "-x": red, "+x": white}, skip=("-y",))
    b.box("cube", (0.6, 0.6, 0.6), white, location=(0.3, 0.2, 0.3), rotation=(0, 0, 0.4))
    b.camera((0, -4.2, 1.3), (0, 0, 1.0), lens=30)
    b.scene.world = D.make_world(b.n("black"), (0, 0, 0), 0.0)
    return white


def scene_cornell(b):
    D._cornell(b)


def scene_glossy_metal(b):
    floor = D.make_principled(b.n("floor"), (0.5, 0.5, 0.5), 0.6)
    glossy = D.make_principled(b.n("glossy"), (0.1, 0.3, 0.8), 0.25)
    metal = D.make_principled(b.n("metal"), (0.95, 0.7, 0.4), 0.3, metallic=1.0)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], floor)
    b.sphere("s_glossy", 0.5, glossy, location=(-0.6, 0, 0.5), segments=24, rings=12)
    b.sphere("s_metal", 0.5, metal, location=(0.6, 0, 0.5), segments=24, rings=12)
    b.light("key", "AREA", (0.5, -1.0, 2.5), rotation=(0.4, 0, 0.2), size=1.0, energy=150.0)
    b.camera((0, -3.2, 1.4), (0, 0, 0.45), lens=40)
    b.scene.world = D.make_world(b.n("sky"), (0.4, 0.5, 0.7), 0.3)


def scene_point(b):
    _room(b)
    b.light("point", "POINT", (-0.4, -0.3, 1.9), energy=60.0, shadow_soft_size=0.0)


def scene_sphere_light(b):
    _room(b)
    lt = b.light("sphere", "POINT", (-0.4, -0.3, 1.8), energy=60.0, shadow_soft_size=0.2)
    lt.data.use_soft_falloff = False


def scene_spot(b):
    _room(b)
    b.light("spot", "SPOT", (0.6, -0.8, 2.2), rotation=(0.5, 0.2, 0), energy=200.0, spot_size=0.9,
            spot_blend=0.3, shadow_soft_size=0.0)


def scene_sun(b):
    floor = D.make_principled(b.n("floor"), (0.6, 0.6, 0.6), 0.9)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], floor)
    b.box("cube", (0.8, 0.8, 0.8), floor, location=(0, 0.3, 0.4), rotation=(0, 0, 0.5))
    b.light("sun", "SUN", (0, 0, 5), rotation=(0.6, 0.3, 0.2), energy=3.0, angle=math.radians(10))
    b.camera((0, -3.5, 2.0), (0, 0, 0.3), lens=35)
    b.scene.world = D.make_world(b.n("black"), (0, 0, 0), 0.0)


def scene_area_disk(b):
    _room(b)
    b.light("disk", "AREA", (0, 0, 2.45), shape="ELLIPSE", size=0.8, size_y=0.4, energy=80.0)


def scene_emissive_panel(b):
    _room(b)
    em = D.make_emission(b.n("panel"), (1.0, 0.85, 0.6), 6.0)
    b.quad("panel", [(-0.4, 1.45, 0.8), (0.4, 1.45, 0.8), (0.4, 1.45, 1.6), (-0.4, 1.45, 1.6)], em)


def scene_world(b):
    floor = D.make_principled(b.n("floor"), (0.6, 0.6, 0.6), 0.7)
    b.quad("floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], floor)
    b.box("cube", (0.8, 0.8, 0.8), floor, location=(0, 0.3, 0.4), rotation=(0, 0, 0.5))
    b.sphere("ball", 0.4, D.make_principled(b.n("ball"), (0.8, 0.3, 0.2), 0.4), location=(-0.9, -0.2, 0.4),
             segments=16, rings=8)
    b.camera((0, -3.5, 2.0), (0, 0, 0.3), lens=35)
    b.scene.world = D.make_world(b.n("sky"), (0.5, 0.6, 0.8), 1.0)


def scene_textured(b):
    img = bpy.data.images.new(b.n("checker"), 8, 8, alpha=True, float_buffer=True)
    px = np.zeros((8, 8, 4), np.float32)
    yy, xx = np.mgrid[0:8, 0:8]
    on = ((xx + yy) % 2 == 0)
    px[..., 0] = np.where(on, 0.8, 0.1)
    px[..., 1] = np.where(on, 0.7, 0.2)
    px[..., 2] = np.where(on, 0.2, 0.6)
    px[..., 3] = 1
    img.pixels.foreach_set(px.ravel())
    mat = D.make_principled(b.n("tex"), (0.8, 0.8, 0.8), 0.8)
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tn = nt.nodes.new("ShaderNodeTexImage")
    tn.image = img
    tn.interpolation = "Linear"  # what GL samples (the exporter does not carry Closest)
    nt.links.new(tn.outputs["Color"], bsdf.inputs["Base Color"])
    b.mesh("floor", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2, 3)], mat)
    me = bpy.data.objects[b.n("floor")].data
    uv = me.uv_layers.active or me.uv_layers.new(name="UVMap")
    for loop, co in zip(uv.data, [(0, 0), (1, 0), (1, 1), (0, 1)]):
        loop.uv = co
    b.light("key", "AREA", (0, 0, 2.0), size=1.5, energy=120.0)
    b.camera((0, -3.0, 2.5), (0, 0, 0), lens=35)
    b.scene.world = D.make_world(b.n("black"), (0, 0, 0), 0.0)


SCENES = {
    "cornell": scene_cornell,
    "glossy_metal": scene_glossy_metal,
    "point": scene_point,
    "sphere_light": scene_sphere_light,
    "spot": scene_spot,
    "sun": scene_sun,
    "area_ellipse": scene_area_disk,
    "emissive_panel": scene_emissive_panel,
    "world": scene_world,
    "textured": scene_textured,
}


def build(name: str, res: int):
    scene = bpy.data.scenes.new(f"pt_test_{name}_{res}")
    r = scene.render
    r.resolution_x = r.resolution_y = res
    r.resolution_percentage = 100
    SCENES[name](D._Builder(scene, f"pt_{name}"))
    return scene


@pytest.fixture(scope="module")
def gl():
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as exc:  # pragma: no cover
        pytest.skip(f"no OpenGL 4.3: {exc}")
    yield ctx
    ctx.release()


def save_png(path: Path, img: np.ndarray):
    from gi_preview.compare import metrics
    ldr = metrics.view_standard(img)
    from gi_preview.blender.reference import ensure_oiio
    ensure_oiio()
    import OpenImageIO as oiio
    path.parent.mkdir(parents=True, exist_ok=True)
    out = (np.clip(ldr[::-1, :, :3], 0, 1) * 255 + 0.5).astype(np.uint8)
    o = oiio.ImageOutput.create(str(path))
    o.open(str(path), oiio.ImageSpec(out.shape[1], out.shape[0], 3, "uint8"))
    o.write_image(out)
    o.close()


def run_scene(ctx, name: str, res: int, batches: int, spp: int, ref_spp: int, out_dir: Path | None = None):
    scene = build(name, res)
    dg = evaluated_depsgraph(scene)
    sd = export_scene(dg)
    ref = get_reference(scene, "full", ref_spp, depsgraph=dg, cache_dir=str(ART / "ref_cache"))
    r = render_offline(ctx, sd, batches, spp_per_frame=spp, seed=1)
    res_ = compare(r["frames"], ref.image[..., :3].astype(np.float64), spp, ref_spp)
    res_["pt_ms"] = r["time_ms"]
    res_["ref_ms"] = ref.time_ms
    if out_dir is not None:
        save_png(out_dir / f"{name}_pt.png", res_["mean_pt"])
        save_png(out_dir / f"{name}_cycles.png", ref.image[..., :3])
        err = np.repeat(np.clip(np.abs(res_["z"]) / res_["tcrit"], 0, 1)[..., None], 3, axis=2)
        save_png(out_dir / f"{name}_z.png", err)
    bpy.data.scenes.remove(scene)
    return res_


@pytest.mark.parametrize("name", list(SCENES))
def test_pt_matches_cycles(gl, name):
    r = run_scene(gl, name, RES, BATCHES, SPP_PER_BATCH, REF_SPP, ART / "pt_vs_cycles")
    msg = (f"{name}: {100 * r['fail_fraction']:.2f}% pixels fail (t > {r['tcrit']:.2f}), relMSE "
           f"{r['relmse']:.3g} vs noise floor {r['noise_floor']:.3g}, mean PT/Cycles {r['mean_ratio']:.4f}")
    print(msg)
    assert r["fail_fraction"] <= MAX_FAIL_FRACTION, msg
    assert r["relmse"] <= NOISE_FLOOR_FACTOR * r["noise_floor"], msg


def test_cornell_256_no_fireflies(gl):
    scene = build("cornell", 256)
    sd = export_scene(evaluated_depsgraph(scene))
    r = render_offline(gl, sd, 8, spp_per_frame=8, seed=3)
    img = r["frames"].mean(axis=0)
    bpy.data.scenes.remove(scene)
    assert np.isfinite(img).all()
    lum = img @ LUMA
    med = float(np.median(lum))
    assert med > 0
    assert lum.max() <= 50 * med, f"max {lum.max()} > 50 x median {med}"
    save_png(ART / "pt_vs_cycles" / "cornell_256_64spp.png", img)
