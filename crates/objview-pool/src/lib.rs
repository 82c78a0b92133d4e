//! The object pool of SPEC §6.
//!
//! - [`build`]: raw assets → normalized pool (mesh + ground-truth cloud + manifest), filters.
//! - [`split`]: difficulty splits from annotations (two-stage rule, train subsets).
//! - [`stats`]: per-split counts, d_plan bucket histogram and means.

pub mod build;
pub mod error;
pub mod split;
pub mod stats;

pub use error::PoolError;

/// The objview version recorded in every output file.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
