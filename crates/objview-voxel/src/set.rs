//! [`VoxelSet`]: a set of voxel keys at one resolution — S_gt of SPEC §4, the voxels of the
//! ground-truth surface cloud.
//!
//! Storage: the sorted unique keys (lexicographic `(x, y, z)` order, so the i-th key has index
//! `i`, the index used by per-view bitsets) and a dense occupancy bitmap over the keys'
//! bounding box grown by a one-voxel empty margin on every side. Bitmap rows run along z and
//! are padded to whole `u64` words, so row-major bit order equals key order and a per-word
//! prefix count (`rank`) turns a bit position into the key's index in O(1). The margin
//! guarantees that a ray entering the grid box first visits an empty cell, which the
//! visibility traversal relies on.
//!
//! Building is a single pass over the points (bounding box in f64, then one `key_of` per
//! point setting a bit); the sorted key list is read back from the bitmap, no sort needed.

use crate::key::{key_of, VoxelKey};
use crate::VoxelError;

/// Largest dense grid (cells, margins and row padding included) a set may allocate:
/// 2³⁰ bits = 128 MiB of bitmap. The unit ball at r = 0.02 needs about 1.3·10⁶.
pub const MAX_GRID_CELLS: usize = 1 << 30;

/// A set of voxel keys with O(1) membership and key → index lookups.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelSet {
    resolution: f64,
    keys: Vec<VoxelKey>,
    /// Key of grid cell (0, 0, 0): the smallest key minus the margin of 1.
    origin: [i32; 3],
    /// Grid size in cells along x, y, z (margins included).
    dims: [usize; 3],
    /// u64 words per z row.
    row_words: usize,
    bits: Vec<u64>,
    /// Number of set bits before each word.
    rank: Vec<u32>,
}

