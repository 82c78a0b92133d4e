//! `objview learn experiment difficulty-aware`: the paper's difficulty-aware training experiment
//! (its fifth finding, Figure 4). Two MA-SCVP networks are trained with the same recipe and seed,
//! one on Main-Raw-Train (the pool's natural, long-tailed d_plan distribution) and one on
//! Main-Balanced-Train (the same size, an equal quota per d_plan bucket), and compared on a
//! held-out Main-Analysis-Test by the reference's offline metric.
//!
//! Stages, each resumable, all under the output folder `DIR`:
//! 1. `splits/`: `objview pool split` of the annotations with `train_size = size`
//!    ([`objview_pool::split::make_splits`]), plus `main_analysis_test.json`
//!    ([`objview_pool::split::analysis_test`]: `analysis` objects of Main-Train-Public in neither
//!    subset, by the Main-Hidden-Test two-stage bucket rule, ChaCha8 stream 3) and
//!    `experiment_train_objects.json` (raw ∪ balanced, each object once);
//! 2. `data/`: `objview learn dataset --method ma-scvp` of the training objects (one dataset;
//!    an object in both subsets is generated once);
//! 3. `models/raw.safetensors`, `models/balanced.safetensors` (+ sidecars and checkpoints):
//!    [`crate::mascvp_train::train_scvp_on_and_describe`] on each subset's cases;
//! 4. `vc.jsonl`: per analysis object, for **each of the 128 start views** s (reference: REF
//!    `A/eval_mascvp_object_worker.cpp`, learned-baselines.md §9): the input grid of the start
//!    view alone (its rendered depth frame, built as the dataset builds case grids) and the view
//!    state {s}; each network's logits; the decoded set {v : sigmoid ≥ γ} (γ = 0.5) minus s;
//!    **VC = |cov(s) ∪ ⋃ cov(v)| / |U_128|** with the r = 0.02 visible voxel sets of tammes-128;
//!    per object the mean and population std of VC over the 128 starts, the mean predicted total
//!    (1 + |decoded|) against the mean ground-truth total (1 + |exact residual set cover of {s}|),
//!    the size bias (their difference) and the VC gap (1 − mean VC), for raw and balanced;
//! 5. `summary.json`: the settings, subset sizes and bucket counts, VC per d_plan bucket (mean
//!    over objects of their mean VC, population std over those objects, object counts) for both
//!    models, the balanced − raw difference on medium/high buckets (d_plan ≥ 6), stage times and
//!    versions; the CLI draws Figure 4 from it (`objview_report::figure4`).
//!
//! Re-running with the same settings resumes (finished objects, epochs and analysis lines are
//! kept); other settings in the same folder are refused, naming the first difference.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use objview_dataset::{
    drive, resolve_inputs, to_line, Annotation, ItemOutcome, ObjectRef, Progress, ResumableJsonl, Shard,
};
use objview_difficulty::CoverStatus;
use objview_pool::split::{analysis_test, bucket_label, bucket_of, proven_d_plan, SplitSettings};
use objview_render::{render, Camera};
use objview_voxel::{bitset_count, union_into};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::dataset::{load_object, view_coverage, DatasetPlan, DatasetSettings, Method, VIEWS};
use crate::input_grid::{pool_grid, InputGrid};
use crate::mascvp::MascvpShape;
use crate::mascvp_train::{
    decode, load_scvp_weights_bytes, train_scvp_on_and_describe, ScvpProgress, ScvpTrainSettings,
};
use crate::rollout::Coverage;
use crate::LearnError;

/// The experiment's settings file in the output folder.
pub const SETTINGS_FILE: &str = "experiment.json";
/// The per-object results (JSON Lines).
pub const VC_FILE: &str = "vc.jsonl";
/// The summary.
pub const SUMMARY_FILE: &str = "summary.json";
/// The two models, in figure order.
pub const MODELS: [&str; 2] = ["raw", "balanced"];
/// Buckets from this index on are "medium/high" d_plan (d_plan ≥ 6).
pub const MEDIUM_FROM_BUCKET: usize = 1;

/// Every setting of the experiment.
#[derive(Debug, Clone)]
pub struct ExperimentSettings {
    /// Objects per training subset (Main-Raw-Train and Main-Balanced-Train).
    pub size: usize,
    /// Objects of Main-Analysis-Test.
    pub analysis: usize,
    /// The pool split's seed and hidden-test fraction (its `train_size` is `size`); the
    /// analysis draw uses the same seed.
    pub split: SplitSettings,
    /// The training data (method ma-scvp).
    pub dataset: DatasetSettings,
    /// The recipe of both networks.
    pub train: ScvpTrainSettings,
    /// Decoding threshold of the VC metric (the reference's 0.5).
    pub gamma: f64,
}

