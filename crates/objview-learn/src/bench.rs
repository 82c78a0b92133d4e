//! The benchmark procedures of `objview learn bench` (the CLI prints them): dataset generation
//! per object, training throughput (samples/s at 32³ and 64³, on 1 and 2 threads) and the
//! planner's cost per step (grid update + network) at 32³ and 64³; for MA-SCVP the training
//! throughput of the scaled and the reference shape and the one-shot planning step (grid +
//! network + decode + TSP); for the completion network the training throughput and the cost of
//! one completion call (the contract's resampling, normalization, network and mapping back).
//!
//! Objects are built-in procedural objects at a chosen triangle count, written to a temporary
//! folder, so the figures are reproducible on any machine.

use std::time::Instant;

use burn::module::Module;
use burn::nn::loss::CrossEntropyLossConfig;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Int, Tensor, TensorData};
use objview_dataset::annotate::GridViews;
use objview_dataset::ObjectRef;
use objview_render::{render, Camera};
use objview_runs::bench::Spread;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::dataset::{generate_object, DatasetSettings, ObjectRecord};
use crate::input_grid::{InputGrid, GRID};
use crate::nbvnet::NbvNet;
use crate::planner::{NetScorer, ViewScorer};
use crate::LearnError;

fn write_object(name: &str, triangles: usize, dir: &std::path::Path) -> Result<ObjectRef, LearnError> {
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let path = dir.join(format!("{name}.obj"));
    objview_geom::write::write_obj(&path, &mesh).map_err(|e| LearnError::io(&path, e))?;
    Ok(ObjectRef::from_mesh(&path))
}

/// Generates the dataset cases of built-in `name` (at about `triangles` triangles) `repeats`
/// times; returns every run's record (seconds per stage, cases).
pub fn dataset_per_object(
    name: &str,
    triangles: usize,
    settings: &DatasetSettings,
    repeats: usize,
) -> Result<Vec<ObjectRecord>, LearnError> {
    let dir = tempfile::tempdir().map_err(|e| LearnError::io(std::path::Path::new("tmp"), e))?;
    let obj = write_object(name, triangles, dir.path())?;
    let cameras = GridViews::new(settings.annotate.view_radius)?.planning().to_vec();
    (0..repeats)
        .map(|_| generate_object(&obj, settings, &cameras, dir.path(), &serde_json::Value::Null))
        .collect()
}

/// Training samples per second at grid `grid` with batch `batch` over `batches` timed batches
/// (after one warm-up batch), on random grids; the spread is of per-batch samples/s.
pub fn training_throughput(grid: usize, batch: usize, batches: usize) -> Spread {
    let base = Device::flex();
    base.seed(1);
    let device = base.autodiff();
    let mut net = NbvNet::new(grid, &device);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let ce = CrossEntropyLossConfig::new().init(&device);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut rates = Vec::new();
    for i in 0..=batches {
        let x: Vec<f32> = (0..batch * grid.pow(3)).map(|_| rng.gen_range(0.1..0.97)).collect();
        let y: Vec<i64> = (0..batch).map(|_| rng.gen_range(0..128)).collect();
        let t = Instant::now();
        let x = Tensor::<5>::from_data(TensorData::new(x, [batch, 1, grid, grid, grid]), &device);
        let y = Tensor::<1, Int>::from_data(TensorData::new(y, [batch]), &device);
        let loss = ce.forward(net.forward(x), y);
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(4e-4, net, grads);
        if i > 0 {
            rates.push(batch as f64 / t.elapsed().as_secs_f64());
        }
    }
    let _ = net.valid();
    Spread::of(rates)
}

