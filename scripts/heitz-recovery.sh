#!/usr/bin/env bash
# Recovery of known roughness and F0 from photos rendered by `heitz` (issue #4's table):
# copper and gold at alpha 0.2, 0.5 and 0.8, nine 32x32 flash photos (the bundled copper-flash
# geometry), references rendered with 64 walks per pixel; each set is fitted with `single`,
# `kulla-conty` and `bitterli` (the position-free estimator of heitz's model: same value).
# The rough sets are fitted with 16 walks per pixel: at 4, the pair loss's own noise is as
# large as the signal of alpha near 0.8 (see docs/reference.md, "stochastic models").
# Prints one line per fit: model, metal, alpha, alpha error, largest F0 error, seconds.
# Takes about 15 minutes on 2 cores. Usage: scripts/heitz-recovery.sh [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-/tmp/bouncefit-heitz-recovery}"
mkdir -p "$out"
cargo build --release --quiet
bf=target/release/bouncefit

source scripts/lib/flash-sets.sh
small_flash_capture "$out/capture.toml"

for metal in copper gold; do
  for alpha in 0.2 0.5 0.8; do
    set="$out/$metal-$alpha"
    echo "{\"model\": \"heitz\", \"alpha\": [$alpha, $alpha], \"fresnel\": {\"kind\": \"schlick\", \"f0\": [${METAL_F0[$metal]}]}}" \
      > "$set.material.json"
    "$bf" synth --material "$set.material.json" --capture "$out/capture.toml" -o "$set" \
      --pixel-samples 64 --seed 7 --force > /dev/null
    walks=4
    [ "$alpha" = 0.8 ] && walks=16
    for model in single kulla-conty bitterli; do
      fit="$out/$metal-$alpha.$model.json"
      "$bf" fit "$set" --models "$model" --pixel-samples "$walks" -o "$fit" --force --quiet > /dev/null
      python3 - "$fit" "$alpha" "${METAL_F0[$metal]}" "$metal" <<'PY'
import json, sys
fit = json.load(open(sys.argv[1]))
alpha, truth, metal = float(sys.argv[2]), [float(v) for v in sys.argv[3].split(",")], sys.argv[4]
error = (fit["alpha"][0] - alpha) / alpha
f0 = max(abs(a - b) for a, b in zip(fit["f0"], truth))
print(f"{fit['model']:12s} {metal} alpha {alpha}: fitted {fit['alpha'][0]:.4f} ({100 * error:+.2f}%), "
      f"F0 error {f0:.4f}, loss {fit['loss']:.4e}, {fit['seconds']:.0f} s")
PY
    done
  done
done
