//! `objview`: the command-line front of the objview benchmark. This binary is thin: it parses
//! arguments (clap), calls the library crates and prints or writes their results. Every error
//! reaches the user as one line on stderr and a non-zero exit code.

mod bench;
mod common;
mod demo;
mod objects;
mod provenance;
mod render;
mod viewset;
mod visibility;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "objview", version, about = "Object-centric view-planning benchmark", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render first-hit depth (and optionally points, a preview, RGB) of a mesh from one pose.
    Render(render::Args),
    /// Generate or check Tammes view sets.
    #[command(subcommand)]
    Viewset(viewset::Command),
    /// Per-view observed surface voxels O(v) of a mesh for a view set (SPEC §4).
    Visibility(visibility::Args),
    /// Built-in procedural objects.
    #[command(subcommand)]
    Objects(objects::Command),
    /// Benchmarks of the hot paths (print medians).
    #[command(subcommand)]
    Bench(bench::Command),
    /// The main job on the built-in objects: synthesize, render, annotate visibility, summarize.
    Demo(demo::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Viewset(c) => viewset::run(c),
        Command::Visibility(a) => visibility::run(a),
        Command::Objects(c) => objects::run(c),
        Command::Bench(c) => bench::run(c),
        Command::Demo(a) => demo::run(a),
    };
    if let Err(e) = result {
        // One line: the chain of causes joined, innermost last.
        let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
        eprintln!("error: {}", msg.join(": "));
        std::process::exit(1);
    }
}
