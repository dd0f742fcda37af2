//! The tracks file (CSV) of a many-patch run: written with fixed decimals, read back with a
//! bad line named.

use super::*;
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::status::{LossReason, TrackStatus};
use std::io::Write;
use std::path::Path;

/// The header of a patch tracks file.
pub const TRACKS_HEADER: &str = "frame,patch,status,x,y,a00,a01,a10,a11,ncc";

/// Writes `run` as CSV: one line per frame and patch, [`TRACKS_HEADER`]'s columns; the status
/// is `tracking` or `lost:<reason>`.
pub fn write_tracks(path: &Path, run: &PatchRun) -> Result<()> {
    let io = |e: std::io::Error| Error::io(path, e);
    let file = std::fs::File::create(path).map_err(io)?;
    let mut out = std::io::BufWriter::new(file);
    writeln!(out, "{TRACKS_HEADER}").map_err(io)?;
    // A line at a time into one buffer; the numbers as `{:.N}` writes them, faster (a thousand
    // patches make 200,000 lines of seven numbers each per 200 frames).
    use std::fmt::Write as _;
    let mut line = String::with_capacity(128);
    for (i, states) in run.frames.iter().enumerate() {
        for (k, s) in states.iter().enumerate() {
            line.clear();
            match s.status {
                TrackStatus::Lost(r) => write!(line, "{i},{k},lost:{},", r.key()),
                _ => write!(line, "{i},{k},tracking,"),
            }
            .expect("writing to a String");
            let [a, b, c, d] = s.linear;
            let numbers = [
                (s.centre.x, 4),
                (s.centre.y, 4),
                (a, 6),
                (b, 6),
                (c, 6),
                (d, 6),
                (s.ncc, 4),
            ];
            for (n, (v, digits)) in numbers.into_iter().enumerate() {
                if n > 0 {
                    line.push(',');
                }
                write_fixed(&mut line, v, digits);
            }
            line.push('\n');
            out.write_all(line.as_bytes()).map_err(io)?;
        }
    }
    out.flush().map_err(io)
}

/// Appends `v` with `digits` decimals exactly as `format!("{v:.digits$}")` does (the binary
/// value rounded half to even), without its slow path: the value's mantissa times `10^digits`
/// is shifted by its exponent in 128-bit integers.
pub(super) fn write_fixed(out: &mut String, v: f64, digits: u32) {
    use std::fmt::Write as _;
    let d = digits as usize;
    if !v.is_finite() || v.abs() >= 1e15 || digits > 9 {
        write!(out, "{v:.d$}").expect("writing to a String");
        return;
    }
    let bits = v.to_bits();
    let (exp, frac) = (((bits >> 52) & 0x7ff) as i32, bits & ((1u64 << 52) - 1));
    // v = m 2^e.
    let (m, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), exp - 1075)
    };
    let scale = 10u128.pow(digits);
    let x = m as u128 * scale;
    let r = if e >= 0 {
        // |v| < 1e15 < 2^50, so x 2^e < 2^80.
        x << e
    } else if -e >= 128 {
        0
    } else {
        let s = (-e) as u32;
        let q = x >> s;
        let rem = x - (q << s);
        let half = 1u128 << (s - 1);
        if rem > half || (rem == half && q & 1 == 1) {
            q + 1
        } else {
            q
        }
    };
    if bits >> 63 == 1 {
        out.push('-');
    }
    let (int, fraction) = (r / scale, r % scale);
    if d == 0 {
        write!(out, "{int}")
    } else {
        write!(out, "{int}.{fraction:0d$}")
    }
    .expect("writing to a String");
}

