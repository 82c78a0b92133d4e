//! Chart primitives shared by every figure of objview (Figure 2 of the paper now, the run
//! reports — NSC vs #views per method, path cost vs NSC — later): a [`Chart`] is one panel with
//! titled axes (linear or log), line/marker [`Series`] (optional jitter, alpha, per-point labels),
//! [`BarSeries`] (histograms, stacked bars) and dashed [`RefLine`]s; a [`Figure`] lays panels out
//! in a grid with an optional caption and writes the SAME drawing as PNG and SVG.
//!
//! Design choices, so that a figure reads well without the code and is reproducible:
//! - the legend sits in its own column right of the plot, so it never covers data; reference
//!   lines are listed in it (dashed) rather than labelled inside the plot;
//! - ticks and tick labels come from [`crate::ticks`], not plotters' defaults;
//! - text uses the embedded font ([`crate::font`]), colours a fixed palette ([`PALETTE`]), and
//!   jitter a seeded generator: the same chart always gives the same bytes.

use std::path::{Path, PathBuf};

use objview_geom::hash::splitmix64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;

use crate::png_text::PngBackend;
/// The axis scale lives with the tick rules that depend on it.
pub use crate::ticks::Scale;
use crate::{font, ticks, PlotError};

/// An opaque colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Rgb(pub u8, pub u8, pub u8);

impl Rgb {
    fn with_alpha(self, alpha: f64) -> RGBAColor {
        RGBColor(self.0, self.1, self.2).mix(alpha)
    }

    /// `#rrggbb`.
    pub fn hex(self) -> String {
        format!("#{:02x}{:02x}{:02x}", self.0, self.1, self.2)
    }
}

/// The fixed series palette (Okabe–Ito, distinguishable with the common colour-vision
/// deficiencies; its yellow is replaced by a dark grey, which reads better on white).
pub const PALETTE: [Rgb; 8] = [
    Rgb(0, 114, 178),   // blue
    Rgb(213, 94, 0),    // vermillion
    Rgb(0, 158, 115),   // bluish green
    Rgb(204, 121, 167), // reddish purple
    Rgb(230, 159, 0),   // orange
    Rgb(86, 180, 233),  // sky blue
    Rgb(90, 90, 90),    // dark grey
    Rgb(0, 0, 0),       // black
];

/// Black, for emphasised series (pool aggregates) and reference lines.
pub const INK: Rgb = Rgb(0, 0, 0);

/// The `i`-th palette colour (cycling).
pub fn palette(i: usize) -> Rgb {
    PALETTE[i % PALETTE.len()]
}

/// One axis: its label (name and unit), scale, optional fixed range and optional fixed ticks.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    /// Axis title: the quantity's name and unit.
    pub label: String,
    /// Linear or base-10 logarithmic.
    pub scale: Scale,
    /// Drawn range; `None`: the data range, padded.
    pub range: Option<(f64, f64)>,
    /// Ticks with their labels; `None`: 1-2-5 ticks labelled with their values.
    pub ticks: Option<Vec<(f64, String)>>,
    /// Computed ticks only at whole numbers (counts, numbers of views).
    pub integer: bool,
}

impl Axis {
    /// A linear axis titled `label`, data range, computed ticks.
    pub fn linear(label: impl Into<String>) -> Self {
        Axis { label: label.into(), scale: Scale::Linear, range: None, ticks: None, integer: false }
    }

    /// A base-10 logarithmic axis titled `label`, data range, computed ticks.
    pub fn log(label: impl Into<String>) -> Self {
        Axis { label: label.into(), scale: Scale::Log, range: None, ticks: None, integer: false }
    }

    /// The axis with the fixed drawn range `lo..hi` (data units) instead of the padded data range.
    pub fn with_range(mut self, lo: f64, hi: f64) -> Self {
        self.range = Some((lo, hi));
        self
    }

    /// The axis with these ticks (position in data units, label) instead of computed ones.
    pub fn with_ticks(mut self, ticks: Vec<(f64, String)>) -> Self {
        self.ticks = Some(ticks);
        self
    }

    /// The axis with computed ticks only at whole numbers.
    pub fn with_integer_ticks(mut self) -> Self {
        self.integer = true;
        self
    }
}

/// Point marker shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Marker {
    /// No marker (a line only).
    None,
    /// Filled circle of radius `marker_size`.
    Circle,
    /// Filled square of half-side `marker_size`.
    Square,
    /// Filled triangle of size `marker_size + 1`.
    Triangle,
    /// Cross of size `marker_size`, 2 px strokes.
    Cross,
}

/// Deterministic jitter: point `i` moves by up to ±`dx` in x and ±`dy` in y (data units), by a
/// seeded generator (SplitMix64 of `seed` and `i`), so the same chart gives the same picture.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Jitter {
    /// Largest horizontal offset, ± data units (at least 0).
    pub dx: f64,
    /// Largest vertical offset, ± data units (at least 0).
    pub dy: f64,
    /// Seed of the offsets.
    pub seed: u64,
}

