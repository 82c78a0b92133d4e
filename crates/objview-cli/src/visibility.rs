//! `objview visibility`: per-view observed surface voxels |O(v)| of one mesh for a view set
//! (SPEC §4), and the size of their union.

use anyhow::Result;
use clap::Parser;
use objview_geom::normalize::{load_normalized, Normalization};
use objview_geom::pose::VIEW_RADIUS;
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;
use objview_voxel::{Visibility, VisibilityMode, VoxelSet, DEFAULT_RESOLUTION};
use serde_json::json;
use std::path::PathBuf;

#[derive(Parser)]
pub struct Args {
    /// Mesh file (OBJ, PLY, STL, OFF, glTF, GLB).
    pub mesh: PathBuf,
    /// `unit`: centre the AABB and scale the farthest vertex to 1; `none`: already normalized.
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Ground-truth cloud (PCD, PLY, NPY, NPZ) in the mesh file's frame; with `--normalize
    /// unit` the mesh's normalization is applied to it. Default: sampled on the mesh (SPEC §1).
    #[arg(long)]
    pub gt_cloud: Option<PathBuf>,
    /// View directions: a file (one `x y z` a line) or a built-in `tammes-N`.
    #[arg(long)]
    pub views: String,
    /// `inverse` (ray walk from voxel centres, the reference's model) or `mesh` (rendered cloud).
    #[arg(long, default_value = "inverse")]
    pub mode: VisibilityMode,
    /// Voxel size r (normalized units).
    #[arg(long, default_value_t = DEFAULT_RESOLUTION, allow_hyphen_values = true)]
    pub resolution: f64,
    /// Output JSON.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    anyhow::ensure!(
        a.resolution.is_finite() && a.resolution > 0.0,
        "--resolution must be a positive number, got {}",
        a.resolution
    );
    let (mesh, transform) = load_normalized(&a.mesh, a.normalize)?;
    let gt = objview_geom::cloud::ground_truth(&mesh, &transform, a.gt_cloud.as_deref())?;
    let views = ViewSet::resolve(&a.views)?;
    let set = VoxelSet::from_points(&gt.points, a.resolution)?;
    let cameras: Vec<Camera> =
        views.poses(VIEW_RADIUS).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();
    let vis = Visibility::new(&set, &mesh, a.mode);
    let per_view = vis.observe_all(&cameras);
    let union = objview_voxel::union(&per_view);
    let out = json!({
        "surface_voxels": set.len(),
        "per_view": per_view.iter().map(|o| o.len()).collect::<Vec<_>>(),
        "union": union.len(),
        "settings": objview_runs::provenance::settings("visibility", json!({
            "mesh": a.mesh.display().to_string(),
            "normalize": a.normalize.to_string(),
            "gt_cloud": gt.source,
            "gt_points": gt.points.len(),
            "views": a.views,
            "num_views": views.len(),
            "view_radius": VIEW_RADIUS,
            "mode": a.mode.to_string(),
            "resolution": a.resolution,
        })),
    });
    crate::common::write_json(&a.out, &out)?;
    println!(
        "{}: surface_voxels={} union={} views={} -> {}",
        a.mesh.display(),
        set.len(),
        union.len(),
        views.len(),
        a.out.display()
    );
    Ok(())
}
