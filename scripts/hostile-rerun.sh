#!/usr/bin/env bash
# Issue 33's hostile cases rerun through the binary (docs/measurements/solve.md, "Numerical
# stress and hostile input"): each must end within 60 s with exit 0 or one line on stderr and a
# non-zero exit — no panic (exit 101), no hang, no special file replaced, no table or image of
# inf/NaN written with exit 0. Special files are made in a scratch folder, never the system's /dev.
# Prints one line per case and a summary; exits 1 when a case fails.
# Usage: scripts/hostile-rerun.sh [path/to/workbench] [scratch dir]   (needs python3, mkfifo)
set -uo pipefail
wb=$(realpath "${1:-target/release/workbench}")
t=$(mkdir -p "${2:-$(mktemp -d)}" && realpath "${2:-$(mktemp -d)}")
fails=0
runs=0

# case NAME EXPECT CMD...: EXPECT is ok (exit 0), refused (non-zero, one stderr line) or either.
case_() {
  local name=$1 expect=$2
  shift 2
  runs=$((runs + 1))
  local err code
  err=$(timeout 60 "$@" 2>&1 >/dev/null)
  code=$?
  local lines
  lines=$(printf '%s' "$err" | grep -c . || true)
  local verdict=pass
  if [ "$code" = 124 ]; then verdict="FAIL (hang past 60 s)"
  elif [ "$code" = 101 ] || printf '%s' "$err" | grep -q panicked; then verdict="FAIL (panic)"
  elif [ "$expect" = ok ] && [ "$code" != 0 ] && [ "$code" != 3 ]; then verdict="FAIL (exit $code)"
  elif [ "$expect" = refused ] && { [ "$code" = 0 ] || [ "$lines" != 1 ]; }; then
    verdict="FAIL (exit $code, $lines lines)"
  elif [ "$expect" = either ] && [ "$code" != 0 ] && [ "$code" != 3 ] && [ "$lines" != 1 ]; then
    verdict="FAIL (exit $code, $lines lines)"
  fi
  [ "$verdict" = pass ] || fails=$((fails + 1))
  printf '%-44s exit %3s  %s  %s\n' "$name" "$code" "$verdict" "$(printf '%s' "$err" | head -c 150 | tr '\n' ' ')"
}

# not_replaced PATH KIND: the special file is still what it was.
not_replaced() {
  runs=$((runs + 1))
  local still=no
  case $2 in
    fifo) [ -p "$1" ] && still=yes ;;
    link) [ -L "$1" ] && still=yes ;;
  esac
  if [ "$still" = yes ]; then
    printf '%-44s %s\n' "  $1 still a $2" pass
  else
    printf '%-44s %s\n' "  $1 still a $2" "FAIL (replaced)"
    fails=$((fails + 1))
  fi
}

# finite FILE: a written table or image holds no inf or NaN.
finite() {
  runs=$((runs + 1))
  [ -f "$1" ] || return 0
  if python3 - "$1" <<'PY'
import json, math, sys
p = sys.argv[1]
if p.endswith(".json"):
    bad = []
    def walk(v):
        if isinstance(v, float) and not math.isfinite(v):
            bad.append(v)
        elif isinstance(v, dict):
            [walk(x) for x in v.values()]
        elif isinstance(v, list):
            [walk(x) for x in v]
    walk(json.load(open(p)))
    sys.exit(1 if bad else 0)
PY
  then printf '%-44s %s\n' "  $1 finite" pass
  else printf '%-44s %s\n' "  $1 finite" "FAIL (inf or NaN)"; fails=$((fails + 1)); fi
}

"$wb" --quiet synth session --out "$t/s" --size 320x240 --fx 350 --radii 30,20,12 >/dev/null
"$wb" --quiet solve "$t/s" >/dev/null || true
fit="$t/s/fit.json"
mkfifo "$t/fifo.json" "$t/fifo.png" "$t/fifo.obj"
echo keep >"$t/target.json"
ln -sf "$t/target.json" "$t/link.json"

# 1. --out on special files.
case_ "solve --out FIFO" refused "$wb" --quiet solve "$t/s" --out "$t/fifo.json"
case_ "solve --out link" refused "$wb" --quiet solve "$t/s" --out "$t/link.json"
case_ "plot --out FIFO" refused "$wb" --quiet plot "$fit" --out "$t/fifo.json"
case_ "calibrate --out link" either "$wb" --quiet calibrate "$t/s" --out "$t/link.json"
not_replaced "$t/fifo.json" fifo
not_replaced "$t/link.json" link
# 2. fits whose errors are not finite.
case_ "solve --start-sigma0 1e300" ok "$wb" --quiet solve "$t/s" --start-sigma0 1e300 --out "$t/f1.json"
case_ "plot of that fit" ok "$wb" --quiet plot "$t/f1.json" --out "$t/p1"
case_ "view of that fit" ok "$wb" --quiet view "$t/f1.json" --out "$t/v1"
case_ "lut of that fit" either "$wb" --quiet lut "$t/f1.json" --out "$t/l1"
finite "$t/l1.json"
case_ "solve --start-light 0,-90" ok "$wb" --quiet solve "$t/s" --start-light 0,-90 --out "$t/f2.json"
case_ "plot of that fit" ok "$wb" --quiet plot "$t/f2.json" --out "$t/p2"
case_ "solve --irradiance 1e300" ok "$wb" --quiet solve "$t/s" --irradiance 1e300 --out "$t/f3.json"
case_ "lut of that fit" either "$wb" --quiet lut "$t/f3.json" --out "$t/l3"
finite "$t/l3.json"
# 3 and 4. hangs and silent wrong output from fit.json values and options.
python3 - "$fit" "$t" <<'PY'
import json, sys
fit, t = json.load(open(sys.argv[1])), sys.argv[2]
def param(f, name, x):
    for p in f["parameters"]:
        if p["name"] == name:
            p["value"] = x
