//! Exact minimum set cover by combinatorial search, for instances of at most 384 views — the
//! planning protocol's size (tammes-128) in one 128-bit word per view set, and the hybrid
//! planners' selections over tammes-360 (`completion-scp`, `completion-mcp`'s full-cover test) in
//! three (`Mask`: the same steps on either width).
//!
//! Why: the set-cover ILPs of real objects have weak LP relaxations (LP 8.9 for an optimum of 11
//! on a gear), and HiGHS spends most of its time proving the bound (35 s on that gear; 40 s even
//! when handed the optimum as a start). Covers here are small (d_plan ≈ 3–20) and every view set
//! fits one 128-bit word, so an exhaustive search that proves "no cover of size k exists" for
//! k = k₀, k₀+1, … is much faster: seconds on the hardest built-in objects (the 100k-triangle
//! gear: ~1–3 s, 884k nodes, with the dual bound; 4–11 s and 1.3M nodes without), milliseconds
//! on most.
//!
//! Method (iterative deepening on the cover size k):
//! - each element (row) is the bit mask of the views covering it; rows are sorted by their
//!   number of views so that the packing bound below sees the most constrained rows first;
//! - a node is (chosen views, allowed views, rows still uncovered). It fails when some row has no
//!   allowed view, or when a *packing bound* exceeds the views left: uncovered rows whose allowed
//!   view sets are pairwise disjoint each need their own view. One pass over the parent's rows
//!   builds the node's rows and tests both as it goes, so a failing node (most of them) stops at
//!   the first rows, the most constrained ones;
//! - it also fails on a *dual bound*: with weights y ≥ 0 on the rows (the LP relaxation's row
//!   duals, when given) scaled so that no view's rows weigh more than 1, every view covers at
//!   most 1 of the uncovered rows' weight, so more weight than views left means no cover (the
//!   packing bound is the special case of 0/1 weights). Any y ≥ 0 is valid after the scaling,
//!   which is done in integer fixed point, so LP round-off can weaken the bound but never make
//!   it wrong. A child whose parent's uncovered weight minus the view's whole load already
//!   exceeds its views left is not visited;
//! - at a node that branches, the weights are adapted to it by *dual ascent*: each uncovered
//!   row, most constrained first, is raised by the least slack (the scale minus the load) of
//!   its allowed views, so they stay a feasible dual of the node's own covering LP; the node
//!   fails when its rows weigh more than its `k_left` heaviest allowed views hold, and a child
//!   is not visited when the rows it leaves weigh more than the `k_left − 1` heaviest views it
//!   may still use hold. The raised weights pass to the children, which raise them further, and
//!   each node's view loads are its parent's less the rows the chosen view covers. The root
//!   duals are optimal at the root only; deeper, where views are chosen and excluded, the ascent
//!   recovers the slack they leave (on the trefoil knot's 128-view instance: 22M nodes → 0.28M);
//! - it branches on the uncovered row with the fewest allowed views: child i takes that row's
//!   i-th view (views ordered by how many uncovered rows they cover, descending) and later
//!   children exclude the earlier views, so each cover is enumerated at most once;
//! - with one view left, the node succeeds iff some allowed view covers every uncovered row.
//!
//! "No cover of size k" is proven when the search for k finishes without success, so the first
//! k that succeeds is the optimum — the same guarantee as an ILP solved with gap 0. The search
//! is deterministic; only a deadline can stop it early, and then only the proven lower bound
//! and the incumbent are reported.

use std::time::Instant;

use crate::setcover::CoverInstance;

/// Largest number of views (columns) the search handles.
pub const SEARCH_MAX_VIEWS: usize = 128 * WIDE_WORDS;

/// Fixed-point scale of the dual weights: a dual value of 1 (the most a row can carry).
const DUAL_SCALE: u64 = 1 << 32;

/// Nodes between two deadline checks.
const DEADLINE_CHECK_NODES: u64 = 1024;

/// Result of [`search_min_cover`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SearchOutcome {
    /// The best cover found (view ids of the instance, ascending): the incumbent passed in, or a
    /// smaller one the search found.
    pub cover: Vec<usize>,
    /// True when the search proved `cover` minimum.
    pub optimal: bool,
    /// Proven lower bound on the minimum cover size (= `cover.len()` when optimal).
    pub lower_bound: usize,
    /// Search nodes visited.
    pub nodes: u64,
}

/// Minimum cover of `inst` (at most [`SEARCH_MAX_VIEWS`] views; `None` for larger instances).
///
/// `lower` is a known lower bound (e.g. ⌈LP⌉; 0 if none), `incumbent` a known cover (view ids);
/// the search tries sizes from the larger of `lower` and its own root bound up to
/// `incumbent.len() − 1`. `priority` (one value per column of `inst`, e.g. the LP relaxation's
/// solution; empty for none) orders the branches: higher first, then more rows covered. It
/// changes how fast a cover is found, never the optimum. `row_dual` (one value per row of
/// `inst`, e.g. the LP relaxation's row duals; empty, negative or non-finite values count as 0)
/// weighs the rows for the dual bound: it only prunes branches that hold no cover, so it
/// changes the work, never the cover found. Stops at `deadline` (if any) with
/// `optimal = false`.
pub fn search_min_cover(
    inst: &CoverInstance,
    lower: usize,
    incumbent: &[usize],
    priority: &[f64],
    row_dual: &[f64],
    deadline: Option<Instant>,
) -> Option<SearchOutcome> {
    let n_views = inst.n_views();
    if n_views <= 128 {
        Some(search::<u128>(inst, lower, incumbent, priority, row_dual, deadline))
    } else if n_views <= SEARCH_MAX_VIEWS {
        Some(search::<Wide>(inst, lower, incumbent, priority, row_dual, deadline))
    } else {
        None
    }
}

