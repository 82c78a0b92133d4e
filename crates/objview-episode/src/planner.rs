//! The planner interface of SPEC §5. A planner never sees the object: it receives observations
//! (depth, optional RGB, the pose it was taken from, the intrinsics) and may ask the environment
//! whether poses are feasible in the episode's view space; it answers with an [`Action`].
//!
//! Frames and units: every pose is a 7-number [`Pose`] in the object frame (normalized object
//! units, roll in radians); depth is camera-frame z in the same units, 0 where nothing was hit.
//!
//! The names planners declare and use (family, execution mode, budget, stop reason) are defined
//! in [`crate::vocab`].

use std::sync::Arc;

use objview_geom::hash::{splitmix64, Fnv};
use objview_geom::{Mesh, Pose};
use objview_render::Intrinsics;
use serde::{Deserialize, Serialize};

use crate::vocab::{Budget, ExecutionMode, Family, StopReason};

/// What a planner answers. It is kept *raw* (seven numbers, a reason string) because remote
/// planners send exactly that: the environment validates it (finite numbers, centre and look-at
/// within [`crate::MAX_POSE_DISTANCE`] of the origin, centre ≠ look-at, a known reason, a
/// feasible pose; see [`crate::validate`]) and ends the episode with `invalid_action` otherwise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Action {
    /// Move the camera to `[cx, cy, cz, lx, ly, lz, roll]` (object frame, radians) and observe.
    Move {
        /// The pose, raw.
        pose: [f64; 7],
    },
    /// End the episode with `reason` (one of [`StopReason`]'s wire names).
    Stop {
        /// The reason, raw.
        reason: String,
    },
}

impl Action {
    /// `Move` to a pose.
    pub fn move_to(pose: &Pose) -> Action {
        Action::Move { pose: pose.to_array() }
    }

    /// `Stop` with a valid reason.
    pub fn stop(reason: StopReason) -> Action {
        Action::Stop { reason: reason.as_str().to_string() }
    }
}

/// One observation handed to the planner.
#[derive(Debug, Clone)]
pub struct Observation {
    /// 0 for the start view, then 1, 2, … (the number of planner moves so far).
    pub step: usize,
    /// The pose it was taken from.
    pub pose: Pose,
    /// The camera intrinsics (SPEC §2).
    pub intrinsics: Intrinsics,
    /// Camera-frame z per pixel, row-major (`v · width + u`), 0.0 where nothing was hit.
    pub depth: Arc<Vec<f32>>,
    /// RGB per pixel (same layout), when the episode renders colour.
    pub rgb: Option<Arc<Vec<[u8; 3]>>>,
}

/// Ground-truth access for oracle planners only (see [`Planner::needs_ground_truth`]).
#[derive(Debug, Clone)]
pub struct OracleAccess {
    /// The hidden (normalized) mesh.
    pub mesh: Arc<Mesh>,
    /// The observable reference cloud of (object, view space) (SPEC §5), in the environment's
    /// order: point i is bit i of [`Environment::oracle_covered`].
    pub reference: Arc<Vec<[f64; 3]>>,
    /// The same points with the environment's spatial index (for coverage queries such as
    /// [`crate::chamfer::Targets::mark_within`], whose bit order is this order).
    pub reference_targets: Arc<crate::chamfer::Targets>,
}

/// What a planner learns when an episode starts.
#[derive(Debug, Clone)]
pub struct EpisodeContext {
    /// The episode's seed, already mixed with the object, view space and budget
    /// (see [`episode_seed`]): a planner's random choices use it and nothing else.
    pub seed: u64,
    /// The object's opaque id (for logs; planners must not use it to look anything up).
    pub object_id: String,
    /// View-space name (`whole`, `quarter`, a file stem).
    pub view_space: String,
    /// The budget protocol.
    pub budget: Budget,
    /// The candidate poses the planner should choose from (e.g. tammes-360 at radius 3).
    pub candidates: Arc<Vec<Pose>>,
    /// Name of the candidate set (`tammes-360`, a file path).
    pub candidate_set: String,
    /// The start pose (the first observation is taken there).
    pub start_pose: Pose,
    /// Camera intrinsics.
    pub intrinsics: Intrinsics,
    /// Ground truth, present only when the planner asked for it.
    pub oracle: Option<OracleAccess>,
}

