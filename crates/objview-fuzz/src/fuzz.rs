//! Fuzzing campaigns and regression replay.
//!
//! [`fuzz`] runs, kind after kind, cases `0, 1, 2, …` of the seeded sequence ([`make_case`])
//! on `jobs` parallel children until the kind's share of the time budget is spent or `max_cases`
//! is reached. Findings (outcomes other than ok or a clean error) are de-duplicated by (kind,
//! class, signature); of each signature the cases with the lowest numbers are kept (so a seed's
//! findings do not depend on which worker got where first). When the kind is done they are
//! shrunk when cheap (drop the files beside the main one, shortest prefix that still fails,
//! chunk removal; never for timeouts) and written under the output folder as
//! `<kind>/<class>-<hash>.<ext>` (a folder of files when the main file needs the files beside
//! it), with a line in `findings.txt` naming the kind, seed, case number and class. Copy a
//! finding into `crates/objview-fuzz/regressions/<kind>/` to keep it.
//!
//! [`replay`] runs every file (or case folder) of `regressions/<kind>/` through its kind's
//! loader, each from a private copy (some loaders rewrite their input), in child processes.

use std::collections::HashMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use objview_geom::hash::fnv1a64;

use crate::corpus::{main_name, seeds, Case};
use crate::exec::{Class, Executor, Limits, Outcome};
use crate::kinds::Kind;
use crate::mutate::make_case;

/// Settings of a campaign.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The `objview-fuzz` binary (re-executed for every child).
    pub exe: PathBuf,
    /// Seed of the case sequence of every kind ([`make_case`]).
    pub seed: u64,
    /// Wall-clock budget of the whole campaign, shared equally by the kinds.
    pub seconds: f64,
    /// At most this many cases per kind (the seeded sequence's first cases).
    pub max_cases: Option<u64>,
    /// The kinds to fuzz, in run order.
    pub kinds: Vec<Kind>,
    /// Where findings are written (nothing is written without it).
    pub out: Option<PathBuf>,
    /// Parallel children.
    pub jobs: usize,
    /// Cases per child process.
    pub batch: usize,
    /// Time and memory limits of every case.
    pub limits: Limits,
    /// Shrink findings before writing them.
    pub minimize: bool,
    /// Print progress and findings on stderr.
    pub verbose: bool,
    /// Where the cases are written (default: [`default_work_root`]).
    pub work_root: Option<PathBuf>,
}

/// Where cases are written by default: `/dev/shm` when it is a writable folder with at least
/// 1 GiB free (a RAM file system: about ten times the throughput of a journaling disk, where
/// rewriting thousands of small files per second dominates), else the system's temporary folder.
pub fn default_work_root() -> PathBuf {
    let shm = Path::new("/dev/shm");
    let ok = shm.is_dir() && free_bytes(shm).is_some_and(|b| b >= 1 << 30) && {
        let probe = shm.join(format!(".objview-fuzz-probe-{}", std::process::id()));
        let ok = std::fs::write(&probe, b"x").is_ok();
        let _ = std::fs::remove_file(&probe);
        ok
    };
    if ok {
        shm.to_path_buf()
    } else {
        std::env::temp_dir()
    }
}

/// Free bytes of the file system holding `p` (`statvfs`).
fn free_bytes(p: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(p.as_os_str().as_bytes()).ok()?;
    // SAFETY: `c` is a valid NUL-terminated path and `st` a writable statvfs owned here.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return None;
    }
    Some(st.f_bavail as u64 * st.f_frsize as u64)
}

impl Settings {
    /// Defaults: 60 s over every real kind, 2 children, batches of 64, default limits.
    pub fn new(exe: PathBuf, seed: u64) -> Settings {
        Settings {
            exe,
            seed,
            seconds: 60.0,
            max_cases: None,
            kinds: Kind::ALL.to_vec(),
            out: None,
            jobs: 2,
            batch: 64,
            limits: Limits::default(),
            minimize: true,
            verbose: false,
            work_root: None,
        }
    }
}

/// Counts of one kind.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct KindStats {
    /// Cases run.
    pub cases: u64,
    /// Cases that loaded a valid object.
    pub ok: u64,
    /// Cases that ended in one clean error.
    pub errors: u64,
    /// Cases with a finding (duplicates included).
    pub findings: u64,
    /// Wall time spent on the kind, seconds.
    pub seconds: f64,
}

impl KindStats {
    /// Cases per second.
    pub fn rate(&self) -> f64 {
        if self.seconds > 0.0 {
            self.cases as f64 / self.seconds
        } else {
            0.0
        }
    }
}

