//! Voxel keys (SPEC §4): the integer cell of a point at resolution `r`.
//!
//! Cells are half-open: key `k` covers `[k·r, (k+1)·r)` on each axis, so a point exactly on a
//! cell face belongs to the cell on its positive side (`p = 0.02` → key 1 at `r = 0.02`) and
//! every point has exactly one key. The key is `floor(p / r)` computed in f64 with a true
//! division (not a multiplication by `1/r`, which rounds differently at cell faces).

/// Integer voxel coordinates `(i, j, k)` along the object-frame x, y, z axes.
pub type VoxelKey = [i32; 3];

/// SPEC §4 difficulty resolution r (object units, the unit ball has radius 1).
pub const DEFAULT_RESOLUTION: f64 = 0.02;

/// The key of object-frame point `p` at resolution `r` (> 0): `floor(p / r)` per axis
/// (half-open cells). Coordinates whose key does not fit in an `i32` (or NaN) saturate as Rust's
/// float-to-int cast does; callers validate inputs first (see `VoxelSet::from_points`).
#[inline]
pub fn key_of(p: [f64; 3], r: f64) -> VoxelKey {
    [floor_i32(p[0] / r), floor_i32(p[1] / r), floor_i32(p[2] / r)]
}

pub(crate) use objview_geom::num::floor_i32;

/// The object-frame centre `(k + ½)·r` of voxel `k` at resolution `r`.
#[inline]
pub fn center_of(k: VoxelKey, r: f64) -> [f64; 3] {
    [(k[0] as f64 + 0.5) * r, (k[1] as f64 + 0.5) * r, (k[2] as f64 + 0.5) * r]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_open_boundaries() {
        let r = DEFAULT_RESOLUTION;
        assert_eq!(key_of([0.02, 0.0, -0.02], r), [1, 0, -1]);
        assert_eq!(key_of([-1e-12, 1e-12, 0.019_999_999], r), [-1, 0, 0]);
        assert_eq!(key_of([0.04, -0.04, 1.0], r), [2, -2, 50]);
        assert_eq!(key_of([-1.0, 0.999_999, -0.999_999], r), [-50, 49, -50]);
    }

    #[test]
    fn centre_lies_in_its_cell() {
        let r = DEFAULT_RESOLUTION;
        for k in [[0, 0, 0], [-1, 5, -50], [49, -50, 3]] {
            let c = center_of(k, r);
            assert_eq!(key_of(c, r), k);
            assert!((c[0] - (k[0] as f64 * r + 0.01)).abs() < 1e-15);
        }
        assert_eq!(center_of([-1, 0, 2], 0.5), [-0.25, 0.25, 1.25]);
    }
}
