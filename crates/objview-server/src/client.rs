//! A blocking client of the API (ureq), and [`run_remote`]: it plays one episode of a local
//! [`Planner`] against a server exactly as [`objview_episode::run_episode`] plays it against a
//! local engine — same context, same observations (depth from `depth.npy`), feasibility through
//! the batch endpoint — so that the result line is the one a local `objview run` writes (wall
//! clock aside).

use std::cell::RefCell;
use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::{Duration, Instant};

use objview_episode::{Action, Budget, Environment, EpisodeContext, EpisodeResult, Observation, Planner};
use objview_geom::Pose;
use objview_render::Intrinsics;
use serde_json::{json, Value};

/// A failed call.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClientError {
    /// The server answered with an error.
    #[error("{status} {code}: {message}")]
    Api {
        /// HTTP status.
        status: u16,
        /// The error code of the body (`invalid_action`, …).
        code: String,
        /// The error message of the body.
        message: String,
    },
    /// The request did not reach the server, or its answer did not arrive.
    #[error("{0}")]
    Transport(String),
    /// The answer was not what the contract says.
    #[error("unexpected answer: {0}")]
    Protocol(String),
    /// What was asked cannot be done remotely.
    #[error("{0}")]
    Unsupported(String),
}

impl ClientError {
    /// The error code of an API error.
    pub fn code(&self) -> Option<&str> {
        match self {
            ClientError::Api { code, .. } => Some(code),
            _ => None,
        }
    }
}

fn protocol(what: impl std::fmt::Display) -> ClientError {
    ClientError::Protocol(what.to_string())
}

/// A raw answer: status, headers we care about, body.
#[derive(Debug, Clone)]
pub struct RawResponse {
    /// HTTP status.
    pub status: u16,
    /// The `Content-Type` header.
    pub content_type: String,
    /// `X-Objview-Step`.
    pub step: Option<String>,
    /// `Server-Timing`.
    pub server_timing: Option<String>,
    /// The body bytes.
    pub body: Vec<u8>,
}

impl RawResponse {
    /// The body as JSON (Null when it is not).
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

/// An observation's metadata (OBS).
#[derive(Debug, Clone, PartialEq)]
pub struct Obs {
    /// The observation's step (0 = start view).
    pub step: usize,
    /// The pose it was taken from.
    pub pose: Pose,
    /// Whether the episode has ended.
    pub done: bool,
    /// `{"source", "reason", "detail"}` once done.
    pub terminal: Value,
}

impl Obs {
    /// Parses OBS.
    pub fn from_json(v: &Value) -> Result<Obs, ClientError> {
        let step = v["step"].as_u64().ok_or_else(|| protocol(format!("OBS without step: {v}")))? as usize;
        let pose = pose_from_json(&v["pose"]).ok_or_else(|| protocol(format!("OBS pose: {v}")))?;
        let done = v["done"].as_bool().ok_or_else(|| protocol(format!("OBS without done: {v}")))?;
        Ok(Obs { step, pose, done, terminal: v["terminal"].clone() })
    }
}

/// A pose from 7 JSON numbers.
pub fn pose_from_json(v: &Value) -> Option<Pose> {
    let a = v.as_array().filter(|a| a.len() == 7)?;
    let mut out = [0.0; 7];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x.as_f64()?;
    }
    Pose::from_array(out)
}

/// A client of one server.
#[derive(Clone)]
pub struct Client {
    base: String,
    token: Option<String>,
    agent: ureq::Agent,
}

impl Client {
    /// A client of the server at `url` (`http://host:port`), with a bearer token if it needs one.
    pub fn new(url: &str, token: Option<&str>) -> Client {
        let agent = ureq::AgentBuilder::new().timeout_connect(Duration::from_secs(30)).build();
        Client { base: url.trim_end_matches('/').to_string(), token: token.map(str::to_string), agent }
    }

    /// The server's URL.
    pub fn url(&self) -> &str {
        &self.base
    }

