//! `objview learn train completion`: the training loop and evaluation of the completion network
//! ([`crate::completion_net`]) on a `completion` dataset ([`crate::completion_data`]).
//!
//! Recipe (PCN / PoinTr's loss, our schedule): loss = `coarse_weight` · CD-L1(coarse, truth) +
//! `fine_weight` · CD-L1(fine, truth) ([`chamfer_loss`], PoinTr's `ChamferDistanceL1`), Adam
//! (lr 1e-3 by default, β = (0.9, 0.999), ε = 1e-8, no weight decay), batch 8, StepLR per epoch
//! (`lr_step` 20 and `lr_factor` 0.5 by default; the shipped run steps every 5 epochs). The
//! loss uses `loss_gt_points` (2048) of each
//! case's ground-truth points, a fresh seeded subset every epoch (the contract's resampling
//! rule; ChaCha8 of (seed, epoch, case)), to keep the loss cheap (training against the whole
//! truth was not compared).
//!
//! Evaluation ([`evaluate_completion`]): per case, the exact Chamfer-L1 ([`chamfer_l1`], f64,
//! both halves kept) against the **whole** stored ground truth, in the object's frame (the
//! normalized figure times the case's scale; the planners work in that frame, [−1, 1]³), of
//! - `net`: the contract's output, the 6144 predicted points followed by the 2048 input points
//!   (what the hybrid planners get);
//! - `net_fine`: the 6144 predicted points alone;
//! - `identity`: the 2048 input points alone (the `identity` backend's output).
//!
//! Means are over cases; per d_plan bucket when the data knows the objects' d_plan (split
//! entries with annotations). The kept epoch has the lowest validation `net` Chamfer-L1 (ties:
//! the earlier); the last epoch without validation objects. Objects go to validation by a hash
//! of their uid ([`is_validation`]); `--heldout` evaluates the kept weights on a second dataset.
//!
//! Determinism and resume are those of [`crate::train`]: the device RNG is seeded with `seed`
//! before the model is built and with `(seed, epoch)` at every epoch start, the case order is a
//! ChaCha8 shuffle seeded with `(seed, epoch)`, and per-epoch checkpoints (weights, optimizer)
//! let `--resume` continue exactly.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use objview_geom::hash::fnv1a64;
use objview_planners::hybrid::completion::{resample, INPUT_POINTS};
use objview_pool::split::{bucket_label, bucket_of};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::checkpoint::{load_safetensors, save_safetensors, trajectory_settings, Checkpoints};
use crate::completion_net::{chamfer_l1, chamfer_loss, to_f64, Chamfer, CompletionNet, CompletionShape};
use crate::npz::{Dtype, NpzReader};
use crate::train::{is_validation, mix, read_manifest, sidecar_path};
use crate::LearnError;

/// Every training setting of the completion network (recorded in the sidecar).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompletionTrainSettings {
    /// The network's shape.
    pub shape: CompletionShape,
    /// Epochs.
    pub epochs: usize,
    /// Batch size.
    pub batch: usize,
    /// Adam's initial learning rate.
    pub lr: f64,
    /// StepLR: the learning rate is multiplied by `lr_factor` every `lr_step` epochs.
    pub lr_step: usize,
    /// StepLR factor (1: constant).
    pub lr_factor: f64,
    /// Ground-truth points per case in the loss (a fresh seeded subset every epoch).
    pub loss_gt_points: usize,
    /// Weight of the coarse output's Chamfer-L1 in the loss.
    pub coarse_weight: f64,
    /// Weight of the fine output's Chamfer-L1 in the loss.
    pub fine_weight: f64,
    /// Seed of initialization, case order and ground-truth subsets.
    pub seed: u64,
    /// Fraction of objects held out for validation.
    pub val_fraction: f64,
    /// Use at most this many training cases per epoch (the first after the epoch's shuffle).
    pub max_cases: Option<usize>,
}

