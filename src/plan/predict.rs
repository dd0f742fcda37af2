//! Motion prediction (tracker parameter `predict=on`, the default): each frame's search starts
//! where the target is going, not where it was. The corners move on at their last velocity
//! times a damping, one of [`DAMPING`] (0: the last pose, no prediction); each damping's
//! prediction is scored against where every tracked frame ended (a running mean of the corners'
//! distance, [`KEEP`]), and the next frame starts from the damping that has predicted best so
//! far. A constant motion (a camera panning at 10 px a frame) is then met within a fraction
//! of a pixel, and a shaking hand, whose velocity does not carry over, falls back to the last
//! pose. Until a damping has been scored the next frame starts from the last pose
//! ([`UNSCORED`]), but for a velocity measured over a loss (below). After a
//! re-initialisation or a move by hand the velocity is unknown: the next frame starts from the
//! last pose and the scores start again. A target found again after a loss
//! of `n` frames moves on at its mean velocity over the gap (where it was last tracked to
//! where it is found, over `n + 1` frames), with the dampings' scores kept from before the
//! loss: a target lost for a frame while moving 20 px a frame was otherwise searched from 20
//! px behind in the next frame, and lost again, every other frame.

use crate::geometry::{Point, Quad};

/// The dampings of the velocity the predictions are made with (0: the last pose).
pub const DAMPING: [f64; 3] = [0.0, 0.5, 1.0];
/// The damping before any has been scored: the last pose. (The velocity taken whole there,
/// from the first two frames after an initialisation, sent searches on a brick wall a period
/// away, where they passed the checks: the slip test's frames off reported lost fell from
/// 0.955 to 0.877.) A velocity measured over a loss, from where the target was last tracked
/// to where it was found, is taken whole ([`Predictor::found_again`]).
pub const UNSCORED: f64 = 0.0;
/// The weight of the past in the running mean of each damping's error.
pub const KEEP: f64 = 0.7;

/// See the module's documentation.
#[derive(Clone, Debug, Default)]
pub struct Predictor {
    /// The corners of the frame tracked before the last one, when both were tracked in a row.
    before: Option<Quad>,
    /// Each damping's running mean error (px), once scored.
    error: Option<[f64; DAMPING.len()]>,
    /// Whether the velocity was measured over a loss (taken whole until scored).
    over_loss: bool,
}

/// `q` moved on by `damping` times its velocity since `before`.
fn moved_on(q: &Quad, before: &Quad, damping: f64) -> Quad {
    let mut out = *q;
    for (o, (p, b)) in out.0.iter_mut().zip(q.0.iter().zip(&before.0)) {
        *o = Point::new(p.x + damping * (p.x - b.x), p.y + damping * (p.y - b.y));
    }
    out
}

/// The mean distance of the corners.
fn distance(a: &Quad, b: &Quad) -> f64 {
    a.0.iter().zip(&b.0).map(|(p, q)| p.dist(*q)).sum::<f64>() / 4.0
}

impl Predictor {
    /// Forgets the velocity and the scores (after a loss, an initialisation, a move by hand).
    pub fn reset(&mut self) {
        *self = Predictor::default();
    }

    /// The damping the next frame is predicted with: the one that has predicted best so far
    /// ([`UNSCORED`] until one has been scored).
    pub fn damping(&self) -> f64 {
        let Some(error) = self.error else {
            return if self.over_loss { 1.0 } else { UNSCORED };
        };
        let mut best = 0;
        for (k, e) in error.iter().enumerate() {
            if *e < error[best] {
                best = k;
            }
        }
        DAMPING[best]
    }

    /// Where the target tracked at `last` is predicted in the next frame (`last` itself when
    /// there is no velocity yet, or when standing still has predicted best).
    pub fn predict(&self, last: &Quad) -> Quad {
        match self.before {
            Some(before) => moved_on(last, &before, self.damping()),
            None => *last,
        }
    }

    /// The target was lost: the velocity is forgotten, the dampings' scores kept.
    pub fn lost(&mut self) {
        self.before = None;
        self.over_loss = false;
    }

    /// The target found at `now` after a loss, `frames` frames after it was last tracked at
    /// `last`: it moves on at its mean velocity over those frames.
    pub fn found_again(&mut self, last: &Quad, now: &Quad, frames: usize) {
        let n = frames.max(1) as f64;
        let mut before = *now;
        for (b, (p, l)) in before.0.iter_mut().zip(now.0.iter().zip(&last.0)) {
            *b = Point::new(p.x - (p.x - l.x) / n, p.y - (p.y - l.y) / n);
        }
        self.before = Some(before);
        self.over_loss = true;
    }

