//! Episodes in memory: the server's shared state and every episode operation the routes call.
//!
//! Each episode lives in a [`Slot`] behind its own `std::sync::Mutex`; the operations here are
//! blocking (engine work: rendering, fusion, metrics; database writes) and the routes run them
//! on tokio's blocking pool, never holding a lock across an `.await`. An action checks the step
//! under the episode's lock, so of two concurrent actions for one step exactly one is applied.
//! Lock order: the episode table, then one episode, then the database.
//!
//! The create request an episode starts from is [`crate::request`]; the protocol's names and
//! limits are [`crate::protocol`].
//!
//! Hidden means hidden: nothing built here for a running episode carries geometry, ground truth,
//! reference points, coverage, CD or a number derived from them, except `metrics` on public
//! splits; file paths never leave the server.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use objview_episode::{Action, Episode, EpisodeSettings, MethodInfo, Scene, TerminalSource};
use objview_geom::Pose;
use objview_render::Camera;
use objview_views::{ViewSet, ViewSpace};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::auth::{Caller, Tokens};
use crate::db::{ActionRow, Db, EpisodeRow};
use crate::error::{ApiError, ServerError};
use crate::lanes::Lanes;
use crate::pool::{ObjectKey, Pool, SceneCache};
use crate::protocol::{CANDIDATE_SETS, VIEW_SPACES};
use crate::request::CreateSpec;
use objview_runs::record::RunRecord;

/// How an episode ended, as the API shows it (read back from stored result lines as written).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TerminalInfo {
    /// The terminal source (`algorithm_stop`, `benchmark`, `exception`).
    pub source: String,
    /// The terminal reason.
    pub reason: String,
    /// Its detail.
    pub detail: String,
}

/// What is kept of a finished episode (read back from its result line on first use).
#[derive(Debug, Clone)]
struct Finished {
    history: Vec<[f64; 7]>,
    terminal: TerminalInfo,
}

impl Finished {
    fn from_line(line: &str) -> Result<Finished, ApiError> {
        let v: Value =
            serde_json::from_str(line).map_err(|e| ApiError::Internal(format!("stored result: {e}")))?;
        let history: Vec<[f64; 7]> = serde_json::from_value(v["visited_poses"].clone())
            .map_err(|e| ApiError::Internal(format!("stored result: {e}")))?;
        let s = |k: &str| v[k].as_str().unwrap_or_default().to_string();
        Ok(Finished {
            history,
            terminal: TerminalInfo {
                source: s("terminal_source"),
                reason: s("terminal_reason"),
                detail: s("terminal_detail"),
            },
        })
    }

    fn obs(&self) -> Value {
        obs_json(self.history.len().saturating_sub(1), self.history.last().copied(), Some(&self.terminal))
    }
}

struct Running {
    ep: Episode,
    record: Value,
    /// When the current observation was produced.
    obs_at: Instant,
    /// When the client loses the episode.
    deadline: Instant,
    /// Actions applied so far (they are stored in the database; replay reads them there).
    applied: usize,
}

impl Running {
    fn step(&self) -> usize {
        self.ep.history().len() - 1
    }

    fn pose(&self) -> Option<[f64; 7]> {
        self.ep.history().last().map(|p| p.to_array())
    }

    fn obs(&self) -> Value {
        let t = self.ep.terminal().map(|t| TerminalInfo {
            source: t.source.to_string(),
            reason: t.reason.clone(),
            detail: t.detail.clone(),
        });
        obs_json(self.step(), self.pose(), t.as_ref())
    }
}

enum Live {
    Running(Box<Running>),
    /// Finished; the summary is read from the database on first use.
    Finished(Option<Box<Finished>>),
}

/// One episode.
pub struct Slot {
    /// `e-` and 16 hex digits.
    pub id: String,
    /// Its owner (a token's hash; empty without tokens).
    pub owner: String,
    /// What it was created with.
    pub spec: CreateSpec,
    /// When it was created (RFC 3339 UTC, as stored).
    pub created_at: String,
    /// Its creation order (the database row id).
    pub seq: i64,
    /// Actions received and not yet answered: while there are some, only they may end the
    /// episode at its time limit (each judged by when it arrived, not by when the engine got
    /// to it).
    in_flight: AtomicUsize,
    live: Mutex<Live>,
}

/// Counts an action in flight on a [`Slot`] until dropped.
pub struct InFlight(Arc<Slot>);

