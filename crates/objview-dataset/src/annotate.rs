//! The difficulty annotation of one object (SPEC §4, paper §3): r_vis, d_sat and the exact d_plan.
//!
//! Pipeline per object, each stage timed:
//! 1. `load`: read the mesh and normalize it (`unit` or `none`);
//! 2. `ground_truth`: read the pool's cloud (split file `gt_cloud`, or `<gt_cloud_dir>/<uid>.*`)
//!    or sample one on the mesh (SPEC §1 count rule, seed `gt_seed`);
//! 3. `voxelize`: S_gt = voxel keys of the cloud at resolution r;
//! 4. `visibility`: O(v) for every view of every tammes-N of the saturation grid (3,032 views),
//!    Y(N) = |∪ O(v)| per grid size; the tammes-128 per-view sets are kept for the cover;
//! 5. `fit`: running maximum, lognormal-CDF fit, N*, d_sat, r_vis ([`objview_difficulty`]);
//! 6. `cover`: U = voxels seen by ≥ k tammes-128 views, d_plan by the exact ILP.
//!
//! The result is an [`Annotation`], one JSON line of `objview annotate`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use objview_difficulty::{
    saturation, solve_min_cover, CoverSettings, CoverStatus, CurvePoint, ReductionStats, SaturationSettings,
    SATURATION_GRID,
};
use objview_geom::cloud::{cloud_count, read_cloud, sample_surface};
use objview_geom::normalize::{load_normalized, Normalization, Transform};
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;
use objview_voxel::{bitset_count, union_bitsets, Visibility, VisibilityMode, VoxelSet, DEFAULT_MAX_RANGE};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::error::DatasetError;
use crate::inputs::ObjectRef;

/// The view-set size of the planning views (SPEC §4: tammes-128).
pub const PLANNING_VIEWS: usize = 128;
/// Cloud file extensions looked up in `--gt-cloud-dir`, in this order.
pub const GT_CLOUD_EXTENSIONS: [&str; 4] = ["pcd", "ply", "npy", "npz"];

/// Every setting of the annotation; recorded in each output line.
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotateSettings {
    /// How meshes are brought to the unit ball.
    pub normalize: Normalization,
    /// O(v) model (`inverse` default, `mesh` extension).
    pub visibility: VisibilityMode,
    /// Voxel size r.
    pub resolution: f64,
    /// `inverse` ray range.
    pub max_range: f64,
    /// Camera distance of view-set poses (SPEC §2: 3.0).
    pub view_radius: f64,
    /// Seed of a generated ground-truth cloud.
    pub gt_seed: u64,
    /// Folder of `<uid>.{pcd,ply,npy,npz}` ground-truth clouds.
    pub gt_cloud_dir: Option<PathBuf>,
    /// Saturation fit constants.
    pub saturation: SaturationSettings,
    /// Exact cover settings (time limit, k, solver threads and seed).
    pub cover: CoverSettings,
}

impl Default for AnnotateSettings {
    fn default() -> Self {
        AnnotateSettings {
            normalize: Normalization::Unit,
            visibility: VisibilityMode::Inverse,
            resolution: objview_voxel::DEFAULT_RESOLUTION,
            max_range: DEFAULT_MAX_RANGE,
            view_radius: objview_geom::pose::VIEW_RADIUS,
            gt_seed: objview_geom::cloud::DEFAULT_CLOUD_SEED,
            gt_cloud_dir: None,
            saturation: SaturationSettings::default(),
            cover: CoverSettings::default(),
        }
    }
}

