//! Markdown and CSV renderings of the report's tables. Markdown follows the paper's number
//! formats (#Views and d_sat/d_plan 1 decimal, NSC/SC and their Δ 3 decimals, Table 5's ΔNSC 4,
//! path cost 2) with the definitions in notes under each table; CSV carries the same rows with 6
//! decimals for scripts. Both are pure functions of the table data.

use crate::aggregate::{Aggregate, Stat};
use crate::format::{
    csv, csv_decimals, csv_num, family_title, fixed, fixed_opt, markdown_table, plural, Align,
};
use crate::load::{FailureLine, InputFile, LineKeys, SkippedLine, Source};
use crate::tables::{MsTable, RankedTable, ReachTable, TerminalTable};

use Align::{Left, Right};

fn locate(files: &[InputFile], s: Source) -> String {
    files
        .get(s.file)
        .map_or_else(|| format!("#{}:{}", s.file, s.line), |f| format!("{}:{}", f.path.display(), s.line))
}

/// Tables 2 and 3 as Markdown rows.
fn ranked_rows(t: &RankedTable) -> Vec<Vec<String>> {
    t.rows
        .iter()
        .map(|r| {
            vec![
                r.setting.label(),
                r.rank.map_or_else(|| "ref".into(), |k| k.to_string()),
                r.method.clone(),
                family_title(r.family.as_str()),
                fixed(r.views, 1),
                fixed(r.nsc, 3),
                fixed(r.path_cost, 2),
                r.time_bin.clone(),
                r.n.to_string(),
            ]
        })
        .collect()
}

fn ranked_headers(tau: &str) -> Vec<(String, Align)> {
    vec![
        ("Setting".into(), Left),
        ("Rank".into(), Right),
        ("Method".into(), Left),
        ("Family".into(), Left),
        ("#Views".into(), Right),
        (format!("NSC@{tau}"), Right),
        ("Path Cost".into(), Right),
        ("Time bin (s)".into(), Left),
        ("N".into(), Right),
    ]
}

fn table(headers: &[(String, Align)], rows: &[Vec<String>]) -> String {
    let h: Vec<(&str, Align)> = headers.iter().map(|(s, a)| (s.as_str(), *a)).collect();
    markdown_table(&h, rows)
}

fn oracle_note(t: &RankedTable) -> Option<String> {
    t.rows.iter().any(|r| r.rank.is_none()).then(|| {
        "Rows ranked `ref` are oracle runs (they read the ground truth): references, not ranked.".to_string()
    })
}

fn notes(lines: &[String]) -> String {
    lines.iter().map(|l| format!("- {l}\n")).collect()
}

/// Table 2 in Markdown.
pub fn quality_markdown(t: &RankedTable, tau: &str, top: usize) -> String {
    let mut out = format!(
        "## Table 2: quality-oriented top-{top} per budget setting (view space `{}`)\n\n",
        t.view_space
    );
    if t.rows.is_empty() {
        out.push_str(&format!("_No episodes in view space `{}`._\n", t.view_space));
        return out;
    }
    out.push_str(&table(&ranked_headers(tau), &ranked_rows(t)));
    let mut n = vec![format!(
        "Ranked by mean NSC@{tau} (ties: lower path cost, then name). #Views include the start view; \
         Time bin: mean total planning time at the setting's checkpoint; N: episodes."
    )];
    n.extend(oracle_note(t));
    out.push('\n');
    out.push_str(&notes(&n));
    out
}

/// Table 3 in Markdown.
pub fn path_markdown(t: &RankedTable, tau: &str, top: usize, threshold: f64) -> String {
    let mut out = format!(
        "## Table 3: path-efficient top-{top} per budget setting (view space `{}`)\n\n",
        t.view_space
    );
    if t.counts.is_empty() {
        out.push_str(&format!("_No episodes in view space `{}`._\n", t.view_space));
        return out;
    }
    out.push_str(&table(&ranked_headers(tau), &ranked_rows(t)));
    let mut n = vec![format!(
        "Methods with mean NSC@{tau} ≥ {threshold}, ranked by mean path cost (ties: higher NSC, then name). \
         In fixed-budget settings read path cost together with #Views: iterative methods may stop early."
    )];
    let counts: Vec<String> = t
        .counts
        .iter()
        .map(|c| format!("{}: {} of {}", c.setting.label(), c.qualifying, c.methods))
        .collect();
    n.push(format!("Methods reaching the threshold: {}.", counts.join("; ")));
    n.extend(oracle_note(t));
    out.push('\n');
    out.push_str(&notes(&n));
    out
}

