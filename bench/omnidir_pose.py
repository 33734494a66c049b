#!/usr/bin/env python3
"""A board bent by a 360-degree lens: corners found, and one pose's fit, per method.

Usage: omnidir_pose.py [--cli BIN] [--methods m1,m2] [--markdown]

The images are OpenCV's omnidirectional camera sample (examples/opencv-omnidir, Apache-2.0, see
its README): sample.jpg, a flat board of 6 x 9 inner corners seen through the lens at 640 x 480,
and three rectifications of it. They have no ground truth. The yardstick for sample.jpg is the
camera: camera.json is Mei's model calibrated from 14 other views of the same camera
(bench/omnidir_camera.py), and with it held fixed one board pose must explain every corner of the
photo; what it cannot is each corner's own error plus what the model leaves out.

Reported per method:
  per image     the points it returns (for the board detectors: the board's corners), and how
                many of them lie within 2 px of conic-corners' labelled corners;
  pose RMS      on sample.jpg: each method's points labelled by matching them to conic-corners'
                board (within 2 px; the positions stay each method's own), the board pose that
                fits them best with camera.json's camera, and the RMS of the reprojection
                residuals' lengths (px, as cv2.calibrateCamera's), on the corners that every
                method finding the board there found, and on each method's own;
  noise         the pose residuals' differences between grid neighbours (along rows and
                columns), RMS per axis over sqrt(2), as in bench/stereo_calib.py: what the camera
                model leaves out is smooth over the board and mostly cancels, a corner's own
                error does not (a truth-free estimate of each corner's error per axis).
Coordinates: x right, y down, the centre of the top-left pixel at (0, 0).
"""
import argparse
import json
import os
import subprocess
import sys

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PHOTOS = os.path.join(ROOT, "examples", "opencv-omnidir")
IMAGES = ("sample.jpg", "sample_rec_cyl.jpg", "sample_rec_log.jpg", "sample_rec_ste.jpg")
MATCH_PX = 2.0
OURS = ("conic-corners-board", "conic-corners-local")


def mei_project(obj, pose, K, xi, D):
    """Mei's unified model, as cv2.omnidir: the point on the unit sphere, projected from
    (0, 0, -xi), then OpenCV's radial and tangential distortion (k1, k2, p1, p2) and K.
    `pose` is (Rodrigues rotation, translation) of the board frame in the camera's."""
    R = cv2.Rodrigues(np.asarray(pose[:3], float))[0]
    X = obj @ R.T + pose[3:]
    s = X / np.linalg.norm(X, axis=1, keepdims=True)
    x, y = s[:, 0] / (s[:, 2] + xi), s[:, 1] / (s[:, 2] + xi)
    k1, k2, p1, p2 = D
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], 1)


def camera_at_half_size():
    """camera.json (1280 x 960) for the 640 x 480 photo, as (K, xi, D); pixel centres at
    integers on both sides, so x_half = (x_full - 0.5) / 2."""
    with open(os.path.join(PHOTOS, "camera.json")) as f:
        cam = json.load(f)
    K = np.array(cam["K"]) / 2
    K[2, 2] = 1
    K[0, 2] -= 0.25
    K[1, 2] -= 0.25
    return K, cam["xi"], np.array(cam["D"])


def pose_residuals(obj, img, camera):
    """Residuals (N x 2, image minus model, px) of the best single board pose.
    Started from cv2.solvePnP on the points lifted to the unit sphere (distortion ignored) and
    seen from their mean direction, then Levenberg-Marquardt on all six parameters."""
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
    if not ok:
        return np.full_like(img, np.nan)
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
    return -residual(p).reshape(-1, 2)


def residual_rms(e):
    """RMS (px) of the lengths of residuals `e` (N x 2), as cv2.calibrateCamera reports it."""
    return float(np.sqrt(2 * np.mean(np.square(e))))


def pose_rms(obj, img, camera):
    """residual_rms of the best single board pose."""
    return residual_rms(pose_residuals(obj, img, camera))


def ours(cli, mode):
    """{image: {(row, col): (x, y)}} of the largest board `conic-corners detect` finds."""
    paths = [os.path.join(PHOTOS, n) for n in IMAGES]
    out = subprocess.run([cli, "detect", "--refine", mode, *paths], capture_output=True,
                         text=True, check=True).stdout
    res = {}
    for line in out.splitlines():
        r = json.loads(line)
        boards = sorted(r["boards"], key=lambda b: -len(b["corners"]))
        res[os.path.basename(r["image"]["path"])] = (
            {(c["row"], c["col"]): (c["x"], c["y"]) for c in boards[0]["corners"]}
            if boards else {})
    return res


def main():
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from board_peers import METHODS as PEERS, run_view
    from stereo_calib import label, neighbour_pairs

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cli", default=os.path.join(ROOT, "target/release/conic-corners"))
    ap.add_argument("--methods", help="comma-separated subset of the peers")
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    peers = a.methods.split(",") if a.methods else list(PEERS)
    found = {m: ours(a.cli, m.rsplit("-", 1)[1]) for m in OURS}
    reference = found["conic-corners-board"]
    returned = {m: {n: len(found[m][n]) for n in IMAGES} for m in OURS}
    labelled = {m: found[m] for m in OURS}
    for m in peers:
        returned[m], labelled[m] = {}, {}
    for n in IMAGES:
        for rec in run_view(PHOTOS, n, (6, 9), peers, 120):
            returned[rec["method"]][n] = len(rec["corners"])
            labelled[rec["method"]][n] = label(rec["corners"], reference[n])
    methods = list(OURS) + peers
    camera = camera_at_half_size()
    common = set.intersection(*(set(labelled[m]["sample.jpg"]) for m in methods
                                if len(labelled[m]["sample.jpg"]) >= 20))
    rows = []
    for m in methods:
        own = labelled[m]["sample.jpg"]
        row = [m] + [f"{returned[m][n]} / {len(labelled[m][n])}" for n in IMAGES]
        for keys in (sorted(common) if common <= set(own) else [], sorted(own)):
            if len(keys) < 6:
                row.append("-")
                continue
            obj = np.array([[c, r, 0.0] for r, c in keys])
            e = pose_residuals(obj, np.array([own[k] for k in keys]), camera)
            res = dict(zip(keys, e))
            diffs = [res[i] - res[j] for i, j in neighbour_pairs(res)]
            row.append(f"{residual_rms(e):.4f} / "
                       f"{np.sqrt(np.mean(np.square(diffs)) / 2):.4f}")
        rows.append(row)
    head = ["method"] + [f"{n}: returned / on our board" for n in IMAGES] + [
        f"pose RMS / noise, {len(common)} common", "pose RMS / noise, own"]
    if a.markdown:
        print("| " + " | ".join(head) + " |")
        print("| --- |" + " ---: |" * (len(head) - 1))
        for r in rows:
            print("| " + " | ".join(r) + " |")
    else:
        for r in [head] + rows:
            print("  ".join(str(x) for x in r))


if __name__ == "__main__":
    main()
