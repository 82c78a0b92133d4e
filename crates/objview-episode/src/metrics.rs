//! The scoring half of an environment step (SPEC §5 "Metrics"): after a view has been rendered
//! and fused, [`crate::engine::Episode`] calls these functions, in this order, to get the
//! numbers of that view's [`crate::result::Metrics`] and its MS checkpoints.
//!
//! | Metric | Definition, as computed here | SPEC § | Function |
//! |---|---|---|---|
//! | SC@τ | Fraction of ground-truth points with a fused point at d² < τ² now, over the current fused cloud (instantaneous, as the reference implementation) | §5 Metrics, SC@τ | [`sc`] ([`crate::coverage`], updated by [`update_coverage`]) |
//! | NSC@τ | The same fraction over the observable reference of (object, view space): the voxel-0.005 fused cloud of every feasible tammes-360 view ([`crate::reference`]) | §5 Metrics, NSC@τ | [`nsc`] |
//! | CD | At checkpoints only: mean nearest-neighbour d² ground truth → fused cloud of the checkpoint's view, plus mean d² fused → ground truth (units²) | §5 Metrics, CD | [`chamfer`] ([`crate::chamfer`]) |
//! | PC | Sum of shell distances ([`crate::path::pose_distance`]) between consecutive camera centres, from the start pose (normalized object units) | §5 Metrics, PC | [`path_cost`] |
//! | MS@δ | n = δ-voxels occupied by the fused cloud; growth = (n − n_prev) / max(n_prev, 1); a view is stable when growth < 0.01; MS@δ triggers at the third stable view in a row and becomes the checkpoint `MS@δ` (never a stop) | §5 MS@δ | [`add_new_voxels`], [`stabilization_step`] ([`crate::stabilization`]) |
//! | #Views | Views executed so far, the start view included | §5 Metrics, #Views | [`views`] |
//! | PR | Seconds spent inside the planner (`reset` and every `act`), summed over the episode; 0 when timings are not recorded | §5 Metrics, PR | [`planning_runtime`] |
//!
//! SPEC v3 (as the reference implementation): SC and NSC are instantaneous — a fused point is a
//! voxel centroid that drifts inside its voxel as views are added, so a point within τ at one
//! view can be just beyond τ at a later one and the fraction can drop by a few points out of
//! 10⁵–10⁶ — and CD is evaluated only where a checkpoint is recorded (`K=5`, `MS@0.02`,
//! `terminal`, …), so steps carry no `cd` ([`crate::result::StepMetrics`]).
//!
//! Per-τ values are keyed by [`tau_key`] (`"0.02"`).

use std::collections::BTreeMap;

use objview_geom::Pose;

use crate::chamfer::Targets;
use crate::coverage::Coverage;
use crate::fusion::FusedCloud;
use crate::grid::ChangedBlocks;
use crate::path::pose_distance;
use crate::stabilization::Stabilization;
use crate::vocab::{tau_key, CheckpointKey};

/// Values per τ of `taus` (in the same order), keyed by [`tau_key`].
fn by_tau(taus: &[f64], values: Vec<f64>) -> BTreeMap<String, f64> {
    taus.iter().zip(values).map(|(&t, x)| (tau_key(t), x)).collect()
}

/// Updates the instantaneous coverage of the ground truth (`gt`: SC) and of the observable
/// reference (`reference`: NSC) after an insertion into `fused` changed the slots grouped in
/// `groups`; the two are independent and updated concurrently on the rayon pool.
pub fn update_coverage(
    gt: &mut Coverage,
    reference: &mut Coverage,
    fused: &FusedCloud,
    groups: &ChangedBlocks,
) {
    rayon::join(|| gt.update(fused, groups), || reference.update(fused, groups));
}

/// Adds the fine voxels of the fused points created by the latest insertion (its last
/// `new_slots` slots) to every MS@δ tracker.
pub fn add_new_voxels(ms: &mut [Stabilization], fused: &FusedCloud, new_slots: usize) {
    let first_new = fused.len() - new_slots;
    for m in ms {
        m.add_fine_keys(fused.key[first_new..].iter().copied());
    }
}

