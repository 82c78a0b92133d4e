//! Exact planning difficulty d_plan (SPEC §4, "Planning difficulty"): the minimum number of views
//! covering the universe U, solved as a 0/1 integer program with the open-source solver HiGHS.
//!
//! Why an ILP: d_plan must be exact (proven optimal), and the exact combinatorial solvers of
//! [`crate::setcover`] do not scale to 128 views. The pipeline of [`solve_min_cover`] is:
//!
//! 1. build the [`CoverInstance`] (universe = elements seen by at least k views) and its
//!    deterministic greedy cover (reported as `greedy_size`);
//! 2. apply the optimum-preserving reductions ([`CoverInstance::reduce`]): forced, dominated and
//!    empty views, dominated elements;
//! 3. solve the LP relaxation of the reduced instance with HiGHS (`lp_bound`);
//! 4. method `auto` (default): the exact combinatorial search of [`crate::search`] (≤ 384
//!    views) from ⌈LP⌉ up, for at most [`SEARCH_SHARE`] of the time limit; it usually proves the
//!    optimum (it is much faster than branch and bound on these instances, see that module);
//! 5. otherwise (method `ilp`, more than 384 views, or the search ran out of its time share) the
//!    ILP `min Σ x_v  s.t.  Σ_{v ∋ e} x_v ≥ 1 ∀e, x_v ∈ {0,1}` with HiGHS, warm-started from the
//!    best cover so far, with the search's proven bound kept; the incumbent starts as the better
//!    of the greedy covers of the original and of the reduced instance;
//! 6. lift the reduced solution back (forced ∪ chosen) and verify that it covers U.
//!
//! Both exact methods give the same d_plan (tested against each other and against brute force);
//! `method` in the result says which one proved it.
//!
//! Status semantics: `d_plan` is `Some` only when HiGHS reports the ILP optimal (relative gap 0).
//! A run stopped by the time limit is [`CoverStatus::TimeLimit`]: it reports the best cover found
//! (the incumbent, never worse than greedy) and a proven lower bound, never an optimum.
//!
//! Bounds: the reductions preserve both the integer and the LP optimum, so
//! `lp_bound = |forced| + LP(reduced)` is the LP relaxation optimum of the full instance.
//! `lower_bound` is the best proven integer lower bound: ⌈lp_bound⌉, raised to
//! `|forced| + ⌈mip_dual_bound⌉` when HiGHS reports its branch-and-bound dual bound (all costs are 1,
//! so any bound may be rounded up); at optimality it equals d_plan.
//!
//! Determinism: HiGHS runs on one thread with a fixed random seed, so an input solved to
//! optimality always yields the same chosen views (HiGHS picks one of possibly several minimum
//! covers; which one may change with the HiGHS version, pinned by Cargo.lock). Runs stopped by the
//! time limit depend on machine speed.
//!
//! Concurrency: solves on different threads run at the same time, with no lock. In the HiGHS
//! version pinned here (1.16) the parallel scheduler is `thread_local`: one per application
//! thread, shared only by the instances used on that thread and never visible to other threads
//! (HiGHS `docs/src/parallel.md`, "Scheduler scope and lifetime"). What that page asks of
//! callers holds in this workspace: every instance on a thread uses the same `threads` value
//! (1: the cover solves here, the TSP and hybrid ILPs of `objview-planners`), and nothing resets
//! a scheduler. (Earlier versions had a process-wide scheduler whose reset from the C API was
//! unsafe across threads, HiGHS PR #3141; the workspace then serialized every HiGHS call with a
//! process-wide lock, which left a core idle whenever two solves met, e.g. 11.9 s of one
//! annotation worker's time in the demo of 2026-12-04.) Concurrent solves giving the same
//! results as serial ones is tested.

use std::time::Instant;

use highs::{ColProblem, HighsModelStatus, Model, Row, Sense};
use serde::{Deserialize, Serialize};

use crate::error::DifficultyError;
use crate::setcover::{CoverInstance, Reduction};

/// Default wall-clock limit for one object's cover solve (seconds, SPEC §4).
pub const DEFAULT_TIME_LIMIT_S: f64 = 300.0;
/// Default HiGHS `random_seed`.
pub const DEFAULT_RANDOM_SEED: i32 = 0;
/// Share of the time limit the combinatorial search may use before the ILP takes over.
pub const SEARCH_SHARE: f64 = 0.5;
/// Tolerance when rounding fractional bounds up to integers (⌈x − tol⌉).
pub const BOUND_ROUNDING_TOL: f64 = 1e-6;

