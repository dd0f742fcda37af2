//! The annotation files of the benchmarks' own layouts, beside the corner files of
//! [`super::read_ground_truth`]: VOT region files (read and written), `x, y, w, h` boxes (GOT-10k,
//! LaSOT), homographies of 9 numbers a line (POT, PlanarTrack), flags of one integer a line,
//! and UCSB's `.warps`.
//!
//! Every reader takes text already read (CRLF and a byte-order mark are the callers' concern:
//! [`crate::files::read_text`] removes both), skips blank trailing lines, and names the file and
//! the 1-based line of anything it cannot read.

use crate::error::{Error, Result};
use crate::geometry::{Point, Quad, apply_homography};
use nalgebra::Matrix3;
use std::path::Path;

/// One line of a VOT region file.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// A special code of a results file: `1` initialisation, `2` failure, `0` a frame skipped
    /// after a failure (a ground-truth file has none).
    Code(u8),
    /// An axis-aligned box: the upper-left corner, width and height.
    Rect { x: f64, y: f64, w: f64, h: f64 },
    /// A polygon of 3 or more points, in the file's order.
    Polygon(Vec<Point>),
    /// A frame without a region: an empty line, a box of no area, a mask (`m...`, not readable
    /// as corners) or NaN values.
    Empty,
}

/// VOT's codes in results files.
pub const VOT_INIT: u8 = 1;
pub const VOT_FAILURE: u8 = 2;
pub const VOT_SKIPPED: u8 = 0;

impl Region {
    /// The four corners of the region: a box's, a polygon of 4 points as given, the axis-aligned
    /// box around a polygon of other counts; `None` for a code or an empty region.
    pub fn quad(&self) -> Option<Quad> {
        match self {
            Region::Rect { x, y, w, h } if *w > 0.0 && *h > 0.0 => {
                Some(Quad::from_rect(*x, *y, *w, *h))
            }
            Region::Polygon(p) if p.len() == 4 => Some(Quad([p[0], p[1], p[2], p[3]])),
            Region::Polygon(p) if p.len() >= 3 => {
                let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
                for q in p {
                    (x0, y0, x1, y1) = (x0.min(q.x), y0.min(q.y), x1.max(q.x), y1.max(q.y));
                }
                (x1 > x0 && y1 > y0).then(|| Quad::from_rect(x0, y0, x1 - x0, y1 - y0))
            }
            _ => None,
        }
    }
}

/// The numbers of a line separated by commas, semicolons, tabs or spaces; an error naming the
/// token that is not a number.
fn numbers(path: &Path, line: usize, text: &str) -> Result<Vec<f64>> {
    text.split(|c: char| c.is_whitespace() || c == ',' || c == ';')
        .filter(|t| !t.is_empty())
        .enumerate()
        .map(|(k, t)| {
            t.parse::<f64>().map_err(|_| Error::Parse {
                path: path.to_path_buf(),
                line,
                message: format!(
                    "'{}' is not a number (value {})",
                    crate::error::short_text(t),
                    k + 1
                ),
            })
        })
        .collect()
}

/// The lines of a file that are frames: every line up to the last non-blank one (a blank line
/// among them is a frame too), each with its 1-based number.
fn frame_lines(text: &str) -> Vec<(usize, &str)> {
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .collect();
    let end = lines
        .iter()
        .rposition(|(_, l)| !l.is_empty())
        .map_or(0, |k| k + 1);
    lines[..end].to_vec()
}

/// Parses a VOT region file: a line per frame, `x,y,w,h` (a box), `x1,y1,...,xn,yn` with n >= 3
/// (a polygon), a single code `0`, `1` or `2` (results files), `m...` (a mask: read as no
/// region) or an empty line.
pub fn parse_vot_regions(path: &Path, text: &str) -> Result<Vec<Region>> {
    frame_lines(text)
        .into_iter()
        .map(|(line, l)| {
            if l.is_empty() || l.starts_with('m') {
                return Ok(Region::Empty);
            }
            let v = numbers(path, line, l)?;
            if v.iter().any(|x| x.is_nan()) {
                return Ok(Region::Empty);
            }
            match v.len() {
                1 if [0.0, 1.0, 2.0].contains(&v[0]) => Ok(Region::Code(v[0] as u8)),
                4 => Ok(Region::Rect {
                    x: v[0],
                    y: v[1],
                    w: v[2],
                    h: v[3],
                }),
                n if n >= 6 && n % 2 == 0 => Ok(Region::Polygon(
                    v.chunks(2).map(|c| Point::new(c[0], c[1])).collect(),
                )),
                n => Err(Error::Parse {
                    path: path.to_path_buf(),
                    line,
                    message: format!(
                        "a VOT region is a code (0, 1, 2), a box x,y,w,h or a polygon of 3 or \
                         more x,y points; found {n} numbers"
                    ),
                }),
            }
        })
        .collect()
}

