//! `completion-nbv` (placeholder while being written).

/// Default fraction of the best gain.
pub const DEFAULT_GAIN_RATIO: f64 = 0.95;
