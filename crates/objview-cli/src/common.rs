//! Small pieces shared by several subcommands: JSON output, output folders and the progress bar.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::Value;
use std::io::IsTerminal;
use std::path::Path;

/// Writes pretty JSON with a trailing newline, creating parent folders.
pub fn write_json(path: &Path, v: &Value) -> Result<()> {
    create_parent(path)?;
    let mut s = serde_json::to_string_pretty(v)?;
    s.push('\n');
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

/// Creates the folder an output file goes into, if missing.
pub fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(())
}

/// A progress bar with ETA on a terminal; hidden otherwise (the summary lines still print).
pub fn progress(n: u64) -> ProgressBar {
    if std::io::stderr().is_terminal() {
        let b = ProgressBar::new(n);
        b.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} objects, {elapsed} elapsed, ETA {eta}")
                .expect("valid template"),
        );
        b
    } else {
        ProgressBar::hidden()
    }
}
