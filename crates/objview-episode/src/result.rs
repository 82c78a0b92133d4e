//! The result of one episode: one JSON line per episode (SPEC §5). Field names are a contract
//! shared with `objview report`, the server and the Python client.
//!
//! Per-τ maps are keyed by τ written as a string with two decimals (`"0.01"`, `"0.02"`,
//! `"0.03"`; [`tau_key`](crate::vocab::tau_key)) and checkpoints by their [`CheckpointKey`] (`K=5`, `MS@0.02`,
//! `terminal`), which orders as its string; `BTreeMap` keeps keys sorted so the same episode
//! always serializes to the same bytes. The family, execution mode, budget and terminal source
//! are the typed names of [`crate::vocab`], written as the same strings as ever. What each
//! metric is, and where it is computed, is tabled in [`crate::metrics`].

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::vocab::{Budget, CheckpointKey, ExecutionMode, Family, TerminalSource};

/// Metrics after one view, as every step records them: everything but CD, which is evaluated
/// only at checkpoints ([`Metrics`]), as the reference implementation's evaluator does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepMetrics {
    /// Views taken so far, start view included (#Views).
    pub views: usize,
    /// SC@τ: fraction of ground-truth points with a fused point closer than τ (d² < τ²) now,
    /// over the current fused cloud ([`crate::coverage`]).
    pub sc: BTreeMap<String, f64>,
    /// NSC@τ: the same fraction over the observable-reference points.
    pub nsc: BTreeMap<String, f64>,
    /// Shell path length from the start pose (normalized object units).
    pub path_cost: f64,
    /// Planning runtime so far (PR), seconds spent inside the planner.
    pub runtime: f64,
}

impl StepMetrics {
    /// The checkpoint metrics of this view, with its Chamfer distance.
    pub fn with_cd(&self, cd: f64) -> Metrics {
        Metrics {
            views: self.views,
            sc: self.sc.clone(),
            nsc: self.nsc.clone(),
            cd,
            path_cost: self.path_cost,
            runtime: self.runtime,
        }
    }
}

/// Metrics of a checkpoint: a step's [`StepMetrics`] plus CD.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Views taken so far, start view included (#Views).
    pub views: usize,
    /// SC@τ: fraction of ground-truth points with a fused point closer than τ (d² < τ²) now.
    pub sc: BTreeMap<String, f64>,
    /// NSC@τ: the same fraction over the observable-reference points.
    pub nsc: BTreeMap<String, f64>,
    /// Chamfer distance: mean squared NN distance GT→fused plus fused→GT over the fused cloud
    /// of the checkpoint's view (units²; [`crate::chamfer`]).
    pub cd: f64,
    /// Shell path length from the start pose (normalized object units).
    pub path_cost: f64,
    /// Planning runtime so far (PR), seconds spent inside the planner.
    pub runtime: f64,
}

impl Metrics {
    /// The same metrics without CD.
    pub fn without_cd(&self) -> StepMetrics {
        StepMetrics {
            views: self.views,
            sc: self.sc.clone(),
            nsc: self.nsc.clone(),
            path_cost: self.path_cost,
            runtime: self.runtime,
        }
    }
}

/// One executed view and its metrics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// 0 = start view.
    pub step: usize,
    /// The executed pose `[cx, cy, cz, lx, ly, lz, roll]`.
    pub pose: [f64; 7],
    /// The metrics after this view (flattened into the step's JSON object; no `cd`: CD is
    /// evaluated at checkpoints only).
    #[serde(flatten)]
    pub metrics: StepMetrics,
    /// Fused points (voxel 0.005 centroids).
    pub fused_points: usize,
    /// Voxel counts of the fused cloud at each MS resolution δ (keys as τ).
    pub ms_voxels: BTreeMap<String, usize>,
    /// Planner time for the action that led to this view (seconds; 0 for the start view).
    pub planner_seconds: f64,
    /// Environment time for this view: render + fusion + metrics (seconds).
    pub engine_seconds: f64,
    /// `engine_seconds` by stage: render, fusion, coverage of the ground truth (SC) and of the
    /// observable reference (NSC) — updated concurrently —, the rest (CD when a checkpoint is
    /// recorded at this view, MS, bookkeeping).
    pub stage_seconds: [f64; 4],
}

