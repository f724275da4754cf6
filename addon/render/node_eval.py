"""A numpy evaluator of shader-node expressions over the UV domain (bpy-free).

``addon/blender/material_nodes.py`` turns the nodes upstream of a Principled BSDF input
into an expression tree of the classes below; this module evaluates such a tree at any set
of UV points, the way Cycles' SVM evaluates the same nodes per shading point:

* :class:`Const` (RGB, Value, unlinked sockets), :class:`UV` (the mesh's UV map),
  :class:`Image` (an Image Texture: Cycles' Linear / Closest interpolation with the texel
  centres at ``(i + 0.5) / size``, Repeat / Extend / Clip / Mirror extension; Color or Alpha
  output), :class:`Op` (Math, Mix, Invert, Color Ramp, Separate / Combine Color, Mapping,
  Vector Math, implicit socket conversions).
* :func:`evaluate(expr, uv)` -> ``(N, C)`` float32 for ``uv`` of shape ``(N, 2)``.
* :func:`bake(expr, width, height)` -> ``(H, W, C)``: the expression at the texel centres of
  a grid over ``[0, 1]^2`` (row 0 = v near 0, Blender's image order). Sampled bilinearly
  with Repeat, a bake reproduces the expression exactly where it is linear in the images
  (an image passed through Separate Color, Multiply, Mix, Invert, ...), and to within a
  texel where it is not (thresholds, Color Ramp steps). :func:`periodic` says whether the
  expression repeats with period 1 in UV (every image Repeat, Mapping by translations and
  integer scales only), i.e. whether the bake is exact for UVs outside ``[0, 1]`` too.

Expressions are frozen dataclasses: ``repr`` is a stable key for bake caches (images are
keyed by their texture index and a content hash given by the producer).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)  # Blender's colour -> float conversion


class Unsupported(Exception):
    """A node the evaluator cannot express (procedural textures, position-dependent inputs)."""


@dataclass(frozen=True)
class Const:
    value: tuple  # 1 (float) or 3 (colour / vector) components


@dataclass(frozen=True)
class UV:
    name: str = ""  # "" = the mesh's active render UV map


@dataclass(frozen=True)
class Image:
    texture: int  # index into SceneData.textures
    key: str  # content key of the pixels (cache key)
    interpolation: str = "Linear"  # Linear | Closest | Cubic | Smart
    extension: str = "REPEAT"  # REPEAT | EXTEND | CLIP | MIRROR
    vector: object = field(default_factory=UV)
    output: str = "Color"  # Color (rgb) | Alpha
    pixels: np.ndarray = field(default=None, repr=False, compare=False, hash=False)


@dataclass(frozen=True)
class Op:
    kind: str  # math | mix | invert | ramp | separate | combine | mapping | vmath | to_float | to_color
    params: tuple = ()
    args: tuple = ()


def channels(e) -> int:
    if isinstance(e, Const):
        return len(e.value)
    if isinstance(e, UV):
        return 3
    if isinstance(e, Image):
        return 1 if e.output == "Alpha" else 3
    k = e.kind
    if k in ("math", "separate", "to_float"):
        return 1
    if k == "ramp":
        return 1 if e.params[0] == "Alpha" else 3
    if k == "mix":
        return 1 if e.params[0] == "FLOAT" else 3
    if k == "vmath":
        return 1 if e.params[0] in _VMATH_SCALAR else 3
    return 3


def images(e) -> list:
    """Every Image node of the expression."""
    if isinstance(e, Image):
        return [e] + images(e.vector)
    if isinstance(e, Op):
        return [i for a in e.args for i in images(a)]
    return []


def uv_maps(e) -> set:
    if isinstance(e, UV):
        return {e.name}
    if isinstance(e, Image):
        return uv_maps(e.vector)
    if isinstance(e, Op):
        return set().union(*(uv_maps(a) for a in e.args)) if e.args else set()
    return set()


def is_const(e) -> bool:
    if isinstance(e, Const):
        return True
    if isinstance(e, (UV, Image)):
        return False
    return all(is_const(a) for a in e.args)


def periodic(e) -> bool:
    """Does the expression repeat with period 1 in u and v?"""
    if isinstance(e, (Const, UV)):
        return True
    if isinstance(e, Image):
        return e.extension == "REPEAT" and _periodic_vector(e.vector)
    return all(periodic(a) for a in e.args)


def _periodic_vector(v) -> bool:
    if isinstance(v, UV):
        return True
    if isinstance(v, Op) and v.kind == "mapping":
        vtype, rot, scale = v.params[0], v.params[2], v.params[3]
        if vtype not in ("POINT", "TEXTURE") or any(abs(r) > 1e-9 for r in rot):
            return False
        s = scale if vtype == "POINT" else tuple(1.0 / x if x else 0.0 for x in scale)
        return all(abs(x - round(x)) < 1e-6 and round(x) != 0 for x in s[:2]) and _periodic_vector(v.args[0])
    return False


# ------------------------------------------------------------------------------ sampling
def _wrap(i: np.ndarray, n: int, ext: str) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices and a validity mask (Clip) under an extension mode."""
    if ext == "REPEAT":
        return np.mod(i, n), np.ones(i.shape, bool)
    if ext == "MIRROR":
        p = np.mod(i, 2 * n)
        return np.where(p < n, p, 2 * n - 1 - p), np.ones(i.shape, bool)
    valid = (i >= 0) & (i < n)
    return np.clip(i, 0, n - 1), (valid if ext == "CLIP" else np.ones(i.shape, bool))


