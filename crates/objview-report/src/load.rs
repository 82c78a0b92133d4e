//! Reading episode result files (JSON Lines of [`EpisodeResult`], SPEC §5) for the report.
//!
//! Files are read in the order given, lines in file order. A line is one of:
//! - an episode result: checked here for what the tables rely on (a known execution mode, a
//!   valid budget, a known family, checkpoint names the result format knows, a `terminal`
//!   checkpoint, NSC/SC at the report's τ in every checkpoint and step), so that later stages
//!   never meet a missing value;
//! - a failure line (a JSON object with an `error` field, written for an episode that could
//!   not run): kept, counted and listed, never fatal;
//! - blank: skipped.
//!
//! Anything else — not JSON, not an object, not an episode result (a `null` where a number is
//! expected, a missing field), a result that fails the checks, an `objview annotate` line, a
//! method whose family or execution mode contradicts an earlier line — is a *skipped line*: left
//! out, and listed with its file, line and reason ([`SkippedLine`]), so that one bad line (a
//! hostile client's result, a hand edit) does not take the rest of the file with it. A torn last
//! line (no trailing newline and not JSON: an interrupted run) is skipped with a warning.
//!
//! Duplicates: of the episode results with the same (uid, method, view space, budget, seed), one
//! is kept. A run that *ended normally* always beats one that did not, wherever the lines are;
//! among runs of the same rank the last line wins. Normal ends are
//! [`objview_episode::ends_normally`]: the planner's own stop (`plan_end`, `candidate_exhausted`,
//! `next_view_visited`, `next_view_infeasible`) or the benchmark's limits (`max_cap_reached`,
//! `enough_info`, `budget_reached`); everything else is a failed run — an `exception`
//! (`planner_error`, `timeout`, `interrupted`, a server abort), an `invalid_action`, an unknown
//! reason. So a completed run followed by an aborted or timed-out re-run keeps the completed
//! one, and so does an aborted run followed by a completed one; two completed runs keep the later.
//! An iterative planner runs once and serves every budget setting (SPEC §5), so iterative runs of
//! the same (uid, method, view space, seed) under several budget labels are also collapsed: a
//! normal end first again, then the most views, then the later line. Both cases are listed as
//! warnings (with the dropped and kept runs' terminal reasons in `report.json`).
//!
//! The kept episodes are sorted by (uid, method, view space, seed, budget, source), so that means
//! do not depend on how shards were concatenated.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use objview_episode::result::EpisodeResult;
use objview_episode::{Budget, CheckpointKey, ExecutionMode, Family};
use serde::Serialize;
use serde_json::{json, Value};

use crate::ReportError;

/// One input file and what it held.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InputFile {
    /// The path as given.
    pub path: PathBuf,
    /// Complete non-blank lines.
    pub lines: usize,
    /// Of those, episode results (before removing duplicates).
    pub episodes: usize,
    /// Of those, failure lines.
    pub failures: usize,
    /// Of those, skipped lines (see [`SkippedLine`]).
    pub skipped: usize,
    /// Whether a torn last line (an interrupted write) was skipped.
    pub torn_last_line: bool,
}

/// Where a line came from: index into the input files, and line number (from 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct Source {
    /// Index into the input files.
    pub file: usize,
    /// Line number, from 1.
    pub line: usize,
}

/// A checked episode result.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    /// Where it was read.
    pub source: Source,
    /// The episode as read.
    pub result: EpisodeResult,
}

/// A failure line: an episode that could not run. Fields other than `error` are taken from the
/// line, or from its `settings` object (`objview run` writes `{uid, mesh, error, settings}` with
/// the planner, view space, budget and seed in `settings`); empty when absent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailureLine {
    /// Where it was read.
    pub source: Source,
    /// Which episode it was.
    #[serde(flatten)]
    pub keys: LineKeys,
    /// Why the episode could not run.
    pub error: String,
    /// An episode result with the same (uid, method, view space, budget, seed) exists (a retry
    /// succeeded).
    pub superseded: bool,
}

