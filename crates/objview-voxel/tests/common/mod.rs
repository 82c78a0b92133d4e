//! Voxel sets shared by the integration tests.

use objview_geom::Pose;
use objview_voxel::{center_of, VoxelKey};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Keys of the voxels (size `r`) whose centres lie within `thickness / 2` of the sphere of
/// `radius` about the origin: a closed spherical shell.
pub fn shell_keys(r: f64, radius: f64, thickness: f64) -> Vec<VoxelKey> {
    let n = (radius / r).ceil() as i32 + 1;
    let mut out = Vec::new();
    for x in -n..n {
        for y in -n..n {
            for z in -n..n {
                let c = center_of([x, y, z], r);
                let d = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                if (d - radius).abs() <= thickness / 2.0 {
                    out.push([x, y, z]);
                }
            }
        }
    }
    out
}

/// Appends random close cameras to `poses` until it holds `until`: centres at radius 1.2–3 in a
/// random direction, looking at a random point within 0.3 of the origin (per axis), with a
/// random roll. (Not every test file that includes this module uses it.)
#[allow(dead_code)]
pub fn push_random_close(poses: &mut Vec<Pose>, rng: &mut ChaCha8Rng, until: usize) {
    while poses.len() < until {
        let v: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if !(0.1..=1.0).contains(&len) {
            continue;
        }
        let rad = rng.gen_range(1.2..3.0);
        poses.push(Pose {
            center: std::array::from_fn(|k| rad * v[k] / len),
            look_at: std::array::from_fn(|_| rng.gen_range(-0.3..0.3)),
            roll: rng.gen_range(-3.2..3.2),
        });
    }
}
