//! The ground-truth mode: corrections kept by [`crate::gt::Corrections`] (journaled, undoable),
//! edits constrained to the shown SSM, keyboard nudging, propagation with a tracker,
//! interpolation, occluded frames and export.

use super::command::Command;
use super::{InspectorApp, Tool};
use crate::dataset::Sequence;
use crate::geometry::{Point, Quad, homography_between};
use crate::gt::{self, Corrections, GtFrame, Mark, Proposal};
use crate::imaging::GrayU8;
use crate::ssm;
use eframe::egui;
use std::sync::{Arc, Mutex};

/// The ground truth of every frame in the shown SSM, with the fit residuals.
pub(super) struct GtTable {
    pub key: (u64, String),
    pub frames: Vec<GtFrame>,
    pub residuals: Vec<Option<f64>>,
}

/// Runtime state of the ground-truth mode (never saved: the corrections live in the journal).
pub struct GtRuntime {
    pub(super) corrections: Corrections,
    pub(super) table: std::cell::RefCell<Option<Arc<GtTable>>>,
    /// The corner the keyboard moves (`None`: the whole quad).
    pub(super) corner: Option<usize>,
    /// Nudge step (px).
    pub(super) step: f64,
    /// A drag in progress: the frame and the quad as dragged (not yet an edit).
    pub(super) drag: Option<(usize, Quad)>,
    /// A propagation's proposal awaiting accept / reject, and one running.
    pub(super) proposal: Option<(String, Proposal)>,
    pub(super) running: Option<Arc<Mutex<Option<crate::Result<Proposal>>>>>,
    pub(super) pending_label: Option<String>,
    /// The first annotated frame's image (the template side of the patch view) and the shown
    /// frame's image.
    pub(super) template_image: Option<(usize, GrayU8)>,
    pub(super) frame_image: Option<(usize, GrayU8)>,
    pub(super) patch_key: Option<(usize, u64, String)>,
    pub(super) patch_textures: Option<[egui::TextureHandle; 2]>,
}

impl Default for GtRuntime {
    fn default() -> Self {
        GtRuntime {
            corrections: Corrections::in_memory(0),
            table: Default::default(),
            corner: Some(0),
            step: 1.0,
            drag: None,
            proposal: None,
            running: None,
            pending_label: None,
            template_image: None,
            frame_image: None,
            patch_key: None,
            patch_textures: None,
        }
    }
}

/// Side of the template / current patches (px).
pub const PATCH: usize = 96;

/// Moves corner `k` of `q` to `to` within `ssm`'s DOF: translation moves the whole quad;
/// isometry turns it about the opposite corner towards `to`; similitude turns and scales it
/// about the opposite corner so that the corner lands on `to`; affine keeps the two neighbours of
/// the corner (the opposite corner follows, a parallelogram stays one); 8-DOF SSMs move the
/// corner alone.
pub fn move_corner(ssm_name: &str, q: &Quad, k: usize, to: Point) -> Quad {
    let k = k.min(3);
    let dof = ssm::build(ssm_name).map(|m| m.dof()).unwrap_or(8);
    let p = q.0[k];
    match dof {
        2 => q.map(|c| Point::new(c.x + to.x - p.x, c.y + to.y - p.y)),
        3 | 4 => {
            let o = q.0[(k + 2) % 4];
            let (ax, ay) = (p.x - o.x, p.y - o.y);
            let (bx, by) = (to.x - o.x, to.y - o.y);
            let n = ax * ax + ay * ay;
            if n < 1e-12 {
                return *q;
            }
            // The complex ratio (b / a) = scale * rotation.
            let (mut re, mut im) = ((bx * ax + by * ay) / n, (by * ax - bx * ay) / n);
            if dof == 3 {
                let s = (re * re + im * im).sqrt().max(1e-12);
                re /= s;
                im /= s;
            }
            q.map(|c| {
                let (x, y) = (c.x - o.x, c.y - o.y);
                Point::new(o.x + re * x - im * y, o.y + im * x + re * y)
            })
        }
        6 => {
            // The affine map fixing both neighbours and taking p to `to`: x -> x + (to - p) * w(x),
            // with w the barycentric weight of p in the triangle (p, n1, n2).
            let (n1, n2) = (q.0[(k + 1) % 4], q.0[(k + 3) % 4]);
            let det = (p.x - n1.x) * (n2.y - n1.y) - (p.y - n1.y) * (n2.x - n1.x);
            if det.abs() < 1e-12 {
                return *q;
            }
            let w = |c: Point| ((c.x - n1.x) * (n2.y - n1.y) - (c.y - n1.y) * (n2.x - n1.x)) / det;
            q.map(|c| {
                let t = w(c);
                Point::new(c.x + t * (to.x - p.x), c.y + t * (to.y - p.y))
            })
        }
        _ => {
            let mut out = *q;
            out.0[k] = to;
            out
        }
    }
}

