//! Planning time of `completion-scp` and `completion-mcp` per plan (completion + steps + ILP +
//! path) and of `completion-nbv` per step (completion + voxels + HPR gains of every candidate)
//! on the built-in mug at ~100k triangles, for the README ("Hybrid planners"):
//! `cargo run --profile ci -p objview-planners --example hybrid_plan_time [-- TRIANGLES [nbv]]`
//! (`nbv`: only the NBV episodes, with median / mean / max step time and every step's sizes,
//! best gain and chosen view). NBV's gains run on rayon's pool: `RAYON_NUM_THREADS=1` measures
//! one thread (the README's figures).

use std::path::Path;
use std::sync::Arc;

use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeSettings};
use objview_geom::cloud::sample_surface;
use objview_geom::normalize::{normalize, Normalization};
use objview_geom::synth::build_with_triangles;
use objview_planners::hybrid::nbv::CompletionNbv;
use objview_planners::hybrid::plan::{CompletionPlan, PlanKind};
use objview_planners::hybrid::HybridSettings;
use objview_views::{start_pose, ViewSet, ViewSpace};

fn main() {
    let tris: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(100_000);
    let nbv_only = std::env::args().nth(2).as_deref() == Some("nbv");
    let mesh = build_with_triangles("mug", tris);
    let n_tris = mesh.num_triangles();
    let (mesh, _) = normalize(mesh, Normalization::Unit, Path::new("mug")).unwrap();
    let gt = sample_surface(&mesh, 100_000, 1);
    let vs = ViewSpace::builtin("whole").unwrap();
    let settings = EpisodeSettings { record_timings: false, ..Default::default() };
    let t = std::time::Instant::now();
    let scene =
        Arc::new(scene_from_parts("mug", mesh, gt, "sampled".into(), &vs, "whole", &settings, None).unwrap());
    println!("mug: {n_tris} triangles, scene + reference {:.1} s", t.elapsed().as_secs_f64());
    let cands = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0));
    let plans: &[(PlanKind, Budget)] = if nbv_only {
        &[]
    } else {
        &[
            (PlanKind::SetCover, Budget::Auto),
            (PlanKind::MaxCoverage, Budget::Fixed(5)),
            (PlanKind::MaxCoverage, Budget::Fixed(10)),
            (PlanKind::MaxCoverage, Budget::Fixed(30)),
        ]
    };
    for &(kind, budget) in plans {
        for completion in ["oracle", "identity"] {
            let s = HybridSettings { completion: completion.into(), ..HybridSettings::default() };
            let mut p = CompletionPlan::new(kind, s).unwrap();
            let r = run_episode(
                scene.clone(),
                &mut p,
                &settings,
                budget,
                0,
                start_pose(3.0),
                cands.clone(),
                serde_json::json!({}),
            )
            .unwrap();
            let info = p.last_plan().expect("a plan was made");
            println!(
                "{:<26} budget {:<4}: plan {:.3} s (completion {:.3}, steps {:.3}, selection {:.3}, path {:.3} over {} nodes); \
                 {} completed pts, {} target / {} occluder voxels, \
                 {} columns, ILP {} ({} chosen, bound {}, gap {}, {:.3} s), {} filled, {} views, NSC@0.02 {:.4}, {}",
                r.method,
                budget.to_string(),
                info.plan_seconds,
                info.completion_seconds,
                // The steps (outlier removal, voxels, the 360 covers) are what the plan's
                // "steps" time holds besides the selection.
                info.steps_seconds - info.selection.seconds,
                info.selection.seconds,
                info.tsp.as_ref().map_or(0.0, |t| t.seconds),
                info.tsp.as_ref().map_or(0, |t| t.order.len()),
                info.completed_points,
                info.target_voxels,
                info.occluder_voxels,
                info.columns,
                info.selection.status,
                info.selection.chosen.len(),
                info.selection.bound,
                info.selection.gap,
                info.selection.seconds,
                info.filled.len(),
                r.visited_poses.len(),
                r.checkpoints[&"terminal".parse().unwrap()].metrics.nsc["0.02"],
                r.terminal_reason,
            );
        }
    }
    // NBV: 10 steps after the start view (cap 11 views).
    let capped = EpisodeSettings { cap: 11, ..settings.clone() };
    for completion in ["oracle", "identity"] {
        let s = HybridSettings { completion: completion.into(), ..HybridSettings::default() };
        let mut p = CompletionNbv::new(s).unwrap();
        let r = run_episode(
            scene.clone(),
            &mut p,
            &capped,
            Budget::Auto,
            0,
            start_pose(3.0),
            cands.clone(),
            serde_json::json!({}),
        )
        .unwrap();
        let steps = p.steps();
        let n = steps.len().max(1) as f64;
        let mean =
            |f: &dyn Fn(&objview_planners::hybrid::nbv::NbvStep) -> f64| steps.iter().map(f).sum::<f64>() / n;
        let mut times: Vec<f64> = steps.iter().map(|s| s.step_seconds).collect();
        times.sort_by(f64::total_cmp);
        let median = if times.is_empty() {
            0.0
        } else if times.len() % 2 == 1 {
            times[times.len() / 2]
        } else {
            (times[times.len() / 2 - 1] + times[times.len() / 2]) / 2.0
        };
        let max = times.last().copied().unwrap_or(0.0);
        println!(
            "{:<26} {} steps: per step median {:.3} s, mean {:.3} s, max {:.3} s (completion {:.3}, HPR gains {:.3}); \
             score points mean {:.0} (max {}), {} views, NSC@0.02 {:.4}, {}",
            r.method,
            steps.len(),
            median,
            mean(&|s| s.step_seconds),
            max,
            mean(&|s| s.completion_seconds),
            mean(&|s| s.gain_seconds),
            mean(&|s| s.score_points as f64),
            steps.iter().map(|s| s.score_points).max().unwrap_or(0),
            r.visited_poses.len(),
            r.checkpoints[&"terminal".parse().unwrap()].metrics.nsc["0.02"],
            r.terminal_reason,
        );
        for (i, s) in steps.iter().enumerate() {
            println!(
                "  step {i}: {:.3} s (gains {:.3}), {} score points, {} scored, best gain {}, chosen {:?} (gain {})",
                s.step_seconds, s.gain_seconds, s.score_points, s.scored, s.best_gain, s.chosen, s.chosen_gain
            );
        }
    }
}
