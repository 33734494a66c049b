#!/usr/bin/env python3
"""Resized, rotated and degraded copies of the real photos, and what `detect` makes of them.

Usage: photo_variants.py --cli CLI [--baseline CLI2] [--photos DIR] --out DIR

The photos have no ground truth; these copies test what does not depend on it: that every copy
still gives one board, with labels that agree with the checker pattern, and how many corners
survive. Each photo is converted to grey (Pillow's `L`) and written as PNG (the JPEG copies as
JPEG) in OUT/:
  _s2, _s4            1/2 and 1/4 size (Lanczos)
  _x0.66, _x0.4, _x0.3 0.66, 0.4 and 0.3 size (Lanczos)
  _r30, _r45          half size rotated by 30 and 45 degrees (bicubic, grey 128 outside)
  _r90, _r180         half size rotated by 90 and 180 degrees (exact)
  _b2                 half size, Gaussian blur of radius 2
  _q15                half size, JPEG quality 15
  _lowc               half size, contrast x 0.3 (Pillow's ImageEnhance)
  _noise              half size, Gaussian noise of sigma 20 levels (seed 1, photos in name order)
  _gamma              half size, gamma 2.2
  _motion, _m3, _m5   half size, horizontal box blur of 9, 3 and 5 samples (wrapping)
  _d3, _d5            half size, box blur of 3 and 5 samples along the diagonal (wrapping)
plus five crops that hold no board (they must give no board).
Then CLI (and BASELINE, if given) runs `detect` on each copy; the table lists every copy's board
sizes, and with a baseline the copies whose boards differ. Exit status 0.
"""
import json
import subprocess

import numpy as np
from PIL import Image, ImageEnhance, ImageFilter
from photo_common import photo_args

CROPS = {  # name: (photo, box)
    "c6top": ("curve_6.jpg", (0, 0, 2248, 800)),
    "c8bot": ("curve_8.jpg", (0, 1450, 1080, 1920)),
    "c4bot": ("curve_4.jpg", (0, 1000, 720, 1280)),
    "mr3tr": ("marker_real3.jpg", (1500, 0, 2422, 500)),
    "c5left": ("curve_5.jpg", (0, 0, 300, 590)),
}


def box(a, length, dy):
    """Mean of `length` copies of `a` shifted along x (and y if dy), wrapping at the borders."""
    h = length // 2
    return sum(np.roll(np.roll(a, s, axis=1), s * dy, axis=0) for s in range(-h, h + 1)) / length


def make(photos, out):
    rng = np.random.default_rng(1)
    names = []
    for f in sorted(photos.glob("*.jpg")):
        im = Image.open(f).convert("L")
        n = f.stem
        for s in (2, 4):
            im.resize((im.width // s, im.height // s), Image.LANCZOS).save(out / f"{n}_s{s}.png")
            names.append(f"{n}_s{s}.png")
        for s in (0.66, 0.4, 0.3):
            size = (int(im.width * s), int(im.height * s))
            im.resize(size, Image.LANCZOS).save(out / f"{n}_x{s}.png")
            names.append(f"{n}_x{s}.png")
        half = im.resize((im.width // 2, im.height // 2), Image.LANCZOS)
        for angle in (30, 45):
            turned = half.rotate(angle, expand=True, fillcolor=128, resample=Image.BICUBIC)
            turned.save(out / f"{n}_r{angle}.png")
        half.transpose(Image.ROTATE_90).save(out / f"{n}_r90.png")
        half.transpose(Image.ROTATE_180).save(out / f"{n}_r180.png")
        half.filter(ImageFilter.GaussianBlur(2)).save(out / f"{n}_b2.png")
        half.save(out / f"{n}_q15.jpg", quality=15)
        ImageEnhance.Contrast(half).enhance(0.3).save(out / f"{n}_lowc.png")
        a = np.asarray(half).astype(float)
        noisy = np.clip(a + rng.normal(0, 20, a.shape), 0, 255).astype("uint8")
        Image.fromarray(noisy).save(out / f"{n}_noise.png")
        Image.fromarray((255 * (a / 255.0) ** 2.2).astype("uint8")).save(out / f"{n}_gamma.png")
        for tag, length, dy in (("motion", 9, 0), ("m3", 3, 0), ("m5", 5, 0), ("d3", 3, 1), ("d5", 5, 1)):
            Image.fromarray(box(a, length, dy).astype("uint8")).save(out / f"{n}_{tag}.png")
        names += [f"{n}_{t}" for t in ("r30.png", "r45.png", "r90.png", "r180.png", "b2.png",
                                        "q15.jpg", "lowc.png", "noise.png", "gamma.png",
                                        "motion.png", "m3.png", "m5.png", "d3.png", "d5.png")]
    for name, (photo, b) in CROPS.items():
        if (photos / photo).exists():
            Image.open(photos / photo).crop(b).save(out / f"{name}.png")
            names.append(f"{name}.png")
    return names


def boards(cli, path):
    run = subprocess.run([cli, "detect", str(path)], capture_output=True, text=True)
    if run.returncode != 0:
        return f"error: {run.stderr.strip()}"
    return [len(b["corners"]) for b in json.loads(run.stdout)["boards"]]


def main():
    args, photos, out = photo_args("photo_variants", __doc__)
    names = make(photos, out)
    differ = 0
    for name in names:
        now = boards(args.cli, out / name)
        line = f"{name:28s} {now}"
        if args.baseline:
            before = boards(args.baseline, out / name)
            if before != now:
                differ += 1
                line += f"   baseline {before}"
        print(line, flush=True)
    print(f"{len(names)} copies" + (f", {differ} differ from the baseline" if args.baseline else ""))


if __name__ == "__main__":
    main()
