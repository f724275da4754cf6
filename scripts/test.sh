#!/usr/bin/env bash
# Set up (idempotent, fast when done) and run the test suite with the bpy module.
# Extra arguments go to pytest, e.g.  bash scripts/test.sh -k install -v
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh

# Headless Chromium for blender_tests/test_report_browser.py (report.html in a browser): installed
# quietly with apt-get when missing and run as root; without it that test is skipped.
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1 \
        && ! command -v google-chrome >/dev/null 2>&1 \
        && [[ "$(id -u)" == 0 ]] && command -v apt-get >/dev/null 2>&1; then
    echo "[test] installing chromium (apt-get) for the report browser test"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium; } \
        >/dev/null 2>&1 || echo "[test] WARNING: could not install chromium; test_report_browser is skipped" >&2
fi

set +e
.venv/bin/python -m pytest blender_tests -q -rs --durations=30 "$@"
rc=$?
set -e
if [[ $rc == 5 ]]; then
    echo "[test] ERROR: pytest collected no tests (exit code 5): blender_tests/ has no tests," \
         "or the arguments deselected all of them" >&2
    exit 1
fi
exit $rc