/// The text of a region line as VOT writes it: a polygon of the four corners, or a code.
pub fn vot_region_line(region: &Region) -> String {
    let n = |v: f64| {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s.is_empty() || s == "-" {
            "0".to_string()
        } else {
            s.to_string()
        }
    };
    match region {
        Region::Code(c) => c.to_string(),
        Region::Rect { x, y, w, h } => format!("{},{},{},{}", n(*x), n(*y), n(*w), n(*h)),
        Region::Polygon(p) => p
            .iter()
            .flat_map(|q| [n(q.x), n(q.y)])
            .collect::<Vec<_>>()
            .join(","),
        Region::Empty => String::new(),
    }
}

/// Parses a file of boxes `x, y, w, h` a line (GOT-10k, LaSOT `groundtruth.txt`, commas or white
/// space); a line of NaN values, a box of no area or an empty line is a frame without a box.
pub fn parse_boxes(path: &Path, text: &str) -> Result<Vec<Option<Quad>>> {
    Ok(rows(path, text, 4, "a box x, y, w, h", false)?
        .into_iter()
        .map(|r| {
            let v = r?;
            Region::Rect {
                x: v[0],
                y: v[1],
                w: v[2],
                h: v[3],
            }
            .quad()
            .filter(|q| q.is_finite())
        })
        .collect())
}

/// Parses a file of `n` finite numbers a line; an empty line is `None`.
pub fn parse_rows(path: &Path, text: &str, n: usize, what: &str) -> Result<Vec<Option<Vec<f64>>>> {
    rows(path, text, n, what, true)
}

/// The rows of `n` numbers of a file (`None` for an empty line), each also finite when `finite`;
/// errors name the line.
fn rows(
    path: &Path,
    text: &str,
    n: usize,
    what: &str,
    finite: bool,
) -> Result<Vec<Option<Vec<f64>>>> {
    frame_lines(text)
        .into_iter()
        .map(|(line, l)| {
            if l.is_empty() {
                return Ok(None);
            }
            let err = |message: String| Error::Parse {
                path: path.to_path_buf(),
                line,
                message,
            };
            let v = numbers(path, line, l)?;
            if v.len() != n {
                return Err(err(format!(
                    "expected {n} numbers ({what}), found {}",
                    v.len()
                )));
            }
            if finite && let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(err(format!("value {} is not a finite number", k + 1)));
            }
            Ok(Some(v))
        })
        .collect()
}

/// Parses homographies of 9 numbers a line (row-major); an empty line, an all-zero row or a
/// singular matrix is `None` (a frame not annotated).
pub fn parse_homographies(path: &Path, text: &str) -> Result<Vec<Option<Matrix3<f64>>>> {
    Ok(parse_rows(path, text, 9, "a 3x3 homography, row by row")?
        .into_iter()
        .map(|r| {
            let v = r?;
            let h = Matrix3::from_row_slice(&v);
            (h.determinant().abs() > 1e-300).then_some(h)
        })
        .collect())
}

/// Parses a file of one integer a line (POT's and PlanarTrack's `_flag.txt`); an empty line is
/// 0. Several numbers on a line are an error naming it.
pub fn parse_flags(path: &Path, text: &str) -> Result<Vec<i64>> {
    frame_lines(text)
        .into_iter()
        .map(|(line, l)| {
            if l.is_empty() {
                return Ok(0);
            }
            let v = numbers(path, line, l)?;
            match v.as_slice() {
                [f] if f.fract() == 0.0 => Ok(*f as i64),
                _ => Err(Error::Parse {
                    path: path.to_path_buf(),
                    line,
                    message: format!("expected one integer flag, found '{}'", l),
                }),
            }
        })
        .collect()
}

