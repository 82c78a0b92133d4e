//! The data of the paper's Tables 2–5 and of the terminal-reason summary, computed from the
//! per-(setting, view space, method) aggregates and the per-episode picks (paper §6, SPEC §5).
//! Rendering to Markdown and CSV lives in [`crate::render`].
//!
//! Definitions (where the paper is terse, the choice made is stated):
//! - Table 2 ranks methods per budget setting by mean NSC@τ, descending (ties: path cost, then
//!   name); Table 3 keeps those with mean NSC@τ ≥ the quality threshold and ranks them by mean
//!   path cost, ascending (ties: NSC descending, then name). The oracle family is never ranked;
//!   its rows are listed as references.
//! - Table 4 compares view spaces A (`whole`) and B (`quarter`) under each method's
//!   maximum-view setting: among the settings the method has in both spaces, the one with the
//!   largest mean #Views in A (ties: the later setting). Both sides are restricted to the objects
//!   evaluated in both spaces when there are any (the count is reported); Δ = A − B.
//! - Table 5 uses oracle-family runs in view space A, pooled by the annotation's
//!   `slow_saturation`: MS columns at the MS checkpoint (`terminal` for runs where MS never
//!   triggered, counted), Tammes-128 NSC at `terminal` (the run exhausts the 128 candidates).
//!   d_sat and d_plan are means over the pool's objects (d_plan over those with a proven one),
//!   the other columns means over runs.
//! - The solver-status summary counts, per (view space, method, budget), the statuses of the
//!   exact steps that planners record in `planner_notes.plan` (the hybrids' selection ILP:
//!   `selection.status`, `selection.gap`; every open-path solve: `tsp.optimal`), so a plan
//!   stopped by a time limit is visible next to the numbers it produced.

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet};

use objview_dataset::Annotation;
use objview_episode::{CheckpointKey, Family};
use serde::Serialize;

use crate::aggregate::{nsc, sc, Aggregate, GroupKey, Stat};
use crate::format::{family_rank, time_bin};
use crate::load::{Episode, FailureLine};
use crate::select::{Pick, Setting};

/// A row of Table 2 or 3.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RankedRow {
    /// The budget setting.
    pub setting: Setting,
    /// 1-based rank; `None` for an oracle reference row.
    pub rank: Option<usize>,
    /// Method name.
    pub method: String,
    /// The family (`classical`, …).
    pub family: Family,
    /// Episodes.
    pub n: usize,
    /// Mean #Views.
    pub views: f64,
    /// Mean NSC@τ.
    pub nsc: f64,
    /// Mean path cost.
    pub path_cost: f64,
    /// Mean total planning time (s) and its bin.
    pub runtime: f64,
    /// The bin of `runtime` (`<0.1`, …).
    pub time_bin: String,
}

/// How many methods a setting had, and how many qualified (Table 3's threshold).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SettingCount {
    /// The budget setting.
    pub setting: Setting,
    /// Ranked (non-oracle) methods with episodes in the setting.
    pub methods: usize,
    /// Of those, the ones that pass the filter (all of them for Table 2).
    pub qualifying: usize,
}

/// Table 2 or 3: per setting, the top methods then the references.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RankedTable {
    /// View space of the table.
    pub view_space: String,
    /// Rows, setting by setting.
    pub rows: Vec<RankedRow>,
    /// Per setting, the candidates and how many passed.
    pub counts: Vec<SettingCount>,
}

fn ranked_row(a: &Aggregate, rank: Option<usize>) -> RankedRow {
    RankedRow {
        setting: a.setting,
        rank,
        method: a.method.clone(),
        family: a.family,
        n: a.n,
        views: a.views.mean,
        nsc: a.nsc.mean,
        path_cost: a.path_cost.mean,
        runtime: a.runtime.mean,
        time_bin: time_bin(a.runtime.mean).to_string(),
    }
}

fn by_quality(a: &&Aggregate, b: &&Aggregate) -> Ordering {
    b.nsc
        .mean
        .total_cmp(&a.nsc.mean)
        .then(a.path_cost.mean.total_cmp(&b.path_cost.mean))
        .then(a.method.cmp(&b.method))
}