/// [`search_min_cover`] with view sets as `M` (at least `inst.n_views()` bits wide).
fn search<M: Mask>(
    inst: &CoverInstance,
    lower: usize,
    incumbent: &[usize],
    priority: &[f64],
    row_dual: &[f64],
    deadline: Option<Instant>,
) -> SearchOutcome {
    let n_views = inst.n_views();
    debug_assert!(inst.is_cover(incumbent));
    let mut incumbent: Vec<usize> = incumbent.to_vec();
    incumbent.sort_unstable();
    if inst.n_elements() == 0 {
        return SearchOutcome { cover: Vec::new(), optimal: true, lower_bound: 0, nodes: 0 };
    }

    // Row masks over column positions.
    let elements = inst.element_ids();
    let mut masks = vec![M::ZERO; inst.n_elements()];
    for (c, &v) in inst.view_ids().iter().enumerate() {
        for e in inst.covered_by(v) {
            let row = elements.binary_search(&e).expect("covered elements are rows");
            masks[row] = masks[row].or(M::bit(c));
        }
    }
    // Dual weights in fixed point, rows sorted (most constrained first) and deduplicated.
    let weight = |row: usize| {
        let y = row_dual.get(row).copied().unwrap_or(0.0);
        if y > 0.0 && y.is_finite() {
            (y.min(1.0) * DUAL_SCALE as f64) as u64
        } else {
            0
        }
    };
    let mut rows: Vec<(M, u64)> = masks.iter().enumerate().map(|(r, &m)| (m, weight(r))).collect();
    rows.sort_unstable_by_key(|&(m, _)| (m.count(), m));
    rows.dedup_by(|b, a| {
        // Duplicates are covered together: one row carrying both weights.
        let same = a.0 == b.0;
        if same {
            a.1 += b.1;
        }
        same
    });
    let root: Vec<Row<M>> =
        rows.into_iter().map(|(mask, weight)| Row { mask, weight, full: u32::MAX }).collect();
    // Each view's load (the weight of its rows); dividing by the largest (or by the scale, if
    // larger) makes the weights a feasible dual whatever the LP's rounding.
    let mut load = vec![0u64; n_views];
    for r in &root {
        for c in r.mask.ones() {
            load[c] += r.weight;
        }
    }
    let denom = load.iter().copied().max().unwrap_or(0).max(DUAL_SCALE);
    let all = M::first_n(n_views);

    // Priority ranks: 0 = highest priority value (ties by column).
    let mut rank = vec![0u32; n_views];
    if priority.len() == n_views {
        let mut cols: Vec<usize> = (0..n_views).collect();
        cols.sort_by(|&a, &b| priority[b].total_cmp(&priority[a]).then(a.cmp(&b)));
        for (r, &c) in cols.iter().enumerate() {
            rank[c] = r as u32;
        }
    }
    let mut s = Search {
        rank,
        denom,
        levels: vec![Vec::new(); n_views + 2],
        n_views,
        loads: vec![0; n_views * (n_views + 2)],
        ranked: vec![Vec::new(); n_views + 2],
        nodes: 0,
        deadline,
        stopped: false,
        found: M::ZERO,
    };
    let root_weight: u64 = root.iter().map(|r| r.weight).sum();
    let root_bound = (packing(&root, all) as usize).max(root_weight.div_ceil(denom) as usize);
    let mut k = lower.max(root_bound).max(1);
    while k < incumbent.len() {
        if s.dfs(0, &root, M::ZERO, M::ZERO, all, k as u32) {
            let mut cover: Vec<usize> = s.found.ones().map(|c| inst.view_ids()[c]).collect();
            cover.sort_unstable();
            debug_assert!(inst.is_cover(&cover) && cover.len() <= k);
            let size = cover.len();
            return SearchOutcome { cover, optimal: true, lower_bound: size, nodes: s.nodes };
        }
        if s.stopped {
            return SearchOutcome { cover: incumbent, optimal: false, lower_bound: k, nodes: s.nodes };
        }
        k += 1;
    }
    let size = incumbent.len();
    SearchOutcome { cover: incumbent, optimal: true, lower_bound: size, nodes: s.nodes }
}

/// A row as the search carries it: the views covering it and its dual weight (fixed point).
#[derive(Debug, Clone, Copy)]
struct Row<M> {
    mask: M,
    weight: u64,
    /// A view that was full (load at `denom`) when the row was last raised or found unraisable
    /// ([`ascend`]'s shortcut; `u32::MAX` before any).
    full: u32,
}

