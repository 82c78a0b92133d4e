//! The environment of SPEC §5: it holds the hidden object, executes one planner action at a
//! time (validate → feasibility → render → fuse → score), keeps the checkpoints, and decides
//! when the episode ends. [`Episode`] is step-driven (the server drives it one request at a
//! time); [`run_episode`] drives a local [`Planner`] to the end.
//!
//! The scoring of each view (SC, NSC, PC, MS, #Views, PR; CD at checkpoints) is
//! [`crate::metrics`].
//!
//! Frames: every pose is in the object frame (normalized object units, roll in radians).

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

use objview_geom::{Mesh, Pose};
use objview_render::{Camera, Frame, Intrinsics, Renderer};
use objview_views::ViewSpace;

use crate::chamfer::Targets;
use crate::coverage::Coverage;
use crate::fusion::FusedCloud;
use crate::grid::{ChangedBlocks, Domain};
use crate::metrics;
use crate::planner::{Action, Environment, EpisodeContext, Observation, OracleAccess, Planner};
use crate::reference::Reference;
use crate::result::{Checkpoint, EpisodeResult, Step, StepMetrics};
use crate::scratch::Pool;
use crate::settings::EpisodeSettings;
use crate::stabilization::Stabilization;
use crate::validate::{check_pose, check_view_pose};
use crate::vocab::{wire_names, Budget, CheckpointKey, ExecutionMode, Family, StopReason, TerminalSource};
use crate::EpisodeError;

/// The hidden object of an episode, prepared once per (object, view space).
#[derive(Debug, Clone)]
pub struct Scene {
    /// Opaque object id.
    pub uid: String,
    /// The normalized mesh.
    pub mesh: Arc<Mesh>,
    /// Ground-truth surface points (normalized frame).
    pub gt: Arc<Vec<[f64; 3]>>,
    /// Where the ground truth came from.
    pub gt_source: String,
    /// The view space (feasibility rules).
    pub space: ViewSpace,
    /// The view-space name recorded in results.
    pub space_name: String,
    /// The observable reference of (object, space).
    pub reference: Arc<Reference>,
    /// The metric grid domain (covers mesh, ground truth and reference).
    pub domain: Domain,
    /// The camera intrinsics of every view (SPEC §2).
    pub intrinsics: Intrinsics,
    /// What every episode on the scene starts from (coverage and CD sets with nothing fused),
    /// built once for the first τ list asked for and shared (see [`Scene::fresh_targets`]).
    pub(crate) targets: std::sync::OnceLock<Arc<FreshTargets>>,
    /// The reference's exact-distance index in [`Coverage::points`] order (the oracle's).
    pub(crate) reference_targets: std::sync::OnceLock<Arc<Targets>>,
    /// The state of an episode after its start view, per start (see [`StartStates`]).
    pub(crate) starts: StartStates,
}

/// What an episode's start view depends on besides the scene: every setting, whether a budget
/// checkpoint falls on the start view (K = 0; the budget and method matter for nothing else
/// there), the start pose (bit for bit) and the intrinsics.
#[derive(Debug, Clone, PartialEq)]
struct StartKey {
    settings: EpisodeSettings,
    checkpoint_at_start: bool,
    pose: [u64; 7],
    intrinsics: Intrinsics,
}

/// What an episode's views write: its state after the start view is what later episodes with
/// the same start copy ([`StartStates`]).
#[derive(Debug, Clone)]
struct Progress {
    fused: FusedCloud,
    /// SC's coverage.
    gt: Coverage,
    /// NSC's coverage.
    reference: Coverage,
    /// Exact GT → fused distances (CD), as of fused epoch `cd_seen`; made (a copy of the
    /// scene's fresh set) by the first CD, so that an episode and a kept start state hold it
    /// only once it differs from the scene's.
    gt_near: Option<Targets>,
    /// Per fused slot: d² to the nearest ground-truth point (fused → GT half of CD), as of
    /// fused epoch `cd_seen`.
    slot_gt_d2: Vec<f64>,
    cd_seen: u32,
    /// CD of the latest view, once computed (a checkpoint at that view).
    cd_now: Option<f64>,
    ms: Vec<Stabilization>,
    history: Vec<Pose>,
    steps: Vec<Step>,
    checkpoints: BTreeMap<CheckpointKey, Checkpoint>,
    path_cost: f64,
    /// The latest view (its depth is the observation; RGB is rendered from its triangle ids).
    frame: Frame,
}

