#!/usr/bin/env bash
# Render the physically based coverage sessions (datasets/pbr-seeds/, docs/uncertainty.md,
# "Coverage on physically based sessions"): eight small `workbench synth pbr` sessions, three
# materials (wax-, soap- and jade-like) under eight lights, each with its own noise seed.
# The test `uncertainty::physically_based_coverage_over_seeds` solves the committed sessions;
# this script only re-renders them (about 45 s a session on 2 cores).
# Usage: scripts/pbr-seeds.sh [path/to/workbench] [output dir]   (default: datasets/pbr-seeds)
set -euo pipefail
cd "$(dirname "$0")/.."
wb=${1:-target/release/workbench}
out=${2:-datasets/pbr-seeds}
source scripts/lib/pbr-render.sh
# name      σt   albedo r,g,b         η     α     azimuth elevation seed material
render_sessions "$wb" "$out" \
  "wax-1    1.0  0.97,0.95,0.92      1.44  0.15  -50  30  101  wax-like" \
  "soap-2   0.5  0.975,0.963,0.945   1.40  0.08   65  15  102  soap-like" \
  "jade-3   2.0  0.90,0.96,0.92      1.62  0.05   40  25  103  jade-like" \
  "wax-4    1.0  0.97,0.95,0.92      1.44  0.15  -30  35  104  wax-like" \
  "soap-5   0.5  0.975,0.963,0.945   1.40  0.08   55  10  105  soap-like" \
  "jade-6   2.0  0.90,0.96,0.92      1.62  0.05  -65  20  106  jade-like" \
  "wax-7    1.0  0.97,0.95,0.92      1.44  0.15   25  40  107  wax-like" \
  "soap-8   0.5  0.975,0.963,0.945   1.40  0.08  -45  15  108  soap-like"
