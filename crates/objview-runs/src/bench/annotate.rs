//! `objview bench annotate` and `objview bench stability`: the cost of the difficulty annotation
//! per stage (with one thread and every thread, and the peak memory), and how much its results
//! depend on the ground-truth sampling seed.
//!
//! Both run on built-in objects written as OBJ files into a temporary folder, so that the
//! annotation reads and normalizes them exactly as it would a user's mesh.

use std::collections::BTreeSet;
use std::path::Path;

use objview_dataset::annotate::{annotate_object, AnnotateSettings, Annotation, GridViews, StageTimings};
use objview_dataset::ObjectRef;
use objview_geom::stats::median;
use objview_geom::synth;
use rayon::prelude::*;
use serde_json::{json, Value};

use super::{peak_rss, reset_peak_rss, thread_pool};
use crate::RunError;

/// Writes built-in object `name` with about `triangles` triangles (0: its default detail) as
/// `<dir>/<name>.obj`; its object reference (uid `name`).
pub fn write_object(name: &str, triangles: usize, dir: &Path) -> Result<ObjectRef, RunError> {
    let obj = synth::find(name).ok_or_else(|| {
        RunError::Invalid(format!("no built-in object named {name:?} (see `objview objects list`)"))
    })?;
    let mesh = if triangles == 0 {
        obj.build(synth::Detail::default())
    } else {
        obj.build_with_triangles(triangles)
    };
    let path = dir.join(format!("{name}.obj"));
    objview_geom::write::write_obj(&path, &mesh)?;
    Ok(ObjectRef::from_mesh(&path))
}

/// The median of each stage over runs (NaN for each when there are none).
pub fn stage_medians<'a>(runs: impl IntoIterator<Item = &'a StageTimings>) -> StageTimings {
    let runs: Vec<&StageTimings> = runs.into_iter().collect();
    let m = |f: fn(&StageTimings) -> f64| median(&mut runs.iter().map(|t| f(t)).collect::<Vec<_>>());
    StageTimings {
        load: m(|t| t.load),
        ground_truth: m(|t| t.ground_truth),
        voxelize: m(|t| t.voxelize),
        visibility: m(|t| t.visibility),
        fit: m(|t| t.fit),
        cover: m(|t| t.cover),
    }
}

fn temp_dir() -> Result<tempfile::TempDir, RunError> {
    tempfile::tempdir().map_err(|e| RunError::io(std::env::temp_dir(), e))
}

fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// What `objview bench annotate` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotateBenchSettings {
    /// Built-in objects to tessellate at each size.
    pub objects: Vec<String>,
    /// Target triangle counts.
    pub sizes: Vec<usize>,
    /// Timed annotations per configuration (the median is reported; at least 1 is run).
    pub repeats: usize,
}

impl Default for AnnotateBenchSettings {
    /// The mug and the gear at ~10k and ~100k triangles, 3 repeats.
    fn default() -> AnnotateBenchSettings {
        AnnotateBenchSettings {
            objects: vec!["mug".into(), "gear".into()],
            sizes: vec![10_000, 100_000],
            repeats: 3,
        }
    }
}

/// One configuration (object, size, thread count) of [`AnnotateBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotateBenchRow {
    /// The built-in object.
    pub object: String,
    /// Its triangles as annotated.
    pub triangles: usize,
    /// |S_gt|.
    pub surface_voxels: usize,
    /// Threads of the pool the annotations ran on.
    pub threads: usize,
    /// Median seconds per stage.
    pub stages: StageTimings,
    /// Median total seconds.
    pub total_seconds: f64,
    /// d_plan of the first run (`None`: not proven, see `d_plan_status`).
    pub d_plan: Option<usize>,
    /// Its status.
    pub d_plan_status: String,
    /// What proved it.
    pub proven_by: String,
    /// Nodes of the cover search.
    pub search_nodes: u64,
    /// Peak resident memory (bytes) where the OS reports it.
    pub peak_rss_bytes: Option<u64>,
    /// Whether the peak was reset before this configuration (otherwise it covers the process
    /// so far).
    pub peak_is_per_configuration: bool,
}

impl AnnotateBenchRow {
    /// The row as `objview bench annotate --json` writes it.
    pub fn to_json(&self) -> Value {
        json!({
            "object": self.object, "triangles": self.triangles, "surface_voxels": self.surface_voxels,
            "threads": self.threads, "median_stage_seconds": self.stages, "median_total_seconds": self.total_seconds,
            "d_plan": self.d_plan, "d_plan_status": self.d_plan_status, "proven_by": self.proven_by,
            "search_nodes": self.search_nodes,
            "peak_rss_bytes": self.peak_rss_bytes, "peak_is_per_configuration": self.peak_is_per_configuration,
        })
    }
}

