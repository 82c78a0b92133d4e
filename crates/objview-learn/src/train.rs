//! `objview learn train`: the training loop of the learned planners (our own, small): seeded,
//! deterministic (same seed → bit-identical weights, on any number of threads), with a
//! validation split by object, per-epoch checkpoints, resume, progress and a JSON log.
//!
//! Recipe (NBV-Net, the reference's public trainer): cross-entropy on logits, Adam (lr 4e-4,
//! β = (0.9, 0.999), ε = 1e-8, no weight decay), batch 8, gradient-norm clip 5.0; the kept
//! epoch is the one of the lowest validation loss (the reference's shipped `best_val_loss.pt`)
//! or, with `--select val-acc`, of the best validation top-1 accuracy (its trainer's default).
//! `--resume` with every epoch already trained only re-selects.
//!
//! Determinism: the device RNG (initialization, dropout) is seeded with `seed` before the model
//! is built and re-seeded with `(seed, epoch)` at the start of every epoch, and the epoch's
//! case order is a ChaCha8 shuffle seeded with `(seed, epoch)`; so a run resumed from the
//! checkpoint of epoch k continues exactly as the uninterrupted run.
//!
//! Burn's Flex device RNG is process-global: one training at a time per process.
//!
//! Data: the dataset's cases are read into memory at the training grid size (64³ grids
//! average-pooled by 64/G, [`crate::input_grid::pool_grid`]); objects go to validation by a
//! hash of their uid (`fnv1a64(uid) mod 1000 < 1000 · val_fraction`), independent of the seed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::nn::loss::CrossEntropyLossConfig;
use burn::optim::grad_clipping::GradientClippingConfig;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Int, Tensor, TensorData};
use objview_geom::hash::{fnv1a64, splitmix64};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::checkpoint::{trajectory_settings, Checkpoints};
use crate::dataset::{FORMAT, FORMAT_VERSION};
use crate::input_grid::pool_grid;
use crate::nbvnet::NbvNet;
use crate::npz::{Dtype, NpzReader};
use crate::LearnError;

/// Every training setting (recorded in the sidecar).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainSettings {
    /// Network input grid (64 the reference, 32 scaled, 16 for quick tests; the data's 64³
    /// grids are average-pooled to it).
    pub grid: usize,
    /// Epochs.
    pub epochs: usize,
    /// Batch size.
    pub batch: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// Seed of initialization, dropout and case order.
    pub seed: u64,
    /// Gradient-norm clip.
    pub clip: f32,
    /// Fraction of objects held out for validation.
    pub val_fraction: f64,
    /// Use at most this many training cases per epoch (`None`: all), the first after the
    /// epoch's shuffle (for quick runs and tests).
    pub max_cases: Option<usize>,
    /// Which epoch's weights are kept.
    #[serde(default)]
    pub select: Selection,
}

/// How the kept epoch is chosen (both are rules of the reference's trainer: its default
/// selection is the best validation accuracy, its shipped checkpoint the best validation loss).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Selection {
    /// The lowest validation loss (the reference's shipped `best_val_loss.pt`).
    #[default]
    #[serde(rename = "val-loss")]
    ValLoss,
    /// The highest validation top-1 accuracy (ties: lower loss, then the earlier epoch).
    #[serde(rename = "val-acc")]
    ValAcc,
}

impl std::str::FromStr for Selection {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "val-loss" => Ok(Selection::ValLoss),
            "val-acc" => Ok(Selection::ValAcc),
            o => Err(format!("unknown selection '{o}' (expected val-loss or val-acc)")),
        }
    }
}

/// The kept epoch (1-based) of `history` under `select`; the last epoch when there is no
/// validation set.
pub fn select_epoch(history: &[EpochLog], select: Selection, has_validation: bool) -> usize {
    if !has_validation || history.is_empty() {
        return history.len();
    }
    let mut best = &history[0];
    for h in &history[1..] {
        let better = match select {
            Selection::ValLoss => h.val_loss < best.val_loss,
            Selection::ValAcc => {
                h.val_acc > best.val_acc || (h.val_acc == best.val_acc && h.val_loss < best.val_loss)
            }
        };
        if better {
            best = h;
        }
    }
    best.epoch
}

