//! `mesh` visibility on a closed cube, batch determinism, and agreement of the two modes where
//! geometry forces it.
//!
//! The cube is [−0.51, 0.51]³ at r = 0.02: its faces lie mid-cell (±25.5·r), so a rendered
//! point's key is insensitive to the renderer's f32 depth (error ~1.5e-7 at depth 2.5, against
//! a 0.01 margin to the nearest cell face), and the outermost cells of each face are 0.01 wide,
//! more than twice the ~0.004 pixel footprint at that distance, so every face cell receives
//! rendered points. The cloud is sampled uniformly on the faces (no point lies exactly on an
//! edge, probability 0). Hence the tolerance for "the six axis views cover S_gt" is zero.

use objview_geom::{Mesh, Pose};
use objview_render::{Camera, Intrinsics};
use objview_voxel::{
    bitset_count, bitset_to_indices, observed_voxels, observed_voxels_mesh, union, union_bitsets, Visibility,
    VisibilityMode, VoxelSet,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const H: f64 = 0.51;

fn cube() -> Mesh {
    let mut pos = Vec::new();
    for i in 0..8 {
        pos.push([
            if i & 1 == 0 { -H } else { H },
            if i & 2 == 0 { -H } else { H },
            if i & 4 == 0 { -H } else { H },
        ]);
    }
    let quads = [[0, 2, 6, 4], [1, 5, 7, 3], [0, 4, 5, 1], [2, 3, 7, 6], [0, 1, 3, 2], [4, 6, 7, 5]];
    let mut tris = Vec::new();
    for q in quads {
        tris.push([q[0], q[1], q[2]]);
        tris.push([q[0], q[2], q[3]]);
    }
    Mesh::new(pos, tris)
}

fn cube_cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|i| {
            let axis = i % 3;
            let side = if (i / 3) % 2 == 0 { -H } else { H };
            let mut p = [rng.gen_range(-H..H), rng.gen_range(-H..H), rng.gen_range(-H..H)];
            p[axis] = side;
            p
        })
        .collect()
}

fn cam(d: [f64; 3]) -> Camera {
    Camera::new(Pose::from_direction(d, 3.0), Intrinsics::default())
}

const AXES: [[f64; 3]; 6] =
    [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];

#[test]
fn cube_face_on_sees_exactly_the_facing_layer_in_both_modes() {
    let mesh = cube();
    let set = VoxelSet::from_points(&cube_cloud(300_000, 1), 0.02).unwrap();
    // The +x face layer: every S_gt voxel with key x = floor(0.51 / 0.02) = 25.
    let layer: Vec<u32> = (0..set.len() as u32).filter(|&i| set.key(i as usize)[0] == 25).collect();
    assert_eq!(layer.len(), 52 * 52);
    let c = cam([1.0, 0.0, 0.0]);
    assert_eq!(observed_voxels_mesh(&set, &mesh, &c), layer);
    // Inverse mode: each layer voxel's pixel ray enters the layer within 0.006 of its own
    // centre (half a pixel plus perspective), and every other voxel's ray crosses the layer.
    assert_eq!(observed_voxels(&set, &c), layer);
}

#[test]
fn six_axis_views_cover_the_closed_cube() {
    let mesh = cube();
    let set = VoxelSet::from_points(&cube_cloud(300_000, 2), 0.02).unwrap();
    let cams: Vec<Camera> = AXES.iter().map(|&d| cam(d)).collect();
    for mode in [VisibilityMode::Mesh, VisibilityMode::Inverse] {
        let vis = Visibility::new(&set, &mesh, mode);
        let bits = vis.observe_all_bitsets(&cams);
        let all = union_bitsets(&bits, set.len());
        assert_eq!(bitset_count(&all), set.len(), "{mode}");
        // Each view sees one face layer: 52² voxels.
        for b in &bits {
            assert_eq!(bitset_count(b), 52 * 52, "{mode}");
        }
    }
}

#[test]
fn batch_matches_single_views_in_order() {
    let mesh = cube();
    let set = VoxelSet::from_points(&cube_cloud(30_000, 3), 0.02).unwrap();
    let cams: Vec<Camera> = [[1.0, 2.0, 0.5], [-0.3, 0.1, 1.0], [0.0, 0.0, -1.0], [2.0, -1.0, -1.0]]
        .iter()
        .map(|&d| cam(d))
        .collect();
    for mode in [VisibilityMode::Inverse, VisibilityMode::Mesh] {
        let vis = Visibility::new(&set, &mesh, mode);
        let batch = vis.observe_all(&cams);
        for (c, b) in cams.iter().zip(&batch) {
            assert_eq!(&vis.observe(c), b);
        }
        let bits = vis.observe_all_bitsets(&cams);
        let u = union_bitsets(&bits, set.len());
        assert_eq!(bitset_to_indices(&u), union(&batch));
        // An oblique view of a cube sees two or three faces: more than one layer.
        assert!(batch[0].len() > 52 * 52 && batch[0].len() < set.len() / 2 + 52 * 4, "{mode}");
    }
}
