//! The completion network end to end: a real `completion` dataset of built-in objects (the
//! contract of its arrays, determinism on 1 and 2 threads, d_plan from split entries), training
//! determinism (rerun, 1 vs 2 threads, resume), a memorisation test, and the `net` backend in a
//! `completion-scp` episode through this crate's hybrid rows.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use objview_dataset::{Shard, Silent};
use objview_learn::completion_data::CompletionDataSettings;
use objview_learn::completion_net::{chamfer_l1, to_f64, CompletionShape};
use objview_learn::completion_train::{
    load_completion_cases, train_completion_and_describe, CompletionTrainSettings, QuietCompletion,
};
use objview_learn::dataset::{DatasetPlan, DatasetSettings, Method};
use objview_learn::npz::{Dtype, NpzReader};
use objview_planners::hybrid::completion::{Normalization, INPUT_POINTS, NET_PREDICTED_POINTS};
use serde_json::{json, Value};

fn write_builtin(dir: &Path, name: &str, triangles: usize) -> PathBuf {
    let mesh = objview_geom::synth::build_with_triangles(name, triangles);
    let p = dir.join(format!("{name}.obj"));
    objview_geom::write::write_obj(&p, &mesh).unwrap();
    p
}

fn settings(partials: usize, gt_points: usize) -> DatasetSettings {
    DatasetSettings {
        method: Method::Completion,
        completion: CompletionDataSettings { partials, max_views: 3, gt_points },
        ..Default::default()
    }
}

fn dataset(inputs: Vec<PathBuf>, out: &Path, s: DatasetSettings, threads: usize) -> Value {
    let plan = DatasetPlan {
        inputs,
        out: out.to_path_buf(),
        settings: s,
        threads: Some(threads),
        shard: Shard::ALL,
        retry_failed: false,
        command: "test".into(),
    };
    plan.run(&Silent).unwrap().1
}

/// A split file of `meshes` (paths relative to it) with annotations giving d_plan 3 and 12 (the
/// second not proven optimal, so unknown).
fn split_file(dir: &Path, meshes: &[PathBuf]) -> PathBuf {
    let entries: Vec<Value> = meshes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            json!({"uid": m.file_stem().unwrap().to_string_lossy(), "mesh": m.file_name().unwrap().to_string_lossy(),
                   "annotation": {"d_plan": if i == 0 { 3 } else { 12 }, "d_plan_status": if i == 0 { "optimal" } else { "time_limit" }}})
        })
        .collect();
    let p = dir.join("split.json");
    std::fs::write(&p, serde_json::to_string(&entries).unwrap()).unwrap();
    p
}