impl Default for TrainSettings {
    fn default() -> Self {
        TrainSettings {
            grid: 32,
            epochs: 10,
            batch: 8,
            lr: 4e-4,
            seed: 42,
            clip: 5.0,
            val_fraction: 0.1,
            max_cases: None,
            select: Selection::ValLoss,
        }
    }
}

impl TrainSettings {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |m: String| Err(LearnError::Invalid(m));
        if ![16, 32, 64].contains(&self.grid) {
            return bad(format!("--grid must be 32 or 64 (16 for quick tests), got {}", self.grid));
        }
        if self.epochs == 0 || self.batch == 0 {
            return bad("--epochs and --batch must be at least 1".into());
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(format!("--lr must be a positive number, got {}", self.lr));
        }
        if !(0.0..1.0).contains(&self.val_fraction) {
            return bad(format!("--val-fraction must be in [0, 1), got {}", self.val_fraction));
        }
        Ok(())
    }
}

/// Cases in memory: grids at the training size and labels.
#[derive(Debug, Clone, Default)]
pub struct Cases {
    /// Grid cells per axis.
    pub grid: usize,
    /// `len · grid³` probabilities.
    pub grids: Vec<f32>,
    /// Oracle labels.
    pub labels: Vec<i64>,
    /// Object uid of each case.
    pub objects: Vec<String>,
}

impl Cases {
    /// Number of cases.
    pub fn len(&self) -> usize {
        self.labels.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }
    fn cells(&self) -> usize {
        self.grid.pow(3)
    }
    fn push_from(&mut self, other: &Cases, i: usize) {
        let c = other.cells();
        self.grids.extend_from_slice(&other.grids[i * c..(i + 1) * c]);
        self.labels.push(other.labels[i]);
        self.objects.push(other.objects[i].clone());
    }
}

/// Whether object `uid` is in the validation part.
pub fn is_validation(uid: &str, fraction: f64) -> bool {
    (fnv1a64(uid.as_bytes()) % 1000) < (fraction * 1000.0).round() as u64
}

/// The dataset's manifest, checked.
pub fn read_manifest(dir: &Path) -> Result<Value, LearnError> {
    let path = dir.join("manifest.json");
    let text = std::fs::read_to_string(&path).map_err(|e| LearnError::io(&path, e))?;
    let m: Value =
        serde_json::from_str(&text).map_err(|e| LearnError::io(&path, format!("not JSON: {e}")))?;
    if m["format"] != FORMAT || m["format_version"] != FORMAT_VERSION {
        return Err(LearnError::io(&path, format!("not an {FORMAT} manifest of version {FORMAT_VERSION}")));
    }
    Ok(m)
}

/// Reads every case of the dataset in `dir` at grid size `grid`.
pub fn load_cases(dir: &Path, grid: usize) -> Result<Cases, LearnError> {
    let m = read_manifest(dir)?;
    let data_grid = m["grid"].as_u64().unwrap_or(0) as usize;
    if data_grid == 0 || !data_grid.is_multiple_of(grid) {
        return Err(LearnError::Invalid(format!(
            "{}: the data's grid {data_grid} cannot be pooled to {grid}",
            dir.join("manifest.json").display()
        )));
    }
    let files: Vec<String> = m["files"]
        .as_array()
        .map(|a| a.iter().filter_map(|f| f.as_str().map(String::from)).collect())
        .unwrap_or_default();
    let parts: Vec<Result<Cases, LearnError>> = files
        .par_iter()
        .map(|f| {
            let path = crate::dataset::resolve_data_file(dir, f)?;
            let mut r = NpzReader::open(&path)?;
            let g = r.array("grid", Some(Dtype::F32))?;
            let labels = r.array("label", Some(Dtype::I64))?.ints();
            let n = labels.len();
            if g.shape != [n, data_grid, data_grid, data_grid] {
                return Err(LearnError::Invalid(format!(
                    "{}: array 'grid' has shape {:?}",
                    path.display(),
                    g.shape
                )));
            }
            if let Some(bad) = labels.iter().find(|&&l| !(0..128).contains(&l)) {
                return Err(LearnError::Invalid(format!(
                    "{}: array 'label' holds {bad}, not a view id",
                    path.display()
                )));
            }
            let vals = g.f32s();
            let c = data_grid.pow(3);
            let mut grids = Vec::with_capacity(n * grid.pow(3));
            for i in 0..n {
                grids.extend(pool_grid(&vals[i * c..(i + 1) * c], data_grid, data_grid / grid));
            }
            let uid = Path::new(f).file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
            Ok(Cases { grid, grids, labels, objects: vec![uid; n] })
        })
        .collect();
    let mut all = Cases { grid, ..Cases::default() };
    for p in parts {
        let p = p?;
        all.grids.extend(p.grids);
        all.labels.extend(p.labels);
        all.objects.extend(p.objects);
    }
    Ok(all)
}