impl InFlight {
    /// Marks an action as received on `slot`.
    pub fn new(slot: Arc<Slot>) -> InFlight {
        slot.in_flight.fetch_add(1, Ordering::SeqCst);
        InFlight(slot)
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// OBS: `{"step", "pose", "intrinsics", "done", "terminal"}`.
fn obs_json(step: usize, pose: Option<[f64; 7]>, terminal: Option<&TerminalInfo>) -> Value {
    json!({"step": step, "pose": pose, "intrinsics": intrinsics_json(),
           "done": terminal.is_some(), "terminal": terminal})
}

/// The camera intrinsics of every observation (SPEC §2; every scene uses them).
fn intrinsics_json() -> Value {
    serde_json::to_value(objview_render::Intrinsics::default()).unwrap_or(Value::Null)
}

/// Applies one raw action as received: an `action` that is not a well-formed move or stop ends
/// the episode with `benchmark` / `invalid_action` (SPEC §5), like the engine does for a bad
/// pose or reason. The same function replays stored actions after a restart.
pub fn apply_raw(ep: &mut Episode, action: &Value, planner_seconds: f64) {
    match serde_json::from_value::<Action>(action.clone()) {
        Ok(a) => ep.apply(&a, planner_seconds),
        Err(e) => {
            ep.add_runtime(planner_seconds);
            ep.end(TerminalSource::Benchmark, "invalid_action", format!("malformed action: {e}"));
        }
    }
}

/// The stored line of a finished episode (without its newline): its result line, or — should a
/// number of the result be NaN or infinite, which JSON would write as `null` and no reader of
/// results accepts — a failure line (`error`, as `objview run` writes for an episode that could
/// not run) that still has the episode's keys, `settings`, `visited_poses` and terminal fields.
pub fn result_line(id: &str, res: &objview_episode::EpisodeResult) -> String {
    let Some(field) = res.non_finite() else {
        return objview_dataset::to_line(res).trim_end().to_string();
    };
    eprintln!(
        "objview serve: episode {id}: the result has a non-finite number at `{field}`; stored as a failure"
    );
    json!({
        "uid": res.uid,
        "method": res.method,
        "family": res.family,
        "execution_mode": res.execution_mode,
        "view_space": res.view_space,
        "budget": res.budget,
        "seed": res.seed,
        "settings": res.settings,
        "visited_poses": res.visited_poses,
        "terminal_source": res.terminal_source,
        "terminal_reason": res.terminal_reason,
        "terminal_detail": res.terminal_detail,
        "error": format!("the result has a non-finite number at `{field}`; it is not recorded as a result"),
    })
    .to_string()
}

/// An episode's state as `GET /v1/episodes` shows and filters it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EpisodeState {
    /// Waiting for an action.
    Running,
    /// Ended (its result is stored).
    Finished,
}

impl EpisodeState {
    /// Every state, in the order the docs name them.
    pub const ALL: [EpisodeState; 2] = [EpisodeState::Running, EpisodeState::Finished];

    /// `running` or `finished`.
    pub fn as_str(self) -> &'static str {
        match self {
            EpisodeState::Running => "running",
            EpisodeState::Finished => "finished",
        }
    }

    /// Parses `running` / `finished`.
    pub fn parse(s: &str) -> Option<EpisodeState> {
        EpisodeState::ALL.into_iter().find(|x| x.as_str() == s)
    }
}

/// The current view: its step, pose and (while running) the engine's depth.
type CurrentView = (usize, Pose, Option<Arc<Vec<f32>>>);

/// An RGB view: its step, width, height and RGB8 pixels (row-major).
pub type RgbView = (usize, u32, u32, Vec<[u8; 3]>);

/// Server settings.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Wait for each action after an observation.
    pub action_timeout: Duration,
    /// Wait for the first action after the create response.
    pub start_timeout: Duration,
    /// Wait for a request body once its head arrived (408 after it).
    pub body_timeout: Duration,
    /// Running episodes at most, in all.
    pub max_running: usize,
    /// Running episodes at most per owner (token), on a server with tokens.
    pub max_running_per_token: usize,
    /// Connection cap and the header and idle limits ([`crate::conn`]).
    pub conn: crate::conn::ConnLimits,
}

/// The server's shared state.
pub struct AppState {
    /// The splits.
    pub pool: Pool,
    /// Prepared scenes.
    pub scenes: SceneCache,
    /// Persistence.
    pub db: Db,
    /// Bearer tokens (none: open server).
    pub tokens: Option<Tokens>,
    /// Time limits.
    pub limits: Limits,
    /// Engine work (starting episodes, applying actions, rendering on request) waits here in
    /// one queue, first come first served, for one of as many lanes as there are cores
    /// ([`crate::lanes`]), so that many clients queue rather than slow every step down together.
    pub engine_lanes: Lanes,
    /// The open connections (their count, evictions and refusals).
    pub connections: Arc<crate::conn::Registry>,
    candidate_sets: BTreeMap<String, Arc<Vec<Pose>>>,
    spaces: BTreeMap<String, ViewSpace>,
    episodes: Mutex<HashMap<String, Arc<Slot>>>,
    /// Running episodes, in all and per owner: a place is taken when a create starts and given
    /// back when it fails or when the episode finishes ([`AppState::finish`], the one way out
    /// of running).
    running: Mutex<RunningCount>,
}

