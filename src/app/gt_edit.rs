//! The ground-truth mode: corrections kept by [`crate::gt::Corrections`] (journaled, undoable),
//! edits constrained to the shown SSM, keyboard nudging, propagation with a tracker,
//! interpolation, occluded frames and export.

use super::Versioned;
use super::command::{Command, GtCommand};
use super::worker::{Job, PropagateJob};
use super::{InspectorApp, Tool};
use crate::dataset::Sequence;
use crate::geometry::{Point, Quad};
use crate::gt::{self, Corrections, GtFrame, Mark, Proposal};
use crate::imaging::GrayF32;
use crate::ssm;
use eframe::egui;
use std::sync::Arc;

/// The ground truth of every frame in the shown SSM, with the fit residuals.
pub(super) struct GtTable {
    pub key: (u64, String),
    pub frames: Vec<GtFrame>,
    pub residuals: Vec<Option<f64>>,
}

/// Runtime state of the ground-truth mode (never saved: the corrections live in the journal).
pub struct GtRuntime {
    /// Every change bumps its version (the ground-truth table and the errors follow it).
    pub(super) corrections: Versioned<Corrections>,
    pub(super) table: std::cell::RefCell<Option<Arc<GtTable>>>,
    /// The corner the keyboard moves (`None`: the whole quad).
    pub(super) corner: Option<usize>,
    /// Nudge step (px).
    pub(super) step: f64,
    /// A drag in progress: the frame and the quad as dragged (not yet an edit).
    pub(super) drag: Option<(usize, Quad)>,
    /// A propagation's proposal awaiting accept / reject.
    pub(super) proposal: Option<(String, Proposal)>,
    /// A propagation is running on the worker.
    pub(super) running: bool,
    /// The timeline's selected frames (inclusive range).
    pub(super) selection: Option<(usize, usize)>,
    /// The first annotated frame's image (the template side of the patch view) and the shown
    /// frame's image.
    pub(super) template_image: Option<(usize, GrayF32)>,
    pub(super) frame_image: Option<(usize, GrayF32)>,
}

impl Default for GtRuntime {
    fn default() -> Self {
        GtRuntime {
            corrections: Versioned::new(Corrections::in_memory(0)),
            table: Default::default(),
            corner: Some(0),
            step: 1.0,
            drag: None,
            proposal: None,
            running: false,
            selection: None,
            template_image: None,
            frame_image: None,
        }
    }
}

/// Side of the template / current patches (px).
pub const PATCH: usize = 96;

/// The template and the shown frame's region, rectified, as an image of `PATCH x PATCH`.
pub(super) fn rectified(img: &GrayF32, q: &Quad) -> Option<egui::ColorImage> {
    let v = gt::rectify(img, q, PATCH)?;
    Some(egui::ColorImage::new(
        [PATCH, PATCH],
        v.into_iter().map(egui::Color32::from_gray).collect(),
    ))
}

impl InspectorApp {
    /// The ground truth of every frame in the shown SSM (cached per corrections version).
    pub(super) fn gt_table(&self) -> Option<Arc<GtTable>> {
        let seq = self.rt.seq.sequence.as_ref()?;
        let key = (self.rt.gt.corrections.version(), self.state.gt_ssm.clone());
        if let Some(t) = self.rt.gt.table.borrow().as_ref().filter(|t| t.key == key) {
            return Some(t.clone());
        }
        let (frames, residuals) =
            gt::ground_truth_in(seq, &self.rt.gt.corrections, &self.state.gt_ssm).ok()?;
        let t = Arc::new(GtTable {
            key,
            frames,
            residuals,
        });
        *self.rt.gt.table.borrow_mut() = Some(t.clone());
        Some(t)
    }

    /// The ground-truth state of a frame as shown (in the chosen SSM, with corrections).
    pub fn gt_frame(&self, frame: usize) -> Option<GtFrame> {
        self.gt_table()?.frames.get(frame).copied()
    }

    /// The fit residual of a frame in the shown SSM (px).
    pub fn gt_residual(&self, frame: usize) -> Option<f64> {
        self.gt_table()?.residuals.get(frame).copied().flatten()
    }

    /// The corrections (journaled).
    pub fn corrections(&self) -> &Corrections {
        &self.rt.gt.corrections
    }

