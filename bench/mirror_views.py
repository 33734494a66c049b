#!/usr/bin/env python3
"""The curved-board benchmark's views and their mirror images: is the accuracy the same?

Usage: mirror_views.py DIR --cli CLI [--baseline CLI2]

DIR is an output directory of `board-accuracy` (DIR/truth.jsonl, DIR/images/*.png). Every view is
mirrored left-right (exactly: no resampling) into DIR/mirrored/images, its truth with x turned
into w - 1 - x (pixel centres at integers). A mirror image is as likely a photo as the original,
and a method that treats both alike has the same error distribution on both sets; one whose rules
depend on which way round something is numbered (rays, labels, scanlines taken from one end) need
not. CLI (and BASELINE, if given) runs `detect` on both sets, and for each the RMSE (px) of the
matched corners by curvature bin is printed as in board_report.py (visible true corners with a
detection within 2 px; bins of the local edge curvature, 1e-3 px^-1), with the top bin over the
flattest. Exit status 0.
"""
import argparse
import json
import math
import pathlib
import subprocess
from collections import defaultdict

import numpy as np
from PIL import Image, ImageOps

from board_report import BIN_NAMES, curvature_bin, match


def mirror(root):
    """Writes the mirrored views and truth under root/mirrored (once); returns that directory."""
    out = root / "mirrored"
    (out / "images").mkdir(parents=True, exist_ok=True)
    if (out / "truth.jsonl").exists():
        return out
    lines = []
    with open(root / "truth.jsonl") as f:
        for line in f:
            t = json.loads(line)
            for view in t["views"].values():
                path = root / view["image"]
                im = Image.open(path)
                ImageOps.mirror(im).save(out / view["image"])
                for c in view["corners"]:
                    c["x"] = im.width - 1 - c["x"]
            lines.append(json.dumps(t))
    (out / "truth.jsonl").write_text("\n".join(lines) + "\n")
    return out


def rmse_by_bin(root, cli):
    """RMSE (px) and count per curvature bin of `cli detect` on the views of `root`."""
    views = []
    with open(root / "truth.jsonl") as f:
        for line in f:
            views += json.loads(line)["views"].values()
    paths = [str(root / v["image"]) for v in views]
    run = subprocess.run([cli, "detect", *paths], capture_output=True, text=True)
    found = {}
    for line in run.stdout.splitlines():
        d = json.loads(line)
        found[pathlib.Path(d["image"]["path"]).name] = [
            (c["x"], c["y"]) for b in d["boards"] for c in b["corners"]
        ]
    sq = defaultdict(list)
    for v in views:
        points = np.array(found.get(pathlib.Path(v["image"]).name, []), dtype=np.float64).reshape(-1, 2)
        kappa = {(c["row"], c["col"]): max(abs(k) for k in c["curvature"]) for c in v["corners"]}
        for key, (dx, dy, _) in match(v, points, 2.0).items():
            b = curvature_bin(kappa[key])
            if b is not None:
                sq[b].append(dx * dx + dy * dy)
    return [(math.sqrt(sum(s) / len(s)) if s else math.nan, len(s)) for s in
            (sq[b] for b in range(len(BIN_NAMES)))]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--cli", required=True)
    ap.add_argument("--baseline")
    args = ap.parse_args()
    root = pathlib.Path(args.dir)
    mirrored = mirror(root)
    clis = [("now", args.cli)] + ([("baseline", args.baseline)] if args.baseline else [])
    print(f"{'cli':9s} {'views':9s} " + " ".join(f"{b:>7s}" for b in BIN_NAMES) + "  top/flat")
    for label, cli in clis:
        for name, d in (("original", root), ("mirrored", mirrored)):
            r = rmse_by_bin(d, cli)
            cells = " ".join(f"{e:7.4f}" for e, _ in r)
            print(f"{label:9s} {name:9s} {cells}  {r[-1][0] / r[0][0]:.3f}")


if __name__ == "__main__":
    main()
