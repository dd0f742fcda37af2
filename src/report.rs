//! Reports of evaluations: the runs saved by `regtrack eval` under one or several output folders
//! (the shards of a larger evaluation, for instance) pooled per tracker over every sequence, as
//! the `ALL` rows of the summaries are; success-rate curves SR(t), t = 0..20 px, grouped as in the
//! paper (the SMs for each AM, the AMs for each SM, the SSMs for each SM and AM), a speed chart,
//! and a markdown table. Figures are PNG and SVG, drawn with plotters; their text uses the bundled
//! DejaVu Sans, so no system font is needed.

use crate::dataset::write_atomic;
use crate::error::{Error, Result};
use crate::eval::{self, RunResult, SR_MAX, Summary};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The font of every figure (DejaVu Sans, Bitstream Vera licence: `assets/fonts/`).
const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
/// The family it is registered under (plotters' default family; what SVG viewers fall back to).
const FAMILY: &str = "sans-serif";

/// Size of the success-rate figures and the width of the speed chart (px).
pub const FIGURE_SIZE: (u32, u32) = (900, 600);
/// The smallest figure drawn (px).
pub const MIN_SIZE: (u32, u32) = (400, 300);
/// Most curves in one figure; a larger group is split into parts.
pub const MAX_CURVES: usize = 12;
/// The SSM the SM and AM comparisons are made with, when it was run (as in the paper).
pub const PREFERRED_SSM: &str = "homography";

/// One tracker pooled over every sequence it was run on.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackerResult {
    /// [`eval::summarize`] of all its runs (`sequence` is `ALL`).
    pub summary: Summary,
    /// The sequences it was run on (sorted).
    pub sequences: Vec<String>,
    /// SR(t) over [`eval::thresholds`], of all its frames.
    pub curve: Vec<(f64, f64)>,
    /// The benchmarks' curves ([`eval::benchmark`]): precision P@t (t = 0..20 px), success by
    /// homography discrepancy (t = 0..200; empty for runs made before it was recorded) and by
    /// IoU (t = 0..1).
    pub precision: Vec<(f64, f64)>,
    pub discrepancy: Vec<(f64, f64)>,
    pub iou: Vec<(f64, f64)>,
    /// Pooled per challenge factor of its sequences (`ALL:<factor>` rows).
    pub factors: Vec<Summary>,
}

impl TrackerResult {
    /// Whether it is a registration tracker (an SM, AM and SSM), not a whole tracker.
    pub fn is_registration(&self) -> bool {
        !self.summary.ssm.is_empty()
    }
}

/// One curve of a figure.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Curve {
    /// The legend: what varies in the figure (the SM, the AM, the SSM, or the whole label).
    pub name: String,
    /// The tracker's label.
    pub tracker: String,
    pub mean_sr: f64,
    /// The line; a non-finite point breaks it (a lost frame is a gap, not a bridge).
    pub points: Vec<(f64, f64)>,
    /// Its colour and dash when the figure should match another view (the inspector's
    /// trackers' colours); `None`: the figure's palette by rank.
    pub style: Option<([u8; 3], bool)>,
    /// Points marked with a cross (the frames reported lost), in the curve's colour.
    pub marks: Vec<(f64, f64)>,
}

/// Which comparison a figure makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum FigureKind {
    /// The SMs, for one AM (SSM fixed).
    SmsPerAm,
    /// The AMs, for one SM (SSM fixed).
    AmsPerSm,
    /// The SSMs, for one SM and AM.
    Ssms,
    /// The whole (learning-based) trackers beside the best registration trackers scored against
    /// translation ground truth (the paper's comparison).
    Learning,
    /// The trackers that are in none of the other figures.
    Others,
}

/// A success-rate figure.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    pub kind: FigureKind,
    /// File name without extension (`sr_am_zncc`, ...).
    pub stem: String,
    pub title: String,
    /// Sorted by mean SR, best first.
    pub curves: Vec<Curve>,
}

/// What [`write_report`] wrote.
#[derive(Clone, Debug)]
pub struct Report {
    /// Sorted by mean SR, best first (ties by label).
    pub trackers: Vec<TrackerResult>,
    pub figures: Vec<Figure>,
    /// Every file written, `report.md` last.
    pub files: Vec<PathBuf>,
}

/// Each tracker's runs pooled over every sequence ([`eval::summarize`] with `ALL`), sorted by
/// mean SR, best first (ties by label).
pub fn pool(runs: &[RunResult]) -> Vec<TrackerResult> {
    let mut out: Vec<TrackerResult> = eval::by_tracker(runs)
        .iter()
        .map(|mine| {
            let errors: Vec<f64> = mine.iter().flat_map(|r| r.sr_errors()).collect();
            let sequences: BTreeSet<String> = mine.iter().map(|r| r.sequence.clone()).collect();
            use eval::benchmark as b;
            TrackerResult {
                summary: eval::summarize(eval::POOLED, mine),
                sequences: sequences.into_iter().collect(),
                curve: eval::success_curve(&errors),
                precision: b::precision_curve(&b::precision_errors(mine)),
                discrepancy: b::discrepancies(mine)
                    .map(|d| b::discrepancy_curve(&d))
                    .unwrap_or_default(),
                iou: b::iou_curve(&b::ious(mine)),
                factors: eval::factor_rows(mine),
            }
        })
        .collect();
    out.sort_by(|a, b| by_mean_sr(&a.summary, &b.summary));
    out
}