    /// The corner the keyboard moves (`None`: the whole quad) and the nudge step.
    pub fn gt_cursor(&self) -> (Option<usize>, f64) {
        (self.rt.gt.corner, self.rt.gt.step)
    }

    /// The pending proposal of a propagation: its frames and why it stopped.
    pub fn gt_proposal(&self) -> Option<&Proposal> {
        self.rt.gt.proposal.as_ref().map(|p| &p.1)
    }

    /// The timeline's selected frames (inclusive).
    pub fn gt_selection(&self) -> Option<(usize, usize)> {
        self.rt.gt.selection
    }

    /// Whether a propagation is running.
    pub fn gt_propagating(&self) -> bool {
        self.rt.gt.running
    }

    /// Opens the corrections journal of a newly opened sequence (replaying it).
    pub(super) fn open_corrections(&mut self, seq: &Sequence) {
        let path = gt::journal_path(seq);
        self.rt.gt.proposal = None;
        self.rt.gt.selection = None;
        self.rt.gt.drag = None;
        self.rt.gt.template_image = None;
        self.rt.gt.frame_image = None;
        match Corrections::open(&path, &seq.name, seq.len()) {
            Ok((c, rec)) => {
                if rec.edits > 0 || rec.damaged() {
                    let mut per_ssm: std::collections::BTreeMap<&str, usize> = Default::default();
                    for s in ssm::REGISTRY.iter().map(|e| e.name) {
                        let n = c.corrected_frames(s).len();
                        if n > 0 {
                            per_ssm.insert(s, n);
                        }
                    }
                    let per: Vec<String> =
                        per_ssm.iter().map(|(s, n)| format!("{s}: {n}")).collect();
                    // Shown in the mode the corrections were made in (reopened in the
                    // homography mode, similitude corrections were invisible until the
                    // dropdown changed): the SSM with the most, when the shown one has none.
                    let shown = self.gt_key();
                    let mut switched = String::new();
                    if c.corrected_frames(&shown).is_empty()
                        && let Some((s, _)) = per_ssm.iter().max_by_key(|(_, n)| **n)
                    {
                        self.state.gt_ssm = (*s).to_string();
                        switched = format!("; shown in {s}, the SSM they were made in");
                    }
                    self.rt.msg.status = format!(
                        "{}: {} frames; restored {} correction(s) ({}) from {}{}{switched}",
                        seq.name,
                        seq.len(),
                        rec.corrected,
                        per.join(", "),
                        path.display(),
                        if rec.truncated_tail {
                            " (its last line, cut by a crash, was dropped)"
                        } else {
                            ""
                        }
                    );
                    if !rec.skipped.is_empty() {
                        let shown: Vec<&str> =
                            rec.skipped.iter().take(3).map(String::as_str).collect();
                        self.error(format!(
                            "the corrections journal is damaged: {} part(s) skipped, every \
                             intact record restored ({}{})",
                            rec.skipped.len(),
                            shown.join("; "),
                            if rec.skipped.len() > 3 { "; ..." } else { "" }
                        ));
                    }
                }
                *self.rt.gt.corrections.edit() = c;
            }
            Err(e) => {
                // Edits that could not be journaled would be lost at the next close or open:
                // none are taken until the journal can be used.
                let why = format!(
                    "the corrections journal cannot be used ({e}); no correction can be kept \
                     until it is fixed or moved away and the sequence reopened"
                );
                self.error(why.clone());
                *self.rt.gt.corrections.edit() = Corrections::refusing(seq.len(), why);
            }
        }
        // The template side of the patch view.
        if let Some(first) = (0..seq.len()).find(|&i| seq.ground_truth(i).is_some())
            && let Ok(img) = seq.load_gray(first)
        {
            self.rt.gt.template_image = Some((first, img.to_f32()));
        }
    }

    fn gt_key(&self) -> String {
        gt::ssm_key(&self.state.gt_ssm).unwrap_or_else(|_| "homography".into())
    }

