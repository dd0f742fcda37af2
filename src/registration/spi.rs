//! Selective pixel integration (MTF's SPI; tracker parameters `spi`, `spi_keep`, `spi_mask_*`):
//! a search reads only the grid points that carry information, chosen once on the template:
//! those where its gradient is largest (the others add little to a Newton step's `J^T J` and
//! nothing to its direction), and never those in a rectangle of the target the user leaves out
//! (a known occluder: a sticker, a logo, a time stamp). Each problem chooses on its own template
//! (each pyramid level, each SSM of the hierarchy), so a search costs about `spi_keep` of its
//! whole grid's. The whole grid stays for what judges a frame (the confidences compare block by
//! block, leaving out the blocks a mask covers: [`super::BlockCorrelation::set_mask`]) and what
//! the inspector shows ([`super::Problem::whole_grid`]).

use crate::spec::{Spi, TrackerParams};

/// Which points a problem's searches read.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Selection {
    /// The fraction of the points kept by the template's gradient (`None`: no ranking).
    pub keep: Option<f64>,
    /// The rectangle left out (left, top, right, bottom in the target's unit square).
    pub mask: Option<[f64; 4]>,
}

impl Selection {
    /// The selection the tracker parameters ask for.
    pub fn of(params: &TrackerParams) -> Self {
        Selection {
            keep: (params.spi == Spi::Gradient).then_some(params.spi_keep),
            mask: params.spi_mask(),
        }
    }

    /// Whether every point is read.
    pub fn is_whole(&self) -> bool {
        self.keep.is_none() && self.mask.is_none()
    }

