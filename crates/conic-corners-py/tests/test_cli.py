"""The Python results equal the CLI's on the same image file (same code, same f32 image)."""

import json
import subprocess

import numpy as np
import pytest

import conic_corners as cc
import render as R
from conftest import cli_has

cv2 = pytest.importorskip("cv2")

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])


def run_json(cmd):
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.fixture(scope="module")
def board_png(tmp_path_factory):
    r, t = R.look_at_pose(12, -18, 4, (-120, -100, 650))
    b = R.FlatBoard(K, r, t)
    gray = R.to_u8(b.render())
    path = tmp_path_factory.mktemp("cli") / "board.png"
    assert cv2.imwrite(str(path), gray)
    return path, gray, b


@pytest.fixture(scope="module")
def colour_png(tmp_path_factory, board_png):
    """The board tinted differently per channel, saved as an RGB PNG (cv2 writes B, G, R)."""
    _, gray, _ = board_png
    g = gray.astype(np.float64)
    rgb = np.stack([g * 0.9 + 20, g * 0.7 + 10, 255 - g * 0.8], -1)
    rgb = np.clip(np.round(rgb), 0, 255).astype(np.uint8)
    path = tmp_path_factory.mktemp("cli") / "colour.png"
    assert cv2.imwrite(str(path), rgb[..., ::-1])
    return path, rgb


def cli_refine(cli, path, points, tmp_path, extra=()):
    pts = tmp_path / "points.json"
    pts.write_text(json.dumps(np.asarray(points, np.float64).tolist()))
    return run_json([cli, "refine", str(path), "--points", str(pts), *extra])["corners"]


def assert_same_as_cli(py_points, py_status, py_residuals, cli_corners):
    assert len(cli_corners) == len(py_points)
    for p, s, r, c in zip(py_points, py_status, py_residuals, cli_corners):
        assert (p[0], p[1]) == (c["x"], c["y"])
        assert cc.STATUS_NAMES[s] == c["status"]
        if c["residual"] is None:
            assert np.isnan(r)
        else:
            assert r == c["residual"]


def starts_for(b):
    truth = b.image_corners().reshape(-1, 2)
    rng = np.random.default_rng(7)
    # Pixel-level starts, a far-off point and one outside: failures must agree too.
    starts = np.round(truth + rng.uniform(-1.5, 1.5, truth.shape))
    return np.vstack([starts, [[3.0, 3.0], [-10.0, 5.0]]])


@pytest.mark.parametrize("extra", [{}, {"reach": 30.0, "stride": 2, "blur": 0.8}])
def test_refine_equals_cli(cli_bin, board_png, tmp_path, extra):
    path, gray, b = board_png
    starts = starts_for(b)
    p, s, r, cov = cc.refine(gray, starts, return_residuals=True, return_covariances=True,
                             **extra)
    flags = [x for k, v in extra.items() for x in (f"--{k}", str(v))]
    cli = cli_refine(cli_bin, path, starts, tmp_path, flags)
    assert_same_as_cli(p, s, r, cli)
    assert (s[:-2] == cc.CONVERGED).all()
    # The covariances are the CLI's, NaN where refinement failed; the larger eigenvalue is σ².
    assert cov.shape == (len(starts), 2, 2)
    for c, k in zip(cov, cli):
        if k["cov"] is None:
            assert np.isnan(c).all() and k["sigma"] is None
        else:
            np.testing.assert_array_equal(c, np.array(k["cov"]))
            assert np.sqrt(np.linalg.eigvalsh(c)[1]) == pytest.approx(k["sigma"], rel=1e-9)
    assert np.isnan(cov[-1]).all()
    # Asked for alone, the covariances come third.
    p2, s2, cov2 = cc.refine(gray, starts, return_covariances=True, **extra)
    np.testing.assert_array_equal(cov2, cov)


def test_refine_colour_equals_cli(cli_bin, colour_png, board_png, tmp_path):
    path, rgb = colour_png
    starts = starts_for(board_png[2])
    cli = cli_refine(cli_bin, path, starts, tmp_path)
    assert_same_as_cli(*cc.refine(rgb, starts, return_residuals=True), cli)
    # OpenCV's B, G, R order with bgr=True, and an RGBA array, give the same.
    assert_same_as_cli(*cc.refine(np.ascontiguousarray(rgb[..., ::-1]), starts, bgr=True,
                                  return_residuals=True), cli)
    rgba = np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 200, np.uint8)], -1)
    assert_same_as_cli(*cc.refine(rgba, starts, return_residuals=True), cli)


@pytest.mark.parametrize("mode", [None, "board", "local"])
def test_detect_equals_cli(cli_bin, board_png, mode):
    if not cli_has(cli_bin, "detect"):
        pytest.skip("this build of the CLI has no `detect` subcommand yet")
    path, gray, _ = board_png
    flags = [] if mode is None else ["--refine", mode]
    out = run_json([cli_bin, "detect", str(path), *flags])
    cli_boards = out["boards"]
    boards = cc.detect(gray) if mode is None else cc.detect(gray, refine=mode)
    assert len(boards) == len(cli_boards)
    for b, c in zip(boards, cli_boards):
        assert (b.rows, b.cols) == (c["rows"], c["cols"])
        # The board's a-posteriori factor on every sigma: the CLI's, a positive float on this
        # 9 × 9 board (it has straight runs of six corners).
        assert b.sigma_scale == c["sigma_scale"]
        assert isinstance(b.sigma_scale, float) and b.sigma_scale > 0
        assert len(b) == len(c["corners"])
        for i, k in enumerate(c["corners"]):
            assert (b.points[i, 0], b.points[i, 1]) == (k["x"], k["y"])
            assert (b.ids[i, 0], b.ids[i, 1]) == (k["row"], k["col"])
            assert cc.STATUS_NAMES[b.status[i]] == k["status"]
            if k["residual"] is None:
                assert np.isnan(b.residuals[i])
            else:
                assert b.residuals[i] == k["residual"]
            assert cc.PATH_NAMES[b.paths[i]] == k["path"]
            if k["sigma"] is None:
                assert np.isnan(b.sigmas[i])
                assert np.isnan(b.covariances[i]).all()
            else:
                assert b.sigmas[i] == k["sigma"]
                np.testing.assert_array_equal(b.covariances[i], np.array(k["cov"]))
        if mode != "local":
            assert (b.paths == cc.PATH_BOARD).any(), "board mode by default, as the CLI"
