//! The vocabulary of episodes (SPEC §5), defined once: method families, execution modes,
//! budgets, stop reasons, terminal sources, checkpoint names and τ keys. Results, the server,
//! `objview run` and `objview report` all write and read these names through the types here.
//!
//! Every type's `Display` writes its wire name — exactly the string result lines, create
//! requests and reports have always carried (`classical`, `budgeted_plan`, `5`, `auto`,
//! `algorithm_stop`, `K=5`, `MS@0.02`, `terminal`, …) — and its `FromStr` reads it back; a name
//! that is not in the vocabulary is a [`ParseError`] that lists the known ones.
//!
//! Serde: [`Family`], [`ExecutionMode`], [`Budget`] and [`CheckpointKey`] are (de)serialized as
//! their wire string, through `Display` and `FromStr` (they were plain strings in results and
//! create requests, so anything but a string is refused as before, with serde's
//! "expected a string"). [`StopReason`] and [`TerminalSource`] keep their derived snake_case
//! serde, which writes the same names as `Display` (the tests check both).
//!
//! Order: [`CheckpointKey`]s compare by their wire string, so a `BTreeMap` keyed by them keeps
//! the order a map keyed by the strings had (`K=10` < `K=30` < `K=5` < `MS@0.02` < `terminal`),
//! and a result serializes to the same bytes.

use std::cmp::Ordering;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A string that is not a name of the vocabulary (the error of every `FromStr` here); its
/// message says what was expected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParseError(pub String);

/// `unknown WHAT "s" (known: a, b, c)`.
fn unknown<T: Copy + fmt::Display>(what: &str, s: &str, all: &[T]) -> ParseError {
    ParseError(format!("unknown {what} {s:?} (known: {})", wire_names(all)))
}

/// The wire names of `all`, comma-separated (`plan_end, candidate_exhausted, …`).
pub fn wire_names<T: fmt::Display>(all: &[T]) -> String {
    all.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ")
}

/// The variant of `all` whose name is `s`.
fn find<T: Copy + fmt::Display>(
    what: &str,
    s: &str,
    all: &[T],
    name: fn(T) -> &'static str,
) -> Result<T, ParseError> {
    all.iter().copied().find(|x| name(*x) == s).ok_or_else(|| unknown(what, s, all))
}

/// `Serialize` as the `Display` string and `Deserialize` from a string through `FromStr`.
macro_rules! serde_as_wire_string {
    ($t:ty) => {
        impl Serialize for $t {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_str(&self.to_string())
            }
        }

        impl<'de> Deserialize<'de> for $t {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<$t, D::Error> {
                let s = String::deserialize(d)?;
                s.parse().map_err(serde::de::Error::custom)
            }
        }
    };
}

/// Method family, as in the paper's Table 1 (plus the ground-truth oracle and sanity baselines).
/// Wire names: `classical`, `learned`, `hybrid`, `oracle`, `baseline`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Family {
    /// Classical (geometric) planners.
    Classical,
    /// Learned planners.
    Learned,
    /// Learned and classical parts.
    Hybrid,
    /// Reads the ground truth (only for diagnostics).
    Oracle,
    /// Sanity baselines (uniform random).
    Baseline,
}

impl Family {
    /// Every family, in declaration order.
    pub const ALL: [Family; 5] =
        [Family::Classical, Family::Learned, Family::Hybrid, Family::Oracle, Family::Baseline];

    /// The wire name (`classical`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            Family::Classical => "classical",
            Family::Learned => "learned",
            Family::Hybrid => "hybrid",
            Family::Oracle => "oracle",
            Family::Baseline => "baseline",
        }
    }

    /// Display name used in tables (`Classical`, …).
    pub fn title(self) -> &'static str {
        match self {
            Family::Classical => "Classical",
            Family::Learned => "Learned",
            Family::Hybrid => "Hybrid",
            Family::Oracle => "Oracle",
            Family::Baseline => "Baseline",
        }
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Family {
    type Err = ParseError;

    fn from_str(s: &str) -> Result<Family, ParseError> {
        find("family", s, &Family::ALL, Family::as_str)
    }
}

serde_as_wire_string!(Family);

/// How a planner runs (paper §6.1): this decides how budgets apply (SPEC §5). Wire names:
/// `iterative`, `budgeted_plan`, `set_cover_plan`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExecutionMode {
    /// Chooses one view at a time. Runs once per episode; the budget checkpoints and MS@δ are
    /// read off that run, which stops at `enough_info` or the cap.
    Iterative,
    /// Plans a fixed number K of views (needs a fixed budget).
    BudgetedPlan,
    /// Plans a finite view set and stops by itself (`plan_end`); the automatic setting.
    SetCoverPlan,
}

