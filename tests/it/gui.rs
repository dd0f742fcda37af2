//! Inspector tests with egui_kittest (no GPU): dropdowns, playback, sessions, a ground-truth
//! corner drag, and a screenshot smoke test under Xvfb.

use crate::common::{TempDir, root};
use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use regtrack::app::InspectorApp;
use regtrack::app::command::Command;
use regtrack::app::state::{SequenceSource, State};
use regtrack::dataset::synth::{SynthConfig, render_sequence};
use regtrack::geometry::Point;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// How many times the inspectors' workers have woken their UI (the app's repaint callback,
/// called after every reply): [`step_until`] waits for the next wake instead of sleeping.
static WAKES: (Mutex<u64>, Condvar) = (Mutex::new(0), Condvar::new());

/// The wake callback the tests' inspectors are built with.
fn wake() {
    let (count, changed) = &WAKES;
    *count.lock().unwrap() += 1;
    changed.notify_all();
}

/// The wakes so far.
fn wakes() -> u64 {
    *WAKES.0.lock().unwrap()
}

/// Waits until a wake after `seen` (any inspector's: a spurious one only costs a check), at
/// most `limit`; returns the wakes then.
fn wait_for_wake(seen: u64, limit: Duration) -> u64 {
    let (count, changed) = &WAKES;
    let guard = count.lock().unwrap();
    let (guard, _) = changed
        .wait_timeout_while(guard, limit, |n| *n == seen)
        .unwrap();
    *guard
}

/// A short synthetic sequence (PNG frames) in `dir`.
fn small_sequence(dir: &std::path::Path, frames: usize) -> std::path::PathBuf {
    let a = root().join("assets");
    let cfg = SynthConfig {
        texture: a.join("textures/skimage_coffee.png"),
        background: Some(a.join("textures/skimage_grass.png")),
        motion: a.join("motion/ucsb_bricks_rt.txt"),
        max_frames: Some(frames),
        jpeg_quality: 0,
        ..SynthConfig::default()
    };
    render_sequence(&cfg, dir, "rt", &|_, _| {}).unwrap();
    dir.join("rt.txt")
}

fn harness(state: State) -> Harness<'static, InspectorApp> {
    let app = InspectorApp::new(state, wake);
    Harness::builder()
        .with_size(egui::Vec2::new(1400.0, 900.0))
        .with_max_steps(10_000)
        .build_ui_state(|ui, app: &mut InspectorApp| app.ui(ui), app)
}

/// How wide the small sequence's frame (640 px) is on screen.
fn frame_width(h: &Harness<'static, InspectorApp>) -> f32 {
    let a = h.state().screen_pos(Point::new(0.0, 0.0)).unwrap();
    let b = h.state().screen_pos(Point::new(639.0, 0.0)).unwrap();
    b.x - a.x
}

/// Steps the UI until `done` holds: the worker runs on its own thread, and each step waits for
/// its next reply (the wake it sends), or at most 50 ms for what no reply announces.
fn step_until(
    h: &mut Harness<'static, InspectorApp>,
    what: &str,
    done: impl Fn(&InspectorApp) -> bool,
) {
    let start = Instant::now();
    let mut seen = wakes();
    while !done(h.state()) {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "timed out waiting for {what}; errors: {:?}; status: {}",
            h.state().errors_shown(),
            h.state().status()
        );
        h.step();
        seen = wait_for_wake(seen, Duration::from_millis(50));
    }
    h.step();
}

/// The inspector on `seq`, its first frame shown, in the ground-truth editing mode.
fn editing_ground_truth(seq: &std::path::Path) -> Harness<'static, InspectorApp> {
    let mut h = harness(state_on(seq));
    step_until(&mut h, "the frame", |a| {
        a.tracked_until() == Some(0) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    h.get_by_label("Edit ground-truth corners").click();
    h.run_steps(4);
    h
}

fn state_on(seq: &std::path::Path) -> State {
    State {
        sequence: SequenceSource::Path(seq.to_path_buf()),
        ..State::default()
    }
}

#[test]
fn pick_an_am_play_and_watch_the_plots_grow() {
    let d = TempDir::new("gui-play");
    let seq = small_sequence(d.path(), 12);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    // Pick NCC for tracker 1 from its dropdown, by label.
    h.get_by_label("AM 1").click();
    h.run_steps(3);
    h.get_by_label("ncc").click();
    h.run_steps(2);
    // Only tracker 1 re-runs (on the worker): its start frame comes back on its own.
    step_until(&mut h, "re-initialisation", |a| {
        a.state.trackers[0].spec.registration().unwrap().am == "ncc"
            && a.tracked_until() == Some(0)
            && a.result(0, 0).is_some()
    });
    let first = h.state().result(0, 0).unwrap().corners;
    h.get_by_label("Play").click();
    step_until(&mut h, "the end of the sequence", |a| {
        a.tracked_until() == Some(11) && !a.is_playing()
    });
    let app = h.state();
    // 11 tracked frames after the start frame: one error per frame, and a success curve.
    assert_eq!(app.errors(0).len(), 11);
    assert_eq!(app.success_curve(0).len(), 201);
    assert!(
        app.success_curve(0)[50].1 > 0.9,
        "SR@5 {:?}",
        app.success_curve(0)[50]
    );
    let last = app.result(0, 11).unwrap().corners;
    assert!(
        first.change_norm(&last) > 5.0,
        "the quad moved: {first} -> {last}"
    );
    assert!(!app.result(0, 11).unwrap().iterations.is_empty());
    assert_eq!(app.state.frame, 11);
}

#[test]
fn sessions_load_and_every_bundled_session_is_valid() {
    for entry in std::fs::read_dir(root().join("sessions")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            let s = State::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert!(!s.trackers.is_empty(), "{}", p.display());
        }
    }
    let d = TempDir::new("gui-session");
    let seq = small_sequence(d.path(), 6);
    let mut state = state_on(&seq);
    state.trackers.truncate(1);
    let r = state.trackers[0].spec.registration_mut().unwrap();
    r.sm = "fclk".into();
    r.am = "ssd".into();
    r.ssm = "affine".into();
    let session = d.path().join("s.toml");
    state.save(&session).unwrap();
    // Start on another session, then load the saved one through the command handler.
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::LoadSession(session.clone()));
    step_until(&mut h, "the loaded session", |a| {
        a.state.trackers.len() == 1 && a.tracked_until() == Some(0)
    });
    assert_eq!(h.state().state.trackers[0].spec.label(), "fclk_ssd_affine");
    // An unknown method is reported at its tracker's line.
    let text = std::fs::read_to_string(&session).unwrap();
    let line = text
        .lines()
        .position(|l| l.trim() == "[[trackers]]")
        .unwrap()
        + 1;
    std::fs::write(&session, text.replace("\"fclk\"", "\"nosuch\"")).unwrap();
    let e = State::load(&session).unwrap_err().to_string();
    assert!(
        e.contains(&format!("s.toml:{line}:")) && e.contains("nosuch"),
        "{e}"
    );
    // A broken session is reported, not a crash.
    std::fs::write(&session, "trackers = 3\n").unwrap();
    h.state_mut().send(Command::LoadSession(session));
    step_until(&mut h, "the error", |a| !a.errors_shown().is_empty());
    assert!(h.state().errors_shown()[0].contains("s.toml"));
}

/// Drags from `from` to `to` in a few steps.
fn drag(h: &mut Harness<'static, InspectorApp>, from: egui::Pos2, to: egui::Pos2) {
    h.hover_at(from);
    h.step();
    h.drag_at(from);
    h.step();
    for k in 1..=4 {
        h.hover_at(from + (to - from) * (k as f32 / 4.0));
        h.step();
    }
    h.drop_at(to);
    h.step();
    h.step();
}

fn press(h: &mut Harness<'static, InspectorApp>, key: egui::Key, modifiers: egui::Modifiers) {
    h.key_press_modifiers(modifiers, key);
    h.step();
    h.step();
}

