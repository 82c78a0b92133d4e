//! The sparse voxel grid shared by fusion and the coverage metrics: fine voxels of size `h`
//! (0.005, SPEC §5 fusion) with key floor(p / h), grouped into dense 8×8×8 blocks that are
//! allocated on first use inside a fixed domain (the object's bounding box plus a margin).
//! Lookups are two array reads, which keeps per-step fusion and nearest-neighbour updates cheap.

use crate::fusion::FusedCloud;
use objview_geom::num::floor_i32;

/// Fine voxels per block edge, as a shift (8 = 1 << 3).
pub const BLOCK_SHIFT: i32 = 3;
/// Fine voxels per block edge.
pub const BLOCK: i32 = 1 << BLOCK_SHIFT;
/// Fine voxels per block.
pub const BLOCK_CELLS: usize = (BLOCK * BLOCK * BLOCK) as usize;
/// "No entry".
pub const NONE: u32 = u32::MAX;

/// The block domain: block keys `lo ..= lo + dims − 1` per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Domain {
    /// Fine voxel size (normalized object units).
    pub h: f64,
    /// Smallest block key per axis.
    pub lo: [i32; 3],
    /// Blocks per axis.
    pub dims: [i32; 3],
}

impl Domain {
    /// The domain covering the box `[min, max]` (object frame) plus `margin` on every side.
    pub fn covering(h: f64, min: [f64; 3], max: [f64; 3], margin: f64) -> Domain {
        let mut lo = [0; 3];
        let mut dims = [0; 3];
        for a in 0..3 {
            let k0 = floor_i32((min[a] - margin) / h) >> BLOCK_SHIFT;
            let k1 = floor_i32((max[a] + margin) / h) >> BLOCK_SHIFT;
            lo[a] = k0;
            dims[a] = k1 - k0 + 1;
        }
        Domain { h, lo, dims }
    }

    /// Number of blocks.
    pub fn num_blocks(&self) -> usize {
        (self.dims[0] * self.dims[1] * self.dims[2]) as usize
    }

    /// Fine voxel key of a point: `floor(p / h)` per axis (true division; the libm-free floor).
    #[inline]
    pub fn key(&self, p: [f64; 3]) -> [i32; 3] {
        [floor_i32(p[0] / self.h), floor_i32(p[1] / self.h), floor_i32(p[2] / self.h)]
    }

    /// [`Domain::key`] of every point of `points`, into `out` (cleared first): the same keys,
    /// computed as one flat loop over the coordinates that the compiler vectorizes (a division,
    /// a floor and a saturating conversion per coordinate; on x86-64 with AVX2, selected at run
    /// time, the floor is one instruction instead of [`floor_i32`]'s truncate-and-correct).
    pub fn keys_into(&self, points: &[[f64; 3]], out: &mut Vec<[i32; 3]>) {
        out.clear();
        out.resize(points.len(), [0; 3]);
        let (src, dst) = (points.as_flattened(), out.as_flattened_mut());
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has the feature `keys_avx2` is compiled for.
            return unsafe { keys_avx2(self.h, src, dst) };
        }
        keys_body(self.h, src, dst)
    }

    /// The smallest and largest fine voxel keys of the domain's blocks (inclusive, per axis):
    /// every key whose block is inside the domain lies in this box.
    pub fn key_box(&self) -> ([i32; 3], [i32; 3]) {
        let lo = self.lo.map(|b| b << BLOCK_SHIFT);
        let hi = std::array::from_fn(|a| ((self.lo[a] + self.dims[a]) << BLOCK_SHIFT) - 1);
        (lo, hi)
    }

    /// Index of the block with block key `b`, if inside the domain.
    #[inline]
    pub fn block_index(&self, b: [i32; 3]) -> Option<usize> {
        let x = b[0] - self.lo[0];
        let y = b[1] - self.lo[1];
        let z = b[2] - self.lo[2];
        if x < 0 || y < 0 || z < 0 || x >= self.dims[0] || y >= self.dims[1] || z >= self.dims[2] {
            return None;
        }
        Some((x + self.dims[0] * (y + self.dims[1] * z)) as usize)
    }

    /// Block key of block index `i`.
    pub fn block_key(&self, i: usize) -> [i32; 3] {
        let i = i as i32;
        let x = i % self.dims[0];
        let y = (i / self.dims[0]) % self.dims[1];
        let z = i / (self.dims[0] * self.dims[1]);
        [x + self.lo[0], y + self.lo[1], z + self.lo[2]]
    }

    /// The box of the cube with key `c` on the grid of cubes `cells` fine voxels wide (a block:
    /// `BLOCK`; a superblock: `BLOCK << SUPER_SHIFT`).
    #[inline]
    pub fn cube_box(&self, c: [i32; 3], cells: i32) -> Aabb {
        let e = self.h * cells as f64;
        let lo = [c[0] as f64 * e, c[1] as f64 * e, c[2] as f64 * e];
        Aabb { lo, hi: [lo[0] + e, lo[1] + e, lo[2] + e] }
    }
}

/// [`Domain::keys_into`] compiled for AVX2 (FMA is not enabled, and the compiler never
/// contracts without it: the same IEEE division, hence the same quotients).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn keys_avx2(h: f64, src: &[f64], dst: &mut [i32]) {
    keys_body(h, src, dst)
}

/// The body of [`Domain::keys_into`]: `floor(x / h)` per coordinate, saturating (NaN → 0), as
/// [`floor_i32`] computes it.
#[inline(always)]
fn keys_body(h: f64, src: &[f64], dst: &mut [i32]) {
    for (k, &x) in dst.iter_mut().zip(src) {
        // `as i32` of the floor, written so that it vectorizes: NaN → 0, then the saturation
        // as a clamp to i32's range (integers, so a clamped floor stays an integer).
        let f = (x / h).floor();
        let f = if f.is_nan() { 0.0 } else { f.clamp(i32::MIN as f64, i32::MAX as f64) };
        // SAFETY: `f` is an integer within i32's range.
        *k = unsafe { f.to_int_unchecked::<i32>() };
    }
}

/// Block key of a fine key (floor division by 8).
#[inline]
pub fn block_of(k: [i32; 3]) -> [i32; 3] {
    [k[0] >> BLOCK_SHIFT, k[1] >> BLOCK_SHIFT, k[2] >> BLOCK_SHIFT]
}

/// The maximal runs of consecutive keys in one block, as `(block key, first, end)` (indices
/// into `keys`), in input order. Pixels along an image row mostly stay in one block, so a
/// view's points make few runs (~16k for ~78k points on the mug): the fusion buckets runs by
/// block, not points.
pub fn block_runs(keys: &[[i32; 3]]) -> impl Iterator<Item = ([i32; 3], usize, usize)> + '_ {
    let mut first = 0;
    std::iter::from_fn(move || {
        let bk = block_of(*keys.get(first)?);
        let end = first + 1 + keys[first + 1..].iter().take_while(|&&k| block_of(k) == bk).count();
        let run = (bk, first, end);
        first = end;
        Some(run)
    })
}

/// Index of fine key `k` inside its block (x fastest).
#[inline]
pub fn local_index(k: [i32; 3]) -> usize {
    let m = BLOCK - 1;
    ((k[0] & m) + BLOCK * ((k[1] & m) + BLOCK * (k[2] & m))) as usize
}

/// The coordinates (x, y, z; each 0..[`BLOCK`]) inside its block of the fine voxel with local
/// index `li`: the inverse of [`local_index`].
#[inline]
pub fn local_coords(li: usize) -> [usize; 3] {
    let (m, s) = (BLOCK as usize - 1, BLOCK_SHIFT as usize);
    [li & m, li >> s & m, li >> (2 * s)]
}

/// Squared Euclidean distance.
#[inline]
pub fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// A point set bucketed on the block grid, as [`nearest_in`] searches it. Points are named by
/// a `u32` index (a fused slot, a target position).
pub trait Bucketed {
    /// The grid.
    fn domain(&self) -> &Domain;
    /// Calls `f(index, position)` for every point in fine voxel `k`.
    fn for_cell<F: FnMut(u32, [f64; 3])>(&self, k: [i32; 3], f: F);
    /// Calls `f(index, position)` for every point in the block with block key `b`, if the block
    /// holds points.
    fn for_block<F: FnMut(u32, [f64; 3])>(&self, b: [i32; 3], f: F);
    /// The occupied blocks grouped by superblock (for searches that reach far).
    fn supergrid(&self) -> &SuperGrid;
    /// Calls `f(index, position)` for every point in the 27 fine voxels within one voxel of
    /// `k` (each voxel once; the order is the store's): runs along x inside a block
    /// (`runs_in_box`: one block lookup per run, an empty block skips its whole run).
    fn for_cells_around<F: FnMut(u32, [f64; 3])>(&self, k: [i32; 3], f: F) {
        self.for_cells_in_box(k.map(|x| x - 1), k.map(|x| x + 1), f)
    }
    /// Calls `f(index, position)` for every point in the fine voxels of the box `lo..=hi`
    /// (voxel keys, per axis; each voxel once, the store's order), by x-runs as
    /// [`Bucketed::for_cells_around`].
    fn for_cells_in_box<F: FnMut(u32, [f64; 3])>(&self, lo: [i32; 3], hi: [i32; 3], f: F);
    /// The position of point `index`.
    fn position(&self, index: u32) -> [f64; 3];
    /// Lowers `best` (`(d², index)`; ties → the smaller index; a `NONE` index is a bound, not a
    /// point) over every point of the block with block key `b`: what showing them one by one to
    /// the scans' comparison gives. Stores with contiguous block points override it with
    /// `lower_best_over`.
    fn lower_best_in_block(&self, b: [i32; 3], p: [f64; 3], best: &mut (f64, u32)) {
        self.for_block(b, |i, q| lower_best(best, dist2(p, q), i));
    }
    /// The slab of the block with block key `b` and box `aabb` (its box in
    /// [`Bucketed::supergrid`]) when the store keeps one per block, made at most once while the
    /// block is unchanged; `None` (the default): the search makes its own. Any valid slab gives
    /// the same answers: it only bounds.
    fn block_slab(&self, _b: [i32; 3], _aabb: &Aabb) -> Option<Slab> {
        None
    }
}

/// The scans' comparison: point `i` at squared distance `d` replaces `best` (`(d², index)`)
/// when it is closer, or as close with a smaller index — a `NONE` index is a bound, not a
/// point, so a point exactly at it does not count.
#[inline(always)]
fn lower_best(best: &mut (f64, u32), d: f64, i: u32) {
    if d < best.0 || (d == best.0 && best.1 != NONE && i < best.1) {
        *best = (d, i);
    }
}

/// [`Bucketed::lower_best_in_block`] over the points `pts` named `index(j)`, in two passes: the
/// smallest d² over all of them (branch-free; a minimum does not depend on the order it is
/// taken in), and only where that can change `best`, the smallest index among the points at it.
/// The result is the smallest (d², index) of `best` and the points — what the one-by-one
/// comparison keeps, whatever the order — so the same bits.
///
/// On x86-64 with AVX2 (selected at run time) both passes take four points per step: their
/// twelve coordinates in three loads, transposed into x, y and z vectors by two shuffles each,
/// then the same subtractions, products and sums as [`dist2`] in the same order (no FMA), so the
/// same distances; the portable passes run two lanes of SSE2 on the interleaved coordinates, and
/// the second pass one point at a time.
#[inline]
pub(crate) fn lower_best_over(
    pts: &[[f64; 3]],
    index: impl Fn(usize) -> u32,
    p: [f64; 3],
    best: &mut (f64, u32),
) {
    #[cfg(target_arch = "x86_64")]
    let avx2 = pts.len() >= 4 && std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    // SAFETY: `avx2` is set only where the CPU has the feature.
    unsafe { lower_best_over_on(avx2, pts, index, p, best) }
}