    /// One journaled, undoable edit; errors are shown once.
    /// Returns whether it was made (or changed nothing); `false`: it could not be journaled
    /// (a full disk, a read-only folder, another writer), and took no effect.
    fn gt_edit(&mut self, label: &str, changes: Vec<(usize, Option<Mark>)>) -> bool {
        let key = self.gt_key();
        let changes: Vec<(String, usize, Option<Mark>)> = changes
            .into_iter()
            .map(|(f, m)| (key.clone(), f, m))
            .collect();
        match self.rt.gt.corrections.edit().edit(label, &changes) {
            Ok(true) => {
                self.rt.msg.status = format!("{label} (Ctrl+Z undoes)");
                true
            }
            Ok(false) => true,
            Err(e) => {
                self.error(format!("the correction was not made: {e}"));
                false
            }
        }
    }

    /// A quad brought into the shown SSM: its best fit from the first annotated frame's quad.
    fn fit_to_ssm(&self, q: &Quad) -> Quad {
        let Ok(m) = ssm::build(&self.state.gt_ssm) else {
            return *q;
        };
        if m.dof() == 8 {
            return *q;
        }
        let base = self
            .gt_table()
            .and_then(|t| t.frames.iter().find_map(|f| f.quad()));
        match base.and_then(|b| gt::best_fit(&*m, &b, q)) {
            Some((_, fit, _)) => fit,
            None => *q,
        }
    }

    /// Handles the ground-truth commands.
    pub(super) fn apply_gt(&mut self, cmd: GtCommand) {
        let frame = self.state.frame;
        match cmd {
            GtCommand::Drag { frame, quad } => self.rt.gt.drag = Some((frame, quad)),
            GtCommand::Commit { frame, quad, label } => {
                self.rt.gt.drag = None;
                let fixed = self.fit_to_ssm(&quad);
                self.gt_edit(
                    &format!("{label} on frame {}", frame + 1),
                    vec![(frame, Some(Mark::Quad(fixed.to_array())))],
                );
            }
            GtCommand::PickCorner(c) => self.rt.gt.corner = c.map(|k| k.min(3)),
            GtCommand::Step(s) => self.rt.gt.step = s.clamp(0.1, 64.0),
            GtCommand::Nudge { dx, dy } => self.nudge(frame, dx, dy),
            GtCommand::ToggleOccluded => self.toggle_occluded(frame),
            GtCommand::Revert => {
                self.gt_edit(
                    &format!("revert frame {} to the original", frame + 1),
                    vec![(frame, None)],
                );
            }
            GtCommand::Undo => self.step_history(true),
            GtCommand::Redo => self.step_history(false),
            GtCommand::Export => self.export_gt(),
            GtCommand::JumpWorst => match self.worst_frame() {
                Some(f) => self.apply(Command::Seek(f)),
                None => {
                    self.rt.msg.status = "no uncorrected frame with a residual or a tracker".into()
                }
            },
            GtCommand::Interpolate => self.interpolate(),
            GtCommand::Propagate => {
                self.propagate(self.state.frame, crate::gt::PropagateLimits::default())
            }
            GtCommand::InterpolateSelection => self.interpolate_selection(),
            GtCommand::PropagateSelection => self.propagate_selection(),
            GtCommand::AcceptProposal => {
                if let Some((label, p)) = self.rt.gt.proposal.take() {
                    let changes = p
                        .frames
                        .iter()
                        .map(|(f, q)| (*f, Some(Mark::Quad(self.fit_to_ssm(q).to_array()))))
                        .collect();
                    if !self.gt_edit(&label, changes) {
                        // Not made: the proposal stays, to be accepted once it can be.
                        self.rt.gt.proposal = Some((label, p));
                    }
                }
            }
            GtCommand::Select(sel) => {
                self.rt.gt.selection = sel.map(|(a, b)| (a.min(b), a.max(b)));
            }
            GtCommand::AcceptProposalInSelection => self.accept_proposal_in_selection(),
            GtCommand::RevertSelection => self.revert_selection(),
            GtCommand::RejectProposal => {
                self.rt.gt.proposal = None;
                self.rt.msg.status = "proposal rejected".into();
            }
        }
    }

    /// Moves the picked corner (or the whole quad) of `frame` by `(dx, dy)`.
    fn nudge(&mut self, frame: usize, dx: f64, dy: f64) {
        let Some(q) = self.ground_truth(frame) else {
            return;
        };
        let moved = match self.rt.gt.corner {
            Some(k) => gt::move_corner(
                &self.state.gt_ssm,
                &q,
                k,
                Point::new(q.0[k].x + dx, q.0[k].y + dy),
            ),
            None => q.map(|c| Point::new(c.x + dx, c.y + dy)),
        };
        let what = match self.rt.gt.corner {
            Some(k) => format!("nudge corner {}", k + 1),
            None => "nudge the quad".into(),
        };
        self.apply_gt(GtCommand::Commit {
            frame,
            quad: moved,
            label: what,
        });
    }

