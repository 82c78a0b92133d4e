//! Per-view visibility O(v) ⊆ S_gt (SPEC §4), in two modes.
//!
//! **`inverse`** (default, as in the reference implementation): for every voxel of S_gt, project
//! its centre into the camera; skip it when the camera-frame z ≤ 1e-9 or the pixel (floor of the
//! projected coordinates) is outside the image; otherwise cast a ray from the camera centre
//! through that pixel's centre through the voxel grid and add the first S_gt voxel it enters.
//! **`mesh`** (extension): O(v) = S_gt ∩ keys of the rendered observed cloud of v.
//!
//! Traversal conventions of `inverse` (where SPEC is silent; they follow the reference
//! implementation's OctoMap-style Amanatides–Woo walk unless noted):
//! - The ray is `o + t·d` with `o` the camera centre and `d` the *unit* direction through the
//!   pixel centre ([`pixel_ray_direction`]), so `t` is the Euclidean distance from the camera
//!   centre. A voxel counts if the walk enters it at `t ≤ max_range` (default 6.0). (The
//!   reference instead compares the entered voxel's *centre* distance with the range; the two
//!   differ only for voxels ~6 units away, never for unit-ball objects seen from radius 3.)
//! - Cell faces are the planes `x = k·r` (k·r evaluated in f64), cells half-open as in
//!   [`crate::key_of`]. The crossing time of a plane is `(k·r − o)·(1/d)`, evaluated directly
//!   (not accumulated), so the walk is reproducible exactly by an independent slab test.
//!   (`key_of` divides, `floor(p / r)`; the two partitions can disagree only for a coordinate
//!   within about an ulp of a plane.)
//! - The walk starts in the cell containing the camera centre (half-open test against the
//!   planes) and checks it first: a camera inside an S_gt voxel sees only that voxel.
//! - 6-connected walk: each step crosses one plane. When several axes cross at the same `t`
//!   (the ray passes exactly through a cell edge or corner) z steps first, then y, then x —
//!   the reference's order — so the walk visits the intermediate cells, which count as entered.
//! - An axis with `d = 0` (exactly) never steps.
//!
//! Speed (all exact: the walk's result never changes, only the work to get it):
//! - one ray per *pixel*, not per voxel: voxels whose centres fall in the same pixel cast the
//!   same ray and add the same voxel (a per-view pixel mask, one `u64` per 8×8 tile; rays are
//!   cast tile by tile, which also keeps consecutive walks in the same part of the grid);
//! - a per-view depth bound: for 4×4-pixel cells, a distance below which no voxel box whose
//!   conservative projected footprint reaches the cell can be entered; a ray starts its walk
//!   there (after all plane crossings strictly before it) instead of at the camera;
//! - otherwise the walk starts where the ray enters the set's grid box (the box has an empty
//!   one-voxel margin and nothing of S_gt lies outside it);
//! - it leaps over empty space with a Chebyshev distance field (a cell at distance D has an
//!   empty `(2D−1)³` neighbourhood): the leap goes to the last cell before the ray leaves that
//!   empty cube, and the walk resumes there with the crossings at the exit instant still to
//!   do, so the tie order is kept;
//! - the walk of a ray with no zero direction component runs in mirrored coordinates in which
//!   every axis steps up (bit-identical crossing times; see `InverseCaster::cast`), with one
//!   range test per step;
//! - `f64::floor` is avoided in hot paths (it is a libm call on baseline x86-64);
//! - latency hiding: the first pass computes each chunk of 64 voxels' projections in a
//!   branch-free loop before the data-dependent updates, and the second pass computes each
//!   tile's ray set-ups (direction, reciprocals, grid-box entry/exit, start cell) before its
//!   walks, so that the sqrt/division chains of different voxels and rays overlap (and the
//!   first loop vectorizes); same operations on the same values;
//! - on x86-64 CPUs with AVX2 and POPCNT (detected at run time) the same code is compiled for
//!   them (wider vectors, hardware popcount in the rank lookups); FMA is not enabled, so every
//!   IEEE operation and rounding is the same.
//!
//! On the `objview bench render` object (built-in `mug`, 98 128 triangles, |S_gt| = 32 043, 16
//! views of tammes-128) `inverse` costs ≈17.8 M instructions per view on one core
//! (`examples/inverse_views.rs` under callgrind on the AVX2 path; ≈38 M with one full walk per
//! voxel): ≈5.2 M in the walks after their start (`cast`, `leap`), the rest in the first pass
//! and the batched ray set-ups; ≈1.5 ms per view on an idle Sapphire Rapids core (was ≈2.05 ms
//! at ≈18.0 M instructions before the batching, which trades a few instructions for overlap).

use crate::key::{center_of, key_of};
use crate::set::VoxelSet;
use crate::VoxelError;
use objview_geom::Mesh;
use objview_render::Camera;
use rayon::prelude::*;
use std::str::FromStr;

/// SPEC §4 default maximum ray range (object units, along the ray from the camera centre).
pub const DEFAULT_MAX_RANGE: f64 = 6.0;

/// Distance-field cap: cells farther than this from S_gt store `FIELD_CAP + 1`.
const FIELD_CAP: u8 = 30;
/// Smallest stored distance at which the walk leaps instead of stepping.
const LEAP_MIN: u8 = 4;
/// Leaps over cubes of at most this Chebyshev radius advance crossing by crossing.
const SMALL_LEAP: usize = 2;

/// How O(v) is computed (SPEC §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum VisibilityMode {
    /// Voxel-centre projection + first-voxel ray walk (the reference implementation's rule).
    #[default]
    Inverse,
    /// S_gt ∩ voxel keys of the rendered observed point cloud.
    Mesh,
}

impl VisibilityMode {
    /// The setting name: `"inverse"` or `"mesh"`.
    pub fn name(self) -> &'static str {
        match self {
            VisibilityMode::Inverse => "inverse",
            VisibilityMode::Mesh => "mesh",
        }
    }
}

impl std::fmt::Display for VisibilityMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for VisibilityMode {
    type Err = VoxelError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "inverse" => Ok(VisibilityMode::Inverse),
            "mesh" => Ok(VisibilityMode::Mesh),
            other => Err(VoxelError::UnknownMode(other.to_string())),
        }
    }
}

/// Unit object-frame direction of the ray from the camera centre through the centre of pixel
/// `(u, v)`: [`Camera::pixel_ray_object`] divided by its Euclidean norm.
#[inline]
pub fn pixel_ray_direction(camera: &Camera, u: u32, v: u32) -> [f64; 3] {
    let q = camera.pixel_ray_object(u, v);
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
    [q[0] / n, q[1] / n, q[2] / n]
}