/// [`lower_best_over`] with the AVX2 passes (`avx2`) or the portable ones.
///
/// # Safety
/// With `avx2` set, the CPU must have AVX2.
#[inline]
unsafe fn lower_best_over_on(
    avx2: bool,
    pts: &[[f64; 3]],
    index: impl Fn(usize) -> u32,
    p: [f64; 3],
    best: &mut (f64, u32),
) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 when `avx2` is set (this function's contract).
    let min = if avx2 { unsafe { min_d2_avx2(pts, p) } } else { min_d2(pts, p) };
    #[cfg(not(target_arch = "x86_64"))]
    let min = {
        let _ = avx2;
        min_d2(pts, p)
    };
    // Nothing below the bound, or only ties with a bound that is not a point.
    if min > best.0 || (min == best.0 && best.1 == NONE) {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    // SAFETY: as above.
    let at = if avx2 { unsafe { first_at_avx2(pts, &index, p, min) } } else { first_at(pts, &index, p, min) };
    #[cfg(not(target_arch = "x86_64"))]
    let at = first_at(pts, &index, p, min);
    if min < best.0 || at < best.1 {
        *best = (min, at);
    }
}

/// The smallest [`dist2`] from `p` to the points (∞ for none), in four lanes that the compiler
/// vectorizes (two to an SSE2 vector, on the interleaved coordinates).
#[inline]
fn min_d2(pts: &[[f64; 3]], p: [f64; 3]) -> f64 {
    const L: usize = 4;
    let mut m = [f64::INFINITY; L];
    let chunks = pts.chunks_exact(L);
    let rest = chunks.remainder();
    for c in chunks {
        for l in 0..L {
            let d = dist2(p, c[l]);
            m[l] = if d < m[l] { d } else { m[l] };
        }
    }
    let mut min = m.iter().fold(f64::INFINITY, |a, &b| if b < a { b } else { a });
    for &q in rest {
        let d = dist2(p, q);
        min = if d < min { d } else { min };
    }
    min
}

/// The smallest `index(j)` of the points at d² `min` from `p` (`u32::MAX` for none).
#[inline]
fn first_at(pts: &[[f64; 3]], index: impl Fn(usize) -> u32, p: [f64; 3], min: f64) -> u32 {
    let mut at = u32::MAX;
    for (j, &q) in pts.iter().enumerate() {
        if dist2(p, q) == min {
            at = at.min(index(j));
        }
    }
    at
}

/// The squared distances from `(px, py, pz)` to the four points whose coordinates start at `f`
/// (twelve f64, point-major), as [`dist2`] computes them: ((dx² + dy²) + dz²), dx = p − q.
///
/// # Safety
/// `f` must point to twelve readable f64.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn dist2_x4(
    f: *const f64,
    px: std::arch::x86_64::__m256d,
    py: std::arch::x86_64::__m256d,
    pz: std::arch::x86_64::__m256d,
) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    // v0 = [x0 y0 | z0 x1], v1 = [y1 z1 | x2 y2], v2 = [z2 x3 | y3 z3] (128-bit halves).
    let (v0, v1, v2) = unsafe { (_mm256_loadu_pd(f), _mm256_loadu_pd(f.add(4)), _mm256_loadu_pd(f.add(8))) };
    let a = _mm256_permute2f128_pd::<0x30>(v0, v1); // [x0 y0 | x2 y2]
    let b = _mm256_permute2f128_pd::<0x21>(v0, v2); // [z0 x1 | z2 x3]
    let c = _mm256_permute2f128_pd::<0x30>(v1, v2); // [y1 z1 | y3 z3]
    let x = _mm256_shuffle_pd::<0b1010>(a, b);
    let y = _mm256_shuffle_pd::<0b0101>(a, c);
    let z = _mm256_shuffle_pd::<0b1010>(b, c);
    let (dx, dy, dz) = (_mm256_sub_pd(px, x), _mm256_sub_pd(py, y), _mm256_sub_pd(pz, z));
    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz))
}

/// [`min_d2`] compiled for AVX2: the whole groups of four points by [`dist2_x4`], the rest as
/// [`min_d2`] takes them.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn min_d2_avx2(pts: &[[f64; 3]], p: [f64; 3]) -> f64 {
    use std::arch::x86_64::*;
    let (px, py, pz) = (_mm256_set1_pd(p[0]), _mm256_set1_pd(p[1]), _mm256_set1_pd(p[2]));
    let full = pts.len() / 4 * 4;
    let flat = pts.as_flattened().as_ptr();
    let mut m = _mm256_set1_pd(f64::INFINITY);
    for c in (0..full).step_by(4) {
        // SAFETY: points c..c + 4 lie within `pts`.
        let d = unsafe { dist2_x4(flat.add(3 * c), px, py, pz) };
        // `minpd(d, m)` is `d < m ? d : m`, the portable pass's comparison.
        m = _mm256_min_pd(d, m);
    }
    let mut lanes = [0.0; 4];
    // SAFETY: `lanes` holds four f64.
    unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), m) };
    let rest = min_d2(&pts[full..], p);
    lanes.iter().fold(rest, |a, &b| if b < a { b } else { a })
}

/// [`first_at`] compiled for AVX2: the whole groups of four points by [`dist2_x4`], the rest as
/// [`first_at`] takes them.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn first_at_avx2(pts: &[[f64; 3]], index: impl Fn(usize) -> u32, p: [f64; 3], min: f64) -> u32 {
    use std::arch::x86_64::*;
    let (px, py, pz) = (_mm256_set1_pd(p[0]), _mm256_set1_pd(p[1]), _mm256_set1_pd(p[2]));
    let full = pts.len() / 4 * 4;
    let flat = pts.as_flattened().as_ptr();
    let target = _mm256_set1_pd(min);
    let mut at = first_at(&pts[full..], |j| index(full + j), p, min);
    for c in (0..full).step_by(4) {
        // SAFETY: points c..c + 4 lie within `pts`.
        let d = unsafe { dist2_x4(flat.add(3 * c), px, py, pz) };
        let mut hits = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(d, target)) as u32;
        while hits != 0 {
            at = at.min(index(c + hits.trailing_zeros() as usize));
            hits &= hits - 1;
        }
    }
    at
}

/// Test helper: for 3,000 random keys in [−24, 24)³, what `for_cells_around(k)` shows must be
/// what 27 `for_cell` calls show (as sorted `(index, position bits)`); returns how many points
/// were shown in all.
#[cfg(test)]
pub(crate) fn assert_around_matches_cells<S: Bucketed>(set: &S, seed: u64) -> usize {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let bits = |q: [f64; 3]| q.map(f64::to_bits);
    let mut shown = 0;
    for _ in 0..3000 {
        let k = [0; 3].map(|_: i32| rng.gen_range(-24..24));
        let mut fast = Vec::new();
        set.for_cells_around(k, |i, q| fast.push((i, bits(q))));
        let mut each = Vec::new();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    set.for_cell([k[0] + dx, k[1] + dy, k[2] + dz], |i, q| each.push((i, bits(q))));
                }
            }
        }
        fast.sort_unstable();
        each.sort_unstable();
        assert_eq!(fast, each, "k {k:?}");
        shown += fast.len();
    }
    shown
}

/// Calls `f(block index, first key, len)` for the fine voxels of the box `lo..=hi` (voxel
/// keys, per axis): per (z, y) row, the x-runs that stay inside one block (`len` voxels from
/// the first, consecutive local indices), skipping runs whose block lies outside `domain`.
#[inline]
pub(crate) fn runs_in_box(
    domain: &Domain,
    lo: [i32; 3],
    hi: [i32; 3],
    mut f: impl FnMut(usize, [i32; 3], usize),
) {
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            let mut x = lo[0];
            while x <= hi[0] {
                // The last x of x's block (two's complement: also right for negative x).
                let end = (x | (BLOCK - 1)).min(hi[0]);
                let kk = [x, y, z];
                if let Some(b) = domain.block_index(block_of(kk)) {
                    f(b, kk, (end - x + 1) as usize);
                }
                x = end + 1;
            }
        }
    }
}

/// Blocks per superblock edge, as a shift (4 = 1 << 2): a superblock is 32 fine voxels wide.
pub const SUPER_SHIFT: i32 = 2;

/// The occupied blocks of a point set grouped by superblock (4×4×4 blocks): the coarse level
/// that keeps a nearest search cheap when the answer is far (a point deep inside an object
/// whose nearest fused point is on the observed outside), where rings of blocks would visit
/// thousands of empty blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct SuperGrid {
    lo: [i32; 3],
    dims: [i32; 3],
    /// Per superblock (x fastest): its occupied blocks with the boxes of their points.
    lists: Vec<Vec<([i32; 3], Aabb)>>,
}

/// An axis-aligned box around a set of points (empty: lo = +∞, hi = −∞).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Per-axis minimum (object frame, normalized units).
    pub lo: [f64; 3],
    /// Per-axis maximum (object frame, normalized units).
    pub hi: [f64; 3],
}

impl Aabb {
    /// The empty box.
    pub const EMPTY: Aabb = Aabb { lo: [f64::INFINITY; 3], hi: [f64::NEG_INFINITY; 3] };

    /// Grows the box to contain `p`.
    #[inline]
    pub fn grow(&mut self, p: [f64; 3]) {
        for (a, &x) in p.iter().enumerate() {
            self.lo[a] = self.lo[a].min(x);
            self.hi[a] = self.hi[a].max(x);
        }
    }

    /// Squared distance from `p` to the box (0 inside; ∞ for the empty box).
    #[inline]
    pub fn dist2(&self, p: [f64; 3]) -> f64 {
        if self.lo[0] > self.hi[0] {
            return f64::INFINITY;
        }
        let mut d2 = 0.0;
        for (a, &x) in p.iter().enumerate() {
            let d = (self.lo[a] - x).max(x - self.hi[a]).max(0.0);
            d2 += d * d;
        }
        d2
    }
}

/// Where a block's entry lives in a [`SuperGrid`] (for [`SuperGrid::grow`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SuperHandle(u32, u32);

impl SuperGrid {
    /// An empty grid over `domain`.
    pub fn new(domain: &Domain) -> SuperGrid {
        let mut lo = [0; 3];
        let mut dims = [0; 3];
        for a in 0..3 {
            lo[a] = domain.lo[a] >> SUPER_SHIFT;
            dims[a] = ((domain.lo[a] + domain.dims[a] - 1) >> SUPER_SHIFT) - lo[a] + 1;
        }
        SuperGrid { lo, dims, lists: vec![Vec::new(); (dims[0] * dims[1] * dims[2]) as usize] }
    }

    /// Records an occupied block with an empty box (call once per block, when it first holds
    /// a point; then [`SuperGrid::grow`] its box with every position its points take). `None`
    /// outside the grid.
    pub fn add_block(&mut self, b: [i32; 3]) -> Option<SuperHandle> {
        let s = [b[0] >> SUPER_SHIFT, b[1] >> SUPER_SHIFT, b[2] >> SUPER_SHIFT];
        let i = self.index(s)?;
        self.lists[i].push((b, Aabb::EMPTY));
        Some(SuperHandle(i as u32, (self.lists[i].len() - 1) as u32))
    }

