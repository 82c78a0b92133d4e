//! Exact shortest open path with a fixed start (an "open TSP"), for the `random-tsp` planner
//! (SPEC §5, paper "Random+TSP"): after drawing K random feasible candidates, the planner visits
//! them in the order that minimizes the camera's travel length. The order must be *exact*:
//! otherwise the baseline's path cost (PC) would measure the quality of a routing heuristic rather
//! than the planner's view choice.
//!
//! Problem: a square matrix `dist[i][j]` (finite, ≥ 0; the cost of going from node i to node j —
//! for the planner, shell distances between camera centres in normalized object units) and a
//! start node s. Find the order of all nodes that starts at s, ends anywhere and minimizes
//! `Σ dist[o_k][o_{k+1}]`. The matrix may be asymmetric.
//!
//! Methods ([`shortest_open_path`]):
//!
//! - n ≤ 2, or n ≤ [`TspSettings::dp_max_nodes`]: Held–Karp dynamic programming over subsets,
//!   O(n² 2ⁿ) time and O(n 2ⁿ) memory, exact in floating point (each state's length is summed
//!   along its path in order, exactly as [`open_path_length`] sums it).
//! - larger n: an integer program solved with HiGHS. A dummy node D at distance 0 from and to every
//!   node closes the path into a tour; the arc D→s (edge {D, s}) is fixed, so the tour reads
//!   s → … → last → D → s. Symmetric matrices use the edge formulation (x_e ∈ {0,1} per
//!   unordered pair, degree 2 at every node); asymmetric ones the arc formulation (out- and
//!   in-degree 1). Subtour elimination constraints Σ_{e ⊆ S} x_e ≤ |S| − 1 are added lazily: solve,
//!   split the integer solution into cycles, add one constraint per cycle, solve again, until the
//!   solution is a single tour. Every solve is warm-started with the best path found so far,
//!   which starts as nearest neighbour + 2-opt + Or-opt ([`heuristic_open_path`]) and is improved by
//!   patching each subtour solution into a path. HiGHS runs with a relative and absolute gap of
//!   0; each solve is the optimum of a relaxation (fewer subtour constraints), hence a lower bound,
//!   and the loop stops as soon as the best path meets it.
//! - symmetric instances of at least [`LP_CUTS_MIN_NODES`] nodes (a hybrid's set-cover plan of
//!   50–129 views) first run an *LP stage*: the LP relaxation is solved and every subtour
//!   constraint its solution violates is added (the support's components, or the cuts below 2
//!   of a Stoer–Wagner minimum cut), until none is (the Held–Karp bound); a path read off the
//!   LP solution (greedy edges by LP value) and improved by 2-opt + Or-opt replaces the
//!   heuristic path when shorter; and every edge whose LP reduced cost exceeds the gap between
//!   the best path and the LP bound (plus a margin of 1e-3 × the length, far above the LP's
//!   tolerances) is fixed at 0 — no shortest path can use it — before each integer solve. All
//!   three only tighten or shrink the integer program: its optimum, hence the returned length,
//!   is the same; the integer loop then needs fewer and smaller solves.
//!
//! Measured (ci profile, a shared 2-core VM, shell distances of random points on the radius-3
//! sphere): the DP takes ~6 ms at 16 nodes and ~0.2 s at 20; the ILP 0.02–0.09 s at 31 nodes,
//! 0.03–0.3 s at 51, 0.15–0.35 s at 65 and 0.6–9 s at 129 (2–12 HiGHS solves) without the LP
//! stage; `cargo run --profile ci -p objview-planners --example tsp_bench` times both on the
//! same instances (README, "Hybrid planners").
//!
//! Exactness: "optimal" means proven by the DP, or by HiGHS within its numerical tolerances plus
//! a relative slack of [`OPTIMALITY_RTOL`] between the best path and the proven bound. If the
//! time limit stops the ILP, the best path found is returned with `optimal: false` and the proven
//! lower bound; optimality is never claimed then.
//!
//! Determinism: the DP breaks ties towards smaller node indices; the heuristics are deterministic;
//! HiGHS runs on one thread with a fixed seed. The same input therefore gives the same order
//! (runs stopped by the time limit depend on machine speed). HiGHS solves on different threads
//! run concurrently (thread-local schedulers, every instance with `threads` = 1; see
//! `objview_difficulty::ilp`).

use std::time::Instant;

use highs::{Col, HighsModelStatus, RowProblem, Sense};
use serde::{Deserialize, Serialize};

/// Default wall-clock limit of one solve, seconds.
pub const DEFAULT_TIME_LIMIT_S: f64 = 60.0;
/// Default largest node count solved by the Held–Karp DP (larger instances go to the ILP).
/// At 16 nodes the DP takes a few milliseconds and about 4.4 MB; the ILP is no faster there.
pub const DEFAULT_DP_MAX_NODES: usize = 16;
/// Largest allowed [`TspSettings::dp_max_nodes`]: the DP at 20 nodes needs about 90 MB and a
/// fraction of a second; beyond that it grows ×2 in memory per node.
pub const DP_NODES_LIMIT: usize = 20;
/// Relative slack (× max(1, bound)) under which a path whose length meets a proven lower bound is
/// declared optimal.
pub const OPTIMALITY_RTOL: f64 = 1e-9;
/// HiGHS `random_seed` (fixed for determinism).
const HIGHS_RANDOM_SEED: i32 = 0;
/// Symmetric instances with at least this many nodes tighten the LP relaxation with subtour
/// constraints before the first integer solve (the LP stage, module docs). Smaller ones are solved
/// as before: there the integer loop takes a few hundredths of a second.
pub const LP_CUTS_MIN_NODES: usize = 48;
/// A subtour constraint is added by the LP stage when the cut around its set carries less than
/// 2 − this (the constraint is violated by more than half of it).
const CUT_EPS: f64 = 1e-6;
/// Most LP rounds of [`tighten_relaxation`].
const MAX_LP_ROUNDS: usize = 100;
/// Relative margin (× max(1, length)) of the reduced-cost fixing after the LP stage: an edge
/// is fixed at 0 only when its reduced cost exceeds the gap between the best path and the LP
/// bound by this much more — orders of magnitude above HiGHS's tolerances (1e-7), so that no
/// edge of a shortest path is ever fixed.
const FIX_MARGIN: f64 = 1e-3;
/// Relative size of the smallest improvement a local-search move must bring (guards against
/// cycling on rounding noise).
const IMPROVE_RTOL: f64 = 1e-10;

/// Invalid input or a solver failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TspError {
    /// No nodes.
    #[error("the distance matrix is empty: a path needs at least the start node")]
    Empty,
    /// A row of the wrong length.
    #[error("the distance matrix is not square: it has {n} rows but row {row} has {len} entries")]
    NotSquare {
        /// Number of rows.
        n: usize,
        /// The first row of the wrong length.
        row: usize,
        /// Its length.
        len: usize,
    },
    /// NaN or ±∞.
    #[error("distance [{i}][{j}] = {value} is not finite")]
    NonFinite {
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The entry.
        value: f64,
    },
    /// A negative distance.
    #[error("distance [{i}][{j}] = {value} is negative; distances must be non-negative")]
    Negative {
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The entry.
        value: f64,
    },
    /// The start node is not a node.
    #[error("start node {start} is out of range: the distance matrix has {n} nodes")]
    StartOutOfRange {
        /// The start node asked for.
        start: usize,
        /// Number of nodes.
        n: usize,
    },
    /// A setting outside its range.
    #[error("invalid TSP setting {name} = {value}: {reason}")]
    InvalidSetting {
        /// The setting's name (a [`TspSettings`] field).
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// HiGHS failed or returned an inconsistent answer.
    #[error("HiGHS failed on the open-path ILP over {n} nodes: {message}")]
    Solver {
        /// Number of nodes.
        n: usize,
        /// What went wrong.
        message: String,
    },
}

/// How the returned order was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TspMethod {
    /// Held–Karp dynamic programming (exact; also the trivial n ≤ 2 cases).
    Dp,
    /// The ILP stage proved the order optimal (normally by HiGHS; for degenerate instances the
    /// heuristic path may already meet the trivial bound, with no HiGHS solve).
    Ilp,
    /// The time limit stopped the ILP before it proved optimality: the best path found
    /// (heuristic, patched subtours or a HiGHS incumbent), not proven optimal.
    Heuristic,
}

impl TspMethod {
    /// The wire name (`dp`, `ilp`, `heuristic`).
    pub fn as_str(self) -> &'static str {
        match self {
            TspMethod::Dp => "dp",
            TspMethod::Ilp => "ilp",
            TspMethod::Heuristic => "heuristic",
        }
    }
}

