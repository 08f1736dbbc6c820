"""Shared helpers of the Python package's tests: the command-line binary the package is
compared with, the bundled photo sets, and fit files without their timings."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def binary():
    """The command line under comparison: $BOUNCEFIT_BIN (run.sh sets it to the test
    profile's build), else target/release/bouncefit."""
    path = Path(os.environ.get("BOUNCEFIT_BIN", ROOT / "target" / "release" / "bouncefit"))
    if not path.is_file():
        pytest.fail(f"no bouncefit binary at {path}: run python/tests/run.sh")
    return str(path)


def cli(*args, check=True):
    """Runs `bouncefit ARGS` in the repository root; returns the finished process."""
    done = subprocess.run([binary(), *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    if check and done.returncode != 0:
        pytest.fail(f"bouncefit {' '.join(map(str, args))} exited {done.returncode}:\n{done.stderr}")
    return done


def cli_error(*args):
    """The message `bouncefit ARGS` prints after `error: ` (it must fail)."""
    done = cli(*args, check=False)
    assert done.returncode == 2, done.stderr
    return done.stderr


def without_timings(value):
    """A fit file's JSON value with every `seconds` entry (wall time) removed."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def read_fit(path):
    return without_timings(json.loads(Path(path).read_text()))


@pytest.fixture(autouse=True)
def in_root(monkeypatch):
    """Every test runs in the repository root, as the command line above, so relative paths
    (and the `capture` field of fit files) agree."""
    monkeypatch.chdir(ROOT)


@pytest.fixture
def broken_set(tmp_path):
    """A copy of datasets/copper-flash whose manifest has a photo without an image."""
    target = tmp_path / "broken"
    shutil.copytree(ROOT / "datasets" / "copper-flash", target)
    manifest = target / "capture.toml"
    manifest.write_text(manifest.read_text().replace('image = "03.exr"', 'picture = "03.exr"'))
    return target
