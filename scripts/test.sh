#!/usr/bin/env bash
# Set up (idempotent, fast when done) and run the test suite with the bpy module.
# Extra arguments go to pytest, e.g.  bash scripts/test.sh -k install -v
#
# Two parts: every test not marked `serial` on two worker processes (pytest-xdist, one test
# file per worker at a time: llvmpipe compiles each shader program on one core, so a second
# process keeps both cores busy), then the `serial` tests in one process on their own (their
# bounds on wall time, latency and thread races assume no other test process). Compiled
# shaders carry over from the first part through Mesa's on-disk shader cache.
# GI_PREVIEW_TEST_WORKERS sets the number of worker processes (0: one process, no xdist).
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

workers="${GI_PREVIEW_TEST_WORKERS:-2}"
run() {  # run <pytest args...>; called as `run ... && rc=0 || rc=$?`, so a failure does not stop the script
    .venv/bin/python -m pytest blender_tests -q -rs --durations=30 "$@"
}
if [[ "$workers" == 0 ]]; then
    run "$@" && rc=0 || rc=$?
    rc_serial=5
else
    echo "[test] part 1: the tests not marked serial, on $workers worker processes"
    run -n "$workers" --dist loadfile -m "not serial" "$@" && rc=0 || rc=$?
    echo "[test] part 2: the serial tests, in one process"
    run -m serial "$@" && rc_serial=0 || rc_serial=$?
fi
if [[ $rc == 5 && $rc_serial == 5 ]]; then
    echo "[test] ERROR: pytest collected no tests (exit code 5): blender_tests/ has no tests," \
         "or the arguments deselected all of them" >&2
    exit 1
fi
for r in "$rc" "$rc_serial"; do
    if [[ $r != 0 && $r != 5 ]]; then
        exit "$r"
    fi
done
exit 0