impl std::fmt::Display for TspMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Settings of [`shortest_open_path`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TspSettings {
    /// Wall-clock limit of the solve (heuristic + ILP), seconds; may be +∞. The DP ignores it
    /// (it is bounded by [`DP_NODES_LIMIT`]).
    pub time_limit_s: f64,
    /// Instances with at most this many nodes are solved by the Held–Karp DP (≤
    /// [`DP_NODES_LIMIT`]); 0 sends every instance with more than 2 nodes to the ILP.
    pub dp_max_nodes: usize,
}

impl Default for TspSettings {
    fn default() -> Self {
        Self { time_limit_s: DEFAULT_TIME_LIMIT_S, dp_max_nodes: DEFAULT_DP_MAX_NODES }
    }
}

impl TspSettings {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), TspError> {
        if self.time_limit_s.is_nan() || self.time_limit_s <= 0.0 {
            return Err(TspError::InvalidSetting {
                name: "time_limit_s",
                value: self.time_limit_s,
                reason: "must be positive (or +inf)",
            });
        }
        if self.dp_max_nodes > DP_NODES_LIMIT {
            return Err(TspError::InvalidSetting {
                name: "dp_max_nodes",
                value: self.dp_max_nodes as f64,
                reason: "the Held-Karp DP is limited to 20 nodes (memory grows as n·2^n)",
            });
        }
        Ok(())
    }
}

/// Result of [`shortest_open_path`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TspResult {
    /// Every node exactly once, starting with the start node.
    pub order: Vec<usize>,
    /// Length of `order` ([`open_path_length`]; for the planner: normalized object units).
    pub length: f64,
    /// Whether `order` is proven shortest (see the module docs for the tolerance).
    pub optimal: bool,
    /// How `order` was obtained.
    pub method: TspMethod,
    /// Proven lower bound on the shortest length (≤ `length`; equal for the DP).
    pub lower_bound: f64,
    /// Length of the nearest-neighbour + 2-opt + Or-opt path (ILP only).
    pub heuristic_length: Option<f64>,
    /// Whether the matrix is exactly symmetric (the ILP then uses the edge formulation).
    pub symmetric: bool,
    /// Wall-clock time of the solve, seconds.
    pub seconds: f64,
    /// Number of HiGHS solves (0 for the DP).
    pub ilp_solves: usize,
    /// Number of subtour elimination constraints added (by the LP stage and the integer loop).
    pub cuts: usize,
    /// Number of LP solves of the LP stage (symmetric instances of at least
    /// [`LP_CUTS_MIN_NODES`] nodes; absent from the JSON when 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lp_solves: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The shortest path over all nodes of `dist` that starts at `start` and ends anywhere (see the
/// module docs for the methods and what "optimal" guarantees).
///
/// Errors: an empty or non-square matrix, a non-finite or negative entry, `start` out of range,
/// invalid settings, or a HiGHS failure.
pub fn shortest_open_path(
    dist: &[Vec<f64>],
    start: usize,
    settings: &TspSettings,
) -> Result<TspResult, TspError> {
    shortest_open_path_with_lp_stage_from(dist, start, settings, LP_CUTS_MIN_NODES)
}

/// [`shortest_open_path`] with the LP stage's node threshold chosen (`usize::MAX`: the integer
/// loop alone, as below [`LP_CUTS_MIN_NODES`]) — for benchmarks and tests that compare the two
/// on the same instances.
pub fn shortest_open_path_with_lp_stage_from(
    dist: &[Vec<f64>],
    start: usize,
    settings: &TspSettings,
    lp_cuts_min_nodes: usize,
) -> Result<TspResult, TspError> {
    settings.validate()?;
    validate_matrix(dist, start)?;
    let t0 = Instant::now();
    let n = dist.len();
    let symmetric = is_symmetric(dist);
    let mut result = if n <= 2 || n <= settings.dp_max_nodes {
        let order = held_karp(dist, start);
        let length = open_path_length(dist, &order);
        TspResult {
            order,
            length,
            optimal: true,
            method: TspMethod::Dp,
            lower_bound: length,
            heuristic_length: None,
            symmetric,
            seconds: 0.0,
            ilp_solves: 0,
            cuts: 0,
            lp_solves: 0,
        }
    } else {
        solve_with_ilp(dist, start, symmetric, settings, t0, lp_cuts_min_nodes)?
    };
    result.seconds = t0.elapsed().as_secs_f64();
    Ok(result)
}

/// Length of the open path `order` under `dist`: `Σ dist[o_k][o_{k+1}]`, summed in order
/// (0 for fewer than two nodes). Indices must be in range.
pub fn open_path_length(dist: &[Vec<f64>], order: &[usize]) -> f64 {
    order.windows(2).map(|w| dist[w[0]][w[1]]).sum()
}

/// A good (not necessarily shortest) open path from `start`: nearest neighbour (ties to the
/// smaller index), then 2-opt and Or-opt (segments of 1–3 nodes, either direction) until no move
/// shortens it. Deterministic. The ILP's initial upper bound.
pub fn heuristic_open_path(dist: &[Vec<f64>], start: usize) -> Result<Vec<usize>, TspError> {
    validate_matrix(dist, start)?;
    Ok(heuristic(dist, start))
}

fn validate_matrix(dist: &[Vec<f64>], start: usize) -> Result<(), TspError> {
    let n = dist.len();
    if n == 0 {
        return Err(TspError::Empty);
    }
    for (i, row) in dist.iter().enumerate() {
        if row.len() != n {
            return Err(TspError::NotSquare { n, row: i, len: row.len() });
        }
        for (j, &value) in row.iter().enumerate() {
            if !value.is_finite() {
                return Err(TspError::NonFinite { i, j, value });
            }
            if value < 0.0 {
                return Err(TspError::Negative { i, j, value });
            }
        }
    }
    if start >= n {
        return Err(TspError::StartOutOfRange { start, n });
    }
    Ok(())
}

fn is_symmetric(dist: &[Vec<f64>]) -> bool {
    (0..dist.len()).all(|i| (i + 1..dist.len()).all(|j| dist[i][j] == dist[j][i]))
}

// ---------------------------------------------------------------------------------------------
// Held–Karp
// ---------------------------------------------------------------------------------------------

/// Held–Karp over the non-start nodes `others` (bit k = others[k]): `cost[mask·m + j]` is the
/// length of the shortest path from `start` through exactly the nodes of `mask`, ending at
/// others[j]. Ties go to the smaller predecessor index and the smaller end index.
fn held_karp(dist: &[Vec<f64>], start: usize) -> Vec<usize> {
    let n = dist.len();
    let others: Vec<usize> = (0..n).filter(|&v| v != start).collect();
    let m = others.len();
    if m == 0 {
        return vec![start];
    }
    debug_assert!(m < usize::BITS as usize && m < u8::MAX as usize);
    let full = (1usize << m) - 1;
    const FROM_START: u8 = u8::MAX;
    let mut cost = vec![f64::INFINITY; (full + 1) * m];
    let mut parent = vec![FROM_START; (full + 1) * m];
    for (j, &v) in others.iter().enumerate() {
        cost[(1 << j) * m + j] = dist[start][v];
    }
    for mask in 1..=full {
        if mask.count_ones() < 2 {
            continue;
        }
        let mut ends = mask;
        while ends != 0 {
            let j = ends.trailing_zeros() as usize;
            ends &= ends - 1;
            let prev = mask ^ (1 << j);
            let to = others[j];
            let (mut best, mut arg) = (f64::INFINITY, FROM_START);
            let mut preds = prev;
            while preds != 0 {
                let i = preds.trailing_zeros() as usize;
                preds &= preds - 1;
                let c = cost[prev * m + i] + dist[others[i]][to];
                if c < best {
                    best = c;
                    arg = i as u8;
                }
            }
            cost[mask * m + j] = best;
            parent[mask * m + j] = arg;
        }
    }
    let mut end = 0;
    for j in 1..m {
        if cost[full * m + j] < cost[full * m + end] {
            end = j;
        }
    }
    let mut rev = Vec::with_capacity(n);
    let (mut mask, mut j) = (full, end);
    loop {
        rev.push(others[j]);
        let p = parent[mask * m + j];
        mask ^= 1 << j;
        if p == FROM_START {
            break;
        }
        j = p as usize;
    }
    debug_assert_eq!(mask, 0);
    rev.push(start);
    rev.reverse();
    rev
}

// ---------------------------------------------------------------------------------------------
// Heuristics (upper bounds)
// ---------------------------------------------------------------------------------------------

fn heuristic(dist: &[Vec<f64>], start: usize) -> Vec<usize> {
    let mut order = nearest_neighbour(dist, start);
    local_search(dist, &mut order);
    order
}

