//! RSE and RSE-Mov (Delmerico et al. 2018, "A comparison of volumetric information gain metrics
//! for active 3D object reconstruction", *rear side entropy*). These are the classical
//! iterative next-best-view planners of SPEC §5, registered as `rse` and `rse-mov`.
//!
//! Each planner keeps an occupancy grid ([`crate::occupancy`]) in the **object frame**
//! (normalized object units, default 64³ voxels over [−1, 1]³), and every observation's depth
//! frame goes into it. The next view is one of the episode's candidate poses (tammes-360 at radius
//! 3): only those that are feasible in the view space and not yet visited are scored. A candidate
//! is scored by casting rays through every `stride`-th pixel centre of its camera. A ray's gain is
//! Σ visibility × entropy over the *unknown* voxels it crosses before the first occupied voxel,
//! where visibility = Π(1 − p) over the voxels before the current one. It counts only when the
//! ray ends on an occupied voxel right after unknown space, i.e. when it sees the rear side of an
//! observed surface through unexplored space. Rays that leave the grid, or that reach an occupied
//! voxel through free space, count 0. RSE moves to the argmax. RSE-Mov trades gain against travel:
//! utility = (1 − γ)·gain/Σgain − γ·cost/Σcost, with cost the Euclidean distance between camera
//! centres.
//!
//! Performance: a planning step scores up to 360 candidates × 16 384 rays through the 64³ grid,
//! too many for a plain voxel walk per ray (about 2 s on one core). Each step first condenses the
//! grid into a [`GainMap`]: per voxel, 1 − p and H(p) as f32 (all sums are f64), plus the
//! occupied shell in 4×4×4 bricks. [`GainMap::view_gain`] then works in two passes. First, it
//! splats the shell front to back into the candidate's ray grid, which gives every ray's first
//! occupied voxel and the face it enters through. Only rays that enter it from an unknown voxel
//! can count, and mid-episode those are a few dozen per view; only they are walked, skipping
//! through uniform boxes when there are many. Both passes reproduce the walk's decisions
//! exactly, so the fast gain equals the plain sum over rays ([`GainMap::view_gain_plain`]) bit
//! for bit (tested). Candidates are scored in parallel (rayon), and each candidate's sum runs over
//! its rays in a fixed order, so the result does not depend on the thread count.
//!
//! Layout: `settings` (the parameters), `gain` (the [`GainMap`] and its view gain),
//! `projection` (image footprints for the splatting), `skip` (the walk through uniform boxes),
//! `select` (RSE and RSE-Mov selection rules); the planner itself is here.

mod gain;
mod projection;
mod select;
mod settings;
mod skip;
#[cfg(test)]
mod tests;

use std::sync::Arc;

use objview_episode::{
    Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use objview_render::Camera;

pub use gain::{GainMap, GainScratch};
pub use select::{select_rse, select_rse_mov};
pub use settings::{RseSettings, RseVariant};

use crate::occupancy::OccupancyGrid;
use crate::registry::{settings_from, settings_json, PlannerEntry};
use select::{distance, same_position};

/// The registry row of `rse`; its settings are [`RseSettings`] (defaults [`RseSettings::rse`]).
pub const RSE_ENTRY: PlannerEntry = PlannerEntry {
    name: "rse",
    family: Family::Classical,
    mode: ExecutionMode::Iterative,
    summary: "next best view by rear-side entropy on an occupancy grid",
    defaults: || settings_json(&RseSettings::rse()),
    build: |settings| Ok(Box::new(Rse::new(settings_from("rse", settings, RseSettings::rse)?))),
};

/// The registry row of `rse-mov`; its settings are [`RseSettings`] (defaults
/// [`RseSettings::rse_mov`]).
pub const RSE_MOV_ENTRY: PlannerEntry = PlannerEntry {
    name: "rse-mov",
    family: Family::Classical,
    mode: ExecutionMode::Iterative,
    summary: "rear-side entropy traded against travel distance (weight gamma)",
    defaults: || settings_json(&RseSettings::rse_mov()),
    build: |settings| Ok(Box::new(Rse::new(settings_from("rse-mov", settings, RseSettings::rse_mov)?))),
};

/// The per-episode state.
#[derive(Debug, Clone)]
struct Episode {
    candidates: Arc<Vec<Pose>>,
    cameras: Vec<Camera>,
    feasible: Vec<bool>,
    visited: Vec<bool>,
    grid: OccupancyGrid,
}

/// What the last planning step saw (for diagnostics and tests).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Candidate indices scored (feasible, not visited), increasing.
    pub candidates: Vec<usize>,
    /// Their gains.
    pub gains: Vec<f64>,
    /// Their travel costs from the current camera centre.
    pub costs: Vec<f64>,
    /// The chosen candidate index, if any.
    pub chosen: Option<usize>,
}

