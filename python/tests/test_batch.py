"""The batch run on a local two-process Dask cluster: a broken set among good ones, results
equal to the command line's, a rerun that skips what is done."""

import csv
import json
import shutil
import subprocess
import sys

from conftest import ROOT, cli, cli_error, read_fit

GOOD = ["copper-flash", "aluminium-pinhole"]
# Uniform fits with the last photo held out: the summary's held-out error is the fit file's.
FLAGS = ["--models", "single,kulla-conty", "--", "--holdout-photo", "8"]


def batch(*args):
    return subprocess.run([sys.executable, "-m", "bouncefit.batch", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT)


def test_batch_fits_each_set_as_the_command_line_does(tmp_path, broken_set):
    sets = tmp_path / "sets"
    sets.mkdir()
    for name in GOOD:
        shutil.copytree(ROOT / "datasets" / name, sets / name)
    shutil.move(broken_set, sets / "broken")
    out = tmp_path / "out"

    done = batch(sets, "-o", out, "--workers", "2", *FLAGS)
    assert done.returncode == 1, done.stderr
    rows = {r["set"]: r for r in json.loads((out / "summary.json").read_text())}
    assert sorted(rows) == ["aluminium-pinhole", "broken", "copper-flash"]
    with open(out / "summary.csv", newline="") as f:
        assert [r["status"] for r in csv.DictReader(f)] == ["ok", "failed", "ok"]

    # The broken set's row carries the command line's message; the others are its fits.
    message = cli_error("fit", sets / "broken", "-o", tmp_path / "unused.json")
    assert message.strip() == f"error: {rows['broken']['error']}"
    for name in GOOD:
        cli("fit", sets / name, "--models", "single,kulla-conty", "--holdout-photo", "8",
            "-o", tmp_path / f"{name}.json", "--quiet")
        expected = read_fit(tmp_path / f"{name}.json")
        assert read_fit(out / "fits" / f"{name}.json") == expected
        assert [rows[name]["alpha_x"], rows[name]["alpha_y"]] == expected["alpha"]
        assert rows[name]["model"] == expected["model"]
        assert rows[name]["heldout_error"] == expected["holdout"]["relative_error"] > 0
    index = json.loads((out / "library" / "index.json").read_text())
    assert sorted(m["set"] for m in index["materials"]) == sorted(GOOD)
    for material in index["materials"]:
        gltf = json.loads((out / "library" / material["gltf"]).read_text())
        assert gltf["materials"]

    # A rerun fits only what failed: the good sets' files are left as they were.
    written = {n: (out / "fits" / f"{n}.json").stat().st_mtime_ns for n in GOOD}
    again = batch(sets, "-o", out, "--workers", "2", *FLAGS)
    assert "3 photo sets, 2 already fitted" in again.stdout
    assert {n: (out / "fits" / f"{n}.json").stat().st_mtime_ns for n in GOOD} == written
    assert "broken: failed" in again.stdout
