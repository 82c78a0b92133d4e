//! `completion-scp` and `completion-mcp` (paper: PoinTr-C+SCP and PoinTr-C+MCP; reference:
//! `shared/research/learned-baselines.md` §7–§8): one completion, then an exact one-shot plan.
//!
//! 1. Start view: the partial cloud gets the frame; the **bootstrap** is the feasible
//!    candidate (not the current pose) farthest from it by shell distance (first wins ties).
//! 2. After the bootstrap view: complete the partial cloud once ([`super::completion`]),
//!    outlier-filter (k = 16, 1.5σ), voxelize, target = predicted − observed, occluders =
//!    observed ∪ predicted, and the cover set of every feasible unvisited candidate
//!    ([`super::steps`]). Needed = target voxels some candidate covers and the bootstrap view
//!    does not.
//! 3. SCP: nothing needed → `plan_end` at once; else the exact minimum set cover
//!    ([`super::cover::set_cover`]). MCP (budget K, the bootstrap counts): the exact max
//!    coverage with K − 1 views ([`super::cover::max_coverage`]; skipped when nothing is needed),
//!    the rest of the budget filled by farthest-point sampling from the start pose, the
//!    bootstrap and the selected views; fewer than K − 1 views in all → `candidate_exhausted`.
//! 4. The selected views are visited along the exact shortest open path from the current pose
//!    ([`crate::tsp`]), then `plan_end`.
//!
//! The reference's start-view quirk (§7 step 5: it marks Tammes-360 view *0* as already
//! chosen, taking the start set's index for a candidate id) is not reproduced: the intended
//! meaning is "the start view is already taken", which the target already encodes (what the
//! start view saw is observed, hence not a target), so the chosen set is the bootstrap alone;
//! for MCP's fill the start pose itself (not view 0) is an anchor.
//!
//! What each plan did (completion sizes, voxel counts, ILP status, bound and gap, path) is kept
//! in [`PlanInfo`] ([`CompletionPlan::last_plan`]).

use std::time::Instant;

use objview_episode::path::pose_distance;
use objview_episode::{
    Action, Budget, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use objview_render::Intrinsics;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::completion::{complete, Completion};
use super::cover::{farthest_fill, max_coverage, set_cover, Selection};
use super::steps::{box_keys, statistical_outlier_removal, PartialCloud, PlanningSets, SOR_K, SOR_STD_MUL};
use super::{HybridSettings, COMPLETION_SEED_SALT};
use crate::random::same_pose;
use crate::tsp::{shortest_open_path, TspResult, TspSettings};

/// Which plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlanKind {
    /// Minimum set cover of the needed voxels (`completion-scp`).
    SetCover,
    /// Max coverage with the budget (`completion-mcp`).
    MaxCoverage,
}

/// What one plan did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanInfo {
    /// The completion backend.
    pub completion: String,
    /// Partial-cloud points sent to completion (after the 1/64 filter).
    pub partial_points: usize,
    /// Completed points (prediction + 2048 input) and how many were predicted.
    pub completed_points: usize,
    /// See `completed_points`.
    pub predicted_points: usize,
    /// Points left after the outlier removal.
    pub filtered_points: usize,
    /// Observed, occluder and target voxels (1/32).
    pub observed_voxels: usize,
    /// See `observed_voxels`.
    pub occluder_voxels: usize,
    /// See `observed_voxels`.
    pub target_voxels: usize,
    /// Candidates that were columns (feasible, unvisited).
    pub columns: usize,
    /// The bootstrap's index in the candidate set.
    pub bootstrap: usize,
    /// The exact selection (ILP status, bound and gap included).
    pub selection: Selection,
    /// Views added by the farthest-point fill (MCP), candidate indices in pick order.
    pub filled: Vec<usize>,
    /// Planned views (candidate indices), in visiting order.
    pub visit_order: Vec<usize>,
    /// The open-path ordering.
    pub tsp: Option<TspResult>,
    /// Why the plan ends (`plan_end` or `candidate_exhausted`).
    pub stop: String,
    /// Seconds: completion (resampling included), the other steps, the whole plan.
    pub completion_seconds: f64,
    /// See `completion_seconds`.
    pub steps_seconds: f64,
    /// See `completion_seconds`.
    pub plan_seconds: f64,
}

