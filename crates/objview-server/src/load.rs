//! The load generator of `objview bench serve`: N concurrent clients (one thread and one HTTP
//! connection pool each) play budgeted episodes of random feasible candidate moves against a
//! server, and the figures are throughput (moves per second) and step latency — measured by the
//! client around each action request, and by the server inside its action handler (the
//! `Server-Timing` header) — and fairness: the longest any client waited for one step response,
//! and how long the slowest and the fastest client took for all their episodes.

use std::sync::{Arc, Barrier};
use std::time::Instant;

use objview_episode::{Action, StopReason};
use objview_geom::Pose;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde_json::{json, Value};

use crate::client::{Client, ClientError};

/// What to run.
#[derive(Debug, Clone)]
pub struct LoadConfig {
    /// The server (`http://host:port`).
    pub url: String,
    /// Bearer token, if the server asks for one.
    pub token: Option<String>,
    /// The split and object (an index, or a uid) every episode uses.
    pub split: String,
    /// The object (uid or index) of the split.
    pub object: String,
    /// The view space.
    pub view_space: String,
    /// Concurrent clients.
    pub clients: usize,
    /// Episodes each client plays, one after another.
    pub episodes_per_client: usize,
    /// Moves per episode (a budgeted plan of K views, then `stop`).
    pub budget: usize,
    /// Seed of the random moves.
    pub seed: u64,
    /// Fetch each observation's depth before acting, as a real planner does.
    pub fetch_depth: bool,
    /// Candidate set the moves are drawn from.
    pub candidate_set: String,
}

/// Median and tail of a set of samples (milliseconds).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Latency {
    /// Number of timed requests.
    pub samples: usize,
    /// Median, milliseconds.
    pub p50_ms: f64,
    /// 99th percentile (nearest rank), milliseconds.
    pub p99_ms: f64,
    /// Mean, milliseconds.
    pub mean_ms: f64,
}

impl Latency {
    fn of(mut v: Vec<f64>) -> Latency {
        v.sort_by(f64::total_cmp);
        let mean = if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
        Latency {
            samples: v.len(),
            p50_ms: objview_geom::stats::percentile(&v, 0.5),
            p99_ms: objview_geom::stats::percentile(&v, 0.99),
            mean_ms: mean,
        }
    }
}

/// The figures of one load run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoadReport {
    /// Concurrent clients.
    pub clients: usize,
    /// Episodes run.
    pub episodes: usize,
    /// Move actions applied.
    pub steps: usize,
    /// Wall time from the first create to the last result (seconds).
    pub seconds: f64,
    /// `steps / seconds`.
    pub steps_per_second: f64,
    /// Around each move request, client side.
    pub client: Latency,
    /// Inside the action handler, server side.
    pub server: Latency,
    /// Creating an episode (takes the start view), client side.
    pub create: Latency,
    /// Fetching an observation's depth (a 1 MiB NPY; no engine work), client side: the cost of
    /// a request apart from the engine's queue.
    pub depth: Latency,
    /// Fairness: the longest any client waited for one step response (client side).
    pub max_wait: MaxWait,
    /// Fairness: seconds each client took for all its episodes, the fastest and the slowest
    /// (every client plays the same number of moves).
    pub client_seconds: (f64, f64),
}

/// The longest wait for a step response, and who waited.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MaxWait {
    /// Milliseconds.
    pub ms: f64,
    /// The client (0-based).
    pub client: usize,
    /// Its ratio to the median step latency (client side): near 1 when every client is served
    /// in turn, large when one is starved.
    pub over_p50: f64,
}

struct ClientStats {
    seconds: f64,
    episodes: usize,
    steps: usize,
    client_ms: Vec<f64>,
    server_ms: Vec<f64>,
    create_ms: Vec<f64>,
    depth_ms: Vec<f64>,
}

