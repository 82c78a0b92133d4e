//! Building a benchmark pool from raw assets (`objview pool build`): every accepted object becomes
//! a normalized mesh and a ground-truth cloud in the pool folder, so that annotation and episodes
//! work on the same frozen geometry, and every rejected one is recorded with its reason.
//!
//! Per object (SPEC §1):
//! 1. load the mesh (any supported format); unreadable files, unsupported formats, non-finite
//!    coordinates, out-of-range indices, meshes without triangles or of zero extent are rejected;
//! 2. conservative filters: fewer than `min_faces` (default 4, the fewest faces of a closed
//!    surface) or more than `max_faces` triangles (default 10M), zero total area;
//! 3. normalize (`unit` by default, or check an already normalized asset with `none`);
//! 4. reject flat objects: smallest AABB extent below `min_extent_ratio` (1e-3) of the largest;
//! 5. ground-truth cloud: the input's own cloud (a split file's `gt_cloud`, mapped by the
//!    normalization) or SPEC §1 samples on the normalized mesh (`clamp(ceil(area / 0.004²),
//!    20 000, 2 000 000)` points, seed `gt_seed`); reject objects with fewer than
//!    `min_surface_voxels` (10) voxels at r = 0.02;
//! 6. write `meshes/<uid>.obj` (exact f64 coordinates) and `pcd_normalized/<uid>.pcd` (binary,
//!    float32) and the stratification statistics ([`ObjectStats`]).
//!
//! The batch is resumable like `annotate`: one line per object in `build.jsonl` (accepted or
//! rejected; rejections are failure lines with an `error` field, redone with `retry_failed`).
//! At the end `manifest.json` (settings, accepted objects with source and statistics, rejected
//! objects with reasons, quantiles) and `pool.json` (a split file of the accepted objects) are
//! written from the whole log, sorted by uid, so they are byte-identical whatever the thread
//! count or the number of interruptions. The pool is everything in the log: building other
//! inputs into the same folder adds them. A log written with other settings is an error.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use objview_dataset::{
    drive, to_line, BatchSummary, Existing, ItemOutcome, ObjectRef, Progress, ResumableJsonl,
};
use objview_geom::cloud::{cloud_count, read_cloud, sample_surface, write_pcd_binary, DEFAULT_CLOUD_SEED};
use objview_geom::io::load_mesh;
use objview_geom::normalize::{normalize, Normalization, Transform};
use objview_geom::write::write_obj;
use objview_geom::{GeomError, Mesh};
use objview_voxel::{key_of, VoxelSet, DEFAULT_RESOLUTION};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::error::PoolError;
use crate::split::write_pretty;

/// Default fewest triangles: 4, the fewest faces of a closed surface (a tetrahedron).
pub const DEFAULT_MIN_FACES: usize = 4;
/// Default most triangles: 10 million (generous; rendering stays in the millisecond range).
pub const DEFAULT_MAX_FACES: usize = 10_000_000;
/// Default flatness limit: smallest AABB extent / largest extent below this is flat.
pub const DEFAULT_MIN_EXTENT_RATIO: f64 = 1e-3;
/// Default fewest voxels of S_gt at the build resolution.
pub const DEFAULT_MIN_SURFACE_VOXELS: usize = 10;
/// Folder of the normalized meshes inside the pool.
pub const MESH_DIR: &str = "meshes";
/// Folder of the ground-truth clouds inside the pool.
pub const CLOUD_DIR: &str = "pcd_normalized";
/// The per-object log (JSON Lines, resumable).
pub const BUILD_LOG: &str = "build.jsonl";
/// The manifest.
pub const MANIFEST_FILE: &str = "manifest.json";
/// The split file of all accepted objects.
pub const POOL_FILE: &str = "pool.json";
/// Settings keys that do not change what a build produces (ignored when resuming).
const PROVENANCE_KEYS: [&str; 3] = ["tool", "version", "command"];

/// Every setting of a build; recorded in each output.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildSettings {
    /// How meshes are brought to the unit ball.
    pub normalize: Normalization,
    /// Fewest triangles accepted.
    pub min_faces: usize,
    /// Most triangles accepted.
    pub max_faces: usize,
    /// Smallest accepted ratio of the smallest to the largest AABB extent.
    pub min_extent_ratio: f64,
    /// Voxel size of the surface-voxel filter and statistics.
    pub resolution: f64,
    /// Fewest voxels of S_gt accepted.
    pub min_surface_voxels: usize,
    /// Seed of sampled ground-truth clouds.
    pub gt_seed: u64,
}

impl Default for BuildSettings {
    fn default() -> Self {
        BuildSettings {
            normalize: Normalization::Unit,
            min_faces: DEFAULT_MIN_FACES,
            max_faces: DEFAULT_MAX_FACES,
            min_extent_ratio: DEFAULT_MIN_EXTENT_RATIO,
            resolution: DEFAULT_RESOLUTION,
            min_surface_voxels: DEFAULT_MIN_SURFACE_VOXELS,
            gt_seed: DEFAULT_CLOUD_SEED,
        }
    }
}