def sample_image(pixels: np.ndarray, uv: np.ndarray, interpolation: str = "Linear",
                 extension: str = "REPEAT") -> np.ndarray:
    """RGBA of an (H, W, 4) image (row 0 = v near 0) at ``uv`` (N, 2), as Cycles samples it."""
    H, W = pixels.shape[:2]
    u = uv[:, 0].astype(np.float64)
    v = uv[:, 1].astype(np.float64)
    if extension == "CLIP":
        outside = (u < 0) | (u > 1) | (v < 0) | (v > 1)
    else:
        outside = None
    if interpolation == "Closest":
        ix, mx = _wrap(np.floor(u * W).astype(np.int64), W, extension)
        iy, my = _wrap(np.floor(v * H).astype(np.int64), H, extension)
        out = pixels[iy, ix].astype(np.float32) * (mx & my)[:, None]
    else:  # Linear (Cubic/Smart are approximated by Linear; the exporter says so)
        x = u * W - 0.5
        y = v * H - 0.5
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = (x - x0)[:, None]
        fy = (y - y0)[:, None]
        x0 = x0.astype(np.int64)
        y0 = y0.astype(np.int64)
        xa, ma = _wrap(x0, W, extension)
        xb, mb = _wrap(x0 + 1, W, extension)
        ya, na = _wrap(y0, H, extension)
        yb, nb = _wrap(y0 + 1, H, extension)
        p = pixels.astype(np.float64)
        c00 = p[ya, xa] * (ma & na)[:, None]
        c10 = p[ya, xb] * (mb & na)[:, None]
        c01 = p[yb, xa] * (ma & nb)[:, None]
        c11 = p[yb, xb] * (mb & nb)[:, None]
        out = ((c00 * (1 - fx) + c10 * fx) * (1 - fy) + (c01 * (1 - fx) + c11 * fx) * fy).astype(np.float32)
    if outside is not None:
        out[outside] = 0.0
    return out


# ------------------------------------------------------------------------------ operations
def _safe_div(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0, a / np.where(b != 0, b, 1), 0.0)


