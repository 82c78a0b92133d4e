//! Small pieces shared by several subcommands: JSON output, output folders, the progress bar
//! and the terminal [`Progress`] of batch commands.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use objview_dataset::{BatchStart, ItemProgress, Progress};
use serde_json::Value;
use std::io::IsTerminal;
use std::path::Path;
use std::sync::Mutex;

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

/// Batch progress on stderr: the start line, one line per finished item (above a progress bar
/// on a terminal), and the torn-line notice. `quiet` keeps only the notice.
pub struct TermProgress {
    bar: Mutex<Option<ProgressBar>>,
    quiet: bool,
}

impl TermProgress {
    /// Progress that prints everything (`quiet`: only the torn-line notice).
    pub fn new(quiet: bool) -> TermProgress {
        TermProgress { bar: Mutex::new(None), quiet }
    }

    fn println(&self, msg: &str) {
        let bar = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match bar.as_ref() {
            Some(b) if std::io::stderr().is_terminal() => b.println(msg),
            _ => eprintln!("{msg}"),
        }
    }
}

impl Progress for TermProgress {
    fn torn(&self, out: &Path) {
        eprintln!(
            "{}: cut off a torn last line (an interrupted write); that object is redone",
            out.display()
        );
    }

    fn start(&self, s: &BatchStart) {
        if self.quiet {
            return;
        }
        eprintln!("{s}");
        *self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(progress(s.todo as u64));
    }

    fn item(&self, item: &ItemProgress<'_>) {
        if self.quiet {
            return;
        }
        if let Some(b) = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner).as_ref() {
            b.inc(1);
        }
        self.println(&item.to_string());
    }

    fn finish(&self) {
        if let Some(b) = self.bar.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
            b.finish_and_clear();
        }
    }
}