impl Progress {
    /// An episode's state before its start view: nothing fused, the scene's fresh target sets.
    fn nothing_seen(
        scene: &Scene,
        settings: &EpisodeSettings,
        start_pose: Pose,
    ) -> Result<Progress, EpisodeError> {
        // The coverage sets are copied now; the distance set only by the first CD, when the
        // scene holds it (sets for another τ list than the scene's are built for this episode
        // alone, and kept).
        let taus = &settings.taus;
        let (gt, reference, gt_near) = match scene.shared_targets(taus) {
            Some(t) => (t.gt.clone(), t.reference.clone(), None),
            None => {
                let f = scene.fresh_targets(taus)?;
                let gt_near = scene.shared_targets(taus).is_none().then_some(f.gt_near);
                (f.gt, f.reference, gt_near)
            }
        };
        let h = settings.fusion_voxel;
        // The fused cloud's fine keys lie in its domain's blocks (any outside are still counted).
        let (fine_lo, fine_hi) = scene.domain.key_box();
        let ms = settings
            .ms_deltas
            .iter()
            .map(|&d| {
                Stabilization::with_box(d, h, settings.ms_growth, settings.ms_stable_steps, fine_lo, fine_hi)
            })
            .collect();
        Ok(Progress {
            fused: FusedCloud::new(scene.domain.clone()),
            gt,
            reference,
            gt_near,
            slot_gt_d2: Vec::new(),
            cd_seen: 0,
            cd_now: None,
            ms,
            history: Vec::new(),
            steps: Vec::new(),
            checkpoints: BTreeMap::new(),
            path_cost: 0.0,
            frame: Frame::empty(Camera::new(start_pose, scene.intrinsics)),
        })
    }
}

/// The start states of a scene's episodes, by [`StartKey`]: every episode on a scene with the
/// same settings and start pose takes the same start view, so the first one's state after it
/// can be copied instead of rendered, fused and scored again (the same state, bit for bit; only
/// the start step's timings differ). Off unless asked for ([`Scene::keep_start_states`]: the
/// server and `bench` do): each kept start costs ~20 MB on a 100k-triangle object with a
/// 300k-point ground truth (the coverage state of every target point, the fused cloud, the
/// depth frame), and saves ~30 ms per episode. The first starts seen are kept. A clone of a
/// [`Scene`] keeps the limit but none of the states, so a changed copy never reuses a state of
/// the original.
#[derive(Debug, Default)]
pub(crate) struct StartStates {
    limit: std::sync::atomic::AtomicUsize,
    list: std::sync::Mutex<Vec<(StartKey, Arc<Progress>)>>,
}

impl Clone for StartStates {
    fn clone(&self) -> Self {
        StartStates { limit: self.limit.load(Ordering::Relaxed).into(), list: Default::default() }
    }
}

impl StartStates {
    fn get(&self, key: &StartKey) -> Option<Arc<Progress>> {
        let list = self.list.lock().unwrap_or_else(|e| e.into_inner());
        list.iter().find(|(k, _)| k == key).map(|(_, s)| s.clone())
    }

    /// Keeps `state()` for `key` if there is room and none is kept yet (the copy is made
    /// outside the lock: concurrent starts of the scene do not wait for it).
    fn remember(&self, key: StartKey, state: impl FnOnce() -> Progress) {
        let room = |list: &Vec<(StartKey, Arc<Progress>)>| {
            list.len() < self.limit.load(Ordering::Relaxed) && !list.iter().any(|(k, _)| *k == key)
        };
        if !room(&self.list.lock().unwrap_or_else(|e| e.into_inner())) {
            return;
        }
        let state = Arc::new(state());
        let mut list = self.list.lock().unwrap_or_else(|e| e.into_inner());
        if room(&list) {
            list.push((key, state));
        }
    }

    /// How many start states are kept.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.list.lock().unwrap_or_else(|e| e.into_inner()).len()
    }
}

/// The target sets of a new episode: coverage of the ground truth (SC) and of the reference
/// (NSC) at a τ list, and the ground truth's exact distances (CD at checkpoints).
#[derive(Debug, Clone)]
pub struct FreshTargets {
    taus: Vec<f64>,
    gt: Coverage,
    reference: Coverage,
    gt_near: Targets,
}

