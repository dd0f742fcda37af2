//! The polish (tracker parameter `polish`, after the methods that linearise with the template's
//! gradients: ICLK, IALK, ESM): FCLK's iterations from where the search ended, toward the AM's
//! own optimum (FCLK's fixed point), as long as each leaves a patch more like the template than
//! the last (the confidence), ending at the most confident point visited. Under light that
//! changes across the target the AM's optimum itself may leave a sparse target, and the
//! template's half of ESM's Jacobian, which no light reaches, held it better there.
//!
//! It is FCLK's iteration ([`crate::sm::fclk`]) with the confidence judged between its two
//! halves: the patch and its gradients sampled at `p`, then (if `p` is the most confident so
//! far) the step from there.

use super::{FrameRun, Stage};
use crate::registration::{SearchMethod, at_least};
use crate::sm::fclk;
use crate::ssm::Params;
use crate::status::LossReason;
use std::cmp::Ordering;
use std::time::Instant;

/// See the module's documentation.
#[derive(Clone, Copy, Debug)]
pub struct Polish;

/// Where the polish ended: the confidence there, the similarity of its last accepted step's
/// start, and its iterations.
#[derive(Clone, Copy, Debug)]
struct Polished {
    confidence: f64,
    similarity: f64,
    iterations: usize,
}

impl Stage for Polish {
    fn name(&self) -> &'static str {
        "polish"
    }

    fn local(&self, _finest: &dyn SearchMethod) -> bool {
        // FCLK samples only where its parameters are.
        true
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> Result<(), LossReason> {
        let polished = polish(run);
        let e = &mut run.estimate;
        e.iterations += polished.iterations;
        e.params = run.finest.ctx.params();
        if polished.iterations > 0 {
            e.corners = run.finest.ctx.corners(&e.params);
            e.similarity = polished.similarity;
        }
        e.confidence = Some(polished.confidence);
        Ok(())
    }
}

/// The polish's loop on the finest level, from the estimate.
fn polish(run: &mut FrameRun<'_>) -> Polished {
    let (eps, max_iters) = (run.params.eps, run.params.max_iters);
    let first = run.estimate.iterations;
    let confidence = &run.judges.template;
    let mut reader = run.src.reader(run.input, run.partial);
    let exec = &mut run.exec;
    let ctx = &mut run.finest.ctx;
    ctx.set_params(run.estimate.params);
    let mut prev = ctx.corners(&ctx.params());
    // The most confident point so far, its confidence and similarity.
    let mut best: Option<(Params, f64, f64)> = None;
    let mut iterations = 0;
    for it in 0..max_iters {
        let iteration_started = Instant::now();
        let p = ctx.params();
        ctx.sample_gradients_at(&reader.view(), &p);
        let c = confidence.of(ctx.whole_held_at(&reader.view(), &p));
        if let Some((bp, bc, bf)) = best
            && c.partial_cmp(&bc) != Some(Ordering::Greater)
        {
            ctx.set_params(bp);
            return Polished {
                confidence: bc,
                similarity: bf,
                iterations,
            };
        }
        let Ok(f) = fclk::step(ctx, &p) else {
            ctx.set_params(p);
            return Polished {
                confidence: c,
                similarity: best.map_or(f64::NAN, |b| b.2),
                iterations,
            };
        };
        best = Some((p, c, f));
        let corners = ctx.corners(&ctx.params());
        if !corners.is_finite() || f.is_nan() {
            ctx.set_params(p);
            return Polished {
                confidence: c,
                similarity: f,
                iterations,
            };
        }
        reader.cover(&corners);
        iterations = it + 1;
        let step = corners.change_norm(&prev);
        prev = corners;
        exec.report(
            ctx,
            &reader.view(),
            (0, first + it),
            (corners, f, step),
            iteration_started,
        );
        if step < eps {
            break;
        }
    }
    // Settled or out of iterations: the last step's end is kept if it is the most confident.
    let q = ctx.params();
    let c = confidence.of(ctx.whole_sample_at(&reader.view(), &q));
    match best {
        Some((bp, bc, bf)) if !at_least(c, bc) => {
            ctx.set_params(bp);
            Polished {
                confidence: bc,
                similarity: bf,
                iterations,
            }
        }
        Some((_, _, bf)) => Polished {
            confidence: c,
            similarity: bf,
            iterations,
        },
        None => Polished {
            confidence: c,
            similarity: f64::NAN,
            iterations,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::IterationCounter;
    use crate::plan::Search;
    use crate::plan::harness::{confidence_at, error, shifted, tracker, with_run};

    /// After ICLK under light that changed, the polish ends at a point at least as confident as
    /// where the search ended (it never leaves its best), near the target, counting its
    /// iterations and giving the confidence it measured.
    #[test]
    fn the_polish_ends_at_its_most_confident_point() {
        let (mut t, mut gray, quads) = tracker(
            ("iclk", "ssd", "homography"),
            |p| p.pyramid_levels = 1,
            (5, 2),
        );
        // A gain on the last frame: ICLK's fixed point is not SSD's optimum there.
        for v in gray[4].data.iter_mut() {
            *v = (*v as f32 * 0.8) as u8;
        }
        let start = shifted(&quads[4], 1.5, 1.0);
        let mut counter = IterationCounter::default();
        with_run(&mut t, &gray[4], &start, &mut counter, |run| {
            Search::default().run(run).unwrap();
            let searched = run.estimate;
            let before = confidence_at(run, &searched.params);
            Polish.run(run).unwrap();
            let e = run.estimate;
            let c = e.confidence.unwrap();
            assert!(c >= before, "{c} < {before}");
            assert_eq!(c, confidence_at(run, &e.params));
            assert_eq!(e.params, run.finest.ctx.params());
            assert!(e.iterations >= searched.iterations);
            // Both within a pixel (the gain moved SSD's optimum), the polish not further.
            let (before, after) = (
                error(&searched.corners, &quads[4]),
                error(&e.corners, &quads[4]),
            );
            assert!(after < 1.0 && after <= before + 0.01, "{before} -> {after}");
        });
        assert!(counter.iterations > 0);
    }
}
