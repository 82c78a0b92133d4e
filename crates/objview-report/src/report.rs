//! The report as a whole: [`build_report`] reads the inputs and computes every table and plot
//! series into a [`Report`] (no I/O besides reading); [`Report::write`] writes the output folder;
//! [`Report::markdown`] gives the tables for the terminal.
//!
//! Output folder ([`OUTPUT_FILES`], then the figures):
//! - `report.md`: header (version, inputs with line counts, settings, warnings), Tables 2–5,
//!   the terminal-reason summary, failure lines, skipped lines (when there are some), and links
//!   to the figures;
//! - `report.json`: the same provenance, counts, duplicates, failures, skipped lines and every
//!   table as data;
//! - `summary.csv` (every (setting, view space, method) with means and standard deviations),
//!   `table2_quality_top.csv`, `table3_path_top.csv`, `table4_reachability.csv`,
//!   `table5_map_stabilization.csv` (only with annotations), `terminal_reasons.csv`,
//!   `failures.csv` (failure lines, then skipped lines; the `kind` column says which);
//! - `nsc_vs_views_<space>.{png,svg}`, `path_cost_vs_nsc_<space>.{png,svg}` and `figures.json`
//!   (every plotted number), unless plots are turned off.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use objview_dataset::{read_annotations, Annotation};
use objview_episode::CheckpointKey;
use serde::Serialize;
use serde_json::{json, Value};

use crate::aggregate::{aggregates, group_picks, Aggregate};
use crate::format::{markdown_table, plural, Align};
use crate::load::{load_results, Duplicate, DuplicateKind, FailureLine, InputFile, SkippedLine};
use crate::plots::{
    nsc_curves, tradeoff_points, write_figures, Curve, FigureContext, FigureFiles, TradeoffPoint,
};
use crate::render;
use crate::select::{pick, settings_of, Setting};
use crate::tables::{
    map_stabilization, path_top, quality_top, reachability, terminal_summary, MsTable, RankedTable,
    ReachTable, TerminalTable,
};
use crate::{ReportError, VERSION};

/// The Markdown report.
pub const REPORT_MD: &str = "report.md";
/// Provenance, counts and every table as JSON.
pub const REPORT_JSON: &str = "report.json";
/// Every (setting, view space, method) aggregate.
pub const SUMMARY_CSV: &str = "summary.csv";
/// Table 2 as CSV.
pub const TABLE2_CSV: &str = "table2_quality_top.csv";
/// Table 3 as CSV.
pub const TABLE3_CSV: &str = "table3_path_top.csv";
/// Table 4 as CSV.
pub const TABLE4_CSV: &str = "table4_reachability.csv";
/// Written only when annotations were given.
pub const TABLE5_CSV: &str = "table5_map_stabilization.csv";
/// The terminal-reason summary as CSV.
pub const TERMINAL_CSV: &str = "terminal_reasons.csv";
/// Every failure line as CSV.
pub const FAILURES_CSV: &str = "failures.csv";

/// The non-figure outputs, in the order [`Report::write`] returns them.
pub const OUTPUT_FILES: [&str; 9] = [
    REPORT_MD,
    REPORT_JSON,
    SUMMARY_CSV,
    TABLE2_CSV,
    TABLE3_CSV,
    TABLE4_CSV,
    TABLE5_CSV,
    TERMINAL_CSV,
    FAILURES_CSV,
];

/// Settings of the report (defaults: the paper's).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReportSettings {
    /// τ of NSC and SC, as keyed in the results (`"0.02"`).
    pub tau: String,
    /// Table 3's filter: mean NSC@τ at least this.
    pub quality_threshold: f64,
    /// Ranked rows per setting in Tables 2 and 3.
    pub top: usize,
    /// View space of Tables 2, 3 and 5, and the A side of Table 4 (`whole`).
    pub space_a: String,
    /// The B side of Table 4 (`quarter`).
    pub space_b: String,
    /// The checkpoint of iterative planners' automatic setting and of Table 5's MS columns.
    pub auto_checkpoint: CheckpointKey,
    /// Draw the figures.
    pub plots: bool,
    /// Failure lines listed in the Markdown (all are in `failures.csv`).
    pub failures_listed: usize,
}