struct Search<M> {
    /// Per column: its priority rank (lower first; all 0 without priorities).
    rank: Vec<u32>,
    /// The dual weights' denominator: every view's load is at most it.
    denom: u64,
    /// Uncovered rows per depth, in the root's order (buffers reused across nodes).
    levels: Vec<Vec<Row<M>>>,
    /// Views in the instance.
    n_views: usize,
    /// Per depth (`n_views` entries each, depth-major): each allowed view's load at the node
    /// of that depth on the current path, the weight of the node's rows it covers (after the
    /// node's dual ascent once it branches).
    loads: Vec<u64>,
    /// Per depth: the node loads of the allowed views, largest first (buffers reused).
    ranked: Vec<Vec<(u64, u32)>>,
    nodes: u64,
    deadline: Option<Instant>,
    stopped: bool,
    /// The cover found (column mask).
    found: M,
}

/// Each allowed view's load, the weight of the `rows` it covers, into `loads` (other entries
/// untouched).
fn node_loads<M: Mask>(rows: &[Row<M>], allowed: M, loads: &mut [u64]) {
    for c in allowed.ones() {
        loads[c] = 0;
    }
    for r in rows {
        if r.weight != 0 {
            for c in r.mask.and(allowed).ones() {
                loads[c] += r.weight;
            }
        }
    }
}

/// Dual ascent on a node's `rows` of total weight `weight`, with the allowed views' loads in
/// `loads` ([`node_loads`]): each row, in order, is raised by the least slack (`denom` −
/// load) of its allowed views, and the loads follow. Returns the rows' new total weight. If
/// every allowed view's load was at most `denom` before, it still is after (a feasible dual of
/// the node's covering LP, scaled by `denom`), and no row can be raised further (each has an
/// allowed view at `denom`).
fn ascend<M: Mask>(rows: &mut [Row<M>], allowed: M, denom: u64, loads: &mut [u64], weight: u64) -> u64 {
    let mut weight = weight;
    for r in rows.iter_mut() {
        let m = r.mask.and(allowed);
        // Most rows are still held by the view that held them at the parent.
        let f = r.full as usize;
        if f < loads.len() && m.has(f) && loads[f] >= denom {
            continue;
        }
        let (mut slack, mut arg) = (u64::MAX, u32::MAX);
        for c in m.ones() {
            let s = denom.saturating_sub(loads[c]);
            if s < slack {
                (slack, arg) = (s, c as u32);
                if s == 0 {
                    break;
                }
            }
        }
        r.full = arg;
        if slack > 0 && slack != u64::MAX {
            for c in m.ones() {
                loads[c] += slack;
            }
            r.weight += slack;
            weight += slack;
        }
    }
    weight
}

/// Greedy packing of `rows` (in their sorted order) with pairwise disjoint allowed views.
fn packing<M: Mask>(rows: &[Row<M>], allowed: M) -> u32 {
    let mut used = M::ZERO;
    let mut pack = 0;
    for r in rows {
        let a = r.mask.and(allowed);
        if a.and(used).is_zero() {
            pack += 1;
            used = used.or(a);
        }
    }
    pack
}

impl<M: Mask> Search<M> {
    /// Whether the rows of `parent` not covered by view mask `bit` (all of them when `bit` is 0)
    /// have a cover of at most `k_left` allowed views. The node's rows go to `levels[depth]`.
    fn dfs(&mut self, depth: usize, parent: &[Row<M>], bit: M, chosen: M, allowed: M, k_left: u32) -> bool {
        self.nodes += 1;
        if self.nodes % DEADLINE_CHECK_NODES == 0 && self.deadline.is_some_and(|d| Instant::now() >= d) {
            self.stopped = true;
        }
        if self.stopped {
            return false;
        }
        let mut rows = std::mem::take(&mut self.levels[depth]);
        rows.clear();
        let result = self.expand(depth, parent, bit, &mut rows, chosen, allowed, k_left);
        self.levels[depth] = rows;
        result
    }

