"""The Python API against the command line: same numbers, same files, same errors."""

import json
import re
import runpy
import threading
import time

import numpy as np
import pytest

import bouncefit
from conftest import ROOT, cli, cli_error, read_fit, without_timings

COPPER = "datasets/copper-flash"
ALUMINIUM = "datasets/aluminium-pinhole"


def test_load_gives_the_images_the_fit_sees():
    photos = bouncefit.load(COPPER)
    assert photos.name == "copper-flash" and photos.sample == (8.0, 8.0)
    assert photos.photos == [f"{i:02}" for i in range(9)]
    assert [im.shape for im in photos.images] == [(128, 128, 3)] * 9
    fit = bouncefit.fit(photos)
    for image, predicted, residual in zip(photos.images, fit.prediction, fit.residuals):
        used = np.any(residual != 0, axis=-1)
        assert used.mean() > 0.5
        # Residuals are prediction minus photo: the arrays are laid out as the photos.
        np.testing.assert_allclose((predicted - residual)[used], image[used], rtol=1e-9)


@pytest.mark.parametrize(
    "photos, options, flags",
    [
        (COPPER, {"models": ["single", "kulla-conty"]}, ["--models", "single,kulla-conty"]),
        (ALUMINIUM, {"fresnel": "conductor", "pixel_samples": 1, "seed": 3},
         ["--fresnel", "conductor", "--pixel-samples", "1", "--seed", "3"]),
    ],
)
def test_fit_is_the_command_lines_fit(tmp_path, photos, options, flags):
    cli("fit", photos, *flags, "-o", tmp_path / "cli.json", "--quiet")
    events = []
    fit = bouncefit.fit(photos, output=tmp_path / "py.json", progress=lambda *e: events.append(e),
                        **options)
    expected = read_fit(tmp_path / "cli.json")
    assert without_timings(fit.data) == expected
    assert read_fit(tmp_path / "py.json") == expected
    assert fit.model == expected["model"] and list(fit.alpha) == expected["alpha"]
    fitted = [message for stage, _, _, message in events if stage == "fitted"]
    assert len(fitted) == len(expected["candidates"])
    assert all(m.split(":")[0] in {c["model"] for c in expected["candidates"]} for m in fitted)


def test_fit_recovers_the_copper_sample():
    truth = json.loads((ROOT / COPPER / "material.json").read_text())
    fit = bouncefit.fit(COPPER)
    assert fit.alpha[0] == pytest.approx(truth["alpha"][0], rel=0.03)
    assert fit.f0 is not None and max(fit.f0) < 1 and fit.f0[0] > fit.f0[2]  # copper is red


def test_maps_fit_is_the_command_lines_fit(tmp_path):
    flags = ["--maps", "--models", "kulla-conty", "--texels", "16x16", "--bases", "2",
             "--holdout-photo", "8"]
    cli("fit", "datasets/two-materials", *flags, "-o", tmp_path / "cli.json", "--quiet")
    fit = bouncefit.fit("datasets/two-materials", "kulla-conty", maps=True, texels="16x16",
                        bases=2, holdout_photo=8)
    expected = read_fit(tmp_path / "cli.json")
    data = without_timings(fit.data)
    assert data.pop("maps") == {}
    assert data.pop("uncertainty") == {}
    assert data == {k: v for k, v in expected.items() if k not in ("maps", "uncertainty")}
    assert fit.maps["roughness"].shape == (16, 16, 2)
    assert fit.maps["diffuse"].shape == fit.maps["specular"].shape == (16, 16, 3)
    # The sample is copper (alpha 0.65) on red paint: both roughnesses are among the texels.
    assert np.any(np.abs(fit.maps["roughness"] - 0.65) < 0.1)
    # Saved under the same file name, the fit file names the same map images.
    (tmp_path / "py").mkdir()
    fit.save(tmp_path / "py" / "cli.json")
    assert read_fit(tmp_path / "py" / "cli.json") == expected
    images = list(expected["maps"].values())
    images += [entry["file"] for entry in expected["uncertainty"].values() if "file" in entry]
    assert len(images) == 6
    for image in images:
        assert (tmp_path / "py" / image).read_bytes() == (tmp_path / image).read_bytes()


def test_render_reproduces_the_photos_of_the_true_material():
    photos = bouncefit.load(COPPER)
    rendered = bouncefit.render(COPPER, f"{COPPER}/material.json")
    assert [r.shape for r in rendered] == [im.shape for im in photos.images]
    for image, render in zip(photos.images, rendered):
        error = np.linalg.norm(render - image) / np.linalg.norm(image)
        assert error < 0.05


