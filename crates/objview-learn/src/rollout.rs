//! Oracle rollouts over per-view visible voxel sets: the labels of the learned planners.
//!
//! Given the visible voxel sets `cov(v)` of the views (bitsets over the object's surface voxels),
//! the universe is `U = ∪ cov(v)`. A rollout from start view `s`: visited = {s}; at every step
//! record the visited views (in order), the covered count, the marginal gain `|cov(v) \ covered|`
//! of every view (0 for visited views) and the **oracle next-best view** — the unvisited view of
//! largest gain, ties to the lowest id (strict `>`); then stop if everything is covered or the
//! best gain is 0, else visit the oracle view and go on (the reference's
//! `rollout_from_cache`, learned-baselines.md §1.2). A step is a *valid case* iff something is
//! still uncovered (then the best gain is positive and the residual cover non-empty).
//!
//! The **residual set cover** of a step (MA-SCVP's label) is a minimum set of unvisited views
//! covering every uncovered voxel of U, solved exactly by the annotation's cover solver
//! ([`objview_difficulty::solve_min_cover`]) with its status.

use objview_difficulty::{solve_min_cover, CoverSettings, CoverStatus, DifficultyError};
use objview_voxel::bitset_count;

/// One recorded step of a rollout.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Visited view ids in visiting order (the start view first).
    pub visited: Vec<usize>,
    /// |covered| before the move.
    pub covered: usize,
    /// Marginal gain of every view (0 for visited ones).
    pub gains: Vec<u32>,
    /// The oracle next-best view (`None` when nothing is left to gain).
    pub nbv: Option<usize>,
    /// Its gain (0 when `nbv` is `None`).
    pub best_gain: u32,
}

impl Step {
    /// Whether this step is a training case (something is still uncovered).
    pub fn is_valid(&self) -> bool {
        self.best_gain > 0
    }
    /// Number of visited views, `m`.
    pub fn m(&self) -> usize {
        self.visited.len()
    }
}

/// One rollout from a start view.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollout {
    /// The start view.
    pub start: usize,
    /// The recorded steps, step `k` having `k + 1` visited views.
    pub steps: Vec<Step>,
}

/// The per-view coverage sets of one object and its universe.
#[derive(Debug, Clone)]
pub struct Coverage {
    /// Per-view bitsets over the surface voxels (`words` u64 each).
    pub sets: Vec<Vec<u64>>,
    /// The union of all sets.
    pub universe: Vec<u64>,
}

impl Coverage {
    /// From per-view bitsets (all of the same length).
    pub fn new(sets: Vec<Vec<u64>>) -> Coverage {
        let words = sets.first().map_or(0, Vec::len);
        let mut universe = vec![0u64; words];
        for s in &sets {
            assert_eq!(s.len(), words, "coverage bitsets must have equal lengths");
            for (u, w) in universe.iter_mut().zip(s) {
                *u |= w;
            }
        }
        Coverage { sets, universe }
    }

    /// |U|.
    pub fn universe_size(&self) -> usize {
        bitset_count(&self.universe)
    }

    /// Number of views.
    pub fn views(&self) -> usize {
        self.sets.len()
    }

    /// The greedy oracle rollout from `start` (see the module docs); `max_steps` caps the number
    /// of recorded steps (`None`: until covered or stuck).
    pub fn rollout(&self, start: usize, max_steps: Option<usize>) -> Rollout {
        let n = self.views();
        let u = self.universe_size();
        let mut covered = self.sets[start].clone();
        let mut visited = vec![start];
        let mut is_visited = vec![false; n];
        is_visited[start] = true;
        let mut steps = Vec::new();
        loop {
            let count = bitset_count(&covered);
            let gains: Vec<u32> = (0..n)
                .map(|v| {
                    if is_visited[v] {
                        0
                    } else {
                        self.sets[v].iter().zip(&covered).map(|(a, c)| (a & !c).count_ones()).sum()
                    }
                })
                .collect();
            let mut best: Option<usize> = None;
            for v in 0..n {
                if !is_visited[v] && gains[v] > 0 && best.is_none_or(|b| gains[v] > gains[b]) {
                    best = Some(v);
                }
            }
            let best_gain = best.map_or(0, |b| gains[b]);
            steps.push(Step { visited: visited.clone(), covered: count, gains, nbv: best, best_gain });
            let done = count == u || best.is_none() || max_steps.is_some_and(|m| steps.len() >= m);
            if done {
                return Rollout { start, steps };
            }
            let b = best.expect("not done");
            for (c, a) in covered.iter_mut().zip(&self.sets[b]) {
                *c |= a;
            }
            visited.push(b);
            is_visited[b] = true;
        }
    }