    /// The points kept (ascending indices, in the grid's order) of a grid whose points are at
    /// `(u, v)` in the target's unit square (`-0.5..0.5`) and where the template's gradient is
    /// `(gx, gy)`; `None` when every point is kept, or when the mask would leave none.
    pub fn points(
        &self,
        (u, v): (&[f32], &[f32]),
        (gx, gy): (&[f32], &[f32]),
    ) -> Option<Vec<usize>> {
        let n = u.len().min(v.len()).min(gx.len()).min(gy.len());
        let outside = |i: usize| {
            self.mask.is_none_or(|[l, t, r, b]| {
                let (x, y) = (u[i] as f64 + 0.5, v[i] as f64 + 0.5);
                !(x >= l && x <= r && y >= t && y <= b)
            })
        };
        let mut kept: Vec<usize> = (0..n).filter(|&i| outside(i)).collect();
        if kept.is_empty() {
            return None;
        }
        if let Some(keep) = self.keep {
            let count = ((keep * n as f64).ceil() as usize).clamp(1, kept.len());
            let energy = |i: usize| gx[i] * gx[i] + gy[i] * gy[i];
            // The largest gradients first; equal ones in the grid's order.
            kept.sort_by(|&a, &b| energy(b).total_cmp(&energy(a)).then(a.cmp(&b)));
            kept.truncate(count);
            kept.sort_unstable();
        }
        (kept.len() < n).then_some(kept)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 x 10 grid of the unit square's cell centres.
    fn grid() -> (Vec<f32>, Vec<f32>) {
        (0..100)
            .map(|i| {
                (
                    ((i % 10) as f32 + 0.5) / 10.0 - 0.5,
                    ((i / 10) as f32 + 0.5) / 10.0 - 0.5,
                )
            })
            .unzip()
    }

    #[test]
    fn the_largest_gradients_are_kept_outside_the_mask_in_the_grids_order() {
        let (u, v) = grid();
        let gx: Vec<f32> = (0..100).map(|i| (i % 10) as f32).collect();
        let gy = vec![0.0; 100];
        assert_eq!(Selection::default().points((&u, &v), (&gx, &gy)), None);
        let by_gradient = Selection {
            keep: Some(0.3),
            mask: None,
        };
        let kept = by_gradient.points((&u, &v), (&gx, &gy)).unwrap();
        assert_eq!(kept.len(), 30);
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        assert!(kept.iter().all(|&i| i % 10 >= 7), "{kept:?}");
        // The left half of the target left out.
        let masked = Selection {
            keep: None,
            mask: Some([0.0, 0.0, 0.5, 1.0]),
        };
        let kept = masked.points((&u, &v), (&gx, &gy)).unwrap();
        assert_eq!(kept.len(), 50);
        assert!(kept.iter().all(|&i| i % 10 >= 5));
        // Both: the fraction is of the whole grid, among the points outside the mask.
        let both = Selection {
            keep: Some(0.7),
            mask: Some([0.0, 0.0, 0.5, 1.0]),
        };
        assert_eq!(both.points((&u, &v), (&gx, &gy)).unwrap(), kept);
        // A mask over everything leaves every point (no search could run on none).
        let all = Selection {
            keep: None,
            mask: Some([0.0, 0.0, 1.0, 1.0]),
        };
        assert_eq!(all.points((&u, &v), (&gx, &gy)), None);
        let p = TrackerParams {
            spi: Spi::Gradient,
            spi_keep: 0.25,
            spi_mask_right: 0.5,
            spi_mask_bottom: 0.25,
            ..Default::default()
        };
        assert_eq!(
            Selection::of(&p),
            Selection {
                keep: Some(0.25),
                mask: Some([0.0, 0.0, 0.5, 0.25])
            }
        );
        assert!(Selection::of(&TrackerParams::default()).is_whole());
    }

    /// A context that selects keeps the whole grid for the confidences and searches the rest:
    /// its grid, template, gradients and `dw/dp` are the whole ones' at the points kept; the
    /// whole patch is what a context without a selection samples; a new region reads the
    /// whole grid again until its template is sampled.
    #[test]
    fn a_selection_keeps_the_whole_grid_beside_the_part_searched() {
        use crate::am::HessianKind;
        use crate::geometry::{Quad, Rect};
        use crate::imaging::{GrayF32, gaussian_kernel};
        use crate::registration::{Context, FrameSource};
        use crate::spec::GridLayout;
        use crate::visual_tracker::FrameInput;
        let img = GrayF32 {
            width: 80,
            height: 80,
            data: (0..80 * 80)
                .map(|i| {
                    let (x, y) = ((i % 80) as f32, (i / 80) as f32);
                    120.0 + 60.0 * (x * 0.3).sin() * (y * 0.05).cos() + 30.0 * (y * 0.4).sin()
                })
                .collect(),
        };
        let mut src = FrameSource::new(gaussian_kernel(1, 0.0), 0);
        let input = FrameInput::Gray32(&img);
        src.prepare(input, Rect::of_size(80, 80));
        let view = src.view(input, 0);
        let quad = Quad::from_rect(15.0, 12.0, 50.0, 44.0);
        let res = 20;
        let make = |selection: Selection| {
            let mut ctx = Context::new(
                crate::ssm::build("homography").unwrap(),
                crate::am::build("ssd").unwrap(),
                HessianKind::Default,
                res,
            );
            ctx.set_selection(selection);
            ctx.set_region(&quad, res, GridLayout::Centres).unwrap();
            ctx.sample_template(&view);
            ctx
        };
        let mut whole = make(Selection::default());
        let selection = Selection {
            keep: Some(0.4),
            mask: Some([0.0, 0.0, 0.2, 1.0]),
        };
        let mut part = make(selection);
        let problem = part.problem();
        let kept = selection
            .points(
                whole.problem().unit_grid(),
                whole.problem().template_gradient(),
            )
            .unwrap();
        assert_eq!(problem.len(), kept.len());
        assert_eq!(kept.len(), (0.4 * (res * res) as f64).ceil() as usize);
        assert!(problem.is_selective() && !whole.problem().is_selective());
        assert_eq!(problem.whole_grid(), whole.problem().grid());
        assert_eq!(problem.whole_template(), whole.problem().template());
        assert_eq!(part.am().template(), problem.template());
        let n = res * res;
        let (wd, _) = whole.problem().dwdp0();
        let (pd, zero) = problem.dwdp0();
        for (k, &i) in kept.iter().enumerate() {
            assert_eq!(problem.grid().0[k], whole.problem().grid().0[i]);
            assert_eq!(problem.unit_grid().1[k], whole.problem().unit_grid().1[i]);
            assert_eq!(problem.template()[k], whole.problem().template()[i]);
            assert_eq!(
                problem.template_gradient().1[k],
                whole.problem().template_gradient().1[i]
            );
            for r in 0..16 {
                assert_eq!(pd[r * kept.len() + k], wd[r * n + i]);
            }
        }
        assert!(problem.moments().is_none());
        assert!(
            zero.iter()
                .zip(whole.problem().dwdp0().1)
                .all(|(a, b)| a == b)
        );
        // The whole patch, sampled or held, is the whole grid's; the search reads its part.
        let mut p = part.params();
        p[0] = 0.02;
        let want = whole.whole_sample_at(&view, &p).to_vec();
        assert_eq!(part.whole_sample_at(&view, &p), &want[..]);
        assert_eq!(part.whole_patch_at(&view, &p), &want[..]);
        assert_eq!(part.whole_values(), &want[..]);
        part.sample_at(&view, &p);
        let values: Vec<f32> = kept.iter().map(|&i| want[i]).collect();
        assert_eq!(part.values(), &values[..]);
        assert_eq!(part.whole_values(), &want[..]);
        // Without a selection the whole patch is the search's own.
        assert_eq!(whole.whole_values(), whole.values());
        // A new region: the whole grid until its template is sampled.
        part.set_region(&quad, res, GridLayout::Centres).unwrap();
        assert_eq!(part.len(), n);
        assert!(!part.problem().is_selective());
        part.sample_template(&view);
        assert_eq!(part.len(), kept.len());
    }
}