/// A line that is neither a usable episode result nor a failure line: left out of every table
/// and listed. What it says of its episode (uid, method, …) is kept when it is a JSON object.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SkippedLine {
    /// Where it was read.
    pub source: Source,
    /// Which episode it was about, as far as the line says.
    #[serde(flatten)]
    pub keys: LineKeys,
    /// Why it was skipped.
    pub reason: String,
}

impl SkippedLine {
    fn new(source: Source, value: Option<&Value>, reason: impl Into<String>) -> SkippedLine {
        let keys = value.filter(|v| v.is_object()).map(line_keys).unwrap_or_default();
        SkippedLine { source, keys, reason: reason.into() }
    }
}

/// What a failure or skipped line says of its episode; empty (`None` for the seed) where the
/// line does not say.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LineKeys {
    /// The object's id.
    pub uid: String,
    /// The method (a failure line of `objview run` names it `planner`).
    pub method: String,
    /// The view space.
    pub view_space: String,
    /// The budget as written (`5`, `auto`).
    pub budget: String,
    /// The seed, when the line has one.
    pub seed: Option<u64>,
}

impl LineKeys {
    /// The keys of an episode result.
    pub fn of_result(r: &EpisodeResult) -> LineKeys {
        LineKeys {
            uid: r.uid.clone(),
            method: r.method.clone(),
            view_space: r.view_space.clone(),
            budget: r.budget.to_string(),
            seed: Some(r.seed),
        }
    }

    /// uid, method, view space, budget and seed as table cells (an absent seed is empty).
    pub fn cells(&self) -> [String; 5] {
        [
            self.uid.clone(),
            self.method.clone(),
            self.view_space.clone(),
            self.budget.clone(),
            self.seed.map(|s| s.to_string()).unwrap_or_default(),
        ]
    }
}

/// Why an episode was dropped in favour of another.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DuplicateKind {
    /// Same (uid, method, view space, budget, seed): a run that ended normally is kept over one
    /// that failed, else the last one.
    SameKey,
    /// An iterative run of the same (uid, method, view space, seed) under another budget label:
    /// a run that ended normally is kept over one that failed, else the run with the most views
    /// (the later one on a tie).
    IterativeBudgets,
}

/// A dropped episode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Duplicate {
    /// Which rule dropped it.
    pub kind: DuplicateKind,
    /// The dropped episode's object.
    pub uid: String,
    /// Its method.
    pub method: String,
    /// Its view space.
    pub view_space: String,
    /// Its budget as written (`5`, `auto`).
    pub budget: String,
    /// Its seed.
    pub seed: u64,
    /// The episode kept instead.
    pub kept: Source,
    /// The episode dropped.
    pub dropped: Source,
    /// The kept episode's terminal reason.
    pub kept_terminal: String,
    /// The dropped episode's terminal reason.
    pub dropped_terminal: String,
    /// Whether the kept episode won because it ended normally and the dropped one did not
    /// (rather than by being the later line or having more views).
    pub failed_run_dropped: bool,
}

/// Everything read from the results files.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// The input files, in the order given.
    pub files: Vec<InputFile>,
    /// Kept episodes, sorted (see the module docs).
    pub episodes: Vec<Episode>,
    /// Failure lines, in input order.
    pub failures: Vec<FailureLine>,
    /// Skipped lines, in input order.
    pub skipped: Vec<SkippedLine>,
    /// Dropped duplicates, in input order of the dropped line.
    pub duplicates: Vec<Duplicate>,
    /// τ keys present in the NSC and SC of every checkpoint and step of every kept episode.
    pub taus: Vec<String>,
}

impl Loaded {
    /// `path:line` of a source.
    pub fn locate(&self, s: Source) -> String {
        locate(&self.files, s)
    }
}

fn locate(files: &[InputFile], s: Source) -> String {
    format!("{}:{}", files[s.file].path.display(), s.line)
}

