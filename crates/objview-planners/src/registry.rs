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

/// A planner called `name` with some parameters changed: `params` maps parameter names to JSON
/// values; dotted names reach nested settings (`occupancy.resolution`). Names are those of the
/// planner's settings (`RseSettings`: `stride`, `gamma`, `occupancy.*`; `TspSettings`:
/// `time_limit_s`, `dp_max_nodes`; oracle: `tau`, `voxel`). An unknown name or a value of the
/// wrong type is an error naming it.
pub fn with_params(name: &str, params: &[(String, serde_json::Value)]) -> Result<Box<dyn Planner>, String> {
    if params.is_empty() {
        return by_name(name);
    }
    let defaults = match name {
        "rse" => serde_json::to_value(crate::rse::RseSettings::rse()),
        "rse-mov" => serde_json::to_value(crate::rse::RseSettings::rse_mov()),
        "random-tsp" => serde_json::to_value(crate::tsp::TspSettings::default()),
        "oracle" => {
            let o = Oracle::default();
            Ok(serde_json::json!({"tau": o.tau, "voxel": o.voxel}))
        }
        "random" => return Err("planner random has no parameters".into()),
        _ => return by_name(name),
    }
    .map_err(|e| e.to_string())?;
    let mut merged = defaults;
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
    let bad = |e: serde_json::Error| format!("planner {name} parameters: {e}");
    Ok(match name {
        "rse" | "rse-mov" => {
            let s: crate::rse::RseSettings = serde_json::from_value(merged).map_err(bad)?;
            Box::new(crate::rse::Rse::new(s))
        }
        "random-tsp" => {
            let s: crate::tsp::TspSettings = serde_json::from_value(merged).map_err(bad)?;
            Box::new(crate::random_tsp::RandomTsp::new(s).map_err(|e| e.to_string())?)
        }
        _ => {
            let tau =
                merged["tau"].as_f64().filter(|t| *t > 0.0).ok_or("oracle tau must be a positive number")?;
            let voxel = merged["voxel"]
                .as_f64()
                .filter(|t| *t > 0.0)
                .ok_or("oracle voxel must be a positive number")?;
            let mut o = Oracle::default();
            o.tau = tau;
            o.voxel = voxel;
            Box::new(o)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn every_name_builds_and_params_apply() {
        for n in NAMES {
            assert_eq!(by_name(n).unwrap().name(), *n);
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
}
