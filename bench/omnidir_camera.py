#!/usr/bin/env python3
"""The camera of examples/opencv-omnidir: calibrate Mei's omnidirectional model with cv2.omnidir.

Usage: omnidir_camera.py omni_calib_data.xml camera.json

Reads OpenCV's tutorial points (15 views of a 6 x 9 board at 1280 x 960), calibrates from views
1..14 (view 0 is sample.jpg's, held out so that a test can fit its pose with a camera it did not
shape) and writes K, xi, D = (k1, k2, p1, p2) and the calibration's RMS as JSON. Needs
opencv-contrib-python-headless (cv2.omnidir), which bench/requirements.txt does not pin.
"""
import json
import sys
import xml.etree.ElementTree as ET

import cv2
import numpy as np


def points(root, tag, dim):
    return [np.array(m.find("data").text.split(), float).reshape(-1, 1, dim) for m in root.find(tag)]


def main(xml_path, out_path):
    root = ET.parse(xml_path).getroot()
    images, boards = points(root, "imagePoints", 2), points(root, "objectPoints", 3)
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 300, 1e-10)
    rms, K, xi, D, _, _, _ = cv2.omnidir.calibrate(
        boards[1:], images[1:], (1280, 960), None, None, None, 0, criteria
    )
    camera = {
        "image_size": [1280, 960],
        "K": K.tolist(),
        "xi": float(xi.ravel()[0]),
        "D": D.ravel().tolist(),
        "rms_px": rms,
        "views": "1-14 of omni_calib_data.xml (view 0, sample.jpg, held out)",
        "tool": f"cv2.omnidir.calibrate, flags 0, opencv-contrib-python-headless {cv2.__version__}",
    }
    with open(out_path, "w") as f:
        json.dump(camera, f, indent=1)
        f.write("\n")
    print(f"omnidir_camera: RMS {rms:.4f} px over views 1-14, written to {out_path}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(*sys.argv[1:])
