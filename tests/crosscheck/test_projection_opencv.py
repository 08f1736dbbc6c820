"""The tool's cameras (`bouncefit records`) against OpenCV.

| camera | reference | compared |
| --- | --- | --- |
| pinhole | cv2.projectPoints with K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], no distortion, and the extrinsics the tool prints (rotation rows right, -up, forward) | the sample's 4 corners and 64 random sample points, every photo |
| pinhole extrinsics | cv2.solvePnP from the tool's own corner pixels | recovers the tool's rotation and translation |
| rectified | cv2.findHomography from the 4 corners (sample plane -> pixels), then cv2.perspectiveTransform | 64 random sample points, every photo: the rectified image is the plane homography of its corners |
| rectified vs pinhole | cv2.warpPerspective of the tool's pinhole render onto the rectified grid by that homography | the tool's rectified render from the same position, pixels away from the edge |

Pixel positions are continuous coordinates (the tool's pixel (c, r) covers [c, c+1] x [r, r+1]); both
implementations use the same K, so no half-pixel shift enters.
"""

import json

import cv2
import numpy as np
import pytest

from conftest import CAPTURES, ROOT, read_exr, report, run, run_json

PIXEL_TOLERANCE = 1e-9


def records(capture):
    return run_json("records", ROOT / "datasets" / capture, "--points", 64, "--seed", 3)


def intrinsics(camera):
    return np.array([[camera["fx"], 0, camera["cx"]], [0, camera["fy"], camera["cy"]], [0, 0, 1.0]])


def pinhole_photos():
    return [(c, p) for c in CAPTURES for p in records(c)["photos"] if p["camera"]["model"] == "pinhole"]


def rectified_photos():
    return [(c, p) for c in CAPTURES for p in records(c)["photos"] if p["camera"]["model"] == "rectified"]


def test_every_capture_has_photos_of_a_known_model():
    models = {p["camera"]["model"] for c in CAPTURES for p in records(c)["photos"]}
    assert models == {"pinhole", "rectified"}


def test_pinhole_projection_matches_cv2_project_points():
    worst = 0.0
    for capture, photo in pinhole_photos():
        extrinsics = photo["world_to_camera"]
        rvec, _ = cv2.Rodrigues(np.array(extrinsics["rotation"]))
        tvec = np.array(extrinsics["translation"])
        for kind in ("corners", "points"):
            world = np.array(photo[kind]["world"])
            ours = np.array(photo[kind]["pixel"], dtype=np.float64)
            reference, _ = cv2.projectPoints(world, rvec, tvec, intrinsics(photo["camera"]), None)
            worst = max(worst, np.abs(ours - reference.reshape(-1, 2)).max())
    report("pinhole projection vs cv2.projectPoints (px)", worst, PIXEL_TOLERANCE)
    assert worst < PIXEL_TOLERANCE


def test_pinhole_extrinsics_are_what_solve_pnp_recovers_from_the_corners():
    worst = 0.0
    for capture, photo in pinhole_photos():
        world = np.array(photo["corners"]["world"] + photo["points"]["world"])
        pixel = np.array(photo["corners"]["pixel"] + photo["points"]["pixel"], dtype=np.float64)
        ok, rvec, tvec = cv2.solvePnP(world, pixel, intrinsics(photo["camera"]), None, flags=cv2.SOLVEPNP_ITERATIVE)
        assert ok
        rotation, _ = cv2.Rodrigues(rvec)
        # The camera centre -R^T t, compared with the tool's position in capture units.
        centre = -rotation.T @ tvec.ravel()
        worst = max(worst, np.abs(centre - np.array(photo["camera"]["position"])).max())
    report("pinhole camera centre from cv2.solvePnP (capture units)", worst, 1e-6)
    assert worst < 1e-6


def test_rectified_pixels_are_the_homography_of_the_corners():
    worst = 0.0
    for capture, photo in rectified_photos():
        plane = np.array(photo["corners"]["world"])[:, :2]
        homography, _ = cv2.findHomography(plane, np.array(photo["corners"]["pixel"]))
        points = np.array(photo["points"]["world"])[:, :2].reshape(-1, 1, 2)
        reference = cv2.perspectiveTransform(points, homography).reshape(-1, 2)
        worst = max(worst, np.abs(np.array(photo["points"]["pixel"]) - reference).max())
    report("rectified pixels vs cv2.findHomography of the corners (px)", worst, PIXEL_TOLERANCE)
    assert worst < PIXEL_TOLERANCE


def test_rectified_render_is_the_warped_pinhole_render(tmp_path):
    """A rectified photo is what a pinhole camera at the same position sees, warped onto the
    sample rectangle: render both with the tool and warp the pinhole one with OpenCV."""
    position, resolution, sample = [2.0, -6.0, 15.0], 96, 8.0
    light = {"kind": "point", "position": [-3.0, 2.0, 12.0], "intensity": [900.0, 900.0, 900.0]}
    cameras = {
        "pinhole": {"model": "pinhole", "position": position, "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                    "fov_y_deg": 45.0, "resolution": [2 * resolution, 2 * resolution]},
        "rectified": {"model": "rectified", "position": position, "resolution": [resolution, resolution]},
    }
    renders = {}
    for name, camera in cameras.items():
        manifest = {"name": name, "units": "cm", "sample": {"width": sample, "height": sample},
                    "camera": camera, "photo": [{"image": "a.exr", "light": light}]}
        folder = tmp_path / name
        folder.mkdir()
        (folder / "capture.toml").write_text(toml(manifest))
        run("render", "--capture", folder, "--material", ROOT / "datasets/aluminium-pinhole/material.json",
            "--pixel-samples", 16, "-o", tmp_path / f"{name}-render")
        renders[name] = read_exr(tmp_path / f"{name}-render" / "a.exr")
    pinhole = run_json("records", tmp_path / "pinhole")["photos"][0]
    rectified = run_json("records", tmp_path / "rectified")["photos"][0]
    homography, _ = cv2.findHomography(np.array(pinhole["corners"]["pixel"]), np.array(rectified["corners"]["pixel"]))
    # Both pixel grids put centres at half-integers; OpenCV's maps integer to integer.
    shift = lambda d: np.array([[1, 0, d], [0, 1, d], [0, 0, 1.0]])
    homography = shift(-0.5) @ homography @ shift(0.5)
    warped = cv2.warpPerspective(renders["pinhole"], homography, (resolution, resolution), flags=cv2.INTER_LINEAR)
    inner = (slice(4, -4), slice(4, -4))
    difference = np.abs(warped - renders["rectified"])[inner] / renders["rectified"][inner]
    report("warped pinhole render vs rectified render, mean relative", difference.mean(), 5e-4)
    assert difference.mean() < 5e-4


def toml(manifest):
    """The few TOML forms a capture manifest needs (tables, arrays of tables, inline tables)."""
    value = lambda v: json.dumps(v) if not isinstance(v, dict) else "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
    lines = [f"{k} = {value(v)}" for k, v in manifest.items() if not isinstance(v, (dict, list))]
    for key in ("sample", "camera"):
        lines += [f"[{key}]"] + [f"{k} = {value(v)}" for k, v in manifest[key].items()]
    for photo in manifest["photo"]:
        lines += ["[[photo]]"] + [f"{k} = {value(v)}" for k, v in photo.items()]
    return "\n".join(lines) + "\n"