/// Best mean SR first, then by label.
fn by_mean_sr(a: &Summary, b: &Summary) -> std::cmp::Ordering {
    b.mean_sr
        .total_cmp(&a.mean_sr)
        .then_with(|| a.tracker.cmp(&b.tracker))
}

/// A name usable in a file name and a markdown link.
fn file_safe(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The SSM of the SM and AM comparisons: [`PREFERRED_SSM`] if any registration tracker used it,
/// else the one most trackers used (ties by name).
pub fn comparison_ssm(trackers: &[TrackerResult]) -> Option<String> {
    let mut count: BTreeMap<&str, usize> = BTreeMap::new();
    for t in trackers.iter().filter(|t| t.is_registration()) {
        *count.entry(t.summary.ssm.as_str()).or_default() += 1;
    }
    if count.contains_key(PREFERRED_SSM) {
        return Some(PREFERRED_SSM.to_string());
    }
    // max_by_key keeps the last maximum: iterate in reverse name order to keep the first name.
    count
        .iter()
        .rev()
        .max_by_key(|(_, n)| **n)
        .map(|(s, _)| s.to_string())
}

/// The success-rate figures: (a) for each AM, its SMs; (b) for each SM, its AMs (both with the
/// [`comparison_ssm`]); (c) for each SM and AM run with several SSMs, the SSMs; (d) the trackers
/// in none of those. A group needs two trackers; one of more than [`MAX_CURVES`] is split.
pub fn sr_figures(trackers: &[TrackerResult]) -> Vec<Figure> {
    let reg: Vec<&TrackerResult> = trackers.iter().filter(|t| t.is_registration()).collect();
    let mut figures = Vec::new();
    let mut shown: BTreeSet<&str> = BTreeSet::new();
    let curve = |t: &TrackerResult, name: &str| Curve {
        name: name.to_string(),
        tracker: t.summary.tracker.clone(),
        mean_sr: t.summary.mean_sr,
        points: t.curve.clone(),
        ..Default::default()
    };
    let mut group = |kind: FigureKind, stem: String, title: String, members: Vec<Curve>| {
        if members.len() >= 2 {
            figures.push((kind, stem, title, members));
        }
    };
    if let Some(ssm) = comparison_ssm(trackers) {
        let fixed: Vec<&TrackerResult> = reg
            .iter()
            .copied()
            .filter(|t| t.summary.ssm == ssm)
            .collect();
        let ams: BTreeSet<&str> = fixed.iter().map(|t| t.summary.am.as_str()).collect();
        for am in ams {
            let members: Vec<&TrackerResult> = fixed
                .iter()
                .copied()
                .filter(|t| t.summary.am == am)
                .collect();
            if members.len() >= 2 {
                shown.extend(members.iter().map(|t| t.summary.tracker.as_str()));
            }
            group(
                FigureKind::SmsPerAm,
                format!("sr_am_{}", file_safe(am)),
                format!("Search methods with AM {am} and SSM {ssm}"),
                members.iter().map(|t| curve(t, &t.summary.sm)).collect(),
            );
        }
        let sms: BTreeSet<&str> = fixed.iter().map(|t| t.summary.sm.as_str()).collect();
        for sm in sms {
            let members: Vec<&TrackerResult> = fixed
                .iter()
                .copied()
                .filter(|t| t.summary.sm == sm)
                .collect();
            if members.len() >= 2 {
                shown.extend(members.iter().map(|t| t.summary.tracker.as_str()));
            }
            group(
                FigureKind::AmsPerSm,
                format!("sr_sm_{}", file_safe(sm)),
                format!("Appearance models with SM {sm} and SSM {ssm}"),
                members.iter().map(|t| curve(t, &t.summary.am)).collect(),
            );
        }
    }
    let pairs: BTreeSet<(&str, &str)> = reg
        .iter()
        .map(|t| (t.summary.sm.as_str(), t.summary.am.as_str()))
        .collect();
    for (sm, am) in pairs {
        let members: Vec<&TrackerResult> = reg
            .iter()
            .copied()
            .filter(|t| t.summary.sm == sm && t.summary.am == am)
            .collect();
        if members.len() >= 2 {
            shown.extend(members.iter().map(|t| t.summary.tracker.as_str()));
        }
        group(
            FigureKind::Ssms,
            format!("sr_ssm_{}_{}", file_safe(sm), file_safe(am)),
            format!("State space models with SM {sm} and AM {am}"),
            members.iter().map(|t| curve(t, &t.summary.ssm)).collect(),
        );
    }
    // The learning-based trackers beside the best registration trackers scored, as they are,
    // against translation ground truth.
    // (Whole trackers scored otherwise, `--gt-ssm own` scoring them against the full ground
    // truth, are drawn with the others.)
    let whole: Vec<&TrackerResult> = trackers
        .iter()
        .filter(|t| !t.is_registration() && t.summary.gt == "translation")
        .collect();
    if !whole.is_empty() {
        let mut best: Vec<&TrackerResult> = reg
            .iter()
            .copied()
            .filter(|t| t.summary.gt == "translation")
            .collect();
        best.sort_by(|a, b| by_mean_sr(&a.summary, &b.summary));
        best.truncate(MAX_CURVES.saturating_sub(whole.len()).min(6));
        let members: Vec<Curve> = whole
            .iter()
            .chain(&best)
            .map(|t| curve(t, &t.summary.tracker))
            .collect();
        if members.len() >= 2 && !best.is_empty() {
            shown.extend(whole.iter().map(|t| t.summary.tracker.as_str()));
            group(
                FigureKind::Learning,
                "sr_learning".to_string(),
                "Learning-based and the best registration trackers (translation ground truth)"
                    .to_string(),
                members,
            );
        }
    }
    let others: Vec<Curve> = trackers
        .iter()
        .filter(|t| !shown.contains(t.summary.tracker.as_str()))
        .map(|t| curve(t, &t.summary.tracker))
        .collect();
    if !others.is_empty() {
        let title = if others.len() == trackers.len() {
            "All trackers"
        } else {
            "Trackers not compared in the other figures"
        };
        // Even a single tracker gets its figure: every tracker is in one.
        figures.push((
            FigureKind::Others,
            "sr_others".to_string(),
            title.to_string(),
            others,
        ));
    }

    let mut out = Vec::new();
    let mut stems: BTreeSet<String> = BTreeSet::new();
    for (kind, stem, title, mut curves) in figures {
        curves.sort_by(|a, b| {
            b.mean_sr
                .total_cmp(&a.mean_sr)
                .then_with(|| a.name.cmp(&b.name))
        });
        let parts = curves.len().div_ceil(MAX_CURVES).max(1);
        for (k, chunk) in curves.chunks(MAX_CURVES).enumerate() {
            let (mut stem, title) = if parts > 1 {
                (
                    format!("{stem}_{}", k + 1),
                    format!("{title} ({}/{parts})", k + 1),
                )
            } else {
                (stem.clone(), title.clone())
            };
            // Distinct methods can have the same file-safe name (`a+b`, `a:b`).
            let base = stem.clone();
            let mut n = 2;
            while !stems.insert(stem.clone()) {
                stem = format!("{base}-{n}");
                n += 1;
            }
            out.push(Figure {
                kind,
                stem,
                title,
                curves: chunk.to_vec(),
            });
        }
    }
    out
}

/// Colours of the curves (Tableau 10); after ten, the colours come back dashed.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The colour and whether the line is dashed, of the `i`-th curve.
pub fn curve_style(i: usize) -> (RGBColor, bool) {
    (PALETTE[i % PALETTE.len()], (i / PALETTE.len()) % 2 == 1)
}

/// Registers the bundled font with plotters (once per process).
fn register_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(Error::report(
            Path::new("assets/fonts/DejaVuSans.ttf"),
            "the bundled font cannot be read",
        ))
    }
}

