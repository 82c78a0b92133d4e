//! `objview learn`: oracle training data, training, evaluation and benchmarks of the learned
//! planners (the logic lives in `objview_learn`).

use std::path::PathBuf;
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::ProgressBar;
use objview_dataset::Shard;
use objview_geom::normalize::Normalization;
use objview_learn::completion_net::CompletionShape;
use objview_learn::completion_train::{CompletionEpochLog, CompletionProgress, CompletionTrainSettings};
use objview_learn::dataset::{DatasetPlan, DatasetSettings, InputSource, Method};
use objview_learn::mascvp::MascvpShape;
use objview_learn::mascvp_train::{ScvpEpochLog, ScvpProgress, ScvpTrainSettings};
use objview_learn::train::{EpochLog, TrainProgress, TrainSettings};

use crate::common::{progress, TermProgress};

#[derive(Subcommand)]
pub enum Command {
    /// Training data of a pool, as `cases/<uid>.npz` + `manifest.json` (resumable, shardable):
    /// for nbv-net and ma-scvp per object the tammes-128 visible voxel sets, greedy oracle
    /// rollouts from every start view, the method's case sampling and each case's 64³ input
    /// grid; for completion per object partial clouds fused from 1-3 rendered tammes-128 views
    /// (resampled to 2048 points, normalized) and the ground-truth cloud.
    Dataset(DatasetArgs),
    /// Train a learned planner's network on a dataset; writes the weights (.safetensors), a
    /// sidecar JSON (command, data, settings, metrics, version) and per-epoch checkpoints.
    Train(TrainArgs),
    /// Weights on a dataset: top-1 agreement with the oracle labels (nbv-net data), or the
    /// Chamfer-L1 of net and identity (completion data).
    Eval(EvalArgs),
    /// Benchmarks: dataset generation per object, training throughput, inference per step.
    Bench(BenchArgs),
    /// Experiments of the paper with learned planners.
    #[command(subcommand)]
    Experiment(ExperimentCommand),
}

#[derive(Subcommand)]
pub enum ExperimentCommand {
    /// The difficulty-aware training experiment (paper Figure 4): MA-SCVP trained on
    /// Main-Raw-Train and on Main-Balanced-Train (same size, recipe and seed), VC at gamma 0.5
    /// over the 128 start views of a held-out Main-Analysis-Test, per d_plan bucket; writes
    /// splits/, data/, models/, vc.jsonl, summary.json and the figure (PNG + SVG). Resumable.
    DifficultyAware(ExperimentArgs),
}

