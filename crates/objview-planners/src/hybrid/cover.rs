//! The exact view-selection steps of `completion-scp` and `completion-mcp` (reference:
//! `shared/research/learned-baselines.md` §7 steps 6–7 and §8):
//!
//! - [`set_cover`]: the fewest candidates covering every needed voxel — the exact minimum set
//!   cover of `objview-difficulty` ([`solve_min_cover`]: reductions, LP bound, combinatorial
//!   search, HiGHS ILP), with the planners' time limit (10 s);
//! - [`max_coverage`]: at most B candidates covering the most needed voxels. Two exact
//!   shortcuts first: a selection covering every reachable element is optimal (nothing can
//!   cover more), so when the greedy selection is one, or the exact set cover (on a share of the
//!   time limit) finds a cover of at most B columns, that is the answer — the common case at
//!   large budgets (K = 30). Otherwise the exact branch and bound of `coverage_search`
//!   (submodular gain bound, deterministic; it proves the K = 5 plans in well under a second)
//!   on half the time left (at most 2 s), and if it has not finished, its incumbent improved by
//!   1-swap exchanges (`swap_search`; optimal if that reaches the search's proven
//!   bound), then a HiGHS ILP warm-started from it for the rest (whose selection, unless proven
//!   optimal, gets the exchanges again):
//!   `max Σ w_g y_g  s.t.  Σ x_i ≤ B,  y_g ≤ Σ_{i covers g} x_i,  x binary,  y ∈ [0, 1]`, where
//!   elements covered by exactly the same candidates are merged into one group g of weight w_g
//!   (an exact reduction; y needs no integrality: for binary x the optimum has y_g =
//!   min(1, Σ x_i)). The reported bound is the smaller of the two solvers' proven bounds;
//! - [`farthest_fill`]: the budget fill, farthest-point sampling over candidate positions.
//!
//! Status semantics, as everywhere in the workspace: a solve is `optimal` only when proven; a
//! run stopped by the time limit is `time_limit` with its incumbent (never worse than greedy)
//! and a proven bound, and the planner records both (never calling it optimal).

use std::collections::HashMap;
use std::time::Instant;

use highs::{ColProblem, HighsModelStatus, Sense};
use objview_difficulty::ilp::{solve_min_cover, CoverSettings, CoverStatus};
use serde::{Deserialize, Serialize};

use super::coverage_search::search_max_coverage;
use super::steps::bit;
use super::swap_search::improve_by_swaps;

/// Default wall-clock limit of the planners' ILPs (the reference's 10 s).
pub const DEFAULT_ILP_TIME_LIMIT_S: f64 = 10.0;

/// Max coverage first looks for a full cover within the budget with the exact set-cover search,
/// on this share of its time limit (at most [`FULL_COVER_MAX_S`]); the ILP gets what is left.
pub const FULL_COVER_SHARE: f64 = 0.2;
/// See [`FULL_COVER_SHARE`].
pub const FULL_COVER_MAX_S: f64 = 2.0;
/// Max coverage runs its exact branch and bound on this share of the time left (at most
/// [`SEARCH_MAX_S`]); a search that has not finished by then hands its incumbent to the HiGHS
/// ILP for the rest. The search proves small budgets (K = 5) in well under a second or not at
/// all in useful time; at large budgets below full coverage the ILP's LP bound does better.
pub const SEARCH_SHARE: f64 = 0.5;
/// See [`SEARCH_SHARE`].
pub const SEARCH_MAX_S: f64 = 2.0;

/// Passes of 1-swap exchanges (`swap_search`) on a max-coverage selection that no
/// solver proved optimal, before and after the ILP (each pass costs chosen × unchosen bitset
/// ANDs, well under a millisecond at K = 30 over a few hundred candidates).
pub const SWAP_PASSES: usize = 200;

