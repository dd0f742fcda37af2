"""Many patches per frame: regtrack's patch tracker beside OpenCV's pyramidal Lucas-Kanade.

Both track the same points (the corners regtrack detects on the first frame) over the same
frames, on one thread; both are timed on tracking alone (frames decoded beforehand) and scored
by `regtrack score-patches` against the sequence's ground truth. OpenCV is not a dependency of
regtrack: install it for this script only (`pip install opencv-python-headless numpy`).

    python3 tests/python/bench_patches_opencv.py --seq data/seq.txt [--size 21 --levels 3]

Not collected by pytest (its name does not start with `test_`).
"""

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
import time


def read_frames(seq_txt):
    """The sequence's frames as grey uint8 arrays (MTF layout: `<root>/<name>/`)."""
    import cv2

    root, name = os.path.split(os.path.splitext(seq_txt)[0])
    folder = os.path.join(root, name)
    files = sorted(
        f for f in os.listdir(folder) if f.lower().endswith((".jpg", ".jpeg", ".png"))
    )
    return [cv2.imread(os.path.join(folder, f), cv2.IMREAD_GRAYSCALE) for f in files]


def first_points(tracks_csv):
    pts = []
    with open(tracks_csv) as f:
        for row in csv.DictReader(f):
            if row["frame"] != "0":
                break
            pts.append((float(row["x"]), float(row["y"])))
    return pts


def run_opencv(frames, pts, size, levels, iterations, eps, out_csv):
    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    p = np.array(pts, dtype=np.float32).reshape(-1, 1, 2)
    alive = np.ones(len(pts), dtype=bool)
    rows = [(0, k, "tracking", x, y) for k, (x, y) in enumerate(pts)]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    times, updates = [], 0
    for i in range(1, len(frames)):
        idx = np.flatnonzero(alive)
        t0 = time.perf_counter()
        if len(idx):
            q, st, _ = cv2.calcOpticalFlowPyrLK(
                frames[i - 1], frames[i], p[idx], None,
                winSize=(size, size), maxLevel=levels - 1, criteria=crit,
            )
        times.append(time.perf_counter() - t0)
        updates += len(idx)
        if len(idx):
            ok = st.ravel() == 1
            p[idx[ok]] = q[ok]
            alive[idx[~ok]] = False
        for k in range(len(pts)):
            x, y = p[k, 0]
            rows.append((i, k, "tracking" if alive[k] else "lost:not_found", x, y))
    with open(out_csv, "w") as f:
        f.write("frame,patch,status,x,y,a00,a01,a10,a11,ncc\n")
        for i, k, s, x, y in rows:
            f.write(f"{i},{k},{s},{x:.4f},{y:.4f},1,0,0,1,1\n")
    total = sum(times)
    times.sort()
    return updates / total, 1.0 / times[len(times) // 2], rows


def opencv_forward_backward(frames, rows, n, size, levels, iterations, eps):
    """The forward-backward error of OpenCV's tracks (untimed): each point tracked at frame i
    tracked back to frame i - 1, against where it was there."""
    import cv2
    import numpy as np

    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    per_frame = [rows[i * n:(i + 1) * n] for i in range(len(frames))]
    errors = []
    for i in range(1, len(frames)):
        both = [k for k in range(n)
                if per_frame[i][k][2] == "tracking" and per_frame[i - 1][k][2] == "tracking"]
        if not both:
            continue
        q = np.array([per_frame[i][k][3:5] for k in both], dtype=np.float32).reshape(-1, 1, 2)
        back, st, _ = cv2.calcOpticalFlowPyrLK(
            frames[i], frames[i - 1], q, None,
            winSize=(size, size), maxLevel=levels - 1, criteria=crit,
        )
        for j, k in enumerate(both):
            if st[j, 0] == 1:
                x, y = per_frame[i - 1][k][3:5]
                errors.append(float(np.hypot(back[j, 0, 0] - x, back[j, 0, 1] - y)))
    errors.sort()
    return sum(errors) / len(errors), errors[len(errors) // 2]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seq", required=True, help="ground-truth file of an MTF-layout sequence")
    ap.add_argument("--regtrack", default="target/release/regtrack")
    ap.add_argument("--patches", type=int, default=1000)
    ap.add_argument("--size", type=int, default=21)
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--min-distance", type=float, default=4.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench-patches-")
    common = [
        "--patch", f"size={args.size}", "--patch", f"levels={args.levels}",
        "--patch", "threads=1", "--patch", f"min_distance={args.min_distance}",
    ]
    results = []
    for warp in ("translation", "affine"):
        speeds = []
        for r in range(args.repeats):
            out = os.path.join(tmp, f"regtrack_{warp}.csv")
            text = subprocess.run(
                [args.regtrack, "track", "--seq", args.seq, "--patches", str(args.patches),
                 "--patch", f"warp={warp}", *common, "--out", out],
                check=True, capture_output=True, text=True,
            ).stdout
            m = re.search(r"speed: (\d+) patch updates/s, ([\d.]+) frames/s", text)
            speeds.append((float(m.group(1)), float(m.group(2))))
            acc = re.search(r"accuracy: (.*)", text).group(1)
        speeds.sort()
        # The forward-backward error, from one more (untimed) run that measures it.
        text = subprocess.run(
            [args.regtrack, "track", "--seq", args.seq, "--patches", str(args.patches),
             "--patch", f"warp={warp}", "--patch", "fb_max=1000", *common,
             "--out", os.path.join(tmp, "fb.csv")],
            check=True, capture_output=True, text=True,
        ).stdout
        m = re.search(r"forward-backward error: mean ([\d.]+) px, median ([\d.]+) px", text)
        fb = (float(m.group(1)), float(m.group(2)))
        results.append((f"regtrack {warp}", speeds[len(speeds) // 2], fb, acc))
    pts = first_points(os.path.join(tmp, "regtrack_translation.csv"))
    frames = read_frames(args.seq)
    cv_speeds = []
    for r in range(args.repeats):
        cv_csv = os.path.join(tmp, "opencv.csv")
        ups, fps, rows = run_opencv(frames, pts, args.size, args.levels, 30, 0.01, cv_csv)
        cv_speeds.append((ups, fps))
    cv_speeds.sort()
    fb = opencv_forward_backward(frames, rows, len(pts), args.size, args.levels, 30, 0.01)
    text = subprocess.run(
        [args.regtrack, "score-patches", "--seq", args.seq, "--tracks", cv_csv],
        check=True, capture_output=True, text=True,
    ).stdout
    acc = re.search(r"accuracy: (.*)", text).group(1)
    results.append(("OpenCV calcOpticalFlowPyrLK", cv_speeds[len(cv_speeds) // 2], fb, acc))
    print(f"{len(pts)} patches, {len(frames)} frames, window {args.size}x{args.size}, "
          f"{args.levels} levels, one thread, medians of {args.repeats} runs")
    for name, (ups, fps), (fb_mean, fb_median), acc in results:
        print(f"| {name} | {ups:,.0f} patch updates/s | {fps:,.1f} frames/s | "
              f"forward-backward error mean {fb_mean:.3f} px, median {fb_median:.3f} px | {acc} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
