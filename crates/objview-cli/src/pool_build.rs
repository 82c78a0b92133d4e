//! `objview pool build`: raw assets → a normalized pool folder (`objview_pool::build`): per
//! accepted object a normalized mesh and a ground-truth cloud, `manifest.json` (settings,
//! accepted objects with statistics, rejected objects with reasons) and `pool.json` (a split file
//! of the pool). Resumable: `build.jsonl` in the pool folder is read first and finished objects
//! are skipped.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args as ClapArgs;
use objview_dataset::resolve_inputs;
use objview_geom::normalize::Normalization;
use objview_pool::build::{
    finish_build, open_build_log, run_build, BuildSettings, DEFAULT_MAX_FACES, DEFAULT_MIN_EXTENT_RATIO,
    DEFAULT_MIN_FACES, DEFAULT_MIN_SURFACE_VOXELS, MANIFEST_FILE, POOL_FILE,
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
    let objects = resolve_inputs(&a.inputs)?;
    let settings_json = objview_runs::provenance::settings("pool build", settings.to_json());
    let (out, existing) = open_build_log(&a.out, &settings_json, a.retry_failed)?;
    let t = Instant::now();
    let summary = run_build(
        &objects,
        &a.out,
        &settings,
        &settings_json,
        out,
        &existing,
        a.threads,
        &crate::common::TermProgress::new(false),
    )?;
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
