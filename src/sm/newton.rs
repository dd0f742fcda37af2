//! The Newton steps of the gradient search methods, on a [`Context`]: the pixel Jacobian
//! `dI/dp = grad I . dw/dp` (the gradients projected on the warp's Jacobian), the AM's
//! gradient and Hessian through it, the Newton system `H dp = -J^T g` (damped with `lm:`) and
//! the update of the parameters. Where the grid has moments (SSMs of six or more parameters,
//! the AMs whose Hessian is `-J^T J` or made from `J^T J`: [`crate::registration::moments`])
//! the forward steps form the same system from the gradient's moments, without `J`.
//!
//! The methods differ in which gradient they project and how they update (FALK: the frame's at
//! `p`, additive; IALK: the template's through the warp's inverse point Jacobian, additive;
//! FCLK: the warped frame's at the identity, composed; ESM: its mean with the template's,
//! composed; ICLK: the template's once per template, composed with the inverse): each method's
//! file says so and calls these.

use super::{Context, LossReason, Update};
use crate::am::Wrt;
pub use crate::linalg::products::{project, project_skipping};
use crate::linalg::{MAX_DOF, Square, clear_square, jt_times};
use crate::ssm::Params;

/// Projects the gradients in the workspace (with respect to the normalised template point) on
/// `dw/dp` into the pixel Jacobian: `dw/dp` at the identity (compositional methods) or, given
/// `p`, at `p` (additive methods).
pub fn project_gradients(ctx: &mut Context, at: Option<&Params>) {
    let (problem, _, work) = ctx.parts_mut();
    let dof = problem.dof();
    match at {
        None => {
            let ((gx, gy), _, jac) = work.projection_mut();
            let (grid_x, grid_y) = problem.grid();
            if problem
                .ssm()
                .project_at_identity(gx, gy, grid_x, grid_y, jac)
            {
                return;
            }
            let (dwdp0, zero) = problem.dwdp0();
            project_skipping(gx, gy, dwdp0, zero, dof, jac);
        }
        Some(p) => {
            problem.jacobian(p, work.dwdp_mut());
            let ((gx, gy), dwdp, jac) = work.projection_mut();
            project_skipping(gx, gy, dwdp, &[false; 2 * MAX_DOF], dof, jac);
        }
    }
}

/// The forward-compositional (FCLK) step from `p`, once the frame's values and gradients
/// have been sampled there ([`Context::sample_gradients_at`]); returns the similarity at `p`.
pub fn forward_compositional_step(ctx: &mut Context, p: &Params) -> Result<f64, LossReason> {
    if moments_step(ctx) {
        ctx.unit_gradient(p);
        let f = ctx.am_gradient(Wrt::Current);
        return moments_newton_step(ctx, Update::Compose).map(|_| f);
    }
    ctx.warped_gradient(p);
    project_gradients(ctx, None);
    forward_step(ctx, Update::Compose)
}

/// Whether the forward steps at the identity form their Newton system from the gradient's
/// moments (SSD, SCV, LSCV, ZNCC and NCC, with SSMs of six or more parameters): then
/// [`Context::unit_gradient`] (or its mean with the template's) and [`moments_newton_step`]
/// stand for the warped gradient, the projection and [`forward_step_from_gradient`].
pub fn moments_step(ctx: &Context) -> bool {
    let am = ctx.am();
    ctx.problem().moments().is_some() && (am.hessian_is_minus_jtj() || am.hessian_from_jtj())
}

/// The Newton step from the gradient with respect to the unit square's coordinates (in the
/// workspace's gradients) and the AM's gradient (in its `grad`), through the moments; needs
/// [`moments_step`].
pub fn moments_newton_step(ctx: &mut Context, update: Update) -> Result<(), LossReason> {
    let g = moments_system(ctx)?;
    solve_own_step(ctx, &g, update)
}