impl Default for ExperimentSettings {
    fn default() -> Self {
        ExperimentSettings {
            size: 16,
            analysis: 16,
            split: SplitSettings::default(),
            dataset: DatasetSettings { method: Method::MaScvp, ..DatasetSettings::default() },
            train: ScvpTrainSettings { epochs: 3, ..ScvpTrainSettings::default() },
            gamma: 0.5,
        }
    }
}

impl ExperimentSettings {
    /// Checks ranges (errors name the flag).
    pub fn validate(&self) -> Result<(), LearnError> {
        if self.size == 0 || self.analysis == 0 {
            return Err(LearnError::Invalid("--size and --analysis must be at least 1".into()));
        }
        if !(self.gamma > 0.0 && self.gamma < 1.0) {
            return Err(LearnError::Invalid(format!("--gamma must be in (0, 1), got {}", self.gamma)));
        }
        if self.dataset.method != Method::MaScvp {
            return Err(LearnError::Invalid("the experiment's data must be of method ma-scvp".into()));
        }
        if !self.dataset.grid.is_multiple_of(self.train.shape.grid) {
            return Err(LearnError::Invalid(format!(
                "--data-grid {} is not a multiple of the network grid {}",
                self.dataset.grid, self.train.shape.grid
            )));
        }
        self.split.validate().map_err(|e| LearnError::Invalid(e.to_string()))?;
        self.dataset.validate()?;
        self.train.validate()
    }

    /// The settings as recorded (and compared when resuming).
    pub fn to_json(&self) -> Value {
        json!({
            "experiment": "difficulty-aware",
            "size": self.size,
            "analysis": self.analysis,
            "split": self.split.to_json(),
            "analysis_rule": "Main-Train-Public objects in neither training subset; the Main-Hidden-Test two-stage bucket rule with quota = analysis (one per non-empty d_plan bucket first, rarest first; then proportional by largest remainders); ChaCha8 seed_from_u64(split seed) stream 3",
            "dataset": self.dataset.to_json(),
            "train": serde_json::to_value(&self.train).expect("settings serialize"),
            "deviation": self.train.shape.deviation(),
            "metric": {
                "name": "VC",
                "gamma": self.gamma,
                "starts": "each of the 128 tammes-128 views, step 0 (visited = {start})",
                "input": "the start view's rendered depth frame in a fresh input grid (as the dataset builds case grids), pooled to the network grid; view state = {start}",
                "rule": "decoded = {v : sigmoid(logit_v) >= gamma} minus the start; VC = |cov(start) ∪ ⋃ cov(decoded)| / |U_128|, cov = the r = 0.02 visible voxel sets of tammes-128",
                "gt_total": "1 + |exact residual set cover of {start}| (the dataset's cover settings)",
                "size_bias": "mean predicted total - mean ground-truth total",
                "vc_gap": "1 - mean VC",
            },
        })
    }
}

/// One model's figures on one analysis object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelVc {
    /// Mean VC over the 128 starts.
    pub vc_mean: f64,
    /// Population std of VC over the starts.
    pub vc_std: f64,
    /// Mean predicted total (1 + |decoded|).
    pub pred_total_mean: f64,
    /// `pred_total_mean` − the object's `gt_total_mean`.
    pub size_bias: f64,
    /// 1 − `vc_mean`.
    pub vc_gap: f64,
    /// VC of every start view (index = start).
    pub vc: Vec<f64>,
}

/// One analysis object's line of `vc.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectVc {
    /// The object.
    pub uid: String,
    /// Its d_plan (from the annotations).
    pub d_plan: usize,
    /// Its d_plan bucket label (`1-5`, `6-10`, …).
    pub bucket: String,
    /// Its d_sat.
    pub d_sat: Option<u64>,
    /// Its r_vis.
    pub r_vis: Option<f64>,
    /// |U_128|.
    pub universe: usize,
    /// Mean ground-truth total (1 + |residual cover of {start}|).
    pub gt_total_mean: f64,
    /// Residual-cover statuses over the starts.
    pub cover_status: BTreeMap<String, usize>,
    /// Per model (`raw`, `balanced`).
    pub models: BTreeMap<String, ModelVc>,
    /// Seconds for this object.
    pub seconds: f64,
    /// The settings.
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// VC of `decoded` ∪ {start} over `coverage`'s universe.
pub fn voxel_coverage(coverage: &Coverage, start: usize, decoded: &[usize]) -> f64 {
    let u = coverage.universe_size();
    if u == 0 {
        return 0.0;
    }
    let mut covered = coverage.sets[start].clone();
    for &v in decoded {
        union_into(&mut covered, &coverage.sets[v]);
    }
    bitset_count(&covered) as f64 / u as f64
}

