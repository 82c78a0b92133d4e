//! Improving a max-coverage selection by exchanging one column at a time — the step between
//! `completion-mcp`'s exact branch and bound and its ILP, and after the ILP, when neither
//! finished ([`super::cover::max_coverage`]).
//!
//! Why: at large budgets that cannot cover the prediction (K = 30 on an object whose
//! completion needs more views), the branch and bound stops at its share of the time and the
//! ILP at the 10 s limit, and the selection they hand back is whatever incumbent they held.
//! A 1-swap neighbourhood is cheap on bitsets (one AND + popcount per pair of columns) and
//! often finds better selections those solvers had not reached. It is a heuristic: the
//! selection it returns is never worse than its input, never reported optimal unless its value
//! reaches a proven bound, and deterministic (no clock decides what it returns).
//!
//! A pass looks at every (chosen r, unchosen a) pair and applies the best strict improvement
//! (ties → the smallest r, then the smallest a); when the budget is not used up it first adds
//! the unchosen column of largest positive gain (ties → the smallest index). It stops at the
//! first pass without an improvement or after `max_passes`.

/// Elements covered by the columns `chosen` of `cols` (equal-length bitsets).
fn value(cols: &[Vec<u64>], chosen: &[usize]) -> usize {
    let words = cols.first().map_or(0, Vec::len);
    let mut u = vec![0u64; words];
    for &c in chosen {
        for (w, x) in u.iter_mut().zip(&cols[c]) {
            *w |= x;
        }
    }
    u.iter().map(|w| w.count_ones() as usize).sum()
}

