//! Coarse to fine: the tracker's search method on coarser pyramid levels first (tracker
//! parameter `pyramid_levels`, the gradient methods), each level from the parameters the
//! coarser one found (they live in the normalised frame, the same at every level), each with
//! its own problem: a grid of half the finer level's points per side ([`level_res`]) and its
//! own template. A coarse level stops once its corners move less than [`COARSE_EPS`] of its own
//! pixels, or after a third of `max_iters`: it only has to bring the search into the finer
//! level's basin.
//!
//! A check between the levels: the coarse levels' estimate is kept only if, at the finest
//! level, the patch there looks at least as much like the template (the confidence, which light
//! does not sway as it sways SSD) as where the frame started. Marks finer than the coarse
//! levels' pixels (a star field) vanish there, and the coarse search then follows the light
//! instead of the target.

use super::{BuildSearcher, FrameRun, Init, Learn, Searcher, Stage};
use crate::error::{Error, Result};
use crate::imaging::COARSE_EPS;
use crate::registration::{Limits, Reader, SearchMethod, at_least};
use crate::spec::TrackerParams;
use crate::status::LossReason;

/// The fewest grid points per side of a pyramid level (each coarser level halves `res`).
pub const MIN_LEVEL_RES: usize = 10;

/// The grid points per side of pyramid level `level` (0 = the finest) of a tracker of `res`:
/// half the finer level's, so that every level samples its own pixels alike.
pub fn level_res(res: usize, level: usize) -> usize {
    (res >> level.min(31)).max(MIN_LEVEL_RES.min(res))
}

/// See the module's documentation.
#[derive(Debug)]
pub struct Pyramid {
    /// Levels 1, 2, ... (coarser and coarser), each with its own problem.
    coarse: Vec<Searcher>,
}

impl Pyramid {
    /// The coarse levels of a tracker of `levels` levels (`None` for one) on the SSM `ssm`.
    pub fn new(
        ssm: &str,
        params: &TrackerParams,
        levels: usize,
        build: BuildSearcher<'_>,
    ) -> Result<Option<Self>> {
        if levels <= 1 {
            return Ok(None);
        }
        let coarse = (1..levels)
            .map(|l| build(ssm, level_res(params.res, l)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Some(Pyramid { coarse }))
    }
}

impl Stage for Pyramid {
    fn name(&self) -> &'static str {
        "pyramid"
    }

    /// The levels are made (and the finest level's region completed) before any is read: a
    /// frame whose search settles at the finest level first (`escalate`) smooths only the
    /// part of the region it reads.
    fn local(&self, _finest: &dyn SearchMethod) -> bool {
        true
    }

    fn levels(&self) -> usize {
        self.coarse.len()
    }

    fn initialize(&mut self, init: &Init<'_>) -> Result<()> {
        let (quad, params) = (init.quad, init.params);
        for (l, Searcher { ctx, sm }) in self.coarse.iter_mut().enumerate() {
            ctx.set_region(quad, level_res(params.res, l + 1), params.grid)?;
            let view = init.src.view(init.input, l + 1);
            ctx.sample_template(&view);
            sm.initialize(ctx, &view).map_err(|r| {
                Error::InvalidRegion(format!(
                    "cannot track {quad} at pyramid level {}: {r}",
                    l + 1
                ))
            })?;
        }
        Ok(())
    }

