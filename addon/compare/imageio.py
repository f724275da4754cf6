"""Small EXR/PNG I/O through OpenImageIO (bpy-free).

OpenImageIO ships with Blender. Inside Blender it is importable as is; with the PyPI ``bpy``
module it becomes importable only after ``bpy.utils.expose_bundled_modules()``. This module
never imports bpy: where a caller has loaded it already, :func:`oiio` exposes the bundled
modules itself; otherwise it raises a clear error.

Orientation: arrays follow Blender's convention, **row 0 = bottom row**. Image files store
the top row first, so every function here flips rows on write and on read
(``bottom_up=False`` turns that off).
"""
from __future__ import annotations

import os
import sys

import numpy as np

_OIIO = None


class ImageIOError(RuntimeError):
    pass


def oiio():
    """The OpenImageIO module, or a clear ImportError."""
    global _OIIO
    if _OIIO is None:
        try:
            import OpenImageIO  # noqa: N813
        except ImportError:
            OpenImageIO = _bundled_oiio()
        if OpenImageIO is None:
            raise ImportError(
                "OpenImageIO is not importable. It ships with Blender; with the PyPI bpy module "
                "call bpy.utils.expose_bundled_modules() before using gi_preview.compare.imageio."
            )
        _OIIO = OpenImageIO
    return _OIIO


def _bundled_oiio():
    """Blender's own OpenImageIO where bpy is loaded (the PyPI bpy module keeps it hidden
    until ``bpy.utils.expose_bundled_modules()``), else None."""
    bpy = sys.modules.get("bpy")
    expose = getattr(getattr(bpy, "utils", None), "expose_bundled_modules", None)
    if expose is None:
        return None
    expose()
    try:
        import OpenImageIO  # noqa: N813
    except ImportError:
        return None
    return OpenImageIO


def _write(path: str, arr: np.ndarray, fmt: str, attrs: dict):
    m = oiio()
    if arr.ndim == 2:
        arr = arr[:, :, None]
    h, w, c = arr.shape
    spec = m.ImageSpec(w, h, c, fmt)
    if c == 4:
        spec.channelnames = ("R", "G", "B", "A")
    elif c == 3:
        spec.channelnames = ("R", "G", "B")
    for k, v in attrs.items():
        spec.attribute(k, v)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    tmp = path + ".tmp" + os.path.splitext(path)[1]
    out = m.ImageOutput.create(tmp)
    if out is None:
        raise ImageIOError(f"cannot create an image writer for {path}: {m.geterror()}")
    try:
        if not out.open(tmp, spec):
            raise ImageIOError(f"cannot open {path} for writing: {out.geterror()}")
        if not out.write_image(np.ascontiguousarray(arr)):
            raise ImageIOError(f"cannot write {path}: {out.geterror()}")
    finally:
        out.close()
    os.replace(tmp, path)  # atomic: a reader never sees half a file


def write_exr(path: str, image: np.ndarray, *, bottom_up: bool = True, half: bool = False):
    """Write a float image (H, W, C) as an EXR (float32 unless ``half``), ZIP-compressed."""
    a = np.asarray(image, np.float32)
    if bottom_up:
        a = a[::-1]
    _write(path, a, "half" if half else "float", {"compression": "zip"})


def to_uint8(ldr: np.ndarray, *, bottom_up: bool = True) -> np.ndarray:
    """An LDR image with values in [0, 1] (already display encoded) as 8-bit, top row first;
    non-finite values become 0 (NaN, -Inf) or 255 (+Inf)."""
    a = np.asarray(ldr, np.float64)
    a = np.nan_to_num(a, nan=0.0, posinf=1.0, neginf=0.0)
    a = (np.clip(a, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return a[::-1] if bottom_up else a


def write_png(path: str, ldr: np.ndarray, *, bottom_up: bool = True):
    """Write an LDR image with values in [0, 1] (already display encoded) as 8-bit PNG."""
    _write(path, to_uint8(ldr, bottom_up=bottom_up), "uint8", {})


def png_bytes(ldr: np.ndarray, *, bottom_up: bool = True) -> bytes:
    """The 8-bit PNG encoding of an LDR image, as bytes (via a temporary file)."""
    import tempfile
    fd, p = tempfile.mkstemp(suffix=".png")
    os.close(fd)
    try:
        write_png(p, ldr, bottom_up=bottom_up)
        with open(p, "rb") as f:
            return f.read()
    finally:
        os.unlink(p)


def read_image(path: str, *, bottom_up: bool = True) -> tuple[np.ndarray, list[str]]:
    """Read all channels of an image as float32 (H, W, C); returns (array, channel names)."""
    m = oiio()
    inp = m.ImageInput.open(path)
    if inp is None:
        raise ImageIOError(f"cannot read {path}: {m.geterror()}")
    try:
        spec = inp.spec()
        names = list(spec.channelnames)
        a = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if a is None:
            raise ImageIOError(f"cannot read pixels of {path}: {inp.geterror()}")
    finally:
        inp.close()
    a = np.asarray(a, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if bottom_up:
        a = a[::-1]
    return np.ascontiguousarray(a), names


def read_exr(path: str, *, bottom_up: bool = True) -> np.ndarray:
    """Read an EXR as float32 (H, W, 4) RGBA (alpha = 1 when absent; a single channel is
    replicated to RGB). Multi-layer files: the first R/G/B/A group is returned."""
    a, names = read_image(path, bottom_up=bottom_up)
    h, w = a.shape[:2]
    idx = {}
    for i, n in enumerate(names):
        last = n.rsplit(".", 1)[-1].upper()
        if last in ("R", "G", "B", "A") and last not in idx:
            idx[last] = i
    out = np.ones((h, w, 4), np.float32)
    if all(k in idx for k in "RGB"):
        for j, k in enumerate("RGB"):
            out[:, :, j] = a[:, :, idx[k]]
    else:
        for j in range(3):
            out[:, :, j] = a[:, :, 0]
    if "A" in idx:
        out[:, :, 3] = a[:, :, idx["A"]]
    return out


def read_exr_layers(path: str, *, bottom_up: bool = True) -> dict[str, np.ndarray]:
    """Read a (multi-layer) EXR grouped by channel prefix: {"ViewLayer.AO": (H, W, C), ...}.

    A channel without a dot goes into the group "" (plain RGBA files)."""
    a, names = read_image(path, bottom_up=bottom_up)
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        prefix = n.rsplit(".", 1)[0] if "." in n else ""
        groups.setdefault(prefix, []).append(i)
    return {k: np.ascontiguousarray(a[:, :, v]) for k, v in groups.items()}