impl ExecutionMode {
    /// Every mode, in declaration order.
    pub const ALL: [ExecutionMode; 3] =
        [ExecutionMode::Iterative, ExecutionMode::BudgetedPlan, ExecutionMode::SetCoverPlan];

    /// The wire name (`iterative`, `budgeted_plan`, `set_cover_plan`).
    pub fn as_str(self) -> &'static str {
        match self {
            ExecutionMode::Iterative => "iterative",
            ExecutionMode::BudgetedPlan => "budgeted_plan",
            ExecutionMode::SetCoverPlan => "set_cover_plan",
        }
    }
}

impl fmt::Display for ExecutionMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for ExecutionMode {
    type Err = ParseError;

    fn from_str(s: &str) -> Result<ExecutionMode, ParseError> {
        find("execution mode", s, &ExecutionMode::ALL, ExecutionMode::as_str)
    }
}

serde_as_wire_string!(ExecutionMode);

/// The budget protocol of an episode (SPEC §5). Wire names: the number K (`5`, `30`) or `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Budget {
    /// K planner-selected views after the start view.
    Fixed(usize),
    /// The planner's own stop (finite plans) or MS@0.02 (iterative planners).
    Auto,
}

impl Budget {
    /// `"5"`, `"30"`, `"auto"`: the wire name (a thin wrapper of `Display`).
    pub fn label(self) -> String {
        self.to_string()
    }

    /// Parses `auto` or a positive integer (a thin wrapper of `FromStr`, with the error as a
    /// string).
    pub fn parse(s: &str) -> Result<Budget, String> {
        s.parse().map_err(|e: ParseError| e.0)
    }
}

impl fmt::Display for Budget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Budget::Fixed(k) => write!(f, "{k}"),
            Budget::Auto => f.write_str("auto"),
        }
    }
}

impl FromStr for Budget {
    type Err = ParseError;

    /// `auto`, or a positive integer as Rust reads one (`5`; also `05` and `+5`, which are
    /// written back as `5`).
    fn from_str(s: &str) -> Result<Budget, ParseError> {
        if s == "auto" {
            return Ok(Budget::Auto);
        }
        match s.parse::<usize>() {
            Ok(k) if k >= 1 => Ok(Budget::Fixed(k)),
            _ => Err(ParseError(format!("budget must be `auto` or a positive integer, got {s:?}"))),
        }
    }
}

serde_as_wire_string!(Budget);

/// The reasons a planner may give for stopping (SPEC §5). Anything else is an invalid action.
/// Wire names: `plan_end`, `candidate_exhausted`, `next_view_visited`, `next_view_infeasible`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// A finite plan has been executed to its end.
    PlanEnd,
    /// No candidate is left to choose from.
    CandidateExhausted,
    /// The planner's next view is one it already visited.
    NextViewVisited,
    /// The planner's next view is not feasible in the view space.
    NextViewInfeasible,
}

impl StopReason {
    /// All valid reasons.
    pub const ALL: [StopReason; 4] = [
        StopReason::PlanEnd,
        StopReason::CandidateExhausted,
        StopReason::NextViewVisited,
        StopReason::NextViewInfeasible,
    ];

    /// The wire name (`plan_end`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            StopReason::PlanEnd => "plan_end",
            StopReason::CandidateExhausted => "candidate_exhausted",
            StopReason::NextViewVisited => "next_view_visited",
            StopReason::NextViewInfeasible => "next_view_infeasible",
        }
    }

    /// Parses a wire name; `None` for an unknown reason (a thin wrapper of `FromStr`).
    pub fn parse(s: &str) -> Option<StopReason> {
        s.parse().ok()
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for StopReason {
    type Err = ParseError;

    fn from_str(s: &str) -> Result<StopReason, ParseError> {
        find("stop reason", s, &StopReason::ALL, StopReason::as_str)
    }
}

/// Where the end of an episode came from. Wire names: `algorithm_stop`, `benchmark`,
/// `exception`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerminalSource {
    /// The planner stopped (`terminal_reason` is its stop reason).
    AlgorithmStop,
    /// The benchmark ended it: `invalid_action`, `max_cap_reached` or `enough_info`.
    Benchmark,
    /// The planner failed (`planner_error`) or a remote planner timed out (`timeout`).
    Exception,
}

