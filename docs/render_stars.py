#!/usr/bin/env python3
"""Renders four dim star fields of issue 17: a static plate of point-like marks (Gaussian dots
of about a pixel) under a gain swing of +-35 %, a light blob crossing the frame, sensor noise of
sigma 2 and JPEG at quality 75; 79 frames of 480x360, the target 140 px a side.

    python3 docs/render_stars.py OUT   -> OUT/s_a.txt ... OUT/s_d.txt and their frame folders

The four differ in the number, size and brightness of the marks and in the blob (s_d: 15 marks
on a nearly black plate). Needs numpy and Pillow.
"""

import os
import sys

import numpy as np
from PIL import Image

HEADER = "frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n"


def render(out, name, n=40, smin=0.6, smax=1.5, bmin=80, bmax=200, blob=60, gain=0.35,
           frames=79, seed=1, plate=12, quality=75, blob_sigma=60):
    rng = np.random.default_rng(seed)
    w, h = 480, 360
    x0, y0, side = 170, 110, 140
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    base = np.full((h, w), 30.0)
    base[y0:y0 + side, x0:x0 + side] = plate
    for _ in range(n):
        cx = x0 + 5 + (side - 10) * rng.uniform()
        cy = y0 + 5 + (side - 10) * rng.uniform()
        r = smin + (smax - smin) * rng.uniform()
        b = bmin + (bmax - bmin) * rng.uniform()
        base += b * np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * r * r))
    folder = os.path.join(out, name)
    os.makedirs(folder, exist_ok=True)
    # Pixel centres are integers; the target's edges are half a pixel outside its first and
    # last pixels.
    lo_x, lo_y, hi_x, hi_y = x0 - 0.5, y0 - 0.5, x0 + side - 0.5, y0 + side - 0.5
    with open(os.path.join(out, name + ".txt"), "w") as gt:
        gt.write(HEADER)
        for i in range(frames):
            t = float(i)
            g = 1 + gain * np.sin(2 * np.pi * t / 80)
            bx, by = 240 + 170 * np.cos(t / 25), 180 + 110 * np.sin(t / 37)
            light = blob * np.exp(-((xs - bx) ** 2 + (ys - by) ** 2) / (2 * blob_sigma ** 2))
            img = base * g + light + rng.normal(0, 2, (h, w))
            frame = Image.fromarray(np.clip(np.round(img), 0, 255).astype(np.uint8))
            file = "frame%05d.jpg" % (i + 1)
            frame.save(os.path.join(folder, file), quality=quality)
            gt.write(f"{file}\t{lo_x}\t{lo_y}\t{hi_x}\t{lo_y}\t{hi_x}\t{hi_y}\t{lo_x}\t{hi_y}\n")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    render(out, "s_a", seed=2)
    render(out, "s_b", n=25, smin=0.5, smax=1.0, bmin=50, bmax=140, blob=80, seed=3)
    render(out, "s_c", n=60, smin=0.5, smax=1.2, bmin=40, bmax=120, blob=90, blob_sigma=45,
           seed=4)
    render(out, "s_d", n=15, smin=0.7, smax=1.6, bmin=60, bmax=180, blob=70, seed=5, plate=5)


if __name__ == "__main__":
    main()
