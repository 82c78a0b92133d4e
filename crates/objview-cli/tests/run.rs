//! End-to-end tests of `objview run` and `objview report`: result lines with the contract's
//! fields, resume after a crash, byte-identical reruns, failure lines that do not stop the
//! batch, refusal to mix runs in one file, random-tsp budgets, and a report over the results.

mod common;

use common::{objview, objview_err, objview_ok, s, tempdir};
use serde_json::Value;

fn write_objects(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let objs = dir.join("objects");
    objview_ok(&["objects", "synth", "--out", s(&objs)]);
    vec![objs.join("cube.obj"), objs.join("cone.obj")]
}

fn lines(p: &std::path::Path) -> Vec<Value> {
    std::fs::read_to_string(p).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

#[test]
fn run_writes_contract_fields_resumes_and_is_deterministic() {
    let dir = tempdir();
    let objs = write_objects(dir.path());
    let cache = dir.path().join("cache");
    let out = dir.path().join("tsp.jsonl");
    let base = |out: &std::path::Path| -> Vec<String> {
        vec![
            "run",
            "--planner",
            "random-tsp",
            "--space",
            "quarter",
            "--budget",
            "5",
            "--objects",
            s(&objs[0]),
            s(&objs[1]),
            "--out",
            s(out),
            "--cache-dir",
            s(&cache),
            "--seed",
            "7",
            "--no-timings",
            "--quiet",
        ]
        .into_iter()
        .map(String::from)
        .collect()
    };
    let args = base(&out);
    let a: Vec<&str> = args.iter().map(|x| x.as_str()).collect();
    objview_ok(&a);
    let v = lines(&out);
    assert_eq!(v.len(), 2);
    for e in &v {
        for f in [
            "settings",
            "uid",
            "method",
            "family",
            "execution_mode",
            "view_space",
            "budget",
            "seed",
            "start_pose",
            "visited_poses",
            "terminal_source",
            "terminal_reason",
            "steps",
            "checkpoints",
        ] {
            assert!(e.get(f).is_some(), "missing field {f}");
        }
        assert_eq!(e["method"], "random-tsp");
        assert_eq!(e["family"], "classical");
        assert_eq!(e["execution_mode"], "budgeted_plan");
        assert_eq!(e["view_space"], "quarter");
        assert_eq!(e["budget"], "5");
        assert_eq!(e["terminal_reason"], "plan_end");
        assert_eq!(e["terminal_source"], "algorithm_stop");
        let poses = e["visited_poses"].as_array().unwrap();
        assert_eq!(poses.len(), 6, "start + K = 5");
        assert_eq!(poses[0], e["start_pose"]);
        for p in poses {
            let p: Vec<f64> = p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            assert_eq!(p.len(), 7);
            // quarter: z >= 0 and y >= 0.
            assert!(p[1] >= 0.0 && p[2] >= 0.0, "{p:?}");
        }
        let cp = &e["checkpoints"];
        for k in ["K=5", "terminal"] {
            let c = &cp[k];
            assert_eq!(c["views"], 6, "{k}");
            for t in ["0.01", "0.02", "0.03"] {
                let (sc, nsc) = (c["sc"][t].as_f64().unwrap(), c["nsc"][t].as_f64().unwrap());
                assert!((0.0..=1.0).contains(&sc) && (0.0..=1.0).contains(&nsc));
                assert!(nsc >= sc - 1e-12, "NSC normalizes by what quarter can see");
            }
            assert!(c["cd"].as_f64().unwrap() > 0.0);
            assert!(c["path_cost"].as_f64().unwrap() > 0.0);
            assert_eq!(c["runtime"].as_f64().unwrap(), 0.0, "--no-timings");
        }
        assert!(cp.get("K=10").is_none());
        assert_eq!(e["steps"].as_array().unwrap().len(), 6);
    }
    // Resume after a crash that left one and a half lines: the same file comes back.
    let full = std::fs::read_to_string(&out).unwrap();
    let first_len = full.find('\n').unwrap() + 1;
    std::fs::write(&out, &full[..first_len + 40]).unwrap();
    let o = objview(&a);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{}: cut off a torn last line (an interrupted write); that object is redone",
            s(&out)
        )),
        "a torn line is dropped silently: {stderr}"
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), full);
    // A complete file: nothing to say.
    let o = objview(&a);
    assert!(!String::from_utf8_lossy(&o.stderr).contains("torn"));
    // A fresh rerun (cached reference) is byte-identical; so is one without the cache.
    let out2 = dir.path().join("tsp2.jsonl");
    let mut args2 = base(&out2);
    args2.push("--no-cache".into());
    let a2: Vec<&str> = args2.iter().map(|x| x.as_str()).collect();
    objview_ok(&a2);
    assert_eq!(std::fs::read_to_string(&out2).unwrap(), full);
    // Another planner into the same file is refused.
    let mut args3 = base(&out);
    args3[2] = "random".into();
    let a3: Vec<&str> = args3.iter().map(|x| x.as_str()).collect();
    let err = objview_err(&a3);
    assert!(err.contains("another run"), "{err}");
}

