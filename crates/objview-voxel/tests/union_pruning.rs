//! `observe_union_into` (the union with ray pruning: rays that can only re-find voxels already
//! in the union are not cast) against the union of full views (`observe_into`, itself tested
//! against the literal walk and a brute force), view after view: the union must be the same
//! bit for bit after every view. Sets with sealed surfaces (cavities, nested shells), thin
//! and thick shells and random blobs; cameras far (tammes directions, the annotation's case),
//! close (radius 1.2–3, offset look-at, roll), exactly on axes and inside the grid box (where
//! pruning gives up); `Visibility::union_all` equal on one and two threads.

mod common;
use common::{push_random_close, shell_keys};
use objview_geom::cloud::{cloud_count, sample_surface, DEFAULT_CLOUD_SEED};
use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;
use objview_voxel::{
    bitset_count, InverseCaster, Visibility, VisibilityMode, VoxelKey, VoxelSet, DEFAULT_RESOLUTION,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// tammes-`n` at radius 3, the six axis directions at radius 2, random cameras at radius
/// 1.2–3 with an offset look-at and roll, and two inside the unit ball.
fn cameras(n: usize, n_random: usize, seed: u64) -> Vec<Camera> {
    let mut poses: Vec<Pose> = ViewSet::resolve(&format!("tammes-{n}")).unwrap().poses(3.0);
    for a in 0..3 {
        for s in [1.0, -1.0] {
            let mut d = [0.0; 3];
            d[a] = s;
            poses.push(Pose::from_direction(d, 2.0));
        }
    }
    push_random_close(&mut poses, &mut ChaCha8Rng::seed_from_u64(seed), n + 6 + n_random);
    poses.push(Pose { center: [0.05, 0.02, 0.01], look_at: [1.0, 0.3, 0.2], roll: 0.0 });
    poses.push(Pose { center: [0.3, -0.6, 0.2], look_at: [0.0, 0.0, 0.0], roll: 0.4 });
    // Every fourth camera gets an image whose size is no multiple of the mask's 8-pixel tiles,
    // an off-centre principal point and (every eighth) a mirrored x axis.
    let odd = |i: usize| Intrinsics {
        width: 517,
        height: 389,
        fx: if i % 8 == 3 { -430.0 } else { 430.0 },
        fy: 455.0,
        cx: 230.3,
        cy: 201.7,
        ..Intrinsics::default()
    };
    poses
        .into_iter()
        .enumerate()
        .map(|(i, p)| Camera::new(p, if i % 4 == 3 { odd(i) } else { Intrinsics::default() }))
        .collect()
}

/// Accumulates both unions view by view and compares them after each view; returns the final
/// union's size.
fn check(set: &VoxelSet, cams: &[Camera]) -> usize {
    let caster = InverseCaster::new(set);
    let words = set.len().div_ceil(64);
    let (mut full, mut pruned) = (vec![0u64; words], vec![0u64; words]);
    for (i, cam) in cams.iter().enumerate() {
        caster.observe_into(cam, &mut full);
        caster.observe_union_into(cam, &mut pruned);
        assert_eq!(pruned, full, "after view {i}, camera {:?}", cam.pose);
    }
    bitset_count(&full)
}

fn ground_truth_set(name: &str, triangles: usize) -> (objview_geom::Mesh, VoxelSet) {
    let mesh = objview_geom::synth::find(name).unwrap().build_with_triangles(triangles);
    let cloud = sample_surface(&mesh, cloud_count(mesh.surface_area()), DEFAULT_CLOUD_SEED);
    let set = VoxelSet::from_points(&cloud, DEFAULT_RESOLUTION).unwrap();
    (mesh, set)
}

#[test]
fn pruned_union_equals_full_union_on_objects_with_sealed_surfaces() {
    for (name, seed) in [("mug", 1), ("sealed-box", 2), ("ball-in-shell", 3), ("hollow-sphere", 4)] {
        let (_, set) = ground_truth_set(name, 20_000);
        let total = check(&set, &cameras(64, 24, seed));
        // Something is seen, and something (sealed) never is.
        assert!(total > set.len() / 4 && total < set.len(), "{name}: {total} of {}", set.len());
    }
}

#[test]
fn pruned_union_equals_full_union_on_shells_and_blobs() {
    let r = DEFAULT_RESOLUTION;
    // A thin and a thick shell (the thick one has sealed voxels between its faces).
    for (thickness, seed) in [(0.5 * r, 5), (3.5 * r, 6)] {
        let set = VoxelSet::from_keys(&shell_keys(r, 0.7, thickness), r).unwrap();
        check(&set, &cameras(32, 16, seed));
    }
    // Random blobs at a coarse resolution: voxels in every configuration of neighbours.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for half in [4, 8, 12] {
        let keys: Vec<VoxelKey> =
            (0..half * half * 6).map(|_| std::array::from_fn(|_| rng.gen_range(-half..half))).collect();
        let set = VoxelSet::from_keys(&keys, 0.6 / half as f64).unwrap();
        check(&set, &cameras(48, 24, 8 + half as u64));
    }
}

