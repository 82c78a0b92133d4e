//! End-to-end tests of `objview annotate`: analytic visibility scenes, record invariants,
//! failure lines, resume after a crash, shards, ground-truth folders, split files and
//! determinism. Voxels are 0.05 (not 0.02) to keep each object around a second.

mod common;

use common::{objview, objview_err, objview_ok, s, tempdir};
use serde_json::Value;
use std::path::{Path, PathBuf};

const R: &str = "0.05";

/// An axis-aligned cube centred at the origin with half-size `h`, as OBJ text (12 triangles),
/// vertex indices starting after `offset` vertices.
fn cube_obj(h: f64, offset: usize) -> String {
    let mut out = String::new();
    for i in 0..8 {
        let (x, y, z) = (
            if i & 1 == 0 { -h } else { h },
            if i & 2 == 0 { -h } else { h },
            if i & 4 == 0 { -h } else { h },
        );
        out += &format!("v {x} {y} {z}\n");
    }
    // Faces (corner indices 0..8), two triangles each.
    for [a, b, c, d] in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
        let o = offset + 1;
        out += &format!("f {} {} {}\nf {} {} {}\n", a + o, b + o, c + o, a + o, c + o, d + o);
    }
    out
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// A line without its wall-clock fields (the only fields that differ between runs).
fn without_times(v: &Value) -> Value {
    let mut v = v.clone();
    if let Some(m) = v.as_object_mut() {
        for k in ["seconds", "solver_seconds", "timings"] {
            m.remove(k);
        }
    }
    v
}

fn annotate(inputs: &[&Path], out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["annotate"];
    args.extend(inputs.iter().map(|p| s(p)));
    args.extend(["--out", s(out), "--resolution", R]);
    args.extend(extra);
    objview_ok(&args)
}

fn check_invariants(v: &Value) {
    let sgt = v["surface_voxels"].as_u64().unwrap();
    let curve = v["curve"].as_array().unwrap();
    assert_eq!(curve.len(), 26);
    let ns: Vec<u64> = curve.iter().map(|p| p[0].as_u64().unwrap()).collect();
    assert_eq!(ns[0], 6);
    assert_eq!(ns[25], 492);
    assert!(curve.iter().all(|p| p[1].as_u64().unwrap() <= sgt));
    let y128 = curve.iter().find(|p| p[0] == 128).unwrap()[1].as_u64().unwrap();
    assert_eq!(v["universe"].as_u64().unwrap(), y128, "U is the union of the tammes-128 views");
    let r_vis = v["r_vis"].as_f64().unwrap();
    assert!(r_vis > 0.0 && r_vis <= 1.0 + 1e-12);
    let d_sat = v["d_sat"].as_u64().unwrap();
    assert!((6..=492).contains(&d_sat));
    assert_eq!(v["slow_saturation"].as_bool().unwrap(), d_sat > 128);
    assert_eq!(v["d_plan_status"], "optimal");
    let d_plan = v["d_plan"].as_u64().unwrap();
    assert_eq!(v["cover_views"].as_array().unwrap().len() as u64, d_plan);
    assert_eq!(v["d_plan_bound"].as_u64().unwrap(), d_plan);
    assert!(d_plan <= v["greedy_cover"].as_u64().unwrap());
    assert!(v["lp_bound"].as_f64().unwrap() <= d_plan as f64 + 1e-6);
    assert!(v["cover_views"].as_array().unwrap().iter().all(|c| c.as_u64().unwrap() < 128));
    assert_eq!(v["settings"]["resolution"], 0.05);
    assert_eq!(v["version"], env!("CARGO_PKG_VERSION"));
}