fn nearest_neighbour(dist: &[Vec<f64>], start: usize) -> Vec<usize> {
    let n = dist.len();
    let mut visited = vec![false; n];
    visited[start] = true;
    let mut order = Vec::with_capacity(n);
    order.push(start);
    let mut current = start;
    for _ in 1..n {
        let mut next = usize::MAX;
        for v in 0..n {
            if !visited[v] && (next == usize::MAX || dist[current][v] < dist[current][next]) {
                next = v;
            }
        }
        visited[next] = true;
        order.push(next);
        current = next;
    }
    order
}

/// Cost of the arc a → b, 0 when b is past the end of the path.
fn arc(dist: &[Vec<f64>], a: usize, b: Option<usize>) -> f64 {
    b.map_or(0.0, |b| dist[a][b])
}

fn improves(new: f64, old: f64) -> bool {
    new < old - IMPROVE_RTOL * (1.0 + old.abs())
}

/// 2-opt and Or-opt moves (first improvement) until none shortens the path; `order[0]` stays.
fn local_search(dist: &[Vec<f64>], order: &mut Vec<usize>) {
    // Each accepted move shortens the path, so this terminates; the cap only bounds the time.
    let max_moves = 100 * order.len() * order.len() + 1000;
    for _ in 0..max_moves {
        if !two_opt_move(dist, order) && !or_opt_move(dist, order) {
            break;
        }
    }
}

/// Applies the first improving reversal of a sub-path `order[i..=j]` (1 ≤ i < j); asymmetric
/// matrices are handled by comparing the segment's forward and backward internal lengths.
fn two_opt_move(dist: &[Vec<f64>], o: &mut [usize]) -> bool {
    let n = o.len();
    for i in 1..n.saturating_sub(1) {
        let before = o[i - 1];
        let (mut forward, mut backward) = (0.0, 0.0);
        for j in i + 1..n {
            forward += dist[o[j - 1]][o[j]];
            backward += dist[o[j]][o[j - 1]];
            let after = o.get(j + 1).copied();
            let old = dist[before][o[i]] + forward + arc(dist, o[j], after);
            let new = dist[before][o[j]] + backward + arc(dist, o[i], after);
            if improves(new, old) {
                o[i..=j].reverse();
                return true;
            }
        }
    }
    false
}

/// Applies the first improving move of a segment of 1–3 nodes (not the start) to another place
/// in the path, possibly reversed.
fn or_opt_move(dist: &[Vec<f64>], o: &mut Vec<usize>) -> bool {
    let n = o.len();
    for len in 1..=3usize {
        for i in 1..n {
            let e = i + len - 1;
            if e >= n {
                break;
            }
            let (prev, first, last, next) = (o[i - 1], o[i], o[e], o.get(e + 1).copied());
            let forward: f64 = (i..e).map(|k| dist[o[k]][o[k + 1]]).sum();
            let backward: f64 = (i..e).map(|k| dist[o[k + 1]][o[k]]).sum();
            // Length saved by taking the segment out.
            let removed = dist[prev][first] + forward + arc(dist, last, next) - arc(dist, prev, next);
            for p in 0..n {
                if p + 1 >= i && p <= e {
                    continue; // p ∈ [i−1, e]: the segment's own place
                }
                let (a, b) = (o[p], o.get(p + 1).copied());
                let base = arc(dist, a, b);
                let add_forward = dist[a][first] + forward + arc(dist, last, b) - base;
                if improves(add_forward, removed) {
                    move_segment(o, i, e, p, false);
                    return true;
                }
                if len > 1 {
                    let add_reversed = dist[a][last] + backward + arc(dist, first, b) - base;
                    if improves(add_reversed, removed) {
                        move_segment(o, i, e, p, true);
                        return true;
                    }
                }
            }
        }
    }
    false
}

/// Moves `o[i..=e]` to just after the node now at position `p` (outside the segment).
fn move_segment(o: &mut Vec<usize>, i: usize, e: usize, p: usize, reversed: bool) {
    let mut segment: Vec<usize> = o.drain(i..=e).collect();
    if reversed {
        segment.reverse();
    }
    let at = if p < i { p + 1 } else { p + 1 - segment.len() };
    o.splice(at..at, segment);
}

/// Joins the cycles of a subtour solution into one path from `start`: `cycles[0]` is the path
/// s → … (the cycle through the dummy, dummy removed); every other cycle is opened at its best
/// edge and inserted, in either direction, where it adds the least length; then local search.
fn patch_subtours(dist: &[Vec<f64>], start: usize, cycles: &[Vec<usize>]) -> Vec<usize> {
    let mut path = cycles[0].clone();
    debug_assert_eq!(path.first(), Some(&start));
    for cycle in &cycles[1..] {
        let c = cycle.len();
        let forward: f64 = (0..c).map(|k| dist[cycle[k]][cycle[(k + 1) % c]]).sum();
        let backward: f64 = (0..c).map(|k| dist[cycle[(k + 1) % c]][cycle[k]]).sum();
        // (delta, insert after path[p], open before cycle[r], reversed)
        let mut best: Option<(f64, usize, usize, bool)> = None;
        for p in 0..path.len() {
            let (a, b) = (path[p], path.get(p + 1).copied());
            let base = arc(dist, a, b);
            for r in 0..c {
                let (head, tail) = (cycle[r], cycle[(r + c - 1) % c]);
                // Forward: head … tail, dropping the arc tail → head.
                let df = dist[a][head] + (forward - dist[tail][head]) + arc(dist, tail, b) - base;
                // Reversed: tail … head, dropping the arc head → tail of the reversed cycle.
                let dr = dist[a][tail] + (backward - dist[head][tail]) + arc(dist, head, b) - base;
                for (delta, reversed) in [(df, false), (dr, true)] {
                    if best.is_none_or(|(d, ..)| delta < d) {
                        best = Some((delta, p, r, reversed));
                    }
                }
            }
        }
        if let Some((_, p, r, reversed)) = best {
            let mut segment: Vec<usize> = cycle[r..].iter().chain(&cycle[..r]).copied().collect();
            if reversed {
                segment.reverse();
            }
            path.splice(p + 1..p + 1, segment);
        }
    }
    local_search(dist, &mut path);
    path
}

/// Σ_{j ≠ start} min_{i ≠ j} dist[i][j]: every node but the start is entered exactly once.
fn trivial_lower_bound(dist: &[Vec<f64>], start: usize) -> f64 {
    let n = dist.len();
    (0..n)
        .filter(|&j| j != start)
        .map(|j| (0..n).filter(|&i| i != j).map(|i| dist[i][j]).fold(f64::INFINITY, f64::min))
        .sum()
}

// ---------------------------------------------------------------------------------------------
// ILP
// ---------------------------------------------------------------------------------------------

/// One ILP variable: the edge {u, v} (symmetric) or the arc u → v (asymmetric), over the nodes
/// 0..n and the dummy n.
#[derive(Debug, Clone, Copy)]
struct Var {
    u: usize,
    v: usize,
    cost: f64,
    fixed: bool,
    /// Fixed at 0: no tour through this edge is shorter than the best path known
    /// ([`tighten_relaxation`]'s reduced-cost test).
    banned: bool,
}

/// The variables of the open-path ILP and an index from node pairs to them.
struct Formulation {
    n_nodes: usize,
    symmetric: bool,
    vars: Vec<Var>,
    /// `index[u·n_nodes + v]`: the variable of (u, v) (both orders when symmetric).
    index: Vec<Option<usize>>,
}

impl Formulation {
    fn new(dist: &[Vec<f64>], start: usize, symmetric: bool) -> Formulation {
        let n = dist.len();
        let dummy = n;
        let mut vars = Vec::new();
        if symmetric {
            for (i, row) in dist.iter().enumerate() {
                for (j, &cost) in row.iter().enumerate().skip(i + 1) {
                    vars.push(Var { u: i, v: j, cost, fixed: false, banned: false });
                }
            }
            for j in 0..n {
                vars.push(Var { u: j, v: dummy, cost: 0.0, fixed: j == start, banned: false });
            }
        } else {
            // Nothing enters the start but the dummy; the dummy leaves only to the start.
            for (i, row) in dist.iter().enumerate() {
                for (j, &cost) in row.iter().enumerate() {
                    if i != j && j != start {
                        vars.push(Var { u: i, v: j, cost, fixed: false, banned: false });
                    }
                }
            }
            for j in (0..n).filter(|&j| j != start) {
                vars.push(Var { u: j, v: dummy, cost: 0.0, fixed: false, banned: false });
            }
            vars.push(Var { u: dummy, v: start, cost: 0.0, fixed: true, banned: false });
        }
        let n_nodes = n + 1;
        let mut index = vec![None; n_nodes * n_nodes];
        for (k, var) in vars.iter().enumerate() {
            index[var.u * n_nodes + var.v] = Some(k);
            if symmetric {
                index[var.v * n_nodes + var.u] = Some(k);
            }
        }
        Formulation { n_nodes, symmetric, vars, index }
    }