fn play(
    cfg: &LoadConfig,
    index: usize,
    candidates: &[Pose],
    barrier: &Barrier,
) -> Result<ClientStats, ClientError> {
    let client = Client::new(&cfg.url, cfg.token.as_deref());
    let mut stats = ClientStats {
        seconds: 0.0,
        episodes: 0,
        steps: 0,
        client_ms: Vec::new(),
        server_ms: Vec::new(),
        create_ms: Vec::new(),
        depth_ms: Vec::new(),
    };
    barrier.wait();
    let started = Instant::now();
    for e in 0..cfg.episodes_per_client {
        let seed = objview_geom::hash::splitmix64(cfg.seed ^ ((index as u64) << 32) ^ e as u64);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let t = Instant::now();
        let object =
            cfg.object.parse::<u64>().map(Value::from).unwrap_or_else(|_| Value::from(cfg.object.clone()));
        let created = client.create(&json!({
            "split": cfg.split, "object": object, "view_space": cfg.view_space, "budget": cfg.budget,
            "method": "load-bench", "family": "baseline", "execution_mode": "budgeted_plan",
            "candidate_set": cfg.candidate_set, "seed": seed,
        }))?;
        stats.create_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let id = created["episode_id"].as_str().unwrap_or_default().to_string();
        let mask = client.feasible(&id, candidates)?;
        let mut order: Vec<usize> = (0..candidates.len()).filter(|&i| mask[i]).collect();
        order.shuffle(&mut rng);
        let mut step = 0;
        for &i in order.iter().take(cfg.budget) {
            if cfg.fetch_depth {
                let t = Instant::now();
                client.depth(&id, step)?;
                stats.depth_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            let t = Instant::now();
            let (obs, server) = client.act(&id, step, &Action::move_to(&candidates[i]))?;
            stats.client_ms.push(t.elapsed().as_secs_f64() * 1e3);
            stats.server_ms.extend(server);
            stats.steps += 1;
            step = obs.step;
            if obs.done {
                break;
            }
        }
        let _ = client.act(&id, step, &Action::stop(StopReason::PlanEnd));
        client.result(&id)?;
        stats.episodes += 1;
    }
    stats.seconds = started.elapsed().as_secs_f64();
    Ok(stats)
}

/// Runs the load and collects the figures. The server must have the split and object.
pub fn run_load(cfg: &LoadConfig) -> Result<LoadReport, ClientError> {
    if cfg.clients == 0 || cfg.episodes_per_client == 0 || cfg.budget == 0 {
        return Err(ClientError::Unsupported(
            "clients, episodes per client and budget must be at least 1".into(),
        ));
    }
    let probe = Client::new(&cfg.url, cfg.token.as_deref());
    probe.health()?;
    let candidates = Arc::new(probe.candidate_set(&cfg.candidate_set)?);
    let barrier = Arc::new(Barrier::new(cfg.clients + 1));
    let handles: Vec<_> = (0..cfg.clients)
        .map(|i| {
            let (cfg, candidates, barrier) = (cfg.clone(), candidates.clone(), barrier.clone());
            std::thread::spawn(move || play(&cfg, i, &candidates, &barrier))
        })
        .collect();
    barrier.wait();
    let t = Instant::now();
    let mut all = Vec::new();
    for h in handles {
        all.push(h.join().map_err(|_| ClientError::Transport("a load client panicked".into()))?);
    }
    let seconds = t.elapsed().as_secs_f64();
    let mut first_err = None;
    let mut stats = Vec::new();
    for r in all {
        match r {
            Ok(s) => stats.push(s),
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    if let Some(e) = first_err {
        return Err(e);
    }
    let steps: usize = stats.iter().map(|s| s.steps).sum();
    let client = Latency::of(stats.iter().flat_map(|s| s.client_ms.iter().copied()).collect());
    let (mut worst, mut who) = (0.0f64, 0);
    for (i, s) in stats.iter().enumerate() {
        if let Some(m) = s.client_ms.iter().copied().max_by(f64::total_cmp) {
            if m > worst {
                (worst, who) = (m, i);
            }
        }
    }
    let secs = stats.iter().map(|s| s.seconds);
    let client_seconds = (secs.clone().fold(f64::INFINITY, f64::min), secs.fold(f64::NEG_INFINITY, f64::max));
    Ok(LoadReport {
        clients: cfg.clients,
        episodes: stats.iter().map(|s| s.episodes).sum(),
        steps,
        seconds,
        steps_per_second: steps as f64 / seconds.max(1e-9),
        server: Latency::of(stats.iter().flat_map(|s| s.server_ms.iter().copied()).collect()),
        create: Latency::of(stats.iter().flat_map(|s| s.create_ms.iter().copied()).collect()),
        depth: Latency::of(stats.iter().flat_map(|s| s.depth_ms.iter().copied()).collect()),
        max_wait: MaxWait { ms: worst, client: who, over_p50: worst / client.p50_ms },
        client_seconds,
        client,
    })
}
