#!/usr/bin/env bash
# Install the system packages workbench needs (Debian 12), skipping what is present.
# Idempotent. As root it installs; otherwise it prints the exact apt-get line and fails.
set -euo pipefail
packages=(libopencv-dev clang libclang-dev pkg-config glslang-tools chromium python3)
missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if ((${#missing[@]})); then
  if [ "$(id -u)" -ne 0 ]; then
    echo "workbench needs system packages; run as root:" >&2
    echo "  apt-get update && apt-get install -y --no-install-recommends ${missing[*]}" >&2
    exit 1
  fi
  echo "installing: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
if ! command -v cargo >/dev/null 2>&1; then
  echo "cargo not found: install Rust (https://rustup.rs) first" >&2
  exit 1
fi
# Mitsuba 3 (with Dr.Jit), for the test that loads and renders `workbench export --to mitsuba`
# (tests/it/medium.rs): from PyPI into the build folder, where the tests look for it; no numpy.
cd "$(dirname "$0")/.."
mitsuba_dir="${CARGO_TARGET_DIR:-target}/python"
if ! PYTHONPATH="$mitsuba_dir" python3 -c "import mitsuba; assert mitsuba.__version__ == '3.9.1'" 2>/dev/null; then
  echo "installing: mitsuba 3.9.1 (PyPI) into $mitsuba_dir" >&2
  python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore --upgrade --target "$mitsuba_dir" mitsuba==3.9.1
fi
