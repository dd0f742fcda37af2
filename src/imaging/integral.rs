//! Integral images (summed-area tables): the sum over any axis-aligned box in four reads, for
//! the box features of RCT and the variance filter of TLD's detector.

use super::GrayF32;

/// The integral image, one row and column larger (`ii[y][x]` = sum of pixels above-left).
pub struct Integral {
    pub w: usize,
    pub h: usize,
    pub data: Vec<f64>,
}

impl Integral {
    /// The sums of the pixels.
    pub fn new(img: &GrayF32) -> Self {
        Self::of(img, |v| v)
    }

    /// The sums of the squared pixels (with [`Integral::new`], the variance of any box).
    pub fn squares(img: &GrayF32) -> Self {
        Self::of(img, |v| v * v)
    }

    fn of(img: &GrayF32, f: impl Fn(f64) -> f64) -> Self {
        let (w, h) = (img.width, img.height);
        let mut data = vec![0.0; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0.0;
            for x in 0..w {
                row += f(img.data[y * w + x] as f64);
                data[(y + 1) * (w + 1) + x + 1] = data[y * (w + 1) + x + 1] + row;
            }
        }
        Integral { w, h, data }
    }

    /// The sum over `x0..x1, y0..y1`, clipped to the image.
    #[inline]
    pub fn sum(&self, x0: i64, y0: i64, x1: i64, y1: i64) -> f64 {
        let cx = |v: i64| v.clamp(0, self.w as i64) as usize;
        let cy = |v: i64| v.clamp(0, self.h as i64) as usize;
        let (x0, x1, y0, y1) = (cx(x0), cx(x1), cy(y0), cy(y1));
        let s = self.w + 1;
        self.data[y1 * s + x1] - self.data[y0 * s + x1] - self.data[y1 * s + x0]
            + self.data[y0 * s + x0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integral_sums_match_direct_sums_and_clip() {
        let img = GrayF32 {
            width: 5,
            height: 4,
            data: (0..20).map(|v| v as f32).collect(),
        };
        let ii = Integral::new(&img);
        let direct: f64 = (1..4)
            .flat_map(|x| (1..3).map(move |y| (y * 5 + x) as f64))
            .sum();
        assert_eq!(ii.sum(1, 1, 4, 3), direct);
        assert_eq!(ii.sum(-3, -3, 10, 10), (0..20).sum::<i32>() as f64);
    }
}