/// Splits cases into (train, validation) by object.
pub fn split(cases: &Cases, val_fraction: f64) -> (Cases, Cases) {
    let mut train = Cases { grid: cases.grid, ..Cases::default() };
    let mut val = Cases { grid: cases.grid, ..Cases::default() };
    for i in 0..cases.len() {
        if is_validation(&cases.objects[i], val_fraction) {
            val.push_from(cases, i);
        } else {
            train.push_from(cases, i);
        }
    }
    (train, val)
}

/// One epoch's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochLog {
    /// 1-based epoch.
    pub epoch: usize,
    /// Mean training loss.
    pub train_loss: f64,
    /// Training top-1 accuracy (during the epoch).
    pub train_acc: f64,
    /// Validation loss (NaN-free; 0 without validation cases).
    pub val_loss: f64,
    /// Validation top-1 agreement with the oracle label.
    pub val_acc: f64,
    /// Seconds of the epoch.
    pub seconds: f64,
    /// Training samples per second.
    pub samples_per_s: f64,
}

/// What a progress display is told.
pub trait TrainProgress: Sync {
    /// A batch finished (`done` of `total` in this epoch).
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64);
    /// An epoch finished.
    fn epoch(&self, log: &EpochLog);
}

/// No progress output.
pub struct Quiet;
impl TrainProgress for Quiet {
    fn batch(&self, _: usize, _: usize, _: usize, _: f64) {}
    fn epoch(&self, _: &EpochLog) {}
}

/// A seed derived from `seed` and `k` (SplitMix64 of both).
pub(crate) fn mix(seed: u64, k: u64) -> u64 {
    splitmix64(seed ^ splitmix64(k.wrapping_add(0x9e37_79b9)))
}

fn batch_tensors(cases: &Cases, idx: &[usize], device: &Device) -> (Tensor<5>, Tensor<1, Int>) {
    let c = cases.cells();
    let g = cases.grid;
    let mut x = Vec::with_capacity(idx.len() * c);
    let mut y = Vec::with_capacity(idx.len());
    for &i in idx {
        x.extend_from_slice(&cases.grids[i * c..(i + 1) * c]);
        y.push(cases.labels[i]);
    }
    let x = Tensor::<5>::from_data(TensorData::new(x, [idx.len(), 1, g, g, g]), device);
    let y = Tensor::<1, Int>::from_data(TensorData::new(y, [idx.len()]), device);
    (x, y)
}

/// Top-1 predictions (lowest index among equal maxima) of `net` for `cases[idx]`.
pub fn predict(net: &NbvNet, cases: &Cases, idx: &[usize], device: &Device) -> Vec<usize> {
    let (x, _) = batch_tensors(cases, idx, device);
    argmax_rows(net.forward(x))
}

/// The index of the largest score, ties to the lowest index (0 for an empty slice).
pub fn argmax(scores: &[f32]) -> usize {
    let mut best = 0;
    for (j, &x) in scores.iter().enumerate() {
        if x > scores[best] {
            best = j;
        }
    }
    best
}

