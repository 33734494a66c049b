#!/usr/bin/env python3
"""Camera calibration from real photos: how well each detector's corners fit a calibrated camera.

Usage: stereo_calib.py [--images DIR] [--cli BIN] [--out DIR] [--markdown] [--methods m1,m2]

The photos are OpenCV's stereo calibration sample (examples/opencv-stereo: left01..14 and
right01..14 but 10, 640 x 480, a board of 9 x 6 inner corners; Apache-2.0, see its LICENSE). They
have no ground truth, so the yardstick is the camera model itself: a pinhole camera with radial
and tangential distortion (OpenCV's five coefficients) explains every view's corners up to the
corners' own errors and what the model leaves out, the same for every method.

Every method's corners are labelled by matching them (within 2 px) to conic-corners' labelled
board, detected with `--pattern 6x9` so that every view is in the print's frame (6 rows of 9
corners, the first square dark) and left and right views label each corner alike; the labels serve
only to pair corners with board points, the positions are each method's own.

Reported per method, for the left and right camera, on the corners that every method found (the
same corners for all) and then on each method's own:
  fit RMS       cv2.calibrateCamera's reprojection RMS (px) over all views;
  held-out RMS  each view left out in turn: the camera calibrated on the other views, the left-out
                view's pose solved with it (solvePnP, iterative) and its corners reprojected; RMS
                (px) over all left-out corners. A corner's own error cannot be fitted away here.
  stereo RMS    cv2.stereoCalibrate with each method's intrinsics fixed (px), over the pairs.
  noise         the held-out residuals' differences between grid neighbours (along rows and
                columns), RMS per axis over sqrt(2): what the model leaves out is smooth over the
                board and mostly cancels, a corner's own error does not (px; a truth-free estimate
                of each corner's error per axis).
  cov scale     for a method that reports covariances: the neighbours' residual differences d
                against their summed covariances, sqrt(median(d' (C_i + C_j)^-1 d) / 1.386) (the
                median of a chi-square with 2 degrees of freedom): 1 where the covariances are
                honest, above 1 where they are too small.
Coordinates: x right, y down, the centre of the top-left pixel at (0, 0) (bench/peers.py checks
each peer's convention).
"""
import argparse
import json
import os
import subprocess
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from board_peers import METHODS as PEERS, run_view  # noqa: E402
from board_report import match  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROWS, COLS = 6, 9
MATCH_PX = 2.0
OURS = ("conic-corners-board", "conic-corners-local")


def ours(cli, images, mode):
    """{image: (labelled board {(r, c): (x, y)} or None, {(x, y): covariance}, ms)} from
    `conic-corners detect`."""
    out = subprocess.run([cli, "detect", "--refine", mode, "--pattern", f"{ROWS}x{COLS}", *images],
                         capture_output=True, text=True, check=True).stdout
    res = {}
    for line in out.splitlines():
        r = json.loads(line)
        boards = [b for b in r["boards"] if len(b["corners"]) >= 4]
        board = {(c["row"], c["col"]): (c["x"], c["y"]) for c in boards[0]["corners"]} \
            if boards else None
        cov = {(c["x"], c["y"]): np.array(c["cov"]) for b in boards for c in b["corners"]
               if c.get("cov") is not None}
        res[r["image"]["path"]] = (board, cov, r["timing_ms"]["total"])
    return res


def label(points, reference):
    """Each point matched to the nearest labelled reference corner within MATCH_PX, as the
    curved-board report matches detections to the truth (board_report.match)."""
    view = {"corners": [{"row": r, "col": c, "x": x, "y": y, "visible": True}
                        for (r, c), (x, y) in reference.items()]}
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return {k: tuple(pts[j]) for k, (_, _, j) in match(view, pts, MATCH_PX).items()}


def board_points(keys):
    return np.array([[c, r, 0.0] for r, c in keys], dtype=np.float32)


def image_points(labelled, keys):
    return np.array([labelled[k] for k in keys], dtype=np.float32).reshape(-1, 1, 2)


