//! Exact minimum set cover by combinatorial search, for instances of at most 128 views — the
//! planning protocol's size (tammes-128).
//!
//! Why: the set-cover ILPs of real objects have weak LP relaxations (LP 8.9 for an optimum of 11
//! on a gear), and HiGHS spends most of its time proving the bound (35 s on that gear; 40 s even
//! when handed the optimum as a start). Covers here are small (d_plan ≈ 3–20) and every view set
//! fits one 128-bit word, so an exhaustive search that proves "no cover of size k exists" for
//! k = k₀, k₀+1, … is much faster: 2–10 s on the hardest built-in objects, milliseconds on most.
//!
//! Method (iterative deepening on the cover size k):
//! - each element (row) is the 128-bit mask of the views covering it; rows are sorted by their
//!   number of views so that the packing bound below sees the most constrained rows first;
//! - a node is (chosen views, allowed views, rows still uncovered). It fails when some row has no
//!   allowed view, or when a *packing bound* exceeds the views left: uncovered rows whose allowed
//!   view sets are pairwise disjoint each need their own view;
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
pub const SEARCH_MAX_VIEWS: usize = 128;

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
/// changes how fast a cover is found, never the optimum. Stops at `deadline` (if any) with
/// `optimal = false`.
pub fn search_min_cover(
    inst: &CoverInstance,
    lower: usize,
    incumbent: &[usize],
    priority: &[f64],
    deadline: Option<Instant>,
) -> Option<SearchOutcome> {
    let n_views = inst.n_views();
    if n_views > SEARCH_MAX_VIEWS {
        return None;
    }
    debug_assert!(inst.is_cover(incumbent));
    let mut incumbent: Vec<usize> = incumbent.to_vec();
    incumbent.sort_unstable();
    if inst.n_elements() == 0 {
        return Some(SearchOutcome { cover: Vec::new(), optimal: true, lower_bound: 0, nodes: 0 });
    }

    // Row masks over column positions.
    let elements = inst.element_ids();
    let mut masks = vec![0u128; inst.n_elements()];
    for (c, &v) in inst.view_ids().iter().enumerate() {
        for e in inst.covered_by(v) {
            let row = elements.binary_search(&e).expect("covered elements are rows");
            masks[row] |= 1u128 << c;
        }
    }
    masks.sort_unstable_by_key(|m| (m.count_ones(), *m));
    masks.dedup();
    let all: u128 = if n_views == 128 { u128::MAX } else { (1u128 << n_views) - 1 };

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
        masks,
        levels: vec![Vec::new(); n_views + 2],
        nodes: 0,
        deadline,
        stopped: false,
        found: 0,
    };
    let root: Vec<u32> = (0..s.masks.len() as u32).collect();
    let root_bound = s.packing(&root, all) as usize;
    let mut k = lower.max(root_bound).max(1);
    while k < incumbent.len() {
        s.levels[0] = root.clone();
        if s.dfs(0, 0, all, k as u32) {
            let mut cover: Vec<usize> = ones(s.found).map(|c| inst.view_ids()[c]).collect();
            cover.sort_unstable();
            debug_assert!(inst.is_cover(&cover) && cover.len() <= k);
            let size = cover.len();
            return Some(SearchOutcome { cover, optimal: true, lower_bound: size, nodes: s.nodes });
        }
        if s.stopped {
            return Some(SearchOutcome { cover: incumbent, optimal: false, lower_bound: k, nodes: s.nodes });
        }
        k += 1;
    }
    let size = incumbent.len();
    Some(SearchOutcome { cover: incumbent, optimal: true, lower_bound: size, nodes: s.nodes })
}

fn ones(mut m: u128) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let c = m.trailing_zeros() as usize;
            m &= m - 1;
            c
        })
    })
}

struct Search {
    /// Per column: its priority rank (lower first; all 0 without priorities).
    rank: Vec<u32>,
    /// Per row: the views covering it, sorted by view count.
    masks: Vec<u128>,
    /// Uncovered rows per depth (buffers reused across nodes).
    levels: Vec<Vec<u32>>,
    nodes: u64,
    deadline: Option<Instant>,
    stopped: bool,
    /// The cover found (column mask).
    found: u128,
}

impl Search {
    /// Greedy packing of `rows` (in their sorted order) with pairwise disjoint allowed views.
    fn packing(&self, rows: &[u32], allowed: u128) -> u32 {
        let mut used = 0u128;
        let mut pack = 0;
        for &r in rows {
            let a = self.masks[r as usize] & allowed;
            if a & used == 0 {
                pack += 1;
                used |= a;
            }
        }
        pack
    }

    /// Whether the rows of `levels[depth]` have a cover of at most `k_left` allowed views.
    fn dfs(&mut self, depth: usize, chosen: u128, allowed: u128, k_left: u32) -> bool {
        self.nodes += 1;
        if self.nodes % DEADLINE_CHECK_NODES == 0 && self.deadline.is_some_and(|d| Instant::now() >= d) {
            self.stopped = true;
        }
        if self.stopped {
            return false;
        }
        let rows = std::mem::take(&mut self.levels[depth]);
        let result = self.expand(depth, &rows, chosen, allowed, k_left);
        self.levels[depth] = rows;
        result
    }