/// See [`AppState::running`].
#[derive(Debug, Default)]
struct RunningCount {
    total: usize,
    by_owner: HashMap<String, usize>,
}

/// A running place taken for a create: given back on drop unless kept (the episode then holds
/// it until [`AppState::finish`]).
struct Place<'a> {
    state: &'a AppState,
    owner: &'a str,
    kept: bool,
}

impl Place<'_> {
    fn keep(mut self) {
        self.kept = true;
    }
}

impl Drop for Place<'_> {
    fn drop(&mut self) {
        if !self.kept {
            self.state.release_running(self.owner);
        }
    }
}

/// A fresh episode id: `e-` and 16 random hex digits.
fn new_id() -> String {
    format!("e-{:016x}", rand::random::<u64>())
}

fn internal(context: &str, e: impl std::fmt::Display) -> ApiError {
    eprintln!("objview serve: {context}: {e}");
    ApiError::Internal(format!("{context} failed (see the server log)"))
}

impl AppState {
    /// The state over `pool`, `db` and `tokens`; finishes (replays) the episodes the database
    /// holds as running, ending them `exception` / `interrupted`.
    pub fn new(
        pool: Pool,
        scenes: SceneCache,
        db: Db,
        tokens: Option<Tokens>,
        limits: Limits,
    ) -> Result<AppState, ServerError> {
        let mut candidate_sets = BTreeMap::new();
        for name in CANDIDATE_SETS {
            let vs = ViewSet::resolve(name).map_err(|e| ServerError::Config(e.to_string()))?;
            candidate_sets.insert(name.to_string(), Arc::new(vs.poses(objview_geom::pose::VIEW_RADIUS)));
        }
        let spaces =
            VIEW_SPACES.iter().filter_map(|n| ViewSpace::builtin(n).map(|s| (n.to_string(), s))).collect();
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let state = AppState {
            pool,
            scenes,
            db,
            tokens,
            limits,
            engine_lanes: Lanes::new(cores)?,
            connections: Arc::default(),
            candidate_sets,
            spaces,
            episodes: Mutex::default(),
            running: Mutex::default(),
        };
        state.recover()?;
        Ok(state)
    }

    /// The poses of a candidate set (radius 3, look-at 0).
    pub fn candidate_set(&self, name: &str) -> Option<&Arc<Vec<Pose>>> {
        self.candidate_sets.get(name)
    }

    fn recover(&self) -> Result<(), ServerError> {
        let db_err = |e: crate::db::DbError| ServerError::Db {
            path: self.db.path().display().to_string(),
            reason: e.to_string(),
        };
        for row in self.db.episodes().map_err(db_err)? {
            let bad = |reason: String| ServerError::Recovery { id: row.id.clone(), reason };
            let spec: CreateSpec = serde_json::from_str(&row.request).map_err(|e| bad(e.to_string()))?;
            let live = if row.state == "running" {
                if self.pool.split(&spec.split).is_none() {
                    eprintln!(
                        "objview serve: episode {} was running on split {} that this server does not have; \
                         it stays unfinished",
                        row.id, spec.split
                    );
                    continue;
                }
                let (mut ep, record) = match self.scene_for(&spec).and_then(|sc| self.prepare(&spec, sc)) {
                    Ok(x) => x,
                    Err(e) => {
                        eprintln!(
                            "objview serve: episode {} cannot be replayed ({e}); it stays unfinished",
                            row.id
                        );
                        continue;
                    }
                };
                let actions = self.db.actions(&row.id).map_err(db_err)?;
                for a in &actions {
                    let v: Value = serde_json::from_str(&a.action).map_err(|e| bad(e.to_string()))?;
                    apply_raw(&mut ep, &v, a.planner_seconds);
                }
                ep.end(
                    TerminalSource::Exception,
                    "interrupted",
                    format!(
                        "the server stopped while the episode was running; {} stored actions replayed",
                        actions.len()
                    ),
                );
                let res = ep.finish(record);
                let line = result_line(&row.id, &res);
                self.db.record_end(&row.id, &row.owner, &row.method, &line).map_err(db_err)?;
                eprintln!(
                    "objview serve: episode {} ended as interrupted ({} views)",
                    row.id,
                    res.steps.len()
                );
                Live::Finished(Some(Box::new(Finished::from_line(&line).map_err(|e| bad(e.to_string()))?)))
            } else {
                Live::Finished(None)
            };
            let slot = Slot {
                id: row.id.clone(),
                owner: row.owner.clone(),
                spec,
                created_at: row.created_at.clone(),
                seq: row.seq,
                in_flight: AtomicUsize::new(0),
                live: Mutex::new(live),
            };
            lock(&self.episodes).insert(row.id.clone(), Arc::new(slot));
        }
        Ok(())
    }