impl TerminalSource {
    /// Every source, in declaration order.
    pub const ALL: [TerminalSource; 3] =
        [TerminalSource::AlgorithmStop, TerminalSource::Benchmark, TerminalSource::Exception];

    /// The wire name (`algorithm_stop`, `benchmark`, `exception`).
    pub fn as_str(self) -> &'static str {
        match self {
            TerminalSource::AlgorithmStop => "algorithm_stop",
            TerminalSource::Benchmark => "benchmark",
            TerminalSource::Exception => "exception",
        }
    }
}

impl fmt::Display for TerminalSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for TerminalSource {
    type Err = ParseError;

    fn from_str(s: &str) -> Result<TerminalSource, ParseError> {
        find("terminal source", s, &TerminalSource::ALL, TerminalSource::as_str)
    }
}

/// The reasons with which the benchmark ends an episode that went as it should (source
/// `benchmark`): the cap, an iterative planner's `enough_info`, a finite plan reaching its budget.
/// The benchmark's other reason, `invalid_action`, is the planner's fault.
pub const NORMAL_BENCHMARK_ENDS: [&str; 3] = ["max_cap_reached", "enough_info", "budget_reached"];

/// Whether an episode that ended with `source` / `reason` ended normally: the planner stopped
/// with a valid stop reason (`algorithm_stop`: `plan_end`, `candidate_exhausted`, …), or the
/// benchmark ended it at a limit ([`NORMAL_BENCHMARK_ENDS`]). Every other end is a failure: an
/// `exception` of any reason (`planner_error`, `timeout`, `interrupted`, an abort), an
/// `invalid_action`, a reason this vocabulary does not know. `objview report` and the server
/// prefer a normal end among duplicate runs of one episode.
pub fn ends_normally(source: TerminalSource, reason: &str) -> bool {
    match source {
        TerminalSource::AlgorithmStop => StopReason::parse(reason).is_some(),
        TerminalSource::Benchmark => NORMAL_BENCHMARK_ENDS.contains(&reason),
        TerminalSource::Exception => false,
    }
}

/// A τ (or an MS resolution δ) written as a key: two decimals (`0.02` → `"0.02"`). Per-τ maps
/// of results (`sc`, `nsc`, `ms_voxels`, `observable_sc`) are keyed by it, and so is
/// [`CheckpointKey::Stabilized`].
pub fn tau_key(tau: f64) -> String {
    format!("{tau:.2}")
}

/// The name of a checkpoint of a result (SPEC §5: the metrics at the view where it was
/// reached). Wire names: `K=5` (k written in decimal), `MS@0.02` (δ written by [`tau_key`]),
/// `terminal`.
///
/// Equality, order and hash are those of the wire string: `Stabilized(0.02)` and
/// `Stabilized(0.021)` are the same key (`MS@0.02`), as they always were, and a map keyed by
/// checkpoint keys iterates in the order of the strings.
#[derive(Debug, Clone, Copy)]
pub enum CheckpointKey {
    /// `K=k`: after k planner-selected views (the start view not counted).
    Budget(usize),
    /// `MS@δ`: map stabilization at resolution δ triggered.
    Stabilized(f64),
    /// `terminal`: after the episode's last view (every result has it).
    Terminal,
}

impl CheckpointKey {
    const TERMINAL: &'static str = "terminal";
}

impl fmt::Display for CheckpointKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CheckpointKey::Budget(k) => write!(f, "K={k}"),
            CheckpointKey::Stabilized(delta) => write!(f, "MS@{}", tau_key(*delta)),
            CheckpointKey::Terminal => f.write_str(CheckpointKey::TERMINAL),
        }
    }
}

impl FromStr for CheckpointKey {
    type Err = ParseError;

    /// Only the form `Display` writes: `K=05` or `MS@0.020` are not checkpoint names (read as
    /// `K=5` or `MS@0.02`, two names of one result could become one key).
    fn from_str(s: &str) -> Result<CheckpointKey, ParseError> {
        let bad = || {
            ParseError(format!(
                "unknown checkpoint {s:?} (known: K=k for a whole number k, MS@δ with δ written with two \
                 decimals such as MS@0.02, terminal)"
            ))
        };
        if s == CheckpointKey::TERMINAL {
            return Ok(CheckpointKey::Terminal);
        }
        let key = if let Some(k) = s.strip_prefix("K=") {
            k.parse::<usize>().ok().map(CheckpointKey::Budget)
        } else if let Some(d) = s.strip_prefix("MS@") {
            d.parse::<f64>().ok().map(CheckpointKey::Stabilized)
        } else {
            None
        };
        // Canonical only: the name must be the one the key writes.
        key.filter(|k| k.to_string() == s).ok_or_else(bad)
    }
}