/// Reads `paths` (see the module docs); `tau` is the τ key every checkpoint must have.
pub fn load_results(paths: &[PathBuf], tau: &str) -> Result<Loaded, ReportError> {
    if paths.is_empty() {
        return Err(ReportError::NoInputs);
    }
    let mut files = Vec::new();
    let mut raw = Vec::new();
    let mut failures = Vec::new();
    let mut skipped = Vec::new();
    for (file, path) in paths.iter().enumerate() {
        let text = objview_geom::fsutil::read_text(path).map_err(|e| ReportError::io(path, e))?;
        let mut info = InputFile {
            path: path.clone(),
            lines: 0,
            episodes: 0,
            failures: 0,
            skipped: 0,
            torn_last_line: false,
        };
        let complete = text.ends_with('\n');
        let all: Vec<&str> = text.lines().collect();
        for (i, line) in all.iter().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let source = Source { file, line: i + 1 };
            let value: Value = match serde_json::from_str(line) {
                Ok(v) => v,
                Err(_) if !complete && i + 1 == all.len() => {
                    info.torn_last_line = true;
                    continue;
                }
                Err(e) => {
                    info.lines += 1;
                    info.skipped += 1;
                    skipped.push(SkippedLine::new(source, None, format!("not JSON ({e})")));
                    continue;
                }
            };
            info.lines += 1;
            match read_line(value, source, tau) {
                Ok(Line::Failure(f)) => {
                    info.failures += 1;
                    failures.push(f);
                }
                Ok(Line::Episode(e)) => {
                    info.episodes += 1;
                    raw.push(*e);
                }
                Err(s) => {
                    info.skipped += 1;
                    skipped.push(*s);
                }
            }
        }
        files.push(info);
    }
    let mut contradicting = BTreeSet::new();
    for (e, reason) in contradicting_methods(&files, &raw) {
        contradicting.insert(e.source);
        let file = &mut files[e.source.file];
        file.episodes -= 1;
        file.skipped += 1;
        skipped.push(SkippedLine { source: e.source, keys: LineKeys::of_result(&e.result), reason });
    }
    raw.retain(|e| !contradicting.contains(&e.source));
    skipped.sort_by_key(|s| s.source);
    let (mut episodes, duplicates) = deduplicate(raw);
    episodes.sort_by(|a, b| sort_key(a).cmp(&sort_key(b)));
    let results: BTreeSet<(&str, &str, &str, String, u64)> = episodes
        .iter()
        .map(|e| {
            let r = &e.result;
            (r.uid.as_str(), r.method.as_str(), r.view_space.as_str(), r.budget.to_string(), r.seed)
        })
        .collect();
    for f in &mut failures {
        let k = &f.keys;
        f.superseded = k.seed.is_some_and(|seed| {
            results.contains(&(
                k.uid.as_str(),
                k.method.as_str(),
                k.view_space.as_str(),
                k.budget.clone(),
                seed,
            ))
        });
    }
    let taus = common_taus(&episodes);
    Ok(Loaded { files, episodes, failures, skipped, duplicates, taus })
}

/// A JSON line read.
enum Line {
    Episode(Box<Episode>),
    Failure(FailureLine),
}

/// A JSON line as a failure line or a checked episode result; the skipped line otherwise.
fn read_line(value: Value, source: Source, tau: &str) -> Result<Line, Box<SkippedLine>> {
    let skip = |v: &Value, reason: String| Box::new(SkippedLine::new(source, Some(v), reason));
    if !value.is_object() {
        return Err(skip(&value, "not a JSON object".into()));
    }
    if value.get("error").is_some() {
        return Ok(Line::Failure(failure_line(source, &value)));
    }
    if value.get("d_sat").is_some() && value.get("method").is_none() {
        return Err(skip(
            &value,
            "an `objview annotate` line, not an episode result (give annotation files as annotations)".into(),
        ));
    }
    match parse_result(&value).and_then(|result| check(result, source, tau)) {
        Ok(e) => Ok(Line::Episode(Box::new(e))),
        Err(reason) => Err(skip(&value, reason)),
    }
}