/// What an exact selection step returned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    /// Selected columns (indices into the `covers` given), ascending.
    pub chosen: Vec<usize>,
    /// Needed elements the selection covers.
    pub covered: usize,
    /// Needed elements.
    pub needed: usize,
    /// `optimal` (proven), `time_limit` (stopped: incumbent + bound), `skipped` (nothing to
    /// solve), or `error: …` (the greedy selection is used).
    pub status: String,
    /// Proven bound on the optimum: a lower bound on the cover size (set cover) or an upper
    /// bound on the covered count (max coverage). Equals the objective when optimal.
    pub bound: f64,
    /// |objective − bound| (0 when optimal).
    pub gap: f64,
    /// Seconds in the solve.
    pub seconds: f64,
}

/// The elements of `needed` (a bitset) that some column covers, intersected per column.
fn masked(covers: &[Vec<u64>], needed: &[u64]) -> Vec<Vec<u64>> {
    covers.iter().map(|c| c.iter().zip(needed).map(|(a, b)| a & b).collect()).collect()
}

fn count(set: &[u64]) -> usize {
    set.iter().map(|w| w.count_ones() as usize).sum()
}

fn covered_by(covers: &[Vec<u64>], chosen: &[usize], needed: &[u64]) -> usize {
    let mut u = vec![0u64; needed.len()];
    for &c in chosen {
        for (w, x) in u.iter_mut().zip(&covers[c]) {
            *w |= x;
        }
    }
    u.iter().zip(needed).map(|(a, b)| (a & b).count_ones() as usize).sum()
}

/// The minimum number of columns of `covers` (bitsets over elements) covering every element
/// of `needed` that some column covers, exact within `time_limit_s`.
pub fn set_cover(covers: &[Vec<u64>], needed: &[u64], time_limit_s: f64) -> Selection {
    let t = Instant::now();
    let views = masked(covers, needed);
    let settings = CoverSettings { time_limit_s, ..CoverSettings::default() };
    let reachable = {
        let mut u = vec![0u64; needed.len()];
        for v in &views {
            for (w, x) in u.iter_mut().zip(v) {
                *w |= x;
            }
        }
        count(&u)
    };
    if reachable == 0 {
        return Selection {
            chosen: Vec::new(),
            covered: 0,
            needed: 0,
            status: "skipped".into(),
            bound: 0.0,
            gap: 0.0,
            seconds: t.elapsed().as_secs_f64(),
        };
    }
    match solve_min_cover(&views, &settings) {
        Ok(r) => {
            let status = match &r.status {
                CoverStatus::Optimal => "optimal".to_string(),
                CoverStatus::TimeLimit => "time_limit".to_string(),
                CoverStatus::Infeasible => "error: infeasible".to_string(),
                CoverStatus::Error(m) => format!("error: {m}"),
            };
            Selection {
                covered: covered_by(&views, &r.best_cover, needed),
                needed: reachable,
                chosen: r.best_cover.clone(),
                status,
                bound: r.lower_bound as f64,
                gap: (r.best_size - r.lower_bound.min(r.best_size)) as f64,
                seconds: r.seconds,
            }
        }
        Err(e) => Selection {
            chosen: Vec::new(),
            covered: 0,
            needed: reachable,
            status: format!("error: {e}"),
            bound: 0.0,
            gap: f64::NAN,
            seconds: t.elapsed().as_secs_f64(),
        },
    }
}

/// The deterministic greedy max coverage: `budget` times the column adding the most weight
/// (ties → smaller index; stops when nothing more is gained).
fn greedy_max_coverage(cols: &[Vec<usize>], weights: &[f64], budget: usize) -> Vec<usize> {
    let mut covered = vec![false; weights.len()];
    let mut chosen = Vec::new();
    for _ in 0..budget {
        let mut best: Option<(f64, usize)> = None;
        for (i, col) in cols.iter().enumerate() {
            if chosen.contains(&i) {
                continue;
            }
            let g: f64 = col.iter().filter(|&&e| !covered[e]).map(|&e| weights[e]).sum();
            if g > 0.0 && best.is_none_or(|(b, _)| g > b) {
                best = Some((g, i));
            }
        }
        let Some((_, i)) = best else { break };
        for &e in &cols[i] {
            covered[e] = true;
        }
        chosen.push(i);
    }
    chosen.sort_unstable();
    chosen
}

