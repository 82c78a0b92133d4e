//! Exact budgeted maximum coverage by depth-first branch and bound — the first solver of
//! `completion-mcp`'s selection step ([`super::cover::max_coverage`]), because the planners'
//! instances (a few thousand target voxels, a few hundred candidate views, budgets K − 1 of
//! 4–29) are where HiGHS's LP-based search is slowest: neighbouring views see nearly the same
//! voxels, so the LP relaxation splits its budget across them and its bound stays far above the
//! optimum; HiGHS hit its 10 s limit on most K = 5 plans of the Main-Hidden-Test campaign.
//!
//! The search enumerates each selection of at most B columns once: at a node (a partial
//! selection S with r picks left) the columns not yet excluded are ordered by their marginal
//! gain Δ_c(S) = |c \ ∪S| (ties → smaller index), and child i takes the i-th column and may only
//! use the columns after it. Coverage is submodular, so f(S ∪ T) ≤ f(S) + Σ_{c∈T} Δ_c(S): child
//! i's best is at most f(S) + Δ_i + (the next r − 1 gains), and at most f(S) + |∪_{j≥i} Δ_j|
//! (what the columns it may still use can add); both fall with i, so the first child whose bound
//! does not beat the incumbent ends the node. The last pick scans its columns in descending
//! parent gain (an upper bound on the gain now) and stops when no later one can win. Incumbents
//! only change on a strict improvement, so the answer is the first optimum in this fixed order
//! — the same on every machine and at every speed, unlike a time-limited solve.
//!
//! Stopped at its deadline, the search reports its incumbent and a proven upper bound: the
//! largest bound of the nodes it left open (the next sibling at each level of the stack, whose
//! bound dominates its later siblings').

use std::time::Instant;

/// What the search returned.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SearchOutcome {
    /// The best selection found (column indices, ascending).
    pub chosen: Vec<usize>,
    /// Elements it covers.
    pub value: usize,
    /// Proven upper bound on the optimum (= `value` when `proven`).
    pub bound: usize,
    /// Whether the search finished (the selection is optimal).
    pub proven: bool,
    /// Nodes visited.
    pub nodes: u64,
}

/// Elements of `col` not in `covered` (equal-length bitsets).
fn gain(col: &[u64], covered: &[u64]) -> usize {
    col.iter().zip(covered).map(|(a, b)| (a & !b).count_ones() as usize).sum()
}

/// Elements the columns `chosen` of `cols` cover together.
fn covered_count(cols: &[Vec<u64>], chosen: impl IntoIterator<Item = usize>) -> usize {
    let mut union = vec![0u64; cols.first().map_or(0, Vec::len)];
    for c in chosen {
        for (w, x) in union.iter_mut().zip(&cols[c]) {
            *w |= x;
        }
    }
    union.iter().map(|w| w.count_ones() as usize).sum()
}

struct Search<'a> {
    cols: &'a [Vec<u64>],
    best_value: usize,
    best: Vec<usize>,
    path: Vec<usize>,
    nodes: u64,
    deadline: Instant,
    stopped: bool,
    open_bound: usize,
}