/// Which exact method proves d_plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoverMethod {
    /// Combinatorial search first (≤ 384 views), the HiGHS ILP if the search runs out of time.
    #[default]
    Auto,
    /// The HiGHS ILP only.
    Ilp,
}

impl std::str::FromStr for CoverMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(CoverMethod::Auto),
            "ilp" => Ok(CoverMethod::Ilp),
            other => Err(format!("unknown cover method '{other}' (expected 'auto' or 'ilp')")),
        }
    }
}

impl std::fmt::Display for CoverMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CoverMethod::Auto => "auto",
            CoverMethod::Ilp => "ilp",
        })
    }
}

/// Settings of [`solve_min_cover`], recorded in every [`CoverResult`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoverSettings {
    /// Wall-clock limit for the whole solve (reductions, LP and ILP), seconds; may be +∞.
    pub time_limit_s: f64,
    /// The universe is the set of elements seen by at least this many views (SPEC §4: k = 1).
    /// Each universe element must still be covered once.
    pub min_views_per_element: usize,
    /// HiGHS threads (1 for run-to-run determinism).
    pub threads: usize,
    /// HiGHS `random_seed` (fixed for determinism).
    pub random_seed: i32,
    /// Exact method.
    #[serde(default)]
    pub method: CoverMethod,
}

impl Default for CoverSettings {
    fn default() -> Self {
        Self {
            time_limit_s: DEFAULT_TIME_LIMIT_S,
            min_views_per_element: 1,
            threads: 1,
            random_seed: DEFAULT_RANDOM_SEED,
            method: CoverMethod::Auto,
        }
    }
}

impl CoverSettings {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), DifficultyError> {
        if self.time_limit_s.is_nan() || self.time_limit_s <= 0.0 {
            return Err(DifficultyError::InvalidSetting {
                name: "time_limit_s",
                value: self.time_limit_s,
                reason: "must be positive (or +inf)",
            });
        }
        if self.min_views_per_element == 0 {
            return Err(DifficultyError::ZeroMinViews);
        }
        if self.threads == 0 || self.threads > i32::MAX as usize {
            return Err(DifficultyError::InvalidSetting {
                name: "threads",
                value: self.threads as f64,
                reason: "must be at least 1",
            });
        }
        if self.random_seed < 0 {
            return Err(DifficultyError::InvalidSetting {
                name: "random_seed",
                value: f64::from(self.random_seed),
                reason: "must be non-negative",
            });
        }
        Ok(())
    }
}

/// Outcome of the exact cover solve.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoverStatus {
    /// The cover is proven minimum (by HiGHS with gap 0, or by the reductions alone).
    Optimal,
    /// The time limit stopped the solver: `best_cover` is the incumbent, `lower_bound` a bound.
    TimeLimit,
    /// HiGHS reported the ILP infeasible. Cannot happen (every element is seen by some view); kept
    /// so that a solver malfunction is recorded rather than hidden.
    Infeasible,
    /// The solver failed or returned an inconsistent answer (message says what).
    Error(String),
}

/// Size statistics of the optimum-preserving reductions ([`CoverInstance::reduce`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReductionStats {
    /// Views in every minimum cover (after dominance), view ids ascending.
    pub forced_views: Vec<usize>,
    /// Views dropped because they cover no remaining element.
    pub empty_views: usize,
    /// Views dropped because another view covers a superset.
    pub dominated_views: usize,
    /// Elements dropped because a forced view covers them.
    pub elements_covered_by_forced: usize,
    /// Elements dropped because covering another element implies covering them.
    pub dominated_elements: usize,
    /// Reduction passes until the fixpoint.
    pub rounds: usize,
    /// Views (ILP columns) left for the solver.
    pub reduced_views: usize,
    /// Elements (ILP rows) left for the solver.
    pub reduced_elements: usize,
}

impl From<&Reduction> for ReductionStats {
    fn from(red: &Reduction) -> Self {
        Self {
            forced_views: red.forced.clone(),
            empty_views: red.empty_views.len(),
            dominated_views: red.dominated_views.len(),
            elements_covered_by_forced: red.elements_covered_by_forced,
            dominated_elements: red.dominated_elements,
            rounds: red.rounds,
            reduced_views: red.reduced.n_views(),
            reduced_elements: red.reduced.n_elements(),
        }
    }
}

