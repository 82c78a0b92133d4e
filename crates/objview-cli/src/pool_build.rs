//! `objview pool build`: raw assets → a normalized pool folder (`objview_pool::build`): per
//! accepted object a normalized mesh and a ground-truth cloud, `manifest.json` (settings,
//! accepted objects with statistics, rejected objects with reasons) and `pool.json` (a split file
//! of the pool). Resumable: `build.jsonl` in the pool folder is read first and finished objects
//! are skipped.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args as ClapArgs;
use objview_dataset::{resolve_inputs, ItemOutcome, ObjectRef};
use objview_geom::normalize::Normalization;
use objview_pool::build::{
    finish_build, open_build_log, run_build, BuildSettings, BUILD_LOG, DEFAULT_MAX_FACES,
    DEFAULT_MIN_EXTENT_RATIO, DEFAULT_MIN_FACES, DEFAULT_MIN_SURFACE_VOXELS, MANIFEST_FILE, POOL_FILE,
};
use objview_voxel::DEFAULT_RESOLUTION;

#[derive(ClapArgs)]
pub struct Args {
    /// Raw assets: mesh files, folders (searched recursively for every supported format) or
    /// split files (.json; their ground-truth clouds are used). The uid of a mesh file is its stem.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Pool folder (created if missing; an earlier build there is resumed).
    #[arg(long)]
    pub out: PathBuf,
    /// `unit`: centre and scale into the unit ball; `none`: already normalized (checked).
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Reject meshes with fewer triangles.
    #[arg(long, default_value_t = DEFAULT_MIN_FACES)]
    pub min_faces: usize,
    /// Reject meshes with more triangles.
    #[arg(long, default_value_t = DEFAULT_MAX_FACES)]
    pub max_faces: usize,
    /// Reject flat meshes: smallest AABB extent below this fraction of the largest.
    #[arg(long, default_value_t = DEFAULT_MIN_EXTENT_RATIO, allow_hyphen_values = true)]
    pub min_extent_ratio: f64,
    /// Reject meshes whose ground-truth cloud has fewer voxels at --resolution.
    #[arg(long, default_value_t = DEFAULT_MIN_SURFACE_VOXELS)]
    pub min_surface_voxels: usize,
    /// Voxel size of the surface-voxel filter and statistics.
    #[arg(long, default_value_t = DEFAULT_RESOLUTION, allow_hyphen_values = true)]
    pub resolution: f64,
    /// Seed of sampled ground-truth clouds.
    #[arg(long, default_value_t = objview_geom::cloud::DEFAULT_CLOUD_SEED)]
    pub gt_seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Redo objects rejected by an earlier run (they are removed from build.jsonl first).
    #[arg(long)]
    pub retry_failed: bool,
}

pub fn run(a: Args) -> Result<()> {
    let settings = BuildSettings {
        normalize: a.normalize,
        min_faces: a.min_faces,
        max_faces: a.max_faces,
        min_extent_ratio: a.min_extent_ratio,
        resolution: a.resolution,
        min_surface_voxels: a.min_surface_voxels,
        gt_seed: a.gt_seed,
    };
    settings.validate()?;
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    anyhow::ensure!(threads >= 1, "--threads must be at least 1");
    let objects = resolve_inputs(&a.inputs)?;
    let settings_json = crate::provenance::settings("pool build", settings.to_json());

    let (out, existing) = open_build_log(&a.out, &settings_json, a.retry_failed)?;
    let log = a.out.join(BUILD_LOG);
    if existing.torn {
        eprintln!(
            "{}: cut off a torn last line (an interrupted write); that object is redone",
            log.display()
        );
    }
    let todo = objects.iter().filter(|o| !existing.done.contains(&o.uid)).count();
    eprintln!(
        "pool build: {} objects, {} already in {}, {todo} to do",
        objects.len(),
        objects.len() - todo,
        log.display()
    );

    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("thread pool")?;
    let terminal = std::io::stderr().is_terminal();
    let bar = crate::common::progress(todo as u64);
    let done = AtomicUsize::new(0);
    let t = Instant::now();
    let progress = |obj: &ObjectRef, outcome: &ItemOutcome| {
        let i = done.fetch_add(1, Ordering::Relaxed) + 1;
        bar.inc(1);
        let v: serde_json::Value = serde_json::from_str(&outcome.line).unwrap_or_default();
        let msg = if outcome.failed {
            format!(
                "[{i}/{todo}] {}: rejected ({}): {}",
                obj.uid,
                v["reason"].as_str().unwrap_or("?"),
                v["error"].as_str().unwrap_or("?")
            )
        } else {
            let st = &v["stats"];
            format!(
                "[{i}/{todo}] {}: {} faces, area {:.3}, {} surface voxels",
                obj.uid,
                st["faces"],
                st["surface_area"].as_f64().unwrap_or(f64::NAN),
                st["surface_voxels"]
            )
        };
        if terminal {
            bar.println(msg);
        } else {
            eprintln!("{msg}");
        }
    };
    let summary =
        pool.install(|| run_build(&objects, &a.out, &settings, &settings_json, out, &existing, progress))?;
    bar.finish_and_clear();
    let manifest = finish_build(&a.out, &settings_json)?;

    println!(
        "pool build: {} built now ({} rejected), {} skipped (already built) in {:.1} s",
        summary.processed,
        summary.failed,
        summary.skipped,
        t.elapsed().as_secs_f64()
    );
    println!(
        "pool: {} accepted, {} rejected -> {}",
        manifest.accepted.len(),
        manifest.rejected.len(),
        a.out.display()
    );
    for (reason, n) in &manifest.reasons {
        println!("  rejected {reason}: {n}");
    }
    if !manifest.summary.is_empty() {
        println!(
            "\n{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}",
            "statistic", "min", "q25", "median", "q75", "max"
        );
        for s in &manifest.summary {
            println!(
                "{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}",
                s.name,
                fmt_stat(s.min),
                fmt_stat(s.q25),
                fmt_stat(s.median),
                fmt_stat(s.q75),
                fmt_stat(s.max)
            );
        }
    }
    println!(
        "\nwrote {} and {} (a split file: `objview annotate {} --normalize none`)",
        a.out.join(MANIFEST_FILE).display(),
        a.out.join(POOL_FILE).display(),
        a.out.join(POOL_FILE).display()
    );
    Ok(())
}

/// Integers as integers, large values with 1 decimal, others with 4.
fn fmt_stat(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{x:.0}")
    } else if x.abs() >= 100.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.4}")
    }
}
