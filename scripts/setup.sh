#!/usr/bin/env bash
# Set up a Debian/Ubuntu machine to develop and test GI Preview. Idempotent: a second run
# only checks and finishes in a few seconds.
#   1. Mesa's EGL/OpenGL libraries (installed with apt-get when missing and run as root);
#   2. .venv at the repository root, made with python3.11 (bpy 5.0 needs CPython 3.11);
#   3. the pinned packages of requirements.txt (skipped when already installed);
#   4. a check that moderngl opens a headless EGL context with OpenGL >= 4.3.
# Environment: PYTHON=/path/to/python3.11 overrides the interpreter used to make .venv.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
REPO="$(pwd)"
VENV="$REPO/.venv"
PY="${PYTHON:-python3.11}"

say() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# --- 1. Mesa EGL / GL ---------------------------------------------------------------
# libegl1 + libgl1: the GLVND loaders glcontext opens; libegl-mesa0: Mesa's EGL vendor;
# libgl1-mesa-dri: the llvmpipe software rasteriser (or the GPU's driver).
GL_PACKAGES=(libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri)
if command -v dpkg-query >/dev/null 2>&1; then
    missing=()
    for pkg in "${GL_PACKAGES[@]}"; do
        status="$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)"
        [[ "$status" == "install ok installed" ]] || missing+=("$pkg")
    done
    if ((${#missing[@]})); then
        if [[ "$(id -u)" == 0 ]] && command -v apt-get >/dev/null 2>&1; then
            say "installing missing system packages: ${missing[*]}"
            apt-get update
            DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}" \
                || die "apt-get could not install: ${missing[*]}"
        else
            die "missing system packages: ${missing[*]}
        install them as root:  sudo apt-get update && sudo apt-get install -y ${missing[*]}"
        fi
    else
        say "system GL packages present: ${GL_PACKAGES[*]}"
    fi
else
    say "warning: not a Debian system (no dpkg-query); make sure Mesa's EGL and OpenGL" \
        "libraries (libEGL.so.1, libGL.so.1, a DRI driver) are installed"
fi

# --- 2. Python 3.11 virtual environment ---------------------------------------------
if [[ ! -x "$VENV/bin/python" ]]; then
    command -v "$PY" >/dev/null 2>&1 || die "$PY not found. bpy 5.0 needs CPython 3.11:
        install it (e.g. apt-get install python3.11 python3.11-venv, or pyenv install 3.11),
        or set PYTHON=/path/to/python3.11"
    say "creating $VENV with $("$PY" --version 2>&1)"
    "$PY" -m venv "$VENV" || die "'$PY -m venv' failed (on Debian/Ubuntu: apt-get install python3.11-venv)"
fi
venv_version="$("$VENV/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
[[ "$venv_version" == "3.11" ]] \
    || die "$VENV uses Python $venv_version, but bpy 5.0 needs 3.11: remove .venv and run again"

# --- 3. Pinned requirements ---------------------------------------------------------
# Fast path: every 'name==version' line of requirements.txt is already installed.
requirements_met() {
    "$VENV/bin/python" - "$REPO/requirements.txt" <<'PYEOF'
import sys
from importlib import metadata

ok = True
for line in open(sys.argv[1], encoding="utf-8"):
    req = line.split("#", 1)[0].strip()
    if not req:
        continue
    name, _, wanted = req.partition("==")
    name = name.split("[", 1)[0].strip()  # dask[distributed]: the extra's packages come with it
    try:
        have = metadata.version(name)
    except metadata.PackageNotFoundError:
        have = None
    if have is None or (wanted and have != wanted.strip()):
        print(f"[setup] needs {req} (installed: {have})")
        ok = False
sys.exit(0 if ok else 1)
PYEOF
}
if requirements_met; then
    say "requirements.txt already satisfied in .venv"
else
    say "installing requirements.txt into .venv (bpy is ~300 MB the first time)"
    "$VENV/bin/python" -m pip install --disable-pip-version-check -r "$REPO/requirements.txt" \
        || die "pip install -r requirements.txt failed"
    requirements_met || die "requirements still not satisfied after pip install"
fi

# --- 4. Headless OpenGL check -------------------------------------------------------
"$VENV/bin/python" - <<'PYEOF' || die "no usable headless OpenGL 4.3 context (see above)"
import ctypes.util
import sys

try:
    import moderngl
except ImportError as ex:
    print(f"[setup] moderngl is not importable from .venv: {ex}")
    sys.exit(1)
try:
    ctx = moderngl.create_standalone_context(backend="egl", require=430)
except Exception as ex:
    print(f"[setup] moderngl.create_standalone_context(backend='egl', require=430) failed: {ex}")
    for lib, pkg in (("EGL", "libegl1 + libegl-mesa0"), ("GL", "libgl1")):
        found = ctypes.util.find_library(lib)
        print(f"[setup]   lib{lib}: {found or 'NOT FOUND (package ' + pkg + ')'}")
    print("[setup]   a DRI driver (llvmpipe/swrast) comes with libgl1-mesa-dri;"
          " OpenGL 4.3 needs Mesa >= 20 for llvmpipe")
    sys.exit(1)
info = ctx.info
print(f"[setup] OpenGL OK: {info['GL_RENDERER']} | {info['GL_VERSION']} (version_code {ctx.version_code})")
ctx.release()
PYEOF
say "done: use $VENV/bin/python"
