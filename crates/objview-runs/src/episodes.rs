//! A batch of online episodes (SPEC §5): one planner, view space, budget and seed over a list
//! of objects, one result line each ([`objview_episode::EpisodeResult`]), resumable (objects
//! already in the results file are skipped), written in input order whatever the thread count.
//!
//! [`EpisodePlan`] is everything such a run is: `objview run` builds one from its arguments,
//! the demo builds several, benchmarks and training-data generation build their own. The
//! settings record of its lines ([`crate::record::RunRecord`]) identifies the run; a results
//! file of another run is refused ([`check_same_run`]) rather than silently "resumed".

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicUsize;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use objview_dataset::annotate::gt_cloud_path;
use objview_dataset::{drive, to_line, BatchSummary, ItemOutcome, ObjectRef, Progress, ResumableJsonl};
use objview_episode::{
    load_scene, run_episode, Budget, EpisodeResult, EpisodeSettings, ExecutionMode, Planner, Scene,
    SceneSource,
};
use objview_geom::normalize::Normalization;
use objview_geom::Pose;
use objview_views::ViewSpace;
use serde_json::{json, Value};

use crate::params::Params;
use crate::record::RunRecord;
use crate::RunError;
use objview_planners::registry::Registry;

/// One episode run over objects, fully resolved.
#[derive(Debug, Clone)]
pub struct EpisodePlan {
    /// The planner's name in the registry.
    pub planner: String,
    /// Its parameters (`--param NAME=VALUE`).
    pub params: Params,
    /// The view space.
    pub space: ViewSpace,
    /// The view-space name results record (`whole`, or a rule file's own name).
    pub space_name: String,
    /// The budget protocol.
    pub budget: Budget,
    /// The objects, in output order.
    pub objects: Vec<ObjectRef>,
    /// The results file (JSON Lines).
    pub out: PathBuf,
    /// The candidate set's name (`tammes-360`, a file).
    pub candidates_name: String,
    /// Its poses at the episode's view radius.
    pub candidates: Arc<Vec<Pose>>,
    /// The user seed (mixed per object, view space and budget).
    pub seed: u64,
    /// Parallel episodes (`None`: every core).
    pub threads: Option<usize>,
    /// How meshes are normalized.
    pub normalize: Normalization,
    /// Folder of ground-truth clouds `<uid>.{pcd,ply,npy,npz}`; `None`: sampled.
    pub gt_cloud_dir: Option<PathBuf>,
    /// Observable-reference cache folder; `None`: no disk cache.
    pub cache_dir: Option<PathBuf>,
    /// The start pose (object frame, normalized units, roll in radians).
    pub start_pose: Pose,
    /// Every episode constant (cap, checkpoints, enough-info rule, timings on/off).
    pub settings: EpisodeSettings,
    /// Redo objects whose earlier line is a failure.
    pub retry_failed: bool,
}

/// Counts of a finished run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// Episodes run now that gave a result.
    pub done: usize,
    /// Objects whose episode could not run (failure lines).
    pub failed: usize,
    /// Objects already in the results file.
    pub skipped: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl RunSummary {
    /// From the batch driver's counts and the start time.
    pub fn from_batch(s: &BatchSummary, started: Instant) -> RunSummary {
        RunSummary {
            done: s.processed - s.failed,
            failed: s.failed,
            skipped: s.skipped,
            seconds: started.elapsed().as_secs_f64(),
        }
    }
}