impl Jitter {
    /// The offset of point `i`.
    pub fn offset(&self, i: usize) -> (f64, f64) {
        let base = splitmix64(self.seed ^ splitmix64(i as u64));
        let u = |k: u64| (splitmix64(base ^ k) >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        (u(1) * self.dx, u(2) * self.dy)
    }
}

/// A named series of (x, y) points drawn as a line, as markers, or both.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text; empty: not in the legend.
    pub name: String,
    /// The (x, y) points in data units, in drawing order (all finite).
    pub points: Vec<(f64, f64)>,
    /// Colour of the line and markers.
    pub color: Rgb,
    /// Line width in pixels; 0: no line.
    pub line_width: u32,
    /// Draw the line dashed (8 px on, 5 px off) instead of solid.
    pub dashed: bool,
    /// Marker drawn at every point.
    pub marker: Marker,
    /// Marker radius in pixels.
    pub marker_size: u32,
    /// Opacity in [0, 1].
    pub alpha: f64,
    /// Empty, or one text per point, drawn next to it.
    pub labels: Vec<String>,
    /// Deterministic offsets applied to the drawn points; `None`: drawn where they are.
    pub jitter: Option<Jitter>,
}

impl Series {
    /// A solid line, 2 px, no markers.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>, color: Rgb) -> Self {
        Series {
            name: name.into(),
            points,
            color,
            line_width: 2,
            dashed: false,
            marker: Marker::None,
            marker_size: 3,
            alpha: 1.0,
            labels: Vec::new(),
            jitter: None,
        }
    }

    /// Markers only (a scatter plot).
    pub fn scatter(name: impl Into<String>, points: Vec<(f64, f64)>, color: Rgb, marker: Marker) -> Self {
        Series { line_width: 0, marker, marker_size: 4, ..Series::line(name, points, color) }
    }

    /// The series with markers of this shape and size (pixels).
    pub fn with_marker(mut self, marker: Marker, size: u32) -> Self {
        self.marker = marker;
        self.marker_size = size;
        self
    }

    /// The series with a line `width` pixels wide (0: no line).
    pub fn with_width(mut self, width: u32) -> Self {
        self.line_width = width;
        self
    }

    /// The series with a dashed line.
    pub fn with_dashes(mut self) -> Self {
        self.dashed = true;
        self
    }

    /// The series with opacity `alpha` in [0, 1].
    pub fn with_alpha(mut self, alpha: f64) -> Self {
        self.alpha = alpha;
        self
    }

    /// The series with one text label per point (empty strings draw nothing).
    pub fn with_labels(mut self, labels: Vec<String>) -> Self {
        self.labels = labels;
        self
    }

    /// The series with its points drawn moved by `jitter`.
    pub fn with_jitter(mut self, jitter: Jitter) -> Self {
        self.jitter = Some(jitter);
        self
    }

    /// The positions drawn: the points, moved by the jitter if any.
    pub fn drawn_points(&self) -> Vec<(f64, f64)> {
        match &self.jitter {
            None => self.points.clone(),
            Some(j) => self
                .points
                .iter()
                .enumerate()
                .map(|(i, &(x, y))| {
                    let (dx, dy) = j.offset(i);
                    (x + dx, y + dy)
                })
                .collect(),
        }
    }
}

/// A filled rectangle from (x0, y0) to (x1, y1) in data units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bar {
    /// Left edge, data units.
    pub x0: f64,
    /// Right edge, data units.
    pub x1: f64,
    /// Bottom edge, data units.
    pub y0: f64,
    /// Top edge, data units.
    pub y1: f64,
}

/// Named bars of one colour (a histogram, or one layer of stacked bars).
#[derive(Clone, Debug, PartialEq)]
pub struct BarSeries {
    /// Legend text; empty: not in the legend.
    pub name: String,
    /// Fill colour of every bar.
    pub color: Rgb,
    /// Fill opacity in [0, 1].
    pub alpha: f64,
    /// The rectangles, drawn with a 1 px white edge.
    pub bars: Vec<Bar>,
}

impl BarSeries {
    /// Bars named `name` (legend text) in `color`, at opacity 0.85.
    pub fn new(name: impl Into<String>, color: Rgb, bars: Vec<Bar>) -> Self {
        BarSeries { name: name.into(), color, alpha: 0.85, bars }
    }

    /// A histogram of `values` with bins `[origin + k·width, origin + (k+1)·width)`, one bar per
    /// non-empty bin (non-finite values are ignored).
    pub fn histogram(name: impl Into<String>, color: Rgb, values: &[f64], origin: f64, width: f64) -> Self {
        let mut counts = std::collections::BTreeMap::<i64, usize>::new();
        for v in values.iter().filter(|v| v.is_finite()) {
            *counts.entry(((v - origin) / width).floor() as i64).or_default() += 1;
        }
        let bars = counts
            .into_iter()
            .map(|(k, c)| Bar {
                x0: origin + k as f64 * width,
                x1: origin + (k + 1) as f64 * width,
                y0: 0.0,
                y1: c as f64,
            })
            .collect();
        BarSeries::new(name, color, bars)
    }
}

/// Direction of a reference line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Orientation {
    /// x = const.
    Vertical,
    /// y = const.
    Horizontal,
}