impl AnnotateSettings {
    /// Checks ranges; errors name the setting.
    pub fn validate(&self) -> Result<(), DatasetError> {
        let positive = |name, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(DatasetError::InvalidSetting {
                    name,
                    reason: format!("must be a positive number, got {v}"),
                })
            }
        };
        positive("resolution", self.resolution)?;
        positive("max_range", self.max_range)?;
        positive("view_radius", self.view_radius)?;
        let wrap = |e: objview_difficulty::DifficultyError| DatasetError::InvalidSetting {
            name: "difficulty",
            reason: e.to_string(),
        };
        self.saturation.validate().map_err(wrap)?;
        self.cover.validate().map_err(wrap)?;
        Ok(())
    }

    /// The settings block of each output line (with the view sets it used).
    pub fn to_json(&self) -> Value {
        json!({
            "normalize": self.normalize.to_string(),
            "visibility": self.visibility.to_string(),
            "resolution": self.resolution,
            "max_range": self.max_range,
            "view_radius": self.view_radius,
            "intrinsics": intrinsics_json(),
            "saturation_grid": SATURATION_GRID,
            "view_sets": "tammes-N for each N of saturation_grid",
            "planning_view_set": format!("tammes-{PLANNING_VIEWS}"),
            "gt_cloud_dir": self.gt_cloud_dir.as_ref().map(|p| p.display().to_string()),
            "gt_seed": self.gt_seed,
            "gt_count_rule": "clamp(ceil(area / 0.004^2), 20000, 2000000)",
            "saturation": self.saturation,
            "cover": {
                "time_limit_s": finite_or_string(self.cover.time_limit_s),
                "min_views_per_element": self.cover.min_views_per_element,
                "threads": self.cover.threads,
                "random_seed": self.cover.random_seed,
                "method": self.cover.method.to_string(),
                "solver": format!(
                    "combinatorial search with dual ascent at its nodes (<= {} views, {}% of the time \
                     limit), then HiGHS ILP",
                    objview_difficulty::SEARCH_MAX_VIEWS,
                    objview_difficulty::ilp::SEARCH_SHARE * 100.0
                ),
                "relative_gap": 0.0,
            },
        })
    }
}

fn finite_or_string(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        json!(x.to_string())
    }
}

