//! Error type of the difficulty core: invalid curves, settings and cover instances.
//!
//! Every failure names the offending value so that a batch run can record why an object's
//! annotation is missing (SPEC §1: a batch goes on with the next object and records the failure).

use thiserror::Error;

/// Errors of the saturation fit and the set-cover routines.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DifficultyError {
    /// The saturation curve needs at least two points to have a shape.
    #[error("saturation curve has {len} point(s), at least 2 are needed")]
    CurveTooShort {
        /// Number of points the curve has.
        len: usize,
    },
    /// View-set sizes must be positive (ln N is taken).
    #[error("saturation curve point {index} has view count N = 0")]
    ZeroViewCount {
        /// Position of the offending point in the curve (0-based).
        index: usize,
    },
    /// View-set sizes must be strictly increasing along the curve.
    #[error("saturation curve is not strictly increasing in N at point {index}: {prev} then {n}")]
    NonIncreasingN {
        /// Position of the offending point in the curve (0-based).
        index: usize,
        /// View count N of the point before it.
        prev: usize,
        /// View count N of the offending point (not greater than `prev`).
        n: usize,
    },
    /// A curve value is negative, NaN or infinite.
    #[error("saturation curve point {index} has invalid value Y = {y}")]
    InvalidY {
        /// Position of the offending point in the curve (0-based).
        index: usize,
        /// Its value Y, voxels.
        y: f64,
    },
    /// Y(N) counts voxels of S_gt, so it can never exceed |S_gt|.
    #[error("saturation curve point {index} has Y = {y} > |S_gt| = {s_gt}")]
    YExceedsGroundTruth {
        /// Position of the offending point in the curve (0-based).
        index: usize,
        /// Its value Y, voxels.
        y: f64,
        /// |S_gt|, the number of ground-truth voxels.
        s_gt: usize,
    },
    /// |S_gt| = 0: there is no surface to normalize by.
    #[error("the ground-truth voxel set S_gt is empty")]
    EmptyGroundTruth,
    /// y_max = 0: no view of any view set observed anything, the fit is undefined.
    #[error("no voxel is observed at any view-set size (y_max = 0); the saturation fit is undefined")]
    NothingObserved,
    /// A setting is out of its valid range.
    #[error("invalid setting {name} = {value}: {reason}")]
    InvalidSetting {
        /// The setting's field name (e.g. `p_clamp`, `time_limit_s`).
        name: &'static str,
        /// The rejected value (integers converted to `f64`).
        value: f64,
        /// The valid range, in words.
        reason: &'static str,
    },
    /// A per-grid count vector does not match the grid.
    #[error("expected {expected} values (one per grid size), got {got}")]
    GridLength {
        /// Number of grid sizes (one value each).
        expected: usize,
        /// Number of values given.
        got: usize,
    },
    /// The universe filter "seen by at least k views" needs k ≥ 1.
    #[error("minimum number of covering views must be at least 1, got 0")]
    ZeroMinViews,
    /// Brute force is only for small instances.
    #[error("brute-force cover supports at most {max} views, the instance has {views}")]
    TooManyViews {
        /// Views of the instance.
        views: usize,
        /// Largest number of views brute force accepts.
        max: usize,
    },
}
