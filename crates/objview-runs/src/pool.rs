//! The pool steps that read annotation files and write pool outputs — splits (SPEC §6),
//! statistics and Figure 2 — with the provenance block each output carries. `objview pool
//! split|stats|plot` and the demo call them and print what they return.

use std::path::{Path, PathBuf};

use objview_dataset::{read_annotations, AnnotationSet};
use objview_plot::{figure2, Figure2Output, Figure2Settings};
use objview_pool::split::{make_splits, write_splits, SplitSettings, Splits};
use objview_pool::stats::{pool_stats, read_split_dir, PoolStats};
use serde_json::{json, Value};

use crate::RunError;

fn inputs_json(paths: &[PathBuf]) -> Value {
    json!(paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>())
}

/// What a split wrote.
#[derive(Debug, Clone)]
pub struct SplitOutput {
    /// The splits.
    pub splits: Splits,
    /// Annotations read (failure lines not counted).
    pub annotations: usize,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Splits the annotated pool of `annotations` (SPEC §6) and writes the split files and the
/// split report into `out_dir`.
pub fn split(
    annotations: &[PathBuf],
    out_dir: &Path,
    settings: &SplitSettings,
) -> Result<SplitOutput, RunError> {
    settings.validate()?;
    let set = read_annotations(annotations)?;
    let splits = make_splits(&set, settings)?;
    let mut block = settings.to_json();
    block["inputs"] = inputs_json(annotations);
    let settings_json = crate::provenance::settings("pool split", block);
    let files = write_splits(&splits, out_dir, &settings_json)?;
    Ok(SplitOutput { splits, annotations: set.annotations.len(), files })
}

/// Counts, the d_plan histogram and means of a pool (and of its splits, given the folder
/// `split` wrote), and the provenance block of its JSON form.
pub fn stats(annotations: &[PathBuf], splits: Option<&Path>) -> Result<(PoolStats, Value), RunError> {
    let set = read_annotations(annotations)?;
    let members = splits.map(read_split_dir).transpose()?;
    let stats = pool_stats(&set, members.as_deref())?;
    let settings = crate::provenance::settings(
        "pool stats",
        json!({
            "inputs": inputs_json(annotations),
            "splits": splits.map(|p| p.display().to_string()),
            "bucket_width": objview_pool::split::BUCKET_WIDTH,
        }),
    );
    Ok((stats, settings))
}

/// Draws the paper's Figure 2 of the annotations into `out` (PNG + SVG + `figures.json`).
pub fn figure(
    annotations: &[PathBuf],
    out: &Path,
    representatives: usize,
) -> Result<Figure2Output, RunError> {
    for p in annotations {
        if !p.is_file() {
            return Err(RunError::Invalid(format!("{}: no such annotations file", p.display())));
        }
    }
    let set: AnnotationSet =
        read_annotations(annotations).map_err(|e| RunError::Invalid(format!("reading annotations: {e}")))?;
    if set.annotations.is_empty() {
        let names: Vec<String> = annotations.iter().map(|p| p.display().to_string()).collect();
        return Err(RunError::Invalid(format!(
            "{}: no annotations to plot ({} failure lines, no successful annotation)",
            names.join(", "),
            set.failures.len()
        )));
    }
    let settings = Figure2Settings { representatives, ..Figure2Settings::default() };
    let inputs: Vec<String> = annotations.iter().map(|p| p.display().to_string()).collect();
    let provenance = crate::provenance::settings(
        "pool plot",
        json!({"inputs": inputs, "annotations": set.annotations.len(), "failures_skipped": set.failures.len()}),
    );
    figure2(&set.annotations, out, &settings, &provenance).map_err(|e| {
        RunError::Invalid(format!(
            "drawing Figure 2 into {}: {}",
            out.display(),
            objview_geom::error::one_line(&e.to_string())
        ))
    })
}
