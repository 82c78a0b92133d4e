//! Which rollout steps become training cases: the reference's case-sampling protocols
//! (`export_method_case`, learned-baselines.md §1.3), with our own seeded RNG (the reference's
//! draws use `std::hash` and unordered-map order, so the *rule* is reproduced, not its draw).
//!
//! - **Long-tail** (MA-SCVP): bucket the valid cases of all rollouts by `m` (visited views);
//!   `g_m` = mean oracle gain of bucket m; `base = g_1` (1 if `g_1 ≤ 0`); keep
//!   `need_m = ceil(need_case_1 · g_m / base)` cases of bucket m (clipped to its size), the first
//!   ones after a seeded shuffle of the bucket.
//! - **NBV** (NBV-Net): a group = the valid cases of one start view's rollout. Shuffle the start
//!   views; add whole groups while the running count is below the long-tail total, a group only
//!   if that brings the count closer to the total (or nothing is selected yet); stop at the
//!   first group that would overshoot more.
//!
//! Cases are returned as `(rollout index, step index)`, sorted.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

use crate::rollout::Rollout;

/// The reference's `longtail_need_case_1`.
pub const NEED_CASE_1: usize = 64;

/// The case-sampling protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    /// Long-tail multiview sampling (MA-SCVP).
    LongTail,
    /// Whole oracle rollouts from random start views (NBV-Net).
    Nbv,
}

/// The long-tail quotas: `m → need_m` over the valid cases of `rollouts`.
pub fn longtail_quota(rollouts: &[Rollout], need_case_1: usize) -> BTreeMap<usize, usize> {
    let mut buckets: BTreeMap<usize, (usize, f64)> = BTreeMap::new();
    for r in rollouts {
        for s in r.steps.iter().filter(|s| s.is_valid()) {
            let e = buckets.entry(s.m()).or_insert((0, 0.0));
            e.0 += 1;
            e.1 += s.best_gain as f64;
        }
    }
    let g = |m: usize| buckets.get(&m).map_or(0.0, |&(n, sum)| sum / n as f64);
    let base = if g(1) > 0.0 { g(1) } else { 1.0 };
    buckets
        .iter()
        .map(|(&m, &(n, _))| {
            let need = (need_case_1 as f64 * g(m) / base).ceil().max(0.0) as usize;
            (m, need.min(n))
        })
        .collect()
}