/// The decoded set of one start: {v : sigmoid(logit_v) ≥ γ} minus the start (ascending, each
/// id once).
pub fn decode_start(logits: &[f32], start: usize, gamma: f64) -> Vec<usize> {
    decode(logits, gamma).into_iter().filter(|&v| v != start).collect()
}

/// Mean and population standard deviation (0 and 0 for an empty slice).
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n;
    (m, var.sqrt())
}

/// A network ready for the analysis.
struct Net {
    net: crate::mascvp::MascvpNet,
    grid: usize,
}

fn load_net(path: &Path, device: &Device) -> Result<Net, LearnError> {
    let bytes = std::fs::read(path).map_err(|e| LearnError::io(path, e))?;
    let side = crate::train::sidecar_path(path);
    let text = std::fs::read_to_string(&side).map_err(|e| LearnError::io(&side, e))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| LearnError::io(&side, format!("not JSON: {e}")))?;
    let shape: MascvpShape = serde_json::from_value(v["settings"]["shape"].clone())
        .map_err(|e| LearnError::io(&side, format!("settings.shape: {e}")))?;
    let net = load_scvp_weights_bytes(&bytes, &shape, device).map_err(|e| LearnError::io(path, e))?;
    Ok(Net { net, grid: shape.grid })
}

/// Logits [starts × 128] of `net` for single-view cases: `grids` (one per start, network grid)
/// with view state {start}.
fn start_logits(net: &Net, grids: &[Vec<f32>], device: &Device) -> Vec<f32> {
    let g = net.grid;
    let mut out = Vec::with_capacity(grids.len() * VIEWS);
    let starts: Vec<usize> = (0..grids.len()).collect();
    for chunk in starts.chunks(16) {
        let mut x = Vec::with_capacity(chunk.len() * g * g * g);
        let mut vs = vec![0f32; chunk.len() * VIEWS];
        for (k, &s) in chunk.iter().enumerate() {
            x.extend_from_slice(&grids[s]);
            vs[k * VIEWS + s] = 1.0;
        }
        let n = chunk.len();
        let x = Tensor::<5>::from_data(TensorData::new(x, [n, 1, g, g, g]), device);
        let vs = Tensor::<2>::from_data(TensorData::new(vs, [n, VIEWS]), device);
        out.extend(net.net.forward(x, vs).into_data().try_to_vec::<f32>().expect("f32 logits"));
    }
    out
}

/// The analysis of one object (stage 4).
pub fn analyze_object(
    obj: &ObjectRef,
    settings: &ExperimentSettings,
    cameras: &[Camera],
    models: &[(String, PathBuf)],
    settings_json: &Value,
) -> Result<ObjectVc, LearnError> {
    let t = Instant::now();
    let ann = obj.annotation.clone().unwrap_or(Value::Null);
    let d_plan = ann["d_plan"]
        .as_u64()
        .ok_or_else(|| LearnError::Invalid(format!("{}: the analysis entry has no d_plan", obj.uid)))?
        as usize;
    let a = &settings.dataset.annotate;
    let (mesh, set) = load_object(obj, a)?;
    let coverage = view_coverage(&mesh, &set, a, cameras);
    let device = Device::flex();
    let nets: Vec<(String, Net)> = models
        .iter()
        .map(|(n, p)| Ok((n.clone(), load_net(p, &device)?)))
        .collect::<Result<_, LearnError>>()?;
    let net_grid = settings.train.shape.grid;
    let data_grid = settings.dataset.grid;
    let mut grid = InputGrid::new(data_grid);
    let mut buf = Vec::with_capacity(data_grid.pow(3));
    let mut grids = Vec::with_capacity(cameras.len());
    let mut gt_totals = Vec::with_capacity(cameras.len());
    let mut status: BTreeMap<String, usize> = BTreeMap::new();
    for (s, cam) in cameras.iter().enumerate() {
        grid.clear();
        grid.insert_depth(cam, &render(&mesh, cam).depth);
        buf.clear();
        grid.write_probabilities(&mut buf);
        grids.push(pool_grid(&buf, data_grid, data_grid / net_grid));
        let (cover, st) = coverage.residual_cover(&[s], &a.cover)?;
        let name = match st {
            CoverStatus::Optimal => "optimal",
            CoverStatus::TimeLimit => "time_limit",
            _ => "error",
        };
        *status.entry(name.to_string()).or_insert(0) += 1;
        gt_totals.push(1.0 + cover.len() as f64);
    }
    let gt_total_mean = mean_std(&gt_totals).0;
    let mut out = BTreeMap::new();
    for (name, net) in &nets {
        let logits = start_logits(net, &grids, &device);
        let (mut vc, mut totals) = (Vec::with_capacity(VIEWS), Vec::with_capacity(VIEWS));
        for (s, row) in logits.chunks(VIEWS).enumerate() {
            let d = decode_start(row, s, settings.gamma);
            vc.push(voxel_coverage(&coverage, s, &d));
            totals.push(1.0 + d.len() as f64);
        }
        let (vc_mean, vc_std) = mean_std(&vc);
        let pred_total_mean = mean_std(&totals).0;
        out.insert(
            name.clone(),
            ModelVc {
                vc_mean,
                vc_std,
                pred_total_mean,
                size_bias: pred_total_mean - gt_total_mean,
                vc_gap: 1.0 - vc_mean,
                vc,
            },
        );
    }
    Ok(ObjectVc {
        uid: obj.uid.clone(),
        d_plan,
        bucket: bucket_of(d_plan).map(bucket_label).unwrap_or_default(),
        d_sat: ann["d_sat"].as_u64(),
        r_vis: ann["r_vis"].as_f64(),
        universe: coverage.universe_size(),
        gt_total_mean,
        cover_status: status,
        models: out,
        seconds: t.elapsed().as_secs_f64(),
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    })
}