/// A dashed line across the plot at a fixed x or y, explained in the legend.
#[derive(Clone, Debug, PartialEq)]
pub struct RefLine {
    /// Vertical (x = `at`) or horizontal (y = `at`).
    pub orientation: Orientation,
    /// Where the line crosses its axis, data units.
    pub at: f64,
    /// Legend text.
    pub label: String,
    /// Line colour (drawn at 0.9 opacity).
    pub color: Rgb,
}

impl RefLine {
    /// A black vertical line at x = `at`, explained by `label`.
    pub fn vertical(at: f64, label: impl Into<String>) -> Self {
        RefLine { orientation: Orientation::Vertical, at, label: label.into(), color: INK }
    }

    /// A black horizontal line at y = `at`, explained by `label`.
    pub fn horizontal(at: f64, label: impl Into<String>) -> Self {
        RefLine { orientation: Orientation::Horizontal, at, label: label.into(), color: INK }
    }

    /// The line in `color`.
    pub fn with_color(mut self, color: Rgb) -> Self {
        self.color = color;
        self
    }
}

/// Where the legend goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Legend {
    /// A column right of the plot (never over the data).
    Right,
    /// No legend; the plot takes the whole panel width.
    None,
}

/// Drawn ranges of a chart: ((x_lo, x_hi), (y_lo, y_hi)).
pub type Ranges = ((f64, f64), (f64, f64));

/// One panel.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    /// Panel title, drawn above the plot.
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// Drawn first (under the series).
    pub bars: Vec<BarSeries>,
    /// Lines and markers, drawn last, in order.
    pub series: Vec<Series>,
    /// Dashed reference lines, drawn between the bars and the series.
    pub ref_lines: Vec<RefLine>,
    /// Where the legend goes.
    pub legend: Legend,
}

impl Chart {
    /// An empty panel titled `title` with these axes and the legend on the right.
    pub fn new(title: impl Into<String>, x: Axis, y: Axis) -> Self {
        Chart {
            title: title.into(),
            x,
            y,
            bars: Vec::new(),
            series: Vec::new(),
            ref_lines: Vec::new(),
            legend: Legend::Right,
        }
    }

    /// The chart with `s` added on top of the other series.
    pub fn with_series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }

    /// The chart with the bars `b` added (on top of earlier bars).
    pub fn with_bars(mut self, b: BarSeries) -> Self {
        self.bars.push(b);
        self
    }

    /// The chart with the reference line `r` added.
    pub fn with_ref_line(mut self, r: RefLine) -> Self {
        self.ref_lines.push(r);
        self
    }

    /// The chart with its legend placed as `legend`.
    pub fn with_legend(mut self, legend: Legend) -> Self {
        self.legend = legend;
        self
    }

    fn invalid(&self, reason: String) -> PlotError {
        PlotError::InvalidChart { title: self.title.clone(), reason }
    }

    /// Checks what drawing relies on: finite values, opacities in [0, 1], one label per point,
    /// sane fixed ranges.
    pub fn validate(&self) -> Result<(), PlotError> {
        for s in &self.series {
            if let Some(i) = s.points.iter().position(|(x, y)| !x.is_finite() || !y.is_finite()) {
                return Err(self.invalid(format!("series '{}': point {i} is not finite", s.name)));
            }
            if !s.labels.is_empty() && s.labels.len() != s.points.len() {
                return Err(self.invalid(format!(
                    "series '{}': {} labels for {} points",
                    s.name,
                    s.labels.len(),
                    s.points.len()
                )));
            }
            if !(0.0..=1.0).contains(&s.alpha) {
                return Err(self.invalid(format!("series '{}': alpha {} is not in [0, 1]", s.name, s.alpha)));
            }
            if let Some(j) = &s.jitter {
                if !(j.dx.is_finite() && j.dy.is_finite() && j.dx >= 0.0 && j.dy >= 0.0) {
                    return Err(self.invalid(format!("series '{}': jitter must be finite and >= 0", s.name)));
                }
            }
        }
        for b in &self.bars {
            if b.bars.iter().any(|r| ![r.x0, r.x1, r.y0, r.y1].iter().all(|v| v.is_finite())) {
                return Err(self.invalid(format!("bars '{}': a bar is not finite", b.name)));
            }
            if !(0.0..=1.0).contains(&b.alpha) {
                return Err(self.invalid(format!("bars '{}': alpha {} is not in [0, 1]", b.name, b.alpha)));
            }
        }
        if let Some(r) = self.ref_lines.iter().find(|r| !r.at.is_finite()) {
            return Err(self.invalid(format!("reference line '{}' is not finite", r.label)));
        }
        for (name, axis) in [("x", &self.x), ("y", &self.y)] {
            if let Some((lo, hi)) = axis.range {
                let bad =
                    !(lo.is_finite() && hi.is_finite() && lo < hi) || (axis.scale == Scale::Log && lo <= 0.0);
                if bad {
                    return Err(self.invalid(format!(
                        "{name} range [{lo}, {hi}] is not a valid {:?} range",
                        axis.scale
                    )));
                }
            }
        }
        Ok(())
    }

    /// Finite values on one axis (x: `true`), for a log axis only positive ones.
    fn axis_values(&self, x: bool) -> Vec<f64> {
        let mut v = Vec::new();
        for s in &self.series {
            v.extend(s.drawn_points().iter().map(|p| if x { p.0 } else { p.1 }));
        }
        for b in &self.bars {
            for r in &b.bars {
                v.extend(if x { [r.x0, r.x1] } else { [r.y0, r.y1] });
            }
        }
        let wanted = if x { Orientation::Vertical } else { Orientation::Horizontal };
        v.extend(self.ref_lines.iter().filter(|r| r.orientation == wanted).map(|r| r.at));
        let scale = if x { self.x.scale } else { self.y.scale };
        v.retain(|a| a.is_finite() && (scale == Scale::Linear || *a > 0.0));
        v
    }

    /// The drawn (lo, hi) of each axis: the fixed range, or the padded data range.
    pub fn ranges(&self) -> Result<Ranges, PlotError> {
        let one = |x: bool| -> Result<(f64, f64), PlotError> {
            let axis = if x { &self.x } else { &self.y };
            if let Some(r) = axis.range {
                return Ok(r);
            }
            let v = self.axis_values(x);
            if v.is_empty() {
                return match axis.scale {
                    Scale::Linear => Ok((0.0, 1.0)),
                    Scale::Log => Err(self.invalid(format!(
                        "no positive value on the log {} axis and no fixed range",
                        if x { "x" } else { "y" }
                    ))),
                };
            }
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            Ok(ticks::padded_range(axis.scale, lo, hi))
        };
        Ok((one(true)?, one(false)?))
    }
}

