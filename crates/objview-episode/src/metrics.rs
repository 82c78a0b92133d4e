//! The scoring half of an environment step (SPEC §5 "Metrics"): after a view has been rendered
//! and fused, [`crate::engine::Episode`] calls these functions, in this order, to get the
//! numbers of that view's [`crate::result::Metrics`] and its MS checkpoints.
//!
//! | Metric | Definition, as computed here | SPEC § | Function |
//! |---|---|---|---|
//! | SC@τ | Fraction of ground-truth points that have had a fused point at d² < τ² at this view or an earlier one (sticky coverage, see below) | §5 Metrics, SC@τ | [`sc`] |
//! | NSC@τ | The same fraction over the observable reference of (object, view space): the voxel-0.005 fused cloud of every feasible tammes-360 view ([`crate::reference`]) | §5 Metrics, NSC@τ | [`nsc`] |
//! | CD | Mean nearest-neighbour d² ground truth → current fused cloud, plus mean d² fused → ground truth; ∞ while nothing is fused (units²) | §5 Metrics, CD | [`chamfer`] (distances kept by [`update_distances`] and [`record_fused_to_gt`]) |
//! | PC | Sum of shell distances ([`crate::path::pose_distance`]) between consecutive camera centres, from the start pose (normalized object units) | §5 Metrics, PC | [`path_cost`] |
//! | MS@δ | n = δ-voxels occupied by the fused cloud; growth = (n − n_prev) / max(n_prev, 1); a view is stable when growth < 0.01; MS@δ triggers at the third stable view in a row and becomes the checkpoint `MS@δ` (never a stop) | §5 MS@δ | [`add_new_voxels`], [`stabilization_step`] ([`crate::stabilization`]) |
//! | #Views | Views executed so far, the start view included | §5 Metrics, #Views | [`views`] |
//! | PR | Seconds spent inside the planner (`reset` and every `act`), summed over the episode; 0 when timings are not recorded | §5 Metrics, PR | [`planning_runtime`] |
//!
//! Two choices the SPEC's wording leaves open, as the code makes them:
//! - SC and NSC are *sticky*: a point counts as covered once it has been within τ at some view
//!   of the episode ([`crate::coverage::Targets::coverage`]). A fused point is a voxel centroid
//!   that drifts inside its voxel as views are added, so the instantaneous fraction can drop by a
//!   few points out of 10⁵–10⁶ although the observations still cover them; sticky coverage never
//!   decreases.
//! - CD is computed after every view (the SPEC needs it at checkpoints), so every step records
//!   it and every checkpoint copies its view's value.
//!
//! Per-τ values are keyed by [`tau_key`] (`"0.02"`).

use std::collections::BTreeMap;

use objview_geom::Pose;

use crate::coverage::Targets;
use crate::fusion::FusedCloud;
use crate::path::pose_distance;
use crate::stabilization::Stabilization;
use crate::vocab::{tau_key, CheckpointKey};

/// Values per τ of `taus` (in the same order), keyed by [`tau_key`].
fn by_tau(taus: &[f64], values: Vec<f64>) -> BTreeMap<String, f64> {
    taus.iter().zip(values).map(|(&t, x)| (tau_key(t), x)).collect()
}

/// Updates the nearest-fused distances of the ground truth (`gt`: SC and CD) and of the
/// observable reference (`reference`: NSC) after `fused` changed the slots `changed`; the two
/// are independent and updated concurrently on the rayon pool (one after the other on a
/// one-thread pool). Returns, per changed slot, its d² to the nearest ground-truth point (the
/// fused → GT half of CD, for [`record_fused_to_gt`]).
pub fn update_distances(
    gt: &mut Targets,
    reference: &mut Targets,
    fused: &FusedCloud,
    changed: &[u32],
) -> Vec<f64> {
    let (to_gt, ()) = rayon::join(
        || gt.update(fused, changed),
        || {
            reference.update(fused, changed);
        },
    );
    to_gt
}

/// Keeps the fused → GT d² per fused slot (`slot_gt_d2`, grown to the `fused_len` slots): the
/// changed slots get their new distances `to_gt` from [`update_distances`].
pub fn record_fused_to_gt(slot_gt_d2: &mut Vec<f64>, fused_len: usize, changed: &[u32], to_gt: Vec<f64>) {
    slot_gt_d2.resize(fused_len, 0.0);
    for (&s, d) in changed.iter().zip(to_gt) {
        slot_gt_d2[s as usize] = d;
    }
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

/// SC@τ for each τ of `taus`: the ground truth's sticky coverage. Call once per view, after
/// [`update_distances`], always with the same τ list.
pub fn sc(gt: &mut Targets, taus: &[f64]) -> BTreeMap<String, f64> {
    by_tau(taus, gt.coverage(taus))
}

/// NSC@τ for each τ of `taus`: the observable reference's sticky coverage. Call once per view,
/// after [`update_distances`], always with the same τ list.
pub fn nsc(reference: &mut Targets, taus: &[f64]) -> BTreeMap<String, f64> {
    by_tau(taus, reference.coverage(taus))
}

/// CD over the current fused cloud: the mean GT → fused d² (`gt`) plus the mean fused → GT d²
/// (`slot_gt_d2`, one per fused slot, from [`record_fused_to_gt`]); ∞ while `fused` is empty.
pub fn chamfer(gt: &Targets, fused: &FusedCloud, slot_gt_d2: &[f64]) -> f64 {
    let fused_mean = if fused.is_empty() { 0.0 } else { slot_gt_d2.iter().sum::<f64>() / fused.len() as f64 };
    if fused.is_empty() {
        f64::INFINITY
    } else {
        gt.mean_d2() + fused_mean
    }
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