impl BuildSettings {
    /// Checks ranges; errors name the setting.
    pub fn validate(&self) -> Result<(), PoolError> {
        let bad = |name, reason: String| Err(PoolError::InvalidSetting { name, reason });
        if self.min_faces == 0 {
            return bad("min_faces", "must be at least 1".into());
        }
        if self.max_faces < self.min_faces {
            return bad("max_faces", format!("{} is below min_faces {}", self.max_faces, self.min_faces));
        }
        if !(self.min_extent_ratio.is_finite() && (0.0..1.0).contains(&self.min_extent_ratio)) {
            return bad("min_extent_ratio", format!("must be in [0, 1), got {}", self.min_extent_ratio));
        }
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return bad("resolution", format!("must be a positive number, got {}", self.resolution));
        }
        Ok(())
    }

    /// The settings block of every output.
    pub fn to_json(&self) -> Value {
        json!({
            "normalize": self.normalize.to_string(),
            "min_faces": self.min_faces,
            "max_faces": self.max_faces,
            "min_extent_ratio": self.min_extent_ratio,
            "resolution": self.resolution,
            "min_surface_voxels": self.min_surface_voxels,
            "gt_seed": self.gt_seed,
            "gt_count_rule": "clamp(ceil(area / 0.004^2), 20000, 2000000)",
            "mesh_format": "OBJ, shortest round-trip f64 coordinates",
            "cloud_format": "PCD binary, float32 x y z",
        })
    }
}

/// Why an object was left out of the pool.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RejectReason {
    /// The file cannot be read or parsed.
    Unreadable,
    /// Not a supported mesh format.
    UnsupportedFormat,
    /// A referenced vertex has a NaN or infinite coordinate.
    NonFinite,
    /// A face references a vertex that does not exist.
    IndexOutOfRange,
    /// No triangles.
    NoTriangles,
    /// All referenced vertices coincide.
    ZeroExtent,
    /// Other invalid geometry reported by the loader.
    InvalidGeometry,
    /// Fewer than `min_faces` triangles.
    TooFewFaces,
    /// More than `max_faces` triangles.
    TooManyFaces,
    /// Total surface area zero (every triangle degenerate).
    ZeroArea,
    /// `--normalize none` on an asset that is not normalized.
    NotNormalized,
    /// Smallest AABB extent below `min_extent_ratio` of the largest.
    Flat,
    /// Fewer than `min_surface_voxels` voxels of S_gt.
    TooFewVoxels,
    /// The input's own ground-truth cloud cannot be read.
    BadGtCloud,
    /// The uid cannot name a file.
    BadUid,
    /// Writing the object's files failed.
    WriteFailed,
}

impl RejectReason {
    /// Every reason, in report order.
    pub const ALL: [RejectReason; 16] = [
        RejectReason::Unreadable,
        RejectReason::UnsupportedFormat,
        RejectReason::NonFinite,
        RejectReason::IndexOutOfRange,
        RejectReason::NoTriangles,
        RejectReason::ZeroExtent,
        RejectReason::InvalidGeometry,
        RejectReason::TooFewFaces,
        RejectReason::TooManyFaces,
        RejectReason::ZeroArea,
        RejectReason::NotNormalized,
        RejectReason::Flat,
        RejectReason::TooFewVoxels,
        RejectReason::BadGtCloud,
        RejectReason::BadUid,
        RejectReason::WriteFailed,
    ];

    /// The reason's name in outputs (`too_few_faces`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            RejectReason::Unreadable => "unreadable",
            RejectReason::UnsupportedFormat => "unsupported_format",
            RejectReason::NonFinite => "non_finite",
            RejectReason::IndexOutOfRange => "index_out_of_range",
            RejectReason::NoTriangles => "no_triangles",
            RejectReason::ZeroExtent => "zero_extent",
            RejectReason::InvalidGeometry => "invalid_geometry",
            RejectReason::TooFewFaces => "too_few_faces",
            RejectReason::TooManyFaces => "too_many_faces",
            RejectReason::ZeroArea => "zero_area",
            RejectReason::NotNormalized => "not_normalized",
            RejectReason::Flat => "flat",
            RejectReason::TooFewVoxels => "too_few_voxels",
            RejectReason::BadGtCloud => "bad_gt_cloud",
            RejectReason::BadUid => "bad_uid",
            RejectReason::WriteFailed => "write_failed",
        }
    }

    /// The reason of a loader or normalization error. The geometry layer reports invalid
    /// geometry as text; the phrases matched here are those of `Mesh::validate`, the loaders and
    /// `normalize` (the build tests trigger each one, so a changed phrase fails them).
    pub fn of_geom_error(e: &GeomError) -> RejectReason {
        match e {
            GeomError::Io { .. } | GeomError::Parse { .. } => RejectReason::Unreadable,
            GeomError::Unsupported { .. } => RejectReason::UnsupportedFormat,
            GeomError::Invalid { reason, .. } => {
                let r = reason.as_str();
                if r.contains("no triangles") {
                    RejectReason::NoTriangles
                } else if r.contains("references vertex") || r.contains("outside 0..") {
                    RejectReason::IndexOutOfRange
                } else if r.contains("non-finite") {
                    RejectReason::NonFinite
                } else if r.contains("zero extent") {
                    RejectReason::ZeroExtent
                } else if r.contains("is not normalized") {
                    RejectReason::NotNormalized
                } else {
                    RejectReason::InvalidGeometry
                }
            }
        }
    }
}

/// Why one object was rejected: the reason and a message naming the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// The rejection class (recorded as [`RejectReason::as_str`]).
    pub reason: RejectReason,
    /// The one-line message, naming the file.
    pub detail: String,
}

impl Rejection {
    fn new(reason: RejectReason, detail: impl Into<String>) -> Self {
        Rejection { reason, detail: detail.into() }
    }

    fn geom(e: GeomError) -> Self {
        Rejection::new(RejectReason::of_geom_error(&e), e.to_string().replace('\n', " "))
    }
}

/// Stratification statistics of an accepted object, in the normalized frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectStats {
    /// Vertices of the mesh file.
    pub vertices: usize,
    /// Triangles.
    pub faces: usize,
    /// AABB extents along x, y, z.
    pub extents: [f64; 3],
    /// Sorted extents: middle / largest.
    pub aspect_mid: f64,
    /// Sorted extents: smallest / largest.
    pub aspect_min: f64,
    /// Total triangle area.
    pub surface_area: f64,
    /// Farthest referenced vertex from the origin (1 after `unit` normalization).
    pub max_radius: f64,
    /// Ground-truth points.
    pub gt_points: usize,
    /// |S_gt| at the build resolution.
    pub surface_voxels: usize,
    /// Voxel cells spanned by the mesh AABB: Π (floor(hi/r) − floor(lo/r) + 1).
    pub aabb_voxels: u64,
    /// surface_voxels / aabb_voxels.
    pub fill_ratio: f64,
}

