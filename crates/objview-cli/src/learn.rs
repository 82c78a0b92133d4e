//! `objview learn`: oracle training data, training, evaluation and benchmarks of the learned
//! planners (the logic lives in `objview_learn`).

use std::path::PathBuf;
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::ProgressBar;
use objview_dataset::Shard;
use objview_geom::normalize::Normalization;
use objview_learn::dataset::{DatasetPlan, DatasetSettings, InputSource, Method};
use objview_learn::mascvp::MascvpShape;
use objview_learn::mascvp_train::{ScvpEpochLog, ScvpProgress, ScvpTrainSettings};
use objview_learn::train::{EpochLog, TrainProgress, TrainSettings};

use crate::common::{progress, TermProgress};

#[derive(Subcommand)]
pub enum Command {
    /// Oracle training data of a pool: per object the tammes-128 visible voxel sets, greedy
    /// oracle rollouts from every start view, the method's case sampling and each case's 64³
    /// input grid, as cases/<uid>.npz + manifest.json (resumable, shardable).
    Dataset(DatasetArgs),
    /// Train a learned planner's network on a dataset; writes the weights (.safetensors), a
    /// sidecar JSON (command, data, settings, metrics, version) and per-epoch checkpoints.
    Train(TrainArgs),
    /// Top-1 agreement of weights with the oracle labels of a dataset.
    Eval(EvalArgs),
    /// Benchmarks: dataset generation per object, training throughput, inference per step.
    Bench(BenchArgs),
}

#[derive(Parser)]
pub struct DatasetArgs {
    /// Pool folders, split files (.json) or meshes.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// The learned method the cases are for: `nbv-net` (whole rollouts, oracle NBV labels) or
    /// `ma-scvp` (long-tail cases with exact residual set covers).
    #[arg(long)]
    pub method: Method,
    /// The dataset folder (resumed when it holds an objects file).
    #[arg(long)]
    pub out: PathBuf,
    /// Case grids from rendered `depth` frames (as planners see them) or from the visible
    /// `voxel-centres` of each view (the reference's training variant).
    #[arg(long, default_value = "depth")]
    pub input: InputSource,
    /// Seed of the case sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The long-tail protocol's need_case_1.
    #[arg(long, default_value_t = objview_learn::sampling::NEED_CASE_1)]
    pub need_case_1: usize,
    /// Residual-cover time limit per case, seconds (ma-scvp).
    #[arg(long, default_value_t = 10.0)]
    pub time_limit: f64,
    /// `unit` or `none` (already normalized).
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Folder of ground-truth clouds `<uid>.{pcd,ply,npy,npz}`.
    #[arg(long)]
    pub gt_cloud_dir: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Only the I-th of N parts (0 <= I < N), by a hash of the uid; shards write their own
    /// objects file into the same folder and the manifest covers every finished shard.
    #[arg(long)]
    pub shard: Option<Shard>,
    /// Redo objects whose earlier line is a failure.
    #[arg(long)]
    pub retry_failed: bool,
}