#[test]
fn the_ground_truth_correction_flow() {
    use regtrack::gt::{GtFrame, Mark};
    let d = TempDir::new("gui-gt");
    let seq = small_sequence(d.path(), 8);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the frame", |a| {
        a.tracked_until() == Some(0) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    // Correct in similitude: pick it from the GT SSM dropdown.
    h.get_by_label("GT SSM").click();
    h.run_steps(3);
    h.get_by_label("similitude").click();
    h.run_steps(2);
    assert_eq!(h.state().state.gt_ssm, "similitude");
    h.get_by_label("Edit ground-truth corners").click();
    // The strip under the frame appears: let the layout settle.
    h.run_steps(4);
    let gt = h.state().ground_truth(0).unwrap();
    let sim = regtrack::ssm::build("similitude").unwrap();

    // Pick: drag corner 1; the opposite corner stays and the quad stays a similitude.
    let from = h.state().screen_pos(gt.0[0]).unwrap();
    drag(&mut h, from, from + egui::Vec2::new(12.0, 9.0));
    let dragged = h.state().ground_truth(0).unwrap();
    assert!(dragged.0[0].dist(gt.0[0]) > 2.0, "{gt} -> {dragged}");
    assert!(
        dragged.0[2].dist(gt.0[2]) < 1e-6,
        "the opposite corner stays"
    );
    let (_, _, r) = regtrack::gt::best_fit(&*sim, &gt, &dragged).unwrap();
    assert!(r < 1e-6, "the edit stays a similitude ({r} px)");
    assert_eq!(h.state().gt_cursor().0, Some(0));

    // Nudge: corner 2 by 3 steps of 1 px to the right, then the step doubles.
    press(&mut h, egui::Key::Num2, egui::Modifiers::NONE);
    assert_eq!(h.state().gt_cursor().0, Some(1));
    for _ in 0..3 {
        press(&mut h, egui::Key::ArrowRight, egui::Modifiers::SHIFT);
    }
    let nudged = h.state().ground_truth(0).unwrap();
    assert!(
        (nudged.0[1].x - dragged.0[1].x - 3.0).abs() < 1e-6
            && (nudged.0[1].y - dragged.0[1].y).abs() < 1e-6,
        "{dragged} -> {nudged}"
    );
    press(&mut h, egui::Key::Plus, egui::Modifiers::NONE);
    assert_eq!(h.state().gt_cursor().1, 2.0);

    // Undo / redo over every edit.
    press(&mut h, egui::Key::Z, egui::Modifiers::COMMAND);
    let undone = h.state().ground_truth(0).unwrap();
    assert!(
        (undone.0[1].x - dragged.0[1].x - 2.0).abs() < 1e-6,
        "one nudge undone"
    );
    for _ in 0..3 {
        press(&mut h, egui::Key::Z, egui::Modifiers::COMMAND);
    }
    assert!(
        h.state().ground_truth(0).unwrap().0[0].dist(gt.0[0]) < 1e-6,
        "back to the start"
    );
    press(
        &mut h,
        egui::Key::Z,
        egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
    );
    assert!(
        h.state().ground_truth(0).unwrap().0[0].dist(dragged.0[0]) < 1e-6,
        "the drag redone"
    );
    for _ in 0..3 {
        press(
            &mut h,
            egui::Key::Z,
            egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
        );
    }
    assert!(h.state().ground_truth(0).unwrap().0[1].dist(nudged.0[1]) < 1e-6);

    // Propagate from the corrected frame, then accept the proposal as one edit.
    h.get_by_label("Propagate").scroll_to_me();
    h.run_steps(10);
    h.get_by_label("Propagate").click();
    step_until(&mut h, "the proposal", |a| a.gt_proposal().is_some());
    let proposal = h.state().gt_proposal().unwrap().clone();
    assert_eq!(proposal.frames.first().unwrap().0, 1);
    assert!(proposal.frames.len() >= 5, "{:?}", proposal.stop);
    h.get_by_label("Accept").click_accesskit();
    h.step();
    h.step();
    let key = "similitude";
    for (f, _) in &proposal.frames {
        assert!(matches!(
            h.state().corrections().mark(key, *f),
            Some(Mark::Quad(_))
        ));
    }
    press(&mut h, egui::Key::Z, egui::Modifiers::COMMAND);
    assert!(
        h.state().corrections().mark(key, 3).is_none(),
        "one undo removes the whole proposal"
    );
    press(&mut h, egui::Key::Y, egui::Modifiers::COMMAND);
    assert!(h.state().corrections().mark(key, 3).is_some());

    // The next frame is occluded (undo showed the frames it changed).
    let f0 = h.state().state.frame;
    // The frame keys are those of every mode: Right, and Page Down.
    press(&mut h, egui::Key::ArrowRight, egui::Modifiers::NONE);
    step_until(&mut h, "the next frame", |a| a.state.frame == f0 + 1);
    press(&mut h, egui::Key::PageDown, egui::Modifiers::NONE);
    let occluded = f0 + 2;
    assert_eq!(h.state().state.frame, occluded);
    press(&mut h, egui::Key::O, egui::Modifiers::NONE);
    assert_eq!(h.state().gt_frame(occluded), Some(GtFrame::Occluded));
    let before_export: Vec<_> = (0..8).map(|f| h.state().gt_frame(f)).collect();

    // A mistyped path fails to open and loses nothing.
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(
            d.path().join("no_such_seq.txt"),
        )));
    step_until(&mut h, "the error", |a| !a.errors_shown().is_empty());
    assert_eq!(h.state().gt_frame(occluded), Some(GtFrame::Occluded));
    assert_eq!(h.state().sequence().unwrap().name, "rt");
    assert_eq!(
        h.state().state.sequence,
        SequenceSource::Path(seq.clone()),
        "the session keeps it"
    );
    h.state_mut().send(Command::DismissError(0));
    h.run_steps(4);

    // Export: the sequence's own format and OptGT, atomically; the original is untouched.
    let original = std::fs::read_to_string(&seq).unwrap();
    assert!(h.state().ground_truth_edited());
    // At the foot of the trackers panel, below the fold at 1400x900: through accesskit (the
    // real window scrolls to it with the wheel).
    h.get_by_label("Export ground truth*").click_accesskit();
    h.step();
    h.step();
    assert!(
        h.state().errors_shown().is_empty(),
        "{:?}",
        h.state().errors_shown()
    );
    assert!(
        !h.state().ground_truth_edited(),
        "{} {:?}",
        h.state().status(),
        h.state().errors_shown()
    );
    assert_eq!(std::fs::read_to_string(&seq).unwrap(), original);
    let exported = d.path().join("rt_gt_similitude.txt");
    let saved = regtrack::dataset::read_ground_truth(&exported).unwrap();
    assert_eq!(saved.len(), 8);
    assert!(saved[occluded].quad.is_none(), "occluded");
    assert!(
        saved[1].quad.unwrap().0[1].dist(before_export[1].unwrap().quad().unwrap().0[1]) < 1e-3
    );
    let opt =
        regtrack::dataset::read_ground_truth(&d.path().join("OptGT/rt_similitude.txt")).unwrap();
    assert!(opt[occluded].quad.is_none() && opt[1].quad.is_some());
    // The exported file opens as the sequence.
    let reopened = regtrack::dataset::Sequence::open(&exported).unwrap();
    assert_eq!(reopened.len(), 8);
    drop(h);

    // Reopening restores every correction from the journal.
    let mut h = harness(State {
        gt_ssm: "similitude".into(),
        ..state_on(&seq)
    });
    step_until(&mut h, "the frame", |a| a.tracked_until() == Some(0));
    for (f, b) in before_export.iter().enumerate() {
        let (a, b) = (h.state().gt_frame(f).unwrap(), b.unwrap());
        match (a.quad(), b.quad()) {
            (Some(x), Some(y)) => assert!(
                regtrack::geometry::alignment_error(&x, &y) < 1e-9,
                "frame {f}"
            ),
            _ => assert_eq!(a, b, "frame {f}"),
        }
    }
    assert!(
        h.state().status().contains("restored"),
        "{}",
        h.state().status()
    );
}

#[test]
fn screenshot_under_xvfb_is_not_blank() {
    let has_xvfb = std::process::Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_xvfb {
        // CI installs Xvfb; elsewhere the smoke test needs it too.
        assert!(
            std::env::var_os("CI").is_none(),
            "xvfb-run is missing on CI"
        );
        eprintln!("skipped: xvfb-run is not installed");
        return;
    }
    let d = TempDir::new("gui-shot");
    let seq = small_sequence(d.path(), 8);
    let shot = d.path().join("shot.png");
    let runtime = d.path().join("xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    let out = std::process::Command::new("xvfb-run")
        .args([
            "-a",
            "-s",
            "-screen 0 1400x900x24",
            env!("CARGO_BIN_EXE_regtrack"),
            "inspect",
            "--seq",
        ])
        .arg(&seq)
        .args(["--frames", "5", "--screenshot"])
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", &runtime)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&shot).unwrap().to_rgb8();
    assert!(img.width() >= 800 && img.height() >= 600);
    // Not blank: many distinct colours, and the frame's content in the middle.
    let mut colours = std::collections::HashSet::new();
    for p in img.pixels().step_by(7) {
        colours.insert(p.0);
    }
    assert!(colours.len() > 500, "only {} colours", colours.len());
    // A sequence that cannot be shown: the window with the error is captured and the command
    // fails, instead of waiting for frames forever.
    let empty = d.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let malformed = d.path().join("bad.txt");
    std::fs::write(&malformed, "1 2 3\n").unwrap();
    for (bad, what) in [(&empty, "no png"), (&malformed, "bad.txt:1")] {
        let shot = d.path().join("bad_shot.png");
        let _ = std::fs::remove_file(&shot);
        let out = std::process::Command::new("timeout")
            .args(["120", "xvfb-run", "-a", "-s", "-screen 0 1400x900x24"])
            .arg(env!("CARGO_BIN_EXE_regtrack"))
            .args(["inspect", "--seq"])
            .arg(bad)
            .args(["--frames", "1", "--screenshot"])
            .arg(&shot)
            .env("XDG_RUNTIME_DIR", &runtime)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_ne!(
            out.status.code(),
            Some(124),
            "{what}: the inspector did not exit"
        );
        assert!(!out.status.success() && err.contains(what), "{what}: {err}");
        assert!(
            shot.is_file(),
            "{what}: the window with the error is captured"
        );
    }
}

#[test]
fn nn_samples_reach_the_frame_view_and_method_parameters_the_panel() {
    let d = TempDir::new("gui-nn");
    let seq = small_sequence(d.path(), 6);
    let mut state = state_on(&seq);
    let r = state.trackers[0].spec.registration_mut().unwrap();
    r.sm = "nn1k".into();
    r.method.set("samples", 200.0);
    // The AM's parameters share the bag and the panel, under their own heading.
    r.am = "lscv".into();
    r.method.set("regions", 2.0);
    state.trackers.truncate(1);
    state.view.show_samples = true;
    let mut h = harness(state);
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    // The method's own parameters are in the panel, from their definitions.
    h.get_by_label("Parameters 1").click();
    h.run_steps(3);
    h.get_by_label("samples");
    h.get_by_label("candidates");
    h.get_by_label("search method");
    h.get_by_label("appearance model");
    h.get_by_label("regions");
    h.get_by_label("Play").click();
    step_until(&mut h, "the end of the sequence", |a| {
        a.tracked_until() == Some(5)
    });
    let a = h.state();
    let v = a
        .result(0, 5)
        .and_then(|r| r.visual.clone())
        .expect("samples of the newest frame");
    assert_eq!(v.quads.len(), 200);
    assert_eq!(v.weights.len(), 200);
    assert!(v.chosen.is_some_and(|k| k < 200));
    // Older frames drop theirs (memory stays bounded).
    assert!(a.result(0, 3).unwrap().visual.is_none());
}

#[test]
fn keyboard_sessions_and_errors_as_a_day_of_use_needs() {
    let d = TempDir::new("gui-day");
    let seq = small_sequence(d.path(), 10);
    // A session saved at frame 5 reopens at frame 5, tracked up to there, with its name shown.
    let mut state = state_on(&seq);
    state.frame = 5;
    let session = d.path().join("day.toml");
    state.save(&session).unwrap();
    let mut h = harness(State::load(&session).unwrap());
    h.state_mut().set_session_path(&session);
    step_until(&mut h, "the saved frame", |a| {
        a.tracked_until() == Some(5) && !a.is_playing()
    });
    assert_eq!(h.state().state.frame, 5);
    h.step();
    assert!(
        h.query_all_by_value(session.to_str().unwrap())
            .next()
            .is_some(),
        "the session field names it"
    );

    // Keyboard: Left goes back, Right forward over tracked frames then tracks the next one,
    // Home to the start, Space plays.
    press(&mut h, egui::Key::ArrowLeft, egui::Modifiers::NONE);
    assert_eq!(h.state().state.frame, 4);
    press(&mut h, egui::Key::ArrowRight, egui::Modifiers::NONE);
    press(&mut h, egui::Key::ArrowRight, egui::Modifiers::NONE);
    step_until(&mut h, "one more tracked frame", |a| {
        a.tracked_until() == Some(6)
    });
    press(&mut h, egui::Key::Home, egui::Modifiers::NONE);
    assert_eq!(h.state().state.frame, 0);
    press(&mut h, egui::Key::F1, egui::Modifiers::NONE);
    assert!(
        h.query_by_label("Keyboard shortcuts").is_some(),
        "F1 opens the help"
    );
    press(&mut h, egui::Key::F1, egui::Modifiers::NONE);

    // A corrupt frame: one error however often it is met, a placeholder instead of the previous
    // image, and the error goes once the sequence opens again successfully.
    let bad = std::fs::read_dir(seq.with_extension(""))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.file_name().unwrap().to_string_lossy().contains("00008"))
        .unwrap();
    std::fs::write(&bad, b"not an image").unwrap();
    press(&mut h, egui::Key::Space, egui::Modifiers::NONE);
    step_until(&mut h, "the corrupt frame", |a| {
        !a.errors_shown().is_empty() && !a.is_playing()
    });
    for _ in 0..3 {
        h.state_mut().send(Command::Seek(7));
        h.run_steps(3);
        h.state_mut().send(Command::Seek(6));
        h.run_steps(3);
    }
    h.state_mut().send(Command::Seek(7));
    step_until(&mut h, "the placeholder", |a| a.bad_frame() == Some(7));
    assert_eq!(
        h.state().errors_shown().len(),
        1,
        "{:?}",
        h.state().errors_shown()
    );
    assert!(h.state().errors_shown()[0].contains("00008"));
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(seq.clone())));
    step_until(&mut h, "the reopened sequence", |a| {
        a.tracked_until() == Some(0)
    });
    assert!(h.state().errors_shown().is_empty(), "a stale error stays");
}