/// Bilinear sample of `img` at `(x, y)` (clamped at the border).
fn bilinear(img: &GrayU8, x: f64, y: f64) -> u8 {
    let (w, h) = (img.width as f64, img.height as f64);
    let x = x.clamp(0.0, w - 1.0);
    let y = y.clamp(0.0, h - 1.0);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let g = |x: usize, y: usize| img.get(x, y) as f64;
    let v = g(x0, y0) * (1.0 - fx) * (1.0 - fy)
        + g(x1, y0) * fx * (1.0 - fy)
        + g(x0, y1) * (1.0 - fx) * fy
        + g(x1, y1) * fx * fy;
    v.round().clamp(0.0, 255.0) as u8
}

/// The region of `img` inside `q`, rectified to `PATCH x PATCH` (gray RGBA).
pub fn rectify(img: &GrayU8, q: &Quad) -> Option<egui::ColorImage> {
    if img.width == 0 || img.height == 0 {
        return None;
    }
    let s = PATCH as f64;
    let square = Quad::from_rect(0.0, 0.0, s, s);
    let h = homography_between(&square, q)?;
    let mut pixels = Vec::with_capacity(PATCH * PATCH);
    for y in 0..PATCH {
        for x in 0..PATCH {
            let p =
                crate::geometry::apply_homography(&h, Point::new(x as f64 + 0.5, y as f64 + 0.5));
            let v = if p.is_finite() {
                bilinear(img, p.x, p.y)
            } else {
                0
            };
            pixels.push(egui::Color32::from_gray(v));
        }
    }
    Some(egui::ColorImage::new([PATCH, PATCH], pixels))
}