impl Default for ReportSettings {
    fn default() -> Self {
        ReportSettings {
            tau: "0.02".into(),
            quality_threshold: 0.95,
            top: 3,
            space_a: "whole".into(),
            space_b: "quarter".into(),
            auto_checkpoint: CheckpointKey::Stabilized(0.02),
            plots: true,
            failures_listed: 20,
        }
    }
}

impl ReportSettings {
    /// Checks ranges; errors name the setting.
    pub fn validate(&self) -> Result<(), ReportError> {
        let bad = |name, reason: &str| Err(ReportError::InvalidSetting { name, reason: reason.into() });
        if self.tau.trim().is_empty() {
            return bad("tau", "must be a τ key such as 0.02");
        }
        if !self.quality_threshold.is_finite() {
            return bad("quality_threshold", "must be a finite number");
        }
        if self.top == 0 {
            return bad("top", "must be at least 1");
        }
        if self.space_a.is_empty() || self.space_b.is_empty() {
            return bad("space_a/space_b", "view-space names must not be empty");
        }
        if self.space_a == self.space_b {
            return bad("space_b", "must differ from space_a");
        }
        Ok(())
    }
}

/// The annotation inputs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AnnotationInputs {
    /// Annotation files, as given.
    pub files: Vec<PathBuf>,
    /// Successful annotations.
    pub annotations: usize,
    /// Failure lines of `objview annotate`.
    pub failures: usize,
}

/// Counts of the inputs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Counts {
    /// Episode result lines read.
    pub episode_lines: usize,
    /// Episodes kept after removing duplicates.
    pub episodes: usize,
    /// Failure lines (episodes that could not run).
    pub failure_lines: usize,
    /// Failure lines with a result for the same episode.
    pub failures_superseded: usize,
    /// Lines skipped as unusable (not JSON, not an episode result, …).
    pub skipped_lines: usize,
    /// Episodes dropped for a later line with the same key.
    pub duplicates_same_key: usize,
    /// Iterative runs dropped for a longer run under another budget label.
    pub duplicates_iterative_budgets: usize,
    /// Kept episodes that contribute to no budget setting.
    pub unused_episodes: usize,
    /// Distinct objects.
    pub objects: usize,
    /// Distinct methods.
    pub methods: usize,
}

/// Everything the report shows, computed by [`build_report`].
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The settings used.
    pub settings: ReportSettings,
    /// Results files with their line counts.
    pub inputs: Vec<InputFile>,
    /// Annotation files; `None` when none were given.
    pub annotation_inputs: Option<AnnotationInputs>,
    /// Counts of episodes, failures, duplicates.
    pub counts: Counts,
    /// Budget settings, in report order.
    pub budget_settings: Vec<Setting>,
    /// View spaces with episodes.
    pub view_spaces: Vec<String>,
    /// Methods, sorted (a method's index fixes its colour).
    pub methods: Vec<String>,
    /// τ keys common to every episode (the summary has NSC/SC at each).
    pub taus: Vec<String>,
    /// Failure lines, in input order.
    pub failures: Vec<FailureLine>,
    /// Skipped lines, in input order.
    pub skipped: Vec<SkippedLine>,
    /// Dropped duplicate episodes.
    pub duplicates: Vec<Duplicate>,
    /// Warnings shown in the Markdown header and `report.json`.
    pub warnings: Vec<String>,
    /// Every (setting, view space, method) aggregate.
    pub aggregates: Vec<Aggregate>,
    /// Table 2.
    pub quality: RankedTable,
    /// Table 3.
    pub path_efficient: RankedTable,
    /// Table 4.
    pub reachability: ReachTable,
    /// `None` without annotations.
    pub map_stabilization: Option<MsTable>,
    /// Terminal reasons and failures per (view space, method).
    pub terminal: TerminalTable,
    /// Exact solver status per (view space, method, budget), from `planner_notes`.
    pub solver: Vec<crate::tables::SolverRow>,
    /// Curves of the NSC-vs-views figures.
    pub curves: Vec<Curve>,
    /// Points of the path-cost-vs-NSC figures.
    pub tradeoff: Vec<TradeoffPoint>,
}