/// Per-bucket figures of one model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BucketVc {
    /// Bucket label.
    pub bucket: String,
    /// Analysis objects in it.
    pub objects: usize,
    /// Mean over its objects of their mean VC.
    pub vc_mean: f64,
    /// Population std over its objects of their mean VC (the error bar).
    pub vc_std: f64,
    /// Mean size bias over its objects.
    pub size_bias: f64,
}

/// Aggregates `vc.jsonl` lines into per-bucket figures per model (buckets ascending).
pub fn bucket_table(lines: &[ObjectVc]) -> BTreeMap<String, Vec<BucketVc>> {
    let mut by: BTreeMap<usize, Vec<&ObjectVc>> = BTreeMap::new();
    for l in lines {
        if let Some(b) = bucket_of(l.d_plan) {
            by.entry(b).or_default().push(l);
        }
    }
    let mut out = BTreeMap::new();
    for m in MODELS {
        let rows = by
            .iter()
            .map(|(&b, objs)| {
                let v: Vec<f64> = objs.iter().filter_map(|o| o.models.get(m).map(|x| x.vc_mean)).collect();
                let bias: Vec<f64> =
                    objs.iter().filter_map(|o| o.models.get(m).map(|x| x.size_bias)).collect();
                let (vc_mean, vc_std) = mean_std(&v);
                BucketVc {
                    bucket: bucket_label(b),
                    objects: v.len(),
                    vc_mean,
                    vc_std,
                    size_bias: mean_std(&bias).0,
                }
            })
            .collect();
        out.insert(m.to_string(), rows);
    }
    out
}

/// The comparison the paper's finding is about: on analysis objects with d_plan ≥ 6, the mean
/// of (balanced − raw) mean VC, how many objects balanced wins / loses / ties, and per model the
/// mean VC there and overall.
pub fn comparison(lines: &[ObjectVc]) -> Value {
    let part = |medium: bool| -> Vec<&ObjectVc> {
        lines
            .iter()
            .filter(|l| bucket_of(l.d_plan).is_some_and(|b| (b >= MEDIUM_FROM_BUCKET) == medium))
            .collect()
    };
    let stats = |objs: &[&ObjectVc]| {
        let get = |o: &ObjectVc, m: &str| o.models.get(m).map_or(f64::NAN, |x| x.vc_mean);
        let diffs: Vec<f64> = objs.iter().map(|o| get(o, "balanced") - get(o, "raw")).collect();
        let raw: Vec<f64> = objs.iter().map(|o| get(o, "raw")).collect();
        let bal: Vec<f64> = objs.iter().map(|o| get(o, "balanced")).collect();
        let size = |m: &str| -> Vec<f64> {
            objs.iter().map(|o| o.models.get(m).map_or(f64::NAN, |x| x.pred_total_mean)).collect()
        };
        let gt: Vec<f64> = objs.iter().map(|o| o.gt_total_mean).collect();
        json!({
            "objects": objs.len(),
            "raw_pred_total_mean": mean_std(&size("raw")).0,
            "balanced_pred_total_mean": mean_std(&size("balanced")).0,
            "gt_total_mean": mean_std(&gt).0,
            "raw_vc_mean": mean_std(&raw).0,
            "balanced_vc_mean": mean_std(&bal).0,
            "balanced_minus_raw": mean_std(&diffs).0,
            "balanced_wins": diffs.iter().filter(|&&d| d > 0.0).count(),
            "balanced_losses": diffs.iter().filter(|&&d| d < 0.0).count(),
            "ties": diffs.iter().filter(|&&d| d == 0.0).count(),
        })
    };
    let medium = part(true);
    let low = part(false);
    let all: Vec<&ObjectVc> = lines.iter().collect();
    let m = stats(&medium);
    let better =
        m["objects"].as_u64().unwrap_or(0) > 0 && m["balanced_minus_raw"].as_f64().unwrap_or(0.0) > 0.0;
    json!({
        "medium_high": m,
        "low": stats(&low),
        "all": stats(&all),
        "medium_high_rule": format!("d_plan >= {} (buckets from {})", MEDIUM_FROM_BUCKET * objview_pool::split::BUCKET_WIDTH + 1, bucket_label(MEDIUM_FROM_BUCKET)),
        "balanced_better_on_medium_high": better,
    })
}

