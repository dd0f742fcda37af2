//! The executor: the iteration loop of one search method on one [`Context`], with the stop
//! test, the line search ([`LineSearch`]), the relearning of a model that follows the light,
//! and the observer. It holds no policy of its own beyond those: where a frame starts, which
//! levels and SSMs it passes through, what is done after (the plan's stages,
//! [`crate::plan`]) are decided by its callers.

use super::{Context, Control, LineSearch, Reader, SearchMethod};
use crate::geometry::{Point, Quad};
use crate::imaging::ImageView;
use crate::observe::{Iteration, MethodVisual, Observer, SELECTED_PIXELS};
use crate::spec::TrackerParams;
use crate::status::LossReason;
use std::time::Instant;

/// When a search stops: after `max_iters` iterations, or once an iteration moves the corners
/// less than `eps` px; and whether the line search shortens a step that lowered the similarity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    pub eps: f64,
    pub max_iters: usize,
    pub line_search: bool,
    /// Below this (px, the corners' change) a step that lowered the similarity ends the frame
    /// (the line search's `SETTLED` times the tracker's `eps`).
    pub settled: f64,
    /// Also stop when the next step, extrapolated from the last two (the search converging
    /// geometrically), would move the corners less than `eps`: `step^2 / previous step < eps`,
    /// on steps the line search kept.
    pub extrapolate: bool,
}

impl Limits {
    /// The tracker's limits.
    pub fn of(params: &TrackerParams) -> Self {
        Limits {
            eps: params.eps,
            max_iters: params.max_iters,
            line_search: params.line_search,
            settled: super::line_search::SETTLED * params.eps,
            extrapolate: false,
        }
    }
}

/// Where a search ended.
#[derive(Clone, Copy, Debug)]
pub struct Ran {
    /// The corners there (frame pixels).
    pub corners: Quad,
    pub iterations: usize,
    /// Whether it stopped by the stop test (not by running out of iterations).
    pub converged: bool,
    /// The similarity at the start of its last iteration.
    pub similarity: f64,
}

/// See the module's documentation. One per frame: it numbers the frame's iterations for the
/// observer and times them from the frame's start.
pub struct Executor<'a> {
    observer: &'a mut dyn Observer,
    frame: usize,
    started: Instant,
}

/// The points of the grid a selective problem reads, in frame pixels under the context's
/// parameters (warped as the sampler warps them).
fn selected_points(ctx: &Context) -> Vec<Point> {
    let xs = ctx.problem().grid().0;
    let (mut px, mut py) = (vec![0.0; xs.len()], vec![0.0; xs.len()]);
    ctx.problem().warp_grid(&ctx.params(), &mut px, &mut py);
    px.iter()
        .zip(&py)
        .map(|(&x, &y)| Point::new(x as f64, y as f64))
        .collect()
}

/// How many times a model that follows the light is relearnt in one search.
const RELEARN: usize = 3;

impl<'a> Executor<'a> {
    /// An executor for frame `frame`, whose update started at `started`.
    pub fn new(observer: &'a mut dyn Observer, frame: usize, started: Instant) -> Self {
        Executor {
            observer,
            frame,
            started,
        }
    }

    /// The frame's index.
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// The observer.
    pub fn observer(&mut self) -> &mut dyn Observer {
        self.observer
    }

