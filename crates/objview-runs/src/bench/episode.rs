//! `objview bench episode`: the cost of one episode step in the environment — render + fusion +
//! SC/NSC at 3 τ + MS, and CD where a checkpoint is recorded — on a built-in object tessellated to a given triangle count with a
//! sampled ground-truth cloud, and the planning time per step of RSE / RSE-Mov on the same
//! object.
//!
//! The engine episode follows a fixed script (a spread order of tammes-360 candidates), once on
//! one thread and once on every thread of the pool, so that the step cost does not depend on a
//! planner's choices; the planners then run their own short episodes on the same scene.

use std::sync::Arc;
use std::time::Instant;

use objview_episode::{
    run_episode, scene_from_parts, Budget, EpisodeResult, EpisodeSettings, ExecutionMode, Scripted,
};
use objview_geom::cloud::sample_surface;
use objview_geom::normalize::{normalize, Normalization};
use objview_geom::Pose;
use objview_views::{start_pose, ViewSet, ViewSpace};
use serde_json::{json, Value};

use super::{thread_pool, Spread};
use crate::RunError;
use objview_planners::registry::Registry;

/// The planners whose planning time per step is measured, in order.
pub const TIMED_PLANNERS: [&str; 2] = ["rse", "rse-mov"];

/// What `objview bench episode` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeBenchSettings {
    /// Built-in object (see `objview objects list`).
    pub object: String,
    /// Target triangle count.
    pub triangles: usize,
    /// Ground-truth points (sampled on the surface).
    pub gt_points: usize,
    /// Views per engine episode (tammes-360 candidates in a fixed spread order; at most 360).
    pub views: usize,
    /// Planner steps timed for each of [`TIMED_PLANNERS`] (0 skips them).
    pub planner_steps: usize,
    /// Short episodes as `bench serve`'s clients play them ([`SHORT_MOVES`] random distinct
    /// tammes-360 moves after the start view, budget [`SHORT_MOVES`]), on one thread (0 skips
    /// them).
    pub short_episodes: usize,
}

/// Moves of a short episode (`objview bench serve`'s default budget).
pub const SHORT_MOVES: usize = 5;

impl Default for EpisodeBenchSettings {
    /// The mug at ~100k triangles with 300k ground-truth points, 50 views, 10 planner steps,
    /// 8 short episodes.
    fn default() -> EpisodeBenchSettings {
        EpisodeBenchSettings {
            object: "mug".into(),
            triangles: 100_000,
            gt_points: 300_000,
            views: 50,
            planner_steps: 10,
            short_episodes: 8,
        }
    }
}

/// Seconds per engine stage: the medians of the one-thread episode over the views without a
/// checkpoint ([`EpisodeBenchReport::stages`]), or the per-episode sums of the short episodes
/// ([`ShortEpisodes::stages`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageMedians {
    /// Depth rendering.
    pub render: f64,
    /// Fusion of the frame into the reconstruction.
    pub fusion: f64,
    /// Coverage of the ground truth (SC) and of the reference (NSC) at every τ.
    pub coverage: f64,
    /// MS and bookkeeping.
    pub rest: f64,
}

/// The engine's cost of short episodes (start view + [`SHORT_MOVES`] random moves, the
/// checkpoint `K=5` with its CD at the last one): what one episode of `objview bench serve`
/// costs the server's engine. Means over the episodes, seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct ShortEpisodes {
    /// Episodes run.
    pub episodes: usize,
    /// Engine seconds per view (start view first), CD included at the last.
    pub per_view: Vec<f64>,
    /// Stage sums per episode over its views (the last view's MS and bookkeeping excluded).
    pub stages: StageMedians,
    /// The last view's MS, bookkeeping and checkpoint CD.
    pub checkpoint: f64,
}

impl ShortEpisodes {
    /// Engine seconds per episode.
    pub fn per_episode(&self) -> f64 {
        self.per_view.iter().sum()
    }