/// What the experiment reports to its caller.
pub trait ExperimentLog: Sync {
    /// A stage starts or ends (one line).
    fn stage(&self, line: &str);
}

/// Prints nothing.
pub struct QuietLog;
impl ExperimentLog for QuietLog {
    fn stage(&self, _: &str) {}
}

/// Where the experiment reports progress: per-object batches (data, analysis), training
/// batches and epochs, stage lines.
pub struct Reporters<'a> {
    /// The data and analysis batches.
    pub batch: &'a dyn Progress,
    /// Training.
    pub train: &'a dyn ScvpProgress,
    /// Stage lines.
    pub log: &'a dyn ExperimentLog,
}

/// Reads `vc.jsonl` (failure lines skipped).
pub fn read_vc(path: &Path) -> Result<Vec<ObjectVc>, LearnError> {
    let text = std::fs::read_to_string(path).map_err(|e| LearnError::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let v: Value =
            serde_json::from_str(line).map_err(|e| LearnError::io(path, format!("line {}: {e}", i + 1)))?;
        if v.get("error").is_some() {
            continue;
        }
        out.push(
            serde_json::from_value(v).map_err(|e| LearnError::io(path, format!("line {}: {e}", i + 1)))?,
        );
    }
    Ok(out)
}

fn write_json(path: &Path, v: &Value) -> Result<(), LearnError> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(v).expect("json") + "\n")
        .map_err(|e| LearnError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| LearnError::io(path, e))
}

/// The first JSON path at which `a` and `b` differ (for the resume refusal).
fn first_difference(a: &Value, b: &Value, at: &str) -> Option<String> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let keys: BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            keys.into_iter().find_map(|k| {
                first_difference(
                    x.get(k).unwrap_or(&Value::Null),
                    y.get(k).unwrap_or(&Value::Null),
                    &format!("{at}.{k}"),
                )
            })
        }
        _ if a == b => None,
        _ => Some(format!("{at}: {a} here, {b} now")),
    }
}

fn subset_counts(objs: &[Annotation]) -> Value {
    let mut c: BTreeMap<usize, usize> = BTreeMap::new();
    let mut d = Vec::new();
    for a in objs {
        if let Ok(dp) = proven_d_plan(a) {
            *c.entry(bucket_of(dp).unwrap_or(0)).or_default() += 1;
            d.push(dp);
        }
    }
    json!({
        "objects": objs.len(),
        "buckets": c.iter().map(|(b, n)| (bucket_label(*b), json!(n))).collect::<serde_json::Map<_, _>>(),
        "d_plan": d,
        "uids": objs.iter().map(|a| a.uid.clone()).collect::<Vec<_>>(),
    })
}