fn by_path(a: &&Aggregate, b: &&Aggregate) -> Ordering {
    a.path_cost
        .mean
        .total_cmp(&b.path_cost.mean)
        .then(b.nsc.mean.total_cmp(&a.nsc.mean))
        .then(a.method.cmp(&b.method))
}

/// Tables 2 and 3: per setting, the methods of `view_space` passing `keep`, sorted by `order`,
/// the first `top` ranked; oracle rows (sorted by name) follow as references.
fn ranked(
    aggregates: &[Aggregate],
    view_space: &str,
    settings: &[Setting],
    top: usize,
    keep: impl Fn(&Aggregate) -> bool,
    order: fn(&&Aggregate, &&Aggregate) -> Ordering,
) -> RankedTable {
    let mut rows = Vec::new();
    let mut counts = Vec::new();
    for &setting in settings {
        let here: Vec<&Aggregate> =
            aggregates.iter().filter(|a| a.setting == setting && a.view_space == view_space).collect();
        if here.is_empty() {
            continue;
        }
        // The oracle family reads the ground truth: never ranked, shown as a reference.
        let ranked_ones: Vec<&Aggregate> =
            here.iter().copied().filter(|a| a.family != Family::Oracle).collect();
        let mut passing: Vec<&Aggregate> = ranked_ones.iter().copied().filter(|a| keep(a)).collect();
        passing.sort_by(order);
        counts.push(SettingCount { setting, methods: ranked_ones.len(), qualifying: passing.len() });
        rows.extend(passing.iter().take(top).enumerate().map(|(i, a)| ranked_row(a, Some(i + 1))));
        rows.extend(here.iter().filter(|a| a.family == Family::Oracle).map(|a| ranked_row(a, None)));
    }
    RankedTable { view_space: view_space.to_string(), rows, counts }
}

/// Table 2: quality-oriented top `top` per setting in `view_space`.
pub fn quality_top(
    aggregates: &[Aggregate],
    view_space: &str,
    settings: &[Setting],
    top: usize,
) -> RankedTable {
    ranked(aggregates, view_space, settings, top, |_| true, by_quality)
}

/// Table 3: path-efficient top `top` per setting among methods with mean NSC ≥ `threshold`.
pub fn path_top(
    aggregates: &[Aggregate],
    view_space: &str,
    settings: &[Setting],
    top: usize,
    threshold: f64,
) -> RankedTable {
    ranked(aggregates, view_space, settings, top, |a| a.nsc.mean >= threshold, by_path)
}

/// A row of Table 4: values are (space A, space B).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReachRow {
    /// Method name.
    pub method: String,
    /// The family.
    pub family: Family,
    /// The maximum-view setting.
    pub setting: Setting,
    /// Whether both sides were restricted to the common objects.
    pub paired: bool,
    /// Objects evaluated in both spaces under the setting (0: none in common, so unpaired).
    pub common_objects: usize,
    /// Episodes used on each side.
    pub n: (usize, usize),
    /// Mean #Views.
    pub views: (f64, f64),
    /// Mean NSC@τ.
    pub nsc: (f64, f64),
    /// NSC A − NSC B.
    pub delta_nsc: f64,
    /// Mean SC@τ.
    pub sc: (f64, f64),
    /// SC A − SC B.
    pub delta_sc: f64,
}

/// Table 4.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReachTable {
    /// View space A (`whole`).
    pub space_a: String,
    /// View space B (`quarter`).
    pub space_b: String,
    /// Rows in family order, then by method.
    pub rows: Vec<ReachRow>,
    /// Methods with episodes in space A only.
    pub only_a: Vec<String>,
    /// Methods with episodes in space B only.
    pub only_b: Vec<String>,
    /// Methods in both spaces without a setting in common.
    pub no_common_setting: Vec<String>,
}

/// Means over `picks` of (#Views, NSC@τ, SC@τ), with the number of picks.
fn view_quality(picks: &[&Pick], tau: &str) -> (usize, f64, f64, f64) {
    let mean = |f: &dyn Fn(&Pick) -> f64| {
        Stat::of(&picks.iter().map(|p| f(p)).collect::<Vec<_>>()).map_or(f64::NAN, |s| s.mean)
    };
    (
        picks.len(),
        mean(&|p| p.metrics.views as f64),
        mean(&|p| nsc(&p.metrics, tau)),
        mean(&|p| sc(&p.metrics, tau)),
    )
}