#[test]
fn the_command_line_help_lists_the_shortcuts() {
    let out = crate::cli::regtrack(&["inspect", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for (keys, _) in regtrack::app::SHORTCUTS {
        for k in keys
            .trim_start_matches("ground-truth mode: ")
            .split([' ', '/', ','])
        {
            if !k.is_empty() && k != "or" {
                assert!(
                    text.contains(k),
                    "`{k}` missing from inspect --help:\n{text}"
                );
            }
        }
    }
}

#[test]
fn only_the_changed_tracker_reruns_and_play_replays() {
    let d = TempDir::new("gui-rerun");
    let seq = small_sequence(d.path(), 10);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Play);
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(9) && !a.is_playing()
    });
    h.state_mut().send(Command::Seek(6));
    h.run_steps(2);
    let first: Vec<_> = (0..10)
        .map(|f| h.state().result(0, f).unwrap().corners)
        .collect();
    // Tracker 2 changes its AM: only it re-runs (up to frame 10); tracker 1 keeps its results and
    // the view stays on frame 7.
    let mut entry = h.state().state.trackers[1].clone();
    entry.spec.registration_mut().unwrap().am = "ncc".into();
    h.state_mut().send(Command::SetTracker(1, Box::new(entry)));
    step_until(&mut h, "tracker 2 re-run", |a| {
        a.result(1, 9).is_some() && a.state.trackers[1].spec.registration().unwrap().am == "ncc"
    });
    assert_eq!(h.state().state.frame, 6, "the view stays");
    assert_eq!(h.state().tracked_until(), Some(9));
    for (f, c) in first.iter().enumerate() {
        assert_eq!(
            h.state().result(0, f).unwrap().corners,
            *c,
            "tracker 1, frame {f}"
        );
    }
    // Adding a tracker runs it alone; removing tracker 1 keeps tracker 2's results.
    h.state_mut().send(Command::AddTracker);
    step_until(&mut h, "the new tracker", |a| a.result(2, 9).is_some());
    let second = h.state().result(1, 9).unwrap().corners;
    h.state_mut().send(Command::RemoveTracker(0));
    h.run_steps(3);
    assert_eq!(h.state().state.trackers.len(), 2);
    assert_eq!(h.state().result(0, 9).unwrap().corners, second);
    // Play after a finished run replays the stored results from the shown frame.
    h.state_mut().send(Command::Seek(2));
    h.run_steps(2);
    h.state_mut().send(Command::Play);
    h.run_steps(2);
    assert!(h.state().is_replaying());
    step_until(&mut h, "the replay's end", |a| !a.is_replaying());
    assert_eq!(h.state().state.frame, 9);
    assert_eq!(
        h.state().result(0, 9).unwrap().corners,
        second,
        "replaying does not re-track"
    );
    assert!(
        h.state().status().contains("end of the sequence"),
        "{}",
        h.state().status()
    );
    // Re-run from here re-tracks and plays, keeping the results before it in the plots; the
    // frame it re-initialised on (error 0 by construction) is not counted.
    let before: Vec<_> = (1..4)
        .map(|f| h.state().result(0, f).unwrap().corners)
        .collect();
    let errors_before = h.state().errors(0);
    assert_eq!(errors_before.len(), 9);
    h.state_mut().send(Command::RerunFrom(4));
    h.step();
    assert_eq!(h.state().tracked_until(), None, "re-initialising");
    step_until(&mut h, "the re-run to the end", |a| {
        a.tracked_until() == Some(9) && !a.is_playing()
    });
    for (k, c) in before.iter().enumerate() {
        assert_eq!(
            h.state().result(0, k + 1).unwrap().corners,
            *c,
            "frame {}",
            k + 1
        );
    }
    let errors = h.state().errors(0);
    let frames: Vec<usize> = errors.iter().map(|e| e.0).collect();
    assert_eq!(frames, vec![1, 2, 3, 5, 6, 7, 8, 9]);
    assert_eq!(&errors[..3], &errors_before[..3]);
    assert_eq!(
        h.state().state.start_frame,
        0,
        "the run still starts on frame 1"
    );
}

#[test]
fn each_iteration_keeps_its_patch_for_the_convergence_view() {
    let d = TempDir::new("gui-iter");
    let seq = small_sequence(d.path(), 6);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Play);
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(5) && !a.is_playing()
    });
    // Frame 1: no motion is predicted yet (frame 0 is the initialisation), so the search starts
    // off the target.
    let r = h.state().result(0, 1).unwrap().clone();
    assert!(r.iterations.len() > 1, "{} iterations", r.iterations.len());
    // Each pyramid level samples its own grid (half the finer level's per side).
    for it in &r.iterations {
        let side = regtrack::plan::level_res(r.res, it.level);
        assert_eq!(it.patch.len(), side * side, "level {}", it.level);
    }
    assert!(r.iterations.iter().any(|it| it.level > 0));
    // The first iteration starts off the target and its level moves onto it: the patches of
    // that level's first and last iterations differ. The last iteration is (to 8-bit
    // rounding) the tracker's final patch.
    let coarse = r.iterations[0].level;
    let settled = r
        .iterations
        .iter()
        .rposition(|it| it.level == coarse)
        .unwrap();
    assert!(settled > 0);
    assert_ne!(r.iterations[0].patch, r.iterations[settled].patch);
    let fine = r.iterations.iter().position(|it| it.level == 0).unwrap();
    let last = &r.iterations.last().unwrap().patch;
    let off: f32 = last
        .iter()
        .zip(&r.patch)
        .map(|(&a, &b)| (a as f32 - b).abs())
        .fold(0.0, f32::max);
    assert!(off <= 0.5 + 1e-3, "{off}");
    // The slider picks an iteration; the frame view and the panel follow it.
    h.state_mut().send(Command::Seek(1));
    h.state_mut().send(Command::SelectIteration(Some(fine)));
    h.run_steps(3);
    let label = format!("warped patch, iteration {}", fine + 1);
    assert!(h.query_by_label(&label).is_some(), "{label}");
    // An iteration of the coarsest level shows its own, smaller patch.
    h.state_mut().send(Command::SelectIteration(Some(0)));
    h.run_steps(3);
    let level = r.iterations[0].level;
    let side = regtrack::plan::level_res(r.res, level);
    let label = format!("iteration 1: pyramid level {level}, {side}x{side}");
    assert!(h.query_by_label(&label).is_some(), "{label}");
}

