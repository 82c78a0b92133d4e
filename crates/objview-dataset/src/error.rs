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
    Io { path: PathBuf, source: std::io::Error },
    /// An input path is neither a supported mesh file, a folder nor a split file (`.json`).
    #[error("{path}: not a mesh file ({expected}), a folder or a split file (.json)")]
    UnsupportedInput { path: PathBuf, expected: &'static str },
    /// A split file is not a JSON array of objects with the required fields.
    #[error("{}: {}", .path.display(), one_line(.reason))]
    SplitFile { path: PathBuf, reason: String },
    /// Two inputs resolve to the same object id.
    #[error(
        "duplicate object id '{}': {} and {}",
        one_line(.uid),
        one_line(&.first.display().to_string()),
        one_line(&.second.display().to_string())
    )]
    DuplicateUid { uid: String, first: PathBuf, second: PathBuf },
    /// A `--shard I/N` argument is malformed.
    #[error("invalid shard '{0}': expected I/N with 0 <= I < N (e.g. 0/4)")]
    Shard(String),
    /// A complete line of a results file is not a JSON object with the key field.
    #[error(
        "{}: line {line}: {} (the file is not a results file of this command, or was edited)",
        .path.display(),
        one_line(.reason)
    )]
    CorruptLine { path: PathBuf, line: usize, reason: String },
    /// `--gt-cloud-dir` has no cloud for this object.
    #[error(
        "no ground-truth cloud for '{}' in {} (looked for {}.pcd, .ply, .npy, .npz)",
        one_line(.uid),
        .dir.display(),
        one_line(.uid)
    )]
    MissingGtCloud { uid: String, dir: PathBuf },
    /// A setting is out of range.
    #[error("invalid setting {name}: {reason}")]
    InvalidSetting { name: &'static str, reason: String },
    /// Geometry (mesh or cloud loading, normalization).
    #[error(transparent)]
    Geom(#[from] objview_geom::GeomError),
    /// View sets.
    #[error(transparent)]
    Views(#[from] objview_views::ViewsError),
    /// Voxelization.
    #[error("{path}: {source}")]
    Voxel { path: PathBuf, source: objview_voxel::VoxelError },
    /// Saturation fit or cover.
    #[error("{path}: {source}")]
    Difficulty { path: PathBuf, source: objview_difficulty::DifficultyError },
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
