//! `objview learn dataset|train|eval` and `run --planner nbv-net` end to end, with the flags
//! and output fields the README promises: a dataset of two small objects, a one-epoch training
//! with its sidecar, its evaluation, an episode with those weights, a resumed dataset run, and
//! one-line errors for bad input.

mod common;

use common::{objview_err, objview_ok, s, tempdir};
use serde_json::Value;

#[test]
fn dataset_train_eval_and_run_with_the_trained_weights() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "2", "--seed", "4", "--out", s(&pool)]);
    let data = dir.path().join("data");
    let out = objview_ok(&[
        "learn",
        "dataset",
        s(&pool),
        "--method",
        "nbv-net",
        "--out",
        s(&data),
        "--threads",
        "2",
    ]);
    assert!(out.contains("2 done, 0 failed"), "{out}");
    let m: Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["format"], "objview-learn-dataset");
    assert_eq!(m["objects"], 2);
    assert_eq!(m["settings"]["pool"]["seed"], 4, "the pool's synth.json is recorded");
    assert!(m["command"].as_str().unwrap().contains("learn dataset"));
    // Resumed: nothing to do.
    let again = objview_ok(&["learn", "dataset", s(&pool), "--method", "nbv-net", "--out", s(&data)]);
    assert!(again.contains("0 done, 0 failed, 2 skipped"), "{again}");

    let w = dir.path().join("w.safetensors");
    let out = objview_ok(&[
        "learn",
        "train",
        "nbv-net",
        "--data",
        s(&data),
        "--out",
        s(&w),
        "--epochs",
        "1",
        "--grid",
        "16",
        "--max-cases",
        "16",
        "--val-fraction",
        "0",
        "--seed",
        "3",
    ]);
    assert!(out.contains("best epoch 1"), "{out}");
    let side: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("w.json")).unwrap()).unwrap();
    for key in ["command", "data", "settings", "history", "final", "deviation", "version", "weights_fnv1a64"]
    {
        assert!(!side[key].is_null(), "sidecar field {key}");
    }
    assert_eq!(side["settings"]["grid"], 16);
    assert_eq!(side["data"]["cases"], m["cases"]);

    let eval = objview_ok(&["learn", "eval", s(&w), "--data", s(&data)]);
    let e: Value = serde_json::from_str(&eval).unwrap();
    assert_eq!(e["cases"], m["cases"]);
    let acc = e["agreement"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&acc));

    let res = dir.path().join("r.jsonl");
    let weights = format!("weights={}", w.display());
    objview_ok(&[
        "run",
        "--planner",
        "nbv-net",
        "--param",
        &weights,
        "--objects",
        s(&pool),
        "--budget",
        "5",
        "--cap",
        "6",
        "--checkpoints",
        "5",
        "--out",
        s(&res),
        "--no-timings",
        "--quiet",
    ]);
    let lines: Vec<Value> =
        std::fs::read_to_string(&res).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2);
    for l in &lines {
        assert_eq!(l["method"], "nbv-net");
        assert_eq!(l["family"], "learned");
        assert_eq!(l["settings"]["planner_params"]["network"]["grid"], 16, "{}", l["settings"]);
    }
}