impl Default for CompletionTrainSettings {
    fn default() -> Self {
        CompletionTrainSettings {
            shape: CompletionShape::small(),
            epochs: 10,
            batch: 8,
            lr: 1e-3,
            lr_step: 20,
            lr_factor: 0.5,
            loss_gt_points: 2048,
            coarse_weight: 1.0,
            fine_weight: 1.0,
            seed: 42,
            val_fraction: 0.1,
            max_cases: None,
        }
    }
}

impl CompletionTrainSettings {
    /// Checks ranges (an error names the flag).
    pub fn validate(&self) -> Result<(), LearnError> {
        self.shape.validate()?;
        let bad = |m: String| Err(LearnError::Invalid(m));
        if self.epochs == 0 || self.batch == 0 || self.lr_step == 0 || self.loss_gt_points == 0 {
            return bad("--epochs, --batch, --lr-step and --loss-gt-points must be at least 1".into());
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(format!("--lr must be a positive number, got {}", self.lr));
        }
        if !(self.lr_factor.is_finite() && self.lr_factor > 0.0 && self.lr_factor <= 1.0) {
            return bad(format!("--lr-factor must be in (0, 1], got {}", self.lr_factor));
        }
        for (name, w) in [("--coarse-weight", self.coarse_weight), ("--fine-weight", self.fine_weight)] {
            if !(w.is_finite() && w >= 0.0) {
                return bad(format!("{name} must be a number >= 0, got {w}"));
            }
        }
        if !(0.0..1.0).contains(&self.val_fraction) {
            return bad(format!("--val-fraction must be in [0, 1), got {}", self.val_fraction));
        }
        Ok(())
    }

    /// The learning rate of (1-based) `epoch` under StepLR.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        self.lr * self.lr_factor.powi(((epoch - 1) / self.lr_step) as i32)
    }
}

/// Completion cases in memory.
#[derive(Debug, Clone, Default)]
pub struct CompletionCases {
    /// Ground-truth points per case.
    pub gt_points: usize,
    /// `len · 2048 · 3` normalized input coordinates.
    pub partial: Vec<f32>,
    /// `len · gt_points · 3` normalized ground-truth coordinates.
    pub gt: Vec<f32>,
    /// Each case's normalization scale (object frame = normalized · scale + centroid).
    pub scale: Vec<f32>,
    /// Object uid of each case.
    pub objects: Vec<String>,
    /// The object's proven d_plan, when the data knows it.
    pub d_plan: Vec<Option<usize>>,
}

impl CompletionCases {
    /// Number of cases.
    pub fn len(&self) -> usize {
        self.objects.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }
    /// The normalized input of case `i` (flat x, y, z).
    pub fn input(&self, i: usize) -> &[f32] {
        let k = INPUT_POINTS * 3;
        &self.partial[i * k..(i + 1) * k]
    }
    /// The normalized ground truth of case `i` (flat x, y, z).
    pub fn truth(&self, i: usize) -> &[f32] {
        let k = self.gt_points * 3;
        &self.gt[i * k..(i + 1) * k]
    }
    fn push_from(&mut self, o: &CompletionCases, i: usize) {
        self.gt_points = o.gt_points;
        self.partial.extend_from_slice(o.input(i));
        self.gt.extend_from_slice(o.truth(i));
        self.scale.push(o.scale[i]);
        self.objects.push(o.objects[i].clone());
        self.d_plan.push(o.d_plan[i]);
    }
    fn extend(&mut self, o: CompletionCases) {
        self.partial.extend(o.partial);
        self.gt.extend(o.gt);
        self.scale.extend(o.scale);
        self.objects.extend(o.objects);
        self.d_plan.extend(o.d_plan);
    }
    /// Distinct objects, in case order.
    pub fn object_list(&self) -> Vec<String> {
        let mut v = self.objects.clone();
        v.dedup();
        v
    }
}