    /// The prepared scene of `spec`'s object and view space, from the scene cache (seconds the
    /// first time, then a lookup). Blocking; the routes call it outside the engine queue.
    pub fn scene_for(&self, spec: &CreateSpec) -> Result<Arc<Scene>, ApiError> {
        let split = self
            .pool
            .split(&spec.split)
            .ok_or_else(|| ApiError::InvalidRequest(format!("unknown split {:?}", spec.split)))?;
        let obj = split.object(&ObjectKey::Uid(spec.object.clone())).ok_or_else(|| {
            ApiError::NotFound(format!("split {} has no object {:?}", spec.split, spec.object))
        })?;
        self.scenes.get(obj, &spec.view_space).map_err(|e| internal("preparing the object", e))
    }

    /// 429 `too_many_episodes` when a new episode of `owner` would exceed a cap on running
    /// episodes (a check only: [`AppState::create`] takes the place).
    pub fn check_running(&self, owner: &str) -> Result<(), ApiError> {
        self.room_for(&lock(&self.running), owner)
    }

    /// The running place of a new episode of `owner`, checked and taken under one lock.
    fn take_place<'a>(&'a self, owner: &'a str) -> Result<Place<'a>, ApiError> {
        let mut r = lock(&self.running);
        self.room_for(&r, owner)?;
        r.total += 1;
        *r.by_owner.entry(owner.to_string()).or_default() += 1;
        Ok(Place { state: self, owner, kept: false })
    }

    /// Ok when a new episode of `owner` fits under the caps, given the running count `r`; else
    /// the 429 that says which cap refuses it.
    fn room_for(&self, r: &RunningCount, owner: &str) -> Result<(), ApiError> {
        let (max, per) = (self.limits.max_running, self.limits.max_running_per_token);
        if r.total >= max {
            return Err(ApiError::TooManyEpisodes(format!(
                "{} episodes are running, the server's limit (--max-running {max}); finish or abort \
                 one, or wait for the time limits of idle ones",
                r.total
            )));
        }
        let mine = r.by_owner.get(owner).copied().unwrap_or(0);
        if self.tokens.is_some() && mine >= per {
            return Err(ApiError::TooManyEpisodes(format!(
                "{mine} episodes of this token are running, the server's limit per token \
                 (--max-running-per-token {per}); finish or abort one, or wait for the time limits \
                 of idle ones"
            )));
        }
        Ok(())
    }

    /// Gives back a place taken by [`AppState::take_place`].
    fn release_running(&self, owner: &str) {
        let mut r = lock(&self.running);
        r.total = r.total.saturating_sub(1);
        if let Some(n) = r.by_owner.get_mut(owner) {
            *n -= 1;
            if *n == 0 {
                r.by_owner.remove(owner);
            }
        }
    }

    /// Builds the episode of `spec` on its prepared `scene` (takes and scores the start view)
    /// and the settings record of its result.
    fn prepare(&self, spec: &CreateSpec, scene: Arc<Scene>) -> Result<(Episode, Value), ApiError> {
        let settings = EpisodeSettings {
            candidates: spec.candidate_set.clone(),
            record_timings: spec.record_timings,
            ..Default::default()
        };
        let candidates = self.candidate_sets.get(&spec.candidate_set).ok_or_else(|| {
            ApiError::InvalidRequest(format!("unknown candidate set {:?}", spec.candidate_set))
        })?;
        let budget = spec.budget;
        let start_pose = objview_views::start_pose(settings.view_radius);
        let record = RunRecord {
            planner: &spec.method,
            planner_params: spec.params.clone(),
            view_space: &spec.view_space,
            space: &scene.space,
            budget,
            seed: spec.seed,
            candidates: &spec.candidate_set,
            candidate_count: candidates.len(),
            start_pose,
            normalize: self.scenes.normalize(),
            settings: &settings,
        }
        .to_json();
        let method = MethodInfo {
            name: spec.method.clone(),
            family: spec.family,
            mode: spec.execution_mode,
            params: spec.params.clone(),
        };
        let ep = Episode::start(scene, settings, method, budget, spec.seed, start_pose)
            .map_err(|e| internal("starting the episode", e))?;
        Ok((ep, record))
    }

    /// The episode `id` if `owner` may see it.
    pub fn slot(&self, owner: &str, id: &str) -> Result<Arc<Slot>, ApiError> {
        lock(&self.episodes)
            .get(id)
            .filter(|s| s.owner == owner)
            .cloned()
            .ok_or_else(|| ApiError::NotFound(format!("no episode {id:?}")))
    }

    /// `POST /v1/episodes`: starts an episode on `scene` ([`AppState::scene_for`]), takes its
    /// start view, stores it; the 201 body.
    pub fn create(&self, owner: &str, spec: CreateSpec, scene: Arc<Scene>) -> Result<Value, ApiError> {
        // Given back unless the episode is stored as running — also if the engine panics.
        let place = self.take_place(owner)?;
        let created = self.create_running(owner, spec, scene)?;
        place.keep();
        Ok(created)
    }

