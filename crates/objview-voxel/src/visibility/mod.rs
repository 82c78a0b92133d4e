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
//!   walks, so that the sqrt/division chains of different voxels and rays overlap; the first
//!   loop vectorizes, and so do the set-ups' square roots and divisions, which run in
//!   structure-of-arrays loops (4 rays per vector square root or division, each lane rounded as
//!   the scalar operation: ≈1–2% of a view on the mug, 2026-12-05); same operations on the same
//!   values;
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
//!
//! Unions: where only |∪ O(v)| over a view set is needed (the annotation's saturation curve,
//! for every grid size but the planning set's 128), [`InverseCaster::observe_union_into`] casts
//! only the pixels whose rays may still see a voxel the union does not hold: the footprints of
//! the voxels not yet in it that have an exterior face neighbour on a face turned to the camera
//! (`prune`). The same union, bit for bit; on the mug's 3,032-view sweep 4.54 → 1.09 s on one
//! core (Intel Xeon VM, 2026-12-05; the threads of a sweep share its unions,
//! [`Visibility::union_all`]), because once a set's union holds the visible surface almost no
//! voxel is live (tammes-492: 12.4M rays → 0.13M).
//!
//! Layout: the modes, [`Visibility`] and the one-call functions are here; `caster` holds
//! [`InverseCaster`] and its entry points, `project` the first pass, `walk` the ray set-up and
//! walks, `prune` the rays a union can skip, `axis` the per-axis cell arithmetic, `field` the
//! distance field, `bitset` the bitset helpers.

mod axis;
mod bitset;
mod caster;
mod field;
mod project;
mod prune;
#[cfg(test)]
mod tests;
mod walk;

use crate::key::key_of;
use crate::set::VoxelSet;
use crate::VoxelError;
use objview_geom::Mesh;
use objview_render::Camera;
use rayon::prelude::*;
use std::str::FromStr;

pub use bitset::{
    bitset_count, bitset_to_indices, coverage_counts, to_bitset, union, union_bitsets, union_into,
};
pub use caster::InverseCaster;

/// SPEC §4 default maximum ray range (object units, along the ray from the camera centre).
pub const DEFAULT_MAX_RANGE: f64 = 6.0;

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
            VisibilityMode::Mesh => InverseCaster {
                set,
                field: Vec::new(),
                dims: set.grid_dims(),
                strides: [0; 3],
                max_range,
                open: std::sync::OnceLock::new(),
            },
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

    /// ORs O(v) for `camera` into the union `acc` (a bitset over set indices); in `inverse`
    /// mode through [`InverseCaster::observe_union_into`], which skips the rays that can only
    /// see voxels already in `acc`.
    pub fn observe_union_into(&self, camera: &Camera, acc: &mut [u64]) {
        match self.mode {
            VisibilityMode::Inverse => self.caster.observe_union_into(camera, acc),
            VisibilityMode::Mesh => union_into(acc, &self.observe_bitset(camera)),
        }
    }

    /// ∪ O(v) over `cameras` as a bitset over set indices, in parallel over views (rayon).
    /// The threads share the union: before each view a thread takes in what the others have
    /// found, and after it publishes what it added, so every view prunes against the most
    /// complete union at hand ([`Visibility::observe_union_into`]). Pruning against any part
    /// of the final union is exact, so the result is the same bits whatever the thread count
    /// and timing.
    pub fn union_all(&self, cameras: &[Camera]) -> Vec<u64> {
        use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
        let words = self.set().len().div_ceil(64);
        let shared: Vec<AtomicU64> = (0..words).map(|_| AtomicU64::new(0)).collect();
        cameras.par_iter().for_each_init(
            || vec![0u64; words],
            |acc, c| {
                for (a, s) in acc.iter_mut().zip(&shared) {
                    *a |= s.load(Relaxed);
                }
                self.observe_union_into(c, acc);
                for (a, s) in acc.iter().zip(&shared) {
                    if a & !s.load(Relaxed) != 0 {
                        s.fetch_or(*a, Relaxed);
                    }
                }
            },
        );
        shared.into_iter().map(AtomicU64::into_inner).collect()
    }

    /// As [`Visibility::observe_all`], as bitsets over set indices.
    pub fn observe_all_bitsets(&self, cameras: &[Camera]) -> Vec<Vec<u64>> {
        cameras.par_iter().map(|c| self.observe_bitset(c)).collect()
    }
}
