//! Per-view timing of O(v) in both visibility modes, one thread, for `objview bench render`
//! and `examples/inverse_views.rs`. Reports medians (robust to a busy machine).

use crate::set::VoxelSet;
use crate::visibility::{indices_of_points, InverseCaster};
use crate::VoxelError;
use objview_geom::{Mesh, Pose};
use objview_render::{Camera, Intrinsics};
use std::time::Instant;

/// Timings of [`bench_visibility`]; times in milliseconds per view.
#[derive(Debug, Clone, PartialEq)]
pub struct VisibilityBench {
    /// |S_gt|.
    pub voxels: usize,
    /// Median time to build S_gt from the cloud (ms, 5 builds).
    pub set_build_ms: f64,
    /// Time to build the `inverse` engine (distance field) once per object (ms).
    pub caster_build_ms: f64,
    /// Median `inverse` O(v) time per view (ms), over all poses and repeats.
    pub inverse_median_ms: f64,
    /// Minimum `inverse` time per view (ms).
    pub inverse_min_ms: f64,
    /// Mean |O(v)| in `inverse` mode.
    pub inverse_mean_observed: f64,
    /// Median `mesh` O(v) time per view (ms, render included), `None` when not run.
    pub mesh_median_ms: Option<f64>,
    /// Median time of the render alone within `mesh_median_ms` (ms).
    pub mesh_render_median_ms: Option<f64>,
    /// Mean |O(v)| in `mesh` mode.
    pub mesh_mean_observed: Option<f64>,
}

/// Times O(v) per view on one thread: S_gt of `cloud` at resolution `r`, every pose of `poses`
/// (object frame, SPEC §2 intrinsics), `repeats` passes for `inverse`; `mesh` mode renders
/// `mesh` for each of the first `mesh_views` poses once (0 skips it). Call it inside a
/// one-thread rayon pool for single-core numbers (the renderer may use rayon).
pub fn bench_visibility(
    mesh: &Mesh,
    cloud: &[[f64; 3]],
    r: f64,
    poses: &[Pose],
    repeats: usize,
    mesh_views: usize,
) -> Result<VisibilityBench, VoxelError> {
    let mut builds = Vec::new();
    let mut set = VoxelSet::from_points(&[], r)?;
    for _ in 0..5 {
        let t = Instant::now();
        set = VoxelSet::from_points(cloud, r)?;
        builds.push(ms(t));
    }
    let set_build_ms = objview_geom::stats::median(&mut builds);
    let t = Instant::now();
    let caster = InverseCaster::new(&set);
    let caster_build_ms = ms(t);
    let cameras: Vec<Camera> = poses.iter().map(|p| Camera::new(*p, Intrinsics::default())).collect();
    let mut times = Vec::new();
    let mut observed = 0usize;
    for rep in 0..repeats.max(1) {
        for cam in &cameras {
            let t = Instant::now();
            let o = caster.observe(cam);
            times.push(ms(t));
            if rep == 0 {
                observed += o.len();
            }
        }
    }
    let inverse_min_ms = times.iter().copied().fold(f64::INFINITY, f64::min);
    let inverse_median_ms = objview_geom::stats::median(&mut times);
    let inverse_mean_observed = observed as f64 / cameras.len().max(1) as f64;
    let (mut mesh_median_ms, mut mesh_render_median_ms, mut mesh_mean_observed) = (None, None, None);
    let nm = mesh_views.min(cameras.len());
    if nm > 0 {
        let (mut times, mut renders) = (Vec::new(), Vec::new());
        let mut observed = 0usize;
        for cam in &cameras[..nm] {
            let t = Instant::now();
            let frame = objview_render::render(mesh, cam);
            renders.push(ms(t));
            observed += indices_of_points(&set, &frame.observed_points()).len();
            times.push(ms(t));
        }
        mesh_median_ms = Some(objview_geom::stats::median(&mut times));
        mesh_render_median_ms = Some(objview_geom::stats::median(&mut renders));
        mesh_mean_observed = Some(observed as f64 / nm as f64);
    }
    Ok(VisibilityBench {
        voxels: set.len(),
        set_build_ms,
        caster_build_ms,
        inverse_median_ms,
        inverse_min_ms,
        inverse_mean_observed,
        mesh_median_ms,
        mesh_render_median_ms,
        mesh_mean_observed,
    })
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
