//! Low-DOF ground truth (the paper's protocol): for an SSM, the warp of the first annotated
//! frame's quad whose corners are closest to each frame's full 8-DOF ground truth.
//!
//! "Closest" is the alignment error E_AL itself (the mean corner distance), not the sum of squared
//! distances: the SSM's closed-form least-squares fit starts an iteratively reweighted
//! least-squares refinement (weights `1 / distance`, Gauss-Newton steps on numeric derivatives
//! of the corners, a step kept only when E_AL falls), so that the result is the lowest E_AL the
//! SSM can reach. The residual E_AL of each frame tells the annotator which frames the SSM cannot
//! represent (and where an 8-DOF annotation may be wrong).
//!
//! Files in MTF's layout: `<root>/OptGT/<seq>_<ssm>.txt` (the quads, in the MTF format) and,
//! beside it, `<seq>_<ssm>_residuals.txt` (frame, residual px).

use crate::dataset::{Sequence, read_ground_truth, write_atomic, write_ground_truth};
use crate::error::{Error, Result};
use crate::geometry::{Quad, alignment_error};
use crate::ssm::{self, Params, Ssm};
use std::path::{Path, PathBuf};

/// The SSM warp of `base` closest to `target` in E_AL: `(parameters, quad, E_AL)`. `None` when
/// the SSM cannot fit the quads at all (degenerate input).
pub fn best_fit(model: &dyn Ssm, base: &Quad, target: &Quad) -> Option<(Params, Quad, f64)> {
    let mut p = model.fit(&base.0, &target.0)?;
    let mut quad = ssm::warp_quad(model, &p, base);
    let mut err = alignment_error(&quad, target);
    if !err.is_finite() {
        return None;
    }
    let n = model.dof();
    if n == 8 {
        // The quad itself: the closed form is exact.
        return Some((p, quad, err));
    }
    let scale = base.mean_side().max(1.0);
    for _ in 0..50 {
        // Residuals r_k (2 per corner) with IRLS weights 1 / |r_k|; numeric Jacobian d quad / dp.
        let mut w = [0.0f64; 4];
        for k in 0..4 {
            w[k] = 1.0 / quad.0[k].dist(target.0[k]).max(1e-9 * scale);
        }
        let mut jac = [[0.0f64; 8]; 8];
        for j in 0..n {
            let h = 1e-6 * (1.0 + p[j].abs());
            let (mut a, mut b) = (p, p);
            a[j] += h;
            b[j] -= h;
            let (qa, qb) = (
                ssm::warp_quad(model, &a, base),
                ssm::warp_quad(model, &b, base),
            );
            for k in 0..4 {
                jac[2 * k][j] = (qa.0[k].x - qb.0[k].x) / (2.0 * h);
                jac[2 * k + 1][j] = (qa.0[k].y - qb.0[k].y) / (2.0 * h);
            }
        }
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut g = nalgebra::DVector::<f64>::zeros(n);
        for r in 0..8 {
            let wk = w[r / 2];
            let res = if r % 2 == 0 {
                target.0[r / 2].x - quad.0[r / 2].x
            } else {
                target.0[r / 2].y - quad.0[r / 2].y
            };
            for i in 0..n {
                g[i] += wk * jac[r][i] * res;
                for j in 0..n {
                    a[(i, j)] += wk * jac[r][i] * jac[r][j];
                }
            }
        }
        let Some(dp) = a.lu().solve(&g) else { break };
        let mut next = p;
        for j in 0..n {
            next[j] += dp[j];
        }
        let q = ssm::warp_quad(model, &next, base);
        let e = alignment_error(&q, target);
        if e.is_nan() || e >= err - 1e-12 {
            break;
        }
        let done = err - e < 1e-9 * scale;
        (p, quad, err) = (next, q, e);
        if done {
            break;
        }
    }
    Some((p, quad, err))
}

