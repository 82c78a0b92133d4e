//! The main job on the built-in objects (`objview demo`), end to end:
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
//!    checkpoint list is the paper's 5, 30) in `whole` and `quarter`, and the ground-truth
//!    oracle over tammes-128 on Main-Hidden-Test and Slow-Saturation (the slow-saturation
//!    table), and every learned or hybrid planner the registry holds (`nbv-net` with its shipped
//!    weights, automatic budget), into `episodes/*.jsonl` (resumable) — all runs' episodes in
//!    one pool ([`run_plans`]), so the cores stay busy across runs;
//! 5. write the report (the paper's Tables 2–5, CSVs, figures) into `report/`.
//!
//! What it tells the user goes through `say` (one call per line or block of lines), batch
//! progress through a [`Progress`]: the command line prints both.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use objview_dataset::{ObjectRef, Progress};
use objview_episode::{Budget, ExecutionMode, Family};
use objview_geom::normalize::{load_normalized, Normalization};
use objview_geom::pose::VIEW_RADIUS;
use objview_pool::split::SplitSettings;
use objview_render::{Camera, Intrinsics};
use objview_views::{start_pose, ViewSet, ViewSpace};
use objview_voxel::{Visibility, VisibilityMode, VoxelSet, DEFAULT_RESOLUTION};
use rayon::prelude::*;
use serde_json::json;

use crate::annotate::AnnotatePlan;
use crate::episodes::{run_plans, EpisodePlan};
use crate::RunError;
use objview_planners::registry::Registry;

/// The demo's settings.
#[derive(Debug, Clone)]
pub struct DemoPlan {
    /// Output folder.
    pub out: PathBuf,
    /// View set of the observable-surface sweep.
    pub views: String,
    /// Exact d_plan time limit per object in the annotation stage, seconds.
    pub time_limit: f64,
    /// Only these built-in objects (empty: all).
    pub objects: Vec<String>,
    /// Stop after the geometry stage.
    pub geometry_only: bool,
    /// Stop after the difficulty stages.
    pub no_episodes: bool,
    /// Main-Hidden-Test quota as a fraction of the main pool.
    pub test_fraction: f64,
}

impl Default for DemoPlan {
    fn default() -> Self {
        DemoPlan {
            out: PathBuf::from("out/demo"),
            views: "tammes-128".into(),
            time_limit: 30.0,
            objects: Vec::new(),
            geometry_only: false,
            no_episodes: false,
            test_fraction: 0.15,
        }
    }
}

/// The classical planners of the episode stage with their budgets.
pub const DEMO_RUNS: [(&str, Budget); 4] = [
    ("random-tsp", Budget::Fixed(5)),
    ("random-tsp", Budget::Fixed(30)),
    ("rse", Budget::Auto),
    ("rse-mov", Budget::Auto),
];

/// The episode stage's runs: [`DEMO_RUNS`], then every learned and hybrid planner of
/// `planners` (iterative ones once with the automatic budget — K = 5 and K = 30 are
/// checkpoints of that run — budgeted plans at K = 5 and K = 30), in registry order.
pub fn demo_runs(planners: &Registry) -> Vec<(&'static str, Budget)> {
    let mut runs = DEMO_RUNS.to_vec();
    for e in planners.entries() {
        if matches!(e.family, Family::Learned | Family::Hybrid) {
            match e.mode {
                ExecutionMode::BudgetedPlan => {
                    runs.push((e.name, Budget::Fixed(5)));
                    runs.push((e.name, Budget::Fixed(30)));
                }
                _ => runs.push((e.name, Budget::Auto)),
            }
        }
    }
    runs
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

fn create_dir(dir: &Path) -> Result<(), RunError> {
    std::fs::create_dir_all(dir).map_err(|e| RunError::io(dir, e))
}

fn write_json(path: &Path, v: &serde_json::Value) -> Result<(), RunError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        create_dir(dir)?;
    }
    let mut s = serde_json::to_string_pretty(v).map_err(|e| RunError::Invalid(e.to_string()))?;
    s.push('\n');
    std::fs::write(path, s).map_err(|e| RunError::io(path, e))
}

