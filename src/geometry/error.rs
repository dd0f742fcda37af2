//! Error measures between a tracked quad and the ground truth.

use super::{Point, Quad};

/// Alignment error E_AL: the mean distance of the four corresponding corners.
pub fn alignment_error(a: &Quad, b: &Quad) -> f64 {
    a.0.iter().zip(&b.0).map(|(p, q)| p.dist(*q)).sum::<f64>() / 4.0
}

/// Centre location error: the distance of the centroids.
pub fn center_error(a: &Quad, b: &Quad) -> f64 {
    a.centroid().dist(b.centroid())
}

/// Signed area of a polygon (shoelace formula).
pub fn polygon_area(p: &[Point]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0
}

/// Clips `subject` by the convex polygon `clip` (Sutherland-Hodgman). `clip` must be wound
/// positively (counter-clockwise in y-up terms: positive shoelace area).
fn clip_convex(subject: &[Point], clip: &[Point]) -> Vec<Point> {
    let mut out: Vec<Point> = subject.to_vec();
    let n = clip.len();
    for i in 0..n {
        if out.is_empty() {
            break;
        }
        let (a, b) = (clip[i], clip[(i + 1) % n]);
        let inside = |p: Point| (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x) >= 0.0;
        let intersect = |p: Point, q: Point| {
            let (dx, dy) = (q.x - p.x, q.y - p.y);
            let (ex, ey) = (b.x - a.x, b.y - a.y);
            let den = dx * ey - dy * ex;
            if den.abs() < 1e-300 {
                return p;
            }
            let t = ((a.x - p.x) * ey - (a.y - p.y) * ex) / den;
            Point::new(p.x + t * dx, p.y + t * dy)
        };
        let input = std::mem::take(&mut out);
        for j in 0..input.len() {
            let (p, q) = (input[j], input[(j + 1) % input.len()]);
            match (inside(p), inside(q)) {
                (true, true) => out.push(q),
                (true, false) => out.push(intersect(p, q)),
                (false, true) => {
                    out.push(intersect(p, q));
                    out.push(q);
                }
                (false, false) => {}
            }
        }
    }
    out
}

fn positively_wound(q: &Quad) -> Vec<Point> {
    let mut v = q.0.to_vec();
    if polygon_area(&v) < 0.0 {
        v.reverse();
    }
    v
}

/// The part of `quad`'s area inside a `width x height` frame, 0 to 1 (the quad clipped to the
/// frame's rectangle; 0 for a quad without area).
pub fn fraction_inside(quad: &Quad, width: usize, height: usize) -> f64 {
    let whole = quad.signed_area().abs();
    if whole.is_nan() || whole <= 0.0 {
        return 0.0;
    }
    let frame = Quad::from_rect(0.0, 0.0, width as f64, height as f64);
    let inside = polygon_area(&clip_convex(
        &positively_wound(quad),
        &positively_wound(&frame),
    ));
    (inside.abs() / whole).clamp(0.0, 1.0)
}

/// Intersection over union of two quads. Exact when at least one is convex; for two non-convex
/// quads it falls back to their bounding boxes. Returns 0 for degenerate input.
pub fn iou(a: &Quad, b: &Quad) -> f64 {
    if !a.is_finite() || !b.is_finite() {
        return 0.0;
    }
    let (area_a, area_b) = (a.signed_area().abs(), b.signed_area().abs());
    let inter = if b.is_convex() {
        polygon_area(&clip_convex(&positively_wound(a), &positively_wound(b))).abs()
    } else if a.is_convex() {
        polygon_area(&clip_convex(&positively_wound(b), &positively_wound(a))).abs()
    } else {
        let (ba, bb) = (a.bbox(), b.bbox());
        let w = (ba.x1.min(bb.x1) - ba.x0.max(bb.x0)).max(0.0);
        let h = (ba.y1.min(bb.y1) - ba.y0.max(bb.y0)).max(0.0);
        let (aa, ab) = (ba.width() * ba.height(), bb.width() * bb.height());
        let i = w * h;
        return if aa + ab - i > 0.0 {
            i / (aa + ab - i)
        } else {
            0.0
        };
    };
    let union = area_a + area_b - inter;
    if union > 0.0 {
        (inter / union).clamp(0.0, 1.0)
    } else {
        0.0
    }
}
