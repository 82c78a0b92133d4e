//! `objview render`: one view of one mesh — depth as NPY, and optionally the observed point
//! cloud (PLY), a colour-mapped depth preview (PNG) and an RGB image (PNG).

use anyhow::{Context, Result};
use clap::Parser;
use objview_geom::normalize::{load_normalized, Normalization};
use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use std::path::PathBuf;

#[derive(Parser)]
pub struct Args {
    /// Mesh file (OBJ, PLY, STL, OFF, glTF, GLB).
    pub mesh: PathBuf,
    /// Camera pose `cx,cy,cz,lx,ly,lz,roll` in the normalized object frame (roll in radians).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_pose)]
    pub pose: Pose,
    /// `unit`: centre the AABB and scale the farthest vertex to 1; `none`: already normalized.
    #[arg(long, default_value = "unit")]
    pub normalize: Normalization,
    /// Output depth: 512×512 float32 NPY, row = image v, camera-frame z, 0 = no hit. The
    /// settings that produced it are written beside it as `<DEPTH>.json`.
    #[arg(long)]
    pub depth: PathBuf,
    /// Output observed point cloud (object frame), binary PLY.
    #[arg(long)]
    pub points: Option<PathBuf>,
    /// Output colour-mapped depth preview, PNG.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// Output RGB image (mesh colours/texture, or shading), PNG.
    #[arg(long)]
    pub rgb: Option<PathBuf>,
}

pub fn parse_pose(s: &str) -> Result<Pose, String> {
    Pose::parse(s)
}

pub fn run(a: Args) -> Result<()> {
    let (mesh, transform) = load_normalized(&a.mesh, a.normalize)?;
    for out in [Some(&a.depth), a.points.as_ref(), a.preview.as_ref(), a.rgb.as_ref()].into_iter().flatten() {
        crate::common::create_parent(out)?;
    }
    let cam = Camera::new(a.pose, Intrinsics::default());
    let frame = objview_render::render(&mesh, &cam);
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    objview_geom::npy::write_npy_f32(&a.depth, &[h, w], &frame.depth)?;
    if let Some(p) = &a.points {
        objview_geom::cloud::write_ply_points(p, &frame.observed_points())?;
    }
    if let Some(p) = &a.preview {
        let img = objview_render::preview::depth_preview(&frame);
        objview_render::preview::save_png(&img, p)?;
    }
    if let Some(p) = &a.rgb {
        let rgb = objview_render::rgb::render_rgb(&mesh, &frame);
        objview_render::preview::save_rgb_png(w as u32, h as u32, &rgb, p)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    // Provenance of every file written above (NPY cannot carry it): `<depth>.json`.
    let k = cam.intrinsics;
    let meta = objview_runs::provenance::settings(
        "render",
        serde_json::json!({
            "mesh": a.mesh.display().to_string(),
            "normalize": a.normalize.to_string(),
            "normalization": {"center": transform.center, "scale": transform.scale},
            "pose": a.pose.to_array(),
            "intrinsics": k,
            "depth": {"file": a.depth.display().to_string(), "dtype": "float32", "shape": [h, w],
                      "value": "camera-frame z of the first hit through each pixel centre; 0 = no hit"},
            "points": a.points.as_ref().map(|p| p.display().to_string()),
            "preview": a.preview.as_ref().map(|p| p.display().to_string()),
            "rgb": a.rgb.as_ref().map(|p| p.display().to_string()),
            "hits": frame.num_hits(),
        }),
    );
    let mut meta_path = a.depth.clone().into_os_string();
    meta_path.push(".json");
    crate::common::write_json(std::path::Path::new(&meta_path), &meta)?;
    println!(
        "{}: {} of {} pixels hit; depth -> {}",
        a.mesh.display(),
        frame.num_hits(),
        w * h,
        a.depth.display()
    );
    Ok(())
}