/// Row-wise [`argmax`] of logits [B, C].
pub fn argmax_rows(logits: Tensor<2>) -> Vec<usize> {
    let [_, c] = logits.dims();
    let v: Vec<f32> = logits.into_data().try_to_vec::<f32>().expect("f32 logits");
    v.chunks(c.max(1)).map(argmax).collect()
}

/// Mean loss and top-1 agreement of `net` (a non-autodiff model) over `cases`.
pub fn evaluate(net: &NbvNet, cases: &Cases, batch: usize, device: &Device) -> (f64, f64) {
    if cases.is_empty() {
        return (0.0, 0.0);
    }
    let ce = CrossEntropyLossConfig::new().init(device);
    let (mut loss, mut correct) = (0.0f64, 0usize);
    let idx: Vec<usize> = (0..cases.len()).collect();
    for chunk in idx.chunks(batch.max(1)) {
        let (x, y) = batch_tensors(cases, chunk, device);
        let logits = net.forward(x);
        let l: f32 = ce.forward(logits.clone(), y).into_scalar();
        loss += l as f64 * chunk.len() as f64;
        correct +=
            argmax_rows(logits).iter().zip(chunk).filter(|(p, &i)| **p as i64 == cases.labels[i]).count();
    }
    (loss / cases.len() as f64, correct as f64 / cases.len() as f64)
}

/// The result of a training run.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// Per-epoch figures.
    pub history: Vec<EpochLog>,
    /// The epoch whose weights were kept ([`select_epoch`]).
    pub best_epoch: usize,
    /// Training and validation case counts.
    pub cases: (usize, usize),
    /// Validation objects.
    pub val_objects: Vec<String>,
    /// Parameters of the network.
    pub params: usize,
}

/// Paths of a training run's files next to `out` (`W.safetensors`): the sidecar `W.json` and
/// the checkpoint folder `W.checkpoints/`.
pub fn sidecar_path(out: &Path) -> PathBuf {
    out.with_extension("json")
}

/// The checkpoint folder of a run writing `out` (see [`crate::checkpoint`]).
pub use crate::checkpoint::checkpoint_dir;

/// Saves `net` as safetensors at `path` (reproducible bytes).
pub fn save_weights(net: &NbvNet, path: &Path) -> Result<(), LearnError> {
    crate::checkpoint::save_safetensors(net, path)
}

/// Loads weights into a fresh G³ network on `device`.
pub fn load_weights(path: &Path, grid: usize, device: &Device) -> Result<NbvNet, LearnError> {
    let bytes = std::fs::read(path).map_err(|e| LearnError::io(path, e))?;
    load_weights_bytes(&bytes, grid, device).map_err(|e| LearnError::io(path, e))
}

/// Loads safetensors bytes into a fresh G³ network on `device`; every tensor must be present.
pub fn load_weights_bytes(bytes: &[u8], grid: usize, device: &Device) -> Result<NbvNet, String> {
    let mut net = NbvNet::new(grid, device);
    crate::checkpoint::load_safetensors(&mut net, bytes, &format!("a {grid}³ NBV-Net"))?;
    Ok(net)
}

