//! `objview run`: one online episode per object (SPEC §5) with a named planner, view space and
//! budget; one JSON line per episode (`objview_episode::result::EpisodeResult`), resumable
//! (objects already in `--out` are skipped), written in input order whatever the thread count.

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use anyhow::{bail, Context, Result};
use clap::Parser;
use objview_dataset::{resolve_inputs, Shard};
use objview_episode::{Budget, EpisodeSettings};
use objview_geom::normalize::Normalization;
use objview_geom::Pose;
use objview_planners::registry::Registry;
use objview_runs::{parse_params, EpisodePlan, RunSummary};
use objview_server::remote::RemotePlan;
use objview_views::{ViewSet, ViewSpace};

use crate::common::TermProgress;

#[derive(Parser, Clone)]
pub struct Args {
    /// Planner (the list is below; `--param` changes its settings).
    #[arg(long)]
    pub planner: String,
    /// A planner parameter `NAME=VALUE` (repeatable; VALUE is JSON or a bare string; dotted
    /// names reach nested settings), e.g. `--param gamma=0.5 --param occupancy.resolution=32`.
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// View space: whole, hemi, quarter, eighth, or a feasibility rule file (.json).
    #[arg(long, default_value = "whole")]
    pub space: String,
    /// Budget: a number K of planner views after the start view (5, 30, …) or `auto`.
    #[arg(long, default_value = "auto")]
    pub budget: String,
    /// Objects: mesh files, folders (searched recursively) or split files (.json). With
    /// --server: split ids of the server, each `SPLIT` (all its objects, in order) or
    /// `SPLIT:ID,ID,…` (objects by uid or index); a split file's path stands for its stem.
    #[arg(long, required = true, num_args = 1..)]
    pub objects: Vec<PathBuf>,
    /// Results file (JSON Lines); an existing file of the same run is resumed.
    #[arg(long)]
    pub out: PathBuf,
    /// Candidate view set handed to the planner: tammes-N or a view-set file.
    #[arg(long, default_value = "tammes-360")]
    pub candidates: String,
    /// Seed (mixed per object, view space and budget).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Parallel episodes (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// `unit` (raw assets) or `none` (already normalized, checked).
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Folder of ground-truth clouds `<uid>.{pcd,ply,npy,npz}`; without it clouds are sampled.
    #[arg(long)]
    pub gt_cloud_dir: Option<PathBuf>,
    /// Observable-reference cache folder (default: $XDG_CACHE_HOME or ~/.cache, objview/reference).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not cache observable references on disk.
    #[arg(long)]
    pub no_cache: bool,
    /// Start pose `cx,cy,cz,lx,ly,lz,roll` (default: direction (1,1,1) at radius 3).
    #[arg(long, allow_hyphen_values = true)]
    pub start_pose: Option<String>,
    /// Maximum views, start included.
    #[arg(long, default_value_t = 129)]
    pub cap: usize,
    /// Budget checkpoints K (comma-separated); iterative runs stop at `enough_info` once these
    /// and every MS@δ exist.
    #[arg(long, value_delimiter = ',', default_value = "5,10,30,50")]
    pub checkpoints: Vec<usize>,
    /// Iterative planners: keep going after every checkpoint exists (until the cap or their own
    /// stop) — e.g. the oracle's tammes-128 exhaustion for the slow-saturation table.
    #[arg(long)]
    pub no_enough_info: bool,
    /// Write 0 for every wall-clock time, so that reruns are byte-identical.
    #[arg(long)]
    pub no_timings: bool,
    /// Redo objects whose earlier line is a failure.
    #[arg(long)]
    pub retry_failed: bool,
    /// Run only the I-th of N parts of the objects (0 <= I < N), by the same hash of the uid as
    /// `annotate --shard`; each shard writes its own --out, and `cat` of the shard files is
    /// the whole run (lines are independent of the shard). Local runs only.
    #[arg(long)]
    pub shard: Option<Shard>,
    /// Do not print per-episode lines.
    #[arg(long)]
    pub quiet: bool,
    /// Run the episodes on an evaluation server (`objview serve`) at this URL instead of a
    /// local engine: the planner runs here and sees only what the API gives it; the result
    /// lines are the server's (identical to a local run's, wall-clock times aside). The
    /// object, its normalization, ground truth, reference cache, start pose, cap and
    /// checkpoints are the server's.
    #[arg(long, value_name = "URL")]
    pub server: Option<String>,
    /// Bearer token for --server (default: $OBJVIEW_TOKEN).
    #[arg(long)]
    pub token: Option<String>,
}

/// The planners this binary offers: the tables of every planner crate it links (the classical
/// and hybrid planners of `objview-planners`, the learned ones of `objview-learn`), with the
/// hybrid rows replaced by `objview-learn`'s, which can build the `net` completion backend and
/// default to it.
pub fn registry() -> &'static Registry {
    static REGISTRY: OnceLock<Registry> = OnceLock::new();
    REGISTRY.get_or_init(|| {
        let mut r = Registry::from_tables(&[objview_planners::registry::TABLE, objview_learn::TABLE])
            .expect("planner names are unique");
        r.replace(objview_learn::completion_backend::HYBRID_TABLE)
            .expect("objview-learn's hybrid rows replace objview-planners' own");
        r
    })
}

