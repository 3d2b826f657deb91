#!/usr/bin/env bash
# Regenerate the bundled default data deterministically (fixed seeds):
#   calib/demo/     15 checkerboard views of the demo camera, with truth.json
#   datasets/demo/  five wax spheres (35 30 25 20 15 mm), one 16-bit linear PNG each, with
#                   session.json (pointing at ../../calib/demo/intrinsics.json, which
#                   `workbench calibrate calib/demo` writes) and truth.json
# Both use the same (default) synthetic camera.
# Usage: datasets/generate.sh [path/to/workbench]   (default: target/release/workbench)
set -euo pipefail
cd "$(dirname "$0")/.."
wb=${1:-target/release/workbench}
"$wb" --quiet synth checkerboard --out calib/demo --seed 7
"$wb" --quiet synth session --out datasets/demo --seed 7 \
  --intrinsics-ref ../../calib/demo/intrinsics.json