/// Reads every case of the `completion` dataset in `dir` (`only`: just these objects; one the
/// dataset does not hold is an error naming it).
pub fn load_completion_cases(
    dir: &Path,
    only: Option<&BTreeSet<String>>,
) -> Result<CompletionCases, LearnError> {
    let m = read_manifest(dir)?;
    let mpath = dir.join("manifest.json");
    if m["method"] != "completion" {
        return Err(LearnError::Invalid(format!(
            "{}: a dataset of method {} (the completion network needs `learn dataset --method completion`)",
            mpath.display(),
            m["method"]
        )));
    }
    let gt_points = m["settings"]["gt_points"].as_u64().unwrap_or(0) as usize;
    if gt_points == 0 {
        return Err(LearnError::Invalid(format!("{}: settings.gt_points is missing", mpath.display())));
    }
    let uid_of =
        |f: &str| Path::new(f).file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    let mut files: Vec<String> = m["files"]
        .as_array()
        .map(|a| a.iter().filter_map(|f| f.as_str().map(String::from)).collect())
        .unwrap_or_default();
    if let Some(only) = only {
        files.retain(|f| only.contains(&uid_of(f)));
        let held: BTreeSet<String> = files.iter().map(|f| uid_of(f)).collect();
        if let Some(missing) = only.iter().find(|u| !held.contains(*u)) {
            return Err(LearnError::Invalid(format!(
                "{}: object '{missing}' has no cases in this dataset",
                mpath.display()
            )));
        }
    }
    let parts: Vec<Result<CompletionCases, LearnError>> = files
        .par_iter()
        .map(|f| {
            let path = crate::dataset::resolve_data_file(dir, f)?;
            let mut r = NpzReader::open(&path)?;
            let partial = r.array("partial", Some(Dtype::F32))?;
            let gt = r.array("gt", Some(Dtype::F32))?;
            let scale = r.array("scale", Some(Dtype::F32))?;
            let d_plan = r.array("d_plan", Some(Dtype::I32))?.ints();
            let n = scale.shape.first().copied().unwrap_or(0);
            let shape_err = |name: &str, shape: &[usize]| {
                LearnError::Invalid(format!(
                    "{}: array '{name}' has shape {shape:?} for {n} cases",
                    path.display()
                ))
            };
            if scale.shape != [n] {
                return Err(shape_err("scale", &scale.shape));
            }
            if partial.shape != [n, INPUT_POINTS, 3] {
                return Err(shape_err("partial", &partial.shape));
            }
            if gt.shape != [n, gt_points, 3] {
                return Err(shape_err("gt", &gt.shape));
            }
            let d = d_plan.first().copied().filter(|&d| d > 0).map(|d| d as usize);
            let (p, g, s) = (partial.f32s(), gt.f32s(), scale.f32s());
            if let Some(i) = p.iter().chain(&g).position(|x| !x.is_finite()) {
                return Err(LearnError::Invalid(format!("{}: value {i} is not finite", path.display())));
            }
            if let Some(i) = s.iter().position(|x| !(x.is_finite() && *x > 0.0)) {
                return Err(LearnError::Invalid(format!(
                    "{}: scale of case {i} is not positive",
                    path.display()
                )));
            }
            Ok(CompletionCases {
                gt_points,
                partial: p,
                gt: g,
                scale: s,
                objects: vec![uid_of(f); n],
                d_plan: vec![d; n],
            })
        })
        .collect();
    let mut all = CompletionCases { gt_points, ..CompletionCases::default() };
    for p in parts {
        all.extend(p?);
    }
    Ok(all)
}

/// Splits cases into (train, validation) by object ([`is_validation`]).
pub fn split_completion(cases: &CompletionCases, val_fraction: f64) -> (CompletionCases, CompletionCases) {
    let mut train = CompletionCases { gt_points: cases.gt_points, ..CompletionCases::default() };
    let mut val = train.clone();
    for i in 0..cases.len() {
        if is_validation(&cases.objects[i], val_fraction) {
            val.push_from(cases, i);
        } else {
            train.push_from(cases, i);
        }
    }
    (train, val)
}

fn input_tensor(cases: &CompletionCases, idx: &[usize], device: &Device) -> Tensor<3> {
    let mut x = Vec::with_capacity(idx.len() * INPUT_POINTS * 3);
    for &i in idx {
        x.extend_from_slice(cases.input(i));
    }
    Tensor::<3>::from_data(TensorData::new(x, [idx.len(), INPUT_POINTS, 3]), device)
}

