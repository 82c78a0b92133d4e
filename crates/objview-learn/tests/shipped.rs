//! The shipped weights. NBV-Net: they load, their sidecar records what produced them, and
//! their top-1 agreement with the oracle labels of the fixed held-out set (eight built-in
//! objects, regenerated here with the dataset command's settings) is exactly what the sidecar
//! says. MA-SCVP and the completion network: below.

use objview_dataset::{Shard, Silent};
use objview_learn::dataset::{DatasetPlan, DatasetSettings, Method};
use objview_learn::planner::{NetScorer, BUILTIN_SIDECAR};
use serde_json::Value;

/// The held-out objects, in the order of the sidecar's dataset command.
const HELDOUT: [&str; 8] = ["mug", "vase", "chair", "table", "gear", "helix", "bowl", "ball-in-cage"];

#[test]
fn shipped_weights_load_and_match_their_sidecar() {
    let side: Value = serde_json::from_str(BUILTIN_SIDECAR).unwrap();
    for key in ["command", "data", "settings", "history", "final", "heldout", "deviation", "version"] {
        assert!(!side[key].is_null(), "sidecar field {key}");
    }
    assert!(side["command"].as_str().unwrap().contains("learn train nbv-net"));
    assert!(
        side["data"]["pool"]["seed"].is_u64() && side["data"]["pool"]["count"].is_u64(),
        "pool seed/size"
    );
    let heldout_cmd = side["heldout"]["dataset_command"].as_str().unwrap();
    for name in HELDOUT {
        assert!(heldout_cmd.contains(&format!("{name}.obj")), "{heldout_cmd}");
    }
    let scorer = NetScorer::builtin().expect("the shipped weights load");
    assert_eq!(scorer.net().grid() as u64, side["settings"]["grid"].as_u64().unwrap());

    let dir = tempfile::tempdir().unwrap();
    objview_geom::synth::write_pool(&dir.path().join("builtins")).unwrap();
    let data = dir.path().join("heldout");
    let plan = DatasetPlan {
        inputs: HELDOUT.iter().map(|n| dir.path().join("builtins").join(format!("{n}.obj"))).collect(),
        out: data.clone(),
        settings: DatasetSettings { method: Method::NbvNet, ..Default::default() },
        threads: Some(2),
        shard: Shard::ALL,
        retry_failed: false,
        command: "test".into(),
    };
    let (_, manifest) = plan.run(&Silent).unwrap();
    assert_eq!(manifest["cases"], side["heldout"]["cases"], "the held-out set is regenerated case for case");
    let r = objview_learn::train::eval_weights("builtin", &data).unwrap();
    assert_eq!(r["agreement"], side["heldout"]["agreement"], "top-1 agreement as recorded");
    let (a, b) = (r["loss"].as_f64().unwrap(), side["heldout"]["loss"].as_f64().unwrap());
    assert!((a - b).abs() < 1e-9, "loss {a} vs {b}");
    assert!(r["agreement"].as_f64().unwrap() > 4.0 / 128.0, "well above chance (1/128)");
}

/// The shipped MA-SCVP weights: they load into the shape their sidecar records, their hash and
/// parameter count are the sidecar's, the sidecar states the scaled-shape deviation, the
/// commands and the data, and the network scores a grid with finite logits.
#[test]
fn shipped_mascvp_weights_load_and_match_their_sidecar() {
    use objview_learn::mascvp::MascvpShape;
    use objview_learn::mascvp_planner::{MascvpScorer, SetScorer, BUILTIN_SIDECAR, BUILTIN_WEIGHTS};
    let side: Value = serde_json::from_str(BUILTIN_SIDECAR).unwrap();
    for key in ["command", "data", "settings", "history", "final", "baseline", "deviation", "version"] {
        assert!(!side[key].is_null(), "sidecar field {key}");
    }
    assert!(side["command"].as_str().unwrap().contains("learn train ma-scvp"));
    assert!(side["data"]["dataset_command"].as_str().unwrap().contains("--method ma-scvp"));
    assert_eq!(side["data"]["method"], "ma-scvp");
    let shape: MascvpShape = serde_json::from_value(side["settings"]["shape"].clone()).unwrap();
    assert_eq!(shape, MascvpShape::scaled(), "the shipped weights are the scaled default shape");
    assert_eq!(side["deviation"].as_str().unwrap(), shape.deviation());
    assert_eq!(
        side["weights_fnv1a64"].as_str().unwrap(),
        format!("{:016x}", objview_geom::hash::fnv1a64(BUILTIN_WEIGHTS))
    );
    let mut scorer = MascvpScorer::builtin().expect("the shipped weights load");
    assert_eq!(shape.trainable_params(scorer.net()) as u64, side["params"].as_u64().unwrap());
    let best = side["best_epoch"].as_u64().unwrap() as usize;
    assert_eq!(side["final"]["val"], side["history"][best - 1]["val"], "final = the kept epoch");
    let mut grid = objview_learn::input_grid::InputGrid::new(64);
    grid.insert_points([3.0, 0.0, 0.0], &[[0.2, 0.1, 0.0], [0.0, 0.3, 0.1]]);
    let mut visited = vec![false; 128];
    visited[3] = true;
    let logits = scorer.logits(&grid, &visited);
    assert_eq!(logits.len(), 128);
    assert!(logits.iter().all(|x| x.is_finite()));
}