impl VoxelSet {
    /// S_gt of a point cloud: the set of `key_of(p, r)` over all points (object frame, r in
    /// object units). Errors on a bad resolution, a non-finite point, a point whose key does not
    /// fit in i32, or a bounding box needing more than [`MAX_GRID_CELLS`] cells. An empty cloud
    /// gives the empty set.
    pub fn from_points(points: &[[f64; 3]], r: f64) -> Result<VoxelSet, VoxelError> {
        check_resolution(r)?;
        if points.is_empty() {
            return Ok(VoxelSet::empty(r));
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut nan = false;
        for p in points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
                nan |= p[a].is_nan();
            }
        }
        if nan || lo.iter().chain(&hi).any(|x| !x.is_finite()) {
            let index = points.iter().position(|p| p.iter().any(|x| !x.is_finite())).unwrap_or(0);
            return Err(VoxelError::NonFinitePoint { index, point: points[index] });
        }
        if lo.iter().chain(&hi).any(|&x| !key_fits(x, r)) {
            let index = points.iter().position(|p| p.iter().any(|&x| !key_fits(x, r))).unwrap_or(0);
            return Err(VoxelError::KeyOutOfRange { index, point: points[index], resolution: r });
        }
        // floor(x / r) is monotone in x, so the key box is the key of the point box.
        let (kmin, kmax) = (key_of(lo, r), key_of(hi, r));
        let mut set = VoxelSet::with_box(r, kmin, kmax)?;
        let inv = 1.0 / r;
        let mut own = std::mem::take(&mut set.bits);
        let fill = |bits: &mut [u64], chunk: &[[f64; 3]]| {
            for p in chunk {
                let k = [fast_key(p[0], r, inv), fast_key(p[1], r, inv), fast_key(p[2], r, inv)];
                let b = set.bit_of_key_unchecked(k);
                bits[b >> 6] |= 1u64 << (b & 63);
            }
        };
        let bits = if points.len() >= PARALLEL_POINTS {
            use rayon::prelude::*;
            let words = own.len();
            points
                // One chunk (one bitmap) per thread.
                .par_chunks(points.len().div_ceil(rayon::current_num_threads()).max(PARALLEL_POINTS / 2))
                .fold(
                    || vec![0u64; words],
                    |mut acc, chunk| {
                        fill(&mut acc, chunk);
                        acc
                    },
                )
                .reduce(
                    || vec![0u64; words],
                    |mut a, b| {
                        a.iter_mut().zip(&b).for_each(|(x, y)| *x |= y);
                        a
                    },
                )
        } else {
            fill(&mut own, points);
            own
        };
        set.bits = bits;
        set.finish();
        Ok(set)
    }

    /// The set of the given keys (any order, duplicates allowed) at resolution `r`. Keys must
    /// leave a margin of 2 to the i32 range.
    pub fn from_keys(keys: &[VoxelKey], r: f64) -> Result<VoxelSet, VoxelError> {
        check_resolution(r)?;
        if keys.is_empty() {
            return Ok(VoxelSet::empty(r));
        }
        let mut kmin = [i32::MAX; 3];
        let mut kmax = [i32::MIN; 3];
        for k in keys {
            for a in 0..3 {
                kmin[a] = kmin[a].min(k[a]);
                kmax[a] = kmax[a].max(k[a]);
            }
        }
        if kmin.iter().chain(&kmax).any(|&k| k <= i32::MIN + 2 || k >= i32::MAX - 2) {
            let index = keys.iter().position(|k| k.iter().any(|&c| c <= i32::MIN + 2 || c >= i32::MAX - 2));
            let index = index.unwrap_or(0);
            let c = crate::key::center_of(keys[index], r);
            return Err(VoxelError::KeyOutOfRange { index, point: c, resolution: r });
        }
        let mut set = VoxelSet::with_box(r, kmin, kmax)?;
        for k in keys {
            let b = set.bit_of_key_unchecked(*k);
            set.bits[b >> 6] |= 1u64 << (b & 63);
        }
        set.finish();
        Ok(set)
    }

    fn empty(r: f64) -> VoxelSet {
        VoxelSet {
            resolution: r,
            keys: Vec::new(),
            origin: [0; 3],
            dims: [0; 3],
            row_words: 0,
            bits: Vec::new(),
            rank: Vec::new(),
        }
    }

    /// An all-empty grid covering keys `kmin..=kmax` plus the margin.
    fn with_box(r: f64, kmin: [i32; 3], kmax: [i32; 3]) -> Result<VoxelSet, VoxelError> {
        let dims: [usize; 3] = std::array::from_fn(|a| (kmax[a] as i64 - kmin[a] as i64 + 3) as usize);
        let row_words = dims[2].div_ceil(64);
        let cells = dims[0].checked_mul(dims[1]).and_then(|c| c.checked_mul(row_words * 64));
        match cells {
            Some(c) if c <= MAX_GRID_CELLS => {}
            _ => return Err(VoxelError::GridTooLarge { dims, limit: MAX_GRID_CELLS }),
        }
        let words = dims[0] * dims[1] * row_words;
        Ok(VoxelSet {
            resolution: r,
            keys: Vec::new(),
            origin: [kmin[0] - 1, kmin[1] - 1, kmin[2] - 1],
            dims,
            row_words,
            bits: vec![0; words],
            rank: Vec::new(),
        })
    }

    /// Fills `rank` and `keys` from the bitmap.
    fn finish(&mut self) {
        let mut rank = Vec::with_capacity(self.bits.len());
        let mut n = 0u32;
        for &w in &self.bits {
            rank.push(n);
            n += w.count_ones();
        }
        let mut keys = Vec::with_capacity(n as usize);
        let row_bits = self.row_words * 64;
        for (wi, &w) in self.bits.iter().enumerate() {
            let mut w = w;
            while w != 0 {
                let b = wi * 64 + w.trailing_zeros() as usize;
                w &= w - 1;
                let z = b % row_bits;
                let xy = b / row_bits;
                let (x, y) = (xy / self.dims[1], xy % self.dims[1]);
                keys.push([self.origin[0] + x as i32, self.origin[1] + y as i32, self.origin[2] + z as i32]);
            }
        }
        self.rank = rank;
        self.keys = keys;
    }

    /// Bit position of a key known to lie inside the grid.
    #[inline]
    fn bit_of_key_unchecked(&self, k: VoxelKey) -> usize {
        let g = [
            (k[0] - self.origin[0]) as usize,
            (k[1] - self.origin[1]) as usize,
            (k[2] - self.origin[2]) as usize,
        ];
        self.bit_of_cell(g)
    }

    /// Bit position of grid cell `g` (grid coordinates, `g < dims`).
    #[inline]
    pub(crate) fn bit_of_cell(&self, g: [usize; 3]) -> usize {
        (g[0] * self.dims[1] + g[1]) * (self.row_words * 64) + g[2]
    }

    /// Grid coordinates of `k`, `None` outside the grid.
    #[inline]
    fn cell_of_key(&self, k: VoxelKey) -> Option<[usize; 3]> {
        let mut g = [0usize; 3];
        for a in 0..3 {
            let d = k[a] as i64 - self.origin[a] as i64;
            if d < 0 || d >= self.dims[a] as i64 {
                return None;
            }
            g[a] = d as usize;
        }
        Some(g)
    }

    /// Whether the bit at position `b` is set.
    #[inline]
    pub(crate) fn bit(&self, b: usize) -> bool {
        (self.bits[b >> 6] >> (b & 63)) & 1 != 0
    }

    /// The index (rank) of the key at set bit `b`.
    #[inline]
    pub(crate) fn index_of_bit(&self, b: usize) -> u32 {
        let w = b >> 6;
        self.rank[w] + (self.bits[w] & ((1u64 << (b & 63)) - 1)).count_ones()
    }

    /// Resolution r (object units per voxel).
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether the set has no voxels.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The keys in sorted (lexicographic x, y, z) order; position = index.
    pub fn keys(&self) -> &[VoxelKey] {
        &self.keys
    }

    /// The key with index `i`.
    pub fn key(&self, i: usize) -> VoxelKey {
        self.keys[i]
    }

    /// Iterates the keys in sorted order.
    pub fn iter(&self) -> std::slice::Iter<'_, VoxelKey> {
        self.keys.iter()
    }

    /// Whether `k` is in the set (O(1)).
    #[inline]
    pub fn contains(&self, k: VoxelKey) -> bool {
        self.cell_of_key(k).is_some_and(|g| self.bit(self.bit_of_cell(g)))
    }

    /// The index of `k` in sorted order (O(1)), `None` if absent.
    #[inline]
    pub fn index_of(&self, k: VoxelKey) -> Option<usize> {
        let g = self.cell_of_key(k)?;
        let b = self.bit_of_cell(g);
        self.bit(b).then(|| self.index_of_bit(b) as usize)
    }

    /// Key of grid cell (0, 0, 0) (the smallest key of the set minus 1 on each axis).
    pub fn grid_origin(&self) -> [i32; 3] {
        self.origin
    }

    /// Grid size in cells along x, y, z, the one-voxel margins included (zeros when empty).
    pub fn grid_dims(&self) -> [usize; 3] {
        self.dims
    }

    /// u64 words per bitmap row along z.
    pub(crate) fn row_words(&self) -> usize {
        self.row_words
    }

    /// The raw occupancy bitmap (rows along z, padded to whole words).
    pub(crate) fn bitmap(&self) -> &[u64] {
        &self.bits
    }
}