impl Scene {
    /// The target sets of a new episode scoring at `taus`. Their indexes are built once per
    /// scene (for the first τ list; episodes use one τ list in practice) and shared.
    pub fn fresh_targets(&self, taus: &[f64]) -> Result<FreshTargets, EpisodeError> {
        if let Some(t) = self.shared_targets(taus) {
            return Ok(t.clone());
        }
        let fresh = FreshTargets {
            taus: taus.to_vec(),
            gt: Coverage::new(self.domain.clone(), &self.gt, taus).map_err(EpisodeError::Setup)?,
            reference: Coverage::new(self.domain.clone(), &self.reference.points, taus)
                .map_err(EpisodeError::Setup)?,
            gt_near: Targets::new(self.domain.clone(), &self.gt, f64::INFINITY)
                .map_err(EpisodeError::Setup)?,
        };
        let _ = self.targets.set(Arc::new(fresh.clone()));
        Ok(fresh)
    }

    /// The fresh target sets the scene holds, if they are for `taus` (the τ list they were
    /// first built for).
    fn shared_targets(&self, taus: &[f64]) -> Option<&FreshTargets> {
        self.targets.get().map(|t| &**t).filter(|t| t.taus == taus)
    }

    /// Keeps the state after the start view of up to `n` starts (settings and start pose) of
    /// this scene's episodes, which later episodes with the same start copy instead of taking
    /// the start view again (see `StartStates` in the source: the same results bit for bit,
    /// ~20 MB per start on a 100k-triangle object). 0 (the default) keeps none; lowering the
    /// limit keeps the states already kept.
    pub fn keep_start_states(&self, n: usize) {
        self.starts.limit.store(n, Ordering::Relaxed);
    }

    /// The observable reference's exact-distance index (points in the order of the NSC
    /// coverage: bit i of [`Episode::reference_covered`] is its point i), built on first use.
    pub fn reference_targets(&self) -> Result<Arc<Targets>, EpisodeError> {
        if let Some(t) = self.reference_targets.get() {
            return Ok(t.clone());
        }
        let t = Arc::new(
            Targets::new(self.domain.clone(), &self.reference.points, f64::INFINITY)
                .map_err(EpisodeError::Setup)?,
        );
        Ok(self.reference_targets.get_or_init(|| t).clone())
    }
}

/// The grid domain for a mesh and its ground truth: their bounding box plus 0.1.
pub fn scene_domain(mesh: &Mesh, gt: &[[f64; 3]], h: f64) -> Domain {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in mesh.positions.iter().chain(gt) {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    if !lo[0].is_finite() {
        lo = [-1.0; 3];
        hi = [1.0; 3];
    }
    Domain::covering(h, lo, hi, 0.1)
}

/// Method facts recorded in results.
#[derive(Debug, Clone)]
pub struct MethodInfo {
    /// Method name (`rse`, a remote planner's name).
    pub name: String,
    /// Its family.
    pub family: Family,
    /// Its execution mode (decides how the budget applies).
    pub mode: ExecutionMode,
    /// Its parameters.
    pub params: serde_json::Value,
}

/// How an episode ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Terminal {
    /// Who ended it.
    pub source: TerminalSource,
    /// The terminal reason (`plan_end`, `invalid_action`, `max_cap_reached`, …).
    pub reason: String,
    /// Human-readable detail (empty when there is nothing to add).
    pub detail: String,
}

/// One running episode.
pub struct Episode {
    scene: Arc<Scene>,
    settings: EpisodeSettings,
    method: MethodInfo,
    budget: Budget,
    seed: u64,
    start_pose: Pose,
    /// What the views so far wrote.
    now: Progress,
    ks: Vec<usize>,
    runtime: f64,
    terminal: Option<Terminal>,
    started: Instant,
}

/// The buffers of one engine step, shared by every episode of the process through
/// [`STEP_SCRATCH`] (see [`crate::scratch`]): the renderer's, the observed points and the
/// changed slots' groups.
#[derive(Default)]
struct StepScratch {
    renderer: Renderer,
    points: Vec<[f64; 3]>,
    groups: ChangedBlocks,
}

/// The step buffers of every episode of the process.
static STEP_SCRATCH: Pool<StepScratch> = Pool::new();

