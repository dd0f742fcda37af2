//! Sum of conditional variance (SCV, Richa et al. 2011): SSD between the current patch and the
//! template mapped to the current appearance, `f = -1/2 sum_i (m(I*_i) - I_i)^2`, where
//! `m(t) ~ E[I | I* = t]` is the conditional expectation of the current intensities given the
//! template's, estimated from their joint histogram (see [`super::intensity_map`] for the
//! estimator: a regularised piecewise-linear regression on 32 linearly binned nodes, exactly
//! invariant to a global gain and bias).
//!
//! The map is re-estimated once per frame in [`Am::update_model`] from the converged patch and is
//! a constant within a frame ([`Am::set_template`] resets it to the identity), so the derivatives
//! are those of SSD against the mapped template `T' = m(I*)`:
//! - with respect to the current pixels: `df/dI = T' - I`, `d2f/dI2 = -Id` (every Hessian kind);
//! - with respect to the template pixels, through the map: `df/dI*_i = m'(I*_i) (I_i - T'_i)`,
//!   `d2f/dI*_i^2 = -m'(I*_i)^2 + (I_i - T'_i) m''(I*_i) = -m'(I*_i)^2` (the map is piecewise
//!   linear: `m'' = 0` between nodes), the same for every kind: the exact Hessian is already
//!   negative semi-definite, and at convergence (`I = T'`) the second term vanishes anyway.
//!
//! The mapped template and its slope are cached per pixel when the map changes, so an iteration
//! costs what SSD's does.
//!
//! The same core with a `3 x 3` grid of maps blended between block centres is LSCV
//! ([`super::lscv`]): the map is then a function of the pixel too, `m(x_i, t)`, which changes
//! nothing above since the pixel positions are fixed.
//!
//! Embedding for nearest-neighbour search: the patch itself (a sample index cannot follow a map
//! that changes every frame: nearest-neighbour search ranks by SSD to the unmapped template).

use super::intensity_map::{MapFit, PlMap, Regions, jt_diag_j};
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::linalg::minus_jtj;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "scv",
    aliases: &[],
    description: "sum of conditional variance (template mapped by E[I | I*], updated per frame)",
    build: AmBuilder::plain(|_| Box::new(Scv::new(ENTRY.name, 1))),
};

/// SCV with `side x side` localised maps (1: SCV proper).
#[derive(Debug, Clone)]
pub struct Scv {
    name: &'static str,
    side: usize,
    template: Vec<f32>,
    regions: Regions,
    maps: Vec<PlMap>,
    fits: Vec<MapFit>,
    /// `m(I*)` per pixel.
    mapped: Vec<f32>,
    /// `m'(I*)^2` per pixel, and whether it is 1 everywhere (identity map).
    slope_sq: Vec<f32>,
    unit_slope: bool,
    /// `m'(I*)` per pixel.
    slope: Vec<f32>,
    /// Where each template pixel falls on the maps' nodes ([`PlMap::locate`]): fixed with the
    /// template, so a new map costs a table lookup per pixel.
    located: Vec<(u8, f64)>,
}

impl Scv {
    pub(crate) fn new(name: &'static str, side: usize) -> Self {
        Scv {
            name,
            side,
            template: Vec::new(),
            regions: Regions::default(),
            maps: Vec::new(),
            fits: Vec::new(),
            mapped: Vec::new(),
            slope_sq: Vec::new(),
            unit_slope: true,
            slope: Vec::new(),
            located: Vec::new(),
        }
    }

    /// Recomputes the mapped template and its slope from the maps.
    fn apply_maps(&mut self) {
        let mut unit = true;
        for i in 0..self.template.len() {
            let (k, f) = self.located[i];
            let (mut v, mut s) = (0.0, 0.0);
            for &(r, w) in &self.regions.weights[i] {
                if w != 0.0 {
                    let (mv, ms) = self.maps[r as usize].eval_at(k as usize, f);
                    v += w as f64 * mv;
                    s += w as f64 * ms;
                }
            }
            self.mapped[i] = v as f32;
            self.slope[i] = s as f32;
            self.slope_sq[i] = (s * s) as f32;
            unit &= (s - 1.0).abs() < 1e-12;
        }
        self.unit_slope = unit;
    }

    fn value(&self, current: &[f32]) -> f64 {
        -0.5 * super::ssd::sum_sq_diff(&self.mapped, current)
    }
}

