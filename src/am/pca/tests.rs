use super::*;
use crate::am::tests::{patch, smooth_patch};
use crate::rng::Rng;

/// `v^T S v` for the weighted scatter of `points` about their weighted mean.
fn scatter_along(points: &[Vec<f32>], weights: &[f64], v: &[f64]) -> f64 {
    let total: f64 = weights.iter().sum();
    let n = v.len();
    let mean: Vec<f64> = (0..n)
        .map(|i| {
            points
                .iter()
                .zip(weights)
                .map(|(p, w)| w * p[i] as f64)
                .sum::<f64>()
                / total
        })
        .collect();
    points
        .iter()
        .zip(weights)
        .map(|(p, w)| {
            let d: f64 = (0..n).map(|i| (p[i] as f64 - mean[i]) * v[i]).sum();
            w * d * d
        })
        .sum()
}

/// `v^T U diag(s^2) U^T v` of the model.
fn model_along(am: &Pca, v: &[f64]) -> f64 {
    let n = v.len();
    let (basis, sigma) = am.basis();
    sigma
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let d: f64 = (0..n).map(|i| basis[j * n + i] as f64 * v[i]).sum();
            s * s * d * d
        })
        .sum()
}

#[test]
fn learning_one_patch_at_a_time_gives_the_weighted_scatter_and_mean() {
    let mut rng = Rng::new(3);
    let n = 200;
    for phi in [1.0, 0.8] {
        let mut am = Pca::new(MAX_COMPONENTS, phi);
        let template = patch(&mut rng, n);
        am.set_template(&template);
        let mut points = vec![template.clone()];
        for _ in 0..7 {
            let p = patch(&mut rng, n);
            am.learn(&p);
            points.push(p);
        }
        // Older patches weigh phi per patch learnt since.
        let m = points.len();
        let weights: Vec<f64> = (0..m).map(|j| phi.powi((m - 1 - j) as i32)).collect();
        let total: f64 = weights.iter().sum();
        for i in 0..n {
            let want: f64 = points
                .iter()
                .zip(&weights)
                .map(|(p, w)| w * p[i] as f64)
                .sum::<f64>()
                / total;
            assert!(
                (am.template()[i] as f64 - want).abs() < 1e-3,
                "phi {phi}: mean at {i}"
            );
        }
        assert_eq!(am.basis().1.len(), m - 1, "phi {phi}: rank");
        for _ in 0..10 {
            let v: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
            let (want, got) = (scatter_along(&points, &weights, &v), model_along(&am, &v));
            assert!(
                (want - got).abs() <= 1e-4 * want,
                "phi {phi}: {got} vs {want}"
            );
        }
        // The basis is orthonormal.
        let (basis, sigma) = am.basis();
        for a in 0..sigma.len() {
            for b in 0..sigma.len() {
                let d = dot(&basis[a * n..(a + 1) * n], &basis[b * n..(b + 1) * n]);
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-4, "phi {phi}: u{a} . u{b} = {d}");
            }
        }
    }
}

#[test]
fn it_keeps_the_largest_components_and_forgets_old_directions() {
    let mut rng = Rng::new(4);
    let n = 100;
    let mut am = Pca::new(2, 0.7);
    let t = patch(&mut rng, n);
    am.set_template(&t);
    let dir = |rng: &mut Rng| -> Vec<f32> { (0..n).map(|_| rng.normal() as f32).collect() };
    let (a, b) = (dir(&mut rng), dir(&mut rng));
    let along =
        |d: &[f32], s: f32| -> Vec<f32> { t.iter().zip(d).map(|(t, d)| t + s * d).collect() };
    // Patches along a, then many along b: the basis ends with b first, a faded.
    for s in [-10.0, 10.0, -10.0, 10.0] {
        am.learn(&along(&a, s));
    }
    for s in [-10.0, 10.0].repeat(12) {
        am.learn(&along(&b, s));
    }
    let (basis, sigma) = am.basis();
    assert!(sigma.len() <= 2);
    let norm = |v: &[f32]| dot(v, v).sqrt();
    let cos_b = dot(&basis[..n], &b) / norm(&b);
    assert!(cos_b.abs() > 0.99, "first component along b: {cos_b}");
    assert!(
        sigma.len() < 2 || sigma[1] < 0.1 * sigma[0],
        "a has faded: {sigma:?}"
    );
    // A patch the model spans (the mean plus the first component) is at distance 0.
    let on: Vec<f32> = am
        .template()
        .iter()
        .zip(&basis[..n])
        .map(|(m, u)| m + 40.0 * u)
        .collect();
    assert!(am.similarity(&on).abs() < 1e-2, "{}", am.similarity(&on));
    // Not finite or of another size: nothing learnt.
    let before = (am.template().to_vec(), am.basis().0.to_vec());
    let mut bad = t.clone();
    bad[3] = f32::NAN;
    am.learn(&bad);
    am.learn(&t[..n - 1]);
    assert_eq!((am.template().to_vec(), am.basis().0.to_vec()), before);
}