    /// The body of [`Search::dfs`]: one pass over the parent's rows collects the node's rows
    /// and, as it goes, fails the node on a row without allowed views or on a packing bound
    /// above `k_left` (rows come most constrained first, so pruned nodes mostly stop early);
    /// then the dual bound, the one-view test, and the branches.
    #[allow(clippy::too_many_arguments)]
    fn expand(
        &mut self,
        depth: usize,
        parent: &[Row<M>],
        bit: M,
        rows: &mut Vec<Row<M>>,
        chosen: M,
        allowed: M,
        k_left: u32,
    ) -> bool {
        let mut used = M::ZERO;
        let mut pack = 0u32;
        let mut branch = (u32::MAX, M::ZERO);
        let mut common = M::FULL;
        let mut weight = 0u64;
        for &r in parent {
            if !r.mask.and(bit).is_zero() {
                continue;
            }
            rows.push(r);
            weight += r.weight;
            let a = r.mask.and(allowed);
            if a.is_zero() {
                return false;
            }
            common = common.and(a);
            let c = a.count();
            if c < branch.0 {
                branch = (c, a);
            }
            if a.and(used).is_zero() {
                pack += 1;
                used = used.or(a);
                if pack > k_left {
                    return false;
                }
            }
        }
        if rows.is_empty() {
            self.found = chosen;
            return true;
        }
        // Uncovered rows carry more dual weight than `k_left` views can hold.
        if k_left == 0 || weight > k_left as u64 * self.denom {
            return false;
        }
        if k_left == 1 {
            if common.is_zero() {
                return false;
            }
            self.found = chosen.or(M::bit(common.first()));
            return true;
        }
        // The allowed views' loads: from the parent's (the rows are the parent's less those
        // `bit` covers, with the weights the parent left them), or from scratch at the root.
        let n = self.n_views;
        let (above, here) = self.loads.split_at_mut(depth * n);
        let loads = &mut here[..n];
        if depth == 0 {
            node_loads(rows, allowed, loads);
        } else {
            loads.copy_from_slice(&above[(depth - 1) * n..]);
            for r in parent {
                if !r.mask.and(bit).is_zero() && r.weight != 0 {
                    for c in r.mask.and(allowed).ones() {
                        loads[c] -= r.weight;
                    }
                }
            }
        }
        // A dual bound adapted to the node (see `branch`), then the branches.
        let mut ranked = std::mem::take(&mut self.ranked[depth]);
        let result = self.branch(depth, rows, branch.1, chosen, allowed, k_left, weight, &mut ranked);
        self.ranked[depth] = ranked;
        result
    }

    /// The branches of a node that passed [`Search::expand`]'s first tests.
    ///
    /// First a dual bound adapted to the node: the rows' weights (inherited from the parent, a
    /// feasible dual there, hence here: the node's rows are fewer and its allowed views fewer)
    /// are raised by *dual ascent* — each row, most constrained first, by the least slack
    /// (`denom` − load) of its allowed views — so every allowed view still holds at most `denom`,
    /// and the node fails when its rows weigh more than the `k_left` heaviest allowed views
    /// hold (at most `k_left · denom`). The raised weights stay in `rows`, so the children
    /// inherit them. Then one child per view of the branching row (`candidates`).
    #[allow(clippy::too_many_arguments)]
    fn branch(
        &mut self,
        depth: usize,
        rows: &mut [Row<M>],
        candidates: M,
        chosen: M,
        allowed: M,
        k_left: u32,
        weight: u64,
        ranked: &mut Vec<(u64, u32)>,
    ) -> bool {
        let base = depth * self.n_views;
        let loads = &mut self.loads[base..base + self.n_views];
        let weight = ascend(rows, allowed, self.denom, loads, weight);
        ranked.clear();
        // Views covering none of the rows add nothing to any sum of loads.
        ranked.extend(allowed.ones().filter(|&c| loads[c] != 0).map(|c| (loads[c], c as u32)));
        ranked.sort_unstable_by(|a, b| b.cmp(a));
        // The most weight `k` allowed views other than `skip` (and not in `excluded`) hold.
        let top = |ranked: &[(u64, u32)], k: u32, skip: u32, excluded: M| -> u64 {
            ranked
                .iter()
                .filter(|&&(_, c)| c != skip && !excluded.has(c as usize))
                .take(k as usize)
                .map(|&(l, _)| l)
                .sum()
        };
        if weight > top(ranked, k_left, u32::MAX, M::ZERO) {
            return false;
        }
        // Candidate views of the branching row, by uncovered rows covered (descending).
        let mut order: Vec<(u32, u32)> = candidates.ones().map(|c| (0, c as u32)).collect();
        for r in rows.iter() {
            let m = r.mask.and(candidates);
            if !m.is_zero() {
                for o in order.iter_mut() {
                    o.0 += m.has(o.1 as usize) as u32;
                }
            }
        }
        let rank = &self.rank;
        order.sort_unstable_by(|a, b| {
            rank[a.1 as usize].cmp(&rank[b.1 as usize]).then(b.0.cmp(&a.0)).then(a.1.cmp(&b.1))
        });
        let mut excluded = M::ZERO;
        for &(_, v) in &order {
            let bit = M::bit(v as usize);
            // The child's rows weigh exactly `weight` − v's load, and its views hold at most
            // what they hold here: no need to visit it when that weight already exceeds what
            // its `k_left − 1` views can hold.
            let child_weight = weight - self.loads[base + v as usize];
            let hopeless = child_weight > top(ranked, k_left - 1, v, excluded);
            if !hopeless
                && self.dfs(depth + 1, rows, bit, chosen.or(bit), allowed.and_not(excluded), k_left - 1)
            {
                return true;
            }
            if self.stopped {
                return false;
            }
            // Every cover with v was searched: the remaining branches exclude it.
            excluded = excluded.or(bit);
        }
        false
    }
}

/// A set of views (columns) as the search carries it: a bitset at least as wide as the
/// instance. `u128` serves the planning protocol's 128 views; [`Wide`] the planners' larger
/// candidate sets (tammes-360). The search runs the same steps on either, so on an instance
/// that fits both it returns the same cover (tested).
trait Mask: Copy + Ord + std::fmt::Debug {
    /// No view.
    const ZERO: Self;
    /// Every bit (the identity of `and`).
    const FULL: Self;
    /// Views 0..n.
    fn first_n(n: usize) -> Self;
    /// View c alone.
    fn bit(c: usize) -> Self;
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    /// `self` without the views of `o`.
    fn and_not(self, o: Self) -> Self;
    fn is_zero(self) -> bool;
    /// Number of views.
    fn count(self) -> u32;
    /// The lowest view (`self` not empty).
    fn first(self) -> usize;
    fn has(self, c: usize) -> bool;
    /// The views, ascending.
    fn ones(self) -> impl Iterator<Item = usize>;
}