#[test]
fn bad_input_is_a_one_line_error() {
    let dir = tempdir();
    let err = objview_err(&[
        "learn",
        "train",
        "nbv-net",
        "--data",
        s(dir.path()),
        "--out",
        s(&dir.path().join("w.safetensors")),
    ]);
    assert!(err.contains("manifest.json"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let err =
        objview_err(&["learn", "train", "other-net", "--data", s(dir.path()), "--out", "w.safetensors"]);
    assert!(err.contains("unknown network"), "{err}");
    let err = objview_err(&[
        "run",
        "--planner",
        "nbv-net",
        "--param",
        "weights=/nonexistent.safetensors",
        "--objects",
        s(dir.path()),
        "--out",
        s(&dir.path().join("r.jsonl")),
    ]);
    assert!(err.contains("/nonexistent.safetensors"), "{err}");
}

/// The Slurm array script, run as two array tasks would run it: each shard writes its own
/// objects file into one folder and the manifest covers both; the union is the unsharded run.
#[test]
fn slurm_shards_merge_into_one_dataset() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "3", "--seed", "5", "--out", s(&pool)]);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scripts/learn-dataset.sbatch");
    let data = dir.path().join("data");
    for i in 0..2 {
        let st = std::process::Command::new("bash")
            .args([script, s(&pool), s(&data)])
            .env("SLURM_ARRAY_TASK_ID", i.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "2")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("OBJVIEW", env!("CARGO_BIN_EXE_objview"))
            .status()
            .unwrap();
        assert!(st.success());
    }
    let m: Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["objects"], 3, "{m}");
    assert_eq!(m["objects_files"].as_array().unwrap().len(), 2);
    let whole = dir.path().join("whole");
    objview_ok(&["learn", "dataset", s(&pool), "--method", "nbv-net", "--out", s(&whole)]);
    let w: Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(w["cases"], m["cases"]);
    let mut a: Vec<String> =
        m["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().into()).collect();
    let mut b: Vec<String> =
        w["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().into()).collect();
    a.sort();
    b.sort();
    assert_eq!(a, b);
    for f in &a {
        assert!(
            common::read(&data.join(f)) == common::read(&whole.join(f)),
            "{f}: same bytes sharded or not"
        );
    }
}

/// `learn dataset --method ma-scvp`, `learn train ma-scvp` (a tiny shape, one epoch) with its
/// sidecar, and `run --planner ma-scvp` with those weights, end to end.
#[test]
fn mascvp_dataset_train_and_run() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "1", "--seed", "4", "--out", s(&pool)]);
    let data = dir.path().join("data");
    objview_ok(&["learn", "dataset", s(&pool), "--method", "ma-scvp", "--out", s(&data), "--threads", "2"]);
    let w = dir.path().join("m.safetensors");
    let out = objview_ok(&[
        "learn",
        "train",
        "ma-scvp",
        "--data",
        s(&data),
        "--out",
        s(&w),
        "--epochs",
        "1",
        "--grid",
        "16",
        "--widths",
        "2,2,2,4",
        "--fc",
        "16",
        "--max-cases",
        "8",
        "--val-fraction",
        "0",
        "--seed",
        "3",
    ]);
    assert!(out.contains("learn train ma-scvp: best epoch 1"), "{out}");
    let side: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("m.json")).unwrap()).unwrap();
    assert_eq!(side["network"], "ma-scvp");
    assert_eq!(side["settings"]["shape"]["blocks"], serde_json::json!([2, 2, 4]));
    assert_eq!(side["settings"]["lr"], 1e-4, "MA-SCVP's default learning rate");
    assert!(side["deviation"].as_str().unwrap().contains("16^3"));
    assert!(side["baseline"]["k"].is_u64() && side["beats_baseline"].is_boolean());
    let err =
        objview_err(&["learn", "train", "ma-scvp", "--data", s(&data), "--out", s(&w), "--widths", "2,2,2"]);
    assert!(err.contains("--widths needs four numbers"), "{err}");

    let results = dir.path().join("r.jsonl");
    let weights = format!("weights={}", w.display());
    objview_ok(&[
        "run",
        "--planner",
        "ma-scvp",
        "--param",
        &weights,
        "--objects",
        s(&pool),
        "--out",
        s(&results),
    ]);
    let line: Value =
        serde_json::from_str(std::fs::read_to_string(&results).unwrap().lines().next().unwrap()).unwrap();
    assert_eq!(line["method"], "ma-scvp");
    assert_eq!(line["execution_mode"], "set_cover_plan");
    let reason = line["terminal_reason"].as_str().unwrap();
    assert!(["plan_end", "candidate_exhausted"].contains(&reason), "{reason}");
}
