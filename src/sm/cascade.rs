//! Composite search methods built from any others.
//!
//! - **Cascade** (`cascade:a+b+...`, and MTF's NNIC as `nnic` = `cascade:nn+iclk`): the stages
//!   run in turn on each frame, each from where the previous one stopped, each until its own stop
//!   test (the tracker's `eps`, or the method's "done") or the tracker's iteration limit. A
//!   sampling stage gives a coarse estimate with a wide basin, a gradient stage refines it.
//! - **Parallel** (`parallel:a+b+...`): every stage runs a whole frame from the same start; the
//!   estimate with the highest similarity is kept. The observer sees one iteration per frame.
//! - **Levenberg-Marquardt** (`lm:a`, for the gradient methods): the Newton system's diagonal is
//!   scaled by `1 + lambda`. Each iteration learns the similarity at the parameters the previous
//!   step reached: if it fell, that step is undone and `lambda` grows tenfold; if it rose, the
//!   step is kept and `lambda` shrinks tenfold (from 0.01 at each frame's start).

use super::{Context, Control, LossReason, MethodVisual, SearchMethod, SmConfig, Step};
use crate::am::Capabilities;
use crate::imaging::ImageView;

/// The union of what the stages need.
pub(super) fn union<'a>(stages: impl IntoIterator<Item = &'a dyn SearchMethod>) -> Capabilities {
    stages.into_iter().fold(Capabilities::default(), |acc, s| {
        let r = s.requires();
        Capabilities {
            derivatives: acc.derivatives || r.derivatives,
            distance: acc.distance || r.distance,
        }
    })
}

/// Whether a stage of a composite has finished its frame: it says so, or (left to the stop
/// test) its corners moved less than `eps`, or it took its `max_iters`.
pub(super) fn finished(
    control: Control,
    moved: f64,
    eps: f64,
    count: usize,
    max_iters: usize,
) -> bool {
    (match control {
        Control::Done => true,
        Control::Continue => false,
        Control::Auto => moved < eps,
    }) || count >= max_iters
}

/// Stages run one after the other on each frame.
#[derive(Debug)]
pub struct Cascade {
    name: String,
    stages: Vec<Box<dyn SearchMethod>>,
    eps: f64,
    max_iters: usize,
    /// The running stage and its iterations on this frame.
    stage: usize,
    count: usize,
}

impl Cascade {
    pub fn new(name: String, stages: Vec<Box<dyn SearchMethod>>, cfg: &SmConfig) -> Self {
        Cascade {
            name,
            stages,
            eps: cfg.tracker.eps,
            max_iters: cfg.tracker.max_iters,
            stage: 0,
            count: 0,
        }
    }
}

impl SearchMethod for Cascade {
    fn name(&self) -> &str {
        &self.name
    }
    fn requires(&self) -> Capabilities {
        union(self.stages.iter().map(|s| &**s))
    }
    fn non_rigid(&self) -> bool {
        self.stages.iter().all(|s| s.non_rigid())
    }
    fn template_linearised(&self) -> bool {
        // The frame ends with the last stage.
        self.stages.last().is_some_and(|s| s.template_linearised())
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        for s in &mut self.stages {
            s.initialize(ctx, img)?;
        }
        Ok(())
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        for s in &mut self.stages {
            s.model_updated(ctx);
        }
    }
    fn start_frame(&mut self, ctx: &mut Context) {
        self.stage = 0;
        self.count = 0;
        if let Some(s) = self.stages.first_mut() {
            s.start_frame(ctx);
        }
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let before = ctx.corners(&ctx.params());
        let k = self.stage.min(self.stages.len() - 1);
        let step = self.stages[k].iterate(ctx, img)?;
        self.count += 1;
        let moved = ctx.corners(&ctx.params()).change_norm(&before);
        if !finished(step.control, moved, self.eps, self.count, self.max_iters) {
            return Ok(Step {
                similarity: step.similarity,
                control: Control::Continue,
            });
        }
        if k + 1 >= self.stages.len() {
            return Ok(Step::done(step.similarity));
        }
        self.stage = k + 1;
        self.count = 0;
        self.stages[k + 1].start_frame(ctx);
        Ok(Step {
            similarity: step.similarity,
            control: Control::Continue,
        })
    }
    fn max_iterations(&self, max_iters: usize) -> usize {
        self.stages
            .iter()
            .map(|s| s.max_iterations(max_iters))
            .sum()
    }
    fn visual(&mut self, ctx: &Context) -> Option<MethodVisual<'_>> {
        // The first stage that shows something (the sampling stage of NNIC).
        let k = (0..self.stages.len()).find(|&k| self.stages[k].visual(ctx).is_some())?;
        self.stages[k].visual(ctx)
    }
}

/// Stages run from the same start; the most similar result is kept.
#[derive(Debug)]
pub struct Parallel {
    name: String,
    stages: Vec<Box<dyn SearchMethod>>,
    eps: f64,
    max_iters: usize,
}

