//! Resampling an axis-aligned window of a frame to a fixed size (the trackers that work on
//! boxes: correlation filters, their scale pyramids, the detectors' normalised patches).

use super::{GrayF32, ImageView, sample_value};

/// Fills `out` (`out_w x out_h`, row-major) with the window of `src_w x src_h` frame pixels
/// centred at `(cx, cy)`, resampled bilinearly; outside the frame the edge is replicated. When a
/// window pixel covers more than 1.5 frame pixels, it averages a `k x k` grid of samples over its
/// footprint (an area filter against aliasing).
#[allow(clippy::too_many_arguments)]
pub fn resample_window(
    img: &GrayF32,
    cx: f64,
    cy: f64,
    src_w: f64,
    src_h: f64,
    out_w: usize,
    out_h: usize,
    out: &mut Vec<f32>,
) {
    out.clear();
    out.resize(out_w * out_h, 0.0);
    if img.data.is_empty() || out_w == 0 || out_h == 0 {
        return;
    }
    let view: ImageView = img.view();
    let sx = src_w / out_w as f64;
    let sy = src_h / out_h as f64;
    let k = sx.max(sy).ceil().clamp(1.0, 8.0) as usize;
    let k = if sx.max(sy) > 1.5 { k } else { 1 };
    let (hw, hh) = (0.5 * out_w as f64, 0.5 * out_h as f64);
    let inv = 1.0 / (k * k) as f32;
    for j in 0..out_h {
        for i in 0..out_w {
            let mut s = 0.0;
            for b in 0..k {
                // Window pixel i spans [i, i + 1) in window units; the window's centre is at
                // out_w / 2, placed on (cx, cy) (pixel centres are at whole coordinates).
                let fy = cy + sy * (j as f64 + (b as f64 + 0.5) / k as f64 - hh);
                for a in 0..k {
                    let fx = cx + sx * (i as f64 + (a as f64 + 0.5) / k as f64 - hw);
                    s += sample_value(&view, fx as f32, fy as f32);
                }
            }
            out[j * out_w + i] = s * inv;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_at_its_own_size_is_a_crop_and_a_halved_one_averages() {
        let (w, h) = (20, 16);
        let img = GrayF32 {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| (i % w) as f32 + 100.0 * (i / w) as f32)
                .collect(),
        };
        let mut out = Vec::new();
        // A 6x4 window centred between pixels 9, 10 and 7, 8: pixels 7..13 x 6..10.
        resample_window(&img, 9.5, 7.5, 6.0, 4.0, 6, 4, &mut out);
        assert_eq!(out[0], img.get(7, 6));
        assert_eq!(out[23], img.get(12, 9));
        // Half size: each output pixel is the mean of a 2x2 block (a linear image: its centre).
        resample_window(&img, 9.5, 7.5, 8.0, 8.0, 4, 4, &mut out);
        let expect = 0.5 * (img.get(6, 4) + img.get(7, 5));
        assert!((out[0] - expect).abs() < 1e-3, "{} vs {expect}", out[0]);
    }
}
