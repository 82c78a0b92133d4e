//! End-to-end tests of the learned layer: a real dataset of a built-in object (invariants,
//! determinism), training determinism (rerun, 1 vs 2 threads, resume), an overfit test, and
//! the `nbv-net` planner in a real episode with a scripted network output.

use std::path::{Path, PathBuf};

use objview_dataset::{Shard, Silent};
use objview_learn::dataset::{DatasetPlan, DatasetSettings, Method, VIEWS};
use objview_learn::npz::{Dtype, NpzReader, NpzWriter};
use objview_learn::train::{train, Quiet, TrainSettings};

fn write_builtin(dir: &Path, name: &str, triangles: usize) -> PathBuf {
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let p = dir.join(format!("{name}.obj"));
    objview_geom::write::write_obj(&p, &mesh).unwrap();
    p
}

fn dataset(meshes: Vec<PathBuf>, out: &Path, method: Method, threads: usize) -> serde_json::Value {
    let plan = DatasetPlan {
        inputs: meshes,
        out: out.to_path_buf(),
        settings: DatasetSettings { method, ..Default::default() },
        threads: Some(threads),
        shard: Shard::ALL,
        retry_failed: false,
        command: "test".into(),
    };
    plan.run(&Silent).unwrap().1
}

/// A real dataset of two small built-in objects: every case satisfies the contract (label =
/// the lowest-id maximum of the gains among unvisited views, gains 0 at visited views, the start
/// view visited, grid values in the clamp range with some known cells), the run is
/// byte-identical on 1 and 2 threads, and a resumed run adds nothing.
#[test]
fn dataset_cases_follow_the_contract_and_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let meshes = vec![write_builtin(dir.path(), "l-shape", 3000), write_builtin(dir.path(), "cup", 3000)];
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let m = dataset(meshes.clone(), &a, Method::NbvNet, 1);
    dataset(meshes.clone(), &b, Method::NbvNet, 2);
    assert_eq!(m["objects"], 2);
    let files: Vec<String> =
        m["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().to_string()).collect();
    let mut total = 0;
    for f in &files {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}: same bytes on 1 and 2 threads"
        );
        let mut r = NpzReader::open(&a.join(f)).unwrap();
        let label = r.array("label", Some(Dtype::I64)).unwrap().ints();
        let n = label.len();
        total += n;
        assert!(n > 0);
        let visited = r.array("visited", Some(Dtype::U8)).unwrap().ints();
        let gains = r.array("gains", Some(Dtype::I32)).unwrap().ints();
        let start = r.array("start", Some(Dtype::I32)).unwrap().ints();
        let step = r.array("step", Some(Dtype::I32)).unwrap().ints();
        let status = r.array("cover_status", Some(Dtype::I8)).unwrap().ints();
        let grid = r.array("grid", Some(Dtype::F32)).unwrap();
        assert_eq!(grid.shape, vec![n, 64, 64, 64]);
        for i in 0..n {
            let vis = &visited[i * VIEWS..(i + 1) * VIEWS];
            let g = &gains[i * VIEWS..(i + 1) * VIEWS];
            assert_eq!(vis.iter().sum::<i64>(), step[i] + 1);
            assert_eq!(vis[start[i] as usize], 1);
            let l = label[i] as usize;
            assert_eq!(vis[l], 0);
            for v in 0..VIEWS {
                if vis[v] == 1 {
                    assert_eq!(g[v], 0);
                }
                assert!(g[v] < g[l] || (g[v] == g[l] && v >= l), "label is the lowest-id maximum");
            }
            assert!(g[l] > 0);
            assert_eq!(status[i], -1, "nbv-net computes no covers");
        }
        let vals = grid.f32s();
        assert!(vals.iter().all(|&p| (0.1191..=0.9711).contains(&p)));
        assert!(vals.iter().any(|&p| p > 0.6) && vals.iter().any(|&p| p < 0.45));
    }
    assert_eq!(m["cases"], total);
    // Resume: nothing left to do, same manifest.
    let again = dataset(meshes, &a, Method::NbvNet, 2);
    assert_eq!(again["cases"], m["cases"]);
    // The Python loader's contract test reads this folder when asked to.
    if let Ok(keep) = std::env::var("OBJVIEW_KEEP_LEARN_DATASET") {
        let _ = std::fs::remove_dir_all(&keep);
        std::fs::rename(&a, &keep).unwrap();
    }
}

/// MA-SCVP data: long-tail cases with exact residual covers that really cover what is left.
#[test]
fn mascvp_cases_carry_residual_covers() {
    let dir = tempfile::tempdir().unwrap();
    let meshes = vec![write_builtin(dir.path(), "l-shape", 3000)];
    let out = dir.path().join("m");
    let m = dataset(meshes, &out, Method::MaScvp, 2);
    let f = m["files"][0].as_str().unwrap();
    let mut r = NpzReader::open(&out.join(f)).unwrap();
    let cover = r.array("cover", Some(Dtype::U8)).unwrap().ints();
    let visited = r.array("visited", Some(Dtype::U8)).unwrap().ints();
    let status = r.array("cover_status", Some(Dtype::I8)).unwrap().ints();
    let label = r.array("label", None).unwrap().ints();
    for i in 0..label.len() {
        assert_eq!(status[i], 0, "optimal");
        let c = &cover[i * VIEWS..(i + 1) * VIEWS];
        assert!(c.iter().sum::<i64>() >= 1);
        assert!(
            (0..VIEWS).all(|v| !(c[v] == 1 && visited[i * VIEWS + v] == 1)),
            "covers use unvisited views"
        );
    }
}