fn uids<'a>(picks: &'a [Pick]) -> BTreeSet<&'a str> {
    picks.iter().map(|p| p.episode.result.uid.as_str()).collect()
}

/// The picks of objects in `common` (all of them when not `paired`).
fn kept<'a, 'b>(picks: &'a [Pick<'b>], paired: bool, common: &BTreeSet<&str>) -> Vec<&'a Pick<'b>> {
    picks.iter().filter(|p| !paired || common.contains(p.episode.result.uid.as_str())).collect()
}

/// Table 4 (module docs) from the aggregates and the picks, at τ key `tau`. Rows in family
/// order, then by method name.
pub fn reachability(
    aggregates: &[Aggregate],
    groups: &BTreeMap<GroupKey, Vec<Pick>>,
    space_a: &str,
    space_b: &str,
    tau: &str,
) -> ReachTable {
    let methods_in = |space: &str| -> BTreeSet<&str> {
        aggregates.iter().filter(|a| a.view_space == space).map(|a| a.method.as_str()).collect()
    };
    let (in_a, in_b) = (methods_in(space_a), methods_in(space_b));
    let mut table = ReachTable {
        space_a: space_a.to_string(),
        space_b: space_b.to_string(),
        rows: Vec::new(),
        only_a: in_a.difference(&in_b).map(|s| s.to_string()).collect(),
        only_b: in_b.difference(&in_a).map(|s| s.to_string()).collect(),
        no_common_setting: Vec::new(),
    };
    for &method in in_a.intersection(&in_b) {
        let has_b = |setting: Setting| {
            aggregates.iter().any(|a| a.method == method && a.view_space == space_b && a.setting == setting)
        };
        // The maximum-view setting among those evaluated in both spaces; ties → the later one.
        let best = aggregates
            .iter()
            .filter(|a| a.method == method && a.view_space == space_a && has_b(a.setting))
            .max_by(|x, y| x.views.mean.total_cmp(&y.views.mean).then(x.setting.cmp(&y.setting)));
        let Some(best) = best else {
            table.no_common_setting.push(method.to_string());
            continue;
        };
        let side = |space: &str| {
            groups.get(&(best.setting, space.to_string(), method.to_string())).map_or(&[][..], Vec::as_slice)
        };
        let (pa, pb) = (side(space_a), side(space_b));
        let common: BTreeSet<&str> = uids(pa).intersection(&uids(pb)).copied().collect();
        let paired = !common.is_empty();
        let (na, views_a, nsc_a, sc_a) = view_quality(&kept(pa, paired, &common), tau);
        let (nb, views_b, nsc_b, sc_b) = view_quality(&kept(pb, paired, &common), tau);
        table.rows.push(ReachRow {
            method: method.to_string(),
            family: best.family,
            setting: best.setting,
            paired,
            common_objects: common.len(),
            n: (na, nb),
            views: (views_a, views_b),
            nsc: (nsc_a, nsc_b),
            delta_nsc: nsc_a - nsc_b,
            sc: (sc_a, sc_b),
            delta_sc: sc_a - sc_b,
        });
    }
    table.rows.sort_by(|x, y| {
        family_rank(x.family.as_str())
            .cmp(&family_rank(y.family.as_str()))
            .then(x.family.as_str().cmp(y.family.as_str()))
            .then(x.method.cmp(&y.method))
    });
    table
}

/// The two pools of Table 5 (by the annotation's `slow_saturation`).
pub const POOLS: [&str; 2] = ["Main", "Slow-Saturation"];

