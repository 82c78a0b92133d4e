//! Figure 2 of the paper (difficulty statistics of a pool) from `objview annotate` results:
//!
//! - `fig2a_saturation`: normalized saturation curves Y(N)/|S_gt| of representative objects,
//!   chosen at the d_sat quantiles of the pool and ordered by d_sat, with the 128-view protocol;
//! - `fig2a_marginal_gain`: their marginal gain ΔY_m/ΔN/|S_gt| between consecutive grid sizes
//!   and the pool mean, on a log axis, with the protocol and the saturation tolerance;
//! - `fig2b_dplan_hist`: the d_plan histogram in the width-5 buckets of SPEC §6 (and per value
//!   when the range is small), main pool and slow-saturation objects stacked;
//! - `fig2c_dsat_vs_dplan`: d_sat against d_plan, slow-saturation objects marked, the
//!   slow-saturation threshold drawn, Pearson and Spearman correlations in the title;
//!
//! each as PNG and SVG, plus `figures.json`: provenance, settings, the files, and every number
//! plotted, so a figure can be checked or redrawn without rerunning anything. The data steps
//! (representative choice, gains, buckets, correlations) are separate public functions so that
//! they are tested on their own and reused by `objview pool stats`-like reports.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use objview_dataset::annotate::{Annotation, PLANNING_VIEWS};
use objview_difficulty::{PLATEAU_STEP, PLATEAU_TOL, SLOW_SATURATION_THRESHOLD};
use serde::Serialize;
use serde_json::{json, Value};

use crate::chart::{
    palette, Axis, Bar, BarSeries, Chart, Figure, Jitter, Legend, Marker, RefLine, Series, INK, PALETTE,
};
use crate::{stats, PlotError, VERSION};

/// File stems written by [`figure2`], in writing order.
pub const FIGURE2_STEMS: [&str; 4] =
    ["fig2a_saturation", "fig2a_marginal_gain", "fig2b_dplan_hist", "fig2c_dsat_vs_dplan"];

/// Name of the data/provenance file written next to the figures.
pub const FIGURES_JSON: &str = "figures.json";

/// Settings of Figure 2. Thresholds that the annotation itself used (slow-saturation threshold,
/// plateau tolerance, voxel size) are read from the annotations' `settings`, not set here.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Figure2Settings {
    /// Number of representative objects in panel (a).
    pub representatives: usize,
    /// The planning view-set size marked in panel (a) (SPEC §4: tammes-128).
    pub protocol_views: usize,
    /// d_plan bucket width (SPEC §6: 5).
    pub bucket_width: usize,
    /// Panel (b) adds per-value bars when max − min d_plan + 1 is at most this.
    pub per_value_max: usize,
    /// Horizontal jitter of panel (c) points, ± d_plan units.
    pub jitter: f64,
    /// Seed of that jitter.
    pub jitter_seed: u64,
    /// Panel (c) labels every point with its uid when there are at most this many points.
    pub label_points_max: usize,
}

impl Default for Figure2Settings {
    fn default() -> Self {
        Figure2Settings {
            representatives: 6,
            protocol_views: PLANNING_VIEWS,
            bucket_width: 5,
            per_value_max: 80,
            jitter: 0.25,
            jitter_seed: 0,
            label_points_max: 12,
        }
    }
}

impl Figure2Settings {
    /// Checks every setting's range; an error names the first bad setting.
    pub fn validate(&self) -> Result<(), PlotError> {
        let bad =
            |name: &'static str, reason: &str| Err(PlotError::InvalidSetting { name, reason: reason.into() });
        if self.representatives == 0 || self.representatives > PALETTE.len() {
            return bad(
                "representatives",
                &format!("must be in 1..={} (one palette colour each)", PALETTE.len()),
            );
        }
        if self.protocol_views == 0 {
            return bad("protocol_views", "must be positive");
        }
        if self.bucket_width == 0 {
            return bad("bucket_width", "must be positive");
        }
        if !(self.jitter.is_finite() && (0.0..0.5).contains(&self.jitter)) {
            return bad("jitter", "must be in [0, 0.5) so that neighbouring d_plan values stay apart");
        }
        Ok(())
    }
}

/// What [`figure2`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure2Output {
    /// The PNG and SVG files, in [`FIGURE2_STEMS`] order (PNG before SVG).
    pub files: Vec<PathBuf>,
    /// `figures.json`.
    pub figures_json: PathBuf,
}

// ------------------------------------------------------------------------------ data steps

/// The representatives of panel (a): objects sorted by (d_sat, N*, uid), the one at rank
/// round(i·(n−1)/(k−1)) for i = 0..k (the median for k = 1; all objects when n ≤ k). Returns
/// indices into `annotations`, in ascending d_sat order.
pub fn select_representatives(annotations: &[Annotation], k: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..annotations.len()).collect();
    order.sort_by(|&a, &b| {
        let (x, y) = (&annotations[a], &annotations[b]);
        x.d_sat.cmp(&y.d_sat).then(x.n_star.total_cmp(&y.n_star)).then(x.uid.cmp(&y.uid))
    });
    let n = order.len();
    if n <= k {
        return order;
    }
    if k == 1 {
        return vec![order[(n - 1) / 2]];
    }
    (0..k).map(|i| order[((i * (n - 1)) as f64 / (k - 1) as f64).round() as usize]).collect()
}