impl InspectorApp {
    /// The ground truth of every frame in the shown SSM (cached per corrections version).
    pub(super) fn gt_table(&self) -> Option<Arc<GtTable>> {
        let seq = self.rt.sequence.as_ref()?;
        let key = (self.rt.gt_version, self.state.gt_ssm.clone());
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

    /// Whether a propagation is running.
    pub fn gt_propagating(&self) -> bool {
        self.rt.gt.running.is_some()
    }

    /// Opens the corrections journal of a newly opened sequence (replaying it).
    pub(super) fn open_corrections(&mut self, seq: &Sequence) {
        let path = gt::journal_path(seq);
        self.rt.gt.proposal = None;
        self.rt.gt.drag = None;
        self.rt.gt.template_image = None;
        self.rt.gt.frame_image = None;
        self.rt.gt.patch_key = None;
        match Corrections::open(&path, &seq.name, seq.len()) {
            Ok((c, rec)) => {
                if rec.edits > 0 || rec.truncated_tail {
                    let mut per_ssm: std::collections::BTreeMap<&str, usize> = Default::default();
                    for s in ssm::REGISTRY.iter().map(|e| e.name) {
                        let n = c.corrected_frames(s).len();
                        if n > 0 {
                            per_ssm.insert(s, n);
                        }
                    }
                    let per: Vec<String> =
                        per_ssm.iter().map(|(s, n)| format!("{s}: {n}")).collect();
                    self.rt.status = format!(
                        "{}: {} frames; restored {} correction(s) ({}) from {}{}",
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
                }
                self.rt.gt.corrections = c;
            }
            Err(e) => {
                self.rt.gt.corrections = Corrections::in_memory(seq.len());
                self.error(format!(
                    "the corrections journal cannot be used ({e}); corrections made now are \
                     NOT saved: fix or move the file and reopen the sequence"
                ));
            }
        }
        self.rt.gt_version += 1;
        // The template side of the patch view.
        if let Some(first) = (0..seq.len()).find(|&i| seq.ground_truth(i).is_some())
            && let Ok(img) = seq.load_gray(first)
        {
            self.rt.gt.template_image = Some((first, img));
        }
    }

    fn gt_changed(&mut self) {
        self.rt.gt_version += 1;
    }

    fn gt_key(&self) -> String {
        gt::ssm_key(&self.state.gt_ssm).unwrap_or_else(|_| "homography".into())
    }

    /// One journaled, undoable edit; errors are shown once.
    fn gt_edit(&mut self, label: &str, changes: Vec<(usize, Option<Mark>)>) {
        let key = self.gt_key();
        let changes: Vec<(String, usize, Option<Mark>)> = changes
            .into_iter()
            .map(|(f, m)| (key.clone(), f, m))
            .collect();
        match self.rt.gt.corrections.edit(label, &changes) {
            Ok(true) => {
                self.rt.status = format!("{label} (Ctrl+Z undoes)");
                self.gt_changed();
            }
            Ok(false) => {}
            Err(e) => self.error(format!("the correction was not made: {e}")),
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
    pub(super) fn apply_gt(&mut self, cmd: Command) {
        let frame = self.state.frame;
        match cmd {
            Command::GtDrag { frame, quad } => self.rt.gt.drag = Some((frame, quad)),
            Command::GtCommit { frame, quad, label } => {
                self.rt.gt.drag = None;
                let fixed = self.fit_to_ssm(&quad);
                self.gt_edit(
                    &format!("{label} on frame {}", frame + 1),
                    vec![(frame, Some(Mark::Quad(fixed.to_array())))],
                );
            }
            Command::GtPickCorner(c) => self.rt.gt.corner = c.map(|k| k.min(3)),
            Command::GtStep(s) => self.rt.gt.step = s.clamp(0.1, 64.0),
            Command::GtNudge { dx, dy } => {
                let Some(q) = self.ground_truth(frame) else {
                    return;
                };
                let moved = match self.rt.gt.corner {
                    Some(k) => move_corner(
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
                self.apply_gt(Command::GtCommit {
                    frame,
                    quad: moved,
                    label: what,
                });
            }
            Command::GtToggleOccluded => {
                let occluded = self.gt_frame(frame) == Some(GtFrame::Occluded);
                // Unmarking goes back to the original corners.
                let after = (!occluded).then_some(Mark::Occluded);
                self.gt_edit(
                    &format!(
                        "{} frame {}",
                        if occluded {
                            "unmark occluded"
                        } else {
                            "mark occluded"
                        },
                        frame + 1
                    ),
                    vec![(frame, after)],
                );
            }
            Command::GtRevert => {
                self.gt_edit(
                    &format!("revert frame {} to the original", frame + 1),
                    vec![(frame, None)],
                );
            }
            Command::GtUndo => self.step_history(true),
            Command::GtRedo => self.step_history(false),
            Command::GtExport => {
                let Some(seq) = self.rt.sequence.clone() else {
                    return;
                };
                match gt::export(&seq, &mut self.rt.gt.corrections, &self.state.gt_ssm) {
                    Ok(paths) => {
                        self.rt.status = format!(
                            "exported: {}",
                            paths
                                .iter()
                                .map(|p| p.display().to_string())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    }
                    Err(e) => self.error(format!("cannot export the ground truth: {e}")),
                }
            }
            Command::GtJumpWorst => {
                if let Some(f) = self.worst_frame() {
                    self.apply(Command::Seek(f));
                } else {
                    self.rt.status = "no uncorrected frame with a residual or a tracker".into();
                }
            }
            Command::GtInterpolate => self.interpolate(),
            Command::GtPropagate => self.propagate(),
            Command::GtAcceptProposal => {
                if let Some((label, p)) = self.rt.gt.proposal.take() {
                    let changes = p
                        .frames
                        .iter()
                        .map(|(f, q)| (*f, Some(Mark::Quad(self.fit_to_ssm(q).to_array()))))
                        .collect();
                    self.gt_edit(&label, changes);
                }
            }
            Command::GtRejectProposal => {
                self.rt.gt.proposal = None;
                self.rt.status = "proposal rejected".into();
            }
            _ => {}
        }
    }

    /// Undo or redo; the view goes to the frames the edit touched.
    fn step_history(&mut self, undo: bool) {
        let c = &mut self.rt.gt.corrections;
        let (r, did, what) = if undo {
            (c.undo(), "undid", "undo")
        } else {
            (c.redo(), "redid", "redo")
        };
        match r {
            Ok(Some((label, frames))) => {
                self.rt.status = format!("{did}: {label}");
                self.gt_changed();
                if let Some(&f) = frames.first()
                    && !frames.contains(&self.state.frame)
                {
                    self.apply(Command::Seek(f));
                }
            }
            Ok(None) => self.rt.status = format!("nothing to {what}"),
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
        match gt::interpolate(&self.state.gt_ssm, (a, qa), (b, qb)) {
            Ok(Some(v)) if !v.is_empty() => {
                let changes = v
                    .into_iter()
                    .map(|(f, q)| (f, Some(Mark::Quad(q.to_array()))))
                    .collect();
                self.gt_edit(&format!("interpolate frames {}-{}", a + 2, b), changes);
            }
            Ok(_) => self.rt.status = "the key frames are adjacent: nothing to interpolate".into(),
            Err(e) => self.error(e.to_string()),
        }
    }

    /// Starts a propagation from the shown frame with the inspected tracker's methods on the
    /// shown SSM, on its own thread.
    fn propagate(&mut self) {
        let Some(seq) = self.rt.sequence.clone() else {
            return;
        };
        let frame = self.state.frame;
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
        let slot = Arc::new(Mutex::new(None));
        let out = slot.clone();
        let label = format!("propagate from frame {} with {}", frame + 1, spec.label());
        let spawned = std::thread::Builder::new()
            .name("gt-propagate".into())
            .spawn(move || {
                let r = gt::propagate(
                    &seq,
                    &spec,
                    (frame, start),
                    &old,
                    &|f| corrected.contains(&f),
                    gt::PropagateLimits::default(),
                );
                if let Ok(mut s) = out.lock() {
                    *s = Some(r);
                }
            });
        match spawned {
            Ok(_) => {
                self.rt.gt.running = Some(slot);
                self.rt.gt.proposal = None;
                self.rt.gt.pending_label = Some(label);
                self.rt.status = "propagating...".into();
            }
            Err(e) => self.error(format!("cannot start the propagation: {e}")),
        }
    }

    /// Collects a finished propagation.
    pub(super) fn poll_propagation(&mut self) {
        let Some(slot) = &self.rt.gt.running else {
            return;
        };
        let done = slot.lock().ok().and_then(|mut s| s.take());
        let Some(result) = done else { return };
        self.rt.gt.running = None;
        match result {
            Ok(p) => {
                self.rt.status = format!(
                    "proposal for {} frame(s); {} — accept or reject it",
                    p.frames.len(),
                    p.stop
                );
                let label = self
                    .rt
                    .gt
                    .pending_label
                    .take()
                    .unwrap_or_else(|| "propagate".into());
                if p.frames.is_empty() {
                    self.rt.status = format!("nothing to propose: {}", p.stop);
                } else {
                    self.rt.gt.proposal = Some((label, p));
                }
            }
            Err(e) => self.error(format!("the propagation failed: {e}")),
        }
    }

    /// The keyboard of the ground-truth mode (when no text field has the focus).
    pub(super) fn gt_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let editing = self.rt.tool == Tool::EditGroundTruth;
        let mut cmds = Vec::new();
        ctx.input(|i| {
            if let Some(m) = super::shortcut(i, egui::Key::Z) {
                cmds.push(if m.shift {
                    Command::GtRedo
                } else {
                    Command::GtUndo
                });
            }
            if super::shortcut(i, egui::Key::Y).is_some() {
                cmds.push(Command::GtRedo);
            }
            if !editing || i.modifiers.command {
                return;
            }
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
                    cmds.push(Command::GtPickCorner(Some(k)));
                }
            }
            if i.key_pressed(egui::Key::Num0) || i.key_pressed(egui::Key::Q) {
                cmds.push(Command::GtPickCorner(None));
            }
            let s = self.rt.gt.step;
            for (key, dx, dy) in [
                (egui::Key::ArrowLeft, -s, 0.0),
                (egui::Key::ArrowRight, s, 0.0),
                (egui::Key::ArrowUp, 0.0, -s),
                (egui::Key::ArrowDown, 0.0, s),
            ] {
                if i.key_pressed(key) {
                    cmds.push(Command::GtNudge { dx, dy });
                }
            }
            if i.key_pressed(egui::Key::Plus) || i.key_pressed(egui::Key::Equals) {
                cmds.push(Command::GtStep(s * 2.0));
            }
            if i.key_pressed(egui::Key::Minus) {
                cmds.push(Command::GtStep(s / 2.0));
            }
            let n = self.frame_count();
            if (i.key_pressed(egui::Key::N) || i.key_pressed(egui::Key::PageDown))
                && self.state.frame + 1 < n
            {
                cmds.push(Command::Seek(self.state.frame + 1));
            }
            if (i.key_pressed(egui::Key::P) || i.key_pressed(egui::Key::PageUp))
                && self.state.frame > 0
            {
                cmds.push(Command::Seek(self.state.frame - 1));
            }
            if i.key_pressed(egui::Key::J) {
                cmds.push(Command::GtJumpWorst);
            }
            if i.key_pressed(egui::Key::O) {
                cmds.push(Command::GtToggleOccluded);
            }
            if i.key_pressed(egui::Key::Enter) && self.rt.gt.proposal.is_some() {
                cmds.push(Command::GtAcceptProposal);
            }
            if i.key_pressed(egui::Key::Escape) && self.rt.gt.proposal.is_some() {
                cmds.push(Command::GtRejectProposal);
            }
        });
        for c in cmds {
            self.send(c);
        }
    }

    /// The template and the shown frame's ground-truth region, rectified, as textures (rebuilt
    /// when the frame or its ground truth changes).
    pub(super) fn gt_patches(&mut self, ctx: &egui::Context) -> Option<[egui::TextureHandle; 2]> {
        let frame = self.state.frame;
        let key = (frame, self.rt.gt_version, self.state.gt_ssm.clone());
        if self.rt.gt.patch_key.as_ref() == Some(&key) {
            return self.rt.gt.patch_textures.clone();
        }
        let (tf, timg) = self.rt.gt.template_image.as_ref()?;
        let (ff, fimg) = self.rt.gt.frame_image.as_ref()?;
        if *ff != frame {
            return self.rt.gt.patch_textures.clone();
        }
        let tq = self.ground_truth(*tf)?;
        let fq = self.ground_truth(frame);
        let a = rectify(timg, &tq)?;
        let b = fq.and_then(|q| rectify(fimg, &q)).unwrap_or_else(|| {
            egui::ColorImage::new(
                [PATCH, PATCH],
                vec![egui::Color32::from_gray(40); PATCH * PATCH],
            )
        });
        let opts = egui::TextureOptions::NEAREST;
        let tex = match self.rt.gt.patch_textures.take() {
            Some([mut x, mut y]) => {
                x.set(a, opts);
                y.set(b, opts);
                [x, y]
            }
            None => [
                ctx.load_texture("gt-template", a, opts),
                ctx.load_texture("gt-current", b, opts),
            ],
        };
        self.rt.gt.patch_textures = Some(tex.clone());
        self.rt.gt.patch_key = Some(key);
        Some(tex)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_moves_stay_in_the_ssm() {
        let q = Quad::from_rect(10.0, 20.0, 40.0, 30.0);
        let to = Point::new(q.0[2].x + 6.0, q.0[2].y + 3.0);
        for name in [
            "translation",
            "isometry",
            "similitude",
            "affine",
            "homography",
        ] {
            let m = ssm::build(name).unwrap();
            let moved = move_corner(name, &q, 2, to);
            let (_, _, r) = gt::best_fit(&*m, &q, &moved).unwrap();
            assert!(
                r < 1e-6,
                "{name}: the moved quad is not a {name} warp ({r} px)"
            );
            if name != "isometry" {
                assert!(
                    moved.0[2].dist(to) < 1e-9,
                    "{name}: the corner reaches the pointer"
                );
            }
            match name {
                "translation" => assert!(moved.0[0].dist(Point::new(16.0, 23.0)) < 1e-9),
                "isometry" | "similitude" => assert!(moved.0[0].dist(q.0[0]) < 1e-9),
                "affine" => {
                    assert!(moved.0[1].dist(q.0[1]) < 1e-9 && moved.0[3].dist(q.0[3]) < 1e-9)
                }
                _ => assert_eq!(moved.0[0], q.0[0]),
            }
        }
    }
}
