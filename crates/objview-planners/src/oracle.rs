//! `oracle`: greedy on the ground truth, for the slow-saturation diagnostic (paper §6.4) — the
//! only planner allowed to read the object. At every step it takes the feasible, not yet
//! visited candidate whose view would add the most observable-reference points at the
//! smallest τ (NSC@0.01 gain), ties → lowest candidate index; it keeps going while gains are 0
//! and stops with `candidate_exhausted` when every candidate was taken.
//!
//! Each candidate's coverage is precomputed on `reset` from that candidate's own fused view
//! (voxel 0.005) and kept as a bitset over the reference points; the gain is measured against
//! the environment's exact coverage of the running episode.

use std::time::Instant;

use objview_episode::fusion::frame_centroids;
use objview_episode::{
    scene_domain, Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner,
    PlannerError, StopReason,
};
use objview_geom::Pose;
use objview_render::{Camera, Frame, Renderer};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::random::same_pose;
use crate::registry::{settings_json, PlannerEntry};

/// The registry row of `oracle`; its settings are [`OracleSettings`].
pub const ENTRY: PlannerEntry = PlannerEntry {
    name: "oracle",
    family: Family::Oracle,
    mode: ExecutionMode::Iterative,
    summary: "greedy on the ground truth: the view adding the most coverage (diagnostics)",
    defaults: || settings_json(&OracleSettings::default()),
    build: |settings| {
        let settings = match settings {
            None => OracleSettings::default(),
            Some(v) => OracleSettings::from_json(&v)?,
        };
        Ok(Box::new(Oracle::new(settings)))
    },
};

/// The oracle's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OracleSettings {
    /// Coverage threshold of the gain (default 0.01).
    pub tau: f64,
    /// Fusion voxel for the per-candidate clouds (default 0.005).
    pub voxel: f64,
}

impl Default for OracleSettings {
    fn default() -> Self {
        OracleSettings { tau: 0.01, voxel: 0.005 }
    }
}

impl OracleSettings {
    /// The settings in `v` (an object with `tau` and `voxel`); both must be positive numbers.
    pub fn from_json(v: &serde_json::Value) -> Result<OracleSettings, String> {
        let tau = v["tau"].as_f64().filter(|t| *t > 0.0).ok_or("oracle tau must be a positive number")?;
        let voxel =
            v["voxel"].as_f64().filter(|t| *t > 0.0).ok_or("oracle voxel must be a positive number")?;
        Ok(OracleSettings { tau, voxel })
    }
}

/// The oracle planner.
#[derive(Debug, Clone)]
pub struct Oracle {
    /// Coverage threshold of the gain (0.01).
    pub tau: f64,
    /// Fusion voxel for the per-candidate clouds (0.005).
    pub voxel: f64,
    candidates: Vec<Pose>,
    feasible: Vec<bool>,
    covers: Vec<Vec<u64>>,
    taken: Vec<bool>,
    /// Seconds spent precomputing candidate coverage in the last reset.
    pub precompute_seconds: f64,
}

impl Oracle {
    /// An oracle with `settings`.
    pub fn new(settings: OracleSettings) -> Oracle {
        Oracle {
            tau: settings.tau,
            voxel: settings.voxel,
            candidates: Vec::new(),
            feasible: Vec::new(),
            covers: Vec::new(),
            taken: Vec::new(),
            precompute_seconds: 0.0,
        }
    }
}

impl Default for Oracle {
    fn default() -> Self {
        Oracle::new(OracleSettings::default())
    }
}

impl Planner for Oracle {
    fn name(&self) -> &str {
        "oracle"
    }
    fn family(&self) -> Family {
        Family::Oracle
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }
    fn params(&self) -> serde_json::Value {
        serde_json::json!({"gain": "observable-reference points newly within tau", "tau": self.tau, "voxel": self.voxel})
    }
    fn needs_ground_truth(&self) -> bool {
        true
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        let t = Instant::now();
        let oracle =
            ctx.oracle.as_ref().ok_or_else(|| PlannerError("the oracle needs ground-truth access".into()))?;
        self.candidates = ctx.candidates.to_vec();
        self.feasible = env.feasible_mask(&self.candidates);
        self.taken = vec![false; self.candidates.len()];
        // The environment's own index of the reference: bit i of a candidate's coverage is
        // reference point i of `env.oracle_covered()`.
        let targets = &oracle.reference_targets;
        // The per-candidate clouds are fused at the oracle's own voxel size.
        let domain = scene_domain(&oracle.mesh, &oracle.reference, self.voxel);
        let words = targets.len().div_ceil(64);
        // Candidates are independent: in parallel on the current rayon pool (each bitset is
        // the same whatever the thread).
        let feasible = &self.feasible;
        let tau = self.tau;
        self.covers = self
            .candidates
            .par_iter()
            .enumerate()
            .map_init(Renderer::new, |renderer, (i, pose)| {
                let mut bits = vec![0u64; words];
                if feasible[i] {
                    let cam = Camera::new(*pose, ctx.intrinsics);
                    let mut frame = Frame::empty(cam);
                    renderer.render_into(&oracle.mesh, &cam, &mut frame);
                    let fused = frame_centroids(&domain, &frame.observed_points());
                    targets.mark_within(&fused, tau, &mut bits);
                }
                bits
            })
            .collect();
        self.precompute_seconds = t.elapsed().as_secs_f64();
        Ok(())
    }
    fn act(&mut self, _obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        let covered =
            env.oracle_covered().ok_or_else(|| PlannerError("the oracle needs the coverage state".into()))?;
        let mut now = vec![0u64; covered.len().div_ceil(64)];
        for (j, &c) in covered.iter().enumerate() {
            if c {
                now[j / 64] |= 1 << (j % 64);
            }
        }
        let history = env.history();
        let mut best: Option<(u64, usize)> = None;
        for i in 0..self.candidates.len() {
            if !self.feasible[i] || self.taken[i] || history.iter().any(|h| same_pose(h, &self.candidates[i]))
            {
                continue;
            }
            let gain: u64 = self.covers[i].iter().zip(&now).map(|(a, b)| (a & !b).count_ones() as u64).sum();
            if best.is_none_or(|(g, _)| gain > g) {
                best = Some((gain, i));
            }
        }
        match best {
            Some((_, i)) => {
                self.taken[i] = true;
                Ok(Action::move_to(&self.candidates[i]))
            }
            None => Ok(Action::stop(StopReason::CandidateExhausted)),
        }
    }
}