/// Seconds per planner step (insert the frame into the 64³ grid, pool, network forward) with
/// a randomly initialized `grid`³ NBV-Net, over the tammes-128 frames of built-in `name`;
/// returns (grid update, network, total) spreads.
pub fn inference_per_step(
    name: &str,
    triangles: usize,
    grid: usize,
    steps: usize,
) -> Result<[Spread; 3], LearnError> {
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let cameras: Vec<Camera> = GridViews::new(objview_geom::pose::VIEW_RADIUS)?.planning().to_vec();
    let frames: Vec<(Camera, Vec<f32>)> =
        cameras.iter().take(steps.max(1)).map(|c| (*c, render(&mesh, c).depth)).collect();
    let device = Device::flex();
    device.seed(2);
    let net = NbvNet::new(grid, &device);
    let dir = tempfile::tempdir().map_err(|e| LearnError::io(std::path::Path::new("tmp"), e))?;
    let w = dir.path().join("w.safetensors");
    crate::train::save_weights(&net, &w)?;
    std::fs::write(dir.path().join("w.json"), format!("{{\"settings\": {{\"grid\": {grid}}}}}"))
        .map_err(|e| LearnError::io(dir.path(), e))?;
    let mut scorer = NetScorer::from_file(&w).map_err(LearnError::Invalid)?;
    let mut g = InputGrid::new(GRID);
    let (mut a, mut b, mut c) = (vec![], vec![], vec![]);
    for (cam, depth) in &frames {
        let t = Instant::now();
        g.insert_depth(cam, depth);
        let t1 = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let s = scorer.scores(&g);
        let t2 = t.elapsed().as_secs_f64();
        assert_eq!(s.len(), 128);
        a.push(t1);
        b.push(t2);
        c.push(t1 + t2);
    }
    Ok([Spread::of(a), Spread::of(b), Spread::of(c)])
}

/// MA-SCVP training samples per second of `shape` with batch `batch` over `batches` timed
/// batches (after one warm-up batch), on random grids and labels; the spread is of per-batch
/// samples/s.
pub fn mascvp_training_throughput(
    shape: &crate::mascvp::MascvpShape,
    batch: usize,
    batches: usize,
) -> Spread {
    let base = Device::flex();
    base.seed(1);
    let device = base.autodiff();
    let mut net = crate::mascvp::MascvpNet::new(shape, &device);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let g = shape.grid;
    let mut rates = Vec::new();
    for i in 0..=batches {
        let x: Vec<f32> = (0..batch * g.pow(3)).map(|_| rng.gen_range(0.1..0.97)).collect();
        let vs: Vec<f32> = (0..batch * 128).map(|_| (rng.gen_range(0..10) == 0) as u8 as f32).collect();
        let y: Vec<f32> = (0..batch * 128).map(|_| (rng.gen_range(0..20) == 0) as u8 as f32).collect();
        let t = Instant::now();
        let x = Tensor::<5>::from_data(TensorData::new(x, [batch, 1, g, g, g]), &device);
        let vs = Tensor::<2>::from_data(TensorData::new(vs, [batch, 128]), &device);
        let y = Tensor::<2>::from_data(TensorData::new(y, [batch, 128]), &device);
        let loss = crate::mascvp_train::weighted_bce_sum(net.forward(x, vs), y, 1.5);
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(1e-4, net, grads);
        if i > 0 {
            rates.push(batch as f64 / t.elapsed().as_secs_f64());
        }
    }
    let _ = net.valid();
    Spread::of(rates)
}

/// The MA-SCVP planner's one-shot network step, as `ma-scvp` runs it, from each of `starts`
/// tammes-128 start views of built-in `name`: insert the start and the bootstrap view's frames
/// into a fresh 64³ grid (`grid update`; the bootstrap is the farthest view), one network call
/// with the shipped weights (`network`: pooling to 32³ + forward), decode at γ = 0.3 and order
/// the decoded views on the exact open path (`plan`: decode + TSP, with the decoded set size).
/// Returns the spreads of (grid update, network, plan, total) and the mean decoded set size.
pub fn mascvp_plan_step(
    name: &str,
    triangles: usize,
    starts: usize,
) -> Result<([Spread; 4], f64), LearnError> {
    use crate::mascvp_planner::{bootstrap_view, plan_views, MascvpScorer};
    use objview_planners::tsp::TspSettings;
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let cameras: Vec<Camera> = GridViews::new(objview_geom::pose::VIEW_RADIUS)?.planning().to_vec();
    let poses: Vec<objview_geom::Pose> = cameras.iter().map(|c| c.pose).collect();
    let mut scorer = MascvpScorer::builtin().map_err(LearnError::Invalid)?;
    let tsp = TspSettings::default();
    let feasible = vec![true; poses.len()];
    let mut g = InputGrid::new(GRID);
    let (mut a, mut b, mut c, mut d, mut sizes) = (vec![], vec![], vec![], vec![], vec![]);
    for s in 0..starts.clamp(1, poses.len()) {
        let s = s * poses.len() / starts.clamp(1, poses.len());
        let mut visited = vec![false; poses.len()];
        visited[s] = true;
        let allowed: Vec<bool> = (0..poses.len()).map(|v| v != s).collect();
        let boot = bootstrap_view(&poses, &allowed, &poses[s]).expect("127 allowed views");
        visited[boot] = true;
        let frames = [render(&mesh, &cameras[s]).depth, render(&mesh, &cameras[boot]).depth];
        let t = Instant::now();
        g.clear();
        g.insert_depth(&cameras[s], &frames[0]);
        g.insert_depth(&cameras[boot], &frames[1]);
        let t1 = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let logits = crate::mascvp_planner::SetScorer::logits(&mut scorer, &g, &visited);
        let t2 = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let plan = plan_views(&logits, 0.3, &visited, &feasible, &poses, &poses[boot], &tsp)
            .map(|p| p.views)
            .unwrap_or_default();
        let t3 = t.elapsed().as_secs_f64();
        sizes.push(plan.len() as f64);
        a.push(t1);
        b.push(t2);
        c.push(t3);
        d.push(t1 + t2 + t3);
    }
    let mean = sizes.iter().sum::<f64>() / sizes.len() as f64;
    Ok(([Spread::of(a), Spread::of(b), Spread::of(c), Spread::of(d)], mean))
}

