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
"$wb" check datasets/demo