/// A stand-in that each typed name of a result reads, and whether a string is one.
type Name = (&'static str, &'static str, fn(&str) -> bool);

/// The typed names of a result's top level, in the order their errors are reported.
const NAMES: [Name; 3] = [
    ("execution_mode", "iterative", |s| s.parse::<ExecutionMode>().is_ok()),
    ("budget", "auto", |s| s.parse::<Budget>().is_ok()),
    ("family", "classical", |s| s.parse::<Family>().is_ok()),
];

/// A JSON object as an episode result, or why it is not one. The family, execution mode, budget
/// and checkpoint names of [`EpisodeResult`] are typed; the reason a line gets is what it was
/// when they were plain strings checked afterwards: a line that fails for another reason too (a
/// missing field, a `null` number) is "not an episode result" with that reason, else an unknown
/// execution mode, else a bad budget; then (never accepted since the names are typed) an unknown
/// family or checkpoint name.
fn parse_result(value: &Value) -> Result<EpisodeResult, String> {
    let error = match serde_json::from_value::<EpisodeResult>(value.clone()) {
        Ok(r) => return Ok(r),
        Err(e) => e,
    };
    // The names that are strings their type does not read.
    let bad: Vec<(&str, String)> = NAMES
        .iter()
        .filter_map(|&(field, _, known)| match value.get(field) {
            Some(Value::String(s)) if !known(s) => Some((field, s.clone())),
            _ => None,
        })
        .collect();
    let checkpoints = value.get("checkpoints").and_then(Value::as_object);
    let bad_checkpoints: Vec<String> = checkpoints
        .map(|m| m.keys().filter(|k| k.parse::<CheckpointKey>().is_err()).cloned().collect())
        .unwrap_or_default();
    let not_a_result = |e: serde_json::Error| format!("not an episode result ({e})");
    if bad.is_empty() && bad_checkpoints.is_empty() {
        return Err(not_a_result(error));
    }
    // The same line with valid stand-ins for those names: does it fail for another reason?
    let mut stand_in = value.clone();
    for &(field, valid, _) in &NAMES {
        if bad.iter().any(|(f, _)| *f == field) {
            stand_in[field] = json!(valid);
        }
    }
    if let Some(Value::Object(m)) = stand_in.get_mut("checkpoints") {
        let mut i = 0;
        for name in &bad_checkpoints {
            let Some(v) = m.remove(name) else { continue };
            let fresh = loop {
                i += 1;
                let k = CheckpointKey::Budget(usize::MAX - i).to_string();
                if !m.contains_key(&k) {
                    break k;
                }
            };
            m.insert(fresh, v);
        }
    }
    if let Err(e) = serde_json::from_value::<EpisodeResult>(stand_in) {
        return Err(not_a_result(e));
    }
    Err(match bad.first() {
        Some(("execution_mode", s)) => {
            format!("unknown execution_mode '{s}' (iterative, budgeted_plan or set_cover_plan)")
        }
        Some(("budget", s)) => s.parse::<Budget>().err().map(|e| e.to_string()).unwrap_or_default(),
        Some((_, s)) => format!("unknown family '{s}' (classical, learned, hybrid, oracle or baseline)"),
        None => format!(
            "unknown checkpoint name '{}' (K=k, MS@δ such as MS@0.02, or terminal)",
            bad_checkpoints.join("', '")
        ),
    })
}

fn sort_key(e: &Episode) -> (&str, &str, &str, u64, String, Source) {
    let r = &e.result;
    (&r.uid, &r.method, &r.view_space, r.seed, r.budget.to_string(), e.source)
}