    /// A frame tracked from `last` (the previous frame's corners) to `now`: each damping's
    /// prediction of `now` is scored, and `last` becomes the velocity's origin.
    pub fn tracked(&mut self, last: &Quad, now: &Quad) {
        if let Some(before) = self.before {
            let errors = DAMPING.map(|d| distance(&moved_on(last, &before, d), now));
            self.error = Some(match self.error {
                Some(old) => std::array::from_fn(|k| KEEP * old[k] + (1.0 - KEEP) * errors[k]),
                None => errors,
            });
        }
        self.before = Some(*last);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x: f64, y: f64) -> Quad {
        Quad::from_rect(x, y, 40.0, 30.0)
    }

    /// A constant motion is predicted exactly once its velocity is known; before that, and
    /// after a reset, the next frame starts from the last pose.
    #[test]
    fn a_constant_motion_is_met_where_it_goes() {
        let mut p = Predictor::default();
        assert_eq!(p.predict(&square(0.0, 0.0)), square(0.0, 0.0));
        p.tracked(&square(0.0, 0.0), &square(10.0, 4.0));
        // A velocity, not yet scored: no prediction yet.
        assert_eq!(p.predict(&square(10.0, 4.0)), square(10.0, 4.0));
        for k in 1..6 {
            let (a, b) = (k as f64, (k + 1) as f64);
            p.tracked(&square(10.0 * a, 4.0 * a), &square(10.0 * b, 4.0 * b));
        }
        assert_eq!(p.damping(), 1.0);
        let next = p.predict(&square(60.0, 24.0));
        assert!(distance(&next, &square(70.0, 28.0)) < 1e-9);
        p.reset();
        assert_eq!(p.predict(&square(60.0, 24.0)), square(60.0, 24.0));
    }

    /// A shaking target whose velocity reverses every frame is predicted best by its last pose:
    /// the prediction falls back to it.
    #[test]
    fn a_shake_falls_back_to_the_last_pose() {
        let mut p = Predictor::default();
        let at = |k: usize| square(if k.is_multiple_of(2) { 0.0 } else { 6.0 }, 0.0);
        for k in 0..8 {
            p.tracked(&at(k), &at(k + 1));
        }
        assert_eq!(p.damping(), 0.0);
        assert_eq!(p.predict(&at(8)), at(8));
        // The motion steadies: the prediction comes back within a few frames.
        let mut k = 0;
        while p.damping() != 1.0 {
            let (a, b) = (k as f64, (k + 1) as f64);
            p.tracked(&square(5.0 * a, 0.0), &square(5.0 * b, 0.0));
            k += 1;
            assert!(k < 10, "{:?}", p.error);
        }
    }

    /// Found again after a loss: the mean velocity over the gap, with the scores from before
    /// the loss (a steady motion is met at once).
    #[test]
    fn a_target_found_again_moves_on_at_its_velocity_over_the_gap() {
        let mut p = Predictor::default();
        for k in 0..6 {
            let (a, b) = (k as f64, (k + 1) as f64);
            p.tracked(&square(20.0 * a, 0.0), &square(20.0 * b, 0.0));
        }
        assert_eq!(p.damping(), 1.0);
        p.lost();
        assert_eq!(p.predict(&square(120.0, 0.0)), square(120.0, 0.0));
        // Lost at frame 7 (last tracked at 120 on frame 6), found at frame 8 at 160.
        p.found_again(&square(120.0, 0.0), &square(160.0, 0.0), 2);
        assert!(distance(&p.predict(&square(160.0, 0.0)), &square(180.0, 0.0)) < 1e-9);
        // No score yet: a velocity over a loss is taken whole.
        let mut fresh = Predictor::default();
        fresh.found_again(&square(0.0, 0.0), &square(40.0, 0.0), 2);
        assert_eq!(fresh.predict(&square(40.0, 0.0)), square(60.0, 0.0));
        // Standing still scored best before the loss: the last pose.
        let mut still = Predictor::default();
        for _ in 0..4 {
            still.tracked(&square(0.0, 0.0), &square(0.0, 0.0));
        }
        still.lost();
        still.found_again(&square(0.0, 0.0), &square(4.0, 0.0), 2);
        assert_eq!(still.predict(&square(4.0, 0.0)), square(4.0, 0.0));
    }
}
