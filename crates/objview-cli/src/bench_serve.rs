//! `objview bench serve`: load on the evaluation server — N concurrent clients playing episodes
//! of random feasible tammes-360 moves — against an in-process server on a free loopback port
//! (a built-in object at a chosen size) or against `--url`. Prints throughput (moves per second)
//! and p50/p99 step latency measured by the clients and inside the server's action handler.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use objview_server::load::{run_load, LoadConfig, LoadReport};
use serde_json::json;

#[derive(Parser)]
pub struct ServeBenchArgs {
    /// Concurrent clients.
    #[arg(long, default_value_t = 32)]
    pub clients: usize,
    /// Episodes each client plays.
    #[arg(long, default_value_t = 2)]
    pub episodes_per_client: usize,
    /// Moves per episode.
    #[arg(long, default_value_t = 5)]
    pub budget: usize,
    /// View space of the episodes.
    #[arg(long, default_value = "whole")]
    pub space: String,
    /// Do not fetch each observation's depth before acting.
    #[arg(long)]
    pub no_depth: bool,
    /// Seed of the random moves.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Built-in object of the in-process server (see `objview objects list`).
    #[arg(long, default_value = "mug")]
    pub object: String,
    /// Its triangle count (the size: ~100k).
    #[arg(long, default_value_t = 100_000)]
    pub triangles: usize,
    /// Its ground-truth points (as `bench episode`).
    #[arg(long, default_value_t = 300_000)]
    pub gt_points: usize,
    /// Target a running server instead (needs --split and --target-object).
    #[arg(long)]
    pub url: Option<String>,
    /// Bearer token for --url (default: $OBJVIEW_TOKEN).
    #[arg(long)]
    pub token: Option<String>,
    /// Split of --url to use.
    #[arg(long)]
    pub split: Option<String>,
    /// Object (uid or index) of --split to use.
    #[arg(long, default_value = "0")]
    pub target_object: String,
    /// Observable-reference cache of the in-process server (default: as `objview run`).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn print(r: &LoadReport, what: &str) {
    println!("bench serve: {what}");
    println!(
        "  {} clients, {} episodes, {} moves in {:.2} s: {:.1} moves/s",
        r.clients, r.episodes, r.steps, r.seconds, r.steps_per_second
    );
    println!(
        "  step latency, client side: p50 {:.2} ms, p99 {:.2} ms (mean {:.2} ms, n = {})",
        r.client.p50_ms, r.client.p99_ms, r.client.mean_ms, r.client.samples
    );
    println!(
        "  step latency, server side (action handler): p50 {:.2} ms, p99 {:.2} ms (mean {:.2} ms, n = {})",
        r.server.p50_ms, r.server.p99_ms, r.server.mean_ms, r.server.samples
    );
    println!("  create (start view): p50 {:.2} ms, p99 {:.2} ms", r.create.p50_ms, r.create.p99_ms);
    if r.depth.samples > 0 {
        println!(
            "  depth fetch (1 MiB NPY, no engine work): p50 {:.2} ms, p99 {:.2} ms",
            r.depth.p50_ms, r.depth.p99_ms
        );
    }
    println!(
        "  fairness: longest wait for a step {:.2} ms (client {}, {:.1}× the p50); all episodes of a client took {:.2}–{:.2} s",
        r.max_wait.ms, r.max_wait.client, r.max_wait.over_p50, r.client_seconds.0, r.client_seconds.1
    );
}

/// This process's CPU time (user, system) before and after a run.
type CpuSpan = Option<((f64, f64), (f64, f64))>;

/// [`run_load`], and this process's CPU time around it.
fn run_timed(cfg: &LoadConfig) -> Result<(LoadReport, CpuSpan)> {
    let before = objview_runs::bench::process_cpu();
    let r = run_load(cfg)?;
    Ok((r, before.zip(objview_runs::bench::process_cpu())))
}

