//! Sum of squared differences: `f = -1/2 sum_i (I*_i - I_i)^2`.

use super::{Am, AmBuilder, HessianKind, Wrt, minus_jtj};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "ssd",
    aliases: &[],
    description: "sum of squared differences",
    build: AmBuilder::plain(|_| Box::new(Ssd::default())),
};

#[derive(Debug, Default, Clone)]
pub struct Ssd {
    template: Vec<f32>,
}

impl Am for Ssd {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    fn hessian_is_minus_jtj(&self) -> bool {
        true
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        -0.5 * sum_sq_diff(&self.template, current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let sign = match wrt {
            Wrt::Current => 1.0,
            Wrt::Template => -1.0,
        };
        -0.5 * residual(&self.template, current, sign, grad)
    }
    fn hessian(
        &mut self,
        _wrt: Wrt,
        _kind: HessianKind,
        _current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        // d2f/dI2 = -Id for both arguments and every kind.
        minus_jtj(jac, dof, out);
    }
}

/// Eight f32 lanes.
type Lanes = [f32; 8];

/// `sum_i (a_i - b_i)^2`: eight lanes within blocks of 256 pixels, f64 across blocks.
pub(crate) fn sum_sq_diff(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let mut lanes: Lanes = [0.0; 8];
        let (ea, eb) = (ca.chunks_exact(8), cb.chunks_exact(8));
        let tail: f32 = ea
            .remainder()
            .iter()
            .zip(eb.remainder())
            .map(|(x, y)| (x - y) * (x - y))
            .sum();
        for (x, y) in ea.zip(eb) {
            for l in 0..8 {
                let d = x[l] - y[l];
                lanes[l] = d.mul_add(d, lanes[l]);
            }
        }
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}

/// `grad_i = sign (t_i - c_i)` and, in the same pass, `sum_i (t_i - c_i)^2`.
pub(crate) fn residual(template: &[f32], current: &[f32], sign: f32, grad: &mut [f32]) -> f64 {
    let mut total = 0.0f64;
    for ((ct, cc), cg) in template
        .chunks(256)
        .zip(current.chunks(256))
        .zip(grad.chunks_mut(256))
    {
        let mut lanes: Lanes = [0.0; 8];
        let (mut et, mut ec, mut eg) = (
            ct.chunks_exact(8),
            cc.chunks_exact(8),
            cg.chunks_exact_mut(8),
        );
        for ((t, c), g) in (&mut et).zip(&mut ec).zip(&mut eg) {
            for l in 0..8 {
                let d = t[l] - c[l];
                g[l] = sign * d;
                lanes[l] = d.mul_add(d, lanes[l]);
            }
        }
        let mut tail = 0.0f32;
        for ((t, c), g) in et
            .remainder()
            .iter()
            .zip(ec.remainder())
            .zip(eg.into_remainder())
        {
            let d = t - c;
            *g = sign * d;
            tail += d * d;
        }
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}
