"""Shader code that compiles on Mesa's llvmpipe but not on every GPU driver.

NVIDIA's GLSL compiler did not finish compiling direct.comp and pt.comp within 100 s on an
H200 (driver 580) while they held Cycles' GGX tables as constant arrays (5,152 floats):
large tables belong in textures or buffers (lib/brdf_tables.glsl reads them from a texture).
This scans every shader for constant arrays above a small size, and checks that the texture
holds exactly the tables the generator writes."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

SHADERS = Path(__file__).resolve().parent.parent / "shaders"
MAX_CONST_ARRAY = 64
_DECL = re.compile(r"\bconst\s+(?:float|int|uint|bool|[iu]?vec[234]|mat[234])\s+(\w+)\s*\[\s*(\d+)\s*\]")


def test_no_large_constant_arrays_in_shaders():
    big = []
    for f in sorted(SHADERS.rglob("*")):
        if f.suffix not in (".glsl", ".comp", ".frag", ".vert", ".geom"):
            continue
        for m in _DECL.finditer(f.read_text()):
            if int(m.group(2)) > MAX_CONST_ARRAY:
                big.append(f"{f.relative_to(SHADERS)}: {m.group(1)}[{m.group(2)}]")
    assert not big, f"constant arrays over {MAX_CONST_ARRAY} elements (use a texture or buffer): {big}"


def test_brdf_lut_holds_the_tables():
    pytest.importorskip("moderngl")
    from gi_preview.render import brdf_tables as T
    from gi_preview.render.gl import get_gl
    from gi_preview.render.shaders import brdf_lut

    def read():
        ctx = get_gl().ctx
        return np.frombuffer(brdf_lut(ctx).read(), np.float32).reshape(-1, 1024)

    lut = get_gl().call(read)
    np.testing.assert_array_equal(lut[0], np.asarray(T.GGX_E, np.float32))
    np.testing.assert_array_equal(lut[1, :32], np.asarray(T.GGX_EAVG, np.float32))
    np.testing.assert_array_equal(lut[2:6].ravel(), np.asarray(T.GGX_SCHLICK_S, np.float32))
    np.testing.assert_array_equal(lut[6:10].ravel(), np.asarray(T.GGX_GLASS_E, np.float32))
    np.testing.assert_array_equal(lut[10:14].ravel(), np.asarray(T.GGX_GLASS_INV_E, np.float32))
