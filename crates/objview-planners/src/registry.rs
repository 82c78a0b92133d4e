//! Planners by name, as `objview run --planner NAME` and the server know them.
//!
//! A planner is registered by one row of plain data, a [`PlannerEntry`]: its name, family,
//! execution mode, a one-line summary, its settings' defaults as JSON and a constructor from
//! (merged) settings JSON. Rows are collected in tables (`&[PlannerEntry]`); this crate's table
//! is [`TABLE`]. A [`Registry`] combines any number of tables (names must be unique), finds a
//! planner by name, applies `--param NAME=VALUE` overrides and renders the help listing.
//!
//! # Adding a planner
//!
//! 1. Write the planner in its own file. The smallest example is [`crate::random`]
//!    (`random.rs`): a struct implementing [`objview_episode::Planner`], and next to it its row,
//!    `pub const ENTRY: PlannerEntry`.
//! 2. If it has parameters, give it a settings type (`Serialize + Deserialize`, like
//!    [`crate::tsp::TspSettings`] of `random_tsp.rs`): the row's `defaults` returns the default
//!    settings as JSON, and its `build` deserializes the merged JSON with [`settings_from`].
//!    A planner without parameters uses [`no_settings`].
//! 3. Add the row to [`TABLE`] (its position is the planner's place in listings).
//!
//! The row's name, family and mode must agree with the built planner's
//! [`name`](objview_episode::Planner::name), [`family`](objview_episode::Planner::family) and
//! [`execution_mode`](objview_episode::Planner::execution_mode); the tests check every row.
//!
//! Planners of other crates (a learned-planner crate, say) export their own table of the same
//! rows (`pub const TABLE: &[PlannerEntry]` or `pub fn table() -> Vec<PlannerEntry>`); only the
//! program that offers them (the CLI) combines the tables, with [`Registry::from_tables`], so
//! crates that only need the classical planners (the server) never link the others.
//!
//! The free functions [`by_name`] and [`with_params`] and the constants [`NAMES`] and
//! [`CLASSICAL`] are this crate's table alone, as before the table existed.

use objview_episode::{ExecutionMode, Family, Planner};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;

/// The constructor of a [`PlannerEntry`]: a fresh planner from `None` (its defaults) or from
/// `Some(settings)` (the defaults after overrides), or an error naming the planner and the
/// problem.
pub type BuildFn = fn(Option<Value>) -> Result<Box<dyn Planner>, String>;

/// One registered planner: what listings show about it, its settings and how to build it.
/// Plain data, so that tables of rows can be `const`.
#[derive(Debug, Clone, Copy)]
pub struct PlannerEntry {
    /// The planner's name (`--planner NAME`, the `method` of results); unique in a registry.
    pub name: &'static str,
    /// Its family (paper Table 1).
    pub family: Family,
    /// How it runs (decides how budgets apply).
    pub mode: ExecutionMode,
    /// One line for the help listing (no trailing period).
    pub summary: &'static str,
    /// The default settings as JSON (an object, whose keys `--param` overrides may name, dotted
    /// for nested settings), or `None` for a planner without parameters ([`no_settings`]).
    pub defaults: fn() -> Option<Value>,
    /// A fresh planner: `None` builds it with its defaults; `Some(settings)` with the defaults
    /// after overrides (an error names the planner and the problem).
    pub build: BuildFn,
}

impl PlannerEntry {
    /// A fresh planner with the default settings.
    pub fn build_default(&self) -> Result<Box<dyn Planner>, String> {
        (self.build)(None)
    }

    /// The default settings with `params` applied: each pair is a parameter name (dotted names
    /// reach nested settings: `occupancy.resolution`) and its new JSON value. An error for a
    /// planner without parameters and for a name that is not a parameter.
    pub fn settings_with(&self, params: &[(String, Value)]) -> Result<Value, String> {
        let name = self.name;
        let mut merged = (self.defaults)().ok_or_else(|| format!("planner {name} has no parameters"))?;
        for (key, value) in params {
            let mut slot = &mut merged;
            for part in key.split('.') {
                slot = slot
                    .as_object_mut()
                    .and_then(|m| m.get_mut(part))
                    .ok_or_else(|| format!("planner {name} has no parameter {key:?}"))?;
            }
            *slot = value.clone();
        }
        Ok(merged)
    }

    /// A fresh planner with `params` applied to its defaults (see
    /// [`PlannerEntry::settings_with`]); without params, the defaults as they are.
    pub fn build_with(&self, params: &[(String, Value)]) -> Result<Box<dyn Planner>, String> {
        if params.is_empty() {
            return self.build_default();
        }
        (self.build)(Some(self.settings_with(params)?))
    }
}

