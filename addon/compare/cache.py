"""On-disk cache of Cycles references (bpy-free).

One entry = ``<key>.exr`` (float32 RGBA, row 0 = bottom once read back) + ``<key>.json``
(sidecar: spp, time_ms, blender_version, bounces, kind, created, and whatever else the
caller put in ``meta``). The key is a sha256 of everything that changes the reference:
the exported scene's fingerprint (geometry, materials, lights, camera, world, resolution),
the reference kind, spp, the bounce limits, the resolution, the seed and the Blender
version (see :func:`reference_key`).

The directory comes from the caller: the Blender layer passes
``bpy.utils.extension_path_user(__package__, create=True)`` when the extension is installed
(entries go in its ``references/`` sub-folder); :func:`default_cache_dir` gives a user cache
folder otherwise. EXR I/O needs OpenImageIO (see :mod:`.imageio`).
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time

import numpy as np

from . import imageio

CACHE_VERSION = 1


def reference_key(fingerprint: str, kind: str, spp: int, bounces: dict, resolution, seed: int,
                  blender_version, **extra) -> str:
    """sha256 hex of the canonical JSON of all inputs (extra keyword values included)."""
    payload = {
        "v": CACHE_VERSION,
        "fingerprint": str(fingerprint),
        "kind": str(kind),
        "spp": int(spp),
        "bounces": {str(k): bounces[k] for k in sorted(bounces or {})},
        "resolution": [int(x) for x in resolution],
        "seed": int(seed),
        "blender_version": [int(x) for x in blender_version] if not isinstance(blender_version, str)
        else blender_version,
        "extra": {str(k): extra[k] for k in sorted(extra)},
    }
    s = json.dumps(payload, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(s.encode("utf-8")).hexdigest()


def default_cache_dir(extension_dir: str | None = None) -> str:
    """``<extension_dir>/references`` when given, else ``$XDG_CACHE_HOME`` (or ~/.cache)
    ``/gi_preview/references``, else a folder in the system temp dir."""
    if extension_dir:
        return os.path.join(extension_dir, "references")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    d = os.path.join(base, "gi_preview", "references")
    try:
        os.makedirs(d, exist_ok=True)
        if os.access(d, os.W_OK):
            return d
    except OSError:
        pass
    return os.path.join(tempfile.gettempdir(), "gi_preview_references")


class ReferenceCache:
    """``get(key) -> (image, meta) | None`` and ``put(key, image, meta)``."""

    def __init__(self, directory: str | None = None):
        self.directory = directory or default_cache_dir()
        os.makedirs(self.directory, exist_ok=True)

    def _paths(self, key: str) -> tuple[str, str]:
        if not key or any(c not in "0123456789abcdef" for c in key):
            raise ValueError(f"not a cache key: {key!r}")
        return os.path.join(self.directory, key + ".exr"), os.path.join(self.directory, key + ".json")

    def __contains__(self, key: str) -> bool:
        exr, js = self._paths(key)
        return os.path.exists(exr) and os.path.exists(js)

    def get(self, key: str):
        """(image float32 (H, W, 4) row 0 bottom, meta dict) or None when absent/unreadable."""
        exr, js = self._paths(key)
        if not (os.path.exists(exr) and os.path.exists(js)):
            return None
        try:
            with open(js, encoding="utf-8") as f:
                meta = json.load(f)
            image = imageio.read_exr(exr)
        except (OSError, ValueError, imageio.ImageIOError):
            return None  # a broken entry is a miss; put() overwrites it
        meta["cache_path"] = exr
        return image, meta

    def put(self, key: str, image: np.ndarray, meta: dict) -> str:
        """Store an entry; the sidecar gets ``created`` (ISO time) and ``key``. Returns the EXR path."""
        exr, js = self._paths(key)
        imageio.write_exr(exr, np.asarray(image, np.float32))
        m = dict(meta)
        m.setdefault("created", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        m["key"] = key
        m["shape"] = list(np.asarray(image).shape)
        tmp = js + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(m, f, indent=1, sort_keys=True, default=str)
        os.replace(tmp, js)
        return exr

    def remove(self, key: str):
        for p in self._paths(key):
            try:
                os.unlink(p)
            except FileNotFoundError:
                pass

    def keys(self) -> list[str]:
        return sorted(f[:-5] for f in os.listdir(self.directory) if f.endswith(".json"))