/// Where an episode is.
#[derive(Debug, Clone, PartialEq)]
enum Phase {
    Start,
    Bootstrapped { bootstrap: usize },
    Executing { plan: Vec<Pose>, next: usize, stop: StopReason },
}

/// `completion-scp` / `completion-mcp`.
pub struct CompletionPlan {
    kind: PlanKind,
    settings: HybridSettings,
    backend: Box<dyn Completion>,
    name: String,
    candidates: Vec<Pose>,
    feasible: Vec<bool>,
    intrinsics: Intrinsics,
    start: Option<Pose>,
    budget: Option<usize>,
    rng: ChaCha8Rng,
    partial: PartialCloud,
    phase: Phase,
    info: Option<PlanInfo>,
}

impl CompletionPlan {
    /// The planner of `kind` with `settings` (the backend must exist; `net` is refused).
    pub fn new(kind: PlanKind, settings: HybridSettings) -> Result<CompletionPlan, String> {
        CompletionPlan::with_net(kind, settings, None)
    }

    /// The planner of `kind` with `settings`, the `net` backend built by `net` when given.
    pub fn with_net(
        kind: PlanKind,
        settings: HybridSettings,
        net: Option<super::NetBackend>,
    ) -> Result<CompletionPlan, String> {
        let backend = settings.backend_with(net)?;
        let base = match kind {
            PlanKind::SetCover => "completion-scp",
            PlanKind::MaxCoverage => "completion-mcp",
        };
        Ok(CompletionPlan {
            kind,
            name: format!("{base}[{}]", backend.name()),
            settings,
            backend,
            candidates: Vec::new(),
            feasible: Vec::new(),
            intrinsics: Intrinsics::default(),
            start: None,
            budget: None,
            rng: ChaCha8Rng::seed_from_u64(0),
            partial: PartialCloud::default(),
            phase: Phase::Start,
            info: None,
        })
    }

    /// What the last plan did (`None` before one was made).
    pub fn last_plan(&self) -> Option<&PlanInfo> {
        self.info.as_ref()
    }

    /// The bootstrap: the feasible candidate, not at `from`, farthest from it (first wins ties).
    fn bootstrap(&self, from: &Pose) -> Option<usize> {
        let mut best: Option<(f64, usize)> = None;
        for (i, c) in self.candidates.iter().enumerate() {
            if !self.feasible[i] || same_pose(c, from) {
                continue;
            }
            let d = pose_distance(from, c);
            if best.is_none_or(|(b, _)| d > b) {
                best = Some((d, i));
            }
        }
        best.map(|(_, i)| i)
    }