/// The Newton system of [`moments_newton_step`]: the AM's Hessian (row-major `dof x dof`, in
/// the workspace's matrix, [`crate::registration::Workspace::newton_mut`]) and `J^T g`
/// (returned), from the moments: `-J^T J` for the least-squares models, and for the
/// correlations their Hessian from `J^T J` and the moments' `J^T x`
/// ([`crate::am::Am::hessian_from_projections`]).
pub fn moments_system(ctx: &mut Context) -> Result<[f64; MAX_DOF], LossReason> {
    let mut g = [0.0; MAX_DOF];
    let (problem, _, work) = ctx.parts_mut();
    let (dof, kind) = (problem.dof(), problem.hessian());
    let (am, moments) = problem.am_and_moments_mut();
    let Some(moments) = moments else {
        return Err(LossReason::Singular);
    };
    let w = work.newton_mut();
    let (gx, gy) = w.gradients;
    moments.minus_jtj_and_jtr(gx, gy, w.grad, w.hessian, &mut g);
    if am.hessian_is_minus_jtj() {
        return Ok(g);
    }
    let jtj = w.scratch;
    for i in 0..dof {
        for j in 0..dof {
            jtj[i * MAX_DOF + j] = -w.hessian[i * dof + j];
        }
    }
    let mut project = |xs: &[&[f32]], out: &mut [[f64; MAX_DOF]]| {
        for (x, o) in xs.iter().zip(out.iter_mut()) {
            moments.jtr(gx, gy, x, o);
        }
    };
    if am.hessian_from_projections(kind, w.values, jtj, &mut project, dof, w.hessian) {
        Ok(g)
    } else {
        Err(LossReason::Singular)
    }
}

/// The Newton step of the forward methods: the AM's gradient and Hessian with respect to the
/// current pixels, through the pixel Jacobian; returns the similarity before the step.
pub fn forward_step(ctx: &mut Context, update: Update) -> Result<f64, LossReason> {
    let f = ctx.am_gradient(Wrt::Current);
    forward_step_from_gradient(ctx, update).map(|_| f)
}

/// [`forward_step`] once the AM's gradient with respect to the current pixels is in the
/// workspace's `grad`: the Hessian, the Newton system, the update.
pub fn forward_step_from_gradient(ctx: &mut Context, update: Update) -> Result<(), LossReason> {
    let (problem, _, work) = ctx.parts_mut();
    let (dof, kind) = (problem.dof(), problem.hessian());
    let w = work.newton_mut();
    clear_square(w.hessian, dof);
    problem
        .am_mut()
        .hessian(Wrt::Current, kind, w.values, w.jac, dof, w.hessian);
    let mut g = [0.0f64; MAX_DOF];
    jt_times(w.jac, w.grad, dof, &mut g);
    solve_own_step(ctx, &g, update)
}

/// Solves the Newton system `H dp = -g` (damped with `lm:`) and applies the step.
pub fn solve_step(
    ctx: &mut Context,
    g: &[f64; MAX_DOF],
    h: &Square,
    update: Update,
) -> Result<(), LossReason> {
    solve_system(ctx, g, Some(h), update)
}

/// [`solve_step`] with the Hessian in the workspace's matrix.
fn solve_own_step(ctx: &mut Context, g: &[f64; MAX_DOF], update: Update) -> Result<(), LossReason> {
    solve_system(ctx, g, None, update)
}

/// The Newton step of `H` (`None`: the workspace's matrix) and `g`, a non-rigid SSM's
/// smoothness prior added (into the workspace's second matrix), applied.
fn solve_system(
    ctx: &mut Context,
    g: &[f64; MAX_DOF],
    h: Option<&Square>,
    update: Update,
) -> Result<(), LossReason> {
    let (problem, state, work) = ctx.parts_mut();
    let dof = problem.dof();
    let w = work.newton_mut();
    let h: &Square = h.unwrap_or(w.hessian);
    let (h, g) = match problem.smoothness() {
        Some(prior) => {
            let g = with_prior(prior, &state.params(), update, g, h, w.scratch, dof);
            (&*w.scratch, g)
        }
        None => (h, *g),
    };
    let dp = w
        .solver
        .step(h, &g, dof, state.damping())
        .ok_or(LossReason::Singular)?;
    ctx.apply(&dp, update)
}

