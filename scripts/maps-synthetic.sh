#!/usr/bin/env bash
# Issue #17's synthetic-truth figure at 256x256: `tests/maps.rs`'s two-material sample (rough
# copper at alpha 0.65 and a red paint, rendered with kulla-conty, 9 flash photos, 1% noise,
# plus a tenth photo lit from the side) fitted back with kulla-conty and with single, the tenth
# photo held out. Prints the maps' errors against the truth and the held-out errors.
# Usage: scripts/maps-synthetic.sh (about a minute on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
BOUNCEFIT_MAPS_SIDE=256 cargo test --release --test maps maps_fits_recover_known_maps -- --nocapture 2>&1 \
  | grep -E 'maps:|test result'
