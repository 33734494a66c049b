#!/usr/bin/env python3
"""Tables of the curved-board benchmark (paper Table I and experiment IV-B).

Usage: board_report.py DIR [--markdown] [--match-px 2]
       board_report.py DIR --selftest   (triangulates the exact truth and solves its poses from a
                                         perturbed start: errors must vanish; checks the
                                         edge-information bound against its closed form)

Reads DIR/truth.jsonl and DIR/ours.jsonl (board-accuracy), DIR/peers.jsonl (board_peers.py; may be
missing). Every method is matched by position, the same way: each visible true corner of a view
takes the nearest detection within --match-px (2 px); the peers' (and our) grid labels are not
used.

1. Error against truth by curvature (Table I style): per method and bin of the corner's local edge
   curvature kappa = max(|kappa_row|, |kappa_col|) (the two grid lines through it, in the image,
   px^-1; bins of 1e-3: [0,1), [1,2), ..., [6,inf)), the RMSE (px) of the matched corners' errors
   and their count; then over all bins the RMSE, median, 95th percentile, and the detection share
   (matched / visible true corners over all views). Then the median per bin, and the RMSE per bin
   over only the corners every method found (the same corners for all: OpenCV finds whole boards
   only, so this set leans towards fully visible, flatter boards).
2. The RMSE per surface kind (RMSE, count).
3. Stereo triangulation (IV-B): in each pair, the corners a method matched in both views (same true
   (row, col)) are triangulated with the known rig and intrinsics: undistorted (radial k1, k2, by
   Newton's method), linear DLT in normalized coordinates, then Gauss-Newton on the pixel
   reprojection error of both views. Reported: corners, reprojection RMSE (px, over the 2-D residual
   of every observation), 3-D error RMSE and median (mm, against the exact corner in the left camera
   frame), and the ratio of the reprojection RMSE to libcbdetect's on the corners both found.
4. Stereo reprojection RMSE by curvature (the paper's Table I proper; kappa = max over both views).
5. Pose estimation (PnP, the paper's IV-C): in every view, the pose of the bent board from the
   corners a method matched (at least 8) and their exact 3-D positions on the surface, by
   Gauss-Newton on the pixel reprojection error (radial distortion included, started from the true
   pose, so that every method reaches its own least-squares minimum). Reported: views solved, RMS
   and median rotation error (deg), translation error (mm) and the error of a tool tip 150 mm from
   the board's centre along the optical axis of the left camera (mm; like the paper's pen tip,
   it amplifies the rotation error), and the tip error's ratio to libcbdetect's on the views both
   solved. Methods that report a sigma per corner are also solved with each corner weighted by
   1/sigma^2 (what a user of the uncertainty would do), and those that report a 2x2 covariance
   with each corner's two residuals whitened by it (weighted by the inverse covariance).
6. Calibration of the sigma (conic-corners-board): share of corners whose error is
   within 1, 2, 3 sigma (sigma = std. dev. in the worst direction; for an isotropic 2-D Gaussian the
   shares would be 39.3 %, 86.5 %, 98.9 %), over the corners that carry a sigma; and per axis, the
   share of the errors' x and y components within 1 and 2 sigma (a 1-D Gaussian: 68.3 %, 95.4 %;
   sigma being the worst direction's, an honest one gives at least these shares). Where a method
   reports a covariance C per corner: the share of corners whose Mahalanobis distance
   d = sqrt(e' C^-1 e) is within 1, 2, 3 (a 2-D Gaussian: 39.3 %, 86.5 %, 98.9 %), the mean of d^2
   (2 for a 2-D Gaussian), and per axis, the share of the x and y components within 1 and 2 of
   their own standard deviations sqrt(C_xx), sqrt(C_yy) (a 1-D Gaussian: 68.3 %, 95.4 %).
7. Edge-information bound: for every visible true corner, the smallest RMS error (px) that an
   unbiased estimator fitting each of its two grid lines from that line's edge pixels can reach
   (Cramer-Rao). Each line is a step edge of contrast (white - black) x lighting gain, blurred by
   sigma_t = sqrt(blur^2 + 1/12) (the blur and the pixel's footprint), under Gaussian noise of
   variance noise^2 + 1/(12 * 255^2) (the 8-bit quantization): every px of edge length carries
   the Fisher information C^2 / (2 sqrt(pi) sigma_t sigma_n^2) about the edge's normal offset.
   Along the line the offset is an unknown parabola in arc length (curvature and tilt are
   nuisances), over the line's visible true corners within 4 squares of the corner (the
   benchmark's own corner window), the chord through them standing in for the arc. Where a
   line's chain stops before 4 squares (the board's end, a silhouette, an occluder) the edge
   may go on for part of a square that the truth does not describe, so the bound is given twice:
   edges ending at the last visible corner, and running one square beyond it. The corner's
   covariance follows from the two offsets' variances and the lines' normals; the bound is the
   root of its trace. Then each method's RMSE over its matched corners divided by the RMS bound
   (one square beyond) over the same corners: the factor lost to the information in the pixels.
8. Run time: mean ms per view (ours in-process, detection only, parallel inside; peers in a child
   process, concurrent with another view: indicative only).
"""
import argparse
import json
import math
import os
import signal
import sys
from collections import defaultdict

