//! Small pieces shared by several subcommands: ground-truth cloud resolution and JSON output.

use anyhow::{Context, Result};
use objview_geom::cloud::{cloud_count, read_cloud, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::normalize::Transform;
use objview_geom::Mesh;
use serde_json::Value;
use std::path::Path;

/// A ground-truth cloud in the normalized object frame and where it came from.
pub struct GroundTruth {
    pub points: Vec<[f64; 3]>,
    /// The file it was read from, or `sampled(seed=…, count=…)`.
    pub source: String,
}

/// Reads the cloud at `path` (mapped by `transform` into the normalized frame) or samples one
/// on `mesh` per SPEC §1 (area-weighted, clamp(ceil(area/0.004²), 20 000, 2 000 000) points,
/// fixed seed).
pub fn ground_truth(mesh: &Mesh, transform: &Transform, path: Option<&Path>) -> Result<GroundTruth> {
    match path {
        Some(p) => {
            let mut pts = read_cloud(p)?;
            if *transform != Transform::IDENTITY {
                for q in &mut pts {
                    *q = transform.apply(*q);
                }
            }
            Ok(GroundTruth { points: pts, source: p.display().to_string() })
        }
        None => {
            let n = cloud_count(mesh.surface_area());
            let pts = sample_surface(mesh, n, DEFAULT_CLOUD_SEED);
            Ok(GroundTruth { points: pts, source: format!("sampled(seed={DEFAULT_CLOUD_SEED}, count={n})") })
        }
    }
}

/// Writes pretty JSON with a trailing newline, creating parent folders.
pub fn write_json(path: &Path, v: &Value) -> Result<()> {
    create_parent(path)?;
    let mut s = serde_json::to_string_pretty(v)?;
    s.push('\n');
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

/// Creates the folder an output file goes into, if missing.
pub fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(())
}