impl PartialEq for CheckpointKey {
    fn eq(&self, other: &CheckpointKey) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for CheckpointKey {}

impl PartialOrd for CheckpointKey {
    fn partial_cmp(&self, other: &CheckpointKey) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for CheckpointKey {
    /// The order of the wire strings.
    fn cmp(&self, other: &CheckpointKey) -> Ordering {
        match (self, other) {
            (CheckpointKey::Terminal, CheckpointKey::Terminal) => Ordering::Equal,
            _ => self.to_string().cmp(&other.to_string()),
        }
    }
}

impl Hash for CheckpointKey {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.to_string().hash(state);
    }
}

serde_as_wire_string!(CheckpointKey);

#[cfg(test)]
mod tests {
    use super::*;

    /// parse(display(x)) == x for every value, and serde writes and reads the same string.
    fn round_trips<T>(values: &[T])
    where
        T: fmt::Display + FromStr + PartialEq + fmt::Debug + Serialize + for<'de> Deserialize<'de>,
        T::Err: fmt::Debug,
    {
        for x in values {
            let wire = x.to_string();
            assert_eq!(&wire.parse::<T>().unwrap(), x, "{wire}");
            assert_eq!(serde_json::to_value(x).unwrap(), serde_json::Value::String(wire.clone()));
            assert_eq!(&serde_json::from_value::<T>(serde_json::Value::String(wire)).unwrap(), x);
        }
    }

    #[test]
    fn every_name_round_trips_through_display_from_str_and_serde() {
        round_trips(&Family::ALL);
        round_trips(&ExecutionMode::ALL);
        round_trips(&StopReason::ALL);
        round_trips(&TerminalSource::ALL);
        round_trips(&[Budget::Fixed(1), Budget::Fixed(5), Budget::Fixed(30), Budget::Auto]);
        round_trips(&[
            CheckpointKey::Budget(0),
            CheckpointKey::Budget(5),
            CheckpointKey::Budget(50),
            CheckpointKey::Stabilized(0.01),
            CheckpointKey::Stabilized(0.02),
            CheckpointKey::Stabilized(0.03),
            CheckpointKey::Terminal,
        ]);
    }

    #[test]
    fn wire_names_are_the_ones_results_have_always_carried() {
        let names = |v: Vec<String>| v.join(" ");
        assert_eq!(
            names(Family::ALL.map(|f| f.to_string()).to_vec()),
            "classical learned hybrid oracle baseline"
        );
        assert_eq!(
            names(ExecutionMode::ALL.map(|m| m.to_string()).to_vec()),
            "iterative budgeted_plan set_cover_plan"
        );
        assert_eq!(
            names(StopReason::ALL.map(|r| r.to_string()).to_vec()),
            "plan_end candidate_exhausted next_view_visited next_view_infeasible"
        );
        assert_eq!(
            names(TerminalSource::ALL.map(|s| s.to_string()).to_vec()),
            "algorithm_stop benchmark exception"
        );
        assert_eq!((Budget::Fixed(30).to_string(), Budget::Auto.to_string()), ("30".into(), "auto".into()));
        let keys = [CheckpointKey::Budget(5), CheckpointKey::Stabilized(0.02), CheckpointKey::Terminal];
        assert_eq!(names(keys.map(|k| k.to_string()).to_vec()), "K=5 MS@0.02 terminal");
        assert_eq!(CheckpointKey::Stabilized(0.1).to_string(), "MS@0.10", "two decimals, as tau_key");
        assert_eq!(tau_key(0.025), format!("{:.2}", 0.025));
    }

    #[test]
    fn only_valid_stops_and_the_benchmark_limits_are_normal_ends() {
        use TerminalSource::{AlgorithmStop, Benchmark, Exception};
        for r in ["plan_end", "candidate_exhausted", "next_view_visited", "next_view_infeasible"] {
            assert!(ends_normally(AlgorithmStop, r), "{r}");
            assert!(!ends_normally(Exception, r), "{r}");
        }
        for r in ["max_cap_reached", "enough_info", "budget_reached"] {
            assert!(ends_normally(Benchmark, r), "{r}");
            assert!(!ends_normally(AlgorithmStop, r), "{r}");
        }
        assert!(!ends_normally(Benchmark, "invalid_action"));
        for r in ["planner_error", "timeout", "interrupted", "aborted", "max_cap_reached"] {
            assert!(!ends_normally(Exception, r), "{r}");
        }
        assert!(!ends_normally(AlgorithmStop, "gave_up"));
        assert!(!ends_normally(Benchmark, "aborted"));
    }