import numpy as np

BINS = [0, 1, 2, 3, 4, 5, 6, math.inf]  # 1e-3 px^-1
BIN_NAMES = ["[0,1)", "[1,2)", "[2,3)", "[3,4)", "[4,5)", "[5,6)", "[6,inf)"]
OURS_ORDER = ("conic-corners-local", "conic-corners-board")
PEER_ORDER = ("opencv-fcc+csp", "opencv-sb", "opencv-sb-accuracy", "libcbdetect", "calib-targets",
              "chess-corners-r5")
REFERENCE = "libcbdetect"
GAUSS_2D = (0.393, 0.865, 0.989)


def read_jsonl(path, required=True):
    if not os.path.exists(path):
        if required:
            sys.exit(f"board_report: {path} not found")
        print(f"board_report: {path} not found, skipped", file=sys.stderr)
        return []
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def curvature_bin(kappa):
    k = kappa * 1e3
    for i in range(len(BINS) - 1):
        if BINS[i] <= k < BINS[i + 1]:
            return i
    return None


def match(view, points, match_px):
    """{(row, col): (dx, dy, index)}: visible true corners with a detection within match_px."""
    truth = [c for c in view["corners"] if c["visible"]]
    if not truth or len(points) == 0:
        return {}
    t = np.array([[c["x"], c["y"]] for c in truth])
    d = np.hypot(t[:, None, 0] - points[None, :, 0], t[:, None, 1] - points[None, :, 1])
    j = d.argmin(axis=1)
    out = {}
    for i, c in enumerate(truth):
        if d[i, j[i]] <= match_px:
            out[(c["row"], c["col"])] = (points[j[i], 0] - c["x"], points[j[i], 1] - c["y"], j[i])
    return out


def project(X, cam, R=None, t=None):
    """Pixel projection (with radial distortion) of (N, 3) points given in the left camera frame."""
    p = X if R is None else X @ np.asarray(R).T + np.asarray(t)
    xn, yn = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    r2 = xn * xn + yn * yn
    d = 1 + cam["k1"] * r2 + cam["k2"] * r2 * r2
    return np.stack([cam["fx"] * xn * d + cam["cx"], cam["fy"] * yn * d + cam["cy"]], axis=1)


def undistort(uv, cam):
    """Normalized undistorted coordinates of (N, 2) pixels: Newton on the radius."""
    xd = (uv[:, 0] - cam["cx"]) / cam["fx"]
    yd = (uv[:, 1] - cam["cy"]) / cam["fy"]
    rd = np.hypot(xd, yd)
    r = rd.copy()
    for _ in range(20):
        f = r * (1 + cam["k1"] * r**2 + cam["k2"] * r**4) - rd
        r = r - f / (1 + 3 * cam["k1"] * r**2 + 5 * cam["k2"] * r**4)
    s = np.where(rd > 0, r / np.maximum(rd, 1e-300), 1.0)
    return np.stack([xd * s, yd * s], axis=1)


def triangulate(uv_l, uv_r, cam_l, cam_r, R, t):
    """(N, 3) points (left camera frame) minimizing the pixel reprojection error in both views."""
    R, t = np.asarray(R), np.asarray(t)
    nl, nr = undistort(uv_l, cam_l), undistort(uv_r, cam_r)
    P0 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P1 = np.hstack([R, t[:, None]])
    X = np.empty((len(uv_l), 3))
    for i in range(len(uv_l)):
        A = np.stack([nl[i, 0] * P0[2] - P0[0], nl[i, 1] * P0[2] - P0[1],
                      nr[i, 0] * P1[2] - P1[0], nr[i, 1] * P1[2] - P1[1]])
        h = np.linalg.svd(A)[2][-1]
        X[i] = h[:3] / h[3]

    def residual(X):
        return np.hstack([project(X, cam_l) - uv_l, project(X, cam_r, R, t) - uv_r])

    for _ in range(5):
        r0 = residual(X)
        J = np.empty((len(X), 4, 3))
        for k in range(3):
            h = 1e-6 * np.maximum(1.0, np.abs(X[:, k]))
            Xh = X.copy()
            Xh[:, k] += h
            J[:, :, k] = (residual(Xh) - r0) / h[:, None]
        JtJ = np.einsum("nik,nil->nkl", J, J)
        Jtr = np.einsum("nik,ni->nk", J, r0)
        X = X - np.linalg.solve(JtJ + 1e-12 * np.eye(3), Jtr[:, :, None])[:, :, 0]
    return X, residual(X)