    /// Sends a request and returns whatever came back (errors included); only a transport
    /// failure is an `Err`.
    pub fn raw(&self, method: &str, path: &str, body: Option<&[u8]>) -> Result<RawResponse, ClientError> {
        let mut req = self.agent.request(method, &format!("{}{path}", self.base));
        if let Some(t) = &self.token {
            req = req.set("Authorization", &format!("Bearer {t}"));
        }
        let res = match body {
            Some(b) => req.set("Content-Type", "application/json").send_bytes(b),
            None => req.call(),
        };
        let resp = match res {
            Ok(r) => r,
            Err(ureq::Error::Status(_, r)) => r,
            Err(ureq::Error::Transport(t)) => {
                return Err(ClientError::Transport(format!("{method} {path}: {t}")))
            }
        };
        let status = resp.status();
        let content_type = resp.content_type().to_string();
        let step = resp.header("x-objview-step").map(str::to_string);
        let server_timing = resp.header("server-timing").map(str::to_string);
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut resp.into_reader(), &mut bytes)
            .map_err(|e| ClientError::Transport(format!("{method} {path}: reading the answer: {e}")))?;
        Ok(RawResponse { status, content_type, step, server_timing, body: bytes })
    }

    fn checked(&self, method: &str, path: &str, body: Option<&Value>) -> Result<RawResponse, ClientError> {
        let text = body.map(|b| b.to_string());
        let r = self.raw(method, path, text.as_deref().map(str::as_bytes))?;
        if r.status >= 400 {
            let v = r.json();
            return Err(ClientError::Api {
                status: r.status,
                code: v["error"]["code"].as_str().unwrap_or("?").to_string(),
                message: v["error"]["message"]
                    .as_str()
                    .map(str::to_string)
                    .unwrap_or_else(|| String::from_utf8_lossy(&r.body).into_owned()),
            });
        }
        Ok(r)
    }

    /// GET a JSON route.
    pub fn get_json(&self, path: &str) -> Result<Value, ClientError> {
        let r = self.checked("GET", path, None)?;
        serde_json::from_slice(&r.body).map_err(|e| protocol(format!("GET {path}: {e}")))
    }

    /// POST JSON to a JSON route.
    pub fn post_json(&self, path: &str, body: &Value) -> Result<Value, ClientError> {
        let r = self.checked("POST", path, Some(body))?;
        serde_json::from_slice(&r.body).map_err(|e| protocol(format!("POST {path}: {e}")))
    }

    /// `GET /v1/health`.
    pub fn health(&self) -> Result<Value, ClientError> {
        self.get_json("/v1/health")
    }

    /// The object uids of a split, in order.
    pub fn split_objects(&self, split: &str) -> Result<Vec<String>, ClientError> {
        let v = self.get_json(&format!("/v1/splits/{split}"))?;
        v["object_ids"]
            .as_array()
            .ok_or_else(|| protocol("no object_ids"))?
            .iter()
            .map(|x| x.as_str().map(str::to_string).ok_or_else(|| protocol("object id")))
            .collect()
    }

    /// The poses of a candidate set.
    pub fn candidate_set(&self, name: &str) -> Result<Vec<Pose>, ClientError> {
        let v = self.get_json(&format!("/v1/candidate-sets/{name}"))?;
        v["poses"]
            .as_array()
            .ok_or_else(|| protocol("no poses"))?
            .iter()
            .map(|p| pose_from_json(p).ok_or_else(|| protocol(format!("pose {p}"))))
            .collect()
    }

    /// `POST /v1/episodes` (the 201 body).
    pub fn create(&self, request: &Value) -> Result<Value, ClientError> {
        self.post_json("/v1/episodes", request)
    }

    /// Feasibility of each pose (several requests when there are more than 4096).
    pub fn feasible(&self, id: &str, poses: &[Pose]) -> Result<Vec<bool>, ClientError> {
        let mut out = Vec::with_capacity(poses.len());
        for chunk in poses.chunks(crate::protocol::MAX_FEASIBLE_POSES) {
            let list: Vec<[f64; 7]> = chunk.iter().map(|p| p.to_array()).collect();
            let v = self.post_json(&format!("/v1/episodes/{id}/feasible"), &json!({ "poses": list }))?;
            let mask = v["feasible"].as_array().ok_or_else(|| protocol("no feasible"))?;
            if mask.len() != chunk.len() {
                return Err(protocol(format!("{} answers for {} poses", mask.len(), chunk.len())));
            }
            for b in mask {
                out.push(b.as_bool().ok_or_else(|| protocol("feasible is not a boolean"))?);
            }
        }
        Ok(out)
    }

    /// Sends the action for `step`; the new OBS and the server's handler time (ms) if it said.
    pub fn act(&self, id: &str, step: usize, action: &Action) -> Result<(Obs, Option<f64>), ClientError> {
        let body = json!({"step": step, "action": action});
        let r = self.checked("POST", &format!("/v1/episodes/{id}/actions"), Some(&body))?;
        let v: Value =
            serde_json::from_slice(&r.body).map_err(|e| protocol(format!("action answer: {e}")))?;
        let ms = r.server_timing.as_deref().and_then(|h| {
            h.split(';').find_map(|p| p.trim().strip_prefix("dur=")).and_then(|d| d.parse::<f64>().ok())
        });
        Ok((Obs::from_json(&v["observation"])?, ms))
    }

    /// Ends the episode with `exception` / `planner_error`, `detail` as its terminal detail;
    /// the last view's OBS (`done`, `terminal` set).
    pub fn abort(&self, id: &str, detail: &str) -> Result<Obs, ClientError> {
        let v = self.post_json(&format!("/v1/episodes/{id}/abort"), &json!({ "detail": detail }))?;
        Obs::from_json(&v["observation"])
    }

    /// `GET /v1/episodes[?state=STATE]`: this token's episodes (every episode on a server
    /// without tokens) in creation order, `running` or `finished` ones only if `state` says so;
    /// each `{"episode_id", "split", "object", "method", "state", "step", "created_at"}`.
    /// Running ones left over from a crashed client can be ended with [`Client::abort`].
    pub fn list_episodes(&self, state: Option<&str>) -> Result<Vec<Value>, ClientError> {
        let path = match state {
            None => "/v1/episodes".to_string(),
            Some(s) => format!("/v1/episodes?state={}", query_escape(s)),
        };
        let v = self.get_json(&path)?;
        v["episodes"]
            .as_array()
            .cloned()
            .ok_or_else(|| protocol(format!("GET {path}: no `episodes` list: {v}")))
    }

    /// The depth of observation `step` (row-major, camera-frame z, 0 = no hit).
    pub fn depth(&self, id: &str, step: usize) -> Result<Vec<f32>, ClientError> {
        let r = self.checked("GET", &format!("/v1/episodes/{id}/observation/depth.npy?step={step}"), None)?;
        let (_, values) = objview_geom::npy::parse_npy_f64(std::path::Path::new("depth.npy"), &r.body)
            .map_err(|e| protocol(format!("depth: {e}")))?;
        Ok(values.into_iter().map(|x| x as f32).collect())
    }

    /// The result line of a finished episode.
    pub fn result(&self, id: &str) -> Result<String, ClientError> {
        let r = self.checked("GET", &format!("/v1/episodes/{id}/result"), None)?;
        String::from_utf8(r.body).map_err(|e| protocol(format!("result: {e}")))
    }
}

