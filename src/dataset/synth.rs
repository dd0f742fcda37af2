//! Synthetic sequences with exact ground truth: a texture rendered into the quad of every frame of
//! a real motion profile, over a background, anti-aliased by supersampling (with a mip-mapped
//! texture, so minification does not alias), with optional nuisances: Gaussian noise, global
//! illumination drift (gain and bias), a moving local light, motion blur along the motion, a
//! partial occluder and JPEG compression. Writes the MTF layout.

use super::Sequence;
use super::groundtruth::{read_ground_truth, write_corners};
use crate::error::{Error, Result};
use crate::geometry::{Point, Quad, apply_homography, homography_from_points};
use crate::imaging::{GrayU8, load_dynamic};
use crate::rng::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// What to render.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthConfig {
    /// The image rendered into the target quad.
    pub texture: PathBuf,
    /// The image behind it (scaled to the frame), or mid-gray.
    pub background: Option<PathBuf>,
    /// A motion profile: four corners per frame (TMT/MTF ground-truth format).
    pub motion: PathBuf,
    /// Frame size; by default the smallest common size holding every corner.
    pub size: Option<(usize, usize)>,
    /// Use only the first frames.
    pub max_frames: Option<usize>,
    /// Take every `step`-th frame of the profile (motion `step` times faster).
    pub step: usize,
    /// Supersampling factor per axis (anti-aliasing).
    pub supersample: usize,
    /// Gaussian noise standard deviation (gray levels).
    pub noise: f32,
    /// Amplitude of the global gain drift (0.2 = +-20%).
    pub gain_drift: f32,
    /// Amplitude of the global bias drift (gray levels).
    pub bias_drift: f32,
    /// Amplitude of a moving local light (0.5 = up to +50% at its centre).
    pub local_light: f32,
    /// Motion blur: number of sub-frames averaged along the motion (0 or 1 = none).
    pub motion_blur: usize,
    /// Side of a moving occluder as a fraction of the target's size (0 = none).
    pub occlusion: f32,
    /// Amplitude of a non-rigid bend of the target, as a fraction of its size (0 = rigid):
    /// the texture waves along both axes, its corners moving with it (the ground truth
    /// follows them), over a period of [`BEND_PERIOD`] frames.
    pub bend: f32,
    /// JPEG quality (1..=100); 0 writes PNG frames instead.
    pub jpeg_quality: u8,
    /// Seed of every random nuisance.
    pub seed: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            texture: PathBuf::new(),
            background: None,
            motion: PathBuf::new(),
            size: None,
            max_frames: None,
            step: 1,
            supersample: 3,
            noise: 0.0,
            gain_drift: 0.0,
            bias_drift: 0.0,
            local_light: 0.0,
            motion_blur: 0,
            occlusion: 0.0,
            bend: 0.0,
            jpeg_quality: 95,
            seed: 1,
        }
    }
}

/// Frames of one period of the bend ([`SynthConfig::bend`]).
pub const BEND_PERIOD: f64 = 80.0;

/// The bend's displacement of the texture's unit-square point `(u, v)` on frame `i`, in the
/// same units: two waves, one across each axis, each moving the points along the other.
fn bend_at(amplitude: f64, u: f64, v: f64, i: usize) -> (f64, f64) {
    use std::f64::consts::{PI, TAU};
    let t = i as f64 / BEND_PERIOD;
    (
        amplitude * (TAU * t).sin() * (1.2 * PI * v + 0.3).sin(),
        amplitude * (TAU * t / 1.3).cos() * (1.2 * PI * u + 0.5).sin(),
    )
}

/// An RGB float image.
#[derive(Clone, Debug)]
struct Rgb {
    w: usize,
    h: usize,
    px: Vec<[f32; 3]>,
}

impl Rgb {
    fn load(path: &Path) -> Result<Rgb> {
        let img = load_dynamic(path)?.to_rgb8();
        Ok(Rgb {
            w: img.width() as usize,
            h: img.height() as usize,
            px: img
                .pixels()
                .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
                .collect(),
        })
    }

