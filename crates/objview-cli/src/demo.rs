//! `objview demo`: the main job on the built-in objects, end to end:
//! 1. synthesize the pool; load and normalize every object, sample its ground-truth cloud,
//!    render the start view (depth NPY + preview PNG) and compute its observable surface over
//!    tammes-128 in `inverse` mode (`summary.json`, a table);
//! 2. annotate every object's difficulty (SPEC §4: r_vis, d_sat, exact d_plan) into
//!    `annotations.jsonl` (resumable: a re-run skips finished objects);
//! 3. split the pool (SPEC §6) into `splits/`, print its statistics, and draw Figure 2 into
//!    `figures/`.
//!
//! Later stages (episodes, baselines, reports) extend this command.

use anyhow::{Context, Result};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use objview_geom::normalize::{load_normalized, Normalization};
use objview_geom::pose::VIEW_RADIUS;
use objview_render::{Camera, Intrinsics};
use objview_views::{start_pose, ViewSet};
use objview_voxel::{Visibility, VisibilityMode, VoxelSet, DEFAULT_RESOLUTION};
use rayon::prelude::*;
use serde_json::json;
use std::io::IsTerminal;
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
    println!("[1/6] synthesized {} built-in objects into {}", paths.len(), objects_dir.display());
    let views = ViewSet::resolve(&a.views)?;
    let cameras: Vec<Camera> =
        views.poses(VIEW_RADIUS).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();

    let bar = progress(paths.len() as u64);
    let rows: Vec<Result<Row, (PathBuf, anyhow::Error)>> = paths
        .par_iter()
        .map(|p| {
            let r = one_object(p, &renders_dir, &cameras).map_err(|e| (p.clone(), e));
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    println!("[2/6] rendered the start view and swept {} ({} views) per object", a.views, views.len());

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
        "\n[3/6] wrote {} ({} objects, {} failed); start-view depth + previews in {}; {:.1} s, {} seconds per object on average",
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
    println!("\n[4/6] annotating the difficulty of every object (SPEC §4) into {}", annotations.display());
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
    println!("\n[5/6] splitting the pool (SPEC §6) into {}", splits.display());
    crate::pool_split::run_split(crate::pool_split::SplitArgs {
        annotations: vec![annotations.clone()],
        out_dir: splits.clone(),
        seed: 0,
        test_fraction: objview_pool::split::DEFAULT_TEST_FRACTION,
        train_size: None,
    })?;
    println!();
    crate::pool_split::run_stats(crate::pool_split::StatsArgs {
        annotations: vec![annotations.clone()],
        splits: Some(splits),
        json: false,
    })?;
    let figures = a.out.join("figures");
    println!("\n[6/6] drawing Figure 2 into {}", figures.display());
    crate::pool_plot::run(crate::pool_plot::Args {
        annotations: vec![annotations],
        out: figures,
        representatives: 6,
    })?;
    println!("\ndemo finished in {:.1} s", t0.elapsed().as_secs_f64());
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

/// A progress bar with ETA on a terminal; hidden otherwise (the summary lines still print).
pub fn progress(n: u64) -> ProgressBar {
    if std::io::stderr().is_terminal() {
        let b = ProgressBar::new(n);
        b.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} objects, {elapsed} elapsed, ETA {eta}")
                .expect("valid template"),
        );
        b
    } else {
        ProgressBar::hidden()
    }
}
