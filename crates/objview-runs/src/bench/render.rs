//! `objview bench render`: depth rendering with one thread and every thread on a built-in
//! object at several triangle counts ([`objview_render::bench`]), compared with Open3D's
//! `RaycastingScene` on the same mesh and poses where Python can import it, and O(v) per view
//! in both visibility modes ([`objview_voxel::bench`]).
//!
//! The peer runs `bench/peer_open3d.py` of the workspace this crate was built from, as a child
//! process in the same run, so that the ratio compares numbers taken on the same machine under
//! the same load.

use std::path::PathBuf;
use std::process::Command as Process;

use objview_geom::cloud::{cloud_count, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::pose::VIEW_RADIUS;
use objview_geom::synth::{self, SynthObject};
use objview_geom::{Mesh, Pose};
use objview_render::bench::RenderBenchResult;
use objview_views::ViewSet;
use objview_voxel::bench::VisibilityBench;
use serde_json::{json, Value};

use crate::RunError;

/// What `objview bench render` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderBenchSettings {
    /// Built-in object to tessellate at each size.
    pub object: String,
    /// Target triangle counts.
    pub sizes: Vec<usize>,
    /// Number of poses (the first N directions of tammes-128, radius 3; at least 1).
    pub poses: usize,
    /// Timed passes over the poses per size (at least 1 is run).
    pub repeats: usize,
    /// Triangle count of the visibility benchmark object (0 skips it).
    pub visibility_triangles: usize,
    /// Views rendered for the `mesh` visibility mode.
    pub mesh_views: usize,
    /// The Python interpreter of the Open3D peer; `None` skips the peer.
    pub python: Option<String>,
}

impl Default for RenderBenchSettings {
    /// The mug at ~10k, 100k and 1M triangles, 16 poses, 5 repeats; visibility on ~100k
    /// triangles with 16 `mesh` views; the peer through `python3`.
    fn default() -> RenderBenchSettings {
        RenderBenchSettings {
            object: "mug".into(),
            sizes: vec![10_000, 100_000, 1_000_000],
            poses: 16,
            repeats: 5,
            visibility_triangles: 100_000,
            mesh_views: 16,
            python: Some("python3".into()),
        }
    }
}

/// One size of [`RenderBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct RenderRow {
    /// objview's figures.
    pub render: RenderBenchResult,
    /// The peer's median per frame (ms), where it ran and reported one.
    pub open3d_median_ms: Option<f64>,
    /// The peer's median over objview's single-thread median.
    pub speedup_vs_open3d: Option<f64>,
    /// What the peer script wrote to stderr when it failed.
    pub peer_error: Option<String>,
}

/// The visibility part of [`RenderBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct VisibilityRow {
    /// Triangles of the object.
    pub triangles: usize,
    /// Points of its sampled ground-truth cloud (SPEC §1 count rule).
    pub gt_points: usize,
    /// The timings.
    pub bench: VisibilityBench,
}

/// The figures of [`RenderBench::run`].
#[derive(Debug, Clone, PartialEq)]
pub struct RenderBenchReport {
    /// What was measured.
    pub settings: RenderBenchSettings,
    /// Poses used.
    pub poses: usize,
    /// Threads of the pool.
    pub threads: usize,
    /// One row per size, in order.
    pub rows: Vec<RenderRow>,
    /// The visibility timings (`None`: skipped).
    pub visibility: Option<VisibilityRow>,
}