impl EpisodePlan {
    /// A rough relative cost of one episode of this plan, used only to start the heavier plans
    /// of [`run_plans`] first (it changes no result): views × (100 + feasible candidates).
    /// Views: K + 1 for a fixed budget; with the automatic one, the largest checkpoint + 1 when
    /// the enough-info stop is on (iterative runs stop there), else the cap. The candidate term:
    /// iterative planners score every feasible candidate each step and plans solve over them,
    /// so a step's planner work grows with their number; the 100 stands for the engine's own
    /// step. Measured in the demo (2026-12-04, s per episode): whole-space auto runs of `rse`,
    /// `rse-mov`, `completion-nbv` 10–12 s (estimate 31 × 460), `completion-mcp` K=30 12 s
    /// (31 × 460), quarter-space auto runs 4–5 s (31 × 191), K=5 runs 1–2 s (6 × 460).
    /// Cheap planners are overestimated (e.g. `random-tsp` K=30, 2 s), which only starts them
    /// early; no long run is underestimated into the tail.
    pub fn work_estimate(&self) -> f64 {
        let s = &self.settings;
        let views = match self.budget {
            Budget::Fixed(k) => k + 1,
            Budget::Auto if s.enough_info => s.checkpoint_ks.iter().max().map_or(s.cap, |&k| k + 1),
            Budget::Auto => s.cap,
        }
        .min(s.cap);
        let feasible = self.space.feasible_mask(&self.candidates).into_iter().filter(|&f| f).count();
        views as f64 * (100 + feasible) as f64
    }

    /// A plan with the SPEC defaults for everything but the planner, objects and output:
    /// view space `whole`, budget `auto`, candidates `tammes-360`, seed 0, every core, unit
    /// normalization, sampled ground truth, the default reference cache, the default start
    /// pose and the default episode settings.
    pub fn new(planner: &str, objects: Vec<ObjectRef>, out: PathBuf) -> Result<EpisodePlan, RunError> {
        let settings = EpisodeSettings::default();
        let space =
            ViewSpace::builtin("whole").ok_or_else(|| RunError::Invalid("no view space whole".into()))?;
        let candidates = objview_views::ViewSet::resolve("tammes-360")
            .map_err(|e| RunError::Invalid(format!("tammes-360: {e}")))?
            .poses(settings.view_radius);
        Ok(EpisodePlan {
            planner: planner.to_string(),
            params: Vec::new(),
            space,
            space_name: "whole".into(),
            budget: Budget::Auto,
            objects,
            out,
            candidates_name: "tammes-360".into(),
            candidates: Arc::new(candidates),
            seed: 0,
            threads: None,
            normalize: Normalization::Unit,
            gt_cloud_dir: None,
            cache_dir: Some(crate::cache::default_reference_cache()),
            start_pose: objview_views::start_pose(settings.view_radius),
            settings,
            retry_failed: false,
        })
    }

    /// What the batch is called in progress output: `run rse / whole / budget auto`.
    pub fn label(&self) -> String {
        format!("run {} / {} / budget {}", self.planner, self.space_name, self.budget.label())
    }

    /// Checks what can be checked before any episode: the planner and its parameters, the
    /// budget against its execution mode, the settings, the start pose's feasibility, the
    /// ground-truth folder. Returns a probe planner (for its recorded parameters).
    pub fn validate(&self, planners: &Registry) -> Result<Box<dyn Planner>, RunError> {
        let probe = planners.with_params(&self.planner, &self.params).map_err(RunError::Invalid)?;
        check_budget(&self.planner, probe.as_ref(), self.budget)?;
        self.settings.validate().map_err(RunError::Invalid)?;
        if !self.space.is_feasible(&self.start_pose) {
            return Err(RunError::Invalid(format!(
                "the start pose is not feasible in view space {}",
                self.space_name
            )));
        }
        if let Some(dir) = &self.gt_cloud_dir {
            if !dir.is_dir() {
                return Err(RunError::Invalid(format!("{}: --gt-cloud-dir is not a folder", dir.display())));
            }
        }
        Ok(probe)
    }

    /// Validates the plan and returns the settings record of its lines, checked against the
    /// results file's existing lines (a different run there is an error).
    pub fn checked_record(&self, planners: &Registry) -> Result<Value, RunError> {
        let probe = self.validate(planners)?;
        let record = self.record(probe.as_ref());
        check_same_run(&self.out, &record)?;
        Ok(record)
    }

    /// The settings record of this run's lines.
    pub fn record(&self, probe: &dyn Planner) -> Value {
        RunRecord {
            planner: &self.planner,
            planner_params: probe.params(),
            view_space: &self.space_name,
            space: &self.space,
            budget: self.budget,
            seed: self.seed,
            candidates: &self.candidates_name,
            candidate_count: self.candidates.len(),
            start_pose: self.start_pose,
            normalize: self.normalize,
            settings: &self.settings,
        }
        .to_json()
    }