fn intrinsics_json() -> Value {
    let k = Intrinsics::default();
    json!({"width": k.width, "height": k.height, "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy})
}

/// The cameras of every grid view set, built once per batch.
#[derive(Debug, Clone)]
pub struct GridViews {
    /// Per grid size N (ascending, [`SATURATION_GRID`]): the cameras of tammes-N.
    pub sets: Vec<(usize, Vec<Camera>)>,
}

impl GridViews {
    /// Resolves tammes-N for every N of the grid at camera distance `radius`.
    pub fn new(radius: f64) -> Result<GridViews, DatasetError> {
        let sets = SATURATION_GRID
            .iter()
            .map(|&n| {
                let vs = ViewSet::resolve(&format!("tammes-{n}"))?;
                let cams =
                    vs.poses(radius).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();
                Ok((n, cams))
            })
            .collect::<Result<Vec<_>, DatasetError>>()?;
        Ok(GridViews { sets })
    }

    /// Total number of views over the grid.
    pub fn total_views(&self) -> usize {
        self.sets.iter().map(|(_, c)| c.len()).sum()
    }

    /// The planning cameras (tammes-128).
    pub fn planning(&self) -> &[Camera] {
        &self.sets.iter().find(|(n, _)| *n == PLANNING_VIEWS).expect("128 is a grid size").1
    }
}

/// Wall-clock seconds per stage (see the module docs).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimings {
    /// Reading and normalizing the mesh, seconds.
    pub load: f64,
    /// Reading or sampling the ground-truth cloud, seconds.
    pub ground_truth: f64,
    /// Voxelizing the cloud into S_gt, seconds.
    pub voxelize: f64,
    /// O(v) for every view of every grid view set and Y(N), seconds.
    pub visibility: f64,
    /// The saturation fit (N*, d_sat, r_vis), seconds.
    pub fit: f64,
    /// The exact cover, seconds.
    pub cover: f64,
}

/// One object's annotation: a line of `objview annotate` (field order = output order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Annotation {
    /// Object id (the mesh file stem, or the split file's `uid`).
    pub uid: String,
    /// The mesh file as given.
    pub mesh: String,
    /// Where the ground-truth cloud came from: a file, or `sampled(seed=…, count=…)`.
    pub gt_cloud: String,
    /// Vertex positions of the mesh as loaded.
    pub vertices: usize,
    /// Triangles of the mesh as loaded.
    pub faces: usize,
    /// Ground-truth cloud size.
    pub gt_points: usize,
    /// |S_gt|.
    pub surface_voxels: usize,
    /// Raw saturation curve [[N, Y(N)], …] over the grid.
    pub curve: Vec<[usize; 2]>,
    /// μ of the lognormal-CDF fit Ŷ(N) = y_max·Φ((ln N − μ)/σ).
    pub mu: f64,
    /// σ of the lognormal-CDF fit (at least 1e-6).
    pub sigma: f64,
    /// Continuous saturation point N*.
    pub n_star: f64,
    /// d_sat = round(N*).
    pub d_sat: usize,
    /// r_vis = Ŷ(N*)/|S_gt|.
    pub r_vis: f64,
    /// Smallest grid N ≥ N*.
    pub grid_n: usize,
    /// Y_m(grid_n)/|S_gt|.
    pub grid_r_vis: f64,
    /// d_sat > 128.
    pub slow_saturation: bool,
    /// The fit degenerated (curve flat from N_min on).
    pub degenerate_fit: bool,
    /// |U|: voxels seen by at least k tammes-128 views.
    pub universe: usize,
    /// Exact d_plan; null unless `d_plan_status` is `optimal`.
    pub d_plan: Option<usize>,
    /// `optimal`, `time_limit`, `infeasible` or `error: …`.
    pub d_plan_status: String,
    /// Proven lower bound on d_plan (= d_plan when optimal).
    pub d_plan_bound: usize,
    /// LP relaxation optimum.
    pub lp_bound: f64,
    /// Size of the greedy cover.
    pub greedy_cover: usize,
    /// The chosen cover: indices into tammes-128 (file order), ascending.
    pub cover_views: Vec<usize>,
    /// What proved d_plan: `search`, `ilp`, `reductions`, or `none` (empty in older files).
    #[serde(default)]
    pub d_plan_proven_by: String,
    /// Nodes of the combinatorial cover search.
    #[serde(default)]
    pub search_nodes: u64,
    /// What the reductions removed before the exact solve.
    pub reduction: ReductionStats,
    /// Time inside the solver (LP + ILP), seconds.
    pub solver_seconds: f64,
    /// Total wall-clock time of this object, seconds.
    pub seconds: f64,
    /// Wall-clock seconds per pipeline stage.
    pub timings: StageTimings,
    /// The settings block ([`AnnotateSettings::to_json`]).
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// A failed object: `{"uid", "mesh", "error", …}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// Object id.
    pub uid: String,
    /// The mesh file as given.
    pub mesh: String,
    /// The error message, on one line.
    pub error: String,
    /// The settings block ([`AnnotateSettings::to_json`]).
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// The ground-truth cloud file of `obj`: the split file's `gt_cloud`, else `<dir>/<uid>.<ext>`
/// for the first existing extension of [`GT_CLOUD_EXTENSIONS`] (an error if none), else `None`
/// (sample one).
pub fn gt_cloud_path(obj: &ObjectRef, dir: Option<&Path>) -> Result<Option<PathBuf>, DatasetError> {
    if let Some(p) = &obj.gt_cloud {
        return Ok(Some(p.clone()));
    }
    let Some(dir) = dir else { return Ok(None) };
    for ext in GT_CLOUD_EXTENSIONS {
        let p = dir.join(format!("{}.{ext}", obj.uid));
        if p.is_file() {
            return Ok(Some(p));
        }
    }
    Err(DatasetError::MissingGtCloud { uid: obj.uid.clone(), dir: dir.to_path_buf() })
}

/// The ground-truth cloud of `obj` in the normalized frame of `mesh` (`transform` is what
/// normalization applied to the mesh): the pool's cloud file when there is one, else a cloud
/// sampled on `mesh` (SPEC §1 count rule, `settings.gt_seed`). Returns the points and where
/// they came from (a path or `sampled(seed=…, count=…)`).
pub fn ground_truth_points(
    obj: &ObjectRef,
    settings: &AnnotateSettings,
    mesh: &objview_geom::Mesh,
    transform: Transform,
) -> Result<(Vec<[f64; 3]>, String), DatasetError> {
    Ok(match gt_cloud_path(obj, settings.gt_cloud_dir.as_deref())? {
        Some(p) => {
            let mut pts = read_cloud(&p)?;
            if transform != Transform::IDENTITY {
                pts.iter_mut().for_each(|q| *q = transform.apply(*q));
            }
            (pts, p.display().to_string())
        }
        None => {
            let n = cloud_count(mesh.surface_area());
            let pts = sample_surface(mesh, n, settings.gt_seed);
            (pts, format!("sampled(seed={}, count={n})", settings.gt_seed))
        }
    })
}

/// Annotates one object (see the module docs). `settings` must be valid; `views` comes from
/// [`GridViews::new`] with `settings.view_radius`. Per-view work runs on the current rayon pool.
pub fn annotate_object(
    obj: &ObjectRef,
    settings: &AnnotateSettings,
    views: &GridViews,
    settings_json: &Value,
) -> Result<Annotation, DatasetError> {
    let t_all = Instant::now();
    let mut timings = StageTimings::default();
    let path = obj.mesh.as_path();

    let t = Instant::now();
    let (mesh, transform) = load_normalized(path, settings.normalize)?;
    timings.load = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let (points, gt_source) = ground_truth_points(obj, settings, &mesh, transform)?;
    timings.ground_truth = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let set = VoxelSet::from_points(&points, settings.resolution)
        .map_err(|source| DatasetError::Voxel { path: path.to_path_buf(), source })?;
    timings.voxelize = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let vis = Visibility::with_max_range(&set, &mesh, settings.visibility, settings.max_range);
    let mut counts = Vec::with_capacity(views.sets.len());
    let mut planning_bits = Vec::new();
    for (n, cams) in &views.sets {
        if *n == PLANNING_VIEWS {
            planning_bits = vis.observe_all_bitsets(cams);
            counts.push(bitset_count(&union_bitsets(&planning_bits, set.len())));
        } else {
            // Only the union is needed here: it skips the rays that can only re-find voxels the
            // union already holds (same bits).
            let acc = vis.union_all(cams);
            counts.push(bitset_count(&acc));
        }
    }
    timings.visibility = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let curve: Vec<CurvePoint> =
        views.sets.iter().zip(&counts).map(|((n, _), &y)| CurvePoint::new(*n, y as f64)).collect();
    let sat = saturation(&curve, set.len(), &settings.saturation)
        .map_err(|source| DatasetError::Difficulty { path: path.to_path_buf(), source })?;
    timings.fit = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let cover = solve_min_cover(&planning_bits, &settings.cover)
        .map_err(|source| DatasetError::Difficulty { path: path.to_path_buf(), source })?;
    timings.cover = t.elapsed().as_secs_f64();

    let status = match &cover.status {
        CoverStatus::Optimal => "optimal".to_string(),
        CoverStatus::TimeLimit => "time_limit".to_string(),
        CoverStatus::Infeasible => "infeasible".to_string(),
        CoverStatus::Error(m) => format!("error: {m}"),
    };
    Ok(Annotation {
        uid: obj.uid.clone(),
        mesh: path.display().to_string(),
        gt_cloud: gt_source,
        vertices: mesh.positions.len(),
        faces: mesh.num_triangles(),
        gt_points: points.len(),
        surface_voxels: set.len(),
        curve: views.sets.iter().zip(&counts).map(|((n, _), &y)| [*n, y]).collect(),
        mu: sat.mu,
        sigma: sat.sigma,
        n_star: sat.n_star,
        d_sat: sat.d_sat,
        r_vis: sat.r_vis,
        grid_n: sat.grid_n,
        grid_r_vis: sat.grid_r_vis,
        slow_saturation: sat.slow_saturation,
        degenerate_fit: sat.degenerate_fit,
        universe: cover.universe,
        d_plan: cover.d_plan,
        d_plan_status: status,
        d_plan_bound: cover.lower_bound,
        lp_bound: cover.lp_bound,
        greedy_cover: cover.greedy_size,
        cover_views: cover.best_cover.clone(),
        d_plan_proven_by: cover.proven_by.clone(),
        search_nodes: cover.search_nodes,
        reduction: cover.reduction.clone(),
        solver_seconds: cover.solver_seconds,
        seconds: t_all.elapsed().as_secs_f64(),
        timings,
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    })
}

impl Annotation {
    /// The progress note of this annotation: `r_vis=0.912 d_sat=12 d_plan=7 (optimal) 3.10 s`.
    pub fn progress_note(&self) -> String {
        let d_plan = self.d_plan.map_or_else(|| "none".to_string(), |d| d.to_string());
        format!(
            "r_vis={:.3} d_sat={} d_plan={d_plan} ({}) {:.2} s",
            self.r_vis, self.d_sat, self.d_plan_status, self.seconds
        )
    }
}

/// Annotates `obj` ([`annotate_object`]) as one item of a batch: its line (the annotation or
/// its failure) and progress note.
pub fn annotate_item(
    obj: &ObjectRef,
    settings: &AnnotateSettings,
    views: &GridViews,
    settings_json: &Value,
) -> crate::ItemOutcome {
    match annotate_object(obj, settings, views, settings_json) {
        Ok(ann) => {
            crate::ItemOutcome { line: crate::to_line(&ann), failed: false, note: ann.progress_note() }
        }
        Err(e) => {
            let f = failure(obj, &e, settings_json);
            crate::ItemOutcome { line: crate::to_line(&f), failed: true, note: f.error }
        }
    }
}

/// The failure line of `obj`.
pub fn failure(obj: &ObjectRef, error: &DatasetError, settings_json: &Value) -> Failure {
    Failure {
        uid: obj.uid.clone(),
        mesh: obj.mesh.display().to_string(),
        error: error.to_string().replace('\n', " "),
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    }
}

/// The lines of one or more `objview annotate` results files.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AnnotationSet {
    /// Successful annotations, in file order (files in the order given).
    pub annotations: Vec<Annotation>,
    /// Failure lines.
    pub failures: Vec<Failure>,
}

