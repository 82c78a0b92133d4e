//! The **`ma-scvp`** planner (family learned, set-cover plan, Tammes-128 at the start pose's
//! radius): the reference's one-shot deployment of MA-SCVP (learned-baselines.md §3.2).
//!
//! 1. First call (the start view): the start camera is mapped to the **nearest Tammes-128
//!    view** (squared Euclidean distance between camera centres; ties to the lowest id), which is
//!    marked visited (it only enters the view state). The observation goes into the 64³ input
//!    grid ([`crate::input_grid`]).
//! 2. **Bootstrap**: among the feasible Tammes-128 views (the view space is queried once, at
//!    reset) other than the nearest one, the visited ones and the current pose, move to the one
//!    with the **largest shell distance** from the current camera (strict ">", so ties go to the
//!    lowest id); none → stop `candidate_exhausted`.
//! 3. Second call: the bootstrap observation goes into the grid; the network is called **once**
//!    with the grid (pooled to its size) and the view state {nearest, bootstrap}.
//! 4. Decode {v : sigmoid(logit_v) ≥ γ} (γ = 0.3 by default, the reference registry's
//!    `gamma_0.3`; setting `gamma`), drop visited views, keep the feasible ones (not the current
//!    pose); order them by the **exact shortest open path** from the current camera over shell
//!    distances ([`objview_planners::tsp`], the solver of `random-tsp`; if it fails, ascending
//!    id order), and execute the whole list.
//! 5. Stop `plan_end` after the last planned view (also at once when the decoded set is empty
//!    or only holds visited views), or `candidate_exhausted` when every decoded unvisited view
//!    was infeasible.
//!
//! Runtime is billed once: all the work (grid update, network, decoding, ordering) happens in
//! the second call; the later calls only hand out the planned moves.
//!
//! Parameters: `weights` (`builtin` = the shipped `data/weights/ma-scvp.safetensors`, compiled
//! in, or a `.safetensors` of `objview learn train ma-scvp` whose sidecar gives the shape),
//! `gamma`, and `tsp` (the ordering's [`TspSettings`]).

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use objview_episode::path::pose_distance;
use objview_episode::{
    Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use objview_planners::random::same_pose;
use objview_planners::random_tsp::distance_matrix;
use objview_planners::registry::{settings_from, settings_json, PlannerEntry};
use objview_planners::tsp::{shortest_open_path, TspResult, TspSettings};
use objview_render::Camera;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::input_grid::{pool_grid, InputGrid, GRID};
use crate::mascvp::{MascvpNet, MascvpShape};
use crate::mascvp_train::{decode, load_scvp_weights_bytes};
use crate::nbvnet::CLASSES;

/// The shipped MA-SCVP weights (safetensors).
pub const BUILTIN_WEIGHTS: &[u8] = include_bytes!("../../../data/weights/ma-scvp.safetensors");
/// The sidecar of [`BUILTIN_WEIGHTS`].
pub const BUILTIN_SIDECAR: &str = include_str!("../../../data/weights/ma-scvp.json");

/// The registry row of `ma-scvp`.
pub const MA_SCVP_ENTRY: PlannerEntry = PlannerEntry {
    name: "ma-scvp",
    family: Family::Learned,
    mode: ExecutionMode::SetCoverPlan,
    summary: "MA-SCVP (reference adaptation): bootstrap to the farthest tammes-128 view, one network call, the gamma-decoded view set on the exact open path",
    defaults: || settings_json(&MascvpSettings::default()),
    build: |s| {
        let s: MascvpSettings = settings_from("ma-scvp", s, MascvpSettings::default)?;
        Ok(Box::new(MascvpPlanner::from_settings(&s)?))
    },
};

/// Settings of `ma-scvp`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MascvpSettings {
    /// `builtin` or a weights file of `objview learn train ma-scvp`.
    pub weights: String,
    /// Decoding threshold on sigmoid scores.
    pub gamma: f64,
    /// The ordering's open-path solver.
    pub tsp: TspSettings,
}

impl Default for MascvpSettings {
    fn default() -> Self {
        MascvpSettings { weights: "builtin".into(), gamma: 0.3, tsp: TspSettings::default() }
    }
}

/// What scores the 128 views (logits) from the input grid and the view state (the network,
/// or a script in tests).
pub trait SetScorer: Send {
    /// Logits of the 128 views for the grid and the visited flags.
    fn logits(&mut self, grid: &InputGrid, visited: &[bool]) -> Vec<f32>;
    /// What to record about it in results.
    fn describe(&self) -> Value;
}

/// MA-SCVP as a [`SetScorer`].
pub struct MascvpScorer {
    net: MascvpNet,
    device: Device,
    sidecar: Value,
    source: String,
}

