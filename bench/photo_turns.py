#!/usr/bin/env python3
"""The real photos turned and mirrored: does `detect` find the same corners, labelled alike?

Usage: photo_turns.py --cli CLI [--baseline CLI2] [--photos DIR] --out DIR

Each photo is converted to grey (Pillow's `L`) and written as PNG in OUT/ upright (`_up`) and
transformed exactly (Pillow's `transpose`, no resampling): turned by 90°, 180° and 270° (`_r90`,
`_r180`, `_r270`, counter-clockwise) and mirrored (`_fx` left-right, `_fy` top-bottom, `_tr`
across the main diagonal). CLI (and BASELINE, if given) runs `detect` on all of them. Every
corner of a transformed copy is mapped back into the upright copy's pixels and matched to the
upright copy's corners within 3 px: `lost` counts the upright corners with no match, `gained` the
copy's corners with none. `labels` is `ok` when one of the eight signed permutations of the label
axes plus one offset maps every matched corner's label onto its upright match's, else the number
of matched corners that disagree with the best such map. `σ` counts the matched pairs more than
0.1 px apart whose difference their covariances (the copy's turned back) do not allow: Mahalanobis
distance² above 11.8, the 99.7 % point of χ² with two degrees of freedom. A copy is the same image,
so such a pair is a corner at least one of whose σ is too small. Exit status 0.
"""
import collections
import json
import math
import pathlib
import subprocess

from PIL import Image
from photo_common import photo_args

# name: (Pillow transpose, map of a pixel centre (x, y) of the copy back to the upright image of
# size (w, h), its linear part)
TRANSFORMS = {
    "r90": (Image.ROTATE_90, lambda x, y, w, h: (w - 1 - y, x), ((0, -1), (1, 0))),
    "r180": (Image.ROTATE_180, lambda x, y, w, h: (w - 1 - x, h - 1 - y), ((-1, 0), (0, -1))),
    "r270": (Image.ROTATE_270, lambda x, y, w, h: (y, h - 1 - x), ((0, 1), (-1, 0))),
    "fx": (Image.FLIP_LEFT_RIGHT, lambda x, y, w, h: (w - 1 - x, y), ((-1, 0), (0, 1))),
    "fy": (Image.FLIP_TOP_BOTTOM, lambda x, y, w, h: (x, h - 1 - y), ((1, 0), (0, -1))),
    "tr": (Image.TRANSPOSE, lambda x, y, w, h: (y, x), ((0, 1), (1, 0))),
}
MATCH_PX = 3.0
# The 99.7 % point of χ² with two degrees of freedom, and the smallest distance (px) counted.
CHI2_2_997 = 11.8
SIGMA_MIN_PX = 0.1


def detect(cli, paths):
    """`detect` on `paths` in one run: {file name: [(x, y, row, col, cov or None), ...]}."""
    run = subprocess.run([cli, "detect", *map(str, paths)], capture_output=True, text=True)
    found = {}
    for line in run.stdout.splitlines():
        d = json.loads(line)
        corners = [
            (c["x"], c["y"], c["row"], c["col"], c.get("cov"))
            for b in d["boards"]
            for c in b["corners"]
        ]
        found[pathlib.Path(d["image"]["path"]).name] = corners
    return found


def turned(cov, j):
    """The covariance `cov` of a copy's corner in the upright image: J cov Jᵀ."""
    return [
        [sum(j[a][k] * cov[k][l] * j[b][l] for k in range(2) for l in range(2)) for b in range(2)]
        for a in range(2)
    ]


def inconsistent(p, q):
    """Whether the corners `p` and `q` (upright pixels, covariances) lie further apart than their
    covariances allow (see the module docs)."""
    dx, dy = p[0] - q[0], p[1] - q[1]
    if p[4] is None or q[4] is None or math.hypot(dx, dy) <= SIGMA_MIN_PX:
        return False
    (a, b), (c, d) = [[p[4][i][k] + q[4][i][k] for k in range(2)] for i in range(2)]
    det = a * d - b * c
    if det <= 0:
        return False
    return (d * dx * dx - (b + c) * dx * dy + a * dy * dy) / det > CHI2_2_997


def compare(upright, copy, back, linear, size):
    """(lost, gained, label disagreements, σ-inconsistent pairs) of `copy` against `upright` (see
    the module docs)."""
    mapped = [
        (*back(x, y, *size), r, c, cov and turned(cov, linear)) for x, y, r, c, cov in copy
    ]

    def nearest(p, corners):
        best = min(corners, key=lambda q: math.hypot(q[0] - p[0], q[1] - p[1]), default=None)
        return best if best and math.hypot(best[0] - p[0], best[1] - p[1]) <= MATCH_PX else None

    lost = sum(1 for p in upright if nearest(p, mapped) is None)
    pairs = [(p, q) for p in mapped if (q := nearest(p, upright))]
    gained = len(mapped) - len(pairs)
    maps = collections.Counter()
    for p, q in pairs:
        for k in range(8):
            r, c = (p[3], p[2]) if k & 4 else (p[2], p[3])
            r, c = (-r if k & 1 else r), (-c if k & 2 else c)
            maps[(k, q[2] - r, q[3] - c)] += 1
    agree = maps.most_common(1)[0][1] if maps else 0
    return lost, gained, len(pairs) - agree, sum(inconsistent(p, q) for p, q in pairs)


def main():
    args, photos, out = photo_args("photo_turns", __doc__)
    sizes = {}
    for f in sorted(photos.glob("*.jpg")):
        im = Image.open(f).convert("L")
        sizes[f.stem] = im.size
        im.save(out / f"{f.stem}_up.png")
        for tag, (op, _, _) in TRANSFORMS.items():
            im.transpose(op).save(out / f"{f.stem}_{tag}.png")
    paths = sorted(out.glob("*.png"))
    clis = [("now", args.cli)] + ([("baseline", args.baseline)] if args.baseline else [])
    for label, cli in clis:
        found = detect(cli, paths)
        print(f"{label}: {cli}")
        print(f"{'photo':16s} {'upright':>7s}  " + "  ".join(f"{t:>19s}" for t in TRANSFORMS))
        totals = collections.Counter()
        for stem, size in sizes.items():
            upright = found.get(f"{stem}_up.png", [])
            totals["up"] += len(upright)
            cells = []
            for tag, (_, back, linear) in TRANSFORMS.items():
                copy = found.get(f"{stem}_{tag}.png", [])
                totals[tag] += len(copy)
                lost, gained, wrong, sigma = compare(upright, copy, back, linear, size)
                totals[tag, "σ"] += sigma
                labels = "ok" if wrong == 0 else f"{wrong} wrong"
                cells.append(f"{len(copy):3d} -{lost}+{gained} {labels:>5s} σ{sigma}")
            print(f"{stem:16s} {len(upright):7d}  " + "  ".join(f"{c:>19s}" for c in cells))
        cells = [f"{totals[t]:3d} σ{totals[t, 'σ']}" for t in TRANSFORMS]
        print(f"{'total':16s} {totals['up']:7d}  " + "  ".join(f"{c:>19s}" for c in cells))
        print()


if __name__ == "__main__":
    main()