#[derive(Parser)]
pub struct ExperimentArgs {
    /// Results files of `objview annotate` of the pool (JSON Lines).
    #[arg(required = true)]
    pub annotations: Vec<PathBuf>,
    /// Output folder (resumed when it holds an experiment of the same settings).
    #[arg(long)]
    pub out: PathBuf,
    /// Objects in each training subset (Main-Raw-Train and Main-Balanced-Train).
    #[arg(long, default_value_t = 16)]
    pub size: usize,
    /// Objects of Main-Analysis-Test (Main-Train-Public objects in neither subset).
    #[arg(long, default_value_t = 16)]
    pub analysis: usize,
    /// Seed of the pool split and the analysis draw.
    #[arg(long, default_value_t = objview_pool::split::DEFAULT_SPLIT_SEED)]
    pub split_seed: u64,
    /// Main-Hidden-Test fraction of the pool split (default 528/5523).
    #[arg(long, default_value_t = objview_pool::split::DEFAULT_TEST_FRACTION)]
    pub test_fraction: f64,
    /// Decoding threshold of the VC metric (the reference's 0.5).
    #[arg(long, default_value_t = 0.5)]
    pub gamma: f64,
    /// Training epochs of each model.
    #[arg(long, default_value_t = 3)]
    pub epochs: usize,
    /// Seed of both trainings (initialization, dropout, case order).
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Network grid (the data is pooled to it).
    #[arg(long, default_value_t = 32)]
    pub grid: usize,
    /// Grid of the training data and of the analysis inputs (a multiple of --grid).
    #[arg(long, default_value_t = 64)]
    pub data_grid: usize,
    /// conv1 and the three blocks' widths (reference: 32,64,128,256; default quarter).
    #[arg(long, value_delimiter = ',', default_value = "8,16,32,64")]
    pub widths: Vec<usize>,
    /// The head's hidden FC widths.
    #[arg(long, value_delimiter = ',', default_value = "512,256,128,128")]
    pub fc: Vec<usize>,
    /// Decoding threshold of the validation F1 that selects each model's kept epoch.
    #[arg(long, default_value_t = 0.3)]
    pub train_gamma: f64,
    /// Fraction of each subset's objects held out for validation (by a hash of the uid).
    #[arg(long, default_value_t = 0.1)]
    pub val_fraction: f64,
    /// At most this many training cases per epoch.
    #[arg(long)]
    pub max_cases: Option<usize>,
    /// The long-tail protocol's need_case_1 of the training data.
    #[arg(long, default_value_t = objview_learn::sampling::NEED_CASE_1)]
    pub need_case_1: usize,
    /// Residual-cover time limit, seconds (training labels and the analysis' ground-truth totals).
    #[arg(long, default_value_t = 10.0)]
    pub time_limit: f64,
    /// Seed of the case sampling.
    #[arg(long, default_value_t = 0)]
    pub data_seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

#[derive(Parser)]
pub struct DatasetArgs {
    /// Pool folders, split files (.json) or meshes.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// The learned method the cases are for: `nbv-net` (whole rollouts, oracle NBV labels),
    /// `ma-scvp` (long-tail cases with exact residual set covers) or `completion` (partial clouds
    /// and ground-truth clouds for the hybrids' completion network).
    #[arg(long)]
    pub method: Method,
    /// completion: partial clouds per object.
    #[arg(long, default_value_t = 8)]
    pub partials: usize,
    /// completion: the most views fused into one partial cloud (the count is uniform in
    /// 1..=max-views).
    #[arg(long, default_value_t = 3)]
    pub max_views: usize,
    /// completion: ground-truth points per object (resampled from the ground-truth cloud).
    #[arg(long, default_value_t = 8192)]
    pub gt_points: usize,
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
    /// The network: `nbv-net`, `ma-scvp` or `completion`.
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
    /// Adam learning rate (default: 4e-4 for nbv-net, 1e-4 for ma-scvp, 1e-3 for completion).
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
    /// ma-scvp, completion: StepLR step (epochs).
    #[arg(long, default_value_t = 20)]
    pub lr_step: usize,
    /// ma-scvp, completion: StepLR factor.
    #[arg(long, default_value_t = 0.5)]
    pub lr_factor: f64,
    /// completion: encoder widths e1,e2,e3,G (stage 1 3->e1->e2, stage 2 2*e2->e3->G; default
    /// 64,128,256,512).
    #[arg(long, value_delimiter = ',')]
    pub encoder: Option<Vec<usize>>,
    /// completion: hidden widths of the coarse decoder (default 512,512).
    #[arg(long, value_delimiter = ',')]
    pub coarse_fc: Option<Vec<usize>>,
    /// completion: hidden width of the folding MLP (default 64).
    #[arg(long)]
    pub fold_width: Option<usize>,
    /// completion: ground-truth points per case in the loss (a fresh seeded subset each epoch).
    #[arg(long, default_value_t = 2048)]
    pub loss_gt_points: usize,
    /// completion: weight of the coarse output's Chamfer-L1 in the loss.
    #[arg(long, default_value_t = 1.0)]
    pub coarse_weight: f64,
    /// completion: weight of the fine output's Chamfer-L1 in the loss.
    #[arg(long, default_value_t = 1.0)]
    pub fine_weight: f64,
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
    /// nbv-net, completion: a second dataset (other objects) to report top-1 agreement
    /// (nbv-net) or the Chamfer-L1 of net and identity (completion) on in the sidecar.
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
        Command::Experiment(ExperimentCommand::DifficultyAware(a)) => difficulty_aware(a),
    }
}

struct StageLog;
impl objview_learn::experiment::ExperimentLog for StageLog {
    fn stage(&self, line: &str) {
        eprintln!("learn experiment: {line}");
    }
}