impl Mask for u128 {
    const ZERO: u128 = 0;
    const FULL: u128 = u128::MAX;
    fn first_n(n: usize) -> u128 {
        if n >= 128 {
            u128::MAX
        } else {
            (1u128 << n) - 1
        }
    }
    #[inline(always)]
    fn bit(c: usize) -> u128 {
        1u128 << c
    }
    #[inline(always)]
    fn and(self, o: u128) -> u128 {
        self & o
    }
    #[inline(always)]
    fn or(self, o: u128) -> u128 {
        self | o
    }
    #[inline(always)]
    fn and_not(self, o: u128) -> u128 {
        self & !o
    }
    #[inline(always)]
    fn is_zero(self) -> bool {
        self == 0
    }
    #[inline(always)]
    fn count(self) -> u32 {
        self.count_ones()
    }
    #[inline(always)]
    fn first(self) -> usize {
        self.trailing_zeros() as usize
    }
    #[inline(always)]
    fn has(self, c: usize) -> bool {
        self >> c & 1 == 1
    }
    fn ones(self) -> impl Iterator<Item = usize> {
        let mut m = self;
        std::iter::from_fn(move || {
            (m != 0).then(|| {
                let c = m.trailing_zeros() as usize;
                m &= m - 1;
                c
            })
        })
    }
}

/// Words of [`Wide`].
const WIDE_WORDS: usize = 3;

/// A view set of up to 384 views: three `u128` words, view c in word c / 128. Ordered by its
/// words from the highest, as the number it spells (the order the search sorts rows in).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Wide([u128; WIDE_WORDS]);

impl PartialOrd for Wide {
    fn partial_cmp(&self, o: &Wide) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}

impl Ord for Wide {
    fn cmp(&self, o: &Wide) -> std::cmp::Ordering {
        self.0.iter().rev().cmp(o.0.iter().rev())
    }
}