/// The corners of the UCSB reference region (in the reference plane's units, millimetres) in
/// each frame, from the `.warps` homographies, which take a frame's pixels to the reference
/// plane: each corner is mapped back by the inverse. A singular or missing homography is a
/// frame without corners.
pub fn corners_from_warps(warps: &[Option<Matrix3<f64>>], reference: &Quad) -> Vec<Option<Quad>> {
    warps
        .iter()
        .map(|h| {
            let inv = h.as_ref()?.try_inverse()?;
            let q = reference.map(|p| apply_homography(&inv, p));
            q.is_finite().then_some(q)
        })
        .collect()
}

/// A row of 8 numbers that are all zero: PlanarTrack's mark of a frame not labelled.
pub fn is_unlabelled(v: &[f64]) -> bool {
    v.iter().all(|x| *x == 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vot_lines_are_read_as_written() {
        let p = Path::new("groundtruth.txt");
        let text = "1\n10,20,30,40\n1,2,3,2,3,4,1,4\n2\n0\n\nm1,2,3\n0,0,4,0,4,4,0,4,-1,2\n";
        let r = parse_vot_regions(p, text).unwrap();
        assert_eq!(r.len(), 8);
        assert_eq!(r[0], Region::Code(1));
        assert_eq!(r[1].quad(), Some(Quad::from_rect(10.0, 20.0, 30.0, 40.0)));
        assert_eq!(r[2].quad().unwrap().0[2], Point::new(3.0, 4.0));
        assert_eq!(
            (r[3].clone(), r[4].clone()),
            (Region::Code(2), Region::Code(0))
        );
        assert_eq!((r[5].quad(), r[6].quad()), (None, None));
        assert_eq!(r[7].quad(), Some(Quad::from_rect(-1.0, 0.0, 5.0, 4.0)));
        for reg in &r[..5] {
            let back = parse_vot_regions(p, &vot_region_line(reg)).unwrap();
            assert_eq!(back, vec![reg.clone()]);
        }
        let e = parse_vot_regions(p, "1,2,3\n").unwrap_err().to_string();
        assert!(e.starts_with("groundtruth.txt:1:"), "{e}");
    }

    #[test]
    fn boxes_flags_and_homographies_name_the_bad_line() {
        let p = Path::new("gt.txt");
        let b = parse_boxes(p, "1,2,3,4\r\nnan,nan,nan,nan\n5 6 0 0\n").unwrap();
        assert_eq!(
            b,
            vec![Some(Quad::from_rect(1.0, 2.0, 3.0, 4.0)), None, None]
        );
        let e = parse_boxes(p, "1,2,3,4\n1,2,3\n").unwrap_err().to_string();
        assert!(e.starts_with("gt.txt:2:"), "{e}");
        assert_eq!(parse_flags(p, "0\n1\n\n0\n").unwrap(), vec![0, 1, 0, 0]);
        assert!(parse_flags(p, "0\n0 1\n").is_err());
        let h = parse_homographies(p, "1 0 0 0 1 0 0 0 1\n0 0 0 0 0 0 0 0 0\n").unwrap();
        assert_eq!(h, vec![Some(Matrix3::identity()), None]);
        assert!(parse_homographies(p, "1 0 0 0 1 0 0 0\n").is_err());
    }

    #[test]
    fn warps_map_the_reference_back_into_the_frame() {
        // A frame where the plane is seen scaled by 2 and shifted: pixels -> mm is the inverse.
        let to_frame = Matrix3::new(2.0, 0.0, 100.0, 0.0, 2.0, 50.0, 0.0, 0.0, 1.0);
        let to_plane = to_frame.try_inverse().unwrap();
        let reference = Quad::from_rect(0.0, 0.0, 10.0, 20.0);
        let c = corners_from_warps(&[Some(to_plane), None], &reference);
        assert_eq!(c[1], None);
        let q = c[0].unwrap();
        assert!((q.0[2].x - 120.0).abs() < 1e-9 && (q.0[2].y - 90.0).abs() < 1e-9);
    }
}
