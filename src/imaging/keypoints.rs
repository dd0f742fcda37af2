//! Keypoints for the keypoint-based trackers (CMT) and the many-patch tracker: the FAST-9 corner
//! detector of Rosten and Drummond with non-maximum suppression, the minimum-eigenvalue corners
//! of Shi and Tomasi ("Good features to track"), the intensity-centroid orientation, and
//! oriented binary (BRIEF-style) descriptors compared by Hamming distance.

use super::GrayF32;
use crate::geometry::Point;
use crate::rng::Rng;

/// A detected corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint {
    pub x: f64,
    pub y: f64,
    /// FAST score: the summed contrast beyond the threshold of the circle's pixels on the
    /// corner's side.
    pub score: f32,
}

impl Keypoint {
    pub fn point(&self) -> Point {
        Point {
            x: self.x,
            y: self.y,
        }
    }
}

/// The 16 pixels of the Bresenham circle of radius 3, clockwise from the top.
const CIRCLE: [(i32, i32); 16] = [
    (0, -3),
    (1, -3),
    (2, -2),
    (3, -1),
    (3, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 3),
    (-1, 3),
    (-2, 2),
    (-3, 1),
    (-3, 0),
    (-3, -1),
    (-2, -2),
    (-1, -3),
];

/// FAST-9 corners of `img` at least `border` pixels from its edges: pixels with 9 contiguous
/// circle pixels all brighter than it by more than `threshold` or all darker, kept where their
/// score is the largest of their 3 x 3 neighbourhood; the `max` best by score. A negative
/// `threshold` counts as 0.
pub fn fast(img: &GrayF32, threshold: f32, border: usize, max: usize) -> Vec<Keypoint> {
    fast_in(img, threshold, border, max, (0, 0, img.width, img.height))
}