/// The `defaults` of a planner without parameters.
pub fn no_settings() -> Option<Value> {
    None
}

/// The `defaults` of a planner whose settings type is `T`: `settings` as JSON.
pub fn settings_json<T: Serialize>(settings: &T) -> Option<Value> {
    Some(serde_json::to_value(settings).expect("planner settings serialize to JSON"))
}

/// The settings a `build` gets: `defaults()` for `None`, else the JSON deserialized as `T`
/// (an error `planner NAME parameters: …` when it does not fit).
pub fn settings_from<T: DeserializeOwned>(
    name: &str,
    settings: Option<Value>,
    defaults: fn() -> T,
) -> Result<T, String> {
    match settings {
        None => Ok(defaults()),
        Some(v) => serde_json::from_value(v).map_err(|e| format!("planner {name} parameters: {e}")),
    }
}

/// The planners of this crate, in listing order.
pub const TABLE: &[PlannerEntry] = &[
    crate::random_tsp::ENTRY,
    crate::rse::RSE_ENTRY,
    crate::rse::RSE_MOV_ENTRY,
    crate::random::ENTRY,
    crate::oracle::ENTRY,
    crate::hybrid::NBV_ENTRY,
    crate::hybrid::SCP_ENTRY,
    crate::hybrid::MCP_ENTRY,
];

const NAME_ARRAY: [&str; TABLE.len()] = {
    let mut names = [""; TABLE.len()];
    let mut i = 0;
    while i < TABLE.len() {
        names[i] = TABLE[i].name;
        i += 1;
    }
    names
};

const CLASSICAL_LEN: usize = {
    let (mut i, mut n) = (0, 0);
    while i < TABLE.len() {
        if matches!(TABLE[i].family, Family::Classical) {
            n += 1;
        }
        i += 1;
    }
    n
};

const CLASSICAL_ARRAY: [&str; CLASSICAL_LEN] = {
    let mut names = [""; CLASSICAL_LEN];
    let (mut i, mut n) = (0, 0);
    while i < TABLE.len() {
        if matches!(TABLE[i].family, Family::Classical) {
            names[n] = TABLE[i].name;
            n += 1;
        }
        i += 1;
    }
    names
};

/// The built-in planner names: those of [`TABLE`], in its order.
pub const NAMES: &[&str] = &NAME_ARRAY;

/// The classical planners the demo and reports compare: the rows of [`TABLE`] of the classical
/// family (the oracle and `random` are diagnostics).
pub const CLASSICAL: &[&str] = &CLASSICAL_ARRAY;

/// Tables of planners combined: lookup by name, parameter overrides and the help listing.
#[derive(Debug, Clone, Default)]
pub struct Registry {
    entries: Vec<PlannerEntry>,
}

impl Registry {
    /// The registry of `tables`, in their order; an error when a name occurs twice.
    pub fn from_tables(tables: &[&[PlannerEntry]]) -> Result<Registry, String> {
        let mut registry = Registry::default();
        for table in tables {
            registry.add(table)?;
        }
        Ok(registry)
    }

    /// This crate's planners ([`TABLE`]).
    pub fn builtin() -> Registry {
        Registry::from_tables(&[TABLE]).expect("the built-in planner names are unique")
    }

    /// Appends the rows of `table`; an error (and nothing added) when one of its names is
    /// already registered or occurs twice in it.
    pub fn add(&mut self, table: &[PlannerEntry]) -> Result<(), String> {
        for (i, row) in table.iter().enumerate() {
            if self.entries.iter().chain(&table[..i]).any(|e| e.name == row.name) {
                return Err(format!("planner {:?} is registered twice", row.name));
            }
        }
        self.entries.extend_from_slice(table);
        Ok(())
    }

    /// Replaces rows by name with those of `table`, each in the place of the row it replaces
    /// (a crate that can build more of a planner than its own crate can — `objview-learn`'s
    /// hybrid rows, which add the `net` completion backend — supersedes those rows this way).
    /// An error (and nothing replaced) when a row of `table` names no registered planner, when
    /// its family or mode differ from the replaced row's, or when a name occurs twice in it.
    pub fn replace(&mut self, table: &[PlannerEntry]) -> Result<(), String> {
        let mut at = Vec::with_capacity(table.len());
        for (i, row) in table.iter().enumerate() {
            if table[..i].iter().any(|e| e.name == row.name) {
                return Err(format!("planner {:?} is replaced twice", row.name));
            }
            let k = self.entries.iter().position(|e| e.name == row.name).ok_or_else(|| {
                format!("planner {:?} is not registered, so it cannot be replaced", row.name)
            })?;
            let old = &self.entries[k];
            if old.family != row.family || old.mode != row.mode {
                return Err(format!("planner {:?}: a replacement must keep its family and mode", row.name));
            }
            at.push(k);
        }
        for (k, row) in at.into_iter().zip(table) {
            self.entries[k] = *row;
        }
        Ok(())
    }