/// The `inverse`-mode engine for one S_gt: the set plus its Chebyshev distance field.
/// Build it once per object and query it for every view (it is `Sync`).
#[derive(Debug, Clone)]
pub struct InverseCaster<'a> {
    set: &'a VoxelSet,
    /// Chebyshev distance (in cells) from each grid cell to the nearest S_gt cell, 0 on S_gt,
    /// `FIELD_CAP + 1` beyond the cap. Layout `(x·ny + y)·nz + z`.
    field: Vec<u8>,
    dims: [usize; 3],
    strides: [usize; 3],
    max_range: f64,
}

/// Outcome of [`InverseCaster::cast`].
enum Cast {
    /// The bitmap bit position of the first S_gt voxel entered.
    Hit(usize),
    /// No S_gt voxel is entered within range.
    Miss,
    /// Not handled by the fast walk: use [`InverseCaster::first_hit_cell`].
    General,
}

/// One ray of [`InverseCaster::observe_into`] and its start state for [`InverseCaster::cast`]
/// (see [`InverseCaster::ray_start`]).
#[derive(Clone, Copy, Default)]
struct Ray {
    /// Unit direction.
    d: [f64; 3],
    /// Lower bound of the entry time of any S_gt box (the depth bound).
    t_lo: f64,
    /// `|d|` and `1/|d|` per axis.
    ad: [f64; 3],
    s: [f64; 3],
    /// Grid-box entry and exit times in the octant's walk coordinates.
    t_in: f64,
    t_out: f64,
    /// Start cell (walk coordinates) and its next crossing time per axis.
    h: [usize; 3],
    tn: [f64; 3],
    /// Octant index (bit a set: the ray moves down axis a).
    oct: u8,
}

/// Per-view constants of [`InverseCaster::cast`] for one octant of ray directions (which axes
/// the ray moves down, walked in mirrored coordinates h = n − 1 − g).
struct Octant<'v> {
    /// Per axis, the plane offsets in walk order: [`ViewPlanes`]' `planes` or `mirror`.
    pl: [&'v [f64]; 3],
    /// Per axis, the first and last of those planes (the grid box).
    box0: [f64; 3],
    box1: [f64; 3],
    /// `next_up(max_range)`: a crossing at or after it is out of range.
    past_range: f64,
    /// Field index of walk cell h: `fbase + Σ h[a]·fstep[a]` (wrapping, so that a negative
    /// step is a two's-complement one).
    fstep: [usize; 3],
    fbase: usize,
    /// Bitmap bit position of walk cell h, likewise.
    bstep: [usize; 3],
    bbase: usize,
}