    /// 0/1 values of the tour start → order… → dummy → start.
    fn values_of(&self, order: &[usize]) -> Vec<f64> {
        let dummy = self.n_nodes - 1;
        let mut x = vec![0.0; self.vars.len()];
        let last = order.last().copied().unwrap_or(dummy);
        let hops = order.windows(2).map(|w| (w[0], w[1])).chain([(last, dummy), (dummy, order[0])]);
        for (u, v) in hops {
            if let Some(k) = self.index[u * self.n_nodes + v] {
                x[k] = 1.0;
            }
        }
        x
    }

    /// Splits a 0/1 solution (chosen variables) into cycles. The first is the one through the
    /// start, as the path start → … (dummy removed); the others follow from their smallest node.
    fn cycles(&self, chosen: &[usize], start: usize) -> Result<Vec<Vec<usize>>, String> {
        let nn = self.n_nodes;
        let dummy = nn - 1;
        // succ/pred for arcs; for edges, the two neighbours (an orientation is chosen below).
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nn];
        let mut indeg = vec![0usize; nn];
        for &k in chosen {
            let Var { u, v, .. } = self.vars[k];
            adj[u].push(v);
            indeg[v] += 1;
            if self.symmetric {
                adj[v].push(u);
            }
        }
        for (node, nbrs) in adj.iter_mut().enumerate() {
            let ok = if self.symmetric { nbrs.len() == 2 } else { nbrs.len() == 1 && indeg[node] == 1 };
            if !ok {
                return Err(format!("the solution violates the degree constraints at node {node}"));
            }
            nbrs.sort_unstable();
        }
        let mut seen = vec![false; nn];
        let mut cycles = Vec::new();
        // The start's cycle, walked away from the dummy.
        let first_step = if self.symmetric {
            if adj[start][0] == dummy {
                adj[start][1]
            } else if adj[start][1] == dummy {
                adj[start][0]
            } else {
                return Err("the fixed edge {dummy, start} is not in the solution".into());
            }
        } else {
            adj[start][0]
        };
        let walk = |from: usize, step: usize, seen: &mut Vec<bool>| -> Result<Vec<usize>, String> {
            let mut cycle = vec![from];
            seen[from] = true;
            let (mut prev, mut cur) = (from, step);
            while cur != from {
                if seen[cur] || cycle.len() > nn {
                    return Err(format!("the solution is not a union of cycles (node {cur})"));
                }
                seen[cur] = true;
                cycle.push(cur);
                let next = if self.symmetric {
                    if adj[cur][0] == prev {
                        adj[cur][1]
                    } else {
                        adj[cur][0]
                    }
                } else {
                    adj[cur][0]
                };
                prev = cur;
                cur = next;
            }
            Ok(cycle)
        };
        let mut head = walk(start, first_step, &mut seen)?;
        if head.last() != Some(&dummy) {
            return Err("the start's cycle does not end at the dummy node".into());
        }
        head.pop();
        cycles.push(head);
        for v in 0..nn {
            if !seen[v] {
                let step = adj[v][0];
                cycles.push(walk(v, step, &mut seen)?);
            }
        }
        Ok(cycles)
    }
}

/// Outcome of one HiGHS solve.
struct IlpRun {
    status: HighsModelStatus,
    /// Variables at 1, when HiGHS has a feasible solution.
    chosen: Option<Vec<usize>>,
    objective: f64,
    dual_bound: Option<f64>,
}

fn run_highs(
    form: &Formulation,
    cuts: &[Vec<usize>],
    warm: &[f64],
    time_limit: f64,
) -> Result<IlpRun, String> {
    let costs: Vec<f64> = form.vars.iter().map(|var| var.cost).collect();
    // The warm start only helps pruning; the solution is HiGHS's own (checked against its
    // objective: `objview_difficulty::warm`).
    let run =
        objview_difficulty::warm::solve_from(|| build_model(form, cuts, true, time_limit), warm, &costs)?;
    Ok(IlpRun {
        status: run.solved.status(),
        chosen: run.chosen(form.vars.len()),
        objective: run.solved.objective_value(),
        dual_bound: run.solved.double_info_value(c"mip_dual_bound").ok().filter(|b| b.is_finite()),
    })
}

/// The HiGHS model of `form` with the subtour constraints of `cuts`: 0/1 variables when
/// `integer`, else its LP relaxation (0 ≤ x ≤ 1); one thread, fixed seed, zero MIP gaps,
/// `time_limit` seconds; its columns are `form.vars`, in order.
fn build_model(
    form: &Formulation,
    cuts: &[Vec<usize>],
    integer: bool,
    time_limit: f64,
) -> Result<highs::Model, String> {
    let nn = form.n_nodes;
    let mut pb = RowProblem::default();
    let cols: Vec<Col> = form
        .vars
        .iter()
        .map(|var| {
            let low = if var.fixed { 1.0 } else { 0.0 };
            let high = if var.banned { 0.0 } else { 1.0 };
            pb.add_column_with_integrality(var.cost, low..=high, integer)
        })
        .collect();
    if form.symmetric {
        let mut incident: Vec<Vec<(Col, f64)>> = vec![Vec::new(); nn];
        for (var, &col) in form.vars.iter().zip(&cols) {
            incident[var.u].push((col, 1.0));
            incident[var.v].push((col, 1.0));
        }
        for row in incident {
            pb.add_row(2.0..=2.0, row);
        }
    } else {
        let mut out: Vec<Vec<(Col, f64)>> = vec![Vec::new(); nn];
        let mut inc: Vec<Vec<(Col, f64)>> = vec![Vec::new(); nn];
        for (var, &col) in form.vars.iter().zip(&cols) {
            out[var.u].push((col, 1.0));
            inc[var.v].push((col, 1.0));
        }
        for row in out.into_iter().chain(inc) {
            pb.add_row(1.0..=1.0, row);
        }
    }
    let mut inside = vec![false; nn];
    for set in cuts {
        set.iter().for_each(|&v| inside[v] = true);
        let row: Vec<(Col, f64)> = form
            .vars
            .iter()
            .zip(&cols)
            .filter(|(var, _)| inside[var.u] && inside[var.v])
            .map(|(_, &col)| (col, 1.0))
            .collect();
        pb.add_row(..=(set.len() - 1) as f64, row);
        set.iter().for_each(|&v| inside[v] = false);
    }
    let mut model =
        pb.try_optimise(Sense::Minimise).map_err(|s| format!("HiGHS rejected the model: {s:?}"))?;
    for (name, r) in [
        ("output_flag", model.try_set_option("output_flag", false)),
        ("log_to_console", model.try_set_option("log_to_console", false)),
        ("threads", model.try_set_option("threads", 1)),
        ("parallel", model.try_set_option("parallel", "off")),
        ("random_seed", model.try_set_option("random_seed", HIGHS_RANDOM_SEED)),
        ("time_limit", model.try_set_option("time_limit", time_limit)),
        ("mip_rel_gap", model.try_set_option("mip_rel_gap", 0.0)),
        ("mip_abs_gap", model.try_set_option("mip_abs_gap", 0.0)),
    ] {
        r.map_err(|e| format!("HiGHS option {name}: {e:?}"))?;
    }
    Ok(model)
}