    /// Bilinear sample with the border replicated.
    #[inline]
    fn sample(&self, x: f32, y: f32) -> [f32; 3] {
        let x = x.clamp(0.0, (self.w - 1) as f32);
        let y = y.clamp(0.0, (self.h - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (ax, ay) = (x - x0 as f32, y - y0 as f32);
        let p = |xx: usize, yy: usize| self.px[yy * self.w + xx];
        let (a, b, c, d) = (p(x0, y0), p(x1, y0), p(x0, y1), p(x1, y1));
        std::array::from_fn(|k| {
            let top = a[k] + ax * (b[k] - a[k]);
            let bot = c[k] + ax * (d[k] - c[k]);
            top + ay * (bot - top)
        })
    }

    /// Half size, 2x2 box filter.
    fn half(&self) -> Rgb {
        let (w, h) = (self.w.div_ceil(2).max(1), self.h.div_ceil(2).max(1));
        let mut px = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut s = [0.0f32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let q = self.px
                        [(2 * y + dy).min(self.h - 1) * self.w + (2 * x + dx).min(self.w - 1)];
                    for k in 0..3 {
                        s[k] += 0.25 * q[k];
                    }
                }
                px.push(s);
            }
        }
        Rgb { w, h, px }
    }

    /// Resized to `w x h` by area averaging (a mip level close to the size, then bilinear).
    fn resized(&self, w: usize, h: usize) -> Rgb {
        let mut src = self.clone();
        while src.w >= 2 * w && src.h >= 2 * h {
            src = src.half();
        }
        let (sx, sy) = (src.w as f32 / w as f32, src.h as f32 / h as f32);
        let px = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                src.sample((x + 0.5) * sx - 0.5, (y + 0.5) * sy - 0.5)
            })
            .collect();
        Rgb { w, h, px }
    }
}

/// Reads a motion profile: every line must have corners.
pub fn read_motion_profile(path: &Path) -> Result<Vec<Quad>> {
    let entries = read_ground_truth(path)?;
    if entries.is_empty() {
        return Err(Error::Sequence {
            path: path.to_path_buf(),
            message: "the motion profile has no frame".into(),
        });
    }
    entries
        .iter()
        .enumerate()
        .map(|(i, e)| {
            e.quad.ok_or_else(|| Error::Sequence {
                path: path.to_path_buf(),
                message: format!("frame {} of the motion profile has no corners", i + 1),
            })
        })
        .collect()
}

/// Puts the corners in the TMT order: clockwise on screen, starting at the upper-left corner of
/// the first frame (the same rotation for every frame).
pub fn canonical_corner_order(quads: &mut [Quad]) {
    let Some(first) = quads.first().copied() else {
        return;
    };
    let reverse = first.signed_area() < 0.0;
    let fix = |q: &Quad| -> Quad {
        if reverse {
            Quad([q.0[0], q.0[3], q.0[2], q.0[1]])
        } else {
            *q
        }
    };
    let f = fix(&first);
    let start = (0..4)
        .min_by(|&a, &b| (f.0[a].x + f.0[a].y).total_cmp(&(f.0[b].x + f.0[b].y)))
        .unwrap_or(0);
    for q in quads.iter_mut() {
        let g = fix(q);
        *q = Quad(std::array::from_fn(|k| g.0[(start + k) % 4]));
    }
}

/// The smallest common frame size holding every corner.
pub fn default_frame_size(quads: &[Quad]) -> (usize, usize) {
    let (mut mx, mut my) = (0.0f64, 0.0f64);
    for q in quads {
        let b = q.bbox();
        mx = mx.max(b.x1);
        my = my.max(b.y1);
    }
    for (w, h) in [
        (640, 480),
        (800, 600),
        (1024, 768),
        (1280, 720),
        (1280, 960),
        (1920, 1080),
    ] {
        if mx < w as f64 && my < h as f64 {
            return (w, h);
        }
    }
    (
        (mx.ceil() as usize + 1).max(16),
        (my.ceil() as usize + 1).max(16),
    )
}

/// Everything needed to render frames, prepared once.
struct Scene {
    cfg: SynthConfig,
    mips: Vec<Rgb>,
    background: Rgb,
    quads: Vec<Quad>,
    /// The ground truth: the quads, or with a bend the corners it moves them to.
    truth: Vec<Quad>,
    w: usize,
    h: usize,
}