/// Reads a tracks file written by [`write_tracks`] (or by another tracker in its layout: the
/// benchmark scores OpenCV's tracks this way). A malformed line is an error naming the file
/// and the line.
pub fn read_tracks(path: &Path) -> Result<PatchRun> {
    let text = crate::files::read_text(path, crate::files::TEXT_LIMIT)?;
    let bad = |line: usize, what: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message: what,
    };
    let mut run = PatchRun::default();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = line.trim();
        if line.is_empty() || (n == 0 && line.starts_with("frame")) {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 10 {
            return Err(bad(
                line_no,
                format!("expected 10 fields ({TRACKS_HEADER}), got {}", f.len()),
            ));
        }
        let int = |k: usize| {
            f[k].parse::<usize>().map_err(|_| {
                bad(
                    line_no,
                    format!(
                        "field {} is not a whole number: '{}'",
                        k + 1,
                        crate::error::short_text(f[k])
                    ),
                )
            })
        };
        let num = |k: usize| {
            f[k].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!(
                            "field {} is not a finite number: '{}'",
                            k + 1,
                            crate::error::short_text(f[k])
                        ),
                    )
                })
        };
        let (frame, patch) = (int(0)?, int(1)?);
        let status = match f[2] {
            "tracking" => TrackStatus::Tracking,
            s => match s.strip_prefix("lost:").map(LossReason::from_key) {
                Some(Some(r)) => TrackStatus::Lost(r),
                _ => {
                    return Err(bad(
                        line_no,
                        format!(
                            "status '{}' is neither 'tracking' nor 'lost:<reason>'",
                            crate::error::short_text(s)
                        ),
                    ));
                }
            },
        };
        if frame > run.frames.len() || (frame + 1 < run.frames.len()) {
            return Err(bad(line_no, format!("frame {frame} out of order")));
        }
        if frame == run.frames.len() {
            run.frames.push(Vec::new());
        }
        let states = &mut run.frames[frame];
        if patch != states.len() {
            return Err(bad(
                line_no,
                format!("patch {patch} out of order (expected {})", states.len()),
            ));
        }
        // A position, not merely a finite number (1e155 squared is infinite).
        let coordinate = |k: usize| {
            num(k).and_then(|v| {
                if v.abs() <= crate::geometry::MAX_COORDINATE {
                    Ok(v)
                } else {
                    Err(bad(
                        line_no,
                        format!(
                            "field {} is {}, beyond any frame (more than {} px)",
                            k + 1,
                            f[k],
                            crate::geometry::MAX_COORDINATE
                        ),
                    ))
                }
            })
        };
        states.push(PatchState {
            centre: Point {
                x: coordinate(3)?,
                y: coordinate(4)?,
            },
            linear: [num(5)?, num(6)?, num(7)?, num(8)?],
            status,
            ncc: num(9)?,
            fb_error: None,
            iterations: 0,
        });
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_decimals_are_those_of_the_standard_formatting() {
        let mut rng = crate::rng::Rng::new(7);
        let mut special = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            0.00005,
            -0.00005,
            0.00015,
            2.5e-7,
            -1e-300,
            f64::MIN_POSITIVE,
            5e-324,
            123456.78125,
            9.99999999e14,
            2e15,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // Halves of the last digit exactly (ties go to even), and random values of every size.
        special.extend((0..2000).map(|k| k as f64 / 2e4 + 1.0 / 32.0));
        special.extend((0..20_000).map(|k| {
            let v = rng.range(-1.0, 1.0) * 10f64.powi((k % 30) - 12);
            if k % 3 == 0 {
                (v * 1e6).round() / 1e6
            } else {
                v
            }
        }));
        let mut mine = String::new();
        for &v in &special {
            for digits in [0u32, 1, 4, 6, 9] {
                mine.clear();
                write_fixed(&mut mine, v, digits);
                assert_eq!(
                    mine,
                    format!("{v:.*}", digits as usize),
                    "{v:e} to {digits}"
                );
            }
        }
    }

    #[test]
    fn points_and_tracks_files_are_read_and_a_bad_line_is_named() {
        let d = std::env::temp_dir().join(format!("regtrack-points-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("points.txt");
        std::fs::write(&p, "# corners\n10,20\n 30.5 40 \n").unwrap();
        assert_eq!(
            read_points(&p).unwrap(),
            vec![Point { x: 10.0, y: 20.0 }, Point { x: 30.5, y: 40.0 }]
        );
        std::fs::write(&p, "10,20\n1,2,3\n").unwrap();
        let e = read_points(&p).unwrap_err().to_string();
        assert!(e.contains("points.txt:2"), "{e}");
        // A run written and read back.
        let state = PatchState {
            centre: Point { x: 1.5, y: 2.25 },
            linear: [1.0, 0.0, 0.0, 1.0],
            status: TrackStatus::Lost(LossReason::OutOfFrame),
            ncc: 0.5,
            fb_error: None,
            iterations: 0,
        };
        let run = PatchRun {
            first: 0,
            frames: vec![vec![state; 2]; 3],
            times: Vec::new(),
        };
        let t = d.join("tracks.csv");
        write_tracks(&t, &run).unwrap();
        assert_eq!(read_tracks(&t).unwrap().frames, run.frames);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