/// The loss's ground truth of case `i` in `epoch`: `n` of its points, the contract's resampling
/// rule with ChaCha8 of (seed, epoch, case).
pub fn loss_truth(cases: &CompletionCases, i: usize, n: usize, seed: u64, epoch: usize) -> Vec<f32> {
    let t = to_f64(cases.truth(i));
    let mut rng = ChaCha8Rng::seed_from_u64(mix(mix(seed, 2_000_000 + epoch as u64), i as u64));
    let pts = resample(&t, n, &mut rng).expect("a finite, non-empty ground truth");
    pts.iter().flat_map(|p| p.map(|x| x as f32)).collect()
}

/// Mean Chamfer figures over cases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CompletionMetrics {
    /// Cases.
    pub cases: usize,
    /// The contract's output (prediction + input) vs the ground truth.
    pub net: Chamfer,
    /// The prediction alone.
    pub net_fine: Chamfer,
    /// The input alone (the `identity` backend).
    pub identity: Chamfer,
}

#[derive(Default, Clone)]
struct Sum {
    n: usize,
    m: [Chamfer; 3],
}

impl Sum {
    fn add(&mut self, c: &[Chamfer; 3]) {
        self.n += 1;
        for (s, x) in self.m.iter_mut().zip(c) {
            s.accuracy += x.accuracy;
            s.completeness += x.completeness;
            s.l1 += x.l1;
        }
    }
    fn mean(&self) -> CompletionMetrics {
        let k = self.n.max(1) as f64;
        let f = |c: &Chamfer| Chamfer {
            accuracy: c.accuracy / k,
            completeness: c.completeness / k,
            l1: c.l1 / k,
        };
        CompletionMetrics {
            cases: self.n,
            net: f(&self.m[0]),
            net_fine: f(&self.m[1]),
            identity: f(&self.m[2]),
        }
    }
}

/// An evaluation: the means over all cases and per d_plan bucket (`unknown` for objects without
/// a proven d_plan), with the objects evaluated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompletionEval {
    /// Over every case.
    pub all: CompletionMetrics,
    /// Per d_plan bucket label (`1-5`, `6-10`, …; `unknown`).
    pub buckets: BTreeMap<String, CompletionMetrics>,
    /// Distinct objects.
    pub objects: usize,
}

/// The Chamfer figures of one case (module docs) from its network prediction (normalized).
pub fn case_chamfers(cases: &CompletionCases, i: usize, fine: &[f32]) -> [Chamfer; 3] {
    let s = cases.scale[i] as f64;
    let input = to_f64(cases.input(i));
    let truth = to_f64(cases.truth(i));
    let pred = to_f64(fine);
    let mut out = pred.clone();
    out.extend_from_slice(&input);
    let obj =
        |c: Chamfer| Chamfer { accuracy: c.accuracy * s, completeness: c.completeness * s, l1: c.l1 * s };
    [obj(chamfer_l1(&out, &truth)), obj(chamfer_l1(&pred, &truth)), obj(chamfer_l1(&input, &truth))]
}

/// Evaluates `net` (a non-autodiff model) on every case (module docs).
pub fn evaluate_completion(net: &CompletionNet, cases: &CompletionCases, device: &Device) -> CompletionEval {
    let mut all = Sum::default();
    let mut buckets: BTreeMap<String, Sum> = BTreeMap::new();
    let idx: Vec<usize> = (0..cases.len()).collect();
    for chunk in idx.chunks(8) {
        let (_, fine) = net.forward(input_tensor(cases, chunk, device));
        let [_, p, _] = fine.dims();
        let v: Vec<f32> = fine.into_data().try_to_vec::<f32>().expect("f32 points");
        let per: Vec<[Chamfer; 3]> = chunk
            .par_iter()
            .enumerate()
            .map(|(k, &i)| case_chamfers(cases, i, &v[k * p * 3..(k + 1) * p * 3]))
            .collect();
        for (c, &i) in per.iter().zip(chunk) {
            all.add(c);
            let label =
                cases.d_plan[i].and_then(bucket_of).map(bucket_label).unwrap_or_else(|| "unknown".into());
            buckets.entry(label).or_default().add(c);
        }
    }
    CompletionEval {
        all: all.mean(),
        buckets: buckets.into_iter().map(|(k, s)| (k, s.mean())).collect(),
        objects: cases.object_list().len(),
    }
}

