//! A planner that plays a fixed list of actions, then stops with `plan_end`: to replay a
//! recorded pose sequence (a result line's `visited_poses`) through the environment, and to
//! drive tests and benchmarks with known views.

use crate::planner::{Action, Environment, EpisodeContext, Observation, Planner, PlannerError};
use crate::vocab::{ExecutionMode, Family, StopReason};
use objview_geom::Pose;

/// The scripted planner (name `scripted`, family baseline).
#[derive(Debug, Clone)]
pub struct Scripted {
    actions: Vec<Action>,
    mode: ExecutionMode,
    next: usize,
}

impl Scripted {
    /// Plays `actions` in order, reporting execution mode `mode`.
    pub fn new(actions: Vec<Action>, mode: ExecutionMode) -> Scripted {
        Scripted { actions, mode, next: 0 }
    }

    /// Moves to each of `poses` in order.
    pub fn poses(poses: &[Pose], mode: ExecutionMode) -> Scripted {
        Scripted::new(poses.iter().map(Action::move_to).collect(), mode)
    }
}

impl Planner for Scripted {
    fn name(&self) -> &str {
        "scripted"
    }
    fn family(&self) -> Family {
        Family::Baseline
    }
    fn execution_mode(&self) -> ExecutionMode {
        self.mode
    }
    fn params(&self) -> serde_json::Value {
        serde_json::json!({"actions": self.actions.len()})
    }
    fn reset(&mut self, _ctx: &EpisodeContext, _env: &dyn Environment) -> Result<(), PlannerError> {
        self.next = 0;
        Ok(())
    }
    fn act(&mut self, _obs: &Observation, _env: &dyn Environment) -> Result<Action, PlannerError> {
        self.next += 1;
        Ok(self.actions.get(self.next - 1).cloned().unwrap_or(Action::stop(StopReason::PlanEnd)))
    }
}
