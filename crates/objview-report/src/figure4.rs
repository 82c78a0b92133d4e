//! The paper's Figure 4 (difficulty-aware training) from the `summary.json` of
//! `objview learn experiment difficulty-aware`:
//! - (a) the d_plan distributions of Main-Raw-Train and Main-Balanced-Train (objects per d_plan
//!   bucket, side by side);
//! - (b) VC per d_plan bucket of Main-Analysis-Test for the two models: the mean over the
//!   bucket's objects of their mean VC over 128 start views, error bars ± the population std over
//!   those objects, each point labelled with its object count.
//!
//! The caption states the subset sizes, the analysis size, γ, and the balanced − raw difference
//! on medium/high buckets with wins and losses — whichever way it goes. A Markdown table of the
//! same numbers comes with it ([`markdown`]). Deterministic: the same summary gives the same
//! bytes.

use std::path::{Path, PathBuf};

use objview_plot::{palette, Axis, Bar, BarSeries, Chart, Figure, Marker, Series};
use serde_json::Value;

use crate::ReportError;

/// File stem of the figure (`figure4.png`, `figure4.svg`).
pub const STEM: &str = "figure4_difficulty_aware";
/// The Markdown table's file name.
pub const TABLE_FILE: &str = "difficulty_aware.md";
/// The experiment's summary file name inside its folder.
pub const SUMMARY: &str = "summary.json";

const MODELS: [(&str, &str); 2] = [("raw", "Main-Raw-Train"), ("balanced", "Main-Balanced-Train")];

