//! `objview pool plot`: the paper's Figure 2 (difficulty statistics of a pool) from
//! `objview annotate` results — saturation curves and marginal gain, d_plan histogram, d_sat vs
//! d_plan — as PNG and SVG, with `figures.json` holding the settings, version and plotted numbers.
//! The drawing lives in `objview-plot`; this file only reads the inputs and reports the paths.

use std::path::PathBuf;

use anyhow::Result;
use objview_plot::Figure2Settings;

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
    let out = objview_runs::pool::figure(&a.annotations, &a.out, a.representatives)?;
    for f in out.files.iter().chain([&out.figures_json]) {
        println!("{}", f.display());
    }
    Ok(())
}
