//! A second hypothesis on hard frames (tracker parameter `second`): complementary trackers
//! fail on different footage (ICLK-ZNCC holds light that changes across the target where the
//! SSD trackers drift; ESM-SSD and FCLK-SSD hold fast motion and blur where ICLK, which
//! linearises at the sharp template, does not). When a tracking frame's search fails the
//! checks, a second tracker of another method and AM searches the frame from the same start;
//! its end is measured by the first tracker's confidences (against the first tracker's template
//! and last patch, so that both ends compare), and the more confident end is judged. Easy
//! frames never pay for it, nor do frames while lost (the re-detection's budget stands).

use super::judge::SearchResult;
use super::{Estimate, RegistrationTracker};
use crate::geometry::Quad;
use crate::observe::NoObserver;
use crate::visual_tracker::{FrameInput, VisualTracker};

impl RegistrationTracker {
    /// The second tracker's end on the frame from `start`, measured by this tracker's
    /// confidences (`None` without a second tracker, or when its end has no finite quad or no
    /// fit in this tracker's SSM).
    pub(super) fn second_hypothesis(
        &mut self,
        input: FrameInput<'_>,
        start: &Quad,
        iterations: usize,
    ) -> Option<SearchResult> {
        let second = self.second.as_mut()?;
        second.set_corners(start).ok()?;
        let out = second.update(input, &mut NoObserver);
        let corners = out.estimate.filter(|q| q.is_finite())?;
        let ctx = &mut self.finest.ctx;
        let params = ctx.problem().fit(&corners)?;
        self.src.hold(input, &corners, self.params.roi_margin);
        let view = self.src.view(input, 0);
        let mut e = Estimate::start(params, ctx.corners(&params));
        let values = ctx.whole_patch_at(&view, &params);
        e.iterations = iterations + out.iterations;
        e.converged = out.converged;
        e.similarity = out.similarity;
        e.confidence = Some(self.judges.template.of(values));
        e.frame_confidence = self.judges.previous().map(|p| p.of(values));
        Some(Ok(e))
    }
}

#[cfg(test)]
mod tests {
    use crate::dataset::demo::demo_config;
    use crate::dataset::synth::{SynthConfig, render_frames};
    use crate::geometry::alignment_error;
    use crate::observe::NoObserver;
    use crate::plan::RegistrationTracker;
    use crate::spec::{RegistrationSpec, SecondHypothesis, TrackerParams};
    use crate::status::TrackStatus;
    use crate::visual_tracker::{FrameInput, VisualTracker};

    #[test]
    fn the_names_of_a_second_hypothesis_are_a_method_and_an_am() {
        assert_eq!(SecondHypothesis::None.names(), None);
        assert_eq!(SecondHypothesis::FclkSsd.names(), Some(("fclk", "ssd")));
        assert_eq!(SecondHypothesis::IclkZncc.names(), Some(("iclk", "zncc")));
    }

    /// The second tracker's end, from a start 4 px off on a later frame, is on the target, and
    /// is measured by the first tracker's confidences: against the first tracker's template as
    /// high as the first tracker's own end there, and against its last patch when it has one;
    /// the iterations of both are counted.
    #[test]
    fn the_second_end_is_measured_by_the_first_trackers_confidences() {
        let (gray, quads) = render_frames(&SynthConfig {
            max_frames: Some(4),
            step: 2,
            ..demo_config()
        })
        .unwrap();
        let spec = |second| RegistrationSpec {
            sm: "iclk".into(),
            am: "zncc".into(),
            ssm: "homography".into(),
            params: TrackerParams {
                second,
                ..TrackerParams::default()
            },
            method: Default::default(),
        };
        let mut t = RegistrationTracker::new(&spec(SecondHypothesis::FclkSsd)).unwrap();
        assert!(
            RegistrationTracker::new(&spec(SecondHypothesis::None))
                .unwrap()
                .second
                .is_none()
        );
        let second = t.second.as_ref().unwrap().spec.clone();
        let second = second.registration().unwrap();
        assert_eq!(
            (second.sm.as_str(), second.am.as_str(), second.ssm.as_str()),
            ("fclk", "ssd", "homography")
        );
        assert_eq!(second.params.second, SecondHypothesis::None);
        t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
            .unwrap();
        let own = t.update(FrameInput::Gray8(&gray[1]), &mut NoObserver);
        assert_eq!(own.status, TrackStatus::Tracking);
        let start = quads[2].map(|p| crate::geometry::Point::new(p.x + 4.0, p.y - 2.0));
        let e = t
            .second_hypothesis(FrameInput::Gray8(&gray[2]), &start, 7)
            .unwrap()
            .unwrap();
        assert!(
            alignment_error(&e.corners, &quads[2]) < 0.5,
            "{:?}",
            e.corners
        );
        assert!(e.iterations > 7);
        // Settled: the second tracker converged (its own stop test, not merely "tracking").
        assert!(e.converged);
        let (c, f) = (e.confidence.unwrap(), e.frame_confidence.unwrap());
        assert!(c > 0.9 && f > 0.9, "{c} {f}");
        // The same measure as the first tracker's: its end on that frame, measured the same.
        let mine = t.update(FrameInput::Gray8(&gray[2]), &mut NoObserver);
        assert!((mine.confidence.unwrap() - c).abs() < 0.05, "{mine:?} {c}");
    }
}
