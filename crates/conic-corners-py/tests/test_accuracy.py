"""Known-answer accuracy: refine on a synthetic corner, detect on rendered flat boards, and a
round trip through cv2.calibrateCamera."""

import numpy as np
import pytest

import conic_corners as cc
import render as R

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
# (rx, ry, rz) degrees and t (mm) of six views of a 9×7-square board of 30 mm squares.
VIEWS = [
    ((15, -20, 5), (-120, -100, 650)),
    ((-20, 15, -8), (-140, -90, 620)),
    ((25, 20, 3), (-150, -110, 700)),
    ((-10, -25, 10), (-110, -120, 640)),
    ((5, 30, -4), (-135, -95, 680)),
    ((-25, -10, 12), (-125, -115, 600)),
]


def board(view) -> R.FlatBoard:
    (rx, ry, rz), t = view
    r, t = R.look_at_pose(rx, ry, rz, t)
    return R.FlatBoard(K, r, t)


@pytest.fixture(scope="module")
def rendered():
    """The six views, rendered once: (board, uint8 image)."""
    return [(b, R.to_u8(b.render())) for b in map(board, VIEWS)]


@pytest.mark.parametrize("blur", [0.7, 1.5])
@pytest.mark.parametrize("centre,angles", [((47.3, 48.6), (20.0, 105.0)), ((50.71, 44.18), (-35.0, 40.0))])
def test_refine_synthetic_corner_within_0_02_px(blur, centre, angles):
    img = R.x_corner(centre=centre, angles_deg=angles, blur=blur)
    truth = np.array(centre)
    start = np.round(truth) + [1.0, -1.0]  # ~1.5 px off, as a pixel-level detector gives
    for image in (img.astype(np.float32), R.to_u8(img)):
        p, status = cc.refine(image, start[None, :])
        assert status.tolist() == [cc.CONVERGED]
        assert np.linalg.norm(p[0] - truth) < 0.02, (p[0], truth)


def test_refine_keeps_shape_and_dtype():
    img = R.to_u8(R.x_corner())
    for shape in [(1, 2), (1, 1, 2)]:
        for dtype in (np.float32, np.float64):
            start = np.array([48.0, 48.0], dtype).reshape(shape)
            p, status = cc.refine(img, start)
            assert p.shape == shape and p.dtype == dtype
            assert status.shape == (1,) and status.dtype == np.uint8
            assert start.ravel().tolist() == [48.0, 48.0], "input not modified"
            assert np.linalg.norm(p.reshape(2) - [47.3, 48.6]) < 0.02


def test_refine_off_corner_and_outside_fail_with_start_position():
    img = R.to_u8(R.x_corner())
    start = np.array([[5.0, 5.0], [-20.0, 10.0], [500.0, 3.0]])
    p, status, residuals = cc.refine(img, start, return_residuals=True)
    assert status.tolist() == [cc.FAILED] * 3
    np.testing.assert_array_equal(p, start)
    assert np.isnan(residuals).all()


def test_detect_flat_board_rows_cols_and_accuracy(rendered):
    for i, (b, img) in enumerate(rendered):
        boards = cc.detect(img)
        assert len(boards) == 1, f"view {i}: {boards}"
        found = boards[0]
        assert (found.rows, found.cols) == b.inner_shape
        assert len(found) == found.rows * found.cols
        truth = b.image_corners()
        # Labels may be any of the grid's symmetries; positions must match the truth one-to-one.
        t = truth.reshape(-1, 2)
        d = np.linalg.norm(found.points[:, None, :] - t[None, :, :], axis=2)
        nearest = d.argmin(1)
        assert len(set(nearest.tolist())) == len(t)
        err = d.min(1)
        assert err.max() < 0.05, f"view {i}: max error {err.max():.4f} px"
        assert (found.status == cc.CONVERGED).all()
        # The labels follow the grid: (row, col) maps to the true (row, col) by a symmetry.
        tr, tc = np.divmod(nearest, b.inner_shape[1])
        ids = found.ids
        for k in range(1, len(ids)):
            dr, dc = ids[k] - ids[0]
            tdr, tdc = tr[k] - tr[0], tc[k] - tc[0]
            assert sorted([abs(dr), abs(dc)]) == sorted([abs(tdr), abs(tdc)])


def test_board_helpers_follow_point_order(rendered):
    found = cc.detect(rendered[0][1])[0]
    obj = found.object_points(0.03)
    assert obj.shape == (len(found), 3) and obj.dtype == np.float32
    np.testing.assert_allclose(obj[:, 0], found.ids[:, 1] * 0.03, rtol=1e-6)
    np.testing.assert_allclose(obj[:, 1], found.ids[:, 0] * 0.03, rtol=1e-6)
    assert (obj[:, 2] == 0).all()
    ip = found.image_points()
    assert ip.shape == (len(found), 1, 2) and ip.dtype == np.float32
    np.testing.assert_allclose(ip[:, 0, :], found.points, atol=1e-4)
    assert found.status_names == ["converged"] * len(found)
    assert found.points.dtype == np.float64 and found.ids.dtype == np.int32


def test_detect_with_expected_corner_count(rendered):
    b, img = rendered[1]
    rows, cols = b.inner_shape
    boards = cc.detect(img, corners=rows * cols)
    assert len(boards) == 1 and (boards[0].rows, boards[0].cols) == (rows, cols)


def test_detect_on_blank_image_finds_nothing():
    assert cc.detect(np.full((120, 160), 77, np.uint8)) == []


def test_calibrate_camera_round_trip(rendered):
    cv2 = pytest.importorskip("cv2")
    obj, img_pts = [], []
    for b, img in rendered:
        boards = cc.detect(img)
        assert len(boards) == 1
        found = boards[0]
        assert (found.rows, found.cols) == b.inner_shape
        obj.append(found.object_points(30.0))
        img_pts.append(found.image_points())
    rms, k, dist, _, _ = cv2.calibrateCamera(obj, img_pts, (640, 480), None, None)
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    assert rms < 0.1, rms
    for got, want in [(fx, 800), (fy, 800), (cx, 320), (cy, 240)]:
        assert abs(got - want) < 0.005 * want, (fx, fy, cx, cy)
