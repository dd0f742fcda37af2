//! Points, quads (the tracked region: four corners), homographies between quads, the similarity
//! normalisation of a tracker's frame, and the error measures (alignment error, centre location
//! error, 1 - IoU).

mod error;
pub use error::{alignment_error, center_error, iou, polygon_area};

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
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
    /// `(min x, min y, max x, max y)`.
    pub fn bbox(&self) -> (f64, f64, f64, f64) {
        self.0.iter().fold(
            (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ),
            |b, p| (b.0.min(p.x), b.1.min(p.y), b.2.max(p.x), b.3.max(p.y)),
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
pub fn homography_from_points(src: &[Point; 4], dst: &[Point; 4]) -> Option<Matrix3<f64>> {
    let mut a = SMatrix::<f64, 8, 8>::zeros();
    let mut b = SVector::<f64, 8>::zeros();
    for k in 0..4 {
        let (x, y) = (src[k].x, src[k].y);
        let (u, v) = (dst[k].x, dst[k].y);
        let r = 2 * k;
        a[(r, 0)] = x;
        a[(r, 1)] = y;
        a[(r, 2)] = 1.0;
        a[(r, 6)] = -u * x;
        a[(r, 7)] = -u * y;
        b[r] = u;
        a[(r + 1, 3)] = x;
        a[(r + 1, 4)] = y;
        a[(r + 1, 5)] = 1.0;
        a[(r + 1, 6)] = -v * x;
        a[(r + 1, 7)] = -v * y;
        b[r + 1] = v;
    }
    let h = a.lu().solve(&b)?;
    if !h.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Matrix3::new(
        h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0,
    ))
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