def rodrigues(w):
    """Rotation matrix of the rotation vector w."""
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    k = np.asarray(w) / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


def solve_pnp(X, uv, cam, R0, t0, w=None):
    """Pose (R, t) mapping the left-camera-frame points X into the view minimizing the pixel
    reprojection error of uv (each point's two residuals weighted by sqrt(w) if w is N weights,
    whitened by the 2x2 covariances if w is N x 2 x 2): Gauss-Newton on a rotation-vector update,
    started at (R0, t0)."""
    R, t = np.asarray(R0, float), np.asarray(t0, float)
    if w is None:
        white = np.broadcast_to(np.eye(2), (len(X), 2, 2))
    elif np.ndim(w) == 1:
        white = np.sqrt(np.asarray(w, float))[:, None, None] * np.eye(2)
    else:
        # L with L' L = C^-1: the transposed Cholesky factor of the inverse covariance.
        white = np.transpose(np.linalg.cholesky(np.linalg.inv(np.asarray(w, float))), (0, 2, 1))

    def residual(R, t):
        return np.einsum("nij,nj->ni", white, project(X, cam, R, t) - uv).ravel()

    for _ in range(10):
        r0 = residual(R, t)
        J = np.empty((len(r0), 6))
        for k in range(6):
            h = 1e-7
            d = np.zeros(6)
            d[k] = h
            Rk, tk = rodrigues(d[:3]) @ R, t + d[3:]
            J[:, k] = (residual(Rk, tk) - r0) / h
        step = np.linalg.lstsq(J, -r0, rcond=None)[0]
        R, t = rodrigues(step[:3]) @ R, t + step[3:]
        if np.linalg.norm(step) < 1e-12:
            break
    return R, t


def rms(v):
    v = np.asarray(v, dtype=np.float64)
    return float(np.sqrt(np.mean(v * v))) if len(v) else None


