//! Points, quads (the tracked region: four corners), homographies between quads, the similarity
//! normalisation of a tracker's frame, and the error measures (alignment error, centre location
//! error, 1 - IoU).

mod error;
pub use error::{alignment_error, center_error, fraction_inside, iou, polygon_area};

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// A point in image (or normalised) coordinates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
}

impl Point {
    pub const fn new(x: f64, y: f64) -> Self {
        Point { x, y }
    }
    /// Euclidean distance.
    pub fn dist(self, o: Point) -> f64 {
        ((self.x - o.x).powi(2) + (self.y - o.y).powi(2)).sqrt()
    }
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
    /// Whether the point is more than half a `width x height` frame beyond its edges: where a
    /// tracked target's centre is taken to have left the frame.
    pub fn far_outside(self, width: usize, height: usize) -> bool {
        let (w, h) = (width as f64, height as f64);
        self.x < -0.5 * w || self.x > 1.5 * w || self.y < -0.5 * h || self.y > 1.5 * h
    }
}

/// An axis-aligned rectangle `[x0, x1) x [y0, y1)` in image (or normalised) coordinates: a
/// region to pre-process, the pixels a patch reads, a bounding box.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Rect {
    /// The whole plane (what a patch whose reads are not bounded reads).
    pub const EVERYTHING: Rect = Rect {
        x0: f64::NEG_INFINITY,
        y0: f64::NEG_INFINITY,
        x1: f64::INFINITY,
        y1: f64::INFINITY,
    };

    pub const fn new(x0: f64, y0: f64, x1: f64, y1: f64) -> Self {
        Rect { x0, y0, x1, y1 }
    }
    /// The rectangle of a `width x height` image.
    pub fn of_size(width: usize, height: usize) -> Self {
        Rect::new(0.0, 0.0, width as f64, height as f64)
    }
    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }
    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }
    /// The rectangle grown by `m` on every side.
    pub fn grown(&self, m: f64) -> Self {
        Rect::new(self.x0 - m, self.y0 - m, self.x1 + m, self.y1 + m)
    }
    /// The smallest rectangle holding both.
    pub fn union(&self, o: &Rect) -> Self {
        Rect::new(
            self.x0.min(o.x0),
            self.y0.min(o.y0),
            self.x1.max(o.x1),
            self.y1.max(o.y1),
        )
    }
    /// Whether `o` lies inside this rectangle (edges included).
    pub fn contains(&self, o: &Rect) -> bool {
        o.x0 >= self.x0 && o.y0 >= self.y0 && o.x1 <= self.x1 && o.y1 <= self.y1
    }
}

/// Four corners in the TMT/MTF order: upper-left, upper-right, lower-right, lower-left (for an
/// upright target). Any consistent order works for tracking; this is the order files use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Quad(pub [Point; 4]);

