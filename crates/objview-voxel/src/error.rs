//! Errors of the voxel layer: bad resolutions, non-finite or out-of-range points, and grids too
//! large to allocate densely. Every error names the offending input so a batch can report it.

use thiserror::Error;

/// Why a voxel set (or a visibility computation) could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum VoxelError {
    /// The resolution must be finite and > 0.
    #[error("voxel resolution must be finite and > 0, got {0}")]
    BadResolution(f64),
    /// A point has a NaN or infinite coordinate.
    #[error("point {index} is not finite: {point:?}")]
    NonFinitePoint {
        /// Index of the point in the input.
        index: usize,
        /// The point.
        point: [f64; 3],
    },
    /// A point's key does not fit the i32 key range (with a margin).
    #[error("point {index} at {point:?} is too far from the origin for resolution {resolution}")]
    KeyOutOfRange {
        /// Index of the point in the input.
        index: usize,
        /// The point.
        point: [f64; 3],
        /// The voxel resolution.
        resolution: f64,
    },
    /// The dense occupancy grid over the set's bounding box would be too large.
    #[error("occupancy grid of {dims:?} cells exceeds the limit of {limit} cells")]
    GridTooLarge {
        /// Cells per axis of the bounding box.
        dims: [usize; 3],
        /// The largest allowed number of cells.
        limit: usize,
    },
    /// An unknown visibility mode name.
    #[error("unknown visibility mode {0:?} (expected \"inverse\" or \"mesh\")")]
    UnknownMode(String),
}
