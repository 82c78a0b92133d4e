//! The hybrid planners of issue 19: point-cloud completion + a classical planning step
//! (paper: PoinTr-C+NBV, PoinTr-C+SCP, PoinTr-C+MCP; the reference's behaviour is written up in
//! `shared/research/learned-baselines.md` §5–§8).
//!
//! - [`completion`]: the completion interface ([`completion::Completion`]) and its service
//!   contract, with the `identity` (lower bound) and `oracle` (ground truth, upper bound,
//!   diagnostic) backends; the learned `net` backend is to come from `objview-learn`.
//! - [`steps`]: the exact shared steps (partial cloud, outlier removal, voxelization, target
//!   and occluders, candidate covers by the `inverse` ray rule of `objview-voxel`).
//! - [`cover`]: exact set cover and max coverage (HiGHS), farthest-point fill.
//! - [`plan`]: `completion-scp` and `completion-mcp`.
//! - [`hpr`]: hidden point removal on an exact-index convex hull.
//! - [`nbv`]: `completion-nbv` (next best view by hidden point removal).
//!
//! Why a module of its own: the three planners share everything but the last step, and the
//! completion backend is a parameter (`completion=net|oracle|identity`) whose value is part of
//! the method name in results (`completion-scp[oracle]`), so bounds are never read as the
//! method.

pub mod completion;
pub mod cover;
pub mod hpr;
pub mod nbv;
pub mod plan;
pub mod steps;

use objview_episode::{ExecutionMode, Family};
use serde::{Deserialize, Serialize};

use crate::registry::{settings_from, settings_json, PlannerEntry};
use completion::Completion;
use plan::{CompletionPlan, PlanKind};

/// Mixed into the episode seed for the completion's resampling RNG.
pub const COMPLETION_SEED_SALT: u64 = 0x636f_6d70_6c65_7465; // "complete"

/// The default backend while the learned one is missing (see the README, "Hybrid planners").
pub const DEFAULT_COMPLETION: &str = "identity";

/// Settings of the three hybrid planners.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridSettings {
    /// Completion backend: `net` (not available yet), `oracle` (ground truth; diagnostic upper
    /// bound), `identity` (no completion; lower bound).
    pub completion: String,
    /// Wall-clock limit of the SCP/MCP ILPs, seconds (the reference's 10).
    pub ilp_time_limit_s: f64,
    /// NBV: candidates within this fraction of the best gain are eligible (0.95).
    pub gain_ratio: f64,
}

impl Default for HybridSettings {
    fn default() -> Self {
        HybridSettings {
            completion: DEFAULT_COMPLETION.into(),
            ilp_time_limit_s: cover::DEFAULT_ILP_TIME_LIMIT_S,
            gain_ratio: nbv::DEFAULT_GAIN_RATIO,
        }
    }
}

impl HybridSettings {
    /// The backend named by `completion` (an error for `net` and unknown names), after
    /// checking the numbers.
    pub fn backend(&self) -> Result<Box<dyn Completion>, String> {
        if self.ilp_time_limit_s.is_nan() || self.ilp_time_limit_s <= 0.0 {
            return Err(format!("ilp_time_limit_s must be positive, got {}", self.ilp_time_limit_s));
        }
        if self.gain_ratio.is_nan() || self.gain_ratio <= 0.0 || self.gain_ratio > 1.0 {
            return Err(format!("gain_ratio must be in (0, 1], got {}", self.gain_ratio));
        }
        completion::backend(&self.completion).map_err(|e| e.to_string())
    }
}

fn build_plan(
    name: &str,
    kind: PlanKind,
    settings: Option<serde_json::Value>,
) -> Result<Box<dyn objview_episode::Planner>, String> {
    let s = settings_from(name, settings, HybridSettings::default)?;
    Ok(Box::new(CompletionPlan::new(kind, s).map_err(|e| format!("planner {name}: {e}"))?))
}

/// The registry row of `completion-nbv`.
pub const NBV_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-nbv",
    family: Family::Hybrid,
    mode: ExecutionMode::Iterative,
    summary: "completion (completion=net|oracle|identity) + next best view by hidden point removal",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| {
        let s = settings_from("completion-nbv", s, HybridSettings::default)?;
        Ok(Box::new(nbv::CompletionNbv::new(s).map_err(|e| format!("planner completion-nbv: {e}"))?))
    },
};

/// The registry row of `completion-scp`.
pub const SCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-scp",
    family: Family::Hybrid,
    mode: ExecutionMode::SetCoverPlan,
    summary: "completion (completion=net|oracle|identity) + exact set cover of the predicted unseen voxels",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| build_plan("completion-scp", PlanKind::SetCover, s),
};

/// The registry row of `completion-mcp`.
pub const MCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-mcp",
    family: Family::Hybrid,
    mode: ExecutionMode::BudgetedPlan,
    summary: "completion (completion=net|oracle|identity) + exact max coverage with K-1 views",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| build_plan("completion-mcp", PlanKind::MaxCoverage, s),
};
