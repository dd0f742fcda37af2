//! Finite-difference checks of every AM's gradient and Hessian.

use super::*;
use crate::linalg::{jt_times, minus_jtj};
use crate::rng::Rng;

/// A random patch of `n` intensities in 20..230 (shared by the models' own tests).
pub(crate) fn patch(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.range(20.0, 230.0) as f32).collect()
}

/// A smooth random texture (a sum of a few sinusoids), `res x res`, around 125.
pub(crate) fn smooth_patch(rng: &mut Rng, res: usize) -> Vec<f32> {
    // A smooth random texture (sum of a few sinusoids) in 20..230.
    let waves: Vec<(f32, f32, f32)> = (0..6)
        .map(|_| {
            (
                rng.range(0.05, 0.4) as f32,
                rng.range(0.05, 0.4) as f32,
                rng.range(0.0, std::f64::consts::TAU) as f32,
            )
        })
        .collect();
    (0..res * res)
        .map(|i| {
            let (x, y) = ((i % res) as f32, (i / res) as f32);
            let v: f32 = waves
                .iter()
                .map(|&(a, b, p)| (a * x + b * y + p).sin())
                .sum();
            125.0 + 17.0 * v
        })
        .collect()
}

/// Every AM with its default parameters, and the histogram models (MI, CCRE) also with few and
/// many bins: the derivative checks below run on each. With each, the finite-difference step
/// (grey levels) for the gradient check: for the histogram models a small fraction of a bin (1
/// grey level at 8 bins, 36 wide; 0.25 at 32, 8 wide), since the B-spline window's third
/// derivative jumps at the bins' edges.
fn models() -> Vec<(String, Box<dyn Am>, f32)> {
    let step = |bins: f64| (8.0 / bins as f32).min(1.0);
    let mut out = Vec::new();
    for e in REGISTRY.iter() {
        match e.build.params.iter().find(|d| d.name == "bins") {
            Some(d) => {
                out.push((e.name.to_string(), e.build.default_model(), step(d.default)));
                for bins in [4.0, 32.0] {
                    let mut p = crate::params::MethodParams::default();
                    p.set("bins", bins);
                    let am = build_with(e.name, &p).expect("bins in range");
                    out.push((format!("{} bins={bins}", e.name), am, step(bins)));
                }
            }
            None => out.push((e.name.to_string(), e.build.default_model(), 1.0)),
        }
        // Channel by channel (`channels = rgb`): three parts of the patch, a copy each.
        let step = e
            .build
            .params
            .iter()
            .find(|d| d.name == "bins")
            .map_or(1.0, |d| step(d.default));
        let rgb = channels::PerChannel::new(e.build.default_model(), 3);
        out.push((format!("{} rgb", e.name), Box::new(rgb), step));
    }
    out
}

/// The length of a test patch of `n` values a channel for the model called `name`: a colour
/// model's (`... rgb`) three times that.
fn whole_parts(name: &str, n: usize) -> usize {
    if name.ends_with(" rgb") { 3 * n } else { n }
}

/// The patch `p` as the model called `name` takes it: a colour model's three channels, `p`,
/// `p` reversed and `p` turned by a seventh (each channel's statistics those of `p`, its
/// pixels elsewhere).
fn colour_parts(name: &str, p: &[f32]) -> Vec<f32> {
    if !name.ends_with(" rgb") {
        return p.to_vec();
    }
    let mut turned = p.to_vec();
    turned.rotate_left(p.len() / 7);
    p.iter()
        .copied()
        .chain(p.iter().rev().copied())
        .chain(turned)
        .collect()
}