    /// [`AppState::create`] once the episode's running place is taken.
    fn create_running(&self, owner: &str, spec: CreateSpec, scene: Arc<Scene>) -> Result<Value, ApiError> {
        let (ep, record) = self.prepare(&spec, scene)?;
        let id = new_id();
        let row = EpisodeRow {
            id: id.clone(),
            owner: owner.to_string(),
            split: spec.split.clone(),
            uid: spec.object.clone(),
            method: spec.method.clone(),
            request: serde_json::to_string(&spec).map_err(|e| internal("storing the episode", e))?,
            state: "running".into(),
            created_at: String::new(),
            seq: 0,
        };
        let (seq, created_at) =
            self.db.insert_episode(&row).map_err(|e| internal("storing the episode", e))?;
        let budget = spec.budget;
        let start = ep.history()[0];
        let now = Instant::now();
        let running =
            Running { ep, record, obs_at: now, deadline: now + self.limits.start_timeout, applied: 0 };
        let body = json!({
            "episode_id": id,
            "object_id": spec.object,
            "split": spec.split,
            "view_space": spec.view_space,
            "budget": spec.budget,
            "seed": objview_episode::episode_seed(spec.seed, &spec.object, &spec.view_space, budget),
            "candidate_set": spec.candidate_set,
            "start_pose": start.to_array(),
            "intrinsics": intrinsics_json(),
            "action_timeout_s": self.limits.action_timeout.as_secs_f64(),
            "observation": running.obs(),
        });
        let slot = Slot {
            id: id.clone(),
            owner: owner.to_string(),
            spec,
            created_at,
            seq,
            in_flight: AtomicUsize::new(0),
            live: Mutex::new(Live::Running(Box::new(running))),
        };
        lock(&self.episodes).insert(id, Arc::new(slot));
        Ok(body)
    }

    /// Ends a running episode without an action (time-out, abort) and stores its result.
    fn end_running(
        &self,
        slot: &Slot,
        live: &mut Live,
        source: TerminalSource,
        reason: &str,
        detail: String,
    ) -> Result<(), ApiError> {
        if let Live::Running(r) = live {
            r.ep.end(source, reason, detail);
        }
        let line = self.finish(slot, live)?;
        self.db
            .record_end(&slot.id, &slot.owner, &slot.spec.method, &line)
            .map_err(|e| internal("storing the result", e))
    }

    /// Turns an ended running episode into a finished one; returns its result line.
    fn finish(&self, slot: &Slot, live: &mut Live) -> Result<String, ApiError> {
        let Live::Running(r) = std::mem::replace(live, Live::Finished(None)) else {
            return Err(ApiError::Internal("the episode had already finished".into()));
        };
        self.release_running(&slot.owner);
        let r = *r;
        let res = r.ep.finish(r.record);
        let line = result_line(&slot.id, &res);
        *live = Live::Finished(Some(Box::new(Finished {
            history: res.visited_poses.clone(),
            terminal: TerminalInfo {
                source: res.terminal_source.to_string(),
                reason: res.terminal_reason.clone(),
                detail: res.terminal_detail.clone(),
            },
        })));
        Ok(line)
    }

    /// Ends the episode with `exception` / `timeout` if its client is late; whether it did.
    fn expire(&self, slot: &Slot, live: &mut Live, now: Instant) -> Result<bool, ApiError> {
        if slot.in_flight.load(Ordering::SeqCst) > 0 {
            return Ok(false);
        }
        self.expire_at(slot, live, now)
    }

    /// [`AppState::expire`] judged at `at` whatever is in flight.
    fn expire_at(&self, slot: &Slot, live: &mut Live, at: Instant) -> Result<bool, ApiError> {
        let Live::Running(r) = live else { return Ok(false) };
        if at < r.deadline {
            return Ok(false);
        }
        let (limit, what) = if r.applied == 0 {
            (self.limits.start_timeout, "the create response")
        } else {
            (self.limits.action_timeout, "the last observation")
        };
        let detail = format!("no action within {} s of {what} (step {})", limit.as_secs_f64(), r.step());
        self.end_running(slot, live, TerminalSource::Exception, "timeout", detail)?;
        Ok(true)
    }

    fn finished_summary(&self, slot: &Slot, live: &mut Live) -> Result<Finished, ApiError> {
        if let Live::Finished(f) = live {
            if f.is_none() {
                let line =
                    self.db.result(&slot.id).map_err(|e| internal("reading the result", e))?.ok_or_else(
                        || ApiError::Internal("the finished episode has no stored result".into()),
                    )?;
                *f = Some(Box::new(Finished::from_line(&line)?));
            }
            if let Some(f) = f {
                return Ok((**f).clone());
            }
        }
        Err(ApiError::Internal("the episode is running".into()))
    }

