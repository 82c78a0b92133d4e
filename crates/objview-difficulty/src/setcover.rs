//! The combinatorial part of the planning difficulty d_plan (SPEC §4): minimum set cover of the
//! voxels seen from the planning views, without an LP solver.
//!
//! - [`CoverInstance`]: columns = views, rows = universe elements (voxels), built from per-view
//!   bitsets (bit i of word i/64 = element i, as in `objview-voxel`), universe = elements seen by at
//!   least k views. Columns keep their original view ids and rows their original element ids, so
//!   reduced instances and solutions always speak in the caller's indices.
//! - [`CoverInstance::reduce`]: optimum-preserving reductions to a fixpoint — empty columns,
//!   dominated columns, forced columns (an element seen by one view), dominated rows.
//! - [`CoverInstance::greedy`]: the deterministic greedy cover (the upper bound SPEC §4 reports).
//! - [`CoverInstance::brute_force`] and [`CoverInstance::branch_and_bound`]: exact solvers for small
//!   instances, the test oracle for the ILP solver that computes d_plan on real objects.

use std::cmp::Ordering;

use crate::error::DifficultyError;

/// Largest instance (in views) that [`CoverInstance::brute_force`] accepts.
pub const BRUTE_FORCE_MAX_VIEWS: usize = 24;

/// Number of u64 words of a bitset over `n` bits.
fn words(n: usize) -> usize {
    n.div_ceil(64)
}

fn bit(set: &[u64], i: usize) -> bool {
    set.get(i >> 6).is_some_and(|w| w >> (i & 63) & 1 == 1)
}

fn set_bit(set: &mut [u64], i: usize) {
    set[i >> 6] |= 1u64 << (i & 63);
}

fn count(set: &[u64]) -> usize {
    set.iter().map(|w| w.count_ones() as usize).sum()
}

fn count_and(a: &[u64], b: &[u64]) -> usize {
    a.iter().zip(b).map(|(x, y)| (x & y).count_ones() as usize).sum()
}

/// a ⊆ b (equal lengths).
fn is_subset(a: &[u64], b: &[u64]) -> bool {
    a.iter().zip(b).all(|(x, y)| x & !y == 0)
}

fn ones(set: &[u64]) -> impl Iterator<Item = usize> + '_ {
    set.iter().enumerate().flat_map(|(wi, &w)| {
        let mut w = w;
        std::iter::from_fn(move || {
            if w == 0 {
                return None;
            }
            let b = w.trailing_zeros() as usize;
            w &= w - 1;
            Some(wi * 64 + b)
        })
    })
}

/// A bitset with the first `n` bits set.
fn full(n: usize) -> Vec<u64> {
    let mut set = vec![u64::MAX; words(n)];
    if n % 64 != 0 {
        if let Some(last) = set.last_mut() {
            *last = (1u64 << (n % 64)) - 1;
        }
    }
    set
}

/// A set-cover instance: which views (columns) cover which universe elements (rows).
///
/// Invariant: every row is covered by at least one column (the constructors take the universe
/// inside the union of the views, and the reductions keep this true), so a cover always exists.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CoverInstance {
    /// Original view id of each column, strictly increasing.
    view_ids: Vec<usize>,
    /// Original element id of each row, strictly increasing.
    element_ids: Vec<usize>,
    /// Per column: bitset over rows.
    cols: Vec<Vec<u64>>,
}

/// Result of [`CoverInstance::reduce`]: optimum(original) = |forced| + optimum(reduced).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reduction {
    /// Views in every cover of the instance left after removing dominated views (view ids, asc).
    pub forced: Vec<usize>,
    /// Views dropped because they cover no remaining element (view ids, ascending).
    pub empty_views: Vec<usize>,
    /// Views dropped because another remaining view covers a superset (view ids, ascending).
    pub dominated_views: Vec<usize>,
    /// Elements dropped because they are covered by a forced view.
    pub elements_covered_by_forced: usize,
    /// Elements dropped because covering another remaining element implies covering them.
    pub dominated_elements: usize,
    /// Passes until no reduction applied.
    pub rounds: usize,
    /// The remaining instance (original view and element ids).
    pub reduced: CoverInstance,
}

