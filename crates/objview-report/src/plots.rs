//! The report's figures, per view space, as PNG and SVG through `objview_plot`:
//! - `nsc_vs_views_<space>`: mean NSC@τ against the number of views (start view included), one
//!   line per method (finite-plan methods: one per budget); an episode that ended before v views
//!   contributes its last value at v (carried forward), so a curve never mixes fewer episodes in;
//!   the x axis turns logarithmic past [`LOG_VIEWS_ABOVE`] views (oracle runs, the 129-view cap);
//! - `path_cost_vs_nsc_<space>`: mean path cost against mean NSC@τ, one point per method and
//!   budget setting, labelled with the setting, with the Table 3 quality threshold drawn.
//!
//! Each method keeps its colour (and, past the eight palette colours, its dash or marker) in
//! every figure. Every plotted number is returned for `figures.json`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use objview_episode::ExecutionMode;
use objview_plot::{palette, Axis, Chart, Figure, Marker, RefLine, Rgb, Series};
use serde::Serialize;
use serde_json::{json, Value};

use crate::aggregate::{tau_value, Aggregate};
use crate::format::file_safe;
use crate::load::Episode;
use crate::select::Setting;
use crate::ReportError;

/// The NSC-vs-views x axis is logarithmic when some curve goes past this many views.
pub const LOG_VIEWS_ABOVE: usize = 40;

/// Markers cycled for methods past the palette (scatter) and for budgets (curves).
const MARKERS: [Marker; 4] = [Marker::Circle, Marker::Square, Marker::Triangle, Marker::Cross];

/// The drawing style of a method, fixed by its index in the report's sorted method list.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MethodStyle {
    /// Palette colour.
    pub color: Rgb,
    /// Lines of methods 8–15, 24–31, … are dashed.
    pub dashed: bool,
    /// Scatter marker: circles for the first eight methods, then squares, …
    pub marker: Marker,
}

impl MethodStyle {
    /// The style of the `i`-th method.
    pub fn of(i: usize) -> MethodStyle {
        let round = i / objview_plot::PALETTE.len();
        MethodStyle { color: palette(i), dashed: round % 2 == 1, marker: MARKERS[round % MARKERS.len()] }
    }
}

/// One point of an NSC curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CurvePoint {
    /// Number of views (start view included).
    pub views: usize,
    /// Mean NSC@τ over the contributing episodes.
    pub nsc: f64,
    /// Contributing episodes.
    pub episodes: usize,
    /// Of those, episodes that had ended before this many views (their last value is used).
    pub carried: usize,
}

/// One line of `nsc_vs_views_<space>`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Curve {
    /// View space.
    pub view_space: String,
    /// Method name.
    pub method: String,
    /// The budget label for finite-plan methods (one curve per budget); `None` for iterative.
    pub budget: Option<String>,
    /// Episodes of the curve.
    pub episodes: usize,
    /// Points at views 1, 2, … (where some episode contributes).
    pub points: Vec<CurvePoint>,
}

impl Curve {
    /// Legend text: `rse (n = 12)`, `random-tsp, budget 30 (n = 12)`.
    pub fn label(&self) -> String {
        match &self.budget {
            None => format!("{} (n = {})", self.method, self.episodes),
            Some(b) => format!("{}, budget {b} (n = {})", self.method, self.episodes),
        }
    }
}

/// One episode's NSC@τ by number of views: (first view count, values from it on, gaps carried).
fn episode_series(e: &Episode, tau: &str) -> Option<(usize, Vec<f64>)> {
    let first = e.result.steps.first()?.metrics.views;
    let mut values: Vec<f64> = Vec::new();
    for s in &e.result.steps {
        let v = s.metrics.views;
        if v < first + values.len() {
            // Not increasing (never expected): the latest value at that count wins.
            if let Some(slot) = v.checked_sub(first).and_then(|i| values.get_mut(i)) {
                *slot = tau_value(&s.metrics.nsc, tau);
            }
            continue;
        }
        let carry = values.last().copied();
        while first + values.len() < v {
            values.push(carry.unwrap_or(f64::NAN));
        }
        values.push(tau_value(&s.metrics.nsc, tau));
    }
    Some((first, values))
}