    /// All rows, in registration order.
    pub fn entries(&self) -> &[PlannerEntry] {
        &self.entries
    }

    /// All names, in registration order.
    pub fn names(&self) -> Vec<&'static str> {
        self.entries.iter().map(|e| e.name).collect()
    }

    /// The row called `name`; an error listing the known names otherwise.
    pub fn get(&self, name: &str) -> Result<&PlannerEntry, String> {
        self.entries
            .iter()
            .find(|e| e.name == name)
            .ok_or_else(|| format!("unknown planner {name:?} (known: {})", self.names().join(", ")))
    }

    /// A fresh planner called `name` with its default (paper) parameters.
    pub fn by_name(&self, name: &str) -> Result<Box<dyn Planner>, String> {
        self.get(name)?.build_default()
    }

    /// A planner called `name` with some parameters changed (see
    /// [`PlannerEntry::settings_with`]). An unknown name, a parameter the planner does not have
    /// or a value of the wrong type is an error naming it.
    pub fn with_params(&self, name: &str, params: &[(String, Value)]) -> Result<Box<dyn Planner>, String> {
        self.get(name)?.build_with(params)
    }

    /// The help listing: one line per planner, `name  family  mode  summary`, in aligned columns
    /// (families as in tables, modes as in results), in registration order.
    pub fn help(&self) -> String {
        let width = |f: &dyn Fn(&PlannerEntry) -> usize| self.entries.iter().map(f).max().unwrap_or(0);
        let wn = width(&|e| e.name.len());
        let wf = width(&|e| e.family.title().len());
        let wm = width(&|e| e.mode.to_string().len());
        let lines: Vec<String> = self
            .entries
            .iter()
            .map(|e| {
                format!("{:wn$}  {:wf$}  {:wm$}  {}", e.name, e.family.title(), e.mode.to_string(), e.summary)
            })
            .collect();
        lines.join("\n")
    }
}

/// A fresh planner called `name` from this crate's table, with its default (paper) parameters.
pub fn by_name(name: &str) -> Result<Box<dyn Planner>, String> {
    Registry::builtin().by_name(name)
}