    /// Marks `frame` occluded, or unmarks it (back to the original corners).
    fn toggle_occluded(&mut self, frame: usize) {
        let occluded = self.gt_frame(frame) == Some(GtFrame::Occluded);
        let after = (!occluded).then_some(Mark::Occluded);
        let what = if occluded {
            "unmark occluded"
        } else {
            "mark occluded"
        };
        self.gt_edit(&format!("{what} frame {}", frame + 1), vec![(frame, after)]);
    }

    /// Writes the corrected ground truth beside the sequence's.
    fn export_gt(&mut self) {
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        match gt::export(&seq, self.rt.gt.corrections.edit(), &self.state.gt_ssm) {
            Ok(paths) => self.rt.msg.status = format!("exported: {}", super::list_paths(&paths)),
            Err(e) => self.error(format!("cannot export the ground truth: {e}")),
        }
    }

    /// The selection's inner frames from its ends' corners.
    fn interpolate_selection(&mut self) {
        let Some((a, b)) = self.rt.gt.selection else {
            return;
        };
        match (self.ground_truth(a), self.ground_truth(b)) {
            (Some(qa), Some(qb)) if b > a + 1 => self.interpolate_between((a, qa), (b, qb)),
            (Some(_), Some(_)) => {
                self.rt.msg.status =
                    "select at least three frames: the ends are the key frames".into()
            }
            _ => self.error(format!(
                "interpolation over frames {}-{} needs corners on both ends",
                a + 1,
                b + 1
            )),
        }
    }

    /// Propagates over the selection, and no further.
    fn propagate_selection(&mut self) {
        let Some((a, b)) = self.rt.gt.selection else {
            return;
        };
        if b == a {
            self.rt.msg.status = "select more than one frame to propagate over".into();
            return;
        }
        let limits = crate::gt::PropagateLimits {
            max_frames: b - a,
            // The user chose the range: frames where the old ground truth agrees are proposed
            // too (the jump and loss stops stay).
            agree_frames: 0,
            ..Default::default()
        };
        self.propagate(a, limits);
    }

    /// Accepts the proposal's frames inside the selection; the rest stays proposed.
    fn accept_proposal_in_selection(&mut self) {
        let Some((a, b)) = self.rt.gt.selection else {
            return;
        };
        let Some((label, whole)) = self.rt.gt.proposal.take() else {
            return;
        };
        let (inside, outside): (Vec<_>, Vec<_>) =
            whole.frames.iter().partition(|(f, _)| (a..=b).contains(f));
        let changes: Vec<(usize, Option<Mark>)> = inside
            .iter()
            .map(|(f, q)| (*f, Some(Mark::Quad(self.fit_to_ssm(q).to_array()))))
            .collect();
        let n = changes.len();
        let rest = gt::Proposal {
            frames: outside,
            stop: whole.stop.clone(),
        };
        if self.gt_edit(
            &format!("{label}, frames {}-{} ({n})", a + 1, b + 1),
            changes,
        ) {
            if !rest.frames.is_empty() {
                self.rt.gt.proposal = Some((label, rest));
            }
        } else {
            // Not made: the whole proposal stays, to be accepted once it can be.
            self.rt.gt.proposal = Some((label, whole));
        }
    }

    /// Deletes the corrections of the selected frames (one edit).
    fn revert_selection(&mut self) {
        let Some((a, b)) = self.rt.gt.selection else {
            return;
        };
        let key = self.gt_key();
        let changes: Vec<(usize, Option<Mark>)> = (a..=b)
            .filter(|&f| self.rt.gt.corrections.mark(&key, f).is_some())
            .map(|f| (f, None))
            .collect();
        if changes.is_empty() {
            self.rt.msg.status = "no correction in the selection".into();
        } else {
            self.gt_edit(
                &format!("delete the corrections of frames {}-{}", a + 1, b + 1),
                changes,
            );
        }
    }

