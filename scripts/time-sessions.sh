#!/usr/bin/env bash
# End-to-end time against decoding on fresh copies (docs/measurements/speed.md, "End to end on
# fresh folders"): solve --joint on the demo, pbr-wax, pbr-soap, pbr-jade and (with DILIGENT=1)
# DiLiGenT's ball as a per-image-light session, printing fit.json's timings
# and, where the session has a truth.json, the light's and η's errors in their stated std.
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
           "images": [{"file": n, "light_intensity": i, "spheres": [{"radius_mm": 20.0}]}
                      for n, i in zip(names, ints)]},
          open(os.path.join(d, "session.json"), "w"))
PY
      ;;
  esac
  rm -rf "$d/detections.json" "$d/fit.json" "$d/overlays"
  "$wb" --quiet solve --joint "$d" --out "$d.fit.json" >"$d.log" 2>&1
  python3 - "$d.fit.json" "$s" "$d/truth.json" <<'PY'
import json, math, os, sys
try:
    f = json.load(open(sys.argv[1]))
except Exception as e:
    sys.exit(f"{sys.argv[2]}: no fit.json ({e})")
t = f["timings"]
d = t["decode_s"]
print(f"{sys.argv[2]:9s} decode {d:.3f} s  detect {t['detect_s']:.2f} s ({t['detect_s']/d:.0f}x)  "
      f"solve {t['solve_s']:.2f} s  jackknife {t['jackknife_s']:.2f} s  total {t['total_s']:.2f} s ({t['total_s']/d:.0f}x)")
# Against the truth where the session has one: the light's error and η's, in their stated std.
if os.path.exists(sys.argv[3]):
    tr = json.load(open(sys.argv[3]))
    if "light_direction" in tr:  # workbench synth session
        light, eta = tr["light_direction"], tr["eta"]
    else:  # workbench synth pbr, ../shared/data/pbr-jade
        light = tr["light"]["direction_to_light_camera_frame"]
        m = tr["material"]
        eta = m.get("eta") or m["boundary"]["int_ior"]
    a, b = f["light_direction"], light
    c = sum(x * y for x, y in zip(a, b)) / math.sqrt(sum(x * x for x in a) * sum(y * y for y in b))
    err = math.degrees(math.acos(max(-1.0, min(1.0, c))))
    s = f["std"]
    print(f"{'':9s} light {err:.4f}° off ({err / s['light_deg']:.2f} of its std {s['light_deg']:.4f}°)  "
          f"η {f['eta']:.4f} ± {s['eta']:.4f} against {eta} ({(f['eta'] - eta) / s['eta']:+.2f} std)")
PY
done