/// Reads `dir/summary.json` of the experiment (one-line errors naming the file).
pub fn read_summary(dir: &Path) -> Result<Value, ReportError> {
    let path = dir.join(SUMMARY);
    let text = std::fs::read_to_string(&path).map_err(|e| ReportError::io(&path, e))?;
    let v: Value = serde_json::from_str(&text).map_err(|e| {
        ReportError::io(&path, std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not JSON: {e}")))
    })?;
    if v["experiment"] != "difficulty-aware" || !v["buckets"].is_object() || !v["subsets"].is_object() {
        return Err(ReportError::InvalidSetting {
            name: "difficulty-aware",
            reason: format!(
                "{} is not the summary of `objview learn experiment difficulty-aware`",
                path.display()
            ),
        });
    }
    Ok(v)
}

/// Width of a d_plan bucket (SPEC §6; `objview_pool::split::BUCKET_WIDTH`), as in the labels.
const BUCKET_WIDTH: usize = 5;

fn bucket_index(label: &str) -> Option<usize> {
    let lo: usize = label.split('-').next()?.parse().ok()?;
    (lo >= 1).then(|| (lo - 1) / BUCKET_WIDTH)
}

fn label_of(b: usize) -> String {
    format!("{}-{}", b * BUCKET_WIDTH + 1, (b + 1) * BUCKET_WIDTH)
}

/// Every bucket index mentioned in the summary (subsets and analysis), ascending.
fn buckets(summary: &Value) -> Vec<usize> {
    let mut set = std::collections::BTreeSet::new();
    for s in ["raw", "balanced", "analysis"] {
        if let Some(m) = summary["subsets"][s]["buckets"].as_object() {
            set.extend(m.keys().filter_map(|k| bucket_index(k)));
        }
    }
    for (m, _) in MODELS {
        if let Some(rows) = summary["buckets"][m].as_array() {
            set.extend(rows.iter().filter_map(|r| r["bucket"].as_str().and_then(bucket_index)));
        }
    }
    set.into_iter().collect()
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The caption: sizes, γ, the medium/high comparison and its verdict.
pub fn caption(summary: &Value) -> String {
    let s = &summary["settings"];
    let c = &summary["comparison"]["medium_high"];
    let diff = num(&c["balanced_minus_raw"]);
    let verdict = if c["objects"].as_u64().unwrap_or(0) == 0 {
        "No analysis object has d_plan >= 6, so the medium/high comparison is empty".to_string()
    } else if summary["comparison"]["balanced_better_on_medium_high"] == true {
        format!(
            "On medium/high d_plan (>= 6, {} objects) balanced is ahead of raw by {:+.4} mean VC (wins {}, losses {}, ties {})",
            c["objects"], diff, c["balanced_wins"], c["balanced_losses"], c["ties"]
        )
    } else {
        format!(
            "On medium/high d_plan (>= 6, {} objects) balanced does NOT beat raw: {:+.4} mean VC (wins {}, losses {}, ties {})",
            c["objects"], diff, c["balanced_wins"], c["balanced_losses"], c["ties"]
        )
    };
    let all = &summary["comparison"]["all"];
    let sizes = if all["gt_total_mean"].is_number() {
        format!(
            " Mean planned views (start + decoded) over all analysis objects: raw {:.2}, balanced {:.2}, ground truth (start + exact residual cover) {:.2}; VC does not charge for set size.",
            num(&all["raw_pred_total_mean"]),
            num(&all["balanced_pred_total_mean"]),
            num(&all["gt_total_mean"])
        )
    } else {
        String::new()
    };
    format!(
        "MA-SCVP ({}) trained with one recipe and seed on Main-Raw-Train and Main-Balanced-Train ({} objects each, {} epochs); \
         VC at gamma {} over the 128 start views of {} Main-Analysis-Test objects; error bars: population std over the bucket's objects; n = objects. \
         {verdict}.{sizes} objview {}.",
        s["train"]["shape"]["grid"].as_u64().map(|g| format!("{g}^3")).unwrap_or_default(),
        s["size"],
        s["train"]["epochs"],
        s["metric"]["gamma"],
        summary["analysis_objects"],
        summary["version"].as_str().unwrap_or("?"),
    )
}

/// Figure 4 of `summary` (see the module docs).
pub fn figure(summary: &Value) -> Figure {
    let bs = buckets(summary);
    let (first, last) = (bs.first().copied().unwrap_or(0), bs.last().copied().unwrap_or(0));
    let ticks: Vec<(f64, String)> = (first..=last).map(|b| (b as f64, label_of(b))).collect();
    let (lo, hi) =
        (bs.first().copied().unwrap_or(0) as f64 - 0.6, bs.last().copied().unwrap_or(0) as f64 + 0.6);
    // (a) subsets' d_plan distributions.
    let mut a = Chart::new(
        "(a) d_plan of the training subsets",
        Axis::linear("d_plan bucket").with_range(lo, hi).with_ticks(ticks.clone()),
        Axis::linear("objects"),
    );
    let mut ymax = 1.0f64;
    for (i, (key, name)) in MODELS.iter().enumerate() {
        let off = if i == 0 { -0.2 } else { 0.2 };
        let mut bars = Vec::new();
        if let Some(m) = summary["subsets"][*key]["buckets"].as_object() {
            for (k, n) in m {
                if let Some(b) = bucket_index(k) {
                    let n = n.as_f64().unwrap_or(0.0);
                    ymax = ymax.max(n);
                    bars.push(Bar { x0: b as f64 + off - 0.18, x1: b as f64 + off + 0.18, y0: 0.0, y1: n });
                }
            }
        }
        let n = summary["subsets"][*key]["objects"].as_u64().unwrap_or(0);
        a = a.with_bars(BarSeries::new(format!("{name} (n = {n})"), palette(i), bars));
    }
    a.y = Axis::linear("objects").with_range(0.0, ymax * 1.15).with_integer_ticks();

    // (b) VC per bucket.
    let mut b = Chart::new(
        "(b) VC per d_plan bucket, Main-Analysis-Test",
        Axis::linear("d_plan bucket").with_range(lo, hi).with_ticks(ticks),
        Axis::linear("VC (mean over objects of the mean over 128 starts)"),
    );
    let mut ylo = 1.0f64;
    for (i, (key, name)) in MODELS.iter().enumerate() {
        let off = if i == 0 { -0.08 } else { 0.08 };
        let rows = summary["buckets"][*key].as_array().cloned().unwrap_or_default();
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for r in &rows {
            let (Some(bi), m, sd) =
                (r["bucket"].as_str().and_then(bucket_index), num(&r["vc_mean"]), num(&r["vc_std"]))
            else {
                continue;
            };
            if !(m.is_finite() && sd.is_finite()) {
                continue;
            }
            let x = bi as f64 + off;
            pts.push((x, m));
            // The counts are the same for both models: labelled once, under the raw points.
            labels.push(if i == 0 { format!("n={}", r["objects"]) } else { String::new() });
            ylo = ylo.min(m - sd);
            b = b.with_series(
                Series::line("", vec![(x, (m - sd).max(0.0)), (x, (m + sd).min(1.0))], palette(i))
                    .with_width(2),
            );
        }
        b = b.with_series(
            Series::line(name.to_string(), pts, palette(i))
                .with_marker(Marker::Circle, 5)
                .with_labels(labels),
        );
    }
    b.y = Axis::linear("VC").with_range((ylo - 0.05).clamp(0.0, 0.95).min(0.9), 1.02);
    Figure::grid(vec![a, b], 2, 1600, 700).with_caption(caption(summary))
}

/// The per-bucket numbers as a Markdown table (+ the comparison line).
pub fn markdown(summary: &Value) -> String {
    let mut s = String::from("## Difficulty-aware training (Figure 4)\n\n");
    s.push_str("| d_plan bucket | raw: objects in subset | balanced: objects in subset | analysis objects | VC raw (mean ± std) | VC balanced (mean ± std) | balanced − raw | size bias raw | size bias balanced |\n");
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let find = |m: &str, label: &str| -> Option<Value> {
        summary["buckets"][m].as_array()?.iter().find(|r| r["bucket"] == label).cloned()
    };
    for b in buckets(summary) {
        let l = label_of(b);
        let cnt = |k: &str| summary["subsets"][k]["buckets"][&l].as_u64().unwrap_or(0);
        let (r, bal) = (find("raw", &l), find("balanced", &l));
        let cell = |x: &Option<Value>| match x {
            Some(v) => format!("{:.4} ± {:.4}", num(&v["vc_mean"]), num(&v["vc_std"])),
            None => "–".into(),
        };
        let diff = match (&r, &bal) {
            (Some(r), Some(b)) => format!("{:+.4}", num(&b["vc_mean"]) - num(&r["vc_mean"])),
            _ => "–".into(),
        };
        let bias =
            |x: &Option<Value>| x.as_ref().map_or("–".into(), |v| format!("{:+.2}", num(&v["size_bias"])));
        s.push_str(&format!(
            "| {l} | {} | {} | {} | {} | {} | {diff} | {} | {} |\n",
            cnt("raw"),
            cnt("balanced"),
            r.as_ref().map_or(0, |v| v["objects"].as_u64().unwrap_or(0)),
            cell(&r),
            cell(&bal),
            bias(&r),
            bias(&bal)
        ));
    }
    s.push('\n');
    s.push_str(&caption(summary));
    s.push('\n');
    s
}

/// Writes the figure (PNG + SVG) and the table into `out` (created if missing); returns the
/// paths.
pub fn write(summary: &Value, out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(out).map_err(|e| ReportError::io(out, e))?;
    let [png, svg] = figure(summary).write(out, STEM)?;
    let md = out.join(TABLE_FILE);
    std::fs::write(&md, markdown(summary)).map_err(|e| ReportError::io(&md, e))?;
    Ok(vec![png, svg, md])
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn summary(better: bool) -> Value {
        json!({
            "experiment": "difficulty-aware",
            "version": "0.0.0",
            "analysis_objects": 4,
            "settings": {"size": 6, "train": {"epochs": 2, "shape": {"grid": 16}}, "metric": {"gamma": 0.5}},
            "subsets": {
                "raw": {"objects": 6, "buckets": {"1-5": 5, "6-10": 1}},
                "balanced": {"objects": 6, "buckets": {"1-5": 2, "6-10": 2, "11-15": 2}},
                "analysis": {"objects": 4, "buckets": {"1-5": 2, "6-10": 1, "11-15": 1}},
            },
            "buckets": {
                "raw": [{"bucket": "1-5", "objects": 2, "vc_mean": 0.9, "vc_std": 0.05, "size_bias": -1.0},
                        {"bucket": "6-10", "objects": 1, "vc_mean": 0.7, "vc_std": 0.0, "size_bias": -2.0},
                        {"bucket": "11-15", "objects": 1, "vc_mean": 0.6, "vc_std": 0.0, "size_bias": -3.0}],
                "balanced": [{"bucket": "1-5", "objects": 2, "vc_mean": 0.88, "vc_std": 0.04, "size_bias": -0.5},
                             {"bucket": "6-10", "objects": 1, "vc_mean": if better { 0.75 } else { 0.65 }, "vc_std": 0.0, "size_bias": -1.0},
                             {"bucket": "11-15", "objects": 1, "vc_mean": 0.6, "vc_std": 0.0, "size_bias": -2.0}],
            },
            "comparison": {
                "medium_high": {"objects": 2, "balanced_minus_raw": if better { 0.025 } else { -0.025 },
                                "balanced_wins": if better { 1 } else { 0 }, "balanced_losses": if better { 0 } else { 1 }, "ties": 1},
                "balanced_better_on_medium_high": better,
                "all": {"raw_pred_total_mean": 1.0, "balanced_pred_total_mean": 4.5, "gt_total_mean": 6.25},
            },
        })
    }

    #[test]
    fn the_caption_says_which_way_it_went() {
        assert!(caption(&summary(true)).contains("balanced is ahead of raw by +0.0250"));
        let c = caption(&summary(false));
        assert!(c.contains("balanced does NOT beat raw: -0.0250"), "{c}");
        assert!(c.contains("6 objects each") && c.contains("16^3") && c.contains("gamma 0.5"), "{c}");
        assert!(
            c.contains("raw 1.00, balanced 4.50, ground truth (start + exact residual cover) 6.25"),
            "{c}"
        );
    }

    #[test]
    fn the_figure_has_both_panels_with_counts_and_error_bars() {
        let f = figure(&summary(true));
        assert_eq!(f.panels.len(), 2);
        let a = &f.panels[0];
        assert_eq!(a.bars.len(), 2);
        let heights: Vec<f64> = a.bars[1].bars.iter().map(|b| b.y1).collect();
        assert_eq!(heights, vec![2.0, 2.0, 2.0]);
        let b = &f.panels[1];
        let named: Vec<&Series> = b.series.iter().filter(|s| !s.name.is_empty()).collect();
        assert_eq!(named.len(), 2);
        assert_eq!(named[0].labels, vec!["n=2", "n=1", "n=1"]);
        assert_eq!(named[1].labels, vec!["", "", ""], "counts once per bucket");
        assert_eq!(named[1].points[1].1, 0.75);
        // One error bar per point: 3 buckets × 2 models, each ± std (clamped to [0, 1]).
        let bars: Vec<&Series> = b.series.iter().filter(|s| s.name.is_empty()).collect();
        assert_eq!(bars.len(), 6);
        let want = [(-0.08, 0.85), (-0.08, 0.95)];
        assert!(
            bars[0]
                .points
                .iter()
                .zip(want)
                .all(|(a, b)| (a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12),
            "{:?}",
            bars[0].points
        );
        let dir = tempfile::tempdir().unwrap();
        let files = write(&summary(true), dir.path()).unwrap();
        assert_eq!(files.len(), 3);
        let again = tempfile::tempdir().unwrap();
        write(&summary(true), again.path()).unwrap();
        for f in &files {
            let name = f.file_name().unwrap();
            assert_eq!(
                std::fs::read(f).unwrap(),
                std::fs::read(again.path().join(name)).unwrap(),
                "{name:?}"
            );
        }
        let md = std::fs::read_to_string(dir.path().join(TABLE_FILE)).unwrap();
        assert!(md.contains("| 6-10 | 1 | 2 | 1 | 0.7000 ± 0.0000 | 0.7500 ± 0.0000 | +0.0500 |"), "{md}");
    }

    #[test]
    fn a_summary_of_something_else_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(SUMMARY), "{\"experiment\": \"other\"}").unwrap();
        let e = read_summary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("is not the summary of `objview learn experiment difficulty-aware`"), "{e}");
        let e = read_summary(&dir.path().join("missing")).unwrap_err().to_string();
        assert!(e.contains("summary.json"), "{e}");
    }
}