/// A failure line's fields: top-level keys, else the same keys in its `settings` object (where
/// `objview run` records them; the method is its `planner` there).
fn failure_line(source: Source, v: &Value) -> FailureLine {
    let error = v.get("error").map_or_else(String::new, |e| match e {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    });
    FailureLine { source, keys: line_keys(v), error, superseded: false }
}

/// The episode keys of a failure or skipped line: top-level keys, else the same keys in its
/// `settings` object (where `objview run` records them; the method is its `planner` there).
fn line_keys(v: &Value) -> LineKeys {
    let find = |keys: &[&str]| -> Option<&Value> {
        let settings = v.get("settings");
        keys.iter()
            .find_map(|k| v.get(*k).filter(|x| !x.is_null()))
            .or_else(|| keys.iter().find_map(|k| settings.and_then(|s| s.get(*k)).filter(|x| !x.is_null())))
    };
    let text = |keys: &[&str]| match find(keys) {
        None => String::new(),
        Some(Value::String(s)) => s.clone(),
        Some(other) => other.to_string(),
    };
    LineKeys {
        uid: text(&["uid"]),
        method: text(&["method", "planner"]),
        view_space: text(&["view_space"]),
        budget: text(&["budget"]),
        seed: find(&["seed"]).and_then(Value::as_u64),
    }
}

/// The checks of the module docs that typing the result ([`parse_result`]) leaves; the reason on
/// failure.
fn check(result: EpisodeResult, source: Source, tau: &str) -> Result<Episode, String> {
    if result.uid.is_empty() || result.method.is_empty() || result.view_space.is_empty() {
        return Err("empty uid, method or view_space".into());
    }
    if !result.checkpoints.contains_key(&CheckpointKey::Terminal) {
        return Err("no `terminal` checkpoint".into());
    }
    let has = |nsc: &BTreeMap<String, f64>, sc: &BTreeMap<String, f64>| {
        nsc.contains_key(tau) && sc.contains_key(tau)
    };
    if let Some((name, _)) = result.checkpoints.iter().find(|(_, c)| !has(&c.metrics.nsc, &c.metrics.sc)) {
        return Err(format!("checkpoint `{name}` has no NSC@{tau} or SC@{tau}"));
    }
    if let Some(s) = result.steps.iter().find(|s| !has(&s.metrics.nsc, &s.metrics.sc)) {
        return Err(format!("step {} has no NSC@{tau} or SC@{tau}", s.step));
    }
    Ok(Episode { source, result })
}

/// A method must have one family and one execution mode: the episodes that contradict the first
/// line of their method, with the reason (naming that line).
fn contradicting_methods<'a>(files: &[InputFile], episodes: &'a [Episode]) -> Vec<(&'a Episode, String)> {
    let mut first: BTreeMap<&str, &Episode> = BTreeMap::new();
    let mut out = Vec::new();
    for e in episodes {
        let r = &e.result;
        let Some(f) = first.get(r.method.as_str()) else {
            first.insert(&r.method, e);
            continue;
        };
        let bad = |field: &str, here: &dyn std::fmt::Display, there: &dyn std::fmt::Display| {
            format!(
                "method '{}' has {field} '{here}' here but '{there}' at {}",
                r.method,
                locate(files, f.source)
            )
        };
        if r.family != f.result.family {
            out.push((e, bad("family", &r.family, &f.result.family)));
        } else if r.execution_mode != f.result.execution_mode {
            out.push((e, bad("execution_mode", &r.execution_mode, &f.result.execution_mode)));
        }
    }
    out
}

fn terminal_views(e: &Episode) -> usize {
    e.result.checkpoints.get(&CheckpointKey::Terminal).map_or(0, |c| c.metrics.views)
}

fn duplicate(kind: DuplicateKind, kept: &Episode, dropped: &Episode) -> Duplicate {
    let r = &dropped.result;
    Duplicate {
        kind,
        uid: r.uid.clone(),
        method: r.method.clone(),
        view_space: r.view_space.clone(),
        budget: r.budget.to_string(),
        seed: r.seed,
        kept: kept.source,
        dropped: dropped.source,
        kept_terminal: kept.result.terminal_reason.clone(),
        dropped_terminal: r.terminal_reason.clone(),
        failed_run_dropped: ended_normally(kept) && !ended_normally(dropped),
    }
}