/// The figures of [`AnnotateBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotateBenchReport {
    /// The settings block (provenance and annotation settings).
    pub settings: Value,
    /// One row per object, size and thread count (one thread, then every core), in that order.
    pub rows: Vec<AnnotateBenchRow>,
}

impl AnnotateBenchReport {
    /// The figures as `objview bench annotate --json` writes them.
    pub fn to_json(&self) -> Value {
        let rows: Vec<Value> = self.rows.iter().map(AnnotateBenchRow::to_json).collect();
        json!({"settings": self.settings, "rows": rows})
    }
}

/// A prepared `objview bench annotate`: the SPEC's annotation settings and views.
#[derive(Debug)]
pub struct AnnotateBench {
    bench: AnnotateBenchSettings,
    settings: AnnotateSettings,
    views: GridViews,
    settings_json: Value,
}

impl AnnotateBench {
    /// Prepares the benchmark (the annotation's views).
    pub fn new(bench: AnnotateBenchSettings) -> Result<AnnotateBench, RunError> {
        let settings = AnnotateSettings::default();
        let views = GridViews::new(settings.view_radius)?;
        let settings_json = crate::provenance::settings("bench annotate", settings.to_json());
        Ok(AnnotateBench { bench, settings, views, settings_json })
    }

    /// Views rendered per object (all 26 tammes-N sets).
    pub fn total_views(&self) -> usize {
        self.views.total_views()
    }

    /// Timed annotations per configuration.
    pub fn repeats(&self) -> usize {
        self.bench.repeats.max(1)
    }

    /// Annotates every object at every size, [`AnnotateBench::repeats`] times with one thread
    /// and as often with every core; `on_row` sees each row as soon as it is measured.
    pub fn run(&self, on_row: &mut dyn FnMut(&AnnotateBenchRow)) -> Result<AnnotateBenchReport, RunError> {
        let dir = temp_dir()?;
        let repeats = self.repeats();
        let mut rows = Vec::new();
        for name in &self.bench.objects {
            for &size in &self.bench.sizes {
                let obj = write_object(name, size, dir.path())?;
                for threads in [1, all_cores()] {
                    let pool = thread_pool(threads)?;
                    let reset = reset_peak_rss();
                    let mut runs = Vec::with_capacity(repeats);
                    for _ in 0..repeats {
                        runs.push(pool.install(|| {
                            annotate_object(&obj, &self.settings, &self.views, &self.settings_json)
                        })?);
                    }
                    let peak = peak_rss();
                    let r = &runs[0];
                    let row = AnnotateBenchRow {
                        object: name.clone(),
                        triangles: r.faces,
                        surface_voxels: r.surface_voxels,
                        threads,
                        stages: stage_medians(runs.iter().map(|r| &r.timings)),
                        total_seconds: median(&mut runs.iter().map(|r| r.seconds).collect::<Vec<_>>()),
                        d_plan: r.d_plan,
                        d_plan_status: r.d_plan_status.clone(),
                        proven_by: r.d_plan_proven_by.clone(),
                        search_nodes: r.search_nodes,
                        peak_rss_bytes: peak,
                        peak_is_per_configuration: reset,
                    };
                    on_row(&row);
                    rows.push(row);
                }
            }
        }
        Ok(AnnotateBenchReport { settings: self.settings_json.clone(), rows })
    }
}

/// What `objview bench stability` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct StabilitySettings {
    /// Ground-truth sampling seeds (at least one).
    pub seeds: Vec<u64>,
    /// Built-in objects (empty: the whole built-in pool).
    pub objects: Vec<String>,
    /// Worker threads (`None`: every core).
    pub threads: Option<usize>,
    /// Exact d_plan time limit per annotation, seconds.
    pub time_limit: f64,
}

impl Default for StabilitySettings {
    /// Seeds 0, 1, 2 on the whole pool, every core, 60 s per d_plan.
    fn default() -> StabilitySettings {
        StabilitySettings { seeds: vec![0, 1, 2], objects: Vec::new(), threads: None, time_limit: 60.0 }
    }
}

/// How one object's annotation moved across the seeds (vectors in seed order).
#[derive(Debug, Clone, PartialEq)]
pub struct StabilityFigures {
    /// d_plan per seed (`None`: not proven).
    pub d_plan: Vec<Option<usize>>,
    /// d_sat per seed.
    pub d_sat: Vec<usize>,
    /// r_vis per seed.
    pub r_vis: Vec<f64>,
    /// Largest minus smallest proven d_plan (0 when fewer than two).
    pub d_plan_spread: usize,
    /// Largest minus smallest d_sat.
    pub d_sat_spread: usize,
    /// Distinct d_plan buckets (width 5) of the proven values.
    pub d_plan_buckets: usize,
    /// Smallest r_vis.
    pub r_vis_min: f64,
    /// Largest r_vis.
    pub r_vis_max: f64,
}

