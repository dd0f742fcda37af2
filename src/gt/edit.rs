//! Editing a ground-truth quad by hand: a corner moved within an SSM's degrees of freedom, and
//! the region of a frame inside a quad, rectified (what the inspector's editor shows beside the
//! template). Free of any window, so that it is tested as it is.

use crate::geometry::{Point, Quad, apply_homography, homography_between};
use crate::imaging::{GrayF32, sample_values};
use crate::ssm;

/// Moves corner `k` of `q` to `to` within `ssm`'s DOF: translation moves the whole quad;
/// isometry turns it about the opposite corner towards `to`; similitude turns and scales it
/// about the opposite corner so that the corner lands on `to`; affine keeps the two neighbours of
/// the corner (the opposite corner follows, a parallelogram stays one); 8-DOF SSMs move the
/// corner alone.
pub fn move_corner(ssm_name: &str, q: &Quad, k: usize, to: Point) -> Quad {
    let k = k.min(3);
    let dof = ssm::build(ssm_name).map(|m| m.dof()).unwrap_or(8);
    let p = q.0[k];
    match dof {
        2 => q.map(|c| Point::new(c.x + to.x - p.x, c.y + to.y - p.y)),
        3 | 4 => {
            let o = q.0[(k + 2) % 4];
            let (ax, ay) = (p.x - o.x, p.y - o.y);
            let (bx, by) = (to.x - o.x, to.y - o.y);
            let n = ax * ax + ay * ay;
            if n < 1e-12 {
                return *q;
            }
            // The complex ratio (b / a) = scale * rotation.
            let (mut re, mut im) = ((bx * ax + by * ay) / n, (by * ax - bx * ay) / n);
            if dof == 3 {
                let s = (re * re + im * im).sqrt().max(1e-12);
                re /= s;
                im /= s;
            }
            q.map(|c| {
                let (x, y) = (c.x - o.x, c.y - o.y);
                Point::new(o.x + re * x - im * y, o.y + im * x + re * y)
            })
        }
        6 => {
            // The affine map fixing both neighbours and taking p to `to`: x -> x + (to - p) * w(x),
            // with w the barycentric weight of p in the triangle (p, n1, n2).
            let (n1, n2) = (q.0[(k + 1) % 4], q.0[(k + 3) % 4]);
            let det = (p.x - n1.x) * (n2.y - n1.y) - (p.y - n1.y) * (n2.x - n1.x);
            if det.abs() < 1e-12 {
                return *q;
            }
            let w = |c: Point| ((c.x - n1.x) * (n2.y - n1.y) - (c.y - n1.y) * (n2.x - n1.x)) / det;
            q.map(|c| {
                let t = w(c);
                Point::new(c.x + t * (to.x - p.x), c.y + t * (to.y - p.y))
            })
        }
        _ => {
            let mut out = *q;
            out.0[k] = to;
            out
        }
    }
}

/// What a pointer pressed on a ground-truth quad takes hold of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grab {
    /// Corner `k`.
    Corner(usize),
    /// The whole quad (pressed inside it).
    Quad,
}

impl Grab {
    /// The corner, or `None` for the whole quad.
    pub fn corner(self) -> Option<usize> {
        match self {
            Grab::Corner(k) => Some(k),
            Grab::Quad => None,
        }
    }
}

/// What a press at `p` takes hold of: the nearest corner within `radius` (px), else the whole
/// quad if `p` is inside it, else nothing.
pub fn grab(q: &Quad, p: Point, radius: f64) -> Option<Grab> {
    let nearest = (0..4)
        .map(|k| (k, q.0[k].dist(p)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, d)| *d < radius);
    if let Some((k, _)) = nearest {
        return Some(Grab::Corner(k));
    }
    // Inside a convex quad: `p` is on the same side of all four edges.
    let side = |a: Point, b: Point| crate::geometry::polygon_area(&[a, b, p]).signum();
    let s: Vec<f64> = (0..4).map(|k| side(q.0[k], q.0[(k + 1) % 4])).collect();
    (s[0] != 0.0 && s.iter().all(|&v| v == s[0])).then_some(Grab::Quad)
}

/// The quad `q0` after a drag from `from` to `to` of what was grabbed: a corner moves within
/// `ssm_name`'s DOF ([`move_corner`]), the whole quad translates.
pub fn drag(ssm_name: &str, q0: &Quad, grab: Grab, from: Point, to: Point) -> Quad {
    match grab {
        Grab::Corner(k) => move_corner(ssm_name, q0, k, to),
        Grab::Quad => q0.map(|c| Point::new(c.x + to.x - from.x, c.y + to.y - from.y)),
    }
}

