//! `objview pool split` and `objview pool stats`: the difficulty splits of SPEC §6 from the
//! results of `objview annotate` (`objview_pool::split`), and the counts, d_plan histogram and
//! means of a pool or of its splits (`objview_pool::stats`). Both are deterministic: the same
//! annotations and seed give the same files and output, whatever the order of the input lines.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use objview_dataset::read_annotations;
use objview_pool::split::{
    bucket_label, make_splits, write_splits, SplitName, SplitSettings, DEFAULT_SPLIT_SEED,
    DEFAULT_TEST_FRACTION, REPORT_FILE,
};
use objview_pool::stats::{pool_stats, read_split_dir};
use serde_json::json;

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

fn inputs_json(paths: &[PathBuf]) -> serde_json::Value {
    json!(paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>())
}

pub fn run_split(a: SplitArgs) -> Result<()> {
    let settings = SplitSettings { seed: a.seed, test_fraction: a.test_fraction, train_size: a.train_size };
    settings.validate()?;
    let set = read_annotations(&a.annotations)?;
    let splits = make_splits(&set, &settings)?;
    let mut block = settings.to_json();
    block["inputs"] = inputs_json(&a.annotations);
    let settings_json = crate::provenance::settings("pool split", block);
    write_splits(&splits, &a.out_dir, &settings_json)?;

    println!(
        "pool split: {} annotations ({} failure lines ignored): {} slow-saturation, {} main, {} excluded \
         (no proven d_plan; reasons in {REPORT_FILE})",
        set.annotations.len(),
        splits.failures,
        splits.slow_saturation.len(),
        splits.main(),
        splits.excluded.len()
    );
    println!(
        "hidden-test quota {} (fraction {}), train size {}",
        splits.hidden_test_quota, a.test_fraction, splits.train_size
    );
    let main_splits = &SplitName::ALL[1..];
    let short = |s: &SplitName| s.as_str().trim_start_matches("main_");
    print!("\n{:<8} {:>6}", "d_plan", "main");
    for s in main_splits {
        print!(" {:>14}", short(s));
    }
    println!();
    let per_split: Vec<Vec<usize>> = main_splits.iter().map(|&s| splits.bucket_counts(s)).collect();
    for b in 0..splits.main_buckets.len() {
        print!("{:<8} {:>6}", bucket_label(b), splits.main_buckets[b]);
        for c in &per_split {
            print!(" {:>14}", c[b]);
        }
        println!();
    }
    print!("{:<8} {:>6}", "total", splits.main());
    for &s in main_splits {
        print!(" {:>14}", splits.get(s).len());
    }
    println!("\n\nwrote {} split files and {REPORT_FILE} to {}", SplitName::ALL.len(), a.out_dir.display());
    Ok(())
}

pub fn run_stats(a: StatsArgs) -> Result<()> {
    let set = read_annotations(&a.annotations)?;
    let members = a.splits.as_deref().map(read_split_dir).transpose()?;
    let stats = pool_stats(&set, members.as_deref())?;
    if a.json {
        let settings = crate::provenance::settings(
            "pool stats",
            json!({
                "inputs": inputs_json(&a.annotations),
                "splits": a.splits.as_ref().map(|p| p.display().to_string()),
                "bucket_width": objview_pool::split::BUCKET_WIDTH,
            }),
        );
        println!("{}", serde_json::to_string_pretty(&stats.to_json(&settings))?);
    } else {
        print!("{}", stats.to_text());
    }
    Ok(())
}