/// A row of Table 5.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MsRow {
    /// The oracle method.
    pub method: String,
    /// `Main` or `Slow-Saturation`.
    pub pool: String,
    /// Distinct objects (N).
    pub objects: usize,
    /// Runs (one per object unless several seeds were run).
    pub runs: usize,
    /// Mean d_sat over the objects.
    pub d_sat: f64,
    /// Mean d_plan over the objects with a proven d_plan, and their number.
    pub d_plan: Option<f64>,
    /// Objects with a proven d_plan.
    pub with_d_plan: usize,
    /// Means over runs at the MS checkpoint.
    pub ms_views: f64,
    /// Mean NSC@τ at the MS checkpoint.
    pub ms_nsc: f64,
    /// Mean NSC at `terminal` (the 128 candidates exhausted).
    pub tammes_nsc: f64,
    /// Mean #Views at `terminal` (129 when every tammes-128 candidate was taken).
    pub tammes_views: f64,
    /// `tammes_nsc − ms_nsc`.
    pub delta_nsc: f64,
    /// Runs without the MS checkpoint (their `terminal` is used for the MS columns).
    pub ms_missing: usize,
}

/// Table 5.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MsTable {
    /// View space of the oracle runs.
    pub view_space: String,
    /// The MS checkpoint (`MS@0.02`).
    pub checkpoint: CheckpointKey,
    /// Rows by method, then pool (Main first).
    pub rows: Vec<MsRow>,
    /// Oracle runs in the view space, annotated or not.
    pub oracle_runs: usize,
    /// Objects of oracle runs without an annotation (left out), sorted.
    pub unannotated: Vec<String>,
    /// Terminal reasons of the annotated oracle runs used: `candidate_exhausted`, or
    /// `max_cap_reached` when the cap (129 views = start + 128) comes with the last candidate.
    pub terminal_reasons: BTreeMap<String, usize>,
}

/// Table 5 (module docs): oracle-family episodes of `view_space`, pooled by `annotations`.
pub fn map_stabilization(
    episodes: &[Episode],
    annotations: &[Annotation],
    view_space: &str,
    checkpoint: &CheckpointKey,
    tau: &str,
) -> MsTable {
    let by_uid: BTreeMap<&str, &Annotation> = annotations.iter().map(|a| (a.uid.as_str(), a)).collect();
    let oracle: Vec<&Episode> = episodes
        .iter()
        .filter(|e| e.result.family == Family::Oracle && e.result.view_space == view_space)
        .collect();
    let mut table = MsTable {
        view_space: view_space.to_string(),
        checkpoint: *checkpoint,
        rows: Vec::new(),
        oracle_runs: oracle.len(),
        unannotated: Vec::new(),
        terminal_reasons: BTreeMap::new(),
    };
    let mut unannotated = BTreeSet::new();
    // (method, pool index) → runs with their annotation.
    let mut pools: BTreeMap<(&str, usize), Vec<(&Episode, &Annotation)>> = BTreeMap::new();
    for e in oracle {
        let Some(a) = by_uid.get(e.result.uid.as_str()) else {
            unannotated.insert(e.result.uid.clone());
            continue;
        };
        *table.terminal_reasons.entry(e.result.terminal_reason.clone()).or_default() += 1;
        pools.entry((e.result.method.as_str(), usize::from(a.slow_saturation))).or_default().push((e, a));
    }
    table.unannotated = unannotated.into_iter().collect();
    for ((method, pool), runs) in pools {
        let objects: BTreeMap<&str, &Annotation> = runs.iter().map(|(_, a)| (a.uid.as_str(), *a)).collect();
        let mean = |v: Vec<f64>| Stat::of(&v).map(|s| s.mean);
        let d_plans: Vec<f64> = objects.values().filter_map(|a| a.d_plan.map(|d| d as f64)).collect();
        let mut ms_missing = 0;
        let mut ms = Vec::new();
        let mut tammes = Vec::new();
        let mut tammes_views = Vec::new();
        for (e, _) in &runs {
            let cps = &e.result.checkpoints;
            let Some(end) = cps.get(&CheckpointKey::Terminal) else { continue };
            let at_ms = match cps.get(checkpoint) {
                Some(c) => c,
                None => {
                    ms_missing += 1;
                    end
                }
            };
            ms.push(&at_ms.metrics);
            tammes.push(nsc(&end.metrics, tau));
            tammes_views.push(end.metrics.views as f64);
        }
        let ms_nsc = mean(ms.iter().map(|m| nsc(m, tau)).collect()).unwrap_or(f64::NAN);
        let tammes_nsc = mean(tammes).unwrap_or(f64::NAN);
        table.rows.push(MsRow {
            method: method.to_string(),
            pool: POOLS[pool].to_string(),
            objects: objects.len(),
            runs: runs.len(),
            d_sat: mean(objects.values().map(|a| a.d_sat as f64).collect()).unwrap_or(f64::NAN),
            with_d_plan: d_plans.len(),
            d_plan: mean(d_plans),
            ms_views: mean(ms.iter().map(|m| m.views as f64).collect()).unwrap_or(f64::NAN),
            ms_nsc,
            tammes_nsc,
            tammes_views: mean(tammes_views).unwrap_or(f64::NAN),
            delta_nsc: tammes_nsc - ms_nsc,
            ms_missing,
        });
    }
    table
}

