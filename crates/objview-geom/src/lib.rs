//! Geometry layer of objview: triangle meshes loaded from real asset formats, their
//! normalization to the unit ball (SPEC §1), ground-truth surface point clouds, camera poses
//! (SPEC §2) and the built-in procedural objects.
//!
//! Everything downstream (renderer, view sets, visibility, difficulty, episodes) consumes the
//! plain types defined here: [`Mesh`], [`Pose`] and point clouds as `Vec<[f64; 3]>`.

pub mod error;
pub mod fsutil;
pub mod hash;
pub mod limits;
pub mod mesh;
pub mod pose;
pub mod stats;

pub use error::GeomError;
pub use limits::Limits;
pub use mesh::{Appearance, Mesh};
pub use pose::Pose;

/// Crate version, recorded in every output file.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

pub mod cloud;
pub mod io;
pub mod normalize;
pub mod npy;
pub mod num;
pub mod synth;
#[cfg(test)]
pub(crate) mod test_support;
pub mod vec3;
pub mod write;