/// Panels in a grid, with an optional caption under them, drawn to PNG and SVG.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// Width in pixels (PNG) and SVG user units.
    pub width: u32,
    /// Height in pixels (PNG) and SVG user units.
    pub height: u32,
    /// Panels per row.
    pub columns: usize,
    /// The panels, row by row.
    pub panels: Vec<Chart>,
    /// A note under the panels (what is left out, how to read it).
    pub caption: Option<String>,
}

/// Default size of a one-panel figure.
pub const DEFAULT_SIZE: (u32, u32) = (1000, 650);

/// Font sizes in pixels.
const TITLE_PX: f64 = 20.0;
const AXIS_PX: f64 = 17.0;
const TICK_PX: f64 = 14.0;
const LEGEND_PX: f64 = 14.0;
const CAPTION_PX: f64 = 14.0;
const POINT_LABEL_PX: f64 = 12.0;

impl Figure {
    /// One chart at [`DEFAULT_SIZE`].
    pub fn single(chart: Chart) -> Self {
        Figure {
            width: DEFAULT_SIZE.0,
            height: DEFAULT_SIZE.1,
            columns: 1,
            panels: vec![chart],
            caption: None,
        }
    }

    /// Panels in `columns` columns on a `width` × `height` canvas.
    pub fn grid(panels: Vec<Chart>, columns: usize, width: u32, height: u32) -> Self {
        Figure { width, height, columns, panels, caption: None }
    }

    /// The figure with `caption` under the panels (word-wrapped; `\n` starts a paragraph).
    pub fn with_caption(mut self, caption: impl Into<String>) -> Self {
        self.caption = Some(caption.into());
        self
    }

    fn validate(&self) -> Result<(), PlotError> {
        if self.width < 200 || self.height < 150 || self.width > 10_000 || self.height > 10_000 {
            return Err(PlotError::InvalidSetting {
                name: "figure size",
                reason: format!("{}x{} is outside 200x150 ..= 10000x10000", self.width, self.height),
            });
        }
        if self.columns == 0 || self.panels.is_empty() {
            return Err(PlotError::InvalidSetting {
                name: "figure layout",
                reason: format!("{} panels in {} columns", self.panels.len(), self.columns),
            });
        }
        self.panels.iter().try_for_each(Chart::validate)
    }

    /// The figure as PNG bytes (RGB, 8 bit).
    pub fn to_png(&self) -> Result<Vec<u8>, PlotError> {
        self.validate()?;
        font::ensure_registered()?;
        let (w, h) = (self.width, self.height);
        let fail = |reason: String| PlotError::Draw { target: "PNG".into(), reason };
        let mut rgb = vec![0u8; w as usize * h as usize * 3];
        {
            let root = PngBackend::new(&mut rgb, (w, h), font::font_ref()?).into_drawing_area();
            draw_figure(&root, self).map_err(fail)?;
            root.present().map_err(|e| fail(e.to_string()))?;
        }
        let mut png = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut png),
            &rgb,
            w,
            h,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| fail(format!("PNG encoding: {e}")))?;
        Ok(png)
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, PlotError> {
        self.validate()?;
        font::ensure_registered()?;
        let fail = |reason: String| PlotError::Draw { target: "SVG".into(), reason };
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (self.width, self.height)).into_drawing_area();
            draw_figure(&root, self).map_err(fail)?;
            root.present().map_err(|e| fail(e.to_string()))?;
        }
        Ok(svg)
    }

    /// Writes `<dir>/<stem>.png` and `<dir>/<stem>.svg` (the folder must exist); returns both
    /// paths, PNG first.
    pub fn write(&self, dir: &Path, stem: &str) -> Result<[PathBuf; 2], PlotError> {
        let png_path = dir.join(format!("{stem}.png"));
        let svg_path = dir.join(format!("{stem}.svg"));
        let at = |path: &Path, e: PlotError| match e {
            PlotError::Draw { reason, .. } => PlotError::Draw { target: path.display().to_string(), reason },
            other => other,
        };
        let png = self.to_png().map_err(|e| at(&png_path, e))?;
        let svg = self.to_svg().map_err(|e| at(&svg_path, e))?;
        std::fs::write(&png_path, png).map_err(|e| PlotError::io(&png_path, e))?;
        std::fs::write(&svg_path, svg).map_err(|e| PlotError::io(&svg_path, e))?;
        Ok([png_path, svg_path])
    }
}

