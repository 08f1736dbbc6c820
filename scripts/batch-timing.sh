#!/usr/bin/env bash
# Issue #48's batch figure: 12 photo sets (the 3 bundled ones, 8 made by `synth` from the
# copper and aluminium sources at alpha 0.1, 0.2, 0.4, 0.6 with 1% noise, and `copper-flash`
# with a broken manifest) fitted with MODELS (default `single`) by `bouncefit fit`, one set
# after another, then by `python -m bouncefit.batch` with 2 and 1 local workers, then rerun
# (which skips the finished sets). Prints each wall time and checks that the batch's fit files
# are the command line's, timings aside. Needs the release build (`cargo build --release`)
# and the package with its batch extra in PYTHON's environment
# (`pip install './python[batch]'`; default python3).
# Usage: scripts/batch-timing.sh [WORK_FOLDER] [MODELS]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="$(realpath -m "${1:-/tmp/bouncefit-batch-timing}")"
models="${2:-single}"
python="${PYTHON:-python3}"
bin="$root/target/release/bouncefit"
rm -rf "$work" && mkdir -p "$work/sets"
cd "$root"

for name in copper-flash aluminium-pinhole two-materials; do
  cp -r "datasets/$name" "$work/sets/$name"
done
for metal in copper:copper-a03:copper-flash aluminium:aluminium-a05:aluminium-pinhole; do
  IFS=: read -r label material capture <<<"$metal"
  for alpha in 0.1 0.2 0.4 0.6; do
    sed -E "s/\"alpha\": \[[^]]*\]/\"alpha\": [$alpha, $alpha]/" \
      "datasets/sources/$material.material.json" >"$work/$label-$alpha.json"
    "$bin" synth --material "$work/$label-$alpha.json" \
      --capture "datasets/sources/$capture.capture.toml" --noise 0.01 \
      -o "$work/sets/$label-a$alpha" >/dev/null 2>&1
  done
done
cp -r datasets/copper-flash "$work/sets/broken"
sed -i 's/image = "03.exr"/picture = "03.exr"/' "$work/sets/broken/capture.toml"

timed() {
  local t0=$EPOCHREALTIME
  "$@" >/dev/null 2>&1 || true
  awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }'
}

mkdir -p "$work/cli"
sequential() {
  for set in "$work"/sets/*/; do
    "$bin" fit "$set" --models "$models" -o "$work/cli/$(basename "$set").json" --quiet --force || true
  done
}
echo "| run | wall time (s) |"
echo "| --- | --- |"
echo "| \`bouncefit fit\` on each set, one after another | $(timed sequential) |"
echo "| \`python -m bouncefit.batch --workers 2\` | $(timed "$python" -m bouncefit.batch "$work/sets" -o "$work/out2" --models "$models" --workers 2) |"
echo "| the same with \`--workers 1\` | $(timed "$python" -m bouncefit.batch "$work/sets" -o "$work/out1" --models "$models" --workers 1) |"
echo "| the rerun of the 2-worker batch (skips the finished sets) | $(timed "$python" -m bouncefit.batch "$work/sets" -o "$work/out2" --models "$models" --workers 2) |"

"$python" - "$work" <<'PY'
import json, sys
from pathlib import Path
work = Path(sys.argv[1])
def plain(v):
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items() if k != "seconds"}
    if isinstance(v, list):
        return [plain(x) for x in v]
    return v
rows = {r["set"]: r for r in json.loads((work / "out2" / "summary.json").read_text())}
same = 0
for name, row in sorted(rows.items()):
    if row["status"] != "ok":
        print(f"{name}: {row['status']}: {row['error']}")
        continue
    # The command line's fit file names its set by the path it was given.
    cli = plain(json.loads((work / "cli" / f"{name}.json").read_text()))
    batch = plain(json.loads((work / "out2" / "fits" / f"{name}.json").read_text()))
    cli.pop("capture"); batch.pop("capture")
    assert cli == batch, name
    same += 1
print(f"{same} of {len(rows)} fit files equal to the command line's (timings and set path aside)")
PY