impl MascvpScorer {
    /// From safetensors bytes and the sidecar JSON text (which gives `settings.shape`).
    pub fn from_bytes(bytes: &[u8], sidecar: &str, source: &str) -> Result<MascvpScorer, String> {
        let sidecar: Value =
            serde_json::from_str(sidecar).map_err(|e| format!("{source}: sidecar is not JSON: {e}"))?;
        let shape: MascvpShape = serde_json::from_value(sidecar["settings"]["shape"].clone())
            .map_err(|e| format!("{source}: sidecar settings.shape: {e}"))?;
        let device = Device::flex();
        let net = load_scvp_weights_bytes(bytes, &shape, &device).map_err(|e| format!("{source}: {e}"))?;
        Ok(MascvpScorer { net, device, sidecar, source: source.to_string() })
    }

    /// The shipped weights.
    pub fn builtin() -> Result<MascvpScorer, String> {
        MascvpScorer::from_bytes(BUILTIN_WEIGHTS, BUILTIN_SIDECAR, "builtin")
    }

    /// A weights file and its sidecar (`W.json` next to `W.safetensors`).
    pub fn from_file(path: &Path) -> Result<MascvpScorer, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let side = crate::train::sidecar_path(path);
        let text = std::fs::read_to_string(&side)
            .map_err(|e| format!("{}: {e} (the weights' sidecar)", side.display()))?;
        MascvpScorer::from_bytes(&bytes, &text, &path.display().to_string())
    }

    /// The network.
    pub fn net(&self) -> &MascvpNet {
        &self.net
    }
}

impl SetScorer for MascvpScorer {
    fn logits(&mut self, grid: &InputGrid, visited: &[bool]) -> Vec<f32> {
        let g = self.net.grid();
        let x = pool_grid(&grid.probabilities(), grid.size(), grid.size() / g);
        let x = Tensor::<5>::from_data(TensorData::new(x, [1, 1, g, g, g]), &self.device);
        let vs: Vec<f32> =
            (0..CLASSES).map(|v| visited.get(v).copied().unwrap_or(false) as u8 as f32).collect();
        let vs = Tensor::<2>::from_data(TensorData::new(vs, [1, CLASSES]), &self.device);
        self.net.forward(x, vs).into_data().try_to_vec::<f32>().expect("f32 logits")
    }
    fn describe(&self) -> Value {
        json!({
            "weights": self.source,
            "shape": self.sidecar["settings"]["shape"],
            "trained_on": self.sidecar.get("data").cloned().unwrap_or(Value::Null),
            "deviation": self.sidecar.get("deviation").cloned().unwrap_or(Value::Null),
            "val_f1": self.sidecar["final"]["val"]["f1"],
            "weights_fnv1a64": self.sidecar.get("weights_fnv1a64").cloned().unwrap_or(Value::Null),
        })
    }
}

/// The view of `poses` nearest to `center` (squared Euclidean distance; ties to the lowest id).
pub fn nearest_view(poses: &[Pose], center: [f64; 3]) -> Option<usize> {
    let d2 = |p: &Pose| (0..3).map(|k| (p.center[k] - center[k]).powi(2)).sum::<f64>();
    let mut best: Option<(usize, f64)> = None;
    for (i, p) in poses.iter().enumerate() {
        let d = d2(p);
        if best.is_none_or(|(_, b)| d < b) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// The bootstrap view: among `poses[v]` with `allowed[v]`, the one farthest (shell distance)
/// from `current`, ties to the lowest id; `None` when none is allowed.
pub fn bootstrap_view(poses: &[Pose], allowed: &[bool], current: &Pose) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (v, p) in poses.iter().enumerate() {
        if !allowed.get(v).copied().unwrap_or(false) {
            continue;
        }
        let d = pose_distance(current, p);
        if best.is_none_or(|(_, b)| d > b) {
            best = Some((v, d));
        }
    }
    best.map(|(v, _)| v)
}

/// The ordered plan of [`plan_views`] and how it was ordered.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    /// Tammes-128 ids in visiting order.
    pub views: Vec<usize>,
    /// The open-path solve (`optimal` only when proven), or why it failed — the views are then
    /// in ascending id order.
    pub path: Result<TspResult, String>,
}