    /// Each level learns its own patch where the frame ended (the levels are made for it).
    fn learn(&mut self, at: &mut Learn<'_>) {
        at.src.build_levels(at.input);
        for (l, searcher) in self.coarse.iter_mut().enumerate() {
            searcher.learn(&at.src.view(at.input, l + 1), &at.params);
        }
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
        let params = run.params;
        let start = run.estimate.params;
        let mut p = start;
        run.src.build_levels(run.input);
        let mut limits = Limits::of(params);
        limits.max_iters = params.max_iters.div_ceil(3);
        for (l, Searcher { ctx, sm }) in self.coarse.iter_mut().enumerate().rev() {
            ctx.set_params(p);
            let view = run.src.view(run.input, l + 1);
            limits.eps = params.eps.max(COARSE_EPS * (1 << (l + 1)) as f64);
            let ran = run.exec.run(
                ctx,
                &mut **sm,
                &limits,
                (l + 1, run.estimate.iterations),
                &mut Reader::Whole(view),
            )?;
            run.estimate.iterations += ran.iterations;
            p = ctx.params();
        }
        if p != start {
            let view = run.src.view(run.input, 0);
            let (ctx, confidence) = (&mut run.finest.ctx, &run.judges.template);
            // The start first: the patch at the coarse estimate, where the search goes on, is
            // then the one in the workspace (a method that samples with `patch_at` does not
            // sample it again; unless the searches read part of the grid, `spi`).
            let at_start = confidence.of(ctx.whole_sample_at(&view, &start));
            let at_coarse = confidence.of(ctx.whole_sample_at(&view, &p));
            // Also when either is NaN: the start is the safe side.
            if !at_least(at_coarse, at_start) {
                p = start;
            }
        }
        run.estimate.params = p;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::{Iteration, Observer};
    use crate::plan::harness::{
        assert_learnt, confidence_at, error, initialize, learn_at, searchers, shifted, tracker,
        with_run,
    };

    /// The pyramid levels the observer saw iterations at.
    #[derive(Default)]
    struct Levels(Vec<usize>);
    impl Observer for Levels {
        fn iteration(&mut self, it: &Iteration<'_>) {
            self.0.push(it.level);
        }
    }

    /// From 9 px off, the coarse levels (coarsest first) bring the estimate near the target;
    /// what the pyramid keeps is never less confident at the finest level than its start (from
    /// the target itself, the start is kept or bettered).
    #[test]
    fn the_coarse_levels_bring_the_start_near_and_never_less_confident() {
        let (mut t, gray, quads) = tracker(("iclk", "ssd", "homography"), |_| {}, (5, 2));
        let params = t.params.clone();
        let mut pyramid = Pyramid::new("homography", &params, 3, &searchers("iclk", "ssd"))
            .unwrap()
            .unwrap();
        assert_eq!(pyramid.levels(), 2);
        initialize(&mut pyramid, &t, &gray[0], &quads[0]);
        for (start, far) in [(shifted(&quads[4], 9.0, -6.0), true), (quads[4], false)] {
            let mut levels = Levels::default();
            let iterations = with_run(&mut t, &gray[4], &start, &mut levels, |run| {
                let from = run.estimate.params;
                pyramid.run(run).unwrap();
                let p = run.estimate.params;
                assert!(confidence_at(run, &p) >= confidence_at(run, &from));
                if far {
                    let q = run.finest.ctx.corners(&p);
                    assert!(error(&q, &quads[4]) < 2.0, "{}", error(&q, &quads[4]));
                }
                run.estimate.iterations
            });
            assert_eq!(iterations, levels.0.len());
            // Coarsest first, never the finest level.
            assert!(!levels.0.is_empty() && levels.0[0] == 2);
            assert!(levels.0.windows(2).all(|w| w[0] >= w[1]) && !levels.0.contains(&0));
        }
    }

    /// An AM that learns (PCA) learns at each coarse level that level's patch where the frame
    /// ended.
    #[test]
    fn each_level_learns_its_own_patch_where_the_frame_ended() {
        let (t, gray, quads) = tracker(("esm", "pca", "homography"), |_| {}, (5, 2));
        let mut pyramid = Pyramid::new("homography", &t.params, 3, &searchers("esm", "pca"))
            .unwrap()
            .unwrap();
        initialize(&mut pyramid, &t, &gray[0], &quads[0]);
        let (mut src, p) = learn_at(&mut pyramid, &t, &gray[4], &quads[4]);
        let input = crate::visual_tracker::FrameInput::Gray8(&gray[4]);
        src.build_levels(input);
        for (l, s) in pyramid.coarse.iter_mut().enumerate() {
            assert_learnt(s, &src.view(input, l + 1), &p);
        }
    }

    #[test]
    fn each_level_samples_half_the_finer_ones_points_down_to_a_floor() {
        assert_eq!(level_res(50, 0), 50);
        assert_eq!(level_res(50, 1), 25);
        assert_eq!(level_res(50, 2), 12);
        assert_eq!(level_res(50, 3), MIN_LEVEL_RES);
        assert_eq!(level_res(8, 2), 8);
        assert_eq!(level_res(50, 40), MIN_LEVEL_RES);
    }
}
