//! Errors of the geometry layer. Every variant names the file it concerns, so that a batch
//! command can record "which object failed and why" without extra context.

use std::path::PathBuf;

/// An error while reading, validating or writing geometry.
#[derive(Debug, thiserror::Error)]
pub enum GeomError {
    /// The file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its content is malformed for its format.
    #[error("{}: {reason}", path.display())]
    Parse { path: PathBuf, reason: String },
    /// The file parsed, but the geometry is unusable (no faces, NaN, zero extent, ...).
    #[error("{}: {reason}", path.display())]
    Invalid { path: PathBuf, reason: String },
    /// The file extension is not a supported format.
    #[error("{}: unsupported format (expected one of {expected})", path.display())]
    Unsupported { path: PathBuf, expected: &'static str },
}

impl GeomError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        GeomError::Io { path: path.into(), source }
    }
    pub fn parse(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        GeomError::Parse { path: path.into(), reason: reason.into() }
    }
    pub fn invalid(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        GeomError::Invalid { path: path.into(), reason: reason.into() }
    }
}
