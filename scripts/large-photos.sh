#!/usr/bin/env bash
# The default solve on 12-megapixel photos (docs/measurements/speed.md, "The medium's pixels in
# blocks on large photos"): the demo's five spheres rendered at 4000×3000 (the demo camera's field
# of view), then `solve --irradiance 1` with the CDRF alone and with the default model (the
# medium after it), each on a fresh copy; prints fit.json's timings against decoding, the
# medium's pixel-channels and rows, and the process's peak memory.
# Usage: scripts/large-photos.sh [path/to/workbench] [scratch dir]   (needs python3, GNU time)
set -euo pipefail
cd "$(dirname "$0")/.."
wb=$(realpath "${1:-target/release/workbench}")
out=${2:-$(mktemp -d)}
mkdir -p "$out"
src="$out/large"
rm -rf "$src"
"$wb" --quiet synth session --out "$src" --seed 7 --size 4000x3000 --fx 4375
for model in cdrf auto; do
  d="$out/large-$model"
  rm -rf "$d"
  cp -r "$src" "$d"
  /usr/bin/time -f "%M" -o "$d.rss" "$wb" --quiet solve "$d" --irradiance 1 --model "$model" >"$d.log" 2>&1
  python3 - "$d/fit.json" "$model" "$d.rss" <<'PY'
import json, sys
f = json.load(open(sys.argv[1]))
t = f["timings"]
d = t["decode_s"]
m = f.get("medium") or {}
rss = int(open(sys.argv[3]).read().split()[-1]) / 1e6
print(f"{sys.argv[2]:5s} decode {d:.2f} s  detect {t['detect_s']:.1f} s  medium {t['medium_s']:.1f} s  "
      f"total {t['total_s']:.1f} s ({t['total_s'] / d:.0f}x decode)  peak {rss:.2f} GB"
      + (f"  medium: {m['pixels']} pixel-channels as {m.get('blocks') or m['pixels']} rows" if m else ""))
PY
done