/// One distinct defect.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// The input kind whose loader misbehaved.
    pub kind: Kind,
    /// The campaign seed of the case sequence.
    pub seed: u64,
    /// Case number in the seeded sequence (reproduce with `objview-fuzz gen`).
    pub case: u64,
    /// How the case ended (panic, abort, timeout, oom or invalid object).
    pub class: Class,
    /// One line: the panic message, signal, reason, …
    pub detail: String,
    /// What identifies the defect for de-duplication: the panic location, the signal, …
    pub signature: String,
    /// Where the (shrunk) input was written.
    pub file: Option<PathBuf>,
    /// The input's size after shrinking.
    pub bytes: usize,
}

/// What a campaign did.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    /// Counts per kind, in run order.
    pub kinds: Vec<(Kind, KindStats)>,
    /// Distinct findings (the first few inputs of each signature).
    pub findings: Vec<Finding>,
    /// Cases per (kind, class, signature), duplicates included.
    pub signatures: Vec<((Kind, Class, String), u64)>,
}

/// Inputs kept per signature: one for a panic, abort or invalid object (the location, signal or
/// reason identifies it), a few for out-of-memory and timeouts (one signature may hide several
/// defects).
fn keep_per_signature(class: Class) -> u64 {
    match class {
        Class::Oom | Class::Timeout => 3,
        _ => 1,
    }
}

/// Per (kind, class, signature): how many cases hit it, and the lowest case numbers (with
/// their outcomes) — the ones written, so that a campaign's findings do not depend on which
/// worker got there first.
type Candidates = HashMap<(Kind, Class, String), (u64, Vec<(u64, Outcome)>)>;

/// Runs a campaign (see the module docs).
pub fn fuzz(settings: &Settings) -> std::io::Result<Summary> {
    let work_root = settings.work_root.clone().unwrap_or_else(default_work_root);
    let root = tempfile::Builder::new().prefix("objview-fuzz-").tempdir_in(&work_root)?;
    let mut written = std::collections::HashSet::new();
    if let Some(out) = &settings.out {
        std::fs::create_dir_all(out)?;
    }
    let per_kind = settings.seconds / settings.kinds.len().max(1) as f64;
    let mut summary = Summary::default();
    for &kind in &settings.kinds {
        let corpus = seeds(kind);
        let start = Instant::now();
        let deadline = start + Duration::from_secs_f64(per_kind.max(0.0));
        let next = AtomicU64::new(0);
        let stats = Mutex::new(KindStats::default());
        let candidates: Mutex<Candidates> = Mutex::new(HashMap::new());
        let errors: Mutex<Vec<std::io::Error>> = Mutex::new(Vec::new());
        std::thread::scope(|s| {
            for job in 0..settings.jobs.max(1) {
                let work = root.path().join(format!("{}-{job}", kind.name()));
                let (corpus, next, stats, candidates, errors) =
                    (&corpus, &next, &stats, &candidates, &errors);
                s.spawn(move || {
                    let r = worker(settings, kind, corpus, &work, deadline, next, stats, candidates);
                    if let Err(e) = r {
                        errors.lock().expect("no panics while holding").push(e);
                    }
                });
            }
        });
        if let Some(e) = errors.into_inner().expect("no panics while holding").pop() {
            return Err(e);
        }
        let mut st = stats.into_inner().expect("no panics while holding");
        st.seconds = start.elapsed().as_secs_f64();
        if settings.verbose {
            eprintln!(
                "{:>12}: {:>6} cases in {:5.1} s ({:6.0}/s): ok {}, clean error {}, findings {}",
                kind.name(),
                st.cases,
                st.seconds,
                st.rate(),
                st.ok,
                st.errors,
                st.findings
            );
        }
        summary.kinds.push((kind, st));
        // Shrink and write the kept inputs, in a fixed order.
        let mut cands: Vec<_> =
            candidates.into_inner().expect("no panics while holding").into_iter().collect();
        cands.sort_by(|a, b| a.0.cmp(&b.0));
        let exec =
            Executor { exe: settings.exe.clone(), limits: settings.limits, work: root.path().join("record") };
        for (key, (count, kept)) in cands {
            summary.signatures.push((key, count));
            for (index, o) in kept {
                let case = make_case(kind, settings.seed, index, &corpus);
                let f = record(settings, kind, index, &case, &o, &exec, &root.path().join("min"))?;
                // Shrinking may take two cases of a signature to the same input: keep it once.
                if f.file.as_ref().is_none_or(|p| written.insert(p.clone())) {
                    log_finding(settings, &f)?;
                    summary.findings.push(f);
                }
            }
        }
    }
    Ok(summary)
}