def summarize(root, match_px):
    truth = read_jsonl(os.path.join(root, "truth.jsonl"))
    dets = read_jsonl(os.path.join(root, "ours.jsonl")) + read_jsonl(
        os.path.join(root, "peers.jsonl"), required=False)
    found = {}
    ms = defaultdict(list)
    errors = defaultdict(int)
    for r in dets:
        pts = np.array([c[:2] for c in r["corners"]], dtype=np.float64).reshape(-1, 2)
        sig = np.array([c[2] if len(c) > 2 and c[2] is not None else np.nan for c in r["corners"]])
        # Covariance [[xx, xy], [xy, yy]] (px^2) where the method reports one, else NaN.
        cov = np.full((len(r["corners"]), 2, 2), np.nan)
        for i, c in enumerate(r["corners"]):
            if len(c) > 5 and None not in c[3:6]:
                cov[i] = [[c[3], c[4]], [c[4], c[5]]]
        found[(r["image"], r["method"])] = (pts, sig, cov)
        if isinstance(r.get("ms"), (int, float)):
            ms[r["method"]].append(r["ms"])
        if r.get("error"):
            errors[r["method"]] += 1
    present = {m for _, m in found}
    methods = [m for m in OURS_ORDER + PEER_ORDER if m in present]
    methods += sorted(present - set(methods))

    # (err, bin, kind, sigma, (image, (row, col)), dx, dy, covariance)
    per = {m: [] for m in methods}
    visible = 0
    stereo = {m: {"res": [], "res_bin": defaultdict(list), "e3": [], "keys": {}} for m in methods}
    # name -> (pair, side) -> (rotation deg, translation mm, tip mm); methods with a sigma also
    # get a "(sigma-weighted)" entry, each corner weighted by 1/sigma^2, and methods with a
    # covariance a "(covariance-weighted)" one.
    pnp = defaultdict(dict)
    for t in truth:
        kind = t["surface"]["kind"]
        views = t["views"]
        for v in views.values():
            visible += sum(c["visible"] for c in v["corners"])
        matched = {}
        for m in methods:
            matched[m] = {}
            for side, v in views.items():
                pts, sig, cov = found.get((v["image"], m),
                                          (np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2, 2))))
                mm = match(v, pts, match_px)
                matched[m][side] = mm
                kap = {(c["row"], c["col"]): max(abs(c["curvature"][0]), abs(c["curvature"][1]))
                       for c in v["corners"]}
                for key, (dx, dy, j) in mm.items():
                    per[m].append((math.hypot(dx, dy), curvature_bin(kap[key]), kind, sig[j],
                                   (v["image"], key), dx, dy, cov[j]))
        # Stereo.
        cam_l, cam_r = views["L"]["camera"], views["R"]["camera"]
        cols = t["cols"]
        kap2 = defaultdict(float)
        for v in views.values():
            for c in v["corners"]:
                k = max(abs(c["curvature"][0]), abs(c["curvature"][1]))
                kap2[(c["row"], c["col"])] = max(kap2[(c["row"], c["col"])], k)
        X_all = np.asarray(t["points3d"], dtype=np.float64)
        tip = X_all.mean(axis=0) + np.array([0.0, 0.0, -150.0])
        poses = {"L": (np.eye(3), np.zeros(3)),
                 "R": (np.asarray(t["rig"]["R"]), np.asarray(t["rig"]["t"]))}
        for m in methods:
            for side, v in views.items():
                mm = matched[m][side]
                if len(mm) < 8:
                    continue
                tv = {(c["row"], c["col"]): c for c in v["corners"]}
                keys = sorted(mm)
                uv = np.array([[tv[k]["x"] + mm[k][0], tv[k]["y"] + mm[k][1]] for k in keys])
                X = np.array([t["points3d"][r * cols + c] for r, c in keys])
                R0, t0 = poses[side]
                _, sig, cov = found.get((v["image"], m), (None, np.zeros(0), np.zeros((0, 2, 2))))
                s_k = np.array([sig[mm[k][2]] for k in keys])
                variants = [(m, None)]
                if np.isfinite(s_k).any():
                    # Corners without a sigma (failed refinement) get the worst one.
                    s_k = np.where(np.isfinite(s_k), s_k, np.nanmax(s_k))
                    variants.append((m + " (sigma-weighted)", 1.0 / np.maximum(s_k, 1e-3) ** 2))
                c_k = np.array([cov[mm[k][2]] for k in keys]).reshape(-1, 2, 2)
                has = np.isfinite(c_k).all(axis=(1, 2))
                if has.any():
                    # Without a covariance: the worst sigma's, isotropic. Each covariance gets
                    # the 1e-3 px floor of the sigma weights on its diagonal.
                    worst = np.nanmax(s_k) ** 2 * np.eye(2)
                    c_k = np.where(has[:, None, None], c_k, worst) + 1e-6 * np.eye(2)
                    variants.append((m + " (covariance-weighted)", c_k))
                for name, w in variants:
                    R, tt = solve_pnp(X, uv, v["camera"], R0, t0, w)
                    cos = (np.trace(R @ R0.T) - 1) / 2
                    rot = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
                    tip_err = float(np.linalg.norm((R @ tip + tt) - (R0 @ tip + t0)))
                    pnp[name][(t["pair"], side)] = (rot, float(np.linalg.norm(tt - t0)), tip_err)
        for m in methods:
            keys = sorted(set(matched[m]["L"]) & set(matched[m]["R"]))
            if not keys:
                continue
            tl = {(c["row"], c["col"]): c for c in views["L"]["corners"]}
            tr = {(c["row"], c["col"]): c for c in views["R"]["corners"]}
            ml, mr = matched[m]["L"], matched[m]["R"]
            uv_l = np.array([[tl[k]["x"] + ml[k][0], tl[k]["y"] + ml[k][1]] for k in keys])
            uv_r = np.array([[tr[k]["x"] + mr[k][0], tr[k]["y"] + mr[k][1]] for k in keys])
            X, res = triangulate(uv_l, uv_r, cam_l, cam_r, t["rig"]["R"], t["rig"]["t"])
            X_true = np.array([t["points3d"][r * cols + c] for r, c in keys])
            s = stereo[m]
            for i, k in enumerate(keys):
                obs = [math.hypot(res[i, 0], res[i, 1]), math.hypot(res[i, 2], res[i, 3])]
                s["res"] += obs
                s["res_bin"][curvature_bin(kap2[k])] += obs
                e3 = float(np.linalg.norm(X[i] - X_true[i]))
                s["e3"].append(e3)
                s["keys"][(t["pair"], k)] = obs
    return methods, per, visible, stereo, pnp, ms, errors


def fmt(v, spec=".4f"):
    return "-" if v is None else format(v, spec)


def by_bin(entries, stat):
    """Cells `stat(errors) (count)` per curvature bin."""
    cells = []
    for b in range(len(BIN_NAMES)):
        eb = [x[0] for x in entries if x[1] == b]
        cells.append(f"{fmt(stat(eb))} ({len(eb)})" if eb else "- (0)")
    return cells


def median(v):
    return float(np.median(v)) if len(v) else None


BOUND_SQUARES = 4  # the corner window of the bound, in squares (as `near_squares` in board_fit)


