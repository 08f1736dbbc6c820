"""Shared helpers of the crosscheck suite: the bouncefit binary, EXR files, the bundled data.

EXR files are read and written with Mitsuba's Bitmap (this OpenCV wheel is built without
OpenEXR), as float32 RGB, the format the tool reads and writes.
"""

import json
import os
import subprocess
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("scalar_rgb")

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).resolve().parent / "fixtures"
CAPTURES = ["copper-flash", "aluminium-pinhole"]


def binary():
    """The binary under test: $BOUNCEFIT_BIN (run.sh sets it to the test profile's build),
    else target/release/bouncefit."""
    path = Path(os.environ.get("BOUNCEFIT_BIN", ROOT / "target" / "release" / "bouncefit"))
    if not path.is_file():
        pytest.fail(f"no bouncefit binary at {path}: run tests/crosscheck/run.sh")
    return str(path)


def run(*args):
    """Runs `bouncefit ARGS`, fails the test on a non-zero exit, returns stdout."""
    done = subprocess.run(
        [binary(), *map(str, args)], capture_output=True, text=True, cwd=ROOT
    )
    if done.returncode != 0:
        pytest.fail(f"bouncefit {' '.join(map(str, args))} exited {done.returncode}:\n{done.stderr}")
    return done.stdout


def run_json(*args):
    """Runs `bouncefit ARGS` and parses the one JSON object it prints."""
    return json.loads(run(*args))


def read_exr(path):
    """An EXR file as a float64 array of shape (height, width, 3)."""
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]


def write_exr(path, rgb):
    """Writes an (height, width, 3) array as a float32 RGB EXR."""
    mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32), mi.Bitmap.PixelFormat.RGB).write(str(path))


def report(name, worst, tolerance):
    """Prints a comparison's worst error against its tolerance (shown by pytest -rA)."""
    print(f"{name}: worst {worst:.3e} (tolerance {tolerance:.0e})")


def relative_error(ours, reference):
    """|ours - reference| / |reference|, elementwise."""
    return np.abs(ours - reference) / np.abs(reference)


@pytest.fixture
def smooth_image():
    """A 40 x 48 float image with smooth gradients, sharp edges and values in (0, 1]."""
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:40, 0:48].astype(np.float64)
    base = np.stack([0.5 + 0.4 * np.sin(x / 5.0), 0.5 + 0.4 * np.cos(y / 4.0), (x + y) / 90.0 + 0.05], -1)
    base[10:20, 15:30] *= 0.2
    return np.clip(base + 0.02 * rng.standard_normal(base.shape), 0.01, 1.0)


def exported_scenes(tmp_path, capture):
    """A bundled capture's truth with Mitsuba's G2 (`height: uncorrelated`, so the export is
    exact), exported as one Mitsuba scene per photo into tmp_path/scenes: (folder, material)."""
    folder = ROOT / "datasets" / capture
    material = json.loads((folder / "material.json").read_text())
    material["height"] = "uncorrelated"
    (tmp_path / "material.json").write_text(json.dumps(material))
    run("export", tmp_path / "material.json", "--format", "mitsuba", "--scene", folder, "-o", tmp_path / "scenes")
    return folder, material


@pytest.fixture(scope="session")
def two_materials_report(tmp_path_factory):
    """The report folder of `compare --maps` on datasets/two-materials (single and kulla-conty,
    photo 8 held out), made once for every test that reads it."""
    folder = tmp_path_factory.mktemp("compare") / "two-materials"
    run("compare", ROOT / "datasets" / "two-materials", "--maps", "--models", "single,kulla-conty",
        "--holdout-photo", 8, "--quiet", "-o", folder)
    return folder