    /// Undo or redo; the view goes to the frames the edit touched.
    fn step_history(&mut self, undo: bool) {
        let c = self.rt.gt.corrections.edit();
        let (r, did, what) = if undo {
            (c.undo(), "undid", "undo")
        } else {
            (c.redo(), "redid", "redo")
        };
        match r {
            Ok(Some((label, frames))) => {
                self.rt.msg.status = format!("{did}: {label}");
                if let Some(&f) = frames.first()
                    && !frames.contains(&self.state.frame)
                {
                    self.apply(Command::Seek(f));
                }
            }
            Ok(None) => self.rt.msg.status = format!("nothing to {what}"),
            Err(e) => self.error(format!("cannot {what}: {e}")),
        }
    }

    /// The uncorrected frame (other than the shown one) that most needs a look: the largest of
    /// its fit residual and the first tracker's error against it.
    fn worst_frame(&self) -> Option<usize> {
        let t = self.gt_table()?;
        let key = self.gt_key();
        let disagreement: std::collections::BTreeMap<usize, f64> =
            self.errors(0).into_iter().collect();
        (0..t.frames.len())
            .filter(|&f| f != self.state.frame && self.rt.gt.corrections.mark(&key, f).is_none())
            .filter_map(|f| {
                let r = t.residuals[f].unwrap_or(0.0);
                let d = disagreement
                    .get(&f)
                    .copied()
                    .filter(|d| d.is_finite())
                    .unwrap_or(0.0);
                let s = r.max(d);
                (s > 0.0).then_some((f, s))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(f, _)| f)
    }

    /// Interpolates between the corrected frames before and after the shown one (or, on a
    /// corrected frame, between it and the previous corrected frame).
    fn interpolate(&mut self) {
        let key = self.gt_key();
        let frame = self.state.frame;
        let marked = self.rt.gt.corrections.corrected_frames(&key);
        let quad_of = |f: usize| match self.rt.gt.corrections.mark(&key, f) {
            Some(Mark::Quad(v)) => Some(Quad::from_array(v)),
            _ => None,
        };
        let before = marked.iter().rev().find(|&&f| f < frame).copied();
        let after = if quad_of(frame).is_some() {
            Some(frame)
        } else {
            marked.iter().find(|&&f| f > frame).copied()
        };
        let (Some(a), Some(b)) = (before, after) else {
            self.error(
                "interpolation needs a corrected key frame before this frame and one at or after it"
                    .into(),
            );
            return;
        };
        let (Some(qa), Some(qb)) = (quad_of(a), quad_of(b)) else {
            self.error("the key frames are marked occluded: nothing to interpolate".into());
            return;
        };
        self.interpolate_between((a, qa), (b, qb));
    }

    /// Replaces the frames strictly between two key frames by the interpolation of their
    /// corners in the shown SSM's parameters (one undoable edit).
    fn interpolate_between(&mut self, (a, qa): (usize, Quad), (b, qb): (usize, Quad)) {
        match gt::interpolate(&self.state.gt_ssm, (a, qa), (b, qb)) {
            Ok(Some(v)) if !v.is_empty() => {
                let changes = v
                    .into_iter()
                    .map(|(f, q)| (f, Some(Mark::Quad(q.to_array()))))
                    .collect();
                self.gt_edit(&format!("interpolate frames {}-{}", a + 2, b), changes);
            }
            Ok(_) => {
                self.rt.msg.status = "the key frames are adjacent: nothing to interpolate".into()
            }
            Err(e) => self.error(e.to_string()),
        }
    }

    /// Starts a propagation from `frame` with the inspected tracker's methods on the shown
    /// SSM, on the worker, stopping where `limits` say.
    fn propagate(&mut self, frame: usize, limits: gt::PropagateLimits) {
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        let Some(start) = self.ground_truth(frame) else {
            self.error("propagation starts from a frame with corners".into());
            return;
        };
        let mut spec = self
            .state
            .trackers
            .get(self.state.selected_tracker)
            .map(|t| t.spec.clone())
            .unwrap_or_else(|| super::state::State::default().trackers[0].spec.clone());
        if let Some(r) = spec.registration_mut() {
            r.ssm = self.state.gt_ssm.clone();
        }
        let key = self.gt_key();
        let corrected: std::collections::BTreeSet<usize> = self
            .rt
            .gt
            .corrections
            .corrected_frames(&key)
            .into_iter()
            .collect();
        let old: Vec<Option<Quad>> = (0..seq.len()).map(|f| self.ground_truth(f)).collect();
        let label = format!("propagate from frame {} with {}", frame + 1, spec.label());
        self.rt.worker.send(Job::Propagate(Box::new(PropagateJob {
            label,
            sequence: seq,
            spec,
            from: (frame, start),
            old,
            corrected,
            limits,
        })));
        self.rt.gt.running = true;
        self.rt.gt.proposal = None;
        self.rt.msg.status = "propagating...".into();
    }

    /// A propagation's proposal, from the worker.
    pub(super) fn proposal_arrived(&mut self, label: String, result: crate::Result<Proposal>) {
        self.rt.gt.running = false;
        match result {
            Ok(p) if p.frames.is_empty() => {
                self.rt.msg.status = format!("nothing to propose: {}", p.stop);
            }
            Ok(p) => {
                self.rt.msg.status = format!(
                    "proposal for {} frame(s); {} — accept or reject it",
                    p.frames.len(),
                    p.stop
                );
                self.rt.gt.proposal = Some((label, p));
            }
            Err(e) => self.error(format!("the propagation failed: {e}")),
        }
    }

    /// The keyboard of the ground-truth mode (when no text field has the focus).
    pub(super) fn gt_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let editing = self.rt.ui.tool == Tool::EditGroundTruth;
        let mut cmds = Vec::new();
        ctx.input(|i| {
            if let Some(m) = super::shortcut(i, egui::Key::Z) {
                cmds.push(if m.shift {
                    Command::Gt(GtCommand::Redo)
                } else {
                    Command::Gt(GtCommand::Undo)
                });
            }
            if super::shortcut(i, egui::Key::Y).is_some() {
                cmds.push(Command::Gt(GtCommand::Redo));
            }
            if !editing || i.modifiers.command {
                return;
            }
            self.corner_keys(i, &mut cmds);
            if i.key_pressed(egui::Key::J) {
                cmds.push(Command::Gt(GtCommand::JumpWorst));
            }
            if i.key_pressed(egui::Key::O) {
                cmds.push(Command::Gt(GtCommand::ToggleOccluded));
            }
            if i.key_pressed(egui::Key::Enter) && self.rt.gt.proposal.is_some() {
                cmds.push(Command::Gt(GtCommand::AcceptProposal));
            }
            if i.key_pressed(egui::Key::Escape) && self.rt.gt.proposal.is_some() {
                cmds.push(Command::Gt(GtCommand::RejectProposal));
            }
        });
        for c in cmds {
            self.send(c);
        }
    }

