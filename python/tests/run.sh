#!/usr/bin/env bash
# The Python package's tests: a venv with the pinned packages of requirements.txt, the package
# built and installed into it, pytest. Extra arguments go to pytest.
#
# The package is built by pip through its own build backend (maturin, as `pip install ./python`
# does), with the dev profile set to the test profile's settings (Cargo.toml [profile.test]),
# into the same target folder: of the crates `cargo test` has just compiled, those whose
# features are the same here are reused (about 210 of 255). The rest are compiled again, the
# main crate among them: pyo3's macros turn on more of syn, `cargo test`'s dev-dependencies
# more of serde, and every crate that derives serde follows.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="$here/.venv"
"$root/scripts/pinned-venv.sh" "$venv" "$here/requirements.txt"
cargo test --no-run --quiet --manifest-path "$root/Cargo.toml"
export MATURIN_PEP517_ARGS="--profile dev --config profile.dev.opt-level=2 \
--config 'profile.dev.debug=\"line-tables-only\"' --config 'profile.dev.package.\"*\".debug=false'"
PATH="$venv/bin:$PATH" "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    --no-build-isolation --no-deps --force-reinstall "$root/python"
target="${CARGO_TARGET_DIR:-$root/target}"
export BOUNCEFIT_BIN="${BOUNCEFIT_BIN:-$target/debug/bouncefit}"
cd "$here"
exec "$venv/bin/python" -m pytest -q -rA -p no:cacheprovider "$@"
