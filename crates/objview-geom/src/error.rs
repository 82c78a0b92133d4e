//! Errors of the geometry layer. Every variant names the file it concerns, so that a batch
//! command can record "which object failed and why" without extra context. The message is
//! always one line: control characters that a hostile file put into a name, URI or header
//! (and so into the path or the reason) are shown escaped (`\n`, `\u{0}`).

use std::path::PathBuf;

/// An error while reading, validating or writing geometry.
#[derive(Debug, thiserror::Error)]
pub enum GeomError {
    /// The file could not be opened, read or written.
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(&source.to_string()))]
    Io {
        /// The file being opened, read or written.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its content is malformed for its format.
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(reason))]
    Parse {
        /// The malformed file.
        path: PathBuf,
        /// What is wrong with its content (one line once escaped).
        reason: String,
    },
    /// The file parsed, but the geometry is unusable (no faces, NaN, zero extent, ...).
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(reason))]
    Invalid {
        /// The file whose geometry is unusable.
        path: PathBuf,
        /// Why the geometry is unusable (no faces, NaN, zero extent, ...).
        reason: String,
    },
    /// The file extension is not a supported format.
    #[error("{}: unsupported format (expected one of {expected})", one_line(&path.display().to_string()))]
    Unsupported {
        /// The file whose extension is not recognized.
        path: PathBuf,
        /// The supported extensions, for the message (e.g. "obj, ply, stl").
        expected: &'static str,
    },
}

impl GeomError {
    /// A [`GeomError::Io`] error: opening, reading or writing `path` failed with `source`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        GeomError::Io { path: path.into(), source }
    }
    /// A [`GeomError::Parse`] error: `path` is malformed for its format, because of `reason`.
    pub fn parse(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        GeomError::Parse { path: path.into(), reason: reason.into() }
    }
    /// A [`GeomError::Invalid`] error: the geometry of `path` is unusable, because of `reason`.
    pub fn invalid(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        GeomError::Invalid { path: path.into(), reason: reason.into() }
    }
}

/// `s` with every control character escaped as Rust would write it (`\n`, `\t`, `\u{0}`), so
/// that an error message stays on one line whatever the input held. Other characters are kept.
pub fn one_line(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_stay_on_one_line_whatever_the_file_put_into_them() {
        let e = GeomError::parse("dir/a\nb.npy", "dtype '<f4\n\0' unsupported");
        assert_eq!(e.to_string(), "dir/a\\nb.npy: dtype '<f4\\n\\u{0}' unsupported");
        let e = GeomError::io("x/b.bi\nn", std::io::Error::new(std::io::ErrorKind::NotFound, "no\rfile"));
        assert_eq!(e.to_string(), "x/b.bi\\nn: no\\rfile");
        let e = GeomError::parse("plain.obj", "naïve reason");
        assert_eq!(e.to_string(), "plain.obj: naïve reason");
    }
}