    /// Steps 2–4 of the module docs, after the bootstrap view.
    fn plan(
        &mut self,
        obs: &Observation,
        env: &dyn Environment,
        bootstrap: usize,
    ) -> Result<Phase, PlannerError> {
        let t0 = Instant::now();
        let err = |e: String| PlannerError(format!("{}: {e}", self.name));
        let history = env.history().to_vec();
        let columns: Vec<usize> = (0..self.candidates.len())
            .filter(|&i| self.feasible[i] && !history.iter().any(|h| same_pose(h, &self.candidates[i])))
            .collect();
        let plan_views = match (self.kind, self.budget) {
            (PlanKind::MaxCoverage, Some(k)) => Some(k.saturating_sub(1)),
            _ => None,
        };
        let completed = complete(self.backend.as_mut(), &self.partial.points, &mut self.rng)
            .map_err(|e| err(e.to_string()))?;
        let completion_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let filtered = statistical_outlier_removal(&completed.points, SOR_K, SOR_STD_MUL);
        let observed = box_keys(&self.partial.points);
        let predicted = box_keys(&filtered);
        let sets = PlanningSets::new(&observed, &predicted);
        // Covers of the columns and of the bootstrap (the chosen view).
        let mut poses: Vec<Pose> = columns.iter().map(|&i| self.candidates[i]).collect();
        poses.push(self.candidates[bootstrap]);
        let covers = sets.covers(&poses, &vec![true; poses.len()], self.intrinsics);
        let (chosen_cover, covers) = covers.split_last().expect("the bootstrap's cover is there");
        let mut needed = vec![0u64; sets.target.len()];
        for c in covers {
            for (w, x) in needed.iter_mut().zip(c) {
                *w |= x;
            }
        }
        for (w, x) in needed.iter_mut().zip(chosen_cover) {
            *w &= !x;
        }
        let limit = self.settings.ilp_time_limit_s;
        let (selection, stop_now) = match self.kind {
            PlanKind::SetCover => {
                let s = set_cover(covers, &needed, limit);
                let none = s.status == "skipped";
                (s, none)
            }
            PlanKind::MaxCoverage => {
                let b = plan_views.unwrap_or(0);
                (max_coverage(covers, &needed, b, limit), b == 0)
            }
        };
        let mut selected: Vec<usize> = selection.chosen.iter().map(|&c| columns[c]).collect();
        let mut filled = Vec::new();
        let mut stop = StopReason::PlanEnd;
        if let (PlanKind::MaxCoverage, Some(b)) = (self.kind, plan_views) {
            if selected.len() < b {
                let eligible: Vec<(usize, [f64; 3])> = columns
                    .iter()
                    .filter(|i| !selected.contains(i))
                    .map(|&i| (i, self.candidates[i].center))
                    .collect();
                let mut anchors =
                    vec![self.start.map_or(obs.pose.center, |p| p.center), self.candidates[bootstrap].center];
                anchors.extend(selected.iter().map(|&i| self.candidates[i].center));
                filled = farthest_fill(&eligible, &anchors, b - selected.len());
                selected.extend(&filled);
            }
            if selected.len() < b {
                stop = StopReason::CandidateExhausted;
            }
        }
        if stop_now {
            selected.clear();
        }
        selected.sort_unstable();
        let steps_seconds = t1.elapsed().as_secs_f64();
        // Order: node 0 = the current pose, node j = selected[j − 1].
        let (visit_order, tsp) = if selected.is_empty() {
            (Vec::new(), None)
        } else {
            let nodes: Vec<Pose> =
                std::iter::once(obs.pose).chain(selected.iter().map(|&i| self.candidates[i])).collect();
            let n = nodes.len();
            let mut dist = vec![vec![0.0; n]; n];
            for i in 0..n {
                for j in i + 1..n {
                    let d = pose_distance(&nodes[i], &nodes[j]);
                    dist[i][j] = d;
                    dist[j][i] = d;
                }
            }
            let tsp =
                shortest_open_path(&dist, 0, &TspSettings::default()).map_err(|e| err(e.to_string()))?;
            (tsp.order[1..].iter().map(|&node| selected[node - 1]).collect::<Vec<usize>>(), Some(tsp))
        };
        self.info = Some(PlanInfo {
            completion: self.backend.name().to_string(),
            partial_points: self.partial.points.len(),
            completed_points: completed.points.len(),
            predicted_points: completed.predicted,
            filtered_points: filtered.len(),
            observed_voxels: observed.len(),
            occluder_voxels: sets.occluders.len(),
            target_voxels: sets.target_len,
            columns: columns.len(),
            bootstrap,
            selection,
            filled,
            visit_order: visit_order.clone(),
            tsp,
            stop: stop.as_str().to_string(),
            completion_seconds,
            steps_seconds,
            plan_seconds: t0.elapsed().as_secs_f64(),
        });
        Ok(Phase::Executing {
            plan: visit_order.iter().map(|&i| self.candidates[i]).collect(),
            next: 0,
            stop,
        })
    }
}

