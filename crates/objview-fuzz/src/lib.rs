//! objview-fuzz: seeded, time-bounded mutation fuzzing of every file loader of objview (mesh
//! formats, point clouds, view sets, rule files, split files, annotation and episode results).
//!
//! The contract under test: every loader, given any bytes, returns one clean (one-line) error
//! or a valid object — never a panic (not even one it catches itself), an abort, a hang or
//! unbounded memory. Each case runs in a child process under an address-space limit and a
//! wall-clock limit, so a crash is observed, classified and kept instead of taking the fuzzer
//! down.
//!
//! - [`kinds`]: the loaders under test and the validity checks of what they return;
//! - [`corpus`]: the built-in seed inputs (generated in code, deterministic);
//! - [`mutate`]: the seeded mutations (case `i` of a seed is always the same bytes);
//! - [`child`]: the child process that runs cases and reports each outcome as it goes;
//! - [`exec`]: the parent side (limits, batching, crash isolation, classification);
//! - [`fuzz`](mod@fuzz): campaigns (time budget, parallel children, de-duplication, shrinking,
//!   writing findings) and the replay of kept regression files;
//! - [`rng`]: the fixed random-number stream.
//!
//! The binary `objview-fuzz` is the entry point (`run`, `replay`, `one`, `gen`, `list`); the
//! tests under `tests/` replay `regressions/`, run a short seeded campaign, and prove with the
//! fake `test-*` kinds that each failure class is detected.

pub mod child;
pub mod corpus;
pub mod exec;
pub mod fuzz;
pub mod kinds;
pub mod mutate;
pub mod rng;

pub use exec::{Class, Limits, Outcome};
pub use fuzz::{fuzz, replay, Finding, Settings, Summary};
pub use kinds::Kind;

/// The regression folder of this crate (`crates/objview-fuzz/regressions`).
pub fn regressions_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("regressions")
}