#[test]
fn at_1000x700_the_frame_keeps_most_of_the_window() {
    let d = TempDir::new("gui-small");
    let seq = small_sequence(d.path(), 3);
    let app = InspectorApp::new(state_on(&seq), wake);
    let mut h = Harness::builder()
        .with_size(egui::Vec2::new(1000.0, 700.0))
        .with_max_steps(10_000)
        .build_ui_state(|ui, app: &mut InspectorApp| app.ui(ui), app);
    step_until(&mut h, "the frame", |a| {
        a.tracked_until() == Some(0) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    h.run_steps(3);
    let with_panels = frame_width(&h);
    assert!(with_panels > 440.0, "the frame is {with_panels} px wide");
    // F2 and F3 hide the panels: the frame gets nearly the whole width.
    press(&mut h, egui::Key::F2, egui::Modifiers::NONE);
    press(&mut h, egui::Key::F3, egui::Modifiers::NONE);
    h.run_steps(3);
    let alone = frame_width(&h);
    assert!(alone > 900.0 || alone > 1.4 * with_panels, "{alone} px");
    assert!(!h.state().state.view.show_trackers_panel && !h.state().state.view.show_plots_panel);
}

#[test]
fn the_cost_landscape_view_sweeps_the_inspected_tracker() {
    let d = TempDir::new("gui-landscape");
    let seq = small_sequence(d.path(), 5);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Play);
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(4) && !a.is_playing()
    });
    h.state_mut().apply(Command::ShowLandscape(true));
    step_until(&mut h, "the curve", |a| {
        matches!(a.landscape_shown(), Some((Ok(_), true)))
    });
    let Some((Ok(l), _)) = h.state().landscape_shown() else {
        unreachable!()
    };
    assert_eq!(l.values.len(), 81);
    // The tracker converged: the best sample is within a step of the estimate.
    assert!(l.best()[0].abs() <= 0.25 + 1e-9, "{:?}", l.best());
    assert!(h.query_by_label("Cost landscape").is_some());
    // A map (two parameters) with its colour bar; enlarged into a window of its own, and back.
    let mut settings = h.state().state.view.landscape;
    settings.y = Some(1);
    h.state_mut().send(Command::SetLandscape(settings));
    h.step();
    step_until(
        &mut h,
        "the map",
        |a| matches!(a.landscape_shown(), Some((Ok(l), true)) if l.axes.len() == 2),
    );
    h.run_steps(2);
    assert!(
        h.query_by_label_contains("the best sample").is_some(),
        "the map's caption"
    );
    h.get_by_label("Enlarge").scroll_to_me();
    h.run_steps(3);
    h.get_by_label("Enlarge").click();
    h.run_steps(3);
    assert!(h.state().landscape_enlarged());
    assert!(
        h.query_by_label_contains("Cost landscape: tracker 1, frame 5")
            .is_some(),
        "its window"
    );
    assert!(h.query_by_label("shown in its own window").is_some());
    // The map exports too, as a figure of its own.
    let plots = d.path().join("plots");
    h.state_mut().send(Command::ExportPlots(plots.clone()));
    step_until(&mut h, "the files", |a| a.status().starts_with("wrote"));
    for f in ["landscape_map.svg", "landscape_map.png"] {
        let p = plots.join(f);
        assert!(
            p.is_file() && std::fs::metadata(&p).unwrap().len() > 1000,
            "{f}"
        );
    }
    assert!(
        h.state().status().contains("landscape_map"),
        "{}",
        h.state().status()
    );
    // At the bottom of the scrolled panel: a pointer's click reaches it (a horizontal scroll
    // bar over it took the click).
    h.get_by_label("Back into the panel").scroll_to_me();
    h.run_steps(3);
    h.get_by_label("Back into the panel").click();
    h.run_steps(3);
    assert!(!h.state().landscape_enlarged());
    assert!(
        h.query_by_label_contains("Cost landscape: tracker")
            .is_none()
    );
}

#[test]
fn ab_mode_lists_the_frames_where_two_trackers_disagree() {
    let d = TempDir::new("gui-ab");
    let seq = small_sequence(d.path(), 10);
    let mut state = state_on(&seq);
    // B is a weaker tracker (translation only) so that the two disagree.
    state.trackers[1].spec.registration_mut().unwrap().ssm = "translation".into();
    let mut h = harness(state);
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Play);
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(9) && !a.is_playing()
    });
    h.get_by_label("A/B").click();
    h.run_steps(3);
    assert_eq!(h.state().state.view.ab, Some((0, 1)));
    let worst = h.state().disagreements(0, 1);
    assert_eq!(worst.len(), 10);
    assert!(
        worst.windows(2).all(|w| w[0].px >= w[1].px),
        "sorted, largest first"
    );
    let (f, dist) = (worst[0].frame, worst[0].px);
    let expect = regtrack::geometry::alignment_error(
        &h.state().result(0, f).unwrap().corners,
        &h.state().result(1, f).unwrap().corners,
    );
    assert!((dist - expect).abs() < 1e-9);
    // Its entry seeks to it.
    let label = format!("frame {}: {dist:.1} px", f + 1);
    h.get_by_label(&label).click();
    h.run_steps(3);
    assert_eq!(h.state().state.frame, f);
}