/// [`fast`] within the pixels `x0..x1, y0..y1` of `region` only.
pub fn fast_in(
    img: &GrayF32,
    threshold: f32,
    border: usize,
    max: usize,
    region: (usize, usize, usize, usize),
) -> Vec<Keypoint> {
    let (w, h) = (img.width, img.height);
    let threshold = threshold.max(0.0);
    let b = border.max(3);
    if w <= 2 * b || h <= 2 * b {
        return Vec::new();
    }
    let (rx0, ry0) = (region.0.max(b), region.1.max(b));
    let (rx1, ry1) = (region.2.min(w - b), region.3.min(h - b));
    if rx0 >= rx1 || ry0 >= ry1 {
        return Vec::new();
    }
    let offs: Vec<isize> = CIRCLE
        .iter()
        .map(|&(dx, dy)| dy as isize * w as isize + dx as isize)
        .collect();
    // The scores of the region, with a margin of one zero pixel all round (what the
    // non-maximum suppression reads beyond the region).
    let (rw, rh) = (rx1 - rx0, ry1 - ry0);
    let sw = rw + 2;
    let mut score = vec![0f32; sw * (rh + 2)];
    let d = &img.data;
    let mut candidate = vec![false; rw];
    for y in ry0..ry1 {
        // Quick rejection, over the row at once (vectorised): a corner's 9 contiguous pixels
        // include at least two of the four compass points (circle pixels 0, 4, 8, 12) on the
        // same side.
        let row = &d[y * w + rx0..y * w + rx1];
        let north = &d[(y - 3) * w + rx0..(y - 3) * w + rx1];
        let south = &d[(y + 3) * w + rx0..(y + 3) * w + rx1];
        let east = &d[y * w + rx0 + 3..y * w + rx1 + 3];
        let west = &d[y * w + rx0 - 3..y * w + rx1 - 3];
        for (x, c) in candidate.iter_mut().enumerate() {
            let p = row[x];
            let (hi, lo) = (p + threshold, p - threshold);
            let (n, e, s, wv) = (north[x], east[x], south[x], west[x]);
            let bright = (n > hi) as u8 + (e > hi) as u8 + (s > hi) as u8 + (wv > hi) as u8;
            let dark = (n < lo) as u8 + (e < lo) as u8 + (s < lo) as u8 + (wv < lo) as u8;
            *c = bright >= 2 || dark >= 2;
        }
        for (cx, _) in candidate.iter().enumerate().filter(|c| *c.1) {
            let x = rx0 + cx;
            let i = y * w + x;
            let p = d[i];
            let (hi, lo) = (p + threshold, p - threshold);
            let at = |k: usize| d[(i as isize + offs[k]) as usize];
            // Masks of the circle pixels beyond the threshold on each side; a corner has 9
            // contiguous bits (the mask is doubled so that runs can wrap around).
            let (mut bm, mut dm) = (0u32, 0u32);
            let (mut bs, mut ds) = (0f32, 0f32);
            // Without branches (on texture the side of each pixel is a coin toss, and the
            // mispredicted branches took most of the time): a pixel not beyond a side adds a
            // zero to that side's sum, which leaves a non-negative sum's bits as they are
            // (`threshold >= 0`, so no pixel is beyond both).
            for k in 0..16 {
                let v = at(k);
                bm |= ((v > hi) as u32) << k;
                dm |= ((v < lo) as u32) << k;
                bs += (v - hi).max(0.0);
                ds += (lo - v).max(0.0);
            }
            let run9 = |m: u32| {
                let mut r = m | (m << 16);
                for _ in 0..8 {
                    r &= r >> 1;
                }
                r != 0
            };
            // The score: the summed contrast beyond the threshold on the corner's side.
            let best = match (run9(bm), run9(dm)) {
                (true, true) => bs.max(ds),
                (true, false) => bs,
                (false, true) => ds,
                (false, false) => 0.0,
            };
            score[(y - ry0 + 1) * sw + cx + 1] = best;
        }
    }
    let mut out = Vec::new();
    for ry in 1..=rh {
        for rx in 1..=rw {
            let s = score[ry * sw + rx];
            if s <= 0.0 {
                continue;
            }
            let mut is_max = true;
            'n: for dy in -1i32..=1 {
                for dx in -1i32..=1 {
                    if (dx, dy) == (0, 0) {
                        continue;
                    }
                    let j = (ry as i32 + dy) as usize * sw + (rx as i32 + dx) as usize;
                    // Ties go to the first in scan order.
                    if score[j] > s || (score[j] == s && (dy < 0 || (dy == 0 && dx < 0))) {
                        is_max = false;
                        break 'n;
                    }
                }
            }
            if is_max {
                out.push(Keypoint {
                    x: (rx0 + rx - 1) as f64,
                    y: (ry0 + ry - 1) as f64,
                    score: s,
                });
            }
        }
    }
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    out.truncate(max);
    out
}

