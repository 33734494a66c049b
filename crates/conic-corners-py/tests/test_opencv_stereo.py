"""Real photos with a calibrated camera as the yardstick: OpenCV's stereo calibration sample
(examples/opencv-stereo, 13 photos per camera, 640 x 480 JPEG, a board of 9 x 6 inner corners) and
its ChArUco photo (examples/opencv-charuco, ArUco markers in the white squares).

The photos have no ground truth, but one pinhole camera with OpenCV's five distortion coefficients
must explain every view; what it cannot explain is the corners' own error plus what the model
leaves out (the same for every detector). bench/stereo_calib.py compares all the peers this way.
"""
import glob
import os

import numpy as np
import pytest

import conic_corners as cc

cv2 = pytest.importorskip("cv2")

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "examples")
PHOTOS = os.path.join(EXAMPLES, "opencv-stereo")
CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 0.001)


def photos(side):
    paths = sorted(glob.glob(os.path.join(PHOTOS, f"{side}[0-9][0-9].jpg")))
    assert len(paths) == 13, paths
    return [cv2.imread(p, cv2.IMREAD_GRAYSCALE) for p in paths]


def calibration_rms(views):
    obj = [o for o, _ in views]
    img = [i for _, i in views]
    return cv2.calibrateCamera(obj, img, (640, 480), None, None)[0]


@pytest.mark.parametrize("side", ["left", "right"])
def test_every_corner_found_and_the_camera_fits_better_than_with_opencv_s(side):
    ours, opencv = [], {5: [], 7: []}
    for img in photos(side):
        boards = cc.detect(img)
        assert len(boards) == 1
        b = boards[0]
        assert sorted((b.rows, b.cols)) == [6, 9] and len(b) == 54, b
        assert len({tuple(i) for i in b.ids}) == 54
        assert np.all(np.isfinite(b.sigmas))
        ours.append((b.object_points(), b.image_points()))
        ok, found = cv2.findChessboardCorners(img, (9, 6))
        assert ok
        board = np.zeros((54, 3), np.float32)
        board[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
        for win in opencv:
            pts = cv2.cornerSubPix(img, found.copy(), (win, win), (-1, -1), CRITERIA)
            opencv[win].append((board, pts))
    rms = calibration_rms(ours)
    best_opencv = min(calibration_rms(v) for v in opencv.values())
    # Measured: 0.160 / 0.159 px (left / right) against OpenCV's best window (7 x 7) 0.183 /
    # 0.188 px; the model's own floor is most of both.
    assert rms < 0.2, rms
    assert rms < 0.95 * best_opencv, (rms, best_opencv)


def test_charuco_photo_labels_match_opencv_s_charuco_ids_and_fit_its_camera():
    """The markers in the white squares are no corners, the 24 junctions are labelled as
    OpenCV's ChArUco detector numbers them (up to the grid's symmetries), and with the camera
    calibrated by OpenCV from other photos the corners fit one pose better than its own."""
    if not hasattr(cv2, "aruco"):
        pytest.skip("this OpenCV has no aruco module")
    folder = os.path.join(EXAMPLES, "opencv-charuco")
    img = cv2.imread(os.path.join(folder, "choriginal.jpg"), cv2.IMREAD_GRAYSCALE)
    calib = cv2.FileStorage(os.path.join(folder, "tutorial_camera_charuco.yml"),
                            cv2.FILE_STORAGE_READ)
    k = calib.getNode("camera_matrix").mat()
    dist = calib.getNode("distortion_coefficients").mat()
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250)
    board = cv2.aruco.CharucoBoard((5, 7), 0.04, 0.02, dictionary)
    theirs, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(img)
    theirs, ids = theirs.reshape(-1, 2).astype(np.float64), ids.ravel()
    assert len(ids) == 24

    boards = cc.detect(img)
    assert len(boards) == 1
    b = boards[0]
    assert sorted((b.rows, b.cols)) == [4, 6] and len(b) == 24, b
    d = np.linalg.norm(b.points[:, None, :] - theirs[None, :, :], axis=2)
    nearest = d.argmin(axis=1)
    # Measured: 0.16 px median, 0.41 px at most (OpenCV's ChArUco corners are themselves a few
    # tenths of a pixel apart from its cornerSubPix on them).
    assert sorted(nearest.tolist()) == list(range(24)), nearest
    assert d.min(axis=1).max() < 0.6, d.min(axis=1)
    # Their (row, col) from the ids, 4 per row; ours must map onto them by a grid isometry.
    rc = np.stack([ids[nearest] // 4, ids[nearest] % 4], axis=1).astype(np.float64)
    a = np.hstack([b.ids.astype(np.float64), np.ones((24, 1))])
    m, *_ = np.linalg.lstsq(a, rc, rcond=None)
    assert np.allclose(a @ m, rc, atol=1e-9)
    # A signed permutation of the axes: one of the grid's eight symmetries.
    assert np.allclose(np.sort(np.abs(m[:2]).ravel()), [0, 0, 1, 1])
    assert np.isclose(abs(np.linalg.det(m[:2])), 1.0) and np.allclose(np.round(m), m)

    def pose_rms(obj, pts):
        pts = np.ascontiguousarray(pts, dtype=np.float32)
        ok, r, t = cv2.solvePnP(obj, pts, k, dist)
        assert ok
        proj, _ = cv2.projectPoints(obj, r, t, k, dist)
        return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - pts) ** 2, axis=1))))

    board_points = np.array([[(i % 4 + 1) * 0.04, (i // 4 + 1) * 0.04, 0.0] for i in ids],
                            np.float32)
    ours = pose_rms(b.object_points(0.04), b.points)
    opencv = pose_rms(board_points, theirs)
    # Measured: 0.184 px against 0.216 px.
    assert ours < 0.25 and ours < opencv, (ours, opencv)


def test_a_known_pattern_labels_every_view_in_the_print_s_frame():
    """With ``pattern=(6, 9)`` every photo's board comes in the print's frame: (0, 0) at the
    corner whose first square is dark. On all 26 photos of this sample that is where
    cv2.findChessboardCorners starts, so in row-major order the corners pair with OpenCV's one to
    one; calibration can take the object points of every view as they are."""
    for side in ("left", "right"):
        for img in photos(side):
            boards = cc.detect(img, pattern=(6, 9))
            assert len(boards) == 1
            b = boards[0]
            assert (b.rows, b.cols, len(b)) == (6, 9, 54)
            order = np.lexsort((b.ids[:, 1], b.ids[:, 0]))
            ok, found = cv2.findChessboardCorners(img, (9, 6))
            assert ok
            found = cv2.cornerSubPix(img, found, (5, 5), (-1, -1), CRITERIA)
            # OpenCV's refined corners lie up to 0.52 px from ours here; a corner paired with
            # the wrong board point would be a square (20-40 px) away.
            gap = np.linalg.norm(b.points[order] - found.reshape(-1, 2), axis=1)
            assert gap.max() < 1.5, gap.max()
    # No board spans another pattern; a pattern without squares is refused.
    assert cc.detect(img, pattern=(6, 8)) == []
    with pytest.raises(ValueError, match="pattern"):
        cc.detect(img, pattern=(1, 9))
