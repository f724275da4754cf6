"""Make this checkout's add-on importable as ``gi_preview`` (for the scripts in scripts/).

The add-on's folder is ``addon/``; Python needs a package named ``gi_preview``, so a
temporary folder holding the symlink ``gi_preview -> <repo>/addon`` goes first on
``sys.path`` (the same arrangement blender_tests/conftest.py makes for the tests).
"""
from __future__ import annotations

import importlib
import os
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON = os.path.join(REPO, "addon")


def import_checkout_package():
    """Import and return ``gi_preview`` from this checkout (a no-op if already imported)."""
    if "gi_preview" in sys.modules:
        return sys.modules["gi_preview"]
    d = tempfile.mkdtemp(prefix="gi_preview_pkg_")
    os.symlink(ADDON, os.path.join(d, "gi_preview"), target_is_directory=True)
    sys.path.insert(0, d)
    return importlib.import_module("gi_preview")


def setup_blender():
    """The benchmark scripts' set-up: a hermetic Blender user folder (before ``bpy`` is
    imported), this checkout's ``gi_preview`` imported and registered. Returns the package."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="gi_preview_user_"))
    pkg = import_checkout_package()
    import bpy  # noqa: F401  (Blender first, then the add-on's registration)
    if not getattr(pkg, "_registered_by_checkout", False):
        pkg.register()
        pkg._registered_by_checkout = True
    return pkg