    /// The residual set cover of a step: a minimum set of unvisited views covering every voxel
    /// of U not covered by `visited` (ascending ids), with the solver status.
    pub fn residual_cover(
        &self,
        visited: &[usize],
        settings: &CoverSettings,
    ) -> Result<(Vec<usize>, CoverStatus), DifficultyError> {
        let words = self.universe.len();
        let mut covered = vec![0u64; words];
        for &v in visited {
            for (c, a) in covered.iter_mut().zip(&self.sets[v]) {
                *c |= a;
            }
        }
        if covered == self.universe {
            return Ok((Vec::new(), CoverStatus::Optimal));
        }
        let residual: Vec<Vec<u64>> = (0..self.views())
            .map(|v| {
                if visited.contains(&v) {
                    vec![0u64; words]
                } else {
                    self.sets[v].iter().zip(&covered).map(|(a, c)| a & !c).collect()
                }
            })
            .collect();
        let r = solve_min_cover(&residual, settings)?;
        Ok((r.best_cover, r.status))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(elems: &[usize], n: usize) -> Vec<u64> {
        let mut b = vec![0u64; n.div_ceil(64)];
        for &e in elems {
            b[e / 64] |= 1 << (e % 64);
        }
        b
    }

    /// Views 0..4 over 6 elements, with a tie: from start 0 = {0,1}, views 1 = {2,3} and
    /// 2 = {3,2} (same gain 2) → view 1 (lowest id); then 3 = {4} and 4 = {4,5} → 4.
    #[test]
    fn greedy_by_hand_with_ties_to_the_lowest_id() {
        let n = 6;
        let c = Coverage::new(vec![
            bits(&[0, 1], n),
            bits(&[2, 3], n),
            bits(&[2, 3], n),
            bits(&[4], n),
            bits(&[4, 5], n),
        ]);
        let r = c.rollout(0, None);
        let picks: Vec<Option<usize>> = r.steps.iter().map(|s| s.nbv).collect();
        assert_eq!(picks, vec![Some(1), Some(4), None]);
        assert_eq!(r.steps[0].gains, vec![0, 2, 2, 1, 2]);
        assert_eq!(r.steps[2].visited, vec![0, 1, 4]);
        assert_eq!(r.steps[2].covered, 6);
        assert!(r.steps[1].is_valid() && !r.steps[2].is_valid());
        let capped = c.rollout(0, Some(1));
        assert_eq!(capped.steps.len(), 1);
    }

    /// Random small instances: the greedy choice against a brute-force recount, and the
    /// residual cover against the brute-force minimum over subsets of unvisited views.
    #[test]
    fn rollouts_and_residual_covers_match_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let settings = CoverSettings::default();
        for _ in 0..40 {
            let (nv, ne) = (rng.gen_range(3..9), rng.gen_range(1..80));
            let sets: Vec<Vec<usize>> =
                (0..nv).map(|_| (0..ne).filter(|_| rng.gen_bool(0.3)).collect()).collect();
            let c = Coverage::new(sets.iter().map(|s| bits(s, ne)).collect());
            let start = rng.gen_range(0..nv);
            let r = c.rollout(start, None);
            for st in &r.steps {
                let cov: std::collections::BTreeSet<usize> =
                    st.visited.iter().flat_map(|&v| sets[v].iter().copied()).collect();
                assert_eq!(st.covered, cov.len());
                let gain = |v: usize| sets[v].iter().filter(|e| !cov.contains(e)).count() as u32;
                let mut best = None;
                for v in 0..nv {
                    if !st.visited.contains(&v) && gain(v) > 0 && best.is_none_or(|b| gain(v) > gain(b)) {
                        best = Some(v);
                    }
                }
                assert_eq!(st.nbv, best);
                let (cover, status) = c.residual_cover(&st.visited, &settings).unwrap();
                assert_eq!(status, CoverStatus::Optimal);
                let all: std::collections::BTreeSet<usize> = sets.iter().flatten().copied().collect();
                let missing: Vec<usize> = all.difference(&cov).copied().collect();
                let free: Vec<usize> = (0..nv).filter(|v| !st.visited.contains(v)).collect();
                let mut min = usize::MAX;
                for mask in 0u32..(1 << free.len()) {
                    let chosen: Vec<usize> = free
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| mask >> i & 1 == 1)
                        .map(|(_, &v)| v)
                        .collect();
                    if missing.iter().all(|e| chosen.iter().any(|&v| sets[v].contains(e))) {
                        min = min.min(chosen.len());
                    }
                }
                assert_eq!(cover.len(), min, "minimum residual cover");
                assert!(missing.iter().all(|e| cover.iter().any(|&v| sets[v].contains(e))));
                assert!(cover.iter().all(|v| !st.visited.contains(v)));
            }
        }
    }
}
