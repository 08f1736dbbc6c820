"""A photo set from numpy arrays and the manifest's geometry: the fit of the same photos as a
folder, and the manifest reader's checks and messages."""

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import bouncefit
from conftest import ROOT, cli_error, without_timings

tomllib = pytest.importorskip("tomllib")

COPPER = "datasets/copper-flash"
ALUMINIUM = "datasets/aluminium-pinhole"


def manifest_of(folder):
    with open(ROOT / folder / "capture.toml", "rb") as f:
        return tomllib.load(f)


def geometry_of(folder):
    """The keyword arguments of `PhotoSet.from_arrays` that say what the set's manifest says."""
    m = manifest_of(folder)
    photos = m["photo"]
    return dict(name=m["name"], units=m["units"], sample=m["sample"], camera=m.get("camera"),
                cameras=[p.get("camera") for p in photos], lights=[p["light"] for p in photos],
                exposures=[p.get("exposure") for p in photos],
                weights=[p.get("weight") for p in photos],
                stems=[Path(p["image"]).stem for p in photos])


def arrays_of(folder, **change):
    """The bundled set `folder` as float32 arrays (read by `load`) and its geometry."""
    images = [image.astype(np.float32) for image in bouncefit.load(folder).images]
    return images, {**geometry_of(folder), **change}


@pytest.mark.parametrize("folder, options", [
    (COPPER, {"models": ["single", "kulla-conty"]}),
    (ALUMINIUM, {"fresnel": "conductor", "pixel_samples": 1}),
])
def test_arrays_fit_as_the_folder_bit_for_bit(folder, options):
    images, geometry = arrays_of(folder)
    photos = bouncefit.PhotoSet.from_arrays(images, **geometry)
    assert photos.path is None and photos.name == geometry["name"]
    assert photos.photos == geometry["stems"]
    by_path = bouncefit.fit(folder, **options)
    by_arrays = bouncefit.fit(photos, **options)
    expected = without_timings(by_path.data)
    got = without_timings(by_arrays.data)
    # Only the name the set goes by differs: its folder, or the name given with the arrays.
    assert (expected.pop("capture"), got.pop("capture")) == (folder, geometry["name"])
    assert got == expected
    for a, b in zip(by_arrays.prediction + by_arrays.residuals,
                    by_path.prediction + by_path.residuals):
        assert np.array_equal(a, b)
    for a, b in zip(bouncefit.render(photos, f"{folder}/material.json"),
                    bouncefit.render(folder, f"{folder}/material.json")):
        assert np.array_equal(a, b)


def test_one_light_for_all_photos_and_resolution_from_the_images():
    images, geometry = arrays_of(COPPER)
    flash = geometry["lights"][0]
    assert all(light == flash for light in geometry["lights"])
    cameras = [{k: v for k, v in (c or {}).items() if k != "resolution"}
               for c in geometry["cameras"]]
    camera = {k: v for k, v in geometry["camera"].items() if k != "resolution"}
    photos = bouncefit.PhotoSet.from_arrays(
        images, **{**geometry, "lights": flash, "cameras": cameras, "camera": camera})
    assert without_timings(bouncefit.fit(photos).data) == without_timings(
        bouncefit.fit(bouncefit.PhotoSet.from_arrays(images, **geometry)).data)


def test_a_mask_leaves_its_pixels_out():
    images, geometry = arrays_of(COPPER)
    masks = [np.ones(image.shape[:2], dtype=bool) for image in images]
    masks[0][:64] = False
    fit = bouncefit.fit(bouncefit.PhotoSet.from_arrays(images, masks=masks, **geometry))
    assert fit.data["excluded"]["masked"] == 64 * 128
    assert np.all(fit.residuals[0][:64] == 0) and np.any(fit.residuals[0][64:] != 0)


def cli_message_of(folder, tmp_path, edit):
    """The command line's message for the set `folder` with its manifest's text edited, the
    manifest's path left out (`photo[0].light.position: ...`)."""
    copy = tmp_path / "set"
    copy.mkdir()
    for file in (ROOT / folder).iterdir():
        (copy / file.name).write_bytes(file.read_bytes())
    manifest = copy / "capture.toml"
    manifest.write_text(edit(manifest.read_text()))
    stderr = cli_error("fit", copy, "-o", tmp_path / "unused.json")
    return stderr.strip().removeprefix(f"error: {manifest}: ")


