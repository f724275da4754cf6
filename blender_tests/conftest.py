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
