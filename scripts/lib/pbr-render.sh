# For the scripts that render the committed physically based sessions (scripts/pbr-seeds.sh,
# scripts/pbr-range.sh): source it from the repository root.
# render_sessions <workbench> <out dir> <row>…: each row "name σt albedo(r,g,b) η α azimuth
# elevation seed material" rendered by `workbench synth pbr` into <out dir>/<name> (640×480,
# fx 800, the sphere 500 mm away, 1024 samples a pixel).
render_sessions() {
  local wb=$1 out=$2
  shift 2
  mkdir -p "$out"
  local row name sigma_t albedo eta alpha az el seed material
  for row in "$@"; do
    read -r name sigma_t albedo eta alpha az el seed material <<<"$row"
    "$wb" --quiet synth pbr --out "$out/$name" --size 640x480 --fx 800 --distance 500 \
      --spp 1024 --sigma-t "$sigma_t" --albedo "$albedo" --eta "$eta" --alpha "$alpha" \
      --light-azimuth "$az" --light-elevation "$el" --material "$material" --seed "$seed"
    echo "$name rendered"
  done
}