impl<'a> IntoIterator for &'a VoxelSet {
    type Item = &'a VoxelKey;
    type IntoIter = std::slice::Iter<'a, VoxelKey>;
    fn into_iter(self) -> Self::IntoIter {
        self.keys.iter()
    }
}

fn check_resolution(r: f64) -> Result<(), VoxelError> {
    if r.is_finite() && r > 0.0 {
        Ok(())
    } else {
        Err(VoxelError::BadResolution(r))
    }
}

/// Point count from which `from_points` fills the bitmap on several threads.
const PARALLEL_POINTS: usize = 1 << 17;

/// `floor(x / r)` for a coordinate whose key is known to fit in i32, exactly as `key_of`
/// computes it, but mostly without the division: `x·(1/r)` differs from `x / r` by a few ulps,
/// which can only change the floor when the quotient is within ~1e-9 (relative) of an integer;
/// those rare cases take the exact division.
#[inline]
fn fast_key(x: f64, r: f64, inv: f64) -> i32 {
    let q = x * inv;
    let t = q as i64;
    let f = if (t as f64) > q { t - 1 } else { t };
    let frac = q - f as f64;
    let eps = 1e-9 * q.abs().max(1.0);
    if frac < eps || frac > 1.0 - eps {
        crate::key::floor_i32(x / r)
    } else {
        f as i32
    }
}

