//! `random`: a uniformly random feasible, not yet visited candidate at every step (the
//! iterative sanity baseline). Stops with `candidate_exhausted` when none is left.

use objview_episode::{
    Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::registry::{no_settings, PlannerEntry};

/// The registry row of `random` (no parameters).
pub const ENTRY: PlannerEntry = PlannerEntry {
    name: "random",
    family: Family::Baseline,
    mode: ExecutionMode::Iterative,
    summary: "a uniformly random feasible, unvisited view per step (sanity baseline)",
    defaults: no_settings,
    build: |_| Ok(Box::new(RandomPlanner::default())),
};

/// Whether two poses are the same camera placement (centre, look-at, roll within 1e-9).
pub fn same_pose(a: &Pose, b: &Pose) -> bool {
    a.to_array().iter().zip(b.to_array()).all(|(x, y)| (x - y).abs() <= 1e-9)
}

/// The random planner.
#[derive(Debug, Clone)]
pub struct RandomPlanner {
    rng: ChaCha8Rng,
    candidates: Vec<Pose>,
    left: Vec<usize>,
}

impl Default for RandomPlanner {
    fn default() -> Self {
        RandomPlanner { rng: ChaCha8Rng::seed_from_u64(0), candidates: Vec::new(), left: Vec::new() }
    }
}

impl Planner for RandomPlanner {
    fn name(&self) -> &str {
        "random"
    }
    fn family(&self) -> Family {
        Family::Baseline
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }
    fn params(&self) -> serde_json::Value {
        serde_json::json!({"rule": "uniform over feasible unvisited candidates", "rng": "ChaCha8(episode seed)"})
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.rng = ChaCha8Rng::seed_from_u64(ctx.seed);
        self.candidates = ctx.candidates.to_vec();
        let mask = env.feasible_mask(&self.candidates);
        self.left = (0..self.candidates.len()).filter(|&i| mask[i]).collect();
        Ok(())
    }
    fn act(&mut self, _obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        let history = env.history();
        let cands = &self.candidates;
        self.left.retain(|&i| !history.iter().any(|h| same_pose(h, &cands[i])));
        if self.left.is_empty() {
            return Ok(Action::stop(StopReason::CandidateExhausted));
        }
        let j = self.rng.gen_range(0..self.left.len());
        let i = self.left.remove(j);
        Ok(Action::move_to(&self.candidates[i]))
    }
}
