//! `objview-fuzz`: the command line of the loader fuzzer (see the library docs).
//!
//! - `run`: a seeded, time-bounded campaign; findings go to `--out` (exit 1 when there are any);
//! - `replay [DIR]`: every kept regression input (default: this crate's `regressions/`);
//! - `one KIND FILE`: one input in a child process, classified;
//! - `gen KIND --seed S --case I --out DIR`: writes case I of a seeded sequence (to reproduce);
//! - `list`: the kinds, their loaders' crates and seed counts;
//! - `child KIND LIST` (internal): the child process the others start.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, Parser, Subcommand};
use objview_fuzz::{corpus, fuzz, mutate, Kind, Limits};

#[global_allocator]
static ALLOC: objview_fuzz::child::OomMarker = objview_fuzz::child::OomMarker;

#[derive(Parser)]
#[command(name = "objview-fuzz", version, about = "Mutation fuzzing of objview's file loaders")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Args, Clone)]
struct LimitArgs {
    /// Wall-clock limit of one case, seconds.
    #[arg(long, default_value_t = 10.0)]
    timeout_secs: f64,
    /// Address-space limit of a child process, MiB.
    #[arg(long, default_value_t = 2048)]
    mem_mb: u64,
    /// Allow the fake test-* kinds (they misbehave on purpose).
    #[arg(long)]
    allow_test_kinds: bool,
}

impl LimitArgs {
    fn limits(&self) -> Limits {
        Limits { timeout: Duration::from_secs_f64(self.timeout_secs.max(0.01)), mem_bytes: self.mem_mb << 20 }
    }

    fn kind(&self, name: &str) -> Result<Kind, String> {
        parse_kind(name, self.allow_test_kinds)
    }
}

/// A kind by name; the test-* kinds only with `allow_test`.
fn parse_kind(name: &str, allow_test: bool) -> Result<Kind, String> {
    Kind::from_name(name)
        .filter(|k| allow_test || !k.is_test())
        .ok_or_else(|| format!("unknown kind '{name}' (kinds: {})", fuzz::kind_names()))
}

#[derive(Subcommand)]
enum Cmd {
    /// Fuzz: mutate the built-in seeds, run each case in a child, keep what fails.
    Run {
        /// Run seed (the same seed gives the same sequence of cases); default: from the clock.
        #[arg(long)]
        seed: Option<u64>,
        /// Total wall-clock budget, shared equally by the kinds.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// At most this many cases per kind.
        #[arg(long)]
        cases: Option<u64>,
        /// Comma-separated kinds (default: all).
        #[arg(long, value_delimiter = ',')]
        kinds: Vec<String>,
        /// Where findings are written (`<kind>/<class>-<hash>.<ext>` and findings.txt).
        #[arg(long, default_value = "fuzz-findings")]
        out: PathBuf,
        /// Parallel child processes (default: the number of CPUs).
        #[arg(long)]
        jobs: Option<usize>,
        /// Cases per child process.
        #[arg(long, default_value_t = 64)]
        batch: usize,
        /// Write findings as found, without shrinking them.
        #[arg(long)]
        no_minimize: bool,
        /// Where cases are written (default: /dev/shm when it has 1 GiB free, else TMPDIR).
        #[arg(long)]
        work_dir: Option<PathBuf>,
        #[command(flatten)]
        limits: LimitArgs,
    },
    /// Run every kept regression input; fail on any finding.
    Replay {
        /// The regression folder (`<kind>/…`); default: crates/objview-fuzz/regressions.
        dir: Option<PathBuf>,
        #[command(flatten)]
        limits: LimitArgs,
    },
    /// Run one file as KIND in a child process and classify it (exit 1 on a finding).
    One {
        kind: String,
        file: PathBuf,
        #[command(flatten)]
        limits: LimitArgs,
    },
    /// Write case I of the sequence of SEED for KIND into a folder.
    Gen {
        kind: String,
        #[arg(long)]
        seed: u64,
        #[arg(long)]
        case: u64,
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        allow_test_kinds: bool,
    },
    /// List the kinds.
    List,
    /// Internal: run the cases of LIST (lines `ID<TAB>PATH`) as KIND and report on stdout.
    #[command(hide = true)]
    Child { kind: String, list: PathBuf },
}

fn main() -> ExitCode {
    match real_main() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("objview-fuzz: {e}");
            ExitCode::from(2)
        }
    }
}

