//! End-to-end test of `objview pool plot` (paper Figure 2): the annotation lines are written by
//! the test itself (hand-made curves, d_sat and d_plan values), the outputs are checked with the
//! hand-written PNG reader of `common/`, as text (SVG) and as JSON; no library code is used.

mod common;

use common::*;
use serde_json::{json, Value};
use std::path::Path;

const GRID: [usize; 26] = [
    6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160, 180, 200, 270, 360,
    432, 492,
];

/// One `objview annotate` line with Y(N) = round(S·0.8·(1 − exp(−N/τ))), S = 5000.
fn line(uid: &str, d_sat: usize, d_plan: Option<usize>, tau: f64) -> String {
    let s = 5000usize;
    let curve: Vec<[usize; 2]> = GRID
        .iter()
        .map(|&n| [n, (s as f64 * 0.8 * (1.0 - (-(n as f64) / tau).exp())).round() as usize])
        .collect();
    json!({
        "uid": uid, "mesh": format!("{uid}.obj"), "gt_cloud": "sampled(seed=0, count=20000)",
        "vertices": 8, "faces": 12, "gt_points": 20000, "surface_voxels": s, "curve": curve,
        "mu": 2.0, "sigma": 1.0, "n_star": d_sat as f64, "d_sat": d_sat, "r_vis": 0.8, "grid_n": d_sat,
        "grid_r_vis": 0.8, "slow_saturation": d_sat > 128, "degenerate_fit": false, "universe": 4000,
        "d_plan": d_plan, "d_plan_status": if d_plan.is_some() { "optimal" } else { "time_limit" },
        "d_plan_bound": d_plan.unwrap_or(2), "lp_bound": 2.0, "greedy_cover": 8, "cover_views": [],
        "d_plan_proven_by": if d_plan.is_some() { "ilp" } else { "none" }, "search_nodes": 0,
        "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
            "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1,
            "reduced_views": 128, "reduced_elements": 10},
        "solver_seconds": 0.1, "seconds": 1.0,
        "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0, "cover": 0.0},
        "settings": {"resolution": 0.02, "saturation": {"slow_saturation_threshold": 128,
            "plateau_tol": 0.0002, "plateau_step": 10.0}},
        "version": "0.1.0"
    })
    .to_string()
}

fn write_lines(path: &Path, lines: &[String]) {
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

#[test]
fn pool_plot_writes_figure_2_deterministically_and_reports_bad_inputs() {
    let dir = tempdir();
    let a = dir.path().join("a.jsonl");
    let b = dir.path().join("b.jsonl");
    write_lines(
        &a,
        &[line("cube", 6, Some(4), 1.0), line("mug", 71, Some(13), 20.0), line("cage", 54, None, 10.0)],
    );
    let failure = json!({"uid": "broken", "mesh": "broken.obj", "error": "no triangles", "settings": {}, "version": "0.1.0"});
    write_lines(
        &b,
        &[line("box", 390, Some(25), 90.0), line("chair", 37, Some(7), 8.0), failure.to_string()],
    );

    let out = dir.path().join("fig");
    let stdout = objview_ok(&["pool", "plot", s(&a), s(&b), "--out", s(&out), "--representatives", "3"]);
    let printed: Vec<&str> = stdout.lines().collect();
    let stems = ["fig2a_saturation", "fig2a_marginal_gain", "fig2b_dplan_hist", "fig2c_dsat_vs_dplan"];
    let mut expected: Vec<String> = Vec::new();
    for stem in stems {
        for ext in ["png", "svg"] {
            expected.push(out.join(format!("{stem}.{ext}")).display().to_string());
        }
    }
    expected.push(out.join("figures.json").display().to_string());
    assert_eq!(printed, expected);

    // PNGs are well-formed and sized; the histogram has two panels (buckets and per value).
    for (stem, w) in stems.iter().zip([1000, 1000, 1500, 1000]) {
        let png = read_png(&out.join(format!("{stem}.png")));
        assert_eq!((png.width, png.height), (w, 650), "{stem}");
    }
    let svg = |stem: &str| String::from_utf8(read(&out.join(format!("{stem}.svg")))).unwrap();
    assert!(
        svg("fig2a_saturation").contains("cube (d_sat=6)")
            && svg("fig2a_saturation").contains("box (d_sat=390)")
    );
    assert!(svg("fig2b_dplan_hist").contains("cage (time_limit)"));
    // d_plan = 4, 13, 25, 7 against d_sat = 6, 71, 390, 37: ranks agree exactly → Spearman 1.
    assert!(svg("fig2c_dsat_vs_dplan").contains("Spearman ρ = 1.00 (n = 4)"));

    let fig: Value = serde_json::from_slice(&read(&out.join("figures.json"))).unwrap();
    assert_eq!(fig["tool"], "objview");
    assert_eq!(fig["command"], "pool plot");
    assert_eq!(fig["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(fig["inputs"], json!([s(&a), s(&b)]));
    assert_eq!(fig["failures_skipped"], 1);
    assert_eq!(fig["settings"]["representatives"], 3);
    // Sorted by d_sat: cube 6, chair 37, cage 54, mug 71, box 390 → ranks 0, 2, 4.
    let reps: Vec<&str> = fig["data"]["fig2a_saturation"]["representatives"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["uid"].as_str().unwrap())
        .collect();
    assert_eq!(reps, ["cube", "cage", "box"]);
    let buckets = &fig["data"]["fig2b_dplan_hist"]["buckets"];
    assert_eq!(buckets[0], json!({"lo": 1, "hi": 5, "main": 1, "slow": 0}));
    assert_eq!(buckets[4], json!({"lo": 21, "hi": 25, "main": 0, "slow": 1}));

    // Same inputs, another folder: byte-identical files.
    let out2 = dir.path().join("fig2");
    objview_ok(&["pool", "plot", s(&a), s(&b), "--out", s(&out2), "--representatives", "3"]);
    for p in &expected {
        let name = Path::new(p).file_name().unwrap();
        assert!(
            read(Path::new(p)) == read(&out2.join(name)),
            "{} differs between runs",
            name.to_string_lossy()
        );
    }

    // Errors: one line naming the file and the reason.
    let missing = dir.path().join("missing.jsonl");
    let e = objview_err(&["pool", "plot", s(&missing), "--out", s(&out)]);
    assert!(e.contains("missing.jsonl") && e.contains("no such annotations file"), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    let only_failures = dir.path().join("f.jsonl");
    write_lines(&only_failures, &[failure.to_string()]);
    let e = objview_err(&["pool", "plot", s(&only_failures), "--out", s(&out)]);
    assert!(e.contains("f.jsonl") && e.contains("no annotations to plot") && e.contains("1 failure"), "{e}");
    let corrupt = dir.path().join("c.jsonl");
    write_lines(&corrupt, &[line("x", 6, Some(1), 1.0), "{not json".to_string()]);
    let e = objview_err(&["pool", "plot", s(&corrupt), "--out", s(&out)]);
    assert!(e.contains("c.jsonl") && e.contains("line 2"), "{e}");
    let e = objview_err(&["pool", "plot", s(&a), "--out", s(&out), "--representatives", "0"]);
    assert!(e.contains("representatives"), "{e}");
}
