//! Objects in batches, and their difficulty annotation (SPEC §4, §6).
//!
//! - [`inputs`]: mesh files, folders and split files → objects with uids; `--shard I/N`.
//! - [`jsonl`]: crash-safe, resumable JSON Lines results written in input order.
//! - [`batch`]: the batch driver: the parallel, resumable loop shared by batch commands
//!   (`annotate`, `run`, `pool build`) and its typed progress events.
//! - [`annotate`]: one object's saturation curve, r_vis, d_sat and exact d_plan.

pub mod annotate;
pub mod batch;
pub mod error;
pub mod inputs;
pub mod jsonl;

pub use annotate::{
    annotate_item, annotate_object, read_annotations, AnnotateSettings, Annotation, AnnotationSet, Failure,
    GridViews, StageTimings,
};
pub use batch::{
    drive, run_batch, run_batches, Batch, BatchStart, BatchSummary, ItemOutcome, ItemProgress, Progress,
    Silent,
};
pub use error::DatasetError;
pub use inputs::{read_split, resolve_inputs, ObjectRef, Shard};
pub use jsonl::{to_line, Existing, OrderedWriter, ResumableJsonl};

/// The objview version recorded in every output line.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
