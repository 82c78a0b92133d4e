//! View sets and view spaces of objview.
//!
//! - [`viewset`]: view-direction sets (SPEC §3): the file format, the shipped `tammes-N` sets
//!   (built in) and the start view.
//! - [`tammes`]: the deterministic Tammes optimizer that generated the shipped sets other than
//!   the two official ones, and the best-known angle table used to check them.
//! - [`feasibility`]: view spaces (SPEC §5): the rule-file format and its evaluation on poses.

pub mod builtin;
pub mod error;
pub mod feasibility;
pub mod tammes;
pub mod viewset;

pub use error::ViewsError;
pub use feasibility::{InequalityTolerance, ViewSpace};
pub use tammes::{best_known_deg, generate, optimize, Effort};
pub use viewset::{start_pose, ViewSet, START_DIRECTION};
