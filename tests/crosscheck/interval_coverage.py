"""Coverage of `fit --mcmc`'s 95% intervals under small model errors (issue #16 item 4).

Not a test (pytest does not collect it): a report, run after `tests/crosscheck/setup.sh` with

    tests/crosscheck/.venv/bin/python tests/crosscheck/interval_coverage.py [SETS] [OUT_DIR]

or through `scripts/interval-coverage.sh`. For each of SETS seeds (default 50) and each kind of
mismatch below, `bouncefit synth` makes a 32x32 nine-photo set of a known `single` GGX material
(Schlick F0 of copper, alpha 0.15, 0.3 or 0.6 by seed; Gaussian noise of 1% of the set's
root-mean-square radiance, the noise model of the default `l2` likelihood; the flash geometry of
copper-flash on even seeds, the pinhole point-light geometry of aluminium-pinhole on odd ones),
the mismatch is applied, and the set is fitted with `fit --models single --mcmc` once per
method: `--model-error discrepancy` (the default), `photos` (the photo-clustered adjustment
alone) and `none` (the likelihood alone). The environment variables METHODS and MISMATCHES
(comma-separated) run a subset; `none` is needed for the width column. A method
`discrepancy@S` passes `--discrepancy-floor S`. ALPHAS and F0 (comma-separated) change the
true material and FIRST_SEED the seeds, for a check on sets unlike those a method was built on.

| mismatch | what differs between the photos and the fitted model |
| --- | --- |
| `exact` | nothing |
| `noise` | each photo's noise is 1% of its own root-mean-square radiance (photos of different brightness), where the likelihood has one level for all |
| `exposure` | each photo's manifest exposure is off by a factor 1 + 0.01 z, z ~ N(0, 1) |
| `filter` | photos point-sampled at pixel centres, fitted with the box filter of 4 sub-samples |
| `tail` | photos are 0.95 GGX + 0.05 Beckmann at the same alpha (a heavier-headed, lighter-tailed lobe) |

Printed: per mismatch and method, the share of sets whose 95% interval holds the true alpha and
the share of (set, channel) pairs whose F0 interval holds the true F0, each with its binomial
standard error, and the median width of the alpha interval over the `none` method's. Every seed
is fixed, so the table is the same on every run of the same binary.
"""

import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

ROOT = Path(__file__).resolve().parents[2]
BINARY = ROOT / "target" / "release" / "bouncefit"
F0 = [float(v) for v in os.environ.get("F0", "0.955,0.638,0.538").split(",")]
ALPHAS = [float(v) for v in os.environ.get("ALPHAS", "0.15,0.3,0.6").split(",")]
FIRST_SEED = int(os.environ.get("FIRST_SEED", "0"))
NOISE = 0.01
EXPOSURE_ERROR = 0.01
TAIL_SHARE = 0.05
MISMATCHES = os.environ.get("MISMATCHES", "exact,noise,exposure,filter,tail").split(",")
METHODS = os.environ.get("METHODS", "discrepancy,photos,none").split(",")


def bouncefit(*args):
    done = subprocess.run([str(BINARY), *map(str, args)], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"bouncefit {' '.join(map(str, args))} exited {done.returncode}:\n{done.stderr}")


def capture_text(seed):
    source = "copper-flash" if seed % 2 == 0 else "aluminium-pinhole"
    text = (ROOT / "datasets" / "sources" / f"{source}.capture.toml").read_text()
    for size in ("[128, 128]", "[96, 96]"):
        text = text.replace(f"resolution = {size}", "resolution = [32, 32]")
    return text


def with_exposures(text, exposures):
    """The manifest with photo i's exposure set to exposures[i] (other exposure lines dropped)."""
    lines, photo = [], 0
    for line in text.splitlines():
        if line.startswith("exposure ="):
            continue
        lines.append(line)
        if line.startswith("image ="):
            lines.append(f"exposure = {exposures[photo]!r}")
            photo += 1
    return "\n".join(lines) + "\n"


def material(path, alpha, ndf):
    path.write_text(json.dumps({
        "model": "single", "ndf": ndf, "height": "correlated", "alpha": [alpha, alpha],
        "fresnel": {"kind": "schlick", "f0": F0}, "diffuse": [0, 0, 0],
    }))


