//! The inspector's keyboard shortcuts: one table, which the window's help overlay (F1) and
//! `regtrack inspect --help` both list. Plain data, so that the command line has it without the
//! GUI feature.

/// The keyboard shortcuts: keys, what they do.
pub const SHORTCUTS: &[(&str, &str)] = &[
    ("Space", "play / pause"),
    (
        "Right / Left",
        "next frame (tracks it if needed) / previous frame, in every mode",
    ),
    (
        "Page Down / Up",
        "next / previous frame (shown, not tracked)",
    ),
    ("Home / End", "start frame / last tracked frame"),
    (
        "P",
        "perturb: every tracker from the ground truth moved by the experiment's noise",
    ),
    (". / ,", "next / previous iteration (the convergence view)"),
    ("Esc", "clear the experiment, close this help"),
    ("Ctrl+O", "open a sequence (file dialog)"),
    ("Ctrl+S", "save the session to the session field's path"),
    ("F1 or ?", "this help"),
    ("F2 / F3", "hide or show the trackers / plots panel"),
    (
        "F4",
        "presentation scale: the frame's labels and quads, the plots' text and lines x2, and back",
    ),
    (
        "Ctrl+Z / Ctrl+Shift+Z",
        "undo / redo a ground-truth correction",
    ),
    ("ground-truth mode: 1-4, 0", "pick a corner, the whole quad"),
    (
        "ground-truth mode: Shift+arrows, + / -",
        "nudge by the step, double / halve the step",
    ),
    (
        "ground-truth mode: J, O",
        "jump to the worst frame, mark occluded",
    ),
    (
        "ground-truth mode: Enter / Esc",
        "accept / reject a proposal",
    ),
];

/// The shortcuts as the command line's help shows them, one per line.
pub fn help_text() -> String {
    let width = SHORTCUTS.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
    let mut out = String::from("Keyboard (F1 or ? in the window shows this too):");
    for (k, what) in SHORTCUTS {
        out.push_str(&format!("\n  {k:<width$}  {what}"));
    }
    out
}
