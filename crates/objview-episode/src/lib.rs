//! Online episodes (SPEC §5, paper §5): a planner that never sees the object asks for camera
//! poses one at a time; the environment checks feasibility, renders, fuses and scores.
//!
//! - [`planner`] — the planner interface (observations, actions, feasibility queries).
//! - [`path`] — path cost under the shell distance.
//! - [`fusion`] — incremental voxel-centroid fusion, on the sparse block grid of [`grid`].
//! - [`coverage`] — instantaneous bounded-radius coverage → SC@τ and NSC@τ of every step.
//! - [`chamfer`] — exact nearest distances → CD at checkpoints (and the observable SC).
//! - [`metrics`] — the scoring of each view: SC, NSC, PC, MS, #Views, PR, CD at checkpoints (a table of their
//!   definitions, SPEC sections and functions).
//! - [`reference`](mod@reference) — the observable reference (NSC's denominator), cached on disk.
//! - [`stabilization`] — MS@δ.
//! - [`scene`] — loading the hidden object (mesh, ground truth, reference).
//! - `scratch` — the step buffers shared by every episode of the process.
//! - [`scripted`] — a planner that plays a fixed action list (replays, tests, benchmarks).
//! - [`engine`] — the environment, checkpoints, budgets and terminal reasons.
//! - [`result`] — the JSON Lines result format; [`settings`] — every SPEC §5 constant.
//! - [`vocab`] — the names of families, execution modes, budgets, stop reasons, terminal
//!   sources and checkpoints, each with its wire string (`Display` / `FromStr`).
//! - [`validate`] — the one check of a pose from outside (bounds, finite numbers).

pub mod path;
pub mod planner;

pub use planner::{
    episode_seed, plan_notes, read_notes, without_seconds, Action, Environment, EpisodeContext, Observation,
    OracleAccess, Planner, PlannerError,
};
pub mod chamfer;
pub mod coverage;
pub mod engine;
pub mod fusion;
pub mod grid;
pub mod metrics;
mod prefetch;
pub mod reference;
pub mod result;
pub mod scene;
mod scratch;
pub mod scripted;
pub mod settings;
pub mod stabilization;
pub mod validate;
pub mod vocab;

pub use engine::{run_episode, scene_domain, Episode, FreshTargets, MethodInfo, Scene, Terminal};
pub use reference::{observable_reference, Reference};
pub use result::EpisodeResult;
pub use scene::{load_scene, scene_from_parts, SceneSource};
pub use scripted::Scripted;
pub use settings::EpisodeSettings;
pub use validate::{check_pose, check_view_pose, PoseError, MAX_POSE_DISTANCE};
pub use vocab::{ends_normally, Budget, CheckpointKey, ExecutionMode, Family, StopReason, TerminalSource};

/// Errors of episode set-up (a running episode never fails: it ends with a terminal reason).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpisodeError {
    /// The settings (or the start pose) are invalid.
    #[error("invalid episode settings: {0}")]
    Settings(String),
    /// The scene cannot be set up (a start view that sees nothing, points outside the domain).
    #[error("episode set-up: {0}")]
    Setup(String),
    /// Reading or writing a file failed: its path and the reason.
    #[error("{0}: {1}")]
    Io(String, String),
    /// A number of the result is NaN or infinite (it would be written as `null`); the field's
    /// path, e.g. `checkpoints.terminal.cd`. The result is not written.
    #[error("the result has a non-finite number at `{0}`; it is not written")]
    NonFinite(String),
}