    /// Moves per second of one core spent on nothing but the engine.
    pub fn moves_per_core_second(&self) -> f64 {
        SHORT_MOVES as f64 / self.per_episode().max(1e-12)
    }
}

/// Planning time per step of one planner (its first step, from the start pose, left out).
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerTiming {
    /// The planner's name.
    pub planner: String,
    /// Steps timed.
    pub steps: usize,
    /// Seconds per step.
    pub seconds: Spread,
}

/// The figures of [`bench_episode`]; times in seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeBenchReport {
    /// What was measured.
    pub settings: EpisodeBenchSettings,
    /// Triangles of the tessellated object.
    pub triangles: usize,
    /// Ground-truth points.
    pub gt_points: usize,
    /// Points of the observable reference.
    pub reference_points: usize,
    /// Views the observable reference was rendered from.
    pub reference_views: usize,
    /// Time to build the scene (mostly the observable reference).
    pub reference_seconds: f64,
    /// Engine seconds per step of the one-thread episode, in step order (CD included at the
    /// views with a checkpoint).
    pub engine_step_seconds: Vec<f64>,
    /// Their spread over the views without a checkpoint: the step cost.
    pub engine: Spread,
    /// The last stage (MS, bookkeeping and CD) at the views with a checkpoint: the cost of a
    /// checkpoint's CD, over how many views.
    pub checkpoint_cd: Spread,
    /// Views with a checkpoint.
    pub checkpoint_views: usize,
    /// `(view, seconds)` of each view with a checkpoint, in view order: the first carries the
    /// first exact distances of every ground-truth point (what a short episode pays).
    pub checkpoint_cd_each: Vec<(usize, f64)>,
    /// Their median after the first 5 views (NaN when there are no more).
    pub engine_median_after_5: f64,
    /// Wall time of the one-thread episode.
    pub engine_episode_seconds: f64,
    /// Threads of the pool (the all-threads episode and the planners run on it).
    pub threads: usize,
    /// Engine seconds per step of the same episode on every thread.
    pub engine_all_threads: Spread,
    /// Wall time of the all-threads episode.
    pub engine_all_threads_episode_seconds: f64,
    /// Stage medians of the one-thread episode.
    pub stages: StageMedians,
    /// Planning times, one per [`TIMED_PLANNERS`] entry (empty when `planner_steps` is 0).
    pub planners: Vec<PlannerTiming>,
    /// Short episodes (`None` when `short_episodes` is 0).
    pub short: Option<ShortEpisodes>,
}

impl EpisodeBenchReport {
    /// One-thread median over all-threads median.
    pub fn all_threads_speedup(&self) -> f64 {
        self.engine.median / self.engine_all_threads.median.max(1e-12)
    }

    /// The figures as `objview bench episode --json` writes them.
    pub fn to_json(&self) -> Value {
        let planners: Vec<Value> = self
            .planners
            .iter()
            .map(|p| {
                json!({"planner": p.planner, "steps": p.steps, "median_s": p.seconds.median,
                       "p90_s": p.seconds.p90, "max_s": p.seconds.max})
            })
            .collect();
        json!({
            "settings": crate::provenance::settings("bench episode", json!({
                "object": self.settings.object, "triangles": self.triangles, "gt_points": self.gt_points,
                "views": self.settings.views, "threads": self.threads,
                "short_episodes": self.settings.short_episodes,
            })),
            "reference_seconds": self.reference_seconds,
            "reference_points": self.reference_points,
            "engine_step_seconds": self.engine_step_seconds,
            "engine_median_s": self.engine.median,
            "engine_p90_s": self.engine.p90,
            "checkpoint_cd": {"views": self.checkpoint_views, "median_s": self.checkpoint_cd.median,
                              "max_s": self.checkpoint_cd.max,
                              "each": self.checkpoint_cd_each.iter()
                                  .map(|(v, s)| json!({"view": v, "seconds": s})).collect::<Vec<_>>()},
            "engine_all_threads": {"threads": self.threads, "median_s": self.engine_all_threads.median,
                                   "p90_s": self.engine_all_threads.p90},
            "stage_median_s": {"render": self.stages.render, "fusion": self.stages.fusion,
                               "coverage": self.stages.coverage, "rest": self.stages.rest},
            "planners": planners,
            "short_episodes": self.short.as_ref().map(|e| json!({
                "episodes": e.episodes, "moves": SHORT_MOVES, "per_view_s": e.per_view,
                "per_episode_s": e.per_episode(),
                "stage_s": {"render": e.stages.render, "fusion": e.stages.fusion,
                            "coverage": e.stages.coverage, "rest": e.stages.rest},
                "checkpoint_s": e.checkpoint,
                "moves_per_core_second": e.moves_per_core_second(),
            })),
        })
    }
}