/// A named checkpoint (`K=5`, `MS@0.02`, `terminal`, …; its name is the key of
/// [`EpisodeResult::checkpoints`]): the metrics at the view where it was reached, and that
/// view's step index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The step index of the view (0 = start view).
    pub step: usize,
    /// The metrics after that view (flattened into the checkpoint's JSON object).
    #[serde(flatten)]
    pub metrics: Metrics,
}

/// The observable reference of (object, view space) used for NSC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInfo {
    /// Reference points (voxel 0.005 centroids of all feasible reference views).
    pub points: usize,
    /// Feasible reference views fused.
    pub views: usize,
    /// Reference view set (`tammes-360`).
    pub view_set: String,
    /// Observable surface ratio: SC@τ of the reference itself.
    pub observable_sc: BTreeMap<String, f64>,
    /// Cache key (hash of mesh, view space, settings and version).
    pub key: String,
    /// Whether it was read from the cache (not written to results: a cached and a fresh
    /// reference are identical, and so must the result lines be).
    #[serde(skip)]
    pub cached: bool,
}

/// One episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeResult {
    /// Every setting and version that produced this line.
    pub settings: serde_json::Value,
    /// The object's id.
    pub uid: String,
    /// Method name (`rse`, `random-tsp`, a remote planner's name).
    pub method: String,
    /// `classical`, `learned`, `hybrid`, `oracle`, `baseline`.
    pub family: Family,
    /// `iterative`, `budgeted_plan`, `set_cover_plan`.
    pub execution_mode: ExecutionMode,
    /// View-space name (`whole`, `quarter`, a rule file's stem).
    pub view_space: String,
    /// `"5"`, `"30"`, `"auto"`.
    pub budget: Budget,
    /// The user seed (the planner got [`crate::episode_seed`] of it).
    pub seed: u64,
    /// The start pose `[cx, cy, cz, lx, ly, lz, roll]`.
    pub start_pose: [f64; 7],
    /// Every executed pose, start included, in order.
    pub visited_poses: Vec<[f64; 7]>,
    /// `algorithm_stop`, `benchmark`, `exception`.
    pub terminal_source: TerminalSource,
    /// `plan_end`, `candidate_exhausted`, `next_view_visited`, `next_view_infeasible`,
    /// `invalid_action`, `max_cap_reached`, `enough_info`, `planner_error`, `timeout`.
    pub terminal_reason: String,
    /// Human-readable detail (why an action was invalid, the planner's error message).
    pub terminal_detail: String,
    /// One record per executed view, start view first.
    pub steps: Vec<Step>,
    /// Named checkpoints, as reached; always `terminal`.
    pub checkpoints: BTreeMap<CheckpointKey, Checkpoint>,
    /// The observable reference NSC was measured against.
    pub reference: ReferenceInfo,
    /// Ground-truth points (|GT|) and where they came from: `sampled(seed=…, count=…)` or
    /// `file:NAME` (the cloud file's name, never its path).
    pub gt_points: usize,
    /// See `gt_points`.
    pub gt_source: String,
    /// Wall time of the episode (seconds), set-up included.
    pub wall_seconds: f64,
    /// The planner's own record of its decisions ([`crate::Planner::notes`]: e.g. the hybrids'
    /// ILP status, bound and gap); absent for planners that keep none. Last in the line, so a
    /// remote run appends it to the server's line ([`EpisodeResult::append_planner_notes`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub planner_notes: Option<serde_json::Value>,
}