/// The bundled font, parsed once.
fn font() -> Option<&'static ab_glyph::FontRef<'static>> {
    static FONT_REF: std::sync::OnceLock<Option<ab_glyph::FontRef<'static>>> =
        std::sync::OnceLock::new();
    FONT_REF
        .get_or_init(|| ab_glyph::FontRef::try_from_slice(FONT).ok())
        .as_ref()
}

/// A backend that draws text itself with the bundled font, each glyph at its pen position and
/// outline bounds (plotters' own `ab_glyph` text drops the glyphs' side bearings, which jumbles
/// the letters), and delegates everything else to the backend it wraps.
struct GlyphText<B>(B);

impl<B: DrawingBackend> GlyphText<B> {
    /// Width, height and ascent (px) of `text` at `size` px.
    fn layout(text: &str, size: f64) -> Option<(f32, f32, f32)> {
        use ab_glyph::{Font, ScaleFont};
        let font = font()?.as_scaled(size as f32);
        let mut width = 0.0;
        let mut prev = None;
        for c in text.chars() {
            let id = font.glyph_id(c);
            if let Some(p) = prev {
                width += font.kern(p, id);
            }
            width += font.h_advance(id);
            prev = Some(id);
        }
        Some((width, font.ascent() - font.descent(), font.ascent()))
    }
}

fn font_missing<E: std::error::Error + Send + Sync>() -> DrawingErrorKind<E> {
    DrawingErrorKind::FontError(Box::new(std::io::Error::other(
        "the bundled font cannot be read",
    )))
}