/// Builds the scene of `settings.object` (view space `whole`, sampled ground truth, no
/// reference cache), runs the scripted engine episode on one thread and on every thread of the
/// current rayon pool, then a short episode of each of [`TIMED_PLANNERS`] made by `planners`.
pub fn bench_episode(
    settings: &EpisodeBenchSettings,
    planners: &Registry,
) -> Result<EpisodeBenchReport, RunError> {
    let name = &settings.object;
    let obj = objview_geom::synth::find(name)
        .ok_or_else(|| RunError::Invalid(format!("--object: no built-in object named {name:?}")))?;
    let (mesh, _) = normalize(
        obj.build_with_triangles(settings.triangles),
        Normalization::Unit,
        std::path::Path::new(name),
    )?;
    let gt = sample_surface(&mesh, settings.gt_points, 0);
    let episode = EpisodeSettings { enough_info: false, ..Default::default() };
    let space = ViewSpace::builtin("whole").ok_or_else(|| RunError::Invalid("no view space whole".into()))?;
    let t = Instant::now();
    let scene = Arc::new(scene_from_parts(
        name,
        mesh.clone(),
        gt,
        "sampled".into(),
        &space,
        "whole",
        &episode,
        None,
    )?);
    // As the server's scenes: episodes after the first copy the start view's state.
    scene.keep_start_states(1);
    let reference_seconds = t.elapsed().as_secs_f64();
    let candidates = Arc::new(ViewSet::resolve("tammes-360")?.poses(episode.view_radius));
    // A spread order: every 37th candidate (37 is coprime with 360).
    let order: Vec<Pose> = (0..settings.views.min(360)).map(|i| candidates[(i * 37) % 360]).collect();
    let engine_run = |threads: usize| -> Result<(EpisodeResult, f64), RunError> {
        thread_pool(threads)?.install(|| {
            let mut script = Scripted::poses(&order, ExecutionMode::SetCoverPlan);
            let t = Instant::now();
            let r = run_episode(
                scene.clone(),
                &mut script,
                &episode,
                Budget::Auto,
                0,
                start_pose(3.0),
                candidates.clone(),
                json!({}),
            )?;
            Ok((r, t.elapsed().as_secs_f64()))
        })
    };
    let (r, engine_episode_seconds) = engine_run(1)?;
    let engine_step_seconds: Vec<f64> = r.steps.iter().map(|s| s.engine_seconds).collect();
    let at_checkpoint: std::collections::BTreeSet<usize> = r.checkpoints.values().map(|c| c.step).collect();
    let plain = |r: &EpisodeResult| -> Vec<f64> {
        r.steps.iter().filter(|s| !at_checkpoint.contains(&s.step)).map(|s| s.engine_seconds).collect()
    };
    let engine = Spread::of(plain(&r));
    let engine_median_after_5 = Spread::of(
        r.steps
            .iter()
            .skip(5)
            .filter(|s| !at_checkpoint.contains(&s.step))
            .map(|s| s.engine_seconds)
            .collect(),
    )
    .median;
    let checkpoint_cd_each: Vec<(usize, f64)> = r
        .steps
        .iter()
        .filter(|s| at_checkpoint.contains(&s.step))
        .map(|s| (s.step, s.stage_seconds[3]))
        .collect();
    let checkpoint_cd = Spread::of(checkpoint_cd_each.iter().map(|c| c.1).collect());
    // The far-target updates run on the rayon pool: the same episode on every thread.
    let threads = rayon::current_num_threads();
    let (r_all, engine_all_threads_episode_seconds) = engine_run(threads)?;
    let engine_all_threads = Spread::of(plain(&r_all));
    let stage = |i: usize| {
        Spread::of(
            r.steps.iter().filter(|s| !at_checkpoint.contains(&s.step)).map(|s| s.stage_seconds[i]).collect(),
        )
        .median
    };
    let stages = StageMedians { render: stage(0), fusion: stage(1), coverage: stage(2), rest: stage(3) };
    let mut timings = Vec::new();
    if settings.planner_steps > 0 {
        for name in TIMED_PLANNERS {
            let mut p = planners.by_name(name).map_err(RunError::Invalid)?;
            let s = EpisodeSettings { cap: settings.planner_steps + 1, ..episode.clone() };
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
            timings.push(PlannerTiming {
                planner: name.to_string(),
                steps: plan.len(),
                seconds: Spread::of(plan),
            });
        }
    }
    let short = (settings.short_episodes > 0)
        .then(|| short_episodes(&scene, &episode, &candidates, settings.short_episodes))
        .transpose()?;
    Ok(EpisodeBenchReport {
        settings: settings.clone(),
        triangles: mesh.num_triangles(),
        gt_points: scene.gt.len(),
        reference_points: scene.reference.points.len(),
        reference_views: scene.reference.poses.len(),
        reference_seconds,
        engine_step_seconds,
        engine,
        checkpoint_views: at_checkpoint.len(),
        checkpoint_cd,
        checkpoint_cd_each,
        engine_median_after_5,
        engine_episode_seconds,
        threads,
        engine_all_threads,
        engine_all_threads_episode_seconds,
        stages,
        planners: timings,
        short,
    })
}

