//! `objview annotate`: the difficulty annotation of SPEC §4 for a batch of objects, one JSON line
//! per object (`objview_dataset::annotate`), resumable (`--out` is read first and finished
//! objects are skipped) and shardable (`--shard I/N`).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use objview_dataset::annotate::{annotate_object, failure, AnnotateSettings, GridViews};
use objview_dataset::{resolve_inputs, run_batch, to_line, ItemOutcome, ResumableJsonl, Shard};
use objview_difficulty::{CoverSettings, DEFAULT_TIME_LIMIT_S};
use objview_geom::normalize::Normalization;
use objview_voxel::{VisibilityMode, DEFAULT_RESOLUTION};

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
    let settings = AnnotateSettings {
        normalize: a.normalize,
        visibility: a.visibility,
        resolution: a.resolution,
        gt_seed: a.gt_seed,
        gt_cloud_dir: a.gt_cloud_dir.clone(),
        cover: CoverSettings {
            time_limit_s: a.time_limit,
            min_views_per_element: a.min_views,
            method: a.cover_method,
            ..Default::default()
        },
        ..Default::default()
    };
    settings.validate()?;
    if let Some(dir) = &a.gt_cloud_dir {
        anyhow::ensure!(dir.is_dir(), "{}: --gt-cloud-dir is not a folder", dir.display());
    }
    let shard = a.shard.unwrap_or(Shard::ALL);
    let objects = shard.select(resolve_inputs(&a.inputs)?);
    let views = GridViews::new(settings.view_radius)?;
    let mut settings_json = crate::provenance::settings("annotate", settings.to_json());
    settings_json["shard"] = serde_json::json!(shard.to_string());

    let (out, existing) = ResumableJsonl::open(&a.out, "uid", a.retry_failed)?;
    if existing.torn {
        eprintln!(
            "{}: cut off a torn last line (an interrupted write); that object is redone",
            a.out.display()
        );
    }
    let todo = objects.iter().filter(|o| !existing.done.contains(&o.uid)).count();
    eprintln!(
        "annotate: {} objects (shard {shard}), {} already in {}, {todo} to do; {} views per object",
        objects.len(),
        objects.len() - todo,
        a.out.display(),
        views.total_views()
    );

    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    anyhow::ensure!(threads >= 1, "--threads must be at least 1");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("thread pool")?;
    let terminal = std::io::stderr().is_terminal();
    let bar = crate::common::progress(todo as u64);
    let done = AtomicUsize::new(0);
    let t = Instant::now();

    let work =
        |obj: &objview_dataset::ObjectRef| match annotate_object(obj, &settings, &views, &settings_json) {
            Ok(ann) => ItemOutcome { line: to_line(&ann), failed: false },
            Err(e) => ItemOutcome { line: to_line(&failure(obj, &e, &settings_json)), failed: true },
        };
    let progress = |obj: &objview_dataset::ObjectRef, outcome: &ItemOutcome| {
        let i = done.fetch_add(1, Ordering::Relaxed) + 1;
        bar.inc(1);
        let v: serde_json::Value = serde_json::from_str(&outcome.line).unwrap_or_default();
        let msg = if outcome.failed {
            format!("[{i}/{todo}] {}: FAILED: {}", obj.uid, v["error"].as_str().unwrap_or("?"))
        } else {
            format!(
                "[{i}/{todo}] {}: r_vis={:.3} d_sat={} d_plan={} ({}) {:.2} s",
                obj.uid,
                v["r_vis"].as_f64().unwrap_or(f64::NAN),
                v["d_sat"],
                v["d_plan"],
                v["d_plan_status"].as_str().unwrap_or("?"),
                v["seconds"].as_f64().unwrap_or(f64::NAN)
            )
        };
        if terminal {
            bar.println(msg);
        } else {
            eprintln!("{msg}");
        }
    };
    let summary = pool.install(|| run_batch(&objects, out, &existing, work, progress))?;
    bar.finish_and_clear();
    println!(
        "annotate: {} done, {} failed, {} skipped (already in the file) in {:.1} s -> {}",
        summary.processed - summary.failed,
        summary.failed,
        summary.skipped,
        t.elapsed().as_secs_f64(),
        a.out.display()
    );
    Ok(())
}
