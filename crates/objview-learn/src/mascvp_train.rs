//! `objview learn train ma-scvp`: labels, loss, decoding, evaluation and the training loop of
//! MA-SCVP ([`crate::mascvp`]).
//!
//! Cases: an `ma-scvp` dataset of `objview learn dataset` (long-tail sampling, need_case_1 =
//! 64); input = the case's 64³ grid average-pooled to the network's G and its view state
//! `visited` (128 flags); label = the exact residual set cover over unvisited views, the
//! dataset's `cover` array as a 128-dim multi-hot. Cases whose cover failed (`cover_status` 2)
//! are skipped; time-limited covers (1) are kept, as the reference keeps TIME_LIMIT solutions.
//!
//! Recipe (MASCVP-orig's, learned-baselines.md §3.4; the reference's own script is not public):
//! loss = **sum** over every (case, view) entry of the batch of the binary cross-entropy on the
//! logits with weight 1.5 on positive entries and 1 on negatives ([`weighted_bce_sum`]); Adam
//! (lr 1e-4, β = (0.9, 0.999), ε = 1e-8, no weight decay, no clipping), batch 8, StepLR(step 20,
//! factor 0.5) per epoch; the kept epoch is the one of the best validation F1 of the γ-decoded
//! set ({v : sigmoid ≥ γ} minus visited views vs the label set; mean over cases; ties: lower
//! validation loss, then the earlier epoch) — the reference ships `best_f1.pt`.
//!
//! A trivial baseline is reported next to it ([`most_frequent_baseline`]): a fixed set, the k
//! views most often in the training labels (minus the visited ones), k chosen on the training
//! cases.
//!
//! Determinism and resume are as for NBV-Net ([`crate::train`]): the device RNG is seeded
//! with `seed` before the model is built and with `(seed, epoch)` at every epoch start, the case
//! order is a ChaCha8 shuffle seeded with `(seed, epoch)`, and per-epoch checkpoints (weights,
//! optimizer) let `--resume` continue exactly. Objects go to validation by a hash of their uid.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::activation::log_sigmoid;
use burn::tensor::{Device, Tensor, TensorData};
use objview_geom::hash::fnv1a64;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::checkpoint::{trajectory_settings, Checkpoints};
use crate::dataset::VIEWS;
use crate::input_grid::pool_grid;
use crate::mascvp::{MascvpNet, MascvpShape};
use crate::npz::{Dtype, NpzReader};
use crate::train::{is_validation, mix, read_manifest, sidecar_path};
use crate::LearnError;

/// Every training setting of MA-SCVP (recorded in the sidecar).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScvpTrainSettings {
    /// The network's shape (its `grid` is the training grid).
    pub shape: MascvpShape,
    /// Epochs.
    pub epochs: usize,
    /// Batch size.
    pub batch: usize,
    /// Adam's initial learning rate.
    pub lr: f64,
    /// StepLR: the learning rate is multiplied by `lr_factor` every `lr_step` epochs.
    pub lr_step: usize,
    /// StepLR factor.
    pub lr_factor: f64,
    /// Weight of positive entries in the BCE.
    pub pos_weight: f64,
    /// Decoding threshold of the validation F1 (the selection rule).
    pub gamma: f64,
    /// Seed of initialization, dropout and case order.
    pub seed: u64,
    /// Fraction of objects held out for validation.
    pub val_fraction: f64,
    /// Use at most this many training cases per epoch (the first after the epoch's shuffle).
    pub max_cases: Option<usize>,
}

impl Default for ScvpTrainSettings {
    fn default() -> Self {
        ScvpTrainSettings {
            shape: MascvpShape::scaled(),
            epochs: 10,
            batch: 8,
            lr: 1e-4,
            lr_step: 20,
            lr_factor: 0.5,
            pos_weight: 1.5,
            gamma: 0.3,
            seed: 42,
            val_fraction: 0.1,
            max_cases: None,
        }
    }
}

