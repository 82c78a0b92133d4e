//! `objview report`: episode results (JSON Lines of `objview run`) → the paper's Tables 2–5 as
//! Markdown and CSV, the full per-method summary, and figures (`objview_report`).

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Parser;
use objview_report::{build_report, ReportSettings};

#[derive(Parser)]
pub struct Args {
    /// Episode result files (JSON Lines); may be left out with --difficulty-aware.
    #[arg(required_unless_present = "difficulty_aware")]
    pub results: Vec<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Difficulty annotations (`objview annotate` output) for the slow-saturation table.
    #[arg(long, num_args = 1..)]
    pub annotations: Vec<PathBuf>,
    /// τ of NSC/SC in the tables.
    #[arg(long, default_value = "0.02")]
    pub tau: String,
    /// Rows per setting in the top-k tables.
    #[arg(long, default_value_t = 3)]
    pub top: usize,
    /// NSC threshold of the path-efficient table.
    #[arg(long, default_value_t = 0.95)]
    pub quality_threshold: f64,
    /// Skip the figures.
    #[arg(long)]
    pub no_plots: bool,
    /// The output folder of `objview learn experiment difficulty-aware`: adds Figure 4
    /// (figure4_difficulty_aware.png/.svg) and its table (difficulty_aware.md).
    #[arg(long)]
    pub difficulty_aware: Option<PathBuf>,
}

pub fn run(a: Args) -> Result<()> {
    let settings = ReportSettings {
        tau: a.tau.clone(),
        top: a.top,
        quality_threshold: a.quality_threshold,
        plots: !a.no_plots,
        ..Default::default()
    };
    let mut files = Vec::new();
    if !a.results.is_empty() {
        files = report_with(&a.results, &a.annotations, &a.out, &settings, true)?;
    }
    if let Some(dir) = &a.difficulty_aware {
        let summary = objview_report::figure4::read_summary(dir)?;
        print!("{}", objview_report::figure4::markdown(&summary));
        let extra = objview_report::figure4::write(&summary, &a.out)?;
        for f in &extra {
            println!("  {}", f.display());
        }
        files.extend(extra);
    }
    println!("report: {} files in {}", files.len(), a.out.display());
    Ok(())
}

/// Builds and writes the report with default settings; prints the tables when `print`.
fn report_with(
    results: &[PathBuf],
    annotations: &[PathBuf],
    out: &Path,
    settings: &ReportSettings,
    print: bool,
) -> Result<Vec<PathBuf>> {
    let report = build_report(results, annotations, settings)?;
    for s in &report.skipped {
        let file = report.inputs.get(s.source.file).map(|f| f.path.display().to_string()).unwrap_or_default();
        eprintln!("report: skipped {file}:{}: {}", s.source.line, s.reason);
    }
    let files = report.write(out)?;
    if print {
        println!("{}", report.markdown());
        println!("Tables (Markdown + CSV) and figures (PNG + SVG):");
        for f in &files {
            println!("  {}", f.display());
        }
    }
    Ok(files)
}