def test_impossible_geometry_raises_the_command_lines_message(tmp_path):
    expected = cli_message_of(COPPER, tmp_path, lambda text: text.replace(
        "position = [3.0, 3.2, 17.2]", "position = [3.0, 3.2, -17.2]", 1))
    assert expected.startswith("photo[1].camera.position: must be above the sample plane")
    images, geometry = arrays_of(COPPER)
    geometry["cameras"][1] = {**geometry["cameras"][1], "position": [3.0, 3.2, -17.2]}
    with pytest.raises(bouncefit.InvalidInputError) as raised:
        bouncefit.PhotoSet.from_arrays(images, **geometry)
    assert str(raised.value) == f"copper-flash: {expected}"


@pytest.mark.parametrize("change, message", [
    ({"lights": {"kind": "spot", "intensity": [1.0, 1.0, 1.0]}},
     "photo[0].light.kind: unknown light kind `spot`"),
    ({"sample": (8.0, 0.0)}, "sample.height: must be finite and positive, got 0"),
    ({"exposures": [0.0] * 9}, "photo[0].exposure: must be finite and positive, got 0"),
    ({"lights": [{"kind": "flash"}] * 9}, "photo[0].light.intensity: missing"),
])
def test_bad_geometry_is_invalid_input_naming_the_field(change, message):
    images, geometry = arrays_of(COPPER, **change)
    with pytest.raises(bouncefit.InvalidInputError, match=re.escape(message)):
        bouncefit.PhotoSet.from_arrays(images, **geometry)


def test_arrays_that_are_not_photos_are_invalid_input():
    images, geometry = arrays_of(COPPER)
    with pytest.raises(bouncefit.InvalidInputError, match=r"images\[2\]: expected a \(height, "):
        bouncefit.PhotoSet.from_arrays(images[:2] + [images[2][..., 0]] + images[3:], **geometry)
    with pytest.raises(bouncefit.InvalidInputError, match="lights: 2 given for 9 images"):
        bouncefit.PhotoSet.from_arrays(images, **{**geometry, "lights": geometry["lights"][:2]})
    resized = [images[0][:64]] + images[1:]
    with pytest.raises(bouncefit.InvalidInputError,
                       match=r"images\[0\]: resolution: the image is 128x64 but photo\[0\]'s "
                             "camera has resolution 128x128"):
        bouncefit.PhotoSet.from_arrays(resized, **geometry)


def test_a_nan_pixel_is_left_out_with_the_command_lines_warning():
    images, geometry = arrays_of(COPPER)
    images[3][10, 20, 1] = np.nan
    photos = bouncefit.PhotoSet.from_arrays(images, **geometry)
    with pytest.warns(bouncefit.BouncefitWarning,
                      match="copper-flash: photos: 1 non-finite and 0 negative pixels excluded"):
        fit = bouncefit.fit(photos)
    assert fit.data["excluded"]["non_finite"] == 1
    # Every pixel non-finite: the command line's error.
    photos = bouncefit.PhotoSet.from_arrays([np.full_like(i, np.nan) for i in images], **geometry)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(bouncefit.InvalidInputError,
                           match=r"copper-flash: photos: every pixel is excluded \(0 outside the "
                                 r"sample, 0 masked, 0 saturated, 147456 non-finite"):
            bouncefit.fit(photos)


def test_unknown_keys_are_warnings_and_no_command_line_reads_arrays():
    images, geometry = arrays_of(COPPER)
    with pytest.warns(bouncefit.BouncefitWarning, match=r"photo\[0\].light.colour: unknown key"):
        lights = [{**geometry["lights"][0], "colour": 2}] + geometry["lights"][1:]
        photos = bouncefit.PhotoSet.from_arrays(images, **{**geometry, "lights": lights})
    with pytest.raises(bouncefit.InvalidInputError, match="held in memory"):
        bouncefit.command_line("fit", photos)


@pytest.mark.parametrize("options", [
    {"models": ["single", "kulla-conty"], "holdout": 3},
    {"models": ["kulla-conty"], "maps": True, "texels": "16x16", "bases": 2, "holdout_photo": 8},
])
def test_arrays_compare_as_the_folder(tmp_path, options):
    folder = "datasets/two-materials" if options.get("maps") else COPPER
    images, geometry = arrays_of(folder)
    photos = bouncefit.PhotoSet.from_arrays(images, **geometry)
    by_path = bouncefit.compare(folder, output=tmp_path / "path", **options)
    by_arrays = bouncefit.compare(photos, output=tmp_path / "arrays", **options)
    # The reports differ only in the name the set goes by and in timings.
    text = json.dumps(without_timings(by_path)).replace(json.dumps(folder),
                                                        json.dumps(geometry["name"]))
    assert json.loads(text) == without_timings(by_arrays)
    model = options["models"][0]
    for report in ("path", "arrays"):
        assert (tmp_path / report / model / "fit.json").is_file()