impl Episode {
    /// Starts an episode: takes the start view at `start_pose` and scores it. Errors: bad
    /// settings, a start pose that [`check_view_pose`] refuses, a start view that sees nothing
    /// of the object (its CD would be infinite).
    pub fn start(
        scene: Arc<Scene>,
        settings: EpisodeSettings,
        method: MethodInfo,
        budget: Budget,
        seed: u64,
        start_pose: Pose,
    ) -> Result<Episode, EpisodeError> {
        let started = Instant::now();
        settings.validate().map_err(EpisodeError::Settings)?;
        check_view_pose(&start_pose.to_array())
            .map_err(|e| EpisodeError::Settings(format!("start pose {:?}: {e}", start_pose.to_array())))?;
        let mut ks = settings.checkpoint_ks.clone();
        if let (Budget::Fixed(k), ExecutionMode::Iterative) = (budget, method.mode) {
            ks.push(k);
        }
        ks.sort_unstable();
        ks.dedup();
        let key = StartKey {
            settings: settings.clone(),
            checkpoint_at_start: ks.contains(&0),
            pose: start_pose.to_array().map(f64::to_bits),
            intrinsics: scene.intrinsics,
        };
        let copied = scene.starts.get(&key);
        let now = match &copied {
            Some(state) => (**state).clone(),
            None => Progress::nothing_seen(&scene, &settings, start_pose)?,
        };
        let mut ep = Episode {
            now,
            ks,
            runtime: 0.0,
            terminal: None,
            started,
            scene,
            settings,
            method,
            budget,
            seed,
            start_pose,
        };
        if copied.is_some() {
            if ep.settings.record_timings {
                // The start step's engine time is the copy's (stage "rest").
                let t = ep.started.elapsed().as_secs_f64();
                ep.now.steps[0].engine_seconds = t;
                ep.now.steps[0].stage_seconds = [0.0, 0.0, 0.0, t];
            }
            return Ok(ep);
        }
        ep.observe(start_pose, 0.0);
        if ep.now.fused.is_empty() {
            // CD (and every later step's, until something is seen) would be infinite.
            return Err(EpisodeError::Setup(format!(
                "the start view from {:?} sees nothing of object {}: its metrics are undefined \
                 (choose a start pose that looks at the object)",
                start_pose.to_array(),
                ep.scene.uid
            )));
        }
        ep.scene.starts.remember(key, || ep.now.clone());
        Ok(ep)
    }

    /// The latest observation (what the planner sees).
    pub fn observation(&self) -> Observation {
        let rgb = self
            .settings
            .render_rgb
            .then(|| Arc::new(objview_render::rgb::render_rgb(&self.scene.mesh, &self.now.frame)));
        Observation {
            step: self.now.steps.len() - 1,
            pose: *self.now.history.last().unwrap_or(&self.start_pose),
            intrinsics: self.scene.intrinsics,
            depth: Arc::new(self.now.frame.depth.clone()),
            rgb,
        }
    }

    /// The latest step's record (metrics after the latest view). Ground truth: not for
    /// planners — the server shows it only for public splits.
    pub fn last_step(&self) -> Option<&Step> {
        self.now.steps.last()
    }

    /// Whether the episode has ended.
    pub fn terminal(&self) -> Option<&Terminal> {
        self.terminal.as_ref()
    }

    /// Poses executed so far, start first.
    pub fn history(&self) -> &[Pose] {
        &self.now.history
    }

    /// The scene.
    pub fn scene(&self) -> &Arc<Scene> {
        &self.scene
    }

    /// For each reference point, whether it is covered at the smallest τ now (NSC's coverage;
    /// oracle use only).
    pub fn reference_covered(&self) -> Vec<bool> {
        let j = (0..self.settings.taus.len())
            .min_by(|&a, &b| self.settings.taus[a].total_cmp(&self.settings.taus[b]))
            .unwrap_or(0);
        self.now.reference.covered(j)
    }

    /// The planner context of this episode (`oracle`: with ground-truth access, whose reference
    /// index is built on first use).
    pub fn context(
        &self,
        candidates: Arc<Vec<Pose>>,
        candidate_set: &str,
        oracle: bool,
    ) -> Result<EpisodeContext, EpisodeError> {
        let oracle = match oracle {
            true => Some(OracleAccess {
                mesh: self.scene.mesh.clone(),
                reference: Arc::new(self.now.reference.points().to_vec()),
                reference_targets: self.scene.reference_targets()?,
            }),
            false => None,
        };
        Ok(EpisodeContext {
            seed: crate::episode_seed(self.seed, &self.scene.uid, &self.scene.space_name, self.budget),
            object_id: self.scene.uid.clone(),
            view_space: self.scene.space_name.clone(),
            budget: self.budget,
            candidates,
            candidate_set: candidate_set.to_string(),
            start_pose: self.start_pose,
            intrinsics: self.scene.intrinsics,
            oracle,
        })
    }