/// A dataset of random grids with labels, written directly (for training tests).
fn synthetic_dataset(dir: &Path, objects: usize, per_object: usize, seed: u64) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    std::fs::create_dir_all(dir.join("cases")).unwrap();
    let mut files = vec![];
    for o in 0..objects {
        let f = format!("cases/obj-{o}.npz");
        let mut w = NpzWriter::create(&dir.join(&f)).unwrap();
        w.begin("grid", Dtype::F32, &[per_object, 64, 64, 64]).unwrap();
        let mut labels = vec![];
        for _ in 0..per_object {
            let label = rng.gen_range(0..128i64);
            // A blob whose position encodes the label, plus noise.
            let (cx, cy) = ((label % 8) as usize * 8 + 4, (label / 8) as usize * 4 + 2);
            let g: Vec<f32> = (0..64 * 64 * 64)
                .map(|i| {
                    let (x, y): (usize, usize) = (i / 4096, (i / 64) % 64);
                    let near = x.abs_diff(cx) < 6 && y.abs_diff(cy) < 6;
                    if near {
                        0.9
                    } else {
                        0.5 + rng.gen_range(-0.05..0.05)
                    }
                })
                .collect();
            w.write_f32(&g).unwrap();
            labels.push(label);
        }
        w.array_i64("label", &[per_object], &labels).unwrap();
        w.finish().unwrap();
        files.push(f);
    }
    let manifest = serde_json::json!({"format": "objview-learn-dataset", "format_version": 1, "method": "nbv-net",
        "views": 128, "grid": 64, "objects": objects, "cases": objects * per_object, "files": files,
        "settings": {}, "command": "synthetic", "version": "test"});
    std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
}

/// Burn's Flex device RNG is process-global: trainings in one process must not overlap.
static TRAINING: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn run_training(data: &Path, out: &Path, s: &TrainSettings, threads: usize, resume: bool) -> Vec<f64> {
    let _one = TRAINING.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let (o, _, _) = pool.install(|| train(data, out, s, resume, &Quiet)).unwrap();
    o.history.iter().map(|h| h.train_loss).collect()
}

/// A short run: the loss decreases; weights are bit-identical on a rerun, on 1 vs 2 threads,
/// and when the run is stopped after epoch 1 and resumed.
#[test]
fn training_is_deterministic_and_resumable() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    synthetic_dataset(&data, 3, 8, 1);
    let s = TrainSettings {
        grid: 16,
        epochs: 3,
        batch: 4,
        lr: 1e-3,
        seed: 7,
        val_fraction: 0.0,
        ..Default::default()
    };
    let w1 = dir.path().join("w1.safetensors");
    let w2 = dir.path().join("w2.safetensors");
    let w3 = dir.path().join("w3.safetensors");
    let losses = run_training(&data, &w1, &s, 1, false);
    assert!(losses[2] < losses[0], "loss decreases: {losses:?}");
    run_training(&data, &w2, &s, 2, false);
    let h = |p: &Path| objview_geom::hash::fnv1a64(&std::fs::read(p).unwrap());
    assert_eq!(h(&w1), h(&w2), "1 vs 2 threads");
    let s1 = TrainSettings { epochs: 1, ..s.clone() };
    run_training(&data, &w3, &s1, 2, false);
    run_training(&data, &w3, &s, 2, true);
    assert_eq!(h(&w1), h(&w3), "resumed run");
    let w4 = dir.path().join("w4.safetensors");
    run_training(&data, &w4, &TrainSettings { seed: 8, ..s.clone() }, 1, false);
    assert_ne!(h(&w1), h(&w4), "another seed, other weights");
}

/// A few cases are memorised to 100 % top-1 (measured in evaluation mode after training).
#[test]
fn a_few_cases_are_memorised() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    synthetic_dataset(&data, 1, 6, 2);
    let s = TrainSettings {
        grid: 16,
        epochs: 80,
        batch: 6,
        lr: 3e-3,
        seed: 1,
        val_fraction: 0.0,
        ..Default::default()
    };
    let w = dir.path().join("w.safetensors");
    run_training(&data, &w, &s, 2, false);
    let device = burn::tensor::Device::flex();
    let net = objview_learn::train::load_weights(&w, 16, &device).unwrap();
    let cases = objview_learn::train::load_cases(&data, 16).unwrap();
    let (_, acc) = objview_learn::train::evaluate(&net, &cases, 8, &device);
    assert_eq!(acc, 1.0);
}
