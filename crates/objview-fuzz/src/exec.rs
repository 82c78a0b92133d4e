//! The parent side: runs cases in child processes (the fuzzer's own binary, `objview-fuzz child
//! KIND LIST`) under a memory limit (`RLIMIT_AS`, set between fork and exec; core dumps off,
//! written files capped) and a wall-clock limit per case (the parent kills the child), and
//! classifies each case.
//!
//! Many cases run in one child, for throughput. The child reports `start ID` before each case,
//! so when it dies — abort, signal, out of memory — or stops answering, the case it was in is
//! known exactly; that case is then re-run alone in a fresh child (its outcome is the solo
//! run's, so that state left by earlier cases in the batch cannot be blamed on it) and the
//! batch goes on with the next case in a new child.

use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::child::PREFIX;
use crate::kinds::Kind;

/// Resource limits of one case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Wall-clock time a case may take.
    pub timeout: Duration,
    /// Address-space limit of the child process (bytes).
    pub mem_bytes: u64,
}

impl Default for Limits {
    /// 10 s and 2 GiB.
    fn default() -> Limits {
        Limits { timeout: Duration::from_secs(10), mem_bytes: 2 << 30 }
    }
}

/// How a case ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Class {
    /// A valid object.
    Ok,
    /// One clean, one-line error.
    Error,
    /// A panic (also one the loader caught and turned into an error).
    Panic,
    /// The process aborted, died of a signal (stack overflow included) or exited mid-case.
    Abort,
    /// No result within the time limit.
    Timeout,
    /// An allocation failed under the memory limit.
    Oom,
    /// An object that breaks an invariant, or an error message that is not one line.
    Invalid,
}

impl Class {
    /// Lower-case name, used in file names and reports.
    pub fn name(self) -> &'static str {
        match self {
            Class::Ok => "ok",
            Class::Error => "error",
            Class::Panic => "panic",
            Class::Abort => "abort",
            Class::Timeout => "timeout",
            Class::Oom => "oom",
            Class::Invalid => "invalid",
        }
    }

    /// Whether this outcome is a defect (anything but ok and a clean error).
    pub fn is_finding(self) -> bool {
        !matches!(self, Class::Ok | Class::Error)
    }
}

/// The outcome of one case.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// How the case ended.
    pub class: Class,
    /// One line: the object summary, error, panic message, signal, …
    pub detail: String,
    /// What identifies the defect for de-duplication: the panic location, the signal, …
    pub signature: String,
}

impl Outcome {
    fn new(class: Class, detail: impl Into<String>, signature: impl Into<String>) -> Outcome {
        Outcome { class, detail: detail.into(), signature: signature.into() }
    }
}

/// Runs cases of a kind in child processes.
#[derive(Debug, Clone)]
pub struct Executor {
    /// The `objview-fuzz` binary.
    pub exe: PathBuf,
    /// Time and memory limits of every case.
    pub limits: Limits,
    /// A private folder for the case lists and the child's stderr.
    pub work: PathBuf,
}

/// The outcomes of the cases a child finished, and the crash that ended it early, if any.
type BatchResult = (Vec<(u64, Outcome)>, Option<Crash>);

/// A child that died (or was killed) in the middle of the case at this index of its list.
struct Crash {
    index: usize,
    outcome: Outcome,
}

impl Executor {
    /// Runs `cases` (id, main file) and returns every case's outcome, in order.
    pub fn run(&self, kind: Kind, cases: &[(u64, PathBuf)]) -> std::io::Result<Vec<(u64, Outcome)>> {
        let mut out = Vec::with_capacity(cases.len());
        let mut rest = cases;
        while !rest.is_empty() {
            let (done, crash) = self.batch(kind, rest)?;
            out.extend(done);
            let Some(Crash { index, outcome }) = crash else { break };
            let id = rest[index].0;
            let outcome = if index > 0 {
                // Earlier cases ran in that process: the solo run decides.
                match self.batch(kind, &rest[index..=index])? {
                    (mut d, None) if d.len() == 1 => d.remove(0).1,
                    (_, Some(c)) => c.outcome,
                    (d, None) => return Err(harness(format!("solo run returned {} results", d.len()))),
                }
            } else {
                outcome
            };
            out.push((id, outcome));
            rest = &rest[index + 1..];
        }
        Ok(out)
    }

    /// Runs one file in a fresh child.
    pub fn run_one(&self, kind: Kind, path: &Path) -> std::io::Result<Outcome> {
        let mut r = self.run(kind, &[(0, path.to_path_buf())])?;
        r.pop().map(|(_, o)| o).ok_or_else(|| harness("no outcome".into()))
    }

