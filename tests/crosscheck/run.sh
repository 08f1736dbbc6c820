#!/usr/bin/env bash
# The crosscheck suite: set up the venv, build the binary, run pytest; then the Python
# package's tests (python/tests/run.sh).
# Extra arguments go to pytest (e.g. `tests/crosscheck/run.sh -k brdf`).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
"$here/setup.sh"
# The binary of the test profile (Cargo.toml: opt-level 2, debug assertions on), which the
# README's `cargo test` has just built for the integration tests: this is then a no-op, where a
# release build compiled every crate a second time (about 10 of CI's 31 minutes on 2 cores).
# It computes what the release binary does (Rust does not reassociate floating point at any
# opt-level); the suite takes about 100 s with it against 57 s with a release binary.
cargo test --no-run --quiet --manifest-path "$root/Cargo.toml"
target="${CARGO_TARGET_DIR:-$root/target}"
export BOUNCEFIT_BIN="${BOUNCEFIT_BIN:-$target/debug/bouncefit}"
cd "$here"
"$here/.venv/bin/python" -m pytest -q -rA "$@"
# The Python package (python/): built into its own venv and tested against this binary.
exec "$root/python/tests/run.sh"
