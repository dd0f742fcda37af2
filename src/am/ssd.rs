//! Sum of squared differences: `f = -1/2 sum_i (I*_i - I_i)^2`.

use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::linalg::minus_jtj;
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

/// Samples a block of [`residual`]'s sums (eight lanes within it, f64 across blocks).
const BLOCK: usize = 256;
/// Blocks [`residual`] sums side by side.
const SIDE_BY_SIDE: usize = 4;

/// `grad_i = sign (t_i - c_i)` and, in the same pass, `sum_i (t_i - c_i)^2`: eight lanes within
/// blocks of 256 samples, f64 across blocks. Four whole blocks at a time, side by side (four
/// independent chains of multiply-adds instead of one), each block's lanes summed in the order
/// of one block at a time, so the same bits.
pub(crate) fn residual(template: &[f32], current: &[f32], sign: f32, grad: &mut [f32]) -> f64 {
    let n = template.len().min(current.len()).min(grad.len());
    let mut total = 0.0f64;
    let group = SIDE_BY_SIDE * BLOCK;
    let grouped = n / group * group;
    for ((ct, cc), cg) in template[..grouped]
        .chunks_exact(group)
        .zip(current[..grouped].chunks_exact(group))
        .zip(grad[..grouped].chunks_exact_mut(group))
    {
        let mut lanes: [Lanes; SIDE_BY_SIDE] = [[0.0; 8]; SIDE_BY_SIDE];
        for j in (0..BLOCK).step_by(8) {
            for (b, acc) in lanes.iter_mut().enumerate() {
                let i = b * BLOCK + j;
                let t: &Lanes = ct[i..i + 8].try_into().expect("eight samples");
                let c: &Lanes = cc[i..i + 8].try_into().expect("eight samples");
                let g: &mut Lanes = (&mut cg[i..i + 8]).try_into().expect("eight samples");
                for l in 0..8 {
                    let d = t[l] - c[l];
                    g[l] = sign * d;
                    acc[l] = d.mul_add(d, acc[l]);
                }
            }
        }
        for acc in &lanes {
            total += (acc.iter().sum::<f32>() + 0.0) as f64;
        }
    }
    let (template, current) = (&template[grouped..n], &current[grouped..n]);
    for ((ct, cc), cg) in template
        .chunks(BLOCK)
        .zip(current.chunks(BLOCK))
        .zip(grad[grouped..n].chunks_mut(BLOCK))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocks side by side give the bits of one block at a time (each block's eight lanes,
    /// then the blocks in order), whole groups, single blocks and the short last one alike.
    #[test]
    fn the_residual_side_by_side_is_block_by_block() {
        let mut rng = crate::rng::Rng::new(9);
        for n in [0, 7, 256, 1000, 1024, 2500, 4109] {
            let t: Vec<f32> = (0..n).map(|_| rng.range(0.0, 255.0) as f32).collect();
            let c: Vec<f32> = (0..n).map(|_| rng.range(0.0, 255.0) as f32).collect();
            let mut grad = vec![0.0; n];
            let total = residual(&t, &c, -1.0, &mut grad);
            // Block by block: the same sums in the same order.
            let mut want = 0.0f64;
            for (ct, cc) in t.chunks(BLOCK).zip(c.chunks(BLOCK)) {
                let mut lanes: Lanes = [0.0; 8];
                let mut tail = 0.0f32;
                for (i, (x, y)) in ct.iter().zip(cc).enumerate() {
                    let d = x - y;
                    if i < ct.len() / 8 * 8 {
                        lanes[i % 8] = d.mul_add(d, lanes[i % 8]);
                    } else {
                        tail += d * d;
                    }
                }
                want += (lanes.iter().sum::<f32>() + tail) as f64;
            }
            assert_eq!(total.to_bits(), want.to_bits(), "{n} samples");
            for ((g, x), y) in grad.iter().zip(&t).zip(&c) {
                assert_eq!(g.to_bits(), (-(x - y)).to_bits());
            }
            assert_eq!(sum_sq_diff(&t, &c).to_bits(), want.to_bits(), "{n} samples");
        }
    }
}