/// CSV of Table 2 or 3 (runtime in seconds besides its bin).
pub fn ranked_csv(t: &RankedTable, tau: &str) -> String {
    let headers: Vec<String> = [
        "view_space",
        "setting",
        "rank",
        "method",
        "family",
        "n",
        "views",
        &format!("nsc@{tau}"),
        "path_cost",
        "runtime_s",
        "time_bin_s",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            vec![
                t.view_space.clone(),
                r.setting.label(),
                r.rank.map_or_else(|| "ref".into(), |k| k.to_string()),
                r.method.clone(),
                r.family.to_string(),
                r.n.to_string(),
                csv_num(Some(r.views)),
                csv_num(Some(r.nsc)),
                csv_num(Some(r.path_cost)),
                csv_num(Some(r.runtime)),
                r.time_bin.clone(),
            ]
        })
        .collect();
    csv(&headers, &rows)
}

/// Short column tags of the two spaces: first letters (`W`/`Q`), or `A`/`B` when they clash.
pub fn space_tags(a: &str, b: &str) -> (String, String) {
    let tag = |s: &str| s.chars().next().map(|c| c.to_uppercase().collect::<String>()).unwrap_or_default();
    let (ta, tb) = (tag(a), tag(b));
    if ta.is_empty() || ta == tb {
        ("A".into(), "B".into())
    } else {
        (ta, tb)
    }
}

/// Table 4 in Markdown.
pub fn reach_markdown(t: &ReachTable, tau: &str) -> String {
    let (a, b) = space_tags(&t.space_a, &t.space_b);
    let mut out = format!(
        "## Table 4: reachability degradation, `{}` ({a}) vs `{}` ({b}), maximum-view setting\n\n",
        t.space_a, t.space_b
    );
    if t.rows.is_empty() {
        out.push_str(&format!("_No method has episodes in both `{}` and `{}`._\n", t.space_a, t.space_b));
    } else {
        let headers = vec![
            ("Method".to_string(), Left),
            ("Family".into(), Left),
            ("Setting".into(), Left),
            ("Objects".into(), Right),
            (format!("#Views {a}/{b}"), Right),
            (format!("NSC@{tau} {a}/{b}"), Right),
            ("ΔNSC".into(), Right),
            (format!("SC@{tau} {a}/{b}"), Right),
            ("ΔSC".into(), Right),
        ];
        let rows: Vec<Vec<String>> = t
            .rows
            .iter()
            .map(|r| {
                vec![
                    r.method.clone(),
                    family_title(r.family.as_str()),
                    r.setting.label(),
                    if r.paired {
                        r.common_objects.to_string()
                    } else {
                        format!("unpaired ({}/{} runs)", r.n.0, r.n.1)
                    },
                    format!("{}/{}", fixed(r.views.0, 1), fixed(r.views.1, 1)),
                    format!("{}/{}", fixed(r.nsc.0, 3), fixed(r.nsc.1, 3)),
                    fixed(r.delta_nsc, 3),
                    format!("{}/{}", fixed(r.sc.0, 3), fixed(r.sc.1, 3)),
                    fixed(r.delta_sc, 3),
                ]
            })
            .collect();
        out.push_str(&table(&headers, &rows));
        out.push('\n');
    }
    let mut n = vec![format!(
        "Setting: the budget setting, among those evaluated in both spaces, with the largest mean #Views in \
         `{}` (ties: the later of K=5, K=30, Automatic). Δ = {a} − {b}.",
        t.space_a
    )];
    n.push(
        "Objects: both sides restricted to the objects evaluated in both spaces under that setting \
         (`unpaired`: none in common, all runs used)."
            .into(),
    );
    let list = |v: &[String]| v.iter().map(|m| format!("`{m}`")).collect::<Vec<_>>().join(", ");
    if !t.only_a.is_empty() {
        n.push(format!("Only in `{}` (not compared): {}.", t.space_a, list(&t.only_a)));
    }
    if !t.only_b.is_empty() {
        n.push(format!("Only in `{}` (not compared): {}.", t.space_b, list(&t.only_b)));
    }
    if !t.no_common_setting.is_empty() {
        n.push(format!("No budget setting in common (not compared): {}.", list(&t.no_common_setting)));
    }
    out.push_str(&notes(&n));
    out
}