/// Whether the episode ended normally ([`objview_episode::ends_normally`]).
fn ended_normally(e: &Episode) -> bool {
    objview_episode::ends_normally(e.result.terminal_source, &e.result.terminal_reason)
}

/// Of the episodes `group` (indices into `raw`), the one `rank` puts highest — the later line
/// on a tie — and a [`Duplicate`] for each of the others.
fn keep_best<R: Ord>(
    raw: &[Episode],
    group: &[usize],
    kind: DuplicateKind,
    rank: impl Fn(&Episode) -> R,
    duplicates: &mut Vec<Duplicate>,
) -> usize {
    let best = group.iter().copied().max_by_key(|&i| (rank(&raw[i]), raw[i].source)).expect("a group");
    for &i in group.iter().filter(|&&i| i != best) {
        duplicates.push(duplicate(kind, &raw[best], &raw[i]));
    }
    best
}

/// The two duplicate rules of the module docs.
fn deduplicate(raw: Vec<Episode>) -> (Vec<Episode>, Vec<Duplicate>) {
    let mut duplicates = Vec::new();
    // Same key: a normal end first, then the last line.
    let mut same: BTreeMap<(String, String, String, String, u64), Vec<usize>> = BTreeMap::new();
    for (i, e) in raw.iter().enumerate() {
        let r = &e.result;
        let key = (r.uid.clone(), r.method.clone(), r.view_space.clone(), r.budget.to_string(), r.seed);
        same.entry(key).or_default().push(i);
    }
    let kept: BTreeSet<usize> = same
        .values()
        .map(|g| keep_best(&raw, g, DuplicateKind::SameKey, ended_normally, &mut duplicates))
        .collect();
    // Iterative runs under several budgets: a normal end first, then the most views, then the
    // later line.
    let mut iterative: BTreeMap<(String, String, String, u64), Vec<usize>> = BTreeMap::new();
    for &i in &kept {
        let r = &raw[i].result;
        if r.execution_mode == ExecutionMode::Iterative {
            let key = (r.uid.clone(), r.method.clone(), r.view_space.clone(), r.seed);
            iterative.entry(key).or_default().push(i);
        }
    }
    let mut dropped = BTreeSet::new();
    for g in iterative.values().filter(|g| g.len() > 1) {
        let rank = |e: &Episode| (ended_normally(e), terminal_views(e));
        let best = keep_best(&raw, g, DuplicateKind::IterativeBudgets, rank, &mut duplicates);
        dropped.extend(g.iter().copied().filter(|&i| i != best));
    }
    duplicates.sort_by_key(|d| d.dropped);
    let episodes =
        raw.into_iter().enumerate().filter(|(i, _)| kept.contains(i) && !dropped.contains(i)).map(|(_, e)| e);
    (episodes.collect(), duplicates)
}

/// τ keys present in the NSC and SC of every checkpoint and step of every episode.
fn common_taus(episodes: &[Episode]) -> Vec<String> {
    let mut common: Option<BTreeSet<String>> = None;
    for e in episodes {
        let maps = e
            .result
            .checkpoints
            .values()
            .map(|c| (&c.metrics.nsc, &c.metrics.sc))
            .chain(e.result.steps.iter().map(|s| (&s.metrics.nsc, &s.metrics.sc)));
        for (nsc, sc) in maps {
            let here: BTreeSet<String> = nsc.keys().filter(|k| sc.contains_key(*k)).cloned().collect();
            common = Some(match common {
                None => here,
                Some(c) => c.intersection(&here).cloned().collect(),
            });
        }
    }
    common.unwrap_or_default().into_iter().collect()
}
