//! `objview run`: one online episode per object (SPEC §5) with a named planner, view space and
//! budget; one JSON line per episode (`objview_episode::result::EpisodeResult`), resumable
//! (objects already in `--out` are skipped), written in input order whatever the thread count.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use objview_dataset::annotate::gt_cloud_path;
use objview_dataset::{resolve_inputs, run_batch, to_line, ItemOutcome, ObjectRef, ResumableJsonl};
use objview_episode::{load_scene, run_episode, Budget, EpisodeSettings, SceneSource};
use objview_geom::normalize::Normalization;
use objview_geom::Pose;
use objview_views::{ViewSet, ViewSpace};
use serde_json::json;

#[derive(Parser, Clone)]
pub struct Args {
    /// Planner: random-tsp, rse, rse-mov, random, oracle.
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

/// The default reference cache folder.
pub fn default_cache_dir() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("objview").join("reference")
}

/// Summary of one `run`.
pub struct RunSummary {
    pub done: usize,
    pub failed: usize,
    pub skipped: usize,
    pub seconds: f64,
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

/// Runs the episodes of `a` (used by `run` and by the demo).
pub fn execute(a: &Args) -> Result<RunSummary> {
    let t = Instant::now();
    let budget = Budget::parse(&a.budget).map_err(anyhow::Error::msg).context("--budget")?;
    let params = parse_params(&a.params)?;
    let probe = objview_planners::registry::with_params(&a.planner, &params).map_err(anyhow::Error::msg)?;
    if probe.execution_mode() == objview_episode::ExecutionMode::BudgetedPlan && budget == Budget::Auto {
        bail!("--planner {} is a budgeted plan: give a fixed --budget K (e.g. 5 or 30), not auto", a.planner);
    }
    if let Some(url) = &a.server {
        return execute_remote(a, url, t, budget, &params, probe.as_ref());
    }
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
    settings.validate().map_err(anyhow::Error::msg)?;
    let candidates = Arc::new(cands.poses(settings.view_radius));
    let start_pose = match &a.start_pose {
        Some(s) => {
            let p = Pose::parse(s).map_err(anyhow::Error::msg).context("--start-pose")?;
            objview_episode::check_view_pose(&p.to_array()).context("--start-pose")?
        }
        None => objview_views::start_pose(settings.view_radius),
    };
    anyhow::ensure!(
        space.is_feasible(&start_pose),
        "the start pose is not feasible in view space {}",
        a.space
    );
    let cache_dir =
        if a.no_cache { None } else { Some(a.cache_dir.clone().unwrap_or_else(default_cache_dir)) };
    if let Some(dir) = &a.gt_cloud_dir {
        anyhow::ensure!(dir.is_dir(), "{}: --gt-cloud-dir is not a folder", dir.display());
    }
    let objects = resolve_inputs(&a.objects)?;
    let record = objview_server::spec::RunRecord {
        planner: &a.planner,
        planner_params: probe.params(),
        view_space: &space_name,
        space: &space,
        budget,
        seed: a.seed,
        candidates: &a.candidates,
        candidate_count: candidates.len(),
        start_pose,
        normalize: a.normalize,
        settings: &settings,
    }
    .to_json();
    check_same_run(&a.out, &record)?;
    let work = |obj: &ObjectRef| -> Result<String> {
        let gt = gt_cloud_path(obj, a.gt_cloud_dir.as_deref())?;
        let src = SceneSource {
            uid: &obj.uid,
            mesh: &obj.mesh,
            gt_cloud: gt.as_deref(),
            normalization: a.normalize,
        };
        let scene = Arc::new(load_scene(&src, &space, &space_name, &settings, cache_dir.as_deref())?);
        let mut planner =
            objview_planners::registry::with_params(&a.planner, &params).map_err(anyhow::Error::msg)?;
        let res = run_episode(
            scene,
            planner.as_mut(),
            &settings,
            budget,
            a.seed,
            start_pose,
            candidates.clone(),
            record.clone(),
        )?;
        Ok(to_line(&res))
    };
    let failure = |obj: &ObjectRef, e: &anyhow::Error| {
        to_line(&json!({
            "uid": obj.uid,
            "mesh": obj.mesh.display().to_string(),
            "error": crate::one_line(e),
            "settings": record,
        }))
    };
    batch(a, &objects, &space_name, budget, t, work, failure)
}

/// `run --server`: the same episodes against an evaluation server. Objects are `SPLIT` or
/// `SPLIT:ID,ID,…` (uids or indices) of the server; settings that belong to the server are
/// refused rather than silently ignored.
fn execute_remote(
    a: &Args,
    url: &str,
    t: Instant,
    budget: Budget,
    params: &[(String, serde_json::Value)],
    probe: &dyn objview_episode::Planner,
) -> Result<RunSummary> {
    if probe.needs_ground_truth() {
        bail!(
            "--planner {} reads the ground truth: it cannot run against a server (run it locally)",
            a.planner
        );
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
    if let Some((flag, _)) = server_side.iter().find(|(_, given)| *given) {
        bail!("{flag} is a setting of the server (objview serve), not of run --server");
    }
    anyhow::ensure!(
        ViewSpace::builtin(&a.space).is_some(),
        "--space {}: a server offers the built-in view spaces only (whole, hemi, quarter, eighth)",
        a.space
    );
    let token = a.token.clone().or_else(|| std::env::var("OBJVIEW_TOKEN").ok());
    let client = objview_server::client::Client::new(url, token.as_deref());
    client.health().with_context(|| format!("--server {url}"))?;
    let mut objects: Vec<ObjectRef> = Vec::new();
    for spec in &a.objects {
        // A split file's path names the split of that id (its stem), as the server does.
        let spec = if objview_dataset::inputs::is_split_file(spec) {
            objview_server::pool::split_id(spec)?
        } else {
            spec.to_string_lossy().into_owned()
        };
        let (split, ids) = match spec.split_once(':') {
            Some((s, ids)) => (s, Some(ids)),
            None => (spec.as_str(), None),
        };
        let uids = client.split_objects(split).with_context(|| format!("--objects {spec}"))?;
        let chosen: Vec<String> = match ids {
            None => uids.clone(),
            Some(ids) => ids
                .split(',')
                .filter(|x| !x.is_empty())
                .map(|id| match id.parse::<usize>() {
                    Ok(i) if !uids.contains(&id.to_string()) => uids.get(i).cloned().with_context(|| {
                        format!("--objects {spec}: split {split} has {} objects, no index {i}", uids.len())
                    }),
                    _ => uids
                        .contains(&id.to_string())
                        .then(|| id.to_string())
                        .with_context(|| format!("--objects {spec}: split {split} has no object {id:?}")),
                })
                .collect::<Result<_>>()?,
        };
        for uid in chosen {
            anyhow::ensure!(!objects.iter().any(|o| o.uid == uid), "--objects: object {uid} is named twice");
            objects.push(ObjectRef { uid, mesh: PathBuf::from(split), gt_cloud: None, annotation: None });
        }
    }
    let candidates = Arc::new(
        client
            .candidate_set(&a.candidates)
            .with_context(|| format!("--candidates {} on the server", a.candidates))?,
    );
    // What this side knows of the settings record (the server writes the full one).
    let record = crate::provenance::settings(
        "run",
        json!({
            "planner": a.planner,
            "planner_params": probe.params(),
            "view_space": a.space,
            "budget": budget.label(),
            "seed": a.seed,
            "candidates": a.candidates,
            "server": url,
        }),
    );
    check_same_run(&a.out, &record)?;
    let work = |obj: &ObjectRef| -> Result<String> {
        let mut planner =
            objview_planners::registry::with_params(&a.planner, params).map_err(anyhow::Error::msg)?;
        let ep = objview_server::client::RemoteEpisode {
            split: obj.mesh.to_string_lossy().into_owned(),
            object: obj.uid.clone(),
            view_space: a.space.clone(),
            budget,
            candidate_set: a.candidates.clone(),
            seed: a.seed,
            record_timings: !a.no_timings,
        };
        Ok(objview_server::client::run_remote(&client, planner.as_mut(), &ep, candidates.clone())?)
    };
    let failure = |obj: &ObjectRef, e: &anyhow::Error| {
        to_line(&json!({
            "uid": obj.uid,
            "split": obj.mesh.display().to_string(),
            "error": crate::one_line(e),
            "settings": record,
        }))
    };
    batch(a, &objects, &a.space, budget, t, work, failure)
}

/// Runs `work` over `objects` into `a.out` (resumable, input order, `--threads` workers) with
/// progress lines; `failure` makes the line of an object whose episode failed.
fn batch(
    a: &Args,
    objects: &[ObjectRef],
    space_name: &str,
    budget: Budget,
    t: Instant,
    work: impl Fn(&ObjectRef) -> Result<String> + Sync,
    failure: impl Fn(&ObjectRef, &anyhow::Error) -> String + Sync,
) -> Result<RunSummary> {
    let (out, existing) = ResumableJsonl::open(&a.out, "uid", a.retry_failed)?;
    if existing.torn {
        eprintln!(
            "{}: cut off a torn last line (an interrupted write); that object is redone",
            a.out.display()
        );
    }
    let todo = objects.iter().filter(|o| !existing.done.contains(&o.uid)).count();
    if !a.quiet {
        eprintln!(
            "run {} / {} / budget {}: {} objects, {} already in {}, {todo} to do",
            a.planner,
            space_name,
            budget.label(),
            objects.len(),
            objects.len() - todo,
            a.out.display()
        );
    }
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    anyhow::ensure!(threads >= 1, "--threads must be at least 1");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("thread pool")?;
    let bar = if a.quiet { indicatif::ProgressBar::hidden() } else { crate::common::progress(todo as u64) };
    let terminal = std::io::stderr().is_terminal();
    let done = AtomicUsize::new(0);
    let work = |obj: &ObjectRef| match work(obj) {
        Ok(line) => ItemOutcome { line, failed: false },
        Err(e) => ItemOutcome { line: failure(obj, &e), failed: true },
    };
    let progress = |obj: &ObjectRef, outcome: &ItemOutcome| {
        let i = done.fetch_add(1, Ordering::Relaxed) + 1;
        bar.inc(1);
        if a.quiet {
            return;
        }
        let v: serde_json::Value = serde_json::from_str(&outcome.line).unwrap_or_default();
        let msg = if outcome.failed {
            format!("[{i}/{todo}] {}: FAILED: {}", obj.uid, v["error"].as_str().unwrap_or("?"))
        } else {
            let t = &v["checkpoints"]["terminal"];
            format!(
                "[{i}/{todo}] {}: {} views, NSC@0.02 {:.3}, SC@0.02 {:.3}, path {:.2}, {} ({})",
                obj.uid,
                t["views"],
                t["nsc"]["0.02"].as_f64().unwrap_or(f64::NAN),
                t["sc"]["0.02"].as_f64().unwrap_or(f64::NAN),
                t["path_cost"].as_f64().unwrap_or(f64::NAN),
                v["terminal_reason"].as_str().unwrap_or("?"),
                v["terminal_source"].as_str().unwrap_or("?"),
            )
        };
        if terminal {
            bar.println(msg);
        } else {
            eprintln!("{msg}");
        }
    };
    let summary = pool.install(|| run_batch(objects, out, &existing, work, progress))?;
    bar.finish_and_clear();
    Ok(RunSummary {
        done: summary.processed - summary.failed,
        failed: summary.failed,
        skipped: summary.skipped,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// `NAME=VALUE` pairs; VALUE is parsed as JSON, else taken as a string.
fn parse_params(raw: &[String]) -> Result<Vec<(String, serde_json::Value)>> {
    raw.iter()
        .map(|p| {
            let (k, v) = p.split_once('=').with_context(|| format!("--param {p:?}: expected NAME=VALUE"))?;
            let value = serde_json::from_str(v).unwrap_or_else(|_| serde_json::Value::String(v.to_string()));
            Ok((k.trim().to_string(), value))
        })
        .collect()
}

/// Refuses to resume a results file written by a different run (planner, space, budget, seed,
/// candidates or settings), which would otherwise silently skip its objects.
fn check_same_run(out: &Path, record: &serde_json::Value) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(out) else { return Ok(()) };
    for (i, line) in text.lines().enumerate() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else { continue };
        let old = &v["settings"];
        for key in [
            "planner",
            "planner_params",
            "view_space",
            "budget",
            "seed",
            "candidates",
            "start_pose",
            "episode",
        ] {
            let mut a = old[key].clone();
            let mut b = record[key].clone();
            if a.is_null() || b.is_null() {
                // A remote run's lines and failure lines know only part of the record.
                continue;
            }
            if key == "episode" {
                // Timings on/off do not change what an episode is.
                for x in [&mut a, &mut b] {
                    if let Some(m) = x.as_object_mut() {
                        m.remove("record_timings");
                    }
                }
            }
            if a != b {
                bail!(
                    "{}:{}: this results file holds another run ({key} = {} here, {} now); use another --out",
                    out.display(),
                    i + 1,
                    a,
                    b
                );
            }
        }
    }
    Ok(())
}