#[derive(Parser)]
pub struct TrainArgs {
    /// The network: `nbv-net` or `ma-scvp`.
    pub network: String,
    /// The dataset folder of `objview learn dataset`.
    #[arg(long)]
    pub data: PathBuf,
    /// The weights file to write (.safetensors); the sidecar is the same path with .json.
    #[arg(long)]
    pub out: PathBuf,
    /// Epochs.
    #[arg(long, default_value_t = 10)]
    pub epochs: usize,
    /// Batch size.
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Adam learning rate (default: 4e-4 for nbv-net, 1e-4 for ma-scvp).
    #[arg(long)]
    pub lr: Option<f64>,
    /// Seed of initialization, dropout and case order.
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Network grid: 64 (the reference shape) or 32 (the data pooled by 2; fits this machine).
    #[arg(long, default_value_t = 32)]
    pub grid: usize,
    /// ma-scvp: conv1 and the three blocks' widths (reference: 32,64,128,256; default quarter).
    #[arg(long, value_delimiter = ',', default_value = "8,16,32,64")]
    pub widths: Vec<usize>,
    /// ma-scvp: the head's hidden FC widths (the reference's by default).
    #[arg(long, value_delimiter = ',', default_value = "512,256,128,128")]
    pub fc: Vec<usize>,
    /// ma-scvp: decoding threshold of the validation F1 that selects the kept epoch.
    #[arg(long, default_value_t = 0.3)]
    pub gamma: f64,
    /// ma-scvp: BCE weight of positive entries.
    #[arg(long, default_value_t = 1.5)]
    pub pos_weight: f64,
    /// ma-scvp: StepLR step (epochs).
    #[arg(long, default_value_t = 20)]
    pub lr_step: usize,
    /// ma-scvp: StepLR factor.
    #[arg(long, default_value_t = 0.5)]
    pub lr_factor: f64,
    /// Fraction of objects held out for validation (by a hash of the uid).
    #[arg(long, default_value_t = 0.1)]
    pub val_fraction: f64,
    /// At most this many training cases per epoch (the first after the epoch's shuffle).
    #[arg(long)]
    pub max_cases: Option<usize>,
    /// Worker threads (default: all cores); the weights do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// nbv-net: which epoch's weights to keep: `val-loss` (lowest validation loss, the
    /// reference's shipped checkpoint) or `val-acc` (best validation top-1, its trainer's
    /// default). ma-scvp always keeps the best validation F1 at --gamma.
    #[arg(long, default_value = "val-loss")]
    pub select: objview_learn::train::Selection,
    /// Continue from the last checkpoint of the same settings and data (with every epoch done,
    /// only re-select).
    #[arg(long)]
    pub resume: bool,
    /// nbv-net: a second dataset (other objects) to report top-1 agreement on in the sidecar.
    #[arg(long)]
    pub heldout: Option<PathBuf>,
}

#[derive(Parser)]
pub struct EvalArgs {
    /// Weights (.safetensors with its sidecar .json), or `builtin`.
    pub weights: String,
    /// The dataset folder.
    #[arg(long)]
    pub data: PathBuf,
}

pub fn run(c: Command) -> Result<()> {
    match c {
        Command::Dataset(a) => dataset(a),
        Command::Train(a) => train(a),
        Command::Eval(a) => eval(a),
        Command::Bench(a) => bench(a),
    }
}

/// The command line as recorded in manifests and sidecars: `objview` and the arguments (the
/// binary's own path says nothing about the run).
fn command_line() -> String {
    std::iter::once("objview".to_string())
        .chain(std::env::args().skip(1).map(|a| if a.contains(' ') { format!("'{a}'") } else { a }))
        .collect::<Vec<_>>()
        .join(" ")
}

fn dataset(a: DatasetArgs) -> Result<()> {
    let mut settings = DatasetSettings {
        method: a.method,
        input: a.input,
        seed: a.seed,
        need_case_1: a.need_case_1,
        ..Default::default()
    };
    settings.annotate.normalize = a.normalize;
    settings.annotate.gt_cloud_dir = a.gt_cloud_dir;
    settings.annotate.cover.time_limit_s = a.time_limit;
    let plan = DatasetPlan {
        inputs: a.inputs,
        out: a.out.clone(),
        settings,
        threads: a.threads,
        shard: a.shard.unwrap_or(Shard::ALL),
        retry_failed: a.retry_failed,
        command: command_line(),
    };
    let (s, manifest) = plan.run(&TermProgress::new(false))?;
    println!(
        "learn dataset: {} done, {} failed, {} skipped; the folder now holds {} objects, {} cases -> {}",
        s.processed - s.failed,
        s.failed,
        s.skipped,
        manifest["objects"],
        manifest["cases"],
        a.out.join("manifest.json").display()
    );
    Ok(())
}

struct BarProgress {
    bar: Mutex<Option<(usize, ProgressBar)>>,
}