impl ScvpTrainSettings {
    /// Checks ranges (an error names the flag).
    pub fn validate(&self) -> Result<(), LearnError> {
        self.shape.validate()?;
        let bad = |m: String| Err(LearnError::Invalid(m));
        if self.epochs == 0 || self.batch == 0 || self.lr_step == 0 {
            return bad("--epochs, --batch and --lr-step must be at least 1".into());
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(format!("--lr must be a positive number, got {}", self.lr));
        }
        if !(self.lr_factor.is_finite() && self.lr_factor > 0.0 && self.lr_factor <= 1.0) {
            return bad(format!("--lr-factor must be in (0, 1], got {}", self.lr_factor));
        }
        if !(self.pos_weight.is_finite() && self.pos_weight > 0.0) {
            return bad(format!("--pos-weight must be a positive number, got {}", self.pos_weight));
        }
        if !(self.gamma > 0.0 && self.gamma < 1.0) {
            return bad(format!("--gamma must be in (0, 1), got {}", self.gamma));
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

/// MA-SCVP cases in memory.
#[derive(Debug, Clone, Default)]
pub struct ScvpCases {
    /// Grid cells per axis.
    pub grid: usize,
    /// `len · grid³` probabilities.
    pub grids: Vec<f32>,
    /// `len · 128` view-state flags.
    pub visited: Vec<u8>,
    /// `len · 128` label flags (the residual set cover).
    pub cover: Vec<u8>,
    /// Object uid of each case.
    pub objects: Vec<String>,
}

impl ScvpCases {
    /// Number of cases.
    pub fn len(&self) -> usize {
        self.objects.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }
    fn cells(&self) -> usize {
        self.grid.pow(3)
    }
    fn push_from(&mut self, o: &ScvpCases, i: usize) {
        let c = o.cells();
        self.grids.extend_from_slice(&o.grids[i * c..(i + 1) * c]);
        self.visited.extend_from_slice(&o.visited[i * VIEWS..(i + 1) * VIEWS]);
        self.cover.extend_from_slice(&o.cover[i * VIEWS..(i + 1) * VIEWS]);
        self.objects.push(o.objects[i].clone());
    }
    fn extend(&mut self, o: ScvpCases) {
        self.grids.extend(o.grids);
        self.visited.extend(o.visited);
        self.cover.extend(o.cover);
        self.objects.extend(o.objects);
    }
    /// The view-state row of case `i`.
    pub fn visited_row(&self, i: usize) -> &[u8] {
        &self.visited[i * VIEWS..(i + 1) * VIEWS]
    }
    /// The label row of case `i`.
    pub fn cover_row(&self, i: usize) -> &[u8] {
        &self.cover[i * VIEWS..(i + 1) * VIEWS]
    }
}

/// Reads every usable case of the `ma-scvp` dataset in `dir` at grid size `grid`; also returns
/// how many were skipped because their cover failed.
pub fn load_scvp_cases(dir: &Path, grid: usize) -> Result<(ScvpCases, usize), LearnError> {
    load_scvp_cases_of(dir, grid, None)
}

/// [`load_scvp_cases`] restricted to the objects in `only` (`None`: every object); an object of
/// `only` that the dataset does not hold is an error naming it.
pub fn load_scvp_cases_of(
    dir: &Path,
    grid: usize,
    only: Option<&BTreeSet<String>>,
) -> Result<(ScvpCases, usize), LearnError> {
    let m = read_manifest(dir)?;
    let mpath = dir.join("manifest.json");
    if m["method"] != "ma-scvp" {
        return Err(LearnError::Invalid(format!(
            "{}: a dataset of method {} (MA-SCVP needs `learn dataset --method ma-scvp`: residual covers)",
            mpath.display(),
            m["method"]
        )));
    }
    let data_grid = m["grid"].as_u64().unwrap_or(0) as usize;
    if data_grid == 0 || !data_grid.is_multiple_of(grid) {
        return Err(LearnError::Invalid(format!(
            "{}: the data's grid {data_grid} cannot be pooled to {grid}",
            mpath.display()
        )));
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
    let parts: Vec<Result<(ScvpCases, usize), LearnError>> = files
        .par_iter()
        .map(|f| {
            let path = crate::dataset::resolve_data_file(dir, f)?;
            let mut r = NpzReader::open(&path)?;
            let g = r.array("grid", Some(Dtype::F32))?;
            let visited = r.array("visited", Some(Dtype::U8))?;
            let cover = r.array("cover", Some(Dtype::U8))?;
            let status = r.array("cover_status", Some(Dtype::I8))?.ints();
            let n = status.len();
            let shape_err = |name: &str, shape: &[usize]| {
                LearnError::Invalid(format!(
                    "{}: array '{name}' has shape {shape:?} for {n} cases",
                    path.display()
                ))
            };
            if g.shape != [n, data_grid, data_grid, data_grid] {
                return Err(shape_err("grid", &g.shape));
            }
            if visited.shape != [n, VIEWS] {
                return Err(shape_err("visited", &visited.shape));
            }
            if cover.shape != [n, VIEWS] {
                return Err(shape_err("cover", &cover.shape));
            }
            if let Some(i) = status.iter().position(|&s| s == -1) {
                return Err(LearnError::Invalid(format!(
                    "{}: case {i} has no residual cover (cover_status -1)",
                    path.display()
                )));
            }
            let (vals, vis, cov) = (g.f32s(), visited.ints(), cover.ints());
            let c = data_grid.pow(3);
            let uid = uid_of(f);
            let mut out = ScvpCases { grid, ..ScvpCases::default() };
            let mut skipped = 0;
            for i in 0..n {
                if status[i] == 2 {
                    skipped += 1;
                    continue;
                }
                out.grids.extend(pool_grid(&vals[i * c..(i + 1) * c], data_grid, data_grid / grid));
                out.visited.extend(vis[i * VIEWS..(i + 1) * VIEWS].iter().map(|&x| (x != 0) as u8));
                out.cover.extend(cov[i * VIEWS..(i + 1) * VIEWS].iter().map(|&x| (x != 0) as u8));
                out.objects.push(uid.clone());
            }
            Ok((out, skipped))
        })
        .collect();
    let mut all = ScvpCases { grid, ..ScvpCases::default() };
    let mut skipped = 0;
    for p in parts {
        let (p, s) = p?;
        all.extend(p);
        skipped += s;
    }
    Ok((all, skipped))
}

/// Splits cases into (train, validation) by object ([`is_validation`]).
pub fn split_scvp(cases: &ScvpCases, val_fraction: f64) -> (ScvpCases, ScvpCases) {
    let mut train = ScvpCases { grid: cases.grid, ..ScvpCases::default() };
    let mut val = ScvpCases { grid: cases.grid, ..ScvpCases::default() };
    for i in 0..cases.len() {
        if is_validation(&cases.objects[i], val_fraction) {
            val.push_from(cases, i);
        } else {
            train.push_from(cases, i);
        }
    }
    (train, val)
}

/// The loss: Σ over every entry of −(w·y·log σ(x) + (1 − y)·log σ(−x)), w = `pos_weight`
/// (MASCVP-orig's "NBVLoss": weighted BCE, summed, not averaged).
pub fn weighted_bce_sum(logits: Tensor<2>, targets: Tensor<2>, pos_weight: f64) -> Tensor<1> {
    let pos = targets.clone() * log_sigmoid(logits.clone()) * pos_weight;
    let neg = (targets.neg() + 1.0) * log_sigmoid(logits.neg());
    (pos + neg).sum().neg()
}

/// The decoded set: {v : sigmoid(logit_v) ≥ γ}, ascending.
pub fn decode(logits: &[f32], gamma: f64) -> Vec<usize> {
    logits
        .iter()
        .enumerate()
        .filter(|(_, &x)| 1.0 / (1.0 + (-(x as f64)).exp()) >= gamma)
        .map(|(v, _)| v)
        .collect()
}

/// Set F1 of `pred` vs `label` (both as ascending id lists); 1 when both are empty.
pub fn set_f1(pred: &[usize], label: &[usize]) -> f64 {
    if pred.is_empty() && label.is_empty() {
        return 1.0;
    }
    let hit = pred.iter().filter(|v| label.contains(v)).count();
    2.0 * hit as f64 / (pred.len() + label.len()) as f64
}

/// Set-quality figures averaged over cases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetMetrics {
    /// Mean F1.
    pub f1: f64,
    /// Mean precision (1 for an empty prediction).
    pub precision: f64,
    /// Mean recall (1 for an empty label).
    pub recall: f64,
    /// Mean predicted set size.
    pub pred_size: f64,
    /// Mean label set size.
    pub label_size: f64,
}

#[derive(Default)]
struct MetricSum {
    m: SetMetrics,
    n: usize,
}

impl MetricSum {
    fn add(&mut self, pred: &[usize], label: &[usize]) {
        let hit = pred.iter().filter(|v| label.contains(v)).count() as f64;
        self.m.f1 += set_f1(pred, label);
        self.m.precision += if pred.is_empty() { 1.0 } else { hit / pred.len() as f64 };
        self.m.recall += if label.is_empty() { 1.0 } else { hit / label.len() as f64 };
        self.m.pred_size += pred.len() as f64;
        self.m.label_size += label.len() as f64;
        self.n += 1;
    }
    fn mean(self) -> SetMetrics {
        let k = self.n.max(1) as f64;
        let m = self.m;
        SetMetrics {
            f1: m.f1 / k,
            precision: m.precision / k,
            recall: m.recall / k,
            pred_size: m.pred_size / k,
            label_size: m.label_size / k,
        }
    }
}

fn ids(row: &[u8]) -> Vec<usize> {
    row.iter().enumerate().filter(|(_, &x)| x != 0).map(|(v, _)| v).collect()
}

/// The decoded set of case `i` without its visited views.
pub fn decode_unvisited(logits: &[f32], visited: &[u8], gamma: f64) -> Vec<usize> {
    decode(logits, gamma).into_iter().filter(|&v| visited.get(v).is_none_or(|&f| f == 0)).collect()
}

fn batch_tensors(cases: &ScvpCases, idx: &[usize], device: &Device) -> (Tensor<5>, Tensor<2>, Tensor<2>) {
    let (c, g) = (cases.cells(), cases.grid);
    let mut x = Vec::with_capacity(idx.len() * c);
    let (mut vs, mut y) = (Vec::with_capacity(idx.len() * VIEWS), Vec::with_capacity(idx.len() * VIEWS));
    for &i in idx {
        x.extend_from_slice(&cases.grids[i * c..(i + 1) * c]);
        vs.extend(cases.visited_row(i).iter().map(|&f| f as f32));
        y.extend(cases.cover_row(i).iter().map(|&f| f as f32));
    }
    let n = idx.len();
    (
        Tensor::<5>::from_data(TensorData::new(x, [n, 1, g, g, g]), device),
        Tensor::<2>::from_data(TensorData::new(vs, [n, VIEWS]), device),
        Tensor::<2>::from_data(TensorData::new(y, [n, VIEWS]), device),
    )
}

/// Logits of `net` (evaluation mode) for `cases[idx]`, row-major [idx.len(), 128].
pub fn logits(net: &MascvpNet, cases: &ScvpCases, idx: &[usize], device: &Device) -> Vec<f32> {
    let (x, vs, _) = batch_tensors(cases, idx, device);
    net.forward(x, vs).into_data().try_to_vec::<f32>().expect("f32 logits")
}

/// Mean loss per case and the set metrics at `gamma` of `net` (a non-autodiff model).
pub fn evaluate_scvp(
    net: &MascvpNet,
    cases: &ScvpCases,
    gamma: f64,
    pos_weight: f64,
    device: &Device,
) -> (f64, SetMetrics) {
    if cases.is_empty() {
        return (0.0, SetMetrics::default());
    }
    let (mut loss, mut sum) = (0.0f64, MetricSum::default());
    let idx: Vec<usize> = (0..cases.len()).collect();
    for chunk in idx.chunks(16) {
        let (x, vs, y) = batch_tensors(cases, chunk, device);
        let out = net.forward(x, vs);
        let l: f32 = weighted_bce_sum(out.clone(), y, pos_weight).into_scalar();
        loss += l as f64;
        let v: Vec<f32> = out.into_data().try_to_vec::<f32>().expect("f32 logits");
        for (row, &i) in v.chunks(VIEWS).zip(chunk) {
            sum.add(&decode_unvisited(row, cases.visited_row(i), gamma), &ids(cases.cover_row(i)));
        }
    }
    (loss / cases.len() as f64, sum.mean())
}

/// The trivial baseline: views ranked by how often they are in `train`'s labels (ties: lowest
/// id); the fixed set of the top k (minus each case's visited views), k in 0..=128 chosen for
/// the best mean F1 on `train`. Returns (k, train metrics, metrics on `eval`).
pub fn most_frequent_baseline(train: &ScvpCases, eval: &ScvpCases) -> (usize, SetMetrics, SetMetrics) {
    let mut count = [0usize; VIEWS];
    for i in 0..train.len() {
        for (v, &f) in train.cover_row(i).iter().enumerate() {
            count[v] += f as usize;
        }
    }
    let mut rank: Vec<usize> = (0..VIEWS).collect();
    rank.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
    let metrics = |cases: &ScvpCases, k: usize| {
        let mut sum = MetricSum::default();
        let mut set: Vec<usize> = rank[..k].to_vec();
        set.sort_unstable();
        for i in 0..cases.len() {
            let vis = cases.visited_row(i);
            let pred: Vec<usize> = set.iter().copied().filter(|&v| vis[v] == 0).collect();
            sum.add(&pred, &ids(cases.cover_row(i)));
        }
        sum.mean()
    };
    let mut best = (0, metrics(train, 0));
    for k in 1..=VIEWS {
        let m = metrics(train, k);
        if m.f1 > best.1.f1 {
            best = (k, m);
        }
    }
    (best.0, best.1, metrics(eval, best.0))
}

/// One epoch's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScvpEpochLog {
    /// 1-based epoch.
    pub epoch: usize,
    /// The epoch's learning rate (StepLR).
    pub lr: f64,
    /// Mean training loss per case (the summed BCE of a case's 128 entries).
    pub train_loss: f64,
    /// Mean validation loss per case (0 without validation cases).
    pub val_loss: f64,
    /// Validation set metrics at the settings' γ.
    pub val: SetMetrics,
    /// Seconds of the epoch.
    pub seconds: f64,
    /// Training samples per second.
    pub samples_per_s: f64,
}

/// What a progress display is told.
pub trait ScvpProgress: Sync {
    /// A batch finished (`done` of `total` in this epoch), with its summed loss per case.
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64);
    /// An epoch finished.
    fn epoch(&self, log: &ScvpEpochLog);
}

/// No progress output.
pub struct QuietScvp;
impl ScvpProgress for QuietScvp {
    fn batch(&self, _: usize, _: usize, _: usize, _: f64) {}
    fn epoch(&self, _: &ScvpEpochLog) {}
}

/// The kept epoch (1-based): the best validation F1, ties to the lower validation loss, then
/// the earlier epoch; the last epoch when there is no validation set.
pub fn select_scvp_epoch(history: &[ScvpEpochLog], has_validation: bool) -> usize {
    if !has_validation || history.is_empty() {
        return history.len();
    }
    let mut best = &history[0];
    for h in &history[1..] {
        if h.val.f1 > best.val.f1 || (h.val.f1 == best.val.f1 && h.val_loss < best.val_loss) {
            best = h;
        }
    }
    best.epoch
}

/// Saves `net` as safetensors at `path` (one metadata key, so the bytes are reproducible).
pub fn save_scvp_weights(net: &MascvpNet, path: &Path) -> Result<(), LearnError> {
    crate::checkpoint::save_safetensors(net, path)
}

/// Loads safetensors bytes into a fresh network of `shape`; every tensor must be present.
pub fn load_scvp_weights_bytes(
    bytes: &[u8],
    shape: &MascvpShape,
    device: &Device,
) -> Result<MascvpNet, String> {
    shape.validate().map_err(|e| e.to_string())?;
    let mut net = MascvpNet::new(shape, device);
    crate::checkpoint::load_safetensors(&mut net, bytes, &format!("the MA-SCVP shape {shape:?}"))?;
    Ok(net)
}

/// The result of a training run.
#[derive(Debug, Clone)]
pub struct ScvpOutcome {
    /// Per-epoch figures.
    pub history: Vec<ScvpEpochLog>,
    /// The kept epoch ([`select_scvp_epoch`]).
    pub best_epoch: usize,
    /// Training and validation case counts.
    pub cases: (usize, usize),
    /// Cases skipped because their cover failed.
    pub skipped: usize,
    /// Validation objects.
    pub val_objects: usize,
    /// Parameters of the network.
    pub params: usize,
    /// The trivial baseline: (k, train metrics, validation metrics).
    pub baseline: (usize, SetMetrics, SetMetrics),
}

/// Trains MA-SCVP on the dataset in `data`, writes the kept weights to `out` and a checkpoint
/// per epoch next to it; `resume` continues from the last checkpoint of the same settings.
pub fn train_scvp(
    data: &Path,
    out: &Path,
    settings: &ScvpTrainSettings,
    resume: bool,
    progress: &dyn ScvpProgress,
) -> Result<ScvpOutcome, LearnError> {
    train_scvp_on(data, None, out, settings, resume, progress)
}

/// [`train_scvp`] on the cases of the objects in `only` (`None`: every object of the dataset);
/// the subset is part of what a checkpoint must match to be resumed.
pub fn train_scvp_on(
    data: &Path,
    only: Option<&BTreeSet<String>>,
    out: &Path,
    settings: &ScvpTrainSettings,
    resume: bool,
    progress: &dyn ScvpProgress,
) -> Result<ScvpOutcome, LearnError> {
    settings.validate()?;
    let (all, skipped) = load_scvp_cases_of(data, settings.shape.grid, only)?;
    if all.is_empty() {
        return Err(LearnError::Invalid(format!("{}: the dataset has no usable cases", data.display())));
    }
    let (train_set, val_set) = split_scvp(&all, settings.val_fraction);
    drop(all);
    if train_set.is_empty() {
        return Err(LearnError::Invalid("no training cases left after the validation split".into()));
    }
    let mut val_objects = val_set.objects.clone();
    val_objects.dedup();
    let baseline = most_frequent_baseline(&train_set, &val_set);

    let base = Device::flex();
    base.seed(settings.seed);
    let device = base.clone().autodiff();
    let mut net = MascvpNet::new(&settings.shape, &device);
    let params = settings.shape.trainable_params(&net);
    let mut optim: ModuleOptimizer = AdamConfig::new().with_epsilon(1e-8).init();

    let settings_json = serde_json::to_value(settings).expect("settings serialize");
    let identity = json!({
        "network": "ma-scvp",
        "settings": trajectory_settings(&settings_json, &["epochs"]),
        "data": data.display().to_string(),
        "objects": only,
    });
    let ckpt = Checkpoints::create(out, identity)?;
    let mut history: Vec<ScvpEpochLog> = Vec::new();
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
            let (x, vs, y) = batch_tensors(&train_set, idx, &device);
            let loss = weighted_bce_sum(net.forward(x, vs), y, settings.pos_weight);
            let grads = loss.backward();
            let l: f32 = loss.into_scalar();
            loss_sum += l as f64;
            let grads = GradientsParams::from_grads(grads, &net);
            net = optim.step(lr, net, grads);
            progress.batch(epoch, bi + 1, batches.len(), l as f64 / idx.len() as f64);
        }
        let seen = order.len();
        let valid = net.valid();
        let (val_loss, val) = evaluate_scvp(&valid, &val_set, settings.gamma, settings.pos_weight, &base);
        let secs = t.elapsed().as_secs_f64();
        let log = ScvpEpochLog {
            epoch,
            lr,
            train_loss: loss_sum / seen as f64,
            val_loss,
            val,
            seconds: secs,
            samples_per_s: seen as f64 / secs,
        };
        progress.epoch(&log);
        history.push(log);
        ckpt.save(epoch, &valid, &net, &optim, &history)?;
    }

    let best_epoch = select_scvp_epoch(&history, !val_set.is_empty());
    ckpt.keep(best_epoch, out)?;
    Ok(ScvpOutcome {
        history,
        best_epoch,
        cases: (train_set.len(), val_set.len()),
        skipped,
        val_objects: val_objects.len(),
        params,
        baseline,
    })
}