impl StabilityFigures {
    /// The figures of one object's annotations, one per seed (at least one).
    pub fn of(runs: &[&Annotation]) -> StabilityFigures {
        let d_plan: Vec<Option<usize>> = runs.iter().map(|r| r.d_plan).collect();
        let d_sat: Vec<usize> = runs.iter().map(|r| r.d_sat).collect();
        let r_vis: Vec<f64> = runs.iter().map(|r| r.r_vis).collect();
        let solved: Vec<usize> = d_plan.iter().flatten().copied().collect();
        let d_plan_spread = solved.iter().max().zip(solved.iter().min()).map_or(0, |(x, y)| x - y);
        let buckets: BTreeSet<usize> =
            solved.iter().filter_map(|&d| objview_pool::split::bucket_of(d)).collect();
        let d_sat_spread = d_sat.iter().max().zip(d_sat.iter().min()).map_or(0, |(x, y)| x - y);
        let (r_vis_min, r_vis_max) =
            r_vis.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        StabilityFigures {
            d_plan,
            d_sat,
            r_vis,
            d_plan_spread,
            d_sat_spread,
            d_plan_buckets: buckets.len(),
            r_vis_min,
            r_vis_max,
        }
    }
}

/// One object of [`StabilityBench::run`]: its figures, or the first error of its annotations.
#[derive(Debug, Clone, PartialEq)]
pub struct StabilityRow {
    /// The built-in object.
    pub object: String,
    /// Its figures, or why one of its annotations failed.
    pub figures: Result<StabilityFigures, String>,
}

/// Counts over the objects of [`StabilityBench::run`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StabilitySummary {
    /// Objects whose annotations all succeeded.
    pub objects: usize,
    /// Of those, objects whose d_plan differs across seeds.
    pub d_plan_moved: usize,
    /// Objects whose d_plan changes bucket.
    pub d_plan_bucket_changed: usize,
    /// Objects whose d_sat differs across seeds.
    pub d_sat_moved: usize,
    /// Median d_sat spread (NaN when no object succeeded).
    pub d_sat_spread_median: f64,
    /// Largest d_sat spread (0 when no object succeeded).
    pub d_sat_spread_max: f64,
    /// Objects with a failed annotation.
    pub failed: usize,
}

impl StabilitySummary {
    /// The counts over `rows`.
    pub fn of(rows: &[StabilityRow]) -> StabilitySummary {
        let done: Vec<&StabilityFigures> = rows.iter().filter_map(|r| r.figures.as_ref().ok()).collect();
        let mut spreads: Vec<f64> = done.iter().map(|f| f.d_sat_spread as f64).collect();
        StabilitySummary {
            objects: done.len(),
            d_plan_moved: done.iter().filter(|f| f.d_plan_spread > 0).count(),
            d_plan_bucket_changed: done.iter().filter(|f| f.d_plan_buckets > 1).count(),
            d_sat_moved: done.iter().filter(|f| f.d_sat_spread > 0).count(),
            d_sat_spread_max: spreads.iter().cloned().fold(0.0, f64::max),
            d_sat_spread_median: median(&mut spreads),
            failed: rows.len() - done.len(),
        }
    }
}

/// The figures of [`StabilityBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct StabilityReport {
    /// The seeds.
    pub seeds: Vec<u64>,
    /// The annotation settings (but the seed).
    pub annotate: AnnotateSettings,
    /// One row per object, in order.
    pub rows: Vec<StabilityRow>,
    /// The counts.
    pub summary: StabilitySummary,
}

impl StabilityReport {
    /// The figures as `objview bench stability --json` writes them (objects that failed are
    /// left out of `objects`).
    pub fn to_json(&self) -> Value {
        let settings = crate::provenance::settings(
            "bench stability",
            json!({"seeds": self.seeds, "annotate": self.annotate.to_json()}),
        );
        let objects: Vec<Value> = self
            .rows
            .iter()
            .filter_map(|r| {
                let f = r.figures.as_ref().ok()?;
                Some(json!({"object": r.object, "d_plan": f.d_plan, "d_sat": f.d_sat, "r_vis": f.r_vis,
                    "d_plan_spread": f.d_plan_spread, "d_sat_spread": f.d_sat_spread,
                    "d_plan_buckets": f.d_plan_buckets}))
            })
            .collect();
        let s = &self.summary;
        json!({"settings": settings, "objects": objects,
            "summary": {"objects": s.objects, "d_plan_moved": s.d_plan_moved,
                        "d_plan_bucket_changed": s.d_plan_bucket_changed,
                        "d_sat_moved": s.d_sat_moved, "failed": s.failed}})
    }
}