#[test]
fn bad_objects_are_recorded_and_the_batch_goes_on() {
    let dir = tempdir();
    let objs = write_objects(dir.path());
    let bad = dir.path().join("broken.obj");
    std::fs::write(&bad, "v 0 0 0\nf 1 2 3\n").unwrap();
    let out = dir.path().join("r.jsonl");
    let o = objview(&[
        "run",
        "--planner",
        "random",
        "--budget",
        "auto",
        "--objects",
        s(&bad),
        s(&objs[0]),
        "--out",
        s(&out),
        "--no-cache",
        "--cap",
        "4",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = lines(&out);
    assert_eq!(v.len(), 2);
    assert_eq!(v[0]["uid"], "broken");
    assert!(v[0]["error"].as_str().unwrap().contains("broken.obj"), "{}", v[0]);
    assert_eq!(v[1]["terminal_reason"], "max_cap_reached");
    assert_eq!(v[1]["visited_poses"].as_array().unwrap().len(), 4);
}

#[test]
fn budget_and_planner_errors_are_clear() {
    let dir = tempdir();
    let objs = write_objects(dir.path());
    let out = dir.path().join("x.jsonl");
    let err = objview_err(&[
        "run",
        "--planner",
        "random-tsp",
        "--budget",
        "auto",
        "--objects",
        s(&objs[0]),
        "--out",
        s(&out),
    ]);
    assert!(err.contains("budgeted plan"), "{err}");
    let err = objview_err(&["run", "--planner", "nbv", "--objects", s(&objs[0]), "--out", s(&out)]);
    assert!(err.contains("unknown planner"), "{err}");
    let err = objview_err(&[
        "run",
        "--planner",
        "rse",
        "--budget",
        "0",
        "--objects",
        s(&objs[0]),
        "--out",
        s(&out),
    ]);
    assert!(err.contains("--budget"), "{err}");
    let err = objview_err(&[
        "run",
        "--planner",
        "rse",
        "--space",
        "nowhere",
        "--objects",
        s(&objs[0]),
        "--out",
        s(&out),
    ]);
    assert!(err.contains("nowhere"), "{err}");
}

#[test]
fn report_reads_runs_and_writes_tables() {
    let dir = tempdir();
    let objs = write_objects(dir.path());
    let cache = dir.path().join("cache");
    let mut files = Vec::new();
    for (planner, budget, space) in [
        ("random-tsp", "5", "whole"),
        ("random-tsp", "5", "quarter"),
        ("random", "auto", "whole"),
        ("random", "auto", "quarter"),
    ] {
        let out = dir.path().join(format!("{planner}_{space}_{budget}.jsonl"));
        objview_ok(&[
            "run",
            "--planner",
            planner,
            "--space",
            space,
            "--budget",
            budget,
            "--objects",
            s(&objs[0]),
            s(&objs[1]),
            "--out",
            s(&out),
            "--cache-dir",
            s(&cache),
            "--no-timings",
            "--quiet",
        ]);
        files.push(out);
    }
    let rep = dir.path().join("report");
    let mut args = vec!["report".to_string()];
    args.extend(files.iter().map(|f| s(f).to_string()));
    args.extend(["--out".into(), s(&rep).into()]);
    let a: Vec<&str> = args.iter().map(|x| x.as_str()).collect();
    let stdout = objview_ok(&a);
    assert!(stdout.contains("Table 2") && stdout.contains("Table 4"), "{stdout}");
    assert!(stdout.contains("random-tsp"), "{stdout}");
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.contains("random-tsp") && md.contains("quarter"));
    assert!(std::fs::read_dir(&rep).unwrap().any(|e| e
        .unwrap()
        .path()
        .extension()
        .is_some_and(|x| x == "png")));
    // Same inputs, same bytes.
    let rep2 = dir.path().join("report2");
    let args2: Vec<String> =
        args.iter().map(|x| if x == s(&rep) { s(&rep2).to_string() } else { x.clone() }).collect();
    let a2: Vec<&str> = args2.iter().map(|x| x.as_str()).collect();
    objview_ok(&a2);
    assert_eq!(std::fs::read(rep.join("report.md")).unwrap(), std::fs::read(rep2.join("report.md")).unwrap());
}

#[test]
fn start_poses_beyond_the_bound_are_refused_and_blind_ones_fail_their_objects() {
    let dir = tempdir();
    let objs = write_objects(dir.path());
    let out = dir.path().join("start.jsonl");
    let args = |pose: &str| -> Vec<String> {
        [
            "run",
            "--planner",
            "random",
            "--budget",
            "auto",
            "--objects",
            s(&objs[0]),
            "--out",
            s(&out),
            "--no-cache",
            "--cap",
            "3",
            "--quiet",
            "--start-pose",
            pose,
        ]
        .iter()
        .map(|x| x.to_string())
        .collect()
    };
    let run = |pose: &str| {
        let a = args(pose);
        objview(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    // Huge but finite: a clear error naming the flag and the bound; nothing is written.
    let o = run("1e300,1e300,1e300,0,0,0,0");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("--start-pose") && err.contains("camera centre is 1.732e300 object units"), "{err}");
    assert!(err.contains("at most 100"), "{err}");
    assert!(!out.exists());
    let o = run("3,0,0,0,0,500,0");
    assert!(String::from_utf8_lossy(&o.stderr).contains("look-at point is 500.000"));
    // Feasible and within the bound, but looking away from the object: the object's line is a
    // failure saying why, never a result with `"cd": null`.
    let o = run("3,0,0,6,0,0,0");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(!text.contains("null"), "{text}");
    let v = lines(&out);
    assert_eq!(v.len(), 1);
    assert!(v[0]["error"].as_str().unwrap().contains("sees nothing of object cube"), "{}", v[0]);
}

/// `run --shard I/N` through the Slurm script, as array tasks run it: the shards partition the
/// objects by the uid hash of `annotate --shard`, their files concatenated hold exactly the
/// lines of the unsharded run, and `report` takes the concatenation.
#[test]
fn sharded_runs_merge_by_cat_into_the_whole_run() {
    let dir = tempdir();
    let objs = dir.path().join("objects");
    objview_ok(&["objects", "synth", "--out", s(&objs)]);
    let picked: Vec<String> = ["cube", "cone", "sphere", "octahedron"]
        .iter()
        .map(|n| s(&objs.join(format!("{n}.obj"))).to_string())
        .collect();
    let cache = dir.path().join("cache");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scripts/run.sbatch");
    let shards = dir.path().join("shards");
    // The script takes one --objects input: a split file of the four objects.
    let split = dir.path().join("four.json");
    let entries: Vec<Value> = picked
        .iter()
        .map(|p| serde_json::json!({"uid": std::path::Path::new(p).file_stem().unwrap().to_str().unwrap(), "mesh": p}))
        .collect();
    std::fs::write(&split, serde_json::to_string(&entries).unwrap()).unwrap();
    for i in 0..3 {
        let st = std::process::Command::new("bash")
            .args([
                script,
                s(&split),
                s(&shards),
                "random-tsp",
                "whole",
                "5",
                "--cache-dir",
                s(&cache),
                "--no-timings",
            ])
            .env("SLURM_ARRAY_TASK_ID", i.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "3")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("OBJVIEW", env!("CARGO_BIN_EXE_objview"))
            .status()
            .unwrap();
        assert!(st.success());
    }
    let mut merged = String::new();
    for i in 0..3 {
        merged +=
            &std::fs::read_to_string(shards.join(format!("random-tsp_whole_5.shard-{i}.jsonl"))).unwrap();
    }
    let cat = dir.path().join("cat.jsonl");
    std::fs::write(&cat, &merged).unwrap();
    let whole = dir.path().join("whole.jsonl");
    objview_ok(&[
        "run",
        "--planner",
        "random-tsp",
        "--budget",
        "5",
        "--objects",
        s(&split),
        "--out",
        s(&whole),
        "--cache-dir",
        s(&cache),
        "--no-timings",
        "--quiet",
    ]);
    let sorted = |text: &str| -> Vec<String> {
        let mut v: Vec<String> = text.lines().map(String::from).collect();
        v.sort();
        v
    };
    assert_eq!(sorted(&merged), sorted(&std::fs::read_to_string(&whole).unwrap()), "byte-identical lines");
    assert_eq!(merged.lines().count(), 4);
    let report = dir.path().join("report");
    objview_ok(&["report", s(&cat), "--out", s(&report), "--no-plots"]);
    assert!(std::fs::read_to_string(report.join("report.md")).unwrap().contains("random-tsp"));
    let err = objview_err(&[
        "run",
        "--planner",
        "random",
        "--objects",
        "x",
        "--out",
        "y.jsonl",
        "--server",
        "http://127.0.0.1:9",
        "--shard",
        "0/2",
    ]);
    assert!(err.contains("--shard"), "{err}");
}

/// The campaign script, as two array tasks run it over two planners (one iterative, one
/// budgeted) and both view spaces: every (planner, space, budget) the protocol needs gets one
/// shard file per task, the shards partition the objects, and `report` takes their
/// concatenation with the K=5, K=30 and automatic settings.
#[test]
fn the_campaign_script_runs_every_setting_per_shard() {
    let dir = tempdir();
    let objs = dir.path().join("objects");
    objview_ok(&["objects", "synth", "--out", s(&objs)]);
    let entries: Vec<Value> = ["cube", "cone", "sphere"]
        .iter()
        .map(|n| serde_json::json!({"uid": n, "mesh": s(&objs.join(format!("{n}.obj")))}))
        .collect();
    let split = dir.path().join("three.json");
    std::fs::write(&split, serde_json::to_string(&entries).unwrap()).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scripts/campaign.sbatch");
    let out = dir.path().join("campaign");
    let cache = dir.path().join("cache");
    for i in 0..2 {
        let o = std::process::Command::new("bash")
            .args([script, s(&split), s(&out), "--cache-dir", s(&cache), "--no-timings"])
            .env("SLURM_ARRAY_TASK_ID", i.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "2")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("CAMPAIGN_PLANNERS", "random random-tsp")
            .env("OBJVIEW", env!("CARGO_BIN_EXE_objview"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let log = String::from_utf8_lossy(&o.stdout);
        assert!(log.contains(&format!("campaign: shard {i}/2 done in")), "{log}");
    }
    let mut names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    let mut want = Vec::new();
    for (planner, budgets) in [("random", &["auto"][..]), ("random-tsp", &["30", "5"][..])] {
        for space in ["quarter", "whole"] {
            for b in budgets {
                for i in 0..2 {
                    want.push(format!("{planner}_{space}_{b}.shard-{i}.jsonl"));
                }
            }
        }
    }
    want.sort();
    assert_eq!(names, want);
    let mut merged = String::new();
    for n in &names {
        merged += &std::fs::read_to_string(out.join(n)).unwrap();
    }
    // 6 settings × 3 objects, each object in exactly one shard of each setting.
    assert_eq!(merged.lines().count(), 18);
    let cat = dir.path().join("cat.jsonl");
    std::fs::write(&cat, &merged).unwrap();
    let report = dir.path().join("report");
    objview_ok(&["report", s(&cat), "--out", s(&report), "--no-plots"]);
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("random-tsp") && md.contains("K=30") && md.contains("Automatic"), "{md}");
}
