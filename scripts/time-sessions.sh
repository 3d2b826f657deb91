#!/usr/bin/env bash
# End-to-end time against decoding on fresh copies (docs/measurements/speed.md, "End to end on
# fresh folders"): solve --joint on the demo, pbr-wax, pbr-soap, pbr-jade and (with DILIGENT=1)
# DiLiGenT's ball as a per-image-light session, printing fit.json's timings.
# Usage: scripts/time-sessions.sh [path/to/workbench] [scratch dir]   (needs python3, ../shared)
set -uo pipefail
cd "$(dirname "$0")/.."
wb=$(realpath "${1:-target/release/workbench}")
out=${2:-$(mktemp -d)}
mkdir -p "$out"
shared=$(realpath ../shared/data)
sessions=(demo pbr-wax pbr-soap jade)
[ "${DILIGENT:-0}" = 1 ] && sessions+=(diligent)
for s in "${sessions[@]}"; do
  d="$out/$s"
  rm -rf "$d" "$d.fit.json"
  case $s in
    demo)
      cp -r datasets/demo "$d"
      cp calib/demo/intrinsics.json "$d/intrinsics.json"
      sed -i 's#"../../calib/demo/intrinsics.json"#"intrinsics.json"#' "$d/session.json" ;;
    pbr-wax | pbr-soap) cp -r "datasets/$s" "$d" ;;
    jade) cp -r "$shared/pbr-jade" "$d" ;;
    diligent)
      python3 - "$shared/diligent-ball" "$d" <<'PY'
import json, os, sys
ball, d = sys.argv[1], sys.argv[2]
os.makedirs(d)
lines = lambda f: [l.split() for l in open(os.path.join(ball, f)) if l.strip()]
names = [l[0] for l in lines("filenames.txt")]
ints = [[float(t) for t in l] for l in lines("light_intensities.txt")]
for n in names:
    os.symlink(os.path.join(ball, n), os.path.join(d, n))
json.dump({"schema": "workbench.session/1", "light": "per-image",
           "images": [{"file": n, "exposure": sum(i) / 3, "spheres": [{"radius_mm": 20.0}]}
                      for n, i in zip(names, ints)]},
          open(os.path.join(d, "session.json"), "w"))
PY
      ;;
  esac
  rm -rf "$d/detections.json" "$d/fit.json" "$d/overlays"
  "$wb" --quiet solve --joint "$d" --out "$d.fit.json" >"$d.log" 2>&1
  python3 - "$d.fit.json" "$s" <<'PY'
import json, sys
try:
    t = json.load(open(sys.argv[1]))["timings"]
except Exception as e:
    sys.exit(f"{sys.argv[2]}: no fit.json ({e})")
d = t["decode_s"]
print(f"{sys.argv[2]:9s} decode {d:.3f} s  detect {t['detect_s']:.2f} s ({t['detect_s']/d:.0f}x)  "
      f"solve {t['solve_s']:.2f} s  jackknife {t['jackknife_s']:.2f} s  total {t['total_s']:.2f} s ({t['total_s']/d:.0f}x)")
PY
done