/// CSV of Table 4.
pub fn reach_csv(t: &ReachTable, tau: &str) -> String {
    let headers: Vec<String> = [
        "method",
        "family",
        "setting",
        "space_a",
        "space_b",
        "paired",
        "common_objects",
        "n_a",
        "n_b",
        "views_a",
        "views_b",
        &format!("nsc@{tau}_a"),
        &format!("nsc@{tau}_b"),
        "delta_nsc",
        &format!("sc@{tau}_a"),
        &format!("sc@{tau}_b"),
        "delta_sc",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                r.family.to_string(),
                r.setting.label(),
                t.space_a.clone(),
                t.space_b.clone(),
                r.paired.to_string(),
                r.common_objects.to_string(),
                r.n.0.to_string(),
                r.n.1.to_string(),
                csv_num(Some(r.views.0)),
                csv_num(Some(r.views.1)),
                csv_num(Some(r.nsc.0)),
                csv_num(Some(r.nsc.1)),
                csv_num(Some(r.delta_nsc)),
                csv_num(Some(r.sc.0)),
                csv_num(Some(r.sc.1)),
                csv_num(Some(r.delta_sc)),
            ]
        })
        .collect();
    csv(&headers, &rows)
}

/// Table 5 in Markdown; `None`: no annotations were given.
pub fn ms_markdown(t: Option<&MsTable>, tau: &str) -> String {
    let Some(t) = t else {
        return "## Table 5: map stabilization (oracle runs)\n\n_Not computed: no annotation files given \
                (Table 5 pools objects by their `slow_saturation` annotation)._\n"
            .into();
    };
    let mut out = format!(
        "## Table 5: map stabilization on main and slow-saturation objects (oracle runs, view space `{}`)\n\n",
        t.view_space
    );
    let methods: std::collections::BTreeSet<&str> = t.rows.iter().map(|r| r.method.as_str()).collect();
    let with_method = methods.len() > 1;
    if t.rows.is_empty() {
        out.push_str(&format!(
            "_No annotated oracle-family runs in view space `{}` ({} oracle runs, {} objects without annotation)._\n",
            t.view_space,
            t.oracle_runs,
            t.unannotated.len()
        ));
        return out;
    }
    let mut headers = Vec::new();
    if with_method {
        headers.push(("Method".to_string(), Left));
    }
    headers.extend([
        ("Pool".to_string(), Left),
        ("N".into(), Right),
        ("d_sat".into(), Right),
        ("d_plan".into(), Right),
        ("MS Views".into(), Right),
        ("MS NSC".into(), Right),
        ("Tammes-128 NSC".into(), Right),
        ("ΔNSC".into(), Right),
    ]);
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            let mut row = Vec::new();
            if with_method {
                row.push(r.method.clone());
            }
            row.extend([
                r.pool.clone(),
                r.objects.to_string(),
                fixed(r.d_sat, 1),
                fixed_opt(r.d_plan, 1),
                fixed(r.ms_views, 1),
                fixed(r.ms_nsc, 3),
                fixed(r.tammes_nsc, 3),
                fixed(r.delta_nsc, 4),
            ]);
            row
        })
        .collect();
    out.push_str(&table(&headers, &rows));
    out.push('\n');
    let mut n = vec![format!(
        "MS at checkpoint `{}`, NSC at τ = {tau}; Tammes-128 NSC at `terminal` (the run exhausts the 128 \
         candidates); ΔNSC = Tammes-128 NSC − MS NSC. N: objects; d_sat and d_plan: means over the objects \
         (d_plan over those with a proven d_plan); other columns: means over runs.",
        t.checkpoint
    )];
    for r in &t.rows {
        let who = if with_method { format!("{} / {}", r.method, r.pool) } else { r.pool.clone() };
        if r.runs != r.objects {
            n.push(format!(
                "{who}: {} of {} (several seeds).",
                plural(r.runs, "run"),
                plural(r.objects, "object")
            ));
        }
        if r.with_d_plan != r.objects {
            n.push(format!(
                "{who}: d_plan over the {} of {} objects with a proven d_plan.",
                r.with_d_plan, r.objects
            ));
        }
        if r.ms_missing > 0 {
            n.push(format!(
                "{who}: {} of {} runs never reached `{}`; their `terminal` is used for the MS columns.",
                r.ms_missing, r.runs, t.checkpoint
            ));
        }
    }
    if !t.unannotated.is_empty() {
        let shown: Vec<String> = t.unannotated.iter().take(10).map(|u| format!("`{u}`")).collect();
        let more = t.unannotated.len().saturating_sub(10);
        n.push(format!(
            "Left out, without an annotation: {} of oracle runs ({}{}).",
            plural(t.unannotated.len(), "object"),
            shown.join(", "),
            if more > 0 { format!(", and {more} more") } else { String::new() }
        ));
    }
    let reasons: Vec<String> = t.terminal_reasons.iter().map(|(r, c)| format!("{c} `{r}`")).collect();
    let views: Vec<String> = t
        .rows
        .iter()
        .map(|r| {
            let who = if with_method { format!("{} / {}", r.method, r.pool) } else { r.pool.clone() };
            format!("{who} {}", fixed(r.tammes_views, 1))
        })
        .collect();
    n.push(format!(
        "Runs end by exhausting the candidates (`candidate_exhausted`, or `max_cap_reached` when the cap \
         comes with the last one); here: {}; mean #Views at `terminal`: {}.",
        reasons.join(", "),
        views.join(", ")
    ));
    if t.terminal_reasons.keys().any(|r| r != "candidate_exhausted" && r != "max_cap_reached") {
        n.push(
            "Some runs ended otherwise: their `terminal` is not a full Tammes-128 reference (see \
             `terminal_reasons.csv`)."
                .into(),
        );
    }
    out.push_str(&notes(&n));
    out
}