def _math(op, a, b, c):
    """Blender's Math node (Cycles svm_math), float arrays."""
    with np.errstate(all="ignore"):
        if op == "ADD":
            return a + b
        if op == "SUBTRACT":
            return a - b
        if op == "MULTIPLY":
            return a * b
        if op == "DIVIDE":
            return _safe_div(a, b)
        if op == "MULTIPLY_ADD":
            return a * b + c
        if op == "POWER":
            ok = (a >= 0) | (np.floor(b) == b)
            return np.where(ok, np.power(np.where(ok, a, 0), b), 0.0)
        if op == "LOGARITHM":
            return np.where((a > 0) & (b > 0), np.log(np.maximum(a, 1e-30)) / np.log(np.maximum(b, 1e-30)), 0.0)
        if op == "SQRT":
            return np.where(a > 0, np.sqrt(np.maximum(a, 0)), 0.0)
        if op == "INVERSE_SQRT":
            return np.where(a > 0, 1.0 / np.sqrt(np.maximum(a, 1e-30)), 0.0)
        if op == "ABSOLUTE":
            return np.abs(a)
        if op == "EXPONENT":
            return np.exp(a)
        if op == "MINIMUM":
            return np.minimum(a, b)
        if op == "MAXIMUM":
            return np.maximum(a, b)
        if op == "LESS_THAN":
            return (a < b).astype(np.float64)
        if op == "GREATER_THAN":
            return (a > b).astype(np.float64)
        if op == "SIGN":
            return np.sign(a)
        if op == "COMPARE":
            return (np.abs(a - b) <= np.maximum(c, 1e-5)).astype(np.float64)
        if op == "SMOOTH_MIN" or op == "SMOOTH_MAX":
            s = -1.0 if op == "SMOOTH_MAX" else 1.0
            a2, b2 = s * a, s * b
            h = np.where(c != 0, np.maximum(c - np.abs(a2 - b2), 0.0) / np.where(c != 0, c, 1), 0.0)
            return s * (np.minimum(a2, b2) - h * h * h * c * (1.0 / 6.0))
        if op == "ROUND":
            return np.floor(a + 0.5)
        if op == "FLOOR":
            return np.floor(a)
        if op == "CEIL":
            return np.ceil(a)
        if op == "TRUNC":
            return np.trunc(a)
        if op == "FRACT":
            return a - np.floor(a)
        if op == "MODULO":
            return np.where(b != 0, np.fmod(a, np.where(b != 0, b, 1)), 0.0)
        if op == "FLOORED_MODULO":
            return np.where(b != 0, a - np.floor(_safe_div(a, b)) * b, 0.0)
        if op == "WRAP":
            rng = b - c
            return np.where(rng != 0, a - rng * np.floor(_safe_div(a - c, rng)), c)
        if op == "SNAP":
            return np.floor(_safe_div(a, b)) * b
        if op == "PINGPONG":
            return np.where(b != 0, np.abs(np.mod(a - b, 2 * np.where(b != 0, b, 1)) - b), 0.0)
        if op == "SINE":
            return np.sin(a)
        if op == "COSINE":
            return np.cos(a)
        if op == "TANGENT":
            return np.tan(a)
        if op == "ARCSINE":
            return np.where(np.abs(a) <= 1, np.arcsin(np.clip(a, -1, 1)), 0.0)
        if op == "ARCCOSINE":
            return np.where(np.abs(a) <= 1, np.arccos(np.clip(a, -1, 1)), 0.0)
        if op == "ARCTANGENT":
            return np.arctan(a)
        if op == "ARCTAN2":
            return np.arctan2(a, b)
        if op == "SINH":
            return np.sinh(a)
        if op == "COSH":
            return np.cosh(a)
        if op == "TANH":
            return np.tanh(a)
        if op == "RADIANS":
            return a * (math.pi / 180.0)
        if op == "DEGREES":
            return a * (180.0 / math.pi)
    raise Unsupported(f"Math operation {op}")


MATH_OPS = ("ADD SUBTRACT MULTIPLY DIVIDE MULTIPLY_ADD POWER LOGARITHM SQRT INVERSE_SQRT ABSOLUTE EXPONENT "
            "MINIMUM MAXIMUM LESS_THAN GREATER_THAN SIGN COMPARE SMOOTH_MIN SMOOTH_MAX ROUND FLOOR CEIL TRUNC "
            "FRACT MODULO FLOORED_MODULO WRAP SNAP PINGPONG SINE COSINE TANGENT ARCSINE ARCCOSINE ARCTANGENT "
            "ARCTAN2 SINH COSH TANH RADIANS DEGREES").split()


