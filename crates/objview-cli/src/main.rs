//! `objview`: the command-line front of the objview benchmark. This binary is thin: it parses
//! arguments (clap), calls the library crates and prints or writes their results. Every error
//! reaches the user as one line on stderr and a non-zero exit code.

mod annotate;
mod bench;
mod bench_annotate;
mod bench_episode;
mod bench_serve;
mod common;
mod demo;
mod feasibility;
mod learn;
mod objects;
mod pool;
mod pool_build;
mod pool_plot;
mod pool_split;
mod render;
mod report;
mod run;
mod serve;
mod viewset;
mod visibility;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

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
    /// Evaluate a view space's feasibility rules on poses or a view set.
    Feasibility(feasibility::Args),
    /// Difficulty annotation (SPEC §4): saturation curve, r_vis, d_sat and exact d_plan per object,
    /// one JSON line each; resumable and shardable.
    Annotate(annotate::Args),
    /// The object pool: build, split, stats, plot (SPEC §6).
    #[command(subcommand)]
    Pool(pool::Command),
    /// Built-in procedural objects.
    #[command(subcommand)]
    Objects(objects::Command),
    /// Benchmarks of the hot paths (print medians).
    #[command(subcommand)]
    Bench(bench::Command),
    /// Online episodes (SPEC §5): one per object with a planner, view space and budget; one JSON
    /// line each; resumable.
    Run(run::Args),
    /// The evaluation server (docs/server-api.md): online episodes over HTTP/JSON for remote
    /// planners on hidden objects, persisted in SQLite.
    Serve(serve::Args),
    /// The finished results of a server's database as `objview run` JSON Lines.
    Export(serve::ExportArgs),
    /// Tables 2–5 of the paper, full summaries and figures from episode results.
    Report(report::Args),
    /// Learned planners: oracle training data, training, evaluation, benchmarks.
    #[command(subcommand)]
    Learn(learn::Command),
    /// The main job on the built-in objects: synthesize, render, annotate visibility, summarize.
    Demo(demo::Args),
}

fn main() {
    // Before anything else: a CPU without the build's baseline (x86-64-v2) would stop with
    // SIGILL at the first POPCNT deep inside a run; say it in one line instead.
    let missing = objview_runs::cpu::missing_baseline();
    if !missing.is_empty() {
        eprintln!("error: {}", objview_runs::cpu::baseline_error(&missing));
        std::process::exit(1);
    }
    // `objview run --help` lists the planners of the registry (a runtime table).
    let command = Cli::command().mut_subcommand("run", |c| c.after_help(run::planners_help()));
    let cli = match command.try_get_matches().and_then(|m| Cli::from_arg_matches(&m)) {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion)
                || matches!(e.kind(), ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand)
            {
                e.exit();
            }
            // One line: clap's first line ("error: ..."), without the usage trailer.
            let text = e.to_string();
            eprintln!("{}", text.lines().next().unwrap_or("error: invalid arguments"));
            std::process::exit(2);
        }
    };
    if ends_quietly_on_closed_pipe(&cli.command) {
        restore_default_sigpipe();
    }
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Viewset(c) => viewset::run(c),
        Command::Visibility(a) => visibility::run(a),
        Command::Feasibility(a) => feasibility::run(a),
        Command::Annotate(a) => annotate::run(a),
        Command::Pool(c) => pool::run(c),
        Command::Objects(c) => objects::run(c),
        Command::Bench(c) => bench::run(c),
        Command::Run(a) => run::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Export(a) => serve::export(a),
        Command::Report(a) => report::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Learn(c) => learn::run(c),
    };
    if let Err(e) = result {
        eprintln!("error: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// Whether `command` gets the default action of SIGPIPE: end at once, quietly, when the reader
/// of its output goes away (`objview report … | head`), as Unix tools do. Rust's runtime
/// ignores SIGPIPE, so a write to a closed pipe fails with EPIPE and `println!` panics with a
/// backtrace. Commands that hold network connections keep ignoring it: the server, a run
/// against a server and the server benchmark, where a peer that closes its socket must be an
/// error on that connection, never the end of the process.
fn ends_quietly_on_closed_pipe(command: &Command) -> bool {
    match command {
        Command::Serve(_) => false,
        Command::Run(a) => a.server.is_none(),
        Command::Bench(bench::Command::Serve(_)) => false,
        _ => true,
    }
}

/// Sets SIGPIPE's action back to the default (terminate the process).
fn restore_default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called on the main thread before any other thread exists; `signal` with
    // SIG_DFL installs no handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The chain of causes joined by ": " on one line, innermost last; a cause whose text the
/// message so far already ends with (errors that print their source) is not repeated.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let c = cause.to_string();
        if msg.ends_with(&c) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&c);
    }
    msg.replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::{ends_quietly_on_closed_pipe, Cli, Command};
    use clap::Parser;

    /// The parsed command of `objview ARGS` (ARGS split at spaces).
    fn command(args: &str) -> Command {
        Cli::try_parse_from(std::iter::once("objview").chain(args.split(' '))).unwrap().command
    }

    #[test]
    fn only_commands_without_network_connections_end_on_a_closed_pipe() {
        for args in
            ["objects list", "report r.jsonl", "bench render", "run --objects o --planner random --out x"]
        {
            assert!(ends_quietly_on_closed_pipe(&command(args)), "{args}");
        }
        for args in [
            "serve --pool p",
            "bench serve",
            "run --server http://127.0.0.1:1 --objects o --planner random --out x",
        ] {
            assert!(!ends_quietly_on_closed_pipe(&command(args)), "{args}");
        }
    }

    #[test]
    fn one_line_drops_repeated_causes() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let e = anyhow::Error::new(objview_geom::GeomError::io("a.obj", io)).context("loading");
        assert_eq!(super::one_line(&e), "loading: a.obj: gone");
    }
}