impl Quad {
    /// Corners from 8 numbers `ulx uly urx ury lrx lry llx lly`.
    pub fn from_array(v: [f64; 8]) -> Self {
        Quad([
            Point::new(v[0], v[1]),
            Point::new(v[2], v[3]),
            Point::new(v[4], v[5]),
            Point::new(v[6], v[7]),
        ])
    }
    /// The 8 numbers `ulx uly urx ury lrx lry llx lly`.
    pub fn to_array(&self) -> [f64; 8] {
        let c = &self.0;
        [
            c[0].x, c[0].y, c[1].x, c[1].y, c[2].x, c[2].y, c[3].x, c[3].y,
        ]
    }
    /// An axis-aligned box from its upper-left corner and size.
    pub fn from_rect(x: f64, y: f64, w: f64, h: f64) -> Self {
        Quad([
            Point::new(x, y),
            Point::new(x + w, y),
            Point::new(x + w, y + h),
            Point::new(x, y + h),
        ])
    }
    /// The unit square `[-0.5, 0.5]^2` in the corner order above.
    pub fn unit_square() -> Self {
        Quad::from_rect(-0.5, -0.5, 1.0, 1.0)
    }
    /// Mean of the corners.
    pub fn centroid(&self) -> Point {
        let (sx, sy) = self
            .0
            .iter()
            .fold((0.0, 0.0), |a, p| (a.0 + p.x, a.1 + p.y));
        Point::new(sx / 4.0, sy / 4.0)
    }
    /// Signed area (shoelace formula); positive for clockwise corners in image coordinates
    /// (y down), as in the TMT order.
    pub fn signed_area(&self) -> f64 {
        polygon_area(&self.0)
    }
    /// Whether the corners form a convex quad without self-intersection.
    pub fn is_convex(&self) -> bool {
        let c = &self.0;
        let mut sign = 0.0f64;
        for i in 0..4 {
            let (a, b, d) = (c[i], c[(i + 1) % 4], c[(i + 2) % 4]);
            let cross = (b.x - a.x) * (d.y - b.y) - (b.y - a.y) * (d.x - b.x);
            if cross.abs() < 1e-12 {
                return false;
            }
            if sign == 0.0 {
                sign = cross.signum();
            } else if cross.signum() != sign {
                return false;
            }
        }
        true
    }
    /// Every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.0.iter().all(|p| p.is_finite())
    }
    /// The smallest axis-aligned rectangle holding the corners.
    pub fn bbox(&self) -> Rect {
        self.0.iter().fold(
            Rect::new(
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ),
            |b, p| Rect::new(b.x0.min(p.x), b.y0.min(p.y), b.x1.max(p.x), b.y1.max(p.y)),
        )
    }
    /// Mean length of the four sides.
    pub fn mean_side(&self) -> f64 {
        (0..4)
            .map(|i| self.0[i].dist(self.0[(i + 1) % 4]))
            .sum::<f64>()
            / 4.0
    }
    /// The quad with every corner mapped by `f`.
    pub fn map(&self, f: impl Fn(Point) -> Point) -> Quad {
        Quad(self.0.map(f))
    }
    /// The L2 norm of the change of the 8 corner coordinates.
    pub fn change_norm(&self, o: &Quad) -> f64 {
        self.0
            .iter()
            .zip(&o.0)
            .map(|(a, b)| (a.x - b.x).powi(2) + (a.y - b.y).powi(2))
            .sum::<f64>()
            .sqrt()
    }
    /// Why the quad cannot be a target's, if it cannot: a coordinate that is not finite or
    /// beyond [`MAX_COORDINATE`], or a quad that is not convex (folded, collinear) or is tiny
    /// ([`Quad::validate`]). What ground truth, corrections and sessions may hold.
    pub fn unusable(&self) -> Option<String> {
        if let Some(x) = self
            .to_array()
            .into_iter()
            .find(|x| !x.is_finite() || x.abs() > MAX_COORDINATE)
        {
            return Some(format!(
                "a corner coordinate of {} is not a pixel position (at most {MAX_COORDINATE:e} px)",
                crate::error::short_number(x, 2)
            ));
        }
        self.validate().err().map(|e| e.to_string())
    }

    /// Checks that a quad can start a tracker: finite, convex and not tiny.
    pub fn validate(&self) -> crate::Result<()> {
        if !self.is_finite() {
            return Err(crate::Error::InvalidRegion(format!(
                "non-finite corner in {self}"
            )));
        }
        if !self.is_convex() {
            return Err(crate::Error::InvalidRegion(format!(
                "{self} is not a convex quad"
            )));
        }
        if self.signed_area().abs() < 4.0 {
            return Err(crate::Error::InvalidRegion(format!(
                "{self} is too small (area {:.2} px^2)",
                self.signed_area().abs()
            )));
        }
        Ok(())
    }
}

impl std::fmt::Display for Quad {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = |v: f64| crate::error::short_number(v, 2);
        let c = &self.0;
        write!(
            f,
            "[({}, {}) ({}, {}) ({}, {}) ({}, {})]",
            n(c[0].x),
            n(c[0].y),
            n(c[1].x),
            n(c[1].y),
            n(c[2].x),
            n(c[2].y),
            n(c[3].x),
            n(c[3].y)
        )
    }
}

/// The largest coordinate a usable quad may have (px): far beyond any frame, small enough that
/// every computation on it stays finite.
pub const MAX_COORDINATE: f64 = 1e7;

/// Applies a homography to a point (`None`-free: a point at infinity gives non-finite values).
#[inline]
pub fn apply_homography(h: &Matrix3<f64>, p: Point) -> Point {
    let v = h * Vector3::new(p.x, p.y, 1.0);
    Point::new(v.x / v.z, v.y / v.z)
}

/// The homography (h33 = 1) mapping the four `src` points onto the four `dst` points exactly,
/// or `None` when three of them are collinear.
///
/// Solved in closed form through the unit square: `H = S(dst) S(src)^-1`, where `S(q)` takes the
/// corners `(0, 0), (1, 0), (1, 1), (0, 1)` to `q`. Writing `S(q) = [a b c; d e f; g h 1]`, the
/// first, second and fourth corners give `c, f`, then `a, d` and `b, e` in terms of `g, h`, and
/// the third gives the 2 x 2 system `g (q1 - q2) + h (q3 - q2) = q0 - q1 + q2 - q3` (zero for a
/// parallelogram, whose `S` is affine). A particle filter fits thousands of these a frame.
pub fn homography_from_points(src: &[Point; 4], dst: &[Point; 4]) -> Option<Matrix3<f64>> {
    let to_src = square_to_quad(src)?.try_inverse()?;
    let h = square_to_quad(dst)? * to_src;
    let h = h / h[(2, 2)];
    h.iter().all(|v| v.is_finite()).then_some(h)
}

