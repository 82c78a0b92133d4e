//! End-to-end tests of `objview pool build`, `pool split` and `pool stats` (SPEC §1, §6).
//!
//! Expected values are derived here, independently of the program: normalized meshes and clouds
//! are checked against the source OBJ's own vertices (AABB centre, farthest vertex), the SPEC §1
//! cloud count is recomputed from the triangle areas of the written mesh, and the split sizes and
//! per-bucket counts of a hand-made annotation set are worked out in the comments.

mod common;

use common::*;
use serde_json::{json, Value};
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

fn read_json(p: &Path) -> Value {
    serde_json::from_slice(&read(p)).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Vertices and 0-based triangles of an OBJ file (`v x y z`, `f a b c` with optional `/…`).
fn read_obj(p: &Path) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let text = String::from_utf8(read(p)).unwrap();
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first() {
            Some(&"v") => v.push([t[1], t[2], t[3]].map(|x| x.parse::<f64>().unwrap())),
            Some(&"f") => {
                let idx: Vec<usize> = t[1..]
                    .iter()
                    .map(|x| x.split('/').next().unwrap().parse::<usize>().unwrap() - 1)
                    .collect();
                for k in 1..idx.len() - 1 {
                    f.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    (v, f)
}

/// Points of a binary PCD with float32 x y z (the header must say so).
fn read_pcd(p: &Path) -> Vec<[f64; 3]> {
    let bytes = read(p);
    let end = bytes.windows(12).position(|w| w == b"DATA binary\n").expect("DATA binary") + 12;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    assert!(header.contains("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"), "{header}");
    let n: usize = header.lines().find_map(|l| l.strip_prefix("POINTS ")).unwrap().parse().unwrap();
    assert_eq!(bytes.len() - end, 12 * n, "{}: data size", p.display());
    bytes[end..]
        .chunks_exact(12)
        .map(|c| std::array::from_fn(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()) as f64))
        .collect()
}

/// An axis-aligned box [−h, h] as 12 triangles.
fn write_box(path: &Path, h: [f64; 3]) {
    let v: Vec<[f64; 3]> =
        (0..8).map(|i| [0, 1, 2].map(|k| if i & (1 << k) == 0 { -h[k] } else { h[k] })).collect();
    let quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let f: Vec<[usize; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    write_obj(path, &v, &f);
}

#[test]
fn pool_build_normalizes_samples_filters_and_resumes() {
    let dir = tempdir();
    let raw = dir.path().join("raw");
    objview_ok(&["objects", "synth", "--out", s(&raw)]);
    let input = dir.path().join("in");
    std::fs::create_dir_all(&input).unwrap();
    for name in ["cube", "mug"] {
        for ext in ["obj", "mtl"] {
            std::fs::copy(raw.join(format!("{name}.{ext}")), input.join(format!("{name}.{ext}"))).unwrap();
        }
    }
    std::fs::write(input.join("broken.off"), "OFF\n3 1\n").unwrap();
    write_box(&input.join("sheet.obj"), [1.0, 1.0, 1e-4]);

    let pool = dir.path().join("pool");
    let stdout = objview_ok(&["pool", "build", s(&input), "--out", s(&pool), "--threads", "2"]);
    assert!(stdout.contains("2 accepted, 2 rejected"), "{stdout}");
    let manifest = read_json(&pool.join("manifest.json"));
    assert_eq!(manifest["counts"], json!({"objects": 4, "accepted": 2, "rejected": 2}));
    assert_eq!(manifest["rejection_reasons"], json!({"flat": 1, "unreadable": 1}));
    let rejected: Vec<(&str, &str)> = manifest["rejected"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["uid"].as_str().unwrap(), r["error"].as_str().unwrap()))
        .collect();
    assert_eq!(rejected[0].0, "broken");
    assert!(rejected[0].1.contains("broken.off"), "{}", rejected[0].1);
    assert_eq!(rejected[1].0, "sheet");
    assert!(rejected[1].1.contains("sheet.obj") && rejected[1].1.contains("flat"), "{}", rejected[1].1);
    assert_eq!(manifest["settings"]["normalize"], "unit");
    assert_eq!(manifest["settings"]["command"], "pool build");
    assert_eq!(manifest["version"], env!("CARGO_PKG_VERSION"));

    let split = read_json(&pool.join("pool.json"));
    assert_eq!(
        split,
        json!([
            {"uid": "cube", "mesh": "meshes/cube.obj", "gt_cloud": "pcd_normalized/cube.pcd"},
            {"uid": "mug", "mesh": "meshes/mug.obj", "gt_cloud": "pcd_normalized/mug.pcd"},
        ])
    );
    for (i, name) in ["cube", "mug"].iter().enumerate() {
        let entry = &manifest["accepted"][i];
        assert_eq!(entry["uid"], *name);
        // The written mesh is the source mapped by (p − AABB centre) / farthest distance.
        let (src, _) = read_obj(&input.join(format!("{name}.obj")));
        let (v, f) = read_obj(&pool.join(format!("meshes/{name}.obj")));
        let lo = [0, 1, 2].map(|k| src.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1, 2].map(|k| src.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max));
        let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
        let r = src.iter().map(|p| norm(sub(*p, c))).fold(0.0, f64::max);
        // (The loader may reorder and split vertices: each written one is a mapped source vertex.)
        let mapped: Vec<[f64; 3]> = src.iter().map(|a| sub(*a, c).map(|x| x / r)).collect();
        for b in &v {
            let d = mapped.iter().map(|m| norm(sub(*m, *b))).fold(f64::INFINITY, f64::min);
            assert!(d < 1e-12, "{name}: {b:?} is no normalized source vertex ({d})");
        }
        let radius = v.iter().map(|p| norm(*p)).fold(0.0, f64::max);
        assert!((radius - 1.0).abs() < 1e-12, "{name}: radius {radius}");
        // SPEC §1 cloud: clamp(ceil(area / 0.004²), 20 000, 2 000 000) points on the surface.
        let area: f64 =
            f.iter().map(|t| 0.5 * norm(cross(sub(v[t[1]], v[t[0]]), sub(v[t[2]], v[t[0]])))).sum();
        let count = ((area / 1.6e-5).ceil() as usize).clamp(20_000, 2_000_000);
        let pts = read_pcd(&pool.join(format!("pcd_normalized/{name}.pcd")));
        assert_eq!(pts.len(), count, "{name}: area {area}");
        assert!(pts.iter().all(|p| norm(*p) <= 1.0 + 1e-6), "{name}: cloud outside the unit ball");
        assert_eq!(entry["gt_source"], format!("sampled(seed=0, count={count})"));
        assert_eq!(entry["stats"]["faces"], f.len());
        assert!((entry["stats"]["surface_area"].as_f64().unwrap() - area).abs() < 1e-9);
        // The pool mesh is accepted as already normalized, with its own cloud: same |S_gt|
        // (up to points moved across a voxel face by the float32 file).
        let vis = dir.path().join(format!("{name}.vis.json"));
        objview_ok(&[
            "visibility",
            s(&pool.join(format!("meshes/{name}.obj"))),
            "--normalize",
            "none",
            "--gt-cloud",
            s(&pool.join(format!("pcd_normalized/{name}.pcd"))),
            "--views",
            "tammes-6",
            "--out",
            s(&vis),
        ]);
        let voxels = read_json(&vis)["surface_voxels"].as_f64().unwrap();
        let built = entry["stats"]["surface_voxels"].as_f64().unwrap();
        assert!((voxels - built).abs() <= 0.002 * built, "{name}: {voxels} vs {built}");
    }

    // Resume: nothing to do, same manifest; another thread count gives the same bytes.
    let before = read(&pool.join("manifest.json"));
    let stdout = objview_ok(&["pool", "build", s(&input), "--out", s(&pool)]);
    assert!(stdout.contains("0 built now") && stdout.contains("4 skipped"), "{stdout}");
    assert!(read(&pool.join("manifest.json")) == before);
    let pool1 = dir.path().join("pool1");
    objview_ok(&["pool", "build", s(&input), "--out", s(&pool1), "--threads", "1"]);
    for f in ["manifest.json", "pool.json", "meshes/mug.obj", "pcd_normalized/mug.pcd", "build.jsonl"] {
        assert!(read(&pool.join(f)) == read(&pool1.join(f)), "{f} depends on the thread count");
    }

    // Other settings on the same pool are refused; bad settings name the flag.
    let err = objview_err(&["pool", "build", s(&input), "--out", s(&pool), "--min-faces", "20"]);
    assert!(err.starts_with("error: ") && err.contains("build.jsonl") && err.contains("min_faces"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let err = objview_err(&["pool", "build", s(&input), "--out", s(&pool1), "--max-faces", "2"]);
    assert!(err.contains("max_faces"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// split and stats on hand-made annotations
// ---------------------------------------------------------------------------------------------

struct Obj {
    uid: String,
    d_plan: Option<u64>,
    status: &'static str,
    slow: bool,
    d_sat: u64,
    r_vis: f64,
    gt_file: bool,
}

/// One `objview annotate` line (every field of the format) for `o`, its mesh in `meshes`.
fn line(o: &Obj, meshes: &Path) -> String {
    let mesh = meshes.join(format!("{}.obj", o.uid));
    let gt = if o.gt_file {
        meshes.join(format!("{}.pcd", o.uid)).display().to_string()
    } else {
        "sampled(seed=0, count=20000)".to_string()
    };
    let v = json!({
        "uid": o.uid, "mesh": mesh.display().to_string(), "gt_cloud": gt, "vertices": 8, "faces": 12,
        "gt_points": 20000, "surface_voxels": 900, "curve": [[6, 400], [492, 800]], "mu": 2.5, "sigma": 0.7,
        "n_star": o.d_sat as f64 + 0.25, "d_sat": o.d_sat, "r_vis": o.r_vis, "grid_n": 48, "grid_r_vis": 0.9,
        "slow_saturation": o.slow, "degenerate_fit": false, "universe": 800, "d_plan": o.d_plan,
        "d_plan_status": o.status, "d_plan_bound": o.d_plan.unwrap_or(9), "lp_bound": 2.5, "greedy_cover": 6,
        "cover_views": [], "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
        "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1, "reduced_views": 0,
        "reduced_elements": 0}, "solver_seconds": 0.01, "seconds": 0.5,
        "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0, "cover": 0.0},
        "settings": {"tool": "objview"}, "version": "0.1.0",
    });
    format!("{}\n", serde_json::to_string(&v).unwrap())
}

/// The hand-made pool: main-pool buckets 1-5: 12, 6-10: 8, 11-15: 4, 16-20: 0, 21-25: 1 (25
/// objects); 3 slow-saturation objects; 3 main objects without a proven positive d_plan.
fn objects() -> Vec<Obj> {
    let mut v = Vec::new();
    let mut push = |uid: String, d_plan: Option<u64>, status, slow, d_sat, r_vis, gt_file| {
        v.push(Obj { uid, d_plan, status, slow, d_sat, r_vis, gt_file })
    };
    for (b, n) in [(0u64, 12u64), (1, 8), (2, 4), (4, 1)] {
        for i in 0..n {
            let d = 5 * b + 1 + i % 5;
            push(
                format!("m{b}{i:02}"),
                Some(d),
                "optimal",
                false,
                20 + 3 * d + i,
                0.5 + 0.01 * i as f64,
                i == 0,
            );
        }
    }
    push("s1".into(), Some(30), "optimal", true, 150, 0.4, false);
    push("s2".into(), None, "time_limit", true, 300, 0.3, false);
    push("s3".into(), Some(4), "optimal", true, 140, 0.45, false);
    push("u1".into(), None, "time_limit", false, 60, 0.6, false);
    push("u2".into(), None, "error: solver failed", false, 70, 0.65, false);
    push("u3".into(), Some(0), "optimal", false, 6, 1.0, false);
    v
}

fn write_annotations(dir: &Path) -> (PathBuf, Vec<Obj>) {
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    let objs = objects();
    let mut text = String::new();
    for o in &objs {
        std::fs::write(meshes.join(format!("{}.obj", o.uid)), "v 0 0 0\n").unwrap();
        text += &line(o, &meshes);
    }
    text += "{\"uid\":\"bad\",\"mesh\":\"bad.obj\",\"error\":\"bad.obj: mesh has no triangles\",\"settings\":{},\"version\":\"0.1.0\"}\n";
    let path = dir.join("ann.jsonl");
    std::fs::write(&path, text).unwrap();
    (path, objs)
}

/// The d_plan bucket of each object of a split file, counted.
fn bucket_counts(split: &Value) -> BTreeMap<u64, usize> {
    let mut m = BTreeMap::new();
    for e in split.as_array().unwrap() {
        *m.entry((e["annotation"]["d_plan"].as_u64().unwrap() - 1) / 5).or_default() += 1;
    }
    m
}

fn uids(split: &Value) -> Vec<String> {
    split.as_array().unwrap().iter().map(|e| e["uid"].as_str().unwrap().to_string()).collect()
}

#[test]
fn pool_split_follows_the_two_stage_rule() {
    let dir = tempdir();
    let (ann, objs) = write_annotations(dir.path());
    let out = dir.path().join("splits");
    let stdout = objview_ok(&["pool", "split", s(&ann), "--out-dir", s(&out), "--test-fraction", "0.2"]);
    assert!(stdout.contains("3 slow-saturation, 25 main, 3 excluded"), "{stdout}");
    let load = |d: &Path, name: &str| read_json(&d.join(format!("{name}.json")));

    // Slow split: s1, s2, s3 whatever their d_plan.
    assert_eq!(uids(&load(&out, "slow_saturation")), ["s1", "s2", "s3"]);
    // Quota round(0.2 · 25) = 5: stage 1 one from each of the 4 non-empty buckets, stage 2 the
    // last one by 1·n_b/25 = 0.48, 0.32, 0.16, 0.04 → bucket 1-5.
    let test = load(&out, "main_hidden_test");
    assert_eq!(bucket_counts(&test), BTreeMap::from([(0, 2), (1, 1), (2, 1), (4, 1)]));
    // Main-Train-Public: the other 20 (10, 7, 3); the default train size is 10; balanced: 3 per
    // bucket (3 non-empty buckets) and the last from the bucket with most left (1-5: 7 left).
    let public = load(&out, "main_train_public");
    assert_eq!(bucket_counts(&public), BTreeMap::from([(0, 10), (1, 7), (2, 3)]));
    let balanced = load(&out, "main_balanced_train");
    assert_eq!(bucket_counts(&balanced), BTreeMap::from([(0, 4), (1, 3), (2, 3)]));
    let raw = load(&out, "main_raw_train");
    assert_eq!(uids(&raw).len(), 10);

    let main: HashSet<String> =
        objs.iter().filter(|o| o.uid.starts_with('m')).map(|o| o.uid.clone()).collect();
    let (tu, pu) = (uids(&test), uids(&public));
    assert!(tu.iter().chain(&pu).all(|u| main.contains(u)));
    assert_eq!(tu.iter().chain(&pu).collect::<HashSet<_>>().len(), 25);
    let public_set: HashSet<&String> = pu.iter().collect();
    for split in [&raw, &balanced, &test, &public] {
        let u = uids(split);
        assert!(u.windows(2).all(|w| w[0] < w[1]), "not sorted by uid: {u:?}");
    }
    assert!(uids(&raw).iter().chain(&uids(&balanced)).all(|u| public_set.contains(u)));

    // Entries: relative paths that resolve to the meshes; gt_cloud only for cloud files.
    for split in [&test, &public] {
        for e in split.as_array().unwrap() {
            let uid = e["uid"].as_str().unwrap();
            let mesh = e["mesh"].as_str().unwrap();
            assert!(mesh.starts_with("../meshes/"), "{mesh}");
            assert!(out.join(mesh).is_file(), "{mesh}");
            let o = objs.iter().find(|o| o.uid == uid).unwrap();
            assert_eq!(e.get("gt_cloud").is_some(), o.gt_file, "{uid}");
            assert_eq!(e["annotation"]["d_sat"], o.d_sat);
            assert_eq!(e["annotation"]["d_plan_status"], "optimal");
        }
    }

    // The report: settings, counts, buckets, exclusions with reasons.
    let report = read_json(&out.join("split_report.json"));
    assert_eq!(report["settings"]["seed"], 0);
    assert_eq!(report["settings"]["test_fraction"], 0.2);
    assert_eq!(report["settings"]["bucket_width"], 5);
    assert_eq!(report["settings"]["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(report["settings"]["inputs"], json!([s(&ann)]));
    assert_eq!(report["counts"]["failures"], 1);
    assert_eq!(report["counts"]["main_hidden_test"], 5);
    assert_eq!(
        report["buckets"][4],
        json!({"bucket": "21-25", "main": 1, "main_hidden_test": 1,
        "main_train_public": 0, "main_raw_train": 0, "main_balanced_train": 0})
    );
    let excluded: Vec<&str> =
        report["excluded"].as_array().unwrap().iter().map(|e| e["uid"].as_str().unwrap()).collect();
    assert_eq!(excluded, ["u1", "u2", "u3"]);
    assert!(report["excluded"][0]["reason"].as_str().unwrap().contains("time_limit"));

    // Same files from the lines in another order, spread over two shard files; another seed
    // draws other objects with the same bucket counts.
    let text = String::from_utf8(read(&ann)).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.reverse();
    let (a, b) = (dir.path().join("a.jsonl"), dir.path().join("b.jsonl"));
    std::fs::write(&a, lines[..15].join("\n") + "\n").unwrap();
    std::fs::write(&b, lines[15..].join("\n") + "\n").unwrap();
    let out2 = dir.path().join("splits2");
    objview_ok(&["pool", "split", s(&a), s(&b), "--out-dir", s(&out2), "--test-fraction", "0.2"]);
    for name in
        ["slow_saturation", "main_hidden_test", "main_train_public", "main_raw_train", "main_balanced_train"]
    {
        let f = format!("{name}.json");
        assert!(read(&out.join(&f)) == read(&out2.join(&f)), "{f} depends on the input order");
    }
    let out3 = dir.path().join("splits3");
    objview_ok(&["pool", "split", s(&ann), "--out-dir", s(&out3), "--test-fraction", "0.2", "--seed", "1"]);
    let test3 = load(&out3, "main_hidden_test");
    assert_eq!(bucket_counts(&test3), bucket_counts(&test));
    assert_ne!(uids(&test3), tu);

    // Errors: one line naming the file or the setting.
    let err = objview_err(&["pool", "split", s(&dir.path().join("nope.jsonl")), "--out-dir", s(&out3)]);
    assert!(err.starts_with("error: ") && err.contains("nope.jsonl"), "{err}");
    let err = objview_err(&["pool", "split", s(&ann), "--out-dir", s(&out3), "--test-fraction", "1.5"]);
    assert!(err.contains("test_fraction"), "{err}");
    let err = objview_err(&["pool", "split", s(&ann), "--out-dir", s(&out3), "--train-size", "30"]);
    assert!(err.contains("train_size") && err.contains("30"), "{err}");
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn pool_stats_counts_histogram_and_means() {
    let dir = tempdir();
    let (ann, objs) = write_annotations(dir.path());
    let text = objview_ok(&["pool", "stats", s(&ann)]);
    assert!(
        text.contains("31 annotated, 1 failed; 3 slow-saturation, 28 main (3 without a proven d_plan)"),
        "{text}"
    );
    // Histogram: 12 objects in 1-5 get the full bar of 40; 8 → 27 (26.67 rounded).
    assert!(text.contains(&format!("      1-5     12 {}\n", "#".repeat(40))), "{text}");
    assert!(text.contains(&format!("     6-10      8 {}\n", "#".repeat(27))), "{text}");
    assert!(text.contains("    16-20      0\n"), "{text}");

    let j: Value = serde_json::from_str(&objview_ok(&["pool", "stats", s(&ann), "--json"])).unwrap();
    assert_eq!(
        j["counts"],
        json!({"annotated": 31, "failures": 1, "slow_saturation": 3, "main": 28, "unsolved_d_plan": 3})
    );
    // Buckets up to s1's d_plan 30 (26-30).
    assert_eq!(j["main_histogram"], json!([12, 8, 4, 0, 1, 0]));
    let main: Vec<&Obj> = objs.iter().filter(|o| !o.slow).collect();
    let g = &j["groups"][1];
    assert_eq!(g["name"], "main");
    let close = |v: &Value, x: f64| (v.as_f64().unwrap() - x).abs() < 1e-9;
    assert!(close(&g["mean_d_sat"], mean(&main.iter().map(|o| o.d_sat as f64).collect::<Vec<_>>())));
    assert!(close(&g["mean_r_vis"], mean(&main.iter().map(|o| o.r_vis).collect::<Vec<_>>())));
    let solved: Vec<f64> =
        main.iter().filter_map(|o| o.d_plan.filter(|&d| d > 0)).map(|d| d as f64).collect();
    assert_eq!(solved.len(), 25);
    assert!(close(&g["mean_d_plan"], mean(&solved)));
    assert_eq!(j["settings"]["command"], "pool stats");

    // Per split: the groups are the split files, with their own means.
    let out = dir.path().join("splits");
    objview_ok(&["pool", "split", s(&ann), "--out-dir", s(&out)]);
    let j: Value =
        serde_json::from_str(&objview_ok(&["pool", "stats", s(&ann), "--splits", s(&out), "--json"]))
            .unwrap();
    let groups = j["groups"].as_array().unwrap();
    assert_eq!(groups.len(), 5);
    for g in groups {
        let name = g["name"].as_str().unwrap();
        let split = read_json(&out.join(format!("{name}.json")));
        let d_sat: Vec<f64> =
            split.as_array().unwrap().iter().map(|e| e["annotation"]["d_sat"].as_f64().unwrap()).collect();
        assert_eq!(g["count"], d_sat.len(), "{name}");
        if d_sat.is_empty() {
            assert_eq!(g["mean_d_sat"], Value::Null, "{name}");
        } else {
            assert!(close(&g["mean_d_sat"], mean(&d_sat)), "{name}");
        }
    }
    let text = objview_ok(&["pool", "stats", s(&ann), "--splits", s(&out)]);
    assert!(text.contains("main_balanced_train"), "{text}");

    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = objview_err(&["pool", "stats", s(&ann), "--splits", s(&empty)]);
    assert!(err.contains("no split files") && err.contains("empty"), "{err}");
}