impl Planner for CompletionPlan {
    fn name(&self) -> &str {
        &self.name
    }
    fn family(&self) -> Family {
        Family::Hybrid
    }
    fn execution_mode(&self) -> ExecutionMode {
        match self.kind {
            PlanKind::SetCover => ExecutionMode::SetCoverPlan,
            PlanKind::MaxCoverage => ExecutionMode::BudgetedPlan,
        }
    }
    fn params(&self) -> serde_json::Value {
        let mut p = serde_json::json!({
            "completion": self.backend.name(),
            "completion_bound": self.backend.bound(),
            "ilp_time_limit_s": self.settings.ilp_time_limit_s,
            "plan": match self.kind { PlanKind::SetCover => "exact_min_set_cover", PlanKind::MaxCoverage => "exact_max_coverage+farthest_fill" },
            "sor": {"k": SOR_K, "std_mul": SOR_STD_MUL},
            "voxels": {"partial": super::steps::PARTIAL_VOXEL, "plan": super::steps::PLAN_VOXEL},
            "order": "exact_shortest_open_path",
            "start_view_quirk": "not reproduced (chosen = bootstrap only)",
        });
        super::describe_backend(&mut p, self.backend.as_ref());
        p
    }
    fn needs_ground_truth(&self) -> bool {
        self.backend.needs_ground_truth()
    }
    /// `{"plan": PlanInfo}` without its seconds (absent when no plan was made): the ILP's
    /// status (`optimal` only when proven, `time_limit` with its incumbent), bound and gap, the
    /// sizes the plan was made on, the fill and the path solve.
    fn notes(&self) -> Option<serde_json::Value> {
        objview_episode::plan_notes(self.info.as_ref())
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.budget = match (self.kind, ctx.budget) {
            (PlanKind::MaxCoverage, Budget::Auto) => {
                return Err(PlannerError(format!(
                    "{} is a budgeted plan and needs a fixed budget K; got budget `auto`",
                    self.name
                )))
            }
            (_, Budget::Fixed(k)) => Some(k),
            (_, Budget::Auto) => None,
        };
        self.backend.reset(ctx).map_err(|e| PlannerError(format!("{}: {e}", self.name)))?;
        self.candidates = ctx.candidates.to_vec();
        self.feasible = env.feasible_mask(&self.candidates);
        self.intrinsics = ctx.intrinsics;
        self.start = Some(ctx.start_pose);
        self.rng = ChaCha8Rng::seed_from_u64(ctx.seed ^ COMPLETION_SEED_SALT);
        self.partial = PartialCloud::default();
        self.phase = Phase::Start;
        self.info = None;
        Ok(())
    }
    fn act(&mut self, obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        self.partial.add(obs);
        if self.phase == Phase::Start {
            if self.budget == Some(0) {
                return Ok(Action::stop(StopReason::PlanEnd));
            }
            return Ok(match self.bootstrap(&obs.pose) {
                Some(b) => {
                    self.phase = Phase::Bootstrapped { bootstrap: b };
                    Action::move_to(&self.candidates[b])
                }
                None => Action::stop(StopReason::CandidateExhausted),
            });
        }
        if let Phase::Bootstrapped { bootstrap } = self.phase {
            if self.kind == PlanKind::MaxCoverage && self.budget.is_some_and(|k| k <= 1) {
                return Ok(Action::stop(StopReason::PlanEnd));
            }
            if self.partial.points.is_empty() {
                return Ok(Action::stop(StopReason::CandidateExhausted));
            }
            self.phase = self.plan(obs, env, bootstrap)?;
        }
        match &mut self.phase {
            Phase::Executing { plan, next, stop } => {
                if let Some(p) = plan.get(*next) {
                    *next += 1;
                    Ok(Action::move_to(p))
                } else {
                    Ok(Action::stop(*stop))
                }
            }
            _ => unreachable!("the phase is Executing after planning"),
        }
    }
}