/// PC after moving from `previous` (none for the start view) to `next`: `total` plus the shell
/// distance between their camera centres.
pub fn path_cost(total: f64, previous: Option<&Pose>, next: &Pose) -> f64 {
    match previous {
        Some(prev) => total + pose_distance(prev, next),
        None => total,
    }
}

/// #Views: the executed views (`history`, start view included).
pub fn views(history: &[Pose]) -> usize {
    history.len()
}

/// PR after the planner spent `seconds` more: `total + seconds`, or `total` when timings are
/// not recorded (PR is then 0 throughout, and results are byte-reproducible).
pub fn planning_runtime(total: f64, seconds: f64, record_timings: bool) -> f64 {
    if record_timings {
        total + seconds
    } else {
        total
    }
}

/// SC@τ for each τ of `taus` (the list `gt` was built with): the ground truth's coverage now.
pub fn sc(gt: &Coverage, taus: &[f64]) -> BTreeMap<String, f64> {
    by_tau(taus, gt.fractions())
}

/// NSC@τ for each τ of `taus` (the list `reference` was built with): the observable
/// reference's coverage now.
pub fn nsc(reference: &Coverage, taus: &[f64]) -> BTreeMap<String, f64> {
    by_tau(taus, reference.fractions())
}

/// CD over the current fused cloud (at a checkpoint): brings the exact nearest distances of the
/// ground truth (`gt`) and of every fused slot (`slot_gt_d2`) up to date with the slots changed
/// since `fused` epoch `*seen` (then sets `*seen` to the current epoch), and returns the mean
/// GT → fused d² plus the mean fused → GT d²; ∞ while `fused` is empty.
pub fn chamfer(gt: &mut Targets, slot_gt_d2: &mut Vec<f64>, fused: &FusedCloud, seen: &mut u32) -> f64 {
    let changed = fused.changed_since(*seen);
    *seen = fused.epoch();
    if !changed.is_empty() {
        let to_gt = gt.update(fused, &changed);
        slot_gt_d2.resize(fused.len(), 0.0);
        for (&s, d) in changed.iter().zip(to_gt) {
            slot_gt_d2[s as usize] = d;
        }
    }
    if fused.is_empty() {
        return f64::INFINITY;
    }
    gt.mean_d2() + slot_gt_d2.iter().sum::<f64>() / fused.len() as f64
}

/// Ends view `step` for every MS@δ tracker (after [`add_new_voxels`]): the δ-voxel count per δ
/// (keyed by [`tau_key`], the step's `ms_voxels`) and the `MS@δ` checkpoints that trigger at
/// this view.
pub fn stabilization_step(
    ms: &mut [Stabilization],
    step: usize,
) -> (BTreeMap<String, usize>, Vec<CheckpointKey>) {
    let mut ms_voxels = BTreeMap::new();
    let mut triggered = Vec::new();
    for m in ms {
        ms_voxels.insert(tau_key(m.delta), m.count());
        if m.end_step(step) {
            triggered.push(CheckpointKey::Stabilized(m.delta));
        }
    }
    (ms_voxels, triggered)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_cost_starts_at_zero_and_adds_shell_distances() {
        let a = Pose::from_array([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        let b = Pose::from_array([0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(path_cost(0.0, None, &a), 0.0);
        assert_eq!(path_cost(1.5, Some(&a), &b), 1.5 + pose_distance(&a, &b));
        assert_eq!(views(&[a, b]), 2);
    }

    #[test]
    fn planning_runtime_adds_only_when_timings_are_recorded() {
        assert_eq!(planning_runtime(1.0, 0.5, true), 1.5);
        assert_eq!(planning_runtime(1.0, 0.5, false), 1.0);
    }

    #[test]
    fn stabilization_names_the_checkpoints_that_trigger() {
        let mut ms = vec![Stabilization::new(0.02, 0.005, 0.01, 1)];
        let (counts, triggered) = stabilization_step(&mut ms, 0);
        assert_eq!((counts["0.02"], triggered.len()), (0, 0));
        // Second view with no growth: stable once, which triggers with one stable step needed.
        let (_, triggered) = stabilization_step(&mut ms, 1);
        assert_eq!(triggered, [CheckpointKey::Stabilized(0.02)]);
        assert_eq!(triggered[0].to_string(), "MS@0.02");
    }
}