/// Shi-Tomasi corners of `img` within the pixels `x0..x1, y0..y1` of `region` and at least
/// `border` pixels from the image's edges: pixels where the smaller eigenvalue of the structure
/// tensor (central-difference gradients, summed over the `(2 radius + 1)`-pixel window, divided
/// by its pixel count) is the largest of its 3 x 3 neighbourhood and at least `quality` times
/// the best; then, strongest first, those at least `min_distance` from every corner kept, at
/// most `max`. The score is the eigenvalue. Ties keep the raster order, so the result depends
/// only on the image.
pub fn shi_tomasi(
    img: &GrayF32,
    radius: usize,
    max: usize,
    min_distance: f64,
    quality: f32,
    border: usize,
    region: (usize, usize, usize, usize),
) -> Vec<Keypoint> {
    let (w, h) = (img.width, img.height);
    let b = border.max(radius + 2);
    if w <= 2 * b || h <= 2 * b || max == 0 {
        return Vec::new();
    }
    let (x0, y0) = (region.0.max(b), region.1.max(b));
    let (x1, y1) = (region.2.min(w - b), region.3.min(h - b));
    if x0 >= x1 || y0 >= y1 {
        return Vec::new();
    }
    // The tensor's entries over the region grown by the window (central differences need one
    // more pixel, which `b` leaves), then box sums along rows and columns.
    let r = radius;
    let (gx0, gy0, gx1, gy1) = (x0 - r - 1, y0 - r - 1, x1 + r + 1, y1 + r + 1);
    let gw = gx1 - gx0;
    let gh = gy1 - gy0;
    let d = &img.data;
    let mut prod = vec![[0f32; 3]; gw * gh];
    for y in gy0 + 1..gy1 - 1 {
        for x in gx0 + 1..gx1 - 1 {
            let i = y * w + x;
            let dx = 0.5 * (d[i + 1] - d[i - 1]);
            let dy = 0.5 * (d[i + w] - d[i - w]);
            prod[(y - gy0) * gw + (x - gx0)] = [dx * dx, dx * dy, dy * dy];
        }
    }
    // Box sums of the window: along the rows, then down the columns.
    let (rw, rh) = (x1 - x0 + 2, y1 - y0 + 2); // one more pixel around for the 3 x 3 maximum
    let mut rows = vec![[0f32; 3]; rw * gh];
    for y in 0..gh {
        for x in 0..rw {
            let cx = x + r; // column in `prod` of the window's centre (x0 - 1 + x)
            let mut acc = [0f32; 3];
            for t in &prod[y * gw + cx - r..=y * gw + cx + r] {
                acc[0] += t[0];
                acc[1] += t[1];
                acc[2] += t[2];
            }
            rows[y * rw + x] = acc;
        }
    }
    let n = ((2 * r + 1) * (2 * r + 1)) as f32;
    let mut eig = vec![0f32; rw * rh];
    for y in 0..rh {
        for x in 0..rw {
            let mut acc = [0f32; 3];
            for k in y..=y + 2 * r {
                let t = rows[k * rw + x];
                acc[0] += t[0];
                acc[1] += t[1];
                acc[2] += t[2];
            }
            let (a, bb, c) = (acc[0] / n, acc[1] / n, acc[2] / n);
            let half_tr = 0.5 * (a + c);
            let disc = (0.25 * (a - c) * (a - c) + bb * bb).sqrt();
            eig[y * rw + x] = (half_tr - disc).max(0.0);
        }
    }
    let best = eig.iter().copied().fold(0f32, f32::max);
    if best <= 0.0 {
        return Vec::new();
    }
    let floor = quality.max(0.0) * best;
    let mut found = Vec::new();
    for y in 1..rh - 1 {
        for x in 1..rw - 1 {
            let v = eig[y * rw + x];
            if v <= 0.0 || v < floor {
                continue;
            }
            let mut peak = true;
            'n: for dy in 0..3 {
                for dx in 0..3 {
                    if eig[(y + dy - 1) * rw + x + dx - 1] > v {
                        peak = false;
                        break 'n;
                    }
                }
            }
            if peak {
                found.push(Keypoint {
                    x: (x0 + x - 1) as f64,
                    y: (y0 + y - 1) as f64,
                    score: v,
                });
            }
        }
    }
    // Strongest first (a stable sort keeps the raster order among equals).
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    let md = min_distance.max(0.0);
    if md <= 0.0 {
        found.truncate(max);
        return found;
    }
    // Greedy spacing with a grid of cells `md` wide: only the 3 x 3 cells around can be close.
    let cell = md;
    let (cw, ch) = (
        (w as f64 / cell).ceil() as usize + 1,
        (h as f64 / cell).ceil() as usize + 1,
    );
    let mut grid: Vec<Vec<(f64, f64)>> = vec![Vec::new(); cw * ch];
    let mut kept = Vec::new();
    for k in found {
        let (cx, cy) = ((k.x / cell) as usize, (k.y / cell) as usize);
        let near = (cy.saturating_sub(1)..=(cy + 1).min(ch - 1)).any(|gy| {
            (cx.saturating_sub(1)..=(cx + 1).min(cw - 1)).any(|gx| {
                grid[gy * cw + gx]
                    .iter()
                    .any(|&(px, py)| (px - k.x).powi(2) + (py - k.y).powi(2) < md * md)
            })
        });
        if !near {
            grid[cy * cw + cx].push((k.x, k.y));
            kept.push(k);
            if kept.len() == max {
                break;
            }
        }
    }
    kept
}

/// The orientation of the patch of `radius` around `(x, y)` by its intensity centroid (radians).
pub fn orientation(img: &GrayF32, x: usize, y: usize, radius: i32) -> f64 {
    let (mut m10, mut m01) = (0f64, 0f64);
    let (w, h) = (img.width as i32, img.height as i32);
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            if dx * dx + dy * dy > radius * radius {
                continue;
            }
            let (u, v) = (x as i32 + dx, y as i32 + dy);
            if u < 0 || v < 0 || u >= w || v >= h {
                continue;
            }
            let val = img.data[(v * w + u) as usize] as f64;
            m10 += dx as f64 * val;
            m01 += dy as f64 * val;
        }
    }
    m01.atan2(m10)
}