/// Completion-network training samples per second of `shape` with batch `batch` over `batches`
/// timed batches (after one warm-up batch), on random clouds (2048 input, 2048 loss ground-truth
/// points, the loss of training: coarse + fine Chamfer-L1); the spread is of per-batch samples/s.
pub fn completion_training_throughput(
    shape: &crate::completion_net::CompletionShape,
    batch: usize,
    batches: usize,
) -> Spread {
    use crate::completion_net::{chamfer_loss, CompletionNet};
    use objview_planners::hybrid::completion::INPUT_POINTS;
    let base = Device::flex();
    base.seed(1);
    let device = base.autodiff();
    let mut net = CompletionNet::new(shape, &device);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut rates = Vec::new();
    for i in 0..=batches {
        let x: Vec<f32> = (0..batch * INPUT_POINTS * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let truth: Vec<Vec<f32>> =
            (0..batch).map(|_| (0..2048 * 3).map(|_| rng.gen_range(-1.0..1.0)).collect()).collect();
        let t = Instant::now();
        let x = burn::tensor::Tensor::<3>::from_data(TensorData::new(x, [batch, INPUT_POINTS, 3]), &device);
        let (coarse, fine) = net.forward(x);
        let loss = chamfer_loss(coarse, &truth) + chamfer_loss(fine, &truth);
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(5e-4, net, grads);
        if i > 0 {
            rates.push(batch as f64 / t.elapsed().as_secs_f64());
        }
    }
    let _ = net.valid();
    Spread::of(rates)
}

/// Seconds per completion call of `backend` as the hybrid planners make it
/// ([`objview_planners::hybrid::completion::complete`]: resampling to 2048, normalization, the
/// backend, mapping back, appending the input) on the partial clouds of built-in `name`: for
/// each of `calls` tammes-128 start views, the fused cloud of the start view and its farthest
/// view (what `completion-scp` completes), made before the clock starts. Returns the spread and
/// the mean partial-cloud size.
pub fn completion_call(
    backend: &mut dyn objview_planners::hybrid::completion::Completion,
    name: &str,
    triangles: usize,
    calls: usize,
) -> Result<(Spread, f64), LearnError> {
    use objview_planners::hybrid::completion::complete;
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let cameras: Vec<Camera> = GridViews::new(objview_geom::pose::VIEW_RADIUS)?.planning().to_vec();
    let n = calls.clamp(1, cameras.len());
    let mut frames = std::collections::BTreeMap::new();
    let (mut secs, mut sizes) = (vec![], vec![]);
    for k in 0..n {
        let s = k * cameras.len() / n;
        let far = (0..cameras.len())
            .max_by(|&a, &b| {
                let d = |v: usize| objview_episode::path::pose_distance(&cameras[s].pose, &cameras[v].pose);
                d(a).total_cmp(&d(b)).then(b.cmp(&a))
            })
            .expect("128 views");
        let partial = crate::completion_data::fused_partial(&mesh, &cameras, &[s, far], &mut frames);
        sizes.push(partial.len() as f64);
        let mut rng = ChaCha8Rng::seed_from_u64(k as u64);
        let t = Instant::now();
        let out = complete(backend, &partial, &mut rng).map_err(|e| LearnError::Invalid(e.to_string()))?;
        secs.push(t.elapsed().as_secs_f64());
        assert_eq!(out.points.len(), out.predicted + 2048);
    }
    let mean = sizes.iter().sum::<f64>() / sizes.len() as f64;
    Ok((Spread::of(secs), mean))
}