/// CSV of Table 5.
pub fn ms_csv(t: &MsTable, tau: &str) -> String {
    let headers: Vec<String> = [
        "method",
        "pool",
        "view_space",
        "objects",
        "runs",
        "d_sat",
        "d_plan",
        "with_d_plan",
        "ms_views",
        &format!("ms_nsc@{tau}"),
        &format!("tammes128_nsc@{tau}"),
        "tammes128_views",
        "delta_nsc",
        "ms_missing",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                r.pool.clone(),
                t.view_space.clone(),
                r.objects.to_string(),
                r.runs.to_string(),
                csv_num(Some(r.d_sat)),
                csv_num(r.d_plan),
                r.with_d_plan.to_string(),
                csv_num(Some(r.ms_views)),
                csv_num(Some(r.ms_nsc)),
                csv_num(Some(r.tammes_nsc)),
                csv_num(Some(r.tammes_views)),
                csv_num(Some(r.delta_nsc)),
                r.ms_missing.to_string(),
            ]
        })
        .collect();
    csv(&headers, &rows)
}

fn or_unknown(s: &str) -> String {
    if s.is_empty() {
        "(unknown)".into()
    } else {
        s.to_string()
    }
}

/// The terminal-reason summary in Markdown.
pub fn terminal_markdown(t: &TerminalTable) -> String {
    let mut out = "## Terminal reasons and failures per view space and method\n\n".to_string();
    if t.rows.is_empty() {
        out.push_str("_No episodes._\n");
        return out;
    }
    let mut headers = vec![
        ("View space".to_string(), Left),
        ("Method".into(), Left),
        ("Family".into(), Left),
        ("Episodes".into(), Right),
    ];
    headers.extend(t.reasons.iter().map(|r| (r.clone(), Right)));
    headers.push(("Failures".into(), Right));
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            let mut row = vec![
                or_unknown(&r.view_space),
                or_unknown(&r.method),
                family_title(r.family.as_str()),
                r.episodes.to_string(),
            ];
            row.extend(t.reasons.iter().map(|k| r.reasons.get(k).copied().unwrap_or(0).to_string()));
            row.push(r.failures.to_string());
            row
        })
        .collect();
    out.push_str(&table(&headers, &rows));
    out.push('\n');
    out.push_str(&notes(&[
        "Episodes after removing duplicates; Failures: failure lines (episodes that could not run) not \
         superseded by a result for the same episode."
            .to_string(),
    ]));
    out
}

