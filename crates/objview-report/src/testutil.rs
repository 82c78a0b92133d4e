//! Synthetic episode results and annotations for the tests: an episode's per-step NSC@0.02 is
//! `base + slope·step` (SC = 0.8·NSC, path cost = `step_cost`·step, runtime = `step_time`·step),
//! so every checkpoint value can be worked out by hand.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use objview_episode::result::{Checkpoint, EpisodeResult, Metrics, ReferenceInfo, Step};
use objview_episode::{Budget, CheckpointKey, ExecutionMode, Family, TerminalSource};
use serde_json::{json, Value};

/// One synthetic episode.
#[derive(Clone, Debug)]
pub struct Spec {
    pub uid: &'static str,
    pub method: &'static str,
    pub family: &'static str,
    pub mode: &'static str,
    pub space: &'static str,
    pub budget: &'static str,
    pub seed: u64,
    /// NSC@0.02 at step 0, and its gain per step.
    pub base: f64,
    pub slope: f64,
    /// Last step index (views = last + 1).
    pub last: usize,
    pub step_cost: f64,
    pub step_time: f64,
    /// Step of the MS@0.02 checkpoint.
    pub ms: Option<usize>,
    pub reason: &'static str,
}

impl Spec {
    /// An iterative classical episode of `uid` in `whole`, 11 views, no MS.
    pub fn new(uid: &'static str, method: &'static str) -> Spec {
        Spec {
            uid,
            method,
            family: "classical",
            mode: "iterative",
            space: "whole",
            budget: "auto",
            seed: 0,
            base: 0.5,
            slope: 0.01,
            last: 10,
            step_cost: 1.0,
            step_time: 0.01,
            ms: None,
            reason: "enough_info",
        }
    }

    pub fn nsc(&self, step: usize) -> f64 {
        self.base + self.slope * step as f64
    }

    pub fn metrics(&self, step: usize) -> Metrics {
        let v = self.nsc(step);
        let per_tau = |x: f64| -> BTreeMap<String, f64> {
            [("0.01", x * 0.5), ("0.02", x), ("0.03", x)].iter().map(|(k, v)| (k.to_string(), *v)).collect()
        };
        Metrics {
            views: step + 1,
            sc: per_tau(0.8 * v),
            nsc: per_tau(v),
            cd: 1.0 - v,
            path_cost: self.step_cost * step as f64,
            runtime: self.step_time * step as f64,
        }
    }

