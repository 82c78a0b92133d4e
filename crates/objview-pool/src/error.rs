//! Error type of the pool layer: settings out of range, annotation and split files that cannot be
//! read or do not match, and output files that cannot be written.
//!
//! Every variant names the file (and where it applies the field or object) and the reason, so a
//! command can print it as one line. Per-object build rejections are not errors: they are
//! recorded in the build outputs ([`crate::build::Rejection`]) and the batch goes on.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of `pool build`, `pool split` and `pool stats`.
#[derive(Debug, Error)]
pub enum PoolError {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A setting is out of range.
    #[error("invalid setting {name}: {reason}")]
    InvalidSetting {
        /// The setting, as the command line spells it.
        name: &'static str,
        /// Why its value is rejected.
        reason: String,
    },
    /// A file's content does not fit what the command needs (a split file naming an object that
    /// the annotations lack, a build log written with other settings, …).
    #[error("{}: {reason}", path.display())]
    Mismatch {
        /// The file whose content does not fit.
        path: PathBuf,
        /// What does not match, naming the object or field.
        reason: String,
    },
    /// Inputs, annotation files, split files and results files of the batch layer.
    #[error(transparent)]
    Dataset(#[from] objview_dataset::DatasetError),
    /// Geometry that cannot be written.
    #[error(transparent)]
    Geom(#[from] objview_geom::GeomError),
}

impl PoolError {
    /// Shorthand for [`PoolError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        PoolError::Io { path: path.into(), source }
    }

    /// Shorthand for [`PoolError::Mismatch`].
    pub fn mismatch(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        PoolError::Mismatch { path: path.into(), reason: reason.into() }
    }
}