    /// Grows the box of a block's points to contain `p`. A box never shrinks, so it stays a
    /// valid bound while points move inside their voxels.
    #[inline]
    pub fn grow(&mut self, h: SuperHandle, p: [f64; 3]) {
        self.lists[h.0 as usize][h.1 as usize].1.grow(p);
    }

    /// Asks the cache for the entry of the block with handle `h` ahead of a
    /// [`SuperGrid::grow_box`].
    #[inline]
    pub(crate) fn prefetch(&self, h: SuperHandle) {
        if let Some(e) = self.lists.get(h.0 as usize).and_then(|l| l.get(h.1 as usize)) {
            crate::prefetch::item(e);
        }
    }

    /// Grows the box of the block with handle `h` by the box `b` (nothing if it is empty):
    /// the box [`SuperGrid::grow`] by each of `b`'s points would give.
    pub fn grow_box(&mut self, h: SuperHandle, b: &Aabb) {
        let e = &mut self.lists[h.0 as usize][h.1 as usize].1;
        for a in 0..3 {
            e.lo[a] = e.lo[a].min(b.lo[a]);
            e.hi[a] = e.hi[a].max(b.hi[a]);
        }
    }

    fn index(&self, s: [i32; 3]) -> Option<usize> {
        let x = s[0] - self.lo[0];
        let y = s[1] - self.lo[1];
        let z = s[2] - self.lo[2];
        if x < 0 || y < 0 || z < 0 || x >= self.dims[0] || y >= self.dims[1] || z >= self.dims[2] {
            return None;
        }
        Some((x + self.dims[0] * (y + self.dims[1] * z)) as usize)
    }

    /// The occupied blocks of superblock key `s` with their boxes (empty outside the grid).
    pub(crate) fn blocks(&self, s: [i32; 3]) -> &[([i32; 3], Aabb)] {
        self.index(s).map_or(&[], |i| &self.lists[i])
    }

    /// Largest Chebyshev ring (in superblocks) around `s` that still meets the grid.
    fn max_ring(&self, s: [i32; 3]) -> i32 {
        (0..3).map(|a| (s[a] - self.lo[a]).max(self.lo[a] + self.dims[a] - 1 - s[a])).max().unwrap_or(0)
    }
}

/// Margin (object units) taken off the gap between a point and a neighbouring voxel's face in
/// [`scan_around`]: a point filed in voxel k (floor(q / h) = k, a rounded division) may lie an
/// ulp or so outside the voxel's exact box [k·h, (k + 1)·h], and k·h itself is rounded; 1e-9
/// is millions of ulps at the metric domains' scale (coordinates of order 1) and far below h.
const FACE_MARGIN: f64 = 1e-9;

/// [`nearest_in`] and [`nearest_in_block`] scan the second layer of voxels around a point
/// ([`scan_ring2`]) when its best after the first is at most this many h² (an answer within 3h
/// may well lie in it; farther ones — unseen surfaces — go straight to the block search).
const RING2_TRY: f64 = 9.0;

/// Lowers `best` (`(d², index)`, ties → the smaller index; a `NONE` index is a bound, not a
/// point) to the nearest point of `set` to `p` among the 27 fine voxels around `k` (p's own
/// voxel): the same answer as showing every point of those voxels to the comparison, without
/// looking at the voxels that cannot hold anything closer. p's voxel is scanned first; then,
/// row by row (y, z neighbours), a neighbouring voxel only if the gap from `p` to its faces
/// (less [`FACE_MARGIN`], so never more than the true distance of any of its points) is at
/// most the best so far. A skipped voxel's points all lie strictly farther than the best at
/// that moment, which only decreases, so they could neither win nor tie.
#[inline]
pub(crate) fn scan_around<S: Bucketed>(set: &S, p: [f64; 3], k: [i32; 3], best: &mut (f64, u32)) {
    let consider = |best: &mut (f64, u32), i: u32, q: [f64; 3]| lower_best(best, dist2(p, q), i);
    let h = set.domain().h;
    // Squared gaps to the lower and upper neighbour voxel per axis (0 when p is within the
    // margin of that face).
    let mut gap = [[0.0f64; 2]; 3];
    for a in 0..3 {
        let lo = (p[a] - k[a] as f64 * h - FACE_MARGIN).max(0.0);
        let hi = ((k[a] + 1) as f64 * h - p[a] - FACE_MARGIN).max(0.0);
        gap[a] = [lo * lo, hi * hi];
    }
    set.for_cells_in_box(k, k, |i, q| consider(best, i, q));
    for dz in [0i32, -1, 1] {
        let gz = if dz == 0 { 0.0 } else { gap[2][(dz > 0) as usize] };
        if gz > best.0 {
            continue;
        }
        for dy in [0i32, -1, 1] {
            let gyz = gz + if dy == 0 { 0.0 } else { gap[1][(dy > 0) as usize] };
            if gyz > best.0 {
                continue;
            }
            let (y, z) = (k[1] + dy, k[2] + dz);
            if dy == 0 && dz == 0 {
                // p's own row: its voxel is done; the x neighbours one by one.
                for dx in [-1, 1] {
                    if gyz + gap[0][(dx > 0) as usize] <= best.0 {
                        let x = k[0] + dx;
                        set.for_cells_in_box([x, y, z], [x, y, z], |i, q| consider(best, i, q));
                    }
                }
                continue;
            }
            let x0 = if gyz + gap[0][0] <= best.0 { k[0] - 1 } else { k[0] };
            let x1 = if gyz + gap[0][1] <= best.0 { k[0] + 1 } else { k[0] };
            set.for_cells_in_box([x0, y, z], [x1, y, z], |i, q| consider(best, i, q));
        }
    }
}

/// The next layer after [`scan_around`]: lowers `best` over the fine voxels at Chebyshev
/// distance 2 from `k` (p's voxel) that could hold something closer — per voxel, the sum over
/// the axes of the squared gap from `p` to it (the neighbour face's gap, plus one voxel width
/// for the outer layer, less [`FACE_MARGIN`]) must not exceed the best so far — and returns
/// whether that settles the search: true when `best` is at most the squared gap from `p` to
/// the faces of the 5×5×5 voxels around `k` (less the margin), which every other point lies
/// beyond. Meant for answers just beyond h — a fused point whose nearest ground-truth sample
/// lies past its 27 voxels, the sample being sparser than the fusion grid — which would
/// otherwise take the whole-block search of [`nearest_in_block`]. Skipped voxels only ever held
/// points strictly farther than the best at that moment, so the answer (ties included) is that
/// of showing every point of the 125 voxels to the comparison.
pub(crate) fn scan_ring2<S: Bucketed>(set: &S, p: [f64; 3], k: [i32; 3], best: &mut (f64, u32)) -> bool {
    let consider = |best: &mut (f64, u32), i: u32, q: [f64; 3]| lower_best(best, dist2(p, q), i);
    let h = set.domain().h;
    // Per axis, the squared gap from p to the voxel at offset −2..=2 (0 for its own layer),
    // and the gap to the outside of the 5×5×5 voxels.
    let mut gap = [[0.0f64; 5]; 3];
    let mut outer = f64::INFINITY;
    for a in 0..3 {
        // The gap to the voxel face at plane index `plane`, which lies below p or above it.
        let g = |plane: i32, below: bool| {
            let x = if below { p[a] - plane as f64 * h } else { plane as f64 * h - p[a] };
            (x - FACE_MARGIN).max(0.0)
        };
        let (l1, l2, l3) = (g(k[a], true), g(k[a] - 1, true), g(k[a] - 2, true));
        let (u1, u2, u3) = (g(k[a] + 1, false), g(k[a] + 2, false), g(k[a] + 3, false));
        gap[a] = [l2 * l2, l1 * l1, 0.0, u1 * u1, u2 * u2];
        outer = outer.min(l3).min(u3);
    }
    // Inner layers first (their gaps are smaller), the outer ones last.
    const ORDER: [i32; 5] = [0, -1, 1, -2, 2];
    for dz in ORDER {
        let gz = gap[2][(dz + 2) as usize];
        if gz > best.0 {
            continue;
        }
        for dy in ORDER {
            let gyz = gz + gap[1][(dy + 2) as usize];
            if gyz > best.0 {
                continue;
            }
            let (y, z) = (k[1] + dy, k[2] + dz);
            if dy.abs() < 2 && dz.abs() < 2 {
                // A row through the 27 voxels: only its two outer voxels are in the layer.
                for dx in [-2, 2] {
                    if gyz + gap[0][(dx + 2) as usize] <= best.0 {
                        let x = k[0] + dx;
                        set.for_cells_in_box([x, y, z], [x, y, z], |i, q| consider(best, i, q));
                    }
                }
                continue;
            }
            // A row of the outer layer: its voxels as far out as the gaps allow (they grow
            // away from p's column).
            let (mut x0, mut x1) = (0, 0);
            while x0 > -2 && gyz + gap[0][(x0 + 1) as usize] <= best.0 {
                x0 -= 1;
            }
            while x1 < 2 && gyz + gap[0][(x1 + 3) as usize] <= best.0 {
                x1 += 1;
            }
            // (p's own column, gap 0, is always admitted: gyz ≤ best above.)
            set.for_cells_in_box([k[0] + x0, y, z], [k[0] + x1, y, z], |i, q| consider(best, i, q));
        }
    }
    best.0 <= outer * outer
}

/// The nearest point of `set` to `p` with squared distance below `bound2` (exact; ties →
/// the smaller index): `(d², index)`, or `(bound2, NONE)` when there is none. The 27 fine voxels
/// around p first (anything outside them is ≥ h away), then, for a best within 3h, the next
/// layer of voxels (`scan_ring2`), then rings of superblocks (after ring R
/// everything unseen is ≥ R·E away, E the superblock edge), visiting the occupied blocks of each
/// superblock that could hold something closer, pruned by their boxes.
pub fn nearest_in<S: Bucketed>(set: &S, p: [f64; 3], bound2: f64) -> (f64, u32) {
    let mut best = (bound2, NONE);
    let domain = set.domain();
    let h = domain.h;
    let k = domain.key(p);
    // Any order: the comparison keeps the smallest (d², index) of what it is shown.
    scan_around(set, p, k, &mut best);
    if best.0 <= h * h || (best.0 <= RING2_TRY * h * h && scan_ring2(set, p, k, &mut best)) {
        return best;
    }
    let grid = set.supergrid();
    let e_super = h * (BLOCK << SUPER_SHIFT) as f64;
    let bk = block_of(k);
    let sk = [bk[0] >> SUPER_SHIFT, bk[1] >> SUPER_SHIFT, bk[2] >> SUPER_SHIFT];
    for r in 0..=grid.max_ring(sk) {
        if r > 0 && ((r - 1) as f64 * e_super).powi(2) >= best.0 {
            break;
        }
        for_each_ring_block(sk, r, |s| {
            if domain.cube_box(s, BLOCK << SUPER_SHIFT).dist2(p) >= best.0 {
                return;
            }
            for (b, aabb) in grid.blocks(s) {
                if aabb.dist2(p) < best.0 {
                    set.lower_best_in_block(*b, p, &mut best);
                }
            }
        });
    }
    best
}

/// The next f64 above a finite `d ≥ 0` (`f64::next_up`, which needs Rust 1.86).
#[inline]
pub(crate) fn above(d: f64) -> f64 {
    debug_assert!(d >= 0.0 && d.is_finite());
    f64::from_bits(d.to_bits() + 1)
}