/// The ILP stage; symmetric instances of at least `lp_cuts_min_nodes` nodes start with the LP
/// stage ([`tighten_relaxation`], [`lp_guided_path`], [`ban_by_reduced_costs`]).
fn solve_with_ilp(
    dist: &[Vec<f64>],
    start: usize,
    symmetric: bool,
    settings: &TspSettings,
    t0: Instant,
    lp_cuts_min_nodes: usize,
) -> Result<TspResult, TspError> {
    let n = dist.len();
    let solver_error = |message: String| TspError::Solver { n, message };
    let remaining = || settings.time_limit_s - t0.elapsed().as_secs_f64();
    let proven = |length: f64, bound: f64| length <= bound + OPTIMALITY_RTOL * bound.abs().max(1.0);

    let mut best = heuristic(dist, start);
    let mut best_len = open_path_length(dist, &best);
    let heuristic_length = best_len;
    let mut lower = trivial_lower_bound(dist, start);
    let mut form = Formulation::new(dist, start, symmetric);
    let mut cuts: Vec<Vec<usize>> = Vec::new();
    let mut solves = 0;
    let mut optimal = proven(best_len, lower);
    let mut lp_solves = 0;
    let mut fixing: Option<LpSolution> = None;
    if symmetric && n >= lp_cuts_min_nodes && !optimal {
        let (solves, lp) = tighten_relaxation(&form, &mut cuts, &remaining).map_err(solver_error)?;
        lp_solves = solves;
        if let Some(lp) = lp {
            // A path read off the LP solution, improved by the local search: usually much
            // closer to the optimum than the nearest-neighbour start, so the fixing below
            // removes more edges.
            let guided = lp_guided_path(&form, dist, start, &lp.values);
            let guided_len = open_path_length(dist, &guided);
            if guided_len < best_len {
                best = guided;
                best_len = guided_len;
            }
            lower = lower.max(lp.value);
            optimal = proven(best_len, lower);
            ban_by_reduced_costs(&mut form, &lp, best_len);
            fixing = Some(lp);
        }
    }

    while !optimal {
        let limit = remaining();
        if limit <= 0.0 {
            break;
        }
        let warm = form.values_of(&best);
        if let Some(lp) = &fixing {
            ban_by_reduced_costs(&mut form, lp, best_len);
        }
        let run = run_highs(&form, &cuts, &warm, limit).map_err(solver_error)?;
        solves += 1;
        let stopped = match run.status {
            HighsModelStatus::Optimal => false,
            HighsModelStatus::ReachedTimeLimit => true,
            other => return Err(solver_error(format!("HiGHS model status {other:?}"))),
        };
        // Every solve is a relaxation (some subtour constraints missing): its bound is valid.
        let bound = match (stopped, run.dual_bound) {
            (false, Some(b)) => Some(b.min(run.objective)),
            (false, None) => Some(run.objective),
            (true, b) => b,
        };
        if let Some(b) = bound {
            lower = lower.max(b);
        }
        let Some(chosen) = run.chosen else {
            if stopped {
                break;
            }
            return Err(solver_error("HiGHS reported an optimum without a solution".into()));
        };
        let cycles = form.cycles(&chosen, start).map_err(solver_error)?;
        if cycles.len() == 1 {
            let length = open_path_length(dist, &cycles[0]);
            if length < best_len {
                best = cycles.into_iter().next().unwrap_or_default();
                best_len = length;
            }
            // A single tour that is optimal for the relaxation is optimal for the problem.
            optimal = !stopped || proven(best_len, lower);
        } else {
            let patched = patch_subtours(dist, start, &cycles);
            let length = open_path_length(dist, &patched);
            if length < best_len {
                best = patched;
                best_len = length;
            }
            optimal = proven(best_len, lower);
            cuts.extend(cycles.into_iter().enumerate().map(|(k, mut c)| {
                if k == 0 {
                    c.push(n); // the start's cycle runs through the dummy
                }
                c
            }));
        }
        if stopped {
            break;
        }
    }

    if lower > best_len {
        if lower > best_len + OPTIMALITY_RTOL * best_len.max(1.0) {
            return Err(solver_error(format!(
                "the proven lower bound {lower} exceeds the length {best_len} of a valid path"
            )));
        }
        lower = best_len;
    }
    debug_assert_eq!(best.len(), n);
    Ok(TspResult {
        order: best,
        length: best_len,
        optimal,
        method: if optimal { TspMethod::Ilp } else { TspMethod::Heuristic },
        lower_bound: lower,
        heuristic_length: Some(heuristic_length),
        symmetric,
        seconds: 0.0,
        ilp_solves: solves,
        cuts: cuts.len(),
        lp_solves,
    })
}

/// The LP stage of symmetric instances: solves the LP relaxation (degree constraints and
/// `cuts`), adds every subtour constraint the solution violates ([`violated_subtours`]) and
/// solves again, until none is violated (the relaxation then holds every subtour constraint:
/// the Held–Karp bound), the time is up or [`MAX_LP_ROUNDS`] rounds have run. Returns the number
/// of LP solves.
///
/// Exact: subtour constraints hold for every tour, so the integer program afterwards has the
/// same optimum; they only make its relaxation, and so its branch and bound, tighter. With
/// them the integer loop needs a solve or two where it needed up to a dozen, each a branch and
/// bound of its own.
fn tighten_relaxation(
    form: &Formulation,
    cuts: &mut Vec<Vec<usize>>,
    remaining: &dyn Fn() -> f64,
) -> Result<(usize, Option<LpSolution>), String> {
    let mut solves = 0;
    let mut last = None;
    let mut known: std::collections::HashSet<Vec<usize>> = cuts.iter().map(|c| sorted(c)).collect();
    for _ in 0..MAX_LP_ROUNDS {
        let limit = remaining();
        if limit <= 0.0 {
            break;
        }
        let model = build_model(form, cuts, false, limit)?;
        let solved = model.try_solve().map_err(|s| format!("HiGHS LP run failed: {s:?}"))?;
        solves += 1;
        match solved.status() {
            HighsModelStatus::Optimal => {}
            // Out of time: the integer loop decides what to do with the time left.
            HighsModelStatus::ReachedTimeLimit => break,
            other => return Err(format!("HiGHS LP status {other:?}")),
        }
        let solution = solved.get_solution();
        let lp = LpSolution {
            values: solution.columns().to_vec(),
            value: solved.objective_value(),
            reduced_costs: solution.dual_columns().to_vec(),
        };
        let mut added = false;
        for set in violated_subtours(form, &lp.values) {
            if known.insert(set.clone()) {
                cuts.push(set);
                added = true;
            }
        }
        last = Some(lp);
        if !added {
            break;
        }
    }
    Ok((solves, last))
}

/// A path guided by the LP solution `x` of the edge formulation `form` of the symmetric `dist`:
/// the greedy edge heuristic over the edges by decreasing LP value (then increasing cost, then
/// node pair; the fixed edge {dummy, start} first) — an edge joins two fragments' ends — closed
/// into a tour through the dummy, read from `start` away from the dummy, then improved by the
/// local search. Deterministic.
fn lp_guided_path(form: &Formulation, dist: &[Vec<f64>], start: usize, x: &[f64]) -> Vec<usize> {
    let nn = form.n_nodes;
    let dummy = nn - 1;
    let mut edges: Vec<usize> = (0..form.vars.len()).collect();
    edges.sort_by(|&a, &b| {
        let (va, vb) = (&form.vars[a], &form.vars[b]);
        vb.fixed
            .cmp(&va.fixed)
            .then(x[b].total_cmp(&x[a]))
            .then(va.cost.total_cmp(&vb.cost))
            .then((va.u, va.v).cmp(&(vb.u, vb.v)))
    });
    let mut parent: Vec<usize> = (0..nn).collect();
    fn find(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nn];
    let mut added = 0;
    for k in edges {
        if added + 1 == nn {
            break;
        }
        let Var { u, v, .. } = form.vars[k];
        if adj[u].len() == 2 || adj[v].len() == 2 {
            continue;
        }
        let (ru, rv) = (find(&mut parent, u), find(&mut parent, v));
        if ru == rv {
            continue;
        }
        parent[ru] = rv;
        adj[u].push(v);
        adj[v].push(u);
        added += 1;
    }
    // One Hamiltonian path over the nodes and the dummy (the graph is complete): its two ends
    // close the tour.
    let ends: Vec<usize> = (0..nn).filter(|&v| adj[v].len() < 2).collect();
    if let [a, b] = ends[..] {
        adj[a].push(b);
        adj[b].push(a);
    }
    let mut order = Vec::with_capacity(nn - 1);
    let (mut prev, mut cur) = (dummy, start);
    while cur != dummy && order.len() < nn {
        order.push(cur);
        let next = if adj[cur][0] == prev { adj[cur][1] } else { adj[cur][0] };
        prev = cur;
        cur = next;
    }
    debug_assert_eq!(order.len(), nn - 1);
    local_search(dist, &mut order);
    order
}

/// Reduced-cost fixing: a tour through edge e is at least the LP optimum + e's reduced cost
/// long (LP duality); above `best_len`, the length of a path known (with the wide margin
/// [`FIX_MARGIN`] for the LP's tolerances), no shortest path uses e, which is fixed at 0.
fn ban_by_reduced_costs(form: &mut Formulation, lp: &LpSolution, best_len: f64) {
    let slack = best_len - lp.value + FIX_MARGIN * best_len.abs().max(1.0);
    for (var, &rc) in form.vars.iter_mut().zip(&lp.reduced_costs) {
        if !var.fixed && rc > slack {
            var.banned = true;
        }
    }
}

/// The last optimal LP of [`tighten_relaxation`]: its value (a lower bound) and the reduced
/// cost of every variable.
struct LpSolution {
    values: Vec<f64>,
    value: f64,
    reduced_costs: Vec<f64>,
}

fn sorted(set: &[usize]) -> Vec<usize> {
    let mut s = set.to_vec();
    s.sort_unstable();
    s
}

