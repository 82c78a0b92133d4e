//! Hand-built `inverse` cases whose answers follow from the definition (SPEC §4) and from the
//! documented traversal conventions (start cell, tie order z → y → x, inclusive range).

use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use objview_voxel::{key_of, observed_voxels, InverseCaster, VoxelKey, VoxelSet};

fn cam(pose: Pose) -> Camera {
    Camera::new(pose, Intrinsics::default())
}

fn keys_of(set: &VoxelSet, idx: &[u32]) -> Vec<VoxelKey> {
    idx.iter().map(|&i| set.key(i as usize)).collect()
}

#[test]
fn single_voxel_sees_itself() {
    for k in [[0, 0, 0], [-3, 7, 2], [10, -10, -40]] {
        let set = VoxelSet::from_keys(&[k], 0.02).unwrap();
        for d in [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-0.3, 0.5, -0.8]] {
            let o = observed_voxels(&set, &cam(Pose::from_direction(d, 3.0)));
            assert_eq!(o, vec![0], "key {k:?} dir {d:?}");
        }
    }
}

#[test]
fn front_voxel_hides_the_one_behind_on_the_axis() {
    // Camera on the +x axis through the voxels' centre line, looking along −x.
    let set = VoxelSet::from_keys(&[[0, 0, 0], [-5, 0, 0]], 0.02).unwrap();
    let c = cam(Pose { center: [3.0, 0.01, 0.01], look_at: [0.0, 0.01, 0.01], roll: 0.3 });
    assert_eq!(keys_of(&set, &observed_voxels(&set, &c)), vec![[0, 0, 0]]);
    // From the other side the other one is in front.
    let c = cam(Pose { center: [-3.0, 0.01, 0.01], look_at: [0.0, 0.01, 0.01], roll: 0.0 });
    assert_eq!(keys_of(&set, &observed_voxels(&set, &c)), vec![[-5, 0, 0]]);
}

#[test]
fn two_layer_slab_face_on_sees_the_front_layer() {
    // Layers x = 0 and x = 1, 20 × 20 voxels each (0.4 units wide), camera at x = 3: each
    // front voxel's pixel ray passes within ~0.004 of its centre where it enters the layer, and
    // every back voxel's ray crosses the front layer first.
    let mut keys = Vec::new();
    for x in 0..2 {
        for y in -10..10 {
            for z in -10..10 {
                keys.push([x, y, z]);
            }
        }
    }
    let set = VoxelSet::from_keys(&keys, 0.02).unwrap();
    let o = observed_voxels(&set, &cam(Pose::from_direction([1.0, 0.0, 0.0], 3.0)));
    let seen = keys_of(&set, &o);
    assert_eq!(seen.len(), 400);
    assert!(seen.iter().all(|k| k[0] == 1));
    assert_eq!(seen.len() as f64 / set.len() as f64, 0.5);
}

#[test]
fn voxels_outside_the_image_or_behind_are_not_counted() {
    // 45° field of view: a voxel at (0, 2, 0) seen from (3, 0, 0) is 33.7° off-axis.
    let set = VoxelSet::from_keys(&[[0, 0, 0], [0, 100, 0], [200, 0, 0]], 0.02).unwrap();
    let c = cam(Pose::from_direction([1.0, 0.0, 0.0], 3.0));
    assert_eq!(keys_of(&set, &observed_voxels(&set, &c)), vec![[0, 0, 0]]);
    // Turned around, only the voxel at x = 4 (now in front) is seen.
    let c = cam(Pose { center: [3.0, 0.0, 0.0], look_at: [5.0, 0.0, 0.0], roll: 0.0 });
    assert_eq!(keys_of(&set, &observed_voxels(&set, &c)), vec![[200, 0, 0]]);
}

#[test]
fn camera_inside_a_voxel_sees_only_that_voxel() {
    let centre = [0.905, -0.013, 0.4];
    let kc = key_of(centre, 0.02);
    let set = VoxelSet::from_keys(&[kc, [0, 0, 0], [2, 3, 1]], 0.02).unwrap();
    let c = cam(Pose { center: centre, look_at: [0.0; 3], roll: 0.0 });
    assert_eq!(keys_of(&set, &observed_voxels(&set, &c)), vec![kc]);
}