impl TrainProgress for BarProgress {
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64) {
        let mut g = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if g.as_ref().is_none_or(|(e, _)| *e != epoch) {
            let b = progress(total as u64);
            *g = Some((epoch, b));
        }
        if let Some((_, b)) = g.as_ref() {
            b.set_position(done as u64);
            if done % 16 == 0 || done == total {
                b.set_message(format!("epoch {epoch} loss {loss:.3}"));
            }
        }
    }
    fn epoch(&self, l: &EpochLog) {
        if let Some((_, b)) = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
            b.finish_and_clear();
        }
        eprintln!(
            "epoch {}: train loss {:.4} acc {:.3} | val loss {:.4} acc {:.3} | {:.0} s, {:.1} samples/s",
            l.epoch, l.train_loss, l.train_acc, l.val_loss, l.val_acc, l.seconds, l.samples_per_s
        );
    }
}

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(t) = threads {
        if t == 0 {
            bail!("--threads must be at least 1");
        }
        b = b.num_threads(t);
    }
    b.build().context("thread pool")
}

fn train(a: TrainArgs) -> Result<()> {
    match a.network.as_str() {
        "nbv-net" => {}
        "ma-scvp" => return train_mascvp(a),
        o => bail!("unknown network '{o}' (this version trains: nbv-net, ma-scvp)"),
    }
    let settings = TrainSettings {
        grid: a.grid,
        epochs: a.epochs,
        batch: a.batch,
        lr: a.lr.unwrap_or(4e-4),
        seed: a.seed,
        val_fraction: a.val_fraction,
        max_cases: a.max_cases,
        select: a.select,
        ..Default::default()
    };
    let command = command_line();
    let progress = BarProgress { bar: Mutex::new(None) };
    let sidecar = pool(a.threads)?.install(|| {
        objview_learn::train::train_and_describe(
            &a.data,
            &a.out,
            &settings,
            a.resume,
            a.heldout.as_deref(),
            &command,
            &progress,
        )
    })?;
    println!(
        "learn train: best epoch {} (val loss {:.4}, val top-1 {:.3}) -> {} (+ {})",
        sidecar["best_epoch"],
        sidecar["final"]["val_loss"].as_f64().unwrap_or(f64::NAN),
        sidecar["final"]["val_acc"].as_f64().unwrap_or(f64::NAN),
        a.out.display(),
        objview_learn::train::sidecar_path(&a.out).display()
    );
    Ok(())
}

impl ScvpProgress for BarProgress {
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64) {
        TrainProgress::batch(self, epoch, done, total, loss);
    }
    fn epoch(&self, l: &ScvpEpochLog) {
        if let Some((_, b)) = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
            b.finish_and_clear();
        }
        eprintln!(
            "epoch {} (lr {:.2e}): train loss {:.3} | val loss {:.3} F1 {:.3} (P {:.3} R {:.3}, |pred| {:.1} vs |label| {:.1}) | {:.0} s, {:.2} samples/s",
            l.epoch, l.lr, l.train_loss, l.val_loss, l.val.f1, l.val.precision, l.val.recall, l.val.pred_size,
            l.val.label_size, l.seconds, l.samples_per_s
        );
    }
}

