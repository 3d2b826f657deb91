#!/usr/bin/env bash
# Render the four corners of the issue's range of media (datasets/pbr-range/, docs/medium.md,
# "Across the issue's range"): σt 0.5 and 3 /mm, albedo 0.70–0.80 and 0.985–0.995, η 1.3 and
# 1.6, each session under its own light and noise seed, as the coverage sessions of
# scripts/pbr-seeds.sh (640×480, fx 800, 1024 samples a pixel; 30–100 s a session on 2 cores,
# the white ones the longest).
# The suite solves thin-dark (`medium::a_first_start_at_the_walls_is_started_again`,
# `uncertainty::a_clipped_highlights_eta_is_covered_with_the_detectors_alpha`); the table in
# docs/medium.md solves all four.
# Usage: scripts/pbr-range.sh [path/to/workbench] [output dir]   (default: datasets/pbr-range)
set -euo pipefail
cd "$(dirname "$0")/.."
wb=${1:-target/release/workbench}
out=${2:-datasets/pbr-range}
source scripts/lib/pbr-render.sh
# name        σt   albedo r,g,b         η     α     azimuth elevation seed material
render_sessions "$wb" "$out" \
  "dense-dark   3.0  0.70,0.75,0.80      1.30  0.10   35  25  31  dense-dark" \
  "dense-white  3.0  0.995,0.99,0.985    1.60  0.10  -40  20  32  dense-white" \
  "thin-dark    0.5  0.70,0.75,0.80      1.60  0.10   50  15  33  thin-dark" \
  "thin-white   0.5  0.995,0.99,0.985    1.30  0.10  -55  30  34  thin-white"
