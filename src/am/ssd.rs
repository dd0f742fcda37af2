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
        for ((g, &t), &c) in grad.iter_mut().zip(&self.template).zip(current) {
            *g = sign * (t - c);
        }
        -0.5 * sum_sq_diff(&self.template, current)
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

fn sum_sq_diff(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let s: f32 = ca.iter().zip(cb).map(|(x, y)| (x - y) * (x - y)).sum();
        total += s as f64;
    }
    total
}