/// Similarity with the `wrt` argument replaced by `x`.
fn f_at(am: &mut dyn Am, wrt: Wrt, template: &[f32], current: &[f32], x: &[f32]) -> f64 {
    match wrt {
        Wrt::Current => {
            am.set_template(template);
            am.similarity(x)
        }
        Wrt::Template => {
            am.set_template(x);
            let v = am.similarity(current);
            am.set_template(template);
            v
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config {
        cases: 24,
        rng_seed: proptest::test_runner::RngSeed::Fixed(21),
        ..Default::default()
    })]

    #[test]
    fn gradients_match_finite_differences(
        t in proptest::collection::vec(20.0f32..230.0, 40),
        noise in proptest::collection::vec(-25.0f32..25.0, 40),
        gain in 0.6f32..1.4,
        bias in -20.0f32..20.0,
    ) {
        let c: Vec<f32> = t.iter().zip(&noise).map(|(&v, &e)| gain * v + bias + e).collect();
        for (name, mut am, step) in models() {
            if !am.exact_derivatives() {
                continue;
            }
            // A colour model's patch: three parts, each the grey patch's pixels reordered.
            let (t, c) = (colour_parts(&name, &t), colour_parts(&name, &c));
            let (t, c, n) = (&t[..], &c[..], t.len());
            for wrt in [Wrt::Current, Wrt::Template] {
                am.set_template(t);
                let mut g = vec![0f32; n];
                let f = am.gradient(wrt, c, &mut g);
                proptest::prop_assert!((f - am.similarity(c)).abs() <= 1e-6 * (1.0 + f.abs()), "{} value", name);
                let x0 = if wrt == Wrt::Current { c.to_vec() } else { t.to_vec() };
                let scale = g.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
                for i in 0..n {
                    let h = step;
                    let (mut xp, mut xm) = (x0.clone(), x0.clone());
                    xp[i] += h;
                    xm[i] -= h;
                    let fd = (f_at(&mut *am, wrt, t, c, &xp) - f_at(&mut *am, wrt, t, c, &xm)) / (2.0 * h as f64);
                    proptest::prop_assert!(
                        (fd - g[i] as f64).abs() <= 2e-3 * scale + 1e-9,
                        "{} {:?} pixel {}: analytic {} vs fd {}", name, wrt, i, g[i], fd
                    );
                }
            }
        }
    }
}

#[test]
fn hessians_match_finite_differences() {
    // d/dd [J^T g(x + J d)] at d = 0 is J^T (d2f/dI2) J: compare with the Newton Hessian.
    let mut rng = Rng::new(5);
    let (n, s) = (60, 3);
    for (name, mut am, _) in models() {
        let n = whole_parts(&name, n);
        let t = patch(&mut rng, n);
        let c: Vec<f32> = t
            .iter()
            .map(|&v| 1.1 * v - 5.0 + rng.range(-30.0, 30.0) as f32)
            .collect();
        let jac: Vec<f32> = (0..n * s).map(|_| rng.range(-2.0, 2.0) as f32).collect();
        // Models without analytic derivatives (SAD) have nothing to check here.
        if !am.exact_derivatives() {
            continue;
        }
        for wrt in [Wrt::Current, Wrt::Template] {
            am.set_template(&t);
            let mut h = [0.0; MAX_DOF * MAX_DOF];
            am.hessian(wrt, HessianKind::Newton, &c, &jac, s, &mut h);
            // After a gradient on the same patch (whose statistics a model may reuse): the same.
            let mut g = vec![0f32; n];
            am.gradient(wrt, &c, &mut g);
            let mut again = [0.0; MAX_DOF * MAX_DOF];
            am.hessian(wrt, HessianKind::Newton, &c, &jac, s, &mut again);
            for (a, b) in h.iter().zip(&again) {
                assert!(
                    (a - b).abs() <= 1e-9 * (1.0 + a.abs()),
                    "{name} {wrt:?}: {a} after a gradient, {b} alone"
                );
            }
            let jtg = |am: &mut dyn Am, d: &[f64]| -> [f64; MAX_DOF] {
                let moved = |x: &[f32]| -> Vec<f32> {
                    x.iter()
                        .enumerate()
                        .map(|(i, &v)| {
                            v + (0..s).map(|k| jac[k * n + i] as f64 * d[k]).sum::<f64>() as f32
                        })
                        .collect()
                };
                let mut g = vec![0f32; n];
                match wrt {
                    Wrt::Current => {
                        am.set_template(&t);
                        am.gradient(wrt, &moved(&c), &mut g);
                    }
                    Wrt::Template => {
                        am.set_template(&moved(&t));
                        am.gradient(wrt, &c, &mut g);
                    }
                }
                let mut out = [0.0; MAX_DOF];
                jt_times(&jac, &g, s, &mut out);
                out
            };
            let scale = h[..s * s].iter().fold(0f64, |m, v| m.max(v.abs()));
            for k in 0..s {
                let step = 0.02;
                let mut dp = [0.0; 3];
                dp[k] = step;
                let gp = jtg(&mut *am, &dp);
                dp[k] = -step;
                let gm = jtg(&mut *am, &dp);
                for i in 0..s {
                    let fd = (gp[i] - gm[i]) / (2.0 * step);
                    assert!(
                        (fd - h[i * s + k]).abs() <= 5e-3 * scale,
                        "{} {:?} H[{},{}]: analytic {} vs fd {}",
                        name,
                        wrt,
                        i,
                        k,
                        h[i * s + k],
                        fd
                    );
                }
            }
        }
    }
}