/// At most `budget` columns of `covers` covering the most elements of `needed`, exact within
/// `time_limit_s` (see the module docs for the model). Nothing needed or `budget` 0 →
/// `skipped` with nothing chosen.
pub fn max_coverage(covers: &[Vec<u64>], needed: &[u64], budget: usize, time_limit_s: f64) -> Selection {
    max_coverage_in(covers, needed, budget, time_limit_s, SEARCH_SHARE)
}

/// [`max_coverage`] with the branch and bound's share of the time left as a parameter (tests
/// run the ILP fallback with share 0).
fn max_coverage_in(
    covers: &[Vec<u64>],
    needed: &[u64],
    budget: usize,
    time_limit_s: f64,
    search_share: f64,
) -> Selection {
    let t = Instant::now();
    let views = masked(covers, needed);
    // Group the needed elements by the set of columns covering them.
    let mut groups: HashMap<Vec<u32>, usize> = HashMap::new();
    for e in 0..needed.len() * 64 {
        if !bit(needed, e) {
            continue;
        }
        let sig: Vec<u32> = (0..views.len()).filter(|&c| bit(&views[c], e)).map(|c| c as u32).collect();
        if !sig.is_empty() {
            *groups.entry(sig).or_default() += 1;
        }
    }
    let mut groups: Vec<(Vec<u32>, usize)> = groups.into_iter().collect();
    groups.sort_unstable();
    let reachable: usize = groups.iter().map(|g| g.1).sum();
    let weights: Vec<f64> = groups.iter().map(|g| g.1 as f64).collect();
    let mut cols: Vec<Vec<usize>> = vec![Vec::new(); views.len()];
    for (g, (sig, _)) in groups.iter().enumerate() {
        for &c in sig {
            cols[c as usize].push(g);
        }
    }
    let budget = budget.min(views.len());
    let skipped = |t: Instant| Selection {
        chosen: Vec::new(),
        covered: 0,
        needed: reachable,
        status: "skipped".into(),
        bound: 0.0,
        gap: 0.0,
        seconds: t.elapsed().as_secs_f64(),
    };
    if reachable == 0 || budget == 0 {
        return skipped(t);
    }
    let greedy = greedy_max_coverage(&cols, &weights, budget);
    let value = |chosen: &[usize]| covered_by(&views, chosen, needed);
    // Covering every reachable element is optimal whatever the instance (the count cannot
    // exceed it), so a full cover within the budget needs no ILP: the greedy selection when it
    // is one, else a set cover of size ≤ budget found (or excluded) by the exact cover search
    // on part of the time limit.
    let optimal = |chosen: Vec<usize>, covered: usize, t: Instant| Selection {
        covered,
        chosen,
        needed: reachable,
        status: "optimal".into(),
        bound: covered as f64,
        gap: 0.0,
        seconds: t.elapsed().as_secs_f64(),
    };
    if value(&greedy) == reachable {
        return optimal(greedy, reachable, t);
    }
    let cover_limit = (time_limit_s * FULL_COVER_SHARE).min(FULL_COVER_MAX_S);
    let settings = CoverSettings { time_limit_s: cover_limit, ..CoverSettings::default() };
    if let Ok(r) = solve_min_cover(&views, &settings) {
        if !r.best_cover.is_empty() && r.best_cover.len() <= budget && value(&r.best_cover) == reachable {
            return optimal(r.best_cover, reachable, t);
        }
    }
    // Dominated columns (group set ⊆ another kept column's; equal sets keep the smaller index)
    // are dropped: a solution using one can use its dominator instead, so the optimum stays.
    let kept = undominated(&cols, weights.len());
    let kept_cols: Vec<Vec<usize>> = kept.iter().map(|&c| cols[c].clone()).collect();
    let kept_greedy: Vec<usize> = greedy.iter().filter_map(|c| kept.binary_search(c).ok()).collect();
    // The exact branch and bound on the reachable elements (each group a run of w_g bits).
    let mut offsets = Vec::with_capacity(weights.len());
    let mut total = 0usize;
    for g in &groups {
        offsets.push(total);
        total += g.1;
    }
    let compact: Vec<Vec<u64>> = kept_cols
        .iter()
        .map(|col| {
            let mut b = vec![0u64; total.div_ceil(64)];
            for &g in col {
                for e in offsets[g]..offsets[g] + groups[g].1 {
                    b[e >> 6] |= 1 << (e & 63);
                }
            }
            b
        })
        .collect();
    let search_s = ((time_limit_s - t.elapsed().as_secs_f64()).max(0.0) * search_share).min(SEARCH_MAX_S);
    let deadline = Instant::now() + std::time::Duration::from_secs_f64(search_s);
    let found = search_max_coverage(&compact, budget, &kept_greedy, deadline);
    if found.proven {
        let chosen: Vec<usize> = found.chosen.iter().map(|&i| kept[i]).collect();
        let covered = value(&chosen);
        return optimal(chosen, covered, t);
    }
    // Not proven: exchanges first (a better incumbent for the ILP's warm start); a selection
    // reaching the search's proven bound is optimal.
    let mut incumbent = found.chosen.clone();
    let swapped = improve_by_swaps(&compact, budget, &mut incumbent, SWAP_PASSES);
    if swapped >= found.bound {
        let chosen: Vec<usize> = incumbent.iter().map(|&i| kept[i]).collect();
        let covered = value(&chosen);
        return optimal(chosen, covered, t);
    }
    let time_limit_s = (time_limit_s - t.elapsed().as_secs_f64()).max(0.0);
    let solved = solve_max_coverage(&kept_cols, &weights, budget, &incumbent, time_limit_s);
    let search_bound = found.bound as f64;
    // Kept indices throughout; the ILP's selection replaces the incumbent only if it covers
    // more, and a selection the ILP did not prove optimal gets the exchanges again.
    let (status, mut chosen, bound) = match solved {
        Ok((status, chosen, bound)) => {
            let chosen = chosen.filter(|c| value_of(&compact, c) > swapped).unwrap_or(incumbent);
            let status = match status {
                HighsModelStatus::Optimal => "optimal".to_string(),
                HighsModelStatus::ReachedTimeLimit => "time_limit".to_string(),
                other => format!("error: HiGHS model status {other:?}"),
            };
            (status, chosen, bound.unwrap_or(reachable as f64).min(search_bound))
        }
        Err(message) => (format!("error: {message}"), incumbent, search_bound),
    };
    if status != "optimal" {
        improve_by_swaps(&compact, budget, &mut chosen, SWAP_PASSES);
    }
    let chosen: Vec<usize> = chosen.iter().map(|&i| kept[i]).collect();
    let covered = value(&chosen);
    let seconds = t.elapsed().as_secs_f64();
    let bound = bound.min(reachable as f64).max(covered as f64);
    let mut sel = Selection { chosen, covered, needed: reachable, status, bound, gap: 0.0, seconds };
    if sel.status == "optimal" || sel.covered as f64 >= sel.bound {
        // HiGHS proved it (gap 0), or the selection reaches a proven bound: the bound is the
        // objective.
        sel.status = "optimal".into();
        sel.bound = sel.covered as f64;
    }
    sel.gap = sel.bound - sel.covered as f64;
    sel
}

