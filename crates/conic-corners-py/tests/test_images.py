"""Image input: every dtype, colour, and non-contiguous views give the same results."""

import numpy as np
import pytest

import conic_corners as cc
import render as R


@pytest.fixture(scope="module")
def corner():
    img = R.x_corner(size=(80, 90), centre=(44.2, 38.7), angles_deg=(10.0, 95.0), blur=1.0)
    return R.to_u8(img)


START = np.array([[45.0, 38.0]])


def refined(img, **kw):
    p, s = cc.refine(img, START, **kw)
    assert s.tolist() == [cc.CONVERGED]
    return p


def test_dtypes_agree(corner):
    ref = refined(corner)
    # Every stage is invariant to an affine change of intensity: 16-bit ×257, floats.
    for img in (corner.astype(np.uint16), corner.astype(np.float32), corner.astype(np.float64)):
        np.testing.assert_array_equal(refined(img), ref)
    np.testing.assert_allclose(refined(corner.astype(np.uint16) * 257), ref, atol=1e-6)
    np.testing.assert_allclose(refined(corner.astype(np.float32) / 255), ref, atol=1e-4)


def test_non_contiguous_views_agree(corner):
    ref = refined(corner)
    big = np.zeros((corner.shape[0] * 2, corner.shape[1] * 2), np.uint8)
    big[::2, ::2] = corner
    view = big[::2, ::2]
    assert not view.flags.c_contiguous
    np.testing.assert_array_equal(refined(view), ref)
    fortran = np.asfortranarray(corner)
    np.testing.assert_array_equal(refined(fortran), ref)
    flipped = corner[::-1, ::-1]  # negative strides
    p, s = cc.refine(flipped, np.array([[corner.shape[1] - 1 - 45.0, corner.shape[0] - 1 - 38.0]]))
    assert s.tolist() == [cc.CONVERGED]
    np.testing.assert_allclose(p[0], [corner.shape[1] - 1 - ref[0, 0], corner.shape[0] - 1 - ref[0, 1]],
                               atol=1e-3)


def test_grey_colour_equals_grey(corner):
    ref = refined(corner)
    rgb = np.repeat(corner[..., None], 3, -1)  # luma of a grey pixel is the grey value
    np.testing.assert_array_equal(refined(rgb), ref)
    np.testing.assert_array_equal(refined(rgb[..., ::-1]), ref)  # strided channels
    rgba = np.concatenate([rgb, np.zeros_like(rgb[..., :1])], -1)  # alpha ignored
    np.testing.assert_array_equal(refined(rgba), ref)
    # Float luma (0.2126 + 0.7152 + 0.0722) · v rounds off the grey value by an ulp or so.
    np.testing.assert_allclose(refined(rgb.astype(np.float32)), ref, atol=1e-6)
    np.testing.assert_array_equal(refined(rgb.astype(np.uint16)), ref)


def test_colour_uses_rec709_luma(corner):
    # A corner that only the green channel shows: luma = 0.7152 · G (+ constant R, B terms).
    rgb = np.zeros(corner.shape + (3,), np.uint8)
    rgb[..., 1] = corner
    rgb[..., 0] = 100
    p_rgb = refined(rgb)
    np.testing.assert_allclose(p_rgb, refined(corner), atol=0.01)
    # In B, G, R order the green channel is still the middle one.
    np.testing.assert_array_equal(refined(rgb[..., ::-1], bgr=True), p_rgb)


def test_lists_are_accepted(corner):
    p, s = cc.refine(corner, START.tolist())
    assert p.dtype == np.float64 and s.tolist() == [cc.CONVERGED]