#[test]
fn hessian_kinds_agree_at_convergence_and_gauss_newton_is_negative() {
    let mut rng = Rng::new(9);
    let (n, s) = (50, 4);
    for (name, mut am, _) in models() {
        let t = patch(&mut rng, n);
        let jac: Vec<f32> = (0..n * s).map(|_| rng.range(-2.0, 2.0) as f32).collect();
        if !am.exact_derivatives() {
            continue;
        }
        am.set_template(&t);
        let mut hn = [0.0; MAX_DOF * MAX_DOF];
        let mut hg = [0.0; MAX_DOF * MAX_DOF];
        let mut ha = [0.0; MAX_DOF * MAX_DOF];
        am.hessian(Wrt::Current, HessianKind::Newton, &t, &jac, s, &mut hn);
        am.hessian(Wrt::Current, HessianKind::GaussNewton, &t, &jac, s, &mut hg);
        let c: Vec<f32> = t
            .iter()
            .map(|&v| v + rng.range(-40.0, 40.0) as f32)
            .collect();
        am.hessian(
            Wrt::Current,
            HessianKind::AfterConvergence,
            &c,
            &jac,
            s,
            &mut ha,
        );
        let scale = hn[..s * s].iter().fold(0f64, |m, v| m.max(v.abs()));
        for i in 0..s * s {
            assert!(
                (hn[i] - hg[i]).abs() <= 1e-4 * scale,
                "{}: Newton vs GN at convergence",
                name
            );
            assert!(
                (hn[i] - ha[i]).abs() <= 1e-4 * scale,
                "{}: Newton vs after-convergence",
                name
            );
        }
        // Gauss-Newton away from convergence: -H is positive semi-definite (x^T H x <= 0).
        am.hessian(Wrt::Current, HessianKind::GaussNewton, &c, &jac, s, &mut hg);
        for _ in 0..20 {
            let x: Vec<f64> = (0..s).map(|_| rng.normal()).collect();
            let q: f64 = (0..s)
                .map(|i| (0..s).map(|j| x[i] * hg[i * s + j] * x[j]).sum::<f64>())
                .sum();
            assert!(
                q <= 1e-9 * scale,
                "{}: GN Hessian not negative semi-definite",
                name
            );
        }
    }
}

#[test]
fn correlation_models_are_invariant_to_gain_and_zncc_to_bias() {
    let mut rng = Rng::new(1);
    let t = patch(&mut rng, 100);
    let gain: Vec<f32> = t.iter().map(|&v| 1.7 * v).collect();
    let bias: Vec<f32> = t.iter().map(|&v| v + 30.0).collect();
    let mut zncc = build("zncc").unwrap();
    zncc.set_template(&t);
    assert!(zncc.similarity(&gain).abs() < 1e-3 && zncc.similarity(&bias).abs() < 1e-3);
    let mut ncc = build("ncc").unwrap();
    ncc.set_template(&t);
    assert!((ncc.similarity(&gain) - 1.0).abs() < 1e-6);
    assert!(ncc.similarity(&bias) < 1.0 - 1e-4);
    let mut ssd = build("ssd").unwrap();
    ssd.set_template(&t);
    assert_eq!(ssd.similarity(&t), 0.0);
    assert!(ssd.similarity(&gain) < -1000.0);
}

#[test]
fn am_parameters_reach_the_model_and_are_checked() {
    use crate::params::MethodParams;
    let mut p = MethodParams::default();
    p.set("regions", 2.0);
    // A search method's parameter in the same bag is left to it.
    p.set("samples", 500.0);
    assert!(build_with("lscv", &p).is_ok());
    // One region is SCV; the default (6x6) follows light that varies across the patch better.
    let mut rng = Rng::new(31);
    let t = patch(&mut rng, 36 * 36);
    let lit: Vec<f32> = t
        .iter()
        .enumerate()
        .map(|(i, &v)| v * (0.6 + 0.8 * (i % 36) as f32 / 36.0))
        .collect();
    let fit = |am: &mut Box<dyn Am>| {
        am.set_template(&t);
        am.update_model(&lit);
        am.similarity(&lit)
    };
    p.set("regions", 1.0);
    let one = fit(&mut build_with("lscv", &p).unwrap());
    assert_eq!(one, fit(&mut build("scv").unwrap()));
    assert!(fit(&mut build("lscv").unwrap()) > 0.5 * one, "{one}");
    p.set("regions", 40.0);
    let e = build_with("lscv", &p).unwrap_err().to_string();
    assert!(e.contains("regions") && e.contains("lscv"), "{e}");
    assert_eq!(param_defs("ssd").unwrap().len(), 0);
}