fn difficulty_aware(a: ExperimentArgs) -> Result<()> {
    let [conv1, b1, b2, b3] = a.widths[..] else {
        bail!("--widths needs four numbers (conv1 and the three blocks), got {:?}", a.widths);
    };
    let shape = MascvpShape { grid: a.grid, conv1, blocks: [b1, b2, b3], fc: a.fc.clone(), dropout: 0.35 };
    let mut dataset = DatasetSettings {
        method: Method::MaScvp,
        grid: a.data_grid,
        need_case_1: a.need_case_1,
        seed: a.data_seed,
        ..Default::default()
    };
    dataset.annotate.cover.time_limit_s = a.time_limit;
    let settings = objview_learn::experiment::ExperimentSettings {
        size: a.size,
        analysis: a.analysis,
        split: objview_pool::split::SplitSettings {
            seed: a.split_seed,
            test_fraction: a.test_fraction,
            train_size: None,
        },
        dataset,
        train: ScvpTrainSettings {
            shape,
            epochs: a.epochs,
            gamma: a.train_gamma,
            seed: a.seed,
            val_fraction: a.val_fraction,
            max_cases: a.max_cases,
            ..Default::default()
        },
        gamma: a.gamma,
    };
    let command = command_line();
    let progress = BarProgress { bar: Mutex::new(None) };
    let summary = pool(a.threads)?.install(|| {
        objview_learn::experiment::run_experiment(
            &a.annotations,
            &a.out,
            &settings,
            a.threads,
            &command,
            &objview_learn::experiment::Reporters {
                batch: &TermProgress::new(false),
                train: &progress,
                log: &StageLog,
            },
        )
    })?;
    let files = objview_report::figure4::write(&summary, &a.out)?;
    print!("{}", objview_report::figure4::markdown(&summary));
    println!(
        "learn experiment difficulty-aware: {} and {} files in {}",
        objview_learn::experiment::SUMMARY_FILE,
        files.len(),
        a.out.display()
    );
    Ok(())
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
    settings.completion = objview_learn::completion_data::CompletionDataSettings {
        partials: a.partials,
        max_views: a.max_views,
        gt_points: a.gt_points,
    };
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
        "completion" => return train_completion(a),
        o => bail!("unknown network '{o}' (this version trains: nbv-net, ma-scvp, completion)"),
    }
    if a.encoder.is_some() || a.coarse_fc.is_some() || a.fold_width.is_some() {
        bail!("--encoder, --coarse-fc and --fold-width are completion options");
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

impl CompletionProgress for BarProgress {
    fn batch(&self, epoch: usize, done: usize, total: usize, loss: f64) {
        TrainProgress::batch(self, epoch, done, total, loss);
    }
    fn epoch(&self, l: &CompletionEpochLog) {
        if let Some((_, b)) = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
            b.finish_and_clear();
        }
        let val = if l.val.cases == 0 {
            "no validation objects".to_string()
        } else {
            format!(
                "val Chamfer-L1 net {:.4} (fine {:.4}) vs identity {:.4}, {} cases",
                l.val.net.l1, l.val.net_fine.l1, l.val.identity.l1, l.val.cases
            )
        };
        eprintln!(
            "epoch {} (lr {:.2e}): train loss {:.4} | {val} | {:.0} s, {:.2} samples/s",
            l.epoch, l.lr, l.train_loss, l.seconds, l.samples_per_s
        );
    }
}

fn train_completion(a: TrainArgs) -> Result<()> {
    let mut shape = CompletionShape::small();
    if let Some(e) = &a.encoder {
        let [e1, e2, e3, g] = e[..] else {
            bail!("--encoder needs four numbers (e1,e2,e3,G), got {e:?}");
        };
        shape.encoder = [e1, e2, e3, g];
    }
    if let Some(c) = &a.coarse_fc {
        shape.coarse_fc = c.clone();
    }
    if let Some(w) = a.fold_width {
        shape.fold_width = w;
    }
    let settings = CompletionTrainSettings {
        shape,
        epochs: a.epochs,
        batch: a.batch,
        lr: a.lr.unwrap_or(1e-3),
        lr_step: a.lr_step,
        lr_factor: a.lr_factor,
        loss_gt_points: a.loss_gt_points,
        coarse_weight: a.coarse_weight,
        fine_weight: a.fine_weight,
        seed: a.seed,
        val_fraction: a.val_fraction,
        max_cases: a.max_cases,
    };
    let command = command_line();
    let progress = BarProgress { bar: Mutex::new(None) };
    let sidecar = pool(a.threads)?.install(|| {
        objview_learn::completion_train::train_completion_and_describe(
            &a.data,
            None,
            &a.out,
            &settings,
            a.resume,
            a.heldout.as_deref(),
            &command,
            &progress,
        )
    })?;
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let val = &sidecar["validation"]["all"];
    let mut line = if val["cases"].as_u64().unwrap_or(0) == 0 {
        format!(
            "learn train completion: best epoch {} (the last: no validation objects)",
            sidecar["best_epoch"]
        )
    } else {
        format!(
            "learn train completion: best epoch {} (validation Chamfer-L1 net {:.4} vs identity {:.4}, {} cases)",
            sidecar["best_epoch"],
            f(&val["net"]["l1"]),
            f(&val["identity"]["l1"]),
            val["cases"]
        )
    };
    if !sidecar["heldout"].is_null() {
        let h = &sidecar["heldout"]["chamfer_l1"]["all"];
        line += &format!(
            "; held-out net {:.4} vs identity {:.4} ({} cases)",
            f(&h["net"]["l1"]),
            f(&h["identity"]["l1"]),
            h["cases"]
        );
    }
    println!("{line} -> {} (+ {})", a.out.display(), objview_learn::train::sidecar_path(&a.out).display());
    Ok(())
}

