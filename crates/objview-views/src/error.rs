//! Error type of the view-set and view-space layer.
//!
//! Every message names the file (or the view-set / view-space name that was asked for) and, in
//! one line, the reason — a line number for view-set files, a JSON path for rule files — so a
//! user can fix the input without reading the source.

use std::path::PathBuf;

/// Control characters (a newline in a JSON key, an id or a path read from a file) are shown
/// escaped so that every message stays on one line: the geometry layer's helper.
pub use objview_geom::error::one_line;

/// Errors of `objview-views`.
#[derive(Debug, thiserror::Error)]
pub enum ViewsError {
    /// A file could not be read or written.
    #[error("{path}: {op} failed: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was attempted ("read", "write").
        op: &'static str,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A bad line in a view-set file.
    #[error("{} line {line}: {}", one_line(.path), one_line(.reason))]
    ViewSetLine {
        /// The file (or `builtin:tammes-N`).
        path: String,
        /// 1-based line number.
        line: usize,
        /// Why the line was rejected.
        reason: String,
    },
    /// A view-set file without a single direction.
    #[error("{path}: view set is empty (no `x y z` lines)")]
    EmptyViewSet {
        /// The file.
        path: String,
    },
    /// `tammes-N` for an N that is not shipped (and no such file exists).
    #[error("view set {spec:?}: not a shipped tammes set (shipped N: {shipped}) and not a readable file")]
    UnknownViewSet {
        /// What was asked for.
        spec: String,
        /// The shipped sizes, comma separated.
        shipped: String,
    },
    /// A rule file that is not valid JSON.
    #[error("{}: invalid JSON: {}", one_line(.path), one_line(.reason))]
    RuleJson {
        /// The file (or `builtin:NAME`).
        path: String,
        /// serde_json's message (with line and column).
        reason: String,
    },
    /// A rule file that is valid JSON but not a valid rule set.
    #[error("{}: {}: {}", one_line(.path), one_line(.json_path), one_line(.reason))]
    Rule {
        /// The file (or `builtin:NAME`).
        path: String,
        /// JSON path of the offending item, e.g. `structured_rule.rules[2].op`.
        json_path: String,
        /// Why it was rejected.
        reason: String,
    },
    /// A view-space name that is neither built in nor a readable file.
    #[error(
        "view space {spec:?}: not a built-in space (whole, hemi, quarter, eighth) and not a readable file"
    )]
    UnknownViewSpace {
        /// What was asked for.
        spec: String,
    },
}