/// `s` percent-encoded for a query string (unreserved characters as they are).
fn query_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// One remote episode to play.
#[derive(Debug, Clone)]
pub struct RemoteEpisode {
    /// The split id.
    pub split: String,
    /// A uid (or an index) of the split.
    pub object: String,
    /// The view space.
    pub view_space: String,
    /// The budget protocol.
    pub budget: Budget,
    /// The candidate set.
    pub candidate_set: String,
    /// The user seed.
    pub seed: u64,
    /// Whether the result records wall-clock times.
    pub record_timings: bool,
}

type PoseKey = [u64; 7];

fn key(p: &Pose) -> PoseKey {
    p.to_array().map(f64::to_bits)
}

/// The environment a remote planner sees: its own history and feasibility answered by the
/// server (cached by exact pose).
struct RemoteEnv<'a> {
    client: &'a Client,
    id: &'a str,
    history: &'a [Pose],
    cache: &'a RefCell<HashMap<PoseKey, bool>>,
    error: &'a RefCell<Option<ClientError>>,
}

impl Environment for RemoteEnv<'_> {
    fn is_feasible(&self, pose: &Pose) -> bool {
        self.feasible_mask(std::slice::from_ref(pose))[0]
    }

    fn feasible_mask(&self, poses: &[Pose]) -> Vec<bool> {
        // A pose beyond the bound is infeasible, as locally; the server would refuse the whole
        // batch (422) for it.
        let in_bounds = |p: &Pose| objview_episode::check_pose(&p.to_array()).is_ok();
        let missing: Vec<Pose> = {
            let cache = self.cache.borrow();
            let mut seen = std::collections::HashSet::new();
            poses
                .iter()
                .filter(|p| in_bounds(p) && !cache.contains_key(&key(p)) && seen.insert(key(p)))
                .copied()
                .collect()
        };
        if !missing.is_empty() {
            match self.client.feasible(self.id, &missing) {
                Ok(mask) => {
                    let mut cache = self.cache.borrow_mut();
                    for (p, f) in missing.iter().zip(mask) {
                        cache.insert(key(p), f);
                    }
                }
                Err(e) => {
                    self.error.borrow_mut().get_or_insert(e);
                    return vec![false; poses.len()];
                }
            }
        }
        let cache = self.cache.borrow();
        poses.iter().map(|p| in_bounds(p) && cache.get(&key(p)).copied().unwrap_or(false)).collect()
    }

    fn history(&self) -> &[Pose] {
        self.history
    }
}