impl EpisodeResult {
    /// The path of the first number that is NaN or infinite (`checkpoints.terminal.cd`,
    /// `checkpoints.terminal.path_cost`, …), or `None` when every number is finite. JSON has no
    /// such numbers (they serialize as `null`), and a reader of results expects a number, so a
    /// result with one must take the error path instead of being written.
    pub fn non_finite(&self) -> Option<String> {
        fn all(prefix: &str, xs: &[f64]) -> Option<String> {
            xs.iter().position(|x| !x.is_finite()).map(|i| format!("{prefix}[{i}]"))
        }
        fn map(prefix: &str, m: &BTreeMap<String, f64>) -> Option<String> {
            m.iter().find(|(_, x)| !x.is_finite()).map(|(k, _)| format!("{prefix}.{k}"))
        }
        fn metrics(prefix: &str, m: &Metrics) -> Option<String> {
            step_metrics(prefix, &m.without_cd())
                .or_else(|| (!m.cd.is_finite()).then(|| format!("{prefix}.cd")))
        }
        fn step_metrics(prefix: &str, m: &StepMetrics) -> Option<String> {
            map(&format!("{prefix}.sc"), &m.sc).or_else(|| map(&format!("{prefix}.nsc"), &m.nsc)).or_else(
                || {
                    [("path_cost", m.path_cost), ("runtime", m.runtime)]
                        .into_iter()
                        .find(|(_, x)| !x.is_finite())
                        .map(|(k, _)| format!("{prefix}.{k}"))
                },
            )
        }
        if let Some(f) = all("start_pose", &self.start_pose) {
            return Some(f);
        }
        for (i, p) in self.visited_poses.iter().enumerate() {
            if let Some(f) = all(&format!("visited_poses[{i}]"), p) {
                return Some(f);
            }
        }
        for (i, s) in self.steps.iter().enumerate() {
            let at = format!("steps[{i}]");
            let found = all(&format!("{at}.pose"), &s.pose)
                .or_else(|| step_metrics(&at, &s.metrics))
                .or_else(|| all(&format!("{at}.stage_seconds"), &s.stage_seconds))
                .or_else(|| {
                    [("planner_seconds", s.planner_seconds), ("engine_seconds", s.engine_seconds)]
                        .into_iter()
                        .find(|(_, x)| !x.is_finite())
                        .map(|(k, _)| format!("{at}.{k}"))
                });
            if found.is_some() {
                return found;
            }
        }
        for (name, c) in &self.checkpoints {
            if let Some(f) = metrics(&format!("checkpoints.{name}"), &c.metrics) {
                return Some(f);
            }
        }
        if let Some(f) = map("reference.observable_sc", &self.reference.observable_sc) {
            return Some(f);
        }
        (!self.wall_seconds.is_finite()).then(|| "wall_seconds".to_string())
    }

