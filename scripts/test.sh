#!/usr/bin/env bash
# README command 2 (and CI): install what is missing, then run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
# The release profile: after `scripts/demo.sh` its dependencies are built already (the test
# profile would build them all again; docs/measurements/speed.md, "Build and suite time").
cargo test --release --locked "$@"