    /// The episode result (family, mode and budget must be valid names).
    pub fn build(&self) -> EpisodeResult {
        let pose = [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let steps: Vec<Step> = (0..=self.last)
            .map(|s| Step {
                step: s,
                pose,
                metrics: self.metrics(s).without_cd(),
                fused_points: 100 * (s + 1),
                ms_voxels: BTreeMap::new(),
                planner_seconds: self.step_time,
                engine_seconds: 0.01,
                stage_seconds: [0.002, 0.002, 0.004, 0.002],
            })
            .collect();
        let cp = |s: usize| Checkpoint { step: s, metrics: self.metrics(s) };
        let mut checkpoints = BTreeMap::new();
        if self.mode == "iterative" {
            for k in [5, 10, 30, 50] {
                if k <= self.last {
                    checkpoints.insert(CheckpointKey::Budget(k), cp(k));
                }
            }
        }
        if let Some(m) = self.ms {
            checkpoints.insert(CheckpointKey::Stabilized(0.02), cp(m));
        }
        checkpoints.insert(CheckpointKey::Terminal, cp(self.last));
        EpisodeResult {
            settings: json!({"test": true}),
            uid: self.uid.into(),
            method: self.method.into(),
            family: self.family.parse().unwrap(),
            execution_mode: self.mode.parse().unwrap(),
            view_space: self.space.into(),
            budget: self.budget.parse().unwrap(),
            seed: self.seed,
            start_pose: pose,
            visited_poses: vec![pose; self.last + 1],
            terminal_source: source_of(self.reason),
            terminal_reason: self.reason.into(),
            terminal_detail: String::new(),
            steps,
            checkpoints,
            reference: ReferenceInfo {
                points: 1000,
                views: 360,
                view_set: "tammes-360".into(),
                observable_sc: BTreeMap::new(),
                key: "k".into(),
                cached: true,
            },
            gt_points: 20000,
            gt_source: "sampled".into(),
            wall_seconds: 1.0,
            planner_notes: None,
        }
    }

    /// The episode as one JSON line (no newline); family, mode and budget are written as given,
    /// valid or not.
    pub fn line(&self) -> String {
        // Stand-ins for invalid names, replaced by the given strings afterwards.
        let or = |s: &'static str, ok: bool, stand_in: &'static str| if ok { s } else { stand_in };
        let valid = Spec {
            family: or(self.family, self.family.parse::<Family>().is_ok(), "classical"),
            mode: or(self.mode, self.mode.parse::<ExecutionMode>().is_ok(), "iterative"),
            budget: or(self.budget, self.budget.parse::<Budget>().is_ok(), "auto"),
            ..self.clone()
        };
        let mut v = serde_json::to_value(valid.build()).unwrap();
        v["family"] = json!(self.family);
        v["execution_mode"] = json!(self.mode);
        v["budget"] = json!(self.budget);
        serde_json::to_string(&v).unwrap()
    }
}

/// The terminal source the engine and the server write with `reason` (listed here by hand).
fn source_of(reason: &str) -> TerminalSource {
    match reason {
        "planner_error" | "timeout" | "interrupted" | "aborted" => TerminalSource::Exception,
        "plan_end" | "candidate_exhausted" | "next_view_visited" | "next_view_infeasible" => {
            TerminalSource::AlgorithmStop
        }
        _ => TerminalSource::Benchmark,
    }
}

/// Writes `lines` (each followed by a newline) to `dir/name`.
pub fn write_lines(dir: &Path, name: &str, lines: &[String]) -> PathBuf {
    let path = dir.join(name);
    let mut text = String::new();
    for l in lines {
        text.push_str(l);
        text.push('\n');
    }
    std::fs::write(&path, text).unwrap();
    path
}

/// An `objview annotate` line for `uid`.
pub fn annotation(uid: &str, d_sat: usize, d_plan: Option<usize>, slow: bool) -> Value {
    json!({
        "uid": uid, "mesh": format!("{uid}.obj"), "gt_cloud": "sampled", "vertices": 8, "faces": 12,
        "gt_points": 20000, "surface_voxels": 1000, "curve": [[6, 500], [8, 600]], "mu": 3.0, "sigma": 1.0,
        "n_star": d_sat as f64, "d_sat": d_sat, "r_vis": 0.8, "grid_n": d_sat,
        "grid_r_vis": 0.8, "slow_saturation": slow, "degenerate_fit": false, "universe": 700,
        "d_plan": d_plan, "d_plan_status": if d_plan.is_some() { "optimal" } else { "time_limit" },
        "d_plan_bound": d_plan.unwrap_or(3), "lp_bound": 2.5, "greedy_cover": 9, "cover_views": [],
        "d_plan_proven_by": if d_plan.is_some() { "ilp" } else { "none" }, "search_nodes": 0,
        "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
            "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1,
            "reduced_views": 128, "reduced_elements": 10},
        "solver_seconds": 0.1, "seconds": 1.0,
        "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0, "cover": 0.0},
        "settings": {"resolution": 0.02},
        "version": "0.1.0"
    })
}

/// Asserts `a ≈ b` within 1e-9.
#[track_caller]
pub fn close(a: f64, b: f64) {
    assert!((a - b).abs() < 1e-9, "{a} != {b}");
}

/// The checked [`crate::load::Episode`] of a spec (line 1 of file 0).
pub fn episode(spec: &Spec) -> crate::load::Episode {
    crate::load::Episode { source: crate::load::Source { file: 0, line: 1 }, result: spec.build() }
}