    /// One episode of `obj` with a fresh planner; `record` is [`EpisodePlan::record`].
    pub fn episode(
        &self,
        obj: &ObjectRef,
        planners: &Registry,
        record: &Value,
    ) -> Result<EpisodeResult, RunError> {
        self.episode_on(Arc::new(self.scene(obj)?), planners, record)
    }

    /// [`EpisodePlan::episode`] on a scene already built by [`EpisodePlan::scene`] (the same
    /// result: an episode only reads its scene).
    pub fn episode_on(
        &self,
        scene: Arc<Scene>,
        planners: &Registry,
        record: &Value,
    ) -> Result<EpisodeResult, RunError> {
        let mut planner = planners.with_params(&self.planner, &self.params).map_err(RunError::Invalid)?;
        Ok(run_episode(
            scene,
            planner.as_mut(),
            &self.settings,
            self.budget,
            self.seed,
            self.start_pose,
            self.candidates.clone(),
            record.clone(),
        )?)
    }

    /// The batch item of `obj`: its episode's line, or a failure line when it could not run.
    pub fn item(&self, obj: &ObjectRef, planners: &Registry, record: &Value) -> ItemOutcome {
        self.outcome(obj, self.episode(obj, planners, record), record)
    }

    /// The batch item of `obj` from its episode's outcome.
    fn outcome(&self, obj: &ObjectRef, res: Result<EpisodeResult, RunError>, record: &Value) -> ItemOutcome {
        match res {
            Ok(res) => episode_item(&res),
            Err(e) => failure_item(obj, "mesh", &obj.mesh.display().to_string(), &e.to_string(), record),
        }
    }

    /// Everything [`EpisodePlan::scene`] depends on, as one string: plans with equal keys
    /// build equal scenes of `obj` (`None` when the ground-truth path cannot be resolved; that
    /// error is the episode's).
    fn scene_key(&self, obj: &ObjectRef) -> Option<String> {
        let gt = gt_cloud_path(obj, self.gt_cloud_dir.as_deref()).ok()?;
        Some(format!(
            "{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
            obj.uid, obj.mesh, gt, self.normalize, self.space_name, self.space, self.settings, self.cache_dir
        ))
    }

    /// The scene of `obj` as this plan's episodes see it (building and caching its observable
    /// reference when the plan has a cache folder that lacks it).
    pub fn scene(&self, obj: &ObjectRef) -> Result<Scene, RunError> {
        let gt = gt_cloud_path(obj, self.gt_cloud_dir.as_deref())?;
        let src = SceneSource {
            uid: &obj.uid,
            mesh: &obj.mesh,
            gt_cloud: gt.as_deref(),
            normalization: self.normalize,
        };
        Ok(load_scene(&src, &self.space, &self.space_name, &self.settings, self.cache_dir.as_deref())?)
    }

    /// Runs the plan's episodes into its results file.
    pub fn run(&self, planners: &Registry, progress: &dyn Progress) -> Result<RunSummary, RunError> {
        let t = Instant::now();
        let record = self.checked_record(planners)?;
        let work = |obj: &ObjectRef| self.item(obj, planners, &record);
        let summary = self.drive(&self.objects, &self.space_name, work, progress)?;
        Ok(RunSummary::from_batch(&summary, t))
    }

    /// The batch driver over `objects` into this plan's results file (shared with runs whose
    /// episodes happen elsewhere, e.g. on an evaluation server).
    pub fn drive(
        &self,
        objects: &[ObjectRef],
        space_name: &str,
        work: impl Fn(&ObjectRef) -> ItemOutcome + Sync,
        progress: &dyn Progress,
    ) -> Result<BatchSummary, RunError> {
        let (out, existing) = ResumableJsonl::open(&self.out, "uid", self.retry_failed)?;
        let what = format!("run {} / {} / budget {}", self.planner, space_name, self.budget.label());
        Ok(drive(&what, None, None, objects, out, &existing, self.threads, work, progress)?)
    }
}