/// One epoch's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompletionEpochLog {
    /// 1-based epoch.
    pub epoch: usize,
    /// The epoch's learning rate.
    pub lr: f64,
    /// Mean training loss per case (weighted coarse + fine Chamfer-L1, normalized frame).
    pub train_loss: f64,
    /// Validation figures (object frame; zero cases without validation objects).
    pub val: CompletionMetrics,
    /// Seconds of the epoch.
    pub seconds: f64,
    /// Training samples per second.
    pub samples_per_s: f64,
}

/// What a progress display is told.
pub trait CompletionProgress: Sync {
    /// A batch finished (`done` of `total` in this epoch), with its loss.
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64);
    /// An epoch finished.
    fn epoch(&self, log: &CompletionEpochLog);
}

/// No progress output.
pub struct QuietCompletion;
impl CompletionProgress for QuietCompletion {
    fn batch(&self, _: usize, _: usize, _: usize, _: f64) {}
    fn epoch(&self, _: &CompletionEpochLog) {}
}

/// The kept epoch (1-based): the lowest validation `net` Chamfer-L1, ties to the earlier
/// epoch; the last epoch without validation cases.
pub fn select_completion_epoch(history: &[CompletionEpochLog], has_validation: bool) -> usize {
    if !has_validation || history.is_empty() {
        return history.len();
    }
    let mut best = &history[0];
    for h in &history[1..] {
        if h.val.net.l1 < best.val.net.l1 {
            best = h;
        }
    }
    best.epoch
}

/// Saves `net` as safetensors at `path` ([`save_safetensors`]: reproducible bytes).
pub fn save_completion_weights(net: &CompletionNet, path: &Path) -> Result<(), LearnError> {
    save_safetensors(net, path)
}

/// Loads safetensors bytes into a fresh network of `shape`; every tensor must be present.
pub fn load_completion_weights_bytes(
    bytes: &[u8],
    shape: &CompletionShape,
    device: &Device,
) -> Result<CompletionNet, String> {
    shape.validate().map_err(|e| e.to_string())?;
    let mut net = CompletionNet::new(shape, device);
    load_safetensors(&mut net, bytes, &format!("the completion shape {shape:?}"))?;
    Ok(net)
}

/// The result of a training run.
#[derive(Debug, Clone)]
pub struct CompletionOutcome {
    /// Per-epoch figures.
    pub history: Vec<CompletionEpochLog>,
    /// The kept epoch ([`select_completion_epoch`]).
    pub best_epoch: usize,
    /// Training and validation case counts.
    pub cases: (usize, usize),
    /// Validation objects.
    pub val_objects: Vec<String>,
    /// The kept weights on the validation cases, per bucket.
    pub val: CompletionEval,
    /// Parameters of the network.
    pub params: usize,
}

