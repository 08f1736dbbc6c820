"""The fitter's image operations (`bouncefit image ...`) against Kornia's, from the fixtures
that make_kornia_fixtures.py wrote (see its table; torch and Kornia are not needed here).

The tool reads float32 EXR inputs (the fixtures' inputs are float32 values) and writes float32,
so tolerances are a few float32 steps. SSIM is compared where Kornia's `padding="valid"` map
is defined: pixels at least 5 px from the edge.
"""

import cv2
import numpy as np
import pytest

from conftest import FIXTURES, read_exr, relative_error, report, run_json, write_exr

F32_TOLERANCE = 1e-6


def fixture(name):
    return np.load(FIXTURES / f"kornia_{name}.npz")


@pytest.mark.parametrize("name, color", [("srgb_decode", "srgb"), ("gamma_decode", "gamma:2.2")])
def test_decode_of_every_code(tmp_path, name, color):
    data = fixture(name)
    cv2.imwrite(str(tmp_path / "codes.png"), data["codes"][..., ::-1])  # OpenCV stores BGR
    run_json("image", "decode", tmp_path / "codes.png", "--color", color, "-o", tmp_path / "out.exr")
    worst = np.abs(read_exr(tmp_path / "out.exr") - data["output"]).max()
    report(f"Kornia {name} (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


@pytest.mark.parametrize("name, color", [("srgb_encode", "srgb"), ("gamma_encode", "gamma:2.2")])
def test_encode(tmp_path, name, color):
    data = fixture(name)
    write_exr(tmp_path / "in.exr", data["input"])
    run_json("image", "encode", tmp_path / "in.exr", "--color", color, "-o", tmp_path / "out.exr")
    worst = np.abs(read_exr(tmp_path / "out.exr") - data["output"]).max()
    report(f"Kornia {name} (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


@pytest.mark.parametrize("op", ["downsample", "blur"])
def test_filters(tmp_path, op):
    data = fixture(op)
    write_exr(tmp_path / "in.exr", data["input"])
    run_json("image", op, tmp_path / "in.exr", "-o", tmp_path / "out.exr")
    ours = read_exr(tmp_path / "out.exr")
    assert ours.shape == data["output"].shape
    worst = relative_error(ours, data["output"]).max()
    report(f"Kornia {op} (relative)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


def test_ssim_interior(tmp_path):
    data = fixture("ssim")
    write_exr(tmp_path / "x.exr", data["prediction"])
    write_exr(tmp_path / "y.exr", data["target"])
    run_json("image", "ssim", tmp_path / "x.exr", tmp_path / "y.exr", "-o", tmp_path / "s.exr")
    interior = read_exr(tmp_path / "s.exr")[5:-5, 5:-5]
    assert interior.shape == data["output"].shape
    worst = np.abs(interior - data["output"]).max()
    report("Kornia ssim, interior (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE
    assert data["output"].min() < 0.9  # the images differ: not a comparison of constants