/// The `--help` text after the options: every planner of [`registry`], one line each.
pub fn planners_help() -> String {
    format!("Planners (name, family, execution mode, summary):\n{}", registry().help())
}

pub fn run(a: Args) -> Result<()> {
    let s = execute(&a)?;
    println!(
        "run {} / {} / budget {}: {} episodes, {} failed, {} skipped (already in the file) in {:.1} s -> {}",
        a.planner,
        a.space,
        a.budget,
        s.done,
        s.failed,
        s.skipped,
        s.seconds,
        a.out.display()
    );
    Ok(())
}

/// The episode plan of `a` (a local run).
pub fn plan(a: &Args) -> Result<EpisodePlan> {
    let budget = Budget::parse(&a.budget).map_err(anyhow::Error::msg).context("--budget")?;
    let space = ViewSpace::resolve(&a.space).with_context(|| format!("--space {}", a.space))?;
    let space_name =
        if ViewSpace::builtin(&a.space).is_some() { a.space.clone() } else { space.name.clone() };
    let cands = ViewSet::resolve(&a.candidates).with_context(|| format!("--candidates {}", a.candidates))?;
    let settings = EpisodeSettings {
        cap: a.cap,
        checkpoint_ks: a.checkpoints.clone(),
        enough_info: !a.no_enough_info,
        record_timings: !a.no_timings,
        candidates: a.candidates.clone(),
        ..Default::default()
    };
    let start_pose = match &a.start_pose {
        Some(s) => {
            let p = Pose::parse(s).map_err(anyhow::Error::msg).context("--start-pose")?;
            objview_episode::check_view_pose(&p.to_array()).context("--start-pose")?
        }
        None => objview_views::start_pose(settings.view_radius),
    };
    Ok(EpisodePlan {
        planner: a.planner.clone(),
        params: parse_params(&a.params)?,
        space,
        space_name,
        budget,
        objects: a.shard.unwrap_or(Shard::ALL).select(resolve_inputs(&a.objects)?),
        out: a.out.clone(),
        candidates_name: a.candidates.clone(),
        candidates: Arc::new(cands.poses(settings.view_radius)),
        seed: a.seed,
        threads: a.threads,
        normalize: a.normalize,
        gt_cloud_dir: a.gt_cloud_dir.clone(),
        cache_dir: objview_runs::cache::reference_cache(a.cache_dir.clone(), a.no_cache),
        start_pose,
        settings,
        retry_failed: a.retry_failed,
    })
}

/// Runs the episodes of `a`.
pub fn execute(a: &Args) -> Result<RunSummary> {
    let progress = TermProgress::new(a.quiet);
    let Some(url) = &a.server else {
        return Ok(plan(a)?.run(registry(), &progress)?);
    };
    if a.shard.is_some() {
        bail!("--shard splits local runs; with --server, give each process its own objects (SPLIT:ID,ID,…)");
    }
    let server_side = [
        ("--start-pose", a.start_pose.is_some()),
        ("--cap", a.cap != 129),
        ("--checkpoints", a.checkpoints != [5, 10, 30, 50]),
        ("--no-enough-info", a.no_enough_info),
        ("--gt-cloud-dir", a.gt_cloud_dir.is_some()),
        ("--cache-dir", a.cache_dir.is_some()),
        ("--no-cache", a.no_cache),
        ("--normalize", a.normalize != Normalization::Unit),
    ];
    let plan = RemotePlan {
        url: url.clone(),
        token: a.token.clone().or_else(|| std::env::var("OBJVIEW_TOKEN").ok()),
        planner: a.planner.clone(),
        params: parse_params(&a.params)?,
        space: a.space.clone(),
        budget: Budget::parse(&a.budget).map_err(anyhow::Error::msg).context("--budget")?,
        candidates: a.candidates.clone(),
        seed: a.seed,
        record_timings: !a.no_timings,
        objects: a.objects.clone(),
        out: a.out.clone(),
        threads: a.threads,
        retry_failed: a.retry_failed,
    };
    // Settings that belong to the server are refused rather than silently ignored (after the
    // planner and budget checks, which come first as for a local run).
    let probe = registry().with_params(&plan.planner, &plan.params).map_err(anyhow::Error::msg)?;
    objview_runs::episodes::check_budget(&plan.planner, probe.as_ref(), plan.budget)?;
    if let Some((flag, _)) = server_side.iter().find(|(_, given)| *given) {
        if !probe.needs_ground_truth() {
            bail!("{flag} is a setting of the server (objview serve), not of run --server");
        }
    }
    Ok(plan.run(registry(), &progress)?)
}