#[test]
fn a_sequence_without_ground_truth_can_be_annotated_from_scratch() {
    let d = TempDir::new("gui-annotate");
    let dir = d.path().join("walk");
    std::fs::create_dir_all(&dir).unwrap();
    for k in 0..3u8 {
        crate::common::write_png(&dir.join(format!("img{k}.png")), 320, 240, k * 9);
    }
    let mut h = harness(state_on(&dir));
    step_until(&mut h, "the frame", |a| {
        a.frame_count() == 3 && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    assert_eq!(h.state().gt_frame(0), Some(regtrack::gt::GtFrame::Missing));
    h.state_mut().send(Command::DismissError(0));
    h.get_by_label("Edit ground-truth corners").click();
    h.run_steps(4);
    let a = h.state().screen_pos(Point::new(100.0, 80.0)).unwrap();
    let b = h.state().screen_pos(Point::new(180.0, 150.0)).unwrap();
    drag(&mut h, a, b);
    let q = h
        .state()
        .ground_truth(0)
        .expect("the box is the frame's ground truth");
    assert!(q.0[0].dist(Point::new(100.0, 80.0)) < 1.0, "{q}");
    assert!(q.0[2].dist(Point::new(180.0, 150.0)) < 1.0, "{q}");
    // Exported, it opens as the sequence with its ground truth.
    // At the foot of the trackers panel, below the fold at 1400x900: through accesskit (the
    // real window scrolls to it with the wheel).
    h.get_by_label("Export ground truth*").click_accesskit();
    h.run_steps(2);
    let exported = dir.join("walk_gt_homography.txt");
    let seq = regtrack::dataset::Sequence::open(&exported).unwrap();
    assert_eq!(seq.len(), 3);
    assert!(seq.ground_truth(0).is_some() && seq.ground_truth(1).is_none());
}

/// A whole tracker picked from the tracker dropdown hides the AM/SSM/SM dropdowns, shows its
/// own parameters, tracks, and shows its internals (KCF's response map).
#[test]
fn a_whole_tracker_from_the_dropdown_tracks_and_shows_its_response_map() {
    let d = TempDir::new("gui-whole");
    let seq = small_sequence(d.path(), 6);
    let mut state = state_on(&seq);
    state.trackers.truncate(1);
    state.view.show_samples = true;
    let mut h = harness(state);
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.get_by_label("AM 1");
    // The type dropdown sits in the tracker's header, showing the current type.
    h.get_by_value("AM x SSM x SM").click();
    h.run_steps(3);
    h.get_by_label("kcf").click();
    h.run_steps(2);
    step_until(&mut h, "KCF on the first frame", |a| {
        a.state.trackers[0].spec.label() == "kcf" && a.result(0, 0).is_some()
    });
    assert!(
        h.query_by_label("AM 1").is_none(),
        "no AM dropdown for a whole tracker"
    );
    h.get_by_label("Parameters 1").click();
    h.run_steps(3);
    h.get_by_label("padding");
    h.get_by_label("Play").click();
    step_until(&mut h, "the end of the sequence", |a| {
        a.tracked_until() == Some(5)
    });
    let a = h.state();
    let v = a
        .result(0, 5)
        .and_then(|r| r.visual.clone())
        .expect("the response of the newest frame");
    let m = v.map.as_ref().expect("a response map");
    assert_eq!(m.values.len(), m.width * m.height);
    assert!(m.width >= 8 && m.height >= 8);
    assert_eq!(a.errors(0).len(), 5);
}

#[test]
fn several_presses_within_one_frame_of_the_window_all_count() {
    // A fast typist (or xdotool) can press a key several times before the window draws again.
    let d = TempDir::new("gui-presses");
    let seq = small_sequence(d.path(), 8);
    let mut h = editing_ground_truth(&seq);
    let before = h.state().ground_truth(0).unwrap();
    press(&mut h, egui::Key::Num2, egui::Modifiers::NONE);
    for _ in 0..3 {
        h.key_press_modifiers(egui::Modifiers::SHIFT, egui::Key::ArrowRight);
    }
    h.run_steps(2);
    let after = h.state().ground_truth(0).unwrap();
    assert!(
        (after.0[1].x - before.0[1].x - 3.0).abs() < 1e-6,
        "three presses, three steps: {before} -> {after}"
    );
    for _ in 0..2 {
        h.key_press_modifiers(egui::Modifiers::NONE, egui::Key::ArrowRight);
    }
    h.run_steps(2);
    // Two presses within a frame of the window: two frames on (tracked on the way), and no
    // edit made by them.
    step_until(&mut h, "frame 3", |a| a.state.frame == 2);
    assert_eq!(h.state().ground_truth(0).unwrap(), after);
}

/// Every value read from a session is checked against the widgets' ranges, and unknown keys are
/// refused, each error naming the file and the line (issue 18: a playback speed of 1e-30 used
/// to panic the worker, a zoom of 1e30 to allocate until the machine ran out of memory).
#[test]
fn a_session_with_values_out_of_range_or_unknown_keys_is_refused_at_the_line() {
    let d = TempDir::new("gui-badsession");
    let session = d.path().join("s.toml");
    // The A/B pair and the landscape's settings are part of a session.
    let mut state = State::default();
    state.view.ab = Some((1, 0));
    state.view.show_landscape = true;
    state.view.landscape = regtrack::app::LandscapeSettings {
        x: 2,
        y: Some(3),
        radius: 7.5,
        around_truth: true,
    };
    // So are the many-patch settings.
    state.patches.count = 120;
    state.patches.params.set("warp", 1.0);
    state.patches.params.set("size", 11.0);
    state.save(&session).unwrap();
    assert_eq!(State::load(&session).unwrap(), state);
    State::default().save(&session).unwrap();
    let good = std::fs::read_to_string(&session).unwrap();
    assert!(State::load(&session).is_ok());
    let set = |key: &str, value: &str| -> String {
        good.lines()
            .map(|l| {
                if l.trim_start().starts_with(&format!("{key} =")) {
                    format!("{key} = {value}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let line_of = |text: &str, key: &str| {
        text.lines()
            .position(|l| l.trim_start().starts_with(&format!("{key} ")))
            .unwrap()
            + 1
    };
    for (key, value, what) in [
        (
            "playback_fps",
            "1e-30",
            "playback_fps = 1.000e-30 must be 0",
        ),
        ("playback_fps", "nan", "playback_fps = NaN"),
        (
            "zoom",
            "1e30",
            "zoom = 1.000e30 must be 0 (fit) or in 0.05..=40",
        ),
        ("selected_tracker", "7", "the session has 2 tracker(s)"),
        ("gt_ssm", "\"warp9\"", "warp9"),
        (
            "radius",
            "1000.0",
            "landscape radius = 1000.00 must be in 0.5..=100",
        ),
        ("x", "9", "landscape parameter 9 does not exist"),
        ("count", "0", "patches: count = 0 must be in 1..=10000"),
    ] {
        let text = set(key, value);
        assert_ne!(text, good, "{key} is in the saved session");
        std::fs::write(&session, &text).unwrap();
        let e = State::load(&session).unwrap_err().to_string();
        let line = line_of(&text, key);
        assert!(
            e.contains(&format!("s.toml:{line}:")) && e.contains(what),
            "{key}: {e}"
        );
    }
    // A patch parameter out of range, and one that does not exist.
    assert!(good.contains("[patches.params]"), "{good}");
    for (key, what) in [("size = 99.0", "size"), ("window = 3.0", "window")] {
        let text = good.replace("[patches.params]", &format!("[patches.params]\n{key}"));
        std::fs::write(&session, &text).unwrap();
        let e = State::load(&session).unwrap_err().to_string();
        let line = line_of(&text, key.split(' ').next().unwrap());
        assert!(
            e.contains(&format!("s.toml:{line}:")) && e.contains(what),
            "{key}: {e}"
        );
    }
    // An unknown key, at the top and in a table.
    for (text, key) in [
        (format!("colour_scheme = 2\n{good}"), "colour_scheme"),
        (
            good.replace("[view]", "[view]\nzoom_speed = 3"),
            "zoom_speed",
        ),
    ] {
        std::fs::write(&session, &text).unwrap();
        let e = State::load(&session).unwrap_err().to_string();
        let line = line_of(&text, key);
        assert!(
            e.contains(&format!("s.toml:{line}:")) && e.contains(key),
            "{key}: {e}"
        );
    }
}

/// Live mode end to end on FFmpeg's test source (the same path as a camera): frames shown as
/// they come, a box dragged on the live image starts a tracker on the frame it was drawn on
/// (the image holds during the drag), Record writes frames and corners as a sequence, and the
/// source stopping mid-run is an error that names it while the recording is kept and opens.
#[test]
fn live_mode_tracks_a_dragged_box_records_and_keeps_the_recording_when_the_source_stops() {
    if std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_err()
    {
        panic!("ffmpeg is needed for the live path (apt install ffmpeg)");
    }
    let d = TempDir::new("gui-live");
    let seq = small_sequence(d.path(), 3);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence", |a| a.tracked_until() == Some(0));
    // 7 s of a 320x240 test pattern at 25 fps, then the source ends (as a camera unplugged).
    h.state_mut().send(Command::OpenCamera {
        source: "lavfi:testsrc=size=320x240:rate=25:duration=7".into(),
        width: 320,
        height: 240,
    });
    step_until(&mut h, "live frames", |a| {
        a.live().is_some_and(|l| l.frames >= 5) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    assert_eq!(h.state().frame_count(), h.state().live().unwrap().frames);
    // Opening a camera arms the box tool for the selected tracker: drag a box on the image.
    let a = h.state().screen_pos(Point::new(60.0, 40.0)).unwrap();
    let b = h.state().screen_pos(Point::new(200.0, 150.0)).unwrap();
    h.hover_at(a);
    h.step();
    h.drag_at(a);
    h.step();
    // The drag starts once the pointer moves; from then on the image holds.
    h.hover_at(a + (b - a) * 0.25);
    h.step();
    assert!(h.state().drawing());
    let held = h.state().state.frame;
    for k in 2..=4 {
        h.hover_at(a + (b - a) * (k as f32 / 4.0));
        // A new live frame arrives while the box is being drawn.
        let arrived = h.state().live().unwrap().frames;
        step_until(&mut h, "a live frame while drawing", |a| {
            a.live().is_some_and(|l| l.frames > arrived)
        });
    }
    // The image held while the box was drawn, though frames kept coming.
    assert_eq!(h.state().state.frame, held);
    assert!(h.state().live().unwrap().frames > held + 1);
    h.drop_at(b);
    h.step();
    h.step();
    step_until(&mut h, "the tracker on its start frame", |a| {
        a.result(0, held).is_some()
    });
    let start = h.state().result(0, held).unwrap().corners;
    assert!(start.0[0].dist(Point::new(60.0, 40.0)) < 1.0, "{start}");
    assert!(start.0[2].dist(Point::new(200.0, 150.0)) < 1.0, "{start}");
    // The status says so (the hint to drag a box does not stay).
    assert!(
        h.state().status().starts_with("tracker 1 started on frame"),
        "{}",
        h.state().status()
    );
    // It follows the newest frames.
    step_until(&mut h, "tracked live frames", |a| {
        a.tracked_until()
            .is_some_and(|f| f > held + 5 && a.result(0, f).is_some())
    });
    let f = h.state().tracked_until().unwrap();
    let r = h.state().result(0, f).unwrap();
    assert_eq!(
        r.status,
        regtrack::tracker::TrackStatus::Tracking,
        "live frame {f}"
    );
    // Record into a folder of the test's own.
    let rec = d.path().join("rec");
    h.state_mut()
        .send(Command::SetRecordFolder(rec.display().to_string()));
    h.step();
    h.get_by_label("Record").click();
    h.step();
    step_until(&mut h, "recorded frames", |a| {
        a.live()
            .and_then(|l| l.recording.as_ref())
            .is_some_and(|r| r.1 >= 10)
    });
    // The source stops by itself: one error naming it; the recording is kept.
    step_until(&mut h, "the source to stop", |a| a.live().is_none());
    let errors = h.state().errors_shown().join(" | ");
    assert!(
        errors.contains("testsrc") && errors.contains("stopped after"),
        "{errors}"
    );
    assert!(errors.contains("recording of"), "{errors}");
    // Nothing of the live run is left in the bottom bar ("1 of 0 ... tracked to frame 1403").
    h.run_steps(2);
    assert_eq!(h.state().tracked_until(), None);
    assert!(h.query_by_label("no sequence open").is_some());
    assert!(h.query_by_label_contains("tracked to frame").is_none());
    let (path, n) = h.state().last_recording().cloned().expect("a recording");
    assert_eq!(path, rec.join("live.txt"));
    let recorded = regtrack::dataset::Sequence::open(&path).unwrap();
    assert_eq!(recorded.len(), n);
    assert!(n >= 10);
    let tracked = (0..n)
        .filter(|&k| recorded.ground_truth(k).is_some())
        .count();
    assert!(
        tracked * 10 >= n * 9,
        "{tracked} of {n} frames have corners"
    );
    // Opened from the bar, it is a sequence to step through, evaluate and correct.
    h.get_by_label(&format!("Open the recording ({n} frames)"))
        .click();
    step_until(&mut h, "the recording", |a| {
        a.frame_count() == n && a.tracked_until() == Some(0)
    });
    // Another sequence opened: the recording's button goes; it stays in the Recent list.
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(seq.clone())));
    step_until(&mut h, "the other sequence", |a| a.frame_count() == 3);
    h.run_steps(2);
    assert!(h.query_by_label_contains("Open the recording").is_none());
    assert!(h.state().recent().contains(&path));
}

/// What the second day of use found in the window's small things: a failed open keeps the
/// shown frame, Esc closes the help, error banners stay at three (the newest), and a new
/// tracker says what it is.
#[test]
fn a_failed_open_keeps_the_frame_esc_closes_the_help_and_errors_stay_few() {
    let d = TempDir::new("gui-second-day");
    let seq = small_sequence(d.path(), 6);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Step);
    h.state_mut().send(Command::Step);
    step_until(&mut h, "two frames", |a| a.tracked_until() == Some(2));
    h.state_mut().send(Command::Seek(2));
    h.step();
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(
            d.path().join("no_such.txt"),
        )));
    step_until(&mut h, "the error", |a| !a.errors_shown().is_empty());
    assert_eq!(
        h.state().state.frame,
        2,
        "a failed open keeps the shown frame"
    );
    assert_eq!(h.state().tracked_until(), Some(2));
    press(&mut h, egui::Key::F1, egui::Modifiers::NONE);
    assert!(h.state().help_shown());
    press(&mut h, egui::Key::Escape, egui::Modifiers::NONE);
    assert!(!h.state().help_shown());
    for k in 0..5 {
        h.state_mut()
            .send(Command::ReportError(format!("error {k}")));
    }
    h.step();
    assert_eq!(
        h.state().errors_shown(),
        &["error 2".to_string(), "error 3".into(), "error 4".into()]
    );
    h.state_mut().send(Command::AddTracker);
    h.step();
    assert!(
        h.state().status().contains("a copy of tracker 2"),
        "{}",
        h.state().status()
    );
}

/// The teacher's experiment: on a tracked frame, P starts every tracker from the ground truth
/// moved by Gaussian noise (seeded), the views show each tracker's run from there, `.` and `,`
/// step its iterations, the next P draws the next start, Esc goes back to the tracked result.
#[test]
fn perturb_and_step_runs_every_tracker_from_the_same_start() {
    let d = TempDir::new("gui-experiment");
    let seq = small_sequence(d.path(), 6);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Step);
    h.state_mut().send(Command::Step);
    step_until(&mut h, "two frames", |a| a.tracked_until() == Some(2));
    h.state_mut().send(Command::Seek(2));
    h.step();
    let tracked = h.state().result(0, 2).unwrap().corners;
    let truth = h.state().ground_truth(2).unwrap();
    h.state_mut().send(Command::SetPerturbSigma(4.0));
    press(&mut h, egui::Key::P, egui::Modifiers::NONE);
    step_until(&mut h, "the experiment", |a| {
        a.experiment_on(2).is_some_and(|e| e.results.is_some())
    });
    let e = h.state().experiment_on(2).unwrap();
    let start = e.start;
    let runs = e.results.clone().unwrap();
    assert_eq!(runs.len(), 2, "both trackers ran");
    let moved = regtrack::geometry::alignment_error(&start, &truth);
    assert!(moved > 1.0 && moved < 20.0, "start {moved} px off");
    for r in &runs {
        assert!(
            r.start.unwrap().change_norm(&start) < 1e-6,
            "tracker {} from the same start",
            r.tracker + 1
        );
        assert!(!r.iterations.is_empty());
        let e = regtrack::geometry::alignment_error(&r.corners, &truth);
        assert!(e < 1.0, "tracker {} converged to {e} px", r.tracker + 1);
    }
    // The views show the experiment's run, its first iteration selected.
    assert!(
        h.state()
            .result(0, 2)
            .unwrap()
            .start
            .unwrap()
            .change_norm(&start)
            < 1e-6
    );
    assert_eq!(h.state().rt_selected_iteration(), Some(0));
    press(&mut h, egui::Key::Period, egui::Modifiers::NONE);
    press(&mut h, egui::Key::Period, egui::Modifiers::NONE);
    assert_eq!(
        h.state().rt_selected_iteration(),
        Some(2.min(runs[0].iterations.len() - 1))
    );
    press(&mut h, egui::Key::Comma, egui::Modifiers::NONE);
    assert_eq!(
        h.state().rt_selected_iteration(),
        Some(1.min(runs[0].iterations.len() - 1))
    );
    // The next press draws the next start of the seeded sequence.
    press(&mut h, egui::Key::P, egui::Modifiers::NONE);
    step_until(&mut h, "the second start", |a| {
        a.experiment_on(2)
            .is_some_and(|e| e.number == 2 && e.results.is_some())
    });
    assert_ne!(h.state().experiment_on(2).unwrap().start, start);
    press(&mut h, egui::Key::Escape, egui::Modifiers::NONE);
    assert!(h.state().experiment_on(2).is_none());
    assert_eq!(h.state().result(0, 2).unwrap().corners, tracked);
}

/// A researcher's export: the plots shown written as SVG and PNG with the report's figure code.
#[test]
fn the_plots_export_as_svg_and_png() {
    let d = TempDir::new("gui-export");
    let seq = small_sequence(d.path(), 6);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence", |a| a.tracked_until() == Some(0));
    h.get_by_label("Play").click();
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(5) && !a.is_playing()
    });
    // The frequency of convergence on the shown frame, in the window: every enabled tracker,
    // ten noise levels, the fraction converging falls as the noise grows.
    h.state_mut().send(Command::Seek(3));
    h.run_steps(2);
    h.get_by_label("Frequency of convergence").click_accesskit();
    h.run_steps(3);
    h.state_mut().send(Command::ConvergenceFrequency(8));
    h.step();
    step_until(&mut h, "the curves", |a| {
        a.frequency().is_some_and(|f| f.result.is_some())
    });
    let f = h.state().frequency().unwrap();
    assert_eq!((f.frame, f.starts), (3, 8));
    let curves = f.result.as_ref().unwrap().as_ref().unwrap();
    assert_eq!(curves.len(), h.state().state.trackers.len());
    for (_, c) in curves {
        assert_eq!(c.points.len(), 10);
        assert!(c.points.iter().all(|p| (0.0..=1.0).contains(&p.1)));
        assert!(
            c.points[0].1 >= c.points[9].1 && c.points[0].1 >= 0.5,
            "{}: {:?}",
            c.tracker,
            c.points
        );
    }
    assert!(
        h.query_by_label_contains("starts per σ").is_some(),
        "the plot's caption"
    );
    let out = d.path().join("plots");
    h.state_mut().send(Command::ExportPlots(out.clone()));
    step_until(&mut h, "the files", |a| a.status().starts_with("wrote"));
    // Where they went, in full.
    assert!(
        h.state().status().contains(&out.display().to_string()),
        "{}",
        h.state().status()
    );
    for f in [
        "sr.svg",
        "sr.png",
        "errors.svg",
        "errors.png",
        "convergence.svg",
        "convergence.png",
    ] {
        let p = out.join(f);
        assert!(
            p.is_file() && std::fs::metadata(&p).unwrap().len() > 1000,
            "{f}"
        );
    }
    let svg = std::fs::read_to_string(out.join("sr.svg")).unwrap();
    assert!(
        svg.contains("success rate") && svg.contains("esm_ssd_homography"),
        "sr.svg"
    );
    // Each tracker in the window's colour, in every figure.
    for t in &h.state().state.trackers {
        let [r, g, b] = t.color;
        let hex = format!("#{r:02X}{g:02X}{b:02X}");
        for f in ["sr.svg", "errors.svg", "convergence.svg"] {
            let svg = std::fs::read_to_string(out.join(f)).unwrap();
            assert!(svg.to_uppercase().contains(&hex), "{f} lacks {hex}");
        }
    }
    // Another sequence: the old frame's frequency of convergence is not shown on it.
    let other = small_sequence(&d.path().join("other"), 4);
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(other)));
    step_until(&mut h, "the other sequence", |a| a.frame_count() == 4);
    h.run_steps(2);
    assert!(h.state().frequency().is_none());
    assert!(h.query_by_label_contains("starts per σ").is_none());
}