impl Reduction {
    /// A cover of the original instance from a cover of the reduced one: forced ∪ `reduced_cover`,
    /// ascending view ids.
    pub fn lift(&self, reduced_cover: &[usize]) -> Vec<usize> {
        let mut all: Vec<usize> = self.forced.iter().chain(reduced_cover).copied().collect();
        all.sort_unstable();
        all.dedup();
        all
    }
}

/// Result of [`CoverInstance::branch_and_bound`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExactCover {
    /// The best cover found, ascending view ids.
    pub views: Vec<usize>,
    /// True when the search completed, so `views` is a minimum cover.
    pub optimal: bool,
    /// Search nodes visited.
    pub nodes: u64,
}

impl CoverInstance {
    /// An instance from per-view bitsets (bitsets may have different lengths; missing words are
    /// empty). The universe is every element seen by at least `min_views` views (SPEC §4: k = 1,
    /// the plain union). View ids are the positions in `views`.
    pub fn from_bitsets(views: &[Vec<u64>], min_views: usize) -> Result<Self, DifficultyError> {
        if min_views == 0 {
            return Err(DifficultyError::ZeroMinViews);
        }
        let span = views.iter().map(Vec::len).max().unwrap_or(0) * 64;
        let mut seen = vec![0u32; span];
        for view in views {
            for e in ones(view) {
                seen[e] += 1;
            }
        }
        let element_ids: Vec<usize> = (0..span).filter(|&e| seen[e] as usize >= min_views).collect();
        let mut row_of = vec![usize::MAX; span];
        for (row, &e) in element_ids.iter().enumerate() {
            row_of[e] = row;
        }
        let cols = views
            .iter()
            .map(|view| {
                let mut col = vec![0u64; words(element_ids.len())];
                for e in ones(view) {
                    if row_of[e] != usize::MAX {
                        set_bit(&mut col, row_of[e]);
                    }
                }
                col
            })
            .collect();
        Ok(Self { view_ids: (0..views.len()).collect(), element_ids, cols })
    }

    /// An instance from per-view lists of element ids (convenience over [`Self::from_bitsets`]).
    pub fn from_index_lists(views: &[Vec<usize>], min_views: usize) -> Result<Self, DifficultyError> {
        let span = views.iter().flatten().max().map_or(0, |&m| m + 1);
        let bitsets: Vec<Vec<u64>> = views
            .iter()
            .map(|list| {
                let mut set = vec![0u64; words(span)];
                for &e in list {
                    set_bit(&mut set, e);
                }
                set
            })
            .collect();
        Self::from_bitsets(&bitsets, min_views)
    }

    /// Number of views (columns).
    pub fn n_views(&self) -> usize {
        self.view_ids.len()
    }

    /// Number of universe elements (rows).
    pub fn n_elements(&self) -> usize {
        self.element_ids.len()
    }

    /// Original view id of each column.
    pub fn view_ids(&self) -> &[usize] {
        &self.view_ids
    }

    /// Original element id of each row.
    pub fn element_ids(&self) -> &[usize] {
        &self.element_ids
    }

    /// Original element ids covered by the view with id `view_id` (empty if not in the instance).
    pub fn covered_by(&self, view_id: usize) -> Vec<usize> {
        match self.view_ids.binary_search(&view_id) {
            Ok(c) => ones(&self.cols[c]).map(|r| self.element_ids[r]).collect(),
            Err(_) => Vec::new(),
        }
    }

    /// True when the views with these ids cover every element (ids not in the instance cover
    /// nothing).
    pub fn is_cover(&self, view_ids: &[usize]) -> bool {
        let mut covered = vec![0u64; words(self.n_elements())];
        for id in view_ids {
            if let Ok(c) = self.view_ids.binary_search(id) {
                for (w, x) in covered.iter_mut().zip(&self.cols[c]) {
                    *w |= x;
                }
            }
        }
        covered == full(self.n_elements())
    }