/// The environment as a planner sees it: feasibility queries and its own history.
pub trait Environment {
    /// Whether `pose` is feasible in the episode's view space (a pose beyond
    /// [`crate::MAX_POSE_DISTANCE`] never is).
    fn is_feasible(&self, pose: &Pose) -> bool;
    /// [`Environment::is_feasible`] for each pose, in order.
    fn feasible_mask(&self, poses: &[Pose]) -> Vec<bool> {
        poses.iter().map(|p| self.is_feasible(p)).collect()
    }
    /// Poses executed so far, start pose first.
    fn history(&self) -> &[Pose];
    /// For oracle planners (who may read the object): for each reference point, whether the
    /// current fused cloud covers it at τ = 0.01. `None` for everyone else.
    fn oracle_covered(&self) -> Option<&[bool]> {
        None
    }
}

/// A planner's own failure (ends the episode with the `exception` terminal source).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct PlannerError(pub String);

/// A view planner. One instance plays one episode at a time: [`Planner::reset`] starts an
/// episode, then [`Planner::act`] is called once per observation (the start view first) until
/// it stops or the environment ends the episode. The time spent inside `reset` and `act` is
/// the episode's planning runtime (PR), measured by the environment.
pub trait Planner: Send {
    /// Method name as it appears in results (`rse`, `random-tsp`, …).
    fn name(&self) -> &str;
    /// Its family.
    fn family(&self) -> Family;
    /// Its execution mode.
    fn execution_mode(&self) -> ExecutionMode;
    /// Its parameters, recorded in every result line.
    fn params(&self) -> serde_json::Value;
    /// Whether it reads ground truth (only the oracle): then [`EpisodeContext::oracle`] is set.
    fn needs_ground_truth(&self) -> bool {
        false
    }
    /// Starts an episode.
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError>;
    /// The next action after observation `obs`.
    fn act(&mut self, obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError>;
    /// What the planner decided in this episode that a reader of its results needs to judge
    /// them — an exact solver's status, proven bound and gap (a solve stopped by its time
    /// limit is never reported optimal), the sizes it planned on — written as the result's
    /// `planner_notes` (absent when `None`). Read once, after the episode ended. It must be
    /// a function of the episode alone (no wall-clock seconds: `--no-timings` results are
    /// byte-identical across runs), and every number in it finite.
    fn notes(&self) -> Option<serde_json::Value> {
        None
    }
}

/// The notes of `planner` as a result line records them: read once, after the episode; a
/// `notes()` that panics counts as none (the episode's result is not lost to it). Local and
/// remote runs both read them here, so their lines agree byte for byte.
pub fn read_notes(planner: &dyn Planner) -> Option<serde_json::Value> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| planner.notes())).ok().flatten()
}

/// `{"plan": info}` without wall-clock fields ([`without_seconds`]) — the [`Planner::notes`]
/// of a planner that records one plan per episode; `None` before a plan was made.
pub fn plan_notes<T: serde::Serialize>(info: Option<&T>) -> Option<serde_json::Value> {
    let plan = serde_json::to_value(info?).ok()?;
    Some(without_seconds(serde_json::json!({ "plan": plan })))
}

