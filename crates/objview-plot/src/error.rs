//! Error type of the figure layer. Every variant names what it is about (the output file, the
//! object uid, the setting) and the reason, so that a failed figure is diagnosable from one line.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of drawing and writing figures.
#[derive(Debug, Error)]
pub enum PlotError {
    /// Creating a folder or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The folder or file being created or written.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The drawing backend failed (plotters), or a PNG could not be encoded; `target` is the
    /// output file, or `PNG`/`SVG` for an in-memory rendering.
    #[error("{target}: drawing failed: {reason}")]
    Draw {
        /// The output file, or `PNG`/`SVG` for an in-memory rendering.
        target: String,
        /// The backend's or encoder's message.
        reason: String,
    },
    /// The embedded font could not be loaded (a broken build, not a user error).
    #[error("embedded font {name}: {reason}")]
    Font {
        /// The font file's name (e.g. `DejaVuSans.ttf`).
        name: &'static str,
        /// Why it could not be loaded.
        reason: String,
    },
    /// A chart cannot be drawn as described (no finite point on a log axis, mismatched labels, …).
    #[error("chart '{title}': {reason}")]
    InvalidChart {
        /// The chart's title.
        title: String,
        /// Why it cannot be drawn.
        reason: String,
    },
    /// There is nothing to plot.
    #[error("no annotations to plot (every input line was a failure, or the inputs are empty)")]
    NoAnnotations,
    /// An annotation cannot be plotted (empty curve, zero surface, …).
    #[error("annotation '{uid}': {reason}")]
    BadAnnotation {
        /// The object id of the annotation.
        uid: String,
        /// What makes it unplottable.
        reason: String,
    },
    /// The annotations were produced with different values of a setting the figure depends on.
    #[error("annotations disagree on setting {key}: '{first_uid}' has {first}, '{other_uid}' has {other}")]
    InconsistentSettings {
        /// Dotted path of the setting inside the annotations' `settings` (e.g. `saturation.plateau_tol`).
        key: String,
        /// Object id of the first annotation.
        first_uid: String,
        /// The setting's value there, as JSON (`nothing` when absent).
        first: String,
        /// Object id of the first annotation that disagrees.
        other_uid: String,
        /// The setting's value there, as JSON (`nothing` when absent).
        other: String,
    },
    /// A setting is out of range.
    #[error("invalid setting {name}: {reason}")]
    InvalidSetting {
        /// The setting's field name (e.g. `jitter`, `width`).
        name: &'static str,
        /// Why its value is rejected.
        reason: String,
    },
}

impl PlotError {
    /// Shorthand for [`PlotError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        PlotError::Io { path: path.into(), source }
    }
}
