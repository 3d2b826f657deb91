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
mkdir -p "$out"
# name      σt   albedo r,g,b         η     α     azimuth elevation
sessions=(
  "wax-1    1.0  0.97,0.95,0.92      1.44  0.15  -50  30"
  "soap-2   0.5  0.975,0.963,0.945   1.40  0.08   65  15"
  "jade-3   2.0  0.90,0.96,0.92      1.62  0.05   40  25"
  "wax-4    1.0  0.97,0.95,0.92      1.44  0.15  -30  35"
  "soap-5   0.5  0.975,0.963,0.945   1.40  0.08   55  10"
  "jade-6   2.0  0.90,0.96,0.92      1.62  0.05  -65  20"
  "wax-7    1.0  0.97,0.95,0.92      1.44  0.15   25  40"
  "soap-8   0.5  0.975,0.963,0.945   1.40  0.08  -45  15"
)
for s in "${sessions[@]}"; do
  read -r name sigma_t albedo eta alpha az el <<<"$s"
  seed=${name##*-}
  "$wb" --quiet synth pbr --out "$out/$name" --size 640x480 --fx 800 --distance 500 \
    --spp 1024 --sigma-t "$sigma_t" --albedo "$albedo" --eta "$eta" --alpha "$alpha" \
    --light-azimuth "$az" --light-elevation "$el" --material "${name%-*}-like" --seed "$((100 + seed))"
  echo "$name rendered"
done
