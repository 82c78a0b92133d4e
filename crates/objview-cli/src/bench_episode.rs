//! `objview bench episode`: the cost of one episode step in the environment — render + fusion +
//! SC/NSC/CD at 3 τ + MS — on a built-in object tessellated to ~100k triangles with a ~300k-point
//! ground-truth cloud, and the planning time per step of RSE / RSE-Mov on the same object.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeSettings, ExecutionMode, Scripted};
use objview_geom::cloud::sample_surface;
use objview_geom::normalize::{normalize, Normalization};
use objview_geom::Pose;
use objview_views::{start_pose, ViewSet, ViewSpace};
use serde_json::json;

#[derive(Parser)]
pub struct EpisodeBenchArgs {
    /// Built-in object (see `objview objects list`).
    #[arg(long, default_value = "mug")]
    pub object: String,
    /// Target triangle count.
    #[arg(long, default_value_t = 100_000)]
    pub triangles: usize,
    /// Ground-truth points (sampled on the surface).
    #[arg(long, default_value_t = 300_000)]
    pub gt_points: usize,
    /// Views per engine episode (tammes-360 candidates in a fixed spread order).
    #[arg(long, default_value_t = 50)]
    pub views: usize,
    /// Planner steps timed for each of rse and rse-mov (0 skips them).
    #[arg(long, default_value_t = 10)]
    pub planner_steps: usize,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

/// (median, nearest-rank p90, max).
fn stats(mut v: Vec<f64>) -> (f64, f64, f64) {
    let med = objview_geom::stats::median(&mut v); // sorts
    (med, objview_geom::stats::percentile(&v, 0.9), objview_geom::stats::percentile(&v, 1.0))
}

pub fn bench_episode(a: EpisodeBenchArgs) -> Result<()> {
    let obj = objview_geom::synth::find(&a.object)
        .with_context(|| format!("--object: no built-in object named {:?}", a.object))?;
    let (mesh, _) = normalize(
        obj.build_with_triangles(a.triangles),
        Normalization::Unit,
        std::path::Path::new(&a.object),
    )?;
    let gt = sample_surface(&mesh, a.gt_points, 0);
    let settings = EpisodeSettings { enough_info: false, ..Default::default() };
    let space = ViewSpace::builtin("whole").context("whole view space")?;
    let t = Instant::now();
    let scene = Arc::new(scene_from_parts(
        &a.object,
        mesh.clone(),
        gt,
        "sampled".into(),
        &space,
        "whole",
        &settings,
        None,
    )?);
    let reference_s = t.elapsed().as_secs_f64();
    println!(
        "{}: {} triangles, {} GT points; observable reference: {} points from {} views in {:.2} s ({:.1} ms/view)",
        a.object,
        mesh.num_triangles(),
        scene.gt.len(),
        scene.reference.points.len(),
        scene.reference.poses.len(),
        reference_s,
        1e3 * reference_s / scene.reference.poses.len().max(1) as f64
    );
    let candidates = Arc::new(ViewSet::resolve("tammes-360")?.poses(settings.view_radius));
    // A spread order: every 37th candidate (37 is coprime with 360).
    let order: Vec<Pose> = (0..a.views.min(360)).map(|i| candidates[(i * 37) % 360]).collect();
    let engine_run = |threads: usize| -> Result<(objview_episode::EpisodeResult, f64)> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("thread pool")?;
        pool.install(|| {
            let mut script = Scripted::poses(&order, ExecutionMode::SetCoverPlan);
            let t = Instant::now();
            let r = run_episode(
                scene.clone(),
                &mut script,
                &settings,
                Budget::Auto,
                0,
                start_pose(3.0),
                candidates.clone(),
                json!({}),
            )?;
            Ok((r, t.elapsed().as_secs_f64()))
        })
    };
    let (r, wall) = engine_run(1)?;
    let engine: Vec<f64> = r.steps.iter().map(|s| s.engine_seconds).collect();
    let (med, p90, max) = stats(engine.clone());
    let (med_late, _, _) = stats(engine.iter().skip(5).copied().collect());
    println!(
        "engine step (render + fusion + SC/NSC/CD at 3 τ + MS), {} views, one thread: median {:.1} ms, p90 {:.1} ms, max {:.1} ms; median after the first 5 views {:.1} ms; episode {:.2} s",
        r.steps.len(),
        1e3 * med,
        1e3 * p90,
        1e3 * max,
        1e3 * med_late,
        wall
    );
    // The far-target updates run on the rayon pool: the same episode on every thread.
    let all = rayon::current_num_threads();
    let (r_all, wall_all) = engine_run(all)?;
    let (med_all, p90_all, _) = stats(r_all.steps.iter().map(|s| s.engine_seconds).collect());
    println!(
        "engine step, {all} threads: median {:.1} ms, p90 {:.1} ms; episode {:.2} s ({:.2}x the one-thread median)",
        1e3 * med_all,
        1e3 * p90_all,
        wall_all,
        med / med_all.max(1e-12)
    );
    let stage = |i: usize| stats(r.steps.iter().map(|s| s.stage_seconds[i]).collect()).0;
    let stages = [stage(0), stage(1), stage(2), stage(3)];
    println!(
        "  by stage (medians, one thread): render {:.1} ms, fusion {:.1} ms, nearest-fused distances of the GT (SC, CD) and the reference (NSC) {:.1} ms, coverage counts + MS {:.1} ms",
        1e3 * stages[0],
        1e3 * stages[1],
        1e3 * stages[2],
        1e3 * stages[3]
    );
    let mut planners = Vec::new();
    if a.planner_steps > 0 {
        for name in ["rse", "rse-mov"] {
            let mut p = objview_planners::registry::by_name(name).map_err(anyhow::Error::msg)?;
            let s = EpisodeSettings { cap: a.planner_steps + 1, ..settings.clone() };
            let r = run_episode(
                scene.clone(),
                p.as_mut(),
                &s,
                Budget::Auto,
                0,
                start_pose(3.0),
                candidates.clone(),
                json!({}),
            )?;
            let plan: Vec<f64> = r.steps.iter().skip(1).map(|s| s.planner_seconds).collect();
            let (pm, pp90, pmax) = stats(plan);
            println!(
                "{name} planning per step ({} steps, all threads of the pool): median {:.1} ms, p90 {:.1} ms, max {:.1} ms",
                r.steps.len() - 1,
                1e3 * pm,
                1e3 * pp90,
                1e3 * pmax
            );
            planners.push(json!({"planner": name, "steps": r.steps.len() - 1, "median_s": pm, "p90_s": pp90, "max_s": pmax}));
        }
    }
    if let Some(path) = &a.json {
        let v = json!({
            "settings": objview_runs::provenance::settings("bench episode", json!({
                "object": a.object, "triangles": mesh.num_triangles(), "gt_points": scene.gt.len(), "views": a.views,
                "threads": rayon::current_num_threads(),
            })),
            "reference_seconds": reference_s,
            "reference_points": scene.reference.points.len(),
            "engine_step_seconds": engine,
            "engine_median_s": med,
            "engine_p90_s": p90,
            "engine_all_threads": {"threads": all, "median_s": med_all, "p90_s": p90_all},
            "stage_median_s": {"render": stages[0], "fusion": stages[1], "distances": stages[2], "coverage_ms": stages[3]},
            "planners": planners,
        });
        crate::common::write_json(path, &v)?;
    }
    Ok(())
}