impl DemoPlan {
    /// Runs the demo: `planners` makes the episode stage's planners, `progress` sees every
    /// batch, `say` every message.
    pub fn run(
        &self,
        planners: &Registry,
        progress: &dyn Progress,
        say: &dyn Fn(&str),
    ) -> Result<(), RunError> {
        let t0 = Instant::now();
        let objects_dir = self.out.join("objects");
        let renders_dir = self.out.join("renders");
        create_dir(&renders_dir)?;
        let mut paths = objview_geom::synth::write_pool(&objects_dir)?;
        for name in &self.objects {
            if objview_geom::synth::find(name).is_none() {
                return Err(RunError::Invalid(format!(
                    "--objects: no built-in object named {name:?} (see `objview objects list`)"
                )));
            }
        }
        if !self.objects.is_empty() {
            paths.retain(|p| self.objects.iter().any(|n| p.file_stem().is_some_and(|s| s == n.as_str())));
        }
        say(&format!("[1/8] synthesized {} built-in objects into {}", paths.len(), objects_dir.display()));
        let views = ViewSet::resolve(&self.views)?;
        let cameras: Vec<Camera> =
            views.poses(VIEW_RADIUS).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();

        let rows: Vec<Result<Row, (PathBuf, String)>> = paths
            .par_iter()
            .map(|p| one_object(p, &renders_dir, &cameras).map_err(|e| (p.clone(), e.to_string())))
            .collect();
        say(&format!(
            "[2/8] rendered the start view and swept {} ({} views) per object",
            self.views,
            views.len()
        ));

        let mut ok = Vec::new();
        let mut failed = Vec::new();
        for r in rows {
            match r {
                Ok(row) => ok.push(row),
                Err((p, e)) => failed.push(json!({"mesh": p.display().to_string(), "error": e})),
            }
        }
        let mut table = format!(
            "\n{:<18} {:>9} {:>9} {:>8} {:>8} {:>7} {:>10}",
            "object", "triangles", "gt_points", "|S_gt|", "|∪O(v)|", "ratio", "start_px"
        );
        for r in &ok {
            table.push_str(&format!(
                "\n{:<18} {:>9} {:>9} {:>8} {:>8} {:>7.3} {:>10}",
                r.name,
                r.triangles,
                r.gt_points,
                r.surface_voxels,
                r.union,
                r.union as f64 / r.surface_voxels.max(1) as f64,
                r.start_hits
            ));
        }
        for f in &failed {
            table.push_str(&format!("\nFAILED {}: {}", f["mesh"], f["error"]));
        }
        say(&table);
        let summary = json!({
            "settings": crate::provenance::settings("demo", json!({
                "views": self.views,
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
        let summary_path = self.out.join("summary.json");
        write_json(&summary_path, &summary)?;
        say(&format!(
            "\n[3/8] wrote {} ({} objects, {} failed); start-view depth + previews in {}; {:.1} s, {:.2} seconds per object on average",
            summary_path.display(),
            ok.len(),
            failed.len(),
            renders_dir.display(),
            t0.elapsed().as_secs_f64(),
            ok.iter().map(|r| r.seconds).sum::<f64>() / ok.len().max(1) as f64
        ));
        if self.geometry_only {
            return Ok(());
        }
        self.difficulty_stages(&paths, planners, progress, say)?;
        say(&format!("\ndemo finished in {:.1} s", t0.elapsed().as_secs_f64()));
        Ok(())
    }

    /// Stages 4–6 (annotate, split + stats, figures), then the episode stages.
    fn difficulty_stages(
        &self,
        objects: &[PathBuf],
        planners: &Registry,
        progress: &dyn Progress,
        say: &dyn Fn(&str),
    ) -> Result<(), RunError> {
        let annotations = self.out.join("annotations.jsonl");
        say(&format!(
            "\n[4/8] annotating the difficulty of every object (SPEC §4) into {}",
            annotations.display()
        ));
        let mut plan = AnnotatePlan::new(objects.to_vec(), annotations.clone());
        plan.settings.cover.time_limit_s = self.time_limit;
        let (s, seconds) = plan.run(progress)?;
        say(&format!(
            "annotate: {} done, {} failed, {} skipped (already in the file) in {seconds:.1} s -> {}",
            s.processed - s.failed,
            s.failed,
            s.skipped,
            annotations.display()
        ));
        let splits = self.out.join("splits");
        say(&format!("\n[5/8] splitting the pool (SPEC §6) into {}", splits.display()));
        let settings = SplitSettings { seed: 0, test_fraction: self.test_fraction, train_size: None };
        let out = crate::pool::split(std::slice::from_ref(&annotations), &splits, &settings)?;
        say(&out.splits.summary_text(out.annotations, self.test_fraction));
        let (stats, _) = crate::pool::stats(std::slice::from_ref(&annotations), Some(&splits))?;
        say(stats.to_text().trim_end());
        let figures = self.out.join("figures");
        say(&format!("\n[6/8] drawing Figure 2 into {}", figures.display()));
        let fig = crate::pool::figure(std::slice::from_ref(&annotations), &figures, 6)?;
        for f in fig.files.iter().chain([&fig.figures_json]) {
            say(&f.display().to_string());
        }
        if !self.no_episodes {
            self.episode_stages(&annotations, planners, say)?;
        }
        Ok(())
    }

    /// Stages 7–8: episodes of every classical planner and the oracle, then the report.
    fn episode_stages(
        &self,
        annotations: &Path,
        planners: &Registry,
        say: &dyn Fn(&str),
    ) -> Result<(), RunError> {
        let splits = self.out.join("splits");
        let test = splits.join("main_hidden_test.json");
        let slow = splits.join("slow_saturation.json");
        let episodes = self.out.join("episodes");
        create_dir(&episodes)?;
        let test_objects = objview_dataset::read_split(&test)?;
        let slow_objects = if slow.exists() { objview_dataset::read_split(&slow)? } else { Vec::new() };
        say(&format!(
            "\n[7/8] online episodes (SPEC §5) on Main-Hidden-Test ({} objects) into {}",
            test_objects.len(),
            episodes.display()
        ));
        let mut plans = Vec::new();
        let runs = demo_runs(planners);
        for space in ["whole", "quarter"] {
            for &(planner, budget) in &runs {
                plans.push(self.episode_plan(
                    &episodes,
                    planner,
                    space,
                    budget,
                    test_objects.clone(),
                    None,
                )?);
            }
        }
        // The slow-saturation diagnostic: the oracle over tammes-128 until it is exhausted.
        for (name, objects) in [("test", &test_objects), ("slow", &slow_objects)] {
            if name == "slow" && objects.is_empty() {
                continue;
            }
            let file = episodes.join(format!("oracle_whole_tammes128_{name}.jsonl"));
            let mut plan =
                self.episode_plan(&episodes, "oracle", "whole", Budget::Auto, objects.clone(), Some(file))?;
            plan.candidates_name = "tammes-128".into();
            plan.candidates = Arc::new(ViewSet::resolve("tammes-128")?.poses(plan.settings.view_radius));
            plan.settings.candidates = "tammes-128".into();
            plan.settings.enough_info = false;
            plans.push(plan);
        }
        // Every run's episodes in one pool (the cores stay busy across runs); each results
        // file is what the run alone would write.
        let t = Instant::now();
        let summaries = run_plans(&plans, planners, None)?;
        for (plan, s) in plans.iter().zip(&summaries) {
            say(&format!(
                "  {:<14} {:<8} budget {:<5} {} episodes ({} failed, {} already done) {:>6.1} s of episodes -> {}",
                plan.planner,
                plan.space_name,
                plan.budget.label(),
                s.done,
                s.failed,
                s.skipped,
                s.seconds,
                plan.out.display()
            ));
        }
        say(&format!("episodes: {} runs in {:.1} s", plans.len(), t.elapsed().as_secs_f64()));
        let files: Vec<PathBuf> = plans.iter().map(|p| p.out.clone()).collect();
        let report_dir = self.out.join("report");
        say(&format!("\n[8/8] report (the paper's Tables 2–5) into {}", report_dir.display()));
        let report = objview_report::build_report(
            &files,
            &[annotations.to_path_buf()],
            &objview_report::ReportSettings::default(),
        )?;
        let written = report.write(&report_dir)?;
        say(&report.markdown());
        say("Tables (Markdown + CSV) and figures (PNG + SVG):");
        for f in &written {
            say(&format!("  {}", f.display()));
        }
        Ok(())
    }

    /// The plan of one demo run: checkpoints 5 and 30, the demo's reference cache, quiet.
    fn episode_plan(
        &self,
        episodes: &Path,
        planner: &str,
        space: &str,
        budget: Budget,
        objects: Vec<ObjectRef>,
        file: Option<PathBuf>,
    ) -> Result<EpisodePlan, RunError> {
        let out =
            file.unwrap_or_else(|| episodes.join(format!("{planner}_{space}_{}.jsonl", budget.label())));
        let mut plan = EpisodePlan::new(planner, objects, out)?;
        plan.space =
            ViewSpace::builtin(space).ok_or_else(|| RunError::Invalid(format!("no view space {space}")))?;
        plan.space_name = space.to_string();
        plan.budget = budget;
        plan.cache_dir = Some(episodes.join("reference-cache"));
        plan.settings.checkpoint_ks = vec![5, 30];
        plan.settings.candidates = plan.candidates_name.clone();
        Ok(plan)
    }
}

fn one_object(path: &Path, renders: &Path, cameras: &[Camera]) -> Result<Row, RunError> {
    let t = Instant::now();
    let name = path.file_stem().unwrap_or_default().to_string_lossy().to_string();
    let (mesh, transform) = load_normalized(path, Normalization::Unit)?;
    let gt = objview_geom::cloud::ground_truth(&mesh, &transform, None)?;
    let set = VoxelSet::from_points(&gt.points, DEFAULT_RESOLUTION)?;
    let vis = Visibility::new(&set, &mesh, VisibilityMode::Inverse);
    let mut acc = vec![0u64; set.len().div_ceil(64)];
    for cam in cameras {
        vis.observe_union_into(cam, &mut acc);
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
