//! `objview objects ...`: the built-in procedural object pool and seeded random pools.

use anyhow::{bail, Result};
use clap::Subcommand;
use objview_geom::synth::random;
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
    /// Write every built-in object as `<name>.obj` into DIR (deterministic bytes); with
    /// --count, write a random pool of N procedural objects instead (plus `synth.json`).
    Synth {
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Write N random objects `p{seed}-{index:05}-{family}.obj` drawn from the parametric
        /// families (`objects list --families`), and the manifest `synth.json` with every
        /// object's family and parameters. The same N and seed give byte-identical files; the
        /// first k objects of a larger N are the pool of N = k.
        #[arg(long, value_name = "N")]
        count: Option<usize>,
        /// Seed of the random pool (with --count; default 0).
        #[arg(long)]
        seed: Option<u64>,
    },
    /// List the built-in objects with their descriptions.
    List {
        /// List the families of random pools (`synth --count`) with their weights instead.
        #[arg(long)]
        families: bool,
    },
}

pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Synth { count: None, seed: Some(_), .. } => {
            bail!("--seed needs --count N (without --count the built-in objects are written)")
        }
        Command::Synth { out, count: None, seed: None } => {
            let paths = objview_geom::synth::write_pool(&out)?;
            println!("wrote {} objects to {}", paths.len(), out.display());
            Ok(())
        }
        Command::Synth { out, count: Some(count), seed } => {
            let seed = seed.unwrap_or(0);
            let paths = random::write_random_pool(&out, seed, count)?;
            let mut per_family: BTreeMap<&str, usize> = BTreeMap::new();
            for i in 0..count {
                *per_family.entry(random::family_of(seed, i).name).or_default() += 1;
            }
            println!(
                "wrote {} random objects (seed {seed}, pool version {}) and {} to {}",
                paths.len(),
                random::POOL_VERSION,
                random::MANIFEST,
                out.display()
            );
            let summary: Vec<String> = per_family.iter().map(|(f, n)| format!("{f} {n}")).collect();
            if !summary.is_empty() {
                println!("families: {}", summary.join(", "));
            }
            Ok(())
        }
        Command::List { families: false } => {
            for o in objview_geom::synth::catalog() {
                println!("{:<22} {}", o.name, o.description);
            }
            Ok(())
        }
        Command::List { families: true } => {
            let total: u32 = random::families().iter().map(|f| f.weight).sum();
            for f in random::families() {
                let share = 100.0 * f.weight as f64 / total as f64;
                println!("{:<14} {:>5.1}%  {}", f.name, share, f.description);
            }
            Ok(())
        }
    }
}
