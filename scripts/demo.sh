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
# A known calibration is not redone: calibrate only when intrinsics.json is missing or older
# than the photos.
if [ ! -f calib/demo/intrinsics.json ] || [ -n "$(find calib/demo -maxdepth 1 -name 'view*' -newer calib/demo/intrinsics.json)" ]; then
  "$wb" calibrate calib/demo
else
  echo "calib/demo/intrinsics.json is up to date: calibration reused"
fi
"$wb" check datasets/demo
"$wb" detect datasets/demo
# The joint fit: reuses detections.json (newer than its inputs) and the calibration.
"$wb" solve --joint datasets/demo --plots datasets/demo/plots