/// The region of `img` inside `q`, rectified to `side x side` gray levels (row by row; the
/// first row runs from the quad's first corner to its second), sampled bilinearly with the
/// border replicated. `None` for an empty image or a quad without a homography.
pub fn rectify(img: &GrayF32, q: &Quad, side: usize) -> Option<Vec<u8>> {
    if img.width == 0 || img.height == 0 || side == 0 {
        return None;
    }
    let s = side as f64;
    let h = homography_between(&Quad::from_rect(0.0, 0.0, s, s), q)?;
    let n = side * side;
    let (mut xs, mut ys) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for y in 0..side {
        for x in 0..side {
            let p = apply_homography(&h, Point::new(x as f64 + 0.5, y as f64 + 0.5));
            let p = if p.is_finite() {
                p
            } else {
                Point::new(-1e6, -1e6)
            };
            xs.push(p.x as f32);
            ys.push(p.y as f32);
        }
    }
    let mut v = vec![0.0f32; n];
    sample_values(&img.view(), &xs, &ys, &mut v);
    Some(
        v.iter()
            .map(|&g| g.round().clamp(0.0, 255.0) as u8)
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_moves_stay_in_the_ssm() {
        let q = Quad::from_rect(10.0, 20.0, 40.0, 30.0);
        let to = Point::new(q.0[2].x + 6.0, q.0[2].y + 3.0);
        for name in [
            "translation",
            "isometry",
            "similitude",
            "affine",
            "homography",
        ] {
            let m = ssm::build(name).unwrap();
            let moved = move_corner(name, &q, 2, to);
            let (_, _, r) = crate::gt::best_fit(&*m, &q, &moved).unwrap();
            assert!(
                r < 1e-6,
                "{name}: the moved quad is not a {name} warp ({r} px)"
            );
            if name != "isometry" {
                assert!(
                    moved.0[2].dist(to) < 1e-9,
                    "{name}: the corner reaches the pointer"
                );
            }
            match name {
                "translation" => assert!(moved.0[0].dist(Point::new(16.0, 23.0)) < 1e-9),
                "isometry" | "similitude" => assert!(moved.0[0].dist(q.0[0]) < 1e-9),
                "affine" => {
                    assert!(moved.0[1].dist(q.0[1]) < 1e-9 && moved.0[3].dist(q.0[3]) < 1e-9)
                }
                _ => assert_eq!(moved.0[0], q.0[0]),
            }
        }
    }

    #[test]
    fn a_press_grabs_the_nearest_corner_or_the_quad_and_a_drag_moves_it() {
        let q = Quad::from_rect(10.0, 20.0, 40.0, 30.0);
        assert_eq!(grab(&q, Point::new(12.0, 21.0), 5.0), Some(Grab::Corner(0)));
        assert_eq!(grab(&q, Point::new(49.0, 49.0), 5.0), Some(Grab::Corner(2)));
        assert_eq!(grab(&q, Point::new(30.0, 35.0), 5.0), Some(Grab::Quad));
        assert_eq!(grab(&q, Point::new(80.0, 35.0), 5.0), None);
        // Clockwise or counter-clockwise, inside is inside.
        let mut ccw = q;
        ccw.0.reverse();
        assert_eq!(grab(&ccw, Point::new(30.0, 35.0), 5.0), Some(Grab::Quad));
        let moved = drag(
            "homography",
            &q,
            Grab::Quad,
            Point::new(30.0, 35.0),
            Point::new(33.0, 31.0),
        );
        assert!(moved.0[0].dist(Point::new(13.0, 16.0)) < 1e-12);
        let corner = drag(
            "homography",
            &q,
            Grab::Corner(1),
            q.0[1],
            Point::new(55.0, 18.0),
        );
        assert_eq!(corner.0[1], Point::new(55.0, 18.0));
        assert_eq!(corner.0[0], q.0[0]);
    }

    #[test]
    fn a_rectified_region_is_the_frame_inside_the_quad() {
        // A horizontal ramp: the rectified axis-aligned square reads the ramp back.
        let mut img = GrayF32::new(64, 48);
        for y in 0..48 {
            for x in 0..64 {
                img.set(x, y, 2.0 * x as f32);
            }
        }
        let q = Quad::from_rect(10.0, 8.0, 32.0, 32.0);
        let r = rectify(&img, &q, 16).unwrap();
        assert_eq!(r.len(), 256);
        for (k, &v) in r.iter().enumerate() {
            // Cell centre (k % 16 + 0.5) of 16 cells over 32 px from x = 10 (pixel k's value
            // lies at coordinate k).
            let x = 10.0 + (k % 16) as f32 * 2.0 + 1.0;
            assert!((v as f32 - 2.0 * x).abs() <= 1.0, "{k}: {v} vs {}", 2.0 * x);
        }
        assert!(rectify(&GrayF32::new(0, 0), &q, 16).is_none());
    }
}
