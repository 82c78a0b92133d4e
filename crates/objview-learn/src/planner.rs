//! The learned planners in episodes, and this crate's registry table ([`TABLE`]: `nbv-net`
//! here, `ma-scvp` in [`crate::mascvp_planner`]).
//!
//! **`nbv-net`** (family learned, iterative, Tammes-128 at the start pose's radius): every
//! observation is inserted into the 64³ input grid ([`crate::input_grid`]); the grid (pooled
//! to the network's size) goes through NBV-Net; the action is the argmax view (ties to the
//! lowest id). The reference's decision rule (learned-baselines.md §2.3), in this order, with
//! **no fallback** to the second-best view (why NBV-Net collapses under `quarter`, paper
//! Table 4):
//! 1. the view was predicted (and executed) earlier in this episode → stop `next_view_visited`;
//! 2. the view is infeasible in the episode's view space (queried once, at reset) or is the
//!    current pose → stop `next_view_infeasible`;
//! 3. otherwise move there.
//!
//! The start pose is not a Tammes-128 view, so predicting "the start view" is not caught by
//! rule 1 (as in the reference).
//!
//! Parameter `weights`: `builtin` (the shipped `data/weights/nbv-net.safetensors`, compiled
//! into the binary) or a `.safetensors` file written by `objview learn train`, whose sidecar
//! JSON (same stem) gives the grid size.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use objview_episode::{
    Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use objview_planners::random::same_pose;
use objview_planners::registry::{settings_from, settings_json, PlannerEntry};
use objview_render::Camera;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::input_grid::{pool_grid, InputGrid, GRID};
use crate::nbvnet::{NbvNet, CLASSES};
use crate::train::{argmax, load_weights_bytes};

/// The shipped NBV-Net weights (safetensors) and their sidecar.
pub const BUILTIN_WEIGHTS: &[u8] = include_bytes!("../../../data/weights/nbv-net.safetensors");
/// The sidecar of [`BUILTIN_WEIGHTS`].
pub const BUILTIN_SIDECAR: &str = include_str!("../../../data/weights/nbv-net.json");

/// This crate's planners.
pub const TABLE: &[PlannerEntry] = &[NBV_NET_ENTRY, crate::mascvp_planner::MA_SCVP_ENTRY];

/// The registry row of `nbv-net`.
pub const NBV_NET_ENTRY: PlannerEntry = PlannerEntry {
    name: "nbv-net",
    family: Family::Learned,
    mode: ExecutionMode::Iterative,
    summary: "NBV-Net (reference adaptation): argmax over tammes-128 from the 64³ occupancy grid; stops on a repeated or infeasible prediction",
    defaults: || settings_json(&NbvNetSettings::default()),
    build: |s| {
        let s: NbvNetSettings = settings_from("nbv-net", s, NbvNetSettings::default)?;
        Ok(Box::new(NbvNetPlanner::from_settings(&s)?))
    },
};

/// Settings of `nbv-net`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NbvNetSettings {
    /// `builtin` or a weights file of `objview learn train`.
    pub weights: String,
}

impl Default for NbvNetSettings {
    fn default() -> Self {
        NbvNetSettings { weights: "builtin".into() }
    }
}

/// What scores the 128 views from the input grid (the network, or a script in tests).
pub trait ViewScorer: Send {
    /// Scores of the 128 views (higher is better) for the grid.
    fn scores(&mut self, grid: &InputGrid) -> Vec<f32>;
    /// What to record about it in results.
    fn describe(&self) -> Value;
}

/// NBV-Net as a [`ViewScorer`].
pub struct NetScorer {
    net: NbvNet,
    device: Device,
    sidecar: Value,
    source: String,
}

impl NetScorer {
    /// From safetensors bytes and the sidecar JSON text (which gives `settings.grid`).
    pub fn from_bytes(bytes: &[u8], sidecar: &str, source: &str) -> Result<NetScorer, String> {
        let sidecar: Value =
            serde_json::from_str(sidecar).map_err(|e| format!("{source}: sidecar is not JSON: {e}"))?;
        let grid = sidecar["settings"]["grid"]
            .as_u64()
            .ok_or(format!("{source}: sidecar has no settings.grid"))? as usize;
        let device = Device::flex();
        let net = load_weights_bytes(bytes, grid, &device).map_err(|e| format!("{source}: {e}"))?;
        Ok(NetScorer { net, device, sidecar, source: source.to_string() })
    }

    /// The shipped weights.
    pub fn builtin() -> Result<NetScorer, String> {
        NetScorer::from_bytes(BUILTIN_WEIGHTS, BUILTIN_SIDECAR, "builtin")
    }

    /// A weights file and its sidecar (`W.json` next to `W.safetensors`).
    pub fn from_file(path: &Path) -> Result<NetScorer, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let side = crate::train::sidecar_path(path);
        let text = std::fs::read_to_string(&side)
            .map_err(|e| format!("{}: {e} (the weights' sidecar)", side.display()))?;
        NetScorer::from_bytes(&bytes, &text, &path.display().to_string())
    }

    /// The network.
    pub fn net(&self) -> &NbvNet {
        &self.net
    }
}