/// The models that say their Hessian with respect to the current pixels is `-J^T J` have it for
/// every kind, with the plain residual as gradient (`g(c + d) = g(c) - d`), also after their
/// model learnt a patch (SCV's maps); those that build it from `J^T J` and projections build
/// the same Hessian from them as from `J`, for every kind.
#[test]
fn the_moments_capabilities_hold_for_the_models_that_claim_them() {
    let mut rng = Rng::new(23);
    let (n, s) = (64, 6);
    let mut claimed = Vec::new();
    for (name, mut am, _) in models() {
        let n = whole_parts(&name, n);
        let t = patch(&mut rng, n);
        let lit: Vec<f32> = t.iter().map(|&v| 0.7 * v + 20.0).collect();
        let c: Vec<f32> = lit
            .iter()
            .map(|&v| v + rng.range(-9.0, 9.0) as f32)
            .collect();
        let jac: Vec<f32> = (0..n * s).map(|_| rng.range(-2.0, 2.0) as f32).collect();
        am.set_template(&t);
        if am.updates_model() {
            am.update_model(&lit);
        }
        // A model that learns (PCA) with something learnt: its Hessian has more than `J^T J`.
        if am.learns() {
            am.learn(&lit);
            am.learn(&c);
        }
        for kind in [
            HessianKind::GaussNewton,
            HessianKind::Newton,
            HessianKind::AfterConvergence,
        ] {
            let mut g = vec![0f32; n];
            am.gradient(Wrt::Current, &c, &mut g);
            let mut h = [0.0; MAX_DOF * MAX_DOF];
            am.hessian(Wrt::Current, kind, &c, &jac, s, &mut h);
            if am.hessian_is_minus_jtj() {
                let mut m = [0.0; MAX_DOF * MAX_DOF];
                minus_jtj(&jac, s, &mut m);
                // A colour model sums its channels' products apart: another order of sums.
                let tol = if name.ends_with(" rgb") { 1e-5 } else { 1e-9 };
                for (a, b) in h[..s * s].iter().zip(&m) {
                    assert!(
                        (a - b).abs() <= tol * b.abs().max(1.0),
                        "{name} {kind:?}: {a} vs {b}"
                    );
                }
                let d: Vec<f32> = (0..n).map(|_| rng.range(-3.0, 3.0) as f32).collect();
                let moved: Vec<f32> = c.iter().zip(&d).map(|(a, b)| a + b).collect();
                let mut g2 = vec![0f32; n];
                am.gradient(Wrt::Current, &moved, &mut g2);
                for i in 0..n {
                    assert!(
                        (g2[i] - (g[i] - d[i])).abs() < 1e-3,
                        "{name}: not the residual"
                    );
                }
                claimed.push(name.clone());
            }
            if am.hessian_from_jtj() {
                am.gradient(Wrt::Current, &c, &mut g);
                let mut jtj = [0.0; MAX_DOF * MAX_DOF];
                let mut m = [0.0; MAX_DOF * MAX_DOF];
                minus_jtj(&jac, s, &mut m);
                for i in 0..s {
                    for j in 0..s {
                        jtj[i * MAX_DOF + j] = -m[i * s + j];
                    }
                }
                let mut project = |xs: &[&[f32]], out: &mut [[f64; MAX_DOF]]| {
                    for (x, o) in xs.iter().zip(out.iter_mut()) {
                        jt_times(&jac, x, s, o);
                    }
                };
                let mut h2 = [0.0; MAX_DOF * MAX_DOF];
                assert!(am.hessian_from_projections(kind, &c, &jtj, &mut project, s, &mut h2));
                let scale = h[..s * s].iter().fold(0f64, |a, v| a.max(v.abs()));
                for (a, b) in h[..s * s].iter().zip(&h2) {
                    assert!((a - b).abs() <= 1e-9 * scale, "{name} {kind:?}: {a} vs {b}");
                }
                claimed.push(name.clone());
            }
        }
    }
    claimed.sort();
    claimed.dedup();
    // Channel by channel, the least-squares models' sums stay least squares; the correlations'
    // Hessians need each channel's `J^T J`, which the moments do not give.
    assert_eq!(
        claimed,
        [
            "lscv", "lscv rgb", "ncc", "pca", "scv", "scv rgb", "ssd", "ssd rgb", "zncc"
        ]
    );
}