/// Per-view constants: plane offsets `k·r − o` for every grid plane, per axis, and the same
/// planes mirrored (`mirror[a][j] = −planes[a][n − j]`), which let a ray moving down an axis
/// be walked as one moving up (see [`InverseCaster::cast`]).
struct ViewPlanes {
    planes: [Vec<f64>; 3],
    mirror: [Vec<f64>; 3],
    /// 1/r, for start-cell guesses.
    inv_r: f64,
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
        InverseCaster { set, field: distance_field(set), dims, strides, max_range }
    }

    /// The set this caster walks.
    pub fn set(&self) -> &'a VoxelSet {
        self.set
    }

    /// The maximum ray range.
    pub fn max_range(&self) -> f64 {
        self.max_range
    }

    fn planes(&self, origin: [f64; 3]) -> ViewPlanes {
        let r = self.set.resolution();
        let g0 = self.set.grid_origin();
        let planes = std::array::from_fn(|a| {
            (0..=self.dims[a]).map(|g| (g0[a] as f64 + g as f64) * r - origin[a]).collect::<Vec<f64>>()
        });
        let mirror = std::array::from_fn(|a| planes[a].iter().rev().map(|&p| -p).collect());
        ViewPlanes { planes, mirror, inv_r: 1.0 / r }
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
        self.observe_body(camera, bits)
    }

    /// [`InverseCaster::observe_into`] compiled for AVX2 and POPCNT (selected at run time):
    /// wider vectors in the first pass and a hardware popcount in the rank lookups. The same
    /// source, so the same IEEE operations per value (FMA, which would change roundings, is
    /// not enabled, and the compiler never contracts without it), hence the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    fn observe_avx2(&self, camera: &Camera, bits: &mut [u64]) {
        self.observe_body(camera, bits)
    }

    /// The body of [`InverseCaster::observe_into`].
    #[inline(always)]
    fn observe_body(&self, camera: &Camera, bits: &mut [u64]) {
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
        let global_min = self.project_voxels(camera, &mut cell_min, &mut mask);
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
                let ray = &mut rays[n_rays];
                ray.t_lo = fmin(cell_min[(v / CELL) * cw + u / CELL], global_min);
                // `pixel_ray_direction` with the per-pixel divisions tabulated (same values).
                let (a, c) = (qu[u], qv[v]);
                let q: [f64; 3] = std::array::from_fn(|i| a * cr[i] + c * cd[i] + cf[i]);
                let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
                ray.d = [q[0] / n, q[1] / n, q[2] / n];
                n_rays += 1;
            }
            for ray in &mut rays[..n_rays] {
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

    /// The set-up of [`InverseCaster::cast`] for `ray` (whose `d` and `t_lo` are set): its
    /// octant, reciprocals, grid-box entry and exit times, start time and start cell. The
    /// start is meaningful only for a ray that `cast` walks (no zero or NaN direction
    /// component, not rejected by the entry/exit tests); for any other it is some in-range
    /// cell, unused.
    #[inline(always)]
    fn ray_start(&self, octants: &[Octant<'_>; 8], ray: &mut Ray, inv_r: f64) {
        let d = ray.d;
        let ad = [d[0].abs(), d[1].abs(), d[2].abs()];
        let s = [1.0 / ad[0], 1.0 / ad[1], 1.0 / ad[2]];
        let oct = (d[0] < 0.0) as usize | ((d[1] < 0.0) as usize) << 1 | ((d[2] < 0.0) as usize) << 2;
        let o = &octants[oct];
        let (b0, b1) = (o.box0, o.box1);
        let t_in = fmax(fmax(b0[0] * s[0], b0[1] * s[1]), b0[2] * s[2]);
        let t_out = fmin(fmin(b1[0] * s[0], b1[1] * s[1]), b1[2] * s[2]);
        // Nothing is entered before t_lo: the state after every crossing at t < t_lo; else
        // the state after every crossing at t ≤ t_in.
        let t_lo = ray.t_lo;
        let t0 = if t_lo > t_in && t_lo > 0.0 { t_lo } else { next_up(t_in) };
        for a in 0..3 {
            (ray.h[a], ray.tn[a]) = start_cell(o.pl[a], s[a], ad[a], inv_r, t0);
        }
        ray.ad = ad;
        ray.s = s;
        ray.t_in = t_in;
        ray.t_out = t_out;
        ray.oct = oct as u8;
    }

    /// The first pass of [`InverseCaster::observe_into`]: marks each voxel's pixel in `mask`
    /// and lowers `cell_min` (per [`CELL`]×[`CELL`]-pixel cell) over each voxel's conservative
    /// footprint to the distance below which its box cannot be entered; returns that distance's
    /// minimum over the voxels whose footprint is unbounded (boxes reaching the camera plane),
    /// which bounds every cell.
    #[inline(always)]
    fn project_voxels(&self, camera: &Camera, cell_min: &mut [f64], mask: &mut [u64]) -> f64 {
        const B: i32 = BLOCK as i32;
        let set = self.set;
        let r = set.resolution();
        let k = &camera.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let mtw = w.div_ceil(TILE);
        let (tw, th) = (w.div_ceil(CELL), h.div_ceil(CELL));
        let mut global_min = f64::INFINITY;
        let rho = 0.5 * 3f64.sqrt() * r; // circumradius of a voxel box
        let z_foot = rho * 1.000_001 + 1e-9;
        let (wf, hf) = (w as f64, h as f64);
        let (afx, afy) = (k.fx.abs() * (1.0 + 1e-9), k.fy.abs() * (1.0 + 1e-9));
        let inv_cell = 1.0 / CELL as f64; // exact: CELL is a power of two
        let (twi, thi) = (tw as i32, th as i32);
        let mut block_min = vec![f64::INFINITY; tw * th];
        // Half-widths (pixels) below which a footprint spans less than B − 1 cells.
        let span = 0.5 * (B - 1) as f64 * CELL as f64 * (1.0 - 1e-9);
        // Per chunk of voxels, the arithmetic runs first in a branch-free loop (which the
        // compiler vectorizes; the same IEEE operations per voxel, so the same values), then
        // the data-dependent updates.
        const CHUNK: usize = 64;
        let mut vals = [[0.0f64; 5]; CHUNK];
        for keys in set.keys().chunks(CHUNK) {
            for (val, key) in vals.iter_mut().zip(keys) {
                let pc = camera.to_camera(center_of(*key, r));
                let z = pc[2];
                // `pixel_of` inlined: the same `Intrinsics::project` arithmetic, so the same
                // pixel.
                let (uc, vc) = (k.fx * pc[0] / z + k.cx, k.fy * pc[1] / z + k.cy);
                let dist = (pc[0] * pc[0] + pc[1] * pc[1] + z * z).sqrt();
                // Used only where z > z_foot (see below).
                let hr = rho * dist / (z * (z - rho));
                *val = [z, uc, vc, dist, hr];
            }
            for &[z, uc, vc, dist, hr] in &vals[..keys.len()] {
                if z > 1e-9 && uc >= 0.0 && vc >= 0.0 && uc < wf && vc < hf {
                    // In [0, w) × [0, h): truncation is the floor.
                    let (u, v) = (uc as i64 as usize, vc as i64 as usize);
                    mask[(v / TILE) * mtw + u / TILE] |= 1u64 << ((v % TILE) * TILE + u % TILE);
                }
                let near = dist - rho;
                let near = near - 1e-9 * near.abs() - 1e-12;
                if z <= z_foot || z.is_nan() {
                    if near < global_min {
                        global_min = near;
                    }
                    continue;
                }
                // Every point q of the ball B(pc, ρ) (which holds the box) has
                // |q_x/q_z − x/z| = |z·δ_x − x·δ_z| / (z·q_z) ≤ ρ·|pc| / (z·(z − ρ)), δ = q − pc
                // (Cauchy–Schwarz, q_z ≥ z − ρ > 0); same for y. A ray through a pixel centre that
                // meets the box does so at a point projecting to that centre, so the centre lies
                // within this half-width (plus one pixel of rounding margin) of the projected voxel
                // centre.
                let (hu, hv) = (afx * hr + 1.0, afy * hr + 1.0);
                // Cells whose pixel centres u + 0.5 can lie in [uc − hu, uc + hu]: from a0 to a1
                // (floors) below.
                let (a0, b0) = ((uc - hu - 0.5) * inv_cell, (vc - hv - 0.5) * inv_cell);
                if a0 >= 0.0 && b0 >= 0.0 && hu < span && hv < span {
                    // Common case: a0, b0 ≥ 0, so truncation is the floor, and the footprint spans
                    // less than B − 1 cells, so a1 < ⌊a0⌋ + B (same for b): it lies in the B×B
                    // block from (⌊a0⌋, ⌊b0⌋). Blocks reaching past the image are clipped below.
                    let (tu0, tv0) = (a0 as i32, b0 as i32);
                    if tu0 < twi && tv0 < thi {
                        let m = &mut block_min[tv0 as usize * tw + tu0 as usize];
                        *m = fmin(*m, near);
                    }
                    continue;
                }
                // Truncation instead of floor: it only differs below 0, where the clamp (or an
                // extra, harmless cell) absorbs it.
                let tu0 = (((uc - hu - 0.5) * inv_cell) as i32).max(0);
                let tu1 = (((uc + hu - 0.5) * inv_cell) as i32).min(twi - 1);
                let tv0 = (((vc - hv - 0.5) * inv_cell) as i32).max(0);
                let tv1 = (((vc + hv - 0.5) * inv_cell) as i32).min(thi - 1);
                if tu1 < tu0 || tv1 < tv0 {
                    continue; // the footprint misses the image
                }
                if tu1 - tu0 < B && tv1 - tv0 < B {
                    // Within the B×B cells from (tu0, tv0): one update here, spread below.
                    let m = &mut block_min[tv0 as usize * tw + tu0 as usize];
                    *m = fmin(*m, near);
                    continue;
                }
                for tv in tv0..=tv1 {
                    for m in &mut cell_min[tv as usize * tw..][tu0 as usize..=tu1 as usize] {
                        *m = fmin(*m, near);
                    }
                }
            }
        }
        // Spread each B×B block's bound over its cells: cell (i, j) takes the minimum over the
        // blocks starting at (i − B + 1..=i, j − B + 1..=j).
        let spread = |src: &[f64], dst: &mut [f64], n: usize, stride: usize, lines: usize, lstride: usize| {
            for l in 0..lines {
                let at = |i: usize| l * lstride + i * stride;
                for i in 0..n {
                    let mut m = src[at(i)];
                    for j in 1..BLOCK.min(i + 1) {
                        m = fmin(m, src[at(i - j)]);
                    }
                    dst[at(i)] = m;
                }
            }
        };
        let mut rows = vec![f64::INFINITY; tw * th];
        spread(&block_min, &mut rows, tw, 1, th, tw);
        spread(&rows, &mut block_min, th, tw, tw, 1);
        for (m, b) in cell_min.iter_mut().zip(&block_min) {
            *m = fmin(*m, *b);
        }
        global_min
    }

    /// The [`Octant`] of direction-sign pattern `m` (bit a set: the ray moves down axis a).
    fn octant<'v>(&self, vp: &'v ViewPlanes, m: usize) -> Octant<'v> {
        let ny = self.dims[1];
        let rb = self.set.row_words() * 64;
        let fs = self.strides;
        let bs = [ny * rb, rb, 1];
        let neg = |a: usize| m >> a & 1 == 1;
        let step = |s: [usize; 3], a: usize| if neg(a) { s[a].wrapping_neg() } else { s[a] };
        let base = |s: [usize; 3]| (0..3).filter(|&a| neg(a)).map(|a| (self.dims[a] - 1) * s[a]).sum();
        let pl: [&[f64]; 3] =
            std::array::from_fn(|a| if neg(a) { &vp.mirror[a][..] } else { &vp.planes[a][..] });
        Octant {
            pl,
            box0: std::array::from_fn(|a| pl[a][0]),
            box1: std::array::from_fn(|a| pl[a][self.dims[a]]),
            past_range: next_up(self.max_range),
            fstep: std::array::from_fn(|a| step(fs, a)),
            fbase: base(fs),
            bstep: std::array::from_fn(|a| step(bs, a)),
            bbase: base(bs),
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

    /// [`InverseCaster::first_hit_cell`] for a ray with no zero direction component in
    /// octant `o`, in cheaper bookkeeping: the bitmap bit of the hit, a miss, or
    /// [`Cast::General`] where the walk starts in the camera's cell (the caller falls back).
    ///
    /// Exactness (the same cells visited in the same order, so the same answer):
    /// - An axis the ray moves down (d < 0) is walked in mirrored coordinates — cell
    ///   h = n − 1 − g, planes `P[j] = −p[n − j]` ([`ViewPlanes`]), s = 1/(−d) — so every axis
    ///   steps +1. IEEE division and multiplication are symmetric in sign, so s = −(1/d) and
    ///   each crossing time `P[j]·s` equals the original `p[n − j]·(1/d)` bit for bit: the walk
    ///   sees the same times and compares them in the same tie order.
    /// - The start state "after every crossing at t ≤ t_in" is the state after every crossing
    ///   at t < next_up(t_in); [`start_cell`] finds the same unique cell as [`cell_at`].
    /// - Instead of testing `t > max_range` and leaving the grid separately, a step stops when
    ///   its crossing time reaches `min(t_out, next_up(max_range))`, t_out the exit time of
    ///   the grid box. Before t_out no crossing leaves the grid (crossing times are monotone in
    ///   the plane index), so the walks agree; at the first crossing at t ≥ t_out the exit
    ///   axis is already in its last layer (its previous plane is crossed strictly earlier),
    ///   which is the empty margin, so from there the original walk only visits empty cells
    ///   until it leaves the grid: a miss either way.
    /// - Leaps are those of `first_hit_cell`, mirrored the same way.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn cast(&self, o: &Octant<'_>, ray: &Ray, inv_r: f64) -> Cast {
        let tmax = self.max_range;
        let [px, py, pz] = o.pl;
        let (ad, [sx, sy, sz]) = (ray.ad, ray.s);
        let (t_in, t_out, t_lo) = (ray.t_in, ray.t_out, ray.t_lo);
        if t_in >= t_out || t_out <= 0.0 || t_in > tmax || t_lo >= t_out || t_lo > tmax {
            return Cast::Miss;
        }
        if t_in < 0.0 && t_lo <= 0.0 {
            return Cast::General; // starts in the camera's cell
        }
        let ([mut hx, mut hy, mut hz], [mut tx, mut ty, mut tz]) = (ray.h, ray.tn);
        let lim = fmin(t_out, o.past_range);
        let [fx, fy, fz] = o.fstep;
        let at = |base: usize, st: [usize; 3], h: [usize; 3]| {
            base.wrapping_add(h[0].wrapping_mul(st[0]))
                .wrapping_add(h[1].wrapping_mul(st[1]))
                .wrapping_add(h[2].wrapping_mul(st[2]))
        };
        let mut idx = at(o.fbase, o.fstep, [hx, hy, hz]);
        let field = &self.field[..];
        loop {
            let dv = field[idx];
            if dv == 0 {
                return Cast::Hit(at(o.bbase, o.bstep, [hx, hy, hz]));
            }
            if dv >= LEAP_MIN {
                let mut h = [hx, hy, hz];
                let mut tn = [tx, ty, tz];
                if !self.leap(&o.pl, [sx, sy, sz], ad, inv_r, (dv - 1) as usize, &mut h, &mut tn) {
                    return Cast::Miss;
                }
                [hx, hy, hz] = h;
                [tx, ty, tz] = tn;
                idx = at(o.fbase, o.fstep, h);
            }
            // One Amanatides–Woo step; ties: z, then y, then x.
            if tz <= ty && tz <= tx {
                if tz >= lim {
                    return Cast::Miss;
                }
                hz += 1;
                tz = pz[hz + 1] * sz;
                idx = idx.wrapping_add(fz);
            } else if ty <= tx {
                if ty >= lim {
                    return Cast::Miss;
                }
                hy += 1;
                ty = py[hy + 1] * sy;
                idx = idx.wrapping_add(fy);
            } else {
                if tx >= lim {
                    return Cast::Miss;
                }
                hx += 1;
                tx = px[hx + 1] * sx;
                idx = idx.wrapping_add(fx);
            }
        }
    }

    /// The leap of [`InverseCaster::first_hit_cell`] in [`InverseCaster::cast`]'s coordinates:
    /// the cells within Chebyshev radius `rad` of `h` are empty; move to the last cell before
    /// the ray leaves that cube. `false` when that is beyond the range.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn leap(
        &self,
        pl: &[&[f64]; 3],
        s: [f64; 3],
        ad: [f64; 3],
        inv_r: f64,
        rad: usize,
        h: &mut [usize; 3],
        tn: &mut [f64; 3],
    ) -> bool {
        let dims = self.dims;
        let mut te = f64::INFINITY;
        for a in 0..3 {
            te = te.min(pl[a][(h[a] + rad + 1).min(dims[a])] * s[a]);
        }
        if te > self.max_range {
            return false;
        }
        for a in 0..3 {
            if rad <= SMALL_LEAP {
                // Short leap: advance crossing by crossing (cheap, no guess).
                while tn[a] < te {
                    h[a] += 1;
                    tn[a] = pl[a][h[a] + 1] * s[a];
                }
            } else {
                h[a] = up_cell(pl[a], s[a], ad[a], inv_r, te, h[a], (h[a] + rad).min(dims[a] - 1));
                tn[a] = pl[a][h[a] + 1] * s[a];
            }
        }
        true
    }

    /// The grid cell of the first S_gt voxel the ray from the view origin along unit `d`
    /// enters, given that no S_gt box is entered before `t_lo` (a lower bound; −∞ if none).
    #[inline]
    fn first_hit_cell(&self, vp: &ViewPlanes, d: [f64; 3], t_lo: f64) -> Option<[usize; 3]> {
        let dims = self.dims;
        let pl = &vp.planes;
        let tmax = self.max_range;
        let mut inv = [0.0f64; 3];
        let mut step = [0i8; 3];
        let mut t_in = f64::NEG_INFINITY;
        let mut t_out = f64::INFINITY;
        for a in 0..3 {
            let n = dims[a];
            if d[a] > 0.0 {
                inv[a] = 1.0 / d[a];
                step[a] = 1;
                t_in = t_in.max(pl[a][0] * inv[a]);
                t_out = t_out.min(pl[a][n] * inv[a]);
            } else if d[a] < 0.0 {
                inv[a] = 1.0 / d[a];
                step[a] = -1;
                t_in = t_in.max(pl[a][n] * inv[a]);
                t_out = t_out.min(pl[a][0] * inv[a]);
            } else if !(pl[a][0] <= 0.0 && 0.0 < pl[a][n]) {
                return None; // parallel to this slab and outside it
            } else if d[a].is_nan() {
                return None;
            }
        }
        // The box boundary layer is empty: grazing rays (t_in == t_out) see nothing.
        if t_in >= t_out || t_out <= 0.0 || t_in > tmax || t_lo >= t_out || t_lo > tmax {
            return None;
        }
        let r = self.set.resolution();
        let mut g = [0usize; 3];
        let mut tn = [f64::INFINITY; 3];
        let start_inside = t_in < 0.0 && t_lo <= 0.0;
        let jump = t_lo > t_in && t_lo > 0.0;
        for a in 0..3 {
            let n = dims[a];
            let p = &pl[a];
            g[a] = if step[a] == 0 || start_inside {
                // The cell containing the camera centre: p[g] ≤ 0 < p[g+1].
                camera_cell(p, r, n)
            } else if jump {
                // Nothing is entered before t_lo: the state after every crossing at t < t_lo.
                cell_at::<false>(p, inv[a], step[a], d[a], r, t_lo, 0, n - 1)
            } else {
                // The state after every crossing at t ≤ t_in.
                cell_at::<true>(p, inv[a], step[a], d[a], r, t_in, 0, n - 1)
            };
            tn[a] = next_crossing(p, inv[a], step[a], g[a]);
        }
        let mut idx = g[0] * self.strides[0] + g[1] * self.strides[1] + g[2];
        let field = &self.field[..];
        loop {
            let dv = field[idx];
            if dv == 0 {
                return Some(g);
            }
            if dv >= LEAP_MIN {
                // Cells within Chebyshev radius `rad` of g are empty: go to the last cell
                // before the ray leaves that cube.
                let rad = (dv - 1) as usize;
                let mut te = f64::INFINITY;
                for a in 0..3 {
                    if step[a] > 0 {
                        te = te.min(pl[a][(g[a] + rad + 1).min(dims[a])] * inv[a]);
                    } else if step[a] < 0 {
                        te = te.min(pl[a][g[a].saturating_sub(rad)] * inv[a]);
                    }
                }
                if te > tmax {
                    return None;
                }
                if rad <= SMALL_LEAP {
                    // Short leap: advance each axis crossing by crossing (cheap, no guess).
                    for a in 0..3 {
                        if step[a] > 0 {
                            while tn[a] < te {
                                g[a] += 1;
                                tn[a] = pl[a][g[a] + 1] * inv[a];
                            }
                        } else if step[a] < 0 {
                            while tn[a] < te {
                                g[a] -= 1;
                                tn[a] = pl[a][g[a]] * inv[a];
                            }
                        }
                    }
                } else {
                    for a in 0..3 {
                        let (lo, hi) = match step[a] {
                            1 => (g[a], (g[a] + rad).min(dims[a] - 1)),
                            -1 => (g[a].saturating_sub(rad), g[a]),
                            _ => continue,
                        };
                        g[a] = cell_at::<false>(&pl[a], inv[a], step[a], d[a], r, te, lo, hi);
                        tn[a] = next_crossing(&pl[a], inv[a], step[a], g[a]);
                    }
                }
                idx = g[0] * self.strides[0] + g[1] * self.strides[1] + g[2];
            }
            // One Amanatides–Woo step; ties: z, then y, then x.
            let a = if tn[2] <= tn[1] && tn[2] <= tn[0] {
                2
            } else if tn[1] <= tn[0] {
                1
            } else {
                0
            };
            if tn[a] > tmax {
                return None;
            }
            if step[a] > 0 {
                g[a] += 1;
                if g[a] == dims[a] {
                    return None;
                }
                tn[a] = pl[a][g[a] + 1] * inv[a];
                idx += self.strides[a];
            } else {
                if g[a] == 0 {
                    return None;
                }
                g[a] -= 1;
                tn[a] = pl[a][g[a]] * inv[a];
                idx -= self.strides[a];
            }
        }
    }
}