#[allow(clippy::too_many_arguments)]
fn worker(
    s: &Settings,
    kind: Kind,
    corpus: &[Case],
    work: &Path,
    deadline: Instant,
    next: &AtomicU64,
    stats: &Mutex<KindStats>,
    candidates: &Mutex<Candidates>,
) -> std::io::Result<()> {
    let exec = Executor { exe: s.exe.clone(), limits: s.limits, work: work.join("exec") };
    let batch = s.batch.max(1) as u64;
    while Instant::now() < deadline {
        let first = next.fetch_add(batch, Ordering::Relaxed);
        let last = match s.max_cases {
            Some(m) if first >= m => break,
            Some(m) => (first + batch).min(m),
            None => first + batch,
        };
        let mut list = Vec::with_capacity((last - first) as usize);
        for (slot, i) in (first..last).enumerate() {
            let case = make_case(kind, s.seed, i, corpus);
            list.push((i, case.write_into_slot(&work.join(format!("s{slot}")))?));
        }
        let outcomes = exec.run(kind, &list)?;
        {
            let mut st = stats.lock().expect("no panics while holding");
            for (_, o) in &outcomes {
                st.cases += 1;
                match o.class {
                    Class::Ok => st.ok += 1,
                    Class::Error => st.errors += 1,
                    _ => st.findings += 1,
                }
            }
        }
        for (i, o) in outcomes {
            if o.class.is_finding() {
                let keep = keep_per_signature(o.class) as usize;
                let mut c = candidates.lock().expect("no panics while holding");
                let (count, kept) = c.entry((kind, o.class, o.signature.clone())).or_default();
                *count += 1;
                kept.push((i, o));
                kept.sort_by_key(|(i, _)| *i);
                kept.truncate(keep);
            }
        }
    }
    Ok(())
}

/// Shrinks and writes one finding.
fn record(
    s: &Settings,
    kind: Kind,
    index: u64,
    case: &Case,
    o: &Outcome,
    exec: &Executor,
    min_dir: &Path,
) -> std::io::Result<Finding> {
    let case = if s.minimize && o.class != Class::Timeout {
        minimize(kind, case, o, exec, min_dir)?
    } else {
        case.clone()
    };
    let file = match &s.out {
        Some(out) => Some(write_finding(out, kind, o.class, &case)?),
        None => None,
    };
    Ok(Finding {
        kind,
        seed: s.seed,
        case: index,
        class: o.class,
        detail: o.detail.clone(),
        signature: o.signature.clone(),
        file,
        bytes: case.len(),
    })
}

/// Prints a finding (when verbose) and appends it to `findings.txt` of the output folder.
fn log_finding(s: &Settings, f: &Finding) -> std::io::Result<()> {
    let line = format!(
        "kind={} seed={} case={} class={} bytes={} file={} crate={} detail={}\n",
        f.kind.name(),
        f.seed,
        f.case,
        f.class.name(),
        f.bytes,
        f.file
            .as_deref()
            .map(|p| s.out.as_deref().and_then(|o| p.strip_prefix(o).ok()).unwrap_or(p))
            .map_or_else(|| "-".into(), |p| p.display().to_string()),
        f.kind.owner(),
        f.detail
    );
    if s.verbose {
        eprint!("FINDING {line}");
    }
    if let Some(out) = &s.out {
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(out.join("findings.txt"))?
            .write_all(line.as_bytes())?;
    }
    Ok(())
}

/// Writes a case as `<out>/<kind>/<class>-<hash>.<ext>`, or as a folder of that name (main file
/// `case.<ext>`) when it has files beside the main one (the name is a hash of the content: the
/// same input is written once). Returns the path.
pub fn write_finding(out: &Path, kind: Kind, class: Class, case: &Case) -> std::io::Result<PathBuf> {
    let mut all = Vec::new();
    for (n, b) in &case.files {
        all.extend_from_slice(n.as_bytes());
        all.push(0);
        all.extend_from_slice(b);
    }
    let stem = format!("{}-{:016x}", class.name(), fnv1a64(&all));
    let dir = out.join(kind.name());
    std::fs::create_dir_all(&dir)?;
    let p = if case.files.len() == 1 { dir.join(format!("{stem}.{}", kind.ext())) } else { dir.join(stem) };
    if case.files.len() == 1 {
        std::fs::write(&p, case.main())?;
    } else {
        case.write_to(&p)?;
    }
    Ok(p)
}

/// Whether `case` still gives the same finding as `want` (class and signature).
fn reproduces(kind: Kind, case: &Case, want: &Outcome, exec: &Executor, dir: &Path) -> std::io::Result<bool> {
    let _ = std::fs::remove_dir_all(dir);
    let main = case.write_to(dir)?;
    let o = exec.run_one(kind, &main)?;
    Ok(o.class == want.class && o.signature == want.signature)
}