/// A scene shared by the episodes of [`run_plans`] with one scene key: built on first use, kept
/// while episodes that need it are left. Generic over the value, so that it is tested without
/// building scenes.
struct Shared<T> {
    slot: Mutex<Slot<T>>,
    /// Episodes of this key not finished yet.
    left: AtomicUsize,
}

type SharedScene = Shared<Scene>;

impl<T> Default for Shared<T> {
    fn default() -> Self {
        Shared { slot: Mutex::new(Slot::Empty), left: AtomicUsize::new(0) }
    }
}

enum Slot<T> {
    Empty,
    /// An episode is building it.
    Building,
    /// Built (or the error building it gave: every episode of the key fails with it).
    Ready(Result<Arc<T>, String>),
}

impl<T> Shared<T> {
    /// The scene, built by `build` if no episode has built it yet. No lock is held while
    /// building, and nothing waits for a build: an episode that comes while another one builds
    /// the scene builds its own copy (the same scene). Waiting would be unsafe inside a rayon
    /// job: the builder may be this very thread, suspended in a parallel loop of the build,
    /// which let it take up this episode meanwhile. In a run, an object's first episodes are
    /// several episodes apart in the queue, so copies are rare.
    fn get(&self, build: impl FnOnce() -> Result<T, RunError>) -> Result<Arc<T>, RunError> {
        let lock = || self.slot.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        {
            let mut slot = lock();
            match &*slot {
                Slot::Ready(r) => return r.clone().map_err(RunError::Invalid),
                Slot::Building => {
                    drop(slot);
                    return build().map(Arc::new);
                }
                Slot::Empty => *slot = Slot::Building,
            }
        }
        let built = build().map(Arc::new).map_err(|e| e.to_string());
        // This episode has not called `done` yet, so the slot is still wanted.
        *lock() = Slot::Ready(built.clone());
        built.map_err(RunError::Invalid)
    }

    /// One episode of this key is done: the last one drops the scene.
    fn done(&self) {
        if self.left.fetch_sub(1, std::sync::atomic::Ordering::AcqRel) == 1 {
            *self.slot.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Slot::Empty;
        }
    }
}

/// Runs several plans as one batch ([`objview_dataset::run_batches`]): the episodes of every
/// plan share one pool of `threads` workers (`None`: every core), so the cores stay busy across
/// plans; each plan's results file is the one [`EpisodePlan::run`] would write (same lines,
/// same order). The episodes of one object in one view space share its scene (built once, by
/// the first of them; see `SharedScene`), so that no two episodes build the same observable
/// reference or target indexes. The episodes of the plans with the largest
/// [`EpisodePlan::work_estimate`] start first, so that the run ends on short episodes instead
/// of one long one with the other cores idle. Each summary's `seconds` is the sum of its plan's
/// episode times, scene builds included (they ran interleaved).
pub fn run_plans(
    plans: &[EpisodePlan],
    planners: &Registry,
    threads: Option<usize>,
) -> Result<Vec<RunSummary>, RunError> {
    let threads = objview_dataset::batch::thread_count(threads)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RunError::Invalid(format!("thread pool: {e}")))?;
    let mut records = Vec::with_capacity(plans.len());
    let mut outs = Vec::with_capacity(plans.len());
    let mut existing = Vec::with_capacity(plans.len());
    for plan in plans {
        records.push(plan.checked_record(planners)?);
        let (out, ex) = ResumableJsonl::open(&plan.out, "uid", plan.retry_failed)?;
        outs.push(out);
        existing.push(ex);
    }
    // The scene of an object in a view space is built once, by the first episode that needs it,
    // shared by every episode of the plans with the same scene key (their episodes only read
    // it), and dropped when the last of them is done: the mesh, the ground truth, the observable
    // reference and the targets' indexes are not rebuilt per episode, and no two episodes build
    // the same reference at once.
    // Each key is computed once, here: per plan, the shared scene of each object to run.
    let mut by_key: HashMap<String, Arc<SharedScene>> = HashMap::new();
    let mut scene_of: Vec<HashMap<&str, Arc<SharedScene>>> = Vec::with_capacity(plans.len());
    for (plan, ex) in plans.iter().zip(&existing) {
        let mut of_plan = HashMap::new();
        for obj in plan.objects.iter().filter(|o| !ex.done.contains(&o.uid)) {
            if let Some(key) = plan.scene_key(obj) {
                let sh = by_key.entry(key).or_default();
                sh.left.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                of_plan.insert(obj.uid.as_str(), sh.clone());
            }
        }
        scene_of.push(of_plan);
    }
    let busy: Vec<std::sync::Mutex<f64>> = plans.iter().map(|_| std::sync::Mutex::new(0.0)).collect();
    let summaries = pool.install(|| {
        let batches = plans
            .iter()
            .zip(outs)
            .zip(&existing)
            .map(|((plan, out), existing)| objview_dataset::Batch {
                items: &plan.objects,
                out,
                existing,
                weight: plan.work_estimate(),
            })
            .collect();
        objview_dataset::run_batches(
            batches,
            |b, obj| {
                let t = Instant::now();
                let plan = &plans[b];
                let outcome = match scene_of[b].get(obj.uid.as_str()) {
                    Some(sh) => {
                        let scene = sh.get(|| plan.scene(obj));
                        let res = scene.and_then(|scene| plan.episode_on(scene, planners, &records[b]));
                        sh.done();
                        plan.outcome(obj, res, &records[b])
                    }
                    None => plan.item(obj, planners, &records[b]),
                };
                *busy[b].lock().unwrap_or_else(std::sync::PoisonError::into_inner) +=
                    t.elapsed().as_secs_f64();
                outcome
            },
            |_, _, _| {},
        )
    })?;
    Ok(summaries
        .iter()
        .zip(busy)
        .map(|(s, b)| RunSummary {
            done: s.processed - s.failed,
            failed: s.failed,
            skipped: s.skipped,
            seconds: b.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner),
        })
        .collect())
}