/// The kept cases of one object under `protocol`, with the RNG seeded by `seed`.
pub fn sample(
    rollouts: &[Rollout],
    protocol: Protocol,
    need_case_1: usize,
    seed: u64,
) -> Vec<(usize, usize)> {
    let quota = longtail_quota(rollouts, need_case_1);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut kept = match protocol {
        Protocol::LongTail => {
            let mut buckets: BTreeMap<usize, Vec<(usize, usize)>> = BTreeMap::new();
            for (ri, r) in rollouts.iter().enumerate() {
                for (si, s) in r.steps.iter().enumerate().filter(|(_, s)| s.is_valid()) {
                    buckets.entry(s.m()).or_default().push((ri, si));
                }
            }
            let mut kept = Vec::new();
            for (m, mut cases) in buckets {
                cases.shuffle(&mut rng);
                kept.extend(cases.into_iter().take(quota[&m]));
            }
            kept
        }
        Protocol::Nbv => {
            let total: usize = quota.values().sum();
            let mut order: Vec<usize> = (0..rollouts.len()).collect();
            order.shuffle(&mut rng);
            let mut kept: Vec<(usize, usize)> = Vec::new();
            for ri in order {
                if kept.len() >= total {
                    break;
                }
                let group: Vec<(usize, usize)> = rollouts[ri]
                    .steps
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| s.is_valid())
                    .map(|(si, _)| (ri, si))
                    .collect();
                let now = kept.len().abs_diff(total);
                let after = (kept.len() + group.len()).abs_diff(total);
                if kept.is_empty() || after < now {
                    kept.extend(group);
                } else {
                    break;
                }
            }
            kept
        }
    };
    kept.sort_unstable();
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rollout::Step;

    /// A synthetic rollout whose valid steps have the given gains (m = 1, 2, …) followed by
    /// one invalid final step.
    fn rollout(start: usize, gains: &[u32]) -> Rollout {
        let mut steps: Vec<Step> = gains
            .iter()
            .enumerate()
            .map(|(k, &g)| Step {
                visited: (0..=k).collect(),
                covered: 0,
                gains: vec![],
                nbv: Some(k + 1),
                best_gain: g,
            })
            .collect();
        steps.push(Step {
            visited: (0..=gains.len()).collect(),
            covered: 0,
            gains: vec![],
            nbv: None,
            best_gain: 0,
        });
        Rollout { start, steps }
    }

    /// 128 rollouts with gains 100, 50, 25, 10 at m = 1..4: quotas ceil(64·g_m/100) =
    /// 64, 32, 16, 7; the long-tail draw keeps exactly that many per bucket, distinct, valid.
    #[test]
    fn longtail_counts_follow_the_rule() {
        let rs: Vec<Rollout> = (0..128).map(|s| rollout(s, &[100, 50, 25, 10])).collect();
        let q = longtail_quota(&rs, NEED_CASE_1);
        assert_eq!(q.into_iter().collect::<Vec<_>>(), vec![(1, 64), (2, 32), (3, 16), (4, 7)]);
        let kept = sample(&rs, Protocol::LongTail, NEED_CASE_1, 9);
        assert_eq!(kept.len(), 64 + 32 + 16 + 7);
        let mut per_m = BTreeMap::new();
        for &(r, s) in &kept {
            assert!(rs[r].steps[s].is_valid());
            *per_m.entry(rs[r].steps[s].m()).or_insert(0) += 1;
        }
        assert_eq!(per_m.into_values().collect::<Vec<_>>(), vec![64, 32, 16, 7]);
        let mut d = kept.clone();
        d.dedup();
        assert_eq!(d.len(), kept.len());
        assert_eq!(kept, sample(&rs, Protocol::LongTail, NEED_CASE_1, 9), "seeded");
        assert_ne!(kept, sample(&rs, Protocol::LongTail, NEED_CASE_1, 10));
    }

    /// Mean gains per bucket (not sums) decide the quota; g_1 ≤ 0 means base 1; quotas are
    /// clipped to the bucket size.
    #[test]
    fn quotas_use_means_and_clip() {
        let rs = vec![rollout(0, &[10, 40]), rollout(1, &[30, 0])];
        // Bucket 1: gains 10, 30 → mean 20; bucket 2: only the valid step (gain 40), mean 40.
        let q = longtail_quota(&rs, 64);
        assert_eq!(q[&1], 2, "ceil(64) clipped to 2 cases");
        assert_eq!(q[&2], 1);
    }

    /// NBV protocol: whole groups; the total is the long-tail total (119); groups of 4 valid
    /// cases: 29 groups = 116 (|116 − 119| = 3), a 30th would give 120 (|1| < 3) so it is
    /// added, then the count is 120 ≥ 119 and the loop stops.
    #[test]
    fn nbv_protocol_takes_whole_groups_up_to_the_total() {
        let rs: Vec<Rollout> = (0..128).map(|s| rollout(s, &[100, 50, 25, 10])).collect();
        let kept = sample(&rs, Protocol::Nbv, NEED_CASE_1, 3);
        assert_eq!(kept.len(), 120);
        let mut groups: BTreeMap<usize, usize> = BTreeMap::new();
        for &(r, _) in &kept {
            *groups.entry(r).or_insert(0) += 1;
        }
        assert_eq!(groups.len(), 30);
        assert!(groups.values().all(|&n| n == 4), "whole groups only");
        // Groups of 6 against a total of 8: the first group (6) is taken; a second (12) is
        // farther from 8 than 6 is (4 > 2), so it stops there.
        let rs: Vec<Rollout> = (0..3).map(|s| rollout(s, &[10, 10, 10, 10, 10, 10])).collect();
        let q: usize = longtail_quota(&rs, 2).values().sum();
        assert_eq!(q, 12);
        let kept = sample(&rs, Protocol::Nbv, 2, 1);
        assert_eq!(kept.len(), 12, "two groups of 6 meet the total of 12 exactly");
        let kept = sample(&rs, Protocol::Nbv, 1, 1);
        assert_eq!(longtail_quota(&rs, 1).values().sum::<usize>(), 6);
        assert_eq!(kept.len(), 6);
    }
}