/// The RSE / RSE-Mov planner (see the module docs).
#[derive(Debug, Clone)]
pub struct Rse {
    settings: RseSettings,
    episode: Option<Episode>,
    last: StepReport,
}

impl Rse {
    /// A planner with `settings` (checked at [`Planner::reset`]).
    pub fn new(settings: RseSettings) -> Rse {
        Rse { settings, episode: None, last: StepReport::default() }
    }

    /// Its settings.
    pub fn settings(&self) -> &RseSettings {
        &self.settings
    }

    /// The occupancy grid of the current episode, if one was started.
    pub fn grid(&self) -> Option<&OccupancyGrid> {
        self.episode.as_ref().map(|e| &e.grid)
    }

    /// What the last [`Planner::act`] computed.
    pub fn last_step(&self) -> &StepReport {
        &self.last
    }
}

impl Planner for Rse {
    fn name(&self) -> &str {
        self.settings.name()
    }

    fn family(&self) -> Family {
        Family::Classical
    }

    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }

    fn params(&self) -> serde_json::Value {
        let s = &self.settings;
        let mut v = serde_json::json!({
            "stride": s.stride,
            "rays_through": "pixel centres (u + 0.5, v + 0.5), u, v = 0, stride, 2·stride, …",
            "occupancy": s.occupancy,
        });
        if s.variant == RseVariant::RseMov {
            v["gamma"] = serde_json::json!(s.gamma);
            v["cost"] = serde_json::json!("euclidean distance between camera centres");
        }
        v
    }

    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.settings.validate()?;
        let grid = OccupancyGrid::new(self.settings.occupancy)
            .map_err(|e| PlannerError(format!("{}: {e}", self.settings.name())))?;
        let candidates = ctx.candidates.clone();
        let feasible = env.feasible_mask(&candidates);
        if feasible.len() != candidates.len() {
            return Err(PlannerError(format!(
                "{}: the feasibility mask has {} entries for {} candidates",
                self.settings.name(),
                feasible.len(),
                candidates.len()
            )));
        }
        let cameras = candidates.iter().map(|p| Camera::new(*p, ctx.intrinsics)).collect();
        let visited = vec![false; candidates.len()];
        self.episode = Some(Episode { candidates, cameras, feasible, visited, grid });
        self.last = StepReport::default();
        Ok(())
    }

    fn act(&mut self, obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        let name = self.settings.name();
        let ep =
            self.episode.as_mut().ok_or_else(|| PlannerError(format!("{name}: act called before reset")))?;
        let camera = Camera::new(obs.pose, obs.intrinsics);
        ep.grid.insert_depth(&camera, &obs.depth).map_err(|e| PlannerError(format!("{name}: {e}")))?;

        // Visited: moves issued (marked when chosen) and every position the camera has been at.
        for pose in env.history().iter().chain(std::iter::once(&obs.pose)) {
            for (i, c) in ep.candidates.iter().enumerate() {
                if same_position(c.center, pose.center) {
                    ep.visited[i] = true;
                }
            }
        }
        let remaining: Vec<usize> =
            (0..ep.candidates.len()).filter(|&i| ep.feasible[i] && !ep.visited[i]).collect();
        if remaining.is_empty() {
            self.last = StepReport::default();
            return Ok(Action::stop(StopReason::CandidateExhausted));
        }

        let map = GainMap::new(&ep.grid);
        let stride = self.settings.stride;
        let cameras: Vec<Camera> = remaining.iter().map(|&i| ep.cameras[i]).collect();
        let gains = map.view_gains(&cameras, stride);
        let costs: Vec<f64> =
            remaining.iter().map(|&i| distance(obs.pose.center, ep.candidates[i].center)).collect();
        let pick = match self.settings.variant {
            RseVariant::Rse => select_rse(&gains),
            RseVariant::RseMov => select_rse_mov(&gains, &costs, self.settings.gamma),
        };
        let Some(pick) = pick else {
            return Ok(Action::stop(StopReason::CandidateExhausted));
        };
        let chosen = remaining[pick];
        ep.visited[chosen] = true;
        self.last = StepReport { candidates: remaining, gains, costs, chosen: Some(chosen) };
        Ok(Action::move_to(&ep.candidates[chosen]))
    }
}