#[test]
fn edge_and_corner_ties_step_z_then_y_then_x() {
    // r = 1 and half-integer origins: every plane crossing time is exact and the diagonal
    // ray crosses x and y planes at identical times.
    let s = 0.5f64.sqrt();
    let o = [-2.5, -2.5, 0.5];
    let d = [s, s, 0.0];
    // Through the edge at (−2, −2): y steps first, so (−3, −2) is entered, (−2, −3) is not.
    let set = VoxelSet::from_keys(&[[-3, -2, 0], [-2, -3, 0]], 1.0).unwrap();
    let hit = InverseCaster::new(&set).first_hit(o, d).unwrap();
    assert_eq!(set.key(hit as usize), [-3, -2, 0]);
    let set = VoxelSet::from_keys(&[[-2, -3, 0], [0, 0, 0]], 1.0).unwrap();
    let hit = InverseCaster::new(&set).first_hit(o, d).unwrap();
    assert_eq!(set.key(hit as usize), [0, 0, 0]);
    // Through a corner: z, then y, then x.
    let t = 1.0 / 3.0f64.sqrt();
    let o = [-2.5, -2.5, -2.5];
    let d = [t, t, t];
    let set = VoxelSet::from_keys(&[[-2, -3, -3], [-3, -2, -2], [-3, -3, -2], [0, 0, 0]], 1.0).unwrap();
    let hit = InverseCaster::new(&set).first_hit(o, d).unwrap();
    assert_eq!(set.key(hit as usize), [-3, -3, -2]);
    let set = VoxelSet::from_keys(&[[-2, -3, -3], [-3, -2, -2], [0, 0, 0]], 1.0).unwrap();
    let hit = InverseCaster::new(&set).first_hit(o, d).unwrap();
    assert_eq!(set.key(hit as usize), [-3, -2, -2]);
    let set = VoxelSet::from_keys(&[[-2, -3, -3], [-2, -2, -3], [0, 0, 0]], 1.0).unwrap();
    let hit = InverseCaster::new(&set).first_hit(o, d).unwrap();
    assert_eq!(set.key(hit as usize), [0, 0, 0]);
}

#[test]
fn range_is_inclusive_and_measured_from_the_camera_centre() {
    // Voxel x ∈ [2, 3) at r = 1, ray from x = −0.5 along +x: entered at t = 2.5 exactly.
    let set = VoxelSet::from_keys(&[[2, 0, 0]], 1.0).unwrap();
    let (o, d) = ([-0.5, 0.5, 0.5], [1.0, 0.0, 0.0]);
    assert_eq!(InverseCaster::with_max_range(&set, 2.5).first_hit(o, d), Some(0));
    assert_eq!(InverseCaster::with_max_range(&set, 2.4999).first_hit(o, d), None);
    // Behind the camera: never.
    assert_eq!(InverseCaster::new(&set).first_hit(o, [-1.0, 0.0, 0.0]), None);
    // A ray parallel to a face, on the half-open boundary plane y = 1, belongs to the cells
    // above it (key y = 1): it misses the voxel at y = 0 and hits the one at y = 1.
    let set = VoxelSet::from_keys(&[[2, 0, 0]], 1.0).unwrap();
    assert_eq!(InverseCaster::new(&set).first_hit([-0.5, 1.0, 0.5], d), None);
    let set = VoxelSet::from_keys(&[[2, 1, 0]], 1.0).unwrap();
    assert_eq!(InverseCaster::new(&set).first_hit([-0.5, 1.0, 0.5], d), Some(0));
}

#[test]
fn empty_set_sees_nothing() {
    let set = VoxelSet::from_points(&[], 0.02).unwrap();
    assert!(observed_voxels(&set, &cam(Pose::from_direction([1.0, 2.0, 3.0], 3.0))).is_empty());
    assert_eq!(InverseCaster::new(&set).first_hit([0.0; 3], [1.0, 0.0, 0.0]), None);
}