    /// Ends the episode (if it has not ended) with `source`/`reason`.
    pub fn end(&mut self, source: TerminalSource, reason: &str, detail: impl Into<String>) {
        if self.terminal.is_none() {
            self.terminal = Some(Terminal { source, reason: reason.to_string(), detail: detail.into() });
        }
    }

    /// Adds planner time (seconds) to PR.
    pub fn add_runtime(&mut self, seconds: f64) {
        self.runtime = metrics::planning_runtime(self.runtime, seconds, self.settings.record_timings);
    }

    /// Applies one action (after the planner spent `planner_seconds` choosing it). A stop, an
    /// invalid action, the cap and `enough_info` end the episode; a finite plan with a fixed
    /// budget K that asks for a move after its K-th view ends with `budget_reached` (the move is
    /// not executed).
    pub fn apply(&mut self, action: &Action, planner_seconds: f64) {
        if self.terminal.is_some() {
            return;
        }
        self.add_runtime(planner_seconds);
        match action {
            Action::Stop { reason } => match StopReason::parse(reason) {
                Some(r) => self.end(TerminalSource::AlgorithmStop, r.as_str(), ""),
                None => self.end(
                    TerminalSource::Benchmark,
                    "invalid_action",
                    format!("unknown stop reason {reason:?} (valid: {})", wire_names(&StopReason::ALL)),
                ),
            },
            Action::Move { pose } => {
                let p = match check_view_pose(pose) {
                    Ok(p) => p,
                    Err(e) => {
                        self.end(TerminalSource::Benchmark, "invalid_action", format!("pose {pose:?}: {e}"));
                        return;
                    }
                };
                if let (ExecutionMode::BudgetedPlan | ExecutionMode::SetCoverPlan, Budget::Fixed(k)) =
                    (self.method.mode, self.budget)
                {
                    // A finite plan that asks for a view beyond its budget: the move is refused.
                    if self.now.history.len() > k {
                        self.end(
                            TerminalSource::Benchmark,
                            "budget_reached",
                            format!(
                                "the plan asked for view {} beyond its budget K = {k}",
                                self.now.history.len()
                            ),
                        );
                        return;
                    }
                }
                if !self.scene.space.is_feasible(&p) {
                    let why = self.scene.space.explain(&p).unwrap_or_default();
                    self.end(
                        TerminalSource::Benchmark,
                        "invalid_action",
                        format!("pose {pose:?} is infeasible in view space {}: {why}", self.scene.space_name),
                    );
                    return;
                }
                self.observe(p, if self.settings.record_timings { planner_seconds } else { 0.0 });
            }
        }
        self.check_limits();
    }

    /// Ends at the cap or (iterative planners) `enough_info`.
    fn check_limits(&mut self) {
        if self.terminal.is_some() {
            return;
        }
        let views = self.now.history.len();
        if views >= self.settings.cap {
            self.end(
                TerminalSource::Benchmark,
                "max_cap_reached",
                format!("{views} views (cap {})", self.settings.cap),
            );
            return;
        }
        match (self.method.mode, self.budget) {
            (ExecutionMode::Iterative, _) => {
                if self.settings.enough_info && self.all_checkpoints_reached() {
                    self.end(TerminalSource::Benchmark, "enough_info", "every checkpoint reached");
                }
            }
            (_, Budget::Fixed(_)) | (_, Budget::Auto) => {}
        }
    }

    fn all_checkpoints_reached(&self) -> bool {
        self.ks.iter().all(|&k| self.now.checkpoints.contains_key(&CheckpointKey::Budget(k)))
            && self
                .settings
                .ms_deltas
                .iter()
                .all(|&d| self.now.checkpoints.contains_key(&CheckpointKey::Stabilized(d)))
    }