def test_export_writes_the_command_lines_file(tmp_path):
    bouncefit.fit(COPPER, output=tmp_path / "fit.json")
    cli("export", tmp_path / "fit.json", "--format", "gltf", "-o", tmp_path / "cli.gltf")
    written = bouncefit.export(tmp_path / "fit.json", "gltf", tmp_path / "py.gltf")
    assert written.read_bytes() == (tmp_path / "cli.gltf").read_bytes()


@pytest.mark.parametrize("maps", [False, True])
def test_a_fit_in_memory_exports_and_renders_as_its_file(tmp_path, maps):
    if maps:
        fit = bouncefit.fit("datasets/two-materials", "kulla-conty", maps=True, texels="16x16",
                            bases=2, output=tmp_path / "fit.json")
        photos = "datasets/two-materials"
    else:
        fit = bouncefit.fit(COPPER, output=tmp_path / "fit.json")
        photos = COPPER
    for format, name in [("gltf", "x.gltf"), ("mitsuba", "x.xml")]:
        (tmp_path / format).mkdir()
        (tmp_path / f"{format}-file").mkdir()
        bouncefit.export(fit, format, tmp_path / format / name)
        bouncefit.export(tmp_path / "fit.json", format, tmp_path / f"{format}-file" / name)
        written = sorted(p.relative_to(tmp_path / format)
                         for p in (tmp_path / format).rglob("*") if p.is_file())
        assert written == sorted(p.relative_to(tmp_path / f"{format}-file")
                                 for p in (tmp_path / f"{format}-file").rglob("*") if p.is_file())
        for path in written:
            assert ((tmp_path / format / path).read_bytes()
                    == (tmp_path / f"{format}-file" / path).read_bytes()), path
    for a, b in zip(bouncefit.render(photos, fit), bouncefit.render(photos, tmp_path / "fit.json")):
        assert np.array_equal(a, b)


def test_compare_ranks_the_models(tmp_path):
    report = bouncefit.compare(COPPER, ["single", "kulla-conty"], tmp_path / "report")
    text = json.dumps(report)
    assert "kulla-conty" in text and "single" in text
    assert (tmp_path / "report" / "single" / "fit.json").is_file()


def test_a_fit_releases_the_gil():
    ticks = 0
    thread = threading.Thread(target=bouncefit.fit, args=(COPPER, ["single", "kulla-conty"]))
    thread.start()
    while thread.is_alive():
        time.sleep(0.001)
        ticks += 1
    assert ticks > 50


UNUSED = "/tmp/bouncefit-unused.json"


@pytest.mark.parametrize(
    "call, flags, exception",
    [
        (lambda: bouncefit.fit("datasets/no-such-set"),
         ["fit", "datasets/no-such-set", "-o", UNUSED], bouncefit.FileError),
        (lambda: bouncefit.fit(COPPER, "no-such-model"),
         ["fit", COPPER, "--models", "no-such-model", "-o", UNUSED], bouncefit.InvalidInputError),
        (lambda: bouncefit.fit(COPPER, pixel_samples=5),
         ["fit", COPPER, "--pixel-samples", "5", "-o", UNUSED], bouncefit.InvalidInputError),
        (lambda: bouncefit.export(f"{COPPER}/material.json", "obj", UNUSED),
         ["export", f"{COPPER}/material.json", "--format", "obj", "-o", UNUSED],
         bouncefit.InvalidInputError),
    ],
)
def test_errors_carry_the_command_lines_message(call, flags, exception):
    stderr = cli_error(*flags)
    with pytest.raises(exception) as raised:
        call()
    assert isinstance(raised.value, bouncefit.BouncefitError)
    assert f"error: {raised.value}" in stderr


def test_a_broken_manifest_is_invalid_input_naming_the_file(broken_set):
    stderr = cli_error("fit", broken_set, "-o", broken_set / "fit.json")
    with pytest.raises(bouncefit.InvalidInputError) as raised:
        bouncefit.fit(broken_set)
    assert isinstance(raised.value, ValueError)
    assert "capture.toml" in str(raised.value)
    assert stderr.strip() == f"error: {raised.value}"


def test_the_quickstart_example_runs(capsys, monkeypatch):
    monkeypatch.setattr("sys.argv", ["quickstart.py", "--texels", "16x16"])
    runpy.run_path(str(ROOT / "python" / "examples" / "quickstart.py"), run_name="__main__")
    printed = capsys.readouterr().out
    assert re.search(r"copper-flash: single, alpha 0\.30\d\d", printed), printed
    assert re.search(r"two-materials: maps 16x16, base materials .*metal alpha 0\.6", printed), printed
    assert "held-out photo 8 predicted to" in printed and ".gltf" in printed
