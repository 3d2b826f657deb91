#!/usr/bin/env bash
# The medium fit on the eleven physically based sessions (docs/medium.md, "The medium fit"):
# `workbench solve <fresh copy> --model medium --irradiance <truth's> --holdout 15` on
# datasets/pbr-soap, datasets/pbr-wax, ../shared/data/pbr-jade (its five single-sphere photos)
# and datasets/pbr-seeds/*, printing per session the errors against the truth (σa, σs′ per
# channel; η and the two it combines; α and its |error|/std), the largest |error|/std over σa,
# σs′ and η, the largest share of σa's and σs′'s values the light's and the outlines' errors alone
# give, the residuals over the noise, the held-out sphere's error (medium / CDRF), the
# profiles, the medium fit's time and the whole solve's (fit.json's timings, and over decoding
# the photos).
# Usage: scripts/medium-sessions.sh [path/to/workbench] [scratch dir] [session names…] (the eleven
# by default; the four corners of datasets/pbr-range by name: dense-dark dense-white thin-dark
# thin-white). IRRADIANCE_SCALE=<factor> passes the truth's irradiance times that factor.
set -uo pipefail
cd "$(dirname "$0")/.."
source scripts/lib/pbr-sessions.sh
pbr_args "$@"
for s in "${sessions[@]}"; do
  d="$out/$s"
  rm -f "$d.fit.json"
  copy_session "$s" "$d"
  e=$(python3 -c "import json,sys; print(float(sys.argv[2]) * json.load(open(sys.argv[1]))['irradiance_in_png_units'])" "$d/truth.json" "${IRRADIANCE_SCALE:-1}")
  "$wb" --quiet solve "$d" --model medium --irradiance "$e" --holdout 15 --out "$d.fit.json" >"$d.log" 2>&1
  python3 - "$d.fit.json" "$d/truth.json" "$s" <<'PY'
import json, sys
try:
    f = json.load(open(sys.argv[1]))
except Exception as e:
    sys.exit(f"{sys.argv[3]}: no fit.json ({e})")
t = json.load(open(sys.argv[2]))
m = t["material"]
if "medium" in m:  # ../shared/data/pbr-jade
    sa, ss = m["medium"]["sigma_a_rgb"], m["medium"]["sigma_s_rgb"]
    eta, alpha = m["boundary"]["int_ior"], m["boundary"]["alpha"]
else:
    st, al = m["sigma_t_per_mm"], m["albedo_rgb"]
    sa, ss = [st * (1 - a) for a in al], [st * a for a in al]
    eta, alpha = m["eta"], m["alpha"]
md = f["medium"]
pct = lambda k, tr: [100 * (md[k]["value"][c] / tr[c] - 1) for c in range(3)]
# A std of null (a parameter at its range's edge: no error stated) counts as no measurement.
z = lambda k, tr: [abs(md[k]["value"][c] - tr[c]) / md[k]["std"][c] if md[k]["std"][c] else float("nan") for c in range(3)]
ea, es = pct("sigma_a_per_mm", sa), pct("sigma_s_reduced_per_mm", ss)
de = md["eta"]["value"] - eta
worst = max((v for v in z("sigma_a_per_mm", sa) + z("sigma_s_reduced_per_mm", ss) + [abs(de) / md["eta"]["std"]] if v == v), default=float("nan"))
h = md.get("holdout") or {}
al_std = md.get("alpha_std")
nan = {"value": float("nan"), "std": float("nan")}
src = md.get("eta_sources") or {"joint": nan, "pixels": nan}
def part(k):  # the largest share of σa's and σs′'s values a carried input's error alone gives
    p = md.get(k)
    if not p:
        return "—"
    return f"{max(100 * p[q][c] / md[q]['value'][c] for q in ('sigma_a_per_mm', 'sigma_s_reduced_per_mm') for c in range(3) if p[q][c] is not None):.1f}%"
print(f"{sys.argv[3]:8s} σa {ea[0]:+.1f} {ea[1]:+.1f} {ea[2]:+.1f}%  σs′ {es[0]:+.1f} {es[1]:+.1f} {es[2]:+.1f}%  "
      f"η {md['eta']['value']:.3f}±{md['eta']['std']:.3f} ({de:+.3f}; joint fit's "
      f"{src['joint']['value']:.3f}±{src['joint']['std']:.3f}, pixels' "
      f"{src['pixels']['value']:.3f}±{src['pixels']['std']:.3f})  "
      f"α {md['alpha']:.3f}±{al_std if al_std is not None else float('nan'):.3f} ({alpha}; "
      f"{abs(md['alpha'] - alpha) / al_std if al_std else float('nan'):.2f} std)  "
      f"err/std {worst:.2f}  light's part {part('std_from_light')}  outlines' {part('std_from_outlines')}  res/noise {md['residual_over_noise']:.2f}  "
      f"held-out {100*h.get('medium_rel_rmse', float('nan')):.2f}%/{100*h.get('cdrf_rel_rmse', float('nan')):.2f}%  "
      f"{md['profiles']} profiles {md['seconds']:.1f} s  "
      f"whole solve {f['timings']['total_s']:.2f} s ({f['timings']['total_s'] / f['timings']['decode_s']:.0f}x decoding)")
PY
done