/// A planner called `name` from this crate's table with some parameters changed: `params` maps
/// parameter names to JSON values; dotted names reach nested settings (`occupancy.resolution`).
/// Names are those of the planner's settings (`RseSettings`: `stride`, `gamma`, `occupancy.*`;
/// `TspSettings`: `time_limit_s`, `dp_max_nodes`; `OracleSettings`: `tau`, `voxel`). An unknown
/// name or a value of the wrong type is an error naming it.
pub fn with_params(name: &str, params: &[(String, Value)]) -> Result<Box<dyn Planner>, String> {
    Registry::builtin().with_params(name, params)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn every_name_builds_and_params_apply() {
        for n in NAMES {
            assert!(by_name(n).unwrap().name().starts_with(*n));
        }
        assert!(by_name("nbv-net").err().unwrap().contains("unknown planner"));
        let p = with_params(
            "rse-mov",
            &[("gamma".into(), json!(0.25)), ("occupancy.resolution".into(), json!(32))],
        )
        .unwrap();
        assert_eq!(p.params()["gamma"], json!(0.25));
        assert!(with_params("rse", &[("gama".into(), json!(0.2))])
            .err()
            .unwrap()
            .contains("no parameter \"gama\""));
        assert!(with_params("rse", &[("stride".into(), json!("four"))])
            .err()
            .unwrap()
            .contains("parameters"));
        let t = with_params("random-tsp", &[("time_limit_s".into(), json!(5.0))]).unwrap();
        assert_eq!(t.params()["tsp_time_limit_s"], json!(5.0));
        assert!(with_params("random", &[("x".into(), json!(1))]).is_err());
        assert!(with_params("oracle", &[("tau".into(), json!(-1))]).is_err());
    }

    #[test]
    fn error_messages_are_unchanged() {
        let err = |name: &str, params: &[(String, Value)]| with_params(name, params).err().unwrap();
        assert_eq!(
            by_name("x").err().unwrap(),
            "unknown planner \"x\" (known: random-tsp, rse, rse-mov, random, oracle, completion-nbv, completion-scp, completion-mcp)"
        );
        assert_eq!(
            err("x", &[("a".into(), json!(1))]),
            "unknown planner \"x\" (known: random-tsp, rse, rse-mov, random, oracle, completion-nbv, completion-scp, completion-mcp)"
        );
        assert_eq!(err("random", &[("x".into(), json!(1))]), "planner random has no parameters");
        assert_eq!(err("rse", &[("gamma.x".into(), json!(1))]), "planner rse has no parameter \"gamma.x\"");
        assert!(err("rse", &[("stride".into(), json!("four"))]).starts_with("planner rse parameters: "));
        assert!(err("random-tsp", &[("dp_max_nodes".into(), json!(-1))])
            .starts_with("planner random-tsp parameters: "));
        assert_eq!(err("oracle", &[("tau".into(), json!(0))]), "oracle tau must be a positive number");
        assert_eq!(err("oracle", &[("voxel".into(), json!("a"))]), "oracle voxel must be a positive number");
        // Settings that parse but are invalid: random-tsp checks them when built.
        assert!(err("random-tsp", &[("dp_max_nodes".into(), json!(1000))]).contains("dp_max_nodes"));
    }

    #[test]
    fn every_row_builds_and_agrees_with_its_planner() {
        let registry = Registry::builtin();
        assert_eq!(registry.names(), NAMES);
        assert_eq!(CLASSICAL, ["random-tsp", "rse", "rse-mov"]);
        for row in TABLE {
            let p = row.build_default().unwrap();
            // A hybrid planner's name shows its completion backend: `NAME[backend]`.
            let name_ok = p.name() == row.name
                || (row.family == Family::Hybrid
                    && p.name()
                        .strip_prefix(row.name)
                        .is_some_and(|b| b.starts_with('[') && b.ends_with(']')));
            assert!(name_ok, "{} vs row {}", p.name(), row.name);
            assert_eq!(p.family(), row.family, "{}", row.name);
            assert_eq!(p.execution_mode(), row.mode, "{}", row.name);
            assert!(!row.summary.is_empty() && !row.summary.contains('\n'), "{}", row.name);
            // Building from the unchanged defaults gives the same planner as building plainly.
            if let Some(defaults) = (row.defaults)() {
                assert!(defaults.is_object(), "{}", row.name);
                let q = (row.build)(Some(defaults)).unwrap();
                assert_eq!((q.name(), q.params()), (p.name(), p.params()), "{}", row.name);
            }
        }
        // The recorded parameters (planner_params in results) of the defaults.
        let params = |n: &str| by_name(n).unwrap().params();
        assert_eq!(params("random")["rule"], "uniform over feasible unvisited candidates");
        assert_eq!(params("oracle")["tau"], json!(0.01));
        assert_eq!(params("oracle")["voxel"], json!(0.005));
        assert_eq!(params("rse")["stride"], 4);
        assert_eq!(params("rse-mov")["gamma"], json!(0.7));
        assert_eq!(params("random-tsp")["tsp_time_limit_s"], json!(60.0));
        let o = with_params("oracle", &[("tau".into(), json!(0.02))]).unwrap();
        assert_eq!((o.params()["tau"].clone(), o.params()["voxel"].clone()), (json!(0.02), json!(0.005)));
    }

    /// A planner of another table (as a learned-planner crate would contribute).
    #[derive(Default)]
    struct Echo {
        k: u64,
    }

    impl Planner for Echo {
        fn name(&self) -> &str {
            "echo"
        }
        fn family(&self) -> Family {
            Family::Learned
        }
        fn execution_mode(&self) -> ExecutionMode {
            ExecutionMode::BudgetedPlan
        }
        fn params(&self) -> Value {
            json!({ "k": self.k })
        }
        fn reset(
            &mut self,
            _: &objview_episode::EpisodeContext,
            _: &dyn objview_episode::Environment,
        ) -> Result<(), objview_episode::PlannerError> {
            Ok(())
        }
        fn act(
            &mut self,
            _: &objview_episode::Observation,
            _: &dyn objview_episode::Environment,
        ) -> Result<objview_episode::Action, objview_episode::PlannerError> {
            Ok(objview_episode::Action::stop(objview_episode::StopReason::PlanEnd))
        }
    }

    #[derive(serde::Serialize, serde::Deserialize)]
    struct EchoSettings {
        k: u64,
    }

    fn echo_defaults() -> Option<Value> {
        settings_json(&EchoSettings { k: 3 })
    }

    fn echo_build(settings: Option<Value>) -> Result<Box<dyn Planner>, String> {
        let s = settings_from("echo", settings, || EchoSettings { k: 3 })?;
        Ok(Box::new(Echo { k: s.k }))
    }

    const OTHER: &[PlannerEntry] = &[PlannerEntry {
        name: "echo",
        family: Family::Learned,
        mode: ExecutionMode::BudgetedPlan,
        summary: "a test planner of another table",
        defaults: echo_defaults,
        build: echo_build,
    }];

    #[test]
    fn tables_combine_and_duplicates_are_errors() {
        let registry = Registry::from_tables(&[TABLE, OTHER]).unwrap();
        assert_eq!(registry.entries().len(), TABLE.len() + 1);
        assert_eq!(registry.by_name("echo").unwrap().params(), json!({"k": 3}));
        assert_eq!(
            registry.with_params("echo", &[("k".into(), json!(7))]).unwrap().params(),
            json!({"k": 7})
        );
        assert_eq!(registry.by_name("rse").unwrap().name(), "rse");
        assert!(registry.get("nope").err().unwrap().ends_with(
            "(known: random-tsp, rse, rse-mov, random, oracle, completion-nbv, completion-scp, completion-mcp, echo)"
        ));
        // The built-in wrappers do not see other tables.
        assert!(by_name("echo").is_err());

        let err = Registry::from_tables(&[TABLE, OTHER, OTHER]).err().unwrap();
        assert_eq!(err, "planner \"echo\" is registered twice");
        assert!(Registry::from_tables(&[TABLE, &[crate::random::ENTRY]]).is_err());
        assert!(Registry::from_tables(&[&[crate::oracle::ENTRY, crate::oracle::ENTRY]]).is_err());
        let mut r = Registry::builtin();
        assert!(r.add(TABLE).is_err());
        assert_eq!(r.entries().len(), TABLE.len(), "a failed add adds nothing");
    }

    #[test]
    fn rows_are_replaced_in_place_by_name() {
        const ECHO_RSE: &[PlannerEntry] = &[PlannerEntry {
            name: "rse",
            family: Family::Classical,
            mode: ExecutionMode::Iterative,
            summary: "rse, replaced",
            defaults: echo_defaults,
            build: echo_build,
        }];
        let mut r = Registry::builtin();
        r.replace(ECHO_RSE).unwrap();
        assert_eq!(r.names(), NAMES, "same names, same order");
        assert_eq!(r.get("rse").unwrap().summary, "rse, replaced");
        assert_eq!(r.by_name("rse").unwrap().params(), json!({"k": 3}), "the new row builds");
        // Unknown names, another family or mode, and repeats are refused, and nothing changes.
        let mut r = Registry::builtin();
        assert_eq!(
            r.replace(OTHER).err().unwrap(),
            "planner \"echo\" is not registered, so it cannot be replaced"
        );
        let other_mode = [PlannerEntry { mode: ExecutionMode::BudgetedPlan, ..ECHO_RSE[0] }];
        assert!(r.replace(&other_mode).err().unwrap().contains("family and mode"));
        assert!(r.replace(&[ECHO_RSE[0], ECHO_RSE[0]]).err().unwrap().contains("replaced twice"));
        assert!(r.replace(&[ECHO_RSE[0], OTHER[0]]).is_err());
        assert_ne!(r.get("rse").unwrap().summary, "rse, replaced", "a failed replace changes nothing");
    }

    #[test]
    fn help_lists_every_planner_on_one_line() {
        let registry = Registry::from_tables(&[TABLE, OTHER]).unwrap();
        let help = registry.help();
        let lines: Vec<&str> = help.lines().collect();
        assert_eq!(lines.len(), registry.entries().len());
        for (line, row) in lines.iter().zip(registry.entries()) {
            assert!(line.starts_with(row.name), "{line}");
            assert!(line.contains(row.family.title()) && line.contains(&row.mode.to_string()), "{line}");
            assert!(line.ends_with(row.summary), "{line}");
        }
        // Aligned columns: every summary starts at the same offset.
        let at: Vec<usize> =
            lines.iter().zip(registry.entries()).map(|(l, r)| l.len() - r.summary.len()).collect();
        assert!(at.windows(2).all(|w| w[0] == w[1]), "{help}");
        let first: Vec<&str> = lines[0].split_whitespace().take(3).collect();
        assert_eq!(first, ["random-tsp", "Classical", "budgeted_plan"], "{help}");
        // Columns are two spaces apart at the widest entry (`completion-scp`, `budgeted_plan`).
        assert!(lines[0].starts_with("random-tsp      Classical  budgeted_plan  "), "{help}");
    }
}