    /// Runs `sm` on `ctx` from its parameters until `limits` stop it, reading `reader`
    /// (pyramid level `level`, whose first iteration is the frame's `first`).
    pub fn run(
        &mut self,
        ctx: &mut Context,
        sm: &mut dyn SearchMethod,
        limits: &Limits,
        (level, first): (usize, usize),
        reader: &mut Reader<'_>,
    ) -> Result<Ran, LossReason> {
        let mut prev = ctx.corners(&ctx.params());
        reader.cover(&prev);
        let (mut converged, mut iterations, mut similarity) = (false, 0, f64::NAN);
        sm.start_frame(ctx);
        let budget = sm.max_iterations(limits.max_iters);
        let mut relearnt = 0;
        let mut line = LineSearch::new(limits.line_search && sm.line_search(), limits.settled);
        // The last step the line search kept (NaN when it was not).
        let mut kept = f64::NAN;
        for it in 0..budget {
            let iteration_started = Instant::now();
            let from = ctx.params();
            ctx.state_mut().forget_step();
            let s = sm.iterate(ctx, &reader.view())?;
            let (f, exhausted) = if s.control == Control::Auto {
                line.after(ctx, from, s.similarity)?
            } else {
                (s.similarity, false)
            };
            let corners = ctx.corners(&ctx.params());
            if !corners.is_finite() || f.is_nan() {
                return Err(LossReason::NonFinite);
            }
            // Where the next patches are sampled (the observer's, the next iteration's).
            reader.cover(&corners);
            let step = corners.change_norm(&prev);
            prev = corners;
            let extrapolated = limits.extrapolate && line.kept() && step * step < limits.eps * kept;
            kept = if line.kept() { step } else { f64::NAN };
            iterations = it + 1;
            similarity = f;
            self.report(
                ctx,
                &reader.view(),
                (level, first + it),
                (corners, f, step),
                iteration_started,
            );
            if self.observer.wants_method_visuals() {
                if let Some(v) = sm.visual(ctx) {
                    self.observer.method_visual(self.frame, first + it, &v);
                } else if ctx.problem().is_selective() {
                    // The grid points the search reads (selective pixel integration), where
                    // the iteration put them.
                    let points = selected_points(ctx);
                    let weights = vec![1.0; points.len()];
                    let v = MethodVisual {
                        points: &points,
                        point_weights: &weights,
                        ..MethodVisual::quads(SELECTED_PIXELS, &[], &[], None)
                    };
                    self.observer.method_visual(self.frame, first + it, &v);
                }
            }
            let stop = exhausted
                || match s.control {
                    Control::Done => true,
                    Control::Continue => false,
                    Control::Auto => step < limits.eps || extrapolated,
                };
            if stop {
                // A model that follows the light (SCV's intensity map) was learnt on the
                // previous frame: once the search has settled, it learns this frame's light
                // there and the search goes on (alternating the warp and the intensity map), up
                // to three times a frame. Learnt only once per frame, after convergence, it
                // lagged one frame behind a steady change of light; learnt where the frame
                // starts, it absorbs the motion.
                if ctx.am().updates_model() && relearnt < RELEARN && it + 1 < budget {
                    relearnt += 1;
                    // The similarity changes with the model: values before and after do not
                    // compare.
                    line = LineSearch::new(line.is_on(), limits.settled);
                    ctx.learn_model(&reader.view());
                    sm.model_updated(ctx);
                    continue;
                }
                converged = true;
                break;
            }
        }
        Ok(Ran {
            corners: prev,
            iterations,
            converged,
            similarity,
        })
    }

