#!/usr/bin/env bash
# README command 2 (and CI): install what is missing, then run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
cargo test --locked "$@"
