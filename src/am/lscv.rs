//! Localised sum of conditional variance (LSCV, Richa et al. 2014): SCV ([`super::scv`]) with
//! one intensity map per sub-region, so that lighting that varies across the target is followed.
//!
//! The square `res x res` sampling grid (row-major, `res = sqrt(N)`) is split into `3 x 3`
//! blocks; each block has its own map `m_r(t) ~ E[I | I* = t]`, fitted in
//! [`Am::update_model`] from the pixels weighted by `a_r(x)`, and the map at pixel `x` blends the
//! maps of the (up to four) nearest block centres bilinearly,
//! `m(x, t) = sum_r a_r(x) m_r(t)` (the weights are clamped at the border blocks and sum to one),
//! so the mapped template has no seams at block borders. A pixel's data thus shapes exactly the
//! maps that will be applied to it. A non-square patch (or one with fewer than 6 pixels a side)
//! falls back to one region, i.e. SCV.
//!
//! The pixel positions being fixed, `m(x_i, .)` is a fixed function of the template intensity
//! per pixel and the derivatives are SCV's: `df/dI = m(x, I*) - I`, `d2f/dI2 = -Id`;
//! `df/dI*_i = m'(x_i, I*_i) (I_i - m(x_i, I*_i))`, `d2f/dI*_i^2 = -m'(x_i, I*_i)^2`, for every
//! Hessian kind.

use super::AmBuilder;
use super::scv::Scv;
use crate::registry::Entry;

/// Blocks per side of the patch.
pub const SIDE: usize = 3;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "lscv",
    aliases: &[],
    description: "localised SCV (3x3 sub-region intensity maps blended bilinearly)",
    build: || Box::new(Scv::new(ENTRY.name, SIDE)),
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn follows_light_that_varies_across_the_target() {
        let res = 50;
        let mut rng = Rng::new(23);
        let t: Vec<f32> = (0..res * res)
            .map(|_| rng.range(20.0, 230.0) as f32)
            .collect();
        // Gain from 0.6 to 1.3 left to right, bias from -10 to 30 top to bottom.
        let lit: Vec<f32> = t
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let (x, y) = ((i % res) as f32 / res as f32, (i / res) as f32 / res as f32);
                (0.6 + 0.7 * x) * v - 10.0 + 40.0 * y
            })
            .collect();
        let mut scv = (crate::am::scv::ENTRY.build)();
        let mut lscv = (ENTRY.build)();
        for am in [&mut scv, &mut lscv] {
            am.set_template(&t);
            am.update_model(&lit);
        }
        let (fs, fl) = (scv.similarity(&lit), lscv.similarity(&lit));
        // Per pixel RMS residual: SCV's global map cannot follow the gradient, LSCV's can.
        let rms = |f: f64| (-2.0 * f / (res * res) as f64).sqrt();
        assert!(rms(fs) > 15.0, "scv {}", rms(fs));
        assert!(
            rms(fl) < 0.25 * rms(fs),
            "lscv {} vs scv {}",
            rms(fl),
            rms(fs)
        );
        // And the tracker still prefers the true patch to a shifted one.
        let shifted: Vec<f32> = (0..res * res).map(|i| lit[(i + 1) % (res * res)]).collect();
        assert!(lscv.similarity(&shifted) < 4.0 * lscv.similarity(&lit));
    }
}