/// The curves of every (view space, method[, budget]), in that order.
pub fn nsc_curves(episodes: &[Episode], tau: &str) -> Vec<Curve> {
    let mut groups: BTreeMap<(String, String, Option<String>), Vec<&Episode>> = BTreeMap::new();
    for e in episodes {
        let r = &e.result;
        let budget = (r.execution_mode != ExecutionMode::Iterative).then(|| r.budget.to_string());
        groups.entry((r.view_space.clone(), r.method.clone(), budget)).or_default().push(e);
    }
    let mut curves = Vec::new();
    for ((view_space, method, budget), members) in groups {
        let series: Vec<(usize, Vec<f64>)> = members.iter().filter_map(|e| episode_series(e, tau)).collect();
        let max_views = series.iter().map(|(f, v)| f + v.len()).max().unwrap_or(1).saturating_sub(1);
        let mut points = Vec::new();
        for views in 1..=max_views {
            let mut sum = 0.0;
            let (mut n, mut carried) = (0, 0);
            for (first, values) in &series {
                let Some(&last) = values.last() else { continue };
                if views < *first {
                    continue;
                }
                let value = match values.get(views - first) {
                    Some(&v) => v,
                    None => {
                        carried += 1;
                        last
                    }
                };
                if value.is_finite() {
                    sum += value;
                    n += 1;
                }
            }
            if n > 0 {
                points.push(CurvePoint { views, nsc: sum / n as f64, episodes: n, carried });
            }
        }
        curves.push(Curve { view_space, method, budget, episodes: series.len(), points });
    }
    curves
}

/// One point of `path_cost_vs_nsc_<space>`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TradeoffPoint {
    /// View space.
    pub view_space: String,
    /// Method name.
    pub method: String,
    /// Budget setting (the point label).
    pub setting: Setting,
    /// Episodes.
    pub n: usize,
    /// Mean NSC@τ (x).
    pub nsc: f64,
    /// Mean path cost (y).
    pub path_cost: f64,
}

/// The points of the trade-off figures, from the aggregates (same order).
pub fn tradeoff_points(aggregates: &[Aggregate]) -> Vec<TradeoffPoint> {
    aggregates
        .iter()
        .map(|a| TradeoffPoint {
            view_space: a.view_space.clone(),
            method: a.method.clone(),
            setting: a.setting,
            n: a.n,
            nsc: a.nsc.mean,
            path_cost: a.path_cost.mean,
        })
        .collect()
}

/// What the figures need besides the data.
#[derive(Clone, Debug)]
pub struct FigureContext<'a> {
    /// τ key of the NSC axis.
    pub tau: &'a str,
    /// Table 3's quality threshold (a reference line).
    pub threshold: f64,
    /// Every method of the report, sorted: a method's index picks its style.
    pub methods: &'a [String],
}

impl FigureContext<'_> {
    fn style(&self, method: &str) -> MethodStyle {
        MethodStyle::of(self.methods.iter().position(|m| m == method).unwrap_or(0))
    }
}

/// A figure written: its stem and files.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FigureFiles {
    /// File stem (`nsc_vs_views_whole`).
    pub figure: String,
    /// View space drawn.
    pub view_space: String,
    /// PNG file name.
    pub png: String,
    /// SVG file name.
    pub svg: String,
}

/// File stems of the two figures of `view_space`, made file-safe and distinct from those of
/// spaces already in `taken`.
fn stems(view_space: &str, taken: &mut BTreeSet<String>) -> (String, String) {
    let base = file_safe(view_space);
    let mut name = base.clone();
    let mut k = 2;
    while !taken.insert(name.clone()) {
        name = format!("{base}_{k}");
        k += 1;
    }
    (format!("nsc_vs_views_{name}"), format!("path_cost_vs_nsc_{name}"))
}

