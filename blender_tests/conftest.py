"""Shared pytest setup for tests run with the PyPI ``bpy`` module.

Done at import time, before any test module imports bpy:
- ``BLENDER_USER_RESOURCES`` points at a fresh temporary folder, so tests never read or
  write the real user's Blender preferences, extensions or caches (hermetic runs);
- a temporary folder holding the symlink ``gi_preview -> <repo>/addon`` goes first on
  ``sys.path``, so tests can ``import gi_preview`` (and its subpackages) without
  installing the extension.
"""

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ADDON_DIR = REPO / "addon"

_TMP = Path(tempfile.mkdtemp(prefix="gi_preview_tests_"))
atexit.register(shutil.rmtree, _TMP, ignore_errors=True)

# Hermetic Blender user folder; must be set before `import bpy` anywhere.
os.environ["BLENDER_USER_RESOURCES"] = str(_TMP / "blender_user")
(_TMP / "blender_user").mkdir()

# `import gi_preview` -> <repo>/addon
_PKG_ROOT = _TMP / "pkg"
_PKG_ROOT.mkdir()
(_PKG_ROOT / "gi_preview").symlink_to(ADDON_DIR, target_is_directory=True)
sys.path.insert(0, str(_PKG_ROOT))


# ---------------------------------------------------------------- fixtures
import pytest  # noqa: E402


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "serial: bounds on wall time, latency or thread races that hold only while no other "
                   "test process shares the cores (scripts/test.sh runs these after the parallel part)")

_ID_COLLECTIONS = ("scenes", "objects", "meshes", "materials", "lights", "cameras", "worlds", "images",
                   "collections", "node_groups", "textures", "curves", "actions", "metaballs")


def _bpy():
    try:
        import bpy
    except ImportError:  # bpy-free test runs
        return None
    return bpy


# Blender's own images, which it keeps pointers to: never removed by the cleanup.
_KEEP = {("images", "Render Result"), ("images", "Viewer Node")}


def _all_ids(bpy) -> dict:
    out = {}
    for attr in _ID_COLLECTIONS:
        for idb in getattr(bpy.data, attr):
            if (attr, idb.name_full) not in _KEEP:
                out[(attr, idb.name_full)] = idb
    return out


@pytest.fixture(scope="session", autouse=True)
def gi_preview_addon():
    """Register the add-on once for the whole run (as Blender does at start-up), so that
    tests see one registration, not repeated register/unregister cycles."""
    bpy = _bpy()
    if bpy is None:
        yield None
        return
    import gi_preview

    gi_preview.register()
    yield gi_preview
    gi_preview.unregister()


@pytest.fixture(autouse=True)
def clean_blend_data():
    """Remove every datablock a test created, so names never collide between tests."""
    bpy = _bpy()
    if bpy is None:
        yield
        return
    before = set(_all_ids(bpy))
    window = bpy.context.window
    scene = window.scene if window is not None else None
    yield
    if window is not None and scene is not None and window.scene != scene:
        window.scene = scene  # never leave the window on a scene about to be removed
    new = [idb for key, idb in _all_ids(bpy).items() if key not in before]
    if new:
        bpy.data.batch_remove(new)