/// Elements the kept columns `chosen` cover (over `compact`'s bits).
fn value_of(compact: &[Vec<u64>], chosen: &[usize]) -> usize {
    let mut u = vec![0u64; compact.first().map_or(0, Vec::len)];
    for &c in chosen {
        for (w, x) in u.iter_mut().zip(&compact[c]) {
            *w |= x;
        }
    }
    count(&u)
}

/// Columns (ascending) not dominated by another: column a is dropped when some column b has a
/// superset of its groups and (b's set is strictly larger, or the sets are equal and b < a).
fn undominated(cols: &[Vec<usize>], groups: usize) -> Vec<usize> {
    let words = groups.div_ceil(64);
    let sets: Vec<Vec<u64>> = cols
        .iter()
        .map(|c| {
            let mut b = vec![0u64; words];
            for &g in c {
                b[g >> 6] |= 1 << (g & 63);
            }
            b
        })
        .collect();
    let subset = |a: &[u64], b: &[u64]| a.iter().zip(b).all(|(x, y)| x & !y == 0);
    (0..cols.len())
        .filter(|&a| {
            !(0..cols.len())
                .any(|b| b != a && subset(&sets[a], &sets[b]) && (cols[b].len() > cols[a].len() || b < a))
        })
        .collect()
}

/// The max-coverage ILP over grouped elements; (status, chosen columns if feasible, dual bound).
type MaxCoverOutcome = (HighsModelStatus, Option<Vec<usize>>, Option<f64>);

