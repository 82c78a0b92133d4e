//! The `random-tsp` planner (paper: "Random+TSP", Classical, budgeted plan; SPEC §5): draw K
//! feasible candidates uniformly at random without replacement, then visit them along the exact
//! shortest open path from the start pose ([`crate::tsp`]).
//!
//! Why: it is the classical baseline that separates *which* views are taken (random) from *how*
//! they are visited (optimally), so its path cost is the least possible for a random view set.
//!
//! Details:
//! - Budget: needs `Budget::Fixed(K)` (a budgeted plan has no automatic stop of its own).
//! - Candidates: the episode's candidate set filtered by the environment's feasibility mask;
//!   if fewer than K are feasible, all of them are visited. A candidate equal to the start pose
//!   is eligible like any other.
//! - Randomness: `ChaCha8Rng::seed_from_u64(ctx.seed)` (the episode seed, already mixed with
//!   object, view space and budget), partial Fisher–Yates over the feasible candidate indices.
//! - Order: node 0 is the start pose, nodes 1..=K the drawn candidates in ascending candidate
//!   index; distances are [`objview_episode::path::pose_distance`] (shell distance between camera
//!   centres, normalized object units), computed once per pair so the matrix is exactly
//!   symmetric. The plan's length is therefore exactly the episode's path cost PC at its end.
//! - Actions: one `move` per planned view, then `stop(plan_end)`; `stop(candidate_exhausted)` at
//!   once when no candidate is feasible.

use objview_episode::path::pose_distance;
use objview_episode::{
    Action, Budget, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::registry::{settings_from, settings_json, PlannerEntry};
use crate::tsp::{shortest_open_path, TspError, TspResult, TspSettings};

/// The registry row of `random-tsp`; its settings are [`TspSettings`] (the path ordering).
pub const ENTRY: PlannerEntry = PlannerEntry {
    name: RandomTsp::NAME,
    family: Family::Classical,
    mode: ExecutionMode::BudgetedPlan,
    summary: "K random feasible views, visited on the exact shortest open path (Random+TSP)",
    defaults: || settings_json(&TspSettings::default()),
    build: |settings| {
        let settings = settings_from(RandomTsp::NAME, settings, TspSettings::default)?;
        Ok(Box::new(RandomTsp::new(settings).map_err(|e| e.to_string())?))
    },
};

/// What [`RandomTsp::reset`](Planner::reset) planned, for reporting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanInfo {
    /// The fixed budget K.
    pub budget: usize,
    /// Number of feasible candidates (of `ctx.candidates`).
    pub feasible_candidates: usize,
    /// Indices into `ctx.candidates` of the planned views, in visiting order
    /// (min(K, feasible) of them).
    pub visit_order: Vec<usize>,
    /// The open-path solve over node 0 = start pose and node i = the i-th drawn candidate in
    /// ascending candidate index; `tsp.length` is the plan's shell length from the start pose
    /// (normalized object units).
    pub tsp: TspResult,
}

/// The Random+TSP planner: K random feasible candidates, visited along the exact shortest open
/// path from the start pose.
#[derive(Debug, Clone, Default)]
pub struct RandomTsp {
    settings: TspSettings,
    /// Set by `reset`: the poses to visit, in order.
    plan: Option<Vec<Pose>>,
    next: usize,
    info: Option<PlanInfo>,
}

impl RandomTsp {
    /// Name in results.
    pub const NAME: &'static str = "random-tsp";

    /// A planner whose path ordering uses `settings` (checked here).
    pub fn new(settings: TspSettings) -> Result<RandomTsp, TspError> {
        settings.validate()?;
        Ok(RandomTsp { settings, ..RandomTsp::default() })
    }

    /// The ordering settings.
    pub fn settings(&self) -> &TspSettings {
        &self.settings
    }

    /// The plan of the current (last reset) episode; `None` before the first successful reset.
    pub fn last_plan(&self) -> Option<&PlanInfo> {
        self.info.as_ref()
    }
}

/// `min(k, feasible.len())` indices drawn uniformly without replacement (partial Fisher–Yates
/// with `ChaCha8Rng::seed_from_u64(seed)`), returned ascending.
fn draw(feasible: &[usize], k: usize, seed: u64) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pool = feasible.to_vec();
    let take = k.min(pool.len());
    for i in 0..take {
        let j = rng.gen_range(i..pool.len());
        pool.swap(i, j);
    }
    pool.truncate(take);
    pool.sort_unstable();
    pool
}

