//! End-to-end test of the main job (`objview demo`) on a few built-in objects: every stage
//! writes its outputs (episodes and report included), and a re-run resumes the annotation and
//! the episodes instead of redoing them.

mod common;

use common::{objview_ok, s, tempdir};
use serde_json::Value;

#[test]
fn demo_runs_every_stage_and_resumes() {
    let dir = tempdir();
    let out = dir.path().join("demo");
    let args = ["demo", "--out", s(&out), "--objects", "cube,cone,mug,chair", "--test-fraction", "0.5"];
    let stdout = objview_ok(&args);
    for stage in
        ["[1/8]", "[2/8]", "[3/8]", "[4/8]", "[5/8]", "[6/8]", "[7/8]", "[8/8]", "Table 2", "demo finished"]
    {
        assert!(stdout.contains(stage), "missing {stage} in:\n{stdout}");
    }
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["objects"].as_array().unwrap().len(), 4);
    let ann = std::fs::read_to_string(out.join("annotations.jsonl")).unwrap();
    let lines: Vec<Value> = ann.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let uids: Vec<&str> = lines.iter().map(|v| v["uid"].as_str().unwrap()).collect();
    assert_eq!(uids, ["cube", "cone", "mug", "chair"]); // catalog order
    assert!(lines.iter().all(|v| v["d_plan_status"] == "optimal"), "{ann}");
    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("splits/split_report.json")).unwrap()).unwrap();
    assert!(report.is_object());
    for f in
        ["slow_saturation", "main_hidden_test", "main_train_public", "main_raw_train", "main_balanced_train"]
    {
        let v: Value =
            serde_json::from_slice(&std::fs::read(out.join(format!("splits/{f}.json"))).unwrap()).unwrap();
        assert!(v.is_array(), "{f}");
    }
    for f in ["fig2a_saturation", "fig2b_dplan_hist", "fig2c_dsat_vs_dplan"] {
        for ext in ["png", "svg"] {
            assert!(out.join(format!("figures/{f}.{ext}")).is_file(), "{f}.{ext}");
        }
    }
    // Episodes: every classical planner in both spaces, the learned nbv-net (shipped weights),
    // and the oracle.
    for f in [
        "nbv-net_whole_auto",
        "nbv-net_quarter_auto",
        "random-tsp_whole_5",
        "random-tsp_whole_30",
        "rse_whole_auto",
        "rse-mov_whole_auto",
        "random-tsp_quarter_5",
        "rse_quarter_auto",
        "oracle_whole_tammes128_test",
    ] {
        let text = std::fs::read_to_string(out.join(format!("episodes/{f}.jsonl"))).unwrap();
        let eps: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert!(!eps.is_empty(), "{f}");
        assert!(
            eps.iter().all(|e| e.get("error").is_none() && e["checkpoints"].get("terminal").is_some()),
            "{f}"
        );
    }
    // The hybrids run with their default completion, the shipped `net`, named in the method.
    for (f, method) in [
        ("completion-scp_whole_auto", "completion-scp[net]"),
        ("completion-mcp_whole_5", "completion-mcp[net]"),
        ("completion-nbv_whole_auto", "completion-nbv[net]"),
    ] {
        let text = std::fs::read_to_string(out.join(format!("episodes/{f}.jsonl"))).unwrap();
        let eps: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert!(!eps.is_empty(), "{f}");
        for e in &eps {
            assert!(e.get("error").is_none(), "{f}: {e}");
            assert_eq!(e["method"], method, "{f}");
            assert_eq!(e["settings"]["planner_params"]["completion_model"]["weights"], "builtin", "{f}");
        }
    }
    let md = std::fs::read_to_string(out.join("report/report.md")).unwrap();
    for t in [
        "Table 2",
        "Table 3",
        "Table 4",
        "Table 5",
        "rse-mov",
        "random-tsp",
        "nbv-net",
        "completion-scp[net]",
    ] {
        assert!(md.contains(t), "report lacks {t}");
    }
    let episodes = std::fs::read_to_string(out.join("episodes/rse_whole_auto.jsonl")).unwrap();
    // A second run keeps the annotations and the episodes and skips them.
    let stdout = objview_ok(&args);
    assert!(stdout.contains("0 done, 0 failed, 4 skipped"), "{stdout}");
    assert_eq!(std::fs::read_to_string(out.join("annotations.jsonl")).unwrap(), ann);
    assert_eq!(std::fs::read_to_string(out.join("episodes/rse_whole_auto.jsonl")).unwrap(), episodes);
    assert!(
        stdout.contains("0 episodes (0 failed, 1 already done)") || stdout.contains("already done)"),
        "{stdout}"
    );
}