// ------------------------------------------------------------------------------------ drawing

type Area<DB> = DrawingArea<DB, Shift>;

fn text_style(px: f64, color: RGBColor) -> TextStyle<'static> {
    let mut style = TextStyle::from((font::FAMILY, px).into_font());
    style.color = color.to_backend_color();
    style
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn text_width<DB: DrawingBackend>(area: &Area<DB>, text: &str, style: &TextStyle) -> Result<u32, String> {
    Ok(area.estimate_text_size(text, style).map_err(err)?.0)
}

/// Greedy word wrap of `text` into lines at most `max_px` wide (a word longer than that gets a
/// line of its own).
fn wrap<DB: DrawingBackend>(
    area: &Area<DB>,
    text: &str,
    style: &TextStyle,
    max_px: u32,
) -> Result<Vec<String>, String> {
    let mut lines: Vec<String> = Vec::new();
    for paragraph in text.split('\n') {
        let mut line = String::new();
        for word in paragraph.split_whitespace() {
            let candidate = if line.is_empty() { word.to_string() } else { format!("{line} {word}") };
            if !line.is_empty() && text_width(area, &candidate, style)? > max_px {
                lines.push(std::mem::replace(&mut line, word.to_string()));
            } else {
                line = candidate;
            }
        }
        lines.push(line);
    }
    Ok(lines)
}

fn draw_figure<DB: DrawingBackend>(root: &Area<DB>, fig: &Figure) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let (w, h) = root.dim_in_pixel();
    let mut body = root.clone();
    if let Some(caption) = &fig.caption {
        let style = text_style(CAPTION_PX, RGBColor(60, 60, 60));
        let lines = wrap(root, caption, &style, w.saturating_sub(40))?;
        let line_h = (CAPTION_PX * 1.35).ceil() as i32;
        let cap_h = line_h * lines.len() as i32 + 16;
        let (top, bottom) = root.split_vertically(h as i32 - cap_h);
        for (i, line) in lines.iter().enumerate() {
            bottom.draw(&Text::new(line.clone(), (20, 6 + i as i32 * line_h), style.clone())).map_err(err)?;
        }
        body = top;
    }
    let rows = fig.panels.len().div_ceil(fig.columns);
    let areas = body.split_evenly((rows, fig.columns));
    for (area, chart) in areas.iter().zip(&fig.panels) {
        draw_chart(area, chart)?;
    }
    Ok(())
}

/// What a legend row shows.
enum Swatch {
    Line { color: Rgb, width: u32, dashed: bool, marker: Marker, alpha: f64 },
    Box { color: Rgb, alpha: f64 },
}

fn legend_rows(chart: &Chart) -> Vec<(String, Swatch)> {
    let mut rows = Vec::new();
    for s in chart.series.iter().filter(|s| !s.name.is_empty()) {
        let swatch = Swatch::Line {
            color: s.color,
            width: s.line_width,
            dashed: s.dashed,
            marker: s.marker,
            alpha: s.alpha.max(0.6),
        };
        rows.push((s.name.clone(), swatch));
    }
    for b in chart.bars.iter().filter(|b| !b.name.is_empty()) {
        rows.push((b.name.clone(), Swatch::Box { color: b.color, alpha: b.alpha }));
    }
    for r in chart.ref_lines.iter().filter(|r| !r.label.is_empty()) {
        let swatch =
            Swatch::Line { color: r.color, width: 2, dashed: true, marker: Marker::None, alpha: 1.0 };
        rows.push((r.label.clone(), swatch));
    }
    rows
}

const SWATCH_W: i32 = 34;

fn draw_marker<DB: DrawingBackend>(
    area: &Area<DB>,
    p: (i32, i32),
    marker: Marker,
    size: u32,
    color: RGBAColor,
) -> Result<(), String> {
    let s = size as i32;
    match marker {
        Marker::None => Ok(()),
        Marker::Circle => area.draw(&Circle::new(p, s, color.filled())).map_err(err),
        Marker::Square => {
            area.draw(&Rectangle::new([(p.0 - s, p.1 - s), (p.0 + s, p.1 + s)], color.filled())).map_err(err)
        }
        Marker::Triangle => area.draw(&TriangleMarker::new(p, s + 1, color.filled())).map_err(err),
        Marker::Cross => area.draw(&Cross::new(p, s, color.stroke_width(2))).map_err(err),
    }
}