/// `value` without its wall-clock fields: every object key named `seconds` or ending in
/// `_seconds`, at any depth. For [`Planner::notes`] built from a planner's own records.
pub fn without_seconds(value: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match value {
        Value::Object(m) => Value::Object(
            m.into_iter()
                .filter(|(k, _)| k != "seconds" && !k.ends_with("_seconds"))
                .map(|(k, v)| (k, without_seconds(v)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.into_iter().map(without_seconds).collect()),
        other => other,
    }
}

/// The per-episode seed of SPEC §5: a 64-bit mix (FNV-1a, then SplitMix64) of the user seed,
/// the object id, the view-space name and the budget label, so that every (object, space,
/// budget) gets its own reproducible stream.
pub fn episode_seed(seed: u64, object_id: &str, view_space: &str, budget: Budget) -> u64 {
    let mut h = Fnv::default();
    for field in
        [&seed.to_le_bytes()[..], object_id.as_bytes(), view_space.as_bytes(), budget.to_string().as_bytes()]
    {
        h.eat(field);
        h.eat(&[0xff]); // field separator: ("ab", "c") ≠ ("a", "bc")
    }
    splitmix64(h.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vocab::{ExecutionMode, Family};

    /// A planner that only has notes: `Some(value)`, or a panic when `None`.
    struct Noted(Option<serde_json::Value>);
    impl Planner for Noted {
        fn name(&self) -> &str {
            "noted"
        }
        fn family(&self) -> Family {
            Family::Baseline
        }
        fn execution_mode(&self) -> ExecutionMode {
            ExecutionMode::Iterative
        }
        fn params(&self) -> serde_json::Value {
            serde_json::json!({})
        }
        fn reset(&mut self, _: &EpisodeContext, _: &dyn Environment) -> Result<(), PlannerError> {
            Ok(())
        }
        fn act(&mut self, _: &Observation, _: &dyn Environment) -> Result<Action, PlannerError> {
            Err(PlannerError("not played".into()))
        }
        fn notes(&self) -> Option<serde_json::Value> {
            Some(self.0.clone().expect("notes that panic"))
        }
    }

    #[test]
    fn notes_are_read_once_and_a_panic_counts_as_none() {
        let v = serde_json::json!({"plan": {"status": "optimal"}});
        assert_eq!(read_notes(&Noted(Some(v.clone()))), Some(v));
        assert_eq!(read_notes(&Noted(None)), None);
    }

    #[test]
    fn plan_notes_wrap_the_plan_without_its_seconds() {
        #[derive(serde::Serialize)]
        struct Info {
            status: &'static str,
            plan_seconds: f64,
            chosen: Vec<usize>,
        }
        let info = Info { status: "time_limit", plan_seconds: 1.25, chosen: vec![3, 1] };
        assert_eq!(
            plan_notes(Some(&info)),
            Some(serde_json::json!({"plan": {"status": "time_limit", "chosen": [3, 1]}}))
        );
        assert_eq!(plan_notes::<Info>(None), None);
    }

    #[test]
    fn without_seconds_drops_every_wall_clock_field_at_any_depth() {
        let v = serde_json::json!({
            "status": "optimal", "seconds": 1.5, "plan_seconds": 2.0,
            "selection": {"gap": 0.0, "seconds": 0.1, "seconds_left": 3},
            "paths": [{"solve_seconds": 0.2, "length": 4.0}]
        });
        assert_eq!(
            without_seconds(v),
            serde_json::json!({
                "status": "optimal",
                "selection": {"gap": 0.0, "seconds_left": 3},
                "paths": [{"length": 4.0}]
            })
        );
    }

    #[test]
    fn stop_reasons_round_trip() {
        for r in StopReason::ALL {
            assert_eq!(StopReason::parse(r.as_str()), Some(r));
        }
        assert_eq!(StopReason::parse("done"), None);
        let a = Action::stop(StopReason::PlanEnd);
        assert_eq!(serde_json::to_string(&a).unwrap(), r#"{"type":"stop","reason":"plan_end"}"#);
    }

    #[test]
    fn episode_seeds_differ_by_every_input() {
        let s = episode_seed(0, "mug", "whole", Budget::Fixed(5));
        assert_eq!(s, episode_seed(0, "mug", "whole", Budget::Fixed(5)));
        assert_ne!(s, episode_seed(1, "mug", "whole", Budget::Fixed(5)));
        assert_ne!(s, episode_seed(0, "cup", "whole", Budget::Fixed(5)));
        assert_ne!(s, episode_seed(0, "mug", "quarter", Budget::Fixed(5)));
        assert_ne!(s, episode_seed(0, "mug", "whole", Budget::Fixed(30)));
        assert_ne!(s, episode_seed(0, "mug", "whole", Budget::Auto));
        // Concatenation ambiguity: ("ab","c") vs ("a","bc").
        assert_ne!(episode_seed(0, "ab", "c", Budget::Auto), episode_seed(0, "a", "bc", Budget::Auto));
    }
}