    /// Renders, fuses and scores the view from `pose` (the scoring: [`crate::metrics`]); CD
    /// only when a checkpoint is recorded at this view.
    fn observe(&mut self, pose: Pose, planner_seconds: f64) {
        let t0 = Instant::now();
        let cam = Camera::new(pose, self.scene.intrinsics);
        let (delta, t_render, t_fuse, t_cov) = STEP_SCRATCH.with(|s| {
            s.renderer.render_into(&self.scene.mesh, &cam, &mut self.now.frame);
            let t_render = t0.elapsed().as_secs_f64();
            self.now.frame.observed_points_into(&mut s.points);
            let delta = self.now.fused.insert_grouped(&s.points, &mut s.groups);
            let t_fuse = t0.elapsed().as_secs_f64();
            metrics::update_coverage(&mut self.now.gt, &mut self.now.reference, &self.now.fused, &s.groups);
            (delta, t_render, t_fuse, t0.elapsed().as_secs_f64())
        });
        metrics::add_new_voxels(&mut self.now.ms, &self.now.fused, delta.new_slots);
        self.now.path_cost = metrics::path_cost(self.now.path_cost, self.now.history.last(), &pose);
        self.now.history.push(pose);
        self.now.cd_now = None;
        let step = self.now.history.len() - 1;
        let taus = &self.settings.taus;
        let scores = StepMetrics {
            views: metrics::views(&self.now.history),
            sc: metrics::sc(&self.now.gt, taus),
            nsc: metrics::nsc(&self.now.reference, taus),
            path_cost: self.now.path_cost,
            runtime: self.runtime,
        };
        let (ms_voxels, mut keys) = metrics::stabilization_step(&mut self.now.ms, step);
        let planner_views = step;
        if self.ks.contains(&planner_views) {
            keys.push(CheckpointKey::Budget(planner_views));
        }
        if !keys.is_empty() {
            let cd = self.cd();
            for key in keys {
                self.now.checkpoints.insert(key, Checkpoint { step, metrics: scores.with_cd(cd) });
            }
        }
        let (engine_seconds, stage_seconds) = if self.settings.record_timings {
            let total = t0.elapsed().as_secs_f64();
            (total, [t_render, t_fuse - t_render, t_cov - t_fuse, total - t_cov])
        } else {
            (0.0, [0.0; 4])
        };
        self.now.steps.push(Step {
            step,
            pose: pose.to_array(),
            metrics: scores,
            fused_points: self.now.fused.len(),
            ms_voxels,
            planner_seconds,
            engine_seconds,
            stage_seconds,
        });
    }

    /// CD of the latest view (computed once per view).
    fn cd(&mut self) -> f64 {
        if let Some(cd) = self.now.cd_now {
            return cd;
        }
        let (scene, taus) = (&self.scene, &self.settings.taus);
        let now = &mut self.now;
        let gt_near = now.gt_near.get_or_insert_with(|| {
            let shared = scene.shared_targets(taus);
            // Left out at the start only when the scene held the sets for this τ list, which it
            // keeps.
            shared.expect("the scene's target sets for the episode's τ list").gt_near.clone()
        });
        let cd = metrics::chamfer(gt_near, &mut now.slot_gt_d2, &now.fused, &mut now.cd_seen);
        self.now.cd_now = Some(cd);
        cd
    }

    /// The result (call after the episode ended; an unfinished episode is recorded as
    /// interrupted).
    pub fn finish(mut self, settings_record: serde_json::Value) -> EpisodeResult {
        if self.terminal.is_none() {
            self.end(TerminalSource::Exception, "interrupted", "the episode was not finished");
        }
        let cd = self.cd();
        let last = self.now.steps.last().expect("the start view is always taken");
        self.now.checkpoints.insert(
            CheckpointKey::Terminal,
            Checkpoint { step: last.step, metrics: last.metrics.with_cd(cd) },
        );
        let t = self.terminal.clone().unwrap_or(Terminal {
            source: TerminalSource::Exception,
            reason: "interrupted".into(),
            detail: String::new(),
        });
        EpisodeResult {
            settings: settings_record,
            uid: self.scene.uid.clone(),
            method: self.method.name.clone(),
            family: self.method.family,
            execution_mode: self.method.mode,
            view_space: self.scene.space_name.clone(),
            budget: self.budget,
            seed: self.seed,
            start_pose: self.start_pose.to_array(),
            visited_poses: self.now.history.iter().map(|p| p.to_array()).collect(),
            terminal_source: t.source,
            terminal_reason: t.reason,
            terminal_detail: t.detail,
            steps: self.now.steps,
            checkpoints: self.now.checkpoints,
            reference: self.scene.reference.info.clone(),
            gt_points: self.scene.gt.len(),
            gt_source: self.scene.gt_source.clone(),
            wall_seconds: if self.settings.record_timings {
                self.started.elapsed().as_secs_f64()
            } else {
                0.0
            },
            planner_notes: None,
        }
    }
}

