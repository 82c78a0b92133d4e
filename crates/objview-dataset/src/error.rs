//! Error type of the batch layer: inputs that cannot be resolved, split files that do not parse,
//! result files that cannot be resumed, and per-object annotation failures.
//!
//! Every variant names the file (and where it applies the JSON field or line) and the reason, so
//! that a batch can record the failure of one object in its output and go on with the next.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of input resolution, JSON Lines I/O and annotation.
#[derive(Debug, Error)]
pub enum DatasetError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// An input path is neither a supported mesh file, a folder nor a split file (`.json`).
    #[error("{path}: not a mesh file ({expected}), a folder or a split file (.json)")]
    UnsupportedInput {
        /// The input path as given.
        path: PathBuf,
        /// The supported mesh extensions, for the message.
        expected: &'static str,
    },
    /// A split file is not a JSON array of objects with the required fields.
    #[error("{}: {}", .path.display(), one_line(.reason))]
    SplitFile {
        /// The split file.
        path: PathBuf,
        /// What is wrong with it (which entry or field).
        reason: String,
    },
    /// Two inputs resolve to the same object id.
    #[error(
        "duplicate object id '{}': {} and {}",
        one_line(.uid),
        one_line(&.first.display().to_string()),
        one_line(&.second.display().to_string())
    )]
    DuplicateUid {
        /// The object id both inputs resolve to.
        uid: String,
        /// The mesh file of the first input with this id.
        first: PathBuf,
        /// The mesh file of the second input with this id.
        second: PathBuf,
    },
    /// A `--shard I/N` argument is malformed.
    #[error("invalid shard '{0}': expected I/N with 0 <= I < N (e.g. 0/4)")]
    Shard(String),
    /// A complete line of a results file is not a JSON object with the key field.
    #[error(
        "{}: line {line}: {} (the file is not a results file of this command, or was edited)",
        .path.display(),
        one_line(.reason)
    )]
    CorruptLine {
        /// The results file.
        path: PathBuf,
        /// The offending line, counted from 1.
        line: usize,
        /// Why the line is unusable (not JSON, no key field, ...).
        reason: String,
    },
    /// `--gt-cloud-dir` has no cloud for this object.
    #[error(
        "no ground-truth cloud for '{}' in {} (looked for {}.pcd, .ply, .npy, .npz)",
        one_line(.uid),
        .dir.display(),
        one_line(.uid)
    )]
    MissingGtCloud {
        /// The object id whose cloud file was looked for.
        uid: String,
        /// The `--gt-cloud-dir` folder searched.
        dir: PathBuf,
    },
    /// A setting is out of range.
    #[error("invalid setting {name}: {reason}")]
    InvalidSetting {
        /// The setting, as the command line spells it (e.g. `--threads`).
        name: &'static str,
        /// Why its value is rejected.
        reason: String,
    },
    /// Geometry (mesh or cloud loading, normalization).
    #[error(transparent)]
    Geom(#[from] objview_geom::GeomError),
    /// View sets.
    #[error(transparent)]
    Views(#[from] objview_views::ViewsError),
    /// Voxelization.
    #[error("{path}: {source}")]
    Voxel {
        /// The mesh file of the object whose cloud was voxelized.
        path: PathBuf,
        /// The voxelization error.
        source: objview_voxel::VoxelError,
    },
    /// Saturation fit or cover.
    #[error("{path}: {source}")]
    Difficulty {
        /// The mesh file of the object being annotated.
        path: PathBuf,
        /// The saturation-fit or cover error.
        source: objview_difficulty::DifficultyError,
    },
}

/// Control characters (a newline in a JSON key, an id or a path read from a file) are shown
/// escaped so that every message stays on one line: the geometry layer's helper.
pub use objview_geom::error::one_line;

impl DatasetError {
    /// Shorthand for [`DatasetError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        DatasetError::Io { path: path.into(), source }
    }
}
