//! The observable reference of (object, view space) (SPEC §5): the fused cloud (voxel 0.005) of
//! every feasible view of the reference view set (tammes-360), fused in view-set order, and its
//! SC@τ against the ground truth (the observable surface ratio). NSC@τ is coverage of this
//! cloud.
//!
//! It costs one render per feasible reference view, so it is cached on disk. The cache key is
//! a hash of everything that determines it — mesh positions and triangles, ground-truth
//! points, view-space rules, reference directions, view radius, intrinsics, fusion voxel, τ
//! list and the crate version — and the full description is stored next to the points and
//! compared on load, so a changed mesh or setting never reuses a stale cache.

use std::path::{Path, PathBuf};

use objview_geom::hash::Fnv;
use objview_geom::{Mesh, Pose};
use objview_render::{Camera, Intrinsics, Renderer};
use objview_views::{ViewSet, ViewSpace};
use serde::{Deserialize, Serialize};

use crate::chamfer::Targets;
use crate::fusion::FusedCloud;
use crate::grid::Domain;
use crate::result::ReferenceInfo;
use crate::settings::EpisodeSettings;
use crate::vocab::tau_key;
use crate::EpisodeError;

/// The observable reference.
#[derive(Debug, Clone)]
pub struct Reference {
    /// Reference points (voxel centroids), in fusion order.
    pub points: Vec<[f64; 3]>,
    /// The feasible reference poses, in order.
    pub poses: Vec<Pose>,
    /// What result lines record about it (sizes, view set, observable SC, cache key).
    pub info: ReferenceInfo,
}

/// What the cache stores next to the points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CacheRecord {
    description: String,
    views: usize,
    points: usize,
    /// Ground-truth points covered by the reference at each τ (integers: exact on reload).
    observable_counts: Vec<usize>,
    gt_points: usize,
}

fn fractions(counts: &[usize], n: usize, taus: &[f64]) -> std::collections::BTreeMap<String, f64> {
    let n = n.max(1) as f64;
    taus.iter().zip(counts).map(|(&t, &c)| (tau_key(t), c as f64 / n)).collect()
}