    /// Greedy cover: repeatedly the view with the largest number of still uncovered elements,
    /// ties to the lowest view id. Returns view ids in the order picked.
    pub fn greedy(&self) -> Vec<usize> {
        let mut uncovered = full(self.n_elements());
        let mut left = self.n_elements();
        let mut picked = Vec::new();
        while left > 0 {
            let mut best = (0usize, 0usize);
            for (c, col) in self.cols.iter().enumerate() {
                let gain = count_and(col, &uncovered);
                if gain > best.1 {
                    best = (c, gain);
                }
            }
            assert!(best.1 > 0, "invariant: every element is covered by some view");
            for (w, x) in uncovered.iter_mut().zip(&self.cols[best.0]) {
                *w &= !x;
            }
            left -= best.1;
            picked.push(self.view_ids[best.0]);
        }
        picked
    }

    /// Minimum cover by enumerating subsets by increasing size, each size in lexicographic order
    /// of column positions: the result is the lexicographically first minimum cover (view ids,
    /// ascending). At most [`BRUTE_FORCE_MAX_VIEWS`] views.
    pub fn brute_force(&self) -> Result<Vec<usize>, DifficultyError> {
        let n = self.n_views();
        if n > BRUTE_FORCE_MAX_VIEWS {
            return Err(DifficultyError::TooManyViews { views: n, max: BRUTE_FORCE_MAX_VIEWS });
        }
        if self.n_elements() == 0 {
            return Ok(Vec::new());
        }
        // Columns as u32 masks per row: row r is covered by subset S iff masks[r] & S != 0.
        let mut masks = vec![0u32; self.n_elements()];
        for (c, col) in self.cols.iter().enumerate() {
            for r in ones(col) {
                masks[r] |= 1 << c;
            }
        }
        for k in 1..=n {
            let mut comb: Vec<usize> = (0..k).collect();
            loop {
                let subset = comb.iter().fold(0u32, |m, &c| m | 1 << c);
                if masks.iter().all(|&m| m & subset != 0) {
                    return Ok(comb.iter().map(|&c| self.view_ids[c]).collect());
                }
                // Next combination in lexicographic order.
                let Some(i) = (0..k).rev().find(|&i| comb[i] < n - k + i) else { break };
                comb[i] += 1;
                for j in i + 1..k {
                    comb[j] = comb[j - 1] + 1;
                }
            }
        }
        unreachable!("invariant: the set of all views is a cover")
    }

    /// Minimum cover by depth-first branch and bound: branch on the uncovered element with the
    /// fewest admissible views (each branch takes one of them, later branches exclude the earlier
    /// ones), prune with max(⌈uncovered / largest gain⌉, number of greedily chosen uncovered
    /// elements with pairwise disjoint admissible view sets). Starts from the greedy cover. With a
    /// `node_limit`, stops early and reports `optimal = false`.
    pub fn branch_and_bound(&self, node_limit: Option<u64>) -> ExactCover {
        let mut greedy = self.greedy();
        greedy.sort_unstable();
        let mut search = Search {
            inst: self,
            rows: self.row_sets(&full(self.n_views())),
            best: greedy.iter().map(|id| self.view_ids.binary_search(id).unwrap()).collect(),
            nodes: 0,
            limit: node_limit.unwrap_or(u64::MAX),
            aborted: false,
        };
        let mut chosen = Vec::new();
        search.run(&full(self.n_elements()), &full(self.n_views()), &mut chosen);
        let mut views: Vec<usize> = search.best.iter().map(|&c| self.view_ids[c]).collect();
        views.sort_unstable();
        ExactCover { views, optimal: !search.aborted, nodes: search.nodes }
    }

    /// Per row: bitset over columns, restricted to the columns in `active_cols`.
    fn row_sets(&self, active_cols: &[u64]) -> Vec<Vec<u64>> {
        let mut rows = vec![vec![0u64; words(self.n_views())]; self.n_elements()];
        for c in ones(active_cols) {
            for r in ones(&self.cols[c]) {
                set_bit(&mut rows[r], c);
            }
        }
        rows
    }