/// Trains the completion network on the dataset in `data` (`only`: its objects to use), writes
/// the kept weights to `out` and a checkpoint per epoch next to it; `resume` continues from the
/// last checkpoint of the same settings and data.
pub fn train_completion(
    data: &Path,
    only: Option<&BTreeSet<String>>,
    out: &Path,
    settings: &CompletionTrainSettings,
    resume: bool,
    progress: &dyn CompletionProgress,
) -> Result<CompletionOutcome, LearnError> {
    settings.validate()?;
    let all = load_completion_cases(data, only)?;
    if all.is_empty() {
        return Err(LearnError::Invalid(format!("{}: the dataset has no cases", data.display())));
    }
    let (train_set, val_set) = split_completion(&all, settings.val_fraction);
    drop(all);
    if train_set.is_empty() {
        return Err(LearnError::Invalid("no training cases left after the validation split".into()));
    }
    let val_objects = val_set.object_list();

    let base = Device::flex();
    base.seed(settings.seed);
    let device = base.clone().autodiff();
    let mut net = CompletionNet::new(&settings.shape, &device);
    let params = net.num_params();
    let mut optim: ModuleOptimizer = AdamConfig::new().with_epsilon(1e-8).init();

    let settings_json = serde_json::to_value(settings).expect("settings serialize");
    let identity = json!({
        "network": "completion",
        "settings": trajectory_settings(&settings_json, &["epochs"]),
        "data": data.display().to_string(),
        "objects": only,
    });
    let ckpt = Checkpoints::create(out, identity)?;
    let mut history: Vec<CompletionEpochLog> = Vec::new();
    if resume {
        let (h, rec) = ckpt.resume(settings.epochs, &mut net)?;
        history = h;
        if let Some(rec) = rec {
            optim = optim.load_record(rec);
        }
    }
    let start_epoch = history.len() + 1;

    for epoch in start_epoch..=settings.epochs {
        let t = Instant::now();
        let lr = settings.lr_at(epoch);
        base.seed(mix(settings.seed, epoch as u64));
        let mut order: Vec<usize> = (0..train_set.len()).collect();
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(settings.seed, 1_000_000 + epoch as u64)));
        if let Some(m) = settings.max_cases {
            order.truncate(m);
        }
        let batches: Vec<&[usize]> = order.chunks(settings.batch).collect();
        let mut loss_sum = 0.0f64;
        for (bi, idx) in batches.iter().enumerate() {
            let truth: Vec<Vec<f32>> = idx
                .par_iter()
                .map(|&i| loss_truth(&train_set, i, settings.loss_gt_points, settings.seed, epoch))
                .collect();
            let (coarse, fine) = net.forward(input_tensor(&train_set, idx, &device));
            let loss = chamfer_loss(coarse, &truth) * settings.coarse_weight
                + chamfer_loss(fine, &truth) * settings.fine_weight;
            let grads = loss.backward();
            let l: f32 = loss.into_scalar();
            loss_sum += l as f64 * idx.len() as f64;
            let grads = GradientsParams::from_grads(grads, &net);
            net = optim.step(lr, net, grads);
            progress.batch(epoch, bi + 1, batches.len(), l as f64);
        }
        let seen = order.len();
        let valid = net.valid();
        let val = if val_set.is_empty() {
            CompletionMetrics::default()
        } else {
            evaluate_completion(&valid, &val_set, &base).all
        };
        let secs = t.elapsed().as_secs_f64();
        let log = CompletionEpochLog {
            epoch,
            lr,
            train_loss: loss_sum / seen as f64,
            val,
            seconds: secs,
            samples_per_s: seen as f64 / secs,
        };
        progress.epoch(&log);
        history.push(log);
        ckpt.save(epoch, &valid, &net, &optim, &history)?;
    }

    let best_epoch = select_completion_epoch(&history, !val_set.is_empty());
    ckpt.keep(best_epoch, out)?;
    let val = if val_set.is_empty() {
        CompletionEval::default()
    } else {
        let bytes = std::fs::read(out).map_err(|e| LearnError::io(out, e))?;
        let kept = load_completion_weights_bytes(&bytes, &settings.shape, &base)
            .map_err(|e| LearnError::io(out, e))?;
        evaluate_completion(&kept, &val_set, &base)
    };
    Ok(CompletionOutcome {
        history,
        best_epoch,
        cases: (train_set.len(), val_set.len()),
        val_objects,
        val,
        params,
    })
}

/// Weights (`builtin` or a file with its sidecar) evaluated on a completion dataset: the
/// held-out figures of `objview learn eval` and of the sidecar's `heldout`.
pub fn eval_completion_weights(weights: &str, data: &Path) -> Result<Value, LearnError> {
    let backend = if weights == "builtin" {
        crate::completion_backend::NetCompletion::builtin()
    } else {
        crate::completion_backend::NetCompletion::from_file(Path::new(weights))
    }
    .map_err(LearnError::Invalid)?;
    let cases = load_completion_cases(data, None)?;
    if cases.is_empty() {
        return Err(LearnError::Invalid(format!("{}: the dataset has no cases", data.display())));
    }
    let e = evaluate_completion(backend.net(), &cases, &Device::flex());
    let m = read_manifest(data)?;
    Ok(json!({
        "weights": weights,
        "data": data.display().to_string(),
        "dataset_command": m["command"],
        "objects": e.objects,
        "cases": e.all.cases,
        "chamfer_l1": eval_json(&e),
        "beats_identity": e.all.net.l1 < e.all.identity.l1,
        "frame": "object (unit-normalized mesh), Chamfer-L1 against the whole stored ground truth",
        "version": crate::VERSION,
    }))
}

