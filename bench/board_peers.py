#!/usr/bin/env python3
"""Run the board-level peers of the curved-board benchmark on its rendered views.

Usage (bench/board_accuracy.sh renders the views first):
  board_peers.py DIR [--jobs 2] [--timeout 120] [--methods m1,m2]

Reads DIR/truth.jsonl (crates/conic-corners-bench/src/bin/board_accuracy.rs; only each view's
"image" and the board's "rows" / "cols" are used, for OpenCV's pattern size) and writes
DIR/peers.jsonl, one line per view and method:
  {"image": "images/0000_L.png", "method": ..., "ms": 123.4, "corners": [[x, y], ...]}
  plus "error": "..." when the method raised, crashed or timed out (corners then empty).
Coordinates: x right, y down, the centre of the top-left pixel at (0, 0).

Methods (bench/peer_detectors.py):
  opencv-fcc+csp      findChessboardCorners + cornerSubPix (winSize (5, 5)).
  opencv-sb           findChessboardCornersSB, default flags.
  opencv-sb-accuracy  findChessboardCornersSB with CALIB_CB_ACCURACY.
  libcbdetect         Geiger et al.: find_corners + find_board_from_corners, board corners.
  calib-targets       calib_targets.detect_chessboard, default parameters.
  chess-corners-r5    ChESS + saddle-point refiner of radius 5; no board structure.

Robustness: each view runs in its own child process (this script with --one), which announces each
method and prints its result as soon as it is done; when the child crashes (a segfault in a C
extension) or a method runs longer than --timeout seconds, that method is recorded as failed and a
new child runs the remaining ones. So one peer failing on one image costs that result only. ms is
the method's wall time in the child; with --jobs > 1 views run concurrently, so times are
indicative only.
"""
import argparse
import json
import os
import select
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

METHODS = (
    "opencv-fcc+csp",
    "opencv-sb",
    "opencv-sb-accuracy",
    "libcbdetect",
    "calib-targets",
    "chess-corners-r5",
)


def runners(pattern):
    """name -> callable on a grey u8 image returning (N, 2) corners."""
    import cv2
    from peer_detectors import (calib_targets, chess_corners, libcbdetect_board, opencv_fcc,
                                opencv_sb)

    return {
        "opencv-fcc+csp": lambda img: opencv_fcc(img, pattern),
        "opencv-sb": lambda img: opencv_sb(img, pattern),
        "opencv-sb-accuracy": lambda img: opencv_sb(img, pattern, cv2.CALIB_CB_ACCURACY),
        "libcbdetect": libcbdetect_board,
        "calib-targets": calib_targets,
        "chess-corners-r5": lambda img: chess_corners(img, 5),
    }


def run_one(path, pattern, methods):
    """Child process: one JSON line per method on stdout, flushed as each finishes."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        sys.exit(f"board_peers: cannot read {path}")
    fns = runners(pattern)
    for m in methods:
        print(json.dumps({"start": m}), flush=True)
        rec = {"method": m}
        t0 = time.perf_counter()
        try:
            pts = np.asarray(fns[m](img), dtype=np.float64).reshape(-1, 2)
            pts = pts[np.all(np.isfinite(pts), axis=1)]
            rec["corners"] = [[float(x), float(y)] for x, y in pts]
        except Exception as e:  # a peer failing on one image is a miss, not a crash
            rec["corners"] = []
            rec["error"] = f"{type(e).__name__}: {e}"
        rec["ms"] = round((time.perf_counter() - t0) * 1e3, 3)
        print(json.dumps(rec), flush=True)


def run_child(cmd, env, timeout, out, todo):
    """Runs one child, filing its results into `out`; returns why it stopped early (or None).

    The child announces each method before running it; each gets `timeout` seconds, after which
    the child is killed."""
    with tempfile.TemporaryFile() as err:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, env=env, bufsize=0)
        fd, buf = p.stdout.fileno(), b""
        deadline, why = time.monotonic() + timeout, None
        while True:
            wait = deadline - time.monotonic()
            if wait <= 0 or not select.select([fd], [], [], wait)[0]:
                p.kill()
                why = f"timeout after {timeout:g} s"
                break
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                break
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if "start" in rec:
                    deadline = time.monotonic() + timeout
                elif rec.get("method") in todo:
                    out[rec["method"]] = rec
        p.stdout.close()
        code = p.wait()
        if why is None and code != 0:
            err.seek(0)
            why = f"exit status {code}: {err.read().decode(errors='replace').strip()[-300:]}"
        return why


def run_view(root, image, pattern, methods, timeout):
    """Every method on one view, in children; a crash or timeout fails one method only."""
    out, todo = {}, list(methods)
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               RAYON_NUM_THREADS="1")
    while todo:
        cmd = [sys.executable, os.path.abspath(__file__), "--one", os.path.join(root, image),
               "--pattern", f"{pattern[0]}x{pattern[1]}", "--methods", ",".join(todo)]
        why = run_child(cmd, env, timeout, out, todo)
        todo = [m for m in todo if m not in out]
        if todo:
            # The first unreported method is the one that crashed or hung.
            fail = todo.pop(0)
            out[fail] = {"method": fail, "corners": [], "ms": None,
                         "error": why or "no result"}
            print(f"board_peers: {fail} on {image}: {why}", file=sys.stderr)
    return [dict(out[m], image=image) for m in methods]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("dir", nargs="?", help="benchmark directory with truth.jsonl")
    ap.add_argument("--jobs", type=int, default=2, help="views processed concurrently (2)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per child (120)")
    ap.add_argument("--methods", help="comma-separated subset of the methods")
    ap.add_argument("--one", metavar="PNG", help=argparse.SUPPRESS)
    ap.add_argument("--pattern", help=argparse.SUPPRESS)
    a = ap.parse_args()
    methods = a.methods.split(",") if a.methods else list(METHODS)
    unknown = set(methods) - set(METHODS)
    if unknown:
        ap.error(f"unknown methods: {', '.join(sorted(unknown))}")
    if a.one:
        cols, rows = (int(v) for v in a.pattern.split("x"))
        run_one(a.one, (cols, rows), methods)
        return
    if not a.dir:
        ap.error("DIR is required")
    views = []
    with open(os.path.join(a.dir, "truth.jsonl")) as f:
        for line in f:
            if line.strip():
                t = json.loads(line)
                for side in ("L", "R"):
                    views.append((t["views"][side]["image"], (t["cols"], t["rows"])))
    out_path = os.path.join(a.dir, "peers.jsonl")
    t0 = time.time()
    with open(out_path + ".part", "w") as out, ThreadPoolExecutor(max(1, a.jobs)) as pool:
        futures = [pool.submit(run_view, a.dir, im, pat, methods, a.timeout) for im, pat in views]
        for i, fut in enumerate(futures, 1):
            out.writelines(json.dumps(r) + "\n" for r in fut.result())
            out.flush()
            print(f"board_peers: {i}/{len(views)} views, {time.time() - t0:.0f} s", file=sys.stderr)
    os.replace(out_path + ".part", out_path)
    print(f"board_peers: wrote {out_path}", file=sys.stderr)


if __name__ == "__main__":
    main()