pub fn run(a: ServeBenchArgs) -> Result<()> {
    // Against `--url` this is the clients' machine; the server's may be another.
    let host = crate::bench::announce_host();
    if a.url.is_some() {
        println!("(the clients' host: the server at --url may run on another machine)");
    }
    let mut cfg = LoadConfig {
        url: String::new(),
        token: a.token.clone().or_else(|| std::env::var("OBJVIEW_TOKEN").ok()),
        split: String::new(),
        object: a.target_object.clone(),
        view_space: a.space.clone(),
        clients: a.clients,
        episodes_per_client: a.episodes_per_client,
        budget: a.budget,
        seed: a.seed,
        fetch_depth: !a.no_depth,
        candidate_set: "tammes-360".into(),
    };
    // In-process: the peak resident memory after the warm-up episode and after the run.
    let mut memory: Option<(u64, u64)> = None;
    let (report, cpu, what, _server, _dir) = if let Some(url) = &a.url {
        cfg.url = url.clone();
        cfg.split = a.split.clone().context("--url needs --split")?;
        let (r, cpu) = run_timed(&cfg)?;
        (r, cpu, format!("{url}, split {}, object {}", cfg.split, cfg.object), None, None)
    } else {
        let dir = tempfile::tempdir().context("temporary folder")?;
        let obj = objview_geom::synth::find(&a.object)
            .with_context(|| format!("--object {}: no such built-in object", a.object))?;
        let mesh = obj.build_with_triangles(a.triangles);
        let mesh_path = dir.path().join(format!("{}.obj", a.object));
        objview_geom::write::write_obj(&mesh_path, &mesh)?;
        let gt =
            objview_geom::cloud::sample_surface(&mesh, a.gt_points, objview_geom::cloud::DEFAULT_CLOUD_SEED);
        let gt_path = dir.path().join(format!("{}.ply", a.object));
        objview_geom::cloud::write_ply_points(&gt_path, &gt)?;
        let split = dir.path().join("bench.json");
        std::fs::write(
            &split,
            json!([{"uid": a.object, "mesh": mesh_path.file_name().and_then(|s| s.to_str()),
                    "gt_cloud": gt_path.file_name().and_then(|s| s.to_str())}])
            .to_string(),
        )?;
        let server_cfg = objview_server::ServerConfig {
            pool: vec![split],
            db: dir.path().join("bench.sqlite"),
            cache_dir: Some(a.cache_dir.clone().unwrap_or_else(objview_runs::cache::default_reference_cache)),
            // Room for every client's episode, whatever --clients.
            max_running: a.clients.max(objview_server::DEFAULT_MAX_RUNNING),
            ..Default::default()
        };
        let server = objview_server::spawn(&server_cfg, "127.0.0.1:0")?;
        cfg.url = server.url();
        cfg.split = "bench".into();
        eprintln!(
            "bench serve: in-process server at {} on {} ({} triangles, {} GT points); preparing the scene",
            cfg.url,
            a.object,
            mesh.num_triangles(),
            gt.len()
        );
        // One warm-up episode builds (or loads) the scene and its observable reference.
        let warm = LoadConfig { clients: 1, episodes_per_client: 1, ..cfg.clone() };
        run_load(&warm)?;
        let warm_peak = objview_runs::bench::peak_rss();
        let (r, cpu) = run_timed(&cfg)?;
        memory = warm_peak.zip(objview_runs::bench::peak_rss());
        let sc = server.state.scenes.stats();
        eprintln!("bench serve: scene cache: {} build(s), {} reuse(s), {} held", sc.builds, sc.hits, sc.held);
        let what = format!(
            "in-process server, {} ({} triangles, {} GT points), view space {}",
            a.object,
            mesh.num_triangles(),
            gt.len(),
            a.space
        );
        (r, cpu, what, Some(server), Some(dir))
    };
    print(&report, &what);
    let concurrent = a.clients.min(report.episodes);
    let memory_json = memory.map(|(warm, peak)| {
        let per = objview_runs::bench::memory_per_episode(warm, peak, concurrent);
        let mib = |b: f64| b / (1024.0 * 1024.0);
        println!(
            "  memory (server and clients, one process): peak RSS {:.0} MiB; {:.0} MiB after the warm-up episode (scene built){}",
            mib(peak as f64),
            mib(warm as f64),
            per.map_or(String::new(), |p| format!(
                ", so ≈ {:.1} MiB per further concurrent episode ({concurrent} at once)",
                mib(p)
            ))
        );
        json!({"peak_rss_bytes": peak, "warm_peak_rss_bytes": warm, "concurrent_episodes": concurrent,
               "bytes_per_further_episode": per})
    });
    let cpu_json = cpu.map(|((u0, s0), (u1, s1))| {
        let (user, system) = (u1 - u0, s1 - s0);
        let cores = host.logical_cpus;
        let busy = (user + system) / report.seconds.max(1e-9);
        println!(
            "  CPU of this process ({}) during the run: user {user:.2} s + system {system:.2} s = {busy:.2} of {cores} cores busy (system time is mostly the kernel zeroing fresh pages; on a VM its cost moves from run to run, and throughput with it)",
            if a.url.is_some() { "the clients only" } else { "server and clients" }
        );
        json!({"user_seconds": user, "system_seconds": system, "cores_busy": busy, "cores": cores})
    });
    if let Some(p) = &a.json {
        let figures = json!({"what": what, "depth_fetched": !a.no_depth, "report": report, "memory": memory_json,
                             "cpu": cpu_json});
        crate::bench::write_figures(p, figures, &host)?;
    }
    Ok(())
}