/// Terminal reasons in report order; others follow alphabetically.
pub const KNOWN_REASONS: [&str; 10] = [
    "plan_end",
    "budget_reached",
    "candidate_exhausted",
    "next_view_visited",
    "next_view_infeasible",
    "invalid_action",
    "max_cap_reached",
    "enough_info",
    "planner_error",
    "timeout",
];

/// A row of the terminal-reason summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TerminalRow {
    /// View space.
    pub view_space: String,
    /// Method name (empty for failure lines that name none).
    pub method: String,
    /// Empty when only failure lines (which may not name it) are known.
    pub family: String,
    /// Episodes (after removing duplicates).
    pub episodes: usize,
    /// Episodes per terminal reason.
    pub reasons: BTreeMap<String, usize>,
    /// Failure lines (episodes that could not run) not superseded by a result.
    pub failures: usize,
}

/// The terminal-reason summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TerminalTable {
    /// Reasons that occur, in report order.
    pub reasons: Vec<String>,
    /// Rows by view space, family order, method.
    pub rows: Vec<TerminalRow>,
}

/// Counts of terminal reasons per (view space, method), with the failure lines.
pub fn terminal_summary(episodes: &[Episode], failures: &[FailureLine]) -> TerminalTable {
    let mut rows: BTreeMap<(String, String), TerminalRow> = BTreeMap::new();
    fn row<'a>(
        rows: &'a mut BTreeMap<(String, String), TerminalRow>,
        space: &str,
        method: &str,
    ) -> &'a mut TerminalRow {
        rows.entry((space.to_string(), method.to_string())).or_insert_with(|| TerminalRow {
            view_space: space.to_string(),
            method: method.to_string(),
            family: String::new(),
            episodes: 0,
            reasons: BTreeMap::new(),
            failures: 0,
        })
    }
    for e in episodes {
        let r = row(&mut rows, &e.result.view_space, &e.result.method);
        r.family = e.result.family.to_string();
        r.episodes += 1;
        *r.reasons.entry(e.result.terminal_reason.clone()).or_default() += 1;
    }
    for f in failures.iter().filter(|f| !f.superseded) {
        row(&mut rows, &f.keys.view_space, &f.keys.method).failures += 1;
    }
    let present: BTreeSet<&str> = rows.values().flat_map(|r| r.reasons.keys().map(String::as_str)).collect();
    let mut reasons: Vec<String> =
        KNOWN_REASONS.iter().filter(|r| present.contains(*r)).map(|r| r.to_string()).collect();
    reasons.extend(present.iter().filter(|r| !KNOWN_REASONS.contains(r)).map(|r| r.to_string()));
    let mut rows: Vec<TerminalRow> = rows.into_values().collect();
    rows.sort_by(|x, y| {
        x.view_space
            .cmp(&y.view_space)
            .then(family_rank(&x.family).cmp(&family_rank(&y.family)))
            .then(x.family.cmp(&y.family))
            .then(x.method.cmp(&y.method))
    });
    TerminalTable { reasons, rows }
}

/// A row of the solver-status summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolverRow {
    /// View space.
    pub view_space: String,
    /// Method name.
    pub method: String,
    /// Budget label (`5`, `auto`, …).
    pub budget: String,
    /// Episodes whose notes hold a plan.
    pub plans: usize,
    /// Plans per selection status (`optimal`, `time_limit`, `skipped`, `error: …`); empty for
    /// planners without a selection step.
    pub selection: BTreeMap<String, usize>,
    /// Largest recorded selection gap (|objective − proven bound|; 0 when every solve was
    /// proven), `None` without a selection step.
    pub max_gap: Option<f64>,
    /// Plans with an open-path solve, and those whose path is not proven shortest.
    pub paths: usize,
    /// See `paths`.
    pub paths_not_proven: usize,
}

