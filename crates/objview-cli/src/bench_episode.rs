//! `objview bench episode`: arguments and printing; the measurement is
//! [`objview_runs::bench::episode`].

use anyhow::Result;
use clap::Parser;
use objview_runs::bench::episode::{bench_episode as measure, EpisodeBenchSettings};

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
    /// Short episodes as `bench serve`'s clients play them (start view + 5 random tammes-360
    /// moves, budget 5, CD at the checkpoint K=5), timed on one thread (0 skips them).
    #[arg(long, default_value_t = 8)]
    pub short_episodes: usize,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

impl EpisodeBenchArgs {
    fn settings(&self) -> EpisodeBenchSettings {
        EpisodeBenchSettings {
            object: self.object.clone(),
            triangles: self.triangles,
            gt_points: self.gt_points,
            views: self.views,
            planner_steps: self.planner_steps,
            short_episodes: self.short_episodes,
        }
    }
}

pub fn bench_episode(a: EpisodeBenchArgs) -> Result<()> {
    let host = crate::bench::announce_host();
    let r = measure(&a.settings(), crate::run::registry())?;
    println!(
        "{}: {} triangles, {} GT points; observable reference: {} points from {} views in {:.2} s ({:.1} ms/view)",
        a.object,
        r.triangles,
        r.gt_points,
        r.reference_points,
        r.reference_views,
        r.reference_seconds,
        1e3 * r.reference_seconds / r.reference_views.max(1) as f64
    );
    println!(
        "engine step (render + fusion + SC/NSC at 3 τ + MS), {} views ({} without a checkpoint), one thread: median {:.2} ms, p90 {:.2} ms, max {:.2} ms; median after the first 5 views {:.2} ms; episode {:.2} s",
        r.engine_step_seconds.len(),
        r.engine_step_seconds.len() - r.checkpoint_views,
        1e3 * r.engine.median,
        1e3 * r.engine.p90,
        1e3 * r.engine.max,
        1e3 * r.engine_median_after_5,
        r.engine_episode_seconds
    );
    println!(
        "engine step, {} threads: median {:.2} ms, p90 {:.2} ms; episode {:.2} s ({:.2}x the one-thread median)",
        r.threads,
        1e3 * r.engine_all_threads.median,
        1e3 * r.engine_all_threads.p90,
        r.engine_all_threads_episode_seconds,
        r.all_threads_speedup()
    );
    println!(
        "  by stage (medians, one thread): render {:.2} ms, fusion {:.2} ms, SC + NSC coverage {:.2} ms, MS + rest {:.2} ms",
        1e3 * r.stages.render,
        1e3 * r.stages.fusion,
        1e3 * r.stages.coverage,
        1e3 * r.stages.rest
    );
    println!(
        "  CD at checkpoints (reported separately): {} views with a checkpoint, median {:.1} ms, max {:.1} ms per checkpoint view",
        r.checkpoint_views,
        1e3 * r.checkpoint_cd.median,
        1e3 * r.checkpoint_cd.max
    );
    let each: Vec<String> =
        r.checkpoint_cd_each.iter().map(|(v, s)| format!("view {v}: {:.1} ms", 1e3 * s)).collect();
    println!("  CD per checkpoint view: {}", each.join(", "));
    for p in &r.planners {
        println!(
            "{} planning per step ({} steps, all threads of the pool): median {:.1} ms, p90 {:.1} ms, max {:.1} ms",
            p.planner,
            p.steps,
            1e3 * p.seconds.median,
            1e3 * p.seconds.p90,
            1e3 * p.seconds.max
        );
    }
    if let Some(e) = &r.short {
        let views: Vec<String> = e.per_view.iter().map(|t| format!("{:.1}", 1e3 * t)).collect();
        println!(
            "short episodes ({} of start + 5 random moves, as `bench serve`'s clients; one thread): engine {:.1} ms per episode = render {:.1} + fusion {:.1} + SC/NSC coverage {:.1} + MS/rest {:.1} + checkpoint K=5 (CD) {:.1} ms; per view [{}] ms; {:.1} moves/s of one core",
            e.episodes,
            1e3 * e.per_episode(),
            1e3 * e.stages.render,
            1e3 * e.stages.fusion,
            1e3 * e.stages.coverage,
            1e3 * e.stages.rest,
            1e3 * e.checkpoint,
            views.join(", "),
            e.moves_per_core_second()
        );
    }
    if let Some(path) = &a.json {
        crate::bench::write_figures(path, r.to_json(), &host)?;
    }
    Ok(())
}
