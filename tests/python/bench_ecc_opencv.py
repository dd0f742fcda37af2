"""The live path of regtrack's ESM-SSD beside OpenCV's ECC (`findTransformECC`), in one run.

OpenCV's ECC aligns a template (the first frame cropped to the bounding box of the
ground-truth quad) to each frame by a homography, iterating as regtrack's trackers do (at most
30 iterations, stop below 0.001, 5x5 Gaussian pre-smoothing). Each frame's input is cropped to
the previous estimate's bounding box grown by a quarter of its size and 8 px (as regtrack's
region of interest), so that ECC does not filter the whole frame. Timed: the crop and the
alignment, from the 8-bit frame (decoded beforehand) to the corners. Both are scored by the
mean corner distance to the ground truth.

regtrack's figure is `regtrack bench`'s live path (8-bit frame to corners, the region's
conversion and smoothing included) of ESM-SSD-homography, run just before and just after
OpenCV, the mean of the two reported. OpenCV is not a dependency of regtrack: install it for
this script only (`pip install opencv-python-headless numpy`).

    python3 tests/python/bench_ecc_opencv.py --seq data/seq.txt [--frames 200]

Not collected by pytest (its name does not start with `test_`).
"""

import argparse
import os
import re
import subprocess
import sys
import time


def read_sequence(seq_txt, frames):
    """Grey uint8 frames and ground-truth quads (MTF layout: `<root>/<name>.txt`, `<root>/<name>/`)."""
    import cv2
    import numpy as np

    root, name = os.path.split(os.path.splitext(seq_txt)[0])
    quads, files = [], []
    with open(seq_txt) as f:
        for line in f.read().splitlines()[1:]:
            parts = line.split()
            if len(parts) < 9:
                continue
            files.append(parts[0])
            quads.append(np.array([float(v) for v in parts[1:9]]).reshape(4, 2))
    n = min(len(files), frames) if frames else len(files)
    images = [cv2.imread(os.path.join(root, name, f), cv2.IMREAD_GRAYSCALE) for f in files[:n]]
    for f, img in zip(files, images):
        if img is None:
            sys.exit(f"cannot read frame {os.path.join(root, name, f)}")
    return images, quads[:n]


def apply(h, pts):
    import numpy as np

    p = np.hstack([pts, np.ones((len(pts), 1))]) @ h.T
    return p[:, :2] / p[:, 2:3]


def run_ecc(images, quads, iterations, eps):
    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    q0 = quads[0]
    x0, y0 = np.floor(q0.min(axis=0)).astype(int)
    x1, y1 = np.ceil(q0.max(axis=0)).astype(int)
    template = images[0][y0:y1, x0:x1]
    corners_t = q0 - np.array([x0, y0])  # the quad in template coordinates
    # Template -> frame.
    warp = np.array([[1, 0, x0], [0, 1, y0], [0, 0, 1]], dtype=np.float64)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    h, w = images[0].shape
    errors, times, lost = [], [], None
    corners = q0
    for i in range(1, len(images)):
        t0 = time.perf_counter()
        bx0, by0 = corners.min(axis=0)
        bx1, by1 = corners.max(axis=0)
        m = 0.25 * max(bx1 - bx0, by1 - by0) + 8
        cx0, cy0 = int(max(0, np.floor(bx0 - m))), int(max(0, np.floor(by0 - m)))
        cx1, cy1 = int(min(w, np.ceil(bx1 + m))), int(min(h, np.ceil(by1 + m)))
        crop = images[i][cy0:cy1, cx0:cx1]
        shift = np.array([[1, 0, -cx0], [0, 1, -cy0], [0, 0, 1]], dtype=np.float64)
        local = (shift @ warp).astype(np.float32)
        try:
            _, local = cv2.findTransformECC(
                template, crop, local, cv2.MOTION_HOMOGRAPHY, crit, None, 5
            )
        except cv2.error:
            lost = i
            times.append(time.perf_counter() - t0)
            break
        warp = np.linalg.inv(shift) @ local.astype(np.float64)
        corners = apply(warp, corners_t)
        times.append(time.perf_counter() - t0)
        errors.append(float(np.mean(np.linalg.norm(corners - quads[i], axis=1))))
    return len(times) / sum(times), errors, lost


def regtrack_live_fps(binary, seq, frames, repeats):
    """`regtrack bench`'s live FPS and its frames tracked for ESM-SSD-homography."""
    cmd = [binary, "bench", "--seq", seq, "--sm", "esm", "--am", "ssd", "--ssm", "homography",
           "--repeats", str(repeats)]
    if frames:
        cmd += ["--frames", str(frames)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    for line in out.splitlines():
        if line.startswith("esm_ssd_homography"):
            cols = re.split(r"\s+", line.strip())
            # tracker frames it/frame us/iter other tracker-FPS live-FPS init ...
            return float(cols[6]), int(cols[1]), line
    sys.exit(f"no ESM row in:\n{out}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seq", required=True)
    ap.add_argument("--frames", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--regtrack", default=os.environ.get("REGTRACK_BIN", "target/release/regtrack"))
    a = ap.parse_args()
    images, quads = read_sequence(a.seq, a.frames)
    before, tracked, row = regtrack_live_fps(a.regtrack, a.seq, a.frames, a.repeats)
    runs = [run_ecc(images, quads, 30, 1e-3) for _ in range(a.repeats)]
    after, _, row2 = regtrack_live_fps(a.regtrack, a.seq, a.frames, a.repeats)
    ecc_fps = sorted(r[0] for r in runs)[len(runs) // 2]
    _, errors, lost = runs[0]
    reg_fps = (before + after) / 2
    errors.sort()
    print(f"{len(images)} frames of {a.seq}, one thread, {a.repeats} repeats (medians)")
    print(f"regtrack bench rows:\n  {row}\n  {row2}")
    print(f"regtrack ESM-SSD live path: {reg_fps:,.0f} FPS ({tracked} frames tracked)")
    print(
        f"OpenCV findTransformECC, homography, cropped: {ecc_fps:,.0f} FPS, "
        f"mean error {sum(errors) / max(1, len(errors)):.2f} px, "
        f"median {errors[len(errors) // 2] if errors else float('nan'):.2f} px"
        + (f", failed at frame {lost}" if lost else "")
    )
    print(f"ratio: {reg_fps / ecc_fps:.1f}x")


if __name__ == "__main__":
    main()