/// Draws both figures of every view space into `out_dir` (which must exist). Returns the files
/// (PNG then SVG, per figure), the list for `figures.json`, and its `data` object.
pub fn write_figures(
    out_dir: &Path,
    curves: &[Curve],
    points: &[TradeoffPoint],
    ctx: &FigureContext,
) -> Result<(Vec<PathBuf>, Vec<FigureFiles>, Value), ReportError> {
    let spaces: BTreeSet<&str> = curves
        .iter()
        .map(|c| c.view_space.as_str())
        .chain(points.iter().map(|p| p.view_space.as_str()))
        .collect();
    let mut files = Vec::new();
    let mut listed = Vec::new();
    let mut data = serde_json::Map::new();
    let mut taken = BTreeSet::new();
    let tau = ctx.tau;
    for space in spaces {
        let (curve_stem, trade_stem) = stems(space, &mut taken);

        // NSC vs #views.
        let here: Vec<&Curve> =
            curves.iter().filter(|c| c.view_space == space && !c.points.is_empty()).collect();
        if !here.is_empty() {
            // Long runs (oracle, the cap) would squeeze the informative first views: log x then.
            let max_views = here.iter().flat_map(|c| c.points.iter().map(|p| p.views)).max().unwrap_or(1);
            let log_x = max_views > LOG_VIEWS_ABOVE;
            let x_label = "#views (start view included)";
            let x_axis = if log_x {
                Axis::log(format!("{x_label}, log scale"))
            } else {
                Axis::linear(x_label).with_integer_ticks()
            };
            let mut chart = Chart::new(
                format!("Mean NSC@{tau} vs number of views, view space {space}"),
                x_axis,
                Axis::linear(format!("NSC@{tau} (mean over episodes)")),
            );
            let mut budget_index: BTreeMap<&str, usize> = BTreeMap::new();
            for c in &here {
                let style = ctx.style(&c.method);
                let pts: Vec<(f64, f64)> = c.points.iter().map(|p| (p.views as f64, p.nsc)).collect();
                let mut s = Series::line(c.label(), pts, style.color);
                if style.dashed {
                    s = s.with_dashes();
                }
                if c.budget.is_some() {
                    let j = budget_index.entry(c.method.as_str()).or_insert(0);
                    s = s.with_marker(MARKERS[*j % MARKERS.len()], 3);
                    *j += 1;
                }
                chart = chart.with_series(s);
            }
            let caption = format!(
                "Mean over episodes of the per-step NSC@{tau} at each view count. An episode that ended \
                 before v views contributes its last value at v (carried forward). Finite-plan methods \
                 have one curve per budget (marked)."
            );
            let fig = Figure::single(chart).with_caption(caption.clone());
            files.extend(fig.write(out_dir, &curve_stem)?);
            listed.push(figure_files(&curve_stem, space));
            data.insert(
                curve_stem.clone(),
                json!({
                    "view_space": space,
                    "x": "views (start view included)",
                    "x_scale": if log_x { "log" } else { "linear" },
                    "y": format!("mean NSC@{tau}"),
                    "carried_forward": "an episode that ended before v views contributes its last value at v; `carried` counts them",
                    "caption": caption,
                    "curves": here.iter().map(|c| json!({
                        "method": c.method,
                        "budget": c.budget,
                        "label": c.label(),
                        "color": ctx.style(&c.method).color.hex(),
                        "episodes": c.episodes,
                        "columns": ["views", "nsc", "episodes", "carried"],
                        "points": c.points.iter().map(|p| json!([p.views, p.nsc, p.episodes, p.carried])).collect::<Vec<_>>(),
                    })).collect::<Vec<_>>(),
                }),
            );
        }

        // Path cost vs NSC.
        let pts: Vec<&TradeoffPoint> = points.iter().filter(|p| p.view_space == space).collect();
        if !pts.is_empty() {
            let mut chart = Chart::new(
                format!("Path cost vs NSC@{tau} per method and budget setting, view space {space}"),
                Axis::linear(format!("NSC@{tau} (mean over episodes)")),
                Axis::linear("path cost (mean, normalized object units)"),
            );
            let methods: BTreeSet<&str> = pts.iter().map(|p| p.method.as_str()).collect();
            let mut json_methods = Vec::new();
            for m in ctx.methods.iter().filter(|m| methods.contains(m.as_str())) {
                let mine: Vec<&&TradeoffPoint> = pts.iter().filter(|p| &p.method == m).collect();
                let style = ctx.style(m);
                let xy: Vec<(f64, f64)> = mine.iter().map(|p| (p.nsc, p.path_cost)).collect();
                let labels: Vec<String> = mine.iter().map(|p| p.setting.short()).collect();
                chart = chart.with_series(
                    Series::scatter(m.clone(), xy, style.color, style.marker).with_labels(labels),
                );
                json_methods.push(json!({
                    "method": m,
                    "color": style.color.hex(),
                    "columns": ["setting", "nsc", "path_cost", "episodes"],
                    "points": mine.iter().map(|p| json!([p.setting, p.nsc, p.path_cost, p.n])).collect::<Vec<_>>(),
                }));
            }
            let threshold = ctx.threshold;
            chart = chart.with_ref_line(RefLine::vertical(
                threshold,
                format!("NSC@{tau} = {threshold}: Table 3 quality threshold"),
            ));
            let caption = format!(
                "One point per method and budget setting (labelled K=k or Auto): means over the \
                 setting's episodes of the path cost and NSC@{tau} at the setting's checkpoint."
            );
            let fig = Figure::single(chart).with_caption(caption.clone());
            files.extend(fig.write(out_dir, &trade_stem)?);
            listed.push(figure_files(&trade_stem, space));
            data.insert(
                trade_stem.clone(),
                json!({
                    "view_space": space,
                    "x": format!("mean NSC@{tau}"),
                    "y": "mean path cost",
                    "threshold": threshold,
                    "caption": caption,
                    "methods": json_methods,
                }),
            );
        }
    }
    Ok((files, listed, Value::Object(data)))
}

fn figure_files(stem: &str, space: &str) -> FigureFiles {
    FigureFiles {
        figure: stem.to_string(),
        view_space: space.to_string(),
        png: format!("{stem}.png"),
        svg: format!("{stem}.svg"),
    }
}
