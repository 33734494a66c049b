"""Exact test images with known corner positions, rendered with numpy only.

Coordinates: x right, y down, the centre of the top-left pixel is (0, 0); pixel (i, j) covers
[i - 0.5, i + 0.5] × [j - 0.5, j + 0.5]. Pixels are box-filtered by supersampling (S × S
samples each) and then blurred with a sampled Gaussian. Both filters are symmetric, so an
X-junction (two straight lines crossing, opposite quadrants equal) keeps its centre exactly: the
truth is the geometric corner.
"""

from __future__ import annotations

import numpy as np


def gaussian_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian blur (sampled kernel, radius 4σ, edge-replicated borders)."""
    if sigma <= 0:
        return img.astype(np.float64)
    r = int(np.ceil(4 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    out = img.astype(np.float64)
    for axis in (0, 1):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (r, r)
        p = np.pad(out, pad, mode="edge")
        n = out.shape[axis]
        acc = np.zeros_like(out)
        for i, w in enumerate(k):
            sl = [slice(None), slice(None)]
            sl[axis] = slice(i, i + n)
            acc += w * p[tuple(sl)]
        out = acc
    return out


def supersample(shape, value_at, s: int = 8, seed: int = 0) -> np.ndarray:
    """Mean of `value_at(x, y)` over s×s stratified samples per pixel (box filter of the pixel
    area). Each sample is jittered within its cell, independently per pixel: a regular grid of
    samples quantizes the coverage of an edge nearly parallel to it the same way in every pixel
    along it, a bias of a few hundredths of a pixel that jitter turns into noise averaging out."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    rng = np.random.default_rng(seed)
    acc = np.zeros((h, w))
    for a in range(s):
        for b in range(s):
            jx, jy = rng.random((2, h, w))
            acc += value_at(xs - 0.5 + (b + jx) / s, ys - 0.5 + (a + jy) / s)
    return acc / (s * s)


def x_corner(size=(96, 96), centre=(47.3, 48.6), angles_deg=(20.0, 105.0), blur=1.0,
             dark=40.0, bright=210.0, s: int = 8) -> np.ndarray:
    """An X-junction of two straight edges through `centre` at the given directions."""
    cx, cy = centre
    n1 = np.array([-np.sin(np.radians(angles_deg[0])), np.cos(np.radians(angles_deg[0]))])
    n2 = np.array([-np.sin(np.radians(angles_deg[1])), np.cos(np.radians(angles_deg[1]))])

    def value(x, y):
        d1 = (x - cx) * n1[0] + (y - cy) * n1[1]
        d2 = (x - cx) * n2[0] + (y - cy) * n2[1]
        return np.where((d1 > 0) == (d2 > 0), bright, dark)

    return gaussian_blur(supersample(size, value, s), blur)


