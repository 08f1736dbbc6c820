"""A notebook's first cells, as a script: fit the bundled copper photos (uniform, two models)
and the two-material sample (maps, one photo held out), look at the numbers, render and
export. Run from the repository root after `pip install ./python`:

    python python/examples/quickstart.py            # the maps fit at one texel a pixel (~15 s)
    python python/examples/quickstart.py --texels 16x16   # a quick look

Each printed figure is what the `bouncefit` command printed after it gives for the same set.
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np

import bouncefit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--texels", help="maps grid, e.g. 64x64 (default: one texel a pixel)")
    args = parser.parse_args()
    out = Path(tempfile.mkdtemp(prefix="bouncefit-quickstart-"))

    # 1. A uniform fit: which model, what roughness and F0 (`bouncefit fit ... --models ...`).
    copper = bouncefit.load("datasets/copper-flash")
    fit = bouncefit.fit(copper, ["single", "kulla-conty"], output=out / "copper.json")
    print(f"copper-flash: {fit.model}, alpha {fit.alpha[0]:.4f}, "
          f"F0 {tuple(round(c, 4) for c in fit.f0)}, loss {fit.data['loss']:.4e}")

    # How well the fit re-renders the photos it saw.
    for stem, image, residual in list(zip(copper.photos, copper.images, fit.residuals))[:3]:
        print(f"  photo {stem}: relative residual {np.linalg.norm(residual) / np.linalg.norm(image):.4f}")

    # 2. Material maps of a patterned sample, photo 8 held out to judge them
    #    (`bouncefit fit datasets/two-materials --maps --models kulla-conty --holdout-photo 8`).
    maps = bouncefit.fit("datasets/two-materials", "kulla-conty", maps=True, holdout_photo=8,
                         texels=args.texels, output=out / "two-materials.json")
    roughness = maps.maps["roughness"][..., 0]
    bases = maps.data["maps_fit"]["bases"]
    held_out = maps.data["holdout"]["relative_error"]
    print(f"two-materials: maps {roughness.shape[1]}x{roughness.shape[0]}, base materials "
          + ", ".join(f"{b['kind']} alpha {b['alpha']:.3f} ({b['share']:.0%})" for b in bases)
          + f"; held-out photo 8 predicted to {held_out:.2%}")

    # 3. Re-render the photos from the maps and export them for a renderer.
    rendered = bouncefit.render("datasets/two-materials", maps)
    print(f"  rendered {len(rendered)} photos of shape {rendered[0].shape}")
    print(f"  glTF: {bouncefit.export(maps, 'gltf', out / 'two-materials.gltf')}")


if __name__ == "__main__":
    main()
