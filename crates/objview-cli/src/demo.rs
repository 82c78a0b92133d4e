//! `objview demo`: the main job on the built-in objects, end to end:
//! 1. synthesize the pool; load and normalize every object, sample its ground-truth cloud,
//!    render the start view (depth NPY + preview PNG) and compute its observable surface over
//!    tammes-128 in `inverse` mode (`summary.json`, a table);
//! 2. annotate every object's difficulty (SPEC §4: r_vis, d_sat, exact d_plan) into
//!    `annotations.jsonl` (resumable: a re-run skips finished objects);
//! 3. split the pool (SPEC §6) into `splits/`, print its statistics, and draw Figure 2 into
//!    `figures/`;
//! 4. run online episodes (SPEC §5) on Main-Hidden-Test: every classical planner (random-tsp at
//!    K = 5 and K = 30, rse and rse-mov once each — their K = 5, K = 30 and MS@0.02 results are
//!    checkpoints of one run, which stops once K = 5, K = 30 and every MS@δ exist: the demo's
//!    checkpoint list is the paper's 5, 30) in `whole` and `quarter`, and the ground-truth oracle over
//!    tammes-128 on Main-Hidden-Test and Slow-Saturation (the slow-saturation table), into
//!    `episodes/*.jsonl` (resumable);
//! 5. write the report (the paper's Tables 2–5, CSVs, figures) into `report/` and print it.

use anyhow::{Context, Result};
use clap::Parser;
use objview_geom::normalize::{load_normalized, Normalization};
use objview_geom::pose::VIEW_RADIUS;
use objview_render::{Camera, Intrinsics};
use objview_views::{start_pose, ViewSet};
use objview_voxel::{Visibility, VisibilityMode, VoxelSet, DEFAULT_RESOLUTION};
use rayon::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Parser)]
pub struct Args {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// View set for the observable-surface sweep.
    #[arg(long, default_value = "tammes-128")]
    pub views: String,
    /// Exact d_plan time limit per object in the annotation stage, seconds.
    #[arg(long, default_value_t = 30.0)]
    pub time_limit: f64,
    /// Only these built-in objects (comma-separated names; default: all).
    #[arg(long, value_delimiter = ',')]
    pub objects: Vec<String>,
    /// Stop after the geometry stage (no annotation, splits or figures).
    #[arg(long)]
    pub geometry_only: bool,
    /// Stop after the difficulty stages (no episodes or report).
    #[arg(long)]
    pub no_episodes: bool,
    /// Main-Hidden-Test quota as a fraction of the main pool. The paper's 528/5523 ≈ 0.0956
    /// leaves only 2–3 of the 28 main built-in objects, so the demo holds out more.
    #[arg(long, default_value_t = 0.15)]
    pub test_fraction: f64,
}

struct Row {
    name: String,
    triangles: usize,
    gt_points: usize,
    surface_voxels: usize,
    union: usize,
    start_hits: usize,
    seconds: f64,
}

pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    let objects_dir = a.out.join("objects");
    let renders_dir = a.out.join("renders");
    std::fs::create_dir_all(&renders_dir).with_context(|| format!("creating {}", renders_dir.display()))?;
    let mut paths = objview_geom::synth::write_pool(&objects_dir)?;
    for name in &a.objects {
        anyhow::ensure!(
            objview_geom::synth::find(name).is_some(),
            "--objects: no built-in object named {name:?} (see `objview objects list`)"
        );
    }
    if !a.objects.is_empty() {
        paths.retain(|p| a.objects.iter().any(|n| p.file_stem().is_some_and(|s| s == n.as_str())));
    }
    println!("[1/8] synthesized {} built-in objects into {}", paths.len(), objects_dir.display());
    let views = ViewSet::resolve(&a.views)?;
    let cameras: Vec<Camera> =
        views.poses(VIEW_RADIUS).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();

    let bar = crate::common::progress(paths.len() as u64);
    let rows: Vec<Result<Row, (PathBuf, anyhow::Error)>> = paths
        .par_iter()
        .map(|p| {
            let r = one_object(p, &renders_dir, &cameras).map_err(|e| (p.clone(), e));
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    println!("[2/8] rendered the start view and swept {} ({} views) per object", a.views, views.len());

    let mut ok = Vec::new();
    let mut failed = Vec::new();
    for r in rows {
        match r {
            Ok(row) => ok.push(row),
            Err((p, e)) => failed.push(json!({"mesh": p.display().to_string(), "error": format!("{e:#}")})),
        }
    }
    println!(
        "\n{:<18} {:>9} {:>9} {:>8} {:>8} {:>7} {:>10}",
        "object", "triangles", "gt_points", "|S_gt|", "|∪O(v)|", "ratio", "start_px"
    );
    for r in &ok {
        println!(
            "{:<18} {:>9} {:>9} {:>8} {:>8} {:>7.3} {:>10}",
            r.name,
            r.triangles,
            r.gt_points,
            r.surface_voxels,
            r.union,
            r.union as f64 / r.surface_voxels.max(1) as f64,
            r.start_hits
        );
    }
    for f in &failed {
        println!("FAILED {}: {}", f["mesh"], f["error"]);
    }
    let summary = json!({
        "settings": crate::provenance::settings("demo", json!({
            "views": a.views,
            "num_views": views.len(),
            "view_radius": VIEW_RADIUS,
            "visibility": VisibilityMode::Inverse.to_string(),
            "resolution": DEFAULT_RESOLUTION,
            "normalize": "unit",
            "gt_cloud": "sampled (SPEC §1, seed 0)",
        })),
        "objects": ok.iter().map(|r| json!({
            "uid": r.name,
            "triangles": r.triangles,
            "gt_points": r.gt_points,
            "surface_voxels": r.surface_voxels,
            "union": r.union,
            "observable_ratio": r.union as f64 / r.surface_voxels.max(1) as f64,
            "start_view_hits": r.start_hits,
        })).collect::<Vec<_>>(),
        "failed": failed,
    });
    let summary_path = a.out.join("summary.json");
    crate::common::write_json(&summary_path, &summary)?;
    println!(
        "\n[3/8] wrote {} ({} objects, {} failed); start-view depth + previews in {}; {:.1} s, {} seconds per object on average",
        summary_path.display(),
        ok.len(),
        failed.len(),
        renders_dir.display(),
        t0.elapsed().as_secs_f64(),
        format_args!("{:.2}", ok.iter().map(|r| r.seconds).sum::<f64>() / ok.len().max(1) as f64)
    );
    if a.geometry_only {
        return Ok(());
    }
    difficulty_stages(&a, &paths, t0)
}

/// Stages 4–6: annotate, split + stats, figures.
fn difficulty_stages(a: &Args, objects: &[PathBuf], t0: Instant) -> Result<()> {
    let annotations = a.out.join("annotations.jsonl");
    println!("\n[4/8] annotating the difficulty of every object (SPEC §4) into {}", annotations.display());
    crate::annotate::run(crate::annotate::Args {
        inputs: objects.to_vec(),
        out: annotations.clone(),
        normalize: Normalization::Unit,
        gt_cloud_dir: None,
        gt_seed: objview_geom::cloud::DEFAULT_CLOUD_SEED,
        visibility: VisibilityMode::Inverse,
        resolution: DEFAULT_RESOLUTION,
        threads: None,
        shard: None,
        time_limit: a.time_limit,
        min_views: 1,
        cover_method: objview_difficulty::CoverMethod::Auto,
        retry_failed: false,
    })?;
    let splits = a.out.join("splits");
    println!("\n[5/8] splitting the pool (SPEC §6) into {}", splits.display());
    crate::pool_split::run_split(crate::pool_split::SplitArgs {
        annotations: vec![annotations.clone()],
        out_dir: splits.clone(),
        seed: 0,
        test_fraction: a.test_fraction,
        train_size: None,
    })?;
    println!();
    crate::pool_split::run_stats(crate::pool_split::StatsArgs {
        annotations: vec![annotations.clone()],
        splits: Some(splits),
        json: false,
    })?;
    let figures = a.out.join("figures");
    println!("\n[6/8] drawing Figure 2 into {}", figures.display());
    crate::pool_plot::run(crate::pool_plot::Args {
        annotations: vec![annotations.clone()],
        out: figures,
        representatives: 6,
    })?;
    if !a.no_episodes {
        episode_stages(a, &annotations)?;
    }
    println!("\ndemo finished in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// One `objview run` of the demo.
fn demo_run(
    out: &Path,
    planner: &str,
    space: &str,
    budget: &str,
    objects: &Path,
    extra: impl FnOnce(&mut crate::run::Args),
) -> Result<PathBuf> {
    let mut args = crate::run::Args {
        planner: planner.into(),
        params: Vec::new(),
        space: space.into(),
        budget: budget.into(),
        objects: vec![objects.to_path_buf()],
        out: out.join(format!("{planner}_{space}_{budget}.jsonl")),
        candidates: "tammes-360".into(),
        seed: 0,
        threads: None,
        normalize: Normalization::Unit,
        gt_cloud_dir: None,
        cache_dir: Some(out.join("reference-cache")),
        no_cache: false,
        start_pose: None,
        cap: 129,
        checkpoints: vec![5, 30],
        no_enough_info: false,
        no_timings: false,
        retry_failed: false,
        quiet: true,
        server: None,
        token: None,
    };
    extra(&mut args);
    let file = args.out.clone();
    let t = Instant::now();
    let s = crate::run::execute(&args)?;
    println!(
        "  {planner:<10} {space:<8} budget {budget:<5} {} episodes ({} failed, {} already done) {:>6.1} s -> {}",
        s.done,
        s.failed,
        s.skipped,
        t.elapsed().as_secs_f64(),
        file.display()
    );
    Ok(file)
}

/// Stages 7–8: episodes of every classical planner and the oracle, then the report.
fn episode_stages(a: &Args, annotations: &Path) -> Result<()> {
    let splits = a.out.join("splits");
    let test = splits.join("main_hidden_test.json");
    let slow = splits.join("slow_saturation.json");
    let episodes = a.out.join("episodes");
    std::fs::create_dir_all(&episodes).with_context(|| format!("creating {}", episodes.display()))?;
    let n_test = objview_dataset::read_split(&test)?.len();
    let n_slow = if slow.exists() { objview_dataset::read_split(&slow)?.len() } else { 0 };
    println!(
        "\n[7/8] online episodes (SPEC §5) on Main-Hidden-Test ({n_test} objects) into {}",
        episodes.display()
    );
    let mut files = Vec::new();
    for space in ["whole", "quarter"] {
        for (planner, budget) in
            [("random-tsp", "5"), ("random-tsp", "30"), ("rse", "auto"), ("rse-mov", "auto")]
        {
            files.push(demo_run(&episodes, planner, space, budget, &test, |_| {})?);
        }
    }
    // The slow-saturation diagnostic: the oracle over tammes-128 until it is exhausted.
    for (name, split) in [("test", &test), ("slow", &slow)] {
        if name == "slow" && n_slow == 0 {
            continue;
        }
        let f = demo_run(&episodes, "oracle", "whole", "auto", split, |r| {
            r.candidates = "tammes-128".into();
            r.no_enough_info = true;
            r.out = r.out.with_file_name(format!("oracle_whole_tammes128_{name}.jsonl"));
        })?;
        files.push(f);
    }
    let report_dir = a.out.join("report");
    println!("\n[8/8] report (the paper's Tables 2–5) into {}", report_dir.display());
    crate::report::write(&files, &[annotations.to_path_buf()], &report_dir, true)?;
    Ok(())
}

fn one_object(path: &Path, renders: &Path, cameras: &[Camera]) -> Result<Row> {
    let t = Instant::now();
    let name = path.file_stem().unwrap_or_default().to_string_lossy().to_string();
    let (mesh, transform) = load_normalized(path, Normalization::Unit)?;
    let gt = objview_geom::cloud::ground_truth(&mesh, &transform, None)?;
    let set = VoxelSet::from_points(&gt.points, DEFAULT_RESOLUTION)?;
    let vis = Visibility::new(&set, &mesh, VisibilityMode::Inverse);
    let mut acc = vec![0u64; set.len().div_ceil(64)];
    for cam in cameras {
        objview_voxel::union_into(&mut acc, &vis.observe_bitset(cam));
    }
    let start = Camera::new(start_pose(VIEW_RADIUS), Intrinsics::default());
    let frame = objview_render::render(&mesh, &start);
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    objview_geom::npy::write_npy_f32(&renders.join(format!("{name}.depth.npy")), &[h, w], &frame.depth)?;
    let img = objview_render::preview::depth_preview(&frame);
    objview_render::preview::save_png(&img, renders.join(format!("{name}.depth.png")))?;
    let rgb = objview_render::rgb::render_rgb(&mesh, &frame);
    objview_render::preview::save_rgb_png(w as u32, h as u32, &rgb, renders.join(format!("{name}.rgb.png")))?;
    Ok(Row {
        name,
        triangles: mesh.num_triangles(),
        gt_points: gt.points.len(),
        surface_voxels: set.len(),
        union: objview_voxel::bitset_count(&acc),
        start_hits: frame.num_hits(),
        seconds: t.elapsed().as_secs_f64(),
    })
}