def make_set(folder, seed, mismatch):
    """Writes the photo set of `seed` with `mismatch` into `folder`; returns the true alpha."""
    alpha = ALPHAS[seed % len(ALPHAS)]
    folder.mkdir(parents=True)
    capture = folder / "source.capture.toml"
    capture.write_text(capture_text(seed))
    ggx = folder / "ggx.material.json"
    material(ggx, alpha, "ggx")
    samples = 1 if mismatch == "filter" else 4
    photos = folder / "photos"
    bouncefit("synth", "--material", ggx, "--capture", capture, "-o", photos,
              "--pixel-samples", samples, "--force")
    if mismatch == "tail":
        beckmann = folder / "beckmann.material.json"
        material(beckmann, alpha, "beckmann")
        bouncefit("synth", "--material", beckmann, "--capture", capture, "-o", folder / "b", "--force")
    rng = np.random.default_rng(seed)
    images = {}
    for image in sorted(photos.glob("*.exr")):
        rgb = np.array(mi.Bitmap(str(image)), dtype=np.float64)[..., :3]
        if mismatch == "tail":
            other = np.array(mi.Bitmap(str(folder / "b" / image.name)), dtype=np.float64)[..., :3]
            rgb = (1 - TAIL_SHARE) * rgb + TAIL_SHARE * other
        images[image] = rgb
    set_rms = np.sqrt(np.mean([np.mean(rgb**2) for rgb in images.values()]))
    for image, rgb in images.items():
        rms = np.sqrt(np.mean(rgb**2)) if mismatch == "noise" else set_rms
        rgb = rgb + NOISE * rms * rng.standard_normal(rgb.shape)
        mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32), mi.Bitmap.PixelFormat.RGB).write(str(image))
    if mismatch == "exposure":
        rng = random.Random(seed)
        manifest = photos / "capture.toml"
        exposures = [1 + EXPOSURE_ERROR * rng.gauss(0, 1) for _ in range(9)]
        manifest.write_text(with_exposures(manifest.read_text(), exposures))
    return alpha


def fit(folder, method):
    out = folder / f"fit-{method}.json"
    name, _, floor = method.partition("@")
    extra = ["--discrepancy-floor", floor] if floor else []
    bouncefit("fit", folder / "photos", "--models", "single", "--mcmc", "--model-error", name,
              *extra, "-o", out, "--force", "--quiet")
    params = json.loads(out.read_text())["posterior"]["params"]
    return params["alpha"]["ci95"], params["f0"]["ci95"]


def one(work, seed, mismatch):
    folder = work / f"{mismatch}-{seed:03d}"
    alpha = make_set(folder, seed, mismatch)
    row = {}
    for method in METHODS:
        (lo, hi), f0 = fit(folder, method)
        row[method] = {
            "alpha": lo <= alpha <= hi,
            "width": (hi - lo) / alpha,
            "f0": [a <= t <= b for (a, b), t in zip(f0, F0)],
        }
    return mismatch, row


def share(hits):
    p = sum(hits) / len(hits)
    return p, (p * (1 - p) / len(hits)) ** 0.5


def main():
    sets = int(sys.argv[1]) if len(sys.argv) > 1 else 50
    work = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(tempfile.mkdtemp(prefix="coverage-"))
    jobs = [(seed, m) for m in MISMATCHES for seed in range(FIRST_SEED, FIRST_SEED + sets)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(lambda job: one(work, *job), jobs))
    print(f"{sets} sets per mismatch, 32x32, 9 photos, 1% noise; work in {work}\n")
    print("| mismatch | model error | alpha covered | F0 covered | alpha width / `none` |")
    print("| --- | --- | --- | --- | --- |")
    for mismatch in MISMATCHES:
        mine = [r for m, r in rows if m == mismatch]
        for method in METHODS:
            alpha, alpha_se = share([r[method]["alpha"] for r in mine])
            f0, f0_se = share([hit for r in mine for hit in r[method]["f0"]])
            ratio = statistics.median(r[method]["width"] / r["none"]["width"] for r in mine)
            print(f"| {mismatch} | {method} | {alpha:.0%} +- {alpha_se:.0%} | {f0:.0%} +- {f0_se:.0%} "
                  f"| {ratio:.2f} |")


if __name__ == "__main__":
    main()