/// Trains NBV-Net on the dataset in `data` and writes the best weights to `out`, the sidecar
/// next to it and a checkpoint per epoch. With `resume`, continues from the last checkpoint of
/// the same settings. `threads` is the rayon pool size (the result does not depend on it).
pub fn train(
    data: &Path,
    out: &Path,
    settings: &TrainSettings,
    resume: bool,
    progress: &dyn TrainProgress,
) -> Result<(TrainOutcome, Cases, Cases), LearnError> {
    settings.validate()?;
    let all = load_cases(data, settings.grid)?;
    if all.is_empty() {
        return Err(LearnError::Invalid(format!("{}: the dataset has no cases", data.display())));
    }
    let (train_set, val_set) = split(&all, settings.val_fraction);
    drop(all);
    if train_set.is_empty() {
        return Err(LearnError::Invalid("no training cases left after the validation split".into()));
    }
    let mut val_objects: Vec<String> = val_set.objects.clone();
    val_objects.dedup();

    let base = Device::flex();
    base.seed(settings.seed);
    let device = base.clone().autodiff();
    let mut net = NbvNet::new(settings.grid, &device);
    let params = net.num_params();
    let mut optim: ModuleOptimizer = AdamConfig::new()
        .with_epsilon(1e-8)
        .with_grad_clipping(Some(GradientClippingConfig::Norm(settings.clip)))
        .init();
    let ce = CrossEntropyLossConfig::new().init(&device);

    // The epoch count and the selection rule do not change the trajectory.
    let settings_json = serde_json::to_value(settings).expect("settings serialize");
    let identity = json!({
        "network": "nbv-net",
        "settings": trajectory_settings(&settings_json, &["epochs", "select"]),
        "data": data.display().to_string(),
    });
    let ckpt = Checkpoints::create(out, identity)?;
    let mut history: Vec<EpochLog> = Vec::new();
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
        base.seed(mix(settings.seed, epoch as u64));
        let mut order: Vec<usize> = (0..train_set.len()).collect();
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(settings.seed, 1_000_000 + epoch as u64)));
        if let Some(m) = settings.max_cases {
            order.truncate(m);
        }
        let batches: Vec<&[usize]> = order.chunks(settings.batch).collect();
        let (mut loss_sum, mut correct) = (0.0f64, 0usize);
        for (bi, idx) in batches.iter().enumerate() {
            let (x, y) = batch_tensors(&train_set, idx, &device);
            let logits = net.forward(x);
            let loss = ce.forward(logits.clone(), y);
            let grads = loss.backward();
            let l: f32 = loss.into_scalar();
            loss_sum += l as f64 * idx.len() as f64;
            correct += argmax_rows(logits.inner())
                .iter()
                .zip(idx.iter())
                .filter(|(p, &i)| **p as i64 == train_set.labels[i])
                .count();
            let grads = GradientsParams::from_grads(grads, &net);
            net = optim.step(settings.lr, net, grads);
            progress.batch(epoch, bi + 1, batches.len(), l as f64);
        }
        let seen = order.len();
        let valid = net.valid();
        let (val_loss, val_acc) = evaluate(&valid, &val_set, 32, &base);
        let secs = t.elapsed().as_secs_f64();
        let log = EpochLog {
            epoch,
            train_loss: loss_sum / seen as f64,
            train_acc: correct as f64 / seen as f64,
            val_loss,
            val_acc,
            seconds: secs,
            samples_per_s: seen as f64 / secs,
        };
        progress.epoch(&log);
        history.push(log);
        ckpt.save(epoch, &valid, &net, &optim, &history)?;
    }

    let best_epoch = select_epoch(&history, settings.select, !val_set.is_empty());
    ckpt.keep(best_epoch, out)?;
    Ok((
        TrainOutcome { history, best_epoch, cases: (train_set.len(), val_set.len()), val_objects, params },
        train_set,
        val_set,
    ))
}

/// The deviation from the reference network recorded in every sidecar and result.
pub fn deviation(grid: usize) -> Value {
    if grid == 64 {
        json!("none: the reference shape (64^3 input, 536,776 parameters)")
    } else {
        json!(format!(
            "scaled down to fit a 2-core CPU: {grid}^3 input (the 64^3 grid average-pooled by {}), \
             same layers and channels; the final Linear is {} -> 128 instead of 4096 -> 128",
            64 / grid,
            8 * (grid / 8).pow(3)
        ))
    }
}