/// Result of [`solve_min_cover`] (SPEC §4: d_plan, chosen views, greedy size, LP bound, status,
/// time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoverResult {
    /// The settings used.
    pub settings: CoverSettings,
    /// Number of input views.
    pub n_views: usize,
    /// |U|: number of elements seen by at least `min_views_per_element` views.
    pub universe: usize,
    /// Solver outcome.
    pub status: CoverStatus,
    /// The minimum number of views covering U; `Some` only when `status` is `Optimal`.
    pub d_plan: Option<usize>,
    /// The best cover found (view ids ascending): a minimum cover when `Optimal`, else the
    /// incumbent (never larger than the greedy cover).
    pub best_cover: Vec<usize>,
    /// `best_cover.len()`.
    pub best_size: usize,
    /// Proven lower bound on the minimum cover size (see the module docs); equals d_plan when
    /// optimal.
    pub lower_bound: usize,
    /// LP relaxation optimum of the full instance (|forced| + LP of the reduced instance). When
    /// `lp_solved` is false (the LP itself hit the time limit), a trivial valid bound instead.
    pub lp_bound: f64,
    /// Whether the LP relaxation was solved to optimality.
    pub lp_solved: bool,
    /// HiGHS' branch-and-bound dual bound for the full instance (|forced| + reduced), if the ILP
    /// was run and reported a finite one.
    pub mip_dual_bound: Option<f64>,
    /// Size of the deterministic greedy cover of the original instance.
    pub greedy_size: usize,
    /// Total wall-clock time of the solve, seconds.
    pub seconds: f64,
    /// Wall-clock time spent inside HiGHS (LP + ILP), seconds.
    pub solver_seconds: f64,
    /// What the reductions removed.
    pub reduction: ReductionStats,
    /// What proved the result: `reductions` (forced views cover U), `search`, `ilp`,
    /// `search+ilp` (a bound of one method met a cover of the other), or `none` (not proven).
    pub proven_by: String,
    /// Nodes of the combinatorial search (0 if it did not run).
    pub search_nodes: u64,
    /// Wall-clock time of the combinatorial search, seconds.
    pub search_seconds: f64,
}

