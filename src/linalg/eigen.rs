//! Eigen-decompositions of small symmetric matrices: the negative semi-definite part of a
//! Hessian, which the AMs without a concave similarity (RIU, SSIM, MI's Newton Hessian) take so
//! that a Newton step goes uphill.

use super::{MAX_DOF, Square};

/// Replaces the symmetric `dof x dof` matrix in `h` (row-major) by its negative semi-definite
/// part (cyclic Jacobi eigen-decomposition, positive eigenvalues set to zero).
pub fn negative_part(h: &mut Square, dof: usize) {
    // The eigenvectors and the rotated matrix on the stack, of a stride that fits `dof`.
    if dof <= 8 {
        jacobi::<8, 64>(h, dof);
    } else {
        jacobi::<MAX_DOF, { MAX_DOF * MAX_DOF }>(h, dof);
    }
}

/// [`negative_part`] with scratch matrices of stride `S` (`SS = S * S`, `dof <= S`).
fn jacobi<const S: usize, const SS: usize>(h: &mut Square, dof: usize) {
    let n = dof;
    let mut a = [0.0f64; SS];
    let mut e = [0.0f64; SS];
    for i in 0..n {
        for j in 0..n {
            a[i * S + j] = 0.5 * (h[i * n + j] + h[j * n + i]);
        }
        e[i * S + i] = 1.0;
    }
    for _sweep in 0..60 {
        let mut off = 0.0;
        let mut total = 0.0;
        for i in 0..n {
            for j in 0..n {
                let v = a[i * S + j] * a[i * S + j];
                total += v;
                if i != j {
                    off += v;
                }
            }
        }
        if off <= 1e-30 * total || total == 0.0 {
            break;
        }
        for p in 0..n {
            for r in p + 1..n {
                let apr = a[p * S + r];
                if apr == 0.0 {
                    continue;
                }
                let (app, arr) = (a[p * S + p], a[r * S + r]);
                let theta = (arr - app) / (2.0 * apr);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akr) = (a[k * S + p], a[k * S + r]);
                    a[k * S + p] = c * akp - s * akr;
                    a[k * S + r] = s * akp + c * akr;
                }
                for k in 0..n {
                    let (apk, ark) = (a[p * S + k], a[r * S + k]);
                    a[p * S + k] = c * apk - s * ark;
                    a[r * S + k] = s * apk + c * ark;
                }
                for k in 0..n {
                    let (ekp, ekr) = (e[k * S + p], e[k * S + r]);
                    e[k * S + p] = c * ekp - s * ekr;
                    e[k * S + r] = s * ekp + c * ekr;
                }
            }
        }
    }
    for i in 0..n {
        for j in 0..n {
            let mut v = 0.0;
            for k in 0..n {
                let l = a[k * S + k];
                if l < 0.0 {
                    v += l * e[i * S + k] * e[j * S + k];
                }
            }
            h[i * n + j] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The negative part of `A = Q diag(l) Q^T` is `Q diag(min(l, 0)) Q^T`: for random
    /// symmetric matrices of every size, a negative definite one is kept, a positive one
    /// vanishes, and the part is negative semi-definite and within 1e-9 of its definition.
    #[test]
    fn the_negative_part_keeps_the_negative_eigenvalues() {
        let mut rng = Rng::new(7);
        for n in 1..=MAX_DOF {
            // A random orthogonal Q (QR of a random matrix) and eigenvalues of both signs.
            let m = nalgebra::DMatrix::from_fn(n, n, |_, _| rng.normal());
            let q = m.qr().q();
            let l: Vec<f64> = (0..n)
                .map(|k| {
                    if k % 2 == 0 {
                        -1.0 - k as f64
                    } else {
                        0.5 + k as f64
                    }
                })
                .collect();
            let build = |f: &dyn Fn(f64) -> f64| {
                let d = nalgebra::DMatrix::from_fn(n, n, |i, j| if i == j { f(l[i]) } else { 0.0 });
                &q * d * q.transpose()
            };
            // The negative part of the matrix `m`, by `negative_part`.
            let negative = |m: &nalgebra::DMatrix<f64>| {
                let mut h = [0.0; MAX_DOF * MAX_DOF];
                for i in 0..n {
                    for j in 0..n {
                        h[i * n + j] = m[(i, j)];
                    }
                }
                negative_part(&mut h, n);
                nalgebra::DMatrix::from_fn(n, n, |i, j| h[i * n + j])
            };
            let close =
                |a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>| (a - b).abs().max() < 1e-9;
            // Both signs; negative definite kept; positive definite gone.
            assert!(
                close(&negative(&build(&|x| x)), &build(&|x| x.min(0.0))),
                "{n}"
            );
            let neg = build(&|x| -x.abs());
            assert!(close(&negative(&neg), &neg), "{n}");
            let zero = nalgebra::DMatrix::zeros(n, n);
            assert!(close(&negative(&build(&|x| x.abs())), &zero), "{n}");
        }
    }
}