/// Draws the legend rows into `area` (its own column); long names are cut with "…".
fn draw_legend<DB: DrawingBackend>(area: &Area<DB>, rows: &[(String, Swatch)]) -> Result<(), String> {
    let style = text_style(LEGEND_PX, RGBColor(0, 0, 0)).pos(Pos::new(HPos::Left, VPos::Center));
    let (w, _) = area.dim_in_pixel();
    let row_h = (LEGEND_PX * 1.7).ceil() as i32;
    let x0 = 8;
    let max_text = w as i32 - x0 - SWATCH_W - 16;
    for (i, (name, swatch)) in rows.iter().enumerate() {
        let y = 14 + i as i32 * row_h;
        match swatch {
            Swatch::Line { color, width, dashed, marker, alpha } => {
                let c = color.with_alpha(*alpha);
                if *width > 0 {
                    let pts = vec![(x0, y), (x0 + SWATCH_W, y)];
                    if *dashed {
                        area.draw(&DashedPathElement::new(pts, 6, 4, c.stroke_width(*width))).map_err(err)?;
                    } else {
                        area.draw(&PathElement::new(pts, c.stroke_width(*width))).map_err(err)?;
                    }
                }
                draw_marker(area, (x0 + SWATCH_W / 2, y), *marker, 4, c)?;
            }
            Swatch::Box { color, alpha } => {
                let rect = [(x0 + 4, y - 7), (x0 + SWATCH_W - 4, y + 7)];
                area.draw(&Rectangle::new(rect, color.with_alpha(*alpha).filled())).map_err(err)?;
            }
        }
        let mut text = name.clone();
        while text.chars().count() > 1 && text_width(area, &text, &style)? as i32 > max_text {
            text.pop();
            while text.ends_with('…') {
                text.pop();
            }
            text = format!("{}…", text.trim_end());
        }
        area.draw(&Text::new(text, (x0 + SWATCH_W + 8, y), style.clone())).map_err(err)?;
    }
    Ok(())
}

/// The ticks of an axis: fixed ones, or computed; with their labels.
fn axis_ticks(axis: &Axis, lo: f64, hi: f64) -> Vec<(f64, String)> {
    match &axis.ticks {
        Some(t) => t.iter().filter(|(v, _)| *v >= lo && *v <= hi).cloned().collect(),
        None => {
            ticks::ticks(axis.scale, lo, hi, axis.integer).into_iter().map(|v| (v, ticks::label(v))).collect()
        }
    }
}

fn draw_chart<DB: DrawingBackend>(area: &Area<DB>, chart: &Chart) -> Result<(), String> {
    let (w, _) = area.dim_in_pixel();
    // Title, wrapped, centred over the whole panel.
    let title_style = text_style(TITLE_PX, RGBColor(0, 0, 0)).pos(Pos::new(HPos::Center, VPos::Top));
    let lines = wrap(area, &chart.title, &title_style, w.saturating_sub(30))?;
    let line_h = (TITLE_PX * 1.3).ceil() as i32;
    for (i, line) in lines.iter().enumerate() {
        area.draw(&Text::new(line.clone(), (w as i32 / 2, 10 + i as i32 * line_h), title_style.clone()))
            .map_err(err)?;
    }
    let (_, body) = area.split_vertically(16 + line_h * lines.len() as i32);

    // Legend column.
    let rows = legend_rows(chart);
    let plot = if chart.legend == Legend::Right && !rows.is_empty() {
        let style = text_style(LEGEND_PX, RGBColor(0, 0, 0));
        let mut widest = 0;
        for (name, _) in &rows {
            widest = widest.max(text_width(&body, name, &style)?);
        }
        let legend_w = (widest as i32 + SWATCH_W + 30).min(w as i32 * 45 / 100);
        let (plot, legend) = body.split_horizontally(w as i32 - legend_w);
        draw_legend(&legend.margin(24, 0, 0, 0), &rows)?;
        plot
    } else {
        body
    };

    let ((x0, x1), (y0, y1)) = chart.ranges().map_err(|e| e.to_string())?;
    let xt = axis_ticks(&chart.x, x0, x1);
    let yt = axis_ticks(&chart.y, y0, y1);
    let xc = AxisCoord { scale: chart.x.scale, lo: x0, hi: x1, ticks: xt.iter().map(|t| t.0).collect() };
    let yc = AxisCoord { scale: chart.y.scale, lo: y0, hi: y1, ticks: yt.iter().map(|t| t.0).collect() };
    draw_plot(&plot, chart, xc, yc, &xt, &yt)
}

/// One drawn axis for plotters: linear or base-10 log mapping of `lo..hi`, bold key points at
/// our ticks (no light points: the mesh draws only the tick grid).
#[derive(Clone, Debug)]
struct AxisCoord {
    scale: Scale,
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
}

impl AxisCoord {
    fn transform(&self, v: f64) -> f64 {
        match self.scale {
            Scale::Linear => v,
            Scale::Log => v.max(f64::MIN_POSITIVE).log10(),
        }
    }
}

impl Ranged for AxisCoord {
    type FormatOption = plotters::coord::ranged1d::DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (a, b) = (self.transform(self.lo), self.transform(self.hi));
        let f = ((self.transform(*value) - a) / (b - a)).clamp(-10.0, 11.0);
        let f = if f.is_finite() { f } else { 0.5 };
        limit.0 + ((limit.1 - limit.0) as f64 * f + 1e-3).floor() as i32
    }

    fn key_points<H: plotters::coord::ranged1d::KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

