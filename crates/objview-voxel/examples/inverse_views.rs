//! `inverse` O(v) on the `objview bench render` visibility object (built-in `mug` at ~100k
//! triangles, SPEC §1 ground-truth cloud, r = 0.02, the first views of tammes-128 at radius 3),
//! one thread, for instruction counting (`valgrind --tool=callgrind`) and quick timings.
//!
//! `cargo run --release -p objview-voxel --example inverse_views [views] [repeats] [check]`
//!
//! With `check` = 1 every view's O(v) is also compared with the literal per-ray walk
//! (`observe_walk`). `views` = 0 runs the setup only (to subtract it from a count).

use objview_geom::cloud::{cloud_count, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::pose::VIEW_RADIUS;
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;
use objview_voxel::{InverseCaster, VoxelSet, DEFAULT_RESOLUTION};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let views: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(16);
    let repeats: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let check = args.get(3).is_some_and(|s| s == "1");
    let mesh = objview_geom::synth::find("mug").expect("mug").build_with_triangles(100_000);
    let cloud = sample_surface(&mesh, cloud_count(mesh.surface_area()), DEFAULT_CLOUD_SEED);
    let set = VoxelSet::from_points(&cloud, DEFAULT_RESOLUTION).expect("set");
    let caster = InverseCaster::new(&set);
    let cams: Vec<Camera> = ViewSet::resolve("tammes-128")
        .expect("tammes-128")
        .poses(VIEW_RADIUS)
        .into_iter()
        .take(views)
        .map(|p| Camera::new(p, Intrinsics::default()))
        .collect();
    let mut times = Vec::new();
    let mut total = 0usize;
    let mut bits = vec![0u64; set.len().div_ceil(64)];
    for _ in 0..repeats {
        for cam in &cams {
            bits.iter_mut().for_each(|w| *w = 0);
            let t = Instant::now();
            caster.observe_into(cam, &mut bits);
            times.push(t.elapsed().as_secs_f64() * 1e3);
            total += bits.iter().map(|w| w.count_ones() as usize).sum::<usize>();
        }
    }
    if check {
        for cam in &cams {
            assert_eq!(caster.observe(cam), caster.observe_walk(cam), "pose {:?}", cam.pose);
        }
    }
    times.sort_by(|a, b| a.total_cmp(b));
    println!(
        "triangles {} points {} |S_gt| {} views {} repeats {}: median {:.3} ms/view, min {:.3}, \
         mean |O(v)| {:.1}{}",
        mesh.num_triangles(),
        cloud.len(),
        set.len(),
        cams.len(),
        repeats,
        times.get(times.len() / 2).copied().unwrap_or(f64::NAN),
        times.first().copied().unwrap_or(f64::NAN),
        total as f64 / times.len().max(1) as f64,
        if check { " (checked against observe_walk)" } else { "" }
    );
}