/// A model that has learnt a few patches near the template.
fn learnt(rng: &mut Rng, n: usize) -> (Pca, Vec<f32>) {
    let mut am = Pca::new(4, 0.9);
    let t = smooth_patch(rng, (n as f64).sqrt() as usize);
    am.set_template(&t);
    for _ in 0..6 {
        let p: Vec<f32> = t
            .iter()
            .map(|v| 0.9 * v + 8.0 + rng.range(-6.0, 6.0) as f32)
            .collect();
        am.learn(&p);
    }
    assert_eq!(am.basis().1.len(), 4);
    (am, t)
}

#[test]
fn derivatives_with_a_learnt_basis_match_finite_differences() {
    let mut rng = Rng::new(8);
    let n = 64;
    let (mut am, t) = learnt(&mut rng, n);
    let mean = am.template().to_vec();
    let c: Vec<f32> = t
        .iter()
        .map(|v| 1.1 * v - 4.0 + rng.range(-9.0, 9.0) as f32)
        .collect();
    for wrt in [Wrt::Current, Wrt::Template] {
        let mut g = vec![0f32; n];
        let f = am.gradient(wrt, &c, &mut g);
        assert!((f - am.similarity(&c)).abs() <= 1e-9 * f.abs());
        let at = |am: &mut Pca, i: usize, h: f32| -> f64 {
            match wrt {
                Wrt::Current => {
                    let mut x = c.clone();
                    x[i] += h;
                    am.similarity(&x)
                }
                Wrt::Template => {
                    let mut m = mean.clone();
                    m[i] += h;
                    am.set_mean(&m);
                    let v = am.similarity(&c);
                    am.set_mean(&mean);
                    v
                }
            }
        };
        let scale = g.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
        for i in 0..n {
            let fd = (at(&mut am, i, 0.5) - at(&mut am, i, -0.5)) / 1.0;
            assert!(
                (fd - g[i] as f64).abs() <= 2e-3 * scale,
                "{wrt:?} {i}: {} vs {fd}",
                g[i]
            );
        }
        // The Hessian through J: the change of J^T g along J.
        let s = 3;
        let jac: Vec<f32> = (0..n * s).map(|_| rng.range(-2.0, 2.0) as f32).collect();
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        am.hessian(wrt, HessianKind::Newton, &c, &jac, s, &mut h);
        let jtg = |am: &mut Pca, d: f64, k: usize| -> [f64; MAX_DOF] {
            let moved = |x: &[f32]| -> Vec<f32> {
                x.iter()
                    .enumerate()
                    .map(|(i, v)| v + (jac[k * n + i] as f64 * d) as f32)
                    .collect()
            };
            let mut g = vec![0f32; n];
            match wrt {
                Wrt::Current => {
                    am.gradient(wrt, &moved(&c), &mut g);
                }
                Wrt::Template => {
                    am.set_mean(&moved(&mean));
                    am.gradient(wrt, &c, &mut g);
                    am.set_mean(&mean);
                }
            }
            let mut out = [0.0; MAX_DOF];
            jt_times(&jac, &g, s, &mut out);
            out
        };
        let hs = h[..s * s].iter().fold(0f64, |m, v| m.max(v.abs()));
        for k in 0..s {
            let (gp, gm) = (jtg(&mut am, 0.05, k), jtg(&mut am, -0.05, k));
            for i in 0..s {
                let fd = (gp[i] - gm[i]) / 0.1;
                assert!(
                    (fd - h[i * s + k]).abs() <= 5e-3 * hs,
                    "{wrt:?} H[{i},{k}]: {} vs {fd}",
                    h[i * s + k]
                );
            }
        }
        // Every kind is the same, and negative semi-definite.
        for kind in [HessianKind::GaussNewton, HessianKind::AfterConvergence] {
            let mut other = [0.0; MAX_DOF * MAX_DOF];
            am.hessian(wrt, kind, &c, &jac, s, &mut other);
            assert_eq!(other, h);
        }
        for _ in 0..10 {
            let x: Vec<f64> = (0..s).map(|_| rng.normal()).collect();
            let q: f64 = (0..s)
                .map(|i| (0..s).map(|j| x[i] * h[i * s + j] * x[j]).sum::<f64>())
                .sum();
            assert!(q <= 1e-9 * hs);
        }
    }
}

