//! The objview evaluation server: online episodes (SPEC §5) over HTTP/JSON for remote planners
//! on objects they never see. docs/server-api.md is the contract.
//!
//! - [`api`] — the routes; [`openapi`] — `GET /openapi.json`.
//! - [`protocol`] — the protocol's names and limits (view spaces, candidate sets, families,
//!   request sizes); [`request`] — the create request, parsed and validated ([`request::CreateSpec`]).
//! - [`state`] — episodes in memory (one lock each), time limits, replay after a restart.
//! - [`db`] — persistence (SQLite, WAL) and `objview export`.
//! - [`pool`] — split files and the cache of prepared scenes.
//! - [`auth`] — bearer tokens and episode owners; [`error`] — errors and their statuses.
//! - [`conn`] — the accept loop: connection cap, header / idle time limits; [`compress`] — gzip
//!   of responses for clients that accept it.
//! - [`client`] — a blocking client, and the driver that runs a local [`objview_episode::Planner`]
//!   against a server; [`remote`] — a batch of such episodes over split objects
//!   (`objview run --server`), on the shared batch driver.
//!
//! The settings record of result lines is `objview_runs::record` (shared with local runs).
//! - [`load`] — the load generator of `objview bench serve`.
//!
//! Engine work (rendering, fusion, metrics) waits in one queue for one of as many engine lanes
//! as cores, each a thread of its own ([`lanes`]); the async side only parses, routes and waits.

pub mod api;
pub mod auth;
pub mod client;
pub mod compress;
pub mod conn;
pub mod db;
pub mod error;
pub mod lanes;
pub mod load;
pub mod openapi;
pub mod pool;
pub mod protocol;
pub mod remote;
pub mod request;
pub mod state;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use objview_geom::normalize::Normalization;

pub use error::{ApiError, ServerError};
pub use state::AppState;

/// Everything `objview serve` is configured with.
#[derive(Debug, Clone)]
pub struct ServerConfig {
    /// Split files (`objview pool split` output).
    pub pool: Vec<PathBuf>,
    /// Split ids whose running episodes show metrics.
    pub public: Vec<String>,
    /// The database file.
    pub db: PathBuf,
    /// The tokens file (none: no authentication).
    pub tokens: Option<PathBuf>,
    /// Seconds a client has for each action after an observation.
    pub action_timeout_s: f64,
    /// Seconds a client has for its first action after the create response.
    pub start_timeout_s: f64,
    /// Observable-reference cache folder (none: not cached on disk).
    pub cache_dir: Option<PathBuf>,
    /// How meshes are normalized (`unit` for raw assets, like `objview run`).
    pub normalize: Normalization,
    /// Prepared scenes kept in memory (least recently used dropped first).
    pub scene_cache: usize,
    /// Open connections at most (lowered to fit the descriptor limit; see [`conn`]).
    pub max_connections: usize,
    /// Seconds from the first byte of a request to the end of its head.
    pub header_timeout_s: f64,
    /// Seconds a handler waits for a request body (408 after).
    pub body_timeout_s: f64,
    /// Seconds a connection without a request in progress stays open after its last activity.
    pub idle_timeout_s: f64,
    /// Running episodes at most, in all (each holds its engine state in memory).
    pub max_running: usize,
    /// Running episodes at most per token (servers with tokens; an open server has one caller).
    pub max_running_per_token: usize,
}

/// Default of [`ServerConfig::max_running`]: 7–8 GiB of engine state on a 100k-triangle object
/// with a 300k-point ground truth (55–66 MiB per running episode; `objview bench serve` prints
/// it).
pub const DEFAULT_MAX_RUNNING: usize = 128;
/// Default of [`ServerConfig::max_running_per_token`].
pub const DEFAULT_MAX_RUNNING_PER_TOKEN: usize = 64;

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            pool: Vec::new(),
            public: Vec::new(),
            db: PathBuf::from("objview-server.sqlite"),
            tokens: None,
            action_timeout_s: 100.0,
            start_timeout_s: 300.0,
            cache_dir: None,
            normalize: Normalization::Unit,
            scene_cache: pool::DEFAULT_SCENE_CACHE,
            max_connections: conn::DEFAULT_MAX_CONNECTIONS,
            header_timeout_s: conn::DEFAULT_HEADER_TIMEOUT_S,
            body_timeout_s: conn::DEFAULT_BODY_TIMEOUT_S,
            idle_timeout_s: conn::DEFAULT_IDLE_TIMEOUT_S,
            max_running: DEFAULT_MAX_RUNNING,
            max_running_per_token: DEFAULT_MAX_RUNNING_PER_TOKEN,
        }
    }
}

fn seconds(name: &str, s: f64) -> Result<Duration, ServerError> {
    if s.is_finite() && s > 0.0 && s < 1e9 {
        Ok(Duration::from_secs_f64(s))
    } else {
        Err(ServerError::Config(format!("{name} must be a positive number of seconds, got {s}")))
    }
}