/// An evaluation as recorded: per figure (`net`, `net_fine`, `identity`) the means over all
/// cases and per d_plan bucket.
pub fn eval_json(e: &CompletionEval) -> Value {
    json!({"all": e.all, "buckets": e.buckets, "objects": e.objects})
}

/// [`train_completion`], then writes the sidecar JSON next to `out`: the exact command, the
/// data, the settings (with the shape and its deviation), every epoch, the kept epoch's
/// validation figures per d_plan bucket, the held-out figures when `heldout` is given, whether
/// `net` beats `identity`, the weights' hash and the version.
#[allow(clippy::too_many_arguments)]
pub fn train_completion_and_describe(
    data: &Path,
    only: Option<&BTreeSet<String>>,
    out: &Path,
    settings: &CompletionTrainSettings,
    resume: bool,
    heldout: Option<&Path>,
    command: &str,
    progress: &dyn CompletionProgress,
) -> Result<Value, LearnError> {
    let t = Instant::now();
    let manifest = read_manifest(data)?;
    let o = train_completion(data, only, out, settings, resume, progress)?;
    let bytes = std::fs::read(out).map_err(|e| LearnError::io(out, e))?;
    let heldout_json = match heldout {
        Some(dir) => {
            let cases = load_completion_cases(dir, None)?;
            let base = Device::flex();
            let net = load_completion_weights_bytes(&bytes, &settings.shape, &base)
                .map_err(|e| LearnError::io(out, e))?;
            let e = evaluate_completion(&net, &cases, &base);
            let m = read_manifest(dir)?;
            json!({"data": dir.display().to_string(), "objects": e.objects, "cases": e.all.cases,
                   "chamfer_l1": eval_json(&e), "beats_identity": e.all.net.l1 < e.all.identity.l1,
                   "dataset_command": m["command"]})
        }
        None => Value::Null,
    };
    let best = &o.history[o.best_epoch - 1];
    let val_beats = (o.cases.1 > 0).then_some(o.val.all.net.l1 < o.val.all.identity.l1);
    let sidecar = json!({
        "network": "completion",
        "weights_format": "safetensors (burn-store), module paths of objview_learn::completion_net::CompletionNet",
        "command": command,
        "data": {
            "dir": data.display().to_string(),
            "method": manifest["method"],
            "objects": manifest["objects"],
            "cases": manifest["cases"],
            "subset": only,
            "train_cases": o.cases.0,
            "val_cases": o.cases.1,
            "val_objects": o.val_objects,
            "partials": manifest["settings"]["partials"],
            "views_per_partial": manifest["settings"]["views_per_partial"],
            "gt_points": manifest["settings"]["gt_points"],
            "pool": manifest["settings"]["pool"],
            "inputs": manifest["settings"]["inputs"],
            "shard": manifest["settings"]["shard"],
            "dataset_command": manifest["command"],
            "dataset_version": manifest["version"],
        },
        "settings": settings,
        "recipe": "loss = coarse_weight * CD-L1(coarse, truth) + fine_weight * CD-L1(fine, truth) (PoinTr's ChamferDistanceL1: mean nearest-neighbour Euclidean distance both ways, averaged; exact neighbours, settings.loss_gt_points ground-truth points per case, a fresh seeded subset each epoch); Adam lr, betas (0.9, 0.999), eps 1e-8, no weight decay, no clipping; StepLR(settings.lr_step, settings.lr_factor) per epoch; kept epoch = lowest validation CD-L1 of the contract output (prediction + input)",
        "metric": "Chamfer-L1 in the object frame (unit-normalized mesh) against the whole stored ground truth (settings gt_points): net = the contract's 8192-point output (6144 predicted + 2048 input), net_fine = the 6144 predicted points, identity = the 2048 input points; accuracy = prediction -> truth half, completeness = truth -> prediction half",
        "deviation": settings.shape.deviation(),
        "params": o.params,
        "history": o.history,
        "best_epoch": o.best_epoch,
        "final": {"train_loss": best.train_loss, "val": best.val},
        "validation": eval_json(&o.val),
        "heldout": heldout_json,
        "beats_identity": {"validation": val_beats, "heldout": heldout_json.get("beats_identity").cloned()},
        "weights_fnv1a64": format!("{:016x}", fnv1a64(&bytes)),
        "seconds": t.elapsed().as_secs_f64(),
        "version": crate::VERSION,
        "burn": "0.22.1 (flex backend)",
    });
    let side = sidecar_path(out);
    std::fs::write(&side, serde_json::to_string_pretty(&sidecar).expect("json") + "\n")
        .map_err(|e| LearnError::io(&side, e))?;
    Ok(sidecar)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(epoch: usize, l1: f64) -> CompletionEpochLog {
        CompletionEpochLog {
            epoch,
            lr: 0.0,
            train_loss: 0.0,
            val: CompletionMetrics { net: Chamfer { l1, ..Default::default() }, ..Default::default() },
            seconds: 0.0,
            samples_per_s: 0.0,
        }
    }

    #[test]
    fn selection_and_steplr() {
        let h = [log(1, 0.3), log(2, 0.2), log(3, 0.2), log(4, 0.25)];
        assert_eq!(select_completion_epoch(&h, true), 2, "ties to the earlier epoch");
        assert_eq!(select_completion_epoch(&h, false), 4);
        let s = CompletionTrainSettings { lr: 1e-3, lr_step: 2, lr_factor: 0.5, ..Default::default() };
        assert_eq!((s.lr_at(1), s.lr_at(2), s.lr_at(3), s.lr_at(5)), (1e-3, 1e-3, 5e-4, 2.5e-4));
        let bad = CompletionTrainSettings { fine_weight: -1.0, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("--fine-weight"));
    }

    /// Per-case figures against hand-computed values: truth = the 8 corners of a cube of side 2
    /// (normalized frame), input = 2048 copies of one corner, the prediction = the other 7
    /// corners (and copies); scale 0.5.
    #[test]
    fn case_figures_in_the_object_frame() {
        let corners: Vec<[f32; 3]> = (0..8)
            .map(|k| {
                [
                    if k & 1 == 1 { 1.0 } else { -1.0 },
                    if k & 2 == 2 { 1.0 } else { -1.0 },
                    if k & 4 == 4 { 1.0 } else { -1.0 },
                ]
            })
            .collect();
        let cases = CompletionCases {
            gt_points: 8,
            partial: (0..INPUT_POINTS).flat_map(|_| corners[0]).collect(),
            gt: corners.iter().flatten().copied().collect(),
            scale: vec![0.5],
            objects: vec!["o".into()],
            d_plan: vec![Some(7)],
        };
        let fine: Vec<f32> = (0..6144).flat_map(|k| corners[1 + k % 7]).collect();
        let [net, fine_only, identity] = case_chamfers(&cases, 0, &fine);
        // identity: input → truth 0; truth → input: 0, three at 2, three at 2√2, one at 2√3.
        let far = (3.0 * 2.0 + 3.0 * 8f64.sqrt() + 12f64.sqrt()) / 8.0;
        assert!((identity.completeness - 0.5 * far).abs() < 1e-12 && identity.accuracy == 0.0);
        // prediction alone: accuracy 0, completeness: corner 0 is 2 from its nearest → 2/8.
        assert_eq!(fine_only.accuracy, 0.0);
        assert!((fine_only.completeness - 0.5 * 2.0 / 8.0).abs() < 1e-12);
        assert_eq!((net.accuracy, net.completeness, net.l1), (0.0, 0.0, 0.0), "the union is the truth");
    }
}