/// Applies best-improvement 1-swaps (and additions while under `budget`) to `chosen` (distinct
/// indices into `cols`, at most `budget`), at most `max_passes` times; returns the final
/// value. `chosen` comes back sorted.
pub(crate) fn improve_by_swaps(
    cols: &[Vec<u64>],
    budget: usize,
    chosen: &mut Vec<usize>,
    max_passes: usize,
) -> usize {
    let words = cols.first().map_or(0, Vec::len);
    chosen.sort_unstable();
    chosen.dedup();
    let mut in_sel = vec![false; cols.len()];
    for &c in chosen.iter() {
        in_sel[c] = true;
    }
    let mut current = value(cols, chosen);
    let mut ones = vec![0u64; words];
    let mut twos = vec![0u64; words];
    let mut open = vec![0u64; words];
    for _ in 0..max_passes {
        // Elements covered at least once and at least twice.
        ones.iter_mut().for_each(|w| *w = 0);
        twos.iter_mut().for_each(|w| *w = 0);
        for &c in chosen.iter() {
            for ((o, t), x) in ones.iter_mut().zip(twos.iter_mut()).zip(&cols[c]) {
                *t |= *o & x;
                *o |= x;
            }
        }
        if chosen.len() < budget {
            // An addition: the unchosen column covering the most uncovered elements.
            let mut best: Option<(usize, usize)> = None;
            for (a, col) in cols.iter().enumerate() {
                if in_sel[a] {
                    continue;
                }
                let g: usize = col.iter().zip(&ones).map(|(x, o)| (x & !o).count_ones() as usize).sum();
                if g > 0 && best.is_none_or(|(bg, _)| g > bg) {
                    best = Some((g, a));
                }
            }
            if let Some((g, a)) = best {
                chosen.push(a);
                chosen.sort_unstable();
                in_sel[a] = true;
                current += g;
                continue;
            }
        }
        // The best exchange: remove r (losing what only r covers), add a (gaining what is then
        // uncovered and a covers).
        let mut best: Option<(usize, usize, usize)> = None; // (gain over the current, r, a)
        for &r in chosen.iter() {
            let mut lost = 0usize;
            for (((u, o), t), x) in open.iter_mut().zip(&ones).zip(&twos).zip(&cols[r]) {
                let only_r = x & o & !t;
                lost += only_r.count_ones() as usize;
                *u = !o | only_r;
            }
            for (a, col) in cols.iter().enumerate() {
                if in_sel[a] {
                    continue;
                }
                let g: usize = col.iter().zip(&open).map(|(x, u)| (x & u).count_ones() as usize).sum();
                if g > lost && best.is_none_or(|(bd, _, _)| g - lost > bd) {
                    best = Some((g - lost, r, a));
                }
            }
        }
        let Some((d, r, a)) = best else { break };
        in_sel[r] = false;
        in_sel[a] = true;
        chosen.retain(|&c| c != r);
        chosen.push(a);
        chosen.sort_unstable();
        current += d;
    }
    debug_assert_eq!(current, value(cols, chosen));
    current
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(n: usize, es: &[usize]) -> Vec<u64> {
        let mut b = vec![0u64; n.div_ceil(64)];
        for &e in es {
            b[e >> 6] |= 1 << (e & 63);
        }
        b
    }

    /// The best value over every selection of at most `budget` columns.
    fn brute(cols: &[Vec<u64>], budget: usize) -> usize {
        (0u32..1 << cols.len())
            .filter(|m| m.count_ones() as usize <= budget)
            .map(|m| value(cols, &(0..cols.len()).filter(|i| m >> i & 1 == 1).collect::<Vec<_>>()))
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn one_exchange_repairs_a_greedy_trap() {
        // Budget 2. Column 0 (the greedy first pick, 4 elements) overlaps both halves; columns
        // 1 and 2 together cover all 6. From {0, 1} (5 elements) the swap 0 → 2 reaches 6.
        let cols = vec![bits(6, &[1, 2, 3, 4]), bits(6, &[0, 1, 2]), bits(6, &[3, 4, 5])];
        let mut chosen = vec![0, 1];
        assert_eq!(value(&cols, &chosen), 5);
        assert_eq!(improve_by_swaps(&cols, 2, &mut chosen, 10), 6);
        assert_eq!(chosen, vec![1, 2]);
        // Under budget: additions first (the largest gain, then the smallest index).
        let mut chosen = vec![];
        assert_eq!(improve_by_swaps(&cols, 2, &mut chosen, 10), 6);
        assert_eq!(chosen, vec![1, 2]);
        // No passes: unchanged.
        let mut chosen = vec![1, 0];
        assert_eq!(improve_by_swaps(&cols, 2, &mut chosen, 0), 5);
        assert_eq!(chosen, vec![0, 1]);
    }

    #[test]
    fn swaps_never_lose_and_never_beat_the_optimum() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let (mut improved, mut reached) = (0, 0);
        for trial in 0..300 {
            let n = rng.gen_range(2..=12);
            let m = rng.gen_range(8..=150);
            // Overlapping arcs of a ring, as neighbouring views see it.
            let cols: Vec<Vec<u64>> = (0..n)
                .map(|_| {
                    let (s, len) = (rng.gen_range(0..m), rng.gen_range(1..=m / 2));
                    bits(m, &(0..len).map(|k| (s + k) % m).filter(|_| rng.gen_bool(0.85)).collect::<Vec<_>>())
                })
                .collect();
            let budget = rng.gen_range(1..n);
            let mut start: Vec<usize> = (0..n).collect();
            for i in (1..n).rev() {
                start.swap(i, rng.gen_range(0..=i));
            }
            start.truncate(rng.gen_range(0..=budget));
            let before = value(&cols, &start);
            let mut chosen = start.clone();
            let after = improve_by_swaps(&cols, budget, &mut chosen, 1000);
            let best = brute(&cols, budget);
            assert_eq!(after, value(&cols, &chosen), "trial {trial}");
            assert!(before <= after && after <= best, "trial {trial}: {before} {after} {best}");
            assert!(chosen.len() <= budget, "trial {trial}");
            assert!(chosen.windows(2).all(|w| w[0] < w[1]), "trial {trial}: {chosen:?}");
            improved += (after > before) as usize;
            reached += (after == best) as usize;
            // Deterministic: the same input gives the same selection.
            let mut again = start.clone();
            improve_by_swaps(&cols, budget, &mut again, 1000);
            assert_eq!(again, chosen, "trial {trial}");
        }
        assert!(improved > 100 && reached > 150, "improved {improved}, reached {reached}");
    }
}
