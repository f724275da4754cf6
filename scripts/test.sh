#!/usr/bin/env bash
# Set up (idempotent, fast when done) and run the test suite with the bpy module.
# Extra arguments go to pytest, e.g.  bash scripts/test.sh -k install -v
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh

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
