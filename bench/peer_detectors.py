"""Board-level peer detectors shared by bench/detect_speed.py and bench/board_peers.py.

Every function takes a grey u8 image (H, W) and returns an (N, 2) float array of corners, x right,
y down, the centre of the top-left pixel at (0, 0) (the convention bench/peers.py --selftest checks
for each library); a failure to find a board is an empty array, not an exception.

  opencv_fcc          findChessboardCorners(pattern, default flags) then, if found,
                      cornerSubPix(winSize (5, 5), zeroZone (-1, -1), EPS+COUNT 40 / 0.001).
  opencv_sb           findChessboardCornersSB(pattern, flags) (flags: 0 or CALIB_CB_ACCURACY).
  libcbdetect_board   Geiger et al.'s detector: min-max normalisation (as in bench/peers.py),
                      find_corners() and find_board_from_corners(); corners = board corners.
  calib_targets       calib_targets.detect_chessboard with default parameters.
  chess_corners       ChESS corners + saddle-point refiner of the given radius, no board
                      structure: a corner detector only.
OpenCV needs the pattern size (inner corners per row, per column); the others find it themselves.
"""
import os
import sys

# peers.py pins the peers' thread pools to one thread before they load.
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import CSP_CRITERIA, libcbdetect_checkerboard, _chess_detector  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402


def _none():
    return np.zeros((0, 2))


def opencv_fcc(img, pattern):
    ok, pts = cv2.findChessboardCorners(img, pattern)
    if not ok:
        return _none()
    pts = cv2.cornerSubPix(img, pts, (5, 5), (-1, -1), CSP_CRITERIA)
    return pts.reshape(-1, 2)


def opencv_sb(img, pattern, flags=0):
    ok, pts = cv2.findChessboardCornersSB(img, pattern, flags=flags)
    return pts.reshape(-1, 2) if ok else _none()


def libcbdetect_board(img):
    cb = libcbdetect_checkerboard(img)
    if cb is None:
        return _none()
    cb.find_corners()
    cb.find_board_from_corners()
    n = int(cb.rows) * int(cb.cols)
    if n <= 0:
        return _none()
    u, v = np.zeros(n), np.zeros(n)
    cb.get_board_corners(u, v)
    pts = np.stack([u, v], axis=1)
    return pts[np.all(np.isfinite(pts), axis=1) & (pts[:, 0] >= 0)]


def calib_targets(img):
    import calib_targets as ct

    r = ct.detect_chessboard(img)
    if r is None:
        return _none()
    return np.array([c.position for c in r.corners], dtype=np.float64).reshape(-1, 2)


def chess_corners(img, radius=2):
    return np.asarray(_chess_detector(radius).detect(np.ascontiguousarray(img)).xy).reshape(-1, 2)