/// Reads one numeric statistic of an object.
pub type StatAccessor = fn(&ObjectStats) -> f64;

/// The numeric statistics summarized by [`summarize`], with their accessors.
pub const STAT_FIELDS: [(&str, StatAccessor); 8] = [
    ("faces", |s| s.faces as f64),
    ("vertices", |s| s.vertices as f64),
    ("surface_area", |s| s.surface_area),
    ("aspect_mid", |s| s.aspect_mid),
    ("aspect_min", |s| s.aspect_min),
    ("gt_points", |s| s.gt_points as f64),
    ("surface_voxels", |s| s.surface_voxels as f64),
    ("fill_ratio", |s| s.fill_ratio),
];

/// An object that passed every filter, ready to be written.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The normalized mesh.
    pub mesh: Mesh,
    /// What normalization applied.
    pub transform: Transform,
    /// The ground-truth cloud (normalized frame).
    pub points: Vec<[f64; 3]>,
    /// Where it came from: a file, or `sampled(seed=…, count=…)`.
    pub gt_source: String,
    /// Stratification statistics of the object.
    pub stats: ObjectStats,
}

/// Loads, filters and normalizes one mesh and makes its ground-truth cloud (steps 1–5 of the
/// module docs), without writing anything.
pub fn prepare_object(
    mesh_path: &Path,
    gt_cloud: Option<&Path>,
    settings: &BuildSettings,
) -> Result<Prepared, Rejection> {
    let mesh = load_mesh(mesh_path).map_err(Rejection::geom)?;
    let faces = mesh.num_triangles();
    let name = mesh_path.display();
    if faces < settings.min_faces {
        return Err(Rejection::new(
            RejectReason::TooFewFaces,
            format!("{name}: {faces} triangles, fewer than min_faces = {}", settings.min_faces),
        ));
    }
    if faces > settings.max_faces {
        return Err(Rejection::new(
            RejectReason::TooManyFaces,
            format!("{name}: {faces} triangles, more than max_faces = {}", settings.max_faces),
        ));
    }
    let raw_area = mesh.surface_area();
    if !(raw_area > 0.0 && raw_area.is_finite()) {
        return Err(Rejection::new(
            RejectReason::ZeroArea,
            format!("{name}: total surface area is {raw_area} (every triangle is degenerate)"),
        ));
    }
    let (mesh, transform) = normalize(mesh, settings.normalize, mesh_path).map_err(Rejection::geom)?;
    let (lo, hi) = mesh.bounds().expect("validated mesh has triangles");
    let extents: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
    let mut sorted = extents;
    sorted.sort_by(f64::total_cmp);
    if sorted[0] < settings.min_extent_ratio * sorted[2] {
        return Err(Rejection::new(
            RejectReason::Flat,
            format!(
                "{name}: flat: smallest extent {:.3e} is below {} of the largest {:.3e}",
                sorted[0], settings.min_extent_ratio, sorted[2]
            ),
        ));
    }
    let surface_area = mesh.surface_area();
    let (points, gt_source) = match gt_cloud {
        Some(p) => {
            let mut pts =
                read_cloud(p).map_err(|e| Rejection::new(RejectReason::BadGtCloud, e.to_string()))?;
            if transform != Transform::IDENTITY {
                pts.iter_mut().for_each(|q| *q = transform.apply(*q));
            }
            (pts, p.display().to_string())
        }
        None => {
            let n = cloud_count(surface_area);
            (
                sample_surface(&mesh, n, settings.gt_seed),
                format!("sampled(seed={}, count={n})", settings.gt_seed),
            )
        }
    };
    let set = VoxelSet::from_points(&points, settings.resolution)
        .map_err(|e| Rejection::new(RejectReason::BadGtCloud, format!("{gt_source}: {e}")))?;
    if set.len() < settings.min_surface_voxels {
        return Err(Rejection::new(
            RejectReason::TooFewVoxels,
            format!(
                "{name}: {} surface voxels at r = {}, fewer than min_surface_voxels = {}",
                set.len(),
                settings.resolution,
                settings.min_surface_voxels
            ),
        ));
    }
    let (klo, khi) = (key_of(lo, settings.resolution), key_of(hi, settings.resolution));
    let aabb_voxels: u64 = (0..3).map(|k| (i64::from(khi[k]) - i64::from(klo[k]) + 1) as u64).product();
    let stats = ObjectStats {
        vertices: mesh.positions.len(),
        faces,
        extents,
        aspect_mid: sorted[1] / sorted[2],
        aspect_min: sorted[0] / sorted[2],
        surface_area,
        max_radius: mesh.max_radius(),
        gt_points: points.len(),
        surface_voxels: set.len(),
        aabb_voxels,
        fill_ratio: set.len() as f64 / aabb_voxels as f64,
    };
    Ok(Prepared { mesh, transform, points, gt_source, stats })
}

/// The normalization applied to an accepted object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NormalizationRecord {
    /// The normalization mode, `unit` or `none`.
    pub mode: String,
    /// `p' = (p − center) · scale`: the point moved to the origin, source file frame.
    pub center: [f64; 3],
    /// Uniform scale factor applied after centring (normalized units per file unit).
    pub scale: f64,
}