/// Reads `results` (episode JSON Lines) and `annotations` (`objview annotate` JSON Lines, may be
/// empty) and computes the report.
pub fn build_report(
    results: &[PathBuf],
    annotations: &[PathBuf],
    settings: &ReportSettings,
) -> Result<Report, ReportError> {
    settings.validate()?;
    let loaded = load_results(results, &settings.tau)?;
    let (annotation_list, annotation_inputs): (Vec<Annotation>, Option<AnnotationInputs>) =
        if annotations.is_empty() {
            (Vec::new(), None)
        } else {
            let set = read_annotations(annotations)?;
            let inputs = AnnotationInputs {
                files: annotations.to_vec(),
                annotations: set.annotations.len(),
                failures: set.failures.len(),
            };
            (set.annotations, Some(inputs))
        };
    let episodes = &loaded.episodes;
    let tau = settings.tau.as_str();
    let budget_settings = settings_of(episodes);
    let groups = group_picks(episodes, &budget_settings, &settings.auto_checkpoint);
    let aggs = aggregates(&groups, tau, &loaded.taus);
    let quality = quality_top(&aggs, &settings.space_a, &budget_settings, settings.top);
    let path_efficient =
        path_top(&aggs, &settings.space_a, &budget_settings, settings.top, settings.quality_threshold);
    let reach = reachability(&aggs, &groups, &settings.space_a, &settings.space_b, tau);
    let map_stab = annotation_inputs.as_ref().map(|_| {
        map_stabilization(episodes, &annotation_list, &settings.space_a, &settings.auto_checkpoint, tau)
    });
    let terminal = terminal_summary(episodes, &loaded.failures);
    let methods: Vec<String> =
        episodes.iter().map(|e| e.result.method.clone()).collect::<BTreeSet<_>>().into_iter().collect();
    let view_spaces: Vec<String> =
        episodes.iter().map(|e| e.result.view_space.clone()).collect::<BTreeSet<_>>().into_iter().collect();
    let objects = episodes.iter().map(|e| e.result.uid.as_str()).collect::<BTreeSet<_>>().len();

    // Episodes that no setting uses.
    let mut unused: BTreeMap<(String, String, String), usize> = BTreeMap::new();
    for e in episodes {
        if budget_settings.iter().all(|&s| pick(e, s, &settings.auto_checkpoint).is_none()) {
            let r = &e.result;
            *unused
                .entry((r.method.clone(), r.execution_mode.to_string(), r.budget.to_string()))
                .or_default() += 1;
        }
    }
    let count_dup = |k: DuplicateKind| loaded.duplicates.iter().filter(|d| d.kind == k).count();
    let counts = Counts {
        episode_lines: loaded.files.iter().map(|f| f.episodes).sum(),
        episodes: episodes.len(),
        failure_lines: loaded.failures.len(),
        failures_superseded: loaded.failures.iter().filter(|f| f.superseded).count(),
        skipped_lines: loaded.skipped.len(),
        duplicates_same_key: count_dup(DuplicateKind::SameKey),
        duplicates_iterative_budgets: count_dup(DuplicateKind::IterativeBudgets),
        unused_episodes: unused.values().sum(),
        objects,
        methods: methods.len(),
    };

    let mut warnings = Vec::new();
    if counts.skipped_lines > 0 {
        warnings.push(format!(
            "{} skipped: not usable as episode results or failure lines (each with its file, line and \
             reason under Skipped lines, in report.json and in failures.csv).",
            plural(counts.skipped_lines, "line")
        ));
    }
    for f in loaded.files.iter().filter(|f| f.torn_last_line) {
        warnings.push(format!("{}: torn last line skipped (an interrupted run).", f.path.display()));
    }
    let failed_dropped = |k: DuplicateKind| {
        let n = loaded.duplicates.iter().filter(|d| d.kind == k && d.failed_run_dropped).count();
        if n == 0 {
            String::new()
        } else {
            format!(" ({n} of them a failed run dropped for a normal one)")
        }
    };
    if counts.duplicates_same_key > 0 {
        warnings.push(format!(
            "Duplicate episodes (same uid, method, view space, budget, seed): {}{}; a run that ended \
             normally (a planner stop, enough_info, the cap or the budget) is kept over one that failed \
             (an exception such as planner_error, timeout or interrupted, an abort, an invalid action), \
             else the last line (pairs in report.json).",
            counts.duplicates_same_key,
            failed_dropped(DuplicateKind::SameKey)
        ));
    }
    if counts.duplicates_iterative_budgets > 0 {
        warnings.push(format!(
            "Iterative runs repeated under another budget label (same uid, method, view space, seed): {}{}; \
             an iterative run serves every setting, so a run that ended normally is kept over one that \
             failed, else the run with the most views (pairs in report.json).",
            counts.duplicates_iterative_budgets,
            failed_dropped(DuplicateKind::IterativeBudgets)
        ));
    }
    for ((method, mode, budget), n) in &unused {
        warnings.push(format!(
            "{} of `{method}` ({mode}, budget {budget}) fit no budget setting and are not in the tables.",
            plural(*n, "episode")
        ));
    }
    for space in [&settings.space_a, &settings.space_b] {
        if !view_spaces.contains(space) {
            warnings.push(format!("No episodes in view space `{space}`."));
        }
    }
    // Runs that did not reach a setting's checkpoint, one line per (method, view space).
    // (method, view space) → ("K=30 2 of 10" per setting with terminal fallbacks, … with steps).
    type Notes = (Vec<String>, Vec<String>);
    let mut fell_back: BTreeMap<(&str, &str), Notes> = BTreeMap::new();
    for a in &aggs {
        let entry = fell_back.entry((a.method.as_str(), a.view_space.as_str())).or_default();
        if a.terminal_fallback > 0 {
            entry.0.push(format!("{} {} of {}", a.setting.label(), a.terminal_fallback, a.n));
        }
        if a.from_step > 0 {
            entry.1.push(format!("{} {} of {}", a.setting.label(), a.from_step, a.n));
        }
    }
    for ((method, space), (terminal, step)) in &fell_back {
        if !terminal.is_empty() {
            warnings.push(format!(
                "`{method}` in `{space}`: runs that ended before a setting's checkpoint contribute their \
                 `terminal` ({}).",
                terminal.join(", ")
            ));
        }
        if !step.is_empty() {
            warnings.push(format!(
                "`{method}` in `{space}`: runs without a `K=k` checkpoint contribute their step k ({}).",
                step.join(", ")
            ));
        }
    }

    Ok(Report {
        settings: settings.clone(),
        inputs: loaded.files.clone(),
        annotation_inputs,
        counts,
        budget_settings,
        view_spaces,
        methods,
        taus: loaded.taus.clone(),
        failures: loaded.failures.clone(),
        skipped: loaded.skipped.clone(),
        duplicates: loaded.duplicates.clone(),
        warnings,
        curves: nsc_curves(episodes, tau),
        tradeoff: tradeoff_points(&aggs),
        aggregates: aggs,
        quality,
        path_efficient,
        reachability: reach,
        map_stabilization: map_stab,
        terminal,
        solver: crate::tables::solver_summary(episodes),
    })
}