impl RenderBenchReport {
    /// The figures as `objview bench render --json` writes them.
    pub fn to_json(&self) -> Value {
        let rows: Vec<Value> = self
            .rows
            .iter()
            .map(|r| {
                json!({"render": r.render, "open3d_median_ms": r.open3d_median_ms,
                       "speedup_vs_open3d": r.speedup_vs_open3d})
            })
            .collect();
        let visibility = self.visibility.as_ref().map_or(Value::Null, |v| {
            json!({
                "triangles": v.triangles,
                "gt_points": v.gt_points,
                "surface_voxels": v.bench.voxels,
                "set_build_ms": v.bench.set_build_ms,
                "inverse_setup_ms": v.bench.caster_build_ms,
                "inverse_median_ms": v.bench.inverse_median_ms,
                "inverse_min_ms": v.bench.inverse_min_ms,
                "mesh_median_ms": v.bench.mesh_median_ms,
            })
        });
        let s = &self.settings;
        json!({
            "settings": crate::provenance::settings("bench render", json!({
                "object": s.object, "sizes": s.sizes, "poses": self.poses, "repeats": s.repeats,
                "threads": self.threads,
            })),
            "render": rows,
            "visibility": visibility,
        })
    }
}

/// A prepared `objview bench render`: the object, the poses and whether the peer is there.
#[derive(Debug)]
pub struct RenderBench {
    settings: RenderBenchSettings,
    object: SynthObject,
    poses: Vec<Pose>,
    peer_version: Option<String>,
}

impl RenderBench {
    /// Finds the object, takes the poses and asks the peer's interpreter for Open3D.
    pub fn new(settings: RenderBenchSettings) -> Result<RenderBench, RunError> {
        let object = synth::find(&settings.object).ok_or_else(|| {
            RunError::Invalid(format!(
                "--object: no built-in object named {:?} (see `objview objects list`)",
                settings.object
            ))
        })?;
        let poses: Vec<Pose> = ViewSet::resolve("tammes-128")?
            .poses(VIEW_RADIUS)
            .into_iter()
            .take(settings.poses.max(1))
            .collect();
        let peer_version = settings.python.as_deref().and_then(open3d_available);
        Ok(RenderBench { settings, object, poses, peer_version })
    }

    /// The settings.
    pub fn settings(&self) -> &RenderBenchSettings {
        &self.settings
    }

    /// Poses rendered per pass.
    pub fn poses(&self) -> usize {
        self.poses.len()
    }

    /// Open3D's version where the peer will run.
    pub fn peer_version(&self) -> Option<&str> {
        self.peer_version.as_deref()
    }

    /// Times every size (and the peer on it), then visibility; `on_row` sees each size's row as
    /// soon as it is measured. Fails, after that row, if the single-thread and parallel renders
    /// of a size differ.
    pub fn run(&self, on_row: &mut dyn FnMut(&RenderRow)) -> Result<RenderBenchReport, RunError> {
        let s = &self.settings;
        let repeats = s.repeats.max(1);
        let mut rows = Vec::new();
        for &size in &s.sizes {
            let mesh = self.object.build_with_triangles(size);
            let render = objview_render::bench::bench_render(&mesh, &self.poses, repeats);
            let (peer_ms, peer_error) = match (&self.peer_version, &s.python) {
                (Some(_), Some(python)) => match run_peer(python, &mesh, &self.poses, repeats)? {
                    Ok(ms) => (ms, None),
                    Err(e) => (None, Some(e)),
                },
                _ => (None, None),
            };
            let row = RenderRow {
                speedup_vs_open3d: peer_ms.map(|p| p / render.single.median_ms),
                open3d_median_ms: peer_ms,
                peer_error,
                render,
            };
            on_row(&row);
            if !row.render.identical {
                return Err(RunError::Invalid(format!(
                    "single-thread and parallel renders differ on {} triangles",
                    row.render.triangles
                )));
            }
            rows.push(row);
        }
        let visibility = if s.visibility_triangles > 0 {
            let mesh = self.object.build_with_triangles(s.visibility_triangles);
            let cloud = sample_surface(&mesh, cloud_count(mesh.surface_area()), DEFAULT_CLOUD_SEED);
            let bench = objview_voxel::bench::bench_visibility(
                &mesh,
                &cloud,
                objview_voxel::DEFAULT_RESOLUTION,
                &self.poses,
                repeats,
                s.mesh_views,
            )?;
            Some(VisibilityRow { triangles: mesh.num_triangles(), gt_points: cloud.len(), bench })
        } else {
            None
        };
        Ok(RenderBenchReport {
            settings: s.clone(),
            poses: self.poses.len(),
            threads: rayon::current_num_threads(),
            rows,
            visibility,
        })
    }
}