    /// `POST /v1/episodes/{id}/actions`: applies `action` if `step` is current; the OBS after it.
    /// `received` is when the action arrived (the end of its planning time).
    pub fn act(&self, slot: &Slot, step: u64, action: &Value, received: Instant) -> Result<Value, ApiError> {
        let mut live = lock(&slot.live);
        if self.expire_at(slot, &mut live, received)? {
            return Err(ApiError::EpisodeFinished(format!(
                "episode {} ended: no action came within the time limit",
                slot.id
            )));
        }
        let Live::Running(r) = &mut *live else {
            return Err(ApiError::EpisodeFinished(format!("episode {} has ended", slot.id)));
        };
        let current = r.step();
        if step != current as u64 {
            return Err(ApiError::StaleStep(format!(
                "`step` is {step}, the current observation is step {current}"
            )));
        }
        let secs = received.saturating_duration_since(r.obs_at).as_secs_f64();
        let row = ActionRow { step: current, action: action.to_string(), planner_seconds: secs };
        let seq = r.applied + 1;
        // Write-ahead: the action is stored before it is applied, so a storage failure (500)
        // leaves the episode as it was, and a crash after this point replays the action.
        self.db.record_action(&slot.id, seq, &row).map_err(|e| internal("storing the action", e))?;
        apply_raw(&mut r.ep, action, secs);
        r.applied = seq;
        if r.ep.terminal().is_some() {
            let line = self.finish(slot, &mut live)?;
            // Should this write fail, a restart recomputes the result from the stored actions.
            self.db
                .record_end(&slot.id, &slot.owner, &slot.spec.method, &line)
                .map_err(|e| internal("storing the result", e))?;
            Ok(self.finished_summary(slot, &mut live)?.obs())
        } else {
            let now = Instant::now();
            r.obs_at = now;
            r.deadline = now + self.limits.action_timeout;
            Ok(r.obs())
        }
    }

    /// `POST /v1/episodes/{id}/abort`: the client's planner failed; the episode ends with
    /// `exception` / `planner_error`, its views scored.
    pub fn abort(&self, slot: &Slot, detail: String) -> Result<Value, ApiError> {
        let mut live = lock(&slot.live);
        if self.expire(slot, &mut live, Instant::now())? || matches!(*live, Live::Finished(_)) {
            return Err(ApiError::EpisodeFinished(format!("episode {} has ended", slot.id)));
        }
        self.end_running(slot, &mut live, TerminalSource::Exception, "planner_error", detail)?;
        Ok(self.finished_summary(slot, &mut live)?.obs())
    }

    /// `GET /v1/episodes/{id}/observation`: OBS of the current view (409 after the end).
    pub fn observation(&self, slot: &Slot) -> Result<Value, ApiError> {
        let mut live = lock(&slot.live);
        self.expire(slot, &mut live, Instant::now())?;
        match &*live {
            Live::Running(r) => Ok(r.obs()),
            Live::Finished(_) => Err(ApiError::EpisodeFinished(format!("episode {} has ended", slot.id))),
        }
    }

    /// The current (or, after the end, last) view's step and pose; 409 `stale_step` when
    /// `want` names another step.
    fn current_view(&self, slot: &Slot, live: &mut Live, want: Option<u64>) -> Result<CurrentView, ApiError> {
        self.expire(slot, live, Instant::now())?;
        let (step, pose, depth) = match live {
            Live::Running(r) => {
                let obs = r.ep.observation();
                (obs.step, obs.pose, Some(obs.depth))
            }
            Live::Finished(_) => {
                let f = self.finished_summary(slot, live)?;
                let last = f.history.last().copied().ok_or_else(|| ApiError::Internal("no views".into()))?;
                let pose = Pose::from_array(last).ok_or_else(|| ApiError::Internal("stored pose".into()))?;
                (f.history.len() - 1, pose, None)
            }
        };
        if let Some(w) = want {
            if w != step as u64 {
                return Err(ApiError::StaleStep(format!(
                    "`step` is {w}, the current observation is step {step}"
                )));
            }
        }
        Ok((step, pose, depth))
    }

    fn render(
        &self,
        slot: &Slot,
        pose: Pose,
    ) -> Result<(Arc<objview_episode::Scene>, objview_render::Frame), ApiError> {
        let split = self
            .pool
            .split(&slot.spec.split)
            .ok_or_else(|| ApiError::Internal("the split is gone".into()))?;
        let obj = split
            .object(&ObjectKey::Uid(slot.spec.object.clone()))
            .ok_or_else(|| ApiError::Internal("the object is gone".into()))?;
        let scene =
            self.scenes.get(obj, &slot.spec.view_space).map_err(|e| internal("preparing the object", e))?;
        let frame = objview_render::render(&scene.mesh, &Camera::new(pose, scene.intrinsics));
        Ok((scene, frame))
    }