impl<B: DrawingBackend> DrawingBackend for GlyphText<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.present()
    }
    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        self.0.blit_bitmap(pos, size, src)
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> std::result::Result<(u32, u32), DrawingErrorKind<B::ErrorType>> {
        let (w, h, _) = Self::layout(text, style.size()).ok_or_else(font_missing)?;
        Ok((w.ceil() as u32, h.ceil() as u32))
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> std::result::Result<(), DrawingErrorKind<B::ErrorType>> {
        use ab_glyph::{Font, ScaleFont, point};
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let (width, height, ascent) = Self::layout(text, style.size()).ok_or_else(font_missing)?;
        let font = font()
            .ok_or_else(font_missing)?
            .as_scaled(style.size() as f32);
        let anchor = style.anchor();
        let x0 = match anchor.h_pos {
            HPos::Left => 0.0,
            HPos::Center => -width / 2.0,
            HPos::Right => -width,
        };
        let top = match anchor.v_pos {
            VPos::Top => 0.0,
            VPos::Center => -height / 2.0,
            VPos::Bottom => -height,
        };
        let transform = style.transform();
        let (w, h) = self.get_size();
        let mut pixels = Vec::new();
        let mut pen = x0;
        let mut prev = None;
        for c in text.chars() {
            let id = font.glyph_id(c);
            if let Some(p) = prev {
                pen += font.kern(p, id);
            }
            prev = Some(id);
            let glyph = id.with_scale_and_position(font.scale(), point(pen, top + ascent));
            pen += font.h_advance(id);
            if let Some(outline) = font.outline_glyph(glyph) {
                let b = outline.px_bounds();
                outline.draw(|x, y, coverage| {
                    if coverage > 0.0 {
                        pixels.push((
                            b.min.x as i32 + x as i32,
                            b.min.y as i32 + y as i32,
                            coverage,
                        ));
                    }
                });
            }
        }
        for (x, y, coverage) in pixels {
            let (x, y) = transform.transform(x, y);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && y >= 0 && x < w as i32 && y < h as i32 {
                self.0.draw_pixel(
                    (x, y),
                    BackendColor {
                        alpha: color.alpha * f64::from(coverage.min(1.0)),
                        rgb: color.rgb,
                    },
                )?;
            }
        }
        Ok(())
    }
}

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A figure to draw.
enum Plot<'a> {
    Sr(&'a Figure),
    /// Curves over other axes (the frequency of convergence).
    Curves(&'a Figure, &'a Axes),
    Speed(&'a [(String, f64)]),
    Map(&'a MapFigure),
}

/// A map of values over a square of offsets (the inspector's 2-D cost landscape), with a path
/// drawn over it.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFigure {
    pub title: String,
    pub x_desc: String,
    pub y_desc: String,
    /// `n x n` values, row `j` at the `j`-th offset of the second axis, non-finite left white.
    pub values: Vec<f64>,
    /// The offsets of both axes (ascending).
    pub offsets: Vec<f64>,
    /// A path over the map (the iterations), and a point to mark (the best sample).
    pub path: Vec<(f64, f64)>,
    pub best: Option<(f64, f64)>,
}

/// A perceptual colour map (dark blue through green to yellow) for `t` in 0..1 (the
/// inspector's landscape map and its exported figure).
pub fn colormap(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let c = |k: usize| (STOPS[i][k] + (STOPS[i + 1][k] - STOPS[i][k]) * f) as u8;
    [c(0), c(1), c(2)]
}

/// The axes of a curve figure.
#[derive(Clone, Debug, PartialEq)]
pub struct Axes {
    pub x_desc: String,
    pub y_desc: String,
    /// The ranges drawn.
    pub x_range: (f64, f64),
    pub y_range: (f64, f64),
    /// What the number after each legend entry is.
    pub legend_header: String,
}

impl Plot<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        match self {
            Plot::Sr(f) => draw_sr(
                area,
                f,
                &Axes {
                    x_desc: "error threshold t (px)".into(),
                    y_desc: "success rate".into(),
                    x_range: (0.0, SR_MAX),
                    y_range: (0.0, 1.02),
                    legend_header: "mean SR".into(),
                },
            ),
            Plot::Curves(f, axes) => draw_sr(area, f, axes),
            Plot::Speed(rows) => draw_speed(area, rows),
            Plot::Map(m) => draw_map(area, m),
        }
    }
}