impl Mask for Wide {
    const ZERO: Wide = Wide([0; WIDE_WORDS]);
    const FULL: Wide = Wide([u128::MAX; WIDE_WORDS]);
    fn first_n(n: usize) -> Wide {
        Wide(std::array::from_fn(|w| u128::first_n(n.saturating_sub(w * 128))))
    }
    #[inline(always)]
    fn bit(c: usize) -> Wide {
        let mut m = Wide::ZERO;
        m.0[c / 128] = 1u128 << (c % 128);
        m
    }
    #[inline(always)]
    fn and(self, o: Wide) -> Wide {
        Wide(std::array::from_fn(|w| self.0[w] & o.0[w]))
    }
    #[inline(always)]
    fn or(self, o: Wide) -> Wide {
        Wide(std::array::from_fn(|w| self.0[w] | o.0[w]))
    }
    #[inline(always)]
    fn and_not(self, o: Wide) -> Wide {
        Wide(std::array::from_fn(|w| self.0[w] & !o.0[w]))
    }
    #[inline(always)]
    fn is_zero(self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }
    #[inline(always)]
    fn count(self) -> u32 {
        self.0.iter().map(|w| w.count_ones()).sum()
    }
    #[inline(always)]
    fn first(self) -> usize {
        let w = self.0.iter().position(|&w| w != 0).unwrap_or(WIDE_WORDS - 1);
        w * 128 + self.0[w].trailing_zeros() as usize
    }
    #[inline(always)]
    fn has(self, c: usize) -> bool {
        self.0[c / 128] >> (c % 128) & 1 == 1
    }
    fn ones(self) -> impl Iterator<Item = usize> {
        (0..WIDE_WORDS).flat_map(move |w| self.0[w].ones().map(move |c| w * 128 + c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn inst(views: &[Vec<usize>]) -> CoverInstance {
        CoverInstance::from_index_lists(views, 1).unwrap()
    }

    /// Random view lists: a view count in `views`, an element count in `elements`, and each
    /// element in each view with a probability drawn from `p`.
    fn random_views(
        rng: &mut ChaCha8Rng,
        views: std::ops::RangeInclusive<usize>,
        elements: std::ops::Range<usize>,
        p: std::ops::Range<f64>,
    ) -> Vec<Vec<usize>> {
        let n_views = rng.gen_range(views);
        let n_el = rng.gen_range(elements);
        let p = rng.gen_range(p);
        (0..n_views).map(|_| (0..n_el).filter(|_| rng.gen_bool(p)).collect()).collect()
    }

    #[test]
    fn wide_masks_search_as_u128_does() {
        // On instances that fit 128 bits, the wide search runs the same steps: the same
        // cover, bound and node count (with priorities and duals too).
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        for case in 0..60 {
            let views = random_views(&mut rng, 60..=128, 1..60, 0.05..0.3);
            let inst = inst(&views);
            let greedy = inst.greedy();
            let priority: Vec<f64> = (0..inst.n_views()).map(|_| rng.gen_range(0.0..1.0)).collect();
            let duals: Vec<f64> = (0..inst.n_elements()).map(|_| rng.gen_range(0.0..0.4)).collect();
            for (pr, du) in [(&[][..], &[][..]), (&priority[..], &duals[..])] {
                let a = search::<u128>(&inst, 0, &greedy, pr, du, None);
                let b = search::<Wide>(&inst, 0, &greedy, pr, du, None);
                assert_eq!(a, b, "case {case}");
            }
        }
    }

    #[test]
    fn wide_rings_are_solved_exactly() {
        // n views on a ring (element i seen by views i and i + 1 mod n): the optimum is
        // ⌈n/2⌉, with views in every word of the wide masks.
        for n in [129usize, 200, 255, 256, 257, 383, 384] {
            let views: Vec<Vec<usize>> = (0..n).map(|v| vec![v, (v + n - 1) % n]).collect();
            let inst = inst(&views);
            let out = search_min_cover(&inst, 0, &inst.greedy(), &[], &[], None).unwrap();
            assert!(out.optimal && inst.is_cover(&out.cover), "{n} views");
            assert_eq!(out.cover.len(), n.div_ceil(2), "{n} views");
        }
    }

    #[test]
    fn more_than_128_views_match_the_ilp() {
        use crate::ilp::{solve_min_cover, CoverMethod, CoverSettings};
        // 129–384 views (the wide masks, every word in use): the search's optimum equals
        // HiGHS's on the same instance, and its cover is a cover.
        let mut rng = ChaCha8Rng::seed_from_u64(32);
        let mut wide = 0;
        for case in 0..12 {
            let n_views = [129, 200, 256, 300, 383, 384][case % 6];
            let n_el: usize = rng.gen_range(20..40);
            let p = rng.gen_range(0.08..0.2);
            let bitsets: Vec<Vec<u64>> = (0..n_views)
                .map(|_| {
                    let mut b = vec![0u64; n_el.div_ceil(64)];
                    for e in 0..n_el {
                        if rng.gen_bool(p) {
                            b[e / 64] |= 1 << (e % 64);
                        }
                    }
                    b
                })
                .collect();
            let ilp =
                CoverSettings { method: CoverMethod::Ilp, time_limit_s: 60.0, ..CoverSettings::default() };
            let auto = CoverSettings { time_limit_s: 60.0, ..CoverSettings::default() };
            let (Ok(a), Ok(b)) = (solve_min_cover(&bitsets, &ilp), solve_min_cover(&bitsets, &auto)) else {
                continue; // an element no view covers
            };
            assert_eq!(a.d_plan, b.d_plan, "case {case}");
            assert!(a.d_plan.is_some(), "case {case}: proven");
            let inst = CoverInstance::from_bitsets(&bitsets, 1).unwrap();
            let greedy = inst.greedy();
            let out = search_min_cover(&inst, 0, &greedy, &[], &[], None).unwrap();
            assert!(out.optimal && inst.is_cover(&out.cover), "case {case}");
            assert_eq!(Some(out.cover.len()), a.d_plan, "case {case}");
            wide += usize::from(inst.n_views() > 128);
        }
        assert!(wide >= 6, "instances wider than 128 views: {wide}");
    }

    #[test]
    fn matches_brute_force_on_random_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for case in 0..400 {
            let views = random_views(&mut rng, 1..=18, 0..60, 0.05..0.5);
            let inst = inst(&views);
            let brute = inst.brute_force().unwrap();
            let greedy = inst.greedy();
            let out = search_min_cover(&inst, 0, &greedy, &[], &[], None).unwrap();
            assert!(out.optimal, "case {case}");
            assert_eq!(out.cover.len(), brute.len(), "case {case}: {views:?}");
            assert!(inst.is_cover(&out.cover), "case {case}");
            assert_eq!(out.lower_bound, brute.len());
            // Branch priorities change the order of the search, never the optimum.
            let priority: Vec<f64> = (0..inst.n_views()).map(|_| rng.gen_range(0.0..1.0)).collect();
            let out = search_min_cover(&inst, 0, &greedy, &priority, &[], None).unwrap();
            assert_eq!((out.cover.len(), out.optimal), (brute.len(), true), "case {case} with priorities");
            assert!(inst.is_cover(&out.cover));
        }
    }

    #[test]
    fn dual_weights_change_the_work_never_the_cover() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let mut changed = 0u32;
        for case in 0..400 {
            let views = random_views(&mut rng, 1..=16, 1..50, 0.1..0.5);
            let inst = inst(&views);
            let brute = inst.brute_force().unwrap();
            let greedy = inst.greedy();
            let plain = search_min_cover(&inst, 0, &greedy, &[], &[], None).unwrap();
            // Any weights: feasible duals, infeasible ones (the scaling must absorb them), and
            // garbage (negative, NaN, infinite: counted as 0).
            let rows = inst.n_elements();
            let duals: Vec<f64> = match case % 4 {
                0 => (0..rows).map(|_| rng.gen_range(0.0..0.3)).collect(),
                1 => vec![1.0; rows],
                2 => (0..rows).map(|_| rng.gen_range(0.0..5.0)).collect(),
                _ => (0..rows).map(|i| [f64::NAN, -1.0, f64::INFINITY, 0.5, 1e-300][i % 5]).collect(),
            };
            let weighted = search_min_cover(&inst, 0, &greedy, &[], &duals, None).unwrap();
            assert!(weighted.optimal, "case {case}");
            assert_eq!(weighted.cover.len(), brute.len(), "case {case}: {views:?} {duals:?}");
            // Pruning only drops branches without a cover: the same first cover. (The node
            // counts differ either way: the nodes' dual ascent starts from these weights.)
            assert_eq!(weighted.cover, plain.cover, "case {case}");
            changed += (weighted.nodes != plain.nodes) as u32;
        }
        assert!(changed > 0, "the weights never changed the work");
    }

    #[test]
    fn dual_ascent_keeps_a_feasible_maximal_dual() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let denom = 1000u64;
        for case in 0..300 {
            let n_views = rng.gen_range(1..=40usize);
            let allowed: u128 = (0..n_views).filter(|_| rng.gen_bool(0.7)).fold(0, |m, c| m | 1 << c);
            // Rows with at least one allowed view; a feasible start (loads ≤ denom) by giving
            // each row at most denom / rows.
            let n_rows = rng.gen_range(1..=30usize);
            let mut rows: Vec<Row<u128>> = Vec::new();
            while rows.len() < n_rows && allowed != 0 {
                let mask: u128 = (0..n_views).filter(|_| rng.gen_bool(0.2)).fold(0, |m, c| m | 1 << c);
                if mask & allowed != 0 {
                    let weight = if case % 3 == 0 { 0 } else { rng.gen_range(0..=denom / n_rows as u64) };
                    rows.push(Row { mask, weight, full: u32::MAX });
                }
            }
            let before = rows.clone();
            let mut loads = vec![u64::MAX; n_views];
            node_loads(&rows, allowed, &mut loads);
            let start: u64 = rows.iter().map(|r| r.weight).sum();
            let total = ascend(&mut rows, allowed, denom, &mut loads, start);
            assert_eq!(total, rows.iter().map(|r| r.weight).sum::<u64>(), "case {case}");
            for (r, b) in rows.iter().zip(&before) {
                assert!(r.weight >= b.weight, "case {case}: a weight fell");
                // Maximal: some allowed view of the row is full.
                assert!(r.mask.and(allowed).ones().any(|c| loads[c] == denom), "case {case}: row not tight");
            }
            for c in allowed.ones() {
                let load: u64 = rows.iter().filter(|r| r.mask.has(c)).map(|r| r.weight).sum();
                assert_eq!(loads[c], load, "case {case}: view {c}");
                assert!(load <= denom, "case {case}: view {c} over the denominator");
            }
        }
        // A child as the search makes it: the rows a view covers leave (their weight leaves the
        // loads), another view is excluded, and the ascent resumes from the inherited weights
        // and `full` hints. The same invariants hold against loads recomputed from scratch.
        for case in 0..300 {
            let n_views = rng.gen_range(2..=40usize);
            let mut allowed = (1u128 << n_views) - 1;
            let n_rows = rng.gen_range(1..=40);
            let mut rows: Vec<Row<u128>> = Vec::new();
            for _ in 0..n_rows {
                let seed = 1u128 << rng.gen_range(0..n_views);
                let mask = (0..n_views).filter(|_| rng.gen_bool(0.2)).fold(seed, |m, c| m | 1 << c);
                rows.push(Row { mask, weight: 0, full: u32::MAX });
            }
            let mut loads = vec![0u64; n_views];
            node_loads(&rows, allowed, &mut loads);
            let mut total = ascend(&mut rows, allowed, denom, &mut loads, 0);
            for _ in 0..3 {
                let v = rng.gen_range(0..n_views);
                for r in rows.iter().filter(|r| r.mask.has(v)) {
                    total -= r.weight;
                    for c in r.mask.and(allowed).ones() {
                        loads[c] -= r.weight;
                    }
                }
                rows.retain(|r| !r.mask.has(v));
                let x = rng.gen_range(0..n_views);
                let kept: Vec<Row<u128>> =
                    rows.iter().copied().filter(|r| r.mask & allowed & !(1 << x) != 0).collect();
                if kept.len() == rows.len() {
                    allowed &= !(1 << x);
                }
                total = ascend(&mut rows, allowed, denom, &mut loads, total);
                assert_eq!(total, rows.iter().map(|r| r.weight).sum::<u64>(), "child case {case}");
                for r in &rows {
                    assert!(r.mask.and(allowed).ones().any(|c| loads[c] == denom), "child case {case}");
                }
                for c in allowed.ones() {
                    let load: u64 = rows.iter().filter(|r| r.mask.has(c)).map(|r| r.weight).sum();
                    assert_eq!(loads[c], load, "child case {case}: view {c}");
                    assert!(load <= denom, "child case {case}: view {c}");
                }
            }
        }
        // By hand: views a = 0, b = 1, c = 2; rows {a, b}, {b, c}, {c} with weights 0.
        // Row 1 takes 1 (a and b full), row 2 nothing (b is full), row 3 takes 1 (c): total 2,
        // the cover size (a or b, plus c).
        let mut rows = vec![
            Row { mask: 0b011u128, weight: 0, full: u32::MAX },
            Row { mask: 0b110, weight: 0, full: u32::MAX },
            Row { mask: 0b100, weight: 0, full: u32::MAX },
        ];
        let mut loads = vec![0; 3];
        node_loads(&rows, 0b111, &mut loads);
        assert_eq!(ascend(&mut rows, 0b111, 1, &mut loads, 0), 2);
        assert_eq!((rows[0].weight, rows[1].weight, rows[2].weight), (1, 0, 1));
        // With view a excluded, row 1 can only be covered by b, and the bound is the same.
        let mut rows2 = rows.iter().map(|r| Row { weight: 0, full: u32::MAX, ..*r }).collect::<Vec<_>>();
        node_loads(&rows2, 0b110, &mut loads);
        assert_eq!(ascend(&mut rows2, 0b110, 1, &mut loads, 0), 2);
    }