/// A budgeted-plan planner needs a fixed budget.
pub fn check_budget(name: &str, planner: &dyn Planner, budget: Budget) -> Result<(), RunError> {
    if planner.execution_mode() == ExecutionMode::BudgetedPlan && budget == Budget::Auto {
        return Err(RunError::Invalid(format!(
            "--planner {name} is a budgeted plan: give a fixed --budget K (e.g. 5 or 30), not auto"
        )));
    }
    Ok(())
}

/// The progress note of an episode: `7 views, NSC@0.02 0.912, SC@0.02 0.871, path 9.42,
/// plan_end (algorithm_stop)` (at its terminal checkpoint).
pub fn episode_note(res: &EpisodeResult) -> String {
    let source = res.terminal_source;
    match res.checkpoints.get(&objview_episode::CheckpointKey::Terminal) {
        Some(t) => format!(
            "{} views, NSC@0.02 {:.3}, SC@0.02 {:.3}, path {:.2}, {} ({source})",
            t.metrics.views,
            t.metrics.nsc.get("0.02").copied().unwrap_or(f64::NAN),
            t.metrics.sc.get("0.02").copied().unwrap_or(f64::NAN),
            t.metrics.path_cost,
            res.terminal_reason,
        ),
        None => format!("{} ({source})", res.terminal_reason),
    }
}

/// The batch item of a finished episode: its line and note.
pub fn episode_item(res: &EpisodeResult) -> ItemOutcome {
    ItemOutcome { line: to_line(res), failed: false, note: episode_note(res) }
}

/// The failure line of an object whose episode could not run: `{"uid", <where_key>: <where>,
/// "error", "settings"}` (`where_key` is `mesh` locally, `split` on a server).
pub fn failure_item(
    obj: &ObjectRef,
    where_key: &str,
    place: &str,
    error: &str,
    record: &Value,
) -> ItemOutcome {
    let error = error.replace('\n', " ");
    let mut line = json!({"uid": obj.uid, "error": error, "settings": record});
    line[where_key] = json!(place);
    ItemOutcome { line: to_line(&line), failed: true, note: error }
}