    /// `GET …/observation/depth.npy`: the step and the depth (512 × 512, row-major).
    pub fn depth(&self, slot: &Slot, want: Option<u64>) -> Result<(usize, Arc<Vec<f32>>), ApiError> {
        let mut live = lock(&slot.live);
        let (step, pose, depth) = self.current_view(slot, &mut live, want)?;
        drop(live);
        match depth {
            Some(d) => Ok((step, d)),
            None => Ok((step, Arc::new(self.render(slot, pose)?.1.depth))),
        }
    }

    /// `GET …/observation/rgb.png`: the step, the image size and its RGB8 pixels.
    pub fn rgb(&self, slot: &Slot, want: Option<u64>) -> Result<RgbView, ApiError> {
        let mut live = lock(&slot.live);
        let (step, pose, _) = self.current_view(slot, &mut live, want)?;
        drop(live);
        let (scene, frame) = self.render(slot, pose)?;
        let rgb = objview_render::rgb::render_rgb(&scene.mesh, &frame);
        Ok((step, frame.width(), frame.height(), rgb))
    }

    /// `POST …/feasible`: feasibility of each pose in the episode's view space.
    pub fn feasible(&self, slot: &Slot, poses: &[Pose]) -> Result<Vec<bool>, ApiError> {
        let space = self
            .spaces
            .get(&slot.spec.view_space)
            .ok_or_else(|| ApiError::Internal("unknown view space".into()))?;
        Ok(space.feasible_mask(poses))
    }

    /// `GET /v1/episodes/{id}`.
    pub fn info(&self, slot: &Slot) -> Result<Value, ApiError> {
        let public = self.pool.split(&slot.spec.split).is_some_and(|s| s.public);
        let mut v = json!({
            "episode_id": slot.id,
            "object_id": slot.spec.object,
            "split": slot.spec.split,
            "view_space": slot.spec.view_space,
            "budget": slot.spec.budget,
            "method": slot.spec.method,
        });
        {
            let mut live = lock(&slot.live);
            self.expire(slot, &mut live, Instant::now())?;
            let m = v.as_object_mut().expect("an object");
            match &mut *live {
                Live::Running(r) => {
                    let history: Vec<[f64; 7]> = r.ep.history().iter().map(|p| p.to_array()).collect();
                    m.insert("state".into(), json!("running"));
                    m.insert("step".into(), json!(r.step()));
                    m.insert("views".into(), json!(history.len()));
                    m.insert("history".into(), json!(history));
                    m.insert("terminal".into(), Value::Null);
                    if public {
                        let metrics =
                            r.ep.last_step()
                                .map(|s| serde_json::to_value(&s.metrics).unwrap_or(Value::Null))
                                .unwrap_or(Value::Null);
                        m.insert("metrics".into(), metrics);
                    }
                }
                Live::Finished(_) => {
                    let f = self.finished_summary(slot, &mut live)?;
                    m.insert("state".into(), json!("finished"));
                    m.insert("step".into(), json!(f.history.len() - 1));
                    m.insert("views".into(), json!(f.history.len()));
                    m.insert("history".into(), json!(f.history));
                    m.insert("terminal".into(), json!(f.terminal));
                }
            }
        }
        Ok(v)
    }

    /// `GET /v1/episodes`: the episodes `owner` may see (every episode without tokens), in
    /// creation order, of one state and one method if asked: `{"episode_id", "split", "object",
    /// "method", "state", "step", "created_at"}` each. An episode past its time limit is ended
    /// first, as any request about it would. `object` is the uid the create answer named.
    pub fn list(
        &self,
        owner: &str,
        state: Option<EpisodeState>,
        method: Option<&str>,
    ) -> Result<Vec<Value>, ApiError> {
        let mut slots: Vec<Arc<Slot>> = lock(&self.episodes)
            .values()
            .filter(|s| s.owner == owner && method.is_none_or(|m| s.spec.method == m))
            .cloned()
            .collect();
        slots.sort_by_key(|s| s.seq);
        let now = Instant::now();
        let mut out = Vec::new();
        for slot in slots {
            let mut live = lock(&slot.live);
            self.expire(&slot, &mut live, now)?;
            let (here, step) = match &*live {
                Live::Running(r) => (EpisodeState::Running, r.step()),
                Live::Finished(_) if state == Some(EpisodeState::Running) => continue,
                Live::Finished(_) => {
                    (EpisodeState::Finished, self.finished_summary(&slot, &mut live)?.history.len() - 1)
                }
            };
            if state.is_some_and(|s| s != here) {
                continue;
            }
            out.push(json!({
                "episode_id": slot.id,
                "split": slot.spec.split,
                "object": slot.spec.object,
                "method": slot.spec.method,
                "state": here.as_str(),
                "step": step,
                "created_at": slot.created_at,
            }));
        }
        Ok(out)
    }

