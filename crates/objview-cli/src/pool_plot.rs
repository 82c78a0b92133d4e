//! `objview pool plot`: the paper's Figure 2 (difficulty statistics of a pool) from
//! `objview annotate` results — saturation curves and marginal gain, d_plan histogram, d_sat vs
//! d_plan — as PNG and SVG, with `figures.json` holding the settings, version and plotted numbers.
//! The drawing lives in `objview-plot`; this file only reads the inputs and reports the paths.

use std::path::PathBuf;

use anyhow::{Context, Result};
use objview_plot::{figure2, Figure2Settings};
use serde_json::json;

#[derive(clap::Args)]
pub struct Args {
    /// Results files of `objview annotate` (JSON Lines; several shards may be given). Failure
    /// lines are skipped.
    #[arg(required = true)]
    pub annotations: Vec<PathBuf>,
    /// Output folder (created if missing); existing figure files in it are overwritten.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of representative objects in panel (a), chosen at evenly spaced d_sat ranks.
    #[arg(long, default_value_t = Figure2Settings::default().representatives)]
    pub representatives: usize,
}

pub fn run(a: Args) -> Result<()> {
    for p in &a.annotations {
        if !p.is_file() {
            anyhow::bail!("{}: no such annotations file", p.display());
        }
    }
    let set = objview_dataset::annotate::read_annotations(&a.annotations).context("reading annotations")?;
    if set.annotations.is_empty() {
        let names: Vec<String> = a.annotations.iter().map(|p| p.display().to_string()).collect();
        anyhow::bail!(
            "{}: no annotations to plot ({} failure lines, no successful annotation)",
            names.join(", "),
            set.failures.len()
        );
    }
    let settings = Figure2Settings { representatives: a.representatives, ..Figure2Settings::default() };
    let inputs: Vec<String> = a.annotations.iter().map(|p| p.display().to_string()).collect();
    let provenance = crate::provenance::settings(
        "pool plot",
        json!({"inputs": inputs, "annotations": set.annotations.len(), "failures_skipped": set.failures.len()}),
    );
    let out = figure2(&set.annotations, &a.out, &settings, &provenance)
        .with_context(|| format!("drawing Figure 2 into {}", a.out.display()))?;
    for f in out.files.iter().chain([&out.figures_json]) {
        println!("{}", f.display());
    }
    Ok(())
}
