//! Small pieces shared by several subcommands: JSON output and output folders.

use anyhow::{Context, Result};
use serde_json::Value;
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