/// The cell `g ∈ [0, n)` with `p[g] ≤ 0 < p[g+1]`, clamped (callers ensure it exists).
#[inline]
fn camera_cell(p: &[f64], r: f64, n: usize) -> usize {
    // A guess (truncation is a floor for the non-negative values that matter), then exact
    // fix-up against the planes.
    let mut g = ((-p[0] / r) as i64).clamp(0, n as i64 - 1) as usize;
    while g > 0 && p[g] > 0.0 {
        g -= 1;
    }
    while g + 1 < n && p[g + 1] <= 0.0 {
        g += 1;
    }
    g
}

/// [`objview_render::Intrinsics::pixel_of`] without `f64::floor` (a libm call on baseline
/// x86-64): for a projected coordinate `x`, `floor(x) ∈ [0, w)` ⟺ `0 ≤ x < w`, and then
/// truncation is the floor. Same result for every input (tested).
#[inline]
pub(crate) fn pixel_of(k: &objview_render::Intrinsics, p: [f64; 3]) -> Option<(u32, u32)> {
    let [u, v] = k.project(p)?;
    if u >= 0.0 && v >= 0.0 && u < k.width as f64 && v < k.height as f64 {
        Some((u as u32, v as u32))
    } else {
        None
    }
}

/// Tile size (pixels) of the per-view pixel mask: one `u64` per tile.
const TILE: usize = 8;
/// Cell size (pixels) of the per-view depth bound.
const CELL: usize = 4;
/// Voxels whose footprint spans at most `BLOCK` × `BLOCK` depth cells update one block entry,
/// spread over the cells afterwards.
const BLOCK: usize = 4;

