//! The optimized `inverse` path (`observe`: one ray per pixel, per-view depth bound, mirrored
//! walk) against the literal per-voxel walk (`observe_walk`) on realistic sets: a ~30k-voxel
//! sphere shell at r = 0.02 and S_gt of the built-in `mug` (~32k voxels, the benchmark object),
//! over many views — the tammes-128 directions at radius 3 and random closer cameras with
//! offset look-at points and rolls. The sets must be bit-identical.

mod common;
use common::{push_random_close, shell_keys};
use objview_geom::cloud::{cloud_count, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;
use objview_voxel::{InverseCaster, VoxelSet, DEFAULT_RESOLUTION};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The first `n` tammes-128 views at radius 3, then random cameras at radius 1.2–3 with a
/// random look-at near the origin and a random roll.
fn cameras(n_tammes: usize, n_random: usize, seed: u64) -> Vec<Camera> {
    let mut poses: Vec<Pose> =
        ViewSet::resolve("tammes-128").unwrap().poses(3.0).into_iter().take(n_tammes).collect();
    push_random_close(&mut poses, &mut ChaCha8Rng::seed_from_u64(seed), n_tammes + n_random);
    poses.into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect()
}

fn check(set: &VoxelSet, cams: &[Camera]) -> usize {
    let caster = InverseCaster::new(set);
    let mut total = 0;
    for cam in cams {
        let fast = caster.observe(cam);
        assert_eq!(fast, caster.observe_walk(cam), "camera {:?}", cam.pose);
        total += fast.len();
    }
    total
}

#[test]
fn thirty_thousand_voxel_shell_matches_the_walk() {
    let r = DEFAULT_RESOLUTION;
    let set = VoxelSet::from_keys(&shell_keys(r, 0.85, 1.5 * r), r).unwrap();
    assert!((25_000..40_000).contains(&set.len()), "{}", set.len());
    let cams = cameras(64, 32, 21);
    let total = check(&set, &cams);
    assert!(total > cams.len() * 1000, "{total}");
}

#[test]
fn mug_ground_truth_set_matches_the_walk() {
    let mesh = objview_geom::synth::find("mug").unwrap().build_with_triangles(20_000);
    let cloud = sample_surface(&mesh, cloud_count(mesh.surface_area()), DEFAULT_CLOUD_SEED);
    let set = VoxelSet::from_points(&cloud, DEFAULT_RESOLUTION).unwrap();
    assert!(set.len() > 20_000, "{}", set.len());
    let cams = cameras(48, 24, 22);
    let total = check(&set, &cams);
    assert!(total > cams.len() * 1000, "{total}");
}
