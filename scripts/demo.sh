#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job on the bundled
# default data (generated deterministically on first use).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
cargo build --release --locked
wb=target/release/workbench
if [ ! -f datasets/demo/session.json ] || [ ! -f calib/demo/truth.json ]; then
  datasets/generate.sh "$wb"
fi
# Calibrated every time (1.5 s; the result is the same to the byte for the same views, so what
# depends on it by content — detections.json, fit.json — is still reused).
"$wb" calibrate calib/demo
"$wb" check datasets/demo
"$wb" detect datasets/demo
# The joint fit: reuses detections.json (its inputs unchanged by content) and the calibration.
"$wb" solve --joint datasets/demo --plots datasets/demo/plots
# Rendering with the measured CDRF: the table, the renderer checked against the fit's spheres,
# and the Stanford bunny when ../shared has it.
"$wb" lut datasets/demo/fit.json
"$wb" render --check --fit datasets/demo/fit.json
bunny=../shared/data/meshes/stanford-bunny.obj
if [ -f "$bunny" ]; then
  "$wb" render "$bunny" --unit m --fit datasets/demo/fit.json --out datasets/demo/bunny.png
  "$wb" view datasets/demo/fit.json --mesh "$bunny" --unit m
else
  echo "$bunny absent: bunny render skipped"
  "$wb" view datasets/demo/fit.json
fi