/// The shipped completion weights: they load into the shape their sidecar records (the default
/// shape), their hash and parameter count are the sidecar's, the sidecar records the commands,
/// the data, the deviation from PoinTr, the kept epoch, the held-out Chamfer-L1 of `net` and
/// `identity` per d_plan bucket and whether `net` beats `identity`; the backend completes a
/// built-in object's partial cloud with 6144 finite predicted points, and `learn eval builtin`
/// works on a regenerated completion dataset.
#[test]
fn shipped_completion_weights_load_and_match_their_sidecar() {
    use objview_learn::completion_backend::{NetCompletion, BUILTIN_SIDECAR, BUILTIN_WEIGHTS};
    use objview_learn::completion_net::CompletionShape;
    use objview_planners::hybrid::completion::{complete, NET_PREDICTED_POINTS};
    let side: Value = serde_json::from_str(BUILTIN_SIDECAR).unwrap();
    for key in
        ["command", "data", "settings", "history", "final", "validation", "heldout", "deviation", "version"]
    {
        assert!(!side[key].is_null(), "sidecar field {key}");
    }
    assert!(side["command"].as_str().unwrap().contains("learn train completion"));
    assert!(side["data"]["dataset_command"].as_str().unwrap().contains("--method completion"));
    assert!(side["heldout"]["dataset_command"].as_str().unwrap().contains("--method completion"));
    assert_eq!(side["data"]["method"], "completion");
    let shape: CompletionShape = serde_json::from_value(side["settings"]["shape"].clone()).unwrap();
    assert_eq!(shape, CompletionShape::small(), "the shipped weights are the default shape");
    assert_eq!(side["deviation"].as_str().unwrap(), shape.deviation());
    assert_eq!(side["params"].as_u64().unwrap() as usize, shape.params());
    assert_eq!(
        side["weights_fnv1a64"].as_str().unwrap(),
        format!("{:016x}", objview_geom::hash::fnv1a64(BUILTIN_WEIGHTS))
    );
    let best = side["best_epoch"].as_u64().unwrap() as usize;
    assert_eq!(side["final"]["val"], side["history"][best - 1]["val"], "final = the kept epoch");
    // The held-out figures: both methods, every bucket, and the verdict agrees with them.
    let h = &side["heldout"]["chamfer_l1"];
    let (net, identity) =
        (h["all"]["net"]["l1"].as_f64().unwrap(), h["all"]["identity"]["l1"].as_f64().unwrap());
    assert_eq!(side["heldout"]["beats_identity"], net < identity);
    assert_eq!(side["beats_identity"]["heldout"], net < identity);
    let buckets = h["buckets"].as_object().unwrap();
    assert!(!buckets.is_empty());
    let cases: u64 = buckets.values().map(|b| b["cases"].as_u64().unwrap()).sum();
    assert_eq!(cases, h["all"]["cases"].as_u64().unwrap(), "buckets partition the held-out cases");

    let mut backend = NetCompletion::builtin().expect("the shipped weights load");
    let mesh = objview_geom::synth::build_with_triangles("mug", 5000);
    let cams = objview_dataset::annotate::GridViews::new(3.0).unwrap().planning().to_vec();
    let partial =
        objview_learn::completion_data::fused_partial(&mesh, &cams, &[0, 64], &mut Default::default());
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
    let out = complete(&mut backend, &partial, &mut rng).unwrap();
    assert_eq!(out.predicted, NET_PREDICTED_POINTS);
    assert!(out.points.iter().all(|p| p.iter().all(|x| x.is_finite())));

    let dir = tempfile::tempdir().unwrap();
    objview_geom::synth::write_pool(&dir.path().join("builtins")).unwrap();
    let data = dir.path().join("c");
    let plan = DatasetPlan {
        inputs: ["mug", "vase"]
            .iter()
            .map(|n| dir.path().join("builtins").join(format!("{n}.obj")))
            .collect(),
        out: data.clone(),
        settings: DatasetSettings { method: Method::Completion, ..Default::default() },
        threads: Some(2),
        shard: Shard::ALL,
        retry_failed: false,
        command: "test".into(),
    };
    plan.run(&Silent).unwrap();
    let e = objview_learn::completion_train::eval_completion_weights("builtin", &data).unwrap();
    assert_eq!(e["cases"], 16);
    let all = &e["chamfer_l1"]["all"];
    for k in ["net", "net_fine", "identity"] {
        let v = all[k]["l1"].as_f64().unwrap();
        assert!(v.is_finite() && v > 0.0, "{k}: {v}");
    }
}
