#!/usr/bin/env bash
# README command 2 (and CI): install what is missing, then run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
# The release profile: after `scripts/demo.sh` its dependencies are built already (the test
# profile would build them all again; docs/measurements/speed.md, "Build and suite time").
# A test whose data (../shared) or tool is missing passes without running, outside CI; each lists
# itself here (tests/it/common/mod.rs, `skipped`), and the list is printed at the end.
skipped="${CARGO_TARGET_DIR:-target}/tmp/skipped-tests.txt"
rm -f "$skipped"
status=0
cargo test --release --locked "$@" || status=$?
if [ -s "$skipped" ]; then
  echo
  echo "SKIPPED: $(wc -l <"$skipped") test(s) passed without running what they check:"
  sed 's/^/  /' "$skipped"
fi
exit "$status"
