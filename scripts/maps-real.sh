#!/usr/bin/env bash
# Issue #17's real-capture figure: material maps of the three real phone-flash sets in
# ../shared/data/real (read from there, never copied), fitted on 8 photos at 256x256 with each
# analytic model, predicting the 9th (photo 8). Prints one line per fit: set, model, held-out
# relative RMSE over linear unclipped pixels, the naive baseline (the mean of the 8 training
# photos), their ratio, the chosen number of bases and roughness floor, whether the maps have
# normals (--normals, or --normals=auto's choice), and the fit's seconds.
# Usage: scripts/maps-real.sh [OUT_DIR] [MODELS] [EXTRA FIT OPTIONS...]
#   e.g. scripts/maps-real.sh /tmp/maps-real single,kulla-conty --normals
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-/tmp/bouncefit-maps-real}"
models="${2:-single,kulla-conty}"
shift $(( $# > 2 ? 2 : $# ))
real=../shared/data/real
if [ ! -d "$real" ]; then
  echo "no real captures at $real (they live in ../shared, beside the project)" >&2
  exit 0
fi
mkdir -p "$out"
cargo build --release --quiet
bf=target/release/bouncefit
printf '%-16s %-12s %9s %9s %6s %5s %6s %7s %7s\n' set model held-out baseline ratio bases floor normals seconds
for set in yellow_box real_cards-blue bath_tile; do
  depth=0
  case $set in yellow_box | bath_tile) depth=0.1 ;; esac
  for model in ${models//,/ }; do
    fit="$out/$set-$model.json"
    "$bf" fit "$real/$set" --maps --models "$model" --holdout-photo 8 --depth "$depth" \
      -o "$fit" --force --quiet "$@" > /dev/null
    python3 - "$set" "$model" "$fit" <<'PY'
import json, sys
s, m, path = sys.argv[1:4]
f = json.load(open(path))
h = f["holdout"]
print(f'{s:<16} {m:<12} {h["relative_error"]:9.4f} {h["mean_photo_error"]:9.4f} '
      f'{h["relative_error"] / h["mean_photo_error"]:6.3f} {len(f["maps_fit"]["bases"]):5d} '
      f'{f["maps_fit"]["roughness_floor"] or 0:6.3f} {"yes" if f["maps_fit"]["normals"] else "no":>7} '
      f'{f["maps_fit"]["seconds"]:7.1f}')
PY
  done
done