def look_at_pose(rx_deg: float, ry_deg: float, rz_deg: float, t) -> tuple:
    """Rotation (board → camera) R = Rz·Ry·Rx and translation t."""
    ax, ay, az = np.radians([rx_deg, ry_deg, rz_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx, np.asarray(t, np.float64)


class FlatBoard:
    """A planar checkerboard of `squares_x × squares_y` squares of side `square` (board units),
    with a one-square white margin, seen through a pinhole camera `k` at pose (r, t).

    Board coordinates: the pattern spans [0, squares_x·square] × [0, squares_y·square] on Z = 0;
    its inner corners are at ((c + 1)·square, (r + 1)·square), r < squares_y - 1, c < squares_x - 1.
    """

    def __init__(self, k, r, t, squares_x=9, squares_y=7, square=30.0,
                 dark=30.0, bright=220.0, background=110.0):
        self.k = np.asarray(k, np.float64)
        self.h = self.k @ np.column_stack([r[:, 0], r[:, 1], t])  # board (X, Y, 1) → image
        self.h_inv = np.linalg.inv(self.h)
        self.sx, self.sy, self.square = squares_x, squares_y, square
        self.dark, self.bright, self.background = dark, bright, background

    @property
    def inner_shape(self) -> tuple:
        """(rows, cols) of inner corners."""
        return self.sy - 1, self.sx - 1

    def board_corners(self) -> np.ndarray:
        """Inner corners in board units, rows × cols × 2, (X, Y)."""
        rows, cols = self.inner_shape
        r, c = np.mgrid[0:rows, 0:cols]
        return np.stack([(c + 1) * self.square, (r + 1) * self.square], -1).astype(np.float64)

    def image_corners(self) -> np.ndarray:
        """True image positions of the inner corners, rows × cols × 2 (x, y)."""
        b = self.board_corners().reshape(-1, 2)
        p = self.h @ np.column_stack([b, np.ones(len(b))]).T
        return (p[:2] / p[2]).T.reshape(self.inner_shape + (2,))

    def value_at(self, x, y):
        w = self.h_inv[2, 0] * x + self.h_inv[2, 1] * y + self.h_inv[2, 2]
        u = (self.h_inv[0, 0] * x + self.h_inv[0, 1] * y + self.h_inv[0, 2]) / w / self.square
        v = (self.h_inv[1, 0] * x + self.h_inv[1, 1] * y + self.h_inv[1, 2]) / w / self.square
        inside = (u >= 0) & (u < self.sx) & (v >= 0) & (v < self.sy)
        margin = (u >= -1) & (u < self.sx + 1) & (v >= -1) & (v < self.sy + 1)
        black = ((np.floor(u) + np.floor(v)) % 2) == 0
        out = np.where(margin, self.bright, self.background)
        return np.where(inside & black, self.dark, out)

    def render(self, size=(480, 640), blur=0.8, s: int = 8) -> np.ndarray:
        """The image (float64, H×W) box-filtered and blurred."""
        return gaussian_blur(supersample(size, self.value_at, s), blur)


def to_u8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


class CylinderBoard(FlatBoard):
    """The board of :class:`FlatBoard` wrapped around a cylinder of radius `radius` (board units)
    whose axis runs along the board's Y (columns bend, rows stay straight in board space), bulging
    towards the camera: the board point (U, V) lies at

        θ = (U − U₀) / radius,  S = (U₀ + radius·sin θ, V, radius·(1 − cos θ))

    in the board frame (U₀ the middle of the pattern, the sheet tangent to Z = 0 there), then goes
    through the pose (r, t) and the camera `k` as the flat board does. Arc length along U is kept,
    so the squares are printed squares bent, not stretched."""

    def __init__(self, k, r, t, radius=220.0, **kw):
        super().__init__(k, r, t, **kw)
        self.r, self.t, self.radius = np.asarray(r, np.float64), np.asarray(t, np.float64), radius
        self.u0 = self.sx * self.square / 2

    def surface(self, u, v):
        """Board-frame 3-D points (…×3) of board coordinates (U, V)."""
        th = (u - self.u0) / self.radius
        return np.stack([self.u0 + self.radius * np.sin(th), v,
                         self.radius * (1 - np.cos(th))], -1)

    def image_corners(self) -> np.ndarray:
        b = self.board_corners()
        p = self.surface(b[..., 0], b[..., 1]) @ self.r.T + self.t
        p = p @ self.k.T
        return p[..., :2] / p[..., 2:]

    def value_at(self, x, y):
        # Ray through the pixel, in the board frame: origin o, direction d = rᵀ k⁻¹ (x, y, 1).
        o = -self.r.T @ self.t
        kinv = np.linalg.inv(self.k)
        dc = np.stack([kinv[0, 0] * x + kinv[0, 1] * y + kinv[0, 2],
                       kinv[1, 1] * y + kinv[1, 2] + 0 * x, np.ones_like(x)], -1)
        d = dc @ self.r  # (rᵀ d_c)ᵀ = d_cᵀ r
        # Nearest intersection with (X − U₀)² + (Z − radius)² = radius².
        ax, az = o[0] - self.u0, o[2] - self.radius
        a = d[..., 0] ** 2 + d[..., 2] ** 2
        b = 2 * (ax * d[..., 0] + az * d[..., 2])
        c = ax ** 2 + az ** 2 - self.radius ** 2
        disc = b * b - 4 * a * c
        hit = disc >= 0
        s = (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a)
        px, py, pz = o[0] + s * d[..., 0], o[1] + s * d[..., 1], o[2] + s * d[..., 2]
        th = np.arctan2(px - self.u0, self.radius - pz)
        u = (self.u0 + self.radius * th) / self.square
        v = py / self.square
        front = hit & (np.abs(th) < np.pi / 2)
        inside = front & (u >= 0) & (u < self.sx) & (v >= 0) & (v < self.sy)
        margin = front & (u >= -1) & (u < self.sx + 1) & (v >= -1) & (v < self.sy + 1)
        black = ((np.floor(u) + np.floor(v)) % 2) == 0
        out = np.where(margin, self.bright, self.background)
        return np.where(inside & black, self.dark, out)