#[test]
fn nested_boxes_hide_the_inner_surface_in_both_visibility_modes() {
    let dir = tempdir();
    // Pre-normalized (farthest vertex at distance 1): outer half-size 1/sqrt(3), inner 0.3.
    let h = 1.0 / 3f64.sqrt();
    let outer = write(dir.path(), "outer.obj", &cube_obj(h, 0));
    let inner = write(dir.path(), "inner.obj", &cube_obj(0.3, 0));
    let both = write(dir.path(), "both.obj", &(cube_obj(h, 0) + &cube_obj(0.3, 8)));
    for mode in ["mesh", "inverse"] {
        let out = dir.path().join(format!("{mode}.jsonl"));
        annotate(&[&outer, &inner, &both], &out, &["--normalize", "none", "--visibility", mode]);
        let v = lines(&out);
        assert_eq!(v.len(), 3);
        v.iter().for_each(check_invariants);
        let (a, b) = (v[0]["surface_voxels"].as_f64().unwrap(), v[1]["surface_voxels"].as_f64().unwrap());
        // The two surfaces are 0.27 apart: their voxel sets are disjoint (up to sampling).
        let c = v[2]["surface_voxels"].as_f64().unwrap();
        assert!((c - (a + b)).abs() <= 0.01 * c, "{mode}: {c} vs {a} + {b}");
        // A convex box alone is fully visible; nested, only the outer share is.
        for i in [0, 1] {
            let r = v[i]["r_vis"].as_f64().unwrap();
            assert!(r > 0.97, "{mode}: lone box r_vis {r}");
        }
        let expected = a / (a + b);
        let r = v[2]["r_vis"].as_f64().unwrap();
        assert!((r - expected).abs() < 0.03, "{mode}: nested r_vis {r}, expected about {expected}");
        // A cube needs at least 2 views (opposite corners see 3 faces each), never more than 6.
        for x in &v {
            let d = x["d_plan"].as_u64().unwrap();
            assert!((2..=6).contains(&d), "{mode}: d_plan {d}");
        }
    }
}