fn tick_text(ticks: &[(f64, String)], v: f64) -> String {
    ticks
        .iter()
        .find(|(t, _)| (t - v).abs() <= 1e-9 * t.abs().max(1e-300))
        .map(|(_, l)| l.clone())
        .unwrap_or_else(|| ticks::label(v))
}

fn draw_plot<DB: DrawingBackend>(
    area: &Area<DB>,
    chart: &Chart,
    x_spec: AxisCoord,
    y_spec: AxisCoord,
    xt: &[(f64, String)],
    yt: &[(f64, String)],
) -> Result<(), String> {
    let tick_style = text_style(TICK_PX, RGBColor(30, 30, 30));
    let axis_style = text_style(AXIS_PX, RGBColor(0, 0, 0));
    let mut y_tick_w = 0;
    for (_, l) in yt {
        y_tick_w = y_tick_w.max(text_width(area, l, &tick_style)?);
    }
    let mut cc = ChartBuilder::on(area)
        .margin_top(6)
        .margin_right(18)
        .margin_left(6)
        .margin_bottom(6)
        .x_label_area_size((TICK_PX + AXIS_PX * 1.2 + 14.0) as u32)
        .y_label_area_size(y_tick_w + (AXIS_PX * 1.6) as u32 + 16)
        .build_cartesian_2d(x_spec, y_spec)
        .map_err(err)?;
    let xf = |v: &f64| tick_text(xt, *v);
    let yf = |v: &f64| tick_text(yt, *v);
    cc.configure_mesh()
        .x_desc(chart.x.label.as_str())
        .y_desc(chart.y.label.as_str())
        .axis_desc_style(axis_style)
        .label_style(tick_style)
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .x_labels(xt.len().max(1))
        .y_labels(yt.len().max(1))
        .bold_line_style(RGBColor(228, 228, 228))
        .light_line_style(TRANSPARENT)
        .axis_style(RGBColor(60, 60, 60))
        .draw()
        .map_err(err)?;

    let ((x_lo, x_hi), (y_lo, y_hi)) = chart.ranges().map_err(|e| e.to_string())?;
    // On a log axis, values at or below zero are drawn at the axis minimum.
    let cx = |v: f64| if chart.x.scale == Scale::Log && v < x_lo { x_lo } else { v };
    let cy = |v: f64| if chart.y.scale == Scale::Log && v < y_lo { y_lo } else { v };

    for b in &chart.bars {
        let fill = b.color.with_alpha(b.alpha).filled();
        cc.draw_series(
            b.bars.iter().map(|r| Rectangle::new([(cx(r.x0), cy(r.y0)), (cx(r.x1), cy(r.y1))], fill)),
        )
        .map_err(err)?;
        let edge = WHITE.stroke_width(1);
        cc.draw_series(
            b.bars.iter().map(|r| Rectangle::new([(cx(r.x0), cy(r.y0)), (cx(r.x1), cy(r.y1))], edge)),
        )
        .map_err(err)?;
    }

    for r in &chart.ref_lines {
        let pts = match r.orientation {
            Orientation::Vertical => vec![(cx(r.at), y_lo), (cx(r.at), y_hi)],
            Orientation::Horizontal => vec![(x_lo, cy(r.at)), (x_hi, cy(r.at))],
        };
        let style = r.color.with_alpha(0.9).stroke_width(2);
        cc.draw_series(std::iter::once(DashedPathElement::new(pts, 8, 5, style))).map_err(err)?;
    }

    let label_style =
        text_style(POINT_LABEL_PX, RGBColor(40, 40, 40)).pos(Pos::new(HPos::Left, VPos::Bottom));
    for s in &chart.series {
        let pts: Vec<(f64, f64)> = s.drawn_points().into_iter().map(|(x, y)| (cx(x), cy(y))).collect();
        let color = s.color.with_alpha(s.alpha);
        if s.line_width > 0 && pts.len() > 1 {
            let style = color.stroke_width(s.line_width);
            if s.dashed {
                cc.draw_series(std::iter::once(DashedPathElement::new(pts.clone(), 8, 5, style)))
                    .map_err(err)?;
            } else {
                cc.draw_series(std::iter::once(PathElement::new(pts.clone(), style))).map_err(err)?;
            }
        }
        let size = s.marker_size as i32;
        match s.marker {
            Marker::None => {}
            Marker::Circle => {
                cc.draw_series(pts.iter().map(|&p| Circle::new(p, size, color.filled()))).map_err(err)?;
            }
            Marker::Square => {
                let sq =
                    |p| EmptyElement::at(p) + Rectangle::new([(-size, -size), (size, size)], color.filled());
                cc.draw_series(pts.iter().map(|&p| sq(p))).map_err(err)?;
            }
            Marker::Triangle => {
                cc.draw_series(pts.iter().map(|&p| TriangleMarker::new(p, size + 1, color.filled())))
                    .map_err(err)?;
            }
            Marker::Cross => {
                cc.draw_series(pts.iter().map(|&p| Cross::new(p, size, color.stroke_width(2))))
                    .map_err(err)?;
            }
        }
        if !s.labels.is_empty() {
            let offset = size + 3;
            let labelled = pts.iter().zip(&s.labels).filter(|(_, l)| !l.is_empty());
            cc.draw_series(labelled.map(|(&p, l)| {
                EmptyElement::at(p) + Text::new(l.clone(), (offset, -offset), label_style.clone())
            }))
            .map_err(err)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo_chart() -> Chart {
        Chart::new("Demo title", Axis::log("N (views)"), Axis::linear("fraction"))
            .with_series(Series::line("a", vec![(6.0, 0.2), (60.0, 0.8), (492.0, 0.9)], palette(0)))
            .with_series(
                Series::scatter("b", vec![(10.0, 0.5), (100.0, 0.6)], palette(1), Marker::Triangle)
                    .with_labels(vec!["p".into(), "q".into()]),
            )
            .with_ref_line(RefLine::vertical(128.0, "N = 128"))
    }

    #[test]
    fn jitter_is_deterministic_bounded_and_varied() {
        let j = Jitter { dx: 0.3, dy: 0.0, seed: 7 };
        let s = Series::scatter("s", vec![(1.0, 2.0); 50], palette(0), Marker::Circle).with_jitter(j);
        let a = s.drawn_points();
        assert_eq!(a, s.drawn_points());
        assert!(a.iter().all(|&(x, y)| (x - 1.0).abs() <= 0.3 && y == 2.0));
        let spread = a.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max)
            - a.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        assert!(spread > 0.3, "jitter should spread points, spread {spread}");
        let other = Series { jitter: Some(Jitter { seed: 8, ..j }), ..s.clone() }.drawn_points();
        assert_ne!(a, other);
    }

    #[test]
    fn histogram_counts_per_bin() {
        let h = BarSeries::histogram("h", palette(0), &[0.5, 1.0, 1.9, 2.0, 7.2, f64::NAN], 0.0, 2.0);
        let got: Vec<(f64, f64, f64)> = h.bars.iter().map(|b| (b.x0, b.x1, b.y1)).collect();
        assert_eq!(got, vec![(0.0, 2.0, 3.0), (2.0, 4.0, 1.0), (6.0, 8.0, 1.0)]);
    }

    #[test]
    fn ranges_cover_data_and_reference_lines() {
        let ((x0, x1), (y0, y1)) = demo_chart().ranges().unwrap();
        assert!(x0 < 6.0 && x1 > 492.0 && x0 > 0.0);
        assert!(y0 < 0.2 && y1 > 0.9);
        let c = Chart::new("t", Axis::linear("x"), Axis::linear("y"))
            .with_ref_line(RefLine::horizontal(128.0, "h"));
        assert!(c.ranges().unwrap().1 .1 > 128.0);
        let c = Chart::new("t", Axis::log("x"), Axis::linear("y"));
        assert!(matches!(c.ranges(), Err(PlotError::InvalidChart { .. })));
    }

    #[test]
    fn invalid_charts_are_rejected_with_the_reason() {
        let bad = demo_chart().with_series(Series::line("nan", vec![(1.0, f64::NAN)], palette(2)));
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("Demo title") && e.contains("'nan'") && e.contains("not finite"), "{e}");
        let bad =
            demo_chart().with_series(Series::line("l", vec![(1.0, 1.0)], palette(2)).with_labels(vec![]));
        assert!(bad.validate().is_ok());
        let bad = demo_chart().with_series(
            Series::line("l", vec![(1.0, 1.0)], palette(2)).with_labels(vec!["a".into(), "b".into()]),
        );
        assert!(bad.validate().unwrap_err().to_string().contains("2 labels for 1 points"));
        let mut bad = demo_chart();
        bad.x.range = Some((0.0, 10.0));
        assert!(bad.validate().unwrap_err().to_string().contains("x range"));
    }

    #[test]
    fn png_and_svg_have_the_same_content_and_are_deterministic() {
        let fig = Figure::single(demo_chart()).with_caption("A caption under the panel");
        let png = fig.to_png().unwrap();
        assert_eq!(png, fig.to_png().unwrap());
        let img = image::load_from_memory(&png).unwrap();
        assert_eq!((img.width(), img.height()), DEFAULT_SIZE);
        // Not blank: some dark (text/axis) and some coloured (series) pixels.
        let rgb = img.to_rgb8();
        assert!(rgb.pixels().filter(|p| p.0.iter().all(|&c| c < 80)).count() > 500);
        assert!(rgb.pixels().any(|p| p.0 == [0, 114, 178]));
        let svg = fig.to_svg().unwrap();
        assert_eq!(svg, fig.to_svg().unwrap());
        for text in [
            "Demo title",
            "N (views)",
            "fraction",
            "N = 128",
            "A caption under the panel",
            ">\np\n<",
            ">\nq\n<",
        ] {
            assert!(svg.contains(text), "SVG lacks {text}");
        }
        assert!(svg.contains("width=\"1000\"") && svg.contains("height=\"650\""));
    }

    #[test]
    fn write_names_the_file_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no/such/dir");
        let e = Figure::single(demo_chart()).write(&missing, "x").unwrap_err().to_string();
        assert!(e.contains("x.png"), "{e}");
        let [png, svg] = Figure::single(demo_chart()).write(dir.path(), "x").unwrap();
        assert!(png.ends_with("x.png") && svg.ends_with("x.svg") && png.exists() && svg.exists());
    }
}