/// The Newton system of the similarity minus a non-rigid SSM's smoothness prior
/// `lambda / 2 (q^T R q)` summed over both components of the control points' displacements
/// `q` after the step (`p + dp`, or `p - dp` for an inverse composition, to first order), with
/// `lambda` the weight times the data's mean curvature (`-H`'s mean diagonal): the Hessian
/// into `out`, the gradient returned.
fn with_prior(
    (weight, r): (f64, &[f64]),
    p: &crate::ssm::Params,
    update: Update,
    g: &[f64; MAX_DOF],
    h: &Square,
    out: &mut Square,
    dof: usize,
) -> [f64; MAX_DOF] {
    let m = dof / 2;
    let curvature = (0..dof).map(|i| -h[i * dof + i]).sum::<f64>() / dof.max(1) as f64;
    let lambda = weight * curvature.max(0.0);
    // The prior's gradient at dp = 0: -lambda R p, or +lambda R p when the step is undone.
    let sign = if update == Update::ComposeInverse {
        1.0
    } else {
        -1.0
    };
    let mut g = *g;
    out[..dof * dof].copy_from_slice(&h[..dof * dof]);
    for a in 0..m {
        for b in 0..m {
            let v = lambda * r[a * m + b];
            for c in 0..2 {
                let (i, j) = (2 * a + c, 2 * b + c);
                out[i * dof + j] -= v;
                g[i] += sign * v * p[j];
            }
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::{self, HessianKind};
    use crate::linalg::minus_jtj;
    use crate::registration::moments::{homography_jacobian, skewed};
    use crate::rng::Rng;
    use crate::spec::GridLayout;
    use crate::ssm;

    /// `h2`, `g2` against `h1`, `g1` (row-major `dof x dof`), each entry within `2e-6` of its own
    /// scale: `sqrt(|H_ii H_jj|)` for `H_ij` (the bound of Cauchy-Schwarz), `sqrt(|H_ii|) |r|`
    /// for `g_i`.
    fn close(h: (&[f64], &[f64]), g: (&[f64], &[f64]), dof: usize, r: &[f32], what: &str) {
        close_to_scale(h, g, (h.0, 1.0), 2e-6, dof, r, what);
    }

    /// [`close`] with the scales taken from `s` times the diagonal of `jtj` (`J^T J` or its
    /// negative: a Hessian `s J^T A J` with `|A| <= 1` has `|H_ij| <= |s| sqrt(jtj_ii jtj_jj)`,
    /// and `|(J^T r)_i| <= sqrt(jtj_ii) |r|`), within `tol`.
    fn close_to_scale(
        h: (&[f64], &[f64]),
        g: (&[f64], &[f64]),
        (jtj, s): (&[f64], f64),
        tol: f64,
        dof: usize,
        r: &[f32],
        what: &str,
    ) {
        let d = |i: usize| jtj[i * dof + i].abs();
        let rn = r
            .iter()
            .map(|&v| (v as f64) * (v as f64))
            .sum::<f64>()
            .sqrt();
        for i in 0..dof {
            for j in 0..dof {
                let (x, y) = (h.0[i * dof + j], h.1[i * dof + j]);
                let scale = s.abs() * (d(i) * d(j)).sqrt();
                assert!(
                    (x - y).abs() <= tol * scale,
                    "{what}: H[{i}][{j}] {x} by the Jacobian, {y} by the moments"
                );
            }
            let (x, y) = (g.0[i], g.1[i]);
            assert!(
                (x - y).abs() <= tol * d(i).sqrt() * rn,
                "{what}: g[{i}] {x} by the Jacobian, {y} by the moments"
            );
        }
    }

    /// The template's gradient `(tx, ty)` in both coordinates: the normalised ones and the unit
    /// square's (the same field).
    fn set_template_gradient(ctx: &mut Context, tx: &[f32], ty: &[f32]) {
        let problem = ctx.problem();
        let unit = *problem.unit();
        let (gu, gv) = problem.unit_grid();
        let (gu, gv) = (gu.to_vec(), gv.to_vec());
        let [gx, gy, tu, tv] = ctx.problem_mut().template_gradients_mut();
        gx.copy_from_slice(tx);
        gy.copy_from_slice(ty);
        for i in 0..tx.len() {
            let j = homography_jacobian(&unit, gu[i] as f64, gv[i] as f64);
            let (a, b) = (tx[i] as f64, ty[i] as f64);
            tu[i] = (a * j[0][0] + b * j[1][0]) as f32;
            tv[i] = (a * j[0][1] + b * j[1][1]) as f32;
        }
    }

    /// The workspace's gradients set to `(gx, gy)`.
    fn set_gradients(ctx: &mut Context, (gx, gy): (&[f32], &[f32])) {
        let (a, b) = ctx.work_mut().gradients_mut();
        a.copy_from_slice(gx);
        b.copy_from_slice(gy);
    }

    /// The pixel gradient `(gx, gy)` as the warped gradient (or its mean with the template's),
    /// projected on `dw/dp` into the context's Jacobian.
    fn through_the_jacobian(ctx: &mut Context, (gx, gy): (&[f32], &[f32]), p: &Params, mean: bool) {
        set_gradients(ctx, (gx, gy));
        if mean {
            ctx.warped_gradient_mean(p);
        } else {
            ctx.warped_gradient(p);
        }
        project_gradients(ctx, None);
    }

    /// The pixel gradient `(gx, gy)` as the gradient with respect to the unit square's
    /// coordinates (or its mean with the template's), in the context's `gx`, `gy`.
    fn in_the_unit_square(ctx: &mut Context, (gx, gy): (&[f32], &[f32]), p: &Params, mean: bool) {
        set_gradients(ctx, (gx, gy));
        if mean {
            ctx.unit_gradient_mean(p);
        } else {
            ctx.unit_gradient(p);
        }
    }

    /// A warp a random step away from the identity.
    fn warp_near_identity(ctx: &Context, rng: &mut Rng) -> Params {
        let mut dp = [0.0; MAX_DOF];
        for v in dp.iter_mut().take(ctx.dof()) {
            *v = 0.03 * rng.normal();
        }
        ctx.ssm().compose(&ctx.ssm().identity(), &dp).unwrap()
    }

    /// The moments' Newton system is the one of the warped gradient through `dw/dp`: every SSM
    /// of six or more parameters, both grid layouts, sizes of one column block, of a last block
    /// that overlaps the one before, and the default 50, a skewed quad, a warp
    /// away from the identity, random pixel gradients and residuals, alone and in their mean
    /// with the template's gradient (ESM's); and ICLK's `J^T r` through the template's Jacobian.
    #[test]
    fn the_moments_give_the_jacobians_newton_system() {
        let mut rng = Rng::new(11);
        let mut checked = 0;
        for entry in ssm::REGISTRY {
            let dof = ssm::build(entry.name).unwrap().dof();
            for layout in [GridLayout::Centres, GridLayout::Border] {
                // A colour grid too: its three parts' systems summed.
                for (res, channels) in [(8, 1), (13, 1), (50, 1), (13, 3), (50, 3)] {
                    let model = ssm::build(entry.name).unwrap();
                    let mut ctx =
                        Context::new(model, am::build("ssd").unwrap(), HessianKind::Default, res);
                    ctx.set_channels(channels);
                    ctx.set_region(&skewed(), res, layout).unwrap();
                    // Six to eight parameters: a family of homographies (the non-rigid
                    // models' fields are not).
                    if !(6..=8).contains(&dof) {
                        assert!(
                            ctx.problem().moments().is_none(),
                            "{}: {dof} parameters",
                            entry.name
                        );
                        continue;
                    }
                    assert!(moments_step(&ctx), "{} has no moments", entry.name);
                    let n = res * res * channels;
                    assert_eq!(ctx.len(), n);
                    let p = warp_near_identity(&ctx, &mut rng);
                    ctx.warp_grid(&p);
                    let mut draw = |scale: f64| -> Vec<f32> {
                        (0..n).map(|_| (scale * rng.normal()) as f32).collect()
                    };
                    let (gx, gy, r) = (draw(20.0), draw(20.0), draw(10.0));
                    // The template's gradient in both coordinates: the same field.
                    let (tx, ty) = (draw(0.3), draw(0.3));
                    set_template_gradient(&mut ctx, &tx, &ty);
                    // ICLK's right-hand side: the template's Jacobian at the identity.
                    let mut jt = vec![0.0; n * dof];
                    project(&tx, &ty, ctx.problem().dwdp0().0, dof, &mut jt);
                    let (mut g1, mut g2) = ([0.0; MAX_DOF], [0.0; MAX_DOF]);
                    jt_times(&jt, &r, dof, &mut g1);
                    let (ta, tb) = ctx.problem().template_unit_gradient();
                    let (ta, tb) = (ta.to_vec(), tb.to_vec());
                    let moments = ctx.problem_mut().moments_mut().unwrap();
                    moments.jtr(&ta, &tb, &r, &mut g2);
                    let mut h1 = [0.0; MAX_DOF * MAX_DOF];
                    minus_jtj(&jt, dof, &mut h1);
                    let what = format!("{} {layout:?} {res}x{res}x{channels} template", entry.name);
                    close((&h1, &h1), (&g1, &g2), dof, &r, &what);
                    for mean in [false, true] {
                        ctx.work_mut().grad_mut().copy_from_slice(&r);
                        through_the_jacobian(&mut ctx, (&gx, &gy), &p, mean);
                        let (mut h1, mut g1) = ([0.0; MAX_DOF * MAX_DOF], [0.0; MAX_DOF]);
                        minus_jtj(ctx.work().jac(), dof, &mut h1);
                        jt_times(ctx.work().jac(), &r, dof, &mut g1);

                        in_the_unit_square(&mut ctx, (&gx, &gy), &p, mean);
                        let (mut h2, mut g2) = ([0.0; MAX_DOF * MAX_DOF], [0.0; MAX_DOF]);
                        let (a, b) = ctx.work().gradients();
                        let (a, b) = (a.to_vec(), b.to_vec());
                        ctx.problem_mut()
                            .moments_mut()
                            .unwrap()
                            .minus_jtj_and_jtr(&a, &b, &r, &mut h2, &mut g2);
                        let what = format!(
                            "{} {layout:?} {res}x{res}x{channels} mean {mean}",
                            entry.name
                        );
                        close((&h1, &h2), (&g1, &g2), dof, &r, &what);
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked >= 4 * 2 * 3 * 2, "{checked} systems checked");
    }

    /// The correlations' Newton system from the moments (`J^T J`, `J^T g` and the `J^T x` their
    /// Hessian needs) is the one through the Jacobian: ZNCC and NCC, each Hessian kind, the
    /// homography and the affine warp, 13 x 13 and 50 x 50, a warp away from the identity,
    /// random patches and gradients, alone and in ESM's mean with the template's gradient.
    #[test]
    fn the_correlations_newton_system_from_the_moments_is_the_jacobians() {
        let mut rng = Rng::new(17);
        let mut checked = 0;
        for am_name in ["zncc", "ncc"] {
            for ssm_name in ["homography", "affine"] {
                for res in [13, 50] {
                    for kind in [
                        HessianKind::GaussNewton,
                        HessianKind::Newton,
                        HessianKind::AfterConvergence,
                    ] {
                        let model = ssm::build(ssm_name).unwrap();
                        let dof = model.dof();
                        let mut ctx = Context::new(model, am::build(am_name).unwrap(), kind, res);
                        ctx.set_region(&skewed(), res, GridLayout::Centres).unwrap();
                        assert!(moments_step(&ctx), "{am_name} {ssm_name} has no moments");
                        let n = res * res;
                        let mut draw = |mean: f64, scale: f64| -> Vec<f32> {
                            (0..n)
                                .map(|_| (mean + scale * rng.normal()) as f32)
                                .collect()
                        };
                        let (template, current) = (draw(120.0, 30.0), draw(110.0, 25.0));
                        let (gx, gy) = (draw(0.0, 20.0), draw(0.0, 20.0));
                        let (tx, ty) = (draw(0.0, 0.3), draw(0.0, 0.3));
                        ctx.problem_mut().am_mut().set_template(&template);
                        set_template_gradient(&mut ctx, &tx, &ty);
                        let p = warp_near_identity(&ctx, &mut rng);
                        ctx.warp_grid(&p);
                        ctx.work_mut().values_mut().copy_from_slice(&current);
                        for mean in [false, true] {
                            // Through the Jacobian.
                            through_the_jacobian(&mut ctx, (&gx, &gy), &p, mean);
                            let values = ctx.values().to_vec();
                            ctx.am_gradient(am::Wrt::Current);
                            let (mut h1, mut g1) = ([0.0; MAX_DOF * MAX_DOF], [0.0; MAX_DOF]);
                            let jac = ctx.work().jac().to_vec();
                            ctx.problem_mut().am_mut().hessian(
                                am::Wrt::Current,
                                kind,
                                &values,
                                &jac,
                                dof,
                                &mut h1,
                            );
                            jt_times(&jac, ctx.work().grad(), dof, &mut g1);
                            // The scale: J^T J and the correlation's factor beta / |P x|^2.
                            let mut jtj = [0.0; MAX_DOF * MAX_DOF];
                            minus_jtj(&jac, dof, &mut jtj);
                            let centred = am_name == "zncc";
                            let x = if kind == HessianKind::AfterConvergence {
                                &template
                            } else {
                                &current
                            };
                            let m = if centred {
                                x.iter().map(|&v| v as f64).sum::<f64>() / n as f64
                            } else {
                                0.0
                            };
                            let norm2: f64 = x.iter().map(|&v| (v as f64 - m).powi(2)).sum();
                            let beta = if centred { n as f64 } else { 1.0 };
                            // Through the moments, on the context's own buffers as the forward
                            // methods call it.
                            in_the_unit_square(&mut ctx, (&gx, &gy), &p, mean);
                            ctx.am_gradient(am::Wrt::Current);
                            let g2 = moments_system(&mut ctx).unwrap();
                            let h2 = ctx.work_mut().newton_mut().hessian.to_vec();
                            let what = format!("{am_name} {ssm_name} {res} {kind:?} mean {mean}");
                            assert!(h1[..dof * dof].iter().any(|&v| v != 0.0), "{what}");
                            let r = ctx.work().grad().to_vec();
                            let scale = (&jtj[..], beta / norm2);
                            close_to_scale((&h1, &h2[..]), (&g1, &g2), scale, 2e-6, dof, &r, &what);
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(checked, 2 * 2 * 2 * 3 * 2);
    }
}
