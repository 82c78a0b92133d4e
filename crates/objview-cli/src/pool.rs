//! `objview pool …`: build a normalized pool from raw assets, split it by difficulty, print its
//! statistics and draw its figures (SPEC §6, paper §4 and Figure 2).

use anyhow::Result;
use clap::Subcommand;

#[derive(Subcommand)]
pub enum Command {
    /// Convert raw assets (GLB, OBJ, …) into a normalized pool: mesh + ground-truth cloud per
    /// object and a manifest, with geometry filters and stratification statistics.
    Build(crate::pool_build::Args),
    /// Write the difficulty splits (slow-saturation, Main-Hidden-Test, Main-Train-Public,
    /// Main-Raw-Train, Main-Balanced-Train) from annotations.
    Split(crate::pool_split::SplitArgs),
    /// Print counts, the d_plan bucket histogram and mean d_sat / d_plan / r_vis per split.
    Stats(crate::pool_split::StatsArgs),
    /// Draw the paper's Figure 2 panels (PNG + SVG) from annotations.
    Plot(crate::pool_plot::Args),
}

pub fn run(c: Command) -> Result<()> {
    match c {
        Command::Build(a) => crate::pool_build::run(a),
        Command::Split(a) => crate::pool_split::run_split(a),
        Command::Stats(a) => crate::pool_split::run_stats(a),
        Command::Plot(a) => crate::pool_plot::run(a),
    }
}
