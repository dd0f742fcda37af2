"""The Python package: tracking a rendered sequence to the command line's corners, the error
paths, threads, a whole tracker, the per-iteration record, the sequence reader and many patches.

Run after `pip install .` (or `maturin develop`): `pytest tests/python`. The command line's
binary is found in target/{debug,release}/ (or `REGTRACK_BIN`).
"""

import os
import pathlib
import subprocess
import threading
import time

import numpy as np
import pytest

import regtrack

ROOT = pathlib.Path(__file__).resolve().parents[2]


def cli():
    env = os.environ.get("REGTRACK_BIN")
    if env:
        return env
    for profile in ("debug", "release"):
        p = ROOT / "target" / profile / "regtrack"
        if p.is_file():
            return str(p)
    pytest.skip("the regtrack binary is not built (cargo build)")


@pytest.fixture(scope="session")
def rendered(tmp_path_factory):
    """A rendered sequence (MTF layout) with exact ground truth, by the command line."""
    out = tmp_path_factory.mktemp("data")
    subprocess.run(
        [
            cli(), "synth",
            "--texture", str(ROOT / "assets/textures/skimage_coffee.png"),
            "--motion", str(ROOT / "assets/motion/ucsb_bricks_rt.txt"),
            "--out", str(out), "--name", "rt", "--frames", "20",
        ],
        check=True,
        capture_output=True,
    )
    return out / "rt.txt"


def read_corners(path):
    rows = []
    for line in pathlib.Path(path).read_text().splitlines()[1:]:
        t = line.split()
        rows.append(None if t[1] == "lost" else np.array([float(v) for v in t[1:]]).reshape(4, 2))
    return rows


