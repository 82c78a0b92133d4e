//! `objview objects ...`: the built-in procedural object pool.

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
    /// Write every built-in object as `<name>.obj` into DIR (deterministic bytes).
    Synth {
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// List the built-in objects with their descriptions.
    List,
}

pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Synth { out } => {
            let paths = objview_geom::synth::write_pool(&out)?;
            println!("wrote {} objects to {}", paths.len(), out.display());
            Ok(())
        }
        Command::List => {
            for o in objview_geom::synth::catalog() {
                println!("{:<22} {}", o.name, o.description);
            }
            Ok(())
        }
    }
}
