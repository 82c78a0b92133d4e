//! The shipped NBV-Net weights: they load, their sidecar records what produced them, and
//! their top-1 agreement with the oracle labels of the fixed held-out set (eight built-in
//! objects, regenerated here with the dataset command's settings) is exactly what the sidecar
//! says.

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
