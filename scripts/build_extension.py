#!/usr/bin/env python3
"""Build the GI Preview extension zips with Blender's own extension builder.

Usage (from the repository root, with the venv that has the bpy module):

    .venv/bin/python scripts/build_extension.py

Steps:
1. Read ``addon/blender_manifest.toml``. Its ``wheels = [...]`` list is the one source
   of truth: each entry is an exact PyPI wheel filename (pinned version and platform).
2. Download each missing wheel once into ``build/wheels_cache/`` with
   ``pip download --only-binary=:all: --no-deps --python-version 3.11 --platform ...``
   and check that pip fetched exactly the listed file.
3. Stage ``addon/`` + ``shaders/`` + the wheels into ``build/gi_preview/``
   (``shaders/`` goes inside the package; ``__pycache__`` and ``*.pyc`` are left out).
4. Run Blender's ``blender_ext.py validate build/gi_preview`` and
   ``build --source-dir build/gi_preview --output-dir dist --split-platforms``, which
   writes one zip per platform named ``dist/<id>-<version>-<platform>.zip``
   (e.g. ``dist/gi_preview-0.1.0-linux_x64.zip``), each holding only its platform's wheels.
5. Run ``validate`` on every zip and print the zip paths; the last line names the zip
   for the platform this script runs on.

Platforms: Linux x64 and Windows x64. There is no macOS zip: GI Preview needs OpenGL 4.3
compute shaders and Apple's OpenGL stops at 4.1 (see ``UNSUPPORTED_PLATFORMS``); the
manifest lists no macOS platform or wheel, and :func:`check_platforms` refuses one.

Only the Python standard library and ``bpy`` (to locate ``blender_ext.py``) are used.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

try:
    import fcntl  # POSIX only; on Windows builds are simply not serialised
except ImportError:
    fcntl = None

REPO = Path(__file__).resolve().parent.parent
ADDON_DIR = REPO / "addon"
SHADERS_DIR = REPO / "shaders"
MANIFEST = ADDON_DIR / "blender_manifest.toml"
BUILD_DIR = REPO / "build"
WHEELS_CACHE = BUILD_DIR / "wheels_cache"
DIST_DIR = REPO / "dist"

# Wheels are bundled for the Python that Blender 4.2 - 5.0 ship.
PYTHON_VERSION = "3.11"

IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", ".DS_Store")

# Blender platforms GI Preview cannot run on, and why (checked against the manifest).
UNSUPPORTED_PLATFORMS = {
    "macos-arm64": "Apple's OpenGL stops at 4.1: no compute shaders (GI Preview needs OpenGL 4.3)",
    "macos-x64": "Apple's OpenGL stops at 4.1: no compute shaders (GI Preview needs OpenGL 4.3)",
}


def check_platforms(manifest: dict) -> None:
    """Refuse a manifest that lists a platform (or bundles a wheel for one) GI Preview
    cannot run on: a zip for it would install and then fail on the first render."""
    bad = [p for p in manifest.get("platforms", []) if p in UNSUPPORTED_PLATFORMS]
    bad_wheels = [w for w in manifest.get("wheels", []) if "macosx" in w]
    if bad or bad_wheels:
        why = "; ".join(f"{p}: {UNSUPPORTED_PLATFORMS[p]}" for p in bad) or UNSUPPORTED_PLATFORMS["macos-arm64"]
        raise SystemExit(f"blender_manifest.toml lists unsupported platforms/wheels "
                         f"{bad + bad_wheels}: {why}")


def read_manifest() -> dict:
    with open(MANIFEST, "rb") as fh:
        return tomllib.load(fh)


def staged_dir(manifest: dict | None = None) -> Path:
    manifest = manifest or read_manifest()
    return BUILD_DIR / manifest["id"]


def blender_platform_of_this_system() -> str:
    """Blender's platform name for this machine, e.g. ``linux-x64`` (same rule as blender_ext.py)."""
    system = {"darwin": "macos"}.get(platform.system().lower(), platform.system().lower())
    machine = platform.machine().lower()
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64", "aarch32": "arm32"}.get(machine, machine)
    return f"{system}-{machine}"


def zip_path_for_platform(blender_platform: str | None = None, manifest: dict | None = None) -> Path:
    """Path of the zip ``build`` writes for a platform: ``dist/<id>-<version>-<platform>.zip``."""
    manifest = manifest or read_manifest()
    blender_platform = blender_platform or blender_platform_of_this_system()
    return DIST_DIR / "{}-{}-{}.zip".format(manifest["id"], manifest["version"], blender_platform.replace("-", "_"))


def source_files() -> list[Path]:
    """Every file that ends up in the zip or decides its content (for staleness checks)."""
    files = [Path(__file__).resolve()]
    for root in (ADDON_DIR, SHADERS_DIR):
        if not root.is_dir():
            continue
        for path in root.rglob("*"):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix not in (".pyc", ".pyo"):
                files.append(path)
    return files


def zip_is_up_to_date(zip_path: Path) -> bool:
    """True when ``zip_path`` exists and is newer than every source file."""
    if not zip_path.is_file():
        return False
    built = zip_path.stat().st_mtime
    return all(path.stat().st_mtime < built for path in source_files())