/// The `build.jsonl` line of an accepted object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Accepted {
    /// Object id (the source file stem, or the split file's `uid`).
    pub uid: String,
    /// The source mesh file as given.
    pub source: String,
    /// The normalized mesh, relative to the pool folder.
    pub mesh: String,
    /// The ground-truth cloud, relative to the pool folder.
    pub gt_cloud: String,
    /// Where the cloud came from: a file, or `sampled(seed=…, count=…)`.
    pub gt_source: String,
    /// The normalization that maps the source mesh to the pool's mesh.
    pub normalization: NormalizationRecord,
    /// Stratification statistics of the normalized object.
    pub stats: ObjectStats,
    /// The build's settings block ([`BuildSettings::to_json`]).
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// The `build.jsonl` line of a rejected object (a failure line: it has `error`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rejected {
    /// Object id.
    pub uid: String,
    /// The source mesh file as given.
    pub source: String,
    /// [`RejectReason::as_str`].
    pub reason: String,
    /// The message, naming the file.
    pub error: String,
    /// The build's settings block ([`BuildSettings::to_json`]).
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// One object's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum BuildRecord {
    /// The object passed every filter and was written to the pool.
    Accepted(Accepted),
    /// The object was rejected, with its reason.
    Rejected(Rejected),
}

impl BuildRecord {
    /// The object's uid.
    pub fn uid(&self) -> &str {
        match self {
            BuildRecord::Accepted(a) => &a.uid,
            BuildRecord::Rejected(r) => &r.uid,
        }
    }

    /// The line of the batch loop (rejections are failure lines).
    pub fn outcome(&self) -> ItemOutcome {
        match self {
            BuildRecord::Accepted(a) => ItemOutcome {
                line: to_line(a),
                failed: false,
                note: format!(
                    "{} faces, area {:.3}, {} surface voxels",
                    a.stats.faces, a.stats.surface_area, a.stats.surface_voxels
                ),
            },
            BuildRecord::Rejected(r) => ItemOutcome {
                line: to_line(r),
                failed: true,
                note: format!("rejected ({}): {}", r.reason, r.error),
            },
        }
    }
}

/// Why `uid` cannot name the object's files, if it cannot.
fn uid_problem(uid: &str) -> Option<&'static str> {
    if uid.is_empty() || uid == "." || uid == ".." {
        Some("is empty, '.' or '..'")
    } else if uid.contains(['/', '\\']) {
        Some("contains a path separator")
    } else if uid.chars().any(char::is_control) {
        Some("contains a control character")
    } else {
        None
    }
}

/// Prepares one object ([`prepare_object`]) and writes its mesh and cloud into `pool_dir`; never
/// fails: a problem is a [`BuildRecord::Rejected`]. `settings_json` is recorded in the line.
pub fn build_object(
    obj: &ObjectRef,
    pool_dir: &Path,
    settings: &BuildSettings,
    settings_json: &Value,
) -> BuildRecord {
    let source = obj.mesh.display().to_string();
    let reject = |r: Rejection| {
        BuildRecord::Rejected(Rejected {
            uid: obj.uid.clone(),
            source: source.clone(),
            reason: r.reason.as_str().to_string(),
            error: r.detail,
            settings: settings_json.clone(),
            version: crate::VERSION.to_string(),
        })
    };
    if let Some(why) = uid_problem(&obj.uid) {
        return reject(Rejection::new(RejectReason::BadUid, format!("{source}: uid {:?} {why}", obj.uid)));
    }
    let prepared = match prepare_object(&obj.mesh, obj.gt_cloud.as_deref(), settings) {
        Ok(p) => p,
        Err(r) => return reject(r),
    };
    let mesh_rel = format!("{MESH_DIR}/{}.obj", obj.uid);
    let cloud_rel = format!("{CLOUD_DIR}/{}.pcd", obj.uid);
    let written = write_obj(&pool_dir.join(&mesh_rel), &prepared.mesh)
        .and_then(|()| write_pcd_binary(&pool_dir.join(&cloud_rel), &prepared.points));
    if let Err(e) = written {
        return reject(Rejection::new(RejectReason::WriteFailed, e.to_string()));
    }
    BuildRecord::Accepted(Accepted {
        uid: obj.uid.clone(),
        source,
        mesh: mesh_rel,
        gt_cloud: cloud_rel,
        gt_source: prepared.gt_source,
        normalization: NormalizationRecord {
            mode: settings.normalize.to_string(),
            center: prepared.transform.center,
            scale: prepared.transform.scale,
        },
        stats: prepared.stats,
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    })
}

/// The first settings key (provenance keys aside) whose value differs, as `key: a vs b`.
fn settings_difference(old: &Value, new: &Value) -> Option<String> {
    let empty = serde_json::Map::new();
    let (o, n) = (old.as_object().unwrap_or(&empty), new.as_object().unwrap_or(&empty));
    let mut keys: Vec<&String> =
        o.keys().chain(n.keys()).filter(|k| !PROVENANCE_KEYS.contains(&k.as_str())).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter().find(|k| o.get(*k) != n.get(*k)).map(|k| {
        let show = |v: Option<&Value>| v.map_or("(missing)".to_string(), Value::to_string);
        format!("{k}: {} vs {}", show(o.get(k)), show(n.get(k)))
    })
}

/// Reads every complete line of a build log.
pub fn read_build_log(path: &Path) -> Result<Vec<BuildRecord>, PoolError> {
    let text = objview_geom::fsutil::read_text(path).map_err(|e| PoolError::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let bad = |e: serde_json::Error| {
            PoolError::mismatch(path, format!("line {}: not a build record ({e})", i + 1))
        };
        let v: Value = serde_json::from_str(line).map_err(bad)?;
        out.push(if v.get("error").is_some() {
            BuildRecord::Rejected(serde_json::from_value(v).map_err(bad)?)
        } else {
            BuildRecord::Accepted(serde_json::from_value(v).map_err(bad)?)
        });
    }
    Ok(out)
}

