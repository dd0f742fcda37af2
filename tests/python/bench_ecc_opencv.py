"""The live path of a regtrack tracker (by default the default tracker) beside OpenCV's ECC
(`findTransformECC`), in one run, like for like.

Like for like: ECC's template is the first frame's target *rectified to 50 x 50*, the pixels
regtrack samples (its 50 x 50 grid at the centres of a tiling of the target), and ECC
iterates as regtrack's trackers do (a homography, at most 30 iterations, stop below 0.001,
5x5 Gaussian pre-smoothing). Each frame's input is cropped to the previous estimate's bounding
box grown by a quarter of its size and 8 px (as regtrack's region of interest), so that ECC
does not filter the whole frame. Timed: the crop and the alignment, from the 8-bit frame
(decoded beforehand) to the corners. Both are scored by the mean corner distance to the
ground truth. For reference, ECC is also run with the target's bounding box at full resolution
as its template (what this script did before: on a 384 x 288 sequence it runs 4.5 times
slower, which flattered every ratio).

regtrack's figure is `regtrack bench`'s live path (8-bit frame to corners, the region's
conversion and smoothing included), run just before and just after OpenCV, the mean of the
two reported, in its settings: the defaults (none of whose checks ECC has), and the classic
single-level method as ECC runs (`--pyramid_levels 1 --line_search off --polish off`), and
any `--extra` settings. Each setting's accuracy is scored like ECC's, from `regtrack track`'s
corners. OpenCV is not a dependency of regtrack: install it for this script only (`pip install
opencv-python-headless numpy`).

    python3 tests/python/bench_ecc_opencv.py --seq data/seq.txt [--frames 200] [--sm esm --am ssd]

Without --sm and --am, the tracker is the default tracker as `regtrack list` names it on its
first line (its methods and the parameters it sets).

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


def rectified_template(image, quad, res=50):
    """The target rectified to `res x res`: pixel (u, v) is the frame at the unit square's point
    ((u + 0.5) / res, (v + 0.5) / res) mapped onto `quad` (regtrack's grid of centres), and the
    homography from template pixels to the frame."""
    import cv2
    import numpy as np

    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)
    to_frame = cv2.getPerspectiveTransform(unit, quad.astype(np.float32)).astype(np.float64)
    pixel_to_unit = np.array([[1 / res, 0, 0.5 / res], [0, 1 / res, 0.5 / res], [0, 0, 1]])
    h = to_frame @ pixel_to_unit
    template = cv2.warpPerspective(
        image, h, (res, res), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    )
    return template, h


def run_ecc(images, quads, iterations, eps, grow=0.25, rectified=True):
    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    q0 = quads[0]
    if rectified:
        template, warp = rectified_template(images[0], q0)
        # The quad's corners in template pixels (the unit square's corners).
        corners_t = np.array([[-0.5, -0.5], [49.5, -0.5], [49.5, 49.5], [-0.5, 49.5]])
    else:
        x0, y0 = np.floor(q0.min(axis=0)).astype(int)
        x1, y1 = np.ceil(q0.max(axis=0)).astype(int)
        template = images[0][y0:y1, x0:x1]
        corners_t = q0 - np.array([x0, y0])
        warp = np.array([[1, 0, x0], [0, 1, y0], [0, 0, 1]], dtype=np.float64)
    # `warp` maps template pixels to the frame.
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    h, w = images[0].shape
    errors, times, lost = [], [], None
    corners = q0
    for i in range(1, len(images)):
        t0 = time.perf_counter()
        bx0, by0 = corners.min(axis=0)
        bx1, by1 = corners.max(axis=0)
        m = grow * max(bx1 - bx0, by1 - by0) + 8
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


# regtrack's settings compared: its defaults, and the classic single-level method (ECC's).
SETTINGS = {
    "defaults": [],
    "single level": ["--pyramid_levels", "1", "--line_search", "off", "--polish", "off"],
}


def default_tracker(binary):
    """The default tracker as `regtrack list`'s first line names it: `(sm, am, [flags])`."""
    first = subprocess.run([binary, "list"], check=True, capture_output=True,
                           text=True).stdout.splitlines()[0]
    names, *params = first.split(": ", 1)[1].split(", ")
    sm, am, _ssm = names.split()
    flags = [f for p in params for f in ("--param", p)]
    return sm, am, flags


def tracker_flags(tracker):
    sm, am, flags = tracker
    return ["--sm", sm, "--am", am] + flags


def regtrack_errors(binary, seq, tracker, settings, quads):
    """Per frame after the first with corners (not reported lost), the mean corner distance of
    `regtrack track`'s corners."""
    import tempfile

    import numpy as np

    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "tracks.txt")
        cmd = [binary, "track", "--seq", seq, "--out", out] + tracker_flags(tracker)
        subprocess.run(cmd + settings, check=True, capture_output=True, text=True)
        with open(out) as f:
            rows = [line.split() for line in f.read().splitlines()[1:] if line.strip()]
    errors = []
    for row, q in zip(rows[1 : len(quads)], quads[1:]):
        try:
            c = np.array([float(v) for v in row[1:9]]).reshape(4, 2)
        except ValueError:
            continue  # a frame reported lost has no corners
        errors.append(float(np.mean(np.linalg.norm(c - q, axis=1))))
    return errors


