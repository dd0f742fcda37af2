//! Descriptor fields (Crivellaro and Lepetit, "Robust 3D Tracking with Descriptor Fields",
//! CVPR 2014; MTF's `dft`): an image's derivatives split by sign into channels of their own,
//! `[dI/dx]+, [dI/dx]-, [dI/dy]+, [dI/dy]-` (each `max(0, +-d)`), which the tracker then smooths
//! and samples like colour channels ([`crate::spec::Channels::Df`]).
//!
//! Why the split: smoothing an image's derivative averages an edge's positive and negative
//! responses away where edges of opposite sign are near (a thin line, a fine texture), so the
//! smoothing that widens a registration's basin also erases what it aligns on; smoothed apart,
//! each sign keeps its evidence. The fields depend on the image's gradients only, so a change
//! of brightness (bias) leaves them, and a change of contrast (gain) scales them all alike.

use super::filter::clip_rect;
use super::{GrayF32, ImageRef, Pixel};
use crate::geometry::Rect;

/// The number of first-order descriptor fields.
pub const FIELDS: usize = 4;

/// Writes the four descriptor fields of `src` within `rect` (rounded outwards to whole pixels
/// and clipped to the image) into `out`, each the image's size (resized when it is not; pixels
/// outside `rect` are left as they were). The derivatives are central differences, a
/// one-sided difference at the image's edges (the border replicated).
pub fn descriptor_fields_into<'a, T: Pixel>(
    src: impl Into<ImageRef<'a, T>>,
    rect: Rect,
    out: &mut [GrayF32; FIELDS],
) {
    let src = src.into();
    let (w, h) = (src.width, src.height);
    for plane in out.iter_mut() {
        if (plane.width, plane.height) != (w, h) {
            *plane = GrayF32::new(w, h);
        }
    }
    let (x0, y0, x1, y1) = clip_rect(rect, (0, 0, w, h));
    if x0 >= x1 || y0 >= y1 {
        return;
    }
    let [xp, xm, yp, ym] = out;
    for y in y0..y1 {
        let row = src.row(y);
        let up = src.row(y.saturating_sub(1));
        let down = src.row((y + 1).min(h - 1));
        let at = y * w;
        for x in x0..x1 {
            let left = row[x.saturating_sub(1)].to_f32();
            let right = row[(x + 1).min(w - 1)].to_f32();
            let dx = 0.5 * (right - left);
            let dy = 0.5 * (down[x].to_f32() - up[x].to_f32());
            xp.data[at + x] = dx.max(0.0);
            xm.data[at + x] = (-dx).max(0.0);
            yp.data[at + x] = dy.max(0.0);
            ym.data[at + x] = (-dy).max(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imaging::GrayU8;

    /// On a ramp rising to the right the x field is its slope and the others are zero; a
    /// bright vertical line gives the positive x field on its left flank and the negative on
    /// its right; outside the rectangle nothing is written; a bias leaves the fields.
    #[test]
    fn fields_split_the_gradient_by_sign() {
        let (w, h) = (12, 9);
        let ramp =
            GrayU8::from_vec(w, h, (0..w * h).map(|i| (10 * (i % w)) as u8).collect()).unwrap();
        let mut out: [GrayF32; FIELDS] = Default::default();
        descriptor_fields_into(&ramp, Rect::new(0.0, 0.0, w as f64, h as f64), &mut out);
        for y in 0..h {
            for x in 1..w - 1 {
                assert_eq!(out[0].get(x, y), 10.0, "({x}, {y})");
                assert_eq!(
                    (out[1].get(x, y), out[2].get(x, y), out[3].get(x, y)),
                    (0.0, 0.0, 0.0)
                );
            }
            // One-sided at the edges: half the step.
            assert_eq!(out[0].get(0, y), 5.0);
        }

        let mut line = GrayU8::new(w, h);
        for y in 0..h {
            line.set(6, y, 200);
        }
        let mut out: [GrayF32; FIELDS] = Default::default();
        descriptor_fields_into(&line, Rect::new(2.0, 1.0, 10.0, 8.0), &mut out);
        assert_eq!((out[0].get(5, 4), out[1].get(5, 4)), (100.0, 0.0));
        assert_eq!((out[0].get(7, 4), out[1].get(7, 4)), (0.0, 100.0));
        assert_eq!(out[0].get(6, 4) + out[1].get(6, 4), 0.0);
        assert_eq!(out[0].get(5, 0), 0.0, "outside the rectangle");

        let brighter =
            GrayU8::from_vec(w, h, line.data.iter().map(|&v| v / 2 + 40).collect()).unwrap();
        let mut again: [GrayF32; FIELDS] = Default::default();
        descriptor_fields_into(&brighter, Rect::new(2.0, 1.0, 10.0, 8.0), &mut again);
        assert_eq!((again[0].get(5, 4), again[1].get(7, 4)), (50.0, 50.0));
    }
}
