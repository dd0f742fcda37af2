//! Sum of absolute differences: `f = -sum_i |I*_i - I_i|`.
//!
//! Not differentiable where a pixel matches (`|.|` has a corner at 0, and at convergence every
//! pixel is there), so it has no analytic derivatives for the gradient-based search methods:
//! `Capabilities::derivatives` is false. No embedding either: the squared L2 distance between
//! embeddings must rank patches as the L1 distance does, and SSD's (the patch itself) does not
//! (one pixel off by 8 versus four pixels off by 3: L1 prefers the first, L2 the second; see the
//! test). An exact embedding exists in a larger space, the thermometer code of each pixel
//! (`e_k(x) = [x > k]`, `k = 0..254`: `sum_k (e_k(a) - e_k(b))^2 = |a - b|` for integer grey
//! levels), but [`Am::embed`] writes as many values as the patch has, 255 times too few, so
//! `Capabilities::distance` is false. SAD can thus only be used by search methods that only
//! evaluate the similarity (the particle filter, and NN, which then ranks by the similarity
//! itself); the tracker builder refuses the others with the reason.
//!
//! [`Am::gradient`] still returns a subgradient (`sign(I*_i - I_i)` with respect to the current
//! pixels, its negative with respect to the template, 0 at ties) and [`Am::hessian`] returns 0
//! (the second derivative almost everywhere), for callers that want them; no search method gets
//! them through the builder.

use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "sad",
    aliases: &[],
    description: "sum of absolute differences (similarity only: NN, particle filter)",
    build: AmBuilder::plain(|_| Box::new(Sad::default())),
};

#[derive(Debug, Default, Clone)]
pub struct Sad {
    template: Vec<f32>,
}

fn sum_abs_diff(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let s: f32 = ca.iter().zip(cb).map(|(x, y)| (x - y).abs()).sum();
        total += s as f64;
    }
    total
}

impl Am for Sad {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            derivatives: false,
            distance: false,
        }
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        -sum_abs_diff(&self.template, current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let sign = match wrt {
            Wrt::Current => 1.0f32,
            Wrt::Template => -1.0,
        };
        for ((g, &t), &c) in grad.iter_mut().zip(&self.template).zip(current) {
            let d = t - c;
            *g = if d > 0.0 {
                sign
            } else if d < 0.0 {
                -sign
            } else {
                0.0
            };
        }
        -sum_abs_diff(&self.template, current)
    }
    fn hessian(
        &mut self,
        _wrt: Wrt,
        _kind: HessianKind,
        _current: &[f32],
        _jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        out[..dof * dof].iter_mut().for_each(|v| *v = 0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_and_subgradient() {
        let mut am = Sad::default();
        am.set_template(&[10.0, 20.0, 30.0]);
        assert_eq!(am.similarity(&[10.0, 20.0, 30.0]), 0.0);
        assert_eq!(am.similarity(&[12.0, 15.0, 30.0]), -7.0);
        let mut g = [0f32; 3];
        am.gradient(Wrt::Current, &[12.0, 15.0, 30.0], &mut g);
        assert_eq!(g, [-1.0, 1.0, 0.0]);
        am.gradient(Wrt::Template, &[12.0, 15.0, 30.0], &mut g);
        assert_eq!(g, [1.0, -1.0, 0.0]);
        assert!(!am.capabilities().derivatives && !am.capabilities().distance);
    }

    #[test]
    fn ranks_differently_from_ssd() {
        // SSD and SAD disagree: one large error versus several small ones.
        let mut am = Sad::default();
        am.set_template(&[0.0; 4]);
        let (one, spread) = ([8.0f32, 0.0, 0.0, 0.0], [3.0f32, 3.0, 3.0, 3.0]);
        assert!(am.similarity(&one) > am.similarity(&spread));
        let ssd = |x: &[f32]| -> f32 { x.iter().map(|v| v * v).sum() };
        assert!(ssd(&one) > ssd(&spread));
    }
}