fn solve_max_coverage(
    cols: &[Vec<usize>],
    weights: &[f64],
    budget: usize,
    start: &[usize],
    time_limit_s: f64,
) -> Result<MaxCoverOutcome, String> {
    let build = || {
        let mut pb = ColProblem::new();
        let budget_row = pb.add_row(..=budget as f64);
        let group_rows: Vec<_> = weights.iter().map(|_| pb.add_row(..=0.0)).collect();
        for col in cols {
            let factors =
                std::iter::once((budget_row, 1.0)).chain(col.iter().map(|&g| (group_rows[g], -1.0)));
            pb.add_integer_column(0.0, 0.0..=1.0, factors);
        }
        for (g, &w) in weights.iter().enumerate() {
            pb.add_column(w, 0.0..=1.0, [(group_rows[g], 1.0)]);
        }
        let mut model =
            pb.try_optimise(Sense::Maximise).map_err(|s| format!("HiGHS rejected the model: {s:?}"))?;
        for (name, r) in [
            ("output_flag", model.try_set_option("output_flag", false)),
            ("log_to_console", model.try_set_option("log_to_console", false)),
            ("threads", model.try_set_option("threads", 1)),
            ("random_seed", model.try_set_option("random_seed", 0)),
            ("time_limit", model.try_set_option("time_limit", time_limit_s)),
            ("mip_rel_gap", model.try_set_option("mip_rel_gap", 0.0)),
            ("mip_abs_gap", model.try_set_option("mip_abs_gap", 0.0)),
        ] {
            r.map_err(|e| format!("HiGHS option {name}: {e:?}"))?;
        }
        model.try_set_option("parallel", "off").map_err(|e| format!("HiGHS option parallel: {e:?}"))?;
        Ok(model)
    };
    // Warm start: the given selection and the groups it covers.
    let mut x: Vec<f64> = (0..cols.len()).map(|i| if start.contains(&i) { 1.0 } else { 0.0 }).collect();
    let mut y = vec![0.0; weights.len()];
    for &i in start {
        for &g in &cols[i] {
            y[g] = 1.0;
        }
    }
    x.extend(y);
    let costs: Vec<f64> = std::iter::repeat_n(0.0, cols.len()).chain(weights.iter().copied()).collect();
    // The solution is HiGHS's own (checked against its objective: `objview_difficulty::warm`).
    let run = objview_difficulty::warm::solve_from(build, &x, &costs)?;
    let chosen = run.chosen(cols.len());
    // A chosen set over budget would be a solver inconsistency: drop it (greedy is used).
    let chosen = chosen.filter(|c| c.len() <= budget);
    let bound = run.solved.double_info_value(c"mip_dual_bound").ok().filter(|b| b.is_finite());
    Ok((run.solved.status(), chosen, bound))
}