/// Y(N)/|S_gt| over the annotation's grid (the raw curve, not the monotone one).
pub fn normalized_curve(a: &Annotation) -> Vec<(f64, f64)> {
    let s = a.surface_voxels as f64;
    a.curve.iter().map(|&[n, y]| (n as f64, y as f64 / s)).collect()
}

/// Marginal gain between two consecutive grid sizes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Gain {
    /// Smaller grid size N of the interval (view count).
    pub n0: usize,
    /// Larger grid size N of the interval (view count).
    pub n1: usize,
    /// Where it is plotted: (n0 + n1) / 2.
    pub x: f64,
    /// (Y_m(n1) − Y_m(n0)) / (n1 − n0) / |S_gt|, Y_m the running maximum (so ≥ 0).
    pub gain: f64,
}

/// The marginal gain of the monotone curve Y_m (running maximum of Y, SPEC §4) per interval
/// of the grid, as a fraction of |S_gt| per added view.
pub fn marginal_gain(a: &Annotation) -> Vec<Gain> {
    let s = a.surface_voxels as f64;
    let mut best = 0usize;
    let monotone: Vec<(usize, usize)> = a
        .curve
        .iter()
        .map(|&[n, y]| {
            best = best.max(y);
            (n, best)
        })
        .collect();
    monotone
        .windows(2)
        .map(|w| {
            let ((n0, y0), (n1, y1)) = (w[0], w[1]);
            Gain { n0, n1, x: (n0 + n1) as f64 / 2.0, gain: (y1 - y0) as f64 / (n1 - n0) as f64 / s }
        })
        .collect()
}

/// One d_plan bucket with its counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Bucket {
    /// Smallest and largest d_plan of the bucket (inclusive).
    pub lo: usize,
    /// Largest d_plan of the bucket (inclusive).
    pub hi: usize,
    /// Main-pool objects (d_sat ≤ threshold).
    pub main: usize,
    /// Slow-saturation objects.
    pub slow: usize,
}

impl Bucket {
    /// `1–5`, or `7` for a one-value bucket.
    pub fn label(&self) -> String {
        if self.lo == self.hi {
            self.lo.to_string()
        } else {
            format!("{}–{}", self.lo, self.hi)
        }
    }
}

/// The bucket of `d` for width `w` (SPEC §6: 1–5, 6–10, …): (lo, hi). d = 0 (an object with
/// nothing to cover) gets the bucket 0–0 of its own.
pub fn bucket_of(d: usize, w: usize) -> (usize, usize) {
    if d == 0 {
        return (0, 0);
    }
    let lo = (d - 1) / w * w + 1;
    (lo, lo + w - 1)
}

/// Counts per bucket of width `w` of (d_plan, slow_saturation) pairs, every bucket from the
/// lowest to the highest non-empty one (empty ones included, so the tail shows its gaps).
/// `w = 1` gives the per-value counts.
pub fn dplan_buckets(values: &[(usize, bool)], w: usize) -> Vec<Bucket> {
    let mut counts = BTreeMap::<usize, (usize, usize, usize)>::new();
    for &(d, slow) in values {
        let (lo, hi) = bucket_of(d, w);
        let e = counts.entry(lo).or_insert((hi, 0, 0));
        if slow {
            e.2 += 1;
        } else {
            e.1 += 1;
        }
    }
    let (Some(&first), Some(&last)) = (counts.keys().next(), counts.keys().next_back()) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut lo = first;
    loop {
        let (hi, main, slow) = counts.get(&lo).copied().unwrap_or((bucket_of(lo, w).1, 0, 0));
        out.push(Bucket { lo, hi, main, slow });
        if lo >= last {
            break;
        }
        lo = hi + 1;
    }
    out
}

// ------------------------------------------------------------------------- settings in data

/// The value at `path` inside every annotation's `settings`: `Ok(Some)` when all agree,
/// `Ok(None)` when none has it, an error naming two disagreeing objects otherwise.
fn common_setting(annotations: &[Annotation], path: &[&str]) -> Result<Option<Value>, PlotError> {
    let get = |a: &Annotation| path.iter().try_fold(&a.settings, |v, k| v.get(k)).cloned();
    let first = &annotations[0];
    let v0 = get(first);
    for a in &annotations[1..] {
        let v = get(a);
        if v != v0 {
            let show = |v: &Option<Value>| v.as_ref().map_or("nothing".to_string(), Value::to_string);
            return Err(PlotError::InconsistentSettings {
                key: path.join("."),
                first_uid: first.uid.clone(),
                first: show(&v0),
                other_uid: a.uid.clone(),
                other: show(&v),
            });
        }
    }
    Ok(v0)
}

/// A numeric setting taken from the annotations, or `default` when they do not record it.
struct Taken {
    value: f64,
    from_annotations: bool,
}

fn numeric_setting(annotations: &[Annotation], path: &[&str], default: f64) -> Result<Taken, PlotError> {
    match common_setting(annotations, path)? {
        None => Ok(Taken { value: default, from_annotations: false }),
        Some(v) => match v.as_f64() {
            Some(value) if value.is_finite() => Ok(Taken { value, from_annotations: true }),
            _ => Err(PlotError::BadAnnotation {
                uid: annotations[0].uid.clone(),
                reason: format!("setting {} is {v}, not a number", path.join(".")),
            }),
        },
    }
}