def line_offset_variance(points, i, beyond, w):
    """Variance (px^2) of a step edge's normal offset at points[i], the edge running along the
    chord polyline `points` (ordered, i the corner) and `beyond` of the end spacings past each
    end, at most BOUND_SQUARES squares from the corner, the offset a parabola in arc length and
    every px of edge carrying the Fisher information w."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(np.asarray(points), axis=0).T))])
    s -= s[i]
    square = (s[-1] - s[0]) / (len(s) - 1)
    lo = max(s[0] - beyond * (s[1] - s[0]), -BOUND_SQUARES * square)
    hi = min(s[-1] + beyond * (s[-1] - s[-2]), BOUND_SQUARES * square)
    u = np.arange(lo, hi + 1e-9, 1.0)
    X = np.vstack([np.ones_like(u), u, u * u]).T
    F = w * X.T @ X
    if np.linalg.cond(F) > 1e12:
        return math.inf
    return float(np.linalg.inv(F)[0, 0])


def information_bound(view, beyond):
    """{(row, col): bound px} for the visible corners of a view with both lines (see item 7)."""
    cam = view["camera"]
    gx, gy = view.get("lighting_gradient", (0.0, 0.0))
    sigma_t = math.sqrt(view["blur"] ** 2 + 1.0 / 12.0)
    var_n = view["noise"] ** 2 + 1.0 / (12.0 * 255.0 ** 2)
    grid = {(c["row"], c["col"]): c for c in view["corners"]}
    out = {}
    for (r, c), q in grid.items():
        if not q["visible"]:
            continue
        gain = 1 + gx * (q["x"] / cam["width"] - 0.5) + gy * (q["y"] / cam["height"] - 0.5)
        contrast = (view["white"] - view["black"]) * gain
        w = contrast * contrast / (2 * math.sqrt(math.pi) * sigma_t * var_n)
        normals, variances = [], []
        for dr, dc in ((0, 1), (1, 0)):
            def run(sign):
                pts = []
                for j in range(1, BOUND_SQUARES + 1):
                    n = grid.get((r + sign * dr * j, c + sign * dc * j))
                    if n is None or not n["visible"]:
                        break
                    pts.append((n["x"], n["y"]))
                return pts
            back, fwd = run(-1), run(1)
            if not back and not fwd:
                break
            pts = back[::-1] + [(q["x"], q["y"])] + fwd
            i = len(back)
            a, b = np.asarray(pts[max(i - 1, 0)]), np.asarray(pts[min(i + 1, len(pts) - 1)])
            t = (b - a) / np.linalg.norm(b - a)
            normals.append([-t[1], t[0]])
            variances.append(line_offset_variance(pts, i, beyond, w))
        if len(normals) < 2 or not all(math.isfinite(v) for v in variances):
            continue
        A = np.asarray(normals)
        if abs(np.linalg.det(A)) < 1e-6:
            continue
        Ai = np.linalg.inv(A)
        out[(r, c)] = math.sqrt(float(np.trace(Ai @ np.diag(variances) @ Ai.T)))
    return out


def bound_tables(root, per, methods):
    """The bound per curvature bin, and each method's RMSE over the bound on its corners."""
    truth = read_jsonl(os.path.join(root, "truth.jsonl"))
    if not truth or not all("white" in v for t in truth for v in t["views"].values()):
        return []
    bounds = {0.0: {}, 1.0: {}}
    kap = {}
    for t in truth:
        for v in t["views"].values():
            for beyond, b in bounds.items():
                b.update({(v["image"], k): x for k, x in information_bound(v, beyond).items()})
            for c in v["corners"]:
                kap[(v["image"], (c["row"], c["col"]))] = curvature_bin(
                    max(abs(c["curvature"][0]), abs(c["curvature"][1])))
    head = ["bound / method"] + BIN_NAMES + ["all", "top / flattest"]
    body = []
    for beyond, name in ((0.0, "bound, edges end at the last visible corner"),
                         (1.0, "bound, edges run one square beyond it")):
        cells, per_bin = [name], []
        for b in range(len(BIN_NAMES)):
            xs = [x for k, x in bounds[beyond].items() if kap[k] == b]
            per_bin.append(rms(xs))
            cells.append(f"{fmt(per_bin[-1])} ({len(xs)})" if xs else "- (0)")
        cells.append(fmt(rms(list(bounds[beyond].values()))))
        ok = per_bin[0] and per_bin[-1]
        cells.append(f"{per_bin[-1] / per_bin[0]:.2f}" if ok else "-")
        body.append(cells)
    tight = bounds[1.0]
    for m in methods:
        cells, ratios = [f"{m}: RMSE / bound"], []
        for b in range(len(BIN_NAMES)):
            pairs = [(x[0], tight[x[4]]) for x in per[m] if x[1] == b and x[4] in tight]
            ratios.append(rms([e for e, _ in pairs]) / rms([d for _, d in pairs])
                          if pairs else None)
            cells.append(f"{ratios[-1]:.1f}" if pairs else "-")
        pairs = [(x[0], tight[x[4]]) for x in per[m] if x[4] in tight]
        cells.append(f"{rms([e for e, _ in pairs]) / rms([d for _, d in pairs]):.1f}"
                     if pairs else "-")
        cells.append(f"{ratios[-1] / ratios[0]:.2f}" if ratios[0] and ratios[-1] else "-")
        body.append(cells)
    return [("Edge-information bound (px, RMS over the visible true corners) by curvature, and "
             "each method's RMSE over the bound (one square beyond) on its matched corners; "
             "last column: top bin over flattest", head, body)]