fn exe() -> Result<PathBuf, String> {
    std::env::current_exe().map_err(|e| format!("cannot locate the objview-fuzz binary: {e}"))
}

fn real_main() -> Result<ExitCode, String> {
    let cli = Cli::parse();
    match cli.command {
        Cmd::Child { kind, list } => {
            let kind = Kind::from_name(&kind).ok_or_else(|| format!("unknown kind '{kind}'"))?;
            Ok(ExitCode::from(objview_fuzz::child::child_main(kind, &list) as u8))
        }
        Cmd::List => {
            for &k in Kind::ALL {
                println!(
                    "{:<12} .{:<6} {:<16} {} seeds",
                    k.name(),
                    k.ext(),
                    k.owner(),
                    corpus::seeds(k).len()
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Gen { kind, seed, case, out, allow_test_kinds } => {
            let kind = parse_kind(&kind, allow_test_kinds)?;
            let c = mutate::make_case(kind, seed, case, &corpus::seeds(kind));
            let main = c.write_to(&out).map_err(|e| format!("{}: {e}", out.display()))?;
            println!("{}", main.display());
            Ok(ExitCode::SUCCESS)
        }
        Cmd::One { kind, file, limits } => {
            let kind = limits.kind(&kind)?;
            let work = tempfile::tempdir_in(fuzz::default_work_root()).map_err(|e| e.to_string())?;
            let exec = objview_fuzz::exec::Executor {
                exe: exe()?,
                limits: limits.limits(),
                work: work.path().to_path_buf(),
            };
            let o = exec.run_one(kind, &file).map_err(|e| e.to_string())?;
            println!("{}: {}", o.class.name(), o.detail);
            Ok(if o.class.is_finding() { ExitCode::from(1) } else { ExitCode::SUCCESS })
        }
        Cmd::Replay { dir, limits } => {
            let dir = dir.unwrap_or_else(objview_fuzz::regressions_dir);
            let all = objview_fuzz::replay(&dir, &exe()?, limits.limits(), limits.allow_test_kinds)
                .map_err(|e| format!("{}: {e}", dir.display()))?;
            let mut bad = 0;
            for r in &all {
                let mark = if r.outcome.class.is_finding() { "FAIL" } else { "pass" };
                bad += usize::from(r.outcome.class.is_finding());
                println!("{mark} {:<8} {} ({})", r.outcome.class.name(), r.path.display(), r.outcome.detail);
            }
            println!("{} regression inputs, {bad} failing", all.len());
            Ok(if bad > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS })
        }
        Cmd::Run { seed, seconds, cases, kinds, out, jobs, batch, no_minimize, work_dir, limits } => {
            let seed = seed.unwrap_or_else(|| {
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(1, |d| d.as_nanos() as u64)
            });
            let kinds: Vec<Kind> = if kinds.is_empty() || kinds == ["all"] {
                Kind::ALL.to_vec()
            } else {
                kinds.iter().map(|k| limits.kind(k)).collect::<Result<_, _>>()?
            };
            let jobs = jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()));
            let mut s = fuzz::Settings::new(exe()?, seed);
            s.seconds = seconds;
            s.max_cases = cases;
            s.kinds = kinds;
            s.out = Some(out.clone());
            s.jobs = jobs;
            s.batch = batch;
            s.limits = limits.limits();
            s.minimize = !no_minimize;
            s.work_root = work_dir;
            s.verbose = true;
            eprintln!(
                "objview-fuzz run --seed {seed} --seconds {seconds} --jobs {jobs} ({} kinds)",
                s.kinds.len()
            );
            let summary = fuzz::fuzz(&s).map_err(|e| e.to_string())?;
            let total: u64 = summary.kinds.iter().map(|(_, st)| st.cases).sum();
            let secs: f64 = summary.kinds.iter().map(|(_, st)| st.seconds).sum();
            println!(
                "seed {seed}: {total} cases in {secs:.1} s ({:.0}/s), {} distinct findings",
                total as f64 / secs.max(1e-9),
                summary.findings.len()
            );
            for f in &summary.findings {
                println!(
                    "  {} case {} {}: {} [{}]",
                    f.kind.name(),
                    f.case,
                    f.class.name(),
                    f.detail,
                    f.file.as_deref().map_or_else(|| "-".into(), |p| p.display().to_string())
                );
            }
            if !summary.findings.is_empty() {
                println!("findings written under {} (see findings.txt)", out.display());
            }
            Ok(if summary.findings.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
    }
}