fn train_mascvp(a: TrainArgs) -> Result<()> {
    if a.heldout.is_some() {
        bail!("--heldout is an nbv-net and completion option (ma-scvp reports validation F1 and a baseline)");
    }
    if a.encoder.is_some() || a.coarse_fc.is_some() || a.fold_width.is_some() {
        bail!("--encoder, --coarse-fc and --fold-width are completion options");
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
    let manifest = objview_learn::train::read_manifest(&a.data)?;
    let r = if manifest["method"] == "completion" {
        objview_learn::completion_train::eval_completion_weights(&a.weights, &a.data)?
    } else {
        objview_learn::train::eval_weights(&a.weights, &a.data)?
    };
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
    /// Which networks: `nbv-net`, `ma-scvp`, `completion` or `all`.
    #[arg(long, default_value = "all")]
    pub network: String,
    /// completion: weights of the timed completion calls (`builtin` or a .safetensors with its
    /// sidecar).
    #[arg(long, default_value = "builtin")]
    pub completion_weights: String,
    /// MA-SCVP: timed training batches (batch 2) of the reference shape (64³, 34 M parameters;
    /// tens of seconds each on this machine); 0 skips it.
    #[arg(long, default_value_t = 1)]
    pub reference_batches: usize,
}

fn ms(s: &objview_runs::bench::Spread) -> String {
    format!("median {:.1} ms (p90 {:.1}, max {:.1})", s.median * 1e3, s.p90 * 1e3, s.max * 1e3)
}

fn bench(a: BenchArgs) -> Result<()> {
    use objview_learn::bench::*;
    crate::bench::announce_host();
    println!("learn bench: {} at ~{} triangles", a.object, a.triangles);
    let (nbv, scvp, completion) = match a.network.as_str() {
        "all" => (true, true, true),
        "nbv-net" => (true, false, false),
        "ma-scvp" => (false, true, false),
        "completion" => (false, false, true),
        o => bail!("--network: unknown network '{o}' (expected nbv-net, ma-scvp, completion or all)"),
    };
    if completion {
        bench_completion(&a)?;
    }
    if scvp {
        bench_mascvp(&a)?;
    }
    if !nbv {
        return Ok(());
    }
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

fn bench_completion(a: &BenchArgs) -> Result<()> {
    use objview_learn::bench::*;
    let mut backend = objview_learn::completion_backend::NetCompletion::named(&a.completion_weights)
        .map_err(anyhow::Error::msg)
        .context("--completion-weights")?;
    let shape: CompletionShape = serde_json::from_value(
        objview_planners::hybrid::completion::Completion::describe(&backend)["shape"].clone(),
    )?;
    let mut line = format!(
        "completion training, shape of the {} weights ({} parameters), batch 8:",
        a.completion_weights,
        shape.params()
    );
    let mut one = 0.0;
    for threads in [1usize, 2] {
        let s = pool(Some(threads))?.install(|| completion_training_throughput(&shape, 8, a.batches));
        if threads == 1 {
            one = s.median;
        }
        line += &format!(" {threads} thread(s) median {:.2} samples/s (x{:.2});", s.median, s.median / one);
    }
    println!("{line}");
    let (s, points) =
        pool(Some(1))?.install(|| completion_call(&mut backend, &a.object, a.triangles, a.steps))?;
    println!(
        "completion call (net, {} weights), 1 thread, {} partial clouds of 2 views (mean {:.0} points): {} (resample to 2048, normalize, network, map back)",
        a.completion_weights,
        a.steps.clamp(1, 128),
        points,
        ms(&s)
    );
    Ok(())
}

fn bench_mascvp(a: &BenchArgs) -> Result<()> {
    use objview_learn::bench::*;
    let scaled = MascvpShape::scaled();
    let mut line = String::from("ma-scvp training, scaled shape (32^3, 8/16/32/64), batch 8:");
    let mut one = 0.0;
    for threads in [1usize, 2] {
        let s = pool(Some(threads))?.install(|| mascvp_training_throughput(&scaled, 8, a.batches));
        if threads == 1 {
            one = s.median;
        }
        line += &format!(" {threads} thread(s) median {:.2} samples/s (x{:.2});", s.median, s.median / one);
    }
    println!("{line}");
    if a.reference_batches > 0 {
        let s = pool(Some(2))?
            .install(|| mascvp_training_throughput(&MascvpShape::reference(), 2, a.reference_batches));
        println!(
            "ma-scvp training, reference shape (64^3, 32/64/128/256), batch 2, 2 threads: median {:.3} samples/s ({:.1} s per sample)",
            s.median,
            1.0 / s.median
        );
    }
    let ([g, n, p, t], size) =
        pool(Some(1))?.install(|| mascvp_plan_step(&a.object, a.triangles, a.steps))?;
    println!(
        "ma-scvp one-shot planning step (shipped weights), 1 thread, {} starts: total {} = grid update (2 frames, 64^3) {} + network {} + decode and open path {} (mean plan {:.1} views)",
        a.steps.clamp(1, 128),
        ms(&t),
        ms(&g),
        ms(&n),
        ms(&p),
        size
    );
    Ok(())
}
