#!/usr/bin/env bash
# What `solve`'s default model costs where the light's irradiance is known
# (docs/measurements/speed.md, "The medium by default where the irradiance is known"): on fresh
# copies of pbr-soap, pbr-wax, pbr-jade (../shared) and the demo (after scripts/demo.sh),
# `solve --irradiance <E>` (--model auto: the medium after the CDRF) against the same with
# `--model cdrf`, alternated, two rounds; prints fit.json's timings. E is truth.json's
# irradiance; the demo's synthetic light has irradiance 1.
# Usage: scripts/auto-default-times.sh [path/to/workbench] [scratch dir]   (needs python3)
set -uo pipefail
cd "$(dirname "$0")/.."
wb=$(realpath "${1:-target/release/workbench}")
out=${2:-$(mktemp -d)}
mkdir -p "$out"
for round in 1 2; do
  for s in pbr-soap pbr-wax pbr-jade demo; do
    case $s in
      pbr-jade) src=../shared/data/pbr-jade ;;
      *) src=datasets/$s ;;
    esac
    if [ ! -f "$src/session.json" ]; then
      echo "$s: $src absent, skipped"
      continue
    fi
    if [ "$s" = demo ]; then
      e=1.0
    else
      e=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['irradiance_in_png_units'])" "$src/truth.json")
    fi
    for m in cdrf auto; do
      d="$out/$s-$m"
      rm -rf "$d"
      cp -r "$src" "$d"
      rm -rf "$d/detections.json" "$d/fit.json" "$d/overlays" "$d/plots"
      if [ "$s" = demo ]; then
        cp calib/demo/intrinsics.json "$d/intrinsics.json"
        sed -i 's#"../../calib/demo/intrinsics.json"#"intrinsics.json"#' "$d/session.json"
      fi
      args=(--quiet solve "$d" --irradiance "$e")
      [ "$m" = cdrf ] && args+=(--model cdrf)
      "$wb" "${args[@]}" >"$d.log" 2>&1
      python3 - "$d/fit.json" "$s" "$m" <<'PY'
import json, sys
try:
    f = json.load(open(sys.argv[1]))
except Exception as e:
    sys.exit(f"{sys.argv[2]} {sys.argv[3]}: no fit.json ({e})")
t = f["timings"]
print(f"{sys.argv[2]:9s} {sys.argv[3]:5s} total {t['total_s']:.2f} s ({t['total_s']/t['decode_s']:.0f}x decode)  "
      f"detect {t['detect_s']:.2f} s  medium {t.get('medium_s', 0.0):.2f} s  medium fitted: {f.get('medium') is not None}")
PY
    done
  done
done