/// The homography taking the corners `(0, 0), (1, 0), (1, 1), (0, 1)` of the unit square to `q`
/// in that order; `None` when three of `q` are collinear.
fn square_to_quad(q: &[Point; 4]) -> Option<Matrix3<f64>> {
    let [p0, p1, p2, p3] = *q;
    let (sx, sy) = (p0.x - p1.x + p2.x - p3.x, p0.y - p1.y + p2.y - p3.y);
    let (dx1, dy1) = (p1.x - p2.x, p1.y - p2.y);
    let (dx2, dy2) = (p3.x - p2.x, p3.y - p2.y);
    let det = dx1 * dy2 - dx2 * dy1;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let g = (sx * dy2 - dx2 * sy) / det;
    let h = (dx1 * sy - sx * dy1) / det;
    let m = Matrix3::new(
        p1.x - p0.x + g * p1.x,
        p3.x - p0.x + h * p3.x,
        p0.x,
        p1.y - p0.y + g * p1.y,
        p3.y - p0.y + h * p3.y,
        p0.y,
        g,
        h,
        1.0,
    );
    // Three collinear corners make `S` singular although `det` is not zero.
    (m.determinant().abs() > 1e-12 * m.norm().powi(3)).then_some(m)
}

/// The homography mapping quad `a` onto quad `b`.
pub fn homography_between(a: &Quad, b: &Quad) -> Option<Matrix3<f64>> {
    homography_from_points(&a.0, &b.0)
}

/// The similarity that normalises a tracker's frame: the initial quad's centroid goes to the
/// origin and its size (square root of its area) to 1, so that warp parameters are of order one
/// whatever the size of the object. Being a similarity it keeps every class of warp
/// (translation, rotation, ..., homography) the same in image and normalised coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normaliser {
    pub cx: f64,
    pub cy: f64,
    /// Pixels per normalised unit.
    pub scale: f64,
}

impl Normaliser {
    /// The normaliser of a quad.
    pub fn of_quad(q: &Quad) -> Self {
        let c = q.centroid();
        let s = q.signed_area().abs().sqrt().max(1e-6);
        Normaliser {
            cx: c.x,
            cy: c.y,
            scale: s,
        }
    }
    /// Image to normalised coordinates.
    pub fn to_norm(&self, p: Point) -> Point {
        Point::new((p.x - self.cx) / self.scale, (p.y - self.cy) / self.scale)
    }
    /// Normalised to image coordinates.
    pub fn to_image(&self, p: Point) -> Point {
        Point::new(p.x * self.scale + self.cx, p.y * self.scale + self.cy)
    }
    /// The matrix of [`Normaliser::to_image`].
    pub fn to_image_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.scale, 0.0, self.cx, 0.0, self.scale, self.cy, 0.0, 0.0, 1.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{SMatrix, SVector};

    /// The direct linear transform written plainly: the 8 x 8 system of `h33 = 1`.
    fn dlt(src: &[Point; 4], dst: &[Point; 4]) -> Option<Matrix3<f64>> {
        let mut a = SMatrix::<f64, 8, 8>::zeros();
        let mut b = SVector::<f64, 8>::zeros();
        for k in 0..4 {
            let (x, y, u, v) = (src[k].x, src[k].y, dst[k].x, dst[k].y);
            let r = 2 * k;
            a.row_mut(r)
                .copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y]);
            a.row_mut(r + 1)
                .copy_from_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y]);
            b[r] = u;
            b[r + 1] = v;
        }
        let h = a.lu().solve(&b)?;
        Some(Matrix3::new(
            h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0,
        ))
    }

    #[test]
    fn the_closed_form_homography_is_the_linear_systems() {
        // A small seeded generator (the crate's is a layer above): uniform in [-1, 1).
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let mut quad = |spread: f64| {
            let base = [(0.0, 0.0), (100.0, 0.0), (100.0, 80.0), (0.0, 80.0)];
            base.map(|(x, y)| {
                Point::new(
                    200.0 + x + spread * uniform(),
                    50.0 + y + spread * uniform(),
                )
            })
        };
        for k in 0..500 {
            // Parallelograms (affine), then ever more projective quads.
            let spread = [0.0, 1.0, 10.0, 25.0][k % 4];
            let (src, dst) = (quad(spread), quad(spread));
            let h = homography_from_points(&src, &dst).expect("a homography");
            let reference = dlt(&src, &dst).unwrap();
            assert!(
                (h - reference).norm() < 1e-9 * reference.norm(),
                "{h} against {reference}"
            );
            for (s, d) in src.iter().zip(&dst) {
                assert!(apply_homography(&h, *s).dist(*d) < 1e-8);
            }
        }
        // Three collinear points: none.
        let line = [(0.0, 0.0), (1.0, 1.0), (2.0, 2.0), (0.0, 3.0)].map(|(x, y)| Point::new(x, y));
        let square = Quad::unit_square().0;
        assert!(homography_from_points(&line, &square).is_none());
        assert!(homography_from_points(&square, &line).is_none());
    }
}