    #[test]
    fn fractional_duals_prove_what_packing_cannot() {
        // A triangle: every two elements share a view, so the packing bound is 1; the LP dual
        // (½ on each element) proves 2 at the root.
        let inst = inst(&[vec![0, 1], vec![1, 2], vec![0, 2]]);
        let plain = search_min_cover(&inst, 0, &[0, 1], &[], &[], None).unwrap();
        assert_eq!((plain.cover.len(), plain.optimal), (2, true));
        assert!(plain.nodes > 0);
        let dual = search_min_cover(&inst, 0, &[0, 1], &[], &[0.5, 0.5, 0.5], None).unwrap();
        assert_eq!((dual.cover.len(), dual.optimal, dual.lower_bound, dual.nodes), (2, true, 2, 0));
        // Weights above a feasible dual are scaled down: 1 on each element weighs 2 per view,
        // so the bound is 3/2 → 2 as well, never 3.
        let scaled = search_min_cover(&inst, 0, &[0, 1], &[], &[1.0, 1.0, 1.0], None).unwrap();
        assert_eq!((scaled.cover.len(), scaled.optimal, scaled.nodes), (2, true, 0));
        // Three disjoint views, greedy incumbent 3: weights of 1 are feasible and prove 3.
        let disjoint = inst_of(&[vec![0], vec![1], vec![2]]);
        let out = search_min_cover(&disjoint, 0, &[0, 1, 2], &[], &[1.0; 3], None).unwrap();
        assert_eq!((out.cover.len(), out.optimal, out.nodes), (3, true, 0));
    }

