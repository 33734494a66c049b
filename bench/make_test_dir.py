#!/usr/bin/env python3
"""Smoke-test data for bench/peers.py and bench/report.py.

NOT the benchmark's renderer (that one lives in the Rust crate and draws curved, perspective-warped
corners with the paper's protocols). This one draws only a straight, symmetric X-junction whose
exact sub-pixel position is known analytically, so it doubles as the check of each peer's
coordinate convention (`peers.py --selftest`).

Coordinates: x right, y down, centre of the top-left pixel = (0, 0) (OpenCV). Pixel (row r,
column c) covers [c-0.5, c+0.5] x [r-0.5, r+0.5].

Usage: make_test_dir.py DIR [--per-value 5] [--seed 1]
  writes DIR/manifest.jsonl, DIR/<protocol>/<value>/NNNN.png and a fake DIR/ours.jsonl
  (truth + N(0, 0.02 px) noise, method "conic-corners").
"""
import argparse
import json
import math
import os

import numpy as np

_SUPERSAMPLE = 4


def _phi(t):
    """Standard normal CDF via Abramowitz & Stegun 7.1.26 for erf (|error| < 1.5e-7, far below
    one 8-bit grey level), since numpy has no erf and scipy is not a dependency."""
    z = np.abs(t) / math.sqrt(2.0)
    k = 1.0 / (1.0 + 0.3275911 * z)
    poly = k * (0.254829592 + k * (-0.284496736 + k * (1.421413741
                                                       + k * (-1.453152027 + k * 1.061405429))))
    erf = 1.0 - poly * np.exp(-z * z)
    return 0.5 * (1.0 + np.sign(t) * erf)


def render_corner(cx, cy, *, size=640, angle=0.0, blur=1.5, dark=0.2, bright=0.8):
    """Float image in [0, 1] of an ideal X-junction at (cx, cy), pixel-integrated.

    The continuous image is s(u) s(v) with (u, v) the point rotated by `angle` about the corner
    and s = sign; blurred by an isotropic Gaussian of std `blur` px it stays separable:
    (2 Phi(u/blur) - 1) (2 Phi(v/blur) - 1). Each pixel averages it over a 4x4 grid of samples
    covering the pixel's square, which models the sensor's box integration. Point symmetry about
    (cx, cy) makes any unbiased symmetric estimator land exactly on the truth.
    """
    offs = (np.arange(_SUPERSAMPLE) + 0.5) / _SUPERSAMPLE - 0.5
    ys = (np.arange(size)[:, None] + offs[None, :]).ravel() - cy
    xs = (np.arange(size)[:, None] + offs[None, :]).ravel() - cx
    c, s = math.cos(angle), math.sin(angle)
    X, Y = np.meshgrid(xs, ys)
    u = c * X + s * Y
    v = -s * X + c * Y
    if blur > 0:
        f = (2.0 * _phi(u / blur) - 1.0) * (2.0 * _phi(v / blur) - 1.0)
    else:
        f = np.sign(u) * np.sign(v)
    f = f.reshape(size, _SUPERSAMPLE, size, _SUPERSAMPLE).mean(axis=(1, 3))
    return dark + (bright - dark) * 0.5 * (1.0 + f)


def to_u8(img):
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


# Smoke-test sweeps: a few values per protocol, straight edges only (this is no renderer of the
# paper's curvature/perspective protocols; "value" is simply what varies here).
_SWEEPS = {
    "noise": {"values": [0.0, 0.03, 0.1], "param": "noise"},
    "blur": {"values": [1.0, 3.0, 5.0], "param": "blur"},
}


def main():
    ap = argparse.ArgumentParser(description="write a small smoke-test DIR for peers.py/report.py")
    ap.add_argument("dir")
    ap.add_argument("--per-value", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    import cv2

    os.makedirs(a.dir, exist_ok=True)
    with open(os.path.join(a.dir, "manifest.jsonl"), "w") as man, \
            open(os.path.join(a.dir, "ours.jsonl"), "w") as ours:
        for protocol, sweep in _SWEEPS.items():
            for value in sweep["values"]:
                for i in range(a.per_value):
                    seed = int(rng.integers(1 << 31))
                    r = np.random.default_rng(seed)
                    noise, blur = (value, 3.0) if sweep["param"] == "noise" else (0.03, value)
                    cx, cy = 320 + r.uniform(-0.5, 0.5), 320 + r.uniform(-0.5, 0.5)
                    bright = r.uniform(0.5, 1.0)
                    f = render_corner(cx, cy, angle=r.uniform(0, math.pi), blur=blur,
                                      dark=0.0, bright=bright)
                    img = to_u8(f + r.normal(0.0, noise, f.shape))
                    rel = f"{protocol}/{value:g}/{i:04d}.png"
                    os.makedirs(os.path.dirname(os.path.join(a.dir, rel)), exist_ok=True)
                    cv2.imwrite(os.path.join(a.dir, rel), img)
                    man.write(json.dumps({"image": rel, "protocol": protocol, "value": value,
                                          "truth": [cx, cy], "crb": None, "seed": seed}) + "\n")
                    ex, ey = r.normal(0.0, 0.02, 2)
                    ours.write(json.dumps({"image": rel, "method": "conic-corners",
                                           "x": cx + ex, "y": cy + ey, "found": True}) + "\n")


if __name__ == "__main__":
    main()