    /// Applies the optimum-preserving reductions until none applies:
    /// 1. drop views covering no remaining element;
    /// 2. drop a view whose remaining covered set is a subset of another remaining view's (equal
    ///    sets: the lower view id stays) — some minimum cover avoids it;
    /// 3. force the only view covering some element into the solution, dropping the elements it
    ///    covers;
    /// 4. drop an element whose set of covering views is a superset of another remaining
    ///    element's (equal sets: the lower element id stays) — covering the other covers it.
    pub fn reduce(&self) -> Reduction {
        let (nc, nr) = (self.n_views(), self.n_elements());
        let mut active_cols = full(nc);
        let mut active_rows = full(nr);
        let mut red = Reduction {
            forced: Vec::new(),
            empty_views: Vec::new(),
            dominated_views: Vec::new(),
            elements_covered_by_forced: 0,
            dominated_elements: 0,
            rounds: 0,
            reduced: CoverInstance { view_ids: Vec::new(), element_ids: Vec::new(), cols: Vec::new() },
        };
        loop {
            red.rounds += 1;
            let mut changed = false;

            // 1 + 2: empty and dominated columns, on the remaining rows.
            let live: Vec<usize> = ones(&active_cols).collect();
            let restricted: Vec<Vec<u64>> = live
                .iter()
                .map(|&c| self.cols[c].iter().zip(&active_rows).map(|(x, y)| x & y).collect())
                .collect();
            let sizes: Vec<usize> = restricted.iter().map(|s| count(s)).collect();
            for (a, &c) in live.iter().enumerate() {
                let list = if sizes[a] == 0 {
                    &mut red.empty_views
                } else if live.iter().enumerate().any(|(b, &d)| {
                    // Equal sets (same size, subset): only the lower view id dominates.
                    b != a
                        && sizes[b] >= sizes[a]
                        && is_subset(&restricted[a], &restricted[b])
                        && (sizes[b] > sizes[a] || d < c)
                }) {
                    &mut red.dominated_views
                } else {
                    continue;
                };
                list.push(self.view_ids[c]);
                active_cols[c >> 6] &= !(1u64 << (c & 63));
                changed = true;
            }

            // 3: forced columns.
            let rows = self.row_sets(&active_cols);
            let mut forced_now = vec![0u64; words(nc)];
            for r in ones(&active_rows) {
                if count(&rows[r]) == 1 {
                    let c = ones(&rows[r]).next().expect("one bit");
                    set_bit(&mut forced_now, c);
                }
            }
            for c in ones(&forced_now) {
                red.forced.push(self.view_ids[c]);
                active_cols[c >> 6] &= !(1u64 << (c & 63));
                for (w, x) in active_rows.iter_mut().zip(&self.cols[c]) {
                    red.elements_covered_by_forced += (*w & x).count_ones() as usize;
                    *w &= !x;
                }
                changed = true;
            }

            // 4: dominated rows (on the columns left after forcing).
            let rows = self.row_sets(&active_cols);
            let dropped = dominated_rows(&rows, &active_rows, nc);
            for r in &dropped {
                active_rows[r >> 6] &= !(1u64 << (r & 63));
            }
            red.dominated_elements += dropped.len();
            changed |= !dropped.is_empty();

            if !changed {
                break;
            }
        }
        red.forced.sort_unstable();
        red.empty_views.sort_unstable();
        red.dominated_views.sort_unstable();
        red.reduced = self.restrict(&active_cols, &active_rows);
        red
    }

    /// The sub-instance on the given columns and rows.
    fn restrict(&self, active_cols: &[u64], active_rows: &[u64]) -> CoverInstance {
        let rows: Vec<usize> = ones(active_rows).collect();
        let cols: Vec<usize> = ones(active_cols).collect();
        CoverInstance {
            view_ids: cols.iter().map(|&c| self.view_ids[c]).collect(),
            element_ids: rows.iter().map(|&r| self.element_ids[r]).collect(),
            cols: cols
                .iter()
                .map(|&c| {
                    let mut col = vec![0u64; words(rows.len())];
                    for (new, &r) in rows.iter().enumerate() {
                        if bit(&self.cols[c], r) {
                            set_bit(&mut col, new);
                        }
                    }
                    col
                })
                .collect(),
        }
    }
}