/// The annotator's timeline: a proposal accepted on a selected range only (the rest stays
/// proposed), and the corrections of a range deleted in one undoable edit.
/// A journal that cannot be used (here: another sequence's) is left as it is and said, and
/// every correction is refused with the reason until it is fixed: a correction kept in memory
/// only would be lost at the next close or open.
#[test]
fn corrections_are_refused_while_the_journal_cannot_be_used() {
    use regtrack::app::command::GtCommand;
    let d = TempDir::new("gui-unusable-journal");
    let path = small_sequence(d.path(), 4);
    let journal = regtrack::gt::journal_path(&regtrack::dataset::Sequence::open(&path).unwrap());
    let other = "{\"kind\":\"header\",\"format\":1,\"sequence\":\"another\"}\n";
    std::fs::write(&journal, other).unwrap();
    let mut h = editing_ground_truth(&path);
    let gt = h.state().ground_truth(0).unwrap();
    h.state_mut().send(Command::Gt(GtCommand::Commit {
        frame: 0,
        quad: gt.map(|p| Point::new(p.x + 6.0, p.y)),
        label: "move".into(),
    }));
    h.step();
    h.step();
    let shown = h.state().errors_shown().join("\n");
    assert!(
        shown.contains("journal of sequence 'another'")
            && shown.contains("no correction can be kept"),
        "{shown}"
    );
    assert!(shown.contains("the correction was not made"), "{shown}");
    assert!(h.state().corrections().mark("homography", 0).is_none());
    assert_eq!(
        std::fs::read_to_string(&journal).unwrap(),
        other,
        "left as it was"
    );
}

/// A proposal whose acceptance cannot be journaled (here: another inspector writes to the same
/// journal, then wrote to it) is not lost: it stays, with the reason shown, and is accepted once
/// the sequence is reopened.
#[test]
fn a_proposal_that_cannot_be_journaled_stays() {
    use regtrack::app::command::GtCommand;
    use regtrack::gt::{Corrections, Mark};
    let d = TempDir::new("gui-unjournaled");
    let path = small_sequence(d.path(), 8);
    let journal = regtrack::gt::journal_path(&regtrack::dataset::Sequence::open(&path).unwrap());
    let mut h = editing_ground_truth(&path);
    // Another inspector's writer, editing after this one read the journal: it holds it.
    let (mut other, _) = Corrections::open(&journal, "rt", 8).unwrap();
    let q = regtrack::geometry::Quad::from_rect(10.0, 10.0, 50.0, 40.0);
    other
        .edit(
            "other",
            &[("homography".into(), 7, Some(Mark::Quad(q.to_array())))],
        )
        .unwrap();
    // Over a chosen range: proposed even where the old ground truth agrees.
    h.state_mut()
        .send(Command::Gt(GtCommand::Select(Some((0, 6)))));
    h.step();
    h.state_mut()
        .send(Command::Gt(GtCommand::PropagateSelection));
    step_until(&mut h, "the proposal", |a| a.gt_proposal().is_some());
    let proposed = h.state().gt_proposal().unwrap().frames.len();
    for (why, other_open) in [("another regtrack is writing", true), ("since", false)] {
        if !other_open {
            other = Corrections::in_memory(8);
        }
        h.state_mut().send(Command::Gt(GtCommand::AcceptProposal));
        h.step();
        h.step();
        let shown = h.state().errors_shown().join("\n");
        assert!(shown.contains(why), "{shown}");
        assert_eq!(
            h.state().gt_proposal().map(|p| p.frames.len()),
            Some(proposed),
            "the proposal stays"
        );
        assert!(h.state().corrections().mark("homography", 1).is_none());
    }
    drop(other);
}