    /// One child over `cases`: the outcomes of the cases it finished, and the crash that ended
    /// it early, if any.
    fn batch(&self, kind: Kind, cases: &[(u64, PathBuf)]) -> std::io::Result<BatchResult> {
        std::fs::create_dir_all(&self.work)?;
        let list = self.work.join("cases.txt");
        let mut text = String::new();
        for (id, p) in cases {
            let p = p.to_str().ok_or_else(|| harness(format!("non-UTF-8 path {}", p.display())))?;
            if p.contains(['\n', '\t']) {
                return Err(harness(format!("path with a tab or newline: {p:?}")));
            }
            text.push_str(&format!("{id}\t{p}\n"));
        }
        std::fs::write(&list, text)?;
        let stderr_path = self.work.join("stderr.txt");
        let stderr = std::fs::File::create(&stderr_path)?;
        let mut cmd = Command::new(&self.exe);
        cmd.arg("child")
            .arg(kind.name())
            .arg(&list)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
            .env("RUST_BACKTRACE", "0");
        let mem = self.limits.mem_bytes;
        // SAFETY: the closure runs between fork and exec and only calls setrlimit, which is
        // async-signal-safe; it touches no memory shared with the parent.
        unsafe {
            cmd.pre_exec(move || {
                let lim = |v: u64| libc::rlimit { rlim_cur: v as libc::rlim_t, rlim_max: v as libc::rlim_t };
                if libc::setrlimit(libc::RLIMIT_AS, &lim(mem)) != 0
                    || libc::setrlimit(libc::RLIMIT_CORE, &lim(0)) != 0
                    || libc::setrlimit(libc::RLIMIT_FSIZE, &lim(256 << 20)) != 0
                {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let mut child = cmd.spawn()?;
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, rx) = mpsc::channel::<String>();
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if let Some(rest) = line.strip_prefix(PREFIX) {
                    if tx.send(rest.to_string()).is_err() {
                        break;
                    }
                }
            }
        });

        let mut done: Vec<(u64, Outcome)> = Vec::new();
        // (index into `cases`, when it started); the oom marker seen during it.
        let mut current: Option<(usize, Instant)> = None;
        let mut oom: Option<u64> = None;
        let mut finished = false;
        let mut killed = false;
        let started = Instant::now();
        loop {
            let wait = match current {
                Some((_, t0)) => (t0 + self.limits.timeout).saturating_duration_since(Instant::now()),
                // Start-up and between cases: generous, but bounded.
                None => (started + self.limits.timeout * 3).saturating_duration_since(Instant::now()),
            };
            match rx.recv_timeout(wait) {
                Ok(line) => {
                    let (verb, rest) = line.split_once(' ').unwrap_or((line.as_str(), ""));
                    match verb {
                        "start" => {
                            let id: u64 =
                                rest.trim().parse().map_err(|_| harness(format!("bad line {line:?}")))?;
                            let k = done.len();
                            if cases.get(k).map(|c| c.0) != Some(id) {
                                return Err(harness(format!("child started case {id}, expected index {k}")));
                            }
                            current = Some((k, Instant::now()));
                            oom = None;
                        }
                        "oom" => oom = rest.trim().parse().ok().or(Some(0)),
                        "done" => finished = true,
                        "ok" | "error" | "invalid" | "panic" | "oom-recovered" => {
                            let (id, text) = rest.split_once(' ').unwrap_or((rest, ""));
                            let id: u64 = id.parse().map_err(|_| harness(format!("bad line {line:?}")))?;
                            if current.map(|(k, _)| cases[k].0) != Some(id) {
                                return Err(harness(format!("result for case {id} out of order")));
                            }
                            done.push((id, parse_result(verb, text)));
                            current = None;
                        }
                        _ => {}
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    let _ = child.kill();
                    killed = true;
                    break;
                }
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
        let status = child.wait()?;
        let _ = reader.join();
        if let Some((index, _)) = current {
            let tail = tail(&stderr_path, 8192);
            let outcome = if killed {
                Outcome::new(Class::Timeout, format!("no result after {:?}", self.limits.timeout), "timeout")
            } else {
                crash_outcome(status, oom, &tail, self.limits.mem_bytes)
            };
            return Ok((done, Some(Crash { index, outcome })));
        }
        if killed || !finished || !status.success() || done.len() != cases.len() {
            return Err(harness(format!(
                "child for {} ended outside a case ({status}, {} of {} results, killed: {killed}); stderr: {}",
                kind.name(),
                done.len(),
                cases.len(),
                tail(&stderr_path, 600).trim()
            )));
        }
        Ok((done, None))
    }
}

fn harness(msg: String) -> std::io::Error {
    std::io::Error::other(format!("objview-fuzz harness: {msg}"))
}

/// The outcome of a result line `VERB TEXT`.
fn parse_result(verb: &str, text: &str) -> Outcome {
    match verb {
        "ok" => Outcome::new(Class::Ok, text, ""),
        "error" => Outcome::new(Class::Error, text, ""),
        "oom-recovered" => Outcome::new(Class::Oom, text, "oom"),
        // The reason up to its first colon, without numbers: "error message is not one line",
        // "vertex colours for vertices", …
        "invalid" => Outcome::new(
            Class::Invalid,
            text,
            text.split(':')
                .next()
                .unwrap_or("")
                .chars()
                .filter(|c| !c.is_ascii_digit())
                .take(60)
                .collect::<String>(),
        ),
        _ => {
            // `caught|uncaught LOCATION MESSAGE`
            let mut it = text.splitn(3, ' ');
            let how = it.next().unwrap_or("");
            let loc = it.next().unwrap_or("");
            let msg = it.next().unwrap_or("");
            let how = if how == "caught" { "caught by the loader" } else { "uncaught" };
            Outcome::new(Class::Panic, format!("panic ({how}) at {loc}: {msg}"), short_location(loc))
        }
    }
}

/// `…/crate-1.2.3/src/file.rs:10` → `crate-1.2.3/src/file.rs:10` (stable across machines).
fn short_location(loc: &str) -> String {
    let parts: Vec<&str> = loc.split('/').collect();
    let keep = parts.iter().rposition(|p| *p == "src").map_or(0, |i| i.saturating_sub(1));
    parts[keep..].join("/")
}

fn signal_name(sig: i32) -> String {
    match sig {
        libc::SIGABRT => "SIGABRT".into(),
        libc::SIGSEGV => "SIGSEGV".into(),
        libc::SIGBUS => "SIGBUS".into(),
        libc::SIGILL => "SIGILL".into(),
        libc::SIGFPE => "SIGFPE".into(),
        libc::SIGKILL => "SIGKILL".into(),
        libc::SIGTRAP => "SIGTRAP".into(),
        libc::SIGXFSZ => "SIGXFSZ (file size limit)".into(),
        libc::SIGXCPU => "SIGXCPU".into(),
        s => format!("signal {s}"),
    }
}

/// Classifies a child that died during a case.
fn crash_outcome(status: ExitStatus, oom: Option<u64>, stderr_tail: &str, mem: u64) -> Outcome {
    let last_line = stderr_tail.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_string();
    if oom.is_some() || stderr_tail.contains("memory allocation of") {
        let size = oom.map_or_else(|| last_line.clone(), |n| format!("an allocation of {n} bytes failed"));
        return Outcome::new(Class::Oom, format!("{size} (address-space limit {} MiB)", mem >> 20), "oom");
    }
    if stderr_tail.contains("has overflowed its stack") {
        return Outcome::new(Class::Abort, format!("stack overflow: {last_line}"), "stack overflow");
    }
    match (status.signal(), status.code()) {
        (Some(sig), _) => {
            let name = signal_name(sig);
            Outcome::new(Class::Abort, format!("killed by {name}; stderr: {last_line}"), name)
        }
        (None, Some(code)) => Outcome::new(
            Class::Abort,
            format!("process exited with code {code} in the middle of a case; stderr: {last_line}"),
            format!("exit {code}"),
        ),
        _ => Outcome::new(Class::Abort, format!("ended with {status}"), "unknown"),
    }
}

/// The last `n` bytes of a file, lossily as text.
fn tail(path: &Path, n: u64) -> String {
    let Ok(mut f) = std::fs::File::open(path) else { return String::new() };
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let _ = f.seek(SeekFrom::Start(len.saturating_sub(n)));
    let mut buf = Vec::new();
    let _ = f.read_to_end(&mut buf);
    String::from_utf8_lossy(&buf).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_and_results_parse() {
        assert_eq!(
            short_location(
                "/home/u/.cargo/registry/src/index.crates.io-6f17/ply-rs-bw-1.0.1/src/parser/mod.rs:40"
            ),
            "ply-rs-bw-1.0.1/src/parser/mod.rs:40"
        );
        assert_eq!(short_location("crates/objview-geom/src/io/off.rs:133"), "objview-geom/src/io/off.rs:133");
        let p = parse_result("panic", "caught a/src/b.rs:3 index out of bounds: 5");
        assert_eq!(p.class, Class::Panic);
        assert_eq!(p.signature, "a/src/b.rs:3");
        assert!(p.detail.contains("caught by the loader") && p.detail.contains("index out of bounds"));
        assert!(!Class::Error.is_finding() && Class::Invalid.is_finding());
    }
}