impl Search<'_> {
    fn improve(&mut self, value: usize, last: Option<usize>) {
        if value > self.best_value {
            self.best_value = value;
            self.best = self.path.clone();
            self.best.extend(last);
        }
    }

    /// The node of selection `self.path` (covering `covered`, `value` elements), `r` picks left,
    /// choosing from `cands`, whose gains here are at most `ubs` (the parent's gains:
    /// submodularity; descending); `bound` is the bound its parent gave it.
    fn node(
        &mut self,
        covered: &[u64],
        value: usize,
        r: usize,
        cands: &[usize],
        ubs: &[usize],
        bound: usize,
    ) {
        self.nodes += 1;
        if self.nodes % 64 == 1 && Instant::now() >= self.deadline {
            self.stopped = true;
        }
        if self.stopped {
            self.open_bound = self.open_bound.max(bound);
            return;
        }
        if r == 1 {
            // The last pick: the first column of largest gain, scanning in descending upper
            // bounds until no later column can beat what is found (or the incumbent).
            let mut best: Option<(usize, usize)> = None;
            for (&c, &ub) in cands.iter().zip(ubs) {
                let beat = best.map_or(self.best_value.saturating_sub(value), |b| b.0);
                if ub <= beat {
                    break;
                }
                let g = gain(&self.cols[c], covered);
                if g > beat && g > 0 {
                    best = Some((g, c));
                }
            }
            match best {
                Some((g, c)) => self.improve(value + g, Some(c)),
                None => self.improve(value, None),
            }
            return;
        }
        if r == 0 {
            self.improve(value, None);
            return;
        }
        let mut gains: Vec<(usize, usize)> = cands
            .iter()
            .filter_map(|&c| {
                let g = gain(&self.cols[c], covered);
                (g > 0).then_some((g, c))
            })
            .collect();
        if gains.is_empty() {
            self.improve(value, None);
            return;
        }
        gains.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        let n = gains.len();
        let mut prefix = Vec::with_capacity(n + 1);
        prefix.push(0usize);
        for &(g, _) in &gains {
            prefix.push(prefix.last().unwrap() + g);
        }
        let order: Vec<usize> = gains.iter().map(|&(_, c)| c).collect();
        let sorted: Vec<usize> = gains.iter().map(|&(g, _)| g).collect();
        // |∪_{j ≥ i} (c_j \ covered)|: what child i and its descendants can add at most.
        let mut suffix = vec![0usize; n];
        let mut union = vec![0u64; covered.len()];
        for i in (0..n).rev() {
            let mut count = 0;
            for ((u, x), y) in union.iter_mut().zip(&self.cols[order[i]]).zip(covered) {
                *u |= x & !y;
                count += u.count_ones() as usize;
            }
            suffix[i] = count;
        }
        // Both parts of the bound fall with i (sorted gains, shrinking suffixes), so the first
        // child it cannot admit ends the node.
        let child_bound = |i: usize| value + (prefix[(i + r).min(n)] - prefix[i]).min(suffix[i]);
        let mut child = covered.to_vec();
        for i in 0..n {
            let b = child_bound(i);
            if b <= self.best_value {
                break;
            }
            for (w, (x, y)) in child.iter_mut().zip(covered.iter().zip(&self.cols[order[i]])) {
                *w = x | y;
            }
            self.path.push(order[i]);
            self.node(&child, value + gains[i].0, r - 1, &order[i + 1..], &sorted[i + 1..], b);
            self.path.pop();
            if self.stopped {
                if i + 1 < n && child_bound(i + 1) > self.best_value {
                    self.open_bound = self.open_bound.max(child_bound(i + 1));
                }
                return;
            }
        }
    }
}