/// Minimum set cover of the universe seen by `views` (per-view bitsets over element ids, bit i of
/// word i/64 = element i), solved exactly with HiGHS. See the module docs for the procedure and
/// the meaning of each reported number.
///
/// Errors only on invalid settings; solver failures are reported in [`CoverResult::status`].
pub fn solve_min_cover(views: &[Vec<u64>], settings: &CoverSettings) -> Result<CoverResult, DifficultyError> {
    settings.validate()?;
    let start = Instant::now();
    let remaining = || (settings.time_limit_s - start.elapsed().as_secs_f64()).max(0.0);

    let inst = CoverInstance::from_bitsets(views, settings.min_views_per_element)?;
    let mut greedy = inst.greedy();
    greedy.sort_unstable();
    let red = inst.reduce();
    let forced = red.forced.len();
    let reduced = &red.reduced;

    // Incumbent: the better of the greedy covers of the original and of the reduced instance.
    let mut reduced_greedy = reduced.greedy();
    reduced_greedy.sort_unstable();
    let lifted_greedy = red.lift(&reduced_greedy);
    debug_assert!(reduced.is_cover(&reduced_greedy));
    let mut best = if lifted_greedy.len() < greedy.len() { lifted_greedy } else { greedy.clone() };

    let mut result = CoverResult {
        settings: settings.clone(),
        n_views: views.len(),
        universe: inst.n_elements(),
        status: CoverStatus::Optimal,
        d_plan: None,
        best_cover: Vec::new(),
        best_size: 0,
        lower_bound: forced,
        lp_bound: forced as f64,
        lp_solved: true,
        mip_dual_bound: None,
        greedy_size: greedy.len(),
        seconds: 0.0,
        solver_seconds: 0.0,
        reduction: ReductionStats::from(&red),
        proven_by: "none".into(),
        search_nodes: 0,
        search_seconds: 0.0,
    };
    // The best cover of the reduced instance (view ids), the warm start of the ILP.
    let mut best_reduced = reduced_greedy.clone();

    if reduced.n_elements() == 0 {
        // The forced views cover everything: the reductions alone prove optimality.
        best = red.lift(&[]);
        result.proven_by = "reductions".into();
    } else {
        let matrix = column_rows(reduced);
        // Trivial bound until the LP says more: at least one more view is needed.
        result.lp_bound = (forced + 1) as f64;
        result.lower_bound = forced + 1;
        let solver_start = Instant::now();

        let lp = solve_relaxation(&matrix, reduced.n_elements(), settings, remaining());
        let (mut lp_values, mut lp_duals): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
        match lp {
            Ok(Some(Relaxation { value, columns, duals })) => {
                lp_values = columns;
                lp_duals = duals;
                result.lp_bound = forced as f64 + value;
                result.lower_bound = result.lower_bound.max(forced + ceil_bound(value));
            }
            Ok(None) => {
                result.lp_solved = false;
                result.status = CoverStatus::TimeLimit;
            }
            Err(message) => {
                result.lp_solved = false;
                result.status = CoverStatus::Error(format!("LP relaxation: {message}"));
            }
        }

        let mut proven = false;
        if result.status == CoverStatus::Optimal && settings.method == CoverMethod::Auto {
            let budget = (settings.time_limit_s * SEARCH_SHARE).min(remaining());
            let t = Instant::now();
            let deadline = t.checked_add(std::time::Duration::from_secs_f64(budget.min(1e9)));
            let lower = result.lower_bound - forced;
            if let Some(out) = crate::search::search_min_cover(
                reduced,
                lower,
                &best_reduced,
                &lp_values,
                &lp_duals,
                deadline,
            ) {
                result.search_nodes = out.nodes;
                result.search_seconds = t.elapsed().as_secs_f64();
                let lifted = red.lift(&out.cover);
                if lifted.len() < best.len() || out.optimal {
                    best_reduced = out.cover.clone();
                    best = if lifted.len() <= best.len() { lifted } else { best };
                }
                result.lower_bound = result.lower_bound.max(forced + out.lower_bound);
                if out.optimal {
                    proven = true;
                    result.lower_bound = best.len();
                    result.proven_by = "search".into();
                }
            }
        }

        if result.status == CoverStatus::Optimal && !proven && remaining() <= 0.0 {
            result.status = CoverStatus::TimeLimit;
        }
        if result.status == CoverStatus::Optimal && !proven {
            // Warm start: the best cover of the reduced instance (feasible there by construction).
            let start_cols = position_mask(reduced, &best_reduced);
            let mip = solve_ilp(&matrix, reduced.n_elements(), &start_cols, settings, remaining());
            if let Some(bound) = mip.dual_bound.filter(|b| b.is_finite()) {
                result.mip_dual_bound = Some(forced as f64 + bound);
                result.lower_bound = result.lower_bound.max(forced + ceil_bound(bound));
            }
            // A feasible HiGHS solution replaces the incumbent if it is a valid, smaller cover.
            let mut solver_cover = None;
            if let Some(chosen) = &mip.chosen {
                let ids: Vec<usize> = chosen.iter().map(|&c| reduced.view_ids()[c]).collect();
                let lifted = red.lift(&ids);
                if inst.is_cover(&lifted) {
                    solver_cover = Some(lifted);
                }
            }
            result.status = match mip.status {
                Ok(HighsModelStatus::Optimal) => match solver_cover {
                    Some(cover) if cover.len() <= best.len() => {
                        best = cover;
                        result.lower_bound = best.len();
                        result.proven_by = "ilp".into();
                        CoverStatus::Optimal
                    }
                    Some(cover) => CoverStatus::Error(format!(
                        "HiGHS optimum {} is worse than the greedy cover {}",
                        cover.len(),
                        best.len()
                    )),
                    None => CoverStatus::Error("HiGHS optimum is not a valid cover".into()),
                },
                Ok(HighsModelStatus::ReachedTimeLimit) => {
                    if let Some(cover) = solver_cover.filter(|c| c.len() < best.len()) {
                        best = cover;
                    }
                    CoverStatus::TimeLimit
                }
                Ok(HighsModelStatus::Infeasible) => CoverStatus::Infeasible,
                Ok(other) => CoverStatus::Error(format!("HiGHS model status {other:?}")),
                Err(message) => CoverStatus::Error(message),
            };
        }
        result.solver_seconds = solver_start.elapsed().as_secs_f64() - result.search_seconds;
    }

    debug_assert!(inst.is_cover(&best), "the incumbent is always a cover");
    // A stopped run whose proven bound (search and/or ILP) meets the best cover (found by the
    // other method) has proven it minimum after all.
    if result.status == CoverStatus::TimeLimit && result.lower_bound == best.len() {
        result.status = CoverStatus::Optimal;
        result.proven_by = "search+ilp".into();
    }
    // A bound above a valid cover would be a solver inconsistency; never report it.
    if result.lower_bound > best.len() {
        if result.status == CoverStatus::Optimal || result.status == CoverStatus::TimeLimit {
            result.status = CoverStatus::Error(format!(
                "lower bound {} exceeds the cover size {}",
                result.lower_bound,
                best.len()
            ));
        }
        result.lower_bound = best.len();
    }
    if result.status == CoverStatus::Optimal {
        result.d_plan = Some(best.len());
        result.lower_bound = best.len();
    }
    result.best_size = best.len();
    result.best_cover = best;
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}