def run(cmd: list[str], **kwargs) -> None:
    print("+", " ".join(str(c) for c in cmd), flush=True)
    subprocess.run([str(c) for c in cmd], check=True, **kwargs)


def parse_wheel_filename(filename: str) -> tuple[str, str, list[str]]:
    """``name-version-pytag-abitag-plat.whl`` -> (name, version, [platform tags])."""
    parts = filename[: -len(".whl")].split("-")
    if len(parts) not in (5, 6):  # 6 when there is a build tag
        raise SystemExit(f"not a wheel filename: {filename}")
    return parts[0], parts[1], parts[-1].split(".")


def fetch_wheels(manifest: dict) -> list[Path]:
    """Make sure every wheel listed in the manifest is in the cache; return their cached paths."""
    WHEELS_CACHE.mkdir(parents=True, exist_ok=True)
    cached = []
    for entry in manifest.get("wheels", []):
        filename = os.path.basename(entry)
        target = WHEELS_CACHE / filename
        if not target.is_file():
            name, version, platform_tags = parse_wheel_filename(filename)
            with tempfile.TemporaryDirectory(dir=BUILD_DIR) as tmp:
                cmd = [
                    sys.executable, "-m", "pip", "download", "--disable-pip-version-check",
                    "--only-binary=:all:", "--no-deps", "--python-version", PYTHON_VERSION,
                    "--dest", tmp,
                ]
                for tag in platform_tags:
                    cmd += ["--platform", tag]
                run(cmd + [f"{name}=={version}"])
                got = sorted(os.listdir(tmp))
                if got != [filename]:
                    raise SystemExit(
                        f"pip downloaded {got} but the manifest lists {filename}: "
                        "fix the wheels list in addon/blender_manifest.toml"
                    )
                shutil.move(os.path.join(tmp, filename), target)
        print(f"wheel: {target.relative_to(REPO)}")
        cached.append(target)
    return cached


def stage(manifest: dict, wheels: list[Path]) -> Path:
    """Copy addon/ + shaders/ + wheels into build/<id>/ (a clean copy every time)."""
    out = staged_dir(manifest)
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(ADDON_DIR, out, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", ".DS_Store", "wheels"))
    if SHADERS_DIR.is_dir():
        if (out / "shaders").exists():
            raise SystemExit("addon/shaders exists and would clash with the top-level shaders/ folder")
        shutil.copytree(SHADERS_DIR, out / "shaders", ignore=IGNORE)
    else:
        print("warning: no shaders/ folder at the repository root; the package has no shaders", file=sys.stderr)
    (out / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, out / "wheels" / wheel.name)
    print(f"staged: {out.relative_to(REPO)}")
    return out


def blender_ext_script() -> str:
    import bpy  # the PyPI bpy module: only used to locate Blender's builder

    path = os.path.join(bpy.utils.resource_path("LOCAL"), "scripts/addons_core/bl_pkg/cli/blender_ext.py")
    if not os.path.isfile(path):
        raise SystemExit(f"Blender's extension builder not found at {path}")
    return path


def build(manifest: dict) -> list[Path]:
    check_platforms(manifest)
    wheels = fetch_wheels(manifest)
    src = stage(manifest, wheels)
    tool = blender_ext_script()

    run([sys.executable, tool, "validate", src])

    DIST_DIR.mkdir(exist_ok=True)
    prefix = "{}-{}".format(manifest["id"], manifest["version"])
    for old in DIST_DIR.glob(prefix + "*.zip"):
        old.unlink()
    run([sys.executable, tool, "build", "--source-dir", src, "--output-dir", DIST_DIR, "--split-platforms"])

    zips = [zip_path_for_platform(p, manifest) for p in manifest["platforms"]]
    for path in zips:
        if not path.is_file():
            raise SystemExit(f"Blender's builder did not write {path}")
        run([sys.executable, tool, "validate", path])
    return zips


@contextlib.contextmanager
def build_lock():
    """Serialise builds: several people or test runs may share one working tree."""
    BUILD_DIR.mkdir(exist_ok=True)
    if fcntl is None:
        yield
        return
    with open(BUILD_DIR / ".build.lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--if-stale", action="store_true",
        help="do nothing when the zip for this platform is newer than every source file",
    )
    args = parser.parse_args(argv)

    with build_lock():
        manifest = read_manifest()
        current = zip_path_for_platform(manifest=manifest)
        if args.if_stale and zip_is_up_to_date(current):
            print(f"up to date: {current}")
            print(f"zip for this platform ({blender_platform_of_this_system()}): {current}")
            return 0
        zips = build(manifest)

    print("\nbuilt:")
    for path in zips:
        print(f"  {path}")
    if current in zips:
        print(f"zip for this platform ({blender_platform_of_this_system()}): {current}")
    else:
        why = UNSUPPORTED_PLATFORMS.get(blender_platform_of_this_system(), "not listed in the manifest")
        print(f"warning: no zip for this platform ({blender_platform_of_this_system()}): {why}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