    fn expand(&mut self, depth: usize, rows: &[u32], chosen: u128, allowed: u128, k_left: u32) -> bool {
        if rows.is_empty() {
            self.found = chosen;
            return true;
        }
        if k_left == 0 {
            return false;
        }
        // One pass: infeasible rows, the branching row, the common views, the packing bound.
        let mut used = 0u128;
        let mut pack = 0u32;
        let mut branch = (u32::MAX, 0u128);
        let mut common = u128::MAX;
        for &r in rows {
            let a = self.masks[r as usize] & allowed;
            if a == 0 {
                return false;
            }
            common &= a;
            let c = a.count_ones();
            if c < branch.0 {
                branch = (c, a);
            }
            if a & used == 0 {
                pack += 1;
                used |= a;
            }
        }
        if pack > k_left {
            return false;
        }
        if k_left == 1 {
            if common == 0 {
                return false;
            }
            self.found = chosen | 1u128 << common.trailing_zeros();
            return true;
        }
        // Candidate views of the branching row, by uncovered rows covered (descending).
        let candidates = branch.1;
        let mut order: Vec<(u32, u32)> = ones(candidates).map(|c| (0, c as u32)).collect();
        for &r in rows {
            let m = self.masks[r as usize] & candidates;
            if m != 0 {
                for o in order.iter_mut() {
                    o.0 += (m >> o.1 & 1) as u32;
                }
            }
        }
        let rank = &self.rank;
        order.sort_unstable_by(|a, b| {
            rank[a.1 as usize].cmp(&rank[b.1 as usize]).then(b.0.cmp(&a.0)).then(a.1.cmp(&b.1))
        });
        let mut allowed = allowed;
        for &(_, v) in &order {
            let bit = 1u128 << v;
            let mut next = std::mem::take(&mut self.levels[depth + 1]);
            next.clear();
            next.extend(rows.iter().copied().filter(|&r| self.masks[r as usize] & bit == 0));
            self.levels[depth + 1] = next;
            if self.dfs(depth + 1, chosen | bit, allowed, k_left - 1) {
                return true;
            }
            if self.stopped {
                return false;
            }
            // Every cover with v was searched: the remaining branches exclude it.
            allowed &= !bit;
        }
        false
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

    #[test]
    fn matches_brute_force_on_random_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for case in 0..400 {
            let n_views = rng.gen_range(1..=18);
            let n_el = rng.gen_range(0..60);
            let p = rng.gen_range(0.05..0.5);
            let views: Vec<Vec<usize>> =
                (0..n_views).map(|_| (0..n_el).filter(|_| rng.gen_bool(p)).collect()).collect();
            let inst = inst(&views);
            let brute = inst.brute_force().unwrap();
            let greedy = inst.greedy();
            let out = search_min_cover(&inst, 0, &greedy, &[], None).unwrap();
            assert!(out.optimal, "case {case}");
            assert_eq!(out.cover.len(), brute.len(), "case {case}: {views:?}");
            assert!(inst.is_cover(&out.cover), "case {case}");
            assert_eq!(out.lower_bound, brute.len());
            // Branch priorities change the order of the search, never the optimum.
            let priority: Vec<f64> = (0..inst.n_views()).map(|_| rng.gen_range(0.0..1.0)).collect();
            let out = search_min_cover(&inst, 0, &greedy, &priority, None).unwrap();
            assert_eq!((out.cover.len(), out.optimal), (brute.len(), true), "case {case} with priorities");
            assert!(inst.is_cover(&out.cover));
        }
    }

    #[test]
    fn finds_the_optimum_where_greedy_fails_and_respects_lower_bounds() {
        // Greedy takes view 2 (6 elements) first and then needs two more; views 0 and 1 suffice.
        let inst = inst(&[vec![0, 1, 2, 3, 6], vec![4, 5, 7, 8, 9], vec![0, 1, 4, 5, 2, 7]]);
        let greedy = inst.greedy();
        assert_eq!(greedy.len(), 3);
        let out = search_min_cover(&inst, 0, &greedy, &[], None).unwrap();
        assert_eq!((out.cover.clone(), out.optimal, out.lower_bound), (vec![0, 1], true, 2));
        // A lower bound equal to the incumbent proves it immediately.
        let out = search_min_cover(&inst, 2, &[0, 1], &[], None).unwrap();
        assert_eq!((out.optimal, out.nodes), (true, 0));
    }

    #[test]
    fn full_width_128_views_and_deadline() {
        // 128 views on a ring: element i is seen by views i and i+1 (mod 128) -> optimum 64.
        let views: Vec<Vec<usize>> = (0..128).map(|v| vec![v, (v + 127) % 128]).collect();
        let inst = inst(&views);
        let greedy = inst.greedy();
        let out = search_min_cover(&inst, 0, &greedy, &[], None).unwrap();
        assert!(out.optimal);
        assert_eq!(out.cover.len(), 64);
        // The root packing bound already proves 64 (64 disjoint pairs).
        assert!(out.nodes < 1000, "{} nodes", out.nodes);

        // An instance too large for the search.
        let big: Vec<Vec<usize>> = (0..129).map(|v| vec![v]).collect();
        let big = inst_of(&big);
        assert!(search_min_cover(&big, 0, &(0..129).collect::<Vec<_>>(), &[], None).is_none());

        // A deadline in the past stops the search on its first check with a valid bound.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let views: Vec<Vec<usize>> =
            (0..128).map(|_| (0..2000).filter(|_| rng.gen_bool(0.05)).collect()).collect();
        let hard = inst_of(&views);
        let g = hard.greedy();
        let out = search_min_cover(&hard, 0, &g, &[], Some(Instant::now())).unwrap();
        if !out.optimal {
            assert_eq!(out.cover.len(), g.len());
            assert!(out.lower_bound < g.len());
        }
    }

    fn inst_of(views: &[Vec<usize>]) -> CoverInstance {
        CoverInstance::from_index_lists(views, 1).unwrap()
    }
}