/// Time of the next plane crossing out of cell `g` along an axis.
#[inline]
fn next_crossing(p: &[f64], inv: f64, step: i8, g: usize) -> f64 {
    match step {
        1 => p[g + 1] * inv,
        -1 => p[g] * inv,
        _ => f64::INFINITY,
    }
}

/// The walk's cell along one axis at time `t`: the state after every crossing at time ≤ t
/// (`INCLUSIVE`) or < t, searched in `[lo, hi]`. The crossing into cell g is at `p[g]·inv`
/// moving up and at `p[g+1]·inv` moving down; crossing times are monotone in g.
#[allow(clippy::too_many_arguments)]
#[inline]
fn cell_at<const INCLUSIVE: bool>(
    p: &[f64],
    inv: f64,
    step: i8,
    d: f64,
    r: f64,
    t: f64,
    lo: usize,
    hi: usize,
) -> usize {
    let done = |c: f64| if INCLUSIVE { c <= t } else { c < t };
    // Guess from the position (truncation; the fix-up below makes it exact).
    let mut g = (((t * d - p[0]) / r) as i64).clamp(lo as i64, hi as i64) as usize;
    if step > 0 {
        while g > lo && !done(p[g] * inv) {
            g -= 1;
        }
        while g < hi && done(p[g + 1] * inv) {
            g += 1;
        }
    } else {
        while g < hi && !done(p[g + 1] * inv) {
            g += 1;
        }
        while g > lo && done(p[g] * inv) {
            g -= 1;
        }
    }
    g
}