impl Taken {
    fn json(&self) -> Value {
        json!({"value": self.value, "source": if self.from_annotations { "annotations" } else { "default" }})
    }
}

/// Checks what the figures rely on: a non-empty curve on strictly increasing N, |S_gt| > 0,
/// the same grid for every object.
fn check_annotations(annotations: &[Annotation]) -> Result<(), PlotError> {
    let first = annotations.first().ok_or(PlotError::NoAnnotations)?;
    for a in annotations {
        let bad = |reason: String| Err(PlotError::BadAnnotation { uid: a.uid.clone(), reason });
        if a.surface_voxels == 0 {
            return bad("surface_voxels is 0 (no ground-truth surface)".into());
        }
        if a.curve.len() < 2 {
            return bad(format!("saturation curve has {} points, at least 2 are needed", a.curve.len()));
        }
        if a.curve.windows(2).any(|w| w[1][0] <= w[0][0]) {
            return bad("saturation curve N values are not strictly increasing".into());
        }
        if a.curve.iter().any(|p| p[1] > a.surface_voxels) {
            return bad("saturation curve exceeds surface_voxels".into());
        }
        if a.curve.iter().map(|p| p[0]).ne(first.curve.iter().map(|p| p[0])) {
            return bad(format!("saturation grid differs from that of '{}'", first.uid));
        }
    }
    Ok(())
}

// ------------------------------------------------------------------------------- the figure

fn fmt_corr(v: Option<f64>) -> String {
    v.map_or("undefined".to_string(), |r| format!("{r:.2}"))
}

fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// Draws Figure 2 of `annotations` into `out_dir` (created if missing): the files of
/// [`FIGURE2_STEMS`] as PNG and SVG, and `figures.json`. `provenance` (a JSON object: tool,
/// version, command, inputs, …) heads `figures.json`. Same inputs give byte-identical files.
pub fn figure2(
    annotations: &[Annotation],
    out_dir: &Path,
    settings: &Figure2Settings,
    provenance: &Value,
) -> Result<Figure2Output, PlotError> {
    settings.validate()?;
    check_annotations(annotations)?;
    let resolution = numeric_setting(annotations, &["resolution"], f64::NAN)?;
    let threshold = numeric_setting(
        annotations,
        &["saturation", "slow_saturation_threshold"],
        SLOW_SATURATION_THRESHOLD as f64,
    )?;
    let plateau_tol = numeric_setting(annotations, &["saturation", "plateau_tol"], PLATEAU_TOL)?;
    let plateau_step = numeric_setting(annotations, &["saturation", "plateau_step"], PLATEAU_STEP)?;
    std::fs::create_dir_all(out_dir).map_err(|e| PlotError::io(out_dir, e))?;

    let n = annotations.len();
    let protocol = settings.protocol_views as f64;
    let protocol_label =
        format!("N = {}: planning view set (tammes-{})", settings.protocol_views, settings.protocol_views);
    let n_axis = "view-set size N (views, tammes-N)";
    let s_gt = if resolution.from_annotations {
        format!("|S_gt| = surface voxels at r = {}", resolution.value)
    } else {
        "|S_gt| = surface voxels".to_string()
    };
    let mut files = Vec::new();
    let mut data = serde_json::Map::new();

    // (a) saturation curves of the representatives.
    let reps = select_representatives(annotations, settings.representatives);
    let mut sorted_d_sat: Vec<usize> = annotations.iter().map(|a| a.d_sat).collect();
    sorted_d_sat.sort_unstable();
    let rep_name = |a: &Annotation| format!("{} (d_sat={})", a.uid, a.d_sat);
    let mut chart = Chart::new(
        format!("(a) Observation saturation: {} representative objects of {n}, ordered by d_sat", reps.len()),
        Axis::log(n_axis),
        Axis::linear("observed surface fraction Y(N) / |S_gt|"),
    );
    let mut rep_json = Vec::new();
    for (i, &k) in reps.iter().enumerate() {
        let a = &annotations[k];
        let pts = normalized_curve(a);
        chart = chart
            .with_series(Series::line(rep_name(a), pts.clone(), palette(i)).with_marker(Marker::Circle, 3));
        let rank = sorted_d_sat.partition_point(|&d| d < a.d_sat);
        rep_json.push(json!({
            "uid": a.uid, "d_sat": a.d_sat, "n_star": a.n_star, "r_vis": a.r_vis,
            "slow_saturation": a.slow_saturation, "surface_voxels": a.surface_voxels,
            "d_sat_rank": rank, "color": palette(i).hex(),
            "curve": pts.iter().map(|&(x, y)| json!([x, y])).collect::<Vec<_>>(),
        }));
    }
    chart = chart.with_ref_line(RefLine::vertical(protocol, protocol_label.clone()));
    let fig = Figure::single(chart).with_caption(format!(
        "Raw Y(N) / |S_gt| over the saturation grid ({s_gt}). Representatives: the objects at evenly \
         spaced ranks of the pool sorted by (d_sat, N*, uid), from the lowest to the highest d_sat."
    ));
    files.extend(fig.write(out_dir, FIGURE2_STEMS[0])?);
    data.insert(
        FIGURE2_STEMS[0].into(),
        json!({"y": "Y(N)/|S_gt| (raw curve)", "protocol_views": settings.protocol_views, "representatives": rep_json}),
    );

    // (a) marginal gain: representatives and pool mean.
    let gains: Vec<Vec<Gain>> = annotations.iter().map(marginal_gain).collect();
    let intervals = gains[0].len();
    let mean: Vec<Gain> = (0..intervals)
        .map(|j| Gain { gain: gains.iter().map(|g| g[j].gain).sum::<f64>() / n as f64, ..gains[0][j] })
        .collect();
    let min_positive = gains
        .iter()
        .flatten()
        .chain(&mean)
        .map(|g| g.gain)
        .filter(|&g| g > 0.0)
        .fold(f64::INFINITY, f64::min);
    // One decade below the decade of the smallest positive gain, so that "zero" stays apart from
    // every real gain.
    let floor_exp = if min_positive.is_finite() { min_positive.log10().floor() as i32 - 1 } else { -6 };
    let floor: f64 = format!("1e{floor_exp}").parse().unwrap_or(1e-6);
    let floored =
        |g: &[Gain]| g.iter().map(|g| (g.x, if g.gain > 0.0 { g.gain } else { floor })).collect::<Vec<_>>();
    let tolerance = plateau_tol.value / plateau_step.value;
    let mut chart = Chart::new(
        "(a) Marginal gain of the monotone saturation curve per added view",
        Axis::log(n_axis),
        Axis::log("marginal gain ΔY_m/ΔN / |S_gt| (fraction per view)"),
    );
    for (i, &k) in reps.iter().enumerate() {
        let s = Series::line(rep_name(&annotations[k]), floored(&gains[k]), palette(i));
        chart = chart.with_series(s.with_width(1).with_marker(Marker::Circle, 2).with_alpha(0.75));
    }
    chart = chart
        .with_series(Series::line(format!("pool mean (n = {n})"), floored(&mean), INK).with_width(3))
        .with_ref_line(RefLine::vertical(protocol, protocol_label.clone()))
        .with_ref_line(
            RefLine::horizontal(
                tolerance,
                format!("saturation tolerance {}·|S_gt| per {} views", plateau_tol.value, plateau_step.value),
            )
            .with_color(palette(6)),
        );
    let fig = Figure::single(chart).with_caption(format!(
        "Gain between consecutive grid sizes N_i < N_(i+1), plotted at (N_i + N_(i+1))/2, of the running \
         maximum Y_m of Y ({s_gt}). Zero gains are drawn at {floor:e}, the floor of the axis."
    ));
    files.extend(fig.write(out_dir, FIGURE2_STEMS[1])?);
    let gain_json = |g: &[Gain]| g.iter().map(|g| json!([g.n0, g.n1, g.x, g.gain])).collect::<Vec<_>>();
    data.insert(
        FIGURE2_STEMS[1].into(),
        json!({
            "columns": ["n0", "n1", "x", "gain"],
            "floor": floor,
            "tolerance_per_view": tolerance,
            "pool_mean": gain_json(&mean),
            "representatives": reps.iter().map(|&k| json!({"uid": annotations[k].uid, "gains": gain_json(&gains[k])})).collect::<Vec<_>>(),
        }),
    );

    // (b) d_plan histogram.
    let thr = threshold.value;
    let with_plan: Vec<&Annotation> = annotations.iter().filter(|a| a.d_plan.is_some()).collect();
    let without: Vec<&Annotation> = annotations.iter().filter(|a| a.d_plan.is_none()).collect();
    let pairs: Vec<(usize, bool)> =
        with_plan.iter().filter_map(|a| a.d_plan.map(|d| (d, a.slow_saturation))).collect();
    let n_slow = pairs.iter().filter(|p| p.1).count();
    let n_main = pairs.len() - n_slow;
    let main_name = format!("main pool, d_sat ≤ {thr} (n = {n_main})");
    let slow_name = format!("slow saturation, d_sat > {thr} (n = {n_slow})");
    let buckets = dplan_buckets(&pairs, settings.bucket_width);
    let per_value = dplan_buckets(&pairs, 1);
    let show_per_value = !per_value.is_empty() && per_value.len() <= settings.per_value_max;
    let stacked = |bs: &[Bucket], half: f64| {
        let main: Vec<Bar> = bs
            .iter()
            .filter(|b| b.main > 0)
            .map(|b| Bar { x0: b.lo as f64 - half, x1: b.hi as f64 + half, y0: 0.0, y1: b.main as f64 })
            .collect();
        let slow: Vec<Bar> = bs
            .iter()
            .filter(|b| b.slow > 0)
            .map(|b| Bar {
                x0: b.lo as f64 - half,
                x1: b.hi as f64 + half,
                y0: b.main as f64,
                y1: (b.main + b.slow) as f64,
            })
            .collect();
        (
            BarSeries::new(main_name.clone(), palette(0), main),
            BarSeries::new(slow_name.clone(), palette(1), slow),
        )
    };
    let count_axis = "objects (count)";
    let every = buckets.len().div_ceil(12).max(1);
    let bucket_ticks: Vec<(f64, String)> = buckets
        .iter()
        .enumerate()
        .filter(|(i, _)| i % every == 0)
        .map(|(_, b)| ((b.lo + b.hi) as f64 / 2.0, b.label()))
        .collect();
    let (m, s) = stacked(&buckets, 0.5);
    let mut panels = vec![Chart::new(
        format!("(b) Planning difficulty d_plan, buckets of {}", settings.bucket_width),
        Axis::linear(format!("d_plan (views), buckets of {}", settings.bucket_width))
            .with_ticks(bucket_ticks),
        Axis::linear(count_axis).with_integer_ticks(),
    )
    .with_bars(m)
    .with_bars(s)];
    if show_per_value {
        // One legend for both panels, right of the second.
        panels[0].legend = Legend::None;
        let (m, s) = stacked(&per_value, 0.4);
        panels.push(
            Chart::new(
                "(b) d_plan per value",
                Axis::linear("d_plan (views)").with_integer_ticks(),
                Axis::linear(count_axis).with_integer_ticks(),
            )
            .with_bars(m)
            .with_bars(s),
        );
    }
    let mut caption = format!(
        "{} objects with a proven d_plan ({n_main} main pool, {n_slow} slow saturation).",
        pairs.len()
    );
    if without.is_empty() {
        caption.push_str(" Every object has a proven d_plan.");
    } else {
        let listed: Vec<String> =
            without.iter().take(5).map(|a| format!("{} ({})", a.uid, a.d_plan_status)).collect();
        let more =
            if without.len() > 5 { format!(", and {} more", without.len() - 5) } else { String::new() };
        caption.push_str(&format!(
            " Not shown: {} without a proven d_plan: {}{more}.",
            without.len(),
            listed.join(", ")
        ));
    }
    let fig = if panels.len() == 2 {
        Figure::grid(panels, 2, 1500, 650)
    } else {
        Figure::grid(panels, 1, 1000, 650)
    }
    .with_caption(caption.clone());
    files.extend(fig.write(out_dir, FIGURE2_STEMS[2])?);
    data.insert(
        FIGURE2_STEMS[2].into(),
        json!({
            "bucket_width": settings.bucket_width,
            "buckets": buckets,
            "per_value": per_value,
            "per_value_panel": show_per_value,
            "without_d_plan": without.iter().map(|a| json!({"uid": a.uid, "d_plan_status": a.d_plan_status, "d_plan_bound": a.d_plan_bound})).collect::<Vec<_>>(),
            "caption": caption,
        }),
    );

    // (c) d_sat vs d_plan.
    let xs: Vec<f64> = with_plan.iter().filter_map(|a| a.d_plan.map(|d| d as f64)).collect();
    let ys: Vec<f64> = with_plan.iter().map(|a| a.d_sat as f64).collect();
    let (pearson, spearman) = (stats::pearson(&xs, &ys), stats::spearman(&xs, &ys));
    let label = with_plan.len() <= settings.label_points_max;
    let jitter = Jitter { dx: settings.jitter, dy: 0.0, seed: settings.jitter_seed };
    let group = |slow: bool| {
        let members: Vec<&&Annotation> = with_plan.iter().filter(|a| a.slow_saturation == slow).collect();
        let pts: Vec<(f64, f64)> =
            members.iter().filter_map(|a| a.d_plan.map(|d| (d as f64, a.d_sat as f64))).collect();
        let labels = if label { members.iter().map(|a| a.uid.clone()).collect() } else { Vec::new() };
        (pts, labels)
    };
    let (main_pts, main_labels) = group(false);
    let (slow_pts, slow_labels) = group(true);
    let main_series = Series::scatter(main_name.clone(), main_pts.clone(), palette(0), Marker::Circle)
        .with_alpha(0.7)
        .with_labels(main_labels)
        .with_jitter(jitter);
    let slow_series = Series::scatter(slow_name.clone(), slow_pts.clone(), palette(1), Marker::Triangle)
        .with_marker(Marker::Triangle, 5)
        .with_alpha(0.85)
        .with_labels(slow_labels)
        .with_jitter(Jitter { seed: jitter.seed ^ 1, ..jitter });
    let drawn = |s: &Series| s.drawn_points().iter().map(|&(x, y)| json!([x, y])).collect::<Vec<_>>();
    let title = format!(
        "(c) d_sat vs d_plan: Pearson r = {}, Spearman ρ = {} (n = {})",
        fmt_corr(pearson),
        fmt_corr(spearman),
        xs.len()
    );
    let chart = Chart::new(
        title.clone(),
        Axis::linear("planning difficulty d_plan (views)").with_integer_ticks(),
        Axis::linear("saturation difficulty d_sat (views)"),
    )
    .with_series(main_series.clone())
    .with_series(slow_series.clone())
    .with_ref_line(
        RefLine::horizontal(thr, format!("d_sat = {thr}: slow-saturation threshold")).with_color(palette(1)),
    );
    let mut caption = format!(
        "Each point is an object with a proven d_plan; x is jittered by up to ±{} (seed {}) to separate \
         equal d_plan values; correlations use the unjittered values.",
        settings.jitter, settings.jitter_seed
    );
    if !without.is_empty() {
        caption.push_str(&format!(" {} objects without a proven d_plan are not shown.", without.len()));
    }
    let fig = Figure::single(chart).with_caption(caption);
    files.extend(fig.write(out_dir, FIGURE2_STEMS[3])?);
    data.insert(
        FIGURE2_STEMS[3].into(),
        json!({
            "title": title,
            "pearson": pearson.map(round6),
            "spearman": spearman.map(round6),
            "n": xs.len(),
            "points": with_plan.iter().map(|a| json!({"uid": a.uid, "d_plan": a.d_plan, "d_sat": a.d_sat, "slow_saturation": a.slow_saturation})).collect::<Vec<_>>(),
            "drawn_main": drawn(&main_series),
            "drawn_slow": drawn(&slow_series),
        }),
    );

    // figures.json.
    let mut top = match provenance {
        Value::Object(m) => m.clone(),
        Value::Null => serde_json::Map::new(),
        other => serde_json::Map::from_iter([("provenance".to_string(), other.clone())]),
    };
    top.insert("plot_version".into(), json!(VERSION));
    top.insert("font".into(), json!(crate::font::FONT_DESCRIPTION));
    top.insert("settings".into(), serde_json::to_value(settings).unwrap_or(Value::Null));
    top.insert(
        "from_annotations".into(),
        json!({
            "resolution": if resolution.from_annotations { json!(resolution.value) } else { Value::Null },
            "slow_saturation_threshold": threshold.json(),
            "plateau_tol": plateau_tol.json(),
            "plateau_step": plateau_step.json(),
            "saturation_grid": annotations[0].curve.iter().map(|p| p[0]).collect::<Vec<_>>(),
        }),
    );
    top.insert(
        "counts".into(),
        json!({
            "annotations": n,
            "slow_saturation": annotations.iter().filter(|a| a.slow_saturation).count(),
            "with_d_plan": pairs.len(),
            "without_d_plan": without.len(),
        }),
    );
    top.insert(
        "files".into(),
        json!(FIGURE2_STEMS
            .iter()
            .map(|s| json!({"figure": s, "png": format!("{s}.png"), "svg": format!("{s}.svg")}))
            .collect::<Vec<_>>()),
    );
    top.insert("data".into(), Value::Object(data));
    let figures_json = out_dir.join(FIGURES_JSON);
    let mut text = serde_json::to_string_pretty(&Value::Object(top))
        .map_err(|e| PlotError::Draw { target: figures_json.display().to_string(), reason: e.to_string() })?;
    text.push('\n');
    std::fs::write(&figures_json, text).map_err(|e| PlotError::io(&figures_json, e))?;
    Ok(Figure2Output { files, figures_json })
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_difficulty::SATURATION_GRID;

    /// A synthetic annotation: Y(N) = round(S·r·(1 − exp(−N/τ))) over the SPEC grid.
    fn ann(uid: &str, d_sat: usize, d_plan: Option<usize>, tau: f64) -> Annotation {
        let s = 10_000usize;
        let curve: Vec<[usize; 2]> = SATURATION_GRID
            .iter()
            .map(|&n| [n, (s as f64 * 0.8 * (1.0 - (-(n as f64) / tau).exp())).round() as usize])
            .collect();
        let v = json!({
            "uid": uid, "mesh": format!("{uid}.obj"), "gt_cloud": "sampled", "vertices": 8, "faces": 12,
            "gt_points": 20000, "surface_voxels": s, "curve": curve, "mu": 3.0, "sigma": 1.0,
            "n_star": d_sat as f64 + 0.25, "d_sat": d_sat, "r_vis": 0.8, "grid_n": d_sat,
            "grid_r_vis": 0.8, "slow_saturation": d_sat > 128, "degenerate_fit": false, "universe": 7000,
            "d_plan": d_plan, "d_plan_status": if d_plan.is_some() { "optimal" } else { "time_limit" },
            "d_plan_bound": d_plan.unwrap_or(3), "lp_bound": 2.5, "greedy_cover": 9, "cover_views": [],
            "d_plan_proven_by": if d_plan.is_some() { "ilp" } else { "none" }, "search_nodes": 0,
            "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
                "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1,
                "reduced_views": 128, "reduced_elements": 10},
            "solver_seconds": 0.1, "seconds": 1.0,
            "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0, "cover": 0.0},
            "settings": {"resolution": 0.02, "saturation": {"slow_saturation_threshold": 128,
                "plateau_tol": 0.0002, "plateau_step": 10.0}},
            "version": "0.1.0"
        });
        serde_json::from_value(v).unwrap()
    }

    fn pool() -> Vec<Annotation> {
        vec![
            ann("bowl", 26, Some(9), 5.0),
            ann("cube", 6, Some(4), 1.0),
            ann("mug", 71, Some(13), 20.0),
            ann("chair", 37, Some(7), 8.0),
            ann("cage", 54, None, 12.0),
            ann("box-hole", 390, Some(25), 90.0),
            ann("gear", 38, Some(11), 9.0),
            ann("shell", 200, Some(12), 60.0),
        ]
    }

    #[test]
    fn representatives_sit_at_evenly_spaced_d_sat_ranks() {
        let d: [usize; 10] = [50, 10, 30, 90, 20, 70, 40, 100, 60, 80];
        let anns: Vec<Annotation> =
            d.iter().enumerate().map(|(i, &d)| ann(&format!("o{i}"), d, Some(3), 5.0)).collect();
        let pick = |k| select_representatives(&anns, k).iter().map(|&i| anns[i].d_sat).collect::<Vec<_>>();
        // Ranks round(i·9/3) = 0, 3, 6, 9.
        assert_eq!(pick(4), vec![10, 40, 70, 100]);
        // Ranks round(i·9/2) = 0, 4.5→5 (round half away from zero), 9.
        assert_eq!(pick(3), vec![10, 60, 100]);
        assert_eq!(pick(1), vec![50]);
        assert_eq!(pick(10), vec![10, 20, 30, 40, 50, 60, 70, 80, 90, 100]);
        assert_eq!(pick(20).len(), 10);
        // Ties on d_sat: N*, then uid.
        let mut t = vec![ann("b", 5, None, 1.0), ann("a", 5, None, 1.0), ann("c", 5, None, 1.0)];
        t[2].n_star = 4.6;
        let order: Vec<&str> = select_representatives(&t, 3).iter().map(|&i| t[i].uid.as_str()).collect();
        assert_eq!(order, ["c", "a", "b"]);
    }

    #[test]
    fn marginal_gain_uses_the_running_maximum() {
        let mut a = ann("x", 6, Some(1), 1.0);
        a.surface_voxels = 100;
        a.curve = vec![[6, 10], [8, 30], [10, 25], [12, 40]];
        // Y_m = 10, 30, 30, 40.
        assert_eq!(
            marginal_gain(&a),
            vec![
                Gain { n0: 6, n1: 8, x: 7.0, gain: 0.1 },
                Gain { n0: 8, n1: 10, x: 9.0, gain: 0.0 },
                Gain { n0: 10, n1: 12, x: 11.0, gain: 0.05 },
            ]
        );
        assert_eq!(normalized_curve(&a), vec![(6.0, 0.1), (8.0, 0.3), (10.0, 0.25), (12.0, 0.4)]);
    }

    #[test]
    fn buckets_follow_spec_6_and_keep_gaps() {
        assert_eq!(bucket_of(1, 5), (1, 5));
        assert_eq!(bucket_of(5, 5), (1, 5));
        assert_eq!(bucket_of(6, 5), (6, 10));
        assert_eq!(bucket_of(0, 5), (0, 0));
        let b = dplan_buckets(&[(1, false), (5, false), (6, true), (13, false), (0, false)], 5);
        let got: Vec<(usize, usize, usize, usize)> = b.iter().map(|b| (b.lo, b.hi, b.main, b.slow)).collect();
        assert_eq!(got, vec![(0, 0, 1, 0), (1, 5, 2, 0), (6, 10, 0, 1), (11, 15, 1, 0)]);
        let b = dplan_buckets(&[(2, false), (17, true)], 5);
        let got: Vec<(usize, usize, usize, usize)> = b.iter().map(|b| (b.lo, b.hi, b.main, b.slow)).collect();
        assert_eq!(got, vec![(1, 5, 1, 0), (6, 10, 0, 0), (11, 15, 0, 0), (16, 20, 0, 1)]);
        let labels: Vec<String> = b.iter().map(Bucket::label).collect();
        assert_eq!(labels, ["1–5", "6–10", "11–15", "16–20"]);
        let v = dplan_buckets(&[(3, false), (5, true), (5, false)], 1);
        let got: Vec<(usize, usize, usize)> = v.iter().map(|b| (b.lo, b.main, b.slow)).collect();
        assert_eq!(got, vec![(3, 1, 0), (4, 0, 0), (5, 1, 1)]);
        assert!(dplan_buckets(&[], 5).is_empty());
    }

    fn read(p: &Path) -> Vec<u8> {
        std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    #[test]
    fn figure2_writes_readable_deterministic_files_and_their_data() {
        let anns = pool();
        let dir = tempfile::tempdir().unwrap();
        let settings = Figure2Settings { representatives: 4, ..Figure2Settings::default() };
        let prov = json!({"tool": "objview", "command": "pool plot", "inputs": ["a.jsonl"]});
        let out = figure2(&anns, dir.path(), &settings, &prov).unwrap();
        assert_eq!(out.files.len(), 8);
        for (stem, size) in FIGURE2_STEMS.iter().zip([(1000, 650), (1000, 650), (1500, 650), (1000, 650)]) {
            let img = image::load_from_memory(&read(&dir.path().join(format!("{stem}.png")))).unwrap();
            assert_eq!((img.width(), img.height()), size, "{stem}");
        }
        let svg = |stem: &str| String::from_utf8(read(&dir.path().join(format!("{stem}.svg")))).unwrap();
        let a = svg("fig2a_saturation");
        for t in [
            "(a) Observation saturation",
            "Y(N) / |S_gt|",
            "tammes-128",
            "cube (d_sat=6)",
            "box-hole (d_sat=390)",
        ] {
            assert!(a.contains(t), "fig2a lacks {t}");
        }
        assert!(svg("fig2a_marginal_gain").contains("pool mean (n = 8)"));
        let b = svg("fig2b_dplan_hist");
        for t in [
            "buckets of 5",
            "objects (count)",
            "21–25",
            "cage (time_limit)",
            "slow saturation, d_sat &gt; 128 (n = 2)",
        ] {
            assert!(b.contains(t), "fig2b lacks {t}");
        }
        let c = svg("fig2c_dsat_vs_dplan");
        // Hand check of the title's numbers through the tested stats functions.
        let with: Vec<&Annotation> = anns.iter().filter(|a| a.d_plan.is_some()).collect();
        let x: Vec<f64> = with.iter().map(|a| a.d_plan.unwrap() as f64).collect();
        let y: Vec<f64> = with.iter().map(|a| a.d_sat as f64).collect();
        let r = stats::pearson(&x, &y).unwrap();
        assert!(c.contains(&format!("Pearson r = {r:.2}")), "{}", &c[..400]);
        assert!(
            c.contains("(n = 7)")
                && c.contains("slow-saturation threshold")
                && c.contains(">\nshell\n</text>")
        );

        let json: Value = serde_json::from_slice(&read(&out.figures_json)).unwrap();
        assert_eq!(json["command"], "pool plot");
        assert_eq!(json["plot_version"], VERSION);
        assert_eq!(json["settings"]["representatives"], 4);
        assert_eq!(json["from_annotations"]["slow_saturation_threshold"]["source"], "annotations");
        assert_eq!(json["counts"]["without_d_plan"], 1);
        let reps: Vec<&str> = json["data"]["fig2a_saturation"]["representatives"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["uid"].as_str().unwrap())
            .collect();
        // d_sat order 6, 26, 37, 38, 54, 71, 200, 390 → ranks 0, round(7/3)=2, round(14/3)=5, 7.
        assert_eq!(reps, ["cube", "chair", "mug", "box-hole"]);
        let buckets = &json["data"]["fig2b_dplan_hist"]["buckets"];
        assert_eq!(buckets[0], json!({"lo": 1, "hi": 5, "main": 1, "slow": 0}));
        assert_eq!(buckets[2], json!({"lo": 11, "hi": 15, "main": 2, "slow": 1}));
        assert_eq!(buckets[4], json!({"lo": 21, "hi": 25, "main": 0, "slow": 1}));
        assert!((json["data"]["fig2c_dsat_vs_dplan"]["pearson"].as_f64().unwrap() - r).abs() < 1e-6);
        let floor = json["data"]["fig2a_marginal_gain"]["floor"].as_f64().unwrap();
        let min_gain =
            anns.iter().flat_map(marginal_gain).map(|g| g.gain).filter(|&g| g > 0.0).fold(1.0, f64::min);
        assert!(
            floor * 10.0 <= min_gain && min_gain < floor * 100.0,
            "floor {floor}, smallest gain {min_gain}"
        );
        let mean = &json["data"]["fig2a_marginal_gain"]["pool_mean"][0];
        let expect: f64 = anns.iter().map(|a| marginal_gain(a)[0].gain).sum::<f64>() / 8.0;
        assert_eq!(mean[0], 6);
        assert!((mean[3].as_f64().unwrap() - expect).abs() < 1e-15);

        // Determinism: a second run elsewhere gives the same bytes, file by file.
        let dir2 = tempfile::tempdir().unwrap();
        figure2(&anns, dir2.path(), &settings, &prov).unwrap();
        for f in out.files.iter().chain([&out.figures_json]) {
            let name = f.file_name().unwrap();
            assert!(
                read(f) == read(&dir2.path().join(name)),
                "{} differs between runs",
                name.to_string_lossy()
            );
        }
    }

    #[test]
    fn figure2_draws_degenerate_pools() {
        // One object, flat curve (all gains 0), no proven d_plan: every panel is still drawn.
        let mut a = ann("flat", 6, None, 0.01);
        a.curve.iter_mut().for_each(|p| p[1] = 8000);
        let dir = tempfile::tempdir().unwrap();
        let out = figure2(&[a], dir.path(), &Figure2Settings::default(), &Value::Null).unwrap();
        assert_eq!(out.files.len(), 8);
        let json: Value = serde_json::from_slice(&read(&out.figures_json)).unwrap();
        assert_eq!(json["data"]["fig2a_marginal_gain"]["floor"], 1e-6);
        assert_eq!(json["data"]["fig2c_dsat_vs_dplan"]["pearson"], Value::Null);
        assert_eq!(json["data"]["fig2b_dplan_hist"]["buckets"], json!([]));
        let c = String::from_utf8(read(&dir.path().join("fig2c_dsat_vs_dplan.svg"))).unwrap();
        assert!(c.contains("Pearson r = undefined") && c.contains("(n = 0)"), "{c}");
        let b = String::from_utf8(read(&dir.path().join("fig2b_dplan_hist.svg"))).unwrap();
        assert!(b.contains("Not shown: 1 without a proven d_plan: flat (time_limit)"));
    }

    #[test]
    fn figure2_rejects_what_it_cannot_plot() {
        let dir = tempfile::tempdir().unwrap();
        let s = Figure2Settings::default();
        let e = figure2(&[], dir.path(), &s, &Value::Null).unwrap_err();
        assert!(matches!(e, PlotError::NoAnnotations));
        let mut anns = pool();
        anns[3].settings["saturation"]["slow_saturation_threshold"] = json!(100);
        let e = figure2(&anns, dir.path(), &s, &Value::Null).unwrap_err().to_string();
        assert!(e.contains("saturation.slow_saturation_threshold") && e.contains("'chair' has 100"), "{e}");
        let mut anns = pool();
        anns[2].curve.pop();
        let e = figure2(&anns, dir.path(), &s, &Value::Null).unwrap_err().to_string();
        assert!(e.contains("'mug'") && e.contains("grid differs"), "{e}");
        let mut anns = pool();
        anns[1].surface_voxels = 0;
        assert!(figure2(&anns, dir.path(), &s, &Value::Null).unwrap_err().to_string().contains("'cube'"));
        let bad = Figure2Settings { representatives: 0, ..s };
        assert!(figure2(&pool(), dir.path(), &bad, &Value::Null)
            .unwrap_err()
            .to_string()
            .contains("representatives"));
    }
}