    /// The keys that pick a corner, move it (or the quad) and change the step.
    fn corner_keys(&self, i: &egui::InputState, cmds: &mut Vec<Command>) {
        for (k, key) in [
            egui::Key::Num1,
            egui::Key::Num2,
            egui::Key::Num3,
            egui::Key::Num4,
        ]
        .into_iter()
        .enumerate()
        {
            if i.key_pressed(key) {
                cmds.push(Command::Gt(GtCommand::PickCorner(Some(k))));
            }
        }
        if i.key_pressed(egui::Key::Num0) || i.key_pressed(egui::Key::Q) {
            cmds.push(Command::Gt(GtCommand::PickCorner(None)));
        }
        let s = self.rt.gt.step;
        // Shift+arrows: the plain arrows change the frame, as in every mode (pressing Right to
        // go on made an edit).
        for (key, dx, dy) in [
            (egui::Key::ArrowLeft, -s, 0.0),
            (egui::Key::ArrowRight, s, 0.0),
            (egui::Key::ArrowUp, 0.0, -s),
            (egui::Key::ArrowDown, 0.0, s),
        ] {
            // Every press counts, also several within one frame of the window.
            let k = super::presses(i, key, true) as f64;
            if k > 0.0 {
                cmds.push(Command::Gt(GtCommand::Nudge {
                    dx: dx * k,
                    dy: dy * k,
                }));
            }
        }
        if i.key_pressed(egui::Key::Plus) || i.key_pressed(egui::Key::Equals) {
            cmds.push(Command::Gt(GtCommand::Step(s * 2.0)));
        }
        if i.key_pressed(egui::Key::Minus) {
            cmds.push(Command::Gt(GtCommand::Step(s / 2.0)));
        }
    }
}