impl Report {
    /// The tables (2–5, terminal reasons, failure lines, skipped lines if any) in Markdown, for
    /// the terminal.
    pub fn markdown(&self) -> String {
        let s = &self.settings;
        let tau = s.tau.as_str();
        let mut parts = vec![
            render::quality_markdown(&self.quality, tau, s.top),
            render::path_markdown(&self.path_efficient, tau, s.top, s.quality_threshold),
            render::reach_markdown(&self.reachability, tau),
            render::ms_markdown(self.map_stabilization.as_ref(), tau),
            render::terminal_markdown(&self.terminal),
        ];
        if !self.solver.is_empty() {
            parts.push(render::solver_markdown(&self.solver));
        }
        parts.push(render::failures_markdown(&self.failures, &self.inputs, s.failures_listed));
        if !self.skipped.is_empty() {
            parts.push(render::skipped_markdown(&self.skipped, &self.inputs, s.failures_listed));
        }
        parts.join("\n")
    }

    /// The header of `report.md`: version, inputs, settings, counts, warnings.
    fn header_markdown(&self) -> String {
        let s = &self.settings;
        let c = &self.counts;
        let mut out = format!("# objview report\n\nobjview-report {VERSION}.\n\n## Inputs\n\n");
        let rows: Vec<Vec<String>> = self
            .inputs
            .iter()
            .map(|f| {
                vec![
                    format!("`{}`", f.path.display()),
                    f.lines.to_string(),
                    f.episodes.to_string(),
                    f.failures.to_string(),
                    f.skipped.to_string(),
                    if f.torn_last_line { "yes".into() } else { "no".into() },
                ]
            })
            .collect();
        out.push_str(&markdown_table(
            &[
                ("Results file", Align::Left),
                ("Lines", Align::Right),
                ("Episodes", Align::Right),
                ("Failures", Align::Right),
                ("Skipped", Align::Right),
                ("Torn last line", Align::Left),
            ],
            &rows,
        ));
        out.push('\n');
        match &self.annotation_inputs {
            None => out.push_str("Annotations: none (Table 5 is not computed).\n\n"),
            Some(a) => {
                let files: Vec<String> = a.files.iter().map(|p| format!("`{}`", p.display())).collect();
                out.push_str(&format!(
                    "Annotations: {} ({}, {}).\n\n",
                    files.join(", "),
                    plural(a.annotations, "annotation"),
                    plural(a.failures, "failure line")
                ));
            }
        }
        out.push_str(&format!(
            "Episodes: {} kept of {} ({}, {}, view spaces {}); {} ({} superseded by a result). Budget \
             settings: {}.\n\n",
            c.episodes,
            plural(c.episode_lines, "result line"),
            plural(c.objects, "object"),
            plural(c.methods, "method"),
            if self.view_spaces.is_empty() {
                "none".to_string()
            } else {
                self.view_spaces.iter().map(|v| format!("`{v}`")).collect::<Vec<_>>().join(", ")
            },
            plural(c.failure_lines, "failure line"),
            c.failures_superseded,
            self.budget_settings.iter().map(|s| s.label()).collect::<Vec<_>>().join(", ")
        ));
        out.push_str(&format!(
            "Settings: τ = {}; Table 3 threshold NSC@{} ≥ {}; top {}; view spaces `{}` (Tables 2, 3, 5; A of \
             Table 4) and `{}` (B of Table 4); automatic setting of iterative planners at `{}`.\n\n",
            s.tau, s.tau, s.quality_threshold, s.top, s.space_a, s.space_b, s.auto_checkpoint
        ));
        out.push_str(
            "Checkpoints per setting: iterative planners run once and serve every setting (K=k: checkpoint \
             `K=k`, or `terminal` if the run ended first; Automatic: the MS checkpoint, or `terminal`); \
             budgeted plans enter K=k with their budget-k runs; set-cover plans enter Automatic with their \
             `auto` runs (and K=k with budget-k runs, if any), all at `terminal`.\n\n",
        );
        if !self.warnings.is_empty() {
            out.push_str("## Warnings\n\n");
            for w in &self.warnings {
                out.push_str(&format!("- {w}\n"));
            }
            out.push('\n');
        }
        out
    }