/// The plan of the network call: decode at `gamma`, drop `visited`, keep `feasible` views that
/// are not the current pose, order them on the exact open path from `current`. `Err` is the
/// stop reason when nothing is left to execute (`plan_end` for an empty or already visited set,
/// `candidate_exhausted` when every decoded unvisited view is infeasible).
pub fn plan_views(
    logits: &[f32],
    gamma: f64,
    visited: &[bool],
    feasible: &[bool],
    poses: &[Pose],
    current: &Pose,
    tsp: &TspSettings,
) -> Result<Planned, StopReason> {
    plan_decoded(&decode(logits, gamma), visited, feasible, poses, current, tsp)
}

/// [`plan_views`] on an already decoded set (ascending Tammes-128 ids with sigmoid ≥ γ).
pub fn plan_decoded(
    decoded: &[usize],
    visited: &[bool],
    feasible: &[bool],
    poses: &[Pose],
    current: &Pose,
    tsp: &TspSettings,
) -> Result<Planned, StopReason> {
    let decoded: Vec<usize> = decoded
        .iter()
        .copied()
        .filter(|&v| v < poses.len() && !visited.get(v).copied().unwrap_or(false))
        .collect();
    if decoded.is_empty() {
        return Err(StopReason::PlanEnd);
    }
    let keep: Vec<usize> = decoded
        .into_iter()
        .filter(|&v| feasible.get(v).copied().unwrap_or(false) && !same_pose(&poses[v], current))
        .collect();
    if keep.is_empty() {
        return Err(StopReason::CandidateExhausted);
    }
    let nodes: Vec<Pose> = std::iter::once(*current).chain(keep.iter().map(|&v| poses[v])).collect();
    Ok(match shortest_open_path(&distance_matrix(&nodes), 0, tsp) {
        Ok(r) => Planned { views: r.order[1..].iter().map(|&n| keep[n - 1]).collect(), path: Ok(r) },
        Err(e) => Planned { views: keep, path: Err(e.to_string()) },
    })
}

/// What the planner decided in an episode (its `planner_notes.plan`, without seconds).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct ScvpPlanInfo {
    /// The Tammes-128 view nearest to the start camera (marked visited).
    pub nearest: Option<usize>,
    /// The bootstrap view (`None`: none was feasible).
    pub bootstrap: Option<usize>,
    /// Views decoded at γ (sigmoid ≥ γ), ascending, before dropping visited or infeasible ones.
    pub decoded: Vec<usize>,
    /// The executed plan, in visiting order.
    pub planned: Vec<usize>,
    /// Its open-path solve (`optimal` only when proven), absent when nothing was ordered.
    pub tsp: Option<TspResult>,
    /// Why the path solve failed (the plan is then in ascending id order).
    pub tsp_error: Option<String>,
    /// The stop the network call decided instead of a plan (`plan_end`, `candidate_exhausted`).
    pub stop: Option<String>,
}

/// The `ma-scvp` planner.
pub struct MascvpPlanner {
    scorer: Box<dyn SetScorer>,
    gamma: f64,
    tsp: TspSettings,
    grid: InputGrid,
    poses: Vec<Pose>,
    feasible: Vec<bool>,
    visited: Vec<bool>,
    calls: usize,
    plan: Vec<usize>,
    next: usize,
    info: Option<ScvpPlanInfo>,
}

impl MascvpPlanner {
    /// With the network the settings name.
    pub fn from_settings(s: &MascvpSettings) -> Result<MascvpPlanner, String> {
        if !(s.gamma > 0.0 && s.gamma < 1.0) {
            return Err(format!("planner ma-scvp: gamma must be in (0, 1), got {}", s.gamma));
        }
        s.tsp.validate().map_err(|e| format!("planner ma-scvp: tsp: {e}"))?;
        let scorer = if s.weights == "builtin" {
            MascvpScorer::builtin()?
        } else {
            MascvpScorer::from_file(Path::new(&s.weights))?
        };
        Ok(MascvpPlanner::with_scorer(Box::new(scorer), s.gamma, s.tsp.clone()))
    }

    /// With any scorer (tests script the network's output this way).
    pub fn with_scorer(scorer: Box<dyn SetScorer>, gamma: f64, tsp: TspSettings) -> MascvpPlanner {
        MascvpPlanner {
            scorer,
            gamma,
            tsp,
            grid: InputGrid::new(GRID),
            poses: Vec::new(),
            feasible: Vec::new(),
            visited: Vec::new(),
            calls: 0,
            plan: Vec::new(),
            next: 0,
            info: None,
        }
    }
}

