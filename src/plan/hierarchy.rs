//! The SSM hierarchy (tracker parameter `ssm_hierarchy`, MTF's `hrch`): before the tracker's
//! own SSM, the same search method with the SSMs of [`HIERARCHY`] that have fewer DOF, each
//! from its SSM's least-squares fit to the corners the previous one found (every problem of a
//! tracker shares the normaliser and the template's corners), at the finest level. The
//! tracker's own SSM then starts from its fit to the last one's corners.

use super::{BuildSearcher, FrameRun, Init, Learn, Searcher, Stage};
use crate::error::{Error, Result};
use crate::registration::{Limits, Reader, SearchMethod};
use crate::status::LossReason;

/// The SSMs of the hierarchy, fewer DOF first; those below the tracker's own are searched
/// before it.
pub const HIERARCHY: [&str; 3] = ["translation", "similitude", "affine"];

/// See the module's documentation.
#[derive(Debug)]
pub struct Hierarchy {
    /// The SSMs below the tracker's, fewer DOF first.
    lower: Vec<Searcher>,
}

impl Hierarchy {
    /// The hierarchy below an SSM of `dof` parameters (`None` when no SSM of [`HIERARCHY`] has
    /// fewer).
    pub fn new(dof: usize, res: usize, build: BuildSearcher<'_>) -> Result<Option<Self>> {
        let mut lower = Vec::new();
        for name in HIERARCHY {
            let s = build(name, res)?;
            if s.ctx.dof() < dof {
                lower.push(s);
            }
        }
        Ok((!lower.is_empty()).then_some(Hierarchy { lower }))
    }
}

impl Stage for Hierarchy {
    fn name(&self) -> &'static str {
        "hierarchy"
    }

    fn local(&self, _finest: &dyn SearchMethod) -> bool {
        false
    }

    fn initialize(&mut self, init: &Init<'_>) -> Result<()> {
        let view = init.src.view(init.input, 0);
        for Searcher { ctx, sm } in self.lower.iter_mut() {
            ctx.set_region(init.quad, init.params.res, init.params.grid)?;
            ctx.sample_template(&view);
            sm.initialize(ctx, &view).map_err(|r| {
                Error::InvalidRegion(format!(
                    "cannot track {} with {}: {r}",
                    init.quad,
                    ctx.ssm().name()
                ))
            })?;
        }
        Ok(())
    }

    /// Each SSM learns the patch of its fit to where the frame ended.
    fn learn(&mut self, at: &mut Learn<'_>) {
        let view = at.src.view(at.input, 0);
        for searcher in self.lower.iter_mut() {
            if let Some(p) = searcher.ctx.problem().fit_normalised(&at.normalised) {
                searcher.learn(&view, &p);
            }
        }
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
        let limits = Limits::of(run.params);
        let view = run.src.view(run.input, 0);
        // The corners in the normalised frame.
        let mut corners = run
            .finest
            .ctx
            .problem()
            .normalised_corners(&run.estimate.params);
        for Searcher { ctx, sm } in self.lower.iter_mut() {
            let p = ctx
                .problem()
                .fit_normalised(&corners)
                .ok_or(LossReason::Singular)?;
            ctx.set_params(p);
            let ran = run.exec.run(
                ctx,
                &mut **sm,
                &limits,
                (0, run.estimate.iterations),
                &mut Reader::Whole(view),
            )?;
            run.estimate.iterations += ran.iterations;
            corners = ctx.problem().normalised_corners(&ctx.params());
        }
        run.estimate.params = run
            .finest
            .ctx
            .problem()
            .fit_normalised(&corners)
            .ok_or(LossReason::Singular)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::IterationCounter;
    use crate::plan::harness::{
        assert_learnt, error, initialize, learn_at, searchers, shifted, tracker, with_run,
    };

    /// Below a homography, translation, similitude and affine in turn; from 4 px off they
    /// bring the estimate (the homography's fit to the affine's corners) near the target. Below
    /// a translation there is nothing.
    /// An AM that learns (PCA) learns at each SSM below the patch of its fit to where the
    /// frame ended.
    #[test]
    fn each_ssm_learns_the_patch_of_its_fit() {
        let (t, gray, quads) = tracker(("fclk", "pca", "homography"), |_| {}, (5, 2));
        let mut h = Hierarchy::new(8, 50, &searchers("fclk", "pca"))
            .unwrap()
            .unwrap();
        initialize(&mut h, &t, &gray[0], &quads[0]);
        let (src, p) = learn_at(&mut h, &t, &gray[4], &quads[4]);
        let normalised = t.finest.ctx.problem().normalised_corners(&p);
        let view = src.view(crate::visual_tracker::FrameInput::Gray8(&gray[4]), 0);
        for s in h.lower.iter_mut() {
            let fit = s.ctx.problem().fit_normalised(&normalised).unwrap();
            assert_learnt(s, &view, &fit);
        }
    }

    #[test]
    fn the_ssms_below_bring_the_estimate_near_the_target() {
        let (mut t, gray, quads) = tracker(
            ("iclk", "ssd", "homography"),
            |p| p.pyramid_levels = 1,
            (5, 2),
        );
        let build = searchers("iclk", "ssd");
        assert!(Hierarchy::new(2, 50, &build).unwrap().is_none());
        let mut h = Hierarchy::new(8, 50, &build).unwrap().unwrap();
        let dofs: Vec<usize> = h.lower.iter().map(|s| s.ctx.dof()).collect();
        assert_eq!(dofs, [2, 4, 6]);
        initialize(&mut h, &t, &gray[0], &quads[0]);
        let start = shifted(&quads[4], 4.0, 3.0);
        let mut counter = IterationCounter::default();
        let e = with_run(&mut t, &gray[4], &start, &mut counter, |run| {
            h.run(run).unwrap();
            run.estimate
        });
        let q = t.finest.ctx.corners(&e.params);
        assert!(error(&q, &quads[4]) < 1.0, "{}", error(&q, &quads[4]));
        assert_eq!(e.iterations as u64, counter.iterations);
        assert!(counter.iterations >= 3);
    }
}
