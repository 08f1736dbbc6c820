#!/usr/bin/env bash
# Regenerate the bundled synthetic photo sets from their sources (material + capture template).
# Usage: datasets/make.sh   (from the repository root; builds the release binary first)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=target/release/bouncefit
$bin synth --material datasets/sources/copper-a03.material.json \
  --capture datasets/sources/copper-flash.capture.toml -o datasets/copper-flash --force
$bin synth --material datasets/sources/aluminium-a05.material.json \
  --capture datasets/sources/aluminium-pinhole.capture.toml -o datasets/aluminium-pinhole --force
$bin synth --material datasets/sources/two-materials.material.json \
  --capture datasets/sources/two-materials.capture.toml -o datasets/two-materials --noise 0.01 --force