def tables(root, match_px):
    methods, per, visible, stereo, pnp, ms, errors = summarize(root, match_px)
    out = []

    head = ["method"] + BIN_NAMES + ["all RMSE", "median", "p95", "matched"]
    body = []
    for m in methods:
        e = per[m]
        row = [m] + by_bin(e, rms)
        errs = np.array([x[0] for x in e])
        row += [fmt(rms(errs)), fmt(float(np.median(errs)) if len(errs) else None),
                fmt(float(np.percentile(errs, 95)) if len(errs) else None),
                f"{len(errs) / visible:.1%}" if visible else "-"]
        body.append(row)
    out.append(("Error against truth (px) by local edge curvature (1e-3 px^-1): RMSE (corners); "
                f"matched: share of the {visible} visible true corners found within "
                f"{match_px:g} px",
                head, body))

    out.append(("Median error against truth (px) by local edge curvature (corners)",
                ["method"] + BIN_NAMES, [[m] + by_bin(per[m], median) for m in methods]))

    common = set.intersection(*({x[4] for x in per[m]} for m in methods)) if methods else set()
    out.append((f"Error against truth (px) on the {len(common)} corners every method found: "
                "RMSE (corners)", ["method"] + BIN_NAMES,
                [[m] + by_bin([x for x in per[m] if x[4] in common], rms) for m in methods]))

    kinds = sorted({x[2] for m in methods for x in per[m]})
    head = ["method"] + kinds
    body = []
    for m in methods:
        row = [m]
        for k in kinds:
            ek = [x[0] for x in per[m] if x[2] == k]
            row.append(f"{fmt(rms(ek))} ({len(ek)})" if ek else "- (0)")
        body.append(row)
    out.append(("Error against truth (px) by surface: RMSE (corners)", head, body))

    ref = stereo.get(REFERENCE, {}).get("keys", {})
    head = ["method", "corners", "reproj RMSE px", "3-D RMSE mm", "3-D median mm",
            f"reproj / {REFERENCE} (shared corners)"]
    body = []
    for m in methods:
        s = stereo[m]
        shared = [k for k in s["keys"] if k in ref]
        ratio = None
        if shared and m != REFERENCE:
            a = rms([o for k in shared for o in s["keys"][k]])
            b = rms([o for k in shared for o in ref[k]])
            ratio = a / b if b else None
        ratio_s = "1" if m == REFERENCE and ref else (
            f"{ratio:.2f} ({len(shared)})" if ratio is not None else "-")
        body.append([m, str(len(s["e3"])), fmt(rms(s["res"])), fmt(rms(s["e3"]), ".3f"),
                     fmt(float(np.median(s["e3"])) if s["e3"] else None, ".3f"), ratio_s])
    out.append(("Stereo triangulation with the known rig (corners found in both views)",
                head, body))

    head = ["method"] + BIN_NAMES
    body = []
    for m in methods:
        rb = stereo[m]["res_bin"]
        body.append([m] + [f"{fmt(rms(rb[b]))} ({len(rb[b]) // 2})" if rb[b] else "- (0)"
                           for b in range(len(BIN_NAMES))])
    out.append(("Stereo reprojection RMSE (px) by curvature (max over both views; 1e-3 px^-1): "
                "RMSE (corners)", head, body))

    ref = pnp.get(REFERENCE, {})
    head = ["method", "views", "rotation RMS deg", "rotation median deg", "translation RMS mm",
            "tip RMS mm", "tip median mm", f"tip / {REFERENCE} (shared views)"]
    body = []
    weightings = ("", " (sigma-weighted)", " (covariance-weighted)")
    for m in [n for m in methods for n in (m + w for w in weightings) if n in pnp]:
        v = pnp[m]
        e = np.array(list(v.values()))
        shared = [k for k in v if k in ref]
        ratio = "1" if m == REFERENCE else "-"
        if shared and m != REFERENCE:
            b = rms([ref[k][2] for k in shared])
            ratio = f"{rms([v[k][2] for k in shared]) / b:.2f} ({len(shared)})" if b else "-"
        body.append([m, str(len(v)), fmt(rms(e[:, 0])), fmt(float(np.median(e[:, 0]))),
                     fmt(rms(e[:, 1]), ".3f"), fmt(rms(e[:, 2]), ".3f"),
                     fmt(float(np.median(e[:, 2])), ".3f"), ratio])
    out.append(("Pose estimation (PnP) of the bent board in each view, from its matched corners "
                "(at least 8); tip: a point 150 mm in front of the board's centre", head, body))

    head = ["method", "corners with sigma", "median sigma px", "within 1 sigma", "2 sigma",
            "3 sigma", "RMS err/sigma", "per axis within 1 sigma", "2 sigma"]
    body = []
    for m in methods:
        es = np.array([(x[0], x[3], x[5], x[6]) for x in per[m]
                       if np.isfinite(x[3]) and x[3] > 0])
        if not len(es):
            continue
        z = es[:, 0] / es[:, 1]
        axes = np.abs(es[:, 2:4]) / es[:, 1:2]
        body.append([m, str(len(es)), fmt(float(np.median(es[:, 1]))),
                     *[f"{np.mean(z <= k):.1%}" for k in (1, 2, 3)], f"{rms(z):.2f}",
                     *[f"{np.mean(axes <= k):.1%}" for k in (1, 2)]])
    if body:
        out.append(("Reported sigma against the actual error (isotropic 2-D Gaussian: "
                    + ", ".join(f"{g:.1%}" for g in GAUSS_2D) + ", RMS err/sigma 1.41; per axis,"
                    " |dx| and |dy| against sigma, a 1-D Gaussian: 68.3%, 95.4%)",
                    head, body))

    head = ["method", "corners with covariance", "d within 1", "2", "3", "mean d^2",
            "per axis within 1 own sigma", "2 own sigmas"]
    body = []
    for m in methods:
        rows = [(x[5], x[6], x[7]) for x in per[m] if np.isfinite(x[7]).all()]
        if not rows:
            continue
        e = np.array([[dx, dy] for dx, dy, _ in rows])
        c = np.array([cv for _, _, cv in rows])
        d2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e)
        axes = np.abs(e) / np.sqrt(np.stack([c[:, 0, 0], c[:, 1, 1]], axis=1))
        body.append([m, str(len(rows)), *[f"{np.mean(d2 <= k * k):.1%}" for k in (1, 2, 3)],
                     f"{float(np.mean(d2)):.2f}", *[f"{np.mean(axes <= k):.1%}" for k in (1, 2)]])
    if body:
        out.append(("Reported covariance against the actual error: Mahalanobis distance d (a 2-D "
                    "Gaussian: " + ", ".join(f"{g:.1%}" for g in GAUSS_2D) + ", mean d^2 2.00); "
                    "per axis, |dx| / sqrt(C_xx) and |dy| / sqrt(C_yy) (a 1-D Gaussian: 68.3%, "
                    "95.4%)", head, body))

    out += bound_tables(root, per, methods)

    head = ["method", "mean ms / view", "views", "failures (raised, crashed, timed out)"]
    body = [[m, fmt(float(np.mean(ms[m])) if ms[m] else None, ".0f"), str(len(ms[m])),
             str(errors[m])] for m in methods]
    out.append(("Run time (indicative: ours in-process on all cores; peers one thread per view, "
                "two views at a time)", head, body))
    return out


