//! The episode set-up shared by local runs (`objview run`) and the server: the settings record
//! that every result line carries. Both build it here, so that a remote episode and a local one
//! with the same planner, object, view space, budget, seed and settings write identical lines
//! (wall-clock times aside).

use objview_episode::{Budget, EpisodeSettings};
use objview_geom::normalize::Normalization;
use objview_geom::Pose;
use objview_views::ViewSpace;
use serde_json::{json, Value};

pub use crate::provenance::VERSION;

/// What identifies a run in its result lines' `settings` field.
#[derive(Debug, Clone)]
pub struct RunRecord<'a> {
    /// The planner (method) name.
    pub planner: &'a str,
    /// Its parameters (for the server: the create request's `params`).
    pub planner_params: Value,
    /// The view-space name results record (`whole`, a rule file's name).
    pub view_space: &'a str,
    /// The view space itself (its rules are recorded).
    pub space: &'a ViewSpace,
    /// The budget protocol.
    pub budget: Budget,
    /// The user seed (before the per-episode mix).
    pub seed: u64,
    /// The candidate set's name (`tammes-360`, a file).
    pub candidates: &'a str,
    /// How many candidate poses it has.
    pub candidate_count: usize,
    /// The start pose (object frame, normalized units, roll in radians).
    pub start_pose: Pose,
    /// How meshes were normalized.
    pub normalize: Normalization,
    /// Every episode constant.
    pub settings: &'a EpisodeSettings,
}

impl RunRecord<'_> {
    /// The `settings` object of a result line: `{"tool", "version", "command": "run", …}`.
    pub fn to_json(&self) -> Value {
        let settings = serde_json::to_value(self.settings).unwrap_or(Value::Null);
        json!({
            "tool": "objview",
            "version": VERSION,
            "command": "run",
            "planner": self.planner,
            "planner_params": self.planner_params,
            "view_space": self.view_space,
            "view_space_rules": format!("{:?}", self.space),
            "budget": self.budget.label(),
            "seed": self.seed,
            "candidates": self.candidates,
            "candidate_count": self.candidate_count,
            "start_pose": self.start_pose.to_array(),
            "normalize": self.normalize.to_string(),
            "episode": settings,
            "intrinsics": {"width": 512, "height": 512, "fov_deg": 45.0},
        })
    }
}