/// Rows (among `active_rows`) whose column set is a superset of another active row's; of equal
/// sets the lowest row stays. Distinct sets are scanned by increasing size; a set is dominated
/// iff it contains a kept (minimal) set, and kept sets are bucketed by their rarest column, which
/// any superset must contain — so only those buckets are checked.
fn dominated_rows(rows: &[Vec<u64>], active_rows: &[u64], n_cols: usize) -> Vec<usize> {
    let mut order: Vec<usize> = ones(active_rows).collect();
    let sizes: Vec<usize> = rows.iter().map(|r| count(r)).collect();
    order.sort_by(|&a, &b| sizes[a].cmp(&sizes[b]).then_with(|| rows[a].cmp(&rows[b])).then(a.cmp(&b)));
    let mut frequency = vec![0usize; n_cols];
    for &r in &order {
        for c in ones(&rows[r]) {
            frequency[c] += 1;
        }
    }
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); n_cols];
    let mut dropped = Vec::new();
    for (i, &r) in order.iter().enumerate() {
        let duplicate = i > 0 && rows[order[i - 1]] == rows[r];
        let dominated =
            duplicate || ones(&rows[r]).any(|c| buckets[c].iter().any(|&k| is_subset(&rows[k], &rows[r])));
        if dominated {
            dropped.push(r);
        } else if let Some(rarest) =
            ones(&rows[r]).min_by(|&a, &b| frequency[a].cmp(&frequency[b]).then(a.cmp(&b)))
        {
            buckets[rarest].push(r);
        }
    }
    dropped.sort_unstable();
    dropped
}

/// State of the branch-and-bound search (column positions, not view ids).
struct Search<'a> {
    inst: &'a CoverInstance,
    /// Per row: bitset over all columns.
    rows: Vec<Vec<u64>>,
    best: Vec<usize>,
    nodes: u64,
    limit: u64,
    aborted: bool,
}