#[test]
fn the_timeline_selection_accepts_a_proposal_in_part_and_deletes_corrections() {
    use regtrack::app::command::GtCommand;
    use regtrack::gt::Mark;
    let d = TempDir::new("gui-timeline");
    let seq = small_sequence(d.path(), 8);
    let mut h = editing_ground_truth(&seq);
    // Frame 1 corrected 6 px to the right: the proposal carries the offset on.
    let gt = h.state().ground_truth(0).unwrap();
    let moved = gt.map(|p| Point::new(p.x + 6.0, p.y));
    h.state_mut().send(Command::Gt(GtCommand::Commit {
        frame: 0,
        quad: moved,
        label: "move".into(),
    }));
    h.step();
    h.get_by_label("Propagate").scroll_to_me();
    h.run_steps(10);
    h.get_by_label("Propagate").click();
    step_until(&mut h, "the proposal", |a| a.gt_proposal().is_some());
    let proposed: Vec<usize> = h
        .state()
        .gt_proposal()
        .unwrap()
        .frames
        .iter()
        .map(|f| f.0)
        .collect();
    assert!(proposed.len() >= 4, "{proposed:?}");
    h.state_mut()
        .send(Command::Gt(GtCommand::Select(Some((3, 2)))));
    h.step();
    assert_eq!(h.state().gt_selection(), Some((2, 3)));
    h.run_steps(3);
    h.get_by_label("Accept the proposal here").click();
    h.step();
    h.step();
    let key = "homography";
    let marked = |h: &Harness<'static, InspectorApp>, f: usize| {
        matches!(h.state().corrections().mark(key, f), Some(Mark::Quad(_)))
    };
    assert!(marked(&h, 2) && marked(&h, 3));
    assert!(
        !marked(&h, 1) && !marked(&h, 4),
        "outside the selection: still proposed"
    );
    let rest: Vec<usize> = h
        .state()
        .gt_proposal()
        .unwrap()
        .frames
        .iter()
        .map(|f| f.0)
        .collect();
    assert!(rest.contains(&1) && !rest.contains(&2), "{rest:?}");
    // Delete the corrections of frames 1-3 (frame 1 is the first correction).
    h.state_mut()
        .send(Command::Gt(GtCommand::Select(Some((0, 2)))));
    h.step();
    h.get_by_label("Delete corrections here").click();
    h.step();
    h.step();
    assert!(!marked(&h, 0) && !marked(&h, 2) && marked(&h, 3));
    // One undo brings both back.
    press(&mut h, egui::Key::Z, egui::Modifiers::COMMAND);
    assert!(marked(&h, 0) && marked(&h, 2));

    // Interpolate over frames 4-8: the ends are the keys (frame 4 corrected, frame 8 the
    // original), frames 5-7 lie between them, one undoable edit.
    h.state_mut().send(Command::Gt(GtCommand::RejectProposal));
    h.state_mut()
        .send(Command::Gt(GtCommand::Select(Some((3, 7)))));
    h.run_steps(4);
    let (q3, q7) = (
        h.state().ground_truth(3).unwrap(),
        h.state().ground_truth(7).unwrap(),
    );
    h.get_by_label("Interpolate here").click();
    h.run_steps(2);
    for f in 4..7 {
        assert!(marked(&h, f), "frame {} interpolated", f + 1);
        let c = h.state().ground_truth(f).unwrap().centroid();
        let (a, b) = (q3.centroid(), q7.centroid());
        let t = (f - 3) as f64 / 4.0;
        let expect = Point::new(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y));
        assert!(
            (c.x - expect.x).hypot(c.y - expect.y) < 1.0,
            "frame {}: centre {c:?}, between the keys {expect:?}",
            f + 1
        );
    }
    assert!(!marked(&h, 7), "the end key stays as it was");
    press(&mut h, egui::Key::Z, egui::Modifiers::COMMAND);
    assert!(!marked(&h, 4) && !marked(&h, 6));

    // Propagate over frames 4-6: a proposal for frames 5 and 6 and no further, although the old
    // ground truth agrees with the tracker there (which stops a propagation on its own).
    h.state_mut()
        .send(Command::Gt(GtCommand::Select(Some((3, 5)))));
    h.run_steps(4);
    h.get_by_label("Propagate here").click();
    h.step();
    step_until(&mut h, "the proposal over the selection", |a| {
        a.gt_proposal().is_some()
    });
    let proposed: Vec<usize> = h
        .state()
        .gt_proposal()
        .unwrap()
        .frames
        .iter()
        .map(|f| f.0)
        .collect();
    assert_eq!(proposed, vec![4, 5]);
}

/// The recent list outlives the window (the preferences file), and a save over another existing
/// session asks first; the session's own file is saved again without a question.
#[test]
fn the_recent_list_survives_a_restart_and_saving_over_another_file_asks() {
    let d = TempDir::new("gui-prefs");
    let seq = small_sequence(d.path(), 3);
    let prefs = d.path().join("config/inspector.toml");
    let mut h = harness(State::default());
    h.state_mut().use_prefs(prefs.clone());
    h.state_mut()
        .send(Command::OpenSequence(SequenceSource::Path(seq.clone())));
    // (The default session's demo opens first: wait for this sequence, not any.)
    step_until(&mut h, "the sequence", |a| {
        a.state.sequence == SequenceSource::Path(seq.clone()) && a.tracked_until() == Some(0)
    });
    assert_eq!(h.state().recent(), std::slice::from_ref(&seq));
    drop(h);
    // The next run starts with it, in the top bar.
    let mut h = harness(State::default());
    h.state_mut().use_prefs(prefs.clone());
    assert_eq!(h.state().recent(), std::slice::from_ref(&seq));
    h.run_steps(2);
    assert!(h.query_by_label("Recent").is_some(), "the recent menu");
    h.get_by_label("Recent").click();
    h.run_steps(2);
    h.get_by_label(&seq.display().to_string()).click();
    h.step();
    step_until(&mut h, "the recent sequence", |a| {
        a.state.sequence == SequenceSource::Path(seq.clone()) && a.tracked_until() == Some(0)
    });

    // Saving over a file that is not this session's: a question; Esc keeps the file.
    let own = d.path().join("own.toml");
    let other = d.path().join("other.toml");
    std::fs::write(&other, "# someone else's\n").unwrap();
    h.state_mut().set_session_path(&own);
    h.state_mut().send(Command::SaveSession(own.clone()));
    h.step();
    assert!(own.is_file() && h.state().overwrite_pending().is_none());
    h.state_mut().send(Command::SaveSession(other.clone()));
    h.run_steps(2);
    assert_eq!(h.state().overwrite_pending(), Some(other.as_path()));
    assert!(
        h.query_by_label("Overwrite").is_some(),
        "the question is shown"
    );
    press(&mut h, egui::Key::Escape, egui::Modifiers::NONE);
    h.step();
    assert!(h.state().overwrite_pending().is_none());
    assert_eq!(
        std::fs::read_to_string(&other).unwrap(),
        "# someone else's\n"
    );
    // Ctrl+S asks again; Overwrite writes it, and it is the session's file from then on.
    h.state_mut()
        .send(Command::SetSessionPath(other.display().to_string()));
    h.step();
    press(&mut h, egui::Key::S, egui::Modifiers::COMMAND);
    h.run_steps(2);
    assert_eq!(h.state().overwrite_pending(), Some(other.as_path()));
    h.get_by_label("Overwrite").click();
    h.run_steps(2);
    assert!(h.state().overwrite_pending().is_none());
    assert!(State::load(&other).is_ok(), "a session now");
    assert!(
        h.state().status().contains("replaced"),
        "{}",
        h.state().status()
    );
    h.state_mut().send(Command::SaveSession(other.clone()));
    h.step();
    assert!(h.state().overwrite_pending().is_none(), "its own file now");
    // The plots panel dragged wider (here: its share kept as a drag keeps it).
    h.state_mut()
        .send(Command::KeepPanelShare("plots".into(), 0.45));
    h.step();
    drop(h);

    // The next run: the sessions saved are offered in the Sessions menu, and the plots panel
    // has the width it was given.
    let mut h = harness(State::default());
    h.state_mut().use_prefs(prefs.clone());
    h.run_steps(3);
    let choices = h.state().session_choices();
    assert_eq!(&choices[..2], &[other.clone(), own.clone()], "{choices:?}");
    h.get_by_label("Sessions").click();
    h.run_steps(2);
    h.get_by_label(&own.display().to_string()).click();
    h.run_steps(2);
    assert_eq!(h.state().session_file(), Some(own.as_path()));
    let left = h.get_by_label("Success rate").rect().left();
    assert!(
        (left - 1400.0 * 0.55).abs() < 20.0,
        "the plots panel starts at {left}"
    );
}

/// Panels keep their share of the window: squeezed by a small window, they grow back with it.
#[test]
fn side_panels_grow_back_when_the_window_does() {
    let d = TempDir::new("gui-share");
    let seq = small_sequence(d.path(), 3);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the frame", |a| {
        a.tracked_until() == Some(0) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
    });
    h.run_steps(3);
    let before = frame_width(&h);
    h.set_size(egui::Vec2::new(1000.0, 700.0));
    h.run_steps(4);
    h.set_size(egui::Vec2::new(1400.0, 900.0));
    h.run_steps(4);
    let after = frame_width(&h);
    assert!(
        (after - before).abs() < 0.05 * before,
        "the frame was {before} px wide, {after} px after the window shrank and grew"
    );
}