/// A prepared `objview bench stability`: the objects written, the settings checked, the pool
/// built.
#[derive(Debug)]
pub struct StabilityBench {
    seeds: Vec<u64>,
    names: Vec<String>,
    objects: Vec<ObjectRef>,
    base: AnnotateSettings,
    views: GridViews,
    pool: rayon::ThreadPool,
    _dir: tempfile::TempDir,
}

impl StabilityBench {
    /// Writes the objects and checks the settings.
    pub fn new(s: StabilitySettings) -> Result<StabilityBench, RunError> {
        if s.seeds.is_empty() {
            return Err(RunError::Invalid("--seeds: give at least one seed".into()));
        }
        let names: Vec<String> = if s.objects.is_empty() {
            synth::catalog().iter().map(|o| o.name.to_string()).collect()
        } else {
            s.objects
        };
        let dir = temp_dir()?;
        let objects = names.iter().map(|n| write_object(n, 0, dir.path())).collect::<Result<_, _>>()?;
        let mut base = AnnotateSettings::default();
        base.cover.time_limit_s = s.time_limit;
        base.validate()?;
        let views = GridViews::new(base.view_radius)?;
        let pool = thread_pool(s.threads.unwrap_or_else(all_cores).max(1))?;
        Ok(StabilityBench { seeds: s.seeds, names, objects, base, views, pool, _dir: dir })
    }

    /// The objects, in order.
    pub fn objects(&self) -> &[String] {
        &self.names
    }

    /// Annotations to run (objects × seeds).
    pub fn annotations(&self) -> usize {
        self.objects.len() * self.seeds.len()
    }

    /// Annotates every object with every seed on the pool; `tick` is called (from the workers)
    /// after each annotation.
    pub fn run(&self, tick: &(dyn Fn() + Sync)) -> StabilityReport {
        let jobs: Vec<(usize, u64)> =
            (0..self.objects.len()).flat_map(|i| self.seeds.iter().map(move |&s| (i, s))).collect();
        let results: Vec<Result<Annotation, String>> = self.pool.install(|| {
            jobs.par_iter()
                .map(|&(i, seed)| {
                    let s = AnnotateSettings { gt_seed: seed, ..self.base.clone() };
                    let sj = crate::provenance::settings("bench stability", s.to_json());
                    let r =
                        annotate_object(&self.objects[i], &s, &self.views, &sj).map_err(|e| e.to_string());
                    tick();
                    r
                })
                .collect()
        });
        let k = self.seeds.len();
        let rows: Vec<StabilityRow> = self
            .names
            .iter()
            .zip(results.chunks(k))
            .map(|(name, rs)| {
                let figures = match rs.iter().find_map(|r| r.as_ref().err()) {
                    Some(e) => Err(e.clone()),
                    None => Ok(StabilityFigures::of(&rs.iter().flatten().collect::<Vec<_>>())),
                };
                StabilityRow { object: name.clone(), figures }
            })
            .collect();
        StabilityReport {
            seeds: self.seeds.clone(),
            annotate: self.base.clone(),
            summary: StabilitySummary::of(&rows),
            rows,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timings(x: f64) -> StageTimings {
        StageTimings {
            load: x,
            ground_truth: 2.0 * x,
            voxelize: 3.0 * x,
            visibility: 4.0 * x,
            fit: 5.0 * x,
            cover: 6.0 * x,
        }
    }

    #[test]
    fn stage_medians_take_each_stage_on_its_own() {
        let mut odd = timings(3.0);
        odd.fit = 0.5; // the smallest fit of the three
        let runs = [timings(1.0), odd, timings(2.0)];
        let m = stage_medians(&runs);
        assert_eq!(m, StageTimings { fit: 5.0, ..timings(2.0) });
        assert_eq!(stage_medians(&runs[..2]).load, 2.0, "even count: mean of the middle two");
        assert!(stage_medians(&[]).cover.is_nan());
    }

    #[test]
    fn a_written_object_is_named_after_the_built_in() {
        let dir = tempfile::tempdir().unwrap();
        let obj = write_object("cube", 100, dir.path()).unwrap();
        assert_eq!(obj.uid, "cube");
        assert!(obj.mesh.is_file());
        assert!(write_object("no-such-object", 0, dir.path()).is_err());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_peak_resident_memory_is_reported_on_linux() {
        let _ = reset_peak_rss();
        assert!(peak_rss().is_some_and(|b| b > 0));
    }
}
