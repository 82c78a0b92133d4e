//! `FusedCloud::insert` alone, as the observable reference builds it: the built-in mug at ~100k
//! triangles (unit-normalized), every feasible tammes-360 view at the SPEC radius fused into one
//! cloud, timing only the insertions (renders excluded), for profiling and A/B runs:
//!
//! `cargo run --profile ci -p objview-episode --example fusion_views [-- REPEATS]`
//!
//! Prints the insertion time per view (median over views, and the total) per repeat, the
//! points per view, the runs of consecutive points in one block per view (what the insertion
//! buckets) and the final cloud size.

use std::path::Path;
use std::time::Instant;

use objview_episode::fusion::FusedCloud;
use objview_episode::grid::{block_runs, Domain};
use objview_geom::normalize::{normalize, Normalization};
use objview_render::{Camera, Frame, Intrinsics, Renderer};
use objview_views::ViewSet;

fn main() {
    let repeats: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3);
    let mesh = objview_geom::synth::build_with_triangles("mug", 100_000);
    let (mesh, _) = normalize(mesh, Normalization::Unit, Path::new("mug")).expect("normalize");
    let (lo, hi) = mesh.bounds().expect("a non-empty mesh");
    let domain = Domain::covering(0.005, lo, hi, 0.05);
    let mut renderer = Renderer::new();
    let views: Vec<Vec<[f64; 3]>> = ViewSet::resolve("tammes-360")
        .expect("tammes-360")
        .poses(objview_geom::pose::VIEW_RADIUS)
        .into_iter()
        .map(|pose| {
            let cam = Camera::new(pose, Intrinsics::default());
            let mut frame = Frame::empty(cam);
            renderer.render_into(&mesh, &cam, &mut frame);
            frame.observed_points()
        })
        .collect();
    let n: usize = views.iter().map(Vec::len).sum();
    let runs: usize = views
        .iter()
        .map(|pts| {
            let mut keys = Vec::new();
            domain.keys_into(pts, &mut keys);
            block_runs(&keys).count()
        })
        .sum();
    for r in 0..repeats {
        let mut fused = FusedCloud::new(domain.clone());
        let mut times: Vec<f64> = Vec::with_capacity(views.len());
        for pts in &views {
            let t = Instant::now();
            std::hint::black_box(fused.insert(pts));
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let total: f64 = times.iter().sum();
        times.sort_by(f64::total_cmp);
        println!(
            "repeat {r}: {} views, {:.0} points in {:.0} block runs per view, {} fused: insert median {:.3} ms/view, total {:.1} ms",
            views.len(),
            n as f64 / views.len() as f64,
            runs as f64 / views.len() as f64,
            fused.len(),
            times[times.len() / 2],
            total
        );
    }
}
