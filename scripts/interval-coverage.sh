#!/usr/bin/env bash
# Issue #16 item 4's coverage figure: the share of synthetic sets whose `fit --mcmc` 95% interval
# holds the truth, for each `--model-error` method, over SETS seeded sets (default 50) for each of
# five mismatches (see tests/crosscheck/interval_coverage.py and docs/intervals.md).
# Uses the crosscheck suite's virtual environment (Mitsuba's EXR reader) and the release binary.
# Takes about 30 minutes on 2 cores at 50 sets. Usage: scripts/interval-coverage.sh [SETS] [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
tests/crosscheck/setup.sh > /dev/null
cargo build --release --quiet
exec tests/crosscheck/.venv/bin/python tests/crosscheck/interval_coverage.py "$@"
