#!/usr/bin/env python3
"""Speed of board detection: conic-corners against its peers, on the same images in one run.

Usage (bench/detect_speed.sh renders the board and builds the binary first):
  detect_speed.py --cli target/release/conic-corners --board B.png --truth B.json
                  [--curve curve_6.jpg] [--runs 10] [--budget 5] [--markdown] [--markdown-out MD] [--json OUT]

Issue "Board detection", item 8: detect + refine of a 1920x1200 image with a 9x9-corner board in
<= 15 ms on one core, and >= 5x faster than findChessboardCornersSB in the same run.

Fairness. Every method runs on one thread (cv2.setNumThreads(1); OMP_NUM_THREADS,
OPENBLAS_NUM_THREADS, MKL_NUM_THREADS, RAYON_NUM_THREADS = 1 for the Python peers, whose Rust
parts use rayon, and for the conic-corners process). Only the detection call is timed, on an image
already decoded in memory: for the peers a time.perf_counter() pair around the call; for
conic-corners the `timing_ms.total` of its JSON, which `detect` measures around the pipeline
(pre-filter to refinement) and which excludes reading, decoding and the u8 -> f32 conversion. The
binary gets the image 1 + runs times in one invocation (processed one after the other, as the
rayon pool has one thread); the first is the warm-up. The median wall time of 3 separate
one-image invocations (start-up, decode, detect, JSON) is printed for context.

Each peer is called once to warm up, then `runs` times; a peer slower than `budget` seconds in
total gets fewer runs (at least 3, and the count is printed): 10 runs of a 10 s call would not fit
a shared machine. The median is reported.

Methods:
  conic-corners         `conic-corners detect` with default parameters (the CLI's).
  opencv-fcc+csp        findChessboardCorners(pattern, default flags) then, if found,
                        cornerSubPix(winSize (5, 5), zeroZone (-1, -1), EPS+COUNT 40 / 0.001).
  opencv-sb             findChessboardCornersSB(pattern), default flags.
  opencv-sb-accuracy    findChessboardCornersSB(pattern, CALIB_CB_ACCURACY).
  libcbdetect           Geiger et al.'s detector: min-max normalisation (as in bench/peers.py),
                        find_corners() and find_board_from_corners(); corners = board corners.
  calib-targets         calib_targets.detect_chessboard with default parameters.
  chess-corners         ChESS corners + saddle-point refiner (radius 2), no board structure: a
                        corner detector only, for context.
OpenCV needs the pattern size: 9x9 inner corners for the rendered board, 9x11 for curve_6 (the
grid calib-targets labels there; the dots of the HydraMarker may defeat OpenCV: a failure is
reported as 0 corners).

Columns: median ms, runs, corners found (all boards), median distance (px) from each visible true
corner to the nearest detection within 3 px and the share of true corners so matched (rendered
board only), and ratio = method ms / conic-corners ms on the same image (> 1: slower than ours).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

# peer_detectors (through peers.py) pins the peers' thread pools to one thread before they load.
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peer_detectors import (  # noqa: E402
    calib_targets, chess_corners, libcbdetect_board, opencv_fcc, opencv_sb,
)

import cv2  # noqa: E402
import numpy as np  # noqa: E402

MATCH_PX = 3.0
WALL_RUNS = 3


def peers(pattern):
    """(name, callable on a grey u8 image returning (N, 2) corners)."""
    return [
        ("opencv-fcc+csp", lambda img: opencv_fcc(img, pattern)),
        ("opencv-sb", lambda img: opencv_sb(img, pattern)),
        ("opencv-sb-accuracy", lambda img: opencv_sb(img, pattern, cv2.CALIB_CB_ACCURACY)),
        ("libcbdetect", libcbdetect_board),
        ("calib-targets", calib_targets),
        ("chess-corners", lambda img: chess_corners(img, 2)),
    ]


def accuracy(points, truth):
    """(median error px, matched share) of the visible truth against `points`, or (None, None)."""
    if truth is None:
        return None, None
    t = np.array([[c["x"], c["y"]] for c in truth if c["visible"]], dtype=np.float64)
    if len(points) == 0 or len(t) == 0:
        return None, 0.0
    d = np.hypot(t[:, None, 0] - points[None, :, 0], t[:, None, 1] - points[None, :, 1]).min(axis=1)
    hit = d[d <= MATCH_PX]
    return (float(np.median(hit)) if len(hit) else None), len(hit) / len(t)


def time_peer(fn, img, runs, budget):
    t0 = time.perf_counter()
    pts = fn(img)  # warm-up
    first = time.perf_counter() - t0
    n = runs if budget <= 0 or first * runs <= budget else max(3, min(runs, int(budget / first)))
    ms = []
    for _ in range(n):
        t0 = time.perf_counter()
        pts = fn(img)
        ms.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ms), n, pts


def run_ours(cli, path, runs, env):
    """Median timing_ms (total and per stage) over `runs` after one warm-up, corners, wall ms."""
    out = subprocess.run([cli, "detect", *([path] * (runs + 1))], env=env, check=True,
                         capture_output=True, text=True).stdout
    dets = [json.loads(line) for line in out.splitlines() if line.strip()][1:]
    stages = {k: statistics.median(d["timing_ms"][k] for d in dets) for k in dets[0]["timing_ms"]}
    pts = np.array([[c["x"], c["y"]] for b in dets[0]["boards"] for c in b["corners"]],
                   dtype=np.float64).reshape(-1, 2)
    wall = []
    for _ in range(WALL_RUNS):
        t0 = time.perf_counter()
        subprocess.run([cli, "detect", path], env=env, check=True, capture_output=True)
        wall.append((time.perf_counter() - t0) * 1e3)
    return stages, len(dets), pts, statistics.median(wall)


def fmt(v, spec, none="-"):
    return none if v is None else format(v, spec)


def render(rows, stages, markdown):
    """The results table and conic-corners' stage timings, as text or markdown."""
    head = ["method", "image", "median ms", "runs", "corners", "err px", "matched", "ratio"]
    body = [[r["method"], r["image"], f"{r['ms']:.1f}", str(r["runs"]), str(r["corners"]),
             fmt(r["err"], ".3f"), fmt(r["matched"], ".0%"), fmt(r["ratio"], ".1f") + "x"]
            for r in rows]
    keys = ["prefilter", "election", "connectivity", "completion", "refine", "board_fit", "total",
            "wall_ms"]
    what = ("conic-corners stages, median ms (total excludes decoding; wall_ms: one process "
            f"reading, decoding, detecting and printing one image, median of {WALL_RUNS})")
    lines = []
    if markdown:
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "|".join(" --- " if i < 2 else " ---: " for i in range(len(head))) + "|")
        lines += ["| " + " | ".join(b) + " |" for b in body]
        lines += ["", f"_{what}:_", "", "| image | " + " | ".join(keys) + " |",
                  "| --- |" + " ---: |" * len(keys)]
        lines += [f"| {name} | " + " | ".join(f"{st[k]:.1f}" for k in keys) + " |"
                  for name, st in stages.items()]
    else:
        widths = [max(len(x) for x in col) for col in zip(head, *body)]
        for i, line in enumerate([head] + body):
            lines.append("  ".join(c.ljust(w) if j < 2 else c.rjust(w)
                                   for j, (c, w) in enumerate(zip(line, widths))))
            if i == 0:
                lines.append("  ".join("-" * w for w in widths))
        lines += ["", f"{what}:"]
        lines += [f"  {name:<8} " + "  ".join(f"{k} {st[k]:.1f}" for k in keys)
                  for name, st in stages.items()]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cli", required=True, help="the conic-corners binary (release build)")
    ap.add_argument("--board", required=True, help="rendered board PNG (render-board)")
    ap.add_argument("--truth", help="its truth JSON (render-board), for the err/matched columns")
    ap.add_argument("--curve", help="curve_6.jpg (skipped with a message when missing)")
    ap.add_argument("--runs", type=int, default=10, help="timed runs after the warm-up (10)")
    ap.add_argument("--budget", type=float, default=5.0,
                    help="seconds per method and image before runs are cut to >= 3 (0: never)")
    ap.add_argument("--markdown", action="store_true", help="print markdown tables")
    ap.add_argument("--markdown-out", metavar="FILE", help="also write the markdown tables here")
    ap.add_argument("--json", help="also write every row (and our stage timings) to this file")
    a = ap.parse_args()
    cv2.setNumThreads(1)
    env = dict(os.environ, RAYON_NUM_THREADS="1", OMP_NUM_THREADS="1")

    truth = None
    pattern = (9, 9)
    if a.truth:
        with open(a.truth) as f:
            t = json.load(f)
        truth, pattern = t["corners"], (t["cols"], t["rows"])
    images = [("board", a.board, truth, pattern)]
    if a.curve and os.path.exists(a.curve):
        images.append(("curve_6", a.curve, None, (9, 11)))
    elif a.curve:
        print(f"detect_speed: skipping curve_6: {a.curve} not found", file=sys.stderr)

    rows, stages = [], {}
    for name, path, truth, pattern in images:
        img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if img is None:
            sys.exit(f"detect_speed: cannot read {path}")
        print(f"detect_speed: {name} ({img.shape[1]}x{img.shape[0]}) ...", file=sys.stderr)
        st, n, pts, wall = run_ours(a.cli, path, a.runs, env)
        stages[name] = dict(st, wall_ms=wall)
        ours = st["total"]
        err, matched = accuracy(pts, truth)
        rows.append(dict(method="conic-corners", image=name, ms=ours, runs=n, corners=len(pts),
                         err=err, matched=matched, ratio=1.0))
        for method, fn in peers(pattern):
            try:
                ms, n, pts = time_peer(fn, img, a.runs, a.budget)
            except Exception as e:  # a peer crashing on an image is a failure, not a crash
                print(f"detect_speed: {method} on {name}: {type(e).__name__}: {e}", file=sys.stderr)
                continue
            err, matched = accuracy(pts, truth)
            rows.append(dict(method=method, image=name, ms=ms, runs=n, corners=len(pts),
                             err=err, matched=matched, ratio=ms / ours))

    sys.stdout.write(render(rows, stages, a.markdown))
    if a.markdown_out:
        with open(a.markdown_out, "w") as f:
            f.write(render(rows, stages, True))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "conic_corners_stages": stages}, f, indent=1)

if __name__ == "__main__":
    main()
