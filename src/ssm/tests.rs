//! Finite-difference checks of every SSM's Jacobian, and compose / invert / fit round trips.

use super::*;
use proptest::prelude::*;

fn params(ssm: &dyn Ssm, raw: &[f64], scale: f64) -> Params {
    let mut p = [0.0; MAX_DOF];
    for k in 0..ssm.dof() {
        p[k] = raw[k] * scale;
    }
    p
}

fn warp(ssm: &dyn Ssm, p: &Params, x: f64, y: f64) -> Point {
    let mut out = [Point::default()];
    ssm.warp_points(p, &[Point::new(x, y)], &mut out);
    out[0]
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(11), ..ProptestConfig::default() })]

    #[test]
    fn jacobians_match_finite_differences(raw in prop::collection::vec(-1.0f64..1.0, MAX_DOF), x in -0.7f64..0.7, y in -0.7f64..0.7) {
        for e in REGISTRY {
            let ssm = (e.build)();
            let s = ssm.dof();
            // Moderate warps: the projective terms smaller so the point stays far from infinity.
            let mut p = params(&*ssm, &raw, 0.15);
            if s == 8 && ssm.name() != "corner" { p[6] *= 0.3; p[7] *= 0.3; }
            let mut jac = vec![0f32; 2 * s];
            ssm.jacobian(&p, &[x as f32], &[y as f32], &mut jac);
            let h = 1e-6;
            for k in 0..s {
                let (mut pp, mut pm) = (p, p);
                pp[k] += h;
                pm[k] -= h;
                let (a, b) = (warp(&*ssm, &pp, x, y), warp(&*ssm, &pm, x, y));
                let (fx, fy) = ((a.x - b.x) / (2.0 * h), (a.y - b.y) / (2.0 * h));
                // One point: out[2k] = dx/dp_k, out[2k + 1] = dy/dp_k.
                prop_assert!(close(jac[2 * k] as f64, fx, 1e-4), "{} dx/dp{}: {} vs {}", ssm.name(), k, jac[2 * k], fx);
                prop_assert!(close(jac[2 * k + 1] as f64, fy, 1e-4), "{} dy/dp{}: {} vs {}", ssm.name(), k, jac[2 * k + 1], fy);
            }
        }
    }

    #[test]
    fn compose_invert_and_fit_round_trip(a in prop::collection::vec(-1.0f64..1.0, MAX_DOF), b in prop::collection::vec(-1.0f64..1.0, MAX_DOF)) {
        let base = Quad::unit_square();
        for e in REGISTRY {
            let ssm = (e.build)();
            if !ssm.projective() {
                continue;
            }
            let p = params(&*ssm, &a, 0.1);
            let q = params(&*ssm, &b, 0.1);
            // compose matches the matrix product (up to scale).
            let c = ssm.compose(&p, &q).unwrap();
            let lhs = warp_quad(&*ssm, &c, &base);
            let rhs = warp_quad(&*ssm, &p, &warp_quad(&*ssm, &q, &base));
            prop_assert!(lhs.change_norm(&rhs) < 1e-9, "{} compose", ssm.name());
            // p o p^-1 = identity.
            let inv = ssm.invert(&p).unwrap();
            let id = ssm.compose(&p, &inv).unwrap();
            prop_assert!(warp_quad(&*ssm, &id, &base).change_norm(&base) < 1e-9, "{} invert", ssm.name());
            // params_from_matrix(matrix(p)) = p.
            let back = ssm.params_from_matrix(&ssm.matrix(&p)).unwrap();
            for k in 0..ssm.dof() { prop_assert!((back[k] - p[k]).abs() < 1e-9, "{} params_from_matrix", ssm.name()); }
            // Fitting the warped corners gives the warp back.
            let target = warp_quad(&*ssm, &p, &base);
            let fit = ssm.fit(&base.0, &target.0).unwrap();
            prop_assert!(warp_quad(&*ssm, &fit, &base).change_norm(&target) < 1e-9, "{} fit", ssm.name());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, rng_seed: proptest::test_runner::RngSeed::Fixed(13), ..ProptestConfig::default() })]

    /// The non-rigid models, on a skewed quad: their compositions and inverses (projections
    /// onto the model) take the quad's corners where the composed (inverted) fields do; the
    /// rest of the quad to second order in the deformations; the fit of a homography moves the
    /// corners onto its targets; the matrix is the homography through the moved corners; a
    /// homography after the warp moves the corners and keeps the shape.
    #[test]
    fn non_rigid_compose_invert_and_fit_follow_the_fields(a in prop::collection::vec(-1.0f64..1.0, MAX_DOF), b in prop::collection::vec(-1.0f64..1.0, MAX_DOF)) {
        let base = Quad::from_array([-0.6, -0.4, 0.5, -0.5, 0.55, 0.6, -0.45, 0.5]);
        for e in REGISTRY {
            let mut ssm = (e.build)();
            if ssm.projective() {
                continue;
            }
            ssm.set_base(&base.0);
            let p = params(&*ssm, &a, 0.01);
            let q = params(&*ssm, &b, 0.01);
            let c = ssm.compose(&p, &q).unwrap();
            let lhs = warp_quad(&*ssm, &c, &base);
            let rhs = warp_quad(&*ssm, &p, &warp_quad(&*ssm, &q, &base));
            prop_assert!(lhs.change_norm(&rhs) < 1e-6, "{} compose: {}", ssm.name(), lhs.change_norm(&rhs));
            // Inside: the composed field at the quad's centre and mid-edges.
            let inside = [Point::new(0.0, 0.05), Point::new(-0.05, -0.45), Point::new(0.52, 0.05)];
            for x in inside {
                let got = warp(&*ssm, &c, x.x, x.y);
                let mid = warp(&*ssm, &q, x.x, x.y);
                let want = warp(&*ssm, &p, mid.x, mid.y);
                // What the model misses of a composition is of second order in the
                // deformations (products of one's gradient, of the control points' spacing, and
                // the other).
                let size = p.iter().chain(&q).fold(0.0f64, |m, v| m.max(v.abs()));
                prop_assert!(got.dist(want) <= 0.2 * ssm.dof() as f64 * size * size + 1e-12, "{} compose at {x:?}: {got:?} vs {want:?}", ssm.name());
            }
            let inv = ssm.invert(&p).unwrap();
            let id = ssm.compose(&p, &inv).unwrap();
            prop_assert!(warp_quad(&*ssm, &id, &base).change_norm(&base) < 1e-6, "{} invert", ssm.name());
            let target = Quad::from_array([-0.62, -0.38, 0.53, -0.52, 0.5, 0.64, -0.47, 0.46]);
            let fit = ssm.fit(&base.0, &target.0).unwrap();
            prop_assert!(warp_quad(&*ssm, &fit, &base).change_norm(&target) < 1e-6, "{} fit", ssm.name());
            let m = ssm.matrix(&p);
            let moved = warp_quad(&*ssm, &p, &base);
            prop_assert!(base.map(|x| apply_homography(&m, x)).change_norm(&moved) < 1e-9, "{} matrix", ssm.name());
            // A homography after the warp (a prediction's motion): the corners where it takes
            // them, the warp's shape between them kept (a pure translation moves every point).
            let shift = nalgebra::Matrix3::new(1.0, 0.0, 0.03, 0.0, 1.0, -0.02, 0.0, 0.0, 1.0);
            let after = ssm.then_matrix(&p, &shift).unwrap();
            let want = moved.map(|x| apply_homography(&shift, x));
            prop_assert!(warp_quad(&*ssm, &after, &base).change_norm(&want) < 1e-6, "{} then_matrix", ssm.name());
            let (x, y) = (0.1, -0.05);
            let (a, b) = (warp(&*ssm, &after, x, y), warp(&*ssm, &p, x, y));
            prop_assert!((a.x - b.x - 0.03).abs() < 1e-9 && (a.y - b.y + 0.02).abs() < 1e-9, "{} then_matrix inside", ssm.name());
        }
    }
}