/// CSV of the terminal-reason summary (one column per reason that occurs).
pub fn terminal_csv(t: &TerminalTable) -> String {
    let mut headers: Vec<String> =
        ["view_space", "method", "family", "episodes"].iter().map(|s| s.to_string()).collect();
    headers.extend(t.reasons.iter().cloned());
    headers.push("failures".into());
    let rows: Vec<Vec<String>> = t
        .rows
        .iter()
        .map(|r| {
            let mut row =
                vec![r.view_space.clone(), r.method.clone(), r.family.to_string(), r.episodes.to_string()];
            row.extend(t.reasons.iter().map(|k| r.reasons.get(k).copied().unwrap_or(0).to_string()));
            row.push(r.failures.to_string());
            row
        })
        .collect();
    csv(&headers, &rows)
}

/// The failure lines in Markdown (the first `limit`).
pub fn failures_markdown(failures: &[FailureLine], files: &[InputFile], limit: usize) -> String {
    let mut out = "## Failure lines\n\n".to_string();
    if failures.is_empty() {
        out.push_str("_None: every episode line is a result._\n");
        return out;
    }
    let headers = [
        ("Line", Left),
        ("uid", Left),
        ("Method", Left),
        ("View space", Left),
        ("Budget", Left),
        ("Seed", Right),
        ("Error", Left),
    ];
    let rows: Vec<Vec<String>> = failures
        .iter()
        .take(limit)
        .map(|f| {
            let error =
                if f.superseded { format!("{} (superseded by a result)", f.error) } else { f.error.clone() };
            std::iter::once(locate(files, f.source)).chain(f.keys.cells()).chain([error]).collect()
        })
        .collect();
    out.push_str(&markdown_table(&headers, &rows));
    if failures.len() > limit {
        out.push_str(&format!("\n{} more in `failures.csv`.\n", failures.len() - limit));
    }
    out
}

/// The skipped lines in Markdown (the first `limit`).
pub fn skipped_markdown(skipped: &[SkippedLine], files: &[InputFile], limit: usize) -> String {
    let mut out = "## Skipped lines\n\n".to_string();
    out.push_str("Lines left out of every table: not usable as an episode result or a failure line.\n\n");
    let headers = [
        ("Line", Left),
        ("uid", Left),
        ("Method", Left),
        ("View space", Left),
        ("Budget", Left),
        ("Seed", Right),
        ("Reason", Left),
    ];
    let rows: Vec<Vec<String>> = skipped
        .iter()
        .take(limit)
        .map(|s| {
            std::iter::once(locate(files, s.source)).chain(s.keys.cells()).chain([s.reason.clone()]).collect()
        })
        .collect();
    out.push_str(&markdown_table(&headers, &rows));
    if skipped.len() > limit {
        out.push_str(&format!("\n{} more in `failures.csv`.\n", skipped.len() - limit));
    }
    out
}

/// CSV of the failure lines, then the skipped lines (`kind`: `failure` or `skipped_line`; the
/// `error` of a skipped line is why it was skipped, `superseded` is empty).
pub fn failures_csv(failures: &[FailureLine], skipped: &[SkippedLine], files: &[InputFile]) -> String {
    let headers: Vec<String> =
        ["kind", "file", "line", "uid", "method", "view_space", "budget", "seed", "superseded", "error"]
            .iter()
            .map(|s| s.to_string())
            .collect();
    // kind, file, line, the episode keys, superseded, error.
    let row = |kind: &str, source: Source, keys: &LineKeys, superseded: String, error: &str| -> Vec<String> {
        let file = files.get(source.file).map(|i| i.path.display().to_string()).unwrap_or_default();
        [kind.to_string(), file, source.line.to_string()]
            .into_iter()
            .chain(keys.cells())
            .chain([superseded, error.to_string()])
            .collect()
    };
    let mut rows: Vec<Vec<String>> = failures
        .iter()
        .map(|f| row("failure", f.source, &f.keys, f.superseded.to_string(), &f.error))
        .collect();
    rows.extend(skipped.iter().map(|s| row("skipped_line", s.source, &s.keys, String::new(), &s.reason)));
    csv(&headers, &rows)
}