#[test]
fn the_hessian_from_projections_is_the_hessian_through_j() {
    let mut rng = Rng::new(11);
    let n = 81;
    let (mut am, t) = learnt(&mut rng, n);
    let s = 4;
    let jac: Vec<f32> = (0..n * s).map(|_| rng.range(-2.0, 2.0) as f32).collect();
    let mut h = [0.0; MAX_DOF * MAX_DOF];
    am.hessian(Wrt::Current, HessianKind::Default, &t, &jac, s, &mut h);
    let mut jtj = [0.0; MAX_DOF * MAX_DOF];
    crate::linalg::accumulate_jtj(&jac, s, &mut jtj);
    let mut project = |xs: &[&[f32]], out: &mut [[f64; MAX_DOF]]| {
        for (x, o) in xs.iter().zip(out.iter_mut()) {
            jt_times(&jac, x, s, o);
        }
    };
    let mut got = [0.0; MAX_DOF * MAX_DOF];
    assert!(am.hessian_from_jtj());
    assert!(am.hessian_from_projections(HessianKind::Default, &t, &jtj, &mut project, s, &mut got));
    for i in 0..s * s {
        assert!(
            (got[i] - h[i]).abs() <= 1e-9 * h[i].abs().max(1.0),
            "{i}: {} vs {}",
            got[i],
            h[i]
        );
    }
}

#[test]
fn before_learning_it_is_ssd() {
    let mut rng = Rng::new(2);
    let n = 50;
    let (t, c) = (patch(&mut rng, n), patch(&mut rng, n));
    let mut pca = ENTRY.build.default_model();
    let mut ssd = crate::am::build("ssd").unwrap();
    pca.set_template(&t);
    ssd.set_template(&t);
    let rel = |a: f64, b: f64| (a - b).abs() <= 1e-6 * a.abs().max(1.0);
    assert!(rel(pca.similarity(&c), ssd.similarity(&c)));
    for wrt in [Wrt::Current, Wrt::Template] {
        let (mut a, mut b) = (vec![0f32; n], vec![0f32; n]);
        pca.gradient(wrt, &c, &mut a);
        ssd.gradient(wrt, &c, &mut b);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-3, "{wrt:?}");
        }
    }
    assert!(pca.learns() && !ssd.learns());
    // The parameters reach the model and are checked.
    let mut p = MethodParams::default();
    p.set("components", 17.0);
    assert!(crate::am::build_with("pca", &p).is_err());
    p.set("components", 2.0);
    p.set("forgetting", 0.6);
    assert!(crate::am::build_with("ivt", &p).is_ok());
}

#[test]
fn what_it_learns_stays_orthogonal_to_the_motion() {
    let mut rng = Rng::new(6);
    let n = 120;
    let mut am = Pca::new(6, 0.9);
    let t = patch(&mut rng, n);
    am.set_template(&t);
    let dof = 3;
    let jac: Vec<f32> = (0..n * dof).map(|_| rng.normal() as f32).collect();
    am.set_motion(&jac, dof);
    // Patches that differ from the template along the motion and otherwise.
    for k in 0..8 {
        let p: Vec<f32> = (0..n)
            .map(|i| t[i] + 3.0 * jac[(k % dof) * n + i] + rng.range(-5.0, 5.0) as f32)
            .collect();
        am.learn(&p);
    }
    let (basis, sigma) = am.basis();
    assert!(!sigma.is_empty());
    let moved: Vec<f32> = am.template().iter().zip(&t).map(|(m, t)| m - t).collect();
    for k in 0..dof {
        let j = &jac[k * n..(k + 1) * n];
        let jn = dot(j, j).sqrt();
        for (u, _) in basis.chunks_exact(n).zip(sigma) {
            assert!(
                (dot(u, j) / jn).abs() < 1e-3,
                "a basis patch along motion {k}"
            );
        }
        let mn = dot(&moved, &moved).sqrt();
        assert!(
            (dot(&moved, j) / (jn * mn)).abs() < 1e-3,
            "the mean moved along motion {k}"
        );
    }
    // A motion is then not absorbed: a patch moved along it is as far as SSD says.
    let along: Vec<f32> = am
        .template()
        .iter()
        .zip(&jac[..n])
        .map(|(m, j)| m + 2.0 * j)
        .collect();
    let ssd = -0.5 * (0..n).map(|i| (2.0 * jac[i] as f64).powi(2)).sum::<f64>();
    assert!((am.similarity(&along) - ssd).abs() < 1e-3 * ssd.abs());
    // A new template forgets the motion until it is given again.
    am.set_template(&t);
    assert!(am.motion.is_empty());
}