/// Squared distance between two boxes (0 when they touch or overlap; a lower bound of the
/// computed `dist2` of any point of one to any point of the other: each per-axis gap is
/// rounded no larger than the points' difference).
#[inline]
pub(crate) fn box_box_dist2(a: &Aabb, b: &Aabb) -> f64 {
    let mut d2 = 0.0;
    for k in 0..3 {
        let g = (b.lo[k] - a.hi[k]).max(a.lo[k] - b.hi[k]).max(0.0);
        d2 += g * g;
    }
    d2
}

/// Scratch of [`nearest_in_block`]: the candidate blocks of one group with their lower bounds,
/// and the slab of each candidate that was scanned.
#[derive(Default)]
pub struct BlockSearch {
    cand: Vec<(f64, [i32; 3], Aabb)>,
    slabs: Vec<Option<Slab>>,
    buf: Vec<[f64; 3]>,
}

/// A slab around the points of one block: every point q has |n·(q − c)| ≤ t (n a unit vector),
/// so |p − q| ≥ |n·(p − c)| − t for any p. On a smooth surface patch with n near its normal the
/// slab is thin, and this bound is far tighter than the block's box for points that lie far
/// off the surface (the inside of a sealed shell), which otherwise scan every block whose box
/// reaches within their distance.
///
/// A store that keeps one per block ([`Bucketed::block_slab`]) makes it at most once while the
/// block is unchanged; otherwise each block search makes its own.
#[derive(Debug, Clone, Copy)]
pub struct Slab {
    n: [f64; 3],
    c: [f64; 3],
    t: f64,
}

impl Slab {
    /// The slab that bounds nothing (`lb2` is always 0).
    const NONE: Slab = Slab { n: [1.0, 0.0, 0.0], c: [0.0; 3], t: f64::INFINITY };

    /// The slab of `pts`: the plane through their centroid, the point farthest from it and the
    /// point farthest from that line, and the largest distance of a point from that plane;
    /// None when fewer than 3 points or no plane.
    fn of_points(pts: &[[f64; 3]]) -> Option<Slab> {
        if pts.len() < 3 {
            return None;
        }
        let mut sum = [0.0; 3];
        for q in pts {
            for a in 0..3 {
                sum[a] += q[a];
            }
        }
        let c = sum.map(|x| x / pts.len() as f64);
        let mut far = ([0.0; 3], 0.0);
        for &q in pts {
            let d = dist2(q, c);
            if d > far.1 {
                far = ([q[0] - c[0], q[1] - c[1], q[2] - c[2]], d);
            }
        }
        let u = far.0;
        let mut best = ([0.0; 3], 0.0);
        for &q in pts {
            let v = [q[0] - c[0], q[1] - c[1], q[2] - c[2]];
            let w = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            let m = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            if m > best.1 {
                best = (w, m);
            }
        }
        if best.1 <= 0.0 || !best.1.is_finite() {
            return None;
        }
        let norm = best.1.sqrt();
        let n = best.0.map(|x| x / norm);
        let t = pts.iter().fold(0.0f64, |t, q| {
            t.max((n[0] * (q[0] - c[0]) + n[1] * (q[1] - c[1]) + n[2] * (q[2] - c[2])).abs())
        });
        Some(Slab { n, c, t })
    }

    /// The slab of the points in box `aabb`, which `fill` writes into `buf` (cleared first),
    /// or [`Slab::NONE`] where the box is thin along an axis (a patch of an axis-aligned face:
    /// the box already bounds as well as a slab could; the points are then not copied).
    fn of_box(aabb: &Aabb, h: f64, buf: &mut Vec<[f64; 3]>, fill: impl FnOnce(&mut Vec<[f64; 3]>)) -> Slab {
        if Slab::box_is_thin(aabb, h) {
            return Slab::NONE;
        }
        buf.clear();
        fill(buf);
        Slab::of_points(buf).unwrap_or(Slab::NONE)
    }

    /// [`Slab::of_box`] of a block whose points are `pts` (contiguous in its store).
    pub(crate) fn of_block(aabb: &Aabb, h: f64, pts: &[[f64; 3]]) -> Slab {
        if Slab::box_is_thin(aabb, h) {
            return Slab::NONE;
        }
        Slab::of_points(pts).unwrap_or(Slab::NONE)
    }

    /// Whether `aabb` is thinner than h/4 along an axis.
    fn box_is_thin(aabb: &Aabb, h: f64) -> bool {
        (0..3).any(|a| aabb.hi[a] - aabb.lo[a] < 0.25 * h)
    }

    /// A lower bound of d² from `p` to every point of the slab's block. Rounding: the dot
    /// products err by far less than the margin taken off (1e-9 of the coordinates' scale, and
    /// |n| may exceed 1 by an ulp), so the bound never exceeds a true distance.
    #[inline]
    pub(crate) fn lb2(&self, p: [f64; 3]) -> f64 {
        let s =
            self.n[0] * (p[0] - self.c[0]) + self.n[1] * (p[1] - self.c[1]) + self.n[2] * (p[2] - self.c[2]);
        let d = (s.abs() - self.t) * (1.0 - 1e-9) - 1e-9;
        if d > 0.0 {
            d * d
        } else {
            0.0
        }
    }
}

/// [`nearest_in`] for every point of `pts`, which should all lie in one block of `set`'s grid
/// (fine keys with the same [`block_of`]; otherwise each point is searched alone): `out[i]` is the nearest point of `set` to `pts[i]` with d² below `bound2`, or
/// `(bound2, NONE)`. The same distances as one [`nearest_in`] per point (exact; among exact ties
/// the index found may differ), for a fraction of the work when the answers lie far away: the
/// first point's nearest neighbour `q₀` bounds every point's answer by its distance to `q₀`,
/// the blocks that could beat that bound for some point of the group are gathered once and
/// sorted by their distance to the group's box, and each point scans them in that order (each
/// starting from its predecessor's answer) until the next block's bound reaches its best. A
/// block is skipped when its box, or its slab (`Slab`: on a smooth surface far thinner than
/// the box), is no closer than the point's best so far: for points far off the surface (the
/// inside of a sealed shell) a box bound lets every block within the answer's distance plus
/// the box's depth through, a slab only those near the answer.
pub fn nearest_in_block<S: Bucketed>(
    set: &S,
    pts: &[[f64; 3]],
    bound2: f64,
    scratch: &mut BlockSearch,
    out: &mut Vec<(f64, u32)>,
) {
    nearest_in_block_with(set, pts, bound2, scratch, out, |_| false)
}

/// [`nearest_in_block`], told which points (`nothing_near(i)` for `pts[i]`, i ≥ 1) have no
/// point of `set` in the 27 fine voxels around them: those go straight to the search of whole
/// blocks, without first looking at those voxels (which would find nothing). The answers are
/// the same whatever `nothing_near` says (the block search alone is complete); it only saves
/// the lookups.
pub fn nearest_in_block_with<S: Bucketed>(
    set: &S,
    pts: &[[f64; 3]],
    bound2: f64,
    scratch: &mut BlockSearch,
    out: &mut Vec<(f64, u32)>,
    nothing_near: impl Fn(usize) -> bool,
) {
    out.clear();
    let Some(&first) = pts.first() else { return };
    let domain = set.domain();
    let bk = block_of(domain.key(first));
    if pts.iter().any(|&p| block_of(domain.key(p)) != bk) {
        // Not one block of this set's grid: one search per point.
        out.extend(pts.iter().map(|&p| nearest_in(set, p, bound2)));
        return;
    }
    let (d0, s0) = nearest_in(set, first, bound2);
    let q0 = (s0 != NONE).then(|| set.position(s0));
    // Each point's starting bound (admitting q₀ itself) and the group's largest.
    let start = |p: [f64; 3]| match q0 {
        Some(q) => above(dist2(p, q)).min(bound2),
        None => bound2,
    };
    let mut gbox = Aabb::EMPTY;
    let mut reach: f64 = 0.0;
    for &p in &pts[1..] {
        gbox.grow(p);
        reach = reach.max(start(p));
    }
    out.push((d0, s0));
    if reach <= 0.0 {
        // A bound of 0 admits nothing (and a single point has no others).
        out.extend(pts[1..].iter().map(|_| (bound2, NONE)));
        return;
    }
    let h2 = domain.h * domain.h;
    let mut gathered = false;
    let mut prev = s0;
    for (i, &p) in pts.iter().enumerate().skip(1) {
        let mut b0 = start(p);
        if prev != NONE {
            b0 = b0.min(above(dist2(p, set.position(prev))));
        }
        let mut best = (b0, NONE);
        if !nothing_near(i) {
            // Anything outside the 27 voxels around p is at least h away.
            let k = domain.key(p);
            scan_around(set, p, k, &mut best);
            // An answer within 3h is likely just beyond the 27 voxels: the next layer of voxels
            // (see `scan_ring2`) before the search of whole blocks.
            if best.0 <= h2 || (best.0 <= RING2_TRY * h2 && scan_ring2(set, p, k, &mut best)) {
                if best.1 != NONE {
                    prev = best.1;
                }
                out.push(best);
                continue;
            }
        }
        if !gathered {
            gathered = true;
            gather_candidates(set, bk, &gbox, reach, &mut scratch.cand);
            scratch.slabs.clear();
            scratch.slabs.resize(scratch.cand.len(), None);
        }
        for (c, (lb, b, aabb)) in scratch.cand.iter().enumerate() {
            if *lb >= best.0 {
                break;
            }
            if aabb.dist2(p) >= best.0 {
                continue;
            }
            // The block's slab, made when a point first scans it.
            let slab = scratch.slabs[c].get_or_insert_with(|| {
                set.block_slab(*b, aabb).unwrap_or_else(|| {
                    Slab::of_box(aabb, domain.h, &mut scratch.buf, |buf| {
                        set.for_block(*b, |_, q| buf.push(q))
                    })
                })
            });
            if slab.lb2(p) >= best.0 {
                continue;
            }
            set.lower_best_in_block(*b, p, &mut best);
        }
        // Nothing found below the start bound only when that bound was `bound2` (q₀ and the
        // predecessor's answer are always found): `(bound2, NONE)`, as nearest_in.
        if best.1 != NONE {
            prev = best.1;
        }
        out.push(best);
    }
}

/// The blocks of `set` whose box is closer than √reach to `gbox` (points of block `bk`), with
/// that squared distance, sorted by it.
fn gather_candidates<S: Bucketed>(
    set: &S,
    bk: [i32; 3],
    gbox: &Aabb,
    reach: f64,
    cand: &mut Vec<(f64, [i32; 3], Aabb)>,
) {
    cand.clear();
    let domain = set.domain();
    let grid = set.supergrid();
    let e_super = domain.h * (BLOCK << SUPER_SHIFT) as f64;
    let sk = [bk[0] >> SUPER_SHIFT, bk[1] >> SUPER_SHIFT, bk[2] >> SUPER_SHIFT];
    for r in 0..=grid.max_ring(sk) {
        // Everything beyond ring r − 1 is at least (r − 1)·E from the group's superblock.
        if r > 0 && ((r - 1) as f64 * e_super).powi(2) >= reach {
            break;
        }
        for_each_ring_block(sk, r, |s| {
            if box_box_dist2(&domain.cube_box(s, BLOCK << SUPER_SHIFT), gbox) >= reach {
                return;
            }
            for (b, aabb) in grid.blocks(s) {
                let lb = box_box_dist2(aabb, gbox);
                if lb < reach {
                    cand.push((lb, *b, *aabb));
                }
            }
        });
    }
    cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
}