impl Scene {
    fn new(cfg: &SynthConfig) -> Result<Scene> {
        if cfg.step == 0 || cfg.supersample == 0 || cfg.supersample > 8 {
            return Err(Error::InvalidParameter(
                "step must be >= 1 and supersample in 1..=8".into(),
            ));
        }
        if !(0.0..=1.0).contains(&cfg.occlusion)
            || cfg.jpeg_quality > 100
            || cfg.motion_blur > 32
            || !(0.0..=0.2).contains(&cfg.bend)
        {
            return Err(Error::InvalidParameter(
                "occlusion must be in 0..=1, jpeg_quality in 0..=100, motion_blur at most 32, \
                 bend in 0..=0.2"
                    .into(),
            ));
        }
        let texture = Rgb::load(&cfg.texture)?;
        let mut profile = read_motion_profile(&cfg.motion)?;
        canonical_corner_order(&mut profile);
        let mut quads: Vec<Quad> = profile.iter().step_by(cfg.step).copied().collect();
        if let Some(m) = cfg.max_frames {
            quads.truncate(m.max(1));
        }
        let (w, h) = cfg.size.unwrap_or_else(|| default_frame_size(&profile));
        if !(16..=8192).contains(&w) || !(16..=8192).contains(&h) {
            return Err(Error::InvalidParameter(format!(
                "frame size {w}x{h}: each side must be in 16..=8192"
            )));
        }
        let background = match &cfg.background {
            Some(p) => Rgb::load(p)?.resized(w, h),
            None => Rgb {
                w,
                h,
                px: vec![[128.0; 3]; w * h],
            },
        };
        let mut mips = vec![texture];
        while mips.len() < 12 {
            let last = &mips[mips.len() - 1];
            if last.w < 4 || last.h < 4 {
                break;
            }
            let next = last.half();
            mips.push(next);
        }
        let mut scene = Scene {
            cfg: cfg.clone(),
            mips,
            background,
            truth: quads.clone(),
            quads,
            w,
            h,
        };
        if cfg.bend > 0.0 {
            scene.truth = (0..scene.quads.len())
                .map(|i| scene.bent_corners(i))
                .collect();
        }
        Ok(scene)
    }

    /// The corners of frame `i`'s quad moved by the bend: the texture's corners displaced in
    /// its unit square, then taken to the frame by the quad's homography.
    fn bent_corners(&self, i: usize) -> Quad {
        let rect = self.texture_rect();
        let q = self.quads[i];
        let Some(h) = homography_from_points(&rect, &q.0) else {
            return q;
        };
        let (tw, th) = (self.mips[0].w as f64, self.mips[0].h as f64);
        Quad(std::array::from_fn(|k| {
            let (u, v) = ((rect[k].x + 0.5) / tw, (rect[k].y + 0.5) / th);
            let (du, dv) = bend_at(self.cfg.bend as f64, u, v, i);
            apply_homography(&h, Point::new((u + du) * tw - 0.5, (v + dv) * th - 0.5))
        }))
    }

    /// The texture point that frame `i`'s bend moves to the texture point `t` (its inverse,
    /// by fixed-point iterations: the bend's gradient is well below one).
    fn unbend(&self, t: Point, i: usize) -> Point {
        let (tw, th) = (self.mips[0].w as f64, self.mips[0].h as f64);
        let (a, b) = ((t.x + 0.5) / tw, (t.y + 0.5) / th);
        let (mut u, mut v) = (a, b);
        for _ in 0..12 {
            let (du, dv) = bend_at(self.cfg.bend as f64, u, v, i);
            (u, v) = (a - du, b - dv);
        }
        Point::new(u * tw - 0.5, v * th - 0.5)
    }

    /// The texture rectangle's corners (pixel edges), in the TMT order.
    fn texture_rect(&self) -> [Point; 4] {
        let (tw, th) = (self.mips[0].w as f64, self.mips[0].h as f64);
        Quad::from_rect(-0.5, -0.5, tw, th).0
    }