    #[test]
    fn unknown_names_are_errors_that_list_the_known_ones() {
        let err = |r: Result<(), ParseError>| r.unwrap_err().to_string();
        assert_eq!(
            err("Classical".parse::<Family>().map(drop)),
            "unknown family \"Classical\" (known: classical, learned, hybrid, oracle, baseline)"
        );
        assert_eq!(
            err("greedy".parse::<ExecutionMode>().map(drop)),
            "unknown execution mode \"greedy\" (known: iterative, budgeted_plan, set_cover_plan)"
        );
        assert!(err("done".parse::<StopReason>().map(drop))
            .starts_with("unknown stop reason \"done\" (known: plan_end,"));
        assert!(
            err("crash".parse::<TerminalSource>().map(drop)).starts_with("unknown terminal source \"crash\"")
        );
        assert_eq!(
            err("five".parse::<Budget>().map(drop)),
            "budget must be `auto` or a positive integer, got \"five\""
        );
        for bad in ["0", "-3", "", "Auto"] {
            assert!(bad.parse::<Budget>().is_err(), "{bad}");
        }
        for bad in
            ["", "K=", "K=05", "K=+5", "K=-1", "k=5", "MS@", "MS@0.020", "MS@.02", "MS@x", "Terminal", "K=5 "]
        {
            let e = err(bad.parse::<CheckpointKey>().map(drop));
            assert!(e.starts_with(&format!("unknown checkpoint {bad:?} (known: K=k")), "{e}");
        }
        // A name with a newline stays on one line in the message.
        assert!(!err("it\nerative".parse::<ExecutionMode>().map(drop)).contains('\n'));
    }

    #[test]
    fn budgets_parse_as_before() {
        assert_eq!(Budget::parse("auto"), Ok(Budget::Auto));
        assert_eq!(Budget::parse("30"), Ok(Budget::Fixed(30)));
        assert_eq!(Budget::parse("05"), Ok(Budget::Fixed(5)));
        assert!(Budget::parse("0").is_err());
        assert!(Budget::parse("-3").is_err());
        assert!(Budget::parse("five").is_err());
        assert_eq!(Budget::Fixed(5).label(), "5");
    }

    #[test]
    fn checkpoint_keys_order_as_their_wire_strings() {
        let mut keys = [
            CheckpointKey::Terminal,
            CheckpointKey::Stabilized(0.03),
            CheckpointKey::Budget(5),
            CheckpointKey::Stabilized(0.01),
            CheckpointKey::Budget(30),
            CheckpointKey::Budget(10),
            CheckpointKey::Budget(50),
            CheckpointKey::Stabilized(0.02),
        ];
        let mut strings: Vec<String> = keys.iter().map(|k| k.to_string()).collect();
        keys.sort();
        strings.sort();
        assert_eq!(keys.iter().map(|k| k.to_string()).collect::<Vec<_>>(), strings);
        assert_eq!(strings, ["K=10", "K=30", "K=5", "K=50", "MS@0.01", "MS@0.02", "MS@0.03", "terminal"]);
        // One wire string, one key.
        assert_eq!(CheckpointKey::Stabilized(0.02), CheckpointKey::Stabilized(0.0201));
        let map: std::collections::BTreeMap<CheckpointKey, u8> =
            [(CheckpointKey::Budget(5), 1), (CheckpointKey::Terminal, 2), (CheckpointKey::Budget(10), 3)]
                .into();
        assert_eq!(serde_json::to_string(&map).unwrap(), r#"{"K=10":3,"K=5":1,"terminal":2}"#);
        let back: std::collections::BTreeMap<CheckpointKey, u8> =
            serde_json::from_str(r#"{"terminal":2,"K=5":1,"K=10":3}"#).unwrap();
        assert_eq!(back, map);
    }

    #[test]
    fn typed_fields_refuse_what_is_not_a_string_as_plain_strings_did() {
        let e = serde_json::from_value::<ExecutionMode>(serde_json::json!(3)).unwrap_err().to_string();
        let s = serde_json::from_value::<String>(serde_json::json!(3)).unwrap_err().to_string();
        assert_eq!(e, s);
        let e = serde_json::from_value::<Budget>(serde_json::json!(5)).unwrap_err().to_string();
        assert_eq!(e, "invalid type: integer `5`, expected a string");
    }
}