/// Runs (or resumes) the whole experiment into `out`; returns the summary written to
/// `out/summary.json`. `threads`: workers of the data and analysis stages (training uses the
/// caller's rayon pool); `command`: the command line, recorded.
pub fn run_experiment(
    annotations: &[PathBuf],
    out: &Path,
    settings: &ExperimentSettings,
    threads: Option<usize>,
    command: &str,
    report: &Reporters<'_>,
) -> Result<Value, LearnError> {
    let (progress, train_progress, log) = (report.batch, report.train, report.log);
    settings.validate()?;
    let t_all = Instant::now();
    let mut timings: BTreeMap<String, f64> = BTreeMap::new();
    std::fs::create_dir_all(out).map_err(|e| LearnError::io(out, e))?;
    let settings_json = objview_runs::provenance::settings("learn experiment difficulty-aware", {
        let mut s = settings.to_json();
        s["annotations"] = json!(annotations.iter().map(|p| p.display().to_string()).collect::<Vec<_>>());
        s
    });
    let spath = out.join(SETTINGS_FILE);
    if spath.is_file() {
        let text = std::fs::read_to_string(&spath).map_err(|e| LearnError::io(&spath, e))?;
        let old: Value =
            serde_json::from_str(&text).map_err(|e| LearnError::io(&spath, format!("not JSON: {e}")))?;
        if let Some(d) = first_difference(&old["settings"], &settings_json, "settings") {
            return Err(LearnError::Invalid(format!(
                "{}: the folder holds an experiment with other settings ({d}); use another --out or the same settings",
                spath.display()
            )));
        }
    } else {
        write_json(&spath, &json!({"settings": settings_json, "command": command}))?;
    }

    // 1. Splits.
    let t = Instant::now();
    let split_dir = out.join("splits");
    let split_settings = SplitSettings { train_size: Some(settings.size), ..settings.split.clone() };
    let so = objview_runs::pool::split(annotations, &split_dir, &split_settings)
        .map_err(|e| LearnError::Invalid(objview_geom::error::one_line(&e.to_string()).into_owned()))?;
    let splits = so.splits;
    let analysis = analysis_test(&splits, settings.analysis, settings.split.seed)
        .map_err(|e| LearnError::Invalid(e.to_string()))?;
    let entries = |objs: &[Annotation]| {
        Value::Array(objs.iter().map(|a| objview_pool::split::split_entry(a, &split_dir)).collect())
    };
    let analysis_file = split_dir.join(objview_pool::split::ANALYSIS_TEST_FILE);
    write_json(&analysis_file, &entries(&analysis))?;
    let mut union: BTreeMap<String, Annotation> = BTreeMap::new();
    for a in splits.main_raw_train.iter().chain(&splits.main_balanced_train) {
        union.insert(a.uid.clone(), a.clone());
    }
    let union: Vec<Annotation> = union.into_values().collect();
    let train_file = split_dir.join("experiment_train_objects.json");
    write_json(&train_file, &entries(&union))?;
    timings.insert("splits".into(), t.elapsed().as_secs_f64());
    log.stage(&format!(
        "splits: {} raw + {} balanced training objects ({} distinct), {} analysis objects -> {}",
        splits.main_raw_train.len(),
        splits.main_balanced_train.len(),
        union.len(),
        analysis.len(),
        split_dir.display()
    ));

    // 2. Data.
    let t = Instant::now();
    let data_dir = out.join("data");
    let plan = DatasetPlan {
        inputs: vec![train_file.clone()],
        out: data_dir.clone(),
        settings: settings.dataset.clone(),
        threads,
        shard: Shard::ALL,
        retry_failed: true,
        command: format!("{command} (stage: learn dataset)"),
    };
    let (ds, _) = plan.run(progress)?;
    if ds.failed > 0 {
        return Err(LearnError::Invalid(format!(
            "{}: {} training objects failed (see their lines); fix or drop them and re-run",
            plan.objects_file().display(),
            ds.failed
        )));
    }
    timings.insert("data".into(), t.elapsed().as_secs_f64());
    log.stage(&format!(
        "data: {} objects generated now, {} kept from before -> {}",
        ds.processed,
        ds.skipped,
        data_dir.display()
    ));

    // 3. Training, same recipe and seed for both.
    let models_dir = out.join("models");
    std::fs::create_dir_all(&models_dir).map_err(|e| LearnError::io(&models_dir, e))?;
    let mut models = Vec::new();
    let mut sidecars = serde_json::Map::new();
    for (name, subset) in [("raw", &splits.main_raw_train), ("balanced", &splits.main_balanced_train)] {
        let t = Instant::now();
        let only: BTreeSet<String> = subset.iter().map(|a| a.uid.clone()).collect();
        let w = models_dir.join(format!("{name}.safetensors"));
        let side = train_scvp_on_and_describe(
            &data_dir,
            Some(&only),
            &w,
            &settings.train,
            true,
            &format!("{command} (stage: learn train ma-scvp, subset {name})"),
            train_progress,
        )?;
        timings.insert(format!("train_{name}"), t.elapsed().as_secs_f64());
        let val = if side["data"]["val_cases"].as_u64().unwrap_or(0) == 0 {
            "no validation objects: last epoch kept".to_string()
        } else {
            format!("val F1 {:.3}", side["final"]["val"]["f1"].as_f64().unwrap_or(f64::NAN))
        };
        log.stage(&format!(
            "train {name}: kept epoch {} of {} ({val}; {} training cases) -> {}",
            side["best_epoch"],
            settings.train.epochs,
            side["data"]["train_cases"],
            w.display()
        ));
        sidecars.insert(
            name.into(),
            json!({"weights": w.display().to_string(), "best_epoch": side["best_epoch"], "final": side["final"],
                   "train_cases": side["data"]["train_cases"], "val_cases": side["data"]["val_cases"],
                   "params": side["params"], "weights_fnv1a64": side["weights_fnv1a64"],
                   "baseline_val_f1": side["baseline"]["val"]["f1"],
                   "epochs": side["history"]}),
        );
        models.push((name.to_string(), w));
    }

    // 4. Analysis.
    let t = Instant::now();
    let views = objview_dataset::annotate::GridViews::new(settings.dataset.annotate.view_radius)?;
    let cameras = views.planning().to_vec();
    let objects = resolve_inputs(std::slice::from_ref(&analysis_file))?;
    let vc_path = out.join(VC_FILE);
    let (w, existing) = ResumableJsonl::open(&vc_path, "uid", true)?;
    let line_settings =
        json!({"experiment": "difficulty-aware", "gamma": settings.gamma, "version": crate::VERSION});
    let vs = drive(
        "learn experiment difficulty-aware: analysis",
        None,
        Some(format!("VC at gamma {} over 128 starts", settings.gamma)),
        &objects,
        w,
        &existing,
        threads,
        |obj| match analyze_object(obj, settings, &cameras, &models, &line_settings) {
            Ok(r) => ItemOutcome {
                note: format!(
                    "d_plan {}: VC raw {:.3} balanced {:.3}, {:.1} s",
                    r.d_plan,
                    r.models.get("raw").map_or(f64::NAN, |m| m.vc_mean),
                    r.models.get("balanced").map_or(f64::NAN, |m| m.vc_mean),
                    r.seconds
                ),
                line: to_line(&r),
                failed: false,
            },
            Err(e) => {
                let msg = objview_geom::error::one_line(&e.to_string()).into_owned();
                ItemOutcome {
                    line: to_line(
                        &json!({"uid": obj.uid, "mesh": obj.mesh.display().to_string(), "error": msg}),
                    ),
                    failed: true,
                    note: msg,
                }
            }
        },
        progress,
    )?;
    timings.insert("analysis".into(), t.elapsed().as_secs_f64());
    log.stage(&format!(
        "analysis: {} objects now, {} kept, {} failed -> {}",
        vs.processed,
        vs.skipped,
        vs.failed,
        vc_path.display()
    ));

    // 5. Summary.
    let lines = read_vc(&vc_path)?;
    let uids: BTreeSet<&str> = analysis.iter().map(|a| a.uid.as_str()).collect();
    let lines: Vec<ObjectVc> = lines.into_iter().filter(|l| uids.contains(l.uid.as_str())).collect();
    let failed_objects: Vec<String> = {
        let ok: BTreeSet<&str> = lines.iter().map(|l| l.uid.as_str()).collect();
        uids.iter().filter(|u| !ok.contains(**u)).map(|u| u.to_string()).collect()
    };
    timings.insert("total_this_run".into(), t_all.elapsed().as_secs_f64());
    let data_seconds: f64 = std::fs::read_to_string(plan.objects_file())
        .ok()
        .map(|t| {
            t.lines()
                .filter_map(|l| serde_json::from_str::<Value>(l).ok())
                .filter_map(|v| v["seconds"].as_f64())
                .sum()
        })
        .unwrap_or(0.0);
    let summary = json!({
        "experiment": "difficulty-aware",
        "command": command,
        "settings": settings_json,
        "subsets": {
            "raw": subset_counts(&splits.main_raw_train),
            "balanced": subset_counts(&splits.main_balanced_train),
            "analysis": subset_counts(&analysis),
        },
        "models": sidecars,
        "analysis_objects": lines.len(),
        "failed_analysis_objects": failed_objects,
        "buckets": bucket_table(&lines),
        "comparison": comparison(&lines),
        "timings": {
            "this_run": timings,
            "data_cpu_seconds": data_seconds,
            "analysis_cpu_seconds": lines.iter().map(|l| l.seconds).sum::<f64>(),
            "train_seconds": sidecars.iter().map(|(k, v)| {
                let epochs = v["epochs"].as_array().map_or(0.0, |h| h.iter().filter_map(|e| e["seconds"].as_f64()).sum::<f64>());
                (k.clone(), json!(epochs))
            }).collect::<serde_json::Map<_, _>>(),
            "note": "this_run: wall seconds of the last invocation (a resumed run skips finished work); data and analysis: summed per-object seconds; train: summed epoch seconds",
        },
        "files": {"splits": "splits/", "data": "data/", "models": "models/", "vc": VC_FILE},
        "version": crate::VERSION,
    });
    write_json(&out.join(SUMMARY_FILE), &summary)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    use objview_voxel::to_bitset as bits;

    /// VC on a hand-built coverage instance: 4 views over 10 voxels, U = {0..8} (voxel 9 seen
    /// by nobody). Start 0 = {0,1,2}; decoded {1} = {2,3} → {0,1,2,3} = 4/9; decoded {2, 3}
    /// = {4,5} ∪ {6,7,8,0} → 8/9 (voxel 3 missing); {1, 2, 3} → 9/9; a decoded set repeating
    /// the start counts nothing extra.
    #[test]
    fn vc_on_a_hand_built_instance() {
        let n = 10;
        let c = Coverage::new(vec![
            bits(&[0, 1, 2], n),
            bits(&[2, 3], n),
            bits(&[4, 5], n),
            bits(&[6, 7, 8, 0], n),
        ]);
        assert_eq!(c.universe_size(), 9);
        assert!((voxel_coverage(&c, 0, &[]) - 3.0 / 9.0).abs() < 1e-15);
        assert!((voxel_coverage(&c, 0, &[1]) - 4.0 / 9.0).abs() < 1e-15);
        assert!((voxel_coverage(&c, 0, &[2, 3]) - 8.0 / 9.0).abs() < 1e-15);
        assert!((voxel_coverage(&c, 0, &[1, 2, 3]) - 1.0).abs() < 1e-15);
        assert!((voxel_coverage(&c, 1, &[0, 1]) - 4.0 / 9.0).abs() < 1e-15);
    }

    /// Decoding at γ = 0.5 keeps logits ≥ 0 and drops the start.
    #[test]
    fn decode_start_thresholds_and_drops_the_start() {
        let mut l = vec![-1.0f32; 128];
        l[0] = 0.0;
        l[5] = 2.0;
        l[7] = -0.01;
        l[9] = 0.3;
        assert_eq!(decode_start(&l, 5, 0.5), vec![0, 9]);
        assert_eq!(decode_start(&l, 1, 0.5), vec![0, 5, 9]);
    }

    fn line(uid: &str, d_plan: usize, raw: f64, bal: f64) -> ObjectVc {
        let m = |v: f64| ModelVc {
            vc_mean: v,
            vc_std: 0.0,
            pred_total_mean: 3.0,
            size_bias: -1.0,
            vc_gap: 1.0 - v,
            vc: vec![],
        };
        ObjectVc {
            uid: uid.into(),
            d_plan,
            bucket: bucket_label(bucket_of(d_plan).unwrap()),
            d_sat: None,
            r_vis: None,
            universe: 10,
            gt_total_mean: 4.0,
            cover_status: BTreeMap::new(),
            models: BTreeMap::from([("raw".to_string(), m(raw)), ("balanced".to_string(), m(bal))]),
            seconds: 0.0,
            settings: Value::Null,
            version: String::new(),
        }
    }

    /// Buckets: mean and population std over objects; the comparison on d_plan ≥ 6 only.
    #[test]
    fn bucket_table_and_comparison_by_hand() {
        let lines = vec![
            line("a", 3, 0.9, 0.8),
            line("b", 5, 0.7, 0.8),
            line("c", 7, 0.5, 0.7),
            line("d", 12, 0.4, 0.3),
            line("e", 14, 0.6, 0.6),
        ];
        let t = bucket_table(&lines);
        let raw = &t["raw"];
        assert_eq!(raw.iter().map(|b| b.bucket.as_str()).collect::<Vec<_>>(), ["1-5", "6-10", "11-15"]);
        assert_eq!(raw.iter().map(|b| b.objects).collect::<Vec<_>>(), [2, 1, 2]);
        assert!((raw[0].vc_mean - 0.8).abs() < 1e-12 && (raw[0].vc_std - 0.1).abs() < 1e-12);
        assert!((raw[2].vc_mean - 0.5).abs() < 1e-12 && (raw[2].vc_std - 0.1).abs() < 1e-12);
        let c = comparison(&lines);
        let m = &c["medium_high"];
        assert_eq!(m["objects"], 3);
        // (0.2 − 0.1 + 0) / 3
        assert!((m["balanced_minus_raw"].as_f64().unwrap() - 0.1 / 3.0).abs() < 1e-12);
        assert_eq!(
            (m["balanced_wins"].as_u64(), m["balanced_losses"].as_u64(), m["ties"].as_u64()),
            (Some(1), Some(1), Some(1))
        );
        assert_eq!(c["balanced_better_on_medium_high"], true);
        assert_eq!(c["low"]["objects"], 2);
        assert_eq!(c["all"]["raw_pred_total_mean"], 3.0);
        assert_eq!(c["all"]["gt_total_mean"], 4.0);
        assert_eq!(mean_std(&[]), (0.0, 0.0));
    }

    #[test]
    fn first_difference_names_the_path() {
        let a = json!({"x": {"y": 1, "z": 2}});
        let b = json!({"x": {"y": 1, "z": 3}});
        assert_eq!(first_difference(&a, &b, "s").unwrap(), "s.x.z: 2 here, 3 now");
        assert!(first_difference(&a, &a, "s").is_none());
    }
}