fn read_points(path: &Path, n: usize) -> Option<Vec<[f64; 3]>> {
    let bytes = std::fs::read(path).ok()?;
    if bytes.len() != n * 24 {
        return None;
    }
    Some(
        bytes
            .chunks_exact(24)
            .map(|c| {
                let f = |i: usize| f64::from_le_bytes(c[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
                [f(0), f(1), f(2)]
            })
            .collect(),
    )
}

/// Writes `bytes` to `path` through a temporary file and a rename. The temporary name is unique
/// per write (process id and a per-process counter): two threads that build the same reference
/// at once (parallel episodes or tests on one object) each rename their own complete file, and
/// the last rename wins with identical content.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), EpisodeError> {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp{}-{n}", std::process::id()));
    std::fs::write(&tmp, bytes).map_err(|e| EpisodeError::Io(tmp.display().to_string(), e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| EpisodeError::Io(path.display().to_string(), e.to_string()))
}

/// A hash of the mesh geometry (positions and triangles).
pub fn mesh_hash(mesh: &Mesh) -> u64 {
    let mut h = Fnv::default();
    for p in &mesh.positions {
        h.eat_f64s(p);
    }
    for t in &mesh.triangles {
        for i in t {
            h.eat(&i.to_le_bytes());
        }
    }
    h.0
}

/// A hash of a point cloud.
pub fn cloud_hash(points: &[[f64; 3]]) -> u64 {
    let mut h = Fnv::default();
    for p in points {
        h.eat_f64s(p);
    }
    h.0
}

/// The full description the cache key is made of.
pub fn describe(
    mesh: &Mesh,
    gt: &[[f64; 3]],
    space: &ViewSpace,
    view_set: &ViewSet,
    intrinsics: &Intrinsics,
    settings: &EpisodeSettings,
) -> String {
    let mut dirs = Fnv::default();
    for d in &view_set.dirs {
        dirs.eat_f64s(d);
    }
    format!(
        "objview-episode {} | mesh {:016x} v{} t{} | gt {:016x} n{} | space {:?} | views {} {:016x} n{} | radius {:?} | \
         intrinsics {:?} | voxel {:?} | taus {:?}",
        env!("CARGO_PKG_VERSION"),
        mesh_hash(mesh),
        mesh.positions.len(),
        mesh.triangles.len(),
        cloud_hash(gt),
        gt.len(),
        space,
        view_set.name,
        dirs.0,
        view_set.len(),
        settings.view_radius,
        intrinsics,
        settings.fusion_voxel,
        settings.taus,
    )
}

/// The reference of (mesh, space): read from `cache_dir` when a record with the same
/// description exists, else built (and stored when `cache_dir` is given).
#[allow(clippy::too_many_arguments)]
pub fn observable_reference(
    mesh: &Mesh,
    gt: &[[f64; 3]],
    domain: &Domain,
    space: &ViewSpace,
    view_set: &ViewSet,
    intrinsics: &Intrinsics,
    settings: &EpisodeSettings,
    cache_dir: Option<&Path>,
) -> Result<Reference, EpisodeError> {
    let description = describe(mesh, gt, space, view_set, intrinsics, settings);
    let mut h = Fnv::default();
    h.eat(description.as_bytes());
    let key = format!("{:016x}", h.0);
    let poses: Vec<Pose> =
        view_set.poses(settings.view_radius).into_iter().filter(|p| space.is_feasible(p)).collect();
    let path: Option<PathBuf> = cache_dir.map(|d| d.join(format!("reference-{key}.json")));
    if let Some(p) = &path {
        if let Ok(bytes) = std::fs::read(p) {
            if let Ok(rec) = serde_json::from_slice::<CacheRecord>(&bytes) {
                if rec.description == description && rec.views == poses.len() {
                    if let Some(points) = read_points(&p.with_extension("bin"), rec.points) {
                        let observable_sc = fractions(&rec.observable_counts, rec.gt_points, &settings.taus);
                        let info = ReferenceInfo {
                            points: 0,
                            views: 0,
                            view_set: view_set.name.clone(),
                            observable_sc,
                            key,
                            cached: true,
                        };
                        return Ok(Reference { points, poses, info }.with_count());
                    }
                }
            }
        }
    }
    let mut fused = FusedCloud::new(domain.clone());
    let mut renderer = Renderer::new();
    for pose in &poses {
        let cam = Camera::new(*pose, *intrinsics);
        let mut frame = objview_render::Frame::empty(cam);
        renderer.render_into(mesh, &cam, &mut frame);
        fused.insert(&frame.observed_points());
    }
    let points = fused.pos.clone();
    // Only d² < τ² matters for the counts: the searches are capped at the largest τ (a target
    // at or beyond it is counted at no τ either way), and the reference points' own distances
    // to the ground truth are never computed.
    let cap = settings.taus.iter().copied().fold(0.0, f64::max);
    let mut t = Targets::new(domain.clone(), gt, cap).map_err(EpisodeError::Setup)?;
    if !fused.is_empty() {
        t.settle(&fused);
    }
    let counts = t.counts(&settings.taus);
    let observable_sc = fractions(&counts, gt.len(), &settings.taus);
    if let (Some(p), Some(dir)) = (&path, cache_dir) {
        std::fs::create_dir_all(dir)
            .map_err(|e| EpisodeError::Io(dir.display().to_string(), e.to_string()))?;
        let mut bin = Vec::with_capacity(points.len() * 24);
        for q in &points {
            for x in q {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        }
        write_atomic(&p.with_extension("bin"), &bin)?;
        let rec = CacheRecord {
            description,
            views: poses.len(),
            points: points.len(),
            observable_counts: counts,
            gt_points: gt.len(),
        };
        let json = serde_json::to_vec_pretty(&rec)
            .map_err(|e| EpisodeError::Io(p.display().to_string(), e.to_string()))?;
        write_atomic(p, &json)?;
    }
    Ok(Reference {
        points,
        poses,
        info: ReferenceInfo {
            points: 0,
            views: 0,
            view_set: view_set.name.clone(),
            observable_sc,
            key,
            cached: false,
        },
    }
    .with_count())
}

impl Reference {
    fn with_count(mut self) -> Reference {
        self.info.points = self.points.len();
        self.info.views = self.poses.len();
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concurrent_atomic_writes_of_one_file_all_succeed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("reference-x.bin");
        let handles: Vec<_> = (0..8u8)
            .map(|_| {
                let path = path.clone();
                std::thread::spawn(move || {
                    for _ in 0..50 {
                        write_atomic(&path, &[7u8; 4096]).unwrap();
                    }
                })
            })
            .collect();
        for h in handles {
            h.join().unwrap();
        }
        assert_eq!(std::fs::read(&path).unwrap(), vec![7u8; 4096]);
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 1, "temporary files left behind: {left:?}");
    }
}