/// Whether `floor(x / r)` leaves a margin of 2 to the i32 range.
fn key_fits(x: f64, r: f64) -> bool {
    let q = (x / r).floor();
    q > (i32::MIN + 2) as f64 && q < (i32::MAX - 2) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn keys_sorted_unique_and_indexed() {
        let pts = [
            [0.011, 0.0, 0.0],
            [0.019, 0.001, 0.0199],
            [-0.5, 0.3, 0.9],
            [0.02, 0.0, 0.0],
            [0.3, -0.7, -0.1],
            [-0.5, 0.3, 0.9],
        ];
        let s = VoxelSet::from_points(&pts, 0.02).unwrap();
        let expect: BTreeSet<VoxelKey> = pts.iter().map(|&p| key_of(p, 0.02)).collect();
        let expect: Vec<VoxelKey> = expect.into_iter().collect();
        assert_eq!(s.keys(), &expect[..]);
        assert_eq!(s.len(), 4);
        for (i, k) in expect.iter().enumerate() {
            assert!(s.contains(*k));
            assert_eq!(s.index_of(*k), Some(i));
        }
        assert!(!s.contains([1, 1, 0]));
        assert_eq!(s.index_of([1000, 0, 0]), None);
        assert_eq!(s.index_of([i32::MIN, i32::MAX, 0]), None);
    }

    #[test]
    fn fast_key_matches_key_of() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for r in [0.02, 0.005, 0.1, 1.0 / 3.0] {
            let inv = 1.0 / r;
            for i in -2000..2000 {
                // Exact multiples of r and their neighbours, where x·(1/r) and x / r can differ.
                let x = i as f64 * r;
                for y in [x, f64::from_bits(x.to_bits() + 1), f64::from_bits(x.to_bits().wrapping_sub(1))] {
                    assert_eq!(fast_key(y, r, inv), key_of([y, 0.0, 0.0], r)[0], "{y} {r}");
                }
            }
            for _ in 0..100_000 {
                let x: f64 = rng.gen_range(-1.5..1.5);
                assert_eq!(fast_key(x, r, inv), key_of([x, 0.0, 0.0], r)[0], "{x} {r}");
            }
        }
    }

    #[test]
    fn parallel_build_matches_sequential_keys() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
        let pts: Vec<[f64; 3]> = (0..PARALLEL_POINTS * 2 + 17)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-1.0..1.0)))
            .collect();
        let s = VoxelSet::from_points(&pts, 0.05).unwrap();
        let want: BTreeSet<VoxelKey> = pts.iter().map(|&p| key_of(p, 0.05)).collect();
        assert_eq!(s.keys(), &want.into_iter().collect::<Vec<_>>()[..]);
    }

    #[test]
    fn errors_and_empty() {
        assert!(VoxelSet::from_points(&[], 0.02).unwrap().is_empty());
        assert_eq!(VoxelSet::from_points(&[[0.0; 3]], 0.0), Err(VoxelError::BadResolution(0.0)));
        let e = VoxelSet::from_points(&[[0.0; 3], [f64::NAN, 0.0, 0.0]], 0.02).unwrap_err();
        assert!(matches!(e, VoxelError::NonFinitePoint { index: 1, .. }), "{e:?}");
        let e = VoxelSet::from_points(&[[0.0; 3], [0.0, 1e12, 0.0]], 0.02).unwrap_err();
        assert!(matches!(e, VoxelError::KeyOutOfRange { index: 1, .. }), "{e:?}");
        let e = VoxelSet::from_points(&[[-1e4, -1e4, -1e4], [1e4, 1e4, 1e4]], 0.02).unwrap_err();
        assert!(matches!(e, VoxelError::GridTooLarge { .. }), "{e:?}");
    }

    #[test]
    fn from_keys_matches_from_points() {
        let keys = [[3, -2, 70], [-64, 0, 0], [3, -2, 69], [0, 0, 0], [3, -2, 70]];
        let a = VoxelSet::from_keys(&keys, 0.5).unwrap();
        let pts: Vec<[f64; 3]> = keys.iter().map(|&k| crate::key::center_of(k, 0.5)).collect();
        let b = VoxelSet::from_points(&pts, 0.5).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.keys(), &[[-64, 0, 0], [0, 0, 0], [3, -2, 69], [3, -2, 70]]);
        assert_eq!(a.grid_origin(), [-65, -3, -1]);
        assert_eq!(a.grid_dims(), [70, 5, 73]);
    }
}
