#!/usr/bin/env bash
# The crosscheck suite: set up the venv, build the release binary, run pytest.
# Extra arguments go to pytest (e.g. `tests/crosscheck/run.sh -k brdf`).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
"$here/setup.sh"
cargo build --release --quiet --manifest-path "$root/Cargo.toml"
target="${CARGO_TARGET_DIR:-$root/target}"
export BOUNCEFIT_BIN="$target/release/bouncefit"
cd "$here"
exec "$here/.venv/bin/python" -m pytest -q -rA "$@"