/// Opens (creating the pool folders) the build log of `pool_dir` for a resumed or fresh build.
/// Errors when a line of an earlier run was built with other settings than `settings_json`
/// (provenance keys aside).
pub fn open_build_log(
    pool_dir: &Path,
    settings_json: &Value,
    retry_failed: bool,
) -> Result<(ResumableJsonl, Existing), PoolError> {
    for sub in [MESH_DIR, CLOUD_DIR] {
        let d = pool_dir.join(sub);
        std::fs::create_dir_all(&d).map_err(|e| PoolError::io(&d, e))?;
    }
    let path = pool_dir.join(BUILD_LOG);
    if path.is_file() {
        // Checked before opening, which would already drop retried lines.
        let text = objview_geom::fsutil::read_text(&path).map_err(|e| PoolError::io(&path, e))?;
        for (i, line) in text.lines().enumerate() {
            let Ok(v) = serde_json::from_str::<Value>(line) else { continue };
            if let Some(diff) = v.get("settings").and_then(|s| settings_difference(s, settings_json)) {
                return Err(PoolError::mismatch(
                    &path,
                    format!(
                        "line {} (uid {}) was built with other settings ({diff}); use another --out or \
                         the same settings",
                        i + 1,
                        v.get("uid").unwrap_or(&Value::Null)
                    ),
                ));
            }
        }
    }
    Ok(ResumableJsonl::open(&path, "uid", retry_failed)?)
}

/// Builds every object of `objects` not in `existing` on `threads` workers (`None`: every
/// core) through the batch driver ([`objview_dataset::drive`]), appending one line each to
/// `out` ([`open_build_log`]); `progress` sees the batch start and each object's outcome.
#[allow(clippy::too_many_arguments)]
pub fn run_build(
    objects: &[ObjectRef],
    pool_dir: &Path,
    settings: &BuildSettings,
    settings_json: &Value,
    out: ResumableJsonl,
    existing: &Existing,
    threads: Option<usize>,
    progress: &dyn Progress,
) -> Result<BatchSummary, PoolError> {
    settings.validate()?;
    let work = |obj: &ObjectRef| build_object(obj, pool_dir, settings, settings_json).outcome();
    Ok(drive("pool build", None, None, objects, out, existing, threads, work, progress)?)
}

/// Quantiles of one statistic over the accepted objects.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatSummary {
    /// The statistic's name (an [`ObjectStats`] field, see [`STAT_FIELDS`]).
    pub name: String,
    /// Smallest value.
    pub min: f64,
    /// First quartile ([`quantile`] 0.25).
    pub q25: f64,
    /// Median ([`quantile`] 0.5).
    pub median: f64,
    /// Third quartile ([`quantile`] 0.75).
    pub q75: f64,
    /// Largest value.
    pub max: f64,
}

/// The `q`-quantile of ascending `sorted` by linear interpolation between closest ranks
/// (position q·(n − 1)); NaN for an empty slice.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// Min, quartiles and max of every [`STAT_FIELDS`] statistic (empty without objects).
pub fn summarize(stats: &[&ObjectStats]) -> Vec<StatSummary> {
    if stats.is_empty() {
        return Vec::new();
    }
    STAT_FIELDS
        .iter()
        .map(|(name, get)| {
            let mut v: Vec<f64> = stats.iter().map(|s| get(s)).collect();
            v.sort_by(f64::total_cmp);
            StatSummary {
                name: name.to_string(),
                min: v[0],
                q25: quantile(&v, 0.25),
                median: quantile(&v, 0.5),
                q75: quantile(&v, 0.75),
                max: v[v.len() - 1],
            }
        })
        .collect()
}

/// What a finished build holds (every line of the log, sorted by uid).
#[derive(Debug, Clone, PartialEq)]
pub struct Manifest {
    /// Lines of the accepted objects, sorted by uid.
    pub accepted: Vec<Accepted>,
    /// Lines of the rejected objects, sorted by uid.
    pub rejected: Vec<Rejected>,
    /// Rejections per reason (reason names).
    pub reasons: BTreeMap<String, usize>,
    /// Quantiles of every [`STAT_FIELDS`] statistic over the accepted objects.
    pub summary: Vec<StatSummary>,
    /// Where `manifest.json` was written (in the pool folder).
    pub manifest_path: PathBuf,
    /// Where `pool.json` (the split file of the accepted objects) was written.
    pub pool_path: PathBuf,
}

