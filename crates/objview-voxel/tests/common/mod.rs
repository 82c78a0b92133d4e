//! Voxel sets shared by the integration tests.

use objview_voxel::{center_of, VoxelKey};

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
