"""The built extension zip installs into Blender and works from its own wheels.

Builds the zip for this platform with scripts/build_extension.py (reusing dist/ when it is
newer than every source file), then, in a fresh Python with bpy and a private
BLENDER_USER_RESOURCES, installs it the way Blender's "Install from Disk" does and checks:
- the add-on ``bl_ext.user_default.gi_preview`` is enabled;
- the render engine ``GI_PREVIEW`` is registered and a scene can select it;
- moderngl, glcontext and flip_evaluator import from the extension's installed wheels
  (copies in the test venv are hidden, as they would not exist inside Blender), and the
  bundled moderngl opens an EGL context;
- disabling the add-on unregisters the engine.
"""

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
BUILD_SCRIPT = REPO / "scripts" / "build_extension.py"
MODULE = "bl_ext.user_default.gi_preview"

# Runs in the child process. argv: zip path, JSON list of folders whose copies of the
# bundled packages must stay hidden (the test venv's site-packages).
CHILD = r'''
import importlib.machinery, json, os, sys

zip_path = sys.argv[1]
hidden_dirs = {os.path.realpath(p) for p in json.loads(sys.argv[2])}
BUNDLED = {"moderngl", "_moderngl", "glcontext", "flip_evaluator"}


class HideVenvCopies:
    """Find the bundled packages anywhere on sys.path except the test venv."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if path is not None or name.split(".")[0] not in BUNDLED:
            return None
        search = [p for p in sys.path if os.path.realpath(p or ".") not in hidden_dirs]
        spec = importlib.machinery.PathFinder.find_spec(name, search)
        if spec is None:
            raise ModuleNotFoundError(f"{name} is not installed from the extension wheels", name=name)
        return spec


sys.meta_path.insert(0, HideVenvCopies)

import bpy  # noqa: E402  (puts Blender's script folders on sys.path)
import addon_utils  # noqa: E402

out = {}
out["install"] = sorted(bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True))
out["enabled"] = list(addon_utils.check("MODULE"))
out["in_prefs"] = "MODULE" in bpy.context.preferences.addons
out["engines"] = sorted(
    getattr(cls, "bl_idname", "") for cls in bpy.types.RenderEngine.__subclasses__()
    if getattr(cls, "is_registered", False))
try:
    bpy.context.scene.render.engine = "GI_PREVIEW"
    out["scene_engine"] = bpy.context.scene.render.engine
except Exception as ex:
    out["scene_engine"] = repr(ex)

site = bpy.utils.user_resource("EXTENSIONS", path=".local/lib/python3.11/site-packages")
out["wheel_site"] = os.path.realpath(site)
out["wheel_site_on_path"] = site in sys.path
out["modules"] = {}
for name in ("moderngl", "glcontext", "flip_evaluator"):
    try:
        module = __import__(name)
        out["modules"][name] = os.path.realpath(module.__file__)
    except Exception as ex:
        out["modules"][name] = "ERROR " + repr(ex)
try:
    import moderngl
    ctx = moderngl.create_standalone_context(backend="egl", require=430)
    out["gl"] = [ctx.info["GL_RENDERER"], ctx.version_code]
    ctx.release()
except Exception as ex:
    out["gl"] = "ERROR " + repr(ex)

addon_utils.disable("MODULE", default_set=True)
out["engines_after_disable"] = sorted(
    getattr(cls, "bl_idname", "") for cls in bpy.types.RenderEngine.__subclasses__()
    if getattr(cls, "is_registered", False))
print("RESULT " + json.dumps(out))
'''.replace("MODULE", MODULE)


def _load_build_module():
    spec = importlib.util.spec_from_file_location("gi_build_extension", BUILD_SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _built_zip(tmp_path: Path) -> Path:
    """Build (if stale) and return a private copy of this platform's zip."""
    proc = subprocess.run(
        [sys.executable, str(BUILD_SCRIPT), "--if-stale"],
        cwd=REPO, capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, f"build_extension.py failed:\n{proc.stdout}\n{proc.stderr}"
    zip_path = _load_build_module().zip_path_for_platform()
    assert zip_path.is_file(), f"no zip for this platform at {zip_path}:\n{proc.stdout}"
    private = tmp_path / zip_path.name
    shutil.copy2(zip_path, private)  # other runs may rebuild dist/ meanwhile
    return private


def test_zip_installs_enables_and_uses_bundled_wheels(tmp_path):
    zip_path = _built_zip(tmp_path)

    user_resources = tmp_path / "blender_user"
    user_resources.mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user_resources))
    venv_site = [p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir()]
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, str(zip_path), json.dumps(venv_site)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
    )
    log = f"--- stdout\n{proc.stdout}\n--- stderr\n{proc.stderr}"
    assert proc.returncode == 0, log
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert lines, log
    out = json.loads(lines[-1][len("RESULT "):])

    assert out["install"] == ["FINISHED"], log
    assert out["enabled"] == [True, True], f"{MODULE} not enabled\n{log}"
    assert out["in_prefs"], log
    assert "GI_PREVIEW" in out["engines"], f"engines: {out['engines']}\n{log}"
    assert out["scene_engine"] == "GI_PREVIEW", log

    site = out["wheel_site"]
    assert site.startswith(os.path.realpath(user_resources)), out
    assert out["wheel_site_on_path"], out
    for name, path in out["modules"].items():
        assert path.startswith(site + os.sep), f"{name} not loaded from the extension wheels: {path}\n{log}"
    assert isinstance(out["gl"], list), f"bundled moderngl could not open an EGL context: {out['gl']}\n{log}"

    assert "GI_PREVIEW" not in out["engines_after_disable"], log


def test_manifest_platforms_match_opengl_43():
    """Only platforms with OpenGL 4.3 compute: no macOS (Apple's OpenGL stops at 4.1), no
    macOS wheel, one wheel of each bundled package per listed platform; the builder refuses
    a manifest that lists macOS again, naming the reason."""
    import pytest

    build = _load_build_module()
    manifest = build.read_manifest()
    assert manifest["platforms"] == ["linux-x64", "windows-x64"]
    assert not [w for w in manifest["wheels"] if "macosx" in w]
    for package in ("moderngl", "glcontext", "flip_evaluator"):
        tags = [w for w in manifest["wheels"] if Path(w).name.startswith(package + "-")]
        assert len(tags) == 2 and any("win_amd64" in w for w in tags) and any("linux" in w for w in tags), tags
    build.check_platforms(manifest)  # the real manifest passes
    with pytest.raises(SystemExit, match="OpenGL stops at 4.1"):
        build.check_platforms({**manifest, "platforms": manifest["platforms"] + ["macos-arm64"]})
    with pytest.raises(SystemExit, match="macosx"):
        build.check_platforms({**manifest, "wheels": manifest["wheels"] + ["./wheels/x-1-cp311-cp311-macosx_11_0_arm64.whl"]})