/// A non-rigid model's basis gradients (its point Jacobians' parts) are the finite differences
/// of its basis (`dw/dp`) across the quad and past it, on a skewed quad.
#[test]
fn non_rigid_basis_gradients_match_finite_differences() {
    let base = Quad::from_array([-0.6, -0.4, 0.5, -0.5, 0.55, 0.6, -0.45, 0.5]);
    let mut rng = crate::rng::Rng::new(29);
    let mut checked = 0;
    for e in REGISTRY {
        let mut ssm = (e.build)();
        if ssm.projective() {
            let mut out = [f32::NAN];
            assert!(!ssm.basis_gradients(&[0.0], &[0.0], &mut out) && out[0].is_nan());
            continue;
        }
        ssm.set_base(&base.0);
        let (dof, id) = (ssm.dof(), ssm.identity());
        for _ in 0..40 {
            let (x, y) = (rng.range(-0.75, 0.75), rng.range(-0.75, 0.75));
            let mut grad = vec![0f32; dof];
            assert!(ssm.basis_gradients(&[x as f32], &[y as f32], &mut grad));
            let phi = |x: f64, y: f64| {
                let mut jac = vec![0f32; 2 * dof];
                ssm.jacobian(&id, &[x as f32], &[y as f32], &mut jac);
                // phi_k is dw_x / dp_2k.
                (0..dof / 2).map(|k| jac[4 * k] as f64).collect::<Vec<_>>()
            };
            let h = 1e-3;
            let (xp, xm, yp, ym) = (phi(x + h, y), phi(x - h, y), phi(x, y + h), phi(x, y - h));
            for k in 0..dof / 2 {
                let (fx, fy) = ((xp[k] - xm[k]) / (2.0 * h), (yp[k] - ym[k]) / (2.0 * h));
                let (gx, gy) = (grad[2 * k] as f64, grad[2 * k + 1] as f64);
                assert!(
                    close(gx, fx, 2e-3) && close(gy, fy, 2e-3),
                    "{} phi{k} at ({x}, {y}): ({gx}, {gy}) vs ({fx}, {fy})",
                    ssm.name()
                );
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 4 * 40);
}

#[test]
fn fit_is_the_least_squares_projection() {
    // A perspective quad projected onto each SSM: no small change of the fitted parameters may
    // lower the corner error (the fit is the least-squares optimum).
    let src = Quad::from_rect(-0.5, -0.5, 1.0, 1.0);
    let dst = Quad::from_array([-0.45, -0.6, 0.52, -0.41, 0.61, 0.55, -0.58, 0.47]);
    for e in REGISTRY {
        let ssm = (e.build)();
        let p = ssm.fit(&src.0, &dst.0).unwrap();
        let err = |p: &Params| {
            let q = warp_quad(&*ssm, p, &src);
            q.0.iter()
                .zip(&dst.0)
                .map(|(a, b)| (a.x - b.x).powi(2) + (a.y - b.y).powi(2))
                .sum::<f64>()
        };
        let e0 = err(&p);
        for k in 0..ssm.dof() {
            for d in [1e-4, -1e-4] {
                let mut q = p;
                q[k] += d;
                assert!(
                    err(&q) >= e0 - 1e-12,
                    "{}: p{} {} lowers the error",
                    ssm.name(),
                    k,
                    d
                );
            }
        }
        if ssm.dof() == 8 {
            assert!(e0 < 1e-18, "{} must fit four corners exactly", ssm.name());
        }
    }
}

#[test]
fn registry_resolves_mtf_aliases() {
    for (alias, name) in [
        ("2", "translation"),
        ("3", "isometry"),
        ("4", "similitude"),
        ("6", "affine"),
        ("8", "homography"),
        ("sl3", "sl3"),
        ("c8", "corner"),
        ("ist", "ist"),
        ("ast", "ast"),
    ] {
        assert_eq!(build(alias).unwrap().name(), name);
    }
    let err = build("bogus").unwrap_err().to_string();
    assert!(
        err.contains("bogus") && err.contains("homography") && err.contains("translation"),
        "{err}"
    );
}

#[test]
fn every_model_names_each_of_its_parameters_once() {
    for e in REGISTRY {
        let ssm = (e.build)();
        let names = ssm.param_names();
        assert_eq!(names.len(), ssm.dof(), "{}", ssm.name());
        let mut sorted = names.to_vec();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), names.len(), "{}: {names:?}", ssm.name());
    }
}