def test_a_tracker_follows_a_rendered_sequence_to_the_command_lines_corners(rendered, tmp_path):
    seq = regtrack.Sequence(rendered)
    assert len(seq) == 20 and seq.name == "rt"
    frames = [f for f, _ in seq]
    gt = seq.ground_truth
    assert gt.shape == (20, 4, 2)
    t = regtrack.Tracker("esm", "ssd", "homography")
    t.initialize(frames[0], gt[0])
    ours = [t.corners]
    for f in frames[1:]:
        corners, status = t.update(f)
        assert status == "tracking"
        assert corners.shape == (4, 2)
        ours.append(corners)
    out = tmp_path / "cli.txt"
    subprocess.run(
        [cli(), "track", "--seq", str(rendered), "--sm", "esm", "--am", "ssd",
         "--ssm", "homography", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    theirs = read_corners(out)
    assert len(theirs) == 20
    for k, (a, b) in enumerate(zip(ours, theirs)):
        # The file holds 4 decimals.
        assert np.abs(a - b).max() < 1e-3, f"frame {k + 1}: {a} vs {b}"
    assert max(regtrack.alignment_error(a, g) for a, g in zip(ours, gt)) < 1.0


def test_colour_and_float_frames_and_any_strides(rendered):
    seq = regtrack.Sequence(rendered)
    f0, g0 = seq[0]
    f1, _ = seq[1]
    results = []
    for convert in (
        lambda f: f,
        lambda f: np.ascontiguousarray(np.stack([f, f, f], axis=2)),  # BGR, grey content
        lambda f: f.astype(np.float32),
        lambda f: np.asfortranarray(f),
        lambda f: np.pad(f, ((0, 0), (0, 3)))[:, :-3],  # a strided view
    ):
        t = regtrack.Tracker("fclk", "zncc", "homography")
        t.initialize(convert(f0), g0)
        c, s = t.update(convert(f1))
        assert s == "tracking"
        results.append(c)
    for c in results[1:]:
        assert np.abs(c - results[0]).max() < 1e-3


def track_all(t, seq):
    """`t` initialised on `seq`'s first frame and ground truth, then updated on every other
    frame (each must be tracked): the corners of every frame."""
    f0, g0 = seq[0]
    t.initialize(f0, g0)
    corners = [t.corners]
    for f, _ in list(seq)[1:]:
        c, s = t.update(f)
        assert s == "tracking"
        corners.append(c)
    return corners


def cli_track(seq, tmp_path, sm, am, ssm, *args):
    """The corners of `regtrack track` on `seq` with `sm am ssm` and `args`."""
    out = tmp_path / f"cli_{sm}_{am}_{ssm}.txt"
    subprocess.run(
        [cli(), "track", "--seq", str(seq), "--sm", sm, "--am", am, "--ssm", ssm,
         *args, "--out", str(out)],
        check=True,
        capture_output=True,
    )
    return read_corners(out)


def test_a_colour_tracker_reads_the_channels_of_a_bgr_frame(rendered, tmp_path):
    seq = regtrack.Sequence(rendered, colour=True)
    grey = regtrack.Sequence(rendered)
    f0, g0 = seq[0]
    assert f0.shape[2] == 3 and f0.dtype == np.uint8 and f0.shape[:2] == grey[0][0].shape
    ours = track_all(regtrack.Tracker("fclk", "zncc", "homography", channels="rgb"), seq)
    # The command line's colour run (it reads the frames in colour for channels=rgb).
    theirs = cli_track(rendered, tmp_path, "fclk", "zncc", "homography", "--channels", "rgb")
    for k, (a, b) in enumerate(zip(ours, theirs)):
        assert np.abs(a - b).max() < 1e-3, f"frame {k + 1}: {a} vs {b}"


def test_a_descriptor_field_tracker_matches_the_command_line(rendered, tmp_path):
    # channels="df" (MTF's descriptor fields): made of the grey frame, so a grey frame and a
    # BGR one track alike, and as the command line does.
    grey = regtrack.Sequence(rendered)
    colour = regtrack.Sequence(rendered, colour=True)
    tracks = [
        track_all(regtrack.Tracker("esm", "ssd", "homography", channels="df"), seq)
        for seq in (grey, colour)
    ]
    theirs = cli_track(rendered, tmp_path, "esm", "ssd", "homography", "--channels", "df")
    for k, (a, b, c) in enumerate(zip(tracks[0], tracks[1], theirs)):
        assert np.abs(a - c).max() < 1e-3, f"frame {k + 1}: {a} vs {c}"
        assert np.abs(b - c).max() < 1e-3, f"frame {k + 1} (BGR): {b} vs {c}"
    with pytest.raises(regtrack.Error, match="channels=df"):
        regtrack.Tracker("fclk", "mi", "homography", channels="df")


def test_errors_name_what_was_expected():
    frame = np.zeros((60, 80), np.uint8)
    frame[20:40, 30:50] = np.arange(400, dtype=np.uint8).reshape(20, 20)
    quad = np.array([[30, 20], [50, 20], [50, 40], [30, 40]], float)
    t = regtrack.Tracker()
    for bad in (np.zeros((6, 8), np.int16), np.zeros((6, 8, 4), np.uint8), np.zeros((0, 8), np.uint8), "frame"):
        with pytest.raises(ValueError, match="frame"):
            t.initialize(bad, quad)
    for bad in ([[0, 0], [1, 1]], np.full((4, 2), np.nan), "corners"):
        with pytest.raises(ValueError, match="corners"):
            t.initialize(frame, bad)
    with pytest.raises(regtrack.Error, match="unknown search method 'nosuch'"):
        regtrack.Tracker("nosuch")
    with pytest.raises(regtrack.Error, match="res must be"):
        regtrack.Tracker(res=100000)
    with pytest.raises(regtrack.Error, match="has no parameter 'bogus'"):
        regtrack.Tracker("esm", "ssd", "homography", bogus=1)
    with pytest.raises(ValueError, match="either a whole tracker"):
        regtrack.Tracker("esm", tracker="kcf")
    with pytest.raises(regtrack.Error, match="lies outside"):
        t.initialize(frame, quad + 1000)
    # Not initialised: a status, not an exception.
    c, s = regtrack.Tracker().update(frame)
    assert s == "uninitialized"
    # A frame of another size than the one it started on (a strided view, a crop): refused,
    # naming both sizes (it was tracked, and reported lost).
    t = regtrack.Tracker()
    t.initialize(frame, quad)
    for other in (frame[::2, ::2], frame[:, :50]):
        with pytest.raises(ValueError, match="initialised on a 80x60 frame"):
            t.update(other)
    c, s = t.update(frame)
    assert s == "tracking"
    # A region partly outside a blank frame: refused with the reason.
    with pytest.raises(regtrack.Error, match="outside the 80x60 frame.*every pixel"):
        regtrack.Tracker().initialize(np.full((60, 80), 7, np.uint8), quad - [40, 0])


def test_parameters_are_the_command_lines(rendered):
    t = regtrack.Tracker("iclk", "ssd", "affine", res=30, max_iters=10, on_loss="continue")
    assert t.label == "iclk_ssd_affine"
    names = {e["name"] for e in regtrack.list_methods()["sm"]}
    assert {"esm", "iclk", "fclk", "nn", "pf"} <= names
    assert "kcf" in {e["name"] for e in regtrack.list_methods()["tracker"]}
    assert "max_iters" in regtrack.list_text()


def test_a_whole_tracker(rendered):
    seq = regtrack.Sequence(rendered)
    t = regtrack.Tracker(tracker="kcf")
    f0, g0 = seq[0]
    t.initialize(f0, g0)
    for f, g in list(seq)[1:6]:
        c, s = t.update(f)
        assert s == "tracking"
        assert regtrack.alignment_error(c, g) < 20


def test_the_iterations_of_a_frame(rendered):
    seq = regtrack.Sequence(rendered)
    t = regtrack.Tracker("esm", "ssd", "homography")
    t.initialize(*seq[0])
    t.update(seq[1][0], record=True)
    it = t.iterations
    n = len(it["similarity"])
    assert n >= 1
    assert it["params"].shape == (n, 8) and it["corners"].shape == (n, 4, 2)
    assert it["step"][-1] < it["step"][0] or n == 1
    t.update(seq[2][0])
    assert t.iterations is None


def test_set_corners_and_a_lost_tracker_says_so(rendered):
    seq = regtrack.Sequence(rendered)
    t = regtrack.Tracker()
    f0, g0 = seq[0]
    t.initialize(f0, g0)
    # A flat frame: the target is gone.
    c, s = t.update(np.full_like(f0, 128))
    assert s.startswith("lost"), s
    assert np.isfinite(c).all()
    t.set_corners(g0)
    c, s = t.update(f0)
    assert s == "tracking"


def test_the_gil_is_released_while_a_tracker_works(rendered):
    """Another Python thread runs while a tracker updates (the speed-up of two trackers in two
    threads is measured by tests/python/bench_overhead.py, not asserted: timings are noisy)."""
    seq = regtrack.Sequence(rendered)
    frames = [f for f, _ in seq]
    t = regtrack.Tracker("esm", "ssd", "homography", res=200, max_iters=100, eps=0)
    t.initialize(frames[0], seq[0][1])

    def spin(seconds):
        n, end = 0, time.perf_counter() + seconds
        while time.perf_counter() < end:
            n += 1
        return n

    alone = spin(0.05) / 0.05
    done = threading.Event()
    calls = []

    def track():
        for f in frames[1:]:
            start = time.perf_counter()
            t.update(f)
            calls.append(time.perf_counter() - start)
        done.set()

    th = threading.Thread(target=track)
    ticks, start = 0, time.perf_counter()
    th.start()
    while not done.is_set():
        ticks += 1
        time.perf_counter()
    th.join()
    elapsed = time.perf_counter() - start
    assert sum(calls) > 0.5 * elapsed, "the updates took most of the time"
    # Held, the GIL would stop this thread for the whole of each update.
    rate = ticks / elapsed
    assert rate > 0.2 * alone, f"{rate:.0f} loops/s while tracking against {alone:.0f} alone"


def test_synth_and_eval_give_the_command_lines_rows(tmp_path):
    seq = regtrack.synth(
        ROOT / "assets/textures/skimage_coffee.png",
        ROOT / "assets/motion/ucsb_bricks_rt.txt",
        tmp_path / "data",
        "rt",
        max_frames=10,
        noise=1.0,
    )
    assert len(seq) == 10 and seq.name == "rt"
    with pytest.raises(ValueError, match="unknown field `nois`"):
        regtrack.synth(ROOT / "assets/textures/skimage_coffee.png",
                       ROOT / "assets/motion/ucsb_bricks_rt.txt", tmp_path / "x", "x", nois=1)
    rows = regtrack.eval(tmp_path / "data", sm=["esm", "iclk"], am=["ssd"], ssm=["homography"],
                         out=tmp_path / "res", res=40)
    assert [r["tracker"] for r in rows] == ["esm_ssd_homography", "iclk_ssd_homography"]
    assert all(r["sequence"] == "rt" and r["frames"] == 9 for r in rows)
    assert rows[0]["sr5"] == 1.0
    import json
    written = json.loads((tmp_path / "res/summary.json").read_text())
    assert [r["sr5"] for r in written] == [r["sr5"] for r in rows]
    whole = regtrack.eval(tmp_path / "data", trackers=["kcf"])
    assert [r["tracker"] for r in whole] == ["kcf"]
    with pytest.raises(regtrack.Error, match="no sequence 'nosuch'"):
        regtrack.eval(tmp_path / "data", seqs=["nosuch"])


def test_a_bending_target_tracked_by_a_non_rigid_warp_from_python(tmp_path):
    """A rendered target that bends (synth's ``bend``), tracked by the thin-plate spline SSM:
    the command line's corners, and the warped lattice in the frame between them."""
    seq = regtrack.synth(
        ROOT / "assets/textures/skimage_coffee.png",
        ROOT / "assets/motion/ucsb_bricks_m1.txt",
        tmp_path / "data",
        "bend",
        max_frames=30,
        noise=1.0,
        bend=0.05,
    )
    frames = [f for f, _ in seq]
    gt = seq.ground_truth
    t = regtrack.Tracker("fclk", "ssd", "tps")
    assert t.label == "fclk_ssd_tps"
    t.initialize(frames[0], gt[0])
    ours = [t.corners]
    for f in frames[1:]:
        corners, status = t.update(f)
        assert status == "tracking"
        ours.append(corners)
    grid = t.warped_grid
    assert grid.shape == (11, 11, 2)
    # The lattice's corners are the tracker's.
    for k, (i, j) in enumerate([(0, 0), (0, 10), (10, 10), (10, 0)]):
        assert np.abs(grid[i, j] - ours[-1][k]).max() < 1e-3
    assert max(regtrack.alignment_error(a, g) for a, g in zip(ours, gt)) < 3.0
    out = tmp_path / "cli.txt"
    subprocess.run(
        [cli(), "track", "--seq", str(tmp_path / "data" / "bend.txt"), "--sm", "fclk",
         "--am", "ssd", "--ssm", "tps", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    for a, b in zip(ours, read_corners(out)):
        assert np.abs(a - b).max() < 1e-3
    assert regtrack.Tracker("esm", "ssd", "homography").warped_grid is None
    with pytest.raises(regtrack.Error, match="non-rigid"):
        regtrack.Tracker("pf", "ssd", "spline")


def test_eval_reads_pot_as_downloaded_and_gives_the_benchmarks_figures(tmp_path):
    import shutil
    regtrack.synth(ROOT / "assets/textures/skimage_coffee.png",
                   ROOT / "assets/motion/ucsb_bricks_rt.txt", tmp_path / "mtf", "rt",
                   max_frames=8, noise=1.0)
    rows = [l.split()[1:] for l in (tmp_path / "mtf/rt.txt").read_text().splitlines()[1:]]
    pot = tmp_path / "pot"
    (pot / "annotation").mkdir(parents=True)
    for name in ["V01_3", "V02_3"]:
        shutil.copytree(tmp_path / "mtf/rt", pot / name)
        # CRLF, the frames not annotated as zeros.
        lines = [" ".join(r) if k % 2 == 0 else " ".join(["0"] * 8) for k, r in enumerate(rows)]
        (pot / "annotation" / f"{name}_gt_points.txt").write_bytes(("\r\n".join(lines) + "\r\n").encode())
    got = regtrack.eval(pot, sm=["esm"], am=["ssd"], ssm=["homography"], res=40)
    by_seq = {r["sequence"]: r for r in got}
    assert set(by_seq) == {"V01_3", "V02_3", "ALL", "ALL:perspective"}
    assert by_seq["V01_3"]["frames"] == 3
    for r in got:
        assert r["p5"] == 1.0 and r["p15"] == 1.0
        assert r["success_h"] > 0.9 and r["success_iou"] > 0.8


def test_a_video_tracks_from_python(rendered, tmp_path):
    import shutil
    if shutil.which("ffmpeg") is None:
        assert not os.environ.get("CI"), "ffmpeg is missing on CI"
        pytest.skip("ffmpeg is not installed")
    clip = tmp_path / "rt.mp4"
    subprocess.run(
        ["ffmpeg", "-v", "error", "-framerate", "25", "-i", str(rendered.parent / "rt/frame%05d.jpg"),
         "-c:v", "libx264", "-crf", "8", "-pix_fmt", "yuv420p", str(clip)],
        check=True,
    )
    shutil.copy(rendered, tmp_path / "rt.txt")
    video = regtrack.Sequence(clip)
    assert len(video) == 20
    gt = video.ground_truth
    t = regtrack.Tracker()
    frame, g0 = video[0]
    # As OpenCV would give it: BGR.
    t.initialize(np.stack([frame] * 3, axis=2), g0)
    errors = []
    for k, (frame, g) in enumerate(video):
        if k == 0:
            continue
        c, s = t.update(np.stack([frame] * 3, axis=2))
        assert s == "tracking"
        errors.append(regtrack.alignment_error(c, g))
    assert max(errors) < 2.0, max(errors)


def test_a_live_source_from_python():
    import shutil
    if shutil.which("ffmpeg") is None:
        assert not os.environ.get("CI"), "ffmpeg is missing on CI"
        pytest.skip("ffmpeg is not installed")
    cam = regtrack.Camera("lavfi:testsrc=size=320x240:rate=30:duration=1", size=(320, 240))
    frames = list(cam)
    assert 5 <= len(frames) <= 30
    assert frames[0].shape == (240, 320) and frames[0].dtype == np.uint8
    assert "stopped after" in cam.stopped
    t = regtrack.Tracker()
    t.initialize(frames[0], [[100, 60], [220, 60], [220, 180], [100, 180]])
    c, s = t.update(frames[1])
    assert c.shape == (4, 2)
    # In colour: BGR frames, which a colour tracker reads.
    colour = list(regtrack.Camera("lavfi:testsrc=size=320x240:rate=30:duration=0.5",
                                  size=(320, 240), colour=True))
    assert colour[0].shape == (240, 320, 3) and colour[0].dtype == np.uint8
    assert (colour[0][:, :, 0] != colour[0][:, :, 2]).any()
    t = regtrack.Tracker("fclk", "ssd", "homography", channels="rgb")
    t.initialize(colour[0], [[100, 60], [220, 60], [220, 180], [100, 180]])
    c, s = t.update(colour[1])
    assert c.shape == (4, 2)
    with pytest.raises(regtrack.Error, match="cannot|not"):
        list(regtrack.Camera("/dev/nosuchcamera", size=(320, 240)))
    # Sizes that cannot be a picture's: named, before anything is allocated (10**9 squared
    # aborted the interpreter).
    with pytest.raises(ValueError, match=r"size must be \(width, height\)"):
        regtrack.Camera("lavfi:testsrc=size=320x240:rate=30", size=(-1, 5))
    with pytest.raises(regtrack.Error, match="each side must be"):
        regtrack.Camera("lavfi:testsrc=size=320x240:rate=30", size=(10**9, 10**9))


def test_many_patches_from_python_match_the_command_line(rendered, tmp_path):
    seq = regtrack.Sequence(rendered)
    frames = [f for f, _ in seq]
    gt = seq.ground_truth
    pt = regtrack.PatchTracker(size=11, threads=1)
    pts = pt.detect(frames[0], 40, region=gt[0])
    assert pts.shape[1] == 2 and 10 <= len(pts) <= 40
    pt.initialize(frames[0], pts)
    assert len(pt) == len(pts)
    ours = [pts]
    for f in frames[1:]:
        centres, tracking = pt.update(f)
        assert centres.shape == (len(pts), 2) and tracking.dtype == bool
        ours.append(centres)
    assert tracking.mean() > 0.8
    assert all(s == "tracking" or s.startswith("lost: ") for s in pt.status)
    assert pt.linear.shape == (len(pts), 2, 2) and pt.ncc.shape == (len(pts),)
    out = tmp_path / "tracks.csv"
    subprocess.run(
        [cli(), "track", "--seq", str(rendered), "--patches", "40", "--patch", "size=11",
         "--patch", "threads=1", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    theirs = np.array([[float(r[3]), float(r[4])] for r in rows]).reshape(len(frames), -1, 2)
    # The same points, the same tracks (the file holds 4 decimals).
    assert np.abs(np.array(ours) - theirs).max() < 1e-3
    # A float frame is the same frame; errors name what was wrong.
    again = regtrack.PatchTracker(size=11, threads=1)
    again.initialize(frames[0].astype(np.float32), pts)
    c, _ = again.update(frames[1].astype(np.float32))
    assert np.abs(c - ours[1]).max() < 1e-9
    with pytest.raises(regtrack.Error, match="sise"):
        regtrack.PatchTracker(sise=11)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        pt.initialize(frames[0], np.zeros((3, 3)))
