"""Compute shaders owned by the tests (blender_tests/shaders/: probes that run one library
function per query), compiled with the add-on's shader library so that their
``#include "lib/..."`` lines resolve to the shipped files."""
from __future__ import annotations

from pathlib import Path

from gi_preview.render.shaders import ProgramCache, ShaderLibrary, shader_roots

TEST_SHADERS = Path(__file__).resolve().parent / "shaders"


def probe_programs(ctx) -> ProgramCache:
    """A program cache of ``ctx`` that finds the tests' shaders first, then the add-on's."""
    return ProgramCache(ctx, ShaderLibrary([TEST_SHADERS, *shader_roots()]))