/// The environment as the planner sees it during one call.
struct PlannerView<'a> {
    space: &'a ViewSpace,
    history: &'a [Pose],
    covered: Option<Vec<bool>>,
}

impl Environment for PlannerView<'_> {
    fn is_feasible(&self, pose: &Pose) -> bool {
        // A pose the environment would refuse as a move is not feasible either.
        check_pose(&pose.to_array()).is_ok() && self.space.is_feasible(pose)
    }
    fn history(&self) -> &[Pose] {
        self.history
    }
    fn oracle_covered(&self) -> Option<&[bool]> {
        self.covered.as_deref()
    }
}

/// Runs `planner` on `scene` to the end of the episode and returns its result. Planner time
/// (reset + every act) is PR; a planner error or panic ends the episode with the `exception`
/// source, scoring the views taken. A result with a non-finite number (it would be written as
/// `null`) is an error ([`EpisodeError::NonFinite`]), never a result.
#[allow(clippy::too_many_arguments)]
pub fn run_episode(
    scene: Arc<Scene>,
    planner: &mut dyn Planner,
    settings: &EpisodeSettings,
    budget: Budget,
    seed: u64,
    start_pose: Pose,
    candidates: Arc<Vec<Pose>>,
    settings_record: serde_json::Value,
) -> Result<EpisodeResult, EpisodeError> {
    let method = MethodInfo {
        name: planner.name().to_string(),
        family: planner.family(),
        mode: planner.execution_mode(),
        params: planner.params(),
    };
    if planner.execution_mode() == ExecutionMode::BudgetedPlan && budget == Budget::Auto {
        return Err(EpisodeError::Settings(format!(
            "{} is a budgeted plan: it needs a fixed budget K, not `auto`",
            planner.name()
        )));
    }
    let oracle = planner.needs_ground_truth();
    let mut ep = Episode::start(scene.clone(), settings.clone(), method, budget, seed, start_pose)?;
    let ctx = ep.context(candidates, &settings.candidates, oracle)?;
    let covered = |ep: &Episode| oracle.then(|| ep.reference_covered());
    let t = Instant::now();
    let reset = {
        let env = PlannerView { space: &scene.space, history: ep.history(), covered: covered(&ep) };
        catch_unwind(AssertUnwindSafe(|| planner.reset(&ctx, &env)))
    };
    ep.add_runtime(t.elapsed().as_secs_f64());
    match reset {
        Ok(Ok(())) => {}
        Ok(Err(e)) => ep.end(TerminalSource::Exception, "planner_error", format!("reset: {e}")),
        Err(p) => {
            ep.end(TerminalSource::Exception, "planner_error", format!("reset panicked: {}", panic_text(&p)))
        }
    }
    ep.check_limits();
    while ep.terminal().is_none() {
        let obs = ep.observation();
        let t = Instant::now();
        let act = {
            let env = PlannerView { space: &scene.space, history: ep.history(), covered: covered(&ep) };
            catch_unwind(AssertUnwindSafe(|| planner.act(&obs, &env)))
        };
        let secs = t.elapsed().as_secs_f64();
        match act {
            Ok(Ok(a)) => ep.apply(&a, secs),
            Ok(Err(e)) => {
                ep.add_runtime(secs);
                ep.end(TerminalSource::Exception, "planner_error", e.to_string());
            }
            Err(p) => {
                ep.add_runtime(secs);
                ep.end(TerminalSource::Exception, "planner_error", format!("panicked: {}", panic_text(&p)));
            }
        }
    }
    let mut result = ep.finish(settings_record);
    result.planner_notes = crate::planner::read_notes(planner);
    match result.non_finite() {
        Some(field) => Err(EpisodeError::NonFinite(field)),
        None => Ok(result),
    }
}