    fn figures_markdown(&self, figures: &[FigureFiles]) -> String {
        let mut out = "## Figures\n\n".to_string();
        if figures.is_empty() {
            out.push_str(if self.settings.plots {
                "_No data to plot._\n"
            } else {
                "_Not drawn (plots off)._\n"
            });
            return out;
        }
        for f in figures {
            out.push_str(&format!(
                "- `{}`: [PNG]({}), [SVG]({})\n\n  ![{}]({})\n\n",
                f.figure, f.png, f.svg, f.figure, f.png
            ));
        }
        out.push_str("Every plotted number is in `figures.json`.\n");
        out
    }

    fn json(&self, figures: &[FigureFiles]) -> Value {
        json!({
            "tool": "objview report",
            "version": VERSION,
            "inputs": val(&self.inputs),
            "annotations": val(&self.annotation_inputs),
            "settings": val(&self.settings),
            "budget_settings": val(&self.budget_settings),
            "view_spaces": self.view_spaces,
            "methods": self.methods,
            "taus": self.taus,
            "counts": val(&self.counts),
            "warnings": self.warnings,
            "duplicates": val(&self.duplicates),
            "failures": val(&self.failures),
            "skipped_lines": val(&self.skipped),
            "tables": {
                "table2_quality_top": val(&self.quality),
                "table3_path_top": val(&self.path_efficient),
                "table4_reachability": val(&self.reachability),
                "table5_map_stabilization": val(&self.map_stabilization),
                "terminal_reasons": val(&self.terminal),
                "solver_status": val(&self.solver),
            },
            "summary": val(&self.aggregates),
            "figures": val(figures),
        })
    }

