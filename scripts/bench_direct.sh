#!/usr/bin/env bash
# DIRECT against Cycles' direct-light reference on every demo scene (quality 0-3), written
# to OUT/<scene>/ (results.json, report.html, chart, PNGs), OUT defaulting to out/bench/direct.
# The numbers of docs/techniques/DIRECT.md. Usage:
#   bash scripts/bench_direct.sh [RES] [REF_SPP] [SAMPLES] [OUT]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
res=${1:-256}; ref=${2:-1024}; samples=${3:-16}; out=${4:-out/bench/direct}
for scene in cornell glossy_spheres sunlit_room emissive_panel many_lights; do
    .venv/bin/python scripts/gi_compare.py "$scene" --techniques DIRECT --quality 0,1,2,3 \
        --res "$res" --ref-spp "$ref" --frames 3 --samples "$samples" --reference direct \
        --out "$out/$scene"
done
