//! SL3: 8 DOF homography parameterised by the Lie algebra sl(3), `H = exp(sum_i p_i G_i)` with
//! the generators of Benhimane and Malis (ESM): `G0 = E13, G1 = E23, G2 = E21, G3 = E12,
//! G4 = E11 - E22, G5 = E22 - E33, G6 = E31, G7 = E32` (1-based matrix units).

use super::{Params, Ssm, SsmBuilder, put};
use crate::geometry::{Point, homography_from_points};
use crate::linalg::{expm, expm3_frechet, logm3};
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "sl3",
    aliases: &["lie"],
    description: "8 DOF homography in the SL(3) Lie algebra parameterisation",
    build: || Box::new(Sl3),
};

#[derive(Debug, Clone, Copy)]
pub struct Sl3;

/// The generator `G_k`.
fn generator(k: usize) -> Matrix3<f64> {
    let mut g = Matrix3::zeros();
    match k {
        0 => g[(0, 2)] = 1.0,
        1 => g[(1, 2)] = 1.0,
        2 => g[(1, 0)] = 1.0,
        3 => g[(0, 1)] = 1.0,
        4 => {
            g[(0, 0)] = 1.0;
            g[(1, 1)] = -1.0;
        }
        5 => {
            g[(1, 1)] = 1.0;
            g[(2, 2)] = -1.0;
        }
        6 => g[(2, 0)] = 1.0,
        _ => g[(2, 1)] = 1.0,
    }
    g
}

fn algebra(p: &Params) -> Matrix3<f64> {
    Matrix3::new(p[4], p[3], p[0], p[2], p[5] - p[4], p[1], p[6], p[7], -p[5])
}

impl Ssm for Sl3 {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        8
    }
    fn param_names(&self) -> &'static [&'static str] {
        &[
            "E13 (tx)", "E23 (ty)", "E21", "E12", "E11-E22", "E22-E33", "E31", "E32",
        ]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        expm(&algebra(p))
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let det = m.determinant();
        if !det.is_finite() || det.abs() < 1e-300 {
            return None;
        }
        // Scale to determinant 1 (a negative scale fixes a negative determinant).
        let m = m / det.cbrt();
        let a = logm3(&m)?;
        Some(super::params(&[
            a[(0, 2)],
            a[(1, 2)],
            a[(1, 0)],
            a[(0, 1)],
            a[(0, 0)],
            -a[(2, 2)],
            a[(2, 0)],
            a[(2, 1)],
        ]))
    }
    fn jacobian(&self, p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let a = algebra(p);
        let h = expm(&a);
        let at_identity = p.iter().all(|&v| v == 0.0);
        // dH/dp_k, as the 8 matrix entries' derivatives (the (2,2) entry is kept too: H is not
        // normalised to h33 = 1 here).
        let dh: [Matrix3<f64>; 8] = std::array::from_fn(|k| {
            if at_identity {
                generator(k)
            } else {
                expm3_frechet(&a, &generator(k))
            }
        });
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            let (x, y) = (x as f64, y as f64);
            let w = h[(2, 0)] * x + h[(2, 1)] * y + h[(2, 2)];
            let wx = (h[(0, 0)] * x + h[(0, 1)] * y + h[(0, 2)]) / w;
            let wy = (h[(1, 0)] * x + h[(1, 1)] * y + h[(1, 2)]) / w;
            for (k, d) in dh.iter().enumerate() {
                let dx = d[(0, 0)] * x + d[(0, 1)] * y + d[(0, 2)];
                let dy = d[(1, 0)] * x + d[(1, 1)] * y + d[(1, 2)];
                let dw = d[(2, 0)] * x + d[(2, 1)] * y + d[(2, 2)];
                put(
                    out,
                    n,
                    i,
                    k,
                    ((dx - wx * dw) / w) as f32,
                    ((dy - wy * dw) / w) as f32,
                );
            }
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        self.params_from_matrix(&homography_from_points(src, dst)?)
    }
}
