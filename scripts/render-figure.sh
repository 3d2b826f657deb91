#!/usr/bin/env bash
# The README's render figure (docs/render-cdrf-vs-lambert.png): the Stanford bunny and a 20 mm
# sphere rendered with the demo fit's CDRF (top) and with plain Lambert shading of the same
# material (bottom), light as fitted (azimuth 70°, elevation 20°). Needs scripts/demo.sh run
# first (datasets/demo/fit.json), ../shared/data/meshes, and Python 3 with numpy and OpenCV
# (for the sphere mesh and the composition only).
set -euo pipefail
cd "$(dirname "$0")/.."
wb=target/release/workbench
fit=datasets/demo/fit.json
bunny=../shared/data/meshes/stanford-bunny.obj
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
py=/usr/bin/python3
"$py" - "$tmp/sphere.obj" <<'PY'
import sys, numpy as np
# A UV sphere of radius 20 mm: 256 × 128 quads, as triangles.
nu, nv, r = 256, 128, 20.0
lines = []
for j in range(nv + 1):
    th = np.pi * j / nv
    for i in range(nu):
        ph = 2 * np.pi * i / nu
        lines.append(f"v {r*np.sin(th)*np.cos(ph):.6f} {r*np.cos(th):.6f} {r*np.sin(th)*np.sin(ph):.6f}")
vid = lambda i, j: j * nu + (i % nu) + 1
for j in range(nv):
    for i in range(nu):
        a, b, c, d = vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)
        if j > 0: lines.append(f"f {a} {b} {c}")
        if j < nv - 1: lines.append(f"f {a} {c} {d}")
open(sys.argv[1], "w").write("\n".join(lines) + "\n")
PY
for s in cdrf lambert; do
  "$wb" render "$bunny" --unit m --fit "$fit" --resolution 720x540 --shading "$s" --out "$tmp/bunny-$s.png"
  "$wb" render "$tmp/sphere.obj" --fit "$fit" --resolution 400x540 --distance 1.6 --shading "$s" --out "$tmp/sphere-$s.png"
done
"$py" - "$tmp" docs/render-cdrf-vs-lambert.png <<'PY'
import sys, cv2, numpy as np
d, out = sys.argv[1], sys.argv[2]
rows = []
for s, label in (("cdrf", "measured CDRF (demo fit)"), ("lambert", "Lambert, same material")):
    row = np.hstack([cv2.imread(f"{d}/bunny-{s}.png"), cv2.imread(f"{d}/sphere-{s}.png")])
    cv2.putText(row, label, (16, 36), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (235, 235, 235), 2, cv2.LINE_AA)
    rows.append(row)
cv2.imwrite(out, np.vstack(rows))
PY
echo "wrote docs/render-cdrf-vs-lambert.png"