/// Loads the pool, opens the database, reads the tokens and finishes the episodes a previous
/// server left running (replayed, ended `exception` / `interrupted`).
pub fn build_state(cfg: &ServerConfig) -> Result<Arc<AppState>, ServerError> {
    for (name, n) in [
        ("--max-connections", cfg.max_connections),
        ("--max-running", cfg.max_running),
        ("--max-running-per-token", cfg.max_running_per_token),
    ] {
        if n == 0 {
            return Err(ServerError::Config(format!("{name} must be at least 1")));
        }
    }
    let fd_limit = conn::descriptor_limit();
    let max_connections = conn::fit_descriptor_limit(cfg.max_connections, fd_limit);
    if max_connections < cfg.max_connections {
        eprintln!(
            "objview serve: --max-connections {} lowered to {max_connections}: the descriptor limit \
             (ulimit -n) is {}, and {} descriptors are kept for files and the database",
            cfg.max_connections,
            fd_limit.unwrap_or_default(),
            conn::DESCRIPTOR_RESERVE
        );
    }
    let limits = state::Limits {
        action_timeout: seconds("--action-timeout", cfg.action_timeout_s)?,
        start_timeout: seconds("--start-timeout", cfg.start_timeout_s)?,
        body_timeout: seconds("--body-timeout", cfg.body_timeout_s)?,
        max_running: cfg.max_running,
        max_running_per_token: cfg.max_running_per_token,
        conn: conn::ConnLimits {
            max_connections,
            header_timeout: seconds("--header-timeout", cfg.header_timeout_s)?,
            idle_timeout: seconds("--idle-timeout", cfg.idle_timeout_s)?,
        },
    };
    if cfg.pool.is_empty() {
        return Err(ServerError::Config("no split files (--pool SPLIT.json)".into()));
    }
    let pool = pool::Pool::load(&cfg.pool, &cfg.public)?;
    let tokens = cfg.tokens.as_deref().map(auth::Tokens::load).transpose()?;
    let db = db::Db::open(&cfg.db)?;
    let scenes = pool::SceneCache::new(cfg.normalize, cfg.cache_dir.clone()).with_capacity(cfg.scene_cache);
    Ok(Arc::new(AppState::new(pool, scenes, db, tokens, limits)?))
}

/// Serves the API on `listener` until `shutdown` resolves (connections under the limits of
/// [`conn`]); a background task ends episodes whose client is late.
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: Arc<AppState>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let tick = (state.limits.action_timeout.min(state.limits.start_timeout) / 4)
        .clamp(Duration::from_millis(20), Duration::from_secs(1));
    let sweeper_state = state.clone();
    let sweeper = tokio::spawn(async move {
        let mut interval = tokio::time::interval(tick);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            interval.tick().await;
            let s = sweeper_state.clone();
            let _ = tokio::task::spawn_blocking(move || s.sweep()).await;
        }
    });
    let (registry, limits) = (state.connections.clone(), state.limits.conn);
    let app = api::router(state);
    conn::serve(listener, app, registry, limits, shutdown).await;
    sweeper.abort();
    Ok(())
}

/// `objview serve`: builds the state, binds `addr`, calls `ready` with the bound address and
/// serves until Ctrl-C.
pub fn run(
    cfg: &ServerConfig,
    addr: &str,
    ready: impl FnOnce(SocketAddr, &AppState),
) -> Result<(), ServerError> {
    let state = build_state(cfg)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ServerError::Io(format!("starting the runtime: {e}")))?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|e| ServerError::Io(format!("binding {addr}: {e}")))?;
        let bound = listener.local_addr().map_err(|e| ServerError::Io(e.to_string()))?;
        ready(bound, &state);
        serve(listener, state, async {
            let _ = tokio::signal::ctrl_c().await;
        })
        .await
    })
}

/// A server running on its own thread (tests, `objview bench serve`); stopped when dropped.
pub struct BackgroundServer {
    /// The bound address.
    pub addr: SocketAddr,
    /// The shared state (for inspection).
    pub state: Arc<AppState>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl BackgroundServer {
    /// `http://ADDR`.
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Stops the server and waits for it.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for BackgroundServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Starts a server for `cfg` on `addr` (e.g. `127.0.0.1:0` for a free port) on a new thread.
pub fn spawn(cfg: &ServerConfig, addr: &str) -> Result<BackgroundServer, ServerError> {
    let state = build_state(cfg)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ServerError::Io(format!("starting the runtime: {e}")))?;
    let std_listener =
        std::net::TcpListener::bind(addr).map_err(|e| ServerError::Io(format!("binding {addr}: {e}")))?;
    std_listener.set_nonblocking(true).map_err(|e| ServerError::Io(e.to_string()))?;
    let bound = std_listener.local_addr().map_err(|e| ServerError::Io(e.to_string()))?;
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let st = state.clone();
    let thread = std::thread::spawn(move || {
        rt.block_on(async move {
            let listener = match tokio::net::TcpListener::from_std(std_listener) {
                Ok(l) => l,
                Err(e) => {
                    eprintln!("objview serve: {e}");
                    return;
                }
            };
            if let Err(e) = serve(listener, st, async {
                let _ = rx.await;
            })
            .await
            {
                eprintln!("objview serve: {e}");
            }
        });
        rt.shutdown_timeout(Duration::from_secs(5));
    });
    Ok(BackgroundServer { addr: bound, state, stop: Some(tx), thread: Some(thread) })
}