/// A sequence's low-DOF ground truth for one SSM.
#[derive(Clone, Debug, PartialEq)]
pub struct LowDofGroundTruth {
    /// The SSM's registry name.
    pub ssm: String,
    /// Per frame, the fitted quad (`None` where the frame has no ground truth).
    pub quads: Vec<Option<Quad>>,
    /// Per frame, E_AL between the fit and the 8-DOF ground truth (px; `None` likewise).
    pub residuals: Vec<Option<f64>>,
}

impl LowDofGroundTruth {
    /// Frames ordered by residual, largest first (the ones worth a look).
    pub fn worst_frames(&self) -> Vec<(usize, f64)> {
        let mut v: Vec<(usize, f64)> = self
            .residuals
            .iter()
            .enumerate()
            .filter_map(|(i, r)| r.map(|r| (i, r)))
            .collect();
        v.sort_by(|a, b| b.1.total_cmp(&a.1));
        v
    }
}

/// Fits `ssm` to every frame of `gt` (8-DOF quads), from the first annotated frame's quad.
pub fn fit_ground_truth(ssm_name: &str, gt: &[Option<Quad>]) -> Result<LowDofGroundTruth> {
    let model = super::quad_model(ssm_name)?;
    let mut quads = vec![None; gt.len()];
    let mut residuals = vec![None; gt.len()];
    if let Some(base) = gt.iter().flatten().next().copied() {
        for (i, q) in gt.iter().enumerate() {
            if let Some(q) = q
                && let Some((_, fit, e)) = best_fit(&*model, &base, q)
            {
                quads[i] = Some(fit);
                residuals[i] = Some(e);
            }
        }
    }
    Ok(LowDofGroundTruth {
        ssm: model.name().to_string(),
        quads,
        residuals,
    })
}

/// The folder of a sequence's ground truth (where OptGT and the corrections journal live): the
/// ground-truth file's folder, else the frames' folder.
pub fn ground_truth_dir(seq: &Sequence) -> PathBuf {
    seq.gt_path
        .as_ref()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .or_else(|| {
            seq.frames
                .first()
                .and_then(|f| f.parent().map(Path::to_path_buf))
        })
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or_else(|| PathBuf::from("."))
}

/// `<dir>/OptGT/<seq>_<ssm>.txt`.
pub fn opt_gt_path(dir: &Path, seq: &str, ssm: &str) -> PathBuf {
    dir.join("OptGT").join(format!("{seq}_{ssm}.txt"))
}

/// Its residuals beside it: `<dir>/OptGT/<seq>_<ssm>_residuals.txt`.
pub fn opt_gt_residuals_path(dir: &Path, seq: &str, ssm: &str) -> PathBuf {
    dir.join("OptGT").join(format!("{seq}_{ssm}_residuals.txt"))
}

