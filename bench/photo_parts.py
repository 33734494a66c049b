#!/usr/bin/env python3
"""Parts of the real photos: does `detect` give one board, labelled like the whole photo?

Usage: photo_parts.py --cli CLI [--baseline CLI2] [--photos DIR] --out DIR [--random N] [--seed S]
                      [--scale F]

A part of a photo shows less of the board, so the pieces on either side of a pen, a finger or a
fold of the surface meet along fewer grid lines than in the whole photo. For every photo (grey,
Pillow's `L`), the parts are its four halves, its four quarters and N random windows (each side
1/4 to 3/4 of the photo's, seeded), each scaled by F (Pillow's Lanczos filter; 1: as cut), as a
board seen from farther away. CLI runs `detect` on the whole photo and on every part. A part's
board corner within 3 of the part's pixels of a corner of the whole photo's board (mapped into
the photo's pixels, pixel centres at integers: `x = (x_part + 0.5) / F - 0.5 + left`) gives a
label offset (whole minus part); a board whose corners give more than one offset is
mislabelled. A part that gives more than one board is split (two boards of one photo are never
right: each photo shows one board). A part that gives no board is listed too (some show no
board at all, or a single column of it). With a baseline CLI, the parts whose outcome differs
are marked. Exit status 0.
"""
import collections
import json
import random
import subprocess
import sys

from PIL import Image
from photo_common import photo_args


def detect(cli, path):
    run = subprocess.run([cli, "detect", str(path)], capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"photo_parts: {cli} failed on {path}: {run.stderr.strip()}")
    return json.loads(run.stdout)["boards"]


def outcome(boards, whole, x0, y0, scale):
    """(corners per board, label offsets per board, unmatched corners per board)."""
    ref = [c for b in whole for c in b["corners"]]
    out = []
    for b in boards:
        offsets, unmatched = collections.Counter(), 0
        for c in b["corners"]:
            x = (c["x"] + 0.5) / scale - 0.5 + x0
            y = (c["y"] + 0.5) / scale - 0.5 + y0
            m = min(ref, key=lambda r: (r["x"] - x) ** 2 + (r["y"] - y) ** 2)
            if ((m["x"] - x) ** 2 + (m["y"] - y) ** 2) ** 0.5 > 3 / scale:
                unmatched += 1
            else:
                offsets[(m["row"] - c["row"], m["col"] - c["col"])] += 1
        out.append((len(b["corners"]), len(offsets), unmatched))
    return out


def verdict(out):
    if not out:
        return "no board"
    if len(out) > 1:
        return "split"
    return "mislabelled" if out[0][1] > 1 else "ok"


def main():
    def extra(ap):
        ap.add_argument("--random", type=int, default=12)
        ap.add_argument("--seed", type=int, default=4)
        ap.add_argument("--scale", type=float, default=1.0)

    args, photos, out = photo_args("photo_parts", __doc__, extra)
    if not 0.05 <= args.scale <= 1.0:
        sys.exit("photo_parts: --scale must lie in [0.05, 1]")
    rng = random.Random(args.seed)
    clis = [args.cli] + ([args.baseline] if args.baseline else [])
    counts = [collections.Counter() for _ in clis]
    differ = 0
    for f in sorted(photos.glob("*.jpg")):
        im = Image.open(f).convert("L")
        w, h = im.size
        boxes = {
            "top": (0, 0, w, h // 2), "bottom": (0, h // 2, w, h),
            "left": (0, 0, w // 2, h), "right": (w // 2, 0, w, h),
        }
        for i in range(2):
            for j in range(2):
                boxes[f"q{i}{j}"] = (i * w // 2, j * h // 2, (i + 1) * w // 2, (j + 1) * h // 2)
        for k in range(args.random):
            cw, ch = rng.randint(w // 4, 3 * w // 4), rng.randint(h // 4, 3 * h // 4)
            x, y = rng.randint(0, w - cw), rng.randint(0, h - ch)
            boxes[f"r{k}"] = (x, y, x + cw, y + ch)
        whole_png = out / f"{f.stem}.png"
        im.save(whole_png)
        wholes = [detect(cli, whole_png) for cli in clis]
        for tag, box in boxes.items():
            path = out / f"{f.stem}_{tag}.png"
            part = im.crop(box)
            if args.scale != 1.0:
                size = (round(part.width * args.scale), round(part.height * args.scale))
                part = part.resize(size, Image.LANCZOS)
            part.save(path)
            results = [
                outcome(detect(cli, path), whole, box[0], box[1], args.scale)
                for cli, whole in zip(clis, wholes)
            ]
            verdicts = [verdict(r) for r in results]
            for c, v in zip(counts, verdicts):
                c[v] += 1
            line = f"{path.name:24s} {str(box):28s} {verdicts[0]:12s} {results[0]}"
            if len(results) > 1 and verdicts[1] != verdicts[0]:
                differ += 1
                line += f"   baseline {verdicts[1]} {results[1]}"
            print(line, flush=True)
    for cli, c in zip(clis, counts):
        print(f"{cli}: " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
    if args.baseline:
        print(f"{differ} parts differ from the baseline")


if __name__ == "__main__":
    main()