    /// Renders frame `i` as 8-bit RGB.
    fn render(&self, i: usize) -> Vec<u8> {
        let cfg = &self.cfg;
        let (w, h) = (self.w, self.h);
        let mut img = self.background.px.clone();
        let q = self.quads[i];
        // Sub-frame quads along the motion (motion blur): an exposure from half-way from the
        // previous frame to half-way to the next, so the ground truth is its middle.
        let sub = cfg.motion_blur.max(1);
        let prev = if i > 0 { self.quads[i - 1] } else { q };
        let next = self.quads.get(i + 1).copied().unwrap_or(q);
        let lerp = |a: &Quad, b: &Quad, t: f64| {
            Quad(std::array::from_fn(|c| {
                Point::new(
                    a.0[c].x + t * (b.0[c].x - a.0[c].x),
                    a.0[c].y + t * (b.0[c].y - a.0[c].y),
                )
            }))
        };
        let subquads: Vec<Quad> = (0..sub)
            .map(|k| {
                let s = if sub == 1 {
                    0.0
                } else {
                    -0.5 + (k as f64 + 0.5) / sub as f64
                };
                if s < 0.0 {
                    lerp(&prev, &q, 1.0 + s)
                } else {
                    lerp(&q, &next, s)
                }
            })
            .collect();
        let rect = self.texture_rect();
        let inverses: Vec<_> = subquads
            .iter()
            .filter_map(|sq| homography_from_points(&sq.0, &rect))
            .collect();
        if !inverses.is_empty() {
            // Mip level: texels per subsample (area ratio, per axis).
            let tex_area = (self.mips[0].w * self.mips[0].h) as f64;
            let scale = (tex_area / q.signed_area().abs().max(1.0)).sqrt() / cfg.supersample as f64;
            let level = if scale > 1.0 {
                (scale.log2().floor() as usize).min(self.mips.len() - 1)
            } else {
                0
            };
            let mip = &self.mips[level];
            let f = (1u32 << level) as f32;
            let (tw, th) = (self.mips[0].w as f64, self.mips[0].h as f64);
            let mut bx = (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            );
            // The bend moves the texture up to its amplitude beyond the quad.
            let pad = 2.0 * cfg.bend as f64 * q.mean_side();
            for sq in &subquads {
                let b = sq.bbox();
                let b = crate::geometry::Rect {
                    x0: b.x0 - pad,
                    y0: b.y0 - pad,
                    x1: b.x1 + pad,
                    y1: b.y1 + pad,
                };
                bx = (
                    bx.0.min(b.x0),
                    bx.1.min(b.y0),
                    bx.2.max(b.x1),
                    bx.3.max(b.y1),
                );
            }
            let x0 = (bx.0.floor() as i64 - 1).clamp(0, w as i64) as usize;
            let y0 = (bx.1.floor() as i64 - 1).clamp(0, h as i64) as usize;
            let x1 = (bx.2.ceil() as i64 + 2).clamp(0, w as i64) as usize;
            let y1 = (bx.3.ceil() as i64 + 2).clamp(0, h as i64) as usize;
            let s = cfg.supersample;
            let n = (s * s * inverses.len()) as f32;
            for y in y0..y1 {
                for x in x0..x1 {
                    let mut acc = [0.0f32; 3];
                    let mut any = false;
                    for hinv in &inverses {
                        for sy in 0..s {
                            for sx in 0..s {
                                let px = x as f64 + (sx as f64 + 0.5) / s as f64 - 0.5;
                                let py = y as f64 + (sy as f64 + 0.5) / s as f64 - 0.5;
                                let mut t = apply_homography(hinv, Point::new(px, py));
                                if cfg.bend > 0.0 {
                                    t = self.unbend(t, i);
                                }
                                let v = if t.x >= -0.5
                                    && t.y >= -0.5
                                    && t.x < tw - 0.5
                                    && t.y < th - 0.5
                                {
                                    any = true;
                                    mip.sample(
                                        (t.x as f32 + 0.5) / f - 0.5,
                                        (t.y as f32 + 0.5) / f - 0.5,
                                    )
                                } else {
                                    self.background.sample(px as f32, py as f32)
                                };
                                for k in 0..3 {
                                    acc[k] += v[k];
                                }
                            }
                        }
                    }
                    if any {
                        img[y * w + x] = acc.map(|v| v / n);
                    }
                }
            }
        }
        self.occlude(&mut img, i);
        self.light_and_noise(&mut img, i);
        img.iter()
            .flat_map(|p| p.map(|v| v.round().clamp(0.0, 255.0) as u8))
            .collect()
    }

    /// A flat gray square crossing the target during the middle of the sequence.
    fn occlude(&self, img: &mut [[f32; 3]], i: usize) {
        let n = self.quads.len();
        if self.cfg.occlusion <= 0.0 || n < 3 {
            return;
        }
        let (start, end) = (n * 3 / 10, (n * 6 / 10).max(n * 3 / 10 + 1));
        if i < start || i >= end {
            return;
        }
        let q = self.quads[i];
        let c = q.centroid();
        let side = self.cfg.occlusion as f64 * q.mean_side();
        let t = (i - start) as f64 / (end - start) as f64;
        // From the left edge of the target to its right edge.
        let cx = c.x - q.mean_side() * 0.5 + t * q.mean_side();
        let (x0, x1) = (
            (cx - side / 2.0).max(0.0) as usize,
            ((cx + side / 2.0).max(0.0) as usize).min(self.w),
        );
        let (y0, y1) = (
            (c.y - side / 2.0).max(0.0) as usize,
            ((c.y + side / 2.0).max(0.0) as usize).min(self.h),
        );
        for y in y0..y1 {
            for x in x0..x1 {
                let shade = 90.0 + 20.0 * (((x / 6 + y / 6) % 2) as f32);
                img[y * self.w + x] = [shade, shade * 0.95, shade * 0.9];
            }
        }
    }