def render(tabs, markdown):
    lines = []
    for title, head, body in tabs:
        lines.append(f"**{title}**" if markdown else f"== {title} ==")
        lines.append("")
        if markdown:
            lines.append("| " + " | ".join(head) + " |")
            lines.append("|" + "|".join(" --- " if i == 0 else " ---: " for i in range(len(head)))
                         + "|")
            lines += ["| " + " | ".join(r) + " |" for r in body]
        else:
            widths = [max(len(x) for x in col) for col in zip(head, *body)]
            for i, r in enumerate([head] + body):
                lines.append("  ".join(c.ljust(w) if j == 0 else c.rjust(w)
                                       for j, (c, w) in enumerate(zip(r, widths))))
                if i == 0:
                    lines.append("  ".join("-" * w for w in widths))
        lines.append("")
    return "\n".join(lines)


def selftest(root):
    """Triangulating every pair's exact corners must give the exact 3-D corners back."""
    worst_px = worst_mm = 0.0
    n = 0
    for t in read_jsonl(os.path.join(root, "truth.jsonl")):
        views = t["views"]
        both = [(cl, cr) for cl, cr in zip(views["L"]["corners"], views["R"]["corners"])
                if cl["visible"] and cr["visible"]]
        if not both:
            continue
        uv_l = np.array([[cl["x"], cl["y"]] for cl, _ in both])
        uv_r = np.array([[cr["x"], cr["y"]] for _, cr in both])
        X, res = triangulate(uv_l, uv_r, views["L"]["camera"], views["R"]["camera"],
                             t["rig"]["R"], t["rig"]["t"])
        X_true = np.array([t["points3d"][cl["row"] * t["cols"] + cl["col"]] for cl, _ in both])
        worst_px = max(worst_px, float(np.abs(res).max()))
        worst_mm = max(worst_mm, float(np.linalg.norm(X - X_true, axis=1).max()))
        n += len(both)
    worst_deg = worst_tip = worst_white = 0.0
    for t in read_jsonl(os.path.join(root, "truth.jsonl")):
        poses = {"L": (np.eye(3), np.zeros(3)),
                 "R": (np.asarray(t["rig"]["R"]), np.asarray(t["rig"]["t"]))}
        tip = np.asarray(t["points3d"]).mean(axis=0) + np.array([0.0, 0.0, -150.0])
        for side, v in t["views"].items():
            vis = [c for c in v["corners"] if c["visible"]]
            if len(vis) < 8:
                continue
            X = np.array([t["points3d"][c["row"] * t["cols"] + c["col"]] for c in vis])
            uv = np.array([[c["x"], c["y"]] for c in vis])
            R0, t0 = poses[side]
            start = (rodrigues([0.03, -0.02, 0.05]) @ R0, t0 + np.array([4.0, -3.0, 6.0]))
            R, tt = solve_pnp(X, uv, v["camera"], *start)
            # On exact corners any whitening reaches the same (exact) pose.
            Rc, tc = solve_pnp(X, uv, v["camera"], *start,
                               np.broadcast_to([[4.0, 1.0], [1.0, 2.0]], (len(X), 2, 2)))
            worst_white = max(worst_white, float(np.abs(Rc - R).max()),
                              float(np.abs(tc - tt).max()))
            cos = (np.trace(R @ R0.T) - 1) / 2
            worst_deg = max(worst_deg, math.degrees(math.acos(max(-1.0, min(1.0, cos)))))
            worst_tip = max(worst_tip, float(np.linalg.norm(R @ tip + tt - (R0 @ tip + t0))))
    # The bound of a straight edge 160 px long through the corner at its middle: the intercept
    # of a least-squares parabola over L px of unit information has variance 9 / (4 L); two such
    # lines crossing at right angles put the corner's squared error at twice that.
    chain = [(20.0 * k, 0.0) for k in range(-4, 5)]
    line_var = line_offset_variance(chain, 4, 0.0, 1.0)
    cross = {"camera": {"width": 400, "height": 400}, "blur": math.sqrt(1 - 1 / 12),
             "noise": math.sqrt(1 / (2 * math.sqrt(math.pi)) - 1 / (12 * 255 ** 2)),
             "black": 0.0, "white": 1.0,
             "corners": [{"row": r, "col": c, "x": 200 + 20.0 * c, "y": 200 + 20.0 * r,
                          "visible": True} for r in range(-4, 5) for c in range(-4, 5)]}
    corner = information_bound(cross, 0.0)[(0, 0)]
    bound_ok = (abs(line_var / (9 / (4 * 160)) - 1) < 0.02
                and abs(corner ** 2 / (2 * line_var) - 1) < 1e-9)
    ok = (n > 0 and worst_px < 1e-6 and worst_mm < 1e-6 and worst_deg < 1e-4
          and worst_tip < 1e-4 and worst_white < 1e-6 and bound_ok)
    print(f"selftest: {n} true corners triangulated, worst reprojection {worst_px:.2e} px, "
          f"worst 3-D error {worst_mm:.2e} mm; poses from the exact corners: worst rotation "
          f"{worst_deg:.2e} deg, worst tip {worst_tip:.2e} mm (whitened by a covariance: "
          f"{worst_white:.1e} from the unweighted pose); edge-information bound of a "
          f"straight 160 px edge {line_var:.5f} (9/640 = {9 / 640:.5f}), of a right-angle "
          f"corner {corner ** 2:.5f}: {'OK' if ok else 'FAILED'}")
    return 0 if ok else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dir")
    ap.add_argument("--markdown", action="store_true", help="markdown tables")
    ap.add_argument("--match-px", type=float, default=2.0,
                    help="largest distance (px) of a detection to its true corner (2)")
    ap.add_argument("--selftest", action="store_true",
                    help="check the triangulation on the exact truth and exit")
    a = ap.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    if a.selftest:
        sys.exit(selftest(a.dir))
    print(render(tables(a.dir, a.match_px), a.markdown))


if __name__ == "__main__":
    main()
