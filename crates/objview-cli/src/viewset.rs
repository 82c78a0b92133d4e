//! `objview viewset ...`: generate Tammes point sets with the project's optimizer and check
//! any view-set file's minimum pairwise angle.

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use objview_views::{tammes, ViewSet};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
    /// Generate N near-optimal Tammes directions (one `x y z` per line).
    Generate {
        /// Number of directions.
        n: usize,
        /// Output file (default: standard output).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Optimizer seed (the shipped sets use the default).
        #[arg(long, default_value_t = tammes::DEFAULT_SEED)]
        seed: u64,
    },
    /// Print `n=<N> min_angle_deg=<x>` for a view-set file (or a built-in `tammes-N`).
    Check {
        /// View-set file, or a built-in name such as `tammes-128`.
        file: String,
    },
}

pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Generate { n, out, seed } => {
            if n < 2 {
                bail!("N must be at least 2, got {n}");
            }
            let set = tammes::generate(n, seed);
            let angle = set.min_angle_deg().unwrap_or(f64::NAN);
            // The same header as the shipped data/viewsets files, so a regenerated set
            // is byte-identical to the shipped one.
            let header = tammes::file_header(&set, seed);
            match out {
                Some(p) => {
                    set.write(&p, &header)?;
                    eprintln!("wrote {n} directions to {} (min angle {angle:.6} deg)", p.display());
                }
                None => print!("{}", set.to_text(&header)),
            }
            Ok(())
        }
        Command::Check { file } => {
            let set = ViewSet::resolve(&file)?;
            let angle = set
                .min_angle_deg()
                .with_context(|| format!("{file}: a view set needs at least 2 directions"))?;
            println!("n={} min_angle_deg={angle:.6}", set.len());
            Ok(())
        }
    }
}