/// Item indices grouped by an integer key, for passes that handle each group once: see
/// [`key_runs`].
#[derive(Debug, Default, PartialEq)]
pub(crate) struct KeyRuns {
    /// `(key, start, end)` by ascending key: `order[start..end]` are the items with that key,
    /// in ascending index order.
    pub runs: Vec<(u64, usize, usize)>,
    pub order: Vec<u32>,
}

/// The items `0..n` whose `key` is `Some`, ordered by (key, index) and split into runs of equal
/// key. Every key must be below `key_bound`. When key and index fit in one `u64` together (the
/// index in the low ⌈log₂ n⌉ bits), the packed values are sorted, several times cheaper than
/// (key, index) pairs; otherwise the pairs are. `n` must fit in a `u32`.
pub(crate) fn key_runs(n: usize, key_bound: u64, key: impl Fn(usize) -> Option<u64>) -> KeyRuns {
    assert!(u32::try_from(n).is_ok(), "key_runs: {n} items do not fit 32-bit indices");
    let index_bits = (usize::BITS - n.saturating_sub(1).leading_zeros()).max(1);
    let mut out = KeyRuns { runs: Vec::new(), order: Vec::with_capacity(n) };
    if key_bound <= 1 << (64 - index_bits) {
        let mut packed: Vec<u64> =
            (0..n).filter_map(|i| key(i).map(|k| (k << index_bits) | i as u64)).collect();
        packed.sort_unstable();
        let index_mask = (1u64 << index_bits) - 1;
        for run in packed.chunk_by(|a, b| a >> index_bits == b >> index_bits) {
            let start = out.order.len();
            out.order.extend(run.iter().map(|&x| (x & index_mask) as u32));
            out.runs.push((run[0] >> index_bits, start, out.order.len()));
        }
    } else {
        let mut pairs: Vec<(u64, u32)> = (0..n).filter_map(|i| key(i).map(|k| (k, i as u32))).collect();
        pairs.sort_unstable();
        for run in pairs.chunk_by(|a, b| a.0 == b.0) {
            let start = out.order.len();
            out.order.extend(run.iter().map(|&(_, i)| i));
            out.runs.push((run[0].0, start, out.order.len()));
        }
    }
    out
}

/// The points of `points` inside `domain` grouped by fine voxel: the run key is `block index ·
/// BLOCK_CELLS + local voxel index` (see [`cell_of_key`]), so the runs come by domain block, then
/// voxel, each listing its points in input order. Points outside `domain` are left out.
pub(crate) fn voxel_runs(domain: &Domain, points: &[[f64; 3]]) -> KeyRuns {
    let mut keys = Vec::new();
    domain.keys_into(points, &mut keys);
    let bound = (domain.num_blocks() * BLOCK_CELLS) as u64;
    key_runs(points.len(), bound, |i| {
        let k = keys[i];
        domain.block_index(block_of(k)).map(|b| (b * BLOCK_CELLS + local_index(k)) as u64)
    })
}

/// [`voxel_runs`] of every point: the layout of the target sets. Points outside `domain` are
/// an error naming how many.
pub(crate) fn keyed_points(domain: &Domain, points: &[[f64; 3]]) -> Result<KeyRuns, String> {
    let keyed = voxel_runs(domain, points);
    let outside = points.len() - keyed.order.len();
    if outside > 0 {
        return Err(format!("{outside} target points lie outside the metric domain"));
    }
    Ok(keyed)
}

/// `(domain block index, local voxel index)` of a [`voxel_runs`] run key.
#[inline]
pub(crate) fn cell_of_key(key: u64) -> (usize, usize) {
    ((key / BLOCK_CELLS as u64) as usize, (key % BLOCK_CELLS as u64) as usize)
}

/// Calls `f` for every block key at Chebyshev distance exactly `r` from `c`.
pub fn for_each_ring_block(c: [i32; 3], r: i32, mut f: impl FnMut([i32; 3])) {
    if r == 0 {
        f(c);
        return;
    }
    for dz in -r..=r {
        for dy in -r..=r {
            let edge = dz.abs() == r || dy.abs() == r;
            if edge {
                for dx in -r..=r {
                    f([c[0] + dx, c[1] + dy, c[2] + dz]);
                }
            } else {
                f([c[0] - r, c[1] + dy, c[2] + dz]);
                f([c[0] + r, c[1] + dy, c[2] + dz]);
            }
        }
    }
}

/// Squared distance between the boxes of two blocks (0 when they touch or overlap).
pub(crate) fn block_box_dist2(d: &Domain, a: [i32; 3], b: [i32; 3]) -> f64 {
    let e = d.h * BLOCK as f64;
    let mut s = 0.0;
    for ax in 0..3 {
        s += block_gap2(a[ax] - b[ax], e);
    }
    s
}

/// The squared gap along one axis between two block boxes `offset` blocks apart (block edge
/// `e`): [`block_box_dist2`] is the sum of the three axes' gaps, in axis order.
#[inline]
fn block_gap2(offset: i32, e: f64) -> f64 {
    let gap = (offset.abs() - 1).max(0) as f64 * e;
    gap * gap
}

/// Lanes of the vectorized nearest scan.
pub(crate) const LANES: usize = 4;

/// The slots changed by one insertion, grouped by block, with each group's box and its
/// positions laid out for a vectorized nearest scan (the coverage updates' input).
#[derive(Default)]
pub struct ChangedBlocks {
    pub(crate) blocks: Vec<ChangedBlock>,
    /// Slots by group, each group padded with NONE to whole lanes.
    pub(crate) slots: Vec<u32>,
    /// Their positions by coordinate (padding at +∞).
    pub(crate) xyz: [Vec<f64>; 3],
    /// Domain block index → index into `blocks`, or NONE.
    pub(crate) lookup: Vec<u32>,
    /// The entries of `lookup` that are set, so that a reset clears exactly those, whichever
    /// domain (object) the value served last (the engine's step buffers are shared by every
    /// episode of the process).
    indexed: Vec<u32>,
}

/// A group of [`ChangedBlocks`] being made ([`ChangedBlocks::begin_group`]): its entries are
/// laid out (as padding) when it begins, and written in place.
pub(crate) struct GroupFill<'a> {
    groups: &'a mut ChangedBlocks,
    start: usize,
    len: usize,
}

impl GroupFill<'_> {
    /// Appends a slot and its position (at most the `n` of [`ChangedBlocks::begin_group`]);
    /// returns its entry (for [`ChangedBlocks::set_slot`]).
    #[inline]
    pub(crate) fn push(&mut self, s: u32, q: [f64; 3]) -> usize {
        let i = self.start + self.len;
        let g = &mut *self.groups;
        g.slots[i] = s;
        g.xyz[0][i] = q[0];
        g.xyz[1][i] = q[1];
        g.xyz[2][i] = q[2];
        self.len += 1;
        i
    }

    /// Closes the group as block `key`'s with `aabb`, the box of its positions, padded to whole
    /// lanes with points at infinity (never nearest).
    #[inline]
    pub(crate) fn end(self, key: [i32; 3], aabb: Aabb) {
        let g = self.groups;
        let end = self.start + self.len.next_multiple_of(LANES);
        g.slots.truncate(end);
        g.xyz.iter_mut().for_each(|c| c.truncate(end));
        g.blocks.push(ChangedBlock { key, range: (self.start, end), aabb, slab: Slab::NONE });
    }
}

pub(crate) struct ChangedBlock {
    pub(crate) key: [i32; 3],
    pub(crate) range: (usize, usize),
    /// The box of its changed slots' positions (a tighter bound than the block's cube).
    pub(crate) aabb: Aabb,
    /// Their slab once [`ChangedBlocks::make_slabs`] ran ([`Slab::NONE`] before: the per-step
    /// coverage update does not use slabs).
    slab: Slab,
}

impl ChangedBlocks {
    /// Groups `changed` (slots of `fused`).
    pub fn new(fused: &FusedCloud, changed: &[u32]) -> ChangedBlocks {
        let mut g = ChangedBlocks::default();
        g.rebuild(fused, changed);
        g
    }

    /// Groups the slots changed by `fused`'s latest insertion, reusing this value's buffers
    /// and reading block-local memory only ([`FusedCloud::latest_blocks`]); the same groups as
    /// [`ChangedBlocks::rebuild`] of its delta.
    /// (The engine has [`FusedCloud::insert_grouped`] make them during the insertion; this is
    /// the plain way, kept as the tests' reference.)
    #[cfg(test)]
    pub fn rebuild_latest(&mut self, fused: &FusedCloud) {
        self.reset(fused);
        for blk in fused.latest_blocks() {
            let (mut g, mut aabb) = (self.begin_group(blk.changed_count()), Aabb::EMPTY);
            blk.for_each_change(|s, q| {
                g.push(s, q);
                aabb.grow(q);
            });
            g.end(blk.key, aabb);
        }
        self.index(fused);
    }

