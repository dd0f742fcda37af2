"""The binding's per-call overhead: the wall time of `Tracker.update` from Python minus the time
the library itself took (`last_update_us`), median over many calls, for grey uint8 frames as
OpenCV gives them and for BGR frames.

    python tests/python/bench_overhead.py [SEQUENCE]   # default: a rendered 640x480 sequence
"""

import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import regtrack

ROOT = pathlib.Path(__file__).resolve().parents[2]


def sequence():
    if len(sys.argv) > 1:
        return regtrack.Sequence(sys.argv[1])
    binary = os.environ.get("REGTRACK_BIN") or next(
        str(p) for p in (ROOT / "target/release/regtrack", ROOT / "target/debug/regtrack") if p.is_file()
    )
    out = tempfile.mkdtemp()
    subprocess.run(
        [binary, "synth", "--texture", str(ROOT / "assets/textures/skimage_coffee.png"),
         "--motion", str(ROOT / "assets/motion/ucsb_bricks_rt.txt"),
         "--out", out, "--name", "rt", "--frames", "40"],
        check=True, capture_output=True,
    )
    return regtrack.Sequence(os.path.join(out, "rt.txt"))


def measure(t, frames, g0, convert, rounds=20):
    wall, lib = [], []
    for _ in range(rounds):
        t.initialize(convert(frames[0]), g0)
        for f in frames[1:]:
            f = convert(f)
            start = time.perf_counter()
            t.update(f)
            wall.append((time.perf_counter() - start) * 1e6)
            lib.append(t.last_update_us)
    over = [w - l for w, l in zip(wall, lib)]
    return statistics.median(wall), statistics.median(lib), statistics.median(over)


def main():
    seq = sequence()
    frames = [f for f, _ in seq]
    g0 = seq[0][1]
    h, w = frames[0].shape
    print(f"{seq.name}: {len(frames)} frames of {w}x{h}")
    for label, convert in (
        ("grey uint8", lambda f: f),
        ("BGR uint8 (H, W, 3)", lambda f: np.stack([f, f, f], axis=2)),
    ):
        t = regtrack.Tracker()
        wall, lib, over = measure(t, frames, g0, convert)
        print(f"{t.label}, {label}: update {wall:.1f} us from Python, {lib:.1f} us in the "
              f"library, overhead {over:.1f} us (median)")
    print(f"two trackers in two threads: {threads(frames, g0):.2f}x the speed of one thread "
          f"({os.cpu_count()} cores)")


def threads(frames, g0, rounds=10):
    """The speed-up of two trackers in two threads over the same work in one (best of 3)."""
    import threading

    def work():
        t = regtrack.Tracker("esm", "ssd", "homography", res=80)
        for _ in range(rounds):
            t.initialize(frames[0], g0)
            for f in frames[1:]:
                t.update(f)

    def serial():
        start = time.perf_counter()
        work()
        work()
        return time.perf_counter() - start

    def parallel():
        ths = [threading.Thread(target=work) for _ in range(2)]
        start = time.perf_counter()
        for th in ths:
            th.start()
        for th in ths:
            th.join()
        return time.perf_counter() - start

    return min(serial() for _ in range(3)) / min(parallel() for _ in range(3))


if __name__ == "__main__":
    main()