/// The frame file names of a sequence (for the MTF format).
pub fn frame_names(seq: &Sequence) -> Vec<String> {
    seq.frames
        .iter()
        .map(|f| {
            f.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect()
}

/// Writes a low-DOF ground truth in OptGT layout under `dir` (atomically); frames without
/// corners are written `occluded` where `occluded` says so (it may be empty), `none` otherwise.
/// Returns the quads file and the residuals file.
pub fn write_opt_gt(
    dir: &Path,
    seq: &Sequence,
    low: &LowDofGroundTruth,
    occluded: &[bool],
) -> Result<(PathBuf, PathBuf)> {
    let path = opt_gt_path(dir, &seq.name, &low.ssm);
    let names = frame_names(seq);
    write_ground_truth(&path, &low.quads, occluded, Some(&names))?;
    let mut text = String::from("frame\tresidual_px\n");
    for (i, r) in low.residuals.iter().enumerate() {
        match r {
            Some(r) => text.push_str(&format!("{}\t{r:.6}\n", i + 1)),
            None => text.push_str(&format!("{}\tnone\n", i + 1)),
        }
    }
    let res = opt_gt_residuals_path(dir, &seq.name, &low.ssm);
    write_atomic(&res, text.as_bytes())?;
    Ok((path, res))
}

/// A sequence's ground truth for a low-DOF SSM ([`low_dof_ground_truth`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LowDofTruth {
    /// Each frame's quad (`None`: not annotated).
    pub quads: Vec<Option<Quad>>,
    /// The OptGT file they were read from (`None`: fitted now, or the sequence's own).
    pub path: Option<PathBuf>,
    /// One for each quad of the file that cannot be a target's, naming the file and line.
    pub warnings: Vec<String>,
}

/// The ground truth of `seq` for `ssm`: read from `<dir>/OptGT/<seq>_<ssm>.txt` when it exists
/// (a file with another number of frames is an error naming it), fitted otherwise. Returns the
/// quads, where they came from (`None`: fitted now) and a warning naming the file and line for
/// each quad that cannot be a target's (folded, collinear, tiny, far beyond any frame: read as
/// not annotated, as the sequence's own ground truth reads them). 8-DOF SSMs (every
/// parameterisation, and the non-rigid SSMs) give the sequence's own ground truth unless
/// `<seq>_homography.txt` (a corrected export) exists.
pub fn low_dof_ground_truth(seq: &Sequence, ssm_name: &str) -> Result<LowDofTruth> {
    let model = super::quad_model(ssm_name)?;
    // Under the key the corrections are kept under: the three 8-DOF parameterisations (and the
    // non-rigid SSMs) read the same file, `_homography`, as they describe the same quads.
    let path = opt_gt_path(
        &ground_truth_dir(seq),
        &seq.name,
        &super::ssm_key(ssm_name)?,
    );
    if path.exists() {
        let mut entries = read_ground_truth(&path)?;
        let warnings = crate::dataset::drop_unusable(&path, &mut entries);
        if entries.len() != seq.len() {
            return Err(Error::Sequence {
                path,
                message: format!(
                    "{} lines of ground truth for the {} frames of '{}'",
                    entries.len(),
                    seq.len(),
                    seq.name
                ),
            });
        }
        let quads = entries.into_iter().map(|e| e.quad).collect();
        return Ok(LowDofTruth {
            quads,
            path: Some(path),
            warnings,
        });
    }
    let quads = if model.dof() == 8 {
        seq.ground_truth.clone()
    } else {
        fit_ground_truth(model.name(), &seq.ground_truth)?.quads
    };
    Ok(LowDofTruth {
        quads,
        path: None,
        warnings: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point;

    fn base() -> Quad {
        Quad::from_rect(100.0, 80.0, 120.0, 90.0)
    }

    #[test]
    fn an_exact_warp_is_recovered_with_zero_residual() {
        for name in [
            "translation",
            "isometry",
            "similitude",
            "affine",
            "homography",
        ] {
            let m = ssm::build(name).unwrap();
            let mut rng = crate::rng::Rng::new(3);
            let p = ssm::random_warp(&*m, &base(), 8.0, &mut rng).unwrap();
            let target = ssm::warp_quad(&*m, &p, &base());
            let (_, q, e) = best_fit(&*m, &base(), &target).unwrap();
            assert!(e < 1e-6, "{name}: residual {e}");
            assert!(alignment_error(&q, &target) < 1e-6);
        }
    }

    #[test]
    fn the_fit_is_no_worse_than_least_squares_and_lowers_e_al() {
        // A projective target: the low-DOF SSMs cannot reach it. The E_AL-optimal fit must be at
        // most the least-squares fit's E_AL, and strictly lower for some SSM.
        let mut target = base();
        target.0[1] = Point::new(target.0[1].x + 12.0, target.0[1].y - 7.0);
        target.0[2] = Point::new(target.0[2].x + 3.0, target.0[2].y + 15.0);
        let mut improved = false;
        for name in ["translation", "isometry", "similitude", "affine"] {
            let m = ssm::build(name).unwrap();
            let ls = m.fit(&base().0, &target.0).unwrap();
            let e_ls = alignment_error(&ssm::warp_quad(&*m, &ls, &base()), &target);
            let (_, _, e) = best_fit(&*m, &base(), &target).unwrap();
            assert!(e <= e_ls + 1e-9, "{name}: {e} > least squares {e_ls}");
            improved |= e < e_ls - 1e-3;
            // No nearby parameters do better (a local optimum of E_AL).
            let (p, _, _) = best_fit(&*m, &base(), &target).unwrap();
            for j in 0..m.dof() {
                for s in [-1.0, 1.0] {
                    let mut q = p;
                    q[j] += s * 1e-4 * (1.0 + p[j].abs());
                    let e2 = alignment_error(&ssm::warp_quad(&*m, &q, &base()), &target);
                    assert!(
                        e2 >= e - 1e-7,
                        "{name}: parameter {j} lowers E_AL {e} -> {e2}"
                    );
                }
            }
        }
        assert!(improved, "the refinement never improved on least squares");
    }

    #[test]
    fn fitting_a_sequence_skips_frames_without_ground_truth() {
        let m = ssm::build("similitude").unwrap();
        let mut gt = vec![Some(base()), None];
        for k in 1..5 {
            let p = m
                .fit(
                    &base().0,
                    &base()
                        .map(|c| Point::new(c.x + 2.0 * k as f64, c.y - k as f64))
                        .0,
                )
                .unwrap();
            gt.push(Some(ssm::warp_quad(&*m, &p, &base())));
        }
        let low = fit_ground_truth("similitude", &gt).unwrap();
        assert_eq!(low.quads.len(), gt.len());
        assert!(low.quads[1].is_none() && low.residuals[1].is_none());
        for r in low.residuals.iter().flatten() {
            assert!(*r < 1e-6);
        }
    }
}

/// What [`fit_sequences`] did for one sequence and SSM.
#[derive(Clone, Debug, PartialEq)]
pub enum FitOutcome {
    /// The OptGT file exists and was kept (it may hold corrections exported by the inspector).
    Kept {
        sequence: String,
        ssm: String,
        path: PathBuf,
    },
    /// The fit was written.
    Written {
        sequence: String,
        ssm: String,
        /// Frames with ground truth.
        frames: usize,
        mean_residual: f64,
        /// The frame (0-based) with the largest residual, and that residual.
        worst: (usize, f64),
        path: PathBuf,
    },
}

/// `regtrack gt-fit`: for each sequence and SSM, the low-DOF ground truth fitted and written in
/// MTF's OptGT layout beside the sequence's ground truth; an existing file is kept unless
/// `force`. A sequence without any ground truth is an error.
pub fn fit_sequences(
    sequences: &[Sequence],
    ssms: &[String],
    force: bool,
) -> Result<Vec<FitOutcome>> {
    let mut out = Vec::new();
    for seq in sequences {
        if seq.ground_truth.iter().all(Option::is_none) {
            return Err(Error::Sequence {
                path: seq.gt_path.clone().unwrap_or_default(),
                message: format!("sequence '{}' has no ground truth to fit", seq.name),
            });
        }
        if seq.ground_truth.first().copied().flatten().is_none() {
            return Err(Error::Sequence {
                path: seq.gt_path.clone().unwrap_or_default(),
                message: format!(
                    "the first frame of '{}' has no usable ground truth, and the low-DOF ground \
                     truth is fitted from it{}",
                    seq.name,
                    seq.warnings
                        .first()
                        .map(|w| format!(" ({w})"))
                        .unwrap_or_default()
                ),
            });
        }
        let dir = ground_truth_dir(seq);
        for name in ssms {
            let low = fit_ground_truth(name, &seq.ground_truth)?;
            let path = opt_gt_path(&dir, &seq.name, &low.ssm);
            if path.exists() && !force {
                out.push(FitOutcome::Kept {
                    sequence: seq.name.clone(),
                    ssm: low.ssm,
                    path,
                });
                continue;
            }
            let (path, _) = write_opt_gt(&dir, seq, &low, &[])?;
            let r: Vec<f64> = low.residuals.iter().flatten().copied().collect();
            out.push(FitOutcome::Written {
                sequence: seq.name.clone(),
                ssm: low.ssm.clone(),
                frames: r.len(),
                mean_residual: r.iter().sum::<f64>() / r.len().max(1) as f64,
                worst: low.worst_frames().first().copied().unwrap_or((0, 0.0)),
                path,
            });
        }
    }
    Ok(out)
}
