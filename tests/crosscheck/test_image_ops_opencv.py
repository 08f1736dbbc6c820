"""The fitter's image operations (`bouncefit image ...`) against OpenCV.

| op | reference | compared |
| --- | --- | --- |
| sRGB decode / encode | IEC 61966-2-1 formula in numpy (OpenCV has no sRGB transfer op) | every 8-bit code, 16-bit codes, floats around the breakpoints |
| gamma decode / encode | cv2.pow | every 8-bit code, floats |
| downsample (pyramid level) | cv2.resize INTER_AREA to half size (2 x 2 block means) | even and odd sizes |
| blur (SSIM window) | cv2.GaussianBlur 11 x 11, sigma 1.5, BORDER_CONSTANT (zero outside) | every pixel |
| ssim | Wang et al. 2004 recipe: local statistics by cv2.GaussianBlur, eq. 13, C1 = (0.01 L)^2, C2 = (0.03 L)^2 | pixels at least 5 px from the edge (the recipe defines no border) |

The tool's outputs are float32 EXR, so tolerances are a few float32 steps.
"""

import cv2
import numpy as np
import pytest

from conftest import read_exr, relative_error, report, run_json, write_exr

F32_TOLERANCE = 1e-6


def srgb_to_linear(v):
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v):
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)


def every_code_png(path, bits):
    """A PNG holding integer codes (RGB planes shifted so each channel sees every code);
    returns the codes as an (h, w, 3) array in RGB order."""
    top = 2**bits - 1
    codes = np.linspace(0, top, 256 if bits == 8 else 4096).round().astype(np.uint16 if bits == 16 else np.uint8)
    grid = codes.reshape(16, -1)
    rgb = np.stack([grid, np.roll(grid, 1, axis=1), np.roll(grid, 7, axis=0)], -1)
    cv2.imwrite(str(path), rgb[..., ::-1])  # OpenCV stores BGR
    return rgb.astype(np.float64) / top


@pytest.mark.parametrize("bits", [8, 16])
def test_srgb_decode_of_every_code(tmp_path, bits):
    stored = every_code_png(tmp_path / "codes.png", bits)
    run_json("image", "decode", tmp_path / "codes.png", "--color", "srgb", "-o", tmp_path / "out.exr")
    worst = np.abs(read_exr(tmp_path / "out.exr") - srgb_to_linear(stored)).max()
    report(f"sRGB decode, {bits}-bit codes (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


def test_gamma_decode_of_every_code_matches_cv2_pow(tmp_path):
    stored = every_code_png(tmp_path / "codes.png", 8)
    run_json("image", "decode", tmp_path / "codes.png", "--color", "gamma:2.2", "-o", tmp_path / "out.exr")
    worst = np.abs(read_exr(tmp_path / "out.exr") - cv2.pow(stored, 2.2)).max()
    report("gamma 2.2 decode, 8-bit codes (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


def linear_ramp():
    """Linear values over [0, 1], dense around the sRGB breakpoint 0.0031308."""
    values = np.concatenate([np.linspace(0, 0.01, 600), np.linspace(0.01, 1, 600)])
    return values.reshape(20, 20, 3)


@pytest.mark.parametrize(
    "color, reference",
    [("srgb", linear_to_srgb), ("gamma:2.2", lambda v: cv2.pow(v, 1 / 2.2))],
)
def test_encode(tmp_path, color, reference):
    write_exr(tmp_path / "in.exr", linear_ramp())
    linear = read_exr(tmp_path / "in.exr")  # the float32 values the tool reads
    run_json("image", "encode", tmp_path / "in.exr", "--color", color, "-o", tmp_path / "out.exr")
    worst = np.abs(read_exr(tmp_path / "out.exr") - reference(linear)).max()
    report(f"{color} encode (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


@pytest.mark.parametrize("size", [(40, 48), (41, 47)])
def test_downsample_is_cv2_area_resize(tmp_path, smooth_image, size):
    height, width = size
    write_exr(tmp_path / "in.exr", np.resize(smooth_image, (height, width, 3)))
    image = read_exr(tmp_path / "in.exr")
    run_json("image", "downsample", tmp_path / "in.exr", "-o", tmp_path / "out.exr")
    # The fitter drops an odd last row/column; INTER_AREA at exactly half size is the block mean.
    even = image[: height // 2 * 2, : width // 2 * 2]
    reference = cv2.resize(even, (width // 2, height // 2), interpolation=cv2.INTER_AREA)
    ours = read_exr(tmp_path / "out.exr")
    assert ours.shape == reference.shape
    worst = relative_error(ours, reference).max()
    report(f"downsample {width}x{height} (relative)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


def test_blur_is_cv2_gaussian_blur_with_zero_border(tmp_path, smooth_image):
    write_exr(tmp_path / "in.exr", smooth_image)
    image = read_exr(tmp_path / "in.exr")
    run_json("image", "blur", tmp_path / "in.exr", "-o", tmp_path / "out.exr")
    reference = cv2.GaussianBlur(image, (11, 11), 1.5, borderType=cv2.BORDER_CONSTANT)
    worst = relative_error(read_exr(tmp_path / "out.exr"), reference).max()
    report("SSIM window blur, every pixel (relative)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE


def wang_ssim(x, y, dynamic_range):
    """SSIM map per channel (Wang et al. 2004, eq. 13) with Gaussian local statistics."""
    blur = lambda image: cv2.GaussianBlur(image, (11, 11), 1.5, borderType=cv2.BORDER_CONSTANT)
    c1, c2 = (0.01 * dynamic_range) ** 2, (0.03 * dynamic_range) ** 2
    mu_x, mu_y = blur(x), blur(y)
    var_x = blur(x * x) - mu_x**2
    var_y = blur(y * y) - mu_y**2
    cov = blur(x * y) - mu_x * mu_y
    return ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))


def test_ssim_map_follows_wang_2004(tmp_path, smooth_image):
    target = smooth_image
    prediction = np.clip(1.1 * target + 0.05 * np.sin(np.arange(target.size).reshape(target.shape)), 0, None)
    write_exr(tmp_path / "x.exr", prediction)
    write_exr(tmp_path / "y.exr", target)
    x, y = read_exr(tmp_path / "x.exr"), read_exr(tmp_path / "y.exr")
    summary = run_json("image", "ssim", tmp_path / "x.exr", tmp_path / "y.exr", "-o", tmp_path / "s.exr")
    reference = wang_ssim(x, y, y.max())
    ours = read_exr(tmp_path / "s.exr")
    interior = (slice(5, -5), slice(5, -5))
    worst = np.abs(ours[interior] - reference[interior]).max()
    report("SSIM map, interior (abs)", worst, F32_TOLERANCE)
    assert worst < F32_TOLERANCE
    assert abs(summary["mean"] - ours.mean()) < 1e-6
    # The images differ enough that SSIM is far from 1: the comparison is not of constants.
    assert reference[interior].min() < 0.9