/// A 256-bit binary descriptor.
pub type Descriptor = [u64; 4];

/// Hamming distance between two descriptors.
#[inline]
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    (a[0] ^ b[0]).count_ones()
        + (a[1] ^ b[1]).count_ones()
        + (a[2] ^ b[2]).count_ones()
        + (a[3] ^ b[3]).count_ones()
}

/// Oriented binary tests: 256 pairs of points in a disc of radius 15, drawn from an isotropic
/// Gaussian (seeded), rotated by the keypoint's orientation; each bit says whether the first
/// point of its pair is darker than the second (on a smoothed image).
#[derive(Clone, Debug)]
pub struct Brief {
    /// The pairs turned to each of [`ANGLES`] orientations, rounded to whole pixels (as ORB's
    /// lookup table: a keypoint's orientation picks the nearest).
    rotated: Vec<Vec<[i32; 4]>>,
}

/// Orientations of the precomputed patterns (12 degrees apart).
pub const ANGLES: usize = 30;

/// Pixels a keypoint must keep from the image's edges to be described.
pub const BRIEF_BORDER: usize = 18;

impl Brief {
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mut pt = || loop {
            let (x, y) = (rng.normal() * 31.0 / 5.0, rng.normal() * 31.0 / 5.0);
            if x * x + y * y <= 15.0 * 15.0 {
                return (x, y);
            }
        };
        let pairs: Vec<[f64; 4]> = (0..256)
            .map(|_| {
                let (a, b) = (pt(), pt());
                [a.0, a.1, b.0, b.1]
            })
            .collect();
        let rotated = (0..ANGLES)
            .map(|k| {
                let t = 2.0 * std::f64::consts::PI * k as f64 / ANGLES as f64;
                let (s, c) = t.sin_cos();
                let r = |u: f64, v: f64| {
                    (
                        (c * u - s * v).round() as i32,
                        (s * u + c * v).round() as i32,
                    )
                };
                pairs
                    .iter()
                    .map(|p| {
                        let (a, b) = (r(p[0], p[1]), r(p[2], p[3]));
                        [a.0, a.1, b.0, b.1]
                    })
                    .collect()
            })
            .collect();
        Brief { rotated }
    }

    /// The descriptor of `smoothed` at keypoint `(x, y)` turned by `angle`; `None` too close to
    /// the edges.
    pub fn describe(&self, smoothed: &GrayF32, x: f64, y: f64, angle: f64) -> Option<Descriptor> {
        let (w, h) = (smoothed.width as f64, smoothed.height as f64);
        let b = BRIEF_BORDER as f64;
        if !(x >= b && y >= b && x < w - b && y < h - b && angle.is_finite()) {
            return None;
        }
        let step = 2.0 * std::f64::consts::PI / ANGLES as f64;
        let k = (angle / step).round().rem_euclid(ANGLES as f64) as usize % ANGLES;
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        let width = smoothed.width as i64;
        let base = cy * width + cx;
        let px = |dx: i32, dy: i32| smoothed.data[(base + dy as i64 * width + dx as i64) as usize];
        let mut d = [0u64; 4];
        for (i, p) in self.rotated[k].iter().enumerate() {
            if px(p[0], p[1]) < px(p[2], p[3]) {
                d[i / 64] |= 1 << (i % 64);
            }
        }
        Some(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imaging::{gaussian_blur, gaussian_kernel};

    #[test]
    fn fast_finds_the_corners_of_a_square_and_nothing_on_its_sides() {
        let mut img = GrayF32::new(80, 80);
        for y in 0..80 {
            for x in 0..80 {
                let inside = (20..50).contains(&x) && (25..55).contains(&y);
                img.set(x, y, if inside { 200.0 } else { 40.0 });
            }
        }
        let kps = fast(&img, 20.0, 3, 100);
        assert_eq!(kps.len(), 4, "{kps:?}");
        for k in &kps {
            let near = [(20.0, 25.0), (49.0, 25.0), (20.0, 54.0), (49.0, 54.0)]
                .iter()
                .any(|&(cx, cy): &(f64, f64)| (k.x - cx).abs() <= 1.0 && (k.y - cy).abs() <= 1.0);
            assert!(near, "{k:?}");
        }
    }

    #[test]
    fn shi_tomasi_finds_the_corners_of_a_square_spaced_and_strongest_first() {
        let mut img = GrayF32::new(80, 80);
        for y in 0..80 {
            for x in 0..80 {
                let inside = (20..50).contains(&x) && (25..55).contains(&y);
                img.set(x, y, if inside { 200.0 } else { 40.0 });
            }
        }
        let img = gaussian_blur(&img, &gaussian_kernel(5, 1.0));
        let kps = shi_tomasi(&img, 3, 100, 5.0, 0.1, 4, (0, 0, 80, 80));
        assert_eq!(kps.len(), 4, "{kps:?}");
        for k in &kps {
            let near = [(19.5, 24.5), (49.5, 24.5), (19.5, 54.5), (49.5, 54.5)]
                .iter()
                .any(|&(cx, cy): &(f64, f64)| (k.x - cx).abs() <= 3.0 && (k.y - cy).abs() <= 3.0);
            assert!(near, "{k:?}");
        }
        assert!(kps.windows(2).all(|p| p[0].score >= p[1].score));
        // A region around one corner finds that one; `max` is kept.
        let one = shi_tomasi(&img, 3, 100, 5.0, 0.1, 4, (10, 15, 30, 35));
        assert_eq!(one.len(), 1, "{one:?}");
        assert_eq!(shi_tomasi(&img, 3, 2, 5.0, 0.1, 4, (0, 0, 80, 80)).len(), 2);
        // A flat image has none.
        assert!(shi_tomasi(&GrayF32::new(80, 80), 3, 10, 5.0, 0.1, 4, (0, 0, 80, 80)).is_empty());
    }

    /// An oriented descriptor of a rotated image matches the original's (few differing bits),
    /// and differs from another place's.
    #[test]
    fn oriented_descriptors_survive_a_rotation() {
        let n = 120;
        let pattern = |u: f64, v: f64| {
            128.0
                + 60.0 * (u / 4.0).sin() * (v / 6.0).cos()
                + 40.0 * ((0.7 * u - v) / 5.0).sin()
                + 30.0 * (-(u - 4.0).powi(2) / 40.0 - (v + 3.0).powi(2) / 60.0).exp()
        };
        let mut a = GrayF32::new(n, n);
        let mut b = GrayF32::new(n, n);
        let th = 0.9f64;
        let c = 60.0;
        for y in 0..n {
            for x in 0..n {
                let (u, v) = (x as f64 - c, y as f64 - c);
                a.set(x, y, pattern(u, v) as f32);
                // b = a rotated by th about the centre.
                let (ru, rv) = (th.cos() * u + th.sin() * v, -th.sin() * u + th.cos() * v);
                b.set(x, y, pattern(ru, rv) as f32);
            }
        }
        let k = gaussian_kernel(5, 2.0);
        let (sa, sb) = (gaussian_blur(&a, &k), gaussian_blur(&b, &k));
        let brief = Brief::new(7);
        let oa = orientation(&sa, 60, 60, 15);
        let ob = orientation(&sb, 60, 60, 15);
        let diff = (ob - oa - th).rem_euclid(2.0 * std::f64::consts::PI);
        assert!(
            diff.min(2.0 * std::f64::consts::PI - diff) < 0.1,
            "{oa} {ob}"
        );
        let da = brief.describe(&sa, 60.0, 60.0, oa).unwrap();
        let db = brief.describe(&sb, 60.0, 60.0, ob).unwrap();
        let other = brief
            .describe(&sa, 80.0, 45.0, orientation(&sa, 80, 45, 15))
            .unwrap();
        let (same, diff) = (hamming(&da, &db), hamming(&da, &other));
        assert!(same < 40 && diff > 2 * same, "{same} {diff}");
        assert!(brief.describe(&sa, 5.0, 60.0, 0.0).is_none());
    }
}