/// [`train`], then writes the sidecar JSON next to `out` (the exact command, the data's
/// manifest summary, the settings, every epoch's figures, the kept epoch's metrics, the
/// held-out agreement when `heldout` is given, the deviation, versions, the weights' hash).
pub fn train_and_describe(
    data: &Path,
    out: &Path,
    settings: &TrainSettings,
    resume: bool,
    heldout: Option<&Path>,
    command: &str,
    progress: &dyn TrainProgress,
) -> Result<Value, LearnError> {
    let t = Instant::now();
    let manifest = read_manifest(data)?;
    let (outcome, _, _) = train(data, out, settings, resume, progress)?;
    let best = &outcome.history[outcome.best_epoch - 1];
    let bytes = std::fs::read(out).map_err(|e| LearnError::io(out, e))?;
    let heldout_json = match heldout {
        Some(dir) => {
            let net = load_weights(out, settings.grid, &Device::flex())?;
            let cases = load_cases(dir, settings.grid)?;
            let (loss, acc) = evaluate(&net, &cases, 32, &Device::flex());
            let m = read_manifest(dir)?;
            json!({"data": dir.display().to_string(), "objects": m["objects"], "cases": cases.len(),
                   "loss": loss, "agreement": acc, "dataset_command": m["command"]})
        }
        None => Value::Null,
    };
    let sidecar = json!({
        "network": "nbv-net",
        "weights_format": "safetensors (burn-store), module paths of objview_learn::nbvnet::NbvNet",
        "command": command,
        "data": {
            "dir": data.display().to_string(),
            "method": manifest["method"],
            "objects": manifest["objects"],
            "cases": manifest["cases"],
            "train_cases": outcome.cases.0,
            "val_cases": outcome.cases.1,
            "val_objects": outcome.val_objects.len(),
            "pool": manifest["settings"]["pool"],
            "inputs": manifest["settings"]["inputs"],
            "input": manifest["settings"]["input"],
            "dataset_command": manifest["command"],
            "dataset_version": manifest["version"],
        },
        "settings": settings,
        "recipe": "cross-entropy on logits; Adam lr, betas (0.9, 0.999), eps 1e-8, no weight decay; gradient-norm clip; kept epoch by settings.select",
        "deviation": deviation(settings.grid),
        "params": outcome.params,
        "history": outcome.history,
        "best_epoch": outcome.best_epoch,
        "final": {"train_loss": best.train_loss, "train_acc": best.train_acc, "val_loss": best.val_loss, "val_acc": best.val_acc},
        "heldout": heldout_json,
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

/// Top-1 agreement and loss of weights (`builtin` or a file with its sidecar) on a dataset.
pub fn eval_weights(weights: &str, data: &Path) -> Result<Value, LearnError> {
    let scorer = if weights == "builtin" {
        crate::planner::NetScorer::builtin()
    } else {
        crate::planner::NetScorer::from_file(Path::new(weights))
    }
    .map_err(LearnError::Invalid)?;
    let net = scorer.net();
    let cases = load_cases(data, net.grid())?;
    let (loss, acc) = evaluate(net, &cases, 32, &Device::flex());
    Ok(json!({"weights": weights, "data": data.display().to_string(), "cases": cases.len(),
              "loss": loss, "agreement": acc, "chance": 1.0 / 128.0}))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(epoch: usize, val_loss: f64, val_acc: f64) -> EpochLog {
        EpochLog {
            epoch,
            train_loss: 0.0,
            train_acc: 0.0,
            val_loss,
            val_acc,
            seconds: 0.0,
            samples_per_s: 0.0,
        }
    }

    #[test]
    fn epoch_selection_rules() {
        let h = [log(1, 4.8, 0.02), log(2, 4.7, 0.02), log(3, 4.75, 0.03), log(4, 4.9, 0.03)];
        assert_eq!(select_epoch(&h, Selection::ValLoss, true), 2);
        assert_eq!(select_epoch(&h, Selection::ValAcc, true), 3, "tie on accuracy: lower loss");
        assert_eq!(select_epoch(&h, Selection::ValAcc, false), 4, "no validation: the last");
        assert_eq!("val-acc".parse::<Selection>(), Ok(Selection::ValAcc));
        assert!("best".parse::<Selection>().is_err());
    }

    #[test]
    fn validation_membership_is_by_uid_and_fraction() {
        let uids: Vec<String> = (0..2000).map(|i| format!("obj-{i}")).collect();
        let n = uids.iter().filter(|u| is_validation(u, 0.1)).count();
        assert!((150..250).contains(&n), "{n} of 2000 at 10 %");
        assert_eq!(uids.iter().filter(|u| is_validation(u, 0.0)).count(), 0);
        assert!(uids.iter().filter(|u| is_validation(u, 0.1)).all(|u| is_validation(u, 0.2)), "nested");
    }
}