def _rgb_to_hsv(c):
    r, g, b = c[:, 0], c[:, 1], c[:, 2]
    mx = np.maximum(np.maximum(r, g), b)
    mn = np.minimum(np.minimum(r, g), b)
    d = mx - mn
    s = np.where(mx != 0, d / np.where(mx != 0, mx, 1), 0.0)
    dd = np.where(d != 0, d, 1)
    cr, cg, cb = (mx - r) / dd, (mx - g) / dd, (mx - b) / dd
    h = np.where(r == mx, cb - cg, np.where(g == mx, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(h < 0, h + 1.0, h)
    h = np.where(s != 0, h, 0.0)
    return np.stack([h, s, mx], 1)


def _hsv_to_rgb(c):
    h, s, v = c[:, 0], c[:, 1], c[:, 2]
    h6 = np.where(h == 1.0, 0.0, h) * 6.0
    i = np.floor(h6)
    f = h6 - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    i = i.astype(int) % 6
    r = np.choose(i, [v, q, p, p, t, v])
    g = np.choose(i, [t, v, v, q, p, p])
    b = np.choose(i, [p, p, t, v, v, q])
    rgb = np.stack([r, g, b], 1)
    return np.where((s != 0)[:, None], rgb, v[:, None].repeat(3, 1))


def _mix_blend(blend, t, a, b):
    """Blender's Mix Color blend modes (Cycles svm_mix), t (N,1), a/b (N,3)."""
    with np.errstate(all="ignore"):
        if blend == "MIX":
            return a + t * (b - a)
        if blend == "ADD":
            return a + t * b
        if blend == "MULTIPLY":
            return a * (1 - t + t * b)
        if blend == "SUBTRACT":
            return a - t * b
        if blend == "SCREEN":
            return 1 - (1 - t + t * (1 - b)) * (1 - a)
        if blend == "DIVIDE":
            return np.where(b != 0, (1 - t) * a + t * a / np.where(b != 0, b, 1), a)
        if blend == "DIFFERENCE":
            return a + t * (np.abs(a - b) - a)
        if blend == "EXCLUSION":
            return np.maximum(a + t * (a + b - 2 * a * b - a), 0.0)
        if blend == "DARKEN":
            return a + t * (np.minimum(a, b) - a)
        if blend == "LIGHTEN":
            return a + t * (np.maximum(a, b) - a)
        if blend == "OVERLAY":
            return np.where(a < 0.5, a * (1 - t + 2 * t * b), 1 - (1 - t + 2 * t * (1 - b)) * (1 - a))
        if blend == "DODGE":
            tmp = 1 - t * b
            return np.where(a != 0, np.where(tmp <= 0, 1.0, np.minimum(a / np.where(tmp > 0, tmp, 1), 1.0)), a)
        if blend == "BURN":
            tmp = (1 - t) + t * b
            return np.where(tmp <= 0, 0.0, np.clip(1 - (1 - a) / np.where(tmp > 0, tmp, 1), 0, 1))
        if blend == "LINEAR_LIGHT":
            return a + t * (2 * b - 1)
        if blend == "SOFT_LIGHT":
            scr = 1 - (1 - b) * (1 - a)
            return (1 - t) * a + t * ((1 - a) * b * a + a * scr)
    raise Unsupported(f"Mix blend mode {blend}")


def _ramp(params, f):
    """Color Ramp (RGB colour mode): params = (output, interpolation, positions, colours)."""
    _out, interp, pos, cols = params
    pos = np.asarray(pos, np.float64)
    cols = np.asarray(cols, np.float64).reshape(-1, 4)
    f = f[:, 0]
    n = len(pos)
    if n == 1:
        return np.repeat(cols[:1], f.shape[0], 0)
    idx = np.searchsorted(pos, f, side="right")  # first element with pos > f
    if interp == "CONSTANT":
        k = np.clip(idx - 1, 0, n - 1)
        return cols[k]
    lo = np.clip(idx - 1, 0, n - 1)
    hi = np.clip(idx, 0, n - 1)
    d = pos[hi] - pos[lo]
    t = np.where(d > 0, (f - pos[lo]) / np.where(d > 0, d, 1), 0.0)
    t = np.clip(t, 0, 1)
    if interp == "EASE":
        t = t * t * (3 - 2 * t)
    elif interp != "LINEAR":
        raise Unsupported(f"Color Ramp interpolation {interp}")
    return cols[lo] * (1 - t[:, None]) + cols[hi] * t[:, None]


def _euler_matrix(rot):
    x, y, z = rot
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _mapping(params, v):
    vtype, loc, rot, scale = params
    R = _euler_matrix(rot)
    loc = np.asarray(loc, np.float64)
    scale = np.asarray(scale, np.float64)
    if vtype == "POINT":
        return (v * scale) @ R.T + loc
    if vtype == "TEXTURE":
        return _safe_div((v - loc) @ R, scale)
    if vtype == "VECTOR":
        return (v * scale) @ R.T
    if vtype == "NORMAL":
        n = _safe_div(v, scale) @ R.T
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        return _safe_div(n, ln)
    raise Unsupported(f"Mapping type {vtype}")


_VMATH_SCALAR = ("DOT_PRODUCT", "LENGTH", "DISTANCE")


def _vmath(op, a, b, c, s):
    with np.errstate(all="ignore"):
        if op == "ADD":
            return a + b
        if op == "SUBTRACT":
            return a - b
        if op == "MULTIPLY":
            return a * b
        if op == "DIVIDE":
            return _safe_div(a, b)
        if op == "MULTIPLY_ADD":
            return a * b + c
        if op == "SCALE":
            return a * s
        if op == "ABSOLUTE":
            return np.abs(a)
        if op == "MINIMUM":
            return np.minimum(a, b)
        if op == "MAXIMUM":
            return np.maximum(a, b)
        if op == "FLOOR":
            return np.floor(a)
        if op == "FRACTION":
            return a - np.floor(a)
        if op == "DOT_PRODUCT":
            return np.sum(a * b, 1, keepdims=True)
        if op == "LENGTH":
            return np.linalg.norm(a, axis=1, keepdims=True)
        if op == "DISTANCE":
            return np.linalg.norm(a - b, axis=1, keepdims=True)
        if op == "NORMALIZE":
            ln = np.linalg.norm(a, axis=1, keepdims=True)
            return _safe_div(a, ln)
    raise Unsupported(f"Vector Math operation {op}")


# ------------------------------------------------------------------------------ evaluation
def evaluate(e, uv: np.ndarray) -> np.ndarray:
    """Value of ``e`` at ``uv`` (N, 2): (N, channels(e)) float32."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    return _eval(e, uv, {}).astype(np.float32)


def _eval(e, uv, memo):
    key = id(e)
    hit = memo.get(key)
    if hit is not None:
        return hit
    out = _eval_node(e, uv, memo)
    memo[key] = out
    return out


def _as(x, c):
    """Implicit conversion to c channels: colour -> float by luminance, float -> colour by copy."""
    if x.shape[1] == c:
        return x
    if c == 1:
        return x[:, :3] @ LUMA.astype(np.float64)[:, None]
    return np.repeat(x[:, :1], c, 1)


def _eval_node(e, uv, memo):
    N = uv.shape[0]
    if isinstance(e, Const):
        return np.broadcast_to(np.asarray(e.value, np.float64), (N, len(e.value))).copy()
    if isinstance(e, UV):
        return np.concatenate([uv, np.zeros((N, 1))], 1)
    if isinstance(e, Image):
        vec = _as(_eval(e.vector, uv, memo), 3)[:, :2]
        if e.pixels is None:
            raise Unsupported(f"image {e.texture} has no pixels")
        rgba = sample_image(e.pixels, vec, e.interpolation, e.extension).astype(np.float64)
        return rgba[:, 3:4] if e.output == "Alpha" else rgba[:, :3]
    args = [_eval(a, uv, memo) for a in e.args]
    k = e.kind
    if k == "to_float":
        return _as(args[0], 1)
    if k == "to_color":
        return _as(args[0], 3)
    if k == "math":
        op, clamp = e.params
        a, b, c = (_as(x, 1) for x in args)
        r = _math(op, a, b, c)
        return np.clip(r, 0, 1) if clamp else r
    if k == "mix":
        dtype, blend, clamp_fac, clamp_res = e.params
        t = _as(args[0], 1)
        if clamp_fac:
            t = np.clip(t, 0, 1)
        if dtype == "FLOAT":
            a, b = _as(args[1], 1), _as(args[2], 1)
            return a + t * (b - a)
        a, b = _as(args[1], 3), _as(args[2], 3)
        if dtype == "VECTOR":
            return a + t * (b - a)
        r = _mix_blend(blend, t, a, b)
        return np.clip(r, 0, 1) if clamp_res else r
    if k == "invert":
        t, c = _as(args[0], 1), _as(args[1], 3)
        return c + t * ((1 - c) - c)
    if k == "ramp":
        rgba = _ramp(e.params, _as(args[0], 1))
        return rgba[:, 3:4] if e.params[0] == "Alpha" else rgba[:, :3]
    if k == "separate":
        mode, ch = e.params
        c = _as(args[0], 3)
        if mode == "HSV":
            c = _rgb_to_hsv(c)
        elif mode != "RGB":
            raise Unsupported(f"Separate Color mode {mode}")
        return c[:, ch:ch + 1]
    if k == "combine":
        (mode,) = e.params
        c = np.concatenate([_as(a, 1) for a in args], 1)
        if mode == "HSV":
            return _hsv_to_rgb(c)
        if mode != "RGB":
            raise Unsupported(f"Combine Color mode {mode}")
        return c
    if k == "mapping":
        return _mapping(e.params, _as(args[0], 3))
    if k == "vmath":
        op = e.params[0]
        a, b, c = (_as(x, 3) for x in args[:3])
        s = _as(args[3], 1) if len(args) > 3 else np.ones((N, 1))
        return _vmath(op, a, b, c, s)
    if k == "gamma":
        c, g = _as(args[0], 3), _as(args[1], 1)
        return np.where(c > 0, np.power(np.maximum(c, 0), g), c)
    if k == "bright_contrast":
        c, br, co = _as(args[0], 3), _as(args[1], 1), _as(args[2], 1)
        a = 1 + co
        b = br - co * 0.5
        return np.maximum(a * c + b, 0.0)
    if k == "hsv":
        h, s, v, f, c = (_as(args[i], 1) for i in range(4)) + (_as(args[4], 3),)
        hsv = _rgb_to_hsv(c)
        hsv[:, 0:1] = np.mod(hsv[:, 0:1] + h + 0.5, 1.0)
        hsv[:, 1:2] = np.clip(hsv[:, 1:2] * s, 0, 1)
        hsv[:, 2:3] = hsv[:, 2:3] * v
        rgb = np.maximum(_hsv_to_rgb(hsv), 0.0)
        return c + f * (rgb - c)
    raise Unsupported(f"operation {k}")


def bake(e, width: int, height: int) -> np.ndarray:
    """``e`` at the texel centres of a width x height grid over [0, 1]^2: (H, W, C) float32."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    uu, vv = np.meshgrid(u, v)
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    return evaluate(e, uv).reshape(height, width, -1)


GRAPH_BAKE_SIZE = 256  # grid of a bake that reads no image (a value graph over UV)


def bake_size(e, cap: int = 2048) -> tuple[int, int]:
    """Grid size for a bake: the largest image involved; GRAPH_BAKE_SIZE when the expression
    reads the UV map but no image (a function of UV sampled finely enough for its gradient)."""
    w = h = 1
    for im in images(e):
        if im.pixels is not None:
            h = max(h, int(im.pixels.shape[0]))
            w = max(w, int(im.pixels.shape[1]))
    if uv_maps_other(e):
        w, h = max(w, GRAPH_BAKE_SIZE), max(h, GRAPH_BAKE_SIZE)
    return min(cap, w), min(cap, h)


def texel_linear(e) -> bool:
    """True when every operation between the images and the output is affine per texel
    (Separate/Combine Color, Mix with a constant factor, Invert, add/multiply by constants),
    so a bake sampled bilinearly equals the expression sampled bilinearly exactly."""
    if isinstance(e, (Const, UV)):
        return True
    if isinstance(e, Image):
        return isinstance(e.vector, UV)
    k = e.kind
    if k in ("separate",) and e.params[0] == "RGB":
        return texel_linear(e.args[0])
    if k == "combine" and e.params[0] == "RGB":
        return all(texel_linear(a) for a in e.args)
    if k in ("to_float", "to_color"):
        return texel_linear(e.args[0])
    if k == "math" and not e.params[1]:
        op = e.params[0]
        nconst = [a for a in e.args if not is_const(a)]
        if op in ("ADD", "SUBTRACT"):
            return all(texel_linear(a) for a in e.args)
        if op in ("MULTIPLY", "DIVIDE", "MULTIPLY_ADD") and len(nconst) <= 1:
            return all(texel_linear(a) for a in e.args) and (op != "DIVIDE" or is_const(e.args[1]))
        return False
    if k == "mix":
        if not is_const(e.args[0]):
            return False
        if e.params[0] == "RGBA":
            blend, clamp_res = e.params[1], e.params[3]
            varying = [a for a in e.args[1:] if not is_const(a)]
            affine_in_one = blend in ("MULTIPLY", "SCREEN", "LINEAR_LIGHT") or \
                (blend == "DIVIDE" and is_const(e.args[2]))
            if clamp_res or not (blend in ("MIX", "ADD", "SUBTRACT") or (affine_in_one and len(varying) <= 1)):
                return False
        return all(texel_linear(a) for a in e.args[1:])
    if k == "invert":
        return is_const(e.args[0]) and texel_linear(e.args[1])
    return False


def closest_grid(e) -> bool:
    """True when every image is sampled Closest on the default UV map and all have one size:
    the expression is then constant over each texel, and a bake at that size is exact."""
    ims = images(e)
    if not ims or any(i.interpolation != "Closest" or not isinstance(i.vector, UV) or i.vector.name
                      for i in ims):
        return False
    return len({i.pixels.shape[:2] for i in ims if i.pixels is not None}) == 1 and not uv_maps_other(e)


def uv_maps_other(e) -> bool:
    """Does anything but an image read the UV map (e.g. a UV output used as a value)?"""
    if isinstance(e, UV):
        return True
    if isinstance(e, Image):
        return False
    if isinstance(e, Op):
        return any(uv_maps_other(a) for a in e.args)
    return False