    /// Tells the observer where an iteration (`level`, `iteration`) ended: corners, similarity,
    /// corner change, and, for observers that show it, the patch there (the next iteration
    /// samples again, so the shared buffers may be used).
    pub fn report(
        &mut self,
        ctx: &mut Context,
        view: &ImageView,
        (level, iteration): (usize, usize),
        (corners, similarity, step): (Quad, f64, f64),
        iteration_started: Instant,
    ) {
        let duration = iteration_started.elapsed();
        let patch = if self.observer.wants_patches() {
            let p = ctx.params();
            ctx.whole_sample_at(view, &p);
            Some(ctx.whole_values())
        } else {
            None
        };
        self.observer.iteration(&Iteration {
            frame: self.frame,
            level,
            iteration,
            params: &ctx.params()[..ctx.dof()],
            corners,
            similarity,
            step,
            elapsed: self.started.elapsed(),
            duration,
            patch,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::HessianKind;
    use crate::geometry::Rect;
    use crate::imaging::{GrayF32, gaussian_kernel};
    use crate::registration::{FrameSource, Step};
    use crate::spec::GridLayout;
    use crate::visual_tracker::FrameInput;

    /// Moves the target by half of what is left of 8 px each iteration (normalised units of a
    /// 40 px target: 0.2), its similarity rising; `done_after` iterations then says it is done.
    #[derive(Debug)]
    struct Halving {
        left: f64,
        done_after: Option<usize>,
        count: usize,
    }
    impl SearchMethod for Halving {
        fn name(&self) -> &str {
            "halving"
        }
        fn iterate(&mut self, ctx: &mut Context, _: &ImageView) -> Result<Step, LossReason> {
            self.count += 1;
            self.left *= 0.5;
            let mut p = ctx.params();
            p[0] += self.left;
            ctx.set_params(p);
            let f = -self.left;
            Ok(match self.done_after {
                Some(n) if self.count >= n => Step::done(f),
                _ => Step::auto(f),
            })
        }
    }

    #[derive(Default)]
    struct Seen(Vec<(usize, usize, usize)>);
    impl Observer for Seen {
        fn iteration(&mut self, it: &Iteration<'_>) {
            self.0.push((it.frame, it.level, it.iteration));
        }
    }

    /// The loop stops when the corners move less than `eps` (or, extrapolating, would at the
    /// next step), after `max_iters`, or when the method says it is done; the observer sees each
    /// iteration numbered from `first`.
    #[test]
    fn the_loop_stops_by_eps_iterations_or_the_method() {
        let img = GrayF32 {
            width: 64,
            height: 64,
            data: (0..64 * 64).map(|i| ((i * 37) % 251) as f32).collect(),
        };
        let mut src = FrameSource::new(gaussian_kernel(1, 0.0), 0);
        let input = FrameInput::Gray32(&img);
        src.prepare(input, Rect::of_size(64, 64));
        let mut ctx = Context::new(
            crate::ssm::build("translation").unwrap(),
            crate::am::build("ssd").unwrap(),
            HessianKind::Default,
            4,
        );
        ctx.set_region(
            &Quad::from_rect(10.0, 10.0, 40.0, 40.0),
            4,
            GridLayout::Centres,
        )
        .unwrap();
        let limits = |eps, max_iters| Limits {
            eps,
            max_iters,
            line_search: false,
            settled: 0.0,
            extrapolate: false,
        };
        let mut run = |limits: Limits, done_after| {
            let mut seen = Seen::default();
            let mut sm = Halving {
                left: 0.4,
                done_after,
                count: 0,
            };
            let ran = Executor::new(&mut seen, 3, Instant::now())
                .run(
                    &mut ctx,
                    &mut sm,
                    &limits,
                    (1, 5),
                    &mut src.reader(input, false),
                )
                .unwrap();
            (ran, seen.0)
        };
        // Steps of 8, 4, 2, 1, 0.5... px (times sqrt 4 corners: 16, 8, 4, 2, 1, 0.5 in the
        // norm of the eight coordinates): below 0.7 at the sixth.
        let (ran, seen) = run(limits(0.7, 30), None);
        assert_eq!((ran.iterations, ran.converged), (6, true));
        assert_eq!(seen, (5..11).map(|i| (3, 1, i)).collect::<Vec<_>>());
        assert!((ran.similarity + 0.4 / 64.0).abs() < 1e-12);
        let (ran, _) = run(limits(0.7, 4), None);
        assert_eq!((ran.iterations, ran.converged), (4, false));
        let (ran, _) = run(limits(0.7, 30), Some(2));
        assert_eq!((ran.iterations, ran.converged), (2, true));
        // Extrapolated: after the step of 1 (the one before 2), the next would be 0.5 < 0.7.
        let (ran, _) = run(
            Limits {
                extrapolate: true,
                ..limits(0.7, 30)
            },
            None,
        );
        assert_eq!((ran.iterations, ran.converged), (5, true));
    }
}
