//! `objview annotate`: the difficulty annotation of SPEC §4 for a batch of objects, one JSON line
//! per object (`objview_dataset::annotate`), resumable (`--out` is read first and finished
//! objects are skipped) and shardable (`--shard I/N`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Parser;
use objview_dataset::annotate::AnnotateSettings;
use objview_dataset::Shard;
use objview_difficulty::{CoverSettings, DEFAULT_TIME_LIMIT_S};
use objview_geom::normalize::Normalization;
use objview_runs::annotate::AnnotatePlan;
use objview_voxel::{VisibilityMode, DEFAULT_RESOLUTION};

use crate::common::TermProgress;

#[derive(Parser)]
pub struct Args {
    /// Mesh files, folders (searched recursively for every supported format) or split files
    /// (.json). The uid of a mesh file is its file stem.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Results file (JSON Lines). An existing file is resumed: objects already in it are skipped.
    #[arg(long)]
    pub out: PathBuf,
    /// `unit`: centre and scale into the unit ball; `none`: already normalized (checked).
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Folder of ground-truth clouds `<uid>.{pcd,ply,npy,npz}` (in the mesh file's frame); a
    /// missing cloud is an error for that object. Without it, clouds are sampled (SPEC §1).
    #[arg(long)]
    pub gt_cloud_dir: Option<PathBuf>,
    /// Seed of sampled ground-truth clouds.
    #[arg(long, default_value_t = objview_geom::cloud::DEFAULT_CLOUD_SEED)]
    pub gt_seed: u64,
    /// O(v) model: `inverse` (reference implementation) or `mesh` (rendered surface).
    #[arg(long, default_value = "inverse")]
    pub visibility: VisibilityMode,
    /// Voxel size r.
    #[arg(long, default_value_t = DEFAULT_RESOLUTION, allow_hyphen_values = true)]
    pub resolution: f64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Annotate only the I-th of N parts (0 <= I < N), chosen by a hash of the uid.
    #[arg(long)]
    pub shard: Option<Shard>,
    /// Solver time limit per object, seconds; a stopped solve is reported as `time_limit`.
    #[arg(long, default_value_t = DEFAULT_TIME_LIMIT_S, allow_hyphen_values = true)]
    pub time_limit: f64,
    /// U = voxels seen by at least this many tammes-128 views (SPEC §4: 1).
    #[arg(long, default_value_t = 1)]
    pub min_views: usize,
    /// Exact d_plan method: `auto` (combinatorial search, HiGHS ILP if it runs out of time) or
    /// `ilp` (HiGHS only).
    #[arg(long, default_value = "auto")]
    pub cover_method: objview_difficulty::CoverMethod,
    /// Redo objects whose earlier line is a failure (they are removed from --out first).
    #[arg(long)]
    pub retry_failed: bool,
}

pub fn run(a: Args) -> Result<()> {
    let plan = AnnotatePlan {
        inputs: a.inputs,
        out: a.out.clone(),
        settings: AnnotateSettings {
            normalize: a.normalize,
            visibility: a.visibility,
            resolution: a.resolution,
            gt_seed: a.gt_seed,
            gt_cloud_dir: a.gt_cloud_dir,
            cover: CoverSettings {
                time_limit_s: a.time_limit,
                min_views_per_element: a.min_views,
                method: a.cover_method,
                ..Default::default()
            },
            ..Default::default()
        },
        threads: a.threads,
        shard: a.shard.unwrap_or(Shard::ALL),
        retry_failed: a.retry_failed,
    };
    let (s, seconds) = plan.run(&TermProgress::new(false))?;
    println!(
        "annotate: {} done, {} failed, {} skipped (already in the file) in {seconds:.1} s -> {}",
        s.processed - s.failed,
        s.failed,
        s.skipped,
        a.out.display()
    );
    Ok(())
}