/// Refuses to resume a results file written by a different run (planner, parameters, view
/// space, budget, seed, candidates, start pose or episode settings), which would otherwise
/// silently skip its objects. Lines that lack a key (remote runs' and failure lines know only
/// part of the record) do not decide it; timings on or off do not change what an episode is.
pub fn check_same_run(out: &Path, record: &Value) -> Result<(), RunError> {
    let Ok(text) = std::fs::read_to_string(out) else { return Ok(()) };
    for (i, line) in text.lines().enumerate() {
        let Ok(v) = serde_json::from_str::<Value>(line) else { continue };
        let old = &v["settings"];
        for key in [
            "planner",
            "planner_params",
            "view_space",
            "budget",
            "seed",
            "candidates",
            "start_pose",
            "episode",
        ] {
            let mut a = old[key].clone();
            let mut b = record[key].clone();
            if a.is_null() || b.is_null() {
                continue;
            }
            if key == "episode" {
                for x in [&mut a, &mut b] {
                    if let Some(m) = x.as_object_mut() {
                        m.remove("record_timings");
                    }
                }
            }
            if a != b {
                return Err(RunError::Invalid(format!(
                    "{}:{}: this results file holds another run ({key} = {a} here, {b} now); use another --out",
                    out.display(),
                    i + 1
                )));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shared_value_is_built_once_shared_and_dropped_after_the_last_user() {
        let sh: Shared<String> = Shared::default();
        sh.left.store(3, std::sync::atomic::Ordering::Relaxed);
        let builds = std::cell::Cell::new(0);
        let build = || {
            builds.set(builds.get() + 1);
            Ok::<_, RunError>(format!("scene {}", builds.get()))
        };
        let a = sh.get(build).unwrap();
        let b = sh.get(build).unwrap();
        assert!(Arc::ptr_eq(&a, &b), "the second user gets the first build");
        assert_eq!((builds.get(), a.as_str()), (1, "scene 1"));
        sh.done();
        sh.done();
        assert!(matches!(*sh.slot.lock().unwrap(), Slot::Ready(_)), "one user is left");
        sh.done();
        assert!(matches!(*sh.slot.lock().unwrap(), Slot::Empty), "dropped after the last user");
        // While a build is under way, a second user builds its own copy instead of waiting.
        *sh.slot.lock().unwrap() = Slot::Building;
        let c = sh.get(build).unwrap();
        assert_eq!((builds.get(), c.as_str()), (2, "scene 2"));
        assert!(matches!(*sh.slot.lock().unwrap(), Slot::Building), "the builder's slot is left alone");
    }

    #[test]
    fn a_failed_build_fails_every_user_with_its_message() {
        let sh: Shared<String> = Shared::default();
        sh.left.store(2, std::sync::atomic::Ordering::Relaxed);
        let builds = std::cell::Cell::new(0);
        let build = || {
            builds.set(builds.get() + 1);
            Err::<String, _>(RunError::Invalid("x.obj: no faces".into()))
        };
        let e1 = sh.get(build).unwrap_err().to_string();
        let e2 = sh.get(build).unwrap_err().to_string();
        assert_eq!((e1.as_str(), e2.as_str(), builds.get()), ("x.obj: no faces", "x.obj: no faces", 1));
    }

    #[test]
    fn work_estimate_is_views_times_feasible_candidates_plus_the_engine() {
        let mut p = EpisodePlan::new("rse", Vec::new(), PathBuf::from("x.jsonl")).unwrap();
        p.settings.checkpoint_ks = vec![5, 30];
        // tammes-360: 360 feasible in `whole`, 91 in `quarter` (SPEC's feasibility counts).
        assert_eq!(p.work_estimate(), 31.0 * 460.0);
        p.budget = Budget::Fixed(5);
        assert_eq!(p.work_estimate(), 6.0 * 460.0);
        p.budget = Budget::Fixed(500);
        assert_eq!(p.work_estimate(), 129.0 * 460.0, "at most the cap");
        p.budget = Budget::Auto;
        p.settings.enough_info = false;
        assert_eq!(p.work_estimate(), 129.0 * 460.0, "no enough-info stop: the cap");
        p.settings.enough_info = true;
        p.space = ViewSpace::builtin("quarter").unwrap();
        assert_eq!(p.work_estimate(), 31.0 * 191.0);
        p.settings.checkpoint_ks.clear();
        assert_eq!(p.work_estimate(), 129.0 * 191.0, "no checkpoint: the cap");
    }

    #[test]
    fn another_run_is_refused_and_timings_or_missing_keys_do_not_count() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("r.jsonl");
        let rec = json!({"planner": "rse", "seed": 1, "episode": {"cap": 129, "record_timings": true}});
        check_same_run(&out, &rec).unwrap(); // no file yet
        let old = json!({"uid": "a", "settings": {"planner": "rse", "seed": 1, "episode": {"cap": 129, "record_timings": false}}});
        let partial = json!({"uid": "b", "error": "x", "settings": {"planner": "rse"}});
        std::fs::write(&out, format!("{old}\n{partial}\n")).unwrap();
        check_same_run(&out, &rec).unwrap();
        let other = json!({"planner": "rse", "seed": 2, "episode": {"cap": 129}});
        let e = check_same_run(&out, &other).unwrap_err().to_string();
        assert!(e.contains("r.jsonl:1: this results file holds another run (seed = 1 here, 2 now)"), "{e}");
    }

    #[test]
    fn plans_run_together_write_what_each_writes_alone() {
        let dir = tempfile::tempdir().unwrap();
        let mut objects = Vec::new();
        for name in ["cube", "cone"] {
            let path = dir.path().join(format!("{name}.obj"));
            objview_geom::write::write_obj(&path, &objview_geom::synth::build_with_triangles(name, 800))
                .unwrap();
            objects.push(ObjectRef::from_mesh(&path));
        }
        let plans_in = |sub: &str| -> Vec<EpisodePlan> {
            let out = dir.path().join(sub);
            std::fs::create_dir_all(&out).unwrap();
            [("random-tsp", "whole", Budget::Fixed(5)), ("random", "quarter", Budget::Fixed(3))]
                .iter()
                .map(|&(planner, space, budget)| {
                    let mut p =
                        EpisodePlan::new(planner, objects.clone(), out.join(format!("{planner}.jsonl")))
                            .unwrap();
                    p.space = ViewSpace::builtin(space).unwrap();
                    p.space_name = space.into();
                    p.budget = budget;
                    p.settings.record_timings = false;
                    p.cache_dir = Some(dir.path().join("cache"));
                    p
                })
                .collect()
        };
        let planners = Registry::builtin();
        let alone = plans_in("alone");
        for p in &alone {
            let s = p.run(&planners, &objview_dataset::Silent).unwrap();
            assert_eq!((s.done, s.failed), (2, 0));
        }
        // Together, with the first episode of the second plan already in its file.
        let together = plans_in("together");
        let first = std::fs::read_to_string(&alone[1].out).unwrap();
        std::fs::write(&together[1].out, format!("{}\n", first.lines().next().unwrap())).unwrap();
        let s = run_plans(&together, &planners, Some(2)).unwrap();
        assert_eq!(
            s.iter().map(|s| (s.done, s.failed, s.skipped)).collect::<Vec<_>>(),
            [(2, 0, 0), (1, 0, 1)]
        );
        assert!(s.iter().all(|s| s.seconds > 0.0));
        for (a, t) in alone.iter().zip(&together) {
            let (a, t) = (std::fs::read_to_string(&a.out).unwrap(), std::fs::read_to_string(&t.out).unwrap());
            assert_eq!(a.lines().count(), 2);
            assert_eq!(a, t);
        }
    }

    #[test]
    fn a_budgeted_plan_needs_a_fixed_budget() {
        let p = objview_planners::registry::by_name("random-tsp").unwrap();
        assert!(check_budget("random-tsp", p.as_ref(), Budget::Auto)
            .unwrap_err()
            .to_string()
            .contains("fixed --budget"));
        check_budget("random-tsp", p.as_ref(), Budget::Fixed(5)).unwrap();
        let it = objview_planners::registry::by_name("rse").unwrap();
        check_budget("rse", it.as_ref(), Budget::Auto).unwrap();
    }
}
