//! Per (budget setting, view space, method) statistics: the means (and sample standard
//! deviations) over episodes of #Views, NSC@τ, SC@τ, CD, path cost and planning runtime at the
//! checkpoint each episode contributes to the setting ([`crate::select::pick`]). Every table of
//! the report is a selection from these, and all of them are written to `summary.csv`, so nothing
//! is hidden behind a top-3.

use std::collections::{BTreeMap, BTreeSet};

use objview_episode::result::Metrics;
use objview_episode::{CheckpointKey, ExecutionMode, Family};
use serde::Serialize;

use crate::load::Episode;
use crate::select::{pick, Pick, PickSource, Setting};

/// Mean and sample standard deviation of a set of values.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Stat {
    /// Mean (summed in episode order).
    pub mean: f64,
    /// Sample standard deviation (n − 1); `None` for a single value.
    pub std: Option<f64>,
}

impl Stat {
    /// The statistics of `values` (summed in the given order); `None` when empty.
    pub fn of(values: &[f64]) -> Option<Stat> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let std = (values.len() > 1)
            .then(|| (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)).sqrt());
        Some(Stat { mean, std })
    }
}

/// (setting, view space, method).
pub type GroupKey = (Setting, String, String);

/// The picks of every episode for every setting, grouped by [`GroupKey`]; within a group in
/// episode order.
pub fn group_picks<'a>(
    episodes: &'a [Episode],
    settings: &[Setting],
    auto_checkpoint: &CheckpointKey,
) -> BTreeMap<GroupKey, Vec<Pick<'a>>> {
    let mut groups: BTreeMap<GroupKey, Vec<Pick<'a>>> = BTreeMap::new();
    for &setting in settings {
        for e in episodes {
            if let Some(p) = pick(e, setting, auto_checkpoint) {
                let key = (setting, e.result.view_space.clone(), e.result.method.clone());
                groups.entry(key).or_default().push(p);
            }
        }
    }
    groups
}

/// The statistics of one (setting, view space, method).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Aggregate {
    /// The budget setting.
    pub setting: Setting,
    /// View space.
    pub view_space: String,
    /// Method name as in the results.
    pub method: String,
    /// The family, as in the results (`classical`, …).
    pub family: Family,
    /// Execution mode (decides the checkpoint of each setting).
    pub execution_mode: ExecutionMode,
    /// Episodes.
    pub n: usize,
    /// Distinct objects.
    pub objects: usize,
    /// Episodes whose metrics are an iterative run's step k (no `K=k` checkpoint recorded).
    pub from_step: usize,
    /// Episodes that ended before the setting's checkpoint and contribute their `terminal`.
    pub terminal_fallback: usize,
    /// #Views (start view included).
    pub views: Stat,
    /// NSC at the report's τ.
    pub nsc: Stat,
    /// SC at the report's τ.
    pub sc: Stat,
    /// Chamfer distance.
    pub cd: Stat,
    /// Path cost (normalized object units).
    pub path_cost: Stat,
    /// Total planning time at the checkpoint (seconds).
    pub runtime: Stat,
    /// NSC at every τ common to all episodes (keys as in the results).
    pub nsc_by_tau: BTreeMap<String, Stat>,
    /// SC at the same τs.
    pub sc_by_tau: BTreeMap<String, Stat>,
}

/// One metric of a pick. The τ keys were checked when loading.
pub fn tau_value(map: &BTreeMap<String, f64>, tau: &str) -> f64 {
    map.get(tau).copied().unwrap_or(f64::NAN)
}

/// Means over `picks` of a metric.
pub fn stat_of(picks: &[&Metrics], f: impl Fn(&Metrics) -> f64) -> Stat {
    let values: Vec<f64> = picks.iter().map(|m| f(m)).collect();
    Stat::of(&values).unwrap_or(Stat { mean: f64::NAN, std: None })
}

/// The NSC@τ of a metrics record.
pub fn nsc(m: &Metrics, tau: &str) -> f64 {
    tau_value(&m.nsc, tau)
}

/// The SC@τ of a metrics record.
pub fn sc(m: &Metrics, tau: &str) -> f64 {
    tau_value(&m.sc, tau)
}

/// The aggregate of one non-empty group; `taus` are the τ keys of the per-τ columns.
pub fn aggregate(key: &GroupKey, picks: &[Pick], tau: &str, taus: &[String]) -> Aggregate {
    let metrics: Vec<&Metrics> = picks.iter().map(|p| p.metrics.as_ref()).collect();
    let first = &picks[0].episode;
    let objects: BTreeSet<&str> = picks.iter().map(|p| p.episode.result.uid.as_str()).collect();
    let count = |s: PickSource| picks.iter().filter(|p| p.source == s).count();
    let by_tau = |f: fn(&Metrics, &str) -> f64| {
        taus.iter().map(|t| (t.clone(), stat_of(&metrics, |m| f(m, t)))).collect::<BTreeMap<_, _>>()
    };
    Aggregate {
        setting: key.0,
        view_space: key.1.clone(),
        method: key.2.clone(),
        family: first.result.family,
        execution_mode: first.result.execution_mode,
        n: picks.len(),
        objects: objects.len(),
        from_step: count(PickSource::Step),
        terminal_fallback: count(PickSource::TerminalFallback),
        views: stat_of(&metrics, |m| m.views as f64),
        nsc: stat_of(&metrics, |m| nsc(m, tau)),
        sc: stat_of(&metrics, |m| sc(m, tau)),
        // CD exists at checkpoints only: a pick read off a step has none, and then the
        // group's CD is unknown (NaN: an empty cell), never a mean over part of it.
        cd: stat_of(&metrics, |m| m.cd),
        path_cost: stat_of(&metrics, |m| m.path_cost),
        runtime: stat_of(&metrics, |m| m.runtime),
        nsc_by_tau: by_tau(nsc),
        sc_by_tau: by_tau(sc),
    }
}

/// Every aggregate, in (setting, view space, method) order.
pub fn aggregates(groups: &BTreeMap<GroupKey, Vec<Pick>>, tau: &str, taus: &[String]) -> Vec<Aggregate> {
    groups.iter().filter(|(_, p)| !p.is_empty()).map(|(k, p)| aggregate(k, p, tau, taus)).collect()
}