/// Shrinks a failing case cheaply (bounded attempts and time): drop the files beside the main
/// one, find the shortest failing prefix of the main file, then remove chunks.
pub fn minimize(
    kind: Kind,
    case: &Case,
    want: &Outcome,
    exec: &Executor,
    dir: &Path,
) -> std::io::Result<Case> {
    let start = Instant::now();
    let mut attempts = 0;
    let budget = |attempts: &mut u32| {
        *attempts += 1;
        *attempts <= 64 && start.elapsed() < Duration::from_secs(10)
    };
    let mut best = case.clone();
    // The files beside the main one, each dropped if not needed.
    let mut k = 1;
    while k < best.files.len() && budget(&mut attempts) {
        let mut c = best.clone();
        c.files.remove(k);
        if reproduces(kind, &c, want, exec, dir)? {
            best = c;
        } else {
            k += 1;
        }
    }
    // Shortest failing prefix (bisection; assumes failing is roughly monotone in length).
    let (mut lo, mut hi) = (0usize, best.main().len());
    while hi - lo > 1 && budget(&mut attempts) {
        let mid = lo + (hi - lo) / 2;
        let mut c = best.clone();
        c.files[0].1.truncate(mid);
        if reproduces(kind, &c, want, exec, dir)? {
            hi = mid;
            best = c;
        } else {
            lo = mid;
        }
    }
    // Chunk removal, big chunks first.
    let mut chunk = best.main().len() / 2;
    while chunk >= 1 {
        let mut pos = 0;
        while pos + chunk <= best.main().len() {
            if !budget(&mut attempts) {
                return Ok(best);
            }
            let mut c = best.clone();
            c.files[0].1.drain(pos..pos + chunk);
            if reproduces(kind, &c, want, exec, dir)? {
                best = c;
            } else {
                pos += chunk;
            }
        }
        chunk /= 2;
    }
    let _ = std::fs::remove_dir_all(dir);
    Ok(best)
}

/// One regression input and its outcome.
#[derive(Debug, Clone)]
pub struct Replayed {
    /// The kind (the regression's folder name).
    pub kind: Kind,
    /// The file or case folder under the regression folder.
    pub path: PathBuf,
    /// How loading it ended.
    pub outcome: Outcome,
}

/// Runs every regression under `dir` (`<kind>/<file>` or `<kind>/<folder>/case.<ext>` plus the
/// files it names). Folders that are not kind names are an error, except test kinds when
/// `allow_test` (hidden files and `*.md` are skipped).
pub fn replay(dir: &Path, exe: &Path, limits: Limits, allow_test: bool) -> std::io::Result<Vec<Replayed>> {
    let root = tempfile::Builder::new().prefix("objview-fuzz-replay-").tempdir_in(default_work_root())?;
    let exec = Executor { exe: exe.to_path_buf(), limits, work: root.path().join("exec") };
    let mut out = Vec::new();
    let mut kinds: Vec<PathBuf> =
        std::fs::read_dir(dir)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
    kinds.sort();
    for kdir in kinds {
        if !kdir.is_dir() {
            continue;
        }
        let name = kdir.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let kind = Kind::from_name(name).filter(|k| allow_test || !k.is_test()).ok_or_else(|| {
            std::io::Error::other(format!("{}: not a kind folder (kinds: {})", kdir.display(), kind_names()))
        })?;
        let mut entries: Vec<PathBuf> =
            std::fs::read_dir(&kdir)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
        entries.retain(|p| {
            let n = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            !n.starts_with('.') && !n.ends_with(".md")
        });
        entries.sort();
        let mut list = Vec::new();
        for (i, e) in entries.iter().enumerate() {
            let case_dir = root.path().join(format!("{name}-{i}"));
            std::fs::create_dir_all(&case_dir)?;
            let main = if e.is_dir() {
                let mut main = None;
                for f in std::fs::read_dir(e)? {
                    let f = f?.path();
                    let fname = f.file_name().expect("entry has a name").to_owned();
                    std::fs::copy(&f, case_dir.join(&fname))?;
                    if fname.to_str() == Some(main_name(kind).as_str()) {
                        main = Some(case_dir.join(&fname));
                    }
                }
                main.ok_or_else(|| {
                    std::io::Error::other(format!("{}: case folder without {}", e.display(), main_name(kind)))
                })?
            } else {
                let p = case_dir.join(e.file_name().expect("entry has a name"));
                std::fs::copy(e, &p)?;
                p
            };
            list.push((i as u64, main));
        }
        for (i, o) in exec.run(kind, &list)? {
            out.push(Replayed { kind, path: entries[i as usize].clone(), outcome: o });
        }
    }
    Ok(out)
}

/// The real kinds' names, comma separated.
pub fn kind_names() -> String {
    Kind::ALL.iter().map(|k| k.name()).collect::<Vec<_>>().join(", ")
}