def calibrate(views, size):
    """views: list of (object points, image points); returns (rms, K, dist)."""
    obj = [o for o, _ in views]
    img = [i for _, i in views]
    rms, k, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    return rms, k, dist


def held_out(views, size):
    """RMS (px) over the corners of each view, reprojected with the camera of the others, and
    each view's residuals (image minus model) by board point."""
    sq, n, residuals = 0.0, 0, []
    for i, (obj, img) in enumerate(views):
        _, k, dist = calibrate(views[:i] + views[i + 1:], size)
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            residuals.append({})
            continue
        proj, _ = cv2.projectPoints(obj, rvec, tvec, k, dist)
        e = (img - proj).reshape(-1, 2).astype(np.float64)
        sq += float(np.sum(e * e))
        n += len(e)
        residuals.append({(int(o[1]), int(o[0])): d for o, d in zip(obj, e)})
    return (np.sqrt(sq / n) if n else float("nan")), residuals


def neighbour_pairs(residuals):
    """(label, label) of grid neighbours (along rows and columns) in one view's residuals."""
    for (r, c) in residuals:
        for q in ((r, c + 1), (r + 1, c)):
            if q in residuals:
                yield (r, c), q


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", default=os.path.join(ROOT, "examples/opencv-stereo"))
    ap.add_argument("--cli", default=os.path.join(ROOT, "target/release/conic-corners"))
    ap.add_argument("--out", help="also write every method's labelled corners here (JSON)")
    ap.add_argument("--methods", help="comma-separated subset of the peers")
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    peers = a.methods.split(",") if a.methods else list(PEERS)
    names = sorted(f for f in os.listdir(a.images) if f.endswith(".jpg"))
    pairs = sorted({f[len("left"):] for f in names if f.startswith("left")}
                   & {f[len("right"):] for f in names if f.startswith("right")})
    images = [os.path.join(a.images, side + p) for p in pairs for side in ("left", "right")]
    size = cv2.imread(images[0], cv2.IMREAD_GRAYSCALE).shape[::-1]

    t0 = time.time()
    found = {m: ours(a.cli, images, m.rsplit("-", 1)[1]) for m in OURS}
    reference = {im: found["conic-corners-board"][im][0] for im in images}
    labelled = {m: {im: found[m][im][0] or {} for im in images} for m in OURS}
    # Covariance by label, for the methods that report one.
    covs = {m: {im: {k: found[m][im][1].get(p) for k, p in labelled[m][im].items()}
                for im in images} for m in OURS}
    ms = {m: [found[m][im][2] for im in images] for m in OURS}
    for m in peers:
        labelled[m], ms[m] = {}, []
    for im in images:
        for rec in run_view(os.path.dirname(im), os.path.basename(im), (COLS, ROWS), peers, 120):
            labelled[rec["method"]][im] = label(rec["corners"], reference[im] or {})
            ms[rec["method"]].append(rec["ms"])
    methods = list(OURS) + peers
    print(f"stereo_calib: {len(images)} photos, {len(methods)} methods, {time.time() - t0:.0f} s",
          file=sys.stderr)
    if a.out:
        with open(a.out, "w") as f:
            json.dump({m: {os.path.basename(im): {f"{r},{c}": p for (r, c), p in v.items()}
                           for im, v in labelled[m].items()} for m in methods}, f)

    common = {im: set.intersection(*(set(labelled[m][im]) for m in methods)) for im in images}
    rows = []
    for m in methods:
        row = {"method": m, "corners": sum(len(v) for v in labelled[m].values()),
               "views": sum(len(v) >= 20 for v in labelled[m].values())}
        for scope in ("common", "own"):
            cams, diffs, d2 = {}, [], []
            for side in ("left", "right"):
                views, view_covs = [], []
                for p in pairs:
                    im = os.path.join(a.images, side + p)
                    keys = sorted(common[im] if scope == "common" else labelled[m][im])
                    if len(keys) >= 20:
                        views.append((board_points(keys), image_points(labelled[m][im], keys)))
                        view_covs.append(covs.get(m, {}).get(im, {}))
                fit, k, dist = calibrate(views, size)
                cams[side] = (k, dist)
                row[f"{scope} {side} fit"] = fit
                row[f"{scope} {side} held-out"], residuals = held_out(views, size)
                for res, cov in zip(residuals, view_covs):
                    for i, j in neighbour_pairs(res):
                        d = res[i] - res[j]
                        diffs.append(d)
                        if cov.get(i) is not None and cov.get(j) is not None:
                            d2.append(float(d @ np.linalg.solve(cov[i] + cov[j], d)))
            row[f"{scope} noise"] = float(np.sqrt(np.mean(np.square(diffs)) / 2.0))
            row[f"{scope} cov scale"] = (float(np.sqrt(np.median(d2) / 1.386)) if d2
                                         else float("nan"))
            # Stereo: the pairs' corners found in both views (and common to all, in that scope).
            obj, il, ir = [], [], []
            for p in pairs:
                li, ri = (os.path.join(a.images, s + p) for s in ("left", "right"))
                keys = set(labelled[m][li]) & set(labelled[m][ri])
                if scope == "common":
                    keys &= common[li] & common[ri]
                keys = sorted(keys)
                if len(keys) >= 20:
                    obj.append(board_points(keys))
                    il.append(image_points(labelled[m][li], keys))
                    ir.append(image_points(labelled[m][ri], keys))
            (kl, dl), (kr, dr) = cams["left"], cams["right"]
            rms = cv2.stereoCalibrate(obj, il, ir, kl, dl, kr, dr, size,
                                      flags=cv2.CALIB_FIX_INTRINSIC)[0]
            row[f"{scope} stereo"] = rms
        valid = [t for t in ms[m] if t is not None]
        row["ms"] = float(np.median(valid)) if valid else float("nan")
        rows.append(row)

    cols = ["corners", "views"] + [f"{s} {c}" for s in ("common", "own")
                                   for c in ("left fit", "left held-out", "right fit",
                                             "right held-out", "stereo", "noise")] + ["ms"]
    best = {c: min(r[c] for r in rows if r["method"] != OURS[0]) for c in cols[2:-1]}
    scales = [f"{s} cov scale" for s in ("common", "own")]
    print(f"Corners common to all methods: {sum(len(v) for v in common.values())} in "
          f"{len(images)} photos. RMS in px; ratio: conic-corners-board over the best other.")
    if a.markdown:
        print("| method | " + " | ".join(cols) + " |")
        print("|---" * (len(cols) + 1) + "|")
        fmt = lambda c, v: f"{v:.0f}" if c in ("corners", "views", "ms") else f"{v:.4f}"
        for r in rows:
            print(f"| {r['method']} | " + " | ".join(fmt(c, r[c]) for c in cols) + " |")
        board = rows[0]
        print("| ratio | | | " + " | ".join(f"{board[c] / best[c]:.2f}" for c in cols[2:-1])
              + " | |")
    else:
        width = max(len(m) for m in methods)
        print(f"{'method':<{width}}  " + "  ".join(f"{c:>{max(len(c), 7)}}" for c in cols))
        for r in rows:
            vals = [f"{r[c]:.0f}" if c in ("corners", "views", "ms") else f"{r[c]:.4f}"
                    for c in cols]
            print(f"{r['method']:<{width}}  " + "  ".join(
                f"{v:>{max(len(c), 7)}}" for c, v in zip(cols, vals)))
        board = rows[0]
        print(f"{'ratio':<{width}}  " + "  ".join(
            f"{'':>{max(len(c), 7)}}" if c in ("corners", "views", "ms")
            else f"{board[c] / best[c]:>{max(len(c), 7)}.2f}" for c in cols))
    print()
    for r in rows:
        if not np.isnan(r[scales[0]]):
            print(f"{r['method']}: covariance scale " + ", ".join(
                f"{c.split()[0]} corners {r[c]:.2f}" for c in scales))


if __name__ == "__main__":
    main()
