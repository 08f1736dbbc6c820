#!/usr/bin/env bash
# pinned-venv.sh VENV REQUIREMENTS: creates the venv VENV with the exact pins of the file
# REQUIREMENTS (from PyPI); does nothing when VENV already holds exactly these pins.
set -euo pipefail
venv="$1"
requirements="$2"
stamp="$venv/requirements.installed"
if ! { [ -f "$stamp" ] && cmp -s "$stamp" "$requirements"; }; then
    python3 -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$requirements"
    cp "$requirements" "$stamp"
    echo "installed $(grep -c '==' "$requirements") pinned packages into $venv"
fi