for name, edit in [("curv1e4", ("albedo_curvature", 1e4)), ("curv1e6", ("albedo_curvature", 1e6)),
                   ("neg", ("sigma0_r", -4.0))]:
    f = json.loads(json.dumps(fit))
    param(f, *edit)
    if edit[0] == "albedo_curvature":
        f["albedo_curvature"] = edit[1]
    if edit[0] == "sigma0_r":
        f["sigma0_mm"][0] = edit[1]
    json.dump(f, open(f"{t}/{name}.json", "w"))
f = json.loads(json.dumps(fit))
f["rmse"]["spheres"][0]["radius_mm"] = 1e-9
json.dump(f, open(f"{t}/tiny.json", "w"))
f = json.loads(json.dumps(fit))
f["sigma0_mm"][0] = 9.0
json.dump(f, open(f"{t}/edited.json", "w"))
PY
for f in curv1e4 curv1e6 neg tiny edited; do
  case_ "plot of $f" refused "$wb" --quiet plot "$t/$f.json" --out "$t/p-$f"
  case_ "lut of $f" refused "$wb" --quiet lut "$t/$f.json" --out "$t/l-$f"
done
case_ "lut --kappa-max 1e300" refused "$wb" --quiet lut "$fit" --out "$t/lk" --kappa-max 1e300
case_ "lut --tolerance 1e-6" refused "$wb" --quiet lut "$fit" --out "$t/lt" --tolerance 1e-6
case_ "lut --preset unity --size 8193x8193" refused "$wb" --quiet lut "$fit" --preset unity --size 8193x8193 --out "$t/lu"
case_ "lut --preset unity --size 2049x2049" ok "$wb" --quiet lut "$fit" --preset unity --size 2049x2049 --out "$t/lu2"
printf 'o 0 0 0\nv 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n' >"$t/tet.obj"
case_ "render --object-size 1e300" refused "$wb" --quiet render "$t/tet.obj" --fit "$fit" --out "$t/r1.png" --object-size 1e300
case_ "render --object-size 1e-300" refused "$wb" --quiet render "$t/tet.obj" --fit "$fit" --out "$t/r2.png" --object-size 1e-300
case_ "render FIFO mesh" refused "$wb" --quiet render "$t/fifo.obj" --fit "$fit" --out "$t/r3.png"
case_ "render /dev/zero as a mesh" refused "$wb" --quiet render /dev/zero --fit "$fit" --out "$t/r4.png"
case_ "render --resolution 16384x16384" refused "$wb" --quiet render "$t/tet.obj" --fit "$fit" --out "$t/r5.png" --resolution 16384x16384
cp -r "$t/s" "$t/sf" && rm "$t/sf/r20.png" && mkfifo "$t/sf/r20.png"
case_ "check with a FIFO photo" refused "$wb" --quiet check "$t/sf"
# 6, 8. synth: sizes beyond the readers'.
case_ "synth session --size 20000x20000" refused "$wb" --quiet synth session --out "$t/big" --size 20000x20000
# 9. an unwritable stderr.
runs=$((runs + 1))
timeout 60 "$wb" --quiet solve "$t/none" 2>/dev/full
code=$?
if [ "$code" = 1 ]; then echo "solve 2>/dev/full                            exit 1  pass"
else echo "solve 2>/dev/full                            exit $code  FAIL"; fails=$((fails + 1)); fi
# 10, 11, 13, 14.
cp -r "$t/s" "$t/cut" && head -c 3000 "$t/s/r20.png" >"$t/cut/r20.png"
case_ "check on a PNG cut short" refused "$wb" --quiet check "$t/cut"
cp -r "$t/s" "$t/twice" && python3 - "$t/twice/session.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["images"].append(dict(s["images"][0], file="./" + s["images"][0]["file"]))
json.dump(s, open(sys.argv[1], "w"))
PY
case_ "a photo listed twice" refused "$wb" --quiet solve "$t/twice"
cp -r "$t/s" "$t/$(printf 'caf\xe9')"
case_ "a non-UTF-8 session folder" refused "$wb" --quiet solve "$t/$(printf 'caf\xe9')"
case_ "--start-light 0,1000" refused "$wb" --quiet solve "$t/s" --start-light 0,1000
python3 - "$t/s/session.json" "$t/huge.json" <<'PY'
import sys
s = open(sys.argv[1]).read()
open(sys.argv[2], "w").write(s.replace('"schema"', '"' + "x" * 10_000_000 + '": 1, "schema"', 1))
PY
mkdir -p "$t/huge" && cp "$t/huge.json" "$t/huge/session.json"
case_ "a 10 MB field name" refused "$wb" --quiet solve "$t/huge"
echo "$runs checks, $fails failed"
[ "$fails" = 0 ]