/// Per (view space, method, budget), what the planners' exact steps reported
/// (`planner_notes.plan`); rows only for episodes that carry such notes, sorted by view space,
/// method, budget (numeric, `auto` last).
pub fn solver_summary(episodes: &[Episode]) -> Vec<SolverRow> {
    // Budgets in numeric order, `auto` last.
    let mut rows: BTreeMap<(String, String, usize), SolverRow> = BTreeMap::new();
    for e in episodes {
        let Some(plan) = e.result.planner_notes.as_ref().and_then(|n| n.get("plan")) else { continue };
        let budget = e.result.budget.label();
        let rank = match e.result.budget {
            objview_episode::Budget::Fixed(k) => k,
            objview_episode::Budget::Auto => usize::MAX,
        };
        let r =
            rows.entry((e.result.view_space.clone(), e.result.method.clone(), rank)).or_insert_with(|| {
                SolverRow {
                    view_space: e.result.view_space.clone(),
                    method: e.result.method.clone(),
                    budget,
                    plans: 0,
                    selection: BTreeMap::new(),
                    max_gap: None,
                    paths: 0,
                    paths_not_proven: 0,
                }
            });
        r.plans += 1;
        if let Some(sel) = plan.get("selection") {
            let status = sel.get("status").and_then(|s| s.as_str()).unwrap_or("unknown");
            *r.selection.entry(status.to_string()).or_default() += 1;
            // A gap the line could not state (null) counts as unbounded.
            let gap = sel.get("gap").map_or(0.0, |g| g.as_f64().unwrap_or(f64::INFINITY));
            r.max_gap = Some(r.max_gap.map_or(gap, |m: f64| m.max(gap)));
        }
        if let Some(tsp) = plan.get("tsp").filter(|t| !t.is_null()) {
            r.paths += 1;
            if tsp.get("optimal").and_then(|o| o.as_bool()) != Some(true) {
                r.paths_not_proven += 1;
            }
        } else if plan.get("tsp_error").is_some_and(|e| !e.is_null()) {
            // A path solve that failed (the plan kept another order): not proven shortest.
            r.paths += 1;
            r.paths_not_proven += 1;
        }
    }
    rows.into_values().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_episode::ExecutionMode;

    fn stat(mean: f64) -> Stat {
        Stat { mean, std: None }
    }

    fn agg(
        setting: Setting,
        method: &str,
        family: Family,
        views: f64,
        nsc: f64,
        path_cost: f64,
    ) -> Aggregate {
        Aggregate {
            setting,
            view_space: "whole".into(),
            method: method.into(),
            family,
            execution_mode: ExecutionMode::Iterative,
            n: 1,
            objects: 1,
            from_step: 0,
            terminal_fallback: 0,
            views: stat(views),
            nsc: stat(nsc),
            sc: stat(nsc * 0.8),
            cd: stat(0.0),
            path_cost: stat(path_cost),
            runtime: stat(0.2),
            nsc_by_tau: BTreeMap::new(),
            sc_by_tau: BTreeMap::new(),
        }
    }

    #[test]
    fn rankings_break_ties_by_path_cost_then_name_and_skip_the_oracle() {
        let k5 = Setting::Fixed(5);
        let aggs = vec![
            agg(k5, "b", Family::Learned, 6.0, 0.9, 10.0),
            agg(k5, "a", Family::Learned, 6.0, 0.9, 10.0),
            agg(k5, "c", Family::Hybrid, 6.0, 0.9, 8.0),
            agg(k5, "d", Family::Classical, 6.0, 0.95, 30.0),
            agg(k5, "z", Family::Oracle, 6.0, 0.99, 5.0),
        ];
        let t = quality_top(&aggs, "whole", &[k5], 3);
        let got: Vec<(Option<usize>, &str)> = t.rows.iter().map(|r| (r.rank, r.method.as_str())).collect();
        assert_eq!(got, [(Some(1), "d"), (Some(2), "c"), (Some(3), "a"), (None, "z")]);
        assert_eq!(t.counts, [SettingCount { setting: k5, methods: 4, qualifying: 4 }]);
        // Path ranking: cost ascending; ties on cost → higher NSC, then name.
        let t = path_top(&aggs, "whole", &[k5], 2, 0.9);
        let got: Vec<&str> = t.rows.iter().map(|r| r.method.as_str()).collect();
        assert_eq!(got, ["c", "a", "z"]);
        let t = path_top(&aggs, "whole", &[k5], 3, 0.92);
        let got: Vec<&str> = t.rows.iter().filter(|r| r.rank.is_some()).map(|r| r.method.as_str()).collect();
        assert_eq!(got, ["d"]);
        assert_eq!(t.counts[0].qualifying, 1);
        // Nothing in another view space.
        assert!(quality_top(&aggs, "quarter", &[k5], 3).rows.is_empty());
    }

    #[test]
    fn solver_summary_counts_statuses_gaps_and_unproven_paths() {
        use crate::testutil::{episode, Spec};
        let mut eps = Vec::new();
        for (uid, status, gap, optimal) in
            [("a", "optimal", 0.0, true), ("b", "time_limit", 7.0, true), ("c", "time_limit", 3.0, false)]
        {
            let mut s = Spec::new(uid, "completion-mcp[net]");
            s.budget = "10";
            let mut e = episode(&s);
            e.result.planner_notes = Some(serde_json::json!({"plan": {
                "selection": {"status": status, "gap": gap}, "tsp": {"optimal": optimal}}}));
            eps.push(e);
        }
        // Budgets sort numerically (30 after 10), whatever the input order.
        let mut s30 = Spec::new("a", "completion-mcp[net]");
        s30.budget = "30";
        let mut e30 = episode(&s30);
        e30.result.planner_notes =
            Some(serde_json::json!({"plan": {"selection": {"status": "optimal", "gap": 0.0}}}));
        eps.insert(0, e30);
        // A plan without a selection step (random-tsp), and an episode without notes.
        let mut e = episode(&Spec::new("a", "random-tsp"));
        e.result.planner_notes = Some(serde_json::json!({"plan": {"tsp": {"optimal": true}}}));
        eps.push(e);
        eps.push(episode(&Spec::new("a", "rse")));
        // ma-scvp: one plan on a proven path, one whose path solve failed (kept in id order).
        for (uid, notes) in [
            ("a", serde_json::json!({"plan": {"tsp": {"optimal": true}, "tsp_error": null}})),
            ("b", serde_json::json!({"plan": {"tsp": null, "tsp_error": "ILP failed"}})),
        ] {
            let mut e = episode(&Spec::new(uid, "ma-scvp"));
            e.result.planner_notes = Some(notes);
            eps.push(e);
        }
        let rows = solver_summary(&eps);
        assert_eq!(rows.len(), 4);
        let scvp = &rows[2];
        assert_eq!(
            (scvp.method.as_str(), scvp.plans, scvp.paths, scvp.paths_not_proven),
            ("ma-scvp", 2, 2, 1)
        );
        assert_eq!((rows[1].budget.as_str(), rows[1].plans, rows[1].paths), ("30", 1, 0));
        let mcp = &rows[0];
        assert_eq!((mcp.method.as_str(), mcp.budget.as_str(), mcp.plans), ("completion-mcp[net]", "10", 3));
        assert_eq!(mcp.selection, BTreeMap::from([("optimal".into(), 1), ("time_limit".into(), 2)]));
        assert_eq!(mcp.max_gap, Some(7.0));
        assert_eq!((mcp.paths, mcp.paths_not_proven), (3, 1));
        let tsp = &rows[3];
        assert_eq!(
            (tsp.method.as_str(), tsp.plans, tsp.max_gap, tsp.paths_not_proven),
            ("random-tsp", 1, None, 0)
        );
        assert!(tsp.selection.is_empty());
        let md = crate::render::solver_markdown(&rows);
        assert!(md.contains("1 `optimal`, 2 `time_limit`"), "{md}");
        assert!(md.contains("| 1 of 3 |"), "{md}");
        assert_eq!(crate::render::solver_markdown(&[]), "");
    }
}