#[test]
fn union_all_equals_the_sequential_union_on_any_thread_count() {
    let (mesh, set) = ground_truth_set("mug", 20_000);
    let cams = cameras(128, 8, 9);
    let caster = InverseCaster::new(&set);
    let mut want = vec![0u64; set.len().div_ceil(64)];
    for cam in &cams {
        caster.observe_into(cam, &mut want);
    }
    for mode in [VisibilityMode::Inverse, VisibilityMode::Mesh] {
        let vis = Visibility::new(&set, &mesh, mode);
        let mut per_view = vec![0u64; want.len()];
        for cam in &cams {
            objview_voxel::union_into(&mut per_view, &vis.observe_bitset(cam));
        }
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let got = pool.install(|| vis.union_all(&cams));
            assert_eq!(got, per_view, "{mode}, {threads} threads");
        }
        if mode == VisibilityMode::Inverse {
            assert_eq!(per_view, want);
        }
    }
}

#[test]
fn a_voxel_entered_only_through_its_top_from_a_camera_one_cell_above_is_found() {
    // Voxel A = (0, 0, 0) with its ±x and +y neighbours occupied: its open faces are −y, +z
    // and −z. The camera sits in the cell layer just above it (k_z = 1), beyond the grid box
    // along +y, and the voxel F = (0, −8, −1) behind A casts a ray (through its pixel) that
    // passes over the +y neighbour and enters A through its top: across the plane z = r, the
    // lower plane of the camera's own cell layer, the boundary case of the facing rule (the
    // only face through which a walk can enter A here). Every voxel but A is already in the
    // union.
    let r = 0.1;
    let mut keys: Vec<VoxelKey> = vec![[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -8, -1]];
    keys.extend((0..12).map(|j| [6, -j, -4])); // enough voxels in the union to prune
    let set = VoxelSet::from_keys(&keys, r).unwrap();
    let [g0, dims] = [set.grid_origin()[1], set.grid_dims()[1] as i32];
    assert!(5 > g0 + dims + 1, "the camera's cell (y = 5) lies beyond the grid box");
    let a = set.index_of([0, 0, 0]).unwrap();
    let cam = Camera::new(
        Pose { center: [0.05, 0.55, 0.19], look_at: [0.05, 0.05, 0.1], roll: 0.0 },
        Intrinsics::default(),
    );
    let caster = InverseCaster::new(&set);
    let mut full = vec![0u64; set.len().div_ceil(64)];
    caster.observe_into(&cam, &mut full);
    assert_eq!(full[a >> 6] >> (a & 63) & 1, 1, "the camera sees A");
    let mut acc: Vec<u64> = vec![0u64; full.len()];
    for i in (0..set.len()).filter(|&i| i != a) {
        acc[i >> 6] |= 1 << (i & 63);
    }
    caster.observe_union_into(&cam, &mut acc);
    assert_eq!(acc[a >> 6] >> (a & 63) & 1, 1, "the pruned union finds A");
}

#[test]
fn a_camera_too_far_for_the_walk_planes_does_not_prune() {
    // At |o| = 2^60 cells the walk's plane offsets (g0 + g)·r − o round together, so its start
    // skips cells: here the ray along +x starts inside the sealed cavity x ∈ 128..=131 and
    // first enters (132, 1, 1), a voxel without an exterior face. Pruning must give up.
    let mut keys: Vec<VoxelKey> = Vec::new();
    for x in 0..=300 {
        for y in 0..=2 {
            for z in 0..=2 {
                if !((128..=131).contains(&x) && y == 1 && z == 1) {
                    keys.push([x, y, z]);
                }
            }
        }
    }
    let set = VoxelSet::from_keys(&keys, 1.0).unwrap();
    let far = (1u64 << 60) as f64;
    let cam = Camera::new(
        Pose { center: [-far, 1.5, 1.5], look_at: [0.0, 1.5, 1.5], roll: 0.0 },
        Intrinsics::from_fov(513, 513, 45.0, 45.0),
    );
    let caster = InverseCaster::with_max_range(&set, 1e19);
    let hidden = set.index_of([132, 1, 1]).unwrap();
    let mut full = vec![0u64; set.len().div_ceil(64)];
    caster.observe_into(&cam, &mut full);
    assert_eq!(full[hidden >> 6] >> (hidden & 63) & 1, 1, "the rounded walk enters the sealed voxel");
    let mut acc = vec![0u64; full.len()];
    for i in (0..set.len()).filter(|&i| i != hidden) {
        acc[i >> 6] |= 1 << (i & 63);
    }
    caster.observe_union_into(&cam, &mut acc);
    assert_eq!(acc[hidden >> 6] >> (hidden & 63) & 1, 1, "the pruned union finds it too");
}
