//! `objview bench ...`: benchmark commands of the hot paths. They print medians per operation
//! (and, where a peer is installed, a ratio against it measured in the same run) and can write
//! the figures as JSON. Benchmarks are commands, never timed unit tests. This module holds the
//! arguments and the printing; the measurements are [`objview_runs::bench`]'s (`bench serve`'s
//! are [`objview_server::load`]'s).

use anyhow::Result;
use clap::{Parser, Subcommand};
use objview_runs::bench::host::Host;
use objview_runs::bench::render::{RenderBench, RenderBenchSettings};
use serde_json::Value;
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub enum Command {
    /// Depth rendering (one thread, all threads) on built-in meshes of ~10k, 100k and 1M
    /// triangles, and per-view O(v) in both visibility modes on a ~100k-triangle object.
    Render(RenderArgs),
    /// Full difficulty annotation (26-size sweep + exact d_plan) of built-in objects of ~10k and
    /// ~100k triangles: time per stage with one thread and all threads, peak memory.
    Annotate(AnnotateBenchArgs),
    /// One episode step in the environment (render + fusion + SC/NSC + MS; the checkpoint CD
    /// reported separately) on a ~100k-triangle object with a ~300k-point ground truth, and
    /// RSE / RSE-Mov planning time per step.
    Episode(crate::bench_episode::EpisodeBenchArgs),
    /// How much d_plan, d_sat and r_vis move when the sampled ground-truth cloud is re-drawn
    /// with other seeds, on the built-in pool.
    Stability(StabilityArgs),
    /// The evaluation server under load: N concurrent clients playing episodes of random
    /// feasible moves; throughput and p50/p99 step latency, client and server side.
    Serve(crate::bench_serve::ServeBenchArgs),
}

#[derive(Parser)]
pub struct AnnotateBenchArgs {
    /// Built-in objects to tessellate at each size (comma-separated, see `objview objects list`).
    #[arg(long, value_delimiter = ',', default_value = "mug,gear")]
    pub objects: Vec<String>,
    /// Target triangle counts.
    #[arg(long, value_delimiter = ',', default_value = "10000,100000")]
    pub sizes: Vec<usize>,
    /// Timed annotations per configuration (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Parser)]
pub struct StabilityArgs {
    /// Ground-truth sampling seeds (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "0,1,2")]
    pub seeds: Vec<u64>,
    /// Built-in objects (comma-separated; default: the whole built-in pool).
    #[arg(long, value_delimiter = ',')]
    pub objects: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Exact d_plan time limit per annotation, seconds (objects that reach it show `?`).
    #[arg(long, default_value_t = 60.0)]
    pub time_limit: f64,
    /// Also write the per-object figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Parser)]
pub struct RenderArgs {
    /// Built-in object to tessellate at each size (see `objview objects list`).
    #[arg(long, default_value = "mug")]
    pub object: String,
    /// Target triangle counts.
    #[arg(long, value_delimiter = ',', default_value = "10000,100000,1000000")]
    pub sizes: Vec<usize>,
    /// Number of poses (the first N directions of tammes-128, radius 3).
    #[arg(long, default_value_t = 16)]
    pub poses: usize,
    /// Timed passes over the poses per size.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Triangle count of the visibility benchmark object (0 skips it).
    #[arg(long, default_value_t = 100_000)]
    pub visibility_triangles: usize,
    /// Views rendered for the `mesh` visibility mode.
    #[arg(long, default_value_t = 16)]
    pub mesh_views: usize,
    /// Skip the Open3D peer even when it is installed.
    #[arg(long)]
    pub no_peer: bool,
    /// Python interpreter used for the Open3D peer.
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Prints the host line every timing benchmark starts with (CPU model, logical CPUs, SIMD
/// features: figures only compare on the same kind of CPU) and returns the host for the
/// `--json` figures.
pub(crate) fn announce_host() -> Host {
    let host = Host::detect();
    println!("{}", host.line());
    host
}

/// Writes a benchmark's `--json` figures with the host added under `"host"`.
pub(crate) fn write_figures(path: &Path, mut figures: Value, host: &Host) -> Result<()> {
    if let Value::Object(m) = &mut figures {
        m.insert("host".into(), host.to_json());
    }
    crate::common::write_json(path, &figures)
}

pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Render(a) => bench_render(a),
        Command::Annotate(a) => crate::bench_annotate::bench_annotate(a),
        Command::Stability(a) => crate::bench_annotate::bench_stability(a),
        Command::Episode(a) => crate::bench_episode::bench_episode(a),
        Command::Serve(a) => crate::bench_serve::run(a),
    }
}

fn bench_render(a: RenderArgs) -> Result<()> {
    let host = announce_host();
    let bench = RenderBench::new(RenderBenchSettings {
        object: a.object.clone(),
        sizes: a.sizes.clone(),
        poses: a.poses,
        repeats: a.repeats,
        visibility_triangles: a.visibility_triangles,
        mesh_views: a.mesh_views,
        python: (!a.no_peer).then(|| a.python.clone()),
    })?;
    println!(
        "objview bench render: object={} poses={} repeats={} image=512x512 threads={}",
        a.object,
        bench.poses(),
        a.repeats,
        rayon::current_num_threads()
    );
    match (bench.peer_version(), a.no_peer) {
        (Some(v), _) => println!("peer: Open3D {v} RaycastingScene (Embree), same mesh and poses"),
        (None, true) => println!("peer: skipped (--no-peer)"),
        (None, false) => {
            println!("peer: Open3D not importable by {} (pip install open3d) — no ratio", a.python)
        }
    }
    println!(
        "{:>10} {:>12} {:>12} {:>12} {:>10} {:>12} {:>9}",
        "triangles", "1thr_med_ms", "1thr_p90_ms", "Nthr_med_ms", "Mrays/s", "open3d_ms", "ratio"
    );
    let report = bench.run(&mut |row| {
        if let Some(e) = &row.peer_error {
            eprintln!("peer failed: {e}");
        }
        let r = &row.render;
        println!(
            "{:>10} {:>12.3} {:>12.3} {:>12.3} {:>10.1} {:>12} {:>9}",
            r.triangles,
            r.single.median_ms,
            r.single.p90_ms,
            r.parallel.median_ms,
            r.single.mrays_per_s,
            row.open3d_median_ms.map_or("-".into(), |p| format!("{p:.3}")),
            row.speedup_vs_open3d.map_or("-".into(), |x| format!("{x:.2}x")),
        );
    })?;
    if bench.peer_version().is_some() {
        println!("ratio = Open3D median / objview single-thread median");
    }
    if let Some(v) = &report.visibility {
        let r = &v.bench;
        println!(
            "visibility O(v), one thread: triangles={} gt_points={} surface_voxels={} (S_gt build {:.2} ms, inverse setup {:.2} ms)",
            v.triangles,
            v.gt_points,
            r.voxels,
            r.set_build_ms,
            r.caster_build_ms
        );
        println!(
            "  inverse: median {:.3} ms/view (min {:.3}), mean |O(v)| {:.0}",
            r.inverse_median_ms, r.inverse_min_ms, r.inverse_mean_observed
        );
        if let (Some(m), Some(o)) = (r.mesh_median_ms, r.mesh_mean_observed) {
            println!("  mesh:    median {m:.3} ms/view (render included), mean |O(v)| {o:.0}");
        }
    }
    if let Some(p) = &a.json {
        write_figures(p, report.to_json(), &host)?;
    }
    Ok(())
}