impl Parallel {
    pub fn new(name: String, stages: Vec<Box<dyn SearchMethod>>, cfg: &SmConfig) -> Self {
        Parallel {
            name,
            stages,
            eps: cfg.tracker.eps,
            max_iters: cfg.tracker.max_iters,
        }
    }
}

impl SearchMethod for Parallel {
    fn name(&self) -> &str {
        &self.name
    }
    fn requires(&self) -> Capabilities {
        union(self.stages.iter().map(|s| &**s))
    }
    fn non_rigid(&self) -> bool {
        self.stages.iter().all(|s| s.non_rigid())
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        for s in &mut self.stages {
            s.initialize(ctx, img)?;
        }
        Ok(())
    }
    fn max_iterations(&self, _max_iters: usize) -> usize {
        1
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        for s in &mut self.stages {
            s.model_updated(ctx);
        }
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        // Each stage runs its own loop with the tracker's stop test and iteration limit.
        let start = ctx.params();
        let start_corners = ctx.corners(&start);
        let mut best: Option<(f64, crate::ssm::Params)> = None;
        let mut first_err = None;
        for s in &mut self.stages {
            ctx.set_params(start);
            s.start_frame(ctx);
            let mut prev = start_corners;
            let mut failed = None;
            for _ in 0..s.max_iterations(self.max_iters) {
                match s.iterate(ctx, img) {
                    Ok(step) => {
                        let now = ctx.corners(&ctx.params());
                        let moved = now.change_norm(&prev);
                        prev = now;
                        if !now.is_finite() {
                            failed = Some(LossReason::NonFinite);
                            break;
                        }
                        match step.control {
                            Control::Done => break,
                            Control::Continue => {}
                            Control::Auto if moved < self.eps => break,
                            Control::Auto => {}
                        }
                    }
                    Err(r) => {
                        failed = Some(r);
                        break;
                    }
                }
            }
            if let Some(r) = failed {
                first_err.get_or_insert(r);
                continue;
            }
            let p = ctx.params();
            let f = ctx.similarity_at(img, &p);
            if f.is_finite() && best.is_none_or(|(b, _)| f > b) {
                best = Some((f, p));
            }
        }
        match best {
            Some((f, p)) => {
                ctx.set_params(p);
                Ok(Step::done(f))
            }
            None => {
                ctx.set_params(start);
                Err(first_err.unwrap_or(LossReason::NonFinite))
            }
        }
    }
    fn visual(&mut self, ctx: &Context) -> Option<MethodVisual<'_>> {
        let k = (0..self.stages.len()).find(|&k| self.stages[k].visual(ctx).is_some())?;
        self.stages[k].visual(ctx)
    }
}

/// A gradient method with Levenberg-Marquardt damping and step rejection.
#[derive(Debug)]
pub struct LevenbergMarquardt {
    name: String,
    inner: Box<dyn SearchMethod>,
    lambda: f64,
    /// The parameters and similarity the last accepted step started from.
    last: Option<(crate::ssm::Params, f64)>,
}

impl LevenbergMarquardt {
    pub fn new(name: String, mut stages: Vec<Box<dyn SearchMethod>>) -> Self {
        let inner = stages.remove(0);
        LevenbergMarquardt {
            name,
            inner,
            lambda: 0.01,
            last: None,
        }
    }
}

impl SearchMethod for LevenbergMarquardt {
    fn name(&self) -> &str {
        &self.name
    }
    fn requires(&self) -> Capabilities {
        self.inner.requires()
    }
    fn non_rigid(&self) -> bool {
        self.inner.non_rigid()
    }
    fn template_linearised(&self) -> bool {
        self.inner.template_linearised()
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        self.inner.initialize(ctx, img)
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        self.inner.model_updated(ctx);
    }
    fn start_frame(&mut self, ctx: &mut Context) {
        self.lambda = 0.01;
        self.last = None;
        self.inner.start_frame(ctx);
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let start = ctx.params();
        ctx.state_mut().set_damping(self.lambda);
        let step = self.inner.iterate(ctx, img);
        ctx.state_mut().set_damping(0.0);
        let step = step?;
        match self.last {
            Some((prev, f_prev)) if step.similarity < f_prev => {
                // The previous step made things worse: undo it, damp more, try again from there.
                ctx.set_params(prev);
                self.lambda = (self.lambda * 10.0).min(1e8);
                Ok(Step {
                    similarity: f_prev,
                    control: if self.lambda >= 1e8 {
                        Control::Done
                    } else {
                        Control::Continue
                    },
                })
            }
            Some((_, f_prev)) if step.similarity > f_prev => {
                self.last = Some((start, step.similarity));
                self.lambda = (self.lambda / 10.0).max(1e-9);
                Ok(step)
            }
            // The first iteration of the frame, or the same point again after a rejection.
            _ => {
                self.last = Some((start, step.similarity));
                Ok(step)
            }
        }
    }
    fn max_iterations(&self, max_iters: usize) -> usize {
        self.inner.max_iterations(max_iters)
    }
}