fn train_mascvp(a: TrainArgs) -> Result<()> {
    if a.heldout.is_some() {
        bail!("--heldout is an nbv-net option (ma-scvp reports validation F1 and a baseline)");
    }
    let [conv1, b1, b2, b3] = a.widths[..] else {
        bail!("--widths needs four numbers (conv1 and the three blocks), got {:?}", a.widths);
    };
    let shape = MascvpShape { grid: a.grid, conv1, blocks: [b1, b2, b3], fc: a.fc.clone(), dropout: 0.35 };
    let settings = ScvpTrainSettings {
        shape,
        epochs: a.epochs,
        batch: a.batch,
        lr: a.lr.unwrap_or(1e-4),
        lr_step: a.lr_step,
        lr_factor: a.lr_factor,
        pos_weight: a.pos_weight,
        gamma: a.gamma,
        seed: a.seed,
        val_fraction: a.val_fraction,
        max_cases: a.max_cases,
    };
    let command = command_line();
    let progress = BarProgress { bar: Mutex::new(None) };
    let sidecar = pool(a.threads)?.install(|| {
        objview_learn::mascvp_train::train_scvp_and_describe(
            &a.data, &a.out, &settings, a.resume, &command, &progress,
        )
    })?;
    println!(
        "learn train ma-scvp: best epoch {} (val F1 {:.3} at gamma {}; most-frequent baseline {:.3}) -> {} (+ {})",
        sidecar["best_epoch"],
        sidecar["final"]["val"]["f1"].as_f64().unwrap_or(f64::NAN),
        a.gamma,
        sidecar["baseline"]["val"]["f1"].as_f64().unwrap_or(f64::NAN),
        a.out.display(),
        objview_learn::train::sidecar_path(&a.out).display()
    );
    Ok(())
}

fn eval(a: EvalArgs) -> Result<()> {
    let r = objview_learn::train::eval_weights(&a.weights, &a.data)?;
    println!("{}", serde_json::to_string_pretty(&r)?);
    Ok(())
}

#[derive(Parser)]
pub struct BenchArgs {
    /// Built-in object to measure.
    #[arg(long, default_value = "mug")]
    pub object: String,
    /// Its triangle count.
    #[arg(long, default_value_t = 100_000)]
    pub triangles: usize,
    /// Dataset generations of the object (on one thread).
    #[arg(long, default_value_t = 1)]
    pub repeats: usize,
    /// Timed training batches per (grid, threads) setting.
    #[arg(long, default_value_t = 6)]
    pub batches: usize,
    /// Timed planner steps per grid.
    #[arg(long, default_value_t = 20)]
    pub steps: usize,
    /// Skip the dataset-generation measurement.
    #[arg(long)]
    pub skip_dataset: bool,
}

fn ms(s: &objview_runs::bench::Spread) -> String {
    format!("median {:.1} ms (p90 {:.1}, max {:.1})", s.median * 1e3, s.p90 * 1e3, s.max * 1e3)
}

fn bench(a: BenchArgs) -> Result<()> {
    use objview_learn::bench::*;
    println!("learn bench: {} at ~{} triangles", a.object, a.triangles);
    if !a.skip_dataset {
        let settings = DatasetSettings::default();
        let recs =
            pool(Some(1))?.install(|| dataset_per_object(&a.object, a.triangles, &settings, a.repeats))?;
        let mut secs: Vec<f64> = recs.iter().map(|r| r.seconds).collect();
        secs.sort_by(f64::total_cmp);
        let r = &recs[0];
        println!(
            "dataset (nbv-net, depth grids, 1 thread): median {:.2} s per object, {} cases; stages of run 1: {}",
            secs[secs.len() / 2],
            r.cases,
            r.timings.iter().map(|(k, v)| format!("{k} {v:.2} s")).collect::<Vec<_>>().join(", ")
        );
    }
    for grid in [32usize, 64] {
        let mut line = format!("training {grid}^3, batch 8:");
        let mut one = 0.0;
        for threads in [1usize, 2] {
            let s = pool(Some(threads))?.install(|| training_throughput(grid, 8, a.batches));
            if threads == 1 {
                one = s.median;
            }
            line +=
                &format!(" {threads} thread(s) median {:.1} samples/s (x{:.2});", s.median, s.median / one);
        }
        println!("{line}");
    }
    for grid in [32usize, 64] {
        let [g, n, t] =
            pool(Some(1))?.install(|| inference_per_step(&a.object, a.triangles, grid, a.steps))?;
        println!(
            "planner step {grid}^3, 1 thread: total {} = grid update {} + network {}",
            ms(&t),
            ms(&g),
            ms(&n)
        );
    }
    Ok(())
}