/// Reads `objview annotate` results files (e.g. the `cat` of several shards). A torn last line
/// (an interrupted run) is ignored; any other line that is not an annotation or a failure is an
/// error naming the file and line. A uid that appears twice is an error (shards overlap).
pub fn read_annotations(paths: &[PathBuf]) -> Result<AnnotationSet, DatasetError> {
    let mut set = AnnotationSet::default();
    let mut seen = std::collections::HashMap::<String, (PathBuf, usize)>::new();
    for path in paths {
        let text = objview_geom::fsutil::read_text(path).map_err(|e| DatasetError::io(path, e))?;
        let complete =
            if text.ends_with('\n') { text.as_str() } else { &text[..text.rfind('\n').map_or(0, |i| i + 1)] };
        for (i, line) in complete.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let corrupt =
                |reason: String| DatasetError::CorruptLine { path: path.clone(), line: i + 1, reason };
            let value: Value = serde_json::from_str(line).map_err(|e| corrupt(format!("not JSON ({e})")))?;
            let uid = value.get("uid").and_then(Value::as_str).unwrap_or_default().to_string();
            if let Some((p, l)) = seen.insert(uid.clone(), (path.clone(), i + 1)) {
                return Err(corrupt(format!(
                    "uid '{}' already at {}:{l}",
                    crate::error::one_line(&uid),
                    p.display()
                )));
            }
            if value.get("error").is_some() {
                let f: Failure = serde_json::from_value(value)
                    .map_err(|e| corrupt(format!("not a failure line ({e})")))?;
                set.failures.push(f);
            } else {
                let a: Annotation =
                    serde_json::from_value(value).map_err(|e| corrupt(format!("not an annotation ({e})")))?;
                set.annotations.push(a);
            }
        }
    }
    Ok(set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_annotations_errors_are_one_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.jsonl");
        let fail = |uid: &str| {
            serde_json::json!({"uid": uid, "mesh": "m.obj", "error": "e", "settings": {}, "version": "0"})
                .to_string()
        };
        // Failure lines are read; a torn last line is ignored.
        std::fs::write(&path, format!("{}\n{}\n{{\"uid\":", fail("a"), fail("b"))).unwrap();
        let set = read_annotations(std::slice::from_ref(&path)).unwrap();
        assert_eq!(set.failures.len(), 2);
        // A uid seen twice is an error naming it, on one line even when the uid holds a newline.
        std::fs::write(&path, format!("{}\n{}\n", fail("x\ny"), fail("x\ny"))).unwrap();
        let msg = read_annotations(std::slice::from_ref(&path)).unwrap_err().to_string();
        assert!(msg.contains("line 2: uid 'x\\ny' already at") && !msg.contains('\n'), "{msg:?}");
        // A complete line that is not an annotation.
        std::fs::write(&path, "{\"uid\":\"a\",\"d_sat\":\"many\"}\n").unwrap();
        let msg = read_annotations(std::slice::from_ref(&path)).unwrap_err().to_string();
        assert!(msg.contains("line 1: not an annotation") && !msg.contains('\n'), "{msg:?}");
    }
}
