"""A board bent by the lens: OpenCV's omnidirectional camera sample (examples/opencv-omnidir).

`sample.jpg` is a 640 x 480 view, through a lens of about 360 degrees, of a flat board of 6 x 9 inner
corners; in the image its grid lines are strongly bent. OpenCV's tutorial gives the board's corner
points in 15 views at 1280 x 960 (omni_calib_data.xml, view 0 is this photo), and camera.json is
the Mei camera that cv2.omnidir calibrates from the other 14 (bench/omnidir_camera.py). With that
camera held fixed, one board pose must explain every corner of this photo: what it cannot is the
corners' own error plus what the model leaves out, the same for every detector.
"""
import json
import os

import numpy as np
import pytest

import conic_corners as cc

cv2 = pytest.importorskip("cv2")

PHOTOS = os.path.join(os.path.dirname(__file__), "..", "..", "..", "examples", "opencv-omnidir")


def mei_project(obj, pose, K, xi, D):
    """Mei's unified model: the point on the unit sphere, projected from (0, 0, -xi), then
    OpenCV's radial and tangential distortion (k1, k2, p1, p2) and K; as cv2.omnidir."""
    rvec, tvec = pose[:3], pose[3:]
    R = cv2.Rodrigues(rvec)[0]
    X = obj @ R.T + tvec
    s = X / np.linalg.norm(X, axis=1, keepdims=True)
    x, y = s[:, 0] / (s[:, 2] + xi), s[:, 1] / (s[:, 2] + xi)
    k1, k2, p1, p2 = D
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], 1)


def camera_at_half_size():
    """camera.json (1280 x 960) for the 640 x 480 photo; pixel centres at integers on both
    sides, so x_half = (x_full - 0.5) / 2."""
    cam = json.load(open(os.path.join(PHOTOS, "camera.json")))
    K = np.array(cam["K"]) / 2
    K[2, 2] = 1
    K[0, 2] -= 0.25
    K[1, 2] -= 0.25
    return K, cam["xi"], np.array(cam["D"])


def pose_rms(obj, img, camera):
    """RMS (px) of the best single pose: started from `cv2.solvePnP` on the points lifted to the
    unit sphere (distortion ignored) and seen from their mean direction, then
    Levenberg-Marquardt on all six parameters."""
    obj = np.asarray(obj, float)
    img = np.asarray(img, float).reshape(-1, 2)
    K, xi, _ = camera

    def residual(p):
        return (mei_project(obj, p, *camera) - img).ravel()

    m = np.linalg.solve(K, np.column_stack([img, np.ones(len(img))]).T).T
    r2 = m[:, 0] ** 2 + m[:, 1] ** 2
    f = (xi + np.sqrt(1 + (1 - xi * xi) * r2)) / (r2 + 1)
    rays = np.column_stack([f * m[:, 0], f * m[:, 1], f - xi])
    z = rays.mean(0) / np.linalg.norm(rays.mean(0))
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    turn = np.array([x, np.cross(z, x), z])  # rows: the new frame's axes
    seen = rays @ turn.T
    ok, rvec, tvec = cv2.solvePnP(obj, seen[:, :2] / seen[:, 2:], np.eye(3), None)
    assert ok
    R = turn.T @ cv2.Rodrigues(rvec)[0]
    p = np.concatenate([cv2.Rodrigues(R)[0].ravel(), turn.T @ tvec.ravel()])
    lam = 1e-3
    for _ in range(200):
        r = residual(p)
        J = np.empty((r.size, 6))
        for k in range(6):
            dp = np.zeros(6)
            dp[k] = 1e-6 * max(1.0, abs(p[k]))
            J[:, k] = (residual(p + dp) - r) / dp[k]
        A = J.T @ J
        step = np.linalg.solve(A + lam * np.diag(np.diag(A)), -J.T @ r)
        if np.sum(residual(p + step) ** 2) < np.sum(r**2):
            p, lam = p + step, lam / 3
        else:
            lam *= 4
    return float(np.sqrt(np.mean(residual(p).reshape(-1, 2) ** 2) * 2))


def test_the_lens_s_bent_board_fits_one_pose_better_than_with_opencv_s_corners():
    img = cv2.imread(os.path.join(PHOTOS, "sample.jpg"), cv2.IMREAD_GRAYSCALE)
    boards = cc.detect(img)
    assert len(boards) == 1
    b = boards[0]
    assert sorted((b.rows, b.cols)) == [6, 9] and len(b) == 54, b
    camera = camera_at_half_size()
    ours = pose_rms(b.object_points(), b.image_points(), camera)

    ok, found = cv2.findChessboardCorners(img, (6, 9))
    assert ok
    board = np.zeros((54, 3))
    board[:, :2] = np.mgrid[0:6, 0:9].T.reshape(-1, 2)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    opencv = {
        w: pose_rms(board, cv2.cornerSubPix(img, found.copy(), (w, w), (-1, -1), criteria), camera)
        for w in (3, 5, 7)
    }
    # Measured: 0.214 px (0.213 with refine="local") against cornerSubPix's 0.500 / 0.234 /
    # 0.232 px (windows 3 / 5 / 7); the tutorial's own points of this view, found at full size
    # and halved, give 0.515 px. The camera model's own floor is most of all of them.
    assert ours < 0.23, (ours, opencv)
    assert ours < 0.95 * min(opencv.values()), (ours, opencv)