fn panic_text(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

/// The create request of `ep` for `planner`.
pub fn create_request(planner: &dyn Planner, ep: &RemoteEpisode) -> Value {
    json!({
        "split": ep.split,
        "object": ep.object,
        "view_space": ep.view_space,
        "budget": ep.budget.to_string(),
        "method": planner.name(),
        "family": planner.family().to_string(),
        "execution_mode": planner.execution_mode().to_string(),
        "candidate_set": ep.candidate_set,
        "seed": ep.seed,
        "params": planner.params(),
        "record_timings": ep.record_timings,
    })
}

/// How long [`run_remote`] keeps asking for a place while the server's cap on running episodes
/// is reached (429 `too_many_episodes`): places come back as episodes end, at the latest at the
/// server's time limits (a 300 s start limit by default).
pub const CREATE_WAIT_MAX: Duration = Duration::from_secs(600);
/// The first wait before asking again; it doubles up to [`CREATE_RETRY_MAX`].
const CREATE_RETRY_FIRST: Duration = Duration::from_millis(250);
const CREATE_RETRY_MAX: Duration = Duration::from_secs(4);

/// `POST /v1/episodes`, asked again while the server answers 429 `too_many_episodes` (a full
/// server: wait for a place, up to [`CREATE_WAIT_MAX`]); any other answer is returned as it is.
pub fn create_waiting(client: &Client, request: &Value) -> Result<Value, ClientError> {
    let started = Instant::now();
    let mut wait = CREATE_RETRY_FIRST;
    loop {
        match client.create(request) {
            Err(ClientError::Api { status: 429, ref code, .. })
                if code == "too_many_episodes" && started.elapsed() + wait <= CREATE_WAIT_MAX =>
            {
                std::thread::sleep(wait);
                wait = (wait * 2).min(CREATE_RETRY_MAX);
            }
            answer => return answer,
        }
    }
}

/// Plays one episode of `planner` on the server and returns its result line (with its newline,
/// as [`objview_dataset::to_line`]). `candidates` are
/// the poses of `ep.candidate_set` (fetch them once with [`Client::candidate_set`]). A planner
/// that fails or panics ends the episode with `exception` / `planner_error` (through `abort`), as
/// locally. The oracle (it reads ground truth) cannot run remotely. A full server (429
/// `too_many_episodes`) is waited for ([`create_waiting`]), so that a run with more threads than
/// the server's caps allow finishes every object instead of failing some.
pub fn run_remote(
    client: &Client,
    planner: &mut dyn Planner,
    ep: &RemoteEpisode,
    candidates: Arc<Vec<Pose>>,
) -> Result<String, ClientError> {
    if planner.needs_ground_truth() {
        return Err(ClientError::Unsupported(format!(
            "planner {} reads the ground truth and cannot run against a server",
            planner.name()
        )));
    }
    let created = create_waiting(client, &create_request(planner, ep))?;
    let id = created["episode_id"].as_str().ok_or_else(|| protocol("no episode_id"))?.to_string();
    let intr = &created["intrinsics"];
    let num = |k: &str| intr[k].as_f64().ok_or_else(|| protocol(format!("intrinsics.{k}")));
    let intrinsics = Intrinsics {
        width: num("width")? as u32,
        height: num("height")? as u32,
        fx: num("fx")?,
        fy: num("fy")?,
        cx: num("cx")?,
        cy: num("cy")?,
        znear: num("znear")?,
        zfar: num("zfar")?,
    };
    let ctx = EpisodeContext {
        seed: created["seed"].as_u64().ok_or_else(|| protocol("no seed"))?,
        object_id: created["object_id"].as_str().unwrap_or_default().to_string(),
        view_space: created["view_space"].as_str().unwrap_or_default().to_string(),
        budget: ep.budget,
        candidates,
        candidate_set: ep.candidate_set.clone(),
        start_pose: pose_from_json(&created["start_pose"]).ok_or_else(|| protocol("start_pose"))?,
        intrinsics,
        oracle: None,
    };
    let mut obs = Obs::from_json(&created["observation"])?;
    let mut history = vec![obs.pose];
    let cache = RefCell::new(HashMap::new());
    let error = RefCell::new(None);
    let check = |error: &RefCell<Option<ClientError>>| match error.borrow_mut().take() {
        Some(e) => Err(e),
        None => Ok(()),
    };
    let reset = {
        let env = RemoteEnv { client, id: &id, history: &history, cache: &cache, error: &error };
        catch_unwind(AssertUnwindSafe(|| planner.reset(&ctx, &env)))
    };
    check(&error)?;
    let failure = match reset {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(format!("reset: {e}")),
        Err(p) => Some(format!("reset panicked: {}", panic_text(&p))),
    };
    if let Some(detail) = failure {
        obs = client.abort(&id, &detail)?;
    }
    while !obs.done {
        let depth = client.depth(&id, obs.step)?;
        let observation =
            Observation { step: obs.step, pose: obs.pose, intrinsics, depth: Arc::new(depth), rgb: None };
        let act = {
            let env = RemoteEnv { client, id: &id, history: &history, cache: &cache, error: &error };
            catch_unwind(AssertUnwindSafe(|| planner.act(&observation, &env)))
        };
        check(&error)?;
        obs = match act {
            Ok(Ok(a)) => client.act(&id, obs.step, &a)?.0,
            Ok(Err(e)) => client.abort(&id, &e.to_string())?,
            Err(p) => client.abort(&id, &format!("panicked: {}", panic_text(&p)))?,
        };
        if obs.step == history.len() {
            history.push(obs.pose);
        }
    }
    let line = client.result(&id)?;
    // The planner's notes live on this side: added as the local run adds them (last field).
    let notes = objview_episode::read_notes(planner);
    let mut line = EpisodeResult::append_planner_notes(line.trim_end(), notes.as_ref())
        .map_err(|e| protocol(format!("result: {e}")))?;
    line.push('\n');
    Ok(line)
}