fn draw_sr<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    axes: &Axes,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let root = root.titled(&fig.title, (FAMILY, 22).into_font().color(&BLACK))?;
    // The legend sits right of the plot, so that it hides no curve.
    let legend_font = (FAMILY, 15).into_font().color(&BLACK);
    let header = axes.legend_header.as_str();
    let entries: Vec<String> = fig
        .curves
        .iter()
        .map(|c| format!("{} ({:.3})", c.name, c.mean_sr))
        .collect();
    let mut text_w = root.estimate_text_size(header, &legend_font)?.0;
    for e in &entries {
        text_w = text_w.max(root.estimate_text_size(e, &legend_font)?.0);
    }
    let (w, h) = root.dim_in_pixel();
    let legend_w = (text_w + 60).max(140).min(w / 2);
    let (plot, legend) = root.split_horizontally(w.saturating_sub(legend_w));

    let mut chart = ChartBuilder::on(&plot)
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(62)
        .build_cartesian_2d(
            axes.x_range.0..axes.x_range.1,
            axes.y_range.0..axes.y_range.1,
        )?;
    // As many decimals as the ranges need.
    let decimals = |span: f64| -> usize {
        if span >= 20.0 {
            0
        } else if span >= 0.5 {
            1
        } else {
            2
        }
    };
    let (dx, dy) = (
        decimals(axes.x_range.1 - axes.x_range.0),
        decimals(axes.y_range.1 - axes.y_range.0),
    );
    chart
        .configure_mesh()
        .x_desc(axes.x_desc.as_str())
        .y_desc(axes.y_desc.as_str())
        .axis_desc_style((FAMILY, 17))
        .label_style((FAMILY, 14))
        .x_labels(11)
        .y_labels(11)
        .x_label_formatter(&|v| format!("{v:.dx$}"))
        .y_label_formatter(&|v| format!("{v:.dy$}"))
        .light_line_style(RGBColor(245, 245, 245))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    let style_of = |i: usize, c: &Curve| match c.style {
        Some(([r, g, b], dashed)) => (RGBColor(r, g, b), dashed),
        None => curve_style(i),
    };
    for (i, c) in fig.curves.iter().enumerate() {
        let (color, dashed) = style_of(i, c);
        let style = Color::stroke_width(&color, 2);
        // Each finite run of points is a line of its own.
        for run in c
            .points
            .split(|p| !(p.0.is_finite() && p.1.is_finite()))
            .filter(|r| !r.is_empty())
        {
            if dashed {
                chart.draw_series(DashedLineSeries::new(run.iter().copied(), 9, 5, style))?;
            } else {
                chart.draw_series(LineSeries::new(run.iter().copied(), style))?;
            }
        }
        chart.draw_series(
            c.marks
                .iter()
                .map(|&p| Cross::new(p, 5, Color::stroke_width(&color, 2))),
        )?;
    }

    let rows = entries.len() as u32 + 1;
    let row_h = ((h.saturating_sub(80)) / rows.max(1)).clamp(12, 26) as i32;
    let top = 24;
    legend.draw(&Text::new(
        header,
        (44, top),
        legend_font.clone().pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    for (i, (e, c)) in entries.iter().zip(&fig.curves).enumerate() {
        let y = top + row_h * (i as i32 + 1);
        let (color, dashed) = style_of(i, c);
        let style = Color::stroke_width(&color, 3);
        if dashed {
            legend.draw(&PathElement::new(vec![(4, y), (16, y)], style))?;
            legend.draw(&PathElement::new(vec![(22, y), (34, y)], style))?;
        } else {
            legend.draw(&PathElement::new(vec![(4, y), (34, y)], style))?;
        }
        legend.draw(&Text::new(
            e.as_str(),
            (44, y),
            legend_font.clone().pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    Ok(())
}

fn draw_map<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, m: &MapFigure) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let root = root.titled(&m.title, (FAMILY, 22).into_font().color(&BLACK))?;
    let n = m.offsets.len();
    let (w, _) = root.dim_in_pixel();
    // The colour bar at the right, with the values at its ends and middle.
    let (plot, bar) = root.split_horizontally(w.saturating_sub(120));
    let (r0, r1) = (
        m.offsets.first().copied().unwrap_or(-1.0),
        m.offsets.last().copied().unwrap_or(1.0),
    );
    let cell = if n > 1 {
        (r1 - r0) / (n - 1) as f64
    } else {
        1.0
    };
    let (lo, hi) = (r0 - cell / 2.0, r1 + cell / 2.0);
    let mut chart = ChartBuilder::on(&plot)
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(62)
        .build_cartesian_2d(lo..hi, lo..hi)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(m.x_desc.as_str())
        .y_desc(m.y_desc.as_str())
        .axis_desc_style((FAMILY, 17))
        .label_style((FAMILY, 14))
        .x_label_formatter(&|v| format!("{v:.1}"))
        .y_label_formatter(&|v| format!("{v:.1}"))
        .draw()?;
    let finite = m.values.iter().copied().filter(|v| v.is_finite());
    let (vlo, vhi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let span = (vhi - vlo).max(1e-12);
    let rgb = |t: f64| {
        let [r, g, b] = colormap(t);
        RGBColor(r, g, b)
    };
    chart.draw_series((0..n * n).filter_map(|k| {
        let v = *m.values.get(k)?;
        let (x, y) = (m.offsets[k % n], m.offsets[k / n]);
        v.is_finite().then(|| {
            Rectangle::new(
                [
                    (x - cell / 2.0, y - cell / 2.0),
                    (x + cell / 2.0, y + cell / 2.0),
                ],
                rgb((v - vlo) / span).filled(),
            )
        })
    }))?;
    if !m.path.is_empty() {
        chart.draw_series(LineSeries::new(
            m.path.iter().copied(),
            Color::stroke_width(&WHITE, 2),
        ))?;
        chart.draw_series(m.path.iter().map(|&p| Circle::new(p, 3, WHITE.filled())))?;
    }
    if let Some(b) = m.best {
        chart.draw_series(std::iter::once(Circle::new(
            b,
            5,
            RGBColor(255, 80, 80).filled(),
        )))?;
    }
    // The colour bar: top the largest f.
    let (_, bh) = bar.dim_in_pixel();
    let (top, bottom) = (40i32, bh as i32 - 70);
    let steps = 64;
    for k in 0..steps {
        let t = k as f64 / (steps - 1) as f64;
        let y0 = bottom - ((bottom - top) as f64 * (k + 1) as f64 / steps as f64) as i32;
        let y1 = bottom - ((bottom - top) as f64 * k as f64 / steps as f64) as i32;
        bar.draw(&Rectangle::new([(10, y0), (34, y1)], rgb(t).filled()))?;
    }
    let font = (FAMILY, 13)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (v, y) in [
        (vhi, top),
        (0.5 * (vlo + vhi), (top + bottom) / 2),
        (vlo, bottom),
    ] {
        bar.draw(&Text::new(format!("{v:.4}"), (40, y), font.clone()))?;
    }
    bar.draw(&Text::new("f", (14, top - 16), font.clone()))?;
    Ok(())
}

/// Draws a map figure (the 2-D cost landscape) to `path` (`.png` or `.svg`).
pub fn draw_map_figure(path: &Path, map: &MapFigure, size: (u32, u32)) -> Result<()> {
    save(path, size, &Plot::Map(map))
}

/// `x` rounded down (`up = false`) or up to a power of ten.
fn decade(x: f64, up: bool) -> f64 {
    let e = x.log10();
    10f64.powf(if up { e.ceil() } else { e.floor() })
}

fn draw_speed<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[(String, f64)],
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let root = root.titled(
        "Speed: tracker-only frames per second (the search alone)",
        (FAMILY, 22).into_font().color(&BLACK),
    )?;
    let label_font: TextStyle = (FAMILY, 14).into();
    let mut name_w = 0;
    for (name, _) in rows {
        name_w = name_w.max(root.estimate_text_size(name, &label_font)?.0);
    }
    let positive: Vec<f64> = rows
        .iter()
        .map(|r| r.1)
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let (lo, hi) = if positive.is_empty() {
        (1.0, 10.0)
    } else {
        let min = positive.iter().copied().fold(f64::INFINITY, f64::min);
        let max = positive.iter().copied().fold(0.0, f64::max);
        // Room right of the longest bar for its value.
        (decade(min, false), decade(max * 3.0, true))
    };
    let n = rows.len().max(1) as f64;
    let mut chart = ChartBuilder::on(&root)
        .margin(14)
        .margin_right(40)
        .x_label_area_size(50)
        .y_label_area_size(name_w + 20)
        .build_cartesian_2d((lo..hi).log_scale(), 0.0..n)?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(0)
        .x_desc("tracker-only FPS (log scale)")
        .axis_desc_style((FAMILY, 17))
        .label_style((FAMILY, 14))
        .x_label_formatter(&|v| {
            if *v >= 1.0 {
                format!("{v:.0}")
            } else {
                format!("{v}")
            }
        })
        .light_line_style(RGBColor(245, 245, 245))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    // Row i spans [i, i + 1]; the names go left of the axis, the values right of the bars.
    let bar = PALETTE[0];
    chart.draw_series(
        rows.iter()
            .enumerate()
            .filter(|(_, r)| r.1.is_finite() && r.1 > 0.0)
            .map(|(i, r)| {
                let mut rect =
                    Rectangle::new([(lo, i as f64), (r.1, i as f64 + 1.0)], bar.filled());
                rect.set_margin(3, 3, 0, 0);
                rect
            }),
    )?;
    let name_font = label_font
        .color(&BLACK)
        .pos(Pos::new(HPos::Right, VPos::Center));
    let value_font = (FAMILY, 13)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (i, r) in rows.iter().enumerate() {
        let y = i as f64 + 0.5;
        let x = if r.1.is_finite() && r.1 > 0.0 {
            r.1
        } else {
            lo
        };
        chart.plotting_area().draw(
            &(EmptyElement::at((lo, y)) + Text::new(r.0.clone(), (-8, 0), name_font.clone())),
        )?;
        chart.plotting_area().draw(
            &(EmptyElement::at((x, y))
                + Text::new(format!("{:.0}", r.1), (6, 0), value_font.clone())),
        )?;
    }
    Ok(())
}

/// Draws `plot` to `path`, a `.png` or `.svg` file.
fn save(path: &Path, (w, h): (u32, u32), plot: &Plot) -> Result<()> {
    if w < MIN_SIZE.0 || h < MIN_SIZE.1 || w > 8192 || h > 8192 {
        return Err(Error::report(
            path,
            format!(
                "a figure of {w}x{h} px: width {}..=8192 and height {}..=8192",
                MIN_SIZE.0, MIN_SIZE.1
            ),
        ));
    }
    register_font()?;
    let fail = |e: String| Error::report(path, format!("cannot draw the figure: {e}"));
    let bytes = match path.extension().and_then(|e| e.to_str()) {
        Some("svg") => {
            let mut svg = String::new();
            {
                let area = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
                plot.draw(&area).map_err(|e| fail(e.to_string()))?;
                area.present().map_err(|e| fail(e.to_string()))?;
            }
            svg.into_bytes()
        }
        Some("png") => {
            let mut rgb = vec![255u8; w as usize * h as usize * 3];
            {
                let area =
                    GlyphText(BitMapBackend::with_buffer(&mut rgb, (w, h))).into_drawing_area();
                plot.draw(&area).map_err(|e| fail(e.to_string()))?;
                area.present().map_err(|e| fail(e.to_string()))?;
            }
            let mut png = Vec::new();
            image::ImageEncoder::write_image(
                image::codecs::png::PngEncoder::new(&mut png),
                &rgb,
                w,
                h,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| Error::ImageWrite {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
            png
        }
        _ => {
            return Err(Error::report(path, "a figure is written as .png or .svg"));
        }
    };
    write_atomic(path, &bytes)
}

/// Draws a success-rate figure to `path` (`.png` or `.svg`).
pub fn draw_sr_figure(path: &Path, figure: &Figure, size: (u32, u32)) -> Result<()> {
    save(path, size, &Plot::Sr(figure))
}

/// Draws curves over other axes (as [`draw_sr_figure`] draws success rates) to `path`.
pub fn draw_curve_figure(
    path: &Path,
    figure: &Figure,
    axes: &Axes,
    size: (u32, u32),
) -> Result<()> {
    save(path, size, &Plot::Curves(figure, axes))
}

/// Draws the horizontal bar chart of tracker-only FPS (log scale) to `path` (`.png` or `.svg`),
/// fastest at the top; `size.1` is the height for up to 20 trackers, more get more room.
pub fn draw_speed_chart(path: &Path, trackers: &[TrackerResult], size: (u32, u32)) -> Result<()> {
    let mut rows: Vec<(String, f64)> = trackers
        .iter()
        .map(|t| (t.summary.tracker.clone(), t.summary.tracker_fps))
        .collect();
    // Bottom to top: the slowest first.
    rows.sort_by(|a, b| a.1.total_cmp(&b.1).then_with(|| b.0.cmp(&a.0)));
    let h = size.1.max(120 + 24 * rows.len() as u32);
    save(path, (size.0, h), &Plot::Speed(&rows))
}

fn fmt_num(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "n/a".to_string()
    }
}

/// The benchmarks' figures of each tracker (P@5, P@15, success by homography discrepancy and
/// by IoU), then the same per challenge factor when the sequences have factors.
fn benchmark_tables(trackers: &[TrackerResult]) -> String {
    let mut md = String::from(
        "\n## As the planar-tracking benchmarks publish\n\nP@t is the fraction of frames whose \
         RMS corner error (POT's and PlanarTrack's alignment error) is at most t px; S(H) the \
         mean over t = 0, 10, ..., 200 of the fraction whose homography discrepancy (the corners \
         (+-1, +-1) through H* H^-1) is at most t; S(IoU) the mean over t = 0, 0.05, ..., 1 of \
         the fraction whose IoU is above t. The curves are in `benchmark_curves.csv`.\n\n\
         | tracker | frames | P@5 | P@15 | S(H) | S(IoU) |\n|---|---:|---:|---:|---:|---:|\n",
    );
    let row = |s: &Summary, first: &str| {
        format!(
            "| {first} | {} | {} | {} | {} | {} |\n",
            s.frames,
            fmt_num(s.p5, 4),
            fmt_num(s.p15, 4),
            fmt_num(s.success_h, 4),
            fmt_num(s.success_iou, 4),
        )
    };
    for t in trackers {
        md.push_str(&row(&t.summary, &t.summary.tracker));
    }
    let mut factors: Vec<&str> = Vec::new();
    for s in trackers.iter().flat_map(|t| t.factors.iter()) {
        if !factors.contains(&s.sequence.as_str()) {
            factors.push(&s.sequence);
        }
    }
    if !factors.is_empty() {
        md.push_str(
            "\n### Per challenge factor\n\nEach tracker's runs on the sequences of a factor, \
             pooled (the `ALL:<factor>` rows of `summary.csv`).\n\n\
             | factor | tracker | frames | P@5 | P@15 | S(H) | S(IoU) |\n\
             |---|---|---:|---:|---:|---:|---:|\n",
        );
        for f in factors {
            let name = f.split_once(':').map_or(f, |x| x.1);
            for t in trackers {
                if let Some(s) = t.factors.iter().find(|s| s.sequence == f) {
                    md.push_str(&row(s, &format!("{name} | {}", t.summary.tracker)));
                }
            }
        }
    }
    md
}

/// The benchmarks' curves of every tracker as CSV: `tracker,curve,t,value` (`precision`,
/// `success_h`, `success_iou`).
pub fn benchmark_curves_csv(trackers: &[TrackerResult]) -> String {
    let mut csv = String::from("tracker,curve,t,value\n");
    for t in trackers {
        for (name, c) in [
            ("precision", &t.precision),
            ("success_h", &t.discrepancy),
            ("success_iou", &t.iou),
        ] {
            for (x, y) in c {
                csv.push_str(&format!(
                    "{},{name},{x},{}\n",
                    t.summary.tracker,
                    fmt_num(*y, 4)
                ));
            }
        }
    }
    csv
}

/// The markdown report: how the runs were pooled, the table (best mean SR first), the figures.
pub fn markdown(dirs: &[PathBuf], trackers: &[TrackerResult], figures: &[Figure]) -> String {
    let mut md = String::from("# Evaluation report\n\n");
    let sequences: BTreeSet<&str> = trackers
        .iter()
        .flat_map(|t| t.sequences.iter().map(|s| s.as_str()))
        .collect();
    md.push_str(&format!(
        "{} trackers on {} sequences ({}), read from {}.\n\n",
        trackers.len(),
        sequences.len(),
        sequences.iter().copied().collect::<Vec<_>>().join(", "),
        dirs.iter()
            .map(|d| format!("`{}`", d.display()))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    if trackers
        .iter()
        .any(|t| t.sequences.len() != sequences.len())
    {
        md.push_str(
            "**Not every tracker was run on every sequence**: compare the rows with care.\n\n",
        );
    }
    // The error the runs were scored by (`eval --error`; the same for every run pooled).
    let (error, unit) = match trackers.first().map(|t| t.summary.error_type.as_str()) {
        Some("center") => ("centre location error is at most t px", " (px)"),
        Some("jaccard") => (
            "Jaccard error, 1 - IoU, is at most t / 20 (the figures' t is 20 (1 - IoU))",
            "",
        ),
        _ => ("alignment error is at most t px", " (px)"),
    };
    md.push_str(&format!(
        "Each tracker's frames are pooled over all its sequences (initialisation frames \
         excluded, and frames without ground truth), as the `ALL` rows of `summary.csv`. SR@t \
         is the fraction of frames whose {error} (a lost frame never counts); mean SR is the \
         mean of SR(t) over t = 0..20 in steps of 0.1; the mean error{unit} is over the frames \
         with corners; a failure is the tracker lost or its alignment error above the failure \
         threshold; FPS are over every frame searched (tracked or lost), of the search alone \
         (tracker) and of the whole update from an 8-bit frame (live).\n\n",
    ));
    md.push_str(&format!(
        "| tracker | frames | SR@5 | SR@10 | SR@20 | mean SR | mean error{unit} | failures | \
         iterations/frame | tracker FPS | live FPS |\n",
    ));
    md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for t in trackers {
        let s = &t.summary;
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            s.tracker,
            s.frames,
            fmt_num(s.sr5, 4),
            fmt_num(s.sr10, 4),
            fmt_num(s.sr20, 4),
            fmt_num(s.mean_sr, 4),
            fmt_num(s.mean_error, 4),
            s.failures,
            fmt_num(s.iterations_per_frame, 2),
            fmt_num(s.tracker_fps, 1),
            fmt_num(s.live_fps, 1),
        ));
    }
    md.push_str(&benchmark_tables(trackers));
    md.push_str("\n## Success rates\n");
    let sections = [
        (
            FigureKind::SmsPerAm,
            "Search methods, for each appearance model",
        ),
        (
            FigureKind::AmsPerSm,
            "Appearance models, for each search method",
        ),
        (FigureKind::Ssms, "State space models"),
        (
            FigureKind::Learning,
            "Learning-based trackers beside the registration trackers",
        ),
        (FigureKind::Others, "Other trackers"),
    ];
    for (kind, heading) in sections {
        let mine: Vec<&Figure> = figures.iter().filter(|f| f.kind == kind).collect();
        if mine.is_empty() {
            continue;
        }
        md.push_str(&format!("\n### {heading}\n"));
        for f in mine {
            md.push_str(&format!(
                "\n![{}]({}.png)\n\n[SVG]({}.svg)\n",
                f.title, f.stem, f.stem
            ));
        }
    }
    md.push_str("\n## Speed\n\n![Tracker-only FPS, log scale](speed.png)\n\n[SVG](speed.svg)\n");
    md
}

/// Reads every run under `dirs`, pools them per tracker, and writes to `out` the success-rate
/// figures and the speed chart (PNG and SVG) and `report.md`.
pub fn write_report(dirs: &[PathBuf], out: &Path, partial: bool) -> Result<Report> {
    let plans = eval::check_plans(dirs)?;
    let runs = eval::read_all_runs(dirs)?;
    // An incomplete set of shards is refused, or (`partial`) labelled in every title.
    let missing = eval::require_complete(dirs, &plans, &runs, partial)?;
    let trackers = pool(&runs);
    let mut figures = sr_figures(&trackers);
    if missing.is_some() {
        for f in &mut figures {
            f.title.push_str(" (partial)");
        }
    }
    let mut files = Vec::new();
    for f in &figures {
        for ext in ["png", "svg"] {
            let p = out.join(format!("{}.{ext}", f.stem));
            draw_sr_figure(&p, f, FIGURE_SIZE)?;
            files.push(p);
        }
    }
    for ext in ["png", "svg"] {
        let p = out.join(format!("speed.{ext}"));
        if missing.is_some() {
            // Each bar says the result is partial.
            let mut labelled = trackers.clone();
            for t in &mut labelled {
                t.summary.tracker.push_str(" (partial)");
            }
            draw_speed_chart(&p, &labelled, FIGURE_SIZE)?;
        } else {
            draw_speed_chart(&p, &trackers, FIGURE_SIZE)?;
        }
        files.push(p);
    }
    let curves = out.join("benchmark_curves.csv");
    write_atomic(&curves, benchmark_curves_csv(&trackers).as_bytes())?;
    files.push(curves);
    let md = out.join("report.md");
    let mut text = markdown(dirs, &trackers, &figures);
    if let Some(inc) = &missing {
        let at = text.find("\n\n").map_or(text.len(), |i| i + 2);
        text.insert_str(
            at,
            &format!("**Partial result** (`--partial`): {inc}. Every figure and row below pools only the runs there are.\n\n"),
        );
    }
    write_atomic(&md, text.as_bytes())?;
    files.push(md);
    Ok(Report {
        trackers,
        figures,
        files,
    })
}
