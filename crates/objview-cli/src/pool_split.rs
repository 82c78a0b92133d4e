//! `objview pool split` and `objview pool stats`: the difficulty splits of SPEC §6 from the
//! results of `objview annotate` (`objview_pool::split`), and the counts, d_plan histogram and
//! means of a pool or of its splits (`objview_pool::stats`). Both are deterministic: the same
//! annotations and seed give the same files and output, whatever the order of the input lines.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use objview_pool::split::{SplitName, SplitSettings, DEFAULT_SPLIT_SEED, DEFAULT_TEST_FRACTION, REPORT_FILE};

#[derive(Args)]
pub struct SplitArgs {
    /// Results files of `objview annotate` (JSON Lines; several shards may be given).
    #[arg(required = true)]
    pub annotations: Vec<PathBuf>,
    /// Output folder of the split files and split_report.json (created if missing).
    #[arg(long)]
    pub out_dir: PathBuf,
    /// Seed of the random draws.
    #[arg(long, default_value_t = DEFAULT_SPLIT_SEED)]
    pub seed: u64,
    /// Main-Hidden-Test quota as a fraction of the main pool (default 528/5523).
    #[arg(long, default_value_t = DEFAULT_TEST_FRACTION, allow_hyphen_values = true)]
    pub test_fraction: f64,
    /// Size of Main-Raw-Train and Main-Balanced-Train (default: half of Main-Train-Public).
    #[arg(long)]
    pub train_size: Option<usize>,
}

#[derive(Args)]
pub struct StatsArgs {
    /// Results files of `objview annotate` (JSON Lines).
    #[arg(required = true)]
    pub annotations: Vec<PathBuf>,
    /// Folder of split files written by `objview pool split`: means per split instead of for
    /// all / main / slow-saturation objects.
    #[arg(long)]
    pub splits: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run_split(a: SplitArgs) -> Result<()> {
    let settings = SplitSettings { seed: a.seed, test_fraction: a.test_fraction, train_size: a.train_size };
    let out = objview_runs::pool::split(&a.annotations, &a.out_dir, &settings)?;
    print!("{}", out.splits.summary_text(out.annotations, a.test_fraction));
    println!("\nwrote {} split files and {REPORT_FILE} to {}", SplitName::ALL.len(), a.out_dir.display());
    Ok(())
}

pub fn run_stats(a: StatsArgs) -> Result<()> {
    let (stats, settings) = objview_runs::pool::stats(&a.annotations, a.splits.as_deref())?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&stats.to_json(&settings))?);
    } else {
        print!("{}", stats.to_text());
    }
    Ok(())
}
