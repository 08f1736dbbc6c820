"""`bouncefit capture` (kornia-apriltag detection, DLT homography, Zhang + Levenberg-Marquardt
pose) against OpenCV on the same phone photos.

| step | reference | compared | tolerance |
| --- | --- | --- | --- |
| tag corners | cv2.aruco (DICT_APRILTAG_36h11, AprilTag corner refinement) | every tag both find, every corner | 0.75 px worst, 0.25 px RMS, 0.1 px mean offset |
| homography | cv2.findHomography (least squares, all points) on the tool's corners | the sample window's corners mapped by both | 0.05 px |
| pose | cv2.solvePnP (iterative) on the tool's corners with the tool's K, distortion and print scale | rotation angle, translation | 0.05 degrees, 0.2% of distance |

The photos are `synth --board --format phone` renders (800x600 JPEG, 1% noise) of the
bundled phone capture template. Conventions, measured on these photos: cv2.aruco's AprilTag
corners already put pixel centres at half-integers as the tool does (mean offset 0.06 px
unshifted, 0.44 px shifted by half a pixel; the tool's corners are unbiased against the
synthetic truth, `board::tests`), and it starts each tag's corners at the tag's bottom-right,
two steps round from the AprilTag reference's top-left. cv2.solvePnP takes the tool's pixels
shifted to OpenCV's integer centres.
"""

import json

import cv2
import numpy as np
import pytest

from conftest import ROOT, report, run

CORNER_TOLERANCE = 0.75
CORNER_RMS = 0.25
CORNER_BIAS = 0.1
HOMOGRAPHY_TOLERANCE = 0.05
ANGLE_TOLERANCE_DEG = 0.05
TRANSLATION_TOLERANCE = 2e-3
ARUCO_CORNER_SHIFT = 2


@pytest.fixture(scope="module")
def captured(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("phone")
    run("board", "-o", tmp / "board", "--dpi", "100")
    board_toml = tmp / "board" / "board.toml"
    run("synth", "--material", ROOT / "datasets/sources/copper-a03.material.json",
        "--capture", ROOT / "datasets/sources/phone-board.capture.toml",
        "--board", board_toml, "--format", "phone", "--noise", "0.01", "-o", tmp / "photos")
    photos = sorted((tmp / "photos").glob("*.jpg"))
    run("capture", *photos, "--board", board_toml, "-o", tmp / "set")
    report_json = json.loads((tmp / "set" / "capture-report.json").read_text())
    board_text = board_toml.read_text()
    return photos, report_json, board_text


def board_corners(board_text):
    """Tag id -> its 4 board-frame corners (TL, TR, BR, BL), parsed from board.toml."""
    import tomllib
    board = tomllib.loads(board_text)
    h = board["tag_size"] / 2
    return {t["id"]: np.array([[t["center"][0] + dx, t["center"][1] + dy] for dx, dy in
                               [(-h, h), (h, h), (h, -h), (-h, -h)]]) for t in board["tag"]}, board


def test_tag_corners_match_opencv_aruco(captured):
    photos, rep, _ = captured
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    detector = cv2.aruco.ArucoDetector(dictionary, params)
    worst, offsets = 0.0, []
    for path, photo in zip(photos, rep["photos"]):
        corners, ids, _ = detector.detectMarkers(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE))
        # cv2.aruco starts a tag's corners two steps round from the tool's top-left.
        theirs = {int(i): np.roll(c.reshape(4, 2), ARUCO_CORNER_SHIFT, axis=0)
                  for i, c in zip(ids.ravel(), corners)}
        ours = {int(t[0]): np.array(t[1]) for t in photo["tags"]}
        common = set(ours) & set(theirs)
        assert len(common) >= len(ours) - 1, f"{path.name}: OpenCV found {sorted(theirs)}, we {sorted(ours)}"
        for i in common:
            d = ours[i] - theirs[i]
            offsets.append(d)
            worst = max(worst, np.linalg.norm(d, axis=1).max())
    offsets = np.concatenate(offsets)
    bias = np.abs(offsets.mean(axis=0)).max()
    rms = np.sqrt((offsets ** 2).sum(axis=1).mean())
    report("tag corners vs cv2.aruco", worst, CORNER_TOLERANCE)
    report("corner RMS difference", rms, CORNER_RMS)
    report("mean corner offset", bias, CORNER_BIAS)
    assert worst < CORNER_TOLERANCE
    assert rms < CORNER_RMS
    assert bias < CORNER_BIAS


def printed(rep, c):
    """A tag's corners as the tool found the board printed: scaled about the tag's centre."""
    c = np.asarray(c, dtype=float)
    centre = c.mean(axis=0)
    return centre + rep["print"]["tag_scale"] * (c - centre)


def test_homographies_match_cv2_find_homography(captured):
    _, rep, board_text = captured
    corners, board = board_corners(board_text)
    w, h = board["window"]["width"] / 2, board["window"]["height"] / 2
    window = np.array([[[-w, h]], [[w, h]], [[w, -h]], [[-w, -h]]])
    worst = 0.0
    for photo in rep["photos"]:
        src = np.concatenate([printed(rep, corners[t[0]]) for t in photo["tags"]])
        dst = np.concatenate([np.array(t[1]) for t in photo["tags"]])
        theirs, _ = cv2.findHomography(src, dst, 0)
        ours = np.array(photo["homography"])
        a = cv2.perspectiveTransform(window, ours)
        b = cv2.perspectiveTransform(window, theirs)
        worst = max(worst, np.abs(a - b).max())
    report("window corners by homography vs cv2.findHomography", worst, HOMOGRAPHY_TOLERANCE)
    assert worst < HOMOGRAPHY_TOLERANCE


def test_poses_match_cv2_solve_pnp(captured):
    _, rep, board_text = captured
    corners, _ = board_corners(board_text)
    f, (cx, cy) = rep["focal_px"], rep["principal_point"]
    k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    # The lens and the print as the tool fitted them: OpenCV's first two radial coefficients
    # are the tool's k1, k2; the tags' squares scaled about their centres.
    distortion = np.array([*rep["distortion"], 0.0, 0.0])
    worst_angle, worst_t = 0.0, 0.0
    for photo in rep["photos"]:
        obj = np.concatenate([np.c_[printed(rep, corners[t[0]]), np.zeros(4)] for t in photo["tags"]])
        # The tool's pixels have centres at half-integers; cv2 at integers.
        img = np.concatenate([np.array(t[1]) for t in photo["tags"]]) - 0.5
        ok, rvec, tvec = cv2.solvePnP(obj, img, k - np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]), distortion,
                                      flags=cv2.SOLVEPNP_ITERATIVE)
        assert ok
        r_ours, _ = cv2.Rodrigues(np.array(photo["rotation_vector"]))
        r_theirs, _ = cv2.Rodrigues(rvec)
        angle = np.degrees(np.arccos(np.clip((np.trace(r_ours.T @ r_theirs) - 1) / 2, -1, 1)))
        t_ours = np.array(photo["translation"])
        rel = np.linalg.norm(t_ours - tvec.ravel()) / np.linalg.norm(t_ours)
        worst_angle, worst_t = max(worst_angle, angle), max(worst_t, rel)
    report("pose rotation vs cv2.solvePnP (deg)", worst_angle, ANGLE_TOLERANCE_DEG)
    report("pose translation vs cv2.solvePnP (relative)", worst_t, TRANSLATION_TOLERANCE)
    assert worst_angle < ANGLE_TOLERANCE_DEG
    assert worst_t < TRANSLATION_TOLERANCE