/// The arrays follow the contract: the input is 2048 normalized points (centroid at the
/// origin, max radius one) on the object's surface; the ground truth is one object-frame cloud
/// in each case's normalization; the run is byte-identical on one and two threads; d_plan comes
/// from the split entry when proven.
#[test]
fn completion_cases_follow_the_contract_and_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let meshes = vec![write_builtin(dir.path(), "l-shape", 3000), write_builtin(dir.path(), "cup", 3000)];
    let split = split_file(dir.path(), &meshes);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let m = dataset(vec![split.clone()], &a, settings(5, 4096), 1);
    dataset(vec![split], &b, settings(5, 4096), 2);
    assert_eq!(
        (m["method"].as_str(), m["objects"].as_u64(), m["cases"].as_u64()),
        (Some("completion"), Some(2), Some(10))
    );
    assert_eq!(m["settings"]["views_per_partial"], json!([1, 3]));
    // Dense samples of the normalized meshes (independent of the data's ground truth), by uid.
    let dense: Vec<Vec<[f64; 3]>> = meshes
        .iter()
        .map(|p| {
            let (mesh, _) =
                objview_geom::normalize::load_normalized(p, objview_geom::normalize::Normalization::Unit)
                    .unwrap();
            objview_geom::cloud::sample_surface(&mesh, 300_000, 9)
        })
        .collect();
    for f in m["files"].as_array().unwrap() {
        let f = f.as_str().unwrap();
        let k = meshes
            .iter()
            .position(|p| f == format!("cases/{}.npz", p.file_stem().unwrap().to_string_lossy()))
            .unwrap();
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}: 1 vs 2 threads"
        );
        let mut r = NpzReader::open(&a.join(f)).unwrap();
        let partial = r.array("partial", Some(Dtype::F32)).unwrap();
        let gt = r.array("gt", Some(Dtype::F32)).unwrap();
        let centroid = r.array("centroid", Some(Dtype::F32)).unwrap().f32s();
        let scale = r.array("scale", Some(Dtype::F32)).unwrap().f32s();
        let views = r.array("views", Some(Dtype::I32)).unwrap().ints();
        let sizes = r.array("partial_points", Some(Dtype::I32)).unwrap().ints();
        let d_plan = r.array("d_plan", Some(Dtype::I32)).unwrap().ints();
        assert_eq!(partial.shape, vec![5, INPUT_POINTS, 3]);
        assert_eq!(gt.shape, vec![5, 4096, 3]);
        assert_eq!(d_plan, vec![if k == 0 { 3 } else { -1 }], "{f}");
        let (p, g) = (partial.f32s(), gt.f32s());
        let mut object_gt: Option<Vec<[f64; 3]>> = None;
        let mut view_sets = std::collections::BTreeSet::new();
        for i in 0..5 {
            let v: Vec<i64> = views[i * 3..i * 3 + 3].iter().copied().filter(|&v| v >= 0).collect();
            assert!((1..=3).contains(&v.len()) && v.iter().all(|&x| x < 128), "{v:?}");
            assert!(views[i * 3..i * 3 + v.len()] == v[..], "ids first, then -1 padding");
            let mut u = v.clone();
            u.sort();
            u.dedup();
            assert_eq!(u.len(), v.len(), "distinct views");
            view_sets.insert(v.clone());
            assert!(sizes[i] > 0);
            let input = to_f64(&p[i * INPUT_POINTS * 3..(i + 1) * INPUT_POINTS * 3]);
            // Normalized: centroid 0, max radius 1 (f32 storage).
            let c: Vec<f64> =
                (0..3).map(|a| input.iter().map(|q| q[a]).sum::<f64>() / INPUT_POINTS as f64).collect();
            assert!(c.iter().all(|x| x.abs() < 1e-5), "{c:?}");
            let rmax =
                input.iter().map(|q| (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt()).fold(0.0, f64::max);
            assert!((rmax - 1.0).abs() < 1e-5, "{rmax}");
            // Object frame: the same ground truth for every case, and the input lies on it
            // (voxel-filter centroids of surface points: within a 1/64 cell of the surface).
            let n = Normalization {
                centroid: [centroid[i * 3] as f64, centroid[i * 3 + 1] as f64, centroid[i * 3 + 2] as f64],
                scale: scale[i] as f64,
            };
            let truth: Vec<[f64; 3]> =
                to_f64(&g[i * 4096 * 3..(i + 1) * 4096 * 3]).iter().map(|q| n.invert(*q)).collect();
            match &object_gt {
                None => object_gt = Some(truth.clone()),
                Some(first) => {
                    let d = first
                        .iter()
                        .zip(&truth)
                        .map(|(x, y)| (0..3).map(|a| (x[a] - y[a]).abs()).fold(0.0, f64::max))
                        .fold(0.0, f64::max);
                    assert!(d < 1e-5, "case {i}: the ground truth moves by {d}");
                }
            }
            let obj_input: Vec<[f64; 3]> = input.iter().map(|q| n.invert(*q)).collect();
            assert!(obj_input.iter().all(|q| q.iter().all(|x| (-1.0..=1.0).contains(x))));
            let d = objview_learn::completion_net::nearest_all(&obj_input, &dense[k]);
            let mean = d.iter().map(|x| x.1).sum::<f64>() / d.len() as f64;
            let max = d.iter().map(|x| x.1).fold(0.0, f64::max);
            assert!(
                mean < 0.006 && max < 0.03,
                "{f} case {i}: input off the surface: mean {mean}, max {max}"
            );
            let c = chamfer_l1(&obj_input, &truth);
            assert!(c.completeness > c.accuracy, "a partial view misses parts of the object: {c:?}");
        }
        assert!(view_sets.len() > 1, "the views vary between partial clouds");
    }
    let cases = load_completion_cases(&a, None).unwrap();
    assert_eq!((cases.len(), cases.gt_points), (10, 4096));
    assert_eq!(cases.d_plan.iter().filter(|d| **d == Some(3)).count(), 5);
    let again = dataset(vec![dir.path().join("split.json")], &a, settings(5, 4096), 2);
    assert_eq!(again["cases"], m["cases"], "resumed: nothing added");
}

