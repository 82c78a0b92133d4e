//! The hybrid planners of issue 19: point-cloud completion + a classical planning step
//! (paper: PoinTr-C+NBV, PoinTr-C+SCP, PoinTr-C+MCP; the reference's behaviour is written up in
//! `shared/research/learned-baselines.md` §5–§8).
//!
//! - [`completion`]: the completion interface ([`completion::Completion`]) and its service
//!   contract, with the `identity` (lower bound) and `oracle` (ground truth, upper bound,
//!   diagnostic) backends; the learned `net` backend comes from `objview-learn` (it needs Burn),
//!   handed in as a [`NetBackend`] constructor by that crate's own hybrid rows
//!   ([`build_hybrid`]).
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
mod coverage_search;
pub mod hpr;
pub mod nbv;
pub mod plan;
pub mod steps;
mod swap_search;

use objview_episode::{ExecutionMode, Family};
use serde::{Deserialize, Serialize};

use crate::registry::{settings_from, settings_json, PlannerEntry};
use completion::Completion;
use plan::{CompletionPlan, PlanKind};

/// Mixed into the episode seed for the completion's resampling RNG.
pub const COMPLETION_SEED_SALT: u64 = 0x636f_6d70_6c65_7465; // "complete"

/// The default backend of this crate's rows, which cannot build `net` (no Burn here);
/// `objview-learn`'s hybrid rows, which can, default to `net` (see the README, "Hybrid
/// planners").
pub const DEFAULT_COMPLETION: &str = "identity";

/// The constructor of the learned `net` backend, provided by the crate that has it
/// (`objview_learn::completion_backend::net_backend`): the backend for these settings (their
/// `completion_weights`), or an error naming the weights.
pub type NetBackend = fn(&HybridSettings) -> Result<Box<dyn Completion>, String>;

/// Settings of the three hybrid planners.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridSettings {
    /// Completion backend: `net` (the learned network; only where its constructor is linked),
    /// `oracle` (ground truth; diagnostic upper bound), `identity` (no completion; lower bound).
    pub completion: String,
    /// The `net` backend's weights: `builtin` (the shipped ones) or a `.safetensors` file of
    /// `objview learn train completion` (with its sidecar). Only `net` reads it.
    #[serde(default = "builtin_weights")]
    pub completion_weights: String,
    /// Wall-clock limit of the SCP/MCP ILPs, seconds (the reference's 10).
    pub ilp_time_limit_s: f64,
    /// NBV: candidates within this fraction of the best gain are eligible (0.95).
    pub gain_ratio: f64,
}

fn builtin_weights() -> String {
    "builtin".into()
}

impl Default for HybridSettings {
    fn default() -> Self {
        HybridSettings {
            completion: DEFAULT_COMPLETION.into(),
            completion_weights: builtin_weights(),
            ilp_time_limit_s: cover::DEFAULT_ILP_TIME_LIMIT_S,
            gain_ratio: nbv::DEFAULT_GAIN_RATIO,
        }
    }
}

impl HybridSettings {
    /// The backend named by `completion` (an error for `net` and unknown names), after
    /// checking the numbers.
    pub fn backend(&self) -> Result<Box<dyn Completion>, String> {
        self.backend_with(None)
    }

    /// The backend named by `completion`, `net` built by `net` when given (else refused, as an
    /// unknown name is), after checking the numbers. `completion_weights` other than `builtin`
    /// is an error for a backend that does not read it.
    pub fn backend_with(&self, net: Option<NetBackend>) -> Result<Box<dyn Completion>, String> {
        if self.ilp_time_limit_s.is_nan() || self.ilp_time_limit_s <= 0.0 {
            return Err(format!("ilp_time_limit_s must be positive, got {}", self.ilp_time_limit_s));
        }
        if self.gain_ratio.is_nan() || self.gain_ratio <= 0.0 || self.gain_ratio > 1.0 {
            return Err(format!("gain_ratio must be in (0, 1], got {}", self.gain_ratio));
        }
        if self.completion != "net" && self.completion_weights != "builtin" {
            return Err(format!(
                "completion_weights is read by completion=net only (completion is {:?})",
                self.completion
            ));
        }
        match (self.completion.as_str(), net) {
            ("net", Some(build)) => build(self),
            _ => completion::backend(&self.completion).map_err(|e| e.to_string()),
        }
    }
}

/// Adds the backend's description (`completion_model`) to a planner's recorded parameters
/// when it has one (the net's weights and shape; nothing for `identity` and `oracle`).
pub(crate) fn describe_backend(params: &mut serde_json::Value, backend: &dyn Completion) {
    let d = backend.describe();
    if !d.is_null() {
        params["completion_model"] = d;
    }
}

/// A hybrid planner (`completion-nbv`, `completion-scp` or `completion-mcp`) from `settings`
/// JSON (`None`: `defaults()`), with the `net` backend built by `net` when given. This crate's
/// rows pass `None`; `objview-learn`'s hybrid rows pass their constructor and default to `net`.
pub fn build_hybrid(
    name: &str,
    settings: Option<serde_json::Value>,
    defaults: fn() -> HybridSettings,
    net: Option<NetBackend>,
) -> Result<Box<dyn objview_episode::Planner>, String> {
    let s = settings_from(name, settings, defaults)?;
    let err = |e: String| format!("planner {name}: {e}");
    Ok(match name {
        "completion-nbv" => Box::new(nbv::CompletionNbv::with_net(s, net).map_err(err)?),
        "completion-scp" => Box::new(CompletionPlan::with_net(PlanKind::SetCover, s, net).map_err(err)?),
        "completion-mcp" => Box::new(CompletionPlan::with_net(PlanKind::MaxCoverage, s, net).map_err(err)?),
        other => return Err(format!("{other:?} is not a hybrid planner")),
    })
}

/// The registry row of `completion-nbv`.
pub const NBV_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-nbv",
    family: Family::Hybrid,
    mode: ExecutionMode::Iterative,
    summary: "completion (completion=net|oracle|identity) + next best view by hidden point removal",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| build_hybrid("completion-nbv", s, HybridSettings::default, None),
};

/// The registry row of `completion-scp`.
pub const SCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-scp",
    family: Family::Hybrid,
    mode: ExecutionMode::SetCoverPlan,
    summary: "completion (completion=net|oracle|identity) + exact set cover of the predicted unseen voxels",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| build_hybrid("completion-scp", s, HybridSettings::default, None),
};

/// The registry row of `completion-mcp`.
pub const MCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-mcp",
    family: Family::Hybrid,
    mode: ExecutionMode::BudgetedPlan,
    summary: "completion (completion=net|oracle|identity) + exact max coverage with K-1 views",
    defaults: || settings_json(&HybridSettings::default()),
    build: |s| build_hybrid("completion-mcp", s, HybridSettings::default, None),
};
