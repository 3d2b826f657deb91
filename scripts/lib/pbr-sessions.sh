# The eleven physically based sessions of docs/medium.md, for scripts that measure on them
# (scripts/medium-sessions.sh, scripts/outline-errors.sh): source it from the repository root.
# PBR_SESSIONS: their names. copy_session <name> <dir>: a fresh copy of one into <dir>
# (datasets/pbr-soap, datasets/pbr-wax, ../shared/data/pbr-jade with its five single-sphere
# photos, datasets/pbr-seeds/*; also the four corners of datasets/pbr-range/ by name), without
# what a run leaves (detections.json, fit.json, overlays).
# pbr_args [path/to/workbench] [scratch dir] [session names…]: the scripts' arguments, as $wb
# (absolute), $out (made; a new temporary folder if not given) and $sessions (all of
# PBR_SESSIONS if none is named).
PBR_SESSIONS=(pbr-soap pbr-wax pbr-jade soap-2 soap-5 soap-8 wax-1 wax-4 wax-7 jade-3 jade-6)

copy_session() {
  local s=$1 d=$2
  rm -rf "$d"
  case $s in
    pbr-soap | pbr-wax) cp -r "datasets/$s" "$d" ;;
    pbr-jade)
      cp -r ../shared/data/pbr-jade "$d"
      python3 - "$d/session.json" <<'PY'
import json, sys
p = sys.argv[1]
s = json.load(open(p))
s["images"] = [i for i in s["images"] if i["file"] != "row.png"]
json.dump(s, open(p, "w"), indent=1)
PY
      ;;
    dense-dark | dense-white | thin-dark | thin-white) cp -r "datasets/pbr-range/$s" "$d" ;;
    *) cp -r "datasets/pbr-seeds/$s" "$d" ;;
  esac
  rm -rf "$d/detections.json" "$d/fit.json" "$d/overlays"
}

pbr_args() {
  wb=$(realpath "${1:-target/release/workbench}")
  out=${2:-$(mktemp -d)}
  shift 2 2>/dev/null || shift $#
  mkdir -p "$out"
  sessions=("$@")
  [ ${#sessions[@]} -eq 0 ] && sessions=("${PBR_SESSIONS[@]}")
}