/// Burn's Flex device RNG is process-global: trainings in one process must not overlap.
static TRAINING: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn tiny_shape() -> CompletionShape {
    CompletionShape {
        encoder: [16, 32, 32, 32],
        coarse_fc: vec![64],
        coarse: 96,
        fold_grid: 8,
        fold_width: 16,
        grid_scale: 0.05,
    }
}

fn run(data: &Path, out: &Path, s: &CompletionTrainSettings, threads: usize, resume: bool) -> Value {
    let _one = TRAINING.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| train_completion_and_describe(data, None, out, s, resume, None, "test", &QuietCompletion))
        .unwrap()
}

fn small_data(dir: &Path) -> PathBuf {
    // Validation at 20 %: cup (fnv1a64 mod 1000 = 143); l-shape (351) and gear (686) train.
    let meshes = vec![
        write_builtin(dir, "l-shape", 2000),
        write_builtin(dir, "cup", 2000),
        write_builtin(dir, "gear", 2000),
    ];
    let data = dir.join("data");
    dataset(meshes, &data, settings(3, 2048), 2);
    data
}

/// Same seed → bit-identical weights on a rerun, on 1 vs 2 threads and when stopped after
/// epoch 1 and resumed; another seed → other weights; the sidecar records what it must.
#[test]
fn training_is_deterministic_and_resumable() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_data(dir.path());
    let s = CompletionTrainSettings {
        shape: tiny_shape(),
        epochs: 2,
        batch: 4,
        lr: 1e-3,
        loss_gt_points: 512,
        seed: 5,
        val_fraction: 0.2,
        ..Default::default()
    };
    let w: Vec<PathBuf> = (1..=4).map(|k| dir.path().join(format!("w{k}.safetensors"))).collect();
    let side = run(&data, &w[0], &s, 1, false);
    run(&data, &w[1], &s, 2, false);
    let h = |p: &Path| objview_geom::hash::fnv1a64(&std::fs::read(p).unwrap());
    assert_eq!(h(&w[0]), h(&w[1]), "1 vs 2 threads");
    run(&data, &w[2], &CompletionTrainSettings { epochs: 1, ..s.clone() }, 2, false);
    let resumed = run(&data, &w[2], &s, 2, true);
    assert_eq!(h(&w[0]), h(&w[2]), "resumed run");
    run(&data, &w[3], &CompletionTrainSettings { seed: 6, ..s.clone() }, 1, false);
    assert_ne!(h(&w[0]), h(&w[3]), "another seed, other weights");
    for key in [
        "command",
        "data",
        "settings",
        "history",
        "final",
        "validation",
        "deviation",
        "version",
        "weights_fnv1a64",
        "beats_identity",
    ] {
        assert!(!side[key].is_null(), "sidecar field {key}");
    }
    assert_eq!(side["weights_fnv1a64"], format!("{:016x}", h(&w[0])));
    assert_eq!(side["params"].as_u64().unwrap() as usize, tiny_shape().params());
    let strip = |v: &Value| -> Vec<Value> {
        v.as_array().unwrap().iter().map(|e| json!([e["train_loss"], e["val"]])).collect()
    };
    // Seconds differ; the figures do not.
    assert_eq!(strip(&side["history"]), strip(&resumed["history"]), "same figures after resume");
    let val = &side["validation"]["all"];
    assert_eq!(val["cases"], 3, "the cup's three partial clouds validate");
    assert!(val["identity"]["l1"].as_f64().unwrap() > 0.0);
}

/// One object's partial clouds are memorised: after training on them, the prediction is much
/// closer to the ground truth than at initialization, and the contract output beats identity.
#[test]
fn a_few_clouds_are_memorised() {
    let dir = tempfile::tempdir().unwrap();
    let meshes = vec![write_builtin(dir.path(), "cup", 2000)];
    let data = dir.path().join("data");
    dataset(meshes, &data, settings(2, 2048), 2);
    let s = CompletionTrainSettings {
        shape: tiny_shape(),
        epochs: 150,
        batch: 2,
        lr: 3e-3,
        loss_gt_points: 1024,
        seed: 1,
        val_fraction: 0.0,
        ..Default::default()
    };
    let w = dir.path().join("w.safetensors");
    let side = run(&data, &w, &s, 2, false);
    let hist = side["history"].as_array().unwrap();
    let first = hist[0]["train_loss"].as_f64().unwrap();
    let last = hist.last().unwrap()["train_loss"].as_f64().unwrap();
    assert!(last < 0.3 * first, "loss {first} -> {last}");
    let e = objview_learn::completion_train::eval_completion_weights(w.to_str().unwrap(), &data).unwrap();
    let all = &e["chamfer_l1"]["all"];
    let (net, identity) = (all["net"]["l1"].as_f64().unwrap(), all["identity"]["l1"].as_f64().unwrap());
    assert!(net < identity, "memorised: net {net} vs identity {identity}");
    assert_eq!(e["beats_identity"], true);
}

