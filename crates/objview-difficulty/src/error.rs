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
    CurveTooShort { len: usize },
    /// View-set sizes must be positive (ln N is taken).
    #[error("saturation curve point {index} has view count N = 0")]
    ZeroViewCount { index: usize },
    /// View-set sizes must be strictly increasing along the curve.
    #[error("saturation curve is not strictly increasing in N at point {index}: {prev} then {n}")]
    NonIncreasingN { index: usize, prev: usize, n: usize },
    /// A curve value is negative, NaN or infinite.
    #[error("saturation curve point {index} has invalid value Y = {y}")]
    InvalidY { index: usize, y: f64 },
    /// Y(N) counts voxels of S_gt, so it can never exceed |S_gt|.
    #[error("saturation curve point {index} has Y = {y} > |S_gt| = {s_gt}")]
    YExceedsGroundTruth { index: usize, y: f64, s_gt: usize },
    /// |S_gt| = 0: there is no surface to normalize by.
    #[error("the ground-truth voxel set S_gt is empty")]
    EmptyGroundTruth,
    /// y_max = 0: no view of any view set observed anything, the fit is undefined.
    #[error("no voxel is observed at any view-set size (y_max = 0); the saturation fit is undefined")]
    NothingObserved,
    /// A setting is out of its valid range.
    #[error("invalid setting {name} = {value}: {reason}")]
    InvalidSetting { name: &'static str, value: f64, reason: &'static str },
    /// A per-grid count vector does not match the grid.
    #[error("expected {expected} values (one per grid size), got {got}")]
    GridLength { expected: usize, got: usize },
    /// The universe filter "seen by at least k views" needs k ≥ 1.
    #[error("minimum number of covering views must be at least 1, got 0")]
    ZeroMinViews,
    /// Brute force is only for small instances.
    #[error("brute-force cover supports at most {max} views, the instance has {views}")]
    TooManyViews { views: usize, max: usize },
}
