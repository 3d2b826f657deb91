#!/usr/bin/env bash
# The detected outlines against the truth on the eleven physically based sessions
# (docs/measurements/detection.md, "Each sector weighted by its rim's contrast"):
# `workbench detect <fresh copy>` on datasets/pbr-soap, datasets/pbr-wax, ../shared/data/pbr-jade
# (its five single-sphere photos) and datasets/pbr-seeds/*, then per sphere its outline's centre
# (x, y) and radius against truth.json's sphere in pixels (the cone's axis and half-angle,
# through fx), each over its stated std (`silhouette_std_px`); per session the mean errors; over
# all spheres the RMS of the sessions' means (what a session's outlines share), the RMS of each
# sphere's error about its session's mean, the RMS of error/std, and the mean radius error per
# radius.
# `--model medium` detects as `solve --model medium` does and measures the outlines drawn for the
# medium (`medium_outline`: the rim weighed by its contrast too); without it, the outlines every
# model's detection draws (`outline`), which the highlights, the light and the CDRF use.
# Usage: scripts/outline-errors.sh [--model cdrf|medium] [path/to/workbench] [scratch dir]
#        [session names…]
set -uo pipefail
cd "$(dirname "$0")/.."
model=cdrf
if [ "${1:-}" = --model ]; then
  model=$2
  shift 2
fi
source scripts/lib/pbr-sessions.sh
pbr_args "$@"
for s in "${sessions[@]}"; do
  d="$out/$s"
  copy_session "$s" "$d"
  "$wb" --quiet detect "$d" --model "$model" >"$d.log" 2>&1 || echo "$s: detect failed (see $d.log)"
done
python3 - "$model" "$out" "${sessions[@]}" <<'PY'
import json, math, sys
from collections import defaultdict
model, out, sessions = sys.argv[1], sys.argv[2], sys.argv[3:]
rows = []  # (session, file, radius_mm, [dx, dy, dr], [std])
for s in sessions:
    d = f"{out}/{s}"
    try:
        det = json.load(open(f"{d}/detections.json"))
    except OSError:
        continue
    t = json.load(open(f"{d}/truth.json"))
    fx = json.load(open(f"{d}/intrinsics.json"))["fx"]
    for im in det["images"]:
        tr = next((i for i in t["images"] if i["file"] == im["file"]), None)
        if tr is None:
            continue
        c = tr["spheres"][0]["centre_mm"] if "spheres" in tr else tr["centre_mm"]
        sp = im["spheres"][0]
        # The medium's outline where it was drawn (`--model medium`), else the one the CDRF uses.
        drawn = sp.get("medium_outline") if model == "medium" else None
        outline = drawn["outline"] if drawn else sp["outline"]
        std = drawn["std_px"] if drawn else sp["silhouette_std_px"]
        n = math.sqrt(sum(x * x for x in c))
        axis, half = outline["axis"], math.radians(outline["half_angle_deg"])
        err = [
            (axis[0] / axis[2] - c[0] / c[2]) * fx,
            (axis[1] / axis[2] - c[1] / c[2]) * fx,
            (math.tan(half) - math.tan(math.asin(sp["radius_mm"] / n))) * fx,
        ]
        rows.append((s, im["file"], sp["radius_mm"], err, std))
rms = lambda v: math.sqrt(sum(x * x for x in v) / len(v)) if v else float("nan")
by = defaultdict(list)
for r in rows:
    by[r[0]].append(r)
print("session    mean error x, y, radius (px)")
for s, rs in by.items():
    m = [sum(r[3][k] for r in rs) / len(rs) for k in range(3)]
    print(f"{s:10s} {m[0]:+.3f} {m[1]:+.3f} {m[2]:+.3f}")
for k, name in enumerate(["centre x", "centre y", "radius"]):
    means = {s: sum(r[3][k] for r in rs) / len(rs) for s, rs in by.items()}
    within = [r[3][k] - means[r[0]] for r in rows]
    z = [r[3][k] / r[4][k] for r in rows]
    print(f"{name:8s}: {len(rows)} spheres, sessions' means RMS {rms(list(means.values())):.3f} px, "
          f"about them {rms(within):.3f} px, error/std RMS {rms(z):.2f}")
per_radius = defaultdict(list)
for r in rows:
    per_radius[r[2]].append(r[3][2])
print("radius error by sphere radius: " + ", ".join(
    f"{rad:g} mm {sum(v) / len(v):+.3f} px" for rad, v in sorted(per_radius.items(), reverse=True)))
PY