def summary(errors):
    """Mean and median of the errors (px)."""
    e = sorted(errors)
    if not e:
        return "no frame"
    return f"mean error {sum(e) / len(e):.2f} px, median {e[len(e) // 2]:.2f} px"


def regtrack_live_fps(binary, seq, frames, repeats, tracker, settings):
    """`regtrack bench`'s live FPS, frames tracked and row for `tracker` (SM, AM, flags),
    homography."""
    sm, am, _ = tracker
    cmd = [binary, "bench", "--seq", seq, "--ssm", "homography", "--repeats", str(repeats)]
    cmd += tracker_flags(tracker) + settings
    if frames:
        cmd += ["--frames", str(frames)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    for line in out.splitlines():
        if line.startswith(f"{sm}_{am}_homography"):
            cols = re.split(r"\s+", line.strip())
            # tracker frames it/frame us/iter other tracker-FPS live-FPS live-us/iter init ...
            return float(cols[6]), int(cols[1]), line
    sys.exit(f"no {sm}_{am} row in:\n{out}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seq", required=True)
    ap.add_argument("--frames", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sm", help="regtrack's search method (default: the default tracker's)")
    ap.add_argument("--am", help="regtrack's appearance model (default: the default tracker's)")
    ap.add_argument("--extra", action="append", default=[],
                    help="more regtrack settings to compare, e.g. --extra '--escalate on'")
    ap.add_argument("--regtrack", default=os.environ.get("REGTRACK_BIN", "target/release/regtrack"))
    a = ap.parse_args()
    settings = dict(SETTINGS)
    for extra in a.extra:
        settings[extra] = extra.split()
    if a.sm is None and a.am is None:
        tracker = default_tracker(a.regtrack)
    else:
        d = default_tracker(a.regtrack)
        tracker = (a.sm or d[0], a.am or d[1], [])
    images, quads = read_sequence(a.seq, a.frames)
    before = {k: regtrack_live_fps(a.regtrack, a.seq, a.frames, a.repeats, tracker, v)
              for k, v in settings.items()}
    runs = [run_ecc(images, quads, 30, 1e-3) for _ in range(a.repeats)]
    full = [run_ecc(images, quads, 30, 1e-3, rectified=False) for _ in range(a.repeats)]
    after = {k: regtrack_live_fps(a.regtrack, a.seq, a.frames, a.repeats, tracker, v)
             for k, v in settings.items()}
    ecc_fps = sorted(r[0] for r in runs)[len(runs) // 2]
    full_fps = sorted(r[0] for r in full)[len(full) // 2]
    print(f"{len(images)} frames of {a.seq}, one thread, {a.repeats} repeats (medians)")
    for label, fps, (_, errors, lost) in [
        ("template rectified to 50x50 (like for like)", ecc_fps, runs[0]),
        ("template the bounding box at full resolution", full_fps, full[0]),
    ]:
        print(
            f"OpenCV findTransformECC, homography, {label}: {fps:,.0f} FPS, {summary(errors)}"
            + (f", failed at frame {lost}" if lost else "")
        )
    for name, extra in settings.items():
        (b, tracked, row), (c, _, row2) = before[name], after[name]
        reg_fps = (b + c) / 2
        errs = regtrack_errors(a.regtrack, a.seq, tracker, extra, quads)
        shown = name if name == " ".join(extra) else f"{name} {' '.join(extra)}"
        name = f"{tracker[0].upper()}-{tracker[1].upper()} {' '.join(tracker[2])}".rstrip()
        print(f"regtrack {name}, {shown}".rstrip())
        print(f"  bench rows:\n    {row}\n    {row2}")
        print(f"  live path: {reg_fps:,.0f} FPS, {summary(errs)} over the {len(errs)} of "
              f"{len(quads) - 1} frames not reported lost")
        print(f"  ratio: {reg_fps / ecc_fps:.1f}x ECC like for like "
              f"({reg_fps / full_fps:.1f}x ECC at full resolution)")


if __name__ == "__main__":
    main()