#[test]
fn failures_are_recorded_and_the_batch_goes_on() {
    let dir = tempdir();
    let good = write(dir.path(), "good.obj", &cube_obj(0.5, 0));
    let bad = write(dir.path(), "bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    let out = dir.path().join("out.jsonl");
    let stdout = annotate(&[&bad, &good], &out, &[]);
    assert!(stdout.contains("1 done, 1 failed"), "{stdout}");
    let v = lines(&out);
    assert_eq!(v[0]["uid"], "bad");
    assert_eq!(v[0]["mesh"], s(&bad));
    let err = v[0]["error"].as_str().unwrap();
    assert!(err.contains("bad.obj"), "{err}");
    assert_eq!(v[1]["uid"], "good");
    check_invariants(&v[1]);
    // A re-run skips both (failures are not retried unless asked) ...
    let stdout = annotate(&[&bad, &good], &out, &[]);
    assert!(stdout.contains("2 skipped"), "{stdout}");
    assert_eq!(lines(&out).len(), 2);
    // ... and --retry-failed redoes only the failure.
    let stdout = annotate(&[&bad, &good], &out, &["--retry-failed"]);
    assert!(stdout.contains("0 done, 1 failed, 1 skipped"), "{stdout}");
    let v = lines(&out);
    assert_eq!((v.len(), v[0]["uid"].as_str(), v[1]["uid"].as_str()), (2, Some("good"), Some("bad")));
}

#[test]
fn resume_after_a_crash_and_shards_and_threads_give_the_same_records() {
    let dir = tempdir();
    let all = dir.path().join("all");
    objview_ok(&["objects", "synth", "--out", s(&all)]);
    let objs = dir.path().join("objs");
    std::fs::create_dir(&objs).unwrap();
    for name in ["cube", "cone", "torus", "l-shape"] {
        for ext in ["obj", "mtl"] {
            std::fs::copy(all.join(format!("{name}.{ext}")), objs.join(format!("{name}.{ext}"))).unwrap();
        }
    }
    let full = dir.path().join("full.jsonl");
    annotate(&[&objs], &full, &["--threads", "1"]);
    let reference: Vec<Value> = lines(&full).iter().map(without_times).collect();
    assert_eq!(reference.len(), 4);
    reference.iter().for_each(check_invariants);

    // Two threads: the same lines in the same (input) order.
    let par = dir.path().join("par.jsonl");
    annotate(&[&objs], &par, &["--threads", "2"]);
    assert_eq!(lines(&par).iter().map(without_times).collect::<Vec<_>>(), reference);

    // A crash after two lines and half of the third.
    let text = std::fs::read_to_string(&full).unwrap();
    let cut: Vec<&str> = text.lines().collect();
    let crashed = dir.path().join("crashed.jsonl");
    std::fs::write(&crashed, format!("{}\n{}\n{}", cut[0], cut[1], &cut[2][..cut[2].len() / 2])).unwrap();
    let out = objview(&["annotate", s(&objs), "--out", s(&crashed), "--resolution", R]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("torn last line"), "{stderr}");
    assert!(String::from_utf8_lossy(&out.stdout).contains("2 done, 0 failed, 2 skipped"));
    let resumed = lines(&crashed);
    assert_eq!(&resumed[..2], &lines(&full)[..2], "kept lines are untouched");
    assert_eq!(resumed.iter().map(without_times).collect::<Vec<_>>(), reference);

    // Shards partition the objects; their concatenation holds every record once.
    let mut uids = Vec::new();
    for i in 0..3 {
        let p = dir.path().join(format!("shard{i}.jsonl"));
        annotate(&[&objs], &p, &["--shard", &format!("{i}/3")]);
        for v in lines(&p) {
            assert_eq!(v["settings"]["shard"], format!("{i}/3"));
            let r = reference.iter().find(|r| r["uid"] == v["uid"]).unwrap();
            let (mut a, mut b) = (without_times(&v), r.clone());
            a["settings"]["shard"] = Value::Null;
            b["settings"]["shard"] = Value::Null;
            assert_eq!(a, b);
            uids.push(v["uid"].as_str().unwrap().to_string());
        }
    }
    uids.sort();
    assert_eq!(uids, ["cone", "cube", "l-shape", "torus"]);
}

#[test]
fn ground_truth_folders_and_split_files() {
    let dir = tempdir();
    let mesh = write(dir.path(), "box.obj", &cube_obj(0.5, 0));
    let other = write(dir.path(), "other.obj", &cube_obj(0.4, 0));
    // A cloud folder with a cloud for `box` only: 6 face centres... plus a dense face sample.
    let clouds = dir.path().join("clouds");
    std::fs::create_dir(&clouds).unwrap();
    let mut ply = String::new();
    let n = 40;
    let mut pts = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (u, w) = (-0.5 + (i as f64 + 0.5) / n as f64, -0.5 + (j as f64 + 0.5) / n as f64);
            pts.extend([[u, w, 0.5], [u, w, -0.5], [u, 0.5, w], [u, -0.5, w], [0.5, u, w], [-0.5, u, w]]);
        }
    }
    ply += &format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n", pts.len());
    for p in &pts {
        ply += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    write(&clouds, "box.ply", &ply);
    let out = dir.path().join("out.jsonl");
    annotate(&[&mesh, &other], &out, &["--gt-cloud-dir", s(&clouds)]);
    let v = lines(&out);
    assert!(v[0]["gt_cloud"].as_str().unwrap().ends_with("box.ply"), "{}", v[0]["gt_cloud"]);
    assert_eq!(v[0]["gt_points"], pts.len());
    check_invariants(&v[0]);
    let err = v[1]["error"].as_str().unwrap();
    assert!(err.contains("no ground-truth cloud for 'other'"), "{err}");

    // A split file with relative paths and the paper's field names.
    let split = write(
        dir.path(),
        "split.json",
        r#"[{"uid": "the-box", "obj_path": "box.obj", "pcd_path": "clouds/box.ply"}]"#,
    );
    let out2 = dir.path().join("split.jsonl");
    annotate(&[&split], &out2, &[]);
    let w = lines(&out2);
    assert_eq!(w[0]["uid"], "the-box");
    assert_eq!(without_times(&w[0])["surface_voxels"], v[0]["surface_voxels"]);
    assert_eq!(w[0]["d_plan"], v[0]["d_plan"]);
}

#[test]
fn argument_errors_name_the_problem() {
    let dir = tempdir();
    let out = dir.path().join("o.jsonl");
    let missing = dir.path().join("nope.obj");
    let e = objview_err(&["annotate", s(&missing), "--out", s(&out)]);
    assert!(e.contains("nope.obj"), "{e}");
    let m = write(dir.path(), "m.obj", &cube_obj(0.5, 0));
    let e = objview_err(&["annotate", s(&m), "--out", s(&out), "--shard", "3/3"]);
    assert!(e.contains("invalid shard '3/3'"), "{e}");
    let e = objview_err(&["annotate", s(&m), "--out", s(&out), "--resolution", "-1"]);
    assert!(e.contains("resolution"), "{e}");
    // A results file of something else is never overwritten.
    std::fs::write(&out, "{\"not\": 1}\n{\"uid\": \"x\"}\n").unwrap();
    let e = objview_err(&["annotate", s(&m), "--out", s(&out)]);
    assert!(e.contains("line 1") && e.contains("no string field 'uid'"), "{e}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "{\"not\": 1}\n{\"uid\": \"x\"}\n");
}