/// At most `budget` of `cols` (equal-length bitsets over the elements that matter) covering the
/// most elements, starting from the incumbent `start` (any selection of at most `budget`
/// columns, e.g. the greedy one); exact unless stopped at `deadline`.
pub(crate) fn search_max_coverage(
    cols: &[Vec<u64>],
    budget: usize,
    start: &[usize],
    deadline: Instant,
) -> SearchOutcome {
    let words = cols.first().map_or(0, Vec::len);
    let start_value = covered_count(cols, start.iter().copied());
    let reachable = covered_count(cols, 0..cols.len());
    let mut s = Search {
        cols,
        best_value: start_value,
        best: start.to_vec(),
        path: Vec::new(),
        nodes: 0,
        deadline,
        stopped: false,
        open_bound: 0,
    };
    let all: Vec<usize> = (0..cols.len()).collect();
    if start_value < reachable {
        s.node(&vec![0u64; words], 0, budget, &all, &vec![usize::MAX; all.len()], reachable);
    }
    let mut chosen = s.best;
    chosen.sort_unstable();
    let bound = if s.stopped { s.open_bound.max(s.best_value).min(reachable) } else { s.best_value };
    SearchOutcome { chosen, value: s.best_value, bound, proven: !s.stopped, nodes: s.nodes }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::time::Duration;

    fn value(cols: &[Vec<u64>], chosen: &[usize]) -> usize {
        covered_count(cols, chosen.iter().copied())
    }

    /// The best value over every selection of at most `budget` columns.
    fn brute(cols: &[Vec<u64>], budget: usize) -> usize {
        (0u32..1 << cols.len())
            .filter(|m| m.count_ones() as usize <= budget)
            .map(|m| value(cols, &(0..cols.len()).filter(|i| m >> i & 1 == 1).collect::<Vec<_>>()))
            .max()
            .unwrap()
    }

    fn instance(rng: &mut ChaCha8Rng, n: usize, m: usize) -> Vec<Vec<u64>> {
        // Overlapping "views": each column a random arc of a ring of m elements, with holes —
        // like neighbouring cameras, the instances where the gain bound is weakest.
        (0..n)
            .map(|_| {
                let mut b = vec![0u64; m.div_ceil(64)];
                let (s, len) = (rng.gen_range(0..m), rng.gen_range(1..=m / 2 + 1));
                for k in 0..len {
                    let e = (s + k) % m;
                    if rng.gen_bool(0.85) {
                        b[e >> 6] |= 1 << (e & 63);
                    }
                }
                b
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_on_random_instances() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let far = Instant::now() + Duration::from_secs(3600);
        for trial in 0..200 {
            let (n, m) = (rng.gen_range(1..=12), rng.gen_range(1..=150));
            let cols = instance(&mut rng, n, m);
            let budget = rng.gen_range(0..=n + 1);
            // A deliberately poor incumbent: nothing, or one column.
            let start: Vec<usize> = if trial % 2 == 0 || budget == 0 { vec![] } else { vec![n - 1] };
            let out = search_max_coverage(&cols, budget, &start, far);
            let best = brute(&cols, budget);
            assert!(out.proven, "trial {trial}");
            assert_eq!((out.value, out.bound), (best, best), "trial {trial}");
            assert!(out.chosen.len() <= budget, "trial {trial}");
            assert_eq!(value(&cols, &out.chosen), best, "trial {trial}");
        }
    }

    #[test]
    fn a_stopped_search_keeps_its_incumbent_and_a_valid_bound() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let cols = instance(&mut rng, 12, 150);
        let best = brute(&cols, 4);
        // A deadline in the past stops the search at its first check (the root).
        let out = search_max_coverage(&cols, 4, &[0], Instant::now());
        assert!(!out.proven && out.nodes == 1, "{out:?}");
        assert_eq!((out.chosen.clone(), out.value), (vec![0], value(&cols, &[0])));
        assert!(best <= out.bound, "{out:?} vs optimum {best}");
        // Stopped somewhere inside a larger tree (the optimum from the unlimited search, which
        // the test above checks against brute force): the incumbent's value is what it covers,
        // and the bound left by the open nodes is never below the optimum.
        let big = instance(&mut rng, 40, 400);
        let full = search_max_coverage(&big, 6, &[], Instant::now() + Duration::from_secs(3600));
        assert!(full.proven);
        for us in [0, 20, 100, 500, 2_000, 10_000] {
            let out = search_max_coverage(&big, 6, &[], Instant::now() + Duration::from_micros(us));
            assert_eq!(value(&big, &out.chosen), out.value, "{us} µs");
            assert!(out.value <= full.value && full.value <= out.bound, "{us} µs: {out:?} vs {full:?}");
            if out.proven {
                assert_eq!((out.value, out.bound), (full.value, full.value));
            }
        }
    }

    #[test]
    fn the_first_optimum_in_gain_order_is_returned() {
        // Columns 0 and 1 are equal, as are 2 and 3: of the equal optima, the smaller indices.
        let c = |es: &[usize]| vec![es.iter().fold(0u64, |w, &e| w | 1 << e)];
        let cols = vec![c(&[0, 1, 2]), c(&[0, 1, 2]), c(&[3, 4]), c(&[3, 4]), c(&[0, 3])];
        let out = search_max_coverage(&cols, 2, &[], Instant::now() + Duration::from_secs(60));
        assert_eq!((out.chosen, out.value, out.proven), (vec![0, 2], 5, true));
    }
}