/// ⌈x − tol⌉ for a non-negative bound of an integer-valued objective.
fn ceil_bound(x: f64) -> usize {
    (x - BOUND_ROUNDING_TOL).ceil().max(0.0) as usize
}

/// Per column of `inst`: its row positions, ascending.
fn column_rows(inst: &CoverInstance) -> Vec<Vec<usize>> {
    let elements = inst.element_ids();
    inst.view_ids()
        .iter()
        .map(|&v| {
            inst.covered_by(v)
                .iter()
                .map(|e| elements.binary_search(e).expect("covered elements are rows of the instance"))
                .collect()
        })
        .collect()
}

/// 0/1 start vector over the columns of `reduced` for a cover of it (view ids ascending).
fn position_mask(reduced: &CoverInstance, cover: &[usize]) -> Vec<f64> {
    reduced.view_ids().iter().map(|v| if cover.binary_search(v).is_ok() { 1.0 } else { 0.0 }).collect()
}

/// The set-cover model over `matrix` (per column: its rows), with binary or [0, 1] columns.
fn build_model(
    matrix: &[Vec<usize>],
    n_rows: usize,
    integer: bool,
    settings: &CoverSettings,
    time_limit: f64,
) -> Result<Model, String> {
    let mut pb = ColProblem::new();
    let rows: Vec<Row> = (0..n_rows).map(|_| pb.add_row(1.0..)).collect();
    for col in matrix {
        let factors = col.iter().map(|&r| (rows[r], 1.0));
        if integer {
            pb.add_integer_column(1.0, 0.0..=1.0, factors);
        } else {
            pb.add_column(1.0, 0.0..=1.0, factors);
        }
    }
    let mut model =
        pb.try_optimise(Sense::Minimise).map_err(|s| format!("HiGHS rejected the model: {s:?}"))?;
    let threads = i32::try_from(settings.threads).expect("validated");
    for (name, r) in [
        ("output_flag", model.try_set_option("output_flag", false)),
        ("log_to_console", model.try_set_option("log_to_console", false)),
        ("threads", model.try_set_option("threads", threads)),
        ("random_seed", model.try_set_option("random_seed", settings.random_seed)),
        ("time_limit", model.try_set_option("time_limit", time_limit)),
    ] {
        r.map_err(|e| format!("HiGHS option {name}: {e:?}"))?;
    }
    if settings.threads == 1 {
        model.try_set_option("parallel", "off").map_err(|e| format!("HiGHS option parallel: {e:?}"))?;
    }
    if integer {
        model.try_set_option("mip_rel_gap", 0.0).map_err(|e| format!("HiGHS option mip_rel_gap: {e:?}"))?;
    }
    Ok(model)
}

/// An optimal LP relaxation: its value, column values and row duals.
struct Relaxation {
    value: f64,
    columns: Vec<f64>,
    duals: Vec<f64>,
}

/// The LP relaxation's optimum; `Ok(None)` when the time limit stopped it.
fn solve_relaxation(
    matrix: &[Vec<usize>],
    n_rows: usize,
    settings: &CoverSettings,
    time_limit: f64,
) -> Result<Option<Relaxation>, String> {
    let model = build_model(matrix, n_rows, false, settings, time_limit)?;
    let solved = model.try_solve().map_err(|s| format!("HiGHS run failed: {s:?}"))?;
    match solved.status() {
        HighsModelStatus::Optimal => {
            let solution = solved.get_solution();
            Ok(Some(Relaxation {
                value: solved.objective_value(),
                columns: solution.columns().to_vec(),
                duals: solution.dual_rows().to_vec(),
            }))
        }
        HighsModelStatus::ReachedTimeLimit => Ok(None),
        other => Err(format!("HiGHS model status {other:?}")),
    }
}

/// What the ILP run returned (positions are columns of the reduced instance).
struct IlpOutcome {
    status: Result<HighsModelStatus, String>,
    chosen: Option<Vec<usize>>,
    dual_bound: Option<f64>,
}

fn solve_ilp(
    matrix: &[Vec<usize>],
    n_rows: usize,
    start: &[f64],
    settings: &CoverSettings,
    time_limit: f64,
) -> IlpOutcome {
    let costs = vec![1.0; matrix.len()];
    let run = match crate::warm::solve_from(
        || build_model(matrix, n_rows, true, settings, time_limit),
        start,
        &costs,
    ) {
        Ok(run) => run,
        Err(message) => return IlpOutcome { status: Err(message), chosen: None, dual_bound: None },
    };
    IlpOutcome {
        status: Ok(run.solved.status()),
        chosen: run.chosen(matrix.len()),
        dual_bound: run.solved.double_info_value(c"mip_dual_bound").ok(),
    }
}