/// Node sets (sorted; the smaller side of each cut) whose subtour constraint the LP solution `x`
/// of the edge formulation `form` violates by more than [`CUT_EPS`] / 2: the connected
/// components of its support when there are several, otherwise the cuts of the phases of a
/// Stoer–Wagner minimum cut whose weight is below 2 − [`CUT_EPS`] (x(E(S)) ≤ |S| − 1 is
/// x(δ(S)) ≥ 2 under the degree constraints). Empty when no subtour constraint is violated:
/// the minimum cut is among the phase cuts.
fn violated_subtours(form: &Formulation, x: &[f64]) -> Vec<Vec<usize>> {
    let nn = form.n_nodes;
    let mut w = vec![0.0f64; nn * nn];
    for (var, &value) in form.vars.iter().zip(x) {
        if value > 0.0 {
            w[var.u * nn + var.v] += value;
            w[var.v * nn + var.u] += value;
        }
    }
    let smaller_side = |set: Vec<usize>| -> Vec<usize> {
        if 2 * set.len() <= nn {
            sorted(&set)
        } else {
            let mut inside = vec![false; nn];
            set.iter().for_each(|&v| inside[v] = true);
            (0..nn).filter(|&v| !inside[v]).collect()
        }
    };
    let proper = |set: &Vec<usize>| set.len() >= 2 && set.len() <= nn - 2;
    // Components of the support (edges above CUT_EPS).
    let mut comp = vec![usize::MAX; nn];
    let mut comps: Vec<Vec<usize>> = Vec::new();
    for root in 0..nn {
        if comp[root] != usize::MAX {
            continue;
        }
        let id = comps.len();
        let mut members = vec![root];
        comp[root] = id;
        let mut k = 0;
        while k < members.len() {
            let u = members[k];
            k += 1;
            for v in 0..nn {
                if comp[v] == usize::MAX && w[u * nn + v] > CUT_EPS {
                    comp[v] = id;
                    members.push(v);
                }
            }
        }
        comps.push(members);
    }
    if comps.len() > 1 {
        let mut out: Vec<Vec<usize>> = comps.into_iter().map(smaller_side).filter(proper).collect();
        out.sort();
        out.dedup();
        return out;
    }
    // Stoer–Wagner: every phase's cut (the last node's group against the rest).
    let mut groups: Vec<Vec<usize>> = (0..nn).map(|v| vec![v]).collect();
    let mut active: Vec<usize> = (0..nn).collect();
    let mut out = Vec::new();
    let mut key = vec![0.0f64; nn];
    let mut added = vec![false; nn];
    while active.len() > 1 {
        for &v in &active {
            key[v] = 0.0;
            added[v] = false;
        }
        let (mut last, mut before_last) = (usize::MAX, usize::MAX);
        for _ in 0..active.len() {
            // The most tightly connected node not yet added (ties: the first in `active`).
            let mut best = usize::MAX;
            for &v in &active {
                if !added[v] && (best == usize::MAX || key[v] > key[best]) {
                    best = v;
                }
            }
            added[best] = true;
            before_last = last;
            last = best;
            for &u in &active {
                if !added[u] {
                    key[u] += w[best * nn + u];
                }
            }
        }
        if key[last] < 2.0 - CUT_EPS {
            let set = smaller_side(groups[last].clone());
            if proper(&set) {
                out.push(set);
            }
        }
        // Merge the last node into the one before it.
        let moved = std::mem::take(&mut groups[last]);
        groups[before_last].extend(moved);
        for &u in &active {
            let sum = w[before_last * nn + u] + w[last * nn + u];
            w[before_last * nn + u] = sum;
            w[u * nn + before_last] = sum;
        }
        w[before_last * nn + before_last] = 0.0;
        active.retain(|&v| v != last);
    }
    out.sort();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_episode::path::shell_distance;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn sphere_points(n: usize, radius: f64, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let v: [f64; 3] = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
            let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if r > 1e-3 && r <= 1.0 {
                out.push([radius * v[0] / r, radius * v[1] / r, radius * v[2] / r]);
            }
        }
        out
    }

    /// Shell distances, each pair computed once (exactly symmetric), as the planner builds them.
    fn shell_matrix(points: &[[f64; 3]]) -> Vec<Vec<f64>> {
        let n = points.len();
        let mut d = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in i + 1..n {
                d[i][j] = shell_distance(points[i], points[j]);
                d[j][i] = d[i][j];
            }
        }
        d
    }

    fn sphere_instance(n: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        shell_matrix(&sphere_points(n, 3.0, rng))
    }

    fn euclidean_instance(n: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        let p: Vec<[f64; 2]> = (0..n).map(|_| [rng.gen_range(0.0..10.0), rng.gen_range(0.0..10.0)]).collect();
        (0..n).map(|i| (0..n).map(|j| (p[i][0] - p[j][0]).hypot(p[i][1] - p[j][1])).collect()).collect()
    }

    /// Random asymmetric costs in [1, 10) (integers, so ties are frequent).
    fn asymmetric_instance(n: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| (0..n).map(|j| if i == j { 0.0 } else { rng.gen_range(1..10) as f64 }).collect())
            .collect()
    }

    /// Shortest open path length from `start` over all permutations of the other nodes.
    fn brute_force(dist: &[Vec<f64>], start: usize) -> f64 {
        fn rec(dist: &[Vec<f64>], path: &mut Vec<usize>, left: &mut Vec<usize>, best: &mut f64) {
            if left.is_empty() {
                *best = best.min(open_path_length(dist, path));
                return;
            }
            for k in 0..left.len() {
                let v = left.remove(k);
                path.push(v);
                rec(dist, path, left, best);
                path.pop();
                left.insert(k, v);
            }
        }
        let mut left: Vec<usize> = (0..dist.len()).filter(|&v| v != start).collect();
        let mut best = f64::INFINITY;
        rec(dist, &mut vec![start], &mut left, &mut best);
        best
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
    }

    fn dp_only() -> TspSettings {
        TspSettings { dp_max_nodes: DP_NODES_LIMIT, ..TspSettings::default() }
    }

    fn ilp_only() -> TspSettings {
        TspSettings { dp_max_nodes: 0, ..TspSettings::default() }
    }

    /// A permutation of 0..n starting at `start`, with the reported length.
    fn check_valid(dist: &[Vec<f64>], start: usize, r: &TspResult) {
        let n = dist.len();
        assert_eq!(r.order.len(), n);
        assert_eq!(r.order[0], start);
        let mut seen = vec![false; n];
        for &v in &r.order {
            assert!(!seen[v], "node {v} twice in {:?}", r.order);
            seen[v] = true;
        }
        assert_eq!(r.length.to_bits(), open_path_length(dist, &r.order).to_bits());
        assert!(r.lower_bound <= r.length, "bound {} above length {}", r.lower_bound, r.length);
    }

    #[test]
    fn dp_and_ilp_equal_brute_force_on_small_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut ilp_runs = 0;
        for n in 1..=8usize {
            for rep in 0..12 {
                let dist = match rep % 3 {
                    0 => sphere_instance(n, &mut rng),
                    1 => euclidean_instance(n, &mut rng),
                    _ => asymmetric_instance(n, &mut rng),
                };
                let start = rng.gen_range(0..n);
                let want = brute_force(&dist, start);
                for settings in [dp_only(), ilp_only()] {
                    let r = shortest_open_path(&dist, start, &settings).unwrap();
                    check_valid(&dist, start, &r);
                    assert!(r.optimal);
                    assert!(
                        close(r.length, want),
                        "n={n} rep={rep} {:?}: {} vs brute force {want}",
                        r.method,
                        r.length
                    );
                    assert!(close(r.lower_bound, want), "bound {} vs {want}", r.lower_bound);
                    if n > 2 && settings.dp_max_nodes == 0 {
                        assert_eq!(r.method, TspMethod::Ilp);
                        assert_eq!(r.symmetric, rep % 3 != 2);
                        ilp_runs += 1;
                    } else {
                        assert_eq!(r.method, TspMethod::Dp);
                    }
                }
            }
        }
        assert_eq!(ilp_runs, 6 * 12);
    }

    #[test]
    fn heuristic_is_a_valid_path_no_worse_than_nearest_neighbour() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for n in [1usize, 2, 3, 7, 20, 40] {
            for dist in [sphere_instance(n, &mut rng), asymmetric_instance(n, &mut rng)] {
                let start = n / 2;
                let h = heuristic_open_path(&dist, start).unwrap();
                let r = TspResult {
                    order: h.clone(),
                    length: open_path_length(&dist, &h),
                    optimal: false,
                    method: TspMethod::Heuristic,
                    lower_bound: 0.0,
                    heuristic_length: None,
                    symmetric: false,
                    seconds: 0.0,
                    ilp_solves: 0,
                    cuts: 0,
                    lp_solves: 0,
                };
                check_valid(&dist, start, &r);
                let nn = nearest_neighbour(&dist, start);
                assert!(r.length <= open_path_length(&dist, &nn));
                if n <= 7 {
                    assert!(r.length >= brute_force(&dist, start) - 1e-9);
                }
            }
        }
    }

    #[test]
    fn local_search_fixes_a_crossing() {
        // Points on a line 0,1,2,3 visited as 0,2,1,3 (length 2+1+2 = 5): the optimum is 0,1,2,3 (3).
        let x = [0.0f64, 1.0, 2.0, 3.0];
        let dist: Vec<Vec<f64>> = x.iter().map(|a| x.iter().map(|b| (a - b).abs()).collect()).collect();
        let mut order = vec![0, 2, 1, 3];
        local_search(&dist, &mut order);
        assert_eq!(order, vec![0, 1, 2, 3]);
        // Asymmetric: going "down" costs 10× more; a start in the middle must go down first.
        let asym: Vec<Vec<f64>> = x
            .iter()
            .map(|a| x.iter().map(|b| if b < a { 10.0 * (a - b) } else { b - a }).collect())
            .collect();
        let r = shortest_open_path(&asym, 1, &ilp_only()).unwrap();
        assert_eq!(r.order, vec![1, 0, 2, 3]);
        assert!(close(r.length, 10.0 + 2.0 + 1.0));
        assert!(!r.symmetric);
    }

    #[test]
    fn dp_equals_ilp_on_medium_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        for n in 10..=14usize {
            for rep in 0..3 {
                let dist = match rep {
                    0 => sphere_instance(n, &mut rng),
                    1 => euclidean_instance(n, &mut rng),
                    _ => asymmetric_instance(n, &mut rng),
                };
                let start = rng.gen_range(0..n);
                let dp = shortest_open_path(&dist, start, &dp_only()).unwrap();
                let ilp = shortest_open_path(&dist, start, &ilp_only()).unwrap();
                check_valid(&dist, start, &dp);
                check_valid(&dist, start, &ilp);
                assert_eq!((dp.method, ilp.method), (TspMethod::Dp, TspMethod::Ilp));
                assert!(dp.optimal && ilp.optimal);
                assert!(
                    close(dp.length, ilp.length),
                    "n={n} rep={rep}: dp {} vs ilp {}",
                    dp.length,
                    ilp.length
                );
                assert!(ilp.ilp_solves >= 1);
                assert!(ilp.length <= ilp.heuristic_length.unwrap());
            }
        }
    }

    /// The LP stage (`lp_cuts_min_nodes` = 0) against the DP on 10–14 nodes and against the
    /// plain integer loop on 50–70 nodes: the same shortest length, and tours that use only
    /// edges the reduced-cost fixing left.
    #[test]
    fn lp_stage_keeps_the_shortest_length() {
        let mut rng = ChaCha8Rng::seed_from_u64(48);
        let solve = |dist: &[Vec<f64>], start: usize, lp_min: usize| {
            let r =
                solve_with_ilp(dist, start, is_symmetric(dist), &ilp_only(), Instant::now(), lp_min).unwrap();
            check_valid(dist, start, &r);
            assert!(r.optimal);
            r
        };
        for n in 10..=14usize {
            for rep in 0..2 {
                let dist =
                    if rep == 0 { sphere_instance(n, &mut rng) } else { euclidean_instance(n, &mut rng) };
                let start = rng.gen_range(0..n);
                let dp = shortest_open_path(&dist, start, &dp_only()).unwrap();
                let lp = solve(&dist, start, 0);
                assert!(close(dp.length, lp.length), "n={n}: dp {} vs lp stage {}", dp.length, lp.length);
            }
        }
        let mut staged = 0;
        for n in [50usize, 60, 70] {
            let dist = sphere_instance(n, &mut rng);
            let start = rng.gen_range(0..n);
            let plain = solve(&dist, start, usize::MAX);
            let lp = solve(&dist, start, 0);
            assert_eq!(plain.lp_solves, 0);
            staged += lp.lp_solves;
            assert!(
                close(plain.length, lp.length),
                "n={n}: plain {} vs lp stage {}",
                plain.length,
                lp.length
            );
        }
        assert!(staged >= 3, "the LP stage ran");
        // Degenerate symmetric costs (integers 1–3: many ties, many optimal paths) and duplicated
        // points (zero distances).
        for rep in 0..2 {
            let n = 50;
            let dist: Vec<Vec<f64>> = if rep == 0 {
                let upper: Vec<Vec<f64>> = (0..n)
                    .map(|i| (0..n).map(|j| if j > i { rng.gen_range(1..=3) as f64 } else { 0.0 }).collect())
                    .collect();
                (0..n)
                    .map(|i| (0..n).map(|j| if j > i { upper[i][j] } else { upper[j][i] }).collect())
                    .collect()
            } else {
                let p = sphere_points(n / 2, 3.0, &mut rng);
                let doubled: Vec<[f64; 3]> = p.iter().chain(&p).copied().collect();
                shell_matrix(&doubled)
            };
            let plain = solve(&dist, 0, usize::MAX);
            let lp = solve(&dist, 0, 0);
            assert!(
                close(plain.length, lp.length),
                "rep {rep}: plain {} vs lp stage {}",
                plain.length,
                lp.length
            );
        }
    }

    /// The phase cuts of `violated_subtours` against brute force over every node set, on random
    /// supports of 5–9 nodes (through a formulation of that many nodes, dummy included): a set
    /// is reported only if its cut is below 2, and when some cut is below 2 the smallest one's
    /// weight is reported; disconnected supports report their components.
    #[test]
    fn violated_subtours_find_the_cuts_below_two() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for case in 0..300 {
            let n = rng.gen_range(4..=8usize); // nodes; the formulation adds the dummy
            let dist = sphere_instance(n, &mut rng);
            let form = Formulation::new(&dist, 0, true);
            let nn = form.n_nodes;
            let x: Vec<f64> = form
                .vars
                .iter()
                .map(|_| if rng.gen_bool(0.5) { 0.0 } else { [0.25, 0.5, 1.0][rng.gen_range(0..3)] })
                .collect();
            let cut_weight = |set: &[usize]| -> f64 {
                let mut inside = vec![false; nn];
                set.iter().for_each(|&v| inside[v] = true);
                form.vars.iter().zip(&x).filter(|(v, _)| inside[v.u] != inside[v.v]).map(|(_, &w)| w).sum()
            };
            let found = violated_subtours(&form, &x);
            for set in &found {
                assert!(set.len() >= 2 && set.len() <= nn - 2, "case {case}: improper set {set:?}");
                assert!(cut_weight(set) < 2.0 - CUT_EPS, "case {case}: {set:?} has cut {}", cut_weight(set));
            }
            // Brute force: the lightest proper cut.
            let mut lightest = f64::INFINITY;
            for mask in 1u32..(1 << nn) - 1 {
                let set: Vec<usize> = (0..nn).filter(|&v| mask >> v & 1 == 1).collect();
                if set.len() >= 2 && set.len() <= nn - 2 {
                    lightest = lightest.min(cut_weight(&set));
                }
            }
            // The support's components (by brute-force closure).
            let mut comp: Vec<usize> = (0..nn).collect();
            for _ in 0..nn {
                for (var, &w) in form.vars.iter().zip(&x) {
                    if w > CUT_EPS {
                        let m = comp[var.u].min(comp[var.v]);
                        comp[var.u] = m;
                        comp[var.v] = m;
                    }
                }
            }
            let mut roots = comp.clone();
            roots.sort_unstable();
            roots.dedup();
            if roots.len() == 1 {
                // The global minimum cut is one of the phase cuts; singletons aside (a node's own
                // cut below 2 is a degree violation, not a subtour), it is reported when below 2.
                let min_reported = found.iter().map(|s| cut_weight(s)).fold(f64::INFINITY, f64::min);
                let singles = (0..nn).map(|v| cut_weight(&[v])).fold(f64::INFINITY, f64::min);
                if lightest < 2.0 - CUT_EPS && lightest < singles {
                    assert!(
                        (min_reported - lightest).abs() < 1e-9,
                        "case {case}: lightest proper cut {lightest}, reported {min_reported}"
                    );
                }
            } else {
                // Every proper component (or its complement, the smaller side) is reported.
                for r in roots {
                    let c: Vec<usize> = (0..nn).filter(|&v| comp[v] == r).collect();
                    let side =
                        if 2 * c.len() <= nn { c } else { (0..nn).filter(|&v| comp[v] != r).collect() };
                    if side.len() >= 2 && side.len() <= nn - 2 {
                        assert!(found.contains(&side), "case {case}: component {side:?} not in {found:?}");
                    }
                }
            }
        }
        // A tour's support violates nothing; two triangles do.
        let dist = sphere_instance(5, &mut rng);
        let form = Formulation::new(&dist, 0, true);
        let on = |pairs: &[(usize, usize)]| -> Vec<f64> {
            form.vars.iter().map(|v| if pairs.contains(&(v.u, v.v)) { 1.0 } else { 0.0 }).collect()
        };
        // Nodes 0..5 and the dummy 5: the tour 0-1-2-3-4-5-0.
        let tour = on(&[(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5)]);
        assert!(violated_subtours(&form, &tour).is_empty());
        let triangles = on(&[(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)]);
        assert_eq!(violated_subtours(&form, &triangles), vec![vec![0, 1, 2], vec![3, 4, 5]]);
    }

    /// The LP-guided path is a path over every node from the start, whatever the LP values.
    #[test]
    fn lp_guided_path_is_a_valid_path() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for n in [3usize, 4, 10, 30] {
            let dist = sphere_instance(n, &mut rng);
            let start = rng.gen_range(0..n);
            let form = Formulation::new(&dist, start, true);
            let x: Vec<f64> = form.vars.iter().map(|_| rng.gen_range(0.0..1.0)).collect();
            let path = lp_guided_path(&form, &dist, start, &x);
            assert_eq!(path[0], start);
            let mut s = path.clone();
            s.sort_unstable();
            assert_eq!(s, (0..n).collect::<Vec<_>>());
        }
    }

    #[test]
    fn ilp_on_31_sphere_points_is_optimal_and_deterministic() {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        let dist = sphere_instance(31, &mut rng);
        let r = shortest_open_path(&dist, 0, &TspSettings::default()).unwrap();
        check_valid(&dist, 0, &r);
        assert!(r.optimal);
        assert_eq!(r.method, TspMethod::Ilp);
        assert!(r.symmetric);
        let heuristic = open_path_length(&dist, &heuristic_open_path(&dist, 0).unwrap());
        assert_eq!(r.heuristic_length, Some(heuristic));
        assert!(r.length <= heuristic);
        assert!(close(r.lower_bound, r.length));
        let again = shortest_open_path(&dist, 0, &TspSettings::default()).unwrap();
        assert_eq!(again.order, r.order);
        assert_eq!(again.length.to_bits(), r.length.to_bits());
        assert_eq!((again.ilp_solves, again.cuts), (r.ilp_solves, r.cuts));
    }

    #[test]
    fn ilp_on_51_sphere_points_is_optimal() {
        let mut rng = ChaCha8Rng::seed_from_u64(51);
        let dist = sphere_instance(51, &mut rng);
        let r = shortest_open_path(&dist, 7, &TspSettings::default()).unwrap();
        check_valid(&dist, 7, &r);
        assert!(r.optimal);
        assert!(r.length <= r.heuristic_length.unwrap());
    }

    #[test]
    fn time_limit_never_claims_optimality() {
        let mut rng = ChaCha8Rng::seed_from_u64(77);
        let dist = sphere_instance(40, &mut rng);
        let settings = TspSettings { time_limit_s: 1e-9, ..TspSettings::default() };
        let r = shortest_open_path(&dist, 0, &settings).unwrap();
        check_valid(&dist, 0, &r);
        assert!(!r.optimal);
        assert_eq!(r.method, TspMethod::Heuristic);
        assert_eq!(Some(r.length), r.heuristic_length);
        assert!(r.lower_bound < r.length);
    }

    #[test]
    fn time_limit_inside_highs_never_claims_optimality() {
        // The ILP needs 0.6–9 s for 129 sphere points (module docs); 50 ms stops it inside a
        // HiGHS solve (or before the first one on a slow machine).
        let mut rng = ChaCha8Rng::seed_from_u64(129);
        let dist = sphere_instance(129, &mut rng);
        let settings = TspSettings { time_limit_s: 0.05, ..TspSettings::default() };
        let r = shortest_open_path(&dist, 0, &settings).unwrap();
        check_valid(&dist, 0, &r);
        assert!(!r.optimal);
        assert_eq!(r.method, TspMethod::Heuristic);
        assert!(r.length <= r.heuristic_length.unwrap());
        assert!(r.lower_bound < r.length);
    }

    #[test]
    fn trivial_cases() {
        let r = shortest_open_path(&[vec![0.0]], 0, &ilp_only()).unwrap();
        assert_eq!((r.order, r.length, r.optimal, r.method), (vec![0], 0.0, true, TspMethod::Dp));
        let d = vec![vec![0.0, 2.5], vec![4.0, 0.0]];
        let r = shortest_open_path(&d, 1, &ilp_only()).unwrap();
        assert_eq!((r.order, r.length, r.optimal), (vec![1, 0], 4.0, true));
        assert_eq!(r.lower_bound, 4.0);
        assert!(!r.symmetric);
        let r = shortest_open_path(&d, 0, &dp_only()).unwrap();
        assert_eq!((r.order, r.length), (vec![0, 1], 2.5));
        // Zero distances everywhere: any order is optimal; the heuristic meets the trivial bound.
        let zero = vec![vec![0.0; 5]; 5];
        let r = shortest_open_path(&zero, 3, &ilp_only()).unwrap();
        check_valid(&zero, 3, &r);
        assert!(r.optimal && r.length == 0.0);
    }

    #[test]
    fn ties_are_broken_deterministically() {
        // All distances equal: every order is optimal; both methods must always return the same one.
        let d = vec![vec![1.0; 9]; 9];
        for settings in [dp_only(), ilp_only()] {
            let a = shortest_open_path(&d, 4, &settings).unwrap();
            let b = shortest_open_path(&d, 4, &settings).unwrap();
            assert_eq!(a.order, b.order);
            assert_eq!(a.length, 8.0);
        }
    }

    #[test]
    fn bad_input_is_an_error_naming_the_problem() {
        let s = TspSettings::default();
        let e = shortest_open_path(&[], 0, &s).unwrap_err();
        assert_eq!(e, TspError::Empty);
        assert!(e.to_string().contains("empty"));
        let e = shortest_open_path(&[vec![0.0, 1.0], vec![1.0]], 0, &s).unwrap_err();
        assert_eq!(e, TspError::NotSquare { n: 2, row: 1, len: 1 });
        assert!(e.to_string().contains("not square"), "{e}");
        let e = shortest_open_path(&[vec![0.0, 1.0], vec![f64::NAN, 0.0]], 0, &s).unwrap_err();
        assert!(matches!(e, TspError::NonFinite { i: 1, j: 0, .. }));
        assert!(e.to_string().contains("[1][0] = NaN is not finite"), "{e}");
        let e = shortest_open_path(&[vec![0.0, f64::INFINITY], vec![1.0, 0.0]], 0, &s).unwrap_err();
        assert!(matches!(e, TspError::NonFinite { i: 0, j: 1, .. }));
        let e = shortest_open_path(&[vec![0.0, -1.0], vec![1.0, 0.0]], 0, &s).unwrap_err();
        assert!(e.to_string().contains("negative"), "{e}");
        let e = shortest_open_path(&[vec![0.0, 1.0], vec![1.0, 0.0]], 2, &s).unwrap_err();
        assert_eq!(e, TspError::StartOutOfRange { start: 2, n: 2 });
        assert!(e.to_string().contains("start node 2 is out of range"), "{e}");
        assert!(heuristic_open_path(&[vec![0.0, 1.0]], 0).is_err());
        for bad in [
            TspSettings { time_limit_s: 0.0, ..TspSettings::default() },
            TspSettings { time_limit_s: f64::NAN, ..TspSettings::default() },
            TspSettings { dp_max_nodes: DP_NODES_LIMIT + 1, ..TspSettings::default() },
        ] {
            let e = shortest_open_path(&[vec![0.0]], 0, &bad).unwrap_err();
            assert!(matches!(e, TspError::InvalidSetting { .. }), "{e}");
        }
        let inf = TspSettings { time_limit_s: f64::INFINITY, ..TspSettings::default() };
        assert!(shortest_open_path(&[vec![0.0]], 0, &inf).is_ok());
    }

    #[test]
    fn patching_joins_subtours_into_one_path() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let dist = sphere_instance(12, &mut rng);
        let cycles = vec![vec![0, 5, 2], vec![1, 3, 4], vec![6, 7, 8, 9, 10, 11]];
        let path = patch_subtours(&dist, 0, &cycles);
        let mut sorted = path.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..12).collect::<Vec<_>>());
        assert_eq!(path[0], 0);
    }
}