fn panic_text(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

#[cfg(test)]
mod start_state_tests {
    use super::*;
    use crate::{Action, Scripted};
    use objview_views::ViewSet;

    /// A unit sphere in `whole` (its start states start empty).
    fn sphere() -> Arc<Scene> {
        static SPHERE: std::sync::OnceLock<Scene> = std::sync::OnceLock::new();
        // A clone: the same content, no start states (and none kept: the built scene's limit).
        Arc::new(SPHERE.get_or_init(build_sphere).clone())
    }

    fn build_sphere() -> Scene {
        let mesh = objview_render::bench::icosphere(3);
        let gt = objview_geom::cloud::sample_surface(&mesh, 20_000, 1);
        let space = ViewSpace::builtin("whole").unwrap();
        let settings = EpisodeSettings { record_timings: false, ..Default::default() };
        crate::scene_from_parts("sphere", mesh, gt, "sampled".into(), &space, "whole", &settings, None)
            .unwrap()
    }

    /// Three moves then whatever the budget allows, as a JSON line (timings off).
    fn run(scene: &Arc<Scene>, settings: &EpisodeSettings, budget: Budget, start: Pose) -> String {
        let candidates = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0));
        let moves: Vec<Action> =
            [7usize, 100, 250].iter().map(|&i| Action::Move { pose: candidates[i].to_array() }).collect();
        let mut p = Scripted::new(moves, ExecutionMode::Iterative);
        let r =
            run_episode(scene.clone(), &mut p, settings, budget, 3, start, candidates, serde_json::json!({}))
                .unwrap();
        serde_json::to_string(&r).unwrap()
    }

    #[test]
    fn a_copied_start_state_gives_the_episode_a_fresh_start_would() {
        let s = EpisodeSettings { record_timings: false, checkpoint_ks: vec![2, 3], ..Default::default() };
        let a = objview_views::start_pose(3.0);
        let b = Pose::from_direction([1.0, -2.0, 0.5], 3.0);
        // Off by default.
        let off = sphere();
        run(&off, &s, Budget::Fixed(3), a);
        assert_eq!(off.starts.len(), 0);
        let scene = sphere();
        scene.keep_start_states(2);
        let first = run(&scene, &s, Budget::Fixed(3), a);
        assert_eq!(scene.starts.len(), 1);
        // The same start again (a copy), with another budget (which cannot change the start
        // view), against another scene with the same content (a fresh start; a clone of a
        // scene has no start states).
        for budget in [Budget::Fixed(3), Budget::Auto] {
            let copied = run(&scene, &s, budget, a);
            let fresh = run(&sphere(), &s, budget, a);
            assert_eq!(copied, fresh, "{budget:?}");
        }
        assert_eq!(run(&scene, &s, Budget::Fixed(3), a), first);
        assert_eq!(scene.starts.len(), 1);
        let cloned = Arc::new((*scene).clone());
        assert_eq!(cloned.starts.len(), 0);
        assert_eq!(cloned.starts.limit.load(Ordering::Relaxed), 2);
        // Another start pose, other settings, a K = 0 checkpoint on the start view: each its
        // own start state, equal to a fresh start's episode.
        let other = EpisodeSettings { taus: vec![0.01, 0.05], ..s.clone() };
        for (settings, budget, start) in
            [(&s, Budget::Fixed(0), a), (&s, Budget::Fixed(3), b), (&other, Budget::Fixed(3), a)]
        {
            let got = run(&scene, settings, budget, start);
            assert_eq!(got, run(&sphere(), settings, budget, start), "{budget:?} {start:?}");
            // And a copy of it, the second time.
            assert_eq!(run(&scene, settings, budget, start), got);
        }
        // Full after the K = 0 start (the other two were not kept, and were still right).
        assert_eq!(scene.starts.len(), 2);
        // After a K = 0 start, an episode without one does not inherit its checkpoint.
        assert!(!run(&scene, &s, Budget::Fixed(2), a).contains("\"K=0\""));
        assert!(run(&scene, &s, Budget::Fixed(0), a).contains("\"K=0\""));
    }

    #[test]
    fn a_copied_start_records_the_copy_as_its_engine_time() {
        let s = EpisodeSettings { record_timings: true, ..Default::default() };
        let scene = sphere();
        scene.keep_start_states(1);
        let start = objview_views::start_pose(3.0);
        let mut ep = Vec::new();
        for _ in 0..2 {
            let method = MethodInfo {
                name: "t".into(),
                family: Family::Classical,
                mode: ExecutionMode::Iterative,
                params: serde_json::json!({}),
            };
            ep.push(Episode::start(scene.clone(), s.clone(), method, Budget::Auto, 0, start).unwrap());
        }
        let (computed, copied) = (&ep[0].now.steps[0], &ep[1].now.steps[0]);
        assert!(computed.stage_seconds[0] > 0.0 && computed.stage_seconds[1] > 0.0);
        assert_eq!(copied.stage_seconds[..3], [0.0; 3]);
        assert!(copied.engine_seconds > 0.0 && copied.stage_seconds[3] == copied.engine_seconds);
        assert_eq!(copied.metrics, computed.metrics);
        assert_eq!(copied.fused_points, computed.fused_points);
    }
}
