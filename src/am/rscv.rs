//! Reversed sum of conditional variance (RSCV, Dick et al. 2013): the current patch is mapped to
//! the template's appearance instead, `f = -1/2 sum_i (I*_i - m(I_i))^2` with
//! `m(c) ~ E[I* | I = c]` (the estimator of [`super::intensity_map`]: a regularised
//! piecewise-linear regression of `I*` on `I` over 32 linearly binned nodes).
//!
//! The map is re-estimated once per frame in [`Am::update_model`] from the converged patch and is
//! held fixed within a frame ([`Am::set_template`] resets it to the identity). Derivatives with
//! the map fixed (`m` continuous, piecewise linear, slope `m'` piecewise constant, `m'' = 0`
//! between nodes; at a node the one-sided slope of the segment above is used):
//! - with respect to the current pixels: `df/dI_i = (I*_i - m(I_i)) m'(I_i)`,
//!   `d2f/dI_i^2 = -m'(I_i)^2 + (I*_i - m(I_i)) m''(I_i) = -m'(I_i)^2` (Newton and Gauss-Newton
//!   coincide); after convergence (`I = I*`) it is `-m'(I*_i)^2`;
//! - with respect to the template pixels: `df/dI* = m(I) - I*`, `d2f/dI*2 = -Id`.
//!
//! Embedding for nearest-neighbour search: `m(patch)`, so that an index of template samples built
//! when the map is the identity stays valid as the map follows the appearance (the reason Dick
//! et al. reversed SCV).

use super::intensity_map::{MapFit, PlMap, jt_diag_j};
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::linalg::minus_jtj;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "rscv",
    aliases: &[],
    description: "reversed SCV (current patch mapped by E[I* | I], updated per frame)",
    build: AmBuilder::plain(|_| Box::new(Rscv::default())),
};

#[derive(Debug, Clone)]
pub struct Rscv {
    template: Vec<f32>,
    map: PlMap,
    identity: bool,
    fit: MapFit,
    /// Scratch: `m'(x)^2` per pixel.
    slope_sq: Vec<f32>,
}

impl Default for Rscv {
    fn default() -> Self {
        Rscv {
            template: Vec::new(),
            map: PlMap::identity(),
            identity: true,
            fit: MapFit::default(),
            slope_sq: Vec::new(),
        }
    }
}

impl Rscv {
    fn value(&self, current: &[f32]) -> f64 {
        let mut total = 0.0f64;
        for (ct, cc) in self.template.chunks(256).zip(current.chunks(256)) {
            let mut s = 0.0f64;
            for (&t, &c) in ct.iter().zip(cc) {
                let d = t as f64 - self.map.eval(c as f64).0;
                s += d * d;
            }
            total += s;
        }
        -0.5 * total
    }
}

impl Am for Rscv {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
        self.map = PlMap::identity();
        self.identity = true;
        self.slope_sq.resize(template.len(), 0.0);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        for (o, &v) in out.iter_mut().zip(patch) {
            *o = self.map.eval(v as f64).0 as f32;
        }
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.value(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let mut total = 0.0f64;
        for ((g, &t), &c) in grad.iter_mut().zip(&self.template).zip(current) {
            let (m, s) = self.map.eval(c as f64);
            let d = t as f64 - m;
            total += d * d;
            *g = match wrt {
                Wrt::Current => (d * s) as f32,
                Wrt::Template => -d as f32,
            };
        }
        -0.5 * total
    }
    fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        if wrt == Wrt::Template || self.identity {
            minus_jtj(jac, dof, out);
            return;
        }
        // The slope at the current pixels (at the template's after convergence): a table
        // look-up per pixel, cheaper than keeping it from the gradient.
        let at = if kind == HessianKind::AfterConvergence {
            &self.template
        } else {
            current
        };
        for (d, &x) in self.slope_sq.iter_mut().zip(at) {
            let s = self.map.eval(x as f64).1;
            *d = (s * s) as f32;
        }
        jt_diag_j(jac, &self.slope_sq, dof, out);
        out.iter_mut().for_each(|v| *v = -*v);
    }
    fn updates_model(&self) -> bool {
        true
    }
    fn update_model(&mut self, current: &[f32]) {
        if current.len() != self.template.len() {
            return;
        }
        self.fit.clear();
        for (&t, &c) in self.template.iter().zip(current) {
            self.fit.add(c as f64, t as f64, 1.0);
        }
        self.fit.solve(&mut self.map);
        self.identity = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    use crate::am::tests::patch;

    #[test]
    fn invariant_to_gain_and_bias_after_a_model_update() {
        let mut rng = Rng::new(13);
        let t = patch(&mut rng, 400);
        let lit: Vec<f32> = t.iter().map(|&v| 1.3 * v - 20.0).collect();
        let mut am = Rscv::default();
        am.set_template(&t);
        assert!(am.similarity(&lit) < -1e4);
        am.update_model(&lit);
        assert!(am.similarity(&lit).abs() < 0.1, "{}", am.similarity(&lit));
        // The embedding maps the lit patch back onto the template.
        let mut e = vec![0f32; t.len()];
        am.embed(&lit, &mut e);
        assert!(e.iter().zip(&t).all(|(a, b)| (a - b).abs() < 1e-2));
    }

    #[test]
    fn current_derivatives_through_a_non_trivial_map() {
        let mut rng = Rng::new(15);
        let n = 64;
        let t = patch(&mut rng, n);
        let c: Vec<f32> = t
            .iter()
            .map(|&v| 255.0 * (v / 255.0).powf(0.7) + rng.range(-10.0, 10.0) as f32)
            .collect();
        let mut am = Rscv::default();
        am.set_template(&t);
        am.update_model(&c);
        let mut g = vec![0f32; n];
        let f = am.gradient(Wrt::Current, &c, &mut g);
        assert!((f - am.similarity(&c)).abs() < 1e-9 * f.abs());
        for i in 0..n {
            // Small steps: the slope jumps at the nodes.
            let h = 2e-3f32;
            let (mut cp, mut cm) = (c.clone(), c.clone());
            cp[i] += h;
            cm[i] -= h;
            let step = cp[i] as f64 - cm[i] as f64;
            let fd = (am.similarity(&cp) - am.similarity(&cm)) / step;
            assert!(
                (fd - g[i] as f64).abs() < 2e-2 * (1.0 + fd.abs()),
                "{i}: {fd} {}",
                g[i]
            );
        }
        // Hessian: -J^T diag(m'(I)^2) J, and at the template's intensities after convergence.
        let jac: Vec<f32> = (0..n).map(|_| rng.range(-1.0, 1.0) as f32).collect();
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        am.hessian(Wrt::Current, HessianKind::Newton, &c, &jac, 1, &mut h);
        let want: f64 = (0..n)
            .map(|i| -(am.map.eval(c[i] as f64).1 * jac[i] as f64).powi(2))
            .sum();
        assert!((h[0] - want).abs() < 1e-4 * want.abs());
        am.hessian(
            Wrt::Current,
            HessianKind::AfterConvergence,
            &c,
            &jac,
            1,
            &mut h,
        );
        let want: f64 = (0..n)
            .map(|i| -(am.map.eval(t[i] as f64).1 * jac[i] as f64).powi(2))
            .sum();
        assert!((h[0] - want).abs() < 1e-4 * want.abs());
    }
}
