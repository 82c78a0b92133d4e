//! `objview learn dataset --method completion`: training pairs of the completion network
//! ([`crate::completion_net`]), one NPZ file per object plus the manifest (the layout,
//! resumption and sharding of [`crate::dataset`]).
//!
//! Per object (timed by stage):
//! 1. `load`: the normalized mesh and its ground-truth cloud, exactly as `annotate` reads them
//!    (a split entry's cloud or the seeded surface sample), resampled to `gt_points` (8192) by
//!    the contract's rule ([`resample`]);
//! 2. `partials`: `partials` partial clouds; each takes a seeded number of views (uniform in
//!    1..=`max_views`, 3 by default) drawn without replacement from tammes-128 at the SPEC view
//!    radius, renders their depth frames with the SPEC camera, back-projects every pixel at its
//!    centre into [−1, 1]³ and fuses them exactly as the hybrid planners keep their partial
//!    cloud ([`PartialCloud`]: the union voxel-filtered at 1/64). The fused cloud is resampled
//!    to 2048 points by the contract's rule and normalized by its centroid and max radius
//!    ([`Normalization`]) — the very input the `net` backend gets at deployment; the ground
//!    truth is mapped with the same normalization. Renders are cached per view;
//! 3. `write`: `cases/<uid>.npz` (temp file, then rename) and one line in the objects file.
//!
//! One ChaCha8 stream per object (seeded by (seed, uid), [`crate::dataset::object_seed`]) draws,
//! in this order: the ground-truth resampling, then per partial cloud its view count, its views
//! and its input resampling. A partial cloud whose views see nothing (an empty fused cloud) is
//! skipped and counted (`empty_partials`).
//!
//! The NPZ arrays of an object with n partial clouds: `partial` f32 `[n, 2048, 3]` (normalized
//! input), `gt` f32 `[n, G, 3]` (ground truth in the same normalization), `centroid` f32 `[n, 3]`
//! and `scale` f32 `[n]` (the normalization: object = normalized · scale + centroid), `views`
//! i32 `[n, max_views]` (tammes-128 ids, −1 padded), `partial_points` i32 `[n]` (fused points before
//! resampling), `d_plan` i32 `[]` (the split entry's proven d_plan, −1 when unknown).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use objview_dataset::annotate::ground_truth_points;
use objview_dataset::ObjectRef;
use objview_episode::Observation;
use objview_geom::normalize::load_normalized;
use objview_planners::hybrid::completion::{resample, Normalization, INPUT_POINTS};
use objview_planners::hybrid::steps::PartialCloud;
use objview_render::{render, Camera};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::dataset::{object_seed, DatasetSettings, VIEWS};
use crate::npz::{Dtype, NpzWriter};
use crate::LearnError;

/// The completion data's own settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompletionDataSettings {
    /// Partial clouds per object.
    pub partials: usize,
    /// The most views fused into one partial cloud (the count is uniform in 1..=max_views).
    pub max_views: usize,
    /// Ground-truth points per object.
    pub gt_points: usize,
}

impl Default for CompletionDataSettings {
    fn default() -> Self {
        CompletionDataSettings { partials: 8, max_views: 3, gt_points: 8192 }
    }
}

impl CompletionDataSettings {
    /// Checks ranges (an error names the flag).
    pub fn validate(&self) -> Result<(), LearnError> {
        if self.partials == 0 {
            return Err(LearnError::Invalid("--partials must be at least 1".into()));
        }
        if !(1..=VIEWS).contains(&self.max_views) {
            return Err(LearnError::Invalid(format!(
                "--max-views must be 1..={VIEWS}, got {}",
                self.max_views
            )));
        }
        if self.gt_points == 0 {
            return Err(LearnError::Invalid("--gt-points must be at least 1".into()));
        }
        Ok(())
    }
}