    #[test]
    fn finds_the_optimum_where_greedy_fails_and_respects_lower_bounds() {
        // Greedy takes view 2 (6 elements) first and then needs two more; views 0 and 1 suffice.
        let inst = inst(&[vec![0, 1, 2, 3, 6], vec![4, 5, 7, 8, 9], vec![0, 1, 4, 5, 2, 7]]);
        let greedy = inst.greedy();
        assert_eq!(greedy.len(), 3);
        let out = search_min_cover(&inst, 0, &greedy, &[], &[], None).unwrap();
        assert_eq!((out.cover.clone(), out.optimal, out.lower_bound), (vec![0, 1], true, 2));
        // A lower bound equal to the incumbent proves it immediately.
        let out = search_min_cover(&inst, 2, &[0, 1], &[], &[], None).unwrap();
        assert_eq!((out.optimal, out.nodes), (true, 0));
    }

    #[test]
    fn full_width_128_views_and_deadline() {
        // 128 views on a ring: element i is seen by views i and i+1 (mod 128) -> optimum 64.
        let views: Vec<Vec<usize>> = (0..128).map(|v| vec![v, (v + 127) % 128]).collect();
        let inst = inst(&views);
        let greedy = inst.greedy();
        let out = search_min_cover(&inst, 0, &greedy, &[], &[], None).unwrap();
        assert!(out.optimal);
        assert_eq!(out.cover.len(), 64);
        // The root packing bound already proves 64 (64 disjoint pairs).
        assert!(out.nodes < 1000, "{} nodes", out.nodes);

        // An instance too large for the search.
        let n = SEARCH_MAX_VIEWS + 1;
        let big: Vec<Vec<usize>> = (0..n).map(|v| vec![v]).collect();
        let big = inst_of(&big);
        assert!(search_min_cover(&big, 0, &(0..n).collect::<Vec<_>>(), &[], &[], None).is_none());

        // A deadline in the past stops the search on its first check with a valid bound.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let views: Vec<Vec<usize>> =
            (0..128).map(|_| (0..2000).filter(|_| rng.gen_bool(0.05)).collect()).collect();
        let hard = inst_of(&views);
        let g = hard.greedy();
        let out = search_min_cover(&hard, 0, &g, &[], &[], Some(Instant::now())).unwrap();
        if !out.optimal {
            assert_eq!(out.cover.len(), g.len());
            assert!(out.lower_bound < g.len());
        }
    }

    fn inst_of(views: &[Vec<usize>]) -> CoverInstance {
        CoverInstance::from_index_lists(views, 1).unwrap()
    }
}
