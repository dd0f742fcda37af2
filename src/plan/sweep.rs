//! The cost landscape of a registration tracker ([`crate::landscape`]): its similarity swept
//! around a warp on a pre-processed frame, with the analytic and the numeric slope at the
//! centre.

use super::RegistrationTracker;
use crate::am::Wrt;
use crate::error::{Error, Result};
use crate::geometry::{Quad, alignment_error};
use crate::imaging::ImageView;
use crate::landscape::{Landscape, LandscapeSpec};
use crate::linalg::MAX_DOF;
use crate::linalg::jt_times;
use crate::registration::Context;
use crate::sm::newton;
use crate::ssm::Params;
use crate::status::TrackStatus;
use crate::visual_tracker::FrameInput;

/// How far (px) beyond the quad's box the swept warps may reach: the pre-processed region must
/// be grown by this.
pub fn reach(spec: &LandscapeSpec) -> f64 {
    3.0 * radius(spec) + 8.0
}

fn radius(spec: &LandscapeSpec) -> f64 {
    spec.radius.abs().max(1e-3)
}

impl RegistrationTracker {
    /// See [`crate::visual_tracker::VisualTracker::landscape`]: the region the sweep reads is
    /// pre-processed, then [`sweep`].
    pub(super) fn sweep(
        &mut self,
        input: FrameInput<'_>,
        at: &Quad,
        spec: &LandscapeSpec,
    ) -> Result<Landscape> {
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidRegion(
                "the tracker is not initialised".into(),
            ));
        }
        at.validate()?;
        let region = self.region_around(at).grown(reach(spec));
        self.src.prepare(input, region);
        let view = self.src.view(input, 0);
        sweep(&mut self.finest.ctx, &view, at, spec)
    }
}

/// Sweeps `ctx`'s similarity on `view` around the warp whose corners are `at` (the context's
/// parameters are left as they were).
pub fn sweep(
    ctx: &mut Context,
    view: &ImageView,
    at: &Quad,
    spec: &LandscapeSpec,
) -> Result<Landscape> {
    let dof = ctx.dof();
    if spec.axes.is_empty() || spec.axes.len() > 2 || spec.axes.iter().any(|&k| k >= dof) {
        return Err(Error::InvalidParameter(format!(
            "the landscape sweeps 1 or 2 of the {dof} parameters of {}",
            ctx.ssm().name()
        )));
    }
    at.validate()?;
    let steps = (spec.steps.max(3) / 2) * 2 + 1;
    let radius = radius(spec);
    let p0 = ctx
        .problem()
        .fit(at)
        .ok_or_else(|| Error::InvalidRegion(format!("cannot fit {} to {at}", ctx.ssm().name())))?;
    // Parameter change per px of mean corner motion, per axis.
    let c0 = ctx.corners(&p0);
    let mut deltas = Vec::new();
    for &k in &spec.axes {
        let h = 1e-6 * (1.0 + p0[k].abs());
        let mut p = p0;
        p[k] += h;
        let moved = alignment_error(&ctx.corners(&p), &c0) / h;
        if !(moved > 0.0 && moved.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "parameter {} does not move the corners",
                k + 1
            )));
        }
        deltas.push(1.0 / moved);
    }
    let saved = ctx.params();
    let offsets: Vec<f64> = (0..steps)
        .map(|i| -radius + 2.0 * radius * i as f64 / (steps - 1) as f64)
        .collect();
    let at_offsets = |u: &[f64]| -> Params {
        let mut p = p0;
        for (j, &k) in spec.axes.iter().enumerate() {
            p[k] += u[j] * deltas[j];
        }
        p
    };
    let mut values = Vec::with_capacity(steps.pow(spec.axes.len() as u32));
    if spec.axes.len() == 1 {
        for &u in &offsets {
            values.push(ctx.similarity_at(view, &at_offsets(&[u])));
        }
    } else {
        for &v in &offsets {
            for &u in &offsets {
                values.push(ctx.similarity_at(view, &at_offsets(&[u, v])));
            }
        }
    }
    // The analytic gradient at the centre, as FALK forms it: the AM's gradient with respect to
    // the current pixels through dI/dp = grad I . dw/dp at p0.
    ctx.sample_gradients_at(view, &p0);
    let s = ctx.problem().norm().scale as f32;
    let (gx, gy) = ctx.work_mut().gradients_mut();
    gx.iter_mut().for_each(|g| *g *= s);
    gy.iter_mut().for_each(|g| *g *= s);
    newton::project_gradients(ctx, Some(&p0));
    let center_value = ctx.am_gradient(Wrt::Current);
    let mut g = [0.0f64; MAX_DOF];
    jt_times(ctx.work().jac(), ctx.work().grad(), dof, &mut g);
    let analytic: Vec<f64> = spec
        .axes
        .iter()
        .zip(&deltas)
        .map(|(&k, &d)| g[k] * d)
        .collect();
    // Central differences of f over +-0.01 px: the slope of the interpolated frame.
    let h = 0.01;
    let mut numeric = Vec::new();
    for j in 0..spec.axes.len() {
        let mut up = vec![0.0; spec.axes.len()];
        let mut down = up.clone();
        up[j] = h;
        down[j] = -h;
        let a = ctx.similarity_at(view, &at_offsets(&up));
        let b = ctx.similarity_at(view, &at_offsets(&down));
        numeric.push((a - b) / (2.0 * h));
    }
    ctx.set_params(saved);
    Ok(Landscape {
        axes: spec.axes.clone(),
        deltas,
        offsets,
        values,
        center: p0,
        center_value,
        analytic,
        numeric,
    })
}
