//! [`InverseCaster`], the `inverse`-mode engine: the set plus its distance field, and the
//! per-view entry points (single rays, the fast two-pass `observe_into`, the literal
//! one-walk-per-voxel `observe_walk_into`). The passes themselves live in [`super::project`]
//! (first pass: projections and depth bounds) and [`super::walk`] (second pass: ray set-up and
//! walks); this module only orchestrates them, so the exactness arguments stay next to the code
//! they are about.

use super::axis::fmin;
use super::bitset::bitset_to_indices;
use super::field::distance_field;
use super::project::{pixel_of, CELL, TILE};
use super::prune::open_faces;
use super::walk::{Cast, Octant, Ray};
use super::{pixel_ray_direction, DEFAULT_MAX_RANGE};
use crate::key::center_of;
use crate::set::VoxelSet;
use objview_render::Camera;
use std::sync::OnceLock;

/// In a pruned union view with at most this many needed pixels, the first pass marks only the
/// voxel centres' pixels and the rays walk from the grid box entry (a speed setting only).
const FEW_PIXELS: usize = 16384;

/// The `inverse`-mode engine for one S_gt: the set plus its Chebyshev distance field.
/// Build it once per object and query it for every view (it is `Sync`).
#[derive(Debug, Clone)]
pub struct InverseCaster<'a> {
    pub(super) set: &'a VoxelSet,
    /// Chebyshev distance (in cells) from each grid cell to the nearest S_gt cell, 0 on S_gt,
    /// `FIELD_CAP + 1` beyond the cap. Layout `(x·ny + y)·nz + z`.
    pub(super) field: Vec<u8>,
    pub(super) dims: [usize; 3],
    pub(super) strides: [usize; 3],
    pub(super) max_range: f64,
    /// Per voxel, its open faces ([`super::prune::open_faces`]), and the bitset over set
    /// indices of the voxels with one: for [`InverseCaster::observe_union_into`] only, so made
    /// by its first call.
    pub(super) open: OnceLock<OpenFaces>,
}

/// The open faces of a set's voxels ([`super::prune::open_faces`]).
#[derive(Debug, Clone)]
pub(super) struct OpenFaces {
    /// Per voxel (set index), bit 2a for +a, 2a + 1 for −a.
    pub(super) faces: Vec<u8>,
    /// Bitset over set indices: the voxels with an open face.
    pub(super) any: Vec<u64>,
}

impl OpenFaces {
    pub(super) fn of(set: &VoxelSet) -> OpenFaces {
        let faces = open_faces(set);
        let mut any = vec![0u64; set.len().div_ceil(64)];
        for (i, _) in faces.iter().enumerate().filter(|(_, &o)| o != 0) {
            any[i >> 6] |= 1 << (i & 63);
        }
        OpenFaces { faces, any }
    }
}