    /// Writes the output folder (created if missing; see the module docs) and returns the files
    /// written: [`OUTPUT_FILES`] (without Table 5's CSV when there are no annotations), then the
    /// figures and `figures.json`. Same report → byte-identical files.
    pub fn write(&self, out_dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
        std::fs::create_dir_all(out_dir).map_err(|e| ReportError::io(out_dir, e))?;
        let tau = self.settings.tau.as_str();
        let (figure_paths, figures) = if self.settings.plots {
            let ctx =
                FigureContext { tau, threshold: self.settings.quality_threshold, methods: &self.methods };
            let (paths, listed, data) = write_figures(out_dir, &self.curves, &self.tradeoff, &ctx)?;
            let mut paths = paths;
            let figures_json = out_dir.join(objview_plot::FIGURES_JSON);
            let doc = json!({
                "tool": "objview report",
                "version": VERSION,
                "plot_version": objview_plot::VERSION,
                "font": objview_plot::font::FONT_DESCRIPTION,
                "inputs": val(&self.inputs),
                "settings": val(&self.settings),
                "files": val(&listed),
                "data": data,
            });
            write_text(&figures_json, &pretty(&doc))?;
            paths.push(figures_json);
            (paths, listed)
        } else {
            (Vec::new(), Vec::new())
        };

        let mut written = Vec::new();
        let mut put = |name: &str, text: String| -> Result<(), ReportError> {
            let path = out_dir.join(name);
            write_text(&path, &text)?;
            written.push(path);
            Ok(())
        };
        let md =
            format!("{}{}\n{}", self.header_markdown(), self.markdown(), self.figures_markdown(&figures));
        put(REPORT_MD, md)?;
        put(REPORT_JSON, pretty(&self.json(&figures)))?;
        put(SUMMARY_CSV, render::summary_csv(&self.aggregates, tau, &self.taus))?;
        put(TABLE2_CSV, render::ranked_csv(&self.quality, tau))?;
        put(TABLE3_CSV, render::ranked_csv(&self.path_efficient, tau))?;
        put(TABLE4_CSV, render::reach_csv(&self.reachability, tau))?;
        if let Some(t) = &self.map_stabilization {
            put(TABLE5_CSV, render::ms_csv(t, tau))?;
        }
        put(TERMINAL_CSV, render::terminal_csv(&self.terminal))?;
        put(FAILURES_CSV, render::failures_csv(&self.failures, &self.skipped, &self.inputs))?;
        written.extend(figure_paths);
        Ok(written)
    }
}

fn pretty(v: &Value) -> String {
    // Serializing a `Value` cannot fail.
    let mut s = serde_json::to_string_pretty(v).unwrap_or_default();
    s.push('\n');
    s
}

fn write_text(path: &Path, text: &str) -> Result<(), ReportError> {
    std::fs::write(path, text).map_err(|e| ReportError::io(path, e))
}

/// A serializable value as JSON. Our types have string keys and serializers that cannot fail;
/// a non-finite number becomes `null`.
fn val<T: Serialize + ?Sized>(x: &T) -> Value {
    serde_json::to_value(x).unwrap_or(Value::Null)
}