/// The `net` backend built from a trained file: `completion-scp` of this crate's hybrid rows
/// runs a real episode with `completion=net`, records the model in its parameters, and the
/// backend predicts 6144 finite points.
#[test]
fn net_backend_runs_a_completion_scp_episode() {
    use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeSettings};
    use objview_planners::registry::Registry;
    let dir = tempfile::tempdir().unwrap();
    let data = small_data(dir.path());
    let w = dir.path().join("w.safetensors");
    let s = CompletionTrainSettings {
        shape: tiny_shape(),
        epochs: 1,
        batch: 4,
        loss_gt_points: 256,
        val_fraction: 0.0,
        ..Default::default()
    };
    let side = run(&data, &w, &s, 2, false);

    let mut reg = Registry::from_tables(&[objview_planners::registry::TABLE, objview_learn::TABLE]).unwrap();
    reg.replace(objview_learn::completion_backend::HYBRID_TABLE).unwrap();
    let params = [
        ("completion".to_string(), json!("net")),
        ("completion_weights".to_string(), json!(w.display().to_string())),
    ];
    let mut p = reg.with_params("completion-scp", &params).unwrap();
    assert_eq!(p.name(), "completion-scp[net]");
    assert_eq!(p.params()["completion_bound"], "method");
    assert_eq!(p.params()["completion_model"]["weights_fnv1a64"], side["weights_fnv1a64"]);
    // The planners crate's own row still refuses net; identity and oracle are unchanged.
    assert!(objview_planners::registry::with_params("completion-scp", &params[..1]).is_err());
    let id = reg.with_params("completion-scp", &[("completion".to_string(), json!("identity"))]).unwrap();
    assert!(id.params().get("completion_model").is_none());
    let bad = reg
        .with_params("completion-scp", &[("completion_weights".to_string(), json!("/no/such.safetensors"))]);
    assert!(bad.err().unwrap().contains("/no/such.safetensors"));

    let mesh = objview_geom::synth::build_with_triangles("cup", 3000);
    let (mesh, _) = objview_geom::normalize::normalize(
        mesh,
        objview_geom::normalize::Normalization::Unit,
        Path::new("cup"),
    )
    .unwrap();
    let gt = objview_geom::cloud::sample_surface(&mesh, 10_000, 1);
    let vs = objview_views::ViewSpace::builtin("whole").unwrap();
    let es = EpisodeSettings { record_timings: false, ..Default::default() };
    let scene =
        Arc::new(scene_from_parts("cup", mesh, gt, "sampled".into(), &vs, "whole", &es, None).unwrap());
    let cands = Arc::new(objview_views::ViewSet::resolve("tammes-360").unwrap().poses(3.0));
    let r = run_episode(
        scene,
        p.as_mut(),
        &es,
        Budget::Auto,
        0,
        objview_views::start_pose(3.0),
        cands,
        json!({}),
    )
    .unwrap();
    assert_eq!(r.method, "completion-scp[net]");
    assert_eq!(r.terminal_reason, "plan_end", "{}", r.terminal_detail);

    let mut b = objview_learn::completion_backend::NetCompletion::from_file(&w).unwrap();
    let partial: Vec<[f64; 3]> = (0..500)
        .map(|i| {
            let t = i as f64 * 0.1;
            [t.cos() * 0.3, t.sin() * 0.3, (i % 7) as f64 * 0.01]
        })
        .collect();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let out = objview_planners::hybrid::completion::complete(&mut b, &partial, &mut rng).unwrap();
    assert_eq!(
        (out.predicted, out.points.len()),
        (NET_PREDICTED_POINTS, NET_PREDICTED_POINTS + INPUT_POINTS)
    );
    assert!(out.points.iter().all(|p| p.iter().all(|x| x.is_finite())));
}
