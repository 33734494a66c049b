"""Every bad input raises the documented exception (and never crashes the interpreter)."""

import numpy as np
import pytest

import conic_corners as cc

GOOD = np.zeros((40, 50), np.uint8)
PTS = np.array([[20.0, 20.0]])


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.int8, np.bool_, np.complex128, np.float16, object])
def test_image_wrong_dtype_is_type_error(dtype):
    img = np.zeros((40, 50), dtype)
    with pytest.raises(TypeError, match="dtype"):
        cc.detect(img)
    with pytest.raises(TypeError, match="dtype"):
        cc.refine(img, PTS)


def test_image_big_endian_is_type_error():
    with pytest.raises(TypeError, match="native byte order"):
        cc.detect(np.zeros((40, 50), ">u2"))


def test_image_string_is_type_error():
    with pytest.raises(TypeError):
        cc.detect("image.png")


@pytest.mark.parametrize("shape", [(50,), (4, 40, 50, 1), (40, 50, 2), (40, 50, 5), (40, 50, 1), ()])
def test_image_wrong_ndim_is_value_error(shape):
    with pytest.raises(ValueError, match="2-D|3-D"):
        cc.detect(np.zeros(shape, np.uint8))
    with pytest.raises(ValueError, match="2-D|3-D"):
        cc.refine(np.zeros(shape, np.uint8), PTS)


@pytest.mark.parametrize("shape", [(0, 50), (40, 0), (0, 0), (0, 10, 3)])
def test_empty_image_is_value_error(shape):
    with pytest.raises(ValueError, match="empty"):
        cc.detect(np.zeros(shape, np.uint8))
    with pytest.raises(ValueError, match="empty"):
        cc.refine(np.zeros(shape, np.float32), PTS)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_float_image_is_value_error(bad):
    img = np.zeros((40, 50), np.float32)
    img[3, 4] = bad
    with pytest.raises(ValueError, match="NaN or infinite"):
        cc.detect(img)
    with pytest.raises(ValueError, match="NaN or infinite"):
        cc.detect(np.full((40, 50), 1e300))  # float64 beyond float32


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.complex64, object])
def test_points_wrong_dtype_is_type_error(dtype):
    with pytest.raises(TypeError, match="float32 or float64"):
        cc.refine(GOOD, np.array([[20, 20]], dtype))


@pytest.mark.parametrize("shape", [(2,), (3, 3), (2, 2, 2), (1, 2, 1), (2, 1, 1, 2)])
def test_points_wrong_shape_is_value_error(shape):
    with pytest.raises(ValueError, match="N×2 or N×1×2"):
        cc.refine(GOOD, np.zeros(shape))


@pytest.mark.parametrize("shape", [(0, 2), (0, 1, 2)])
def test_points_empty_is_value_error(shape):
    with pytest.raises(ValueError, match="empty"):
        cc.refine(GOOD, np.zeros(shape, np.float32))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_points_non_finite_is_value_error(bad):
    pts = np.array([[20.0, 20.0], [10.0, bad]], np.float32)
    with pytest.raises(ValueError, match="point 1 is not finite"):
        cc.refine(GOOD, pts)


@pytest.mark.parametrize("corners", [0, -1, -100])
def test_non_positive_corners_is_value_error(corners):
    with pytest.raises(ValueError, match="corners must be at least 1"):
        cc.detect(GOOD, corners)


def test_non_integer_corners_is_type_error():
    with pytest.raises(TypeError):
        cc.detect(GOOD, 2.5)
    with pytest.raises(TypeError):
        cc.detect(GOOD, "48")


@pytest.mark.parametrize(
    "params,message",
    [
        ({"reach": -1.0}, "reach"),
        ({"reach": 0.0}, "reach"),
        ({"reach": float("nan")}, "reach"),
        ({"reach": float("inf")}, "reach"),
        ({"stride": 0}, "stride"),
        ({"stride": -2}, "stride"),
        ({"stride": 1000}, "stride"),
        ({"blur": -0.5}, "blur"),
        ({"blur": float("nan")}, "blur"),
        ({"blur": 100.0}, "blur"),
    ],
)
def test_bad_refine_params_are_value_errors(params, message):
    with pytest.raises(ValueError, match=message):
        cc.refine(GOOD, PTS, **params)
    with pytest.raises(ValueError, match=message):
        cc.detect(GOOD, **params)


@pytest.mark.parametrize(
    "params,message",
    [
        ({"sigma": 0.0}, "sigma"),
        ({"sigma": -2.0}, "sigma"),
        ({"sigma": 100.0}, "sigma"),
        ({"sigma": float("nan")}, "sigma"),
        ({"min_board_corners": 0}, "min_board_corners"),
        ({"min_board_corners": -3}, "min_board_corners"),
        ({"min_board_corners": 3}, "min_board_corners"),
    ],
)
def test_bad_detect_params_are_value_errors(params, message):
    with pytest.raises(ValueError, match=message):
        cc.detect(GOOD, **params)


def test_unknown_keyword_is_type_error():
    with pytest.raises(TypeError):
        cc.detect(GOOD, sigmaa=2.0)
    with pytest.raises(TypeError):
        cc.refine(GOOD, PTS, window=5)


def test_object_points_bad_square_size():
    b = cc.Board(2, 2, np.zeros((4, 2)), np.zeros((4, 2), np.int32), np.zeros(4),
                 np.zeros(4, np.uint8), np.zeros(4), np.zeros(4, np.uint8), np.full(4, np.nan),
                 np.full((4, 2, 2), np.nan))
    for s in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="square_size"):
            b.object_points(s)


def test_ragged_points_are_value_error():
    with pytest.raises(ValueError):
        cc.refine(GOOD, [[1.0, 2.0], [3.0]])


def test_native_module_validates_too():
    # The compiled functions check everything themselves: no path around the Python wrapper crashes.
    from conic_corners import _native

    with pytest.raises(TypeError):
        _native.detect([[0, 1], [2, 3]])
    with pytest.raises(TypeError):
        _native.refine(GOOD, [[1.0, 2.0]])
    with pytest.raises(ValueError):
        _native.refine(GOOD, np.zeros((1, 3)))