/// Shell distances between all pairs of `poses` (normalized object units), each pair computed
/// once and mirrored so the matrix is exactly symmetric (also the learned set-cover planners'
/// ordering input).
pub fn distance_matrix(poses: &[Pose]) -> Vec<Vec<f64>> {
    let n = poses.len();
    let mut dist = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            let d = pose_distance(&poses[i], &poses[j]);
            dist[i][j] = d;
            dist[j][i] = d;
        }
    }
    dist
}

impl Planner for RandomTsp {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn family(&self) -> Family {
        Family::Classical
    }

    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::BudgetedPlan
    }

    fn params(&self) -> serde_json::Value {
        serde_json::json!({
            "selection": "uniform_without_replacement",
            "candidates": "feasible",
            "order": "exact_shortest_open_path",
            "distance": "shell",
            "tsp_time_limit_s": self.settings.time_limit_s,
            "tsp_dp_max_nodes": self.settings.dp_max_nodes,
        })
    }

    /// `{"plan": PlanInfo}` without its seconds: the drawn views and the open-path solve
    /// (`optimal` only when proven, with its lower bound).
    fn notes(&self) -> Option<serde_json::Value> {
        objview_episode::plan_notes(self.info.as_ref())
    }

    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.plan = None;
        self.next = 0;
        self.info = None;
        let k = match ctx.budget {
            Budget::Fixed(k) => k,
            Budget::Auto => {
                return Err(PlannerError(
                    "random-tsp is a budgeted plan (it visits K random candidates) and needs a fixed \
                     budget K; got budget `auto`"
                        .into(),
                ))
            }
        };
        let candidates = &ctx.candidates;
        let mask = env.feasible_mask(candidates);
        if mask.len() != candidates.len() {
            return Err(PlannerError(format!(
                "random-tsp: the environment answered {} feasibility flags for {} candidates",
                mask.len(),
                candidates.len()
            )));
        }
        let feasible: Vec<usize> = mask.iter().enumerate().filter(|(_, &f)| f).map(|(i, _)| i).collect();
        let chosen = draw(&feasible, k, ctx.seed);
        let poses: Vec<Pose> =
            std::iter::once(ctx.start_pose).chain(chosen.iter().map(|&i| candidates[i])).collect();
        let tsp = shortest_open_path(&distance_matrix(&poses), 0, &self.settings).map_err(|e| {
            PlannerError(format!(
                "random-tsp: ordering {} candidates from the start pose {:?}: {e}",
                chosen.len(),
                ctx.start_pose.to_array()
            ))
        })?;
        let visit_order: Vec<usize> = tsp.order[1..].iter().map(|&node| chosen[node - 1]).collect();
        self.plan = Some(visit_order.iter().map(|&i| candidates[i]).collect());
        self.info = Some(PlanInfo { budget: k, feasible_candidates: feasible.len(), visit_order, tsp });
        Ok(())
    }

    fn act(&mut self, _obs: &Observation, _env: &dyn Environment) -> Result<Action, PlannerError> {
        let plan = self
            .plan
            .as_ref()
            .ok_or_else(|| PlannerError("random-tsp: act called without a successful reset".into()))?;
        if let Some(pose) = plan.get(self.next) {
            self.next += 1;
            Ok(Action::move_to(pose))
        } else if plan.is_empty() {
            Ok(Action::stop(StopReason::CandidateExhausted))
        } else {
            Ok(Action::stop(StopReason::PlanEnd))
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use objview_episode::path::path_length;
    use objview_render::Intrinsics;

    use super::*;

    /// Feasibility by a rule on the pose; empty history.
    struct FakeEnv {
        rule: fn(&Pose) -> bool,
    }

    impl Environment for FakeEnv {
        fn is_feasible(&self, pose: &Pose) -> bool {
            (self.rule)(pose)
        }
        fn history(&self) -> &[Pose] {
            &[]
        }
    }

    fn upper_half(p: &Pose) -> bool {
        p.center[2] >= 0.0
    }

    /// `n` poses on a Fibonacci spiral at radius 3 looking at the origin.
    fn candidates(n: usize) -> Vec<Pose> {
        objview_views::tammes::fibonacci(n).into_iter().map(|d| Pose::from_direction(d, 3.0)).collect()
    }

    fn ctx(seed: u64, budget: Budget, cands: Vec<Pose>) -> EpisodeContext {
        EpisodeContext {
            seed,
            object_id: "obj".into(),
            view_space: "test".into(),
            budget,
            candidates: Arc::new(cands),
            candidate_set: "fibonacci".into(),
            start_pose: Pose::from_direction([1.0, 0.2, 0.1], 3.0),
            intrinsics: Intrinsics::default(),
            oracle: None,
        }
    }

    fn observation(step: usize, pose: Pose) -> Observation {
        Observation { step, pose, intrinsics: Intrinsics::default(), depth: Arc::new(Vec::new()), rgb: None }
    }

    /// Runs an episode: the moves (as poses) and the final stop reason.
    fn run(planner: &mut RandomTsp, ctx: &EpisodeContext, env: &FakeEnv) -> (Vec<Pose>, String) {
        planner.reset(ctx, env).unwrap();
        let mut moves = Vec::new();
        let mut pose = ctx.start_pose;
        for step in 0..=ctx.candidates.len() + 1 {
            match planner.act(&observation(step, pose), env).unwrap() {
                Action::Move { pose: p } => {
                    pose = Pose::from_array(p).unwrap();
                    moves.push(pose);
                }
                Action::Stop { reason } => return (moves, reason),
            }
        }
        panic!("the planner never stopped");
    }

    fn index_of(cands: &[Pose], p: &Pose) -> usize {
        cands.iter().position(|c| c == p).expect("a move to a pose outside the candidate set")
    }

    /// Shortest open path length from `start` over all orders of `poses` (brute force).
    fn brute_force(start: Pose, poses: &[Pose]) -> f64 {
        fn rec(path: &mut Vec<Pose>, left: &mut Vec<Pose>, best: &mut f64) {
            if left.is_empty() {
                *best = best.min(path_length(path));
            }
            for k in 0..left.len() {
                let p = left.remove(k);
                path.push(p);
                rec(path, left, best);
                path.pop();
                left.insert(k, p);
            }
        }
        let mut best = f64::INFINITY;
        rec(&mut vec![start], &mut poses.to_vec(), &mut best);
        best
    }

    #[test]
    fn plans_k_distinct_feasible_candidates_along_the_shortest_path() {
        let cands = candidates(40);
        let env = FakeEnv { rule: upper_half };
        for k in 1..=6usize {
            for seed in 0..4u64 {
                let c = ctx(seed * 1000 + k as u64, Budget::Fixed(k), cands.clone());
                let mut planner = RandomTsp::default();
                let (moves, reason) = run(&mut planner, &c, &env);
                assert_eq!(reason, "plan_end");
                assert_eq!(moves.len(), k);
                let mut ids: Vec<usize> = moves.iter().map(|p| index_of(&cands, p)).collect();
                assert!(moves.iter().all(upper_half), "an infeasible candidate was planned");
                let info = planner.last_plan().unwrap();
                assert_eq!(info.visit_order, ids);
                ids.sort_unstable();
                ids.dedup();
                assert_eq!(ids.len(), k, "a candidate was planned twice");
                let mut path = vec![c.start_pose];
                path.extend(&moves);
                let length = path_length(&path);
                assert!(info.tsp.optimal);
                assert!((length - info.tsp.length).abs() < 1e-12, "{length} vs {}", info.tsp.length);
                let best = brute_force(c.start_pose, &moves);
                assert!(length <= best + 1e-9, "k={k} seed={seed}: plan {length} vs shortest {best}");
                assert_eq!(info.budget, k);
                assert_eq!(info.feasible_candidates, cands.iter().filter(|p| upper_half(p)).count());
            }
        }
    }

    #[test]
    fn same_seed_same_plan_different_seed_different_set() {
        let cands = candidates(60);
        let env = FakeEnv { rule: |_| true };
        let plan = |seed: u64| {
            let mut planner = RandomTsp::default();
            run(&mut planner, &ctx(seed, Budget::Fixed(5), cands.clone()), &env).0
        };
        let a = plan(42);
        assert_eq!(a, plan(42));
        let set = |moves: &[Pose]| {
            let mut ids: Vec<usize> = moves.iter().map(|p| index_of(&cands, p)).collect();
            ids.sort_unstable();
            ids
        };
        let others = (0..5u64).filter(|&s| set(&plan(s)) != set(&a)).count();
        assert!(others >= 4, "only {others} of 5 other seeds drew a different set");
    }

    #[test]
    fn draws_are_uniform_over_feasible_candidates() {
        // 10 feasible of 20; K = 3: each feasible candidate is drawn with probability 0.3.
        let cands = candidates(20);
        let feasible: Vec<usize> = (0..20).filter(|i| i % 2 == 0).collect();
        let mut counts = [0usize; 20];
        let trials = 3000u64;
        for seed in 0..trials {
            for i in draw(&feasible, 3, objview_geom::hash::splitmix64(seed)) {
                counts[i] += 1;
            }
        }
        // Expected 900, standard deviation ≈ 25: allow 5σ.
        for (i, &c) in counts.iter().enumerate() {
            if i % 2 == 0 {
                assert!((775..=1025).contains(&c), "candidate {i} drawn {c} times of {trials}");
            } else {
                assert_eq!(c, 0);
            }
        }
        assert_eq!(cands.len(), 20);
    }

    #[test]
    fn auto_budget_is_an_error() {
        let mut planner = RandomTsp::default();
        let env = FakeEnv { rule: |_| true };
        let err = planner.reset(&ctx(1, Budget::Auto, candidates(10)), &env).unwrap_err();
        assert!(err.0.contains("budgeted plan") && err.0.contains("fixed budget"), "{}", err.0);
        assert!(planner.last_plan().is_none());
        // Nothing was planned: acting is an error too.
        assert!(planner.act(&observation(0, Pose::from_direction([1.0, 0.0, 0.0], 3.0)), &env).is_err());
    }

    #[test]
    fn fewer_feasible_than_k_visits_all_then_plan_end() {
        let cands = candidates(30);
        // Only the topmost candidates (z > 2.5) are feasible.
        let env = FakeEnv { rule: |p| p.center[2] > 2.5 };
        let feasible: Vec<usize> = (0..30).filter(|&i| cands[i].center[2] > 2.5).collect();
        assert!((1..5).contains(&feasible.len()), "{} feasible", feasible.len());
        let mut planner = RandomTsp::default();
        let (moves, reason) = run(&mut planner, &ctx(9, Budget::Fixed(5), cands.clone()), &env);
        assert_eq!(reason, "plan_end");
        let mut ids: Vec<usize> = moves.iter().map(|p| index_of(&cands, p)).collect();
        ids.sort_unstable();
        assert_eq!(ids, feasible);
    }

    #[test]
    fn no_feasible_candidate_stops_with_candidate_exhausted() {
        let mut planner = RandomTsp::default();
        let env = FakeEnv { rule: |_| false };
        let (moves, reason) = run(&mut planner, &ctx(3, Budget::Fixed(5), candidates(12)), &env);
        assert!(moves.is_empty());
        assert_eq!(reason, "candidate_exhausted");
        assert_eq!(planner.last_plan().unwrap().tsp.order, vec![0]);
    }

    #[test]
    fn budget_30_uses_the_exact_ilp() {
        let cands = candidates(360);
        let env = FakeEnv { rule: |_| true };
        let mut planner = RandomTsp::default();
        let (moves, reason) = run(&mut planner, &ctx(5, Budget::Fixed(30), cands.clone()), &env);
        assert_eq!((moves.len(), reason.as_str()), (30, "plan_end"));
        let info = planner.last_plan().unwrap();
        assert!(info.tsp.optimal && info.tsp.symmetric);
        assert_eq!(info.tsp.method, crate::tsp::TspMethod::Ilp);
        assert!(info.tsp.length <= info.tsp.heuristic_length.unwrap());
        let mut path = vec![planner_start()];
        path.extend(&moves);
        assert!((path_length(&path) - info.tsp.length).abs() < 1e-12);
    }

    fn planner_start() -> Pose {
        ctx(0, Budget::Auto, Vec::new()).start_pose
    }

    #[test]
    fn interface() {
        let planner = RandomTsp::default();
        assert_eq!(planner.name(), "random-tsp");
        assert_eq!(planner.family(), Family::Classical);
        assert_eq!(planner.execution_mode(), ExecutionMode::BudgetedPlan);
        assert!(!planner.needs_ground_truth());
        let params = planner.params();
        assert_eq!(params["tsp_time_limit_s"], 60.0);
        assert_eq!(params["order"], "exact_shortest_open_path");
        assert!(RandomTsp::new(TspSettings { time_limit_s: -1.0, ..TspSettings::default() }).is_err());
    }
}
