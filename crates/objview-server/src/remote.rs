//! `objview run --server`: a batch of episodes of a local planner against an evaluation server.
//! The planner runs here and sees only what the API gives it ([`crate::client::run_remote`]);
//! the objects are a server's split objects (`SPLIT` or `SPLIT:ID,ID,…`, uids or indices); the
//! result lines are the server's, written through the same resumable batch driver as local runs
//! (`objview_dataset::drive`), so a file of a remote run reads like a local one.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use objview_dataset::{drive, ItemOutcome, ObjectRef, Progress, ResumableJsonl};
use objview_episode::{Budget, EpisodeResult};
use objview_planners::registry::Registry;
use objview_runs::episodes::{check_budget, check_same_run, episode_note, failure_item};
use objview_runs::{Params, RunError, RunSummary};
use serde_json::json;

use crate::client::{run_remote, Client, RemoteEpisode};

/// One remote run, fully resolved.
#[derive(Debug, Clone)]
pub struct RemotePlan {
    /// The server's base URL.
    pub url: String,
    /// Bearer token, if the server asks for one.
    pub token: Option<String>,
    /// The planner's name in the registry.
    pub planner: String,
    /// Its parameters.
    pub params: Params,
    /// A built-in view space of the server (`whole`, `hemi`, `quarter`, `eighth`).
    pub space: String,
    /// The budget protocol.
    pub budget: Budget,
    /// The server's candidate set (`tammes-360`, …).
    pub candidates: String,
    /// The user seed.
    pub seed: u64,
    /// Whether results record wall-clock times.
    pub record_timings: bool,
    /// Objects: `SPLIT` (all its objects, in order) or `SPLIT:ID,ID,…`; a split file's path
    /// stands for its stem.
    pub objects: Vec<PathBuf>,
    /// The results file (JSON Lines).
    pub out: PathBuf,
    /// Parallel episodes (`None`: every core).
    pub threads: Option<usize>,
    /// Redo objects whose earlier line is a failure.
    pub retry_failed: bool,
}

fn invalid(msg: impl Into<String>) -> RunError {
    RunError::Invalid(msg.into())
}

impl RemotePlan {
    /// The server's objects named by [`RemotePlan::objects`], each with its split id as `mesh`.
    pub fn resolve_objects(&self, client: &Client) -> Result<Vec<ObjectRef>, RunError> {
        let mut objects: Vec<ObjectRef> = Vec::new();
        for spec in &self.objects {
            // A split file's path names the split of that id (its stem), as the server does.
            let spec = if objview_dataset::inputs::is_split_file(spec) {
                crate::pool::split_id(spec).map_err(|e| invalid(e.to_string()))?
            } else {
                spec.to_string_lossy().into_owned()
            };
            let (split, ids) = match spec.split_once(':') {
                Some((s, ids)) => (s, Some(ids)),
                None => (spec.as_str(), None),
            };
            let uids = client.split_objects(split).map_err(|e| invalid(format!("--objects {spec}: {e}")))?;
            let chosen: Vec<String> = match ids {
                None => uids.clone(),
                Some(ids) => ids
                    .split(',')
                    .filter(|x| !x.is_empty())
                    .map(|id| match id.parse::<usize>() {
                        Ok(i) if !uids.contains(&id.to_string()) => uids.get(i).cloned().ok_or_else(|| {
                            invalid(format!(
                                "--objects {spec}: split {split} has {} objects, no index {i}",
                                uids.len()
                            ))
                        }),
                        _ => uids.contains(&id.to_string()).then(|| id.to_string()).ok_or_else(|| {
                            invalid(format!("--objects {spec}: split {split} has no object {id:?}"))
                        }),
                    })
                    .collect::<Result<_, _>>()?,
            };
            for uid in chosen {
                if objects.iter().any(|o| o.uid == uid) {
                    return Err(invalid(format!("--objects: object {uid} is named twice")));
                }
                objects.push(ObjectRef { uid, mesh: PathBuf::from(split), gt_cloud: None, annotation: None });
            }
        }
        Ok(objects)
    }

    /// Runs the plan's episodes on the server into its results file.
    pub fn run(&self, planners: &Registry, progress: &dyn Progress) -> Result<RunSummary, RunError> {
        let t = Instant::now();
        let probe = planners.with_params(&self.planner, &self.params).map_err(RunError::Invalid)?;
        check_budget(&self.planner, probe.as_ref(), self.budget)?;
        if probe.needs_ground_truth() {
            return Err(invalid(format!(
                "--planner {} reads the ground truth: it cannot run against a server (run it locally)",
                self.planner
            )));
        }
        if objview_views::ViewSpace::builtin(&self.space).is_none() {
            return Err(invalid(format!(
                "--space {}: a server offers the built-in view spaces only (whole, hemi, quarter, eighth)",
                self.space
            )));
        }
        let client = Client::new(&self.url, self.token.as_deref());
        client.health().map_err(|e| invalid(format!("--server {}: {e}", self.url)))?;
        let objects = self.resolve_objects(&client)?;
        let candidates = Arc::new(
            client
                .candidate_set(&self.candidates)
                .map_err(|e| invalid(format!("--candidates {} on the server: {e}", self.candidates)))?,
        );
        // What this side knows of the settings record (the server writes the full one).
        let record = objview_runs::provenance::settings(
            "run",
            json!({
                "planner": self.planner,
                "planner_params": probe.params(),
                "view_space": self.space,
                "budget": self.budget.label(),
                "seed": self.seed,
                "candidates": self.candidates,
                "server": self.url,
            }),
        );
        check_same_run(&self.out, &record)?;
        let work = |obj: &ObjectRef| -> Result<String, String> {
            let mut planner = planners.with_params(&self.planner, &self.params)?;
            let ep = RemoteEpisode {
                split: obj.mesh.to_string_lossy().into_owned(),
                object: obj.uid.clone(),
                view_space: self.space.clone(),
                budget: self.budget,
                candidate_set: self.candidates.clone(),
                seed: self.seed,
                record_timings: self.record_timings,
            };
            run_remote(&client, planner.as_mut(), &ep, candidates.clone()).map_err(|e| e.to_string())
        };
        let item = |obj: &ObjectRef| match work(obj) {
            Ok(line) => {
                // The server's line, read once for the progress note (it is not re-serialized).
                let note = serde_json::from_str::<EpisodeResult>(&line)
                    .map(|r| episode_note(&r))
                    .unwrap_or_default();
                ItemOutcome { line, failed: false, note }
            }
            Err(e) => failure_item(obj, "split", &obj.mesh.display().to_string(), &e, &record),
        };
        let (out, existing) = ResumableJsonl::open(&self.out, "uid", self.retry_failed)?;
        let what = format!("run {} / {} / budget {}", self.planner, self.space, self.budget.label());
        let s = drive(&what, None, None, &objects, out, &existing, self.threads, item, progress)?;
        Ok(RunSummary::from_batch(&s, t))
    }
}