    /// Starts the next group, of at most `n` slots: push them, then [`GroupFill::end`] it.
    #[inline]
    pub(crate) fn begin_group(&mut self, n: usize) -> GroupFill<'_> {
        let start = self.slots.len();
        let end = start + n.next_multiple_of(LANES);
        self.slots.resize(end, NONE);
        self.xyz.iter_mut().for_each(|c| c.resize(end, f64::INFINITY));
        GroupFill { groups: self, start, len: 0 }
    }

    /// Sets the slot of entry `at` (made with a placeholder by [`GroupFill::push`]).
    #[inline]
    pub(crate) fn set_slot(&mut self, at: usize, s: u32) {
        self.slots[at] = s;
    }

    /// Clears the groups (and their lookup entries).
    pub(crate) fn reset(&mut self, fused: &FusedCloud) {
        let n = fused.domain.num_blocks();
        if self.lookup.len() != n {
            self.lookup = vec![NONE; n];
        } else {
            for &b in &self.indexed {
                self.lookup[b as usize] = NONE;
            }
        }
        self.indexed.clear();
        self.blocks.clear();
        self.slots.clear();
        self.xyz.iter_mut().for_each(Vec::clear);
    }

    /// Computes every group's slab (see [`nearest_in_block`]), for searches from points far
    /// off the surface.
    pub(crate) fn make_slabs(&mut self, h: f64) {
        let mut buf = Vec::new();
        let (slots, xyz) = (&self.slots, &self.xyz);
        for g in &mut self.blocks {
            let (lo, hi) = g.range;
            g.slab = Slab::of_box(&g.aabb, h, &mut buf, |buf| {
                buf.extend((lo..hi).filter(|&i| slots[i] != NONE).map(|i| [xyz[0][i], xyz[1][i], xyz[2][i]]))
            });
        }
    }

    /// Whether group `gi` may hold a point closer to `p` than d² `best` by its box and its slab
    /// (which bounds nothing unless [`ChangedBlocks::make_slabs`] ran).
    #[inline]
    pub(crate) fn may_beat(&self, gi: usize, p: [f64; 3], best: f64) -> bool {
        let g = &self.blocks[gi];
        g.aabb.dist2(p) < best && g.slab.lb2(p) < best
    }

    /// Points the lookup at the groups.
    pub(crate) fn index(&mut self, fused: &FusedCloud) {
        for (gi, g) in self.blocks.iter().enumerate() {
            if let Some(b) = fused.domain.block_index(g.key) {
                self.lookup[b] = gi as u32;
                self.indexed.push(b as u32);
            }
        }
    }

    /// Groups `changed` (slots of `fused`) again, reusing this value's buffers (an episode
    /// keeps one: no large allocation per step).
    pub fn rebuild(&mut self, fused: &FusedCloud, changed: &[u32]) {
        self.reset(fused);
        let mut v: Vec<(u32, u32)> = changed.iter().map(|&s| (fused.block[s as usize], s)).collect();
        // An insertion's delta is already by block (then voxel); anything else is sorted.
        if v.windows(2).any(|w| w[0].0 > w[1].0) {
            v.sort_unstable();
        }
        for run in v.chunk_by(|a, b| a.0 == b.0) {
            let key = fused.domain.block_key(run[0].0 as usize);
            let (mut g, mut aabb) = (self.begin_group(run.len()), Aabb::EMPTY);
            for &(_, s) in run {
                let q = fused.pos[s as usize];
                g.push(s, q);
                aabb.grow(q);
            }
            g.end(key, aabb);
        }
        self.index(fused);
    }

    /// The nearest changed slot of group `g` to `p`: (d², position in `slots`). The positions
    /// are stored by coordinate and padded to whole lanes so that this loop vectorizes; ties
    /// go to the earlier slot of the lane.
    #[inline]
    pub(crate) fn nearest_in_group(&self, g: &ChangedBlock, p: [f64; 3]) -> (f64, usize) {
        let (lo, hi) = g.range;
        let (xs, ys, zs) = (&self.xyz[0][lo..hi], &self.xyz[1][lo..hi], &self.xyz[2][lo..hi]);
        let mut m = [f64::INFINITY; LANES];
        let mut at = [0usize; LANES];
        for (c, ((x, y), z)) in
            xs.chunks_exact(LANES).zip(ys.chunks_exact(LANES)).zip(zs.chunks_exact(LANES)).enumerate()
        {
            for l in 0..LANES {
                let dx = x[l] - p[0];
                let dy = y[l] - p[1];
                let dz = z[l] - p[2];
                let d = dx * dx + dy * dy + dz * dz;
                let better = d < m[l];
                m[l] = if better { d } else { m[l] };
                at[l] = if better { c * LANES + l } else { at[l] };
            }
        }
        let mut best = (f64::INFINITY, lo);
        for l in 0..LANES {
            if m[l] < best.0 || (m[l] == best.0 && lo + at[l] < best.1) {
                best = (m[l], lo + at[l]);
            }
        }
        best
    }

    /// Groups whose block box is closer than √max_d2 to target block `tb`, with that lower
    /// bound: by dense lookup of the blocks around `tb` when that is cheaper than a scan.
    pub(crate) fn candidates(&self, domain: &Domain, tb: [i32; 3], max_d2: f64, out: &mut Vec<(f64, usize)>) {
        let e = domain.h * BLOCK as f64;
        // A block `reach + 1` blocks away along an axis is at least `reach · e ≥ √max_d2` away.
        let reach = if max_d2.is_finite() { (max_d2.sqrt() / e).ceil() as i64 } else { i64::MAX };
        let side = reach.saturating_mul(2).saturating_add(1);
        let volume = side.saturating_mul(side).saturating_mul(side);
        if volume < self.blocks.len() as i64 {
            // The box around `tb` clipped to the domain once (offsets per axis), the lookup's
            // index by strides, and each axis's gap per offset (`block_gap2`, summed in
            // `block_box_dist2`'s order): the same entries as one `block_index` and
            // `block_box_dist2` per block.
            let r = reach as i32;
            let rel: [i32; 3] = std::array::from_fn(|a| tb[a] - domain.lo[a]);
            let span: [(i32, i32); 3] =
                std::array::from_fn(|a| ((-r).max(-rel[a]), r.min(domain.dims[a] - 1 - rel[a])));
            // Within one block of `tb` every block touches it: all gaps 0 (the common case, τ_max
            // below a block's edge), not computed.
            let touching = r <= 1;
            for dz in span[2].0..=span[2].1 {
                let gz = block_gap2(dz, e);
                for dy in span[1].0..=span[1].1 {
                    let gy = block_gap2(dy, e);
                    let row =
                        (domain.dims[0] * ((rel[1] + dy) + domain.dims[1] * (rel[2] + dz)) + rel[0]) as isize;
                    for dx in span[0].0..=span[0].1 {
                        let gi = self.lookup[(row + dx as isize) as usize];
                        if gi != NONE {
                            let lb = if touching { 0.0 } else { (block_gap2(dx, e) + gy) + gz };
                            if lb < max_d2 {
                                out.push((lb, gi as usize));
                            }
                        }
                    }
                }
            }
        } else {
            for (gi, g) in self.blocks.iter().enumerate() {
                let lb = block_box_dist2(domain, tb, g.key);
                if lb < max_d2 {
                    out.push((lb, gi));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_runs_are_the_maximal_runs_of_one_block() {
        // Keys that stay in a block for a while, jump, and come back: the runs tile the input
        // in order, each within one block, and no two neighbouring runs share a block.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        assert_eq!(block_runs(&[]).count(), 0);
        for n in [1usize, 2, 50, 3000] {
            let mut k = [0i32; 3];
            let keys: Vec<[i32; 3]> = (0..n)
                .map(|_| {
                    let a = rng.gen_range(0..3);
                    k[a] += rng.gen_range(-3..=3);
                    k
                })
                .collect();
            let runs: Vec<([i32; 3], usize, usize)> = block_runs(&keys).collect();
            let mut at = 0;
            for (r, &(bk, first, end)) in runs.iter().enumerate() {
                assert_eq!(first, at, "{n} keys: run {r} starts where the last ended");
                assert!(end > first);
                assert!(keys[first..end].iter().all(|&k| block_of(k) == bk));
                if r > 0 {
                    assert_ne!(runs[r - 1].0, bk, "{n} keys: runs {} and {r} are one", r - 1);
                }
                at = end;
            }
            assert_eq!(at, n);
            assert!(n < 50 || (runs.len() > 1 && runs.len() < n), "{n} keys in {} runs", runs.len());
        }
    }

    #[test]
    fn local_coords_invert_local_index() {
        for li in 0..BLOCK_CELLS {
            let c = local_coords(li);
            assert!(c.iter().all(|&x| x < BLOCK as usize));
            // Any block: the same local index.
            for base in [[0, 0, 0], [-8, 16, -24]] {
                let k = [0, 1, 2].map(|a| base[a] + c[a] as i32);
                assert_eq!(local_index(k), li);
            }
        }
    }

    #[test]
    fn key_box_is_the_keys_of_the_domain_blocks() {
        let d = Domain::covering(0.005, [-1.0, -0.3, 0.2], [0.9, 0.4, 1.1], 0.1);
        let (lo, hi) = d.key_box();
        for a in 0..3 {
            for (k, inside) in [(lo[a] - 1, false), (lo[a], true), (hi[a], true), (hi[a] + 1, false)] {
                let mut key = lo;
                key[a] = k;
                assert_eq!(d.block_index(block_of(key)).is_some(), inside, "axis {a}, key {k}");
            }
        }
        // Points of the covered box (margin included) key inside it.
        for p in [[-1.1, -0.4, 0.1], [1.0, 0.5, 1.2], [0.0, 0.0, 0.5]] {
            let k = d.key(p);
            assert!((0..3).all(|a| lo[a] <= k[a] && k[a] <= hi[a]), "{p:?} → {k:?}");
        }
    }

    #[test]
    fn keys_into_equals_key_on_every_kind_of_coordinate() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let d = Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05);
        // Random coordinates, exact multiples of h and their neighbours (floor at the edge),
        // negative zero, huge values (saturation), infinities and NaN; more than one vector's
        // worth and a ragged tail.
        let mut special = vec![0.0, -0.0, 0.005, -0.005, 0.015, -0.015, 1e300, -1e300, 2.2e7, -2.2e7];
        special.extend([f64::INFINITY, f64::NEG_INFINITY, f64::NAN, f64::MIN_POSITIVE, -f64::MIN_POSITIVE]);
        for i in -300..300 {
            let x = i as f64 * 0.005;
            special.extend([x, x.next_up(), x.next_down()]);
        }
        let mut pts: Vec<[f64; 3]> =
            (0..1001).map(|_| [0; 3].map(|_: i32| rng.gen_range(-1.2..1.2))).collect();
        pts.extend(special.chunks(3).map(|c| std::array::from_fn(|a| c[a % c.len()])));
        pts.extend(special.iter().map(|&x| [x, -x, x * 0.5]));
        let mut out = vec![[7; 3]; 3];
        d.keys_into(&pts, &mut out);
        assert_eq!(out.len(), pts.len());
        for (p, k) in pts.iter().zip(&out) {
            assert_eq!(*k, d.key(*p), "{p:?}");
        }
        // The non-vectorized body too.
        let mut plain = vec![0i32; pts.len() * 3];
        keys_body(d.h, pts.as_flattened(), &mut plain);
        assert_eq!(plain, out.as_flattened());
    }

    #[test]
    fn key_runs_group_by_key_then_index_on_both_sorts() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // Keys drawn from few values (long runs), some items without a key; the same items
        // through the packed sort (the index in the low ⌈log₂ n⌉ bits: 12 for 3000 items, 21
        // for 2^20 + 5) and the pair sort (a key bound above 2^(64 − those bits)), against a map
        // from key to indices filled in index order.
        for (n, spread, big) in [
            (0usize, 1u64, false),
            (1, 1, false),
            (2, 1, false),
            (3000, 40, false),
            (3000, 40, true),
            (5000, 1 << 43, false),
            (4096, (1 << 52) - 7, false),
            (4097, (1 << 51) + 9, false),
            ((1 << 20) + 5, 3000, false),
            ((1 << 20) + 5, 3000, true),
        ] {
            let offset = if big { 1u64 << 60 } else { 0 };
            let keys: Vec<Option<u64>> =
                (0..n).map(|_| rng.gen_bool(0.9).then(|| offset + rng.gen_range(0..spread))).collect();
            let bound = offset + spread;
            let got = key_runs(n, bound, |i| keys[i]);
            let mut want: std::collections::BTreeMap<u64, Vec<u32>> = Default::default();
            for (i, k) in keys.iter().enumerate() {
                if let Some(k) = k {
                    want.entry(*k).or_default().push(i as u32);
                }
            }
            assert_eq!(got.runs.len(), want.len(), "n {n}");
            for (&(k, a, b), (wk, wi)) in got.runs.iter().zip(&want) {
                assert_eq!((k, &got.order[a..b]), (*wk, &wi[..]), "n {n} key {k}");
            }
            assert_eq!(got.order.len(), keys.iter().flatten().count());
        }
    }

    #[test]
    fn keyed_points_lists_every_point_by_block_voxel_then_index() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        let d = Domain::covering(0.01, [-0.3; 3], [0.3; 3], 0.0);
        // Clustered points (many share a voxel and a block), a few exactly on voxel faces.
        let mut pts: Vec<[f64; 3]> = (0..4000)
            .map(|_| {
                [0; 3]
                    .map(|_: i32| (rng.gen_range(-30..30) as f64 * 0.01 + rng.gen_range(0.0..0.02)).min(0.29))
            })
            .collect();
        pts.extend([[0.0; 3], [-0.01, 0.0, 0.01], [0.0; 3]]);
        // Against the definition: (block index, local index, input index), sorted.
        let mut want: Vec<(usize, usize, u32)> = pts
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                let k = d.key(p);
                (d.block_index(block_of(k)).unwrap(), local_index(k), i as u32)
            })
            .collect();
        want.sort_unstable();
        let got = keyed_points(&d, &pts).unwrap();
        let mut flat = Vec::new();
        for &(key, s, e) in &got.runs {
            assert!(s < e);
            let (b, c) = cell_of_key(key);
            flat.extend(got.order[s..e].iter().map(|&i| (b, c, i)));
        }
        assert_eq!(flat, want);
        assert_eq!(want.chunk_by(|a, b| (a.0, a.1) == (b.0, b.1)).count(), got.runs.len());
        // Points outside: the error counts them; NaN keys to voxel 0, inside this domain.
        pts.extend([[5.0, 0.0, 0.0], [0.0, -9.0, 0.0], [f64::INFINITY, 0.0, 0.0], [f64::NAN; 3]]);
        assert_eq!(keyed_points(&d, &pts).unwrap_err(), "3 target points lie outside the metric domain");
    }

    #[test]
    fn keys_and_blocks_floor() {
        let d = Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05);
        assert_eq!(d.key([0.0, 0.0049, -0.0001]), [0, 0, -1]);
        assert_eq!(block_of([-1, 7, 8]), [-1, 0, 1]);
        assert_eq!(local_index([-1, 0, 0]), 7);
        assert_eq!(local_index([8, 9, 0]), 8);
        for i in [0, 17, d.num_blocks() - 1] {
            assert_eq!(d.block_index(d.block_key(i)), Some(i));
        }
        assert_eq!(d.block_index([d.lo[0] - 1, d.lo[1], d.lo[2]]), None);
        // The domain covers ±1.05: key of 1.05 lies in a block inside.
        assert!(d.block_index(block_of(d.key([1.05, -1.05, 0.0]))).is_some());
        // Box distance: block [0,0.04)³.
        let block = d.cube_box([0, 0, 0], BLOCK);
        assert!((block.dist2([0.05, 0.02, 0.02]) - 1e-4).abs() < 1e-15);
        assert_eq!(block.dist2([0.01, 0.02, 0.03]), 0.0);
    }

    #[test]
    fn boxes_bound_their_points() {
        let mut b = Aabb::EMPTY;
        assert_eq!(b.dist2([0.0; 3]), f64::INFINITY);
        b.grow([0.0, 0.0, 0.0]);
        b.grow([1.0, 0.5, 0.0]);
        assert_eq!(b.dist2([0.5, 0.25, 0.0]), 0.0);
        assert!((b.dist2([2.0, 0.5, -1.0]) - 2.0).abs() < 1e-15);
        // Superblocks: blocks 0 and 3 share superblock 0, block 4 starts superblock 1.
        let d = Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05);
        let mut g = SuperGrid::new(&d);
        let h0 = g.add_block([0, 0, 0]).unwrap();
        g.add_block([3, 0, 0]).unwrap();
        g.add_block([4, 0, 0]).unwrap();
        assert!(g.add_block([1000, 0, 0]).is_none());
        g.grow(h0, [0.01, 0.01, 0.01]);
        let keys: Vec<_> = g.blocks([0, 0, 0]).iter().map(|e| e.0).collect();
        assert_eq!(keys, vec![[0, 0, 0], [3, 0, 0]]);
        assert_eq!(g.blocks([0, 0, 0])[0].1.dist2([0.01, 0.01, 0.01]), 0.0);
        assert_eq!(g.blocks([1, 0, 0]).len(), 1);
    }

    #[test]
    fn ring_covers_every_block_once() {
        for r in 0..4 {
            let mut seen = std::collections::HashSet::new();
            for_each_ring_block([0, 0, 0], r, |b| assert!(seen.insert(b)));
            let n = (2 * r + 1).pow(3) - if r > 0 { (2 * r - 1).pow(3) } else { 0 };
            assert_eq!(seen.len() as i32, n);
            assert!(seen.iter().all(|b| b.iter().map(|x| x.abs()).max() == Some(r)));
        }
    }

    /// Brute force: the smallest d² of `pts` to `p` below `bound2`, or `bound2`.
    fn brute(pts: &[[f64; 3]], p: [f64; 3], bound2: f64) -> f64 {
        pts.iter().map(|&q| dist2(p, q)).filter(|&d| d < bound2).fold(bound2, f64::min)
    }

    #[test]
    fn slabs_bound_their_blocks() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.0);
        let e = domain.h * BLOCK as f64;
        let mut tight = 0;
        for trial in 0..400 {
            let bk = [0; 3].map(|_: i32| rng.gen_range(-14..14));
            let lo = domain.cube_box(bk, BLOCK).lo;
            let inside = |u: [f64; 3]| [0, 1, 2].map(|a| lo[a] + (0.001 + 0.998 * u[a]) * e);
            // A tilted plane, a curved patch, a line, one repeated point, or a cloud, by trial.
            let n = rng.gen_range(1..120);
            let tilt: [f64; 2] = [rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5)];
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let (x, y) = (rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0));
                    let z = match trial % 5 {
                        0 => 0.5 + tilt[0] * (x - 0.5) + tilt[1] * (y - 0.5),
                        1 => 0.3 + 0.4 * ((x - 0.5) * (x - 0.5) + (y - 0.5) * (y - 0.5)),
                        2 => return inside([x, x, x]),
                        3 => return inside([0.4, 0.6, 0.5]),
                        _ => rng.gen_range(0.0..1.0),
                    };
                    inside([x, y, z])
                })
                .collect();
            let slab = Slab::of_points(&pts);
            if trial % 5 == 3 || pts.len() < 3 {
                assert!(slab.is_none(), "trial {trial}: {} points span no plane", pts.len());
                continue;
            }
            // Points on a line may still give a slab (rounding leaves a tiny cross product):
            // any unit normal bounds, so it must bound too.
            let Some(slab) = slab else { continue };
            for _ in 0..50 {
                let p: [f64; 3] = [0; 3].map(|_: i32| rng.gen_range(-0.7..0.7));
                let want = pts.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min);
                assert!(slab.lb2(p) <= want, "trial {trial}: {} > {want}", slab.lb2(p));
                if trial % 5 == 0 && slab.lb2(p) > 0.5 * want {
                    tight += 1;
                }
            }
        }
        // On a plane the slab is as thin as the plane: the bound is most of the distance for
        // many queries (a box around a tilted patch is not).
        assert!(tight > 1000, "{tight}");
    }

    /// The full 27-voxel scan that [`scan_around`] prunes.
    /// Shows every point of the fine voxels within Chebyshev distance `r` of `k` to the
    /// comparison of the scans.
    fn scan_all<S: Bucketed>(set: &S, p: [f64; 3], k: [i32; 3], r: i32, best: &mut (f64, u32)) {
        set.for_cells_in_box(k.map(|x| x - r), k.map(|x| x + r), |i, q| {
            let d = dist2(p, q);
            if d < best.0 || (d == best.0 && best.1 != NONE && i < best.1) {
                *best = (d, i);
            }
        });
    }

    /// Runs `check(target set, fused cloud, points, query, its key, starting bound)` on
    /// `trials` queries against a point set built for ties and roundings: points on a lattice
    /// of voxel faces and corners (exact ties between voxels, points a rounding away from their
    /// voxel's box), duplicated (ties of the index rule), plus a random cloud sparse enough
    /// (4,000 points in 0.2³, h = 0.005) that many answers lie a voxel or two away; as a target
    /// set (several points per voxel) and as a fused cloud (one per voxel). Queries lie on or a
    /// rounding away from the lattice, or near a point; starting bounds are none, a point's
    /// distance (as the block searches start), a random value, or a tie away.
    fn tie_heavy_queries(
        seed: u64,
        trials: usize,
        mut check: impl FnMut(
            &crate::chamfer::Targets,
            &FusedCloud,
            &[[f64; 3]],
            [f64; 3],
            [i32; 3],
            (f64, u32),
            usize,
        ),
    ) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let h = 0.005;
        let domain = Domain::covering(h, [-0.2; 3], [0.2; 3], 0.0);
        let mut pts: Vec<[f64; 3]> = Vec::new();
        for _ in 0..4000 {
            let lattice = |rng: &mut rand_chacha::ChaCha8Rng| rng.gen_range(-20..20) as f64 * h;
            let q = match rng.gen_range(0..4) {
                0 => [lattice(&mut rng), lattice(&mut rng), lattice(&mut rng)],
                1 => [lattice(&mut rng), rng.gen_range(-0.1..0.1), lattice(&mut rng)],
                _ => [0; 3].map(|_: i32| rng.gen_range(-0.1..0.1)),
            };
            pts.push(q);
            if rng.gen_bool(0.2) {
                pts.push(q);
            }
        }
        let targets = crate::chamfer::Targets::new(domain.clone(), &pts, f64::INFINITY).unwrap();
        let mut fused = FusedCloud::new(domain.clone());
        fused.insert(&pts);
        for trial in 0..trials {
            let near = |rng: &mut rand_chacha::ChaCha8Rng| {
                let x = rng.gen_range(-20..20) as f64 * h;
                match rng.gen_range(0..3) {
                    0 => x,
                    1 => x + rng.gen_range(-1e-12..1e-12),
                    _ => x + rng.gen_range(-0.5..0.5) * h,
                }
            };
            let p = if trial % 2 == 0 {
                [near(&mut rng), near(&mut rng), near(&mut rng)]
            } else {
                pts[rng.gen_range(0..pts.len())].map(|x| x + rng.gen_range(-2.0..2.0) * h)
            };
            let k = domain.key(p);
            let some = pts[rng.gen_range(0..pts.len())];
            let start = match trial % 4 {
                0 => (f64::INFINITY, NONE),
                1 => (dist2(p, some), NONE),
                2 => (rng.gen_range(0.0..4.0) * h * h, NONE),
                _ => (dist2(p, some), 0),
            };
            check(&targets, &fused, &pts, p, k, start, trial);
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn four_distances_at_once_are_dist2_bit_for_bit() {
        // Random coordinates (on the lattice of the test below every sum would be exact, and a
        // changed order of operations would go unseen): each lane is `dist2` of its point, and
        // the AVX2 minimum search answers what the portable one answers.
        use rand::{Rng, SeedableRng};
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: only the portable path exists here");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(45);
        for trial in 0..2000 {
            let scale = [1e-3, 1.0, 37.0][trial % 3];
            let n = rng.gen_range(4..48);
            let pts: Vec<[f64; 3]> =
                (0..n).map(|_| [0; 3].map(|_: i32| rng.gen_range(-1.0..1.0) * scale)).collect();
            let p = [0; 3].map(|_: i32| rng.gen_range(-1.0..1.0) * scale);
            let mut lanes = [0.0; 4];
            // SAFETY: the CPU has AVX2 (checked above) and `pts` holds at least four points.
            unsafe {
                use std::arch::x86_64::*;
                let d = dist2_x4(
                    pts.as_flattened().as_ptr(),
                    _mm256_set1_pd(p[0]),
                    _mm256_set1_pd(p[1]),
                    _mm256_set1_pd(p[2]),
                );
                _mm256_storeu_pd(lanes.as_mut_ptr(), d);
            }
            for (l, &d) in lanes.iter().enumerate() {
                assert_eq!(d.to_bits(), dist2(p, pts[l]).to_bits(), "trial {trial}, lane {l}");
            }
            let names: Vec<u32> = (0..n as u32).rev().collect();
            let start = if trial % 2 == 0 { (f64::INFINITY, NONE) } else { (dist2(p, pts[n / 2]), NONE) };
            let (mut a, mut b) = (start, start);
            // SAFETY: the CPU has AVX2 (checked above); the portable passes need nothing.
            unsafe {
                lower_best_over_on(true, &pts, |j| names[j], p, &mut a);
                lower_best_over_on(false, &pts, |j| names[j], p, &mut b);
            }
            assert_eq!((a.0.to_bits(), a.1), (b.0.to_bits(), b.1), "trial {trial}");
        }
    }

    #[test]
    fn block_minima_equal_one_by_one_comparisons() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(44);
        let mut changed = 0;
        for trial in 0..5000 {
            // Points on a coarse lattice (many exact ties), some duplicated, named by distinct
            // indices in random order; every length from empty to a few lanes plus a remainder.
            let n = rng.gen_range(0..40);
            let lattice =
                |rng: &mut rand_chacha::ChaCha8Rng| [0; 3].map(|_: i32| rng.gen_range(-2..3) as f64 * 0.25);
            let mut pts: Vec<[f64; 3]> = Vec::new();
            while pts.len() < n {
                let q = if !pts.is_empty() && rng.gen_bool(0.2) {
                    pts[rng.gen_range(0..pts.len())]
                } else {
                    lattice(&mut rng)
                };
                pts.push(q);
            }
            let mut names: Vec<u32> = (0..n as u32).map(|j| j * 3 + 1).collect();
            for j in (1..names.len()).rev() {
                names.swap(j, rng.gen_range(0..=j));
            }
            let p = lattice(&mut rng);
            let tie = |rng: &mut rand_chacha::ChaCha8Rng| {
                if pts.is_empty() {
                    1.0
                } else {
                    dist2(p, pts[rng.gen_range(0..pts.len())])
                }
            };
            let start = match trial % 4 {
                0 => (f64::INFINITY, NONE),
                1 => (tie(&mut rng), NONE),
                2 => (tie(&mut rng), rng.gen_range(0..3 * n as u32 + 2)),
                _ => (rng.gen_range(0.0..1.0), NONE),
            };
            let mut want = start;
            for (j, &q) in pts.iter().enumerate() {
                let d = dist2(p, q);
                if d < want.0 || (d == want.0 && want.1 != NONE && names[j] < want.1) {
                    want = (d, names[j]);
                }
            }
            let mut got = start;
            lower_best_over(&pts, |j| names[j], p, &mut got);
            assert_eq!(got, want, "trial {trial}: {pts:?} from {p:?}, start {start:?}");
            // The portable passes too (on a CPU with AVX2 the call above took the AVX2 ones).
            let mut portable = start;
            // SAFETY: the portable passes need no CPU feature.
            unsafe { lower_best_over_on(false, &pts, |j| names[j], p, &mut portable) };
            assert_eq!(portable, want, "portable, trial {trial}: {pts:?} from {p:?}, start {start:?}");
            changed += (got != start) as usize;
        }
        assert!(changed > 2000, "the cases should improve the bound: {changed}");
    }

    #[test]
    fn pruned_27_voxel_scans_equal_full_ones() {
        let (mut pruned_hits, mut far) = (0, 0);
        tie_heavy_queries(41, 20_000, |targets, fused, _, p, k, start, trial| {
            let (mut a, mut b) = (start, start);
            scan_around(targets, p, k, &mut a);
            scan_all(targets, p, k, 1, &mut b);
            assert_eq!(a, b, "targets, trial {trial}: {p:?}");
            let (mut a, mut b) = (start, start);
            scan_around(fused, p, k, &mut a);
            scan_all(fused, p, k, 1, &mut b);
            assert_eq!(a, b, "fused, trial {trial}: {p:?}");
            pruned_hits += (a.1 != start.1) as usize;
            far += (a.0 > fused.domain.h * fused.domain.h) as usize;
        });
        assert!(pruned_hits > 5000 && far > 1000, "cases: {pruned_hits} improved, {far} far");
    }

    #[test]
    fn the_second_layer_scan_equals_a_full_one_and_settles_only_exact_answers() {
        let (mut settled_beyond_h, mut unsettled) = (0, 0);
        tie_heavy_queries(42, 20_000, |targets, fused, pts, p, k, start, trial| {
            let h2 = fused.domain.h * fused.domain.h;
            for (name, settled, a, b) in [
                {
                    let (mut a, mut b) = (start, start);
                    scan_around(targets, p, k, &mut a);
                    let settled = scan_ring2(targets, p, k, &mut a);
                    scan_all(targets, p, k, 2, &mut b);
                    ("targets", settled, a, b)
                },
                {
                    let (mut a, mut b) = (start, start);
                    scan_around(fused, p, k, &mut a);
                    let settled = scan_ring2(fused, p, k, &mut a);
                    scan_all(fused, p, k, 2, &mut b);
                    ("fused", settled, a, b)
                },
            ] {
                // The same answer as every point of the 125 voxels, index included.
                assert_eq!(a, b, "{name}, trial {trial}: {p:?}");
                if settled {
                    // Nothing anywhere in the set is strictly closer (brute force over the
                    // target points, or over the fused cloud's centroids). Without a point
                    // found, `a` is still the starting bound.
                    let all: &[[f64; 3]] = if name == "fused" { &fused.pos } else { pts };
                    let set_min = all.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min);
                    assert!(set_min >= a.0, "{name}, trial {trial}: {p:?}");
                    assert!(a.1 == NONE || set_min == a.0, "{name}, trial {trial}: {p:?}");
                    settled_beyond_h += (a.0 > h2 && a.1 != NONE) as usize;
                } else {
                    unsettled += 1;
                }
            }
        });
        assert!(
            settled_beyond_h > 2000 && unsettled > 1000,
            "cases: {settled_beyond_h} settled beyond h, {unsettled} not"
        );
    }

    #[test]
    fn block_searches_find_what_brute_force_finds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.0);
        // Patches of surface — flat and axis-aligned (thin boxes), tilted, curved (slabs) — one
        // moved by a second insertion, and a lone far point, so that queries meet near answers,
        // far answers and answers in other superblocks.
        let mut fused = FusedCloud::new(domain.clone());
        let patch = |rng: &mut rand_chacha::ChaCha8Rng, c: [f64; 3], n: usize, tilt: f64, bend: f64| {
            (0..n)
                .map(|_| {
                    let (x, y) = (rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1));
                    [c[0] + x, c[1] + y, c[2] + tilt * (x + 0.5 * y) + bend * (x * x + y * y)]
                })
                .collect::<Vec<[f64; 3]>>()
        };
        fused.insert(&patch(&mut rng, [0.2, 0.1, -0.3], 4000, 0.0, 0.0));
        fused.insert(&patch(&mut rng, [-0.3, 0.0, 0.35], 3000, 0.7, 0.0));
        fused.insert(&patch(&mut rng, [0.2, 0.1, -0.3], 2000, 0.0, 0.0));
        fused.insert(&patch(&mut rng, [0.25, -0.3, 0.1], 3000, 0.3, 4.0));
        fused.insert(&[[0.5, -0.5, 0.5]]);
        let all: Vec<[f64; 3]> = fused.pos.clone();
        let mut scratch = BlockSearch::default();
        let mut out = Vec::new();
        let mut far = 0;
        for trial in 0..300 {
            // A group of queries inside one random block.
            let c: [f64; 3] = [0; 3].map(|_: i32| rng.gen_range(-0.55..0.55));
            let bk = block_of(domain.key(c));
            let e = domain.h * BLOCK as f64;
            let n = rng.gen_range(1..40);
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| [0, 1, 2].map(|a| (bk[a] as f64 + rng.gen_range(0.01..0.99)) * e))
                .filter(|&p| block_of(domain.key(p)) == bk)
                .collect();
            let bound2 = if trial % 3 == 0 { 0.04 } else { f64::INFINITY };
            // Told nothing (as `nearest_in_block`), told the truth about the 27 voxels around
            // each point, told that none has anything near (a lie where it does): the same
            // answers.
            let near = |p: [f64; 3]| {
                let k = domain.key(p);
                all.iter().any(|&q| {
                    let kq = domain.key(q);
                    (0..3).all(|a| (kq[a] - k[a]).abs() <= 1)
                })
            };
            let truth: Vec<bool> = pts.iter().map(|&p| !near(p)).collect();
            let mut told = Vec::new();
            nearest_in_block_with(&fused, &pts, bound2, &mut scratch, &mut told, |i| truth[i]);
            let mut lied = Vec::new();
            nearest_in_block_with(&fused, &pts, bound2, &mut scratch, &mut lied, |_| true);
            nearest_in_block(&fused, &pts, bound2, &mut scratch, &mut out);
            assert_eq!(out.len(), pts.len());
            for (o, (t, l)) in out.iter().zip(told.iter().zip(&lied)) {
                assert_eq!((o.0, t.0), (l.0, l.0), "trial {trial}");
            }
            for (&p, &(d, s)) in pts.iter().zip(&out) {
                let want = brute(&all, p, bound2);
                assert_eq!(d, want, "trial {trial}: {p:?}");
                if s == NONE {
                    assert_eq!(d, bound2);
                } else {
                    assert_eq!(dist2(p, fused.pos[s as usize]), d);
                    assert_eq!(d, nearest_in(&fused, p, bound2).0);
                }
                if d > 0.01 && d.is_finite() {
                    far += 1;
                }
            }
        }
        assert!(far > 1000, "the trials should meet far answers ({far})");
        // Bound 0 admits nothing; an empty group gives nothing.
        nearest_in_block(&fused, &[[0.1, 0.1, 0.1], [0.101, 0.1, 0.1]], 0.0, &mut scratch, &mut out);
        assert_eq!(out, vec![(0.0, NONE); 2]);
        nearest_in_block(&fused, &[], 1.0, &mut scratch, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn candidate_groups_are_every_group_within_reach() {
        // Groups in most blocks of a small domain: for target blocks inside, on the edges and
        // outside it, and radii whose box takes the dense lookup (reach 1–3) or the scan of all
        // groups (∞), the candidates are exactly the groups whose block cube is closer than the
        // radius, with `block_box_dist2`'s value bit for bit.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let domain = Domain::covering(0.005, [-0.2; 3], [0.2; 3], 0.05);
        let pts: Vec<[f64; 3]> =
            (0..4000).map(|_| std::array::from_fn(|_| rng.gen_range(-0.24..0.24))).collect();
        let mut fused = FusedCloud::new(domain.clone());
        fused.insert(&pts);
        let groups = ChangedBlocks::new(&fused, &fused.latest_changed());
        assert!(groups.blocks.len() > 343, "{} groups", groups.blocks.len());
        let mut out = Vec::new();
        for max_d2 in [0.0, 1e-12, 0.03f64 * 0.03, 0.04 * 0.04, 0.05 * 0.05, 0.1 * 0.1, f64::INFINITY] {
            for z in domain.lo[2] - 2..domain.lo[2] + domain.dims[2] + 2 {
                for y in [domain.lo[1] - 1, domain.lo[1], domain.lo[1] + 4, domain.lo[1] + domain.dims[1] - 1]
                {
                    for x in domain.lo[0] - 1..domain.lo[0] + domain.dims[0] + 1 {
                        let tb = [x, y, z];
                        out.clear();
                        groups.candidates(&domain, tb, max_d2, &mut out);
                        out.sort_by_key(|a| a.1);
                        let want: Vec<(f64, usize)> = groups
                            .blocks
                            .iter()
                            .enumerate()
                            .map(|(gi, g)| (block_box_dist2(&domain, tb, g.key), gi))
                            .filter(|&(lb, _)| lb < max_d2)
                            .collect();
                        assert_eq!(out, want, "block {tb:?}, max d² {max_d2}");
                    }
                }
            }
        }
    }
}