/// Every model's closed-form projection at the identity (where it has one) is the projection of
/// the gradients on its Jacobian's rows there, for points and gradients of every sign; the
/// homography, affine and translation models have one.
#[test]
fn projections_at_the_identity_are_those_on_the_jacobian() {
    let mut rng = crate::rng::Rng::new(23);
    let mut with_form = Vec::new();
    for e in REGISTRY {
        let ssm = (e.build)();
        let dof = ssm.dof();
        for n in [0usize, 1, 7, 37, 2500] {
            let xs: Vec<f32> = (0..n).map(|_| rng.range(-0.6, 0.6) as f32).collect();
            let ys: Vec<f32> = (0..n).map(|_| rng.range(-0.6, 0.6) as f32).collect();
            let gx: Vec<f32> = (0..n).map(|_| rng.range(-300.0, 300.0) as f32).collect();
            let gy: Vec<f32> = (0..n).map(|_| rng.range(-300.0, 300.0) as f32).collect();
            let mut fast = vec![f32::NAN; dof * n];
            if !ssm.project_at_identity(&gx, &gy, &xs, &ys, &mut fast) {
                assert!(
                    fast.iter().all(|v| v.is_nan()),
                    "{}: jac touched",
                    ssm.name()
                );
                continue;
            }
            let mut dwdp = vec![0f32; 2 * dof * n];
            ssm.jacobian(&ssm.identity(), &xs, &ys, &mut dwdp);
            // The projection written plainly: J_k = gx dw_x/dp_k + gy dw_y/dp_k.
            let dense: Vec<f32> = (0..dof * n)
                .map(|at| {
                    let (k, i) = (at / n, at % n);
                    gx[i] * dwdp[2 * k * n + i] + gy[i] * dwdp[(2 * k + 1) * n + i]
                })
                .collect();
            for k in 0..dof * n {
                assert!(
                    fast[k] == dense[k],
                    "{} n {n}: row {} point {}: {} vs {}",
                    ssm.name(),
                    k / n,
                    k % n,
                    fast[k],
                    dense[k]
                );
            }
            with_form.push(ssm.name());
        }
    }
    with_form.dedup();
    assert_eq!(with_form, ["translation", "affine", "homography"]);
}
