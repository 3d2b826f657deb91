#!/usr/bin/env bash
# The fuzz targets' seed corpora (fuzz/corpus/<target>/, ignored by git), regenerated from the
# demo's outputs and the bundled physically based session, as docs/measurements/solve.md
# ("Fuzzing") describes them. Run scripts/demo.sh first. Then, by hand (nightly toolchain):
#   cargo +nightly fuzz run -O <target> fuzz/corpus/<target> -- -max_total_time=90 -rss_limit_mb=2048
set -euo pipefail
cd "$(dirname "$0")/.."
wb=target/release/workbench
if [ ! -x "$wb" ] || [ ! -f datasets/demo/fit.json ] || [ ! -f calib/demo/intrinsics.json ]; then
  echo "fuzz-corpus: run scripts/demo.sh first (needs $wb, datasets/demo/fit.json, calib/demo/intrinsics.json)" >&2
  exit 1
fi
c=fuzz/corpus
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
rm -rf "$c"
mkdir -p "$c"/{session_json,fit_json,image_load,detections_json,intrinsics_json,mesh}

# JSON: the demo's and pbr-wax's session, detections and intrinsics; the demo's fit.
cp -r datasets/pbr-wax "$tmp/wax"
rm -f "$tmp/wax/detections.json" "$tmp/wax/fit.json"
"$wb" --quiet detect "$tmp/wax" >/dev/null
cp datasets/demo/session.json "$c/session_json/demo.json"
cp datasets/pbr-wax/session.json "$c/session_json/pbr-wax.json"
cp datasets/demo/fit.json "$c/fit_json/demo.json"
cp datasets/demo/detections.json "$c/detections_json/demo.json"
cp "$tmp/wax/detections.json" "$c/detections_json/pbr-wax.json"
cp calib/demo/intrinsics.json "$c/intrinsics_json/demo.json"
cp datasets/pbr-wax/intrinsics.json "$c/intrinsics_json/pbr-wax.json"
# Issue 33's holes as seeds: a failed fit (standard errors null), values at the extremes, and a
# session listing one photo twice.
"$wb" --quiet synth session --out "$tmp/small" --size 320x240 --fx 350 --radii 30,20,12 >/dev/null
"$wb" --quiet solve "$tmp/small" --start-sigma0 1e300 --out "$c/fit_json/failed.json" >/dev/null || true
python3 - "$c" <<'PY'
import json, sys
c = sys.argv[1]
fit = json.load(open(f"{c}/fit_json/demo.json"))
for name, edit in [("curvature", ("albedo_curvature", 1e4)), ("negative", ("sigma0_r", -4.0))]:
    f = json.loads(json.dumps(fit))
    for p in f["parameters"]:
        if p["name"] == edit[0]:
            p["value"] = edit[1]
    f["rmse"]["spheres"][0]["radius_mm"] = 1e-9
    json.dump(f, open(f"{c}/fit_json/{name}.json", "w"))
s = json.load(open(f"{c}/session_json/demo.json"))
s["images"].append(dict(s["images"][0], file="./" + s["images"][0]["file"]))
json.dump(s, open(f"{c}/session_json/twice.json", "w"))
PY

# Images: a 16-bit PNG (the demo's), two JPEGs with EXIF (a small synthetic session) and an 8-bit
# TIFF (written here, baseline and uncompressed).
cp datasets/demo/r15.png "$c/image_load/demo-r15.png"
"$wb" --quiet synth session --out "$tmp/jpeg" --size 160x120 --radii 30,15 --format jpeg >/dev/null
n=0
for f in "$tmp"/jpeg/*.jpg; do
  n=$((n + 1))
  cp "$f" "$c/image_load/synth-$n.jpg"
  [ "$n" = 2 ] && break
done
python3 - "$c/image_load/grey.tif" <<'PY'
import struct, sys
w, h = 8, 6
pixels = bytes((x * 30 + y * 10) % 256 for y in range(h) for x in range(w) for _ in range(3))
entries = [  # tag, type (3 SHORT, 4 LONG), count, value
    (256, 3, 1, w), (257, 3, 1, h), (258, 3, 3, None), (259, 3, 1, 1), (262, 3, 1, 2),
    (273, 4, 1, None), (277, 3, 1, 3), (278, 3, 1, h), (279, 4, 1, len(pixels)),
]
ifd_at = 8
bits_at = ifd_at + 2 + 12 * len(entries) + 4
data_at = bits_at + 6
out = bytearray(b"II*\x00" + struct.pack("<I", ifd_at))
out += struct.pack("<H", len(entries))
for tag, typ, count, value in entries:
    if tag == 258:
        out += struct.pack("<HHII", tag, typ, count, bits_at)
    elif tag == 273:
        out += struct.pack("<HHII", tag, typ, count, data_at)
    elif typ == 3:
        out += struct.pack("<HHIHH", tag, typ, count, value, 0)
    else:
        out += struct.pack("<HHII", tag, typ, count, value)
out += struct.pack("<I", 0) + struct.pack("<HHH", 8, 8, 8) + pixels
open(sys.argv[1], "wb").write(out)
PY

# Meshes: a tetrahedron as OBJ and as ASCII PLY.
cat >"$c/mesh/tetrahedron.obj" <<'OBJ'
v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
f 1 3 2
f 1 2 4
f 1 4 3
f 2 3 4
OBJ
cat >"$c/mesh/tetrahedron.ply" <<'PLY'
ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
element face 4
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
0 0 1
3 0 2 1
3 0 1 3
3 0 3 2
3 1 2 3
PLY
for t in "$c"/*; do echo "$(basename "$t"): $(ls "$t" | wc -l) files"; done