    fn light_and_noise(&self, img: &mut [[f32; 3]], i: usize) {
        let cfg = &self.cfg;
        let t = i as f32;
        let gain = 1.0 + cfg.gain_drift * (2.0 * std::f32::consts::PI * t / 150.0).sin();
        let bias = cfg.bias_drift * (2.0 * std::f32::consts::PI * t / 97.0).sin();
        let (w, h) = (self.w as f32, self.h as f32);
        let (lx, ly) = (
            w * (0.5 + 0.35 * (t / 60.0).cos()),
            h * (0.5 + 0.35 * (t / 45.0).sin()),
        );
        let r2 = 2.0 * (0.25 * w.min(h)).powi(2);
        let mut rng = Rng::new(cfg.seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let plain = cfg.gain_drift == 0.0 && cfg.bias_drift == 0.0 && cfg.local_light == 0.0;
        if plain && cfg.noise == 0.0 {
            return;
        }
        for (k, p) in img.iter_mut().enumerate() {
            let mut g = gain;
            if cfg.local_light != 0.0 {
                let (x, y) = ((k % self.w) as f32, (k / self.w) as f32);
                g *= 1.0 + cfg.local_light * (-((x - lx).powi(2) + (y - ly).powi(2)) / r2).exp();
            }
            let noise = if cfg.noise > 0.0 {
                cfg.noise * rng.normal() as f32
            } else {
                0.0
            };
            for v in p.iter_mut() {
                *v = *v * g + bias + noise;
            }
        }
    }
}

/// Renders a sequence in memory: the 8-bit gray frames (luma of the rendered RGB; `jpeg_quality`
/// is ignored) and the ground-truth quad of each.
pub fn render_frames(cfg: &SynthConfig) -> Result<(Vec<GrayU8>, Vec<Quad>)> {
    let scene = Scene::new(cfg)?;
    let frames = (0..scene.quads.len())
        .into_par_iter()
        .map(|i| {
            let rgb = scene.render(i);
            GrayU8 {
                width: scene.w,
                height: scene.h,
                data: rgb
                    .chunks_exact(3)
                    .map(|p| crate::imaging::luma(p[0], p[1], p[2]))
                    .collect(),
            }
        })
        .collect();
    Ok((frames, scene.truth.clone()))
}

/// Renders a sequence into `<out_root>/<name>.txt` and `<out_root>/<name>/frame%05d.{jpg,png}`,
/// calling `progress(done, total)` as frames are written. Returns the sequence.
pub fn render_sequence(
    cfg: &SynthConfig,
    out_root: &Path,
    name: &str,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Sequence> {
    // A name, not a path: `../../x` or `/tmp/x` would write outside `out_root`.
    let plain = !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\'])
        && !name.chars().any(char::is_control);
    if !plain {
        return Err(Error::InvalidParameter(format!(
            "sequence name {name:?}: a name without path separators (it is written as \
             OUT/NAME.txt and OUT/NAME/)"
        )));
    }
    let scene = Scene::new(cfg)?;
    let dir = out_root.join(name);
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let total = scene.quads.len();
    let done = AtomicUsize::new(0);
    let ext = if cfg.jpeg_quality == 0 { "png" } else { "jpg" };
    (0..total).into_par_iter().try_for_each(|i| -> Result<()> {
        let rgb = scene.render(i);
        let path = dir.join(format!("frame{:05}.{ext}", i + 1));
        let img =
            image::RgbImage::from_raw(scene.w as u32, scene.h as u32, rgb).ok_or_else(|| {
                Error::ImageWrite {
                    path: path.clone(),
                    message: "frame buffer of the wrong size".into(),
                }
            })?;
        let enc_err = |e: image::ImageError| Error::ImageWrite {
            path: path.clone(),
            message: e.to_string(),
        };
        let file = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
        let mut writer = std::io::BufWriter::new(file);
        if cfg.jpeg_quality == 0 {
            img.write_to(&mut writer, image::ImageFormat::Png)
                .map_err(enc_err)?;
        } else {
            let enc =
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut writer, cfg.jpeg_quality);
            img.write_with_encoder(enc).map_err(enc_err)?;
        }
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d, total);
        Ok(())
    })?;
    let gt_path = out_root.join(format!("{name}.txt"));
    let corners: Vec<Option<Quad>> = scene.truth.iter().map(|q| Some(*q)).collect();
    write_corners(&gt_path, &corners, ext)?;
    Sequence::open(&gt_path)
}