/// Writes `manifest.json` and `pool.json` of `pool_dir` from its build log (module docs).
pub fn finish_build(pool_dir: &Path, settings_json: &Value) -> Result<Manifest, PoolError> {
    let mut accepted = Vec::new();
    let mut rejected = Vec::new();
    for r in read_build_log(&pool_dir.join(BUILD_LOG))? {
        match r {
            BuildRecord::Accepted(a) => accepted.push(a),
            BuildRecord::Rejected(r) => rejected.push(r),
        }
    }
    accepted.sort_by(|a, b| a.uid.cmp(&b.uid));
    rejected.sort_by(|a, b| a.uid.cmp(&b.uid));
    let mut reasons = BTreeMap::new();
    for r in &rejected {
        *reasons.entry(r.reason.clone()).or_insert(0usize) += 1;
    }
    let summary = summarize(&accepted.iter().map(|a| &a.stats).collect::<Vec<_>>());
    let manifest = json!({
        "version": crate::VERSION,
        "settings": settings_json,
        "counts": {"objects": accepted.len() + rejected.len(), "accepted": accepted.len(), "rejected": rejected.len()},
        "rejection_reasons": reasons,
        "statistics": summary,
        "accepted": accepted.iter().map(|a| json!({
            "uid": a.uid, "source": a.source, "mesh": a.mesh, "gt_cloud": a.gt_cloud, "gt_source": a.gt_source,
            "normalization": a.normalization, "stats": a.stats,
        })).collect::<Vec<_>>(),
        "rejected": rejected.iter().map(|r| json!({
            "uid": r.uid, "source": r.source, "reason": r.reason, "error": r.error,
        })).collect::<Vec<_>>(),
    });
    let pool: Vec<Value> =
        accepted.iter().map(|a| json!({"uid": a.uid, "mesh": a.mesh, "gt_cloud": a.gt_cloud})).collect();
    let manifest_path = pool_dir.join(MANIFEST_FILE);
    let pool_path = pool_dir.join(POOL_FILE);
    write_pretty(&manifest_path, &manifest)?;
    write_pretty(&pool_path, &Value::Array(pool))?;
    Ok(Manifest { accepted, rejected, reasons, summary, manifest_path, pool_path })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned box [c − h, c + h] as OBJ text (8 vertices, 12 triangles).
    fn box_obj(c: [f64; 3], h: [f64; 3]) -> String {
        let mut s = String::new();
        for i in 0..8 {
            let sign = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
            s +=
                &format!("v {} {} {}\n", c[0] + sign(1) * h[0], c[1] + sign(2) * h[1], c[2] + sign(4) * h[2]);
        }
        for q in [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]] {
            s += &format!(
                "f {} {} {}\nf {} {} {}\n",
                q[0] + 1,
                q[1] + 1,
                q[2] + 1,
                q[0] + 1,
                q[2] + 1,
                q[3] + 1
            );
        }
        s
    }

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// A box 2 × 1 × 0.5 centred at (5, 5, 5): normalized by 1/√1.3125 (half-diagonal).
    fn good_box(dir: &Path) -> PathBuf {
        write(dir, "good.obj", &box_obj([5.0; 3], [1.0, 0.5, 0.25]))
    }

    fn rejection(path: &Path, settings: &BuildSettings) -> Rejection {
        match prepare_object(path, None, settings) {
            Ok(_) => panic!("{} was accepted", path.display()),
            Err(r) => r,
        }
    }

    #[test]
    fn every_filter_rejects_its_bad_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let tetra = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n";
        let tiny = "OFF\n4 4 0\n0 0 0\n0.01 0 0\n0 0.01 0\n0 0 0.01\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n";
        let s = BuildSettings::default();
        let cases: Vec<(PathBuf, BuildSettings, RejectReason, &str)> = vec![
            (d.join("missing.obj"), s.clone(), RejectReason::Unreadable, "missing.obj"),
            (
                write(d, "truncated.off", "OFF\n3 1 0\n0 0 0\n"),
                s.clone(),
                RejectReason::Unreadable,
                "truncated.off",
            ),
            (
                write(d, "notes.txt", "hello"),
                s.clone(),
                RejectReason::UnsupportedFormat,
                "unsupported format",
            ),
            (
                write(d, "nan.off", &tetra.replace("1 0 0\n", "nan 0 0\n")),
                s.clone(),
                RejectReason::NonFinite,
                "non-finite",
            ),
            (
                write(d, "index.off", &tetra.replace("3 1 2 3", "3 1 2 7")),
                s.clone(),
                RejectReason::IndexOutOfRange,
                "vertex 7",
            ),
            (
                write(d, "negative.off", &tetra.replace("3 1 2 3", "3 1 2 -1")),
                s.clone(),
                RejectReason::IndexOutOfRange,
                "-1",
            ),
            (
                write(d, "empty.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n"),
                s.clone(),
                RejectReason::NoTriangles,
                "no triangles",
            ),
            (
                write(
                    d,
                    "point.off",
                    "OFF\n3 4 0\n1 1 1\n1 1 1\n1 1 1\n3 0 1 2\n3 0 1 2\n3 0 1 2\n3 0 1 2\n",
                ),
                s.clone(),
                RejectReason::ZeroExtent,
                "zero extent",
            ),
            (
                write(
                    d,
                    "line.off",
                    "OFF\n4 4 0\n0 0 0\n1 0 0\n2 0 0\n3 0 0\n3 0 1 2\n3 1 2 3\n3 0 2 3\n3 0 1 3\n",
                ),
                s.clone(),
                RejectReason::ZeroArea,
                "area is 0",
            ),
            (
                write(d, "two.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n"),
                s.clone(),
                RejectReason::TooFewFaces,
                "2 triangles",
            ),
            (
                good_box(d),
                BuildSettings { max_faces: 11, ..s.clone() },
                RejectReason::TooManyFaces,
                "12 triangles",
            ),
            (
                write(d, "sheet.obj", &box_obj([0.0; 3], [0.5, 0.5, 0.5e-4])),
                s.clone(),
                RejectReason::Flat,
                "flat",
            ),
            (
                good_box(d),
                BuildSettings { normalize: Normalization::None, ..s.clone() },
                RejectReason::NotNormalized,
                "is not normalized",
            ),
            (
                write(d, "tiny.off", tiny),
                BuildSettings { normalize: Normalization::None, ..s.clone() },
                RejectReason::TooFewVoxels,
                "1 surface voxels",
            ),
        ];
        for (path, settings, reason, needle) in cases {
            let r = rejection(&path, &settings);
            assert_eq!(r.reason, reason, "{}: {}", path.display(), r.detail);
            assert!(r.detail.contains(needle), "{}: {}", path.display(), r.detail);
        }
        // The unit tetrahedron itself passes (4 faces is the default minimum).
        assert!(prepare_object(&write(d, "tetra.off", tetra), None, &s).is_ok());
    }

    #[test]
    fn a_good_mesh_is_normalized_sampled_and_measured() {
        let dir = tempfile::tempdir().unwrap();
        let path = good_box(dir.path());
        let pool = dir.path().join("pool");
        let (out, ex) = open_build_log(&pool, &json!({}), false).unwrap();
        drop((out, ex));
        let obj = ObjectRef::from_mesh(&path);
        let BuildRecord::Accepted(a) = build_object(&obj, &pool, &BuildSettings::default(), &json!({"k": 1}))
        else {
            panic!("rejected")
        };
        let scale = 1.0 / 1.3125f64.sqrt();
        assert_eq!(a.normalization.center, [5.0; 3]);
        assert!((a.normalization.scale - scale).abs() < 1e-15);
        assert_eq!((a.mesh.as_str(), a.gt_cloud.as_str()), ("meshes/good.obj", "pcd_normalized/good.pcd"));
        // Area 2·(2·1 + 2·0.5 + 1·0.5) = 7 before, 7/1.3125 after; count = ceil(area / 0.004²).
        let area = 7.0 / 1.3125;
        let count = 333_334;
        assert_eq!((area / 1.6e-5f64).ceil(), count as f64);
        assert_eq!(a.gt_source, format!("sampled(seed=0, count={count})"));
        let st = &a.stats;
        assert_eq!((st.vertices, st.faces, st.gt_points), (8, 12, count));
        assert!((st.surface_area - area).abs() < 1e-12);
        assert!((st.max_radius - 1.0).abs() < 1e-12);
        for (e, want) in st.extents.iter().zip([2.0, 1.0, 0.5]) {
            assert!((e - want * scale).abs() < 1e-12);
        }
        assert!((st.aspect_mid - 0.5).abs() < 1e-12 && (st.aspect_min - 0.25).abs() < 1e-12);
        // Half extents 0.8729, 0.4364, 0.2182 → keys -44..=43, -22..=21, -11..=10.
        assert_eq!(st.aabb_voxels, 88 * 44 * 22);
        assert!((st.fill_ratio - st.surface_voxels as f64 / 85_184.0).abs() < 1e-15);

        // The files: the mesh reads back with radius 1, the cloud has `count` points on the box.
        let mesh = load_mesh(&pool.join(&a.mesh)).unwrap();
        assert!((mesh.max_radius() - 1.0).abs() < 1e-12);
        assert_eq!(mesh.num_triangles(), 12);
        let pts = read_cloud(&pool.join(&a.gt_cloud)).unwrap();
        assert_eq!(pts.len(), count);
        let half = [scale, 0.5 * scale, 0.25 * scale];
        for p in pts.iter().step_by(997) {
            let on_face = (0..3).any(|k| (p[k].abs() - half[k]).abs() < 1e-6);
            let inside = (0..3).all(|k| p[k].abs() <= half[k] + 1e-6);
            assert!(on_face && inside, "{p:?}");
        }
        // |S_gt| independently: distinct floor(p / r) of the (float32) file points.
        let keys: std::collections::HashSet<[i64; 3]> =
            pts.iter().map(|p| p.map(|c| (c / 0.02).floor() as i64)).collect();
        let diff = (keys.len() as f64 - st.surface_voxels as f64).abs();
        assert!(diff <= 0.001 * keys.len() as f64, "{} vs {}", keys.len(), st.surface_voxels);

        // Deterministic files.
        let again = dir.path().join("again");
        std::fs::create_dir_all(again.join(MESH_DIR)).unwrap();
        std::fs::create_dir_all(again.join(CLOUD_DIR)).unwrap();
        build_object(&obj, &again, &BuildSettings::default(), &json!({"k": 1}));
        for f in [&a.mesh, &a.gt_cloud] {
            assert_eq!(std::fs::read(pool.join(f)).unwrap(), std::fs::read(again.join(f)).unwrap(), "{f}");
        }
    }

    #[test]
    fn uids_and_clouds_of_split_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let path = good_box(dir.path());
        let s = BuildSettings::default();
        let mut obj = ObjectRef::from_mesh(&path);
        obj.uid = "a/b".into();
        let BuildRecord::Rejected(r) = build_object(&obj, dir.path(), &s, &json!({})) else { panic!() };
        assert_eq!(r.reason, "bad_uid");
        assert!(r.error.contains("path separator"), "{}", r.error);

        // A cloud given with the input is mapped by the normalization.
        let cloud = dir.path().join("c.ply");
        write_objview_ply(&cloud, &[[5.0, 5.0, 5.0], [6.0, 5.5, 5.25], [4.0, 4.5, 4.75]]);
        obj = ObjectRef::from_mesh(&path);
        obj.gt_cloud = Some(cloud.clone());
        let p = prepare_object(
            &obj.mesh,
            obj.gt_cloud.as_deref(),
            &BuildSettings { min_surface_voxels: 1, ..s.clone() },
        )
        .unwrap();
        assert_eq!(p.gt_source, cloud.display().to_string());
        let k = 1.0 / 1.3125f64.sqrt();
        assert_eq!(p.points[0], [0.0; 3]);
        assert!((p.points[1][0] - k).abs() < 1e-12 && (p.points[2][2] + 0.25 * k).abs() < 1e-12);
        assert_eq!(p.stats.surface_voxels, 3);
        // Three points: too few voxels by default; a missing cloud is its own reason.
        assert_eq!(
            prepare_object(&obj.mesh, Some(&cloud), &s).unwrap_err().reason,
            RejectReason::TooFewVoxels
        );
        let missing = dir.path().join("nope.ply");
        assert_eq!(
            prepare_object(&obj.mesh, Some(&missing), &s).unwrap_err().reason,
            RejectReason::BadGtCloud
        );
    }

    fn write_objview_ply(path: &Path, pts: &[[f64; 3]]) {
        objview_geom::cloud::write_ply_points(path, pts).unwrap();
    }

    #[test]
    fn quantiles_interpolate_between_ranks() {
        let v = [1.0, 2.0, 3.0, 4.0];
        assert_eq!([0.0, 0.25, 0.5, 0.75, 1.0].map(|q| quantile(&v, q)), [1.0, 1.75, 2.5, 3.25, 4.0]);
        assert_eq!(quantile(&[7.0], 0.3), 7.0);
        assert!(quantile(&[], 0.5).is_nan());
        assert!(summarize(&[]).is_empty());
    }

    fn build(objects: &[ObjectRef], pool: &Path, settings: &BuildSettings, threads: usize) -> BatchSummary {
        build_retry(objects, pool, settings, threads, false)
    }

    fn build_retry(
        objects: &[ObjectRef],
        pool: &Path,
        settings: &BuildSettings,
        threads: usize,
        retry: bool,
    ) -> BatchSummary {
        let sj = json!({"tool": "objview", "version": "test", "build": settings.to_json()});
        let (out, ex) = open_build_log(pool, &sj, retry).unwrap();
        let summary =
            run_build(objects, pool, settings, &sj, out, &ex, Some(threads), &objview_dataset::Silent)
                .unwrap();
        finish_build(pool, &sj).unwrap();
        summary
    }

    #[test]
    fn batch_is_resumable_deterministic_and_checks_settings() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let inputs = [
            write(d, "b_cube.obj", &box_obj([0.0; 3], [1.0, 1.0, 1.0])),
            write(d, "a_sheet.obj", &box_obj([0.0; 3], [1.0, 1.0, 1e-5])),
            write(d, "c_broken.off", "OFF\nbroken"),
        ];
        let objects: Vec<ObjectRef> = inputs.iter().map(|p| ObjectRef::from_mesh(p)).collect();
        let s = BuildSettings::default();
        let (p1, p2) = (d.join("p1"), d.join("p2"));
        let first = build(&objects, &p1, &s, 1);
        assert_eq!((first.processed, first.failed), (3, 2));
        build(&objects, &p2, &s, 2);
        let manifest = std::fs::read_to_string(p1.join(MANIFEST_FILE)).unwrap();
        for f in [MANIFEST_FILE, POOL_FILE, "meshes/b_cube.obj", "pcd_normalized/b_cube.pcd"] {
            assert_eq!(std::fs::read(p1.join(f)).unwrap(), std::fs::read(p2.join(f)).unwrap(), "{f}");
        }
        let m: Value = serde_json::from_str(&manifest).unwrap();
        assert_eq!(m["counts"], json!({"objects": 3, "accepted": 1, "rejected": 2}));
        assert_eq!(m["rejection_reasons"], json!({"flat": 1, "unreadable": 1}));
        assert_eq!(m["rejected"][0]["uid"], "a_sheet");
        assert_eq!(m["accepted"][0]["stats"]["faces"], 12);
        assert_eq!(m["statistics"][0]["name"], "faces");
        assert_eq!(m["settings"]["build"]["min_faces"], 4);
        // pool.json is a split file with the pool's own files.
        let pool = objview_dataset::read_split(&p1.join(POOL_FILE)).unwrap();
        assert_eq!(pool.len(), 1);
        assert_eq!(pool[0].mesh, p1.join("meshes/b_cube.obj"));
        assert_eq!(pool[0].gt_cloud.as_deref(), Some(p1.join("pcd_normalized/b_cube.pcd").as_path()));

        // Re-run: nothing to do, same outputs; a torn last line is redone.
        let again = build(&objects, &p1, &s, 2);
        assert_eq!((again.skipped, again.processed), (3, 0));
        assert_eq!(std::fs::read_to_string(p1.join(MANIFEST_FILE)).unwrap(), manifest);
        let log = p1.join(BUILD_LOG);
        let text = std::fs::read_to_string(&log).unwrap();
        let cut = text[..text.len() - 1].rfind('\n').unwrap() + 1;
        std::fs::write(&log, &text[..cut + 10]).unwrap();
        let resumed = build(&objects, &p1, &s, 1);
        assert_eq!((resumed.skipped, resumed.processed), (2, 1));
        assert_eq!(std::fs::read_to_string(p1.join(MANIFEST_FILE)).unwrap(), manifest);

        // Retrying the rejected objects redoes them (appended last) and gives the same manifest.
        let retried = build_retry(&objects, &p1, &s, 1, true);
        assert_eq!((retried.skipped, retried.processed, retried.failed), (1, 2, 2));
        let log = std::fs::read_to_string(p1.join(BUILD_LOG)).unwrap();
        assert!(log.starts_with("{\"uid\":\"b_cube\""), "{log}");
        assert_eq!(std::fs::read_to_string(p1.join(MANIFEST_FILE)).unwrap(), manifest);

        // Other settings: refused, naming the setting.
        let other = BuildSettings { min_faces: 6, ..s };
        let sj = json!({"tool": "objview", "version": "test", "build": other.to_json()});
        let err = open_build_log(&p1, &sj, false).unwrap_err().to_string();
        assert!(err.contains("build.jsonl") && err.contains("min_faces"), "{err}");
    }

    #[test]
    fn settings_are_checked() {
        for (s, needle) in [
            (BuildSettings { min_faces: 0, ..Default::default() }, "min_faces"),
            (BuildSettings { max_faces: 3, ..Default::default() }, "max_faces"),
            (BuildSettings { min_extent_ratio: 1.0, ..Default::default() }, "min_extent_ratio"),
            (BuildSettings { resolution: -1.0, ..Default::default() }, "resolution"),
        ] {
            assert!(s.validate().unwrap_err().to_string().contains(needle), "{needle}");
        }
        assert!(BuildSettings::default().validate().is_ok());
    }
}
