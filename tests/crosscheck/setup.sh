#!/usr/bin/env bash
# Creates tests/crosscheck/.venv with the pinned packages of requirements.txt (from PyPI),
# tests/crosscheck/node/node_modules with the pinned npm packages of node/package-lock.json, and
# installs Debian's chromium (headless browser of test_report_chromium.py) where missing.
# Idempotent: does nothing when all of them are already there.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
"$here/../../scripts/pinned-venv.sh" "$here/.venv" "$here/requirements.txt"

# The Khronos glTF validator (npm gltf-validator, pinned in node/package-lock.json) for
# test_export_maps.py; Node and npm come from the distribution where missing (root on CI).
node_dir="$here/node"
node_stamp="$node_dir/node_modules/package-lock.installed"
if ! command -v npm >/dev/null; then
    apt-get update -qq && apt-get install -y -qq nodejs npm >/dev/null
fi
if ! { [ -f "$node_stamp" ] && cmp -s "$node_stamp" "$node_dir/package-lock.json"; }; then
    npm ci --prefix "$node_dir" --no-audit --no-fund --loglevel=error
    cp "$node_dir/package-lock.json" "$node_stamp"
    echo "crosscheck: installed gltf-validator into $node_dir/node_modules"
fi

# Headless Chromium for test_report_chromium.py, from the distribution where missing (root on CI).
if ! command -v chromium >/dev/null; then
    apt-get update -qq && apt-get install -y -qq chromium >/dev/null
fi