/// The settings of a completion dataset as recorded.
pub fn settings_json(s: &DatasetSettings) -> Value {
    let c = &s.completion;
    json!({
        "method": "completion",
        "views": format!("tammes-{VIEWS}"),
        "partials": c.partials,
        "views_per_partial": [1, c.max_views],
        "gt_points": c.gt_points,
        "input_points": INPUT_POINTS,
        "partial_cloud": "depth frames (SPEC camera) back-projected at pixel centres into [-1,1]^3, fused and voxel-filtered at 1/64 (the hybrid planners' PartialCloud)",
        "resample": "the completion contract's rule (objview_planners::hybrid::completion::resample): random permutation prefix, or tiling plus a random subset",
        "normalization": "centroid and max radius of the resampled input (the completion contract's); ground truth mapped with it",
        "seed": s.seed,
        "rng": "ChaCha8(splitmix64(fnv1a(seed, uid))): ground-truth resampling, then per partial its view count, views and input resampling",
        "annotate": s.annotate.to_json(),
    })
}

/// The manifest's description of the arrays.
pub fn arrays_json() -> Value {
    json!({
        "partial": "float32 [n, 2048, 3], resampled fused partial cloud, normalized",
        "gt": "float32 [n, G, 3], ground-truth cloud in each partial's normalization",
        "centroid": "float32 [n, 3]", "scale": "float32 [n] (object frame = normalized * scale + centroid)",
        "views": "int32 [n, max_views], tammes-128 ids, -1 padded",
        "partial_points": "int32 [n], fused points before resampling",
        "d_plan": "int32 [], proven d_plan of the split entry, -1 unknown"
    })
}

/// What one object produced (its line in the objects file).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CompletionRecord {
    /// The object.
    pub uid: String,
    /// The NPZ file, relative to the dataset folder.
    pub file: String,
    /// Partial clouds written.
    pub cases: usize,
    /// Partial clouds skipped because their views saw nothing.
    pub empty_partials: usize,
    /// Mean fused points of a partial cloud before resampling.
    pub mean_partial_points: f64,
    /// Where the ground truth came from, and its size before resampling.
    pub gt_source: String,
    /// See `gt_source`.
    pub gt_cloud_points: usize,
    /// The split entry's proven d_plan, if any.
    pub d_plan: Option<usize>,
    /// Seconds per stage.
    pub timings: BTreeMap<String, f64>,
    /// Total seconds.
    pub seconds: f64,
    /// The settings.
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// The proven d_plan of a split entry's annotation (`d_plan` set and `d_plan_status` optimal).
pub fn annotated_d_plan(obj: &ObjectRef) -> Option<usize> {
    let a = obj.annotation.as_ref()?;
    if a["d_plan_status"] != "optimal" {
        return None;
    }
    a["d_plan"].as_u64().filter(|&d| d > 0).map(|d| d as usize)
}

/// The fused partial cloud of `views` (the hybrids' [`PartialCloud`] after one frame per view,
/// in order); `frames` caches the depth frames by view id.
pub fn fused_partial(
    mesh: &objview_geom::mesh::Mesh,
    cameras: &[Camera],
    views: &[usize],
    frames: &mut BTreeMap<usize, Arc<Vec<f32>>>,
) -> Vec<[f64; 3]> {
    let mut partial = PartialCloud::default();
    for (step, &v) in views.iter().enumerate() {
        let depth = frames.entry(v).or_insert_with(|| Arc::new(render(mesh, &cameras[v]).depth)).clone();
        let obs =
            Observation { step, pose: cameras[v].pose, intrinsics: cameras[v].intrinsics, depth, rgb: None };
        partial.add(&obs);
    }
    partial.points
}

fn f32s(points: &[[f64; 3]]) -> Vec<f32> {
    points.iter().flat_map(|p| p.map(|x| x as f32)).collect()
}