/// [`cell_at`] for an axis walked upwards (`p` increasing, crossing into cell g at `p[g]·s`,
/// `s` > 0; `ad` = |d|): the cell after every crossing at time < t, searched in `[lo, hi]`.
/// The crossing times are non-decreasing in g, so "crossed before t" holds for a prefix of
/// cells and the answer — the last crossed cell, clamped to `[lo, hi]` — is unique, whatever
/// the guess the fix-up loops start from. `t` and the plane times are never NaN.
#[inline(always)]
fn up_cell(p: &[f64], s: f64, ad: f64, inv_r: f64, t: f64, lo: usize, hi: usize) -> usize {
    let mut g = (((t * ad - p[0]) * inv_r) as i64).clamp(lo as i64, hi as i64) as usize;
    while g > lo && p[g] * s >= t {
        g -= 1;
    }
    while g < hi && p[g + 1] * s < t {
        g += 1;
    }
    g
}

/// [`up_cell`] over the whole axis (`p` holds the n + 1 planes of n cells) and the time of the
/// next crossing out of that cell, `p[g + 1]·s`: the same cell, with the common case — the
/// guess is right — checked by one pair of comparisons.
#[inline(always)]
fn start_cell(p: &[f64], s: f64, ad: f64, inv_r: f64, t: f64) -> (usize, f64) {
    let hi = p.len() - 2;
    let g = (((t * ad - p[0]) * inv_r) as i64).clamp(0, hi as i64) as usize;
    let w = &p[g..g + 2];
    let next = w[1] * s;
    if (g == 0 || w[0] * s < t) && (g == hi || next >= t) {
        return (g, next);
    }
    let g = up_cell(p, s, ad, inv_r, t, 0, hi);
    (g, p[g + 1] * s)
}

/// The smallest f64 above `x` (`f64::next_up`, newer than the MSRV); NaN and +∞ map to
/// themselves.
#[inline]
fn next_up(x: f64) -> f64 {
    if x.is_nan() || x == f64::INFINITY {
        x
    } else if x == 0.0 {
        f64::from_bits(1)
    } else if x > 0.0 {
        f64::from_bits(x.to_bits() + 1)
    } else {
        f64::from_bits(x.to_bits() - 1)
    }
}

/// `a.max(b)` for non-NaN operands without the NaN handling (`maxsd` alone). Which zero it
/// returns for ±0 may differ; callers only compare the result.
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// `a.min(b)` for non-NaN operands, as [`fmax`].
#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if a < b {
        a
    } else {
        b
    }
}

/// Chebyshev (L∞) distance transform of the set's occupancy grid, capped: repeated one-cell
/// dilations of the bitmap (shift-OR along z inside each row, OR of neighbouring rows along y
/// and x), recording the level at which each cell is first reached.
fn distance_field(set: &VoxelSet) -> Vec<u8> {
    let [nx, ny, nz] = set.grid_dims();
    let mut field = vec![FIELD_CAP + 1; nx * ny * nz];
    if set.is_empty() {
        return field;
    }
    let rw = set.row_words();
    let rows = nx * ny;
    // Valid-bit mask of the last word of a row.
    let tail = nz - (rw - 1) * 64;
    let last_mask = if tail == 64 { u64::MAX } else { (1u64 << tail) - 1 };
    let mut cur: Vec<u64> = set.bitmap().to_vec();
    let write_new = |field: &mut [u8], new: &[u64], level: u8| {
        for (wi, &w) in new.iter().enumerate() {
            let mut w = w;
            while w != 0 {
                let bit = wi * 64 + w.trailing_zeros() as usize;
                w &= w - 1;
                let (row, z) = (bit / (rw * 64), bit % (rw * 64));
                field[row * nz + z] = level;
            }
        }
    };
    write_new(&mut field, &cur, 0);
    let mut tmp = vec![0u64; cur.len()];
    let mut next = vec![0u64; cur.len()];
    for level in 1..=FIELD_CAP {
        // z: shift-OR inside each row, carrying across words.
        for row in 0..rows {
            let s = &cur[row * rw..(row + 1) * rw];
            for i in 0..rw {
                let mut w = s[i] | (s[i] << 1) | (s[i] >> 1);
                if i > 0 {
                    w |= s[i - 1] >> 63;
                }
                if i + 1 < rw {
                    w |= s[i + 1] << 63;
                }
                if i + 1 == rw {
                    w &= last_mask;
                }
                tmp[row * rw + i] = w;
            }
        }
        // y: OR of rows y−1, y, y+1 (same x).
        for x in 0..nx {
            for y in 0..ny {
                let base = (x * ny + y) * rw;
                for i in 0..rw {
                    let mut w = tmp[base + i];
                    if y > 0 {
                        w |= tmp[base - rw + i];
                    }
                    if y + 1 < ny {
                        w |= tmp[base + rw + i];
                    }
                    next[base + i] = w;
                }
            }
        }
        // x: OR of planes x−1, x, x+1.
        let plane = ny * rw;
        for x in 0..nx {
            for j in 0..plane {
                let mut w = next[x * plane + j];
                if x > 0 {
                    w |= next[(x - 1) * plane + j];
                }
                if x + 1 < nx {
                    w |= next[(x + 1) * plane + j];
                }
                tmp[x * plane + j] = w;
            }
        }
        // tmp = dilated; new cells = tmp & !cur.
        let mut any_new = false;
        for (n, (&d, &c)) in next.iter_mut().zip(tmp.iter().zip(&cur)) {
            *n = d & !c;
            any_new |= *n != 0;
        }
        if !any_new {
            break;
        }
        write_new(&mut field, &next, level);
        std::mem::swap(&mut cur, &mut tmp);
    }
    field
}

