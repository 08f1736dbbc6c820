#!/usr/bin/env bash
# Creates tests/crosscheck/.venv with the pinned packages of requirements.txt (from PyPI).
# Idempotent: does nothing when the venv already holds exactly these pins.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="$here/.venv"
stamp="$venv/requirements.installed"
if [ -f "$stamp" ] && cmp -s "$stamp" "$here/requirements.txt"; then
    exit 0
fi
python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
cp "$here/requirements.txt" "$stamp"
echo "crosscheck: installed $(grep -c '==' "$here/requirements.txt") pinned packages into $venv"
