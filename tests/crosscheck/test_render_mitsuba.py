"""`bouncefit render` of a capture against Mitsuba 3 rendering the scenes that
`bouncefit export --format mitsuba --scene CAPTURE` writes (one scene per photo: the sample with
the roughconductor, a perspective sensor with a box pixel filter, the photo's point light or
flash, the `direct` integrator).

The material is the capture's truth with `height: uncorrelated`, the G2 of Mitsuba's
roughconductor, so the export is exact. Compared: the mean relative difference over the pixels
wholly on the sample (their four corners inside the sample's projected outline, from
`bouncefit records`), all channels and photos; pixels the sample's edge crosses depend on how
each renderer estimates the covered fraction (16 stratified samples against 64 random ones) and
are reported, not asserted. Mitsuba's render is Monte Carlo over each pixel (64 samples); the
difference is printed with the time of both renders, measured in the same run.
"""

import time

import cv2
import mitsuba as mi
import numpy as np
import pytest

from conftest import CAPTURES, exported_scenes, read_exr, report, run, run_json

TOLERANCE = 0.01


def wholly_on_sample(photo):
    """Per pixel: are all four pixel corners inside the sample's projected outline?"""
    width, height = photo["resolution"]
    outline = np.array(photo["corners"]["pixel"], dtype=np.float32).reshape(-1, 1, 2)
    rows, columns = np.mgrid[0 : height + 1, 0 : width + 1]
    inside = np.array(
        [cv2.pointPolygonTest(outline, (float(x), float(y)), True) >= -1e-9 for x, y in zip(columns.ravel(), rows.ravel())]
    ).reshape(height + 1, width + 1)
    return inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]


@pytest.mark.parametrize("capture", CAPTURES)
def test_render_matches_mitsuba(tmp_path, capture):
    folder, material = exported_scenes(tmp_path, capture)

    start = time.perf_counter()
    run("render", "--capture", folder, "--material", tmp_path / "material.json", "--pixel-samples", 16,
        "-o", tmp_path / "ours")
    ours_seconds = time.perf_counter() - start

    photos = run_json("records", folder)["photos"]
    differences, edges, mitsuba_seconds = [], [], 0.0
    for photo in photos:
        start = time.perf_counter()
        image = np.array(mi.render(mi.load_file(str(tmp_path / "scenes" / f"{photo['stem']}.xml"))), dtype=np.float64)
        mitsuba_seconds += time.perf_counter() - start
        ours = read_exr(tmp_path / "ours" / f"{photo['stem']}.exr")
        assert image.shape == ours.shape
        inside = wholly_on_sample(photo)
        on_sample = ours.sum(-1) > 0
        assert inside.sum() > 0.3 * inside.size and (ours[inside] > 0).all()
        relative = np.abs(image - ours) / np.where(ours > 0, ours, 1.0)
        differences.append(relative[inside])
        edges.append(relative[on_sample & ~inside])
    mean = np.concatenate(differences).mean()
    report(f"{capture}: bouncefit render vs Mitsuba 3, mean relative over wholly covered pixels", mean, TOLERANCE)
    edges = np.concatenate(edges)
    edge_text = f"mean {edges.mean():.3e} over {edges.size} values" if edges.size else "none (rectified)"
    print(f"  worst single value {np.concatenate(differences).max():.3e}; edge pixels (partly covered): {edge_text}")
    print(f"  time for {len(photos)} photos: Mitsuba 3 scalar_rgb (64 spp, load + render) {mitsuba_seconds:.2f} s, "
          f"bouncefit render (16 samples per pixel, whole command) {ours_seconds:.2f} s")
    assert mean < TOLERANCE