    /// `line` (one serialized result without `planner_notes`, as a server writes it) with
    /// `notes` added exactly as [`EpisodeResult`] serializes them — the last field — so a
    /// remote run's line equals the local run's byte for byte. `None` leaves the line as it
    /// is. Errors: `line` is not a JSON object or already carries `planner_notes`.
    pub fn append_planner_notes(line: &str, notes: Option<&serde_json::Value>) -> Result<String, String> {
        let Some(notes) = notes else { return Ok(line.to_string()) };
        let trimmed = line.trim_end();
        let parsed: serde_json::Value =
            serde_json::from_str(trimmed).map_err(|e| format!("result line is not JSON: {e}"))?;
        let Some(fields) = parsed.as_object() else {
            return Err("result line is not a JSON object".into());
        };
        if fields.contains_key("planner_notes") {
            return Err("result line already has planner_notes".into());
        }
        let body = trimmed.strip_suffix('}').ok_or("result line does not end with `}`")?;
        let notes = serde_json::to_string(notes).map_err(|e| format!("planner_notes: {e}"))?;
        let sep = if fields.is_empty() { "" } else { "," };
        Ok(format!("{body}{sep}\"planner_notes\":{notes}}}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metrics(cd: f64) -> Metrics {
        let taus = BTreeMap::from([("0.02".to_string(), 0.5)]);
        Metrics { views: 1, sc: taus.clone(), nsc: taus, cd, path_cost: 0.0, runtime: 0.0 }
    }

    fn result(cd: f64) -> EpisodeResult {
        let step = Step {
            step: 0,
            pose: [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            metrics: metrics(cd).without_cd(),
            fused_points: 1,
            ms_voxels: BTreeMap::new(),
            planner_seconds: 0.0,
            engine_seconds: 0.0,
            stage_seconds: [0.0; 4],
        };
        EpisodeResult {
            settings: serde_json::json!({}),
            uid: "o".into(),
            method: "m".into(),
            family: Family::Classical,
            execution_mode: ExecutionMode::Iterative,
            view_space: "whole".into(),
            budget: Budget::Auto,
            seed: 0,
            start_pose: step.pose,
            visited_poses: vec![step.pose],
            terminal_source: TerminalSource::AlgorithmStop,
            terminal_reason: "plan_end".into(),
            terminal_detail: String::new(),
            checkpoints: BTreeMap::from([(
                CheckpointKey::Terminal,
                Checkpoint { step: 0, metrics: metrics(cd) },
            )]),
            steps: vec![step],
            reference: ReferenceInfo {
                points: 1,
                views: 1,
                view_set: "tammes-360".into(),
                observable_sc: BTreeMap::new(),
                key: String::new(),
                cached: false,
            },
            gt_points: 1,
            gt_source: "sampled".into(),
            wall_seconds: 0.0,
            planner_notes: None,
        }
    }

    #[test]
    fn planner_notes_are_absent_when_none_and_appended_as_the_local_line_writes_them() {
        let plain = result(0.1);
        let line = serde_json::to_string(&plain).unwrap();
        assert!(!line.contains("planner_notes"));
        let notes = serde_json::json!({"plan": {"status": "time_limit", "bound": 12.0, "gap": 2.0}});
        let mut noted = plain.clone();
        noted.planner_notes = Some(notes.clone());
        let local = serde_json::to_string(&noted).unwrap();
        assert_eq!(EpisodeResult::append_planner_notes(&line, Some(&notes)).unwrap(), local);
        assert_eq!(EpisodeResult::append_planner_notes(&line, None).unwrap(), line);
        let back: EpisodeResult = serde_json::from_str(&local).unwrap();
        assert_eq!(back, noted);
        // Older lines (no field) still read.
        assert_eq!(serde_json::from_str::<EpisodeResult>(&line).unwrap().planner_notes, None);
        let err = EpisodeResult::append_planner_notes(&local, Some(&notes)).unwrap_err();
        assert!(err.contains("already"), "{err}");
        assert!(EpisodeResult::append_planner_notes("[1]", Some(&notes)).is_err());
    }

    #[test]
    fn a_finite_result_has_no_non_finite_field() {
        assert_eq!(result(0.1).non_finite(), None);
    }

    #[test]
    fn the_first_non_finite_number_is_named_by_its_path() {
        assert_eq!(result(f64::INFINITY).non_finite().as_deref(), Some("checkpoints.terminal.cd"));
        let mut r = result(0.1);
        r.checkpoints.get_mut(&CheckpointKey::Terminal).unwrap().metrics.path_cost = f64::NAN;
        assert_eq!(r.non_finite().as_deref(), Some("checkpoints.terminal.path_cost"));
        r.visited_poses[0][6] = f64::NEG_INFINITY;
        assert_eq!(r.non_finite().as_deref(), Some("visited_poses[0][6]"));
        let mut r = result(0.1);
        r.steps[0].metrics.nsc.insert("0.01".into(), f64::NAN);
        assert_eq!(r.non_finite().as_deref(), Some("steps[0].nsc.0.01"));
        // Written as JSON, such a number would be a null.
        let line = serde_json::to_string(&result(f64::INFINITY)).unwrap();
        assert!(line.contains("\"cd\":null"), "{line}");
    }

    #[test]
    fn steps_carry_no_cd_and_checkpoints_do() {
        let v = serde_json::to_value(result(0.25)).unwrap();
        assert!(v["steps"][0].get("cd").is_none(), "{}", v["steps"][0]);
        assert_eq!(v["steps"][0]["sc"]["0.02"], 0.5);
        assert_eq!(v["checkpoints"]["terminal"]["cd"], 0.25);
    }
}
