//! `objview serve` (the evaluation server of docs/server-api.md) and `objview export` (its
//! finished results as `objview run` JSON Lines). The server itself is `objview_server`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use objview_geom::normalize::Normalization;

#[derive(Parser)]
pub struct Args {
    /// Split files (`objview pool split` output); each is a split whose id is the file stem.
    #[arg(long, required = true, num_args = 1..)]
    pub pool: Vec<PathBuf>,
    /// Address to listen on (port 0: a free port, printed on start).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: String,
    /// The database (SQLite, WAL): episodes, actions and results; reopened after a restart.
    #[arg(long, default_value = "objview-server.sqlite")]
    pub db: PathBuf,
    /// Bearer tokens, one per line (`#` comments, an optional name after the token); without
    /// it the server is open.
    #[arg(long)]
    pub tokens: Option<PathBuf>,
    /// A split (id) whose running episodes show their metrics (repeatable); a bare `--public`
    /// makes every split of the pool public (a development server).
    #[arg(long, num_args = 0..=1, default_missing_value = "*")]
    pub public: Vec<String>,
    /// Seconds a client has for each action after an observation.
    #[arg(long, default_value_t = 100.0)]
    pub action_timeout: f64,
    /// Seconds a client has for its first action after the create response.
    #[arg(long, default_value_t = 300.0)]
    pub start_timeout: f64,
    /// Observable-reference cache folder (default: as `objview run`).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not cache observable references on disk.
    #[arg(long)]
    pub no_cache: bool,
    /// `unit` (raw assets) or `none` (already normalized, checked), as `objview run`.
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Prepared scenes (mesh, ground truth, observable reference, indexes, and the state after
    /// the start view that later creates copy) kept in memory; the least recently used is
    /// dropped first.
    #[arg(long, default_value_t = objview_server::pool::DEFAULT_SCENE_CACHE)]
    pub scene_cache: usize,
    /// Open connections at most (lowered to fit the descriptor limit). Beyond it a new
    /// connection closes the one that has been idle (or half-sent) the longest; when every open
    /// one is busy with a request, the new one gets 503 `overloaded`.
    #[arg(long, default_value_t = objview_server::conn::DEFAULT_MAX_CONNECTIONS)]
    pub max_connections: usize,
    /// Seconds from the first byte of a request to the end of its head (else closed).
    #[arg(long, default_value_t = objview_server::conn::DEFAULT_HEADER_TIMEOUT_S)]
    pub header_timeout: f64,
    /// Seconds for a request body to arrive (else 408 `request_timeout`, closed).
    #[arg(long, default_value_t = objview_server::conn::DEFAULT_BODY_TIMEOUT_S)]
    pub body_timeout: f64,
    /// Seconds a connection with no request in progress stays open after its last activity.
    #[arg(long, default_value_t = objview_server::conn::DEFAULT_IDLE_TIMEOUT_S)]
    pub idle_timeout: f64,
    /// Running episodes at most, in all: each holds its engine state in memory (55–66 MiB on a
    /// 100k-triangle object with a 300k-point ground truth; `objview bench serve` prints it).
    /// A create beyond it gets 429 `too_many_episodes`.
    #[arg(long, default_value_t = objview_server::DEFAULT_MAX_RUNNING)]
    pub max_running: usize,
    /// Running episodes at most per token (with --tokens), so that one client cannot take every
    /// place; beyond it, 429 `too_many_episodes`.
    #[arg(long, default_value_t = objview_server::DEFAULT_MAX_RUNNING_PER_TOKEN)]
    pub max_running_per_token: usize,
}

pub fn run(a: Args) -> Result<()> {
    let cfg = objview_server::ServerConfig {
        pool: a.pool,
        public: a.public,
        db: a.db.clone(),
        tokens: a.tokens,
        action_timeout_s: a.action_timeout,
        start_timeout_s: a.start_timeout,
        cache_dir: if a.no_cache {
            None
        } else {
            Some(a.cache_dir.unwrap_or_else(objview_runs::cache::default_reference_cache))
        },
        normalize: a.normalize,
        scene_cache: a.scene_cache,
        max_connections: a.max_connections,
        header_timeout_s: a.header_timeout,
        body_timeout_s: a.body_timeout,
        idle_timeout_s: a.idle_timeout,
        max_running: a.max_running,
        max_running_per_token: a.max_running_per_token,
    };
    objview_server::run(&cfg, &a.addr, |addr, state| {
        let splits: Vec<String> = state
            .pool
            .splits
            .iter()
            .map(|s| {
                format!("{} ({} objects{})", s.id, s.objects.len(), if s.public { ", public" } else { "" })
            })
            .collect();
        let l = &state.limits;
        println!(
            "objview serve: listening on http://{addr} | splits: {} | db {} | connections <= {} \
             (header {} s, body {} s, idle {} s) | running episodes <= {} ({} per token)",
            splits.join(", "),
            a.db.display(),
            l.conn.max_connections,
            l.conn.header_timeout.as_secs_f64(),
            l.body_timeout.as_secs_f64(),
            l.conn.idle_timeout.as_secs_f64(),
            l.max_running,
            l.max_running_per_token
        );
        let _ = std::io::stdout().flush();
    })?;
    Ok(())
}

#[derive(Parser)]
pub struct ExportArgs {
    /// The server's database.
    #[arg(long)]
    pub db: PathBuf,
    /// Results file (JSON Lines, `objview run` format; `objview report` reads it).
    #[arg(long)]
    pub out: PathBuf,
    /// Only this method's results.
    #[arg(long)]
    pub method: Option<String>,
}

pub fn export(a: ExportArgs) -> Result<()> {
    let lines = objview_server::db::export(&a.db, a.method.as_deref())?;
    crate::common::create_parent(&a.out)?;
    let mut text = String::new();
    for l in &lines {
        text.push_str(l);
        text.push('\n');
    }
    std::fs::write(&a.out, text).with_context(|| format!("writing {}", a.out.display()))?;
    println!("export: {} results -> {}", lines.len(), a.out.display());
    Ok(())
}