/// O(v) in `inverse` mode for one camera (object-frame pose; see [`Camera`]) as sorted unique
/// indices into `set`, with the default range. Builds the distance field on every call: for
/// many views build an [`InverseCaster`] once.
pub fn observed_voxels(set: &VoxelSet, camera: &Camera) -> Vec<u32> {
    InverseCaster::new(set).observe(camera)
}

/// O(v) in `mesh` mode: `set` ∩ voxel keys (at the set's resolution) of the observed cloud of
/// `mesh` rendered from `camera` (object frame, SPEC §2), as sorted unique indices into `set`.
pub fn observed_voxels_mesh(set: &VoxelSet, mesh: &Mesh, camera: &Camera) -> Vec<u32> {
    let frame = objview_render::render(mesh, camera);
    indices_of_points(set, &frame.observed_points())
}

/// Sorted unique indices of the set voxels containing any of `points` (object frame): the
/// second half of `mesh` mode, after rendering.
pub fn indices_of_points(set: &VoxelSet, points: &[[f64; 3]]) -> Vec<u32> {
    let r = set.resolution();
    let mut bits = vec![0u64; set.len().div_ceil(64)];
    for p in points {
        if let Some(i) = set.index_of(key_of(*p, r)) {
            bits[i >> 6] |= 1u64 << (i & 63);
        }
    }
    bitset_to_indices(&bits)
}

/// O(v) of one object in either mode: holds the set, the mesh (for `mesh` mode) and the
/// `inverse` engine, and answers single views or batches of views in parallel.
#[derive(Debug, Clone)]
pub struct Visibility<'a> {
    mode: VisibilityMode,
    mesh: &'a Mesh,
    caster: InverseCaster<'a>,
}

impl<'a> Visibility<'a> {
    /// Visibility of `set` (S_gt of `mesh`) in `mode` with the default range.
    pub fn new(set: &'a VoxelSet, mesh: &'a Mesh, mode: VisibilityMode) -> Visibility<'a> {
        Visibility::with_max_range(set, mesh, mode, DEFAULT_MAX_RANGE)
    }

    /// As [`Visibility::new`] with an explicit `inverse` ray range (object units).
    pub fn with_max_range(
        set: &'a VoxelSet,
        mesh: &'a Mesh,
        mode: VisibilityMode,
        max_range: f64,
    ) -> Visibility<'a> {
        let caster = match mode {
            VisibilityMode::Inverse => InverseCaster::with_max_range(set, max_range),
            // Mesh mode never walks rays: skip the distance field.
            VisibilityMode::Mesh => {
                InverseCaster { set, field: Vec::new(), dims: set.grid_dims(), strides: [0; 3], max_range }
            }
        };
        Visibility { mode, mesh, caster }
    }

    /// The mode.
    pub fn mode(&self) -> VisibilityMode {
        self.mode
    }

    /// The voxel set S_gt.
    pub fn set(&self) -> &'a VoxelSet {
        self.caster.set
    }

    /// O(v) for one camera (object frame) as a bitset over set indices.
    pub fn observe_bitset(&self, camera: &Camera) -> Vec<u64> {
        match self.mode {
            VisibilityMode::Inverse => self.caster.observe_bitset(camera),
            VisibilityMode::Mesh => {
                to_bitset(&observed_voxels_mesh(self.caster.set, self.mesh, camera), self.set().len())
            }
        }
    }

    /// O(v) for one camera as sorted unique set indices.
    pub fn observe(&self, camera: &Camera) -> Vec<u32> {
        bitset_to_indices(&self.observe_bitset(camera))
    }

    /// O(v) for every camera, in parallel over views (rayon); result `i` belongs to
    /// `cameras[i]` whatever the thread count.
    pub fn observe_all(&self, cameras: &[Camera]) -> Vec<Vec<u32>> {
        cameras.par_iter().map(|c| self.observe(c)).collect()
    }

    /// As [`Visibility::observe_all`], as bitsets over set indices.
    pub fn observe_all_bitsets(&self, cameras: &[Camera]) -> Vec<Vec<u64>> {
        cameras.par_iter().map(|c| self.observe_bitset(c)).collect()
    }
}

/// A bitset of `len` bits (`len.div_ceil(64)` words) with the given indices set.
/// Panics on an index ≥ `len`.
pub fn to_bitset(indices: &[u32], len: usize) -> Vec<u64> {
    let mut bits = vec![0u64; len.div_ceil(64)];
    for &i in indices {
        assert!((i as usize) < len, "index {i} out of range {len}");
        bits[i as usize >> 6] |= 1u64 << (i & 63);
    }
    bits
}

/// The set indices of a bitset, ascending.
pub fn bitset_to_indices(bits: &[u64]) -> Vec<u32> {
    let n: u32 = bits.iter().map(|w| w.count_ones()).sum();
    let mut out = Vec::with_capacity(n as usize);
    for (wi, &w) in bits.iter().enumerate() {
        let mut w = w;
        while w != 0 {
            out.push((wi * 64) as u32 + w.trailing_zeros());
            w &= w - 1;
        }
    }
    out
}

/// `acc |= other`, word by word (`other` may be shorter).
pub fn union_into(acc: &mut [u64], other: &[u64]) {
    for (a, b) in acc.iter_mut().zip(other) {
        *a |= *b;
    }
}

/// Union of sorted index lists, sorted unique.
pub fn union(lists: &[Vec<u32>]) -> Vec<u32> {
    let mut all: Vec<u32> = lists.iter().flatten().copied().collect();
    all.sort_unstable();
    all.dedup();
    all
}

