"""Writes tests/crosscheck/fixtures/kornia_*.npz: inputs and Kornia's outputs of the image
operations the fitter uses, for test_image_ops_kornia.py (which needs neither torch nor Kornia).

Needs torch and kornia (not in CI: the torch wheel is several GB). Regenerate with
    python3 -m venv /tmp/kornia-venv
    /tmp/kornia-venv/bin/pip install torch kornia numpy
    /tmp/kornia-venv/bin/python tests/crosscheck/make_kornia_fixtures.py

| fixture | input | Kornia op | the fitter's op |
| --- | --- | --- | --- |
| srgb_decode | every 8-bit code / 255 | kornia.color.rgb_to_linear_rgb | image decode --color srgb (of the PNG) |
| srgb_encode | linear ramp | kornia.color.linear_rgb_to_rgb | image encode --color srgb |
| gamma_decode | every 8-bit code / 255 | kornia.enhance.adjust_gamma(x, 2.2) | image decode --color gamma:2.2 |
| gamma_encode | linear ramp | kornia.enhance.adjust_gamma(x, 1 / 2.2) | image encode --color gamma:2.2 |
| downsample | 40 x 48 image | kornia.geometry.transform.resize(..., interpolation="area") to half size | image downsample (the pyramid's 2 x 2 block mean; kornia.geometry.pyrdown is a Gaussian pyramid, which the fitter does not use) |
| blur | 40 x 48 image | kornia.filters.gaussian_blur2d(11 x 11, sigma 1.5, border_type="constant") | image blur |
| ssim | two 40 x 48 images | kornia.metrics.ssim(window 11, max_val = brightest target, padding="valid") | image ssim, interior pixels |

Inputs are float32 values (stored exactly in EXR); Kornia runs in float64. PSNR is not used by the
fitter, so there is no PSNR fixture.
"""

from pathlib import Path

import kornia
import numpy as np
import torch

OUT = Path(__file__).resolve().parent / "fixtures"


def tensor(image):
    """(h, w, 3) numpy -> (1, 3, h, w) float64 tensor."""
    return torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1)[None]))


def array(t):
    """(1, 3, h, w) tensor -> (h, w, 3) numpy float64."""
    return t[0].permute(1, 2, 0).double().numpy()


def images():
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:40, 0:48].astype(np.float64)
    base = np.stack([0.5 + 0.4 * np.sin(x / 4.0), 0.5 + 0.4 * np.cos(y / 3.0), (x + y) / 90.0 + 0.05], -1)
    base[12:22, 18:33] *= 0.25
    target = np.clip(base + 0.03 * rng.standard_normal(base.shape), 0.01, 1.0).astype(np.float32)
    prediction = np.clip(1.15 * target + 0.04 * rng.standard_normal(base.shape), 0.0, None).astype(np.float32)
    return target.astype(np.float64), prediction.astype(np.float64)


def main():
    OUT.mkdir(exist_ok=True)
    codes = np.arange(256, dtype=np.uint8).reshape(16, 16)
    codes = np.stack([codes, np.roll(codes, 1, axis=1), np.roll(codes, 5, axis=0)], -1)
    stored = codes.astype(np.float64) / 255.0
    ramp = np.concatenate([np.linspace(0, 0.01, 300), np.linspace(0.01, 1, 300)]).reshape(10, 20, 3)
    ramp = ramp.astype(np.float32).astype(np.float64)
    target, prediction = images()
    half = (target.shape[0] // 2, target.shape[1] // 2)
    fixtures = {
        "srgb_decode": dict(codes=codes, output=array(kornia.color.rgb_to_linear_rgb(tensor(stored)))),
        "srgb_encode": dict(input=ramp, output=array(kornia.color.linear_rgb_to_rgb(tensor(ramp)))),
        "gamma_decode": dict(codes=codes, output=array(kornia.enhance.adjust_gamma(tensor(stored), 2.2))),
        "gamma_encode": dict(input=ramp, output=array(kornia.enhance.adjust_gamma(tensor(ramp), 1 / 2.2))),
        "downsample": dict(
            input=target,
            output=array(kornia.geometry.transform.resize(tensor(target), half, interpolation="area")),
        ),
        "blur": dict(
            input=target,
            output=array(kornia.filters.gaussian_blur2d(tensor(target), (11, 11), (1.5, 1.5), border_type="constant")),
        ),
        "ssim": dict(
            prediction=prediction,
            target=target,
            output=array(kornia.metrics.ssim(tensor(prediction), tensor(target), 11, max_val=float(target.max()), padding="valid")),
        ),
    }
    for name, arrays in fixtures.items():
        np.savez_compressed(OUT / f"kornia_{name}.npz", **arrays)
    print(f"wrote {len(fixtures)} fixtures to {OUT} (torch {torch.__version__}, kornia {kornia.__version__})")


if __name__ == "__main__":
    main()