/// [`train_scvp`], then writes the sidecar JSON next to `out`: the exact command, the data,
/// the settings (with the shape and its deviation), every epoch, the kept epoch's metrics, the
/// trivial baseline and whether the network beats it, the weights' hash and the version.
pub fn train_scvp_and_describe(
    data: &Path,
    out: &Path,
    settings: &ScvpTrainSettings,
    resume: bool,
    command: &str,
    progress: &dyn ScvpProgress,
) -> Result<Value, LearnError> {
    train_scvp_on_and_describe(data, None, out, settings, resume, command, progress)
}

/// [`train_scvp_and_describe`] on the objects in `only` (recorded in the sidecar's
/// `data.subset`).
pub fn train_scvp_on_and_describe(
    data: &Path,
    only: Option<&BTreeSet<String>>,
    out: &Path,
    settings: &ScvpTrainSettings,
    resume: bool,
    command: &str,
    progress: &dyn ScvpProgress,
) -> Result<Value, LearnError> {
    let t = Instant::now();
    let manifest = read_manifest(data)?;
    let o = train_scvp_on(data, only, out, settings, resume, progress)?;
    let best = &o.history[o.best_epoch - 1];
    let bytes = std::fs::read(out).map_err(|e| LearnError::io(out, e))?;
    let (k, base_train, base_val) = o.baseline;
    let beats = best.val.f1 > base_val.f1;
    let sidecar = json!({
        "network": "ma-scvp",
        "weights_format": "safetensors (burn-store), module paths of objview_learn::mascvp::MascvpNet",
        "command": command,
        "data": {
            "dir": data.display().to_string(),
            "method": manifest["method"],
            "objects": manifest["objects"],
            "cases": manifest["cases"],
            "subset": only,
            "train_cases": o.cases.0,
            "val_cases": o.cases.1,
            "skipped_cases": o.skipped,
            "val_objects": o.val_objects,
            "need_case_1": manifest["settings"]["need_case_1"],
            "pool": manifest["settings"]["pool"],
            "inputs": manifest["settings"]["inputs"],
            "input": manifest["settings"]["input"],
            "dataset_command": manifest["command"],
            "dataset_version": manifest["version"],
        },
        "settings": settings,
        "recipe": "weighted BCE on logits (weight settings.pos_weight on positive entries), summed over the batch's (case, view) entries; Adam lr, betas (0.9, 0.999), eps 1e-8, no weight decay, no clipping; StepLR(settings.lr_step, settings.lr_factor) per epoch; kept epoch = best validation F1 of the settings.gamma-decoded set minus visited views (mean over cases)",
        "deviation": settings.shape.deviation(),
        "params": o.params,
        "history": o.history,
        "best_epoch": o.best_epoch,
        "final": {"train_loss": best.train_loss, "val_loss": best.val_loss, "val": best.val, "gamma": settings.gamma},
        "baseline": {
            "rule": "most frequent views: the fixed set of the k views most often in the training labels, minus visited views; k chosen for the best training F1",
            "k": k, "train": base_train, "val": base_val,
        },
        "beats_baseline": beats,
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

/// The path of a run's sidecar (re-exported for the planner).
pub fn scvp_sidecar_path(out: &Path) -> PathBuf {
    sidecar_path(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_matches_a_hand_computed_case() {
        let device = Device::flex();
        // Entries: (logit 0, label 1) → 1.5·ln 2; (2, 0) → ln(1 + e²); (−1, 1) → 1.5·ln(1 + e);
        // (0.5, 0) → ln(1 + e^0.5).
        let x = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 2.0, -1.0, 0.5], [2, 2]), &device);
        let y = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 0.0, 1.0, 0.0], [2, 2]), &device);
        let l: f32 = weighted_bce_sum(x, y, 1.5).into_scalar();
        let e = std::f64::consts::E;
        let want = 1.5 * 2f64.ln() + (1.0 + e * e).ln() + 1.5 * (1.0 + e).ln() + (1.0 + 0.5f64.exp()).ln();
        assert!((l as f64 - want).abs() < 1e-5, "{l} vs {want}");
    }

    #[test]
    fn decoding_thresholds_sigmoid_and_drops_visited() {
        // sigmoid(-0.85) = 0.2994 < 0.3 ≤ sigmoid(-0.84) = 0.3015; sigmoid(0) = 0.5.
        let mut s = vec![-5.0f32; 128];
        s[3] = -0.84;
        s[4] = -0.85;
        s[10] = 0.0;
        s[127] = 3.0;
        assert_eq!(decode(&s, 0.3), vec![3, 10, 127]);
        assert_eq!(decode(&s, 0.5), vec![10, 127]);
        let mut vis = vec![0u8; 128];
        vis[10] = 1;
        assert_eq!(decode_unvisited(&s, &vis, 0.3), vec![3, 127]);
        assert_eq!(set_f1(&[3, 127], &[3, 5]), 0.5);
        assert_eq!(set_f1(&[], &[]), 1.0);
        assert_eq!(set_f1(&[1], &[]), 0.0);
    }

    #[test]
    fn steplr_and_selection() {
        let s = ScvpTrainSettings::default();
        assert_eq!(s.lr_at(1), 1e-4);
        assert_eq!(s.lr_at(20), 1e-4);
        assert_eq!(s.lr_at(21), 5e-5);
        assert_eq!(s.lr_at(41), 2.5e-5);
        let log = |epoch, val_loss, f1| ScvpEpochLog {
            epoch,
            lr: 0.0,
            train_loss: 0.0,
            val_loss,
            val: SetMetrics { f1, ..Default::default() },
            seconds: 0.0,
            samples_per_s: 0.0,
        };
        let h = [log(1, 5.0, 0.2), log(2, 4.0, 0.3), log(3, 3.0, 0.3), log(4, 2.0, 0.25)];
        assert_eq!(select_scvp_epoch(&h, true), 3);
        assert_eq!(select_scvp_epoch(&h, false), 4);
    }

    /// The baseline's k and F1 against brute force over every fixed top-k set.
    #[test]
    fn most_frequent_baseline_by_brute_force() {
        let mut c = ScvpCases { grid: 16, ..Default::default() };
        let rows: [&[usize]; 4] = [&[1, 2], &[2, 5], &[2, 7], &[1, 2, 9]];
        for r in rows {
            let mut cov = vec![0u8; 128];
            for &v in r {
                cov[v] = 1;
            }
            c.cover.extend(cov);
            let mut vis = vec![0u8; 128];
            vis[0] = 1;
            c.visited.extend(vis);
            c.objects.push("o".into());
        }
        let (k, tr, _) = most_frequent_baseline(&c, &c);
        // Ranking 2 (4×), 1 (2×), then 5, 7, 9 (1× each, by id). k = 1: F1 = mean(2/3, 2/3, 2/3,
        // 2/4) = 0.625; k = 2: {1, 2}: mean(1, 1/2, 1/2, 4/5) = 0.7; k = 3: {1, 2, 5}:
        // mean(4/5, 4/5, 2/5, 4/6) = 0.6667.
        assert_eq!(k, 2);
        assert!((tr.f1 - 0.7).abs() < 1e-12, "{}", tr.f1);
        assert_eq!(tr.pred_size, 2.0);
        assert_eq!(tr.label_size, 2.25);
    }
}