/// Union of bitsets of `len` bits.
pub fn union_bitsets(sets: &[Vec<u64>], len: usize) -> Vec<u64> {
    let mut acc = vec![0u64; len.div_ceil(64)];
    for s in sets {
        union_into(&mut acc, s);
    }
    acc
}

/// For each of `len` voxels, the number of bitsets (views) containing it — for the SPEC §4
/// option of keeping only voxels seen by at least k views.
pub fn coverage_counts(sets: &[Vec<u64>], len: usize) -> Vec<u32> {
    let mut counts = vec![0u32; len];
    for s in sets {
        for i in bitset_to_indices(s) {
            counts[i as usize] += 1;
        }
    }
    counts
}

/// Number of set bits.
pub fn bitset_count(bits: &[u64]) -> usize {
    bits.iter().map(|w| w.count_ones() as usize).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_parse_and_display() {
        assert_eq!("inverse".parse::<VisibilityMode>().unwrap(), VisibilityMode::Inverse);
        assert_eq!("mesh".parse::<VisibilityMode>().unwrap(), VisibilityMode::Mesh);
        assert!("Mesh".parse::<VisibilityMode>().is_err());
        assert_eq!(VisibilityMode::default().to_string(), "inverse");
    }

    #[test]
    fn fast_pixel_of_matches_intrinsics() {
        use rand::{Rng, SeedableRng};
        let k = objview_render::Intrinsics::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut cases: Vec<[f64; 3]> = (0..200_000)
            .map(|_| [rng.gen_range(-1.5..1.5), rng.gen_range(-1.5..1.5), rng.gen_range(-0.5..3.0)])
            .collect();
        // Exactly on the image border and on pixel edges.
        for (u, v) in [(0.0, 0.0), (512.0, 3.0), (511.999_999, 0.0), (-1e-12, 5.0), (256.0, 512.0)] {
            cases.push([(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0]);
        }
        cases.push([0.0, 0.0, 1e-9]);
        cases.push([0.0, 0.0, 1.1e-9]);
        for p in cases {
            assert_eq!(pixel_of(&k, p), k.pixel_of(p), "{p:?}");
        }
    }

    #[test]
    fn bitset_helpers_roundtrip() {
        let a = vec![0u32, 5, 63, 64, 130];
        let b = to_bitset(&a, 131);
        assert_eq!(b.len(), 3);
        assert_eq!(bitset_to_indices(&b), a);
        assert_eq!(bitset_count(&b), 5);
        let c = to_bitset(&[1, 64, 129], 131);
        let u = union_bitsets(&[b, c], 131);
        assert_eq!(bitset_to_indices(&u), vec![0, 1, 5, 63, 64, 129, 130]);
        assert_eq!(union(&[vec![3, 1], vec![2, 3]]), vec![1, 2, 3]);
        let cov = coverage_counts(&[to_bitset(&[0, 2], 4), to_bitset(&[2, 3], 4), to_bitset(&[2], 4)], 4);
        assert_eq!(cov, vec![1, 0, 3, 1]);
    }

    #[test]
    fn next_up_is_the_next_float() {
        assert_eq!(next_up(1.0), 1.0 + f64::EPSILON);
        assert_eq!(next_up(0.0), f64::from_bits(1));
        assert_eq!(next_up(-0.0), f64::from_bits(1));
        assert_eq!(next_up(-1.0), -1.0 + f64::EPSILON / 2.0);
        assert_eq!(next_up(f64::MAX), f64::INFINITY);
        assert_eq!(next_up(f64::INFINITY), f64::INFINITY);
        assert_eq!(next_up(f64::NEG_INFINITY), -f64::MAX);
        assert!(next_up(f64::NAN).is_nan());
        for x in [2.5f64, -3.75, 1e-300, -1e-300, 6.0] {
            let y = next_up(x);
            assert!(y > x && (x + y) / 2.0 == x || (x + y) / 2.0 == y, "{x}");
        }
    }

    /// `up_cell` on mirrored planes finds the same cell as `cell_at` walking down, and on the
    /// planes themselves the same as `cell_at` walking up, for times on and around crossings.
    #[test]
    fn up_cell_matches_cell_at_both_ways() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let r = 0.02;
        for _ in 0..2000 {
            let n = rng.gen_range(3..40usize);
            let o: f64 = rng.gen_range(-1.0..1.0);
            let g0 = rng.gen_range(-30..10) as f64;
            let p: Vec<f64> = (0..=n).map(|g| (g0 + g as f64) * r - o).collect();
            let m: Vec<f64> = p.iter().rev().map(|&x| -x).collect();
            let d: f64 = rng.gen_range(0.01..1.0);
            let s = 1.0 / d;
            let mut times: Vec<f64> = p.iter().map(|&x| x * s).collect();
            times.extend((0..10).map(|_| rng.gen_range(-3.0..3.0)));
            for t in times.clone() {
                times.push(next_up(t));
            }
            for &t in &times {
                let (lo, hi) = (0, n - 1);
                let up = cell_at::<false>(&p, s, 1, d, r, t, lo, hi);
                assert_eq!(up_cell(&p, s, d, 1.0 / r, t, lo, hi), up, "up t {t}");
                let down = cell_at::<false>(&p, -s, -1, -d, r, t, lo, hi);
                assert_eq!(n - 1 - up_cell(&m, s, d, 1.0 / r, t, lo, hi), down, "down t {t}");
                let incl = cell_at::<true>(&p, s, 1, d, r, t, lo, hi);
                assert_eq!(up_cell(&p, s, d, 1.0 / r, next_up(t), lo, hi), incl, "inclusive t {t}");
                assert_eq!(start_cell(&p, s, d, 1.0 / r, t), (up, p[up + 1] * s), "start t {t}");
            }
        }
    }

    /// Brute-force Chebyshev distances on a small grid.
    #[test]
    fn distance_field_is_exact_chebyshev() {
        let keys = [[0, 0, 0], [7, 1, -3], [2, 9, 4], [-5, 3, 70]];
        let set = VoxelSet::from_keys(&keys, 0.1).unwrap();
        let f = distance_field(&set);
        let [nx, ny, nz] = set.grid_dims();
        let o = set.grid_origin();
        for x in 0..nx {
            for y in 0..ny {
                for z in 0..nz {
                    let k = [o[0] + x as i32, o[1] + y as i32, o[2] + z as i32];
                    let d = keys
                        .iter()
                        .map(|q| (0..3).map(|a| (q[a] - k[a]).abs()).max().unwrap())
                        .min()
                        .unwrap();
                    let want = d.min(FIELD_CAP as i32 + 1) as u8;
                    assert_eq!(f[(x * ny + y) * nz + z], want, "cell {k:?}");
                }
            }
        }
    }
}