impl<'a> InverseCaster<'a> {
    /// The caster for `set` with the default range [`DEFAULT_MAX_RANGE`].
    pub fn new(set: &'a VoxelSet) -> InverseCaster<'a> {
        InverseCaster::with_max_range(set, DEFAULT_MAX_RANGE)
    }

    /// The caster for `set`; rays count voxels entered at distance ≤ `max_range` (object
    /// units) from the camera centre.
    pub fn with_max_range(set: &'a VoxelSet, max_range: f64) -> InverseCaster<'a> {
        let dims = set.grid_dims();
        let strides = [dims[1] * dims[2], dims[2], 1];
        InverseCaster { set, field: distance_field(set), dims, strides, max_range, open: OnceLock::new() }
    }

    /// The set this caster walks.
    pub fn set(&self) -> &'a VoxelSet {
        self.set
    }

    /// The maximum ray range.
    pub fn max_range(&self) -> f64 {
        self.max_range
    }

    /// Index (into the set) of the first S_gt voxel entered by the ray `origin + t·dir`,
    /// `0 ≤ t ≤ max_range`; object frame, `dir` must be a unit vector (t is a distance).
    /// Conventions in the module documentation.
    pub fn first_hit(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<u32> {
        if self.set.is_empty() {
            return None;
        }
        let vp = self.planes(origin);
        self.first_hit_cell(&vp, dir, f64::NEG_INFINITY)
            .map(|g| self.set.index_of_bit(self.set.bit_of_cell(g)))
    }

    /// O(v) for `camera` (object-frame pose, SPEC §2 intrinsics or others) as a bitset over
    /// set indices (`len.div_ceil(64)` words).
    pub fn observe_bitset(&self, camera: &Camera) -> Vec<u64> {
        let mut bits = vec![0u64; self.set.len().div_ceil(64)];
        self.observe_into(camera, &mut bits);
        bits
    }

    /// O(v) for `camera` as sorted unique set indices.
    pub fn observe(&self, camera: &Camera) -> Vec<u32> {
        bitset_to_indices(&self.observe_bitset(camera))
    }

    /// ORs O(v) for `camera` into `bits` (a bitset over set indices, at least
    /// `len.div_ceil(64)` words).
    ///
    /// Same set as [`InverseCaster::observe_walk_into`] (tested against it and a brute force),
    /// faster. A first pass over the voxels projects each centre, marks its pixel in a per-view
    /// pixel mask (one `u64` per 8×8-pixel tile) and builds a coarse depth bound: for each
    /// 4×4-pixel cell, a distance below which no voxel box whose projection can reach the cell
    /// is entered (`|centre − camera| − r·√3/2` over a conservative footprint of the projected
    /// bounding sphere). The second pass casts one ray per *marked pixel*, tile by tile: voxels
    /// projecting to the same pixel cast the same ray and add the same voxel, so one walk
    /// answers them all; every walk starts at its cell's bound instead of at the grid box,
    /// which skips the empty space in front of the object in O(1).
    pub fn observe_into(&self, camera: &Camera, bits: &mut [u64]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt") {
            // SAFETY: the CPU has the features `observe_avx2` is compiled for.
            return unsafe { self.observe_avx2(camera, bits) };
        }
        self.observe_body::<false>(camera, bits)
    }

    /// ORs O(v) for `camera` into the union `acc` (a bitset over set indices, at least
    /// `len.div_ceil(64)` words): afterwards `acc` is `acc ∪ O(v)`, as after
    /// [`InverseCaster::observe_into`] with `bits = acc`, with less work when `acc` already
    /// holds much of the set.
    ///
    /// Exact: a ray through a pixel centre that enters a voxel's box passes within the voxel's
    /// conservative projected footprint (the one of the depth bound), so a pixel outside the
    /// footprints of every voxel not yet in `acc` can only see voxels of `acc`; such pixels are
    /// not cast. The others are cast exactly as by `observe_into`. Where some footprint is
    /// unbounded (a voxel box reaching the camera plane) every pixel is cast.
    pub fn observe_union_into(&self, camera: &Camera, acc: &mut [u64]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt") {
            // SAFETY: the CPU has the features `union_avx2` is compiled for.
            return unsafe { self.union_avx2(camera, acc) };
        }
        self.observe_body::<true>(camera, acc)
    }