/// Farthest-point fill: `count` times, the eligible position (in the given order, first wins
/// ties) maximizing the minimum squared Euclidean distance to the anchors so far; each pick
/// becomes an anchor. Returns indices into `eligible`'s positions (`eligible[i]` is the
/// position of candidate i), in pick order; fewer when the eligible run out.
pub fn farthest_fill(eligible: &[(usize, [f64; 3])], anchors: &[[f64; 3]], count: usize) -> Vec<usize> {
    let d2 =
        |a: &[f64; 3], b: &[f64; 3]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2);
    let mut nearest: Vec<f64> = eligible
        .iter()
        .map(|(_, p)| anchors.iter().map(|a| d2(p, a)).fold(f64::INFINITY, f64::min))
        .collect();
    let mut taken = vec![false; eligible.len()];
    let mut out = Vec::new();
    while out.len() < count {
        let mut best: Option<(f64, usize)> = None;
        for (j, &d) in nearest.iter().enumerate() {
            if !taken[j] && best.is_none_or(|(b, _)| d > b) {
                best = Some((d, j));
            }
        }
        let Some((_, j)) = best else { break };
        taken[j] = true;
        out.push(eligible[j].0);
        let p = eligible[j].1;
        for (k, (_, q)) in eligible.iter().enumerate() {
            nearest[k] = nearest[k].min(d2(q, &p));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_instance(rng: &mut ChaCha8Rng, cols: usize, elements: usize, p: f64) -> Vec<Vec<u64>> {
        (0..cols)
            .map(|_| {
                let mut b = vec![0u64; elements.div_ceil(64)];
                for e in 0..elements {
                    if rng.gen_bool(p) {
                        b[e >> 6] |= 1 << (e & 63);
                    }
                }
                b
            })
            .collect()
    }

    /// Every subset of the columns, as (subset, covered count of `needed`).
    fn subsets(covers: &[Vec<u64>], needed: &[u64]) -> Vec<(Vec<usize>, usize)> {
        (0u32..1 << covers.len())
            .map(|m| {
                let s: Vec<usize> = (0..covers.len()).filter(|i| m >> i & 1 == 1).collect();
                let c = covered_by(covers, &s, needed);
                (s, c)
            })
            .collect()
    }

    /// The most needed elements any ≤ `budget` columns cover (brute force).
    fn best_within(covers: &[Vec<u64>], needed: &[u64], budget: usize) -> usize {
        subsets(covers, needed).into_iter().filter(|(s, _)| s.len() <= budget).map(|(_, c)| c).max().unwrap()
    }

    #[test]
    fn set_cover_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for trial in 0..25 {
            let (n, m) = (rng.gen_range(1..=10), rng.gen_range(1..=70));
            let p = rng.gen_range(0.05..0.4);
            let covers = random_instance(&mut rng, n, m, p);
            let mut needed = random_instance(&mut rng, 1, m, 0.8).remove(0);
            if trial == 0 {
                needed.iter_mut().for_each(|w| *w = 0);
            }
            let all: Vec<usize> = (0..n).collect();
            let reachable = covered_by(&covers, &all, &needed);
            let sel = set_cover(&covers, &needed, 10.0);
            if reachable == 0 {
                assert_eq!((sel.status.as_str(), sel.chosen.len()), ("skipped", 0));
                continue;
            }
            let best = subsets(&covers, &needed)
                .into_iter()
                .filter(|(_, c)| *c == reachable)
                .map(|(s, _)| s.len())
                .min()
                .unwrap();
            assert_eq!(sel.status, "optimal", "trial {trial}");
            assert_eq!(sel.chosen.len(), best, "trial {trial}");
            assert_eq!((sel.covered, sel.needed), (reachable, reachable), "trial {trial}");
            assert_eq!((sel.bound, sel.gap), (best as f64, 0.0));
        }
    }

    #[test]
    fn max_coverage_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for trial in 0..30 {
            let (n, m) = (rng.gen_range(1..=10), rng.gen_range(1..=80));
            let p = rng.gen_range(0.05..0.4);
            let covers = random_instance(&mut rng, n, m, p);
            let needed = random_instance(&mut rng, 1, m, 0.7).remove(0);
            let budget = rng.gen_range(0..=n + 1);
            let sel = max_coverage(&covers, &needed, budget, 10.0);
            let best = best_within(&covers, &needed, budget);
            assert!(sel.chosen.len() <= budget, "trial {trial}");
            assert_eq!(sel.covered, best, "trial {trial}: {sel:?}");
            if sel.status != "skipped" {
                assert_eq!(sel.status, "optimal", "trial {trial}");
                assert_eq!((sel.bound, sel.gap), (best as f64, 0.0), "trial {trial}");
            } else {
                assert_eq!(best, 0, "trial {trial}");
            }
        }
    }

    /// A random instance whose budget (2–4 of `min_n`–14 columns) is usually below full
    /// coverage: (covers, needed, budget, columns).
    fn small_budget_instance(rng: &mut ChaCha8Rng, min_n: usize) -> (Vec<Vec<u64>>, Vec<u64>, usize, usize) {
        let (n, m) = (rng.gen_range(min_n..=14), rng.gen_range(60..=120));
        let p = rng.gen_range(0.1..0.3);
        let covers = random_instance(rng, n, m, p);
        let needed = random_instance(rng, 1, m, 0.9).remove(0);
        let budget = rng.gen_range(2..=4);
        (covers, needed, budget, n)
    }

    #[test]
    fn a_stopped_search_hands_over_to_the_ilp() {
        // With a search share of 0 the branch and bound stops at its root, and the HiGHS ILP
        // (warm-started from its incumbent) must still reach the brute-force optimum.
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let mut handed_over = 0;
        for trial in 0..12 {
            let (covers, needed, budget, n) = small_budget_instance(&mut rng, 12);
            let sel = max_coverage_in(&covers, &needed, budget, 10.0, 0.0);
            let best = best_within(&covers, &needed, budget);
            // Below full coverage neither shortcut applies, and the search stops at its root.
            let all: Vec<usize> = (0..n).collect();
            handed_over += usize::from(best < covered_by(&covers, &all, &needed));
            assert_eq!((sel.covered, sel.status.as_str()), (best, "optimal"), "trial {trial}: {sel:?}");
            assert_eq!((sel.bound, sel.gap), (best as f64, 0.0), "trial {trial}");
            assert!(sel.chosen.len() <= budget);
        }
        assert!(handed_over >= 6, "only {handed_over} of 12 instances reached the ILP");
    }

    #[test]
    fn a_stopped_selection_is_never_worse_than_the_exchanged_greedy_and_never_called_optimal_below_its_bound()
    {
        // No time at all: the cover shortcut, the branch and bound and the ILP all stop at once,
        // so what comes back is the greedy selection after the exchanges (or better), with a
        // proven bound; `optimal` only where the selection reaches that bound.
        let mut rng = ChaCha8Rng::seed_from_u64(14);
        let (mut stopped, mut exchanged) = (0, 0);
        for trial in 0..40 {
            let (covers, needed, budget, _) = small_budget_instance(&mut rng, 10);
            let m = needed.len() * 64;
            let sel = max_coverage_in(&covers, &needed, budget, 0.0, 0.0);
            let best = best_within(&covers, &needed, budget);
            // Greedy and the exchanges on the plain instance (no grouping, no dominance): only
            // to check that these instances give the exchanges something to do.
            let cols: Vec<Vec<u64>> =
                covers.iter().map(|c| c.iter().zip(&needed).map(|(a, b)| a & b).collect()).collect();
            let as_lists: Vec<Vec<usize>> =
                cols.iter().map(|c| (0..m).filter(|&e| c[e >> 6] >> (e & 63) & 1 == 1).collect()).collect();
            let mut greedy = greedy_max_coverage(&as_lists, &vec![1.0; m], budget);
            let greedy_value = covered_by(&covers, &greedy, &needed);
            let swapped =
                super::super::swap_search::improve_by_swaps(&cols, budget, &mut greedy, SWAP_PASSES);
            exchanged += usize::from(swapped > greedy_value);
            assert!(sel.chosen.len() <= budget, "trial {trial}");
            assert_eq!(sel.covered, covered_by(&covers, &sel.chosen, &needed), "trial {trial}");
            assert!(
                greedy_value <= sel.covered && sel.covered <= best,
                "trial {trial}: {sel:?}, best {best}"
            );
            assert!(sel.bound >= best as f64, "trial {trial}: {sel:?}, best {best}");
            assert_eq!(sel.gap, sel.bound - sel.covered as f64, "trial {trial}");
            if sel.status == "optimal" {
                assert_eq!((sel.covered, sel.gap), (best, 0.0), "trial {trial}");
            } else {
                stopped += 1;
                assert!(sel.gap > 0.0, "trial {trial}: {sel:?}");
            }
        }
        assert!(stopped >= 10 && exchanged >= 1, "stopped {stopped}, exchanged {exchanged}");
    }

    #[test]
    fn exchanges_repair_a_greedy_trap_without_time() {
        // A greedy trap with no time to search: only the exchanges reach the optimum. Elements
        // 0..9, budget 2, no column dominated, no full cover within the budget: greedy takes
        // {1..6} then {0..3} (7 elements); swapping {1..6} for {4..7} gives 8, the optimum.
        let col = |es: &[usize]| vec![es.iter().fold(0u64, |w, &e| w | 1 << e)];
        let covers = vec![col(&[1, 2, 3, 4, 5, 6]), col(&[0, 1, 2, 3]), col(&[4, 5, 6, 7]), col(&[8])];
        let needed = col(&[0, 1, 2, 3, 4, 5, 6, 7, 8]);
        let sel = max_coverage_in(&covers, &needed, 2, 0.0, 0.0);
        assert_eq!((sel.chosen.clone(), sel.covered), (vec![1, 2], 8), "{sel:?}");
    }

    #[test]
    fn a_greedy_trap_is_solved_exactly() {
        // Elements 0..6. Greedy takes column 0 (covers 4: {1,2,3,4}) then one of 2 → 5; the
        // optimum with B = 2 is columns 1 + 2 covering all 6.
        let col = |es: &[usize]| vec![es.iter().fold(0u64, |w, &e| w | 1 << e)];
        let covers = vec![col(&[1, 2, 3, 4]), col(&[0, 1, 2]), col(&[3, 4, 5])];
        let needed = col(&[0, 1, 2, 3, 4, 5]);
        let sel = max_coverage(&covers, &needed, 2, 10.0);
        assert_eq!((sel.chosen.clone(), sel.covered, sel.status.as_str()), (vec![1, 2], 6, "optimal"));
        let sel = set_cover(&covers, &needed, 10.0);
        assert_eq!(sel.chosen, vec![1, 2]);
    }

    #[test]
    fn farthest_fill_order() {
        // Points on a line; anchor at 0. Picks: 10 (farthest), then 5 (mid: min distance 5 to
        // both), then between 2 (min 2) and 3 (min 2 to 5? |3−5|=2, |3−0|=3 → 2) and 7, 8:
        // 2 → min(2, 3)=2; 3 → min(3, 2)=2; 7 → min(2, 3)=2; 8 → min(3, 2)=2: all tie at 2,
        // so the first eligible in order wins (2).
        let line: Vec<(usize, [f64; 3])> = [2.0, 3.0, 5.0, 7.0, 8.0, 10.0]
            .iter()
            .enumerate()
            .map(|(i, &x)| (100 + i, [x, 0.0, 0.0]))
            .collect();
        assert_eq!(farthest_fill(&line, &[[0.0; 3]], 3), vec![105, 102, 100]);
        // Asking for more than exist: all of them, once.
        let all = farthest_fill(&line, &[[0.0; 3]], 10);
        assert_eq!(all.len(), 6);
        // Ties at the first pick: the first in order.
        let sym = [(0, [1.0, 0.0, 0.0]), (1, [-1.0, 0.0, 0.0])];
        assert_eq!(farthest_fill(&sym, &[[0.0; 3]], 1), vec![0]);
    }
}
