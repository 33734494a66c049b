"""Command line shared by the scripts that run `detect` on copies of the real photos
(`photo_variants.py`, `photo_parts.py`, `photo_turns.py`)."""
import argparse
import pathlib
import sys


def photo_args(name, doc, extra=None):
    """Parses `--cli`, `--baseline`, `--photos`, `--out` (plus what `extra(parser)` adds) with
    `doc` as the help text; exits with a message naming `name` when the photos' directory is
    missing. Returns (args, photos directory, output directory, created)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", required=True)
    ap.add_argument("--baseline")
    ap.add_argument("--photos", default="../shared/images/curved-hydramarker")
    ap.add_argument("--out", required=True)
    if extra:
        extra(ap)
    args = ap.parse_args()
    photos, out = pathlib.Path(args.photos), pathlib.Path(args.out)
    if not photos.is_dir():
        sys.exit(f"{name}: {photos} not found")
    out.mkdir(parents=True, exist_ok=True)
    return args, photos, out