impl Planner for MascvpPlanner {
    fn name(&self) -> &str {
        "ma-scvp"
    }
    fn family(&self) -> Family {
        Family::Learned
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::SetCoverPlan
    }
    fn params(&self) -> Value {
        json!({"network": self.scorer.describe(), "views": "tammes-128", "gamma": self.gamma,
               "input_grid": "64^3 octomap log-odds over [-1,1]^3",
               "rule": "nearest tammes-128 view visited; bootstrap to the farthest feasible view; one call; decode sigmoid >= gamma minus visited, feasible only; exact open path; plan_end / candidate_exhausted",
               "tsp_time_limit_s": self.tsp.time_limit_s, "tsp_dp_max_nodes": self.tsp.dp_max_nodes})
    }
    /// `{"plan": ScvpPlanInfo}` without seconds: nearest and bootstrap views, the decoded set,
    /// the executed order and its open-path solve (or why it failed), or the stop decided.
    fn notes(&self) -> Option<Value> {
        objview_episode::plan_notes(self.info.as_ref())
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        let r = ctx.start_pose.radius();
        let radius = if (r - objview_geom::pose::VIEW_RADIUS).abs() < 1e-9 {
            objview_geom::pose::VIEW_RADIUS
        } else {
            r
        };
        let vs = objview_views::ViewSet::resolve("tammes-128").map_err(|e| PlannerError(e.to_string()))?;
        self.poses = vs.poses(radius);
        self.feasible = env.feasible_mask(&self.poses);
        self.visited = vec![false; self.poses.len()];
        self.grid.clear();
        self.calls = 0;
        self.plan.clear();
        self.next = 0;
        self.info = None;
        Ok(())
    }
    fn act(&mut self, obs: &Observation, _env: &dyn Environment) -> Result<Action, PlannerError> {
        self.calls += 1;
        match self.calls {
            1 => {
                let near = nearest_view(&self.poses, obs.pose.center)
                    .ok_or_else(|| PlannerError("ma-scvp: no tammes-128 views".into()))?;
                self.visited[near] = true;
                self.grid.insert_depth(&Camera::new(obs.pose, obs.intrinsics), &obs.depth);
                let allowed: Vec<bool> = (0..self.poses.len())
                    .map(|v| self.feasible[v] && !self.visited[v] && !same_pose(&self.poses[v], &obs.pose))
                    .collect();
                let boot = bootstrap_view(&self.poses, &allowed, &obs.pose);
                self.info = Some(ScvpPlanInfo {
                    nearest: Some(near),
                    bootstrap: boot,
                    stop: boot.is_none().then(|| StopReason::CandidateExhausted.to_string()),
                    ..ScvpPlanInfo::default()
                });
                match boot {
                    Some(b) => {
                        self.visited[b] = true;
                        Ok(Action::move_to(&self.poses[b]))
                    }
                    None => Ok(Action::stop(StopReason::CandidateExhausted)),
                }
            }
            2 => {
                self.grid.insert_depth(&Camera::new(obs.pose, obs.intrinsics), &obs.depth);
                let logits = self.scorer.logits(&self.grid, &self.visited);
                let info = self.info.get_or_insert_with(ScvpPlanInfo::default);
                info.decoded = decode(&logits, self.gamma);
                let planned = plan_decoded(
                    &info.decoded,
                    &self.visited,
                    &self.feasible,
                    &self.poses,
                    &obs.pose,
                    &self.tsp,
                );
                match planned {
                    Ok(Planned { views, path }) => {
                        for &v in &views {
                            self.visited[v] = true;
                        }
                        info.planned = views.clone();
                        match path {
                            Ok(r) => info.tsp = Some(r),
                            Err(e) => info.tsp_error = Some(e),
                        }
                        self.plan = views;
                        self.next = 1;
                        Ok(Action::move_to(&self.poses[self.plan[0]]))
                    }
                    Err(reason) => {
                        info.stop = Some(reason.to_string());
                        Ok(Action::stop(reason))
                    }
                }
            }
            _ => match self.plan.get(self.next) {
                Some(&v) => {
                    self.next += 1;
                    Ok(Action::move_to(&self.poses[v]))
                }
                None => Ok(Action::stop(StopReason::PlanEnd)),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_planners::tsp::open_path_length;

    fn poses() -> Vec<Pose> {
        objview_views::ViewSet::resolve("tammes-128").unwrap().poses(3.0)
    }

    /// The bootstrap choice against brute force (max distance first, then the lowest id among
    /// the maxima), over many allowed masks and current poses.
    #[test]
    fn bootstrap_is_the_farthest_allowed_view_lowest_id_on_ties() {
        use rand::{Rng, SeedableRng};
        let p = poses();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for trial in 0..200 {
            let allowed: Vec<bool> =
                (0..128).map(|_| rng.gen_bool(if trial % 10 == 0 { 0.02 } else { 0.4 })).collect();
            let current =
                if trial % 3 == 0 { p[rng.gen_range(0..128)] } else { objview_views::start_pose(3.0) };
            let got = bootstrap_view(&p, &allowed, &current);
            let ds: Vec<(usize, f64)> =
                (0..128).filter(|&v| allowed[v]).map(|v| (v, pose_distance(&current, &p[v]))).collect();
            let want = ds
                .iter()
                .map(|x| x.1)
                .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))))
                .map(|max| ds.iter().find(|x| x.1 == max).unwrap().0);
            assert_eq!(got, want, "trial {trial}");
        }
        // Exact ties: the same pose twice → the lower id.
        let twin = vec![p[4], p[9], p[9]];
        assert_eq!(bootstrap_view(&twin, &[true, true, true], &p[4]), Some(1));
        assert_eq!(bootstrap_view(&p, &[false; 128], &p[0]), None);
    }

    #[test]
    fn nearest_view_is_the_closest_centre() {
        let p = poses();
        for v in [0usize, 17, 127] {
            assert_eq!(nearest_view(&p, p[v].center), Some(v));
        }
        let s = objview_views::start_pose(3.0);
        let want = (0..128)
            .min_by(|&a, &b| {
                let d = |v: usize| (0..3).map(|k| (p[v].center[k] - s.center[k]).powi(2)).sum::<f64>();
                d(a).total_cmp(&d(b)).then(a.cmp(&b))
            })
            .unwrap();
        assert_eq!(nearest_view(&p, s.center), Some(want));
    }

    /// Decode, filter and order on scripted logits; the order is the shortest of all
    /// permutations (brute force).
    #[test]
    fn plan_decodes_filters_and_orders_by_brute_force() {
        let p = poses();
        let mut logits = vec![-4.0f32; 128];
        for v in [2usize, 9, 30, 31, 77, 100] {
            logits[v] = 1.0;
        }
        logits[55] = -0.9; // sigmoid 0.289 < 0.3: not decoded
        let mut visited = vec![false; 128];
        visited[9] = true;
        let mut feasible = vec![true; 128];
        feasible[31] = false;
        let current = p[60];
        let tsp = TspSettings::default();
        let planned = plan_views(&logits, 0.3, &visited, &feasible, &p, &current, &tsp).unwrap();
        let solve = planned.path.clone().expect("the open path is solved");
        assert!(solve.optimal);
        let plan = planned.views;
        let mut set = plan.clone();
        set.sort_unstable();
        assert_eq!(set, vec![2, 30, 77, 100]);
        let len = |order: &[usize]| {
            let nodes: Vec<Pose> = std::iter::once(current).chain(order.iter().map(|&v| p[v])).collect();
            open_path_length(&distance_matrix(&nodes), &(0..nodes.len()).collect::<Vec<_>>())
        };
        let mut best = f64::INFINITY;
        let items = [2usize, 30, 77, 100];
        for a in 0..4 {
            for b in 0..4 {
                for c in 0..4 {
                    for d in 0..4 {
                        let o = [a, b, c, d];
                        let mut u = o.to_vec();
                        u.sort_unstable();
                        u.dedup();
                        if u.len() == 4 {
                            best = best.min(len(&o.map(|i| items[i])));
                        }
                    }
                }
            }
        }
        assert!((len(&plan) - best).abs() < 1e-12, "{} vs brute force {best}", len(&plan));
        assert!((solve.length - best).abs() < 1e-12 && solve.order.len() == 5, "{solve:?}");
        // Stop rules.
        assert_eq!(
            plan_views(&[-4.0; 128], 0.3, &visited, &feasible, &p, &current, &tsp),
            Err(StopReason::PlanEnd)
        );
        let mut only_visited = vec![-4.0f32; 128];
        only_visited[9] = 2.0;
        assert_eq!(
            plan_views(&only_visited, 0.3, &visited, &feasible, &p, &current, &tsp),
            Err(StopReason::PlanEnd)
        );
        let mut only_bad = vec![-4.0f32; 128];
        only_bad[31] = 2.0;
        only_bad[60] = 2.0; // the current pose
        assert_eq!(
            plan_views(&only_bad, 0.3, &visited, &feasible, &p, &current, &tsp),
            Err(StopReason::CandidateExhausted)
        );
        // γ = 0.5 drops what only 0.3 keeps.
        let mut g = vec![-4.0f32; 128];
        g[5] = -0.5; // sigmoid 0.378
        assert_eq!(
            plan_views(&g, 0.3, &visited, &feasible, &p, &current, &tsp).map(|p| p.views),
            Ok(vec![5])
        );
        assert_eq!(plan_views(&g, 0.5, &visited, &feasible, &p, &current, &tsp), Err(StopReason::PlanEnd));
    }
}