/// Open3D's version if `python -c "import open3d"` works.
pub fn open3d_available(python: &str) -> Option<String> {
    let out = Process::new(python).args(["-c", "import open3d; print(open3d.__version__)"]).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Runs `bench/peer_open3d.py` with `python` on `mesh` and `poses`: its median ms per frame
/// (`None` if it reported none), or, when the script failed, what it wrote to stderr.
pub fn run_peer(
    python: &str,
    mesh: &Mesh,
    poses: &[Pose],
    repeats: usize,
) -> Result<Result<Option<f64>, String>, RunError> {
    let script = peer_script()?;
    let dir = tempfile::tempdir().map_err(|e| RunError::io(std::env::temp_dir(), e))?;
    let mesh_path = dir.path().join("mesh.ply");
    objview_geom::write::write_ply(&mesh_path, mesh)?;
    let poses_path = dir.path().join("poses.txt");
    std::fs::write(&poses_path, poses_text(poses)).map_err(|e| RunError::io(&poses_path, e))?;
    let out = Process::new(python)
        .arg(&script)
        .arg(&mesh_path)
        .arg(&poses_path)
        .arg("--repeats")
        .arg(repeats.to_string())
        .output()
        .map_err(|e| RunError::io(&script, e))?;
    if !out.status.success() {
        return Ok(Err(String::from_utf8_lossy(&out.stderr).trim().to_string()));
    }
    let v: Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| RunError::Invalid(format!("parsing the output of {}: {e}", script.display())))?;
    Ok(Ok(v["median_ms"].as_f64()))
}

/// The peer's pose file: one pose a line, its 7 numbers in shortest round-trip form.
fn poses_text(poses: &[Pose]) -> String {
    poses
        .iter()
        .map(|p| p.to_array().iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(" ") + "\n")
        .collect()
}

/// `bench/peer_open3d.py` beside the workspace this crate was built from.
fn peer_script() -> Result<PathBuf, RunError> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../bench/peer_open3d.py");
    if !p.exists() {
        return Err(RunError::Invalid(format!("peer script {} not found", p.display())));
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_render_bench_without_peer_reports_every_size_in_order() {
        let settings = RenderBenchSettings {
            object: "cube".into(),
            sizes: vec![50, 200],
            poses: 2,
            repeats: 1,
            visibility_triangles: 0,
            mesh_views: 0,
            python: None,
        };
        let bench = RenderBench::new(settings).unwrap();
        assert_eq!((bench.poses(), bench.peer_version()), (2, None));
        let mut seen = 0;
        let r = bench.run(&mut |_| seen += 1).unwrap();
        assert_eq!(seen, 2);
        assert!(r.rows[0].render.triangles < r.rows[1].render.triangles);
        for row in &r.rows {
            assert!(row.render.identical);
            assert_eq!((row.open3d_median_ms, row.speedup_vs_open3d, &row.peer_error), (None, None, &None));
            let t = row.render.single;
            assert!(t.median_ms.is_finite() && t.median_ms <= t.p90_ms);
        }
        let v = r.to_json();
        assert_eq!(v["settings"]["command"], "bench render");
        assert_eq!(v["visibility"], Value::Null);
        assert_eq!(v["render"].as_array().map(Vec::len), Some(2));
    }

    #[test]
    fn the_peer_script_ships_with_the_workspace_and_poses_are_one_a_line() {
        assert!(peer_script().is_ok());
        let text = poses_text(&[Pose::from_direction([1.0, 0.0, 0.0], 3.0); 2]);
        assert_eq!(text.lines().count(), 2);
        assert!(text.lines().all(|l| l.split(' ').count() == 7));
    }
}
