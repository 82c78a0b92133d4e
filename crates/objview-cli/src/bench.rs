//! `objview bench ...`: benchmark commands of the hot paths. They print medians per operation
//! (and, where a peer is installed, a ratio against it measured in the same run) and can write
//! the figures as JSON. Benchmarks are commands, never timed unit tests.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use objview_geom::cloud::{cloud_count, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::pose::VIEW_RADIUS;
use objview_geom::{synth, Mesh, Pose};
use objview_views::ViewSet;
use serde_json::json;
use std::path::PathBuf;
use std::process::Command as Process;

#[derive(Subcommand)]
pub enum Command {
    /// Depth rendering (one thread, all threads) on built-in meshes of ~10k, 100k and 1M
    /// triangles, and per-view O(v) in both visibility modes on a ~100k-triangle object.
    Render(RenderArgs),
    /// Full difficulty annotation (26-size sweep + exact d_plan) of built-in objects of ~10k and
    /// ~100k triangles: time per stage with one thread and all threads, peak memory.
    Annotate(AnnotateBenchArgs),
    /// One episode step in the environment (render + fusion + metrics) on a ~100k-triangle
    /// object with a ~300k-point ground truth, and RSE / RSE-Mov planning time per step.
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
    let obj = synth::find(&a.object).with_context(|| {
        format!("--object: no built-in object named {:?} (see `objview objects list`)", a.object)
    })?;
    let poses: Vec<Pose> =
        ViewSet::resolve("tammes-128")?.poses(VIEW_RADIUS).into_iter().take(a.poses.max(1)).collect();
    let peer = if a.no_peer { None } else { open3d_available(&a.python) };
    println!(
        "objview bench render: object={} poses={} repeats={} image=512x512 threads={}",
        a.object,
        poses.len(),
        a.repeats,
        rayon::current_num_threads()
    );
    match (&peer, a.no_peer) {
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
    let mut rows = Vec::new();
    for &size in &a.sizes {
        let mesh = obj.build_with_triangles(size);
        let r = objview_render::bench::bench_render(&mesh, &poses, a.repeats.max(1));
        let peer_ms = match &peer {
            Some(_) => run_peer(&a.python, &mesh, &poses, a.repeats.max(1))?,
            None => None,
        };
        let ratio = peer_ms.map(|p| p / r.single.median_ms);
        println!(
            "{:>10} {:>12.3} {:>12.3} {:>12.3} {:>10.1} {:>12} {:>9}",
            r.triangles,
            r.single.median_ms,
            r.single.p90_ms,
            r.parallel.median_ms,
            r.single.mrays_per_s,
            peer_ms.map_or("-".into(), |p| format!("{p:.3}")),
            ratio.map_or("-".into(), |x| format!("{x:.2}x")),
        );
        anyhow::ensure!(
            r.identical,
            "single-thread and parallel renders differ on {} triangles",
            r.triangles
        );
        rows.push(json!({"render": r, "open3d_median_ms": peer_ms, "speedup_vs_open3d": ratio}));
    }
    if peer.is_some() {
        println!("ratio = Open3D median / objview single-thread median");
    }

    let mut vis_json = serde_json::Value::Null;
    if a.visibility_triangles > 0 {
        let mesh = obj.build_with_triangles(a.visibility_triangles);
        let n = cloud_count(mesh.surface_area());
        let cloud = sample_surface(&mesh, n, DEFAULT_CLOUD_SEED);
        let r = objview_voxel::bench::bench_visibility(
            &mesh,
            &cloud,
            objview_voxel::DEFAULT_RESOLUTION,
            &poses,
            a.repeats.max(1),
            a.mesh_views,
        )?;
        println!(
            "visibility O(v), one thread: triangles={} gt_points={} surface_voxels={} (S_gt build {:.2} ms, inverse setup {:.2} ms)",
            mesh.num_triangles(),
            cloud.len(),
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
        vis_json = json!({
            "triangles": mesh.num_triangles(),
            "gt_points": cloud.len(),
            "surface_voxels": r.voxels,
            "set_build_ms": r.set_build_ms,
            "inverse_setup_ms": r.caster_build_ms,
            "inverse_median_ms": r.inverse_median_ms,
            "inverse_min_ms": r.inverse_min_ms,
            "mesh_median_ms": r.mesh_median_ms,
        });
    }
    if let Some(p) = &a.json {
        let v = json!({
            "settings": objview_runs::provenance::settings("bench render", json!({
                "object": a.object, "sizes": a.sizes, "poses": poses.len(), "repeats": a.repeats,
                "threads": rayon::current_num_threads(),
            })),
            "render": rows,
            "visibility": vis_json,
        });
        crate::common::write_json(p, &v)?;
    }
    Ok(())
}

/// Open3D's version if `python -c "import open3d"` works.
fn open3d_available(python: &str) -> Option<String> {
    let out = Process::new(python).args(["-c", "import open3d; print(open3d.__version__)"]).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Runs `bench/peer_open3d.py` on `mesh` and `poses`; its median ms per frame.
fn run_peer(python: &str, mesh: &Mesh, poses: &[Pose], repeats: usize) -> Result<Option<f64>> {
    let script = peer_script()?;
    let dir = tempfile::tempdir()?;
    let mesh_path = dir.path().join("mesh.ply");
    objview_geom::write::write_ply(&mesh_path, mesh)?;
    let poses_path = dir.path().join("poses.txt");
    let text: String = poses
        .iter()
        .map(|p| p.to_array().iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(&poses_path, text)?;
    let out = Process::new(python)
        .arg(&script)
        .arg(&mesh_path)
        .arg(&poses_path)
        .arg("--repeats")
        .arg(repeats.to_string())
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    if !out.status.success() {
        eprintln!("peer failed: {}", String::from_utf8_lossy(&out.stderr).trim());
        return Ok(None);
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("parsing the output of {}", script.display()))?;
    Ok(v["median_ms"].as_f64())
}

/// `bench/peer_open3d.py` beside the workspace this binary was built from.
fn peer_script() -> Result<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../bench/peer_open3d.py");
    anyhow::ensure!(p.exists(), "peer script {} not found", p.display());
    Ok(p)
}
