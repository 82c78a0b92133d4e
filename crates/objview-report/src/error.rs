//! Error type of `objview report`. Every variant names what it is about (the input or output
//! file, the setting) and why, so that a failed report is diagnosable from one line of output.
//! A bad line of a results file is not an error: it is skipped and listed
//! ([`crate::load::SkippedLine`]).

use std::path::PathBuf;

use objview_dataset::DatasetError;
use objview_plot::PlotError;
use thiserror::Error;

/// Errors of reading results, building tables and writing the report.
#[derive(Debug, Error)]
pub enum ReportError {
    /// Reading an input or writing an output file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
    /// The annotation files could not be read (the inner error names the file and line).
    #[error("annotations: {0}")]
    Annotations(#[from] DatasetError),
    /// A figure could not be drawn or written.
    #[error("figure: {0}")]
    Plot(#[from] PlotError),
    /// A report setting is out of range.
    #[error("invalid setting {name}: {reason}")]
    InvalidSetting {
        /// The setting's name.
        name: &'static str,
        /// Why its value is refused.
        reason: String,
    },
    /// No results file was given.
    #[error("no episode result files given")]
    NoInputs,
}

impl ReportError {
    /// Shorthand for [`ReportError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        ReportError::Io { path: path.into(), source }
    }
}