impl Am for Scv {
    fn name(&self) -> &'static str {
        self.name
    }
    /// LSCV's regions are blocks of the square grid (SCV has one).
    fn needs_grid(&self) -> bool {
        self.side > 1
    }
    // With respect to the current pixels: the residual against the mapped template and `-Id`
    // (see the module's documentation), so the forward methods take the moments' system.
    fn hessian_is_minus_jtj(&self) -> bool {
        true
    }
    fn set_template(&mut self, template: &[f32]) {
        let n = template.len();
        self.template.clear();
        self.template.extend_from_slice(template);
        if self.regions.weights.len() != n {
            self.regions = Regions::new(n, self.side);
        }
        let count = self.regions.count();
        self.maps.clear();
        self.maps.resize(count, PlMap::identity());
        self.fits.resize(count, MapFit::default());
        self.mapped.resize(n, 0.0);
        self.slope.resize(n, 0.0);
        self.slope_sq.resize(n, 0.0);
        self.located.clear();
        self.located.extend(template.iter().map(|&t| {
            let (k, f) = PlMap::locate(t as f64);
            (k as u8, f)
        }));
        self.apply_maps();
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.value(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        match wrt {
            // The residual and its sum of squares in one pass.
            Wrt::Current => return -0.5 * super::ssd::residual(&self.mapped, current, 1.0, grad),
            Wrt::Template => {
                for (((g, &t), &c), &s) in grad
                    .iter_mut()
                    .zip(&self.mapped)
                    .zip(current)
                    .zip(&self.slope)
                {
                    *g = s * (c - t);
                }
            }
        }
        self.value(current)
    }
    fn hessian(
        &mut self,
        wrt: Wrt,
        _kind: HessianKind,
        _current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        if wrt == Wrt::Current || self.unit_slope {
            minus_jtj(jac, dof, out);
        } else {
            jt_diag_j(jac, &self.slope_sq, dof, out);
            out.iter_mut().for_each(|v| *v = -*v);
        }
    }
    fn updates_model(&self) -> bool {
        true
    }
    fn update_model(&mut self, current: &[f32]) {
        if current.len() != self.template.len() {
            return;
        }
        self.fits.iter_mut().for_each(MapFit::clear);
        for (i, (&(k, f), &c)) in self.located.iter().zip(current).enumerate() {
            for &(r, w) in &self.regions.weights[i] {
                if w != 0.0 {
                    self.fits[r as usize].add_at(k as usize, f, c as f64, w as f64);
                }
            }
        }
        for (fit, map) in self.fits.iter().zip(self.maps.iter_mut()) {
            fit.solve(map);
        }
        self.apply_maps();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    use crate::am::tests::patch;

    #[test]
    fn invariant_to_gain_and_bias_after_a_model_update() {
        let mut rng = Rng::new(3);
        let t = patch(&mut rng, 400);
        let lit: Vec<f32> = t.iter().map(|&v| 0.7 * v + 40.0).collect();
        let mut scv = Scv::new("scv", 1);
        scv.set_template(&t);
        let before = scv.similarity(&lit);
        assert!(before < -1e4);
        scv.update_model(&lit);
        assert!(scv.similarity(&lit).abs() < 1e-3 * before.abs() * 1e-3);
        // The mapped template is the lit one, and a shifted patch is worse.
        let worse: Vec<f32> = lit.iter().rev().copied().collect();
        assert!(scv.similarity(&worse) < -1e4);
        // set_template resets the map.
        scv.set_template(&t);
        assert_eq!(scv.similarity(&t), 0.0);
    }

    #[test]
    fn follows_a_non_linear_intensity_change() {
        let mut rng = Rng::new(4);
        let t = patch(&mut rng, 2500);
        let gamma: Vec<f32> = t
            .iter()
            .map(|&v| 255.0 * (v / 255.0).powf(0.6) + rng.range(-2.0, 2.0) as f32)
            .collect();
        let mut scv = Scv::new("scv", 1);
        scv.set_template(&t);
        scv.update_model(&gamma);
        // What is left is about the noise (variance 4/3 per pixel).
        let per_px = -2.0 * scv.similarity(&gamma) / 2500.0;
        assert!(per_px < 2.0, "{per_px}");
    }

    #[test]
    fn template_derivatives_through_a_non_trivial_map() {
        // FD of f(I*) with the map held fixed (small steps: the slope jumps at the nodes).
        let mut rng = Rng::new(5);
        let n = 64;
        let t = patch(&mut rng, n);
        let c: Vec<f32> = t
            .iter()
            .map(|&v| 255.0 * (v / 255.0).powf(1.5) + rng.range(-10.0, 10.0) as f32)
            .collect();
        let mut scv = Scv::new("scv", 1);
        scv.set_template(&t);
        scv.update_model(&c);
        let mut g = vec![0f32; n];
        scv.gradient(Wrt::Template, &c, &mut g);
        let f_of = |scv: &Scv, i: usize, x: f64| -> f64 {
            let (mut v, _) = scv.maps[0].eval(x);
            v -= c[i] as f64;
            -0.5 * v * v
        };
        for i in 0..n {
            let (x, h) = (t[i] as f64, 1e-4);
            let fd = (f_of(&scv, i, x + h) - f_of(&scv, i, x - h)) / (2.0 * h);
            assert!(
                (fd - g[i] as f64).abs() < 1e-2 * (1.0 + fd.abs()),
                "{i}: {fd} {}",
                g[i]
            );
        }
        // The Hessian wrt the template is -J^T diag(m'^2) J.
        let jac: Vec<f32> = (0..2 * n).map(|_| rng.range(-1.0, 1.0) as f32).collect();
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        scv.hessian(Wrt::Template, HessianKind::Newton, &c, &jac, 2, &mut h);
        let want: f64 = (0..n)
            .map(|i| -(scv.slope[i] as f64).powi(2) * (jac[i] as f64) * (jac[n + i] as f64))
            .sum();
        assert!((h[1] - want).abs() < 1e-4 * want.abs().max(1.0));
    }
}