/// Generates the partial clouds of one object and writes `out_dir/cases/<uid>.npz`.
pub fn generate_completion_object(
    obj: &ObjectRef,
    settings: &DatasetSettings,
    cameras: &[Camera],
    out_dir: &Path,
    settings_json: &Value,
) -> Result<CompletionRecord, LearnError> {
    let t_all = Instant::now();
    let mut timings = BTreeMap::new();
    let mut t = Instant::now();
    let c = &settings.completion;
    let a = &settings.annotate;
    let path = obj.mesh.as_path();
    let (mesh, transform) =
        load_normalized(path, a.normalize).map_err(objview_dataset::DatasetError::from)?;
    let (gt_raw, gt_source) = ground_truth_points(obj, a, &mesh, transform)?;
    let mut rng = ChaCha8Rng::seed_from_u64(object_seed(settings.seed, &obj.uid));
    let gt = resample(&gt_raw, c.gt_points, &mut rng)
        .map_err(|e| LearnError::Invalid(format!("{}: ground truth: {e}", path.display())))?;
    timings.insert("load".to_string(), t.elapsed().as_secs_f64());
    t = Instant::now();

    let mut frames = BTreeMap::new();
    let (mut partial, mut truth, mut centroid, mut scale) = (vec![], vec![], vec![], vec![]);
    let (mut views_arr, mut sizes) = (vec![], vec![]);
    let mut empty = 0;
    for _ in 0..c.partials {
        let k = rng.gen_range(1..=c.max_views);
        let mut ids: Vec<usize> = (0..cameras.len()).collect();
        for i in 0..k {
            let j = rng.gen_range(i..ids.len());
            ids.swap(i, j);
        }
        ids.truncate(k);
        let fused = fused_partial(&mesh, cameras, &ids, &mut frames);
        if fused.is_empty() {
            empty += 1;
            continue;
        }
        let input = resample(&fused, INPUT_POINTS, &mut rng)
            .map_err(|e| LearnError::Invalid(format!("{}: partial cloud: {e}", path.display())))?;
        let n = Normalization::of(&input);
        partial.extend(f32s(&input.iter().map(|p| n.apply(*p)).collect::<Vec<_>>()));
        truth.extend(f32s(&gt.iter().map(|p| n.apply(*p)).collect::<Vec<_>>()));
        centroid.extend(n.centroid.map(|x| x as f32));
        scale.push(n.scale as f32);
        views_arr.extend((0..c.max_views).map(|i| ids.get(i).map(|&v| v as i32).unwrap_or(-1)));
        sizes.push(fused.len() as i32);
    }
    timings.insert("partials".to_string(), t.elapsed().as_secs_f64());
    t = Instant::now();

    let n = sizes.len();
    let cases_dir = out_dir.join("cases");
    std::fs::create_dir_all(&cases_dir).map_err(|e| LearnError::io(&cases_dir, e))?;
    let file = format!("cases/{}.npz", obj.uid);
    let final_path = out_dir.join(&file);
    let tmp = out_dir.join(format!("cases/{}.npz.tmp", obj.uid));
    let d_plan = annotated_d_plan(obj);
    let mut w = NpzWriter::create(&tmp)?;
    w.begin("partial", Dtype::F32, &[n, INPUT_POINTS, 3])?;
    w.write_f32(&partial)?;
    w.begin("gt", Dtype::F32, &[n, c.gt_points, 3])?;
    w.write_f32(&truth)?;
    w.begin("centroid", Dtype::F32, &[n, 3])?;
    w.write_f32(&centroid)?;
    w.begin("scale", Dtype::F32, &[n])?;
    w.write_f32(&scale)?;
    w.array_i32("views", &[n, c.max_views], &views_arr)?;
    w.array_i32("partial_points", &[n], &sizes)?;
    w.array_i32("d_plan", &[], &[d_plan.map(|d| d as i32).unwrap_or(-1)])?;
    w.finish()?;
    std::fs::rename(&tmp, &final_path).map_err(|e| LearnError::io(&final_path, e))?;
    timings.insert("write".to_string(), t.elapsed().as_secs_f64());

    Ok(CompletionRecord {
        uid: obj.uid.clone(),
        file,
        cases: n,
        empty_partials: empty,
        mean_partial_points: if n == 0 {
            0.0
        } else {
            sizes.iter().map(|&x| x as f64).sum::<f64>() / n as f64
        },
        gt_source,
        gt_cloud_points: gt_raw.len(),
        d_plan,
        timings,
        seconds: t_all.elapsed().as_secs_f64(),
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    })
}