/// Runs `n` short episodes on `scene` on a one-thread pool: episode e moves to
/// [`SHORT_MOVES`] distinct feasible candidates drawn with ChaCha8 seeded by
/// `splitmix64(e)`, budget [`SHORT_MOVES`].
fn short_episodes(
    scene: &Arc<objview_episode::Scene>,
    episode: &EpisodeSettings,
    candidates: &Arc<Vec<Pose>>,
    n: usize,
) -> Result<ShortEpisodes, RunError> {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let feasible: Vec<Pose> = candidates.iter().filter(|p| scene.space.is_feasible(p)).copied().collect();
    let mut per_view = [0.0; SHORT_MOVES + 1];
    let mut stage = [0.0; 4];
    let mut checkpoint = 0.0;
    thread_pool(1)?.install(|| -> Result<(), RunError> {
        for e in 0..n {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(objview_geom::hash::splitmix64(e as u64));
            let moves: Vec<Pose> = feasible.choose_multiple(&mut rng, SHORT_MOVES).copied().collect();
            let mut script = Scripted::poses(&moves, ExecutionMode::Iterative);
            let r = run_episode(
                scene.clone(),
                &mut script,
                episode,
                Budget::Fixed(SHORT_MOVES),
                e as u64,
                start_pose(3.0),
                candidates.clone(),
                json!({}),
            )?;
            let last = r.steps.len() - 1;
            for (v, s) in r.steps.iter().enumerate() {
                if let Some(t) = per_view.get_mut(v) {
                    *t += s.engine_seconds;
                }
                for (a, &x) in stage.iter_mut().zip(&s.stage_seconds) {
                    *a += x;
                }
                if v == last {
                    stage[3] -= s.stage_seconds[3];
                    checkpoint += s.stage_seconds[3];
                }
            }
        }
        Ok(())
    })?;
    let m = 1.0 / n as f64;
    Ok(ShortEpisodes {
        episodes: n,
        per_view: per_view.iter().map(|t| t * m).collect(),
        stages: StageMedians {
            render: stage[0] * m,
            fusion: stage[1] * m,
            coverage: stage[2] * m,
            rest: stage[3] * m,
        },
        checkpoint: checkpoint * m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tiny_episode_gives_finite_ordered_figures() {
        let settings = EpisodeBenchSettings {
            object: "cube".into(),
            triangles: 200,
            gt_points: 2000,
            views: 3,
            planner_steps: 1,
            short_episodes: 2,
        };
        let r = bench_episode(&settings, &objview_planners::registry::Registry::builtin()).unwrap();
        assert_eq!(r.engine_step_seconds.len(), 4, "the start and 3 views");
        for s in [r.engine, r.engine_all_threads].iter().chain(r.planners.iter().map(|p| &p.seconds)) {
            assert!(s.median.is_finite() && s.median >= 0.0, "{s:?}");
            assert!(s.median <= s.p90 && s.p90 <= s.max, "{s:?}");
        }
        // The engine figures are those of the views without a checkpoint.
        let plain_max = (r.engine_step_seconds.iter().enumerate())
            .filter(|(v, _)| !r.checkpoint_cd_each.iter().any(|c| c.0 == *v))
            .map(|(_, &t)| t)
            .fold(0.0, f64::max);
        assert_eq!(r.engine.max, plain_max);
        assert!(r.engine_median_after_5.is_nan(), "only 4 steps");
        // One entry per checkpoint view, in view order, whose largest is the reported max.
        assert!(r.checkpoint_views >= 1, "the terminal checkpoint at least");
        assert_eq!(r.checkpoint_cd_each.len(), r.checkpoint_views);
        assert!(r.checkpoint_cd_each.windows(2).all(|w| w[0].0 < w[1].0), "{:?}", r.checkpoint_cd_each);
        assert_eq!(r.checkpoint_cd.max, r.checkpoint_cd_each.iter().map(|c| c.1).fold(0.0, f64::max));
        assert_eq!(
            r.planners.iter().map(|p| (p.planner.as_str(), p.steps)).collect::<Vec<_>>(),
            [("rse", 1), ("rse-mov", 1)]
        );
        assert_eq!(r.gt_points, 2000);
        assert!(r.reference_points > 0 && r.reference_views > 0);
        let v = r.to_json();
        for key in [
            "settings",
            "reference_seconds",
            "reference_points",
            "engine_step_seconds",
            "engine_median_s",
            "engine_p90_s",
            "engine_all_threads",
            "stage_median_s",
            "planners",
        ] {
            assert!(v.get(key).is_some(), "{key}");
        }
        assert_eq!(v["settings"]["command"], "bench episode");
        assert_eq!(v["checkpoint_cd"]["each"].as_array().map(Vec::len), Some(r.checkpoint_views));
        assert_eq!(v["checkpoint_cd"]["each"][0]["view"], r.checkpoint_cd_each[0].0);
        assert_eq!(v["planners"][1]["planner"], "rse-mov");
        // Short episodes: the start view and SHORT_MOVES moves, whose per-view times add up to
        // the stages and the checkpoint.
        let e = r.short.as_ref().expect("short episodes were asked for");
        assert_eq!((e.episodes, e.per_view.len()), (2, SHORT_MOVES + 1));
        let stages = e.stages.render + e.stages.fusion + e.stages.coverage + e.stages.rest;
        assert!((stages + e.checkpoint - e.per_episode()).abs() < 1e-9, "{e:?}");
        assert!(e.checkpoint > 0.0 && e.moves_per_core_second().is_finite(), "{e:?}");
        assert_eq!(v["short_episodes"]["moves"], SHORT_MOVES);
        assert_eq!(v["settings"]["short_episodes"], 2);
        let none = bench_episode(
            &EpisodeBenchSettings { short_episodes: 0, planner_steps: 0, ..settings },
            &objview_planners::registry::Registry::builtin(),
        )
        .unwrap();
        assert!(none.short.is_none() && none.to_json()["short_episodes"].is_null());
    }
}