    /// [`InverseCaster::observe_union_into`] compiled for AVX2 and POPCNT, as
    /// [`InverseCaster::observe_avx2`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    fn union_avx2(&self, camera: &Camera, acc: &mut [u64]) {
        self.observe_body::<true>(camera, acc)
    }

    /// [`InverseCaster::observe_into`] compiled for AVX2 and POPCNT (selected at run time):
    /// wider vectors in the first pass and a hardware popcount in the rank lookups. The same
    /// source, so the same IEEE operations per value (FMA, which would change roundings, is
    /// not enabled, and the compiler never contracts without it), hence the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    fn observe_avx2(&self, camera: &Camera, bits: &mut [u64]) {
        self.observe_body::<false>(camera, bits)
    }

    /// The body of [`InverseCaster::observe_into`] and (`UNION`) of
    /// [`InverseCaster::observe_union_into`], where `bits` is the union.
    #[inline(always)]
    fn observe_body<const UNION: bool>(&self, camera: &Camera, bits: &mut [u64]) {
        let set = self.set;
        if set.is_empty() {
            return;
        }
        assert!(bits.len() >= set.len().div_ceil(64), "bitset too short");
        let vp = self.planes(camera.center);
        let k = &camera.intrinsics;
        let (tw, th) = ((k.width as usize).div_ceil(TILE), (k.height as usize).div_ceil(TILE));
        let (cw, ch) = ((k.width as usize).div_ceil(CELL), (k.height as usize).div_ceil(CELL));
        let mut cell_min = vec![f64::INFINITY; cw * ch];
        // Bit (v % 8)·8 + u % 8 of word (v / 8)·tw + u / 8: pixel (u, v) is some voxel's pixel.
        let mut mask = vec![0u64; tw * th];
        // In a union, only the pixels whose rays may see a voxel not yet in it.
        let mut need = Vec::new();
        let prune = UNION && {
            need = vec![0u64; tw * th];
            self.needed_pixels(camera, bits, &mut need)
        };
        if prune && need.iter().all(|&n| n == 0) {
            return;
        }
        let global_min = if prune && need.iter().map(|n| n.count_ones() as usize).sum::<usize>() <= FEW_PIXELS
        {
            // Few pixels to cast: their centres' pixels only, and walks from the grid box
            // entry (no depth bound, which costs a footprint per voxel).
            self.project_centres(camera, &need, &mut mask);
            f64::NEG_INFINITY
        } else {
            self.project_voxels(camera, &mut cell_min, &mut mask)
        };
        if prune {
            mask.iter_mut().zip(&need).for_each(|(m, n)| *m &= n);
        }
        let qu: Vec<f64> = (0..k.width).map(|u| k.pixel_ray(u, 0)[0]).collect();
        let qv: Vec<f64> = (0..k.height).map(|v| k.pixel_ray(0, v)[1]).collect();
        let (cr, cd, cf) = (camera.right, camera.down, camera.forward);
        let octants: [Octant<'_>; 8] = std::array::from_fn(|m| self.octant(&vp, m));
        // Per tile, the rays' set-up arithmetic (direction, reciprocals, grid-box entry and
        // exit, start cell) runs first for all its marked pixels, in loops without
        // data-dependent branches, so that the long sqrt/division latency chains of
        // different rays overlap; the walks follow. Same operations on the same values, so
        // the same bits; a ray that `cast` rejects before its walk just wastes its start.
        let mut rays = [Ray::default(); TILE * TILE];
        // Per-tile structure-of-arrays scratch for the arithmetic part of the set-up, so that it
        // runs in loops over plain arrays (vectorized: 4 rays per square root or division).
        let mut pa = [0.0f64; TILE * TILE];
        let mut pc = [0.0f64; TILE * TILE];
        let mut dd = [[0.0f64; TILE * TILE]; 3];
        let mut ss = [[0.0f64; TILE * TILE]; 3];
        for (t, &m) in mask.iter().enumerate() {
            if m == 0 {
                continue;
            }
            let (u0, v0) = ((t % tw) * TILE, (t / tw) * TILE);
            let mut m = m;
            let mut n_rays = 0;
            while m != 0 {
                let b = m.trailing_zeros() as usize;
                m &= m - 1;
                let (u, v) = (u0 + b % TILE, v0 + b / TILE);
                rays[n_rays].t_lo = fmin(cell_min[(v / CELL) * cw + u / CELL], global_min);
                // `pixel_ray_direction` with the per-pixel divisions tabulated (same values).
                (pa[n_rays], pc[n_rays]) = (qu[u], qv[v]);
                n_rays += 1;
            }
            // The same IEEE operations per ray as one at a time (a vector square root or
            // division rounds each lane exactly as the scalar one), so the same bits.
            for j in 0..n_rays {
                let (a, c) = (pa[j], pc[j]);
                let q: [f64; 3] = std::array::from_fn(|i| a * cr[i] + c * cd[i] + cf[i]);
                let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
                for i in 0..3 {
                    let d = q[i] / n;
                    dd[i][j] = d;
                    ss[i][j] = 1.0 / d.abs();
                }
            }
            for (j, ray) in rays[..n_rays].iter_mut().enumerate() {
                ray.d = [dd[0][j], dd[1][j], dd[2][j]];
                ray.s = [ss[0][j], ss[1][j], ss[2][j]];
                self.ray_start(&octants, ray, vp.inv_r);
            }
            for ray in &rays[..n_rays] {
                let (d, t_lo) = (ray.d, ray.t_lo);
                let moving = |x: f64| x != 0.0 && !x.is_nan();
                let cast = if moving(d[0]) && moving(d[1]) && moving(d[2]) {
                    self.cast(&octants[ray.oct as usize], ray, vp.inv_r)
                } else {
                    Cast::General
                };
                let bit = match cast {
                    Cast::Hit(bit) => bit,
                    Cast::Miss => continue,
                    Cast::General => match self.first_hit_cell(&vp, d, t_lo) {
                        Some(g) => set.bit_of_cell(g),
                        None => continue,
                    },
                };
                let i = set.index_of_bit(bit) as usize;
                bits[i >> 6] |= 1u64 << (i & 63);
            }
        }
    }

    /// O(v) for `camera` (object-frame pose) by walking one ray per projected voxel (3D DDA,
    /// [`InverseCaster::first_hit`]); the same set as [`InverseCaster::observe`], slower.
    /// Kept as the literal form of SPEC §4 and as a cross-check.
    pub fn observe_walk(&self, camera: &Camera) -> Vec<u32> {
        let mut bits = vec![0u64; self.set.len().div_ceil(64)];
        self.observe_walk_into(camera, &mut bits);
        bitset_to_indices(&bits)
    }

    /// ORs the walked O(v) for `camera` into `bits` (see [`InverseCaster::observe_walk`]).
    pub fn observe_walk_into(&self, camera: &Camera, bits: &mut [u64]) {
        let set = self.set;
        if set.is_empty() {
            return;
        }
        assert!(bits.len() >= set.len().div_ceil(64), "bitset too short");
        let vp = self.planes(camera.center);
        let r = set.resolution();
        let k = &camera.intrinsics;
        for key in set.keys() {
            let Some((u, v)) = pixel_of(k, camera.to_camera(center_of(*key, r))) else {
                continue;
            };
            let d = pixel_ray_direction(camera, u, v);
            if let Some(g) = self.first_hit_cell(&vp, d, f64::NEG_INFINITY) {
                let i = set.index_of_bit(set.bit_of_cell(g)) as usize;
                bits[i >> 6] |= 1u64 << (i & 63);
            }
        }
    }
}