impl Search<'_> {
    fn run(&mut self, uncovered: &[u64], allowed: &[u64], chosen: &mut Vec<usize>) {
        if self.aborted {
            return;
        }
        self.nodes += 1;
        if self.nodes > self.limit {
            self.aborted = true;
            return;
        }
        let left = count(uncovered);
        if left == 0 {
            if chosen.len() < self.best.len() {
                self.best = chosen.clone();
            }
            return;
        }
        if chosen.len() + 1 >= self.best.len() {
            return; // at least one more view is needed, which cannot improve on the incumbent
        }
        // Branching row: fewest admissible columns (ties: lowest row).
        let mut branch: Option<(usize, usize)> = None;
        for r in ones(uncovered) {
            let k = count_and(&self.rows[r], allowed);
            if branch.is_none_or(|(_, best)| k < best) {
                branch = Some((r, k));
            }
        }
        let (row, k) = branch.expect("uncovered is not empty");
        if k == 0 {
            return; // infeasible under the exclusions of this branch
        }
        if chosen.len() + self.lower_bound(uncovered, allowed, left) >= self.best.len() {
            return;
        }
        let admissible: Vec<u64> = self.rows[row].iter().zip(allowed).map(|(x, y)| x & y).collect();
        let mut candidates: Vec<(usize, usize)> =
            ones(&admissible).map(|c| (c, count_and(&self.inst.cols[c], uncovered))).collect();
        // Larger gains first (finds good covers early), ties by column.
        candidates.sort_by(|a, b| match b.1.cmp(&a.1) {
            Ordering::Equal => a.0.cmp(&b.0),
            o => o,
        });
        let mut allowed = allowed.to_vec();
        for (c, _) in candidates {
            let next: Vec<u64> = uncovered.iter().zip(&self.inst.cols[c]).map(|(u, x)| u & !x).collect();
            chosen.push(c);
            self.run(&next, &allowed, chosen);
            chosen.pop();
            // Every cover containing c has been explored: exclude c from the remaining branches.
            allowed[c >> 6] &= !(1u64 << (c & 63));
        }
    }

    /// Lower bound on the number of further views needed to cover `uncovered`.
    fn lower_bound(&self, uncovered: &[u64], allowed: &[u64], left: usize) -> usize {
        let max_gain =
            ones(allowed).map(|c| count_and(&self.inst.cols[c], uncovered)).max().unwrap_or(0).max(1);
        let by_size = left.div_ceil(max_gain);
        // Uncovered rows with pairwise disjoint admissible column sets need distinct views.
        let mut used = vec![0u64; allowed.len()];
        let mut disjoint = 0;
        for r in ones(uncovered) {
            let cols: Vec<u64> = self.rows[r].iter().zip(allowed).map(|(x, y)| x & y).collect();
            if cols.iter().zip(&used).all(|(x, u)| x & u == 0) {
                disjoint += 1;
                for (u, x) in used.iter_mut().zip(&cols) {
                    *u |= x;
                }
            }
        }
        by_size.max(disjoint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn inst(views: &[&[usize]]) -> CoverInstance {
        CoverInstance::from_index_lists(&views.iter().map(|v| v.to_vec()).collect::<Vec<_>>(), 1).unwrap()
    }

    /// Minimum cover size by checking every subset of views against plain element lists — an
    /// oracle independent of the bitset code.
    fn oracle_min(views: &[Vec<usize>], universe: &[usize]) -> usize {
        let n = views.len();
        (0u32..1 << n)
            .filter(|&mask| {
                universe.iter().all(|e| (0..n).any(|v| mask >> v & 1 == 1 && views[v].contains(e)))
            })
            .map(|mask| mask.count_ones() as usize)
            .min()
            .expect("all views cover the universe")
    }

    /// A random instance: some views are copies or subsets of earlier ones, to exercise the
    /// column reductions.
    fn random_views(rng: &mut ChaCha8Rng) -> Vec<Vec<usize>> {
        let n_views = rng.gen_range(1..=16);
        let n_elements = rng.gen_range(0..=70);
        let density = rng.gen_range(0.03..0.45);
        let mut views: Vec<Vec<usize>> = Vec::new();
        for _ in 0..n_views {
            let view = match (views.is_empty(), rng.gen_range(0..6)) {
                (false, 0) => views[rng.gen_range(0..views.len())].clone(),
                (false, 1) => {
                    let src = &views[rng.gen_range(0..views.len())];
                    src.iter().copied().filter(|_| rng.gen_bool(0.6)).collect()
                }
                _ => (0..n_elements).filter(|_| rng.gen_bool(density)).collect(),
            };
            views.push(view);
        }
        views
    }

    fn union(views: &[Vec<usize>]) -> Vec<usize> {
        let mut all: Vec<usize> = views.iter().flatten().copied().collect();
        all.sort_unstable();
        all.dedup();
        all
    }

    #[test]
    fn universe_is_the_union_or_the_elements_seen_k_times() {
        let views = vec![vec![0, 3, 70], vec![3, 4], vec![3, 70, 130], vec![]];
        let one = CoverInstance::from_index_lists(&views, 1).unwrap();
        assert_eq!(one.element_ids(), &[0, 3, 4, 70, 130]);
        assert_eq!(one.view_ids(), &[0, 1, 2, 3]);
        let two = CoverInstance::from_index_lists(&views, 2).unwrap();
        assert_eq!(two.element_ids(), &[3, 70]);
        assert_eq!(two.covered_by(2), vec![3, 70]);
        assert_eq!(two.covered_by(1), vec![3]);
        let three = CoverInstance::from_index_lists(&views, 3).unwrap();
        assert_eq!(three.element_ids(), &[3]);
        assert_eq!(CoverInstance::from_index_lists(&views, 0), Err(DifficultyError::ZeroMinViews));
        // Bitsets of different lengths; bit i of word i/64.
        let bits = vec![vec![1u64 << 5], vec![0, 1u64 << 1, 1u64 << 63]];
        let b = CoverInstance::from_bitsets(&bits, 1).unwrap();
        assert_eq!(b.element_ids(), &[5, 65, 191]);
        assert!(b.is_cover(&[0, 1]) && !b.is_cover(&[1]) && !b.is_cover(&[0, 7]));
    }

    #[test]
    fn empty_universe() {
        let e = CoverInstance::from_bitsets(&[vec![0u64], vec![]], 1).unwrap();
        assert_eq!(e.n_elements(), 0);
        assert!(e.greedy().is_empty());
        assert_eq!(e.brute_force().unwrap(), Vec::<usize>::new());
        assert!(e.branch_and_bound(None).views.is_empty());
        let red = e.reduce();
        assert_eq!(red.empty_views, vec![0, 1]);
        assert_eq!(red.reduced.n_views(), 0);
        let none = CoverInstance::from_bitsets(&[], 1).unwrap();
        assert!(none.is_cover(&[]) && none.greedy().is_empty());
    }

    #[test]
    fn greedy_worst_case_picks_k_sets_where_two_suffice() {
        // Elements in two rows R1, R2; blocks S_i (i = 1..k) of 2^i elements, half in each row.
        // |R1| = |R2| = 2^k − 1 < 2^k = |S_k|, and after taking S_k, …, S_{i+1} the rows keep
        // 2^i − 1 new elements against S_i's 2^i: greedy takes S_k, …, S_1 (k sets), optimum 2.
        let k = 5;
        let (mut r1, mut r2) = (Vec::new(), Vec::new());
        let mut blocks = Vec::new();
        let mut next = 0;
        for i in 1..=k {
            let half = 1usize << (i - 1);
            let block: Vec<usize> = (next..next + 2 * half).collect();
            r1.extend(&block[..half]);
            r2.extend(&block[half..]);
            next += 2 * half;
            blocks.push(block);
        }
        let mut views = vec![r1, r2];
        views.extend(blocks);
        let instance = CoverInstance::from_index_lists(&views, 1).unwrap();
        // View ids: R1 = 0, R2 = 1, S_i = i + 1.
        assert_eq!(instance.greedy(), vec![6, 5, 4, 3, 2]);
        assert_eq!(instance.brute_force().unwrap(), vec![0, 1]);
        let bb = instance.branch_and_bound(None);
        assert!(bb.optimal);
        assert_eq!(bb.views.len(), 2);
    }

    #[test]
    fn greedy_breaks_ties_to_the_lowest_view_id() {
        let i = inst(&[&[0, 1], &[2, 3], &[0, 1], &[1, 2]]);
        assert_eq!(i.greedy(), vec![0, 1]);
        let j = inst(&[&[0], &[1, 2], &[3, 4], &[0, 1, 3]]);
        // Gains: 1, 2, 2, 3 → view 3; then {2, 4}: views 1 and 2 tie at 1 → view 1, then view 2.
        assert_eq!(j.greedy(), vec![3, 1, 2]);
    }

    #[test]
    fn reductions_on_hand_made_instances() {
        // View 1 ⊂ view 0; view 3 = view 2 (view 3 dropped, lower id stays); view 4 is empty.
        let i = inst(&[&[0, 1, 2], &[1, 2], &[3, 4], &[3, 4], &[]]);
        let red = i.reduce();
        assert_eq!(red.dominated_views, vec![1, 3]);
        assert_eq!(red.empty_views, vec![4]);
        // Then every element has one view left: views 0 and 2 forced, nothing remains.
        assert_eq!(red.forced, vec![0, 2]);
        assert_eq!(red.elements_covered_by_forced, 5);
        assert_eq!(red.reduced.n_elements(), 0);
        assert_eq!(red.lift(&[]), vec![0, 2]);
        // Dominated rows: element 0 is seen by {0, 1}, element 1 by {0, 1, 2} ⊇ → dropped;
        // element 2 by {1, 2}, element 3 by {2, 0}: an odd cycle, nothing forced or dominated among
        // 0, 2, 3 (pairwise incomparable) and views pairwise incomparable.
        let cyc = inst(&[&[0, 1, 3], &[0, 1, 2], &[1, 2, 3]]);
        let red = cyc.reduce();
        assert_eq!(red.dominated_elements, 1);
        assert_eq!(red.reduced.element_ids(), &[0, 2, 3]);
        assert_eq!(red.reduced.view_ids(), &[0, 1, 2]);
        assert!(red.forced.is_empty());
        assert_eq!(red.reduced.brute_force().unwrap().len(), 2);
        // Duplicate rows: the lower element id stays.
        let dup = inst(&[&[5, 9], &[5, 9, 1], &[1]]);
        let red = dup.reduce();
        // Views: {5, 9} ⊂ {1, 5, 9} and {1} ⊂ it: both dominated, view 1 forced.
        assert_eq!(red.dominated_views, vec![0, 2]);
        assert_eq!(red.forced, vec![1]);
        let rows_only = inst(&[&[5, 9, 2], &[5, 9, 3], &[2, 3]]);
        let red = rows_only.reduce();
        assert_eq!(red.reduced.element_ids(), &[2, 3, 5], "9 duplicates 5 and is dropped");
    }

    #[test]
    fn reductions_preserve_the_optimum_on_random_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(0x0b7e_c0de);
        let mut reduced_something = 0;
        for round in 0..300 {
            let views = random_views(&mut rng);
            let k = if round % 4 == 3 { 2 } else { 1 };
            let instance = CoverInstance::from_index_lists(&views, k).unwrap();
            // Universe by definition, independently.
            let universe: Vec<usize> = union(&views)
                .into_iter()
                .filter(|e| views.iter().filter(|v| v.contains(e)).count() >= k)
                .collect();
            assert_eq!(instance.element_ids(), universe.as_slice(), "round {round}");
            let opt = if universe.is_empty() { 0 } else { oracle_min(&views, &universe) };

            let bf = instance.brute_force().unwrap();
            assert_eq!(bf.len(), opt, "round {round}: brute force");
            assert!(instance.is_cover(&bf));
            let bb = instance.branch_and_bound(None);
            assert!(bb.optimal);
            assert_eq!(bb.views.len(), opt, "round {round}: branch and bound");
            assert!(instance.is_cover(&bb.views));
            let greedy = instance.greedy();
            assert!(greedy.len() >= opt, "round {round}: greedy below optimum");
            assert!(instance.is_cover(&greedy));

            let red = instance.reduce();
            let sub = red.reduced.brute_force().unwrap();
            assert_eq!(red.forced.len() + sub.len(), opt, "round {round}: reductions changed the optimum");
            let lifted = red.lift(&sub);
            assert_eq!(lifted.len(), opt);
            assert!(instance.is_cover(&lifted), "round {round}: lifted solution is not a cover");
            // The fixpoint: no empty, dominated or forced column and no dominated row remain.
            let r = &red.reduced;
            let cols: Vec<Vec<usize>> = r.view_ids().iter().map(|&v| r.covered_by(v)).collect();
            for (a, ca) in cols.iter().enumerate() {
                assert!(!ca.is_empty(), "round {round}: empty column left");
                for (b, cb) in cols.iter().enumerate() {
                    assert!(
                        a == b || !ca.iter().all(|e| cb.contains(e)),
                        "round {round}: dominated column left"
                    );
                }
            }
            let rows: Vec<Vec<usize>> = r
                .element_ids()
                .iter()
                .map(|e| (0..cols.len()).filter(|&c| cols[c].contains(e)).collect())
                .collect();
            for (a, ra) in rows.iter().enumerate() {
                assert!(ra.len() >= 2, "round {round}: forced column left");
                for (b, rb) in rows.iter().enumerate() {
                    assert!(
                        a == b || !rb.iter().all(|c| ra.contains(c)),
                        "round {round}: dominated row left"
                    );
                }
            }
            if red.reduced.n_elements() < instance.n_elements() {
                reduced_something += 1;
            }
        }
        assert!(reduced_something > 100, "the random family exercises the reductions: {reduced_something}");
    }

    #[test]
    fn branch_and_bound_beyond_brute_force_size() {
        // 40 views on 120 elements (too many views for brute force): B&B returns a cover no larger
        // than greedy, and solving the reduced instance gives the same optimum.
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..5 {
            let views: Vec<Vec<usize>> =
                (0..40).map(|_| (0..120).filter(|_| rng.gen_bool(0.08)).collect()).collect();
            let instance = CoverInstance::from_index_lists(&views, 1).unwrap();
            let bb = instance.branch_and_bound(None);
            assert!(bb.optimal && instance.is_cover(&bb.views));
            assert!(bb.views.len() <= instance.greedy().len());
            // Reducing first gives the same optimum.
            let red = instance.reduce();
            let sub = red.reduced.branch_and_bound(None);
            assert_eq!(red.forced.len() + sub.views.len(), bb.views.len());
            assert!(instance.is_cover(&red.lift(&sub.views)));
            // A node limit of 1 stops at the root with the greedy incumbent.
            let stopped = instance.branch_and_bound(Some(1));
            assert!(instance.is_cover(&stopped.views));
            if !stopped.optimal {
                assert_eq!(stopped.views.len(), instance.greedy().len());
            }
        }
        let big = CoverInstance::from_index_lists(&vec![vec![0]; 25], 1).unwrap();
        assert_eq!(big.brute_force(), Err(DifficultyError::TooManyViews { views: 25, max: 24 }));
    }
}