/// Patches tracked from the shown frame are drawn on every frame they reached, with the count
/// of those still tracking in the sidebar; Clear removes them.
#[test]
fn patches_are_tracked_from_the_shown_frame_and_drawn() {
    let d = TempDir::new("gui-patches");
    let seq = small_sequence(d.path(), 6);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the first frame", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Seek(1));
    h.step();
    step_until(&mut h, "frame 2", |a| a.state.frame == 1);
    let mut settings = h.state().state.patches.clone();
    settings.count = 40;
    settings.params.set("warp", 1.0);
    h.state_mut().send(Command::SetPatchSettings(settings));
    h.state_mut().send(Command::TrackPatches);
    h.step();
    step_until(&mut h, "the patches", |a| {
        a.patches().is_some_and(|p| p.result.is_some())
    });
    let app = h.state();
    assert!(app.patches_on(0).is_none(), "they start on the shown frame");
    let n = app.patches_on(1).expect("patches on frame 2").0.len();
    assert!(n >= 20, "{n}");
    let (last, half) = app.patches_on(5).expect("patches on the last frame");
    assert_eq!(half, 7.0);
    let on = last.iter().filter(|s| s.tracking()).count();
    assert!(on as f64 > 0.8 * n as f64, "{on} of {n}");
    h.state_mut().send(Command::Seek(5));
    h.run_steps(3);
    h.get_by_label("Patches").click_accesskit();
    h.run_steps(3);
    let label = format!("{on} of {n} tracking on this frame");
    assert!(h.query_by_label(&label).is_some(), "{label}");
    h.state_mut().send(Command::ClearPatches);
    h.step();
    assert!(h.state().patches().is_none());
}

/// Where a new user got stuck (issue 45): Play on a frame past the tracked ones starts there
/// (not on frame 1); zoomed in, the ground-truth mode follows the target from frame to frame;
/// a sequence corrected in similitude reopens in similitude.
#[test]
fn play_starts_on_the_shown_frame_the_view_follows_and_corrections_reopen_in_their_mode() {
    let d = TempDir::new("gui-newuser");
    let seq = small_sequence(d.path(), 12);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence", |a| a.tracked_until() == Some(0));
    h.state_mut().send(Command::Seek(6));
    h.run_steps(2);
    h.state_mut().send(Command::Play);
    step_until(&mut h, "the end", |a| {
        a.tracked_until() == Some(11) && !a.is_playing()
    });
    assert_eq!(h.state().state.start_frame, 6);
    assert!(h.state().result(0, 3).is_none(), "tracked from frame 1");
    assert!(h.state().result(0, 7).is_some());

    // The per-frame plots of speed and iterations, under the speed table.
    h.get_by_label("Speed and iterations per frame")
        .scroll_to_me();
    h.run_steps(10);
    h.get_by_label("Speed and iterations per frame").click();
    h.run_steps(3);
    assert!(h.query_by_label("no frame tracked yet").is_none());
    assert_eq!(h.state().per_frame_speed(0).len(), 5, "frames 8..12");
    // F4: the presentation scale, and back.
    press(&mut h, egui::Key::F4, egui::Modifiers::NONE);
    assert_eq!(h.state().state.view.label_scale, 2.0);
    press(&mut h, egui::Key::F4, egui::Modifiers::NONE);
    assert_eq!(h.state().state.view.label_scale, 1.0);

    // Zoomed in far from the target, in the ground-truth mode: the next frame is centred on it.
    h.get_by_label("Edit ground-truth corners").click();
    h.state_mut().send(Command::Seek(6));
    h.run_steps(3);
    let mut view = h.state().state.view.clone();
    assert!(view.follow_in_gt_mode, "on by default");
    view.zoom = 6.0;
    view.center = [1.0, 1.0];
    h.state_mut().send(Command::SetView(view));
    h.run_steps(2);
    press(&mut h, egui::Key::ArrowRight, egui::Modifiers::NONE);
    step_until(&mut h, "the next frame", |a| a.state.frame == 7);
    h.run_steps(3);
    let c = h.state().ground_truth(7).unwrap().centroid();
    let at = h.state().state.view.center;
    assert!(
        (at[0] as f64 - c.x).abs() < 1.0 && (at[1] as f64 - c.y).abs() < 1.0,
        "{at:?} vs {c:?}"
    );

    // A correction in similitude; reopened with the homography shown, it shows in similitude.
    h.state_mut().send(Command::SetGtSsm("similitude".into()));
    h.run_steps(2);
    press(&mut h, egui::Key::ArrowRight, egui::Modifiers::SHIFT);
    assert_eq!(
        h.state().corrections().corrected_frames("similitude"),
        vec![7]
    );
    drop(h);
    let mut h = harness(state_on(&seq));
    step_until(&mut h, "the sequence again", |a| {
        a.tracked_until() == Some(0)
    });
    assert_eq!(h.state().state.gt_ssm, "similitude");
    assert!(
        h.state().status().contains("similitude"),
        "{}",
        h.state().status()
    );
}

/// The first screen at the window's default size (1280x800) and at 1000x700, tracked a few
/// frames, an iteration selected: no widget reaches past the window's edge or from the plots
/// panel into the frame, and no two labels of the top bar, the bottom bar or the plots panel
/// overlap (at 1280x800 the plots panel cut its plots and squeezed a column of images to 10
/// px, its label one letter a line).
#[test]
fn at_the_default_size_and_at_1000x700_nothing_is_cut_and_no_labels_overlap() {
    use egui::accesskit::Role;
    use egui_kittest::kittest::NodeT;
    let d = TempDir::new("gui-layout");
    let seq = small_sequence(d.path(), 8);
    for (w, h_px) in [(1280.0f32, 800.0f32), (1000.0, 700.0)] {
        let app = InspectorApp::new(state_on(&seq), wake);
        let mut h = Harness::builder()
            .with_size(egui::Vec2::new(w, h_px))
            .with_max_steps(10_000)
            .build_ui_state(|ui, app: &mut InspectorApp| app.ui(ui), app);
        step_until(&mut h, "the frame", |a| {
            a.tracked_until() == Some(0) && a.screen_pos(Point::new(0.0, 0.0)).is_some()
        });
        h.state_mut().send(Command::Play);
        step_until(&mut h, "the end", |a| {
            a.tracked_until() == Some(7) && !a.is_playing()
        });
        h.state_mut().send(Command::Seek(4));
        h.state_mut().send(Command::SelectIteration(Some(1)));
        h.run_steps(4);
        let panel = |name: &str| regtrack::app::panel_rect(&h.ctx, name).expect(name);
        let (trackers, plots) = (panel("trackers"), panel("plots"));
        let plots_left = plots.left();
        let trackers_right = trackers.right();
        let mut shown = Vec::new();
        for role in [
            Role::Label,
            Role::Button,
            Role::CheckBox,
            Role::TextInput,
            Role::Slider,
            Role::ComboBox,
            Role::SpinButton,
        ] {
            for n in h.query_all_by_role(role) {
                let r = n.rect();
                // Scrolled out of view (reachable by scrolling): not on the screen.
                if r.bottom() <= 0.0 || r.top() >= h_px || r.width() <= 0.0 {
                    continue;
                }
                let name = n.accesskit_node().label().unwrap_or_default();
                shown.push((name, role, r));
            }
        }
        assert!(shown.len() > 40, "{} widgets", shown.len());
        for (name, role, r) in &shown {
            assert!(
                r.left() >= -1.0 && r.right() <= w + 1.0,
                "{w}x{h_px}: {role:?} {name:?} at {r:?} is cut by the window"
            );
            if r.center().x > plots_left {
                assert!(
                    r.left() >= plots_left - 1.0,
                    "{w}x{h_px}: {role:?} {name:?} at {r:?} reaches out of the plots panel"
                );
            }
            // The trackers panel, below the top bar and above the playback bar.
            if r.center().x < trackers_right
                && r.top() > trackers.top()
                && r.bottom() < trackers.bottom()
            {
                assert!(
                    r.right() <= trackers_right + 1.0,
                    "{w}x{h_px}: {role:?} {name:?} at {r:?} reaches out of the trackers panel \
                     (its right edge at {trackers_right})"
                );
            }
        }
        // The convergence view's three images share the panel's width: none squeezed.
        let panel = plots.width();
        h.get_by_label_contains("|error|").scroll_to_me();
        h.run_steps(3);
        let left = |label: &str| h.get_by_label_contains(label).rect().left();
        let cols = [left("template"), left("warped patch"), left("|error|")];
        for k in 0..2 {
            let col = cols[k + 1] - cols[k];
            assert!(
                col >= 0.25 * panel,
                "{w}x{h_px}: a column of the images is {col} px of a {panel} px panel"
            );
        }
        assert!(
            cols[2] + 0.2 * panel <= w,
            "{w}x{h_px}: the third column at {}",
            cols[2]
        );
        // Labels of the bars and of the plots panel.
        let labels: Vec<_> = shown
            .iter()
            .filter(|(name, role, r)| {
                *role == Role::Label
                    && !name.is_empty()
                    && (r.left() >= plots_left || r.top() < 60.0 || r.bottom() > h_px - 40.0)
            })
            .collect();
        for (i, a) in labels.iter().enumerate() {
            for b in &labels[i + 1..] {
                let overlap = a.2.intersect(b.2);
                assert!(
                    overlap.width() <= 1.0 || overlap.height() <= 1.0,
                    "{w}x{h_px}: {:?} at {:?} overlaps {:?} at {:?}",
                    a.0,
                    a.2,
                    b.0,
                    b.2
                );
            }
        }
    }
}