    /// `GET /v1/episodes/{id}/result`: the result line (409 while running).
    pub fn result(&self, slot: &Slot) -> Result<String, ApiError> {
        let mut live = lock(&slot.live);
        self.expire(slot, &mut live, Instant::now())?;
        if matches!(*live, Live::Running(_)) {
            return Err(ApiError::EpisodeRunning(format!("episode {} is still running", slot.id)));
        }
        drop(live);
        self.db
            .result(&slot.id)
            .map_err(|e| internal("reading the result", e))?
            .ok_or_else(|| ApiError::Internal("the finished episode has no stored result".into()))
    }

    /// Ends every episode whose client is late (the background sweeper calls this).
    pub fn sweep(&self) {
        let now = Instant::now();
        let slots: Vec<Arc<Slot>> = lock(&self.episodes).values().cloned().collect();
        for slot in slots {
            // A busy episode is being acted on; its own request checks the deadline.
            let Ok(mut live) = slot.live.try_lock() else { continue };
            if let Err(e) = self.expire(&slot, &mut live, now) {
                eprintln!("objview serve: ending episode {} at its time limit: {e}", slot.id);
            }
        }
    }
}

/// Who is calling, from the request's bearer token and this server's tokens
/// ([`Caller::from_parts`]).
impl axum::extract::FromRequestParts<Arc<AppState>> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        state: &Arc<AppState>,
    ) -> Result<Caller, ApiError> {
        Caller::from_parts(parts, state.tokens.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-view result whose terminal checkpoint has CD = `cd`.
    fn one_view_result(cd: f64) -> objview_episode::EpisodeResult {
        let m = json!({"views": 1, "sc": {"0.02": 0.5}, "nsc": {"0.02": 0.5}, "cd": 0.1, "path_cost": 0.0,
                       "runtime": 0.0});
        let mut step = json!({"step": 0, "pose": [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "fused_points": 1,
                              "ms_voxels": {}, "planner_seconds": 0.0, "engine_seconds": 0.0,
                              "stage_seconds": [0.0, 0.0, 0.0, 0.0]});
        let mut terminal = json!({"step": 0});
        for (k, v) in m.as_object().unwrap() {
            step[k] = v.clone();
            terminal[k] = v.clone();
        }
        let mut r: objview_episode::EpisodeResult = serde_json::from_value(json!({
            "settings": {"planner": "m"}, "uid": "cube", "method": "m", "family": "classical",
            "execution_mode": "iterative", "view_space": "whole", "budget": "auto", "seed": 0,
            "start_pose": [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            "visited_poses": [[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]],
            "terminal_source": "algorithm_stop", "terminal_reason": "plan_end", "terminal_detail": "",
            "steps": [step], "checkpoints": {"terminal": terminal},
            "reference": {"points": 1, "views": 1, "view_set": "tammes-360", "observable_sc": {}, "key": ""},
            "gt_points": 1, "gt_source": "sampled", "wall_seconds": 0.0
        }))
        .unwrap();
        r.checkpoints.get_mut(&objview_episode::CheckpointKey::Terminal).unwrap().metrics.cd = cd;
        r
    }

    #[test]
    fn a_finite_result_is_stored_as_its_result_line() {
        let r = one_view_result(0.1);
        let line = result_line("e-1", &r);
        assert_eq!(serde_json::from_str::<objview_episode::EpisodeResult>(&line).unwrap(), r);
    }

    #[test]
    fn a_result_with_a_non_finite_number_is_stored_as_a_failure_line_without_nulls() {
        let line = result_line("e-1", &one_view_result(f64::INFINITY));
        assert!(!line.contains("null"), "{line}");
        let v: Value = serde_json::from_str(&line).unwrap();
        assert!(v["error"].as_str().unwrap().contains("`checkpoints.terminal.cd`"), "{v}");
        assert_eq!(
            (v["uid"].as_str(), v["method"].as_str(), v["budget"].as_str()),
            (Some("cube"), Some("m"), Some("auto"))
        );
        // The server can still answer about the episode from it.
        let f = Finished::from_line(&line).unwrap();
        assert_eq!((f.history.len(), f.terminal.reason.as_str()), (1, "plan_end"));
    }

    #[test]
    fn observations_show_only_step_pose_intrinsics_and_terminal() {
        let t =
            TerminalInfo { source: "benchmark".into(), reason: "invalid_action".into(), detail: "x".into() };
        let v = obs_json(3, Some([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]), Some(&t));
        assert_eq!(
            v,
            json!({"step": 3, "pose": [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "intrinsics": intrinsics_json(),
                   "done": true,
                   "terminal": {"source": "benchmark", "reason": "invalid_action", "detail": "x"}})
        );
        assert_eq!(obs_json(0, None, None)["done"], false);
    }
}
