"""detect's two refine modes: board-wide curve fitting ("board", the default) against the
single-corner refiner ("local"), on rendered flat and cylinder boards with known corners."""

import numpy as np
import pytest

import conic_corners as cc
import render as R

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])


def errors(found: cc.Board, truth: np.ndarray) -> np.ndarray:
    """Distance (px) of each found corner to its nearest true corner, one-to-one checked."""
    t = truth.reshape(-1, 2)
    d = np.linalg.norm(found.points[:, None, :] - t[None, :, :], axis=2)
    assert len(set(d.argmin(1).tolist())) == len(found), "two corners matched one truth"
    return d.min(1)


@pytest.fixture(scope="module")
def scenes():
    """(name, board, uint8 image): a tilted flat board and the same pose on two cylinders."""
    r, t = R.look_at_pose(10, -15, 4, (-135, -100, 600))
    boards = [("flat", R.FlatBoard(K, r, t)),
              ("cylinder r=180", R.CylinderBoard(K, r, t, radius=180.0)),
              ("cylinder r=150", R.CylinderBoard(K, r, t, radius=150.0))]
    return [(name, b, R.to_u8(b.render(s=4))) for name, b in boards]


@pytest.fixture(scope="module")
def detections(scenes):
    """Per scene: (name, board, local Board, board-fit Board)."""
    out = []
    for name, b, img in scenes:
        local, fitted = cc.detect(img, refine="local"), cc.detect(img)
        assert len(local) == 1 and len(fitted) == 1, (name, local, fitted)
        out.append((name, b, local[0], fitted[0]))
    return out


def test_default_is_board(scenes):
    _, _, img = scenes[1]
    a, b = cc.detect(img)[0], cc.detect(img, refine="board")[0]
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.sigmas, b.sigmas)


def test_both_modes_find_the_same_corners(detections):
    for name, b, local, fitted in detections:
        assert (local.rows, local.cols) == (fitted.rows, fitted.cols) == b.inner_shape, name
        np.testing.assert_array_equal(local.ids, fitted.ids, err_msg=name)
        np.testing.assert_array_equal(local.scores, fitted.scores, err_msg=name)
        assert len(fitted) == b.inner_shape[0] * b.inner_shape[1], name


def test_local_mode_has_local_paths_and_sigmas(detections):
    # Only corners the local refiner fails on, or sees on one side only (here the column
    # foreshortened by the cylinder), go to the junction model or the gradient estimate (or, at
    # hairline slivers, the completion's fit), and those are placed as well.
    for name, b, local, _ in detections:
        assert set(local.path_names) <= {"local", "junction", "gradient", "hairline"}, name
        other = local.paths != cc.PATH_LOCAL
        rows, cols = local.ids[:, 0], local.ids[:, 1]
        edge = (rows == 0) | (cols == 0) | (rows == local.rows - 1) | (cols == local.cols - 1)
        assert not (other & ~edge).any(), (name, local.ids[other & ~edge])
        e = errors(local, b.image_corners())
        assert (e[other] < 0.1).all(), (name, e[other])
        placed = local.status != cc.FAILED
        s = local.sigmas
        assert (np.isfinite(s[placed]) & (s[placed] > 0)).mean() > 0.95, name
        assert local.paths.dtype == np.uint8 and local.sigmas.dtype == np.float64


def test_sigma_finite_positive_on_board_path(detections):
    for name, _, _, fitted in detections:
        on_board = fitted.paths == cc.PATH_BOARD
        # Doubtful board answers may take the junction model's (accuracy: next test).
        assert set(fitted.paths.tolist()) <= {
            cc.PATH_LOCAL, cc.PATH_BOARD, cc.PATH_GRADIENT, cc.PATH_JUNCTION, cc.PATH_HAIRLINE}
        assert on_board.mean() > 0.8, f"{name}: only {on_board.sum()}/{len(fitted)} board-fitted"
        s = fitted.sigmas
        assert (np.isfinite(s[on_board]) & (s[on_board] > 0)).all(), name
        # A corner that no refiner could place is not reported.
        assert (fitted.status != cc.FAILED).all(), name
        # A sigma is a small fraction of a pixel on these clean renders (the largest at the
        # ends of strongly bent rows).
        assert s[on_board].max() < 0.25, (name, s[on_board].max())
        assert fitted.path_names == [cc.PATH_NAMES[p] for p in fitted.paths]


def test_board_fit_at_least_as_accurate(detections):
    for name, b, local, fitted in detections:
        el, eb = errors(local, b.image_corners()), errors(fitted, b.image_corners())
        print(f"{name}: local median {np.median(el):.4f} max {el.max():.4f}; "
              f"board median {np.median(eb):.4f} max {eb.max():.4f} px")
        assert eb.max() < 0.1, (name, eb.max())
        # Equal within the rendering's own noise (stratified supersampling, 8-bit rounding).
        assert np.median(eb) <= np.median(el) + 0.002, (name, np.median(eb), np.median(el))
        assert np.sqrt(np.mean(eb ** 2)) <= np.sqrt(np.mean(el ** 2)) + 0.002, name
        assert eb.max() <= el.max() + 0.002, name


def test_sigma_predicts_the_error(detections):
    """`sigma` is a worst-direction standard deviation, so the 2-D error should be within 2·sigma
    for most corners; the renderer's own biases (8-bit rounding, finite supersampling) are not in
    the model, so the share asked for is an honest 70 % over all scenes rather than 95 %."""
    within, total, ratios = 0, 0, []
    for _, b, _, fitted in detections:
        on_board = fitted.paths == cc.PATH_BOARD
        e = errors(fitted, b.image_corners())[on_board]
        s = fitted.sigmas[on_board]
        within += int((e <= 2 * s).sum())
        total += len(e)
        ratios.extend((e / s).tolist())
    share = within / total
    print(f"error within 2 sigma: {within}/{total} = {share:.2f}; "
          f"median error/sigma {np.median(ratios):.2f}")
    assert share >= 0.7, share
    # Nor is sigma uselessly pessimistic.
    assert np.median(ratios) > 0.1, np.median(ratios)


def test_covariances_go_with_sigmas(detections):
    """Each covariance is symmetric and positive definite, and its larger eigenvalue is the
    corner's sigma squared, in both modes."""
    for name, _, local, fitted in detections:
        for board in (local, fitted):
            c = board.covariances
            assert c.shape == (len(board), 2, 2) and c.dtype == np.float64, name
            placed = np.isfinite(board.sigmas)
            assert np.isfinite(c[placed]).all() and np.isnan(c[~placed]).all(), name
            np.testing.assert_array_equal(c[:, 0, 1], c[:, 1, 0])
            eig = np.linalg.eigvalsh(c[placed])
            assert (eig[:, 0] > 0).all(), name
            np.testing.assert_allclose(np.sqrt(eig[:, 1]), board.sigmas[placed], rtol=1e-9)


@pytest.mark.parametrize("bad", ["Board", "", "global", "local "])
def test_bad_refine_value_raises(bad):
    img = np.zeros((32, 32), np.uint8)
    with pytest.raises(ValueError, match="refine"):
        cc.detect(img, refine=bad)


def test_non_string_refine_raises_type_error():
    with pytest.raises(TypeError):
        cc.detect(np.zeros((32, 32), np.uint8), refine=1)
