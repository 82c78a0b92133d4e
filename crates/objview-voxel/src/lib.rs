//! Voxels and per-view visibility for the difficulty annotations of SPEC §4.
//!
//! - [`key`]: voxel keys at resolution r (half-open cells) and voxel centres.
//! - [`set`]: [`VoxelSet`], the sorted voxel set S_gt of a ground-truth cloud with O(1)
//!   membership and key → index lookups (indices address per-view bitsets).
//! - [`visibility`]: O(v) ⊆ S_gt per camera, modes `inverse` (ray walk, default) and `mesh`
//!   (rendered cloud), single views or batches, bitset helpers for unions and set cover.
//! - [`mod@bench`]: per-view timing of both modes (`objview bench render`).

pub mod bench;
pub mod error;
pub mod key;
pub mod set;
pub mod visibility;

pub use error::VoxelError;
pub use key::{center_of, key_of, VoxelKey, DEFAULT_RESOLUTION};
pub use set::VoxelSet;
pub use visibility::{
    bitset_count, bitset_to_indices, coverage_counts, observed_voxels, observed_voxels_mesh,
    pixel_ray_direction, to_bitset, union, union_bitsets, union_into, InverseCaster, Visibility,
    VisibilityMode, DEFAULT_MAX_RANGE,
};
