//! Planners by name, as `objview run --planner NAME` and the server know them.

use objview_episode::Planner;

use crate::oracle::Oracle;
use crate::random::RandomPlanner;

/// The built-in planner names.
pub const NAMES: &[&str] = &["random-tsp", "rse", "rse-mov", "random", "oracle"];

/// The classical planners the demo and reports compare (the oracle and `random` are
/// diagnostics).
pub const CLASSICAL: &[&str] = &["random-tsp", "rse", "rse-mov"];

/// A fresh planner called `name` with its default (paper) parameters.
pub fn by_name(name: &str) -> Result<Box<dyn Planner>, String> {
    match name {
        "random" => Ok(Box::new(RandomPlanner::default())),
        "oracle" => Ok(Box::new(Oracle::default())),
        "random-tsp" => crate::random_tsp::RandomTsp::new(Default::default())
            .map(|p| Box::new(p) as Box<dyn Planner>)
            .map_err(|e| e.to_string()),
        "rse" => Ok(Box::new(crate::rse::Rse::new(crate::rse::RseSettings::rse()))),
        "rse-mov" => Ok(Box::new(crate::rse::Rse::new(crate::rse::RseSettings::rse_mov()))),
        _ => Err(format!("unknown planner {name:?} (known: {})", NAMES.join(", "))),
    }
}