impl ViewScorer for NetScorer {
    fn scores(&mut self, grid: &InputGrid) -> Vec<f32> {
        let g = self.net.grid();
        let full = grid.probabilities();
        let x = pool_grid(&full, grid.size(), grid.size() / g);
        let x = Tensor::<5>::from_data(TensorData::new(x, [1, 1, g, g, g]), &self.device);
        self.net.forward(x).into_data().try_to_vec::<f32>().expect("f32 logits")
    }
    fn describe(&self) -> Value {
        json!({
            "weights": self.source,
            "grid": self.net.grid(),
            "trained_on": self.sidecar.get("data").cloned().unwrap_or(Value::Null),
            "deviation": self.sidecar.get("deviation").cloned().unwrap_or(Value::Null),
            "weights_fnv1a64": self.sidecar.get("weights_fnv1a64").cloned().unwrap_or(Value::Null),
        })
    }
}

/// The decision of one step (see the module docs), from the scores and the episode state.
pub fn decide(
    scores: &[f32],
    predicted: &[usize],
    feasible: &[bool],
    current_is: Option<usize>,
) -> Result<usize, StopReason> {
    let best = argmax(scores);
    if best >= CLASSES || best >= feasible.len() {
        return Err(StopReason::NextViewInfeasible);
    }
    if predicted.contains(&best) {
        return Err(StopReason::NextViewVisited);
    }
    if !feasible[best] || current_is == Some(best) {
        return Err(StopReason::NextViewInfeasible);
    }
    Ok(best)
}

/// The `nbv-net` planner.
pub struct NbvNetPlanner {
    scorer: Box<dyn ViewScorer>,
    grid: InputGrid,
    poses: Vec<Pose>,
    feasible: Vec<bool>,
    predicted: Vec<usize>,
}

impl NbvNetPlanner {
    /// With the network the settings name.
    pub fn from_settings(s: &NbvNetSettings) -> Result<NbvNetPlanner, String> {
        let scorer = if s.weights == "builtin" {
            NetScorer::builtin()?
        } else {
            NetScorer::from_file(Path::new(&s.weights))?
        };
        Ok(NbvNetPlanner::with_scorer(Box::new(scorer)))
    }

    /// With any scorer (tests script the network's output this way).
    pub fn with_scorer(scorer: Box<dyn ViewScorer>) -> NbvNetPlanner {
        NbvNetPlanner {
            scorer,
            grid: InputGrid::new(GRID),
            poses: Vec::new(),
            feasible: Vec::new(),
            predicted: Vec::new(),
        }
    }
}

impl Planner for NbvNetPlanner {
    fn name(&self) -> &str {
        "nbv-net"
    }
    fn family(&self) -> Family {
        Family::Learned
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }
    fn params(&self) -> Value {
        json!({"network": self.scorer.describe(), "views": "tammes-128", "input_grid": "64^3 octomap log-odds over [-1,1]^3", "rule": "argmax; stop next_view_visited / next_view_infeasible, no fallback"})
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        // The views' radius is the start pose's (SPEC: 3.0; an ulp of rounding is not kept).
        let r = ctx.start_pose.radius();
        let radius = if (r - objview_geom::pose::VIEW_RADIUS).abs() < 1e-9 {
            objview_geom::pose::VIEW_RADIUS
        } else {
            r
        };
        let vs = objview_views::ViewSet::resolve("tammes-128").map_err(|e| PlannerError(e.to_string()))?;
        self.poses = vs.poses(radius);
        self.feasible = env.feasible_mask(&self.poses);
        self.predicted.clear();
        self.grid.clear();
        Ok(())
    }
    fn act(&mut self, obs: &Observation, _env: &dyn Environment) -> Result<Action, PlannerError> {
        let camera = Camera::new(obs.pose, obs.intrinsics);
        self.grid.insert_depth(&camera, &obs.depth);
        let scores = self.scorer.scores(&self.grid);
        let current = self.poses.iter().position(|p| same_pose(p, &obs.pose));
        match decide(&scores, &self.predicted, &self.feasible, current) {
            Ok(v) => {
                self.predicted.push(v);
                Ok(Action::move_to(&self.poses[v]))
            }
            Err(reason) => Ok(Action::stop(reason)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_hot(v: usize) -> Vec<f32> {
        let mut s = vec![0.0; 128];
        s[v] = 1.0;
        s
    }

    /// Every row of [`TABLE`] agrees with the planner it builds (with the shipped weights).
    #[test]
    fn table_rows_agree_with_their_planners() {
        for e in TABLE {
            let p = e.build_default().unwrap();
            assert_eq!((p.name(), p.family(), p.execution_mode()), (e.name, e.family, e.mode));
        }
        let bad = NBV_NET_ENTRY.build_with(&[("weights".into(), json!("/no/such/file.safetensors"))]);
        assert!(bad.err().unwrap().contains("/no/such/file.safetensors"));
    }

    #[test]
    fn decision_rules_in_the_reference_order() {
        let all = vec![true; 128];
        assert_eq!(decide(&one_hot(5), &[], &all, None), Ok(5));
        assert_eq!(decide(&one_hot(5), &[5], &all, None), Err(StopReason::NextViewVisited));
        let mut f = all.clone();
        f[5] = false;
        assert_eq!(decide(&one_hot(5), &[], &f, None), Err(StopReason::NextViewInfeasible));
        // visited is checked before feasibility
        assert_eq!(decide(&one_hot(5), &[5], &f, None), Err(StopReason::NextViewVisited));
        assert_eq!(decide(&one_hot(5), &[], &all, Some(5)), Err(StopReason::NextViewInfeasible));
        // ties go to the lowest id; no fallback to the runner-up
        let mut s = vec![0.0; 128];
        s[9] = 2.0;
        s[3] = 2.0;
        assert_eq!(decide(&s, &[], &all, None), Ok(3));
        assert_eq!(decide(&s, &[3], &all, None), Err(StopReason::NextViewVisited));
    }
}
