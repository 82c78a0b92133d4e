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

/// `learn dataset --method completion`, `learn train completion` (a tiny network, one epoch),
/// `learn eval` on completion data, and `run --planner completion-scp --param completion=net`
/// with those weights; the planner's default backend is `net` (the shipped weights).
#[test]
fn completion_dataset_train_eval_and_run() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "2", "--seed", "4", "--out", s(&pool)]);
    let data = dir.path().join("data");
    let out = objview_ok(&[
        "learn",
        "dataset",
        s(&pool),
        "--method",
        "completion",
        "--partials",
        "3",
        "--gt-points",
        "1024",
        "--out",
        s(&data),
        "--threads",
        "2",
    ]);
    assert!(out.contains("2 done, 0 failed"), "{out}");
    let m: Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json")).unwrap()).unwrap();
    assert_eq!((m["method"].as_str(), m["cases"].as_u64()), (Some("completion"), Some(6)));
    assert_eq!(m["settings"]["gt_points"], 1024);
    let w = dir.path().join("c.safetensors");
    let out = objview_ok(&[
        "learn",
        "train",
        "completion",
        "--data",
        s(&data),
        "--out",
        s(&w),
        "--epochs",
        "1",
        "--encoder",
        "8,8,8,8",
        "--coarse-fc",
        "16",
        "--fold-width",
        "8",
        "--loss-gt-points",
        "256",
        "--val-fraction",
        "0",
        "--seed",
        "3",
    ]);
    assert!(out.contains("learn train completion: best epoch 1"), "{out}");
    let side: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("c.json")).unwrap()).unwrap();
    assert_eq!(side["network"], "completion");
    assert_eq!(side["settings"]["shape"]["encoder"], serde_json::json!([8, 8, 8, 8]));
    assert_eq!(side["settings"]["lr"], 1e-3, "the completion default learning rate");
    assert!(side["deviation"].as_str().unwrap().contains("PoinTr"));
    assert!(side["data"]["dataset_command"].as_str().unwrap().contains("--method completion"));
    let err = objview_err(&[
        "learn",
        "train",
        "completion",
        "--data",
        s(&data),
        "--out",
        s(&w),
        "--encoder",
        "8,8",
    ]);
    assert!(err.contains("--encoder needs four numbers"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let err =
        objview_err(&["learn", "train", "nbv-net", "--data", s(&data), "--out", s(&w), "--fold-width", "8"]);
    assert!(err.contains("completion options"), "{err}");

    let eval: Value =
        serde_json::from_str(&objview_ok(&["learn", "eval", s(&w), "--data", s(&data)])).unwrap();
    assert_eq!(eval["cases"], 6);
    let all = &eval["chamfer_l1"]["all"];
    assert!(all["net"]["l1"].as_f64().unwrap() > 0.0 && all["identity"]["l1"].as_f64().unwrap() > 0.0);
    assert!(eval["beats_identity"].is_boolean());

    for (params, method) in [
        (
            vec!["completion=net".to_string(), format!("completion_weights={}", w.display())],
            "completion-scp[net]",
        ),
        (vec![], "completion-scp[net]"),
        (vec!["completion=identity".to_string()], "completion-scp[identity]"),
    ] {
        let res = dir.path().join(format!("r-{}.jsonl", params.len()));
        let mut args =
            vec!["run", "--planner", "completion-scp", "--objects", s(&pool), "--out", s(&res), "--quiet"];
        for p in &params {
            args.extend(["--param", p.as_str()]);
        }
        objview_ok(&args);
        let lines: Vec<Value> = std::fs::read_to_string(&res)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        for l in &lines {
            assert_eq!(l["method"], method, "{params:?}");
            assert_eq!(l["family"], "hybrid");
            let model = &l["settings"]["planner_params"]["completion_model"];
            if method.ends_with("[net]") {
                let want = if params.is_empty() { "builtin".to_string() } else { w.display().to_string() };
                assert_eq!(model["weights"], want.as_str(), "{}", l["settings"]);
            } else {
                assert!(model.is_null());
            }
        }
    }
    let err = objview_err(&[
        "run",
        "--planner",
        "completion-nbv",
        "--param",
        "completion_weights=/nonexistent.safetensors",
        "--objects",
        s(&pool),
        "--out",
        s(&dir.path().join("bad.jsonl")),
    ]);
    assert!(err.contains("/nonexistent.safetensors"), "{err}");
}

/// `learn experiment difficulty-aware` end to end on a small annotated pool (tiny network, one
/// epoch): the splits (equal subset sizes, analysis objects in neither subset), per-object VC
/// lines over 128 starts, the summary and Figure 4; a re-run resumes every stage; other
/// settings in the same folder are refused naming the difference; `objview report
/// --difficulty-aware` draws the figure from the folder.
#[test]
fn difficulty_aware_experiment_end_to_end() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "10", "--seed", "4", "--out", s(&pool)]);
    let ann = dir.path().join("ann.jsonl");
    objview_ok(&["annotate", s(&pool), "--out", s(&ann), "--threads", "2"]);
    let out = dir.path().join("exp");
    let args = |extra: &[&'static str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "learn",
            "experiment",
            "difficulty-aware",
            s(&ann),
            "--out",
            s(&out),
            "--size",
            "3",
            "--analysis",
            "2",
            "--epochs",
            "1",
            "--grid",
            "16",
            "--data-grid",
            "16",
            "--widths",
            "2,2,2,4",
            "--fc",
            "16",
            "--need-case-1",
            "4",
            "--time-limit",
            "2",
            "--val-fraction",
            "0",
            "--threads",
            "2",
        ]
        .iter()
        .map(|x| x.to_string())
        .collect();
        v.extend(extra.iter().map(|x| x.to_string()));
        v
    };
    let run = |extra: &[&'static str]| {
        let a = args(extra);
        objview_ok(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let first = run(&[]);
    assert!(first.contains("## Difficulty-aware training (Figure 4)"), "{first}");
    let summary: Value = serde_json::from_slice(&common::read(&out.join("summary.json"))).unwrap();
    assert_eq!(summary["subsets"]["raw"]["objects"], 3);
    assert_eq!(summary["subsets"]["balanced"]["objects"], 3);
    assert_eq!(summary["analysis_objects"], 2);
    assert!(summary["settings"]["deviation"].as_str().unwrap().contains("16^3"));
    let uids = |k: &str| -> Vec<String> {
        summary["subsets"][k]["uids"]
            .as_array()
            .unwrap()
            .iter()
            .map(|u| u.as_str().unwrap().to_string())
            .collect()
    };
    let train: std::collections::BTreeSet<String> = uids("raw").into_iter().chain(uids("balanced")).collect();
    assert!(uids("analysis").iter().all(|u| !train.contains(u)), "analysis objects are held out");
    let vc = std::fs::read_to_string(out.join("vc.jsonl")).unwrap();
    assert_eq!(vc.lines().count(), 2);
    for l in vc.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        assert!(uids("analysis").contains(&v["uid"].as_str().unwrap().to_string()));
        for m in ["raw", "balanced"] {
            let per: Vec<f64> =
                v["models"][m]["vc"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            assert_eq!(per.len(), 128, "one VC per start view");
            assert!(per.iter().all(|x| (0.0..=1.0).contains(x)));
            let mean = per.iter().sum::<f64>() / 128.0;
            assert!((mean - v["models"][m]["vc_mean"].as_f64().unwrap()).abs() < 1e-12);
            let gap = v["models"][m]["vc_gap"].as_f64().unwrap();
            assert!((gap - (1.0 - mean)).abs() < 1e-12);
        }
        assert!(v["gt_total_mean"].as_f64().unwrap() >= 2.0, "start view + at least one cover view");
    }
    for f in [
        "figure4_difficulty_aware.png",
        "figure4_difficulty_aware.svg",
        "difficulty_aware.md",
        "models/raw.json",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let raw_side: Value = serde_json::from_slice(&common::read(&out.join("models/raw.json"))).unwrap();
    let raw_subset: Vec<String> = raw_side["data"]["subset"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| u.as_str().unwrap().to_string())
        .collect();
    assert_eq!(raw_subset, uids("raw"), "the raw model saw exactly Main-Raw-Train");

    // Resumed: nothing is generated, trained or analysed again; the summary's numbers stay.
    let before: Vec<Vec<u8>> = ["vc.jsonl", "data/objects.jsonl", "models/raw.safetensors"]
        .iter()
        .map(|f| common::read(&out.join(f)))
        .collect();
    let again = run(&[]);
    assert!(again.contains("## Difficulty-aware training"), "{again}");
    for (f, b) in ["vc.jsonl", "data/objects.jsonl", "models/raw.safetensors"].iter().zip(&before) {
        assert_eq!(&common::read(&out.join(f)), b, "{f} is kept as it was");
    }
    let s2: Value = serde_json::from_slice(&common::read(&out.join("summary.json"))).unwrap();
    assert_eq!(s2["buckets"], summary["buckets"]);
    assert_eq!(s2["models"]["raw"]["weights_fnv1a64"], summary["models"]["raw"]["weights_fnv1a64"]);

    let a = args(&["--gamma", "0.4"]);
    let err = objview_err(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(err.contains("other settings") && err.contains("gamma"), "{err}");

    let rep = dir.path().join("report");
    let printed = objview_ok(&["report", "--difficulty-aware", s(&out), "--out", s(&rep)]);
    assert!(printed.contains("| d_plan bucket |"), "{printed}");
    assert!(rep.join("figure4_difficulty_aware.png").is_file() && rep.join("difficulty_aware.md").is_file());
    assert_eq!(
        common::read(&rep.join("difficulty_aware.md")),
        common::read(&out.join("difficulty_aware.md"))
    );
}