/// `summary.csv`: every aggregate with means and standard deviations.
pub fn summary_csv(aggregates: &[Aggregate], tau: &str, taus: &[String]) -> String {
    let mut headers: Vec<String> = [
        "setting",
        "view_space",
        "method",
        "family",
        "execution_mode",
        "n",
        "objects",
        "from_step",
        "terminal_fallback",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let stat_cols = |name: &str| [format!("{name}_mean"), format!("{name}_std")];
    headers.extend(stat_cols("views"));
    headers.extend(stat_cols(&format!("nsc@{tau}")));
    headers.extend(stat_cols(&format!("sc@{tau}")));
    let others: Vec<&String> = taus.iter().filter(|t| t.as_str() != tau).collect();
    for t in &others {
        headers.extend(stat_cols(&format!("nsc@{t}")));
        headers.extend(stat_cols(&format!("sc@{t}")));
    }
    headers.extend(stat_cols("cd"));
    headers.extend(stat_cols("path_cost"));
    headers.extend(stat_cols("runtime_s"));
    headers.push("time_bin_s".into());
    let stat = |s: Option<&Stat>| match s {
        Some(s) => [csv_num(Some(s.mean)), csv_num(s.std)],
        None => [String::new(), String::new()],
    };
    let rows: Vec<Vec<String>> = aggregates
        .iter()
        .map(|a| {
            let mut row = vec![
                a.setting.label(),
                a.view_space.clone(),
                a.method.clone(),
                a.family.to_string(),
                a.execution_mode.to_string(),
                a.n.to_string(),
                a.objects.to_string(),
                a.from_step.to_string(),
                a.terminal_fallback.to_string(),
            ];
            row.extend(stat(Some(&a.views)));
            row.extend(stat(Some(&a.nsc)));
            row.extend(stat(Some(&a.sc)));
            for t in &others {
                row.extend(stat(a.nsc_by_tau.get(*t)));
                row.extend(stat(a.sc_by_tau.get(*t)));
            }
            // Chamfer distances are small (units²): 9 decimals.
            row.extend([csv_decimals(Some(a.cd.mean), 9), csv_decimals(a.cd.std, 9)]);
            row.extend(stat(Some(&a.path_cost)));
            row.extend(stat(Some(&a.runtime)));
            row.push(crate::format::time_bin(a.runtime.mean).to_string());
            row
        })
        .collect();
    csv(&headers, &rows)
}

/// The solver-status summary in Markdown (empty when no episode carries plan notes).
pub fn solver_markdown(rows: &[crate::tables::SolverRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let headers = [
        ("View space".to_string(), Align::Left),
        ("Method".to_string(), Align::Left),
        ("Budget".to_string(), Align::Left),
        ("Plans".to_string(), Align::Right),
        ("Selection ILP".to_string(), Align::Left),
        ("Max gap".to_string(), Align::Right),
        ("Paths not proven shortest".to_string(), Align::Right),
    ];
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let sel: Vec<String> = r.selection.iter().map(|(s, c)| format!("{c} `{s}`")).collect();
            vec![
                r.view_space.clone(),
                r.method.clone(),
                r.budget.clone(),
                r.plans.to_string(),
                if sel.is_empty() { "—".into() } else { sel.join(", ") },
                r.max_gap.map_or("—".into(), |g| format!("{g}")),
                format!("{} of {}", r.paths_not_proven, r.paths),
            ]
        })
        .collect();
    format!(
        "## Exact solver status\n\nFrom the planners' `planner_notes.plan`: the selection ILP's status per \
         plan (`optimal` only when proven; `time_limit` keeps its incumbent, and the gap to its proven \
         bound is in voxels or views) and the open-path solves not proven shortest.\n\n{}",
        table(&headers, &body)
    )
}
