//! Budget settings and the checkpoint each episode contributes to them (SPEC §5, paper §5.2).
//!
//! The settings are `K=5`, `K=30` and `Automatic`, plus `K=k` for every other fixed budget that a
//! finite-plan episode was run with. Which metrics an episode contributes to a setting depends
//! on its execution mode:
//! - iterative planners run once and serve every setting: `K=k` → checkpoint `K=k`; when the run
//!   has no such checkpoint, its step `k` (for a K the runner does not checkpoint; a step has no
//!   CD, so that pick's CD is NaN and its group's CD cell stays empty) or, when it
//!   ended before k planner views, `terminal`; `Automatic` → the MS checkpoint (`MS@0.02`), else
//!   `terminal` (MS never triggered before the run ended);
//! - budgeted plans: `K=k` ← their `budget == "k"` episodes at `terminal`; no `Automatic`;
//! - set-cover plans: `Automatic` ← their `budget == "auto"` episodes at `terminal`; `K=k` ← their
//!   `budget == "k"` episodes at `terminal` when there are any.

use std::borrow::Cow;
use std::fmt;

use objview_episode::result::{EpisodeResult, Metrics};
use objview_episode::{Budget, CheckpointKey, ExecutionMode};
use serde::{Serialize, Serializer};

use crate::load::Episode;

/// The budget settings always reported (paper §5.2).
pub const DEFAULT_SETTINGS: [Setting; 3] = [Setting::Fixed(5), Setting::Fixed(30), Setting::Automatic];

/// A budget setting. Ordered as reported: fixed budgets by K, then automatic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Setting {
    /// K planner-selected views after the start view.
    Fixed(usize),
    /// The planner's own stop (finite plans) or map stabilization (iterative planners).
    Automatic,
}

impl Setting {
    /// `K=5` (the name of its checkpoint), `Automatic`.
    pub fn label(self) -> String {
        match self {
            Setting::Fixed(k) => CheckpointKey::Budget(k).to_string(),
            Setting::Automatic => "Automatic".into(),
        }
    }

    /// A short label for plot annotations: `K=5`, `Auto`.
    pub fn short(self) -> String {
        match self {
            Setting::Fixed(k) => CheckpointKey::Budget(k).to_string(),
            Setting::Automatic => "Auto".into(),
        }
    }
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.label())
    }
}

impl Serialize for Setting {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.label())
    }
}

/// The settings of a report: [`DEFAULT_SETTINGS`] and every fixed budget of a finite-plan
/// episode, in report order.
pub fn settings_of(episodes: &[Episode]) -> Vec<Setting> {
    let mut out: Vec<Setting> = DEFAULT_SETTINGS.to_vec();
    for e in episodes {
        if let (Budget::Fixed(k), false) =
            (e.result.budget, e.result.execution_mode == ExecutionMode::Iterative)
        {
            out.push(Setting::Fixed(k));
        }
    }
    out.sort();
    out.dedup();
    out
}

/// Where the metrics of a pick came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PickSource {
    /// The setting's own checkpoint (`K=k`, the MS checkpoint, or `terminal` for finite plans).
    Checkpoint,
    /// An iterative run without a `K=k` checkpoint that went on past k views: its step k.
    Step,
    /// An iterative run that ended before the setting's checkpoint: its `terminal`.
    TerminalFallback,
}

/// The metrics an episode contributes to a setting.
#[derive(Clone, Debug, PartialEq)]
pub struct Pick<'a> {
    /// The contributing episode.
    pub episode: &'a Episode,
    /// Its metrics at the chosen checkpoint, or at the chosen step with CD NaN.
    pub metrics: Cow<'a, Metrics>,
    /// Where the metrics came from.
    pub source: PickSource,
}

fn terminal(r: &EpisodeResult) -> Option<&Metrics> {
    r.checkpoints.get(&CheckpointKey::Terminal).map(|c| &c.metrics)
}

/// What `episode` contributes to `setting` (module docs); `None` when it does not take part.
/// `auto_checkpoint` is the MS checkpoint of the automatic setting (`MS@0.02`).
pub fn pick<'a>(episode: &'a Episode, setting: Setting, auto_checkpoint: &CheckpointKey) -> Option<Pick<'a>> {
    let r = &episode.result;
    let found =
        |metrics: &'a Metrics, source| Some(Pick { episode, metrics: Cow::Borrowed(metrics), source });
    match (r.execution_mode, setting) {
        (ExecutionMode::Iterative, Setting::Fixed(k)) => {
            if let Some(c) = r.checkpoints.get(&CheckpointKey::Budget(k)) {
                return found(&c.metrics, PickSource::Checkpoint);
            }
            if let Some(s) = r.steps.iter().find(|s| s.step == k) {
                return Some(Pick {
                    episode,
                    metrics: Cow::Owned(s.metrics.with_cd(f64::NAN)),
                    source: PickSource::Step,
                });
            }
            found(terminal(r)?, PickSource::TerminalFallback)
        }
        (ExecutionMode::Iterative, Setting::Automatic) => match r.checkpoints.get(auto_checkpoint) {
            Some(c) => found(&c.metrics, PickSource::Checkpoint),
            None => found(terminal(r)?, PickSource::TerminalFallback),
        },
        (ExecutionMode::BudgetedPlan, Setting::Fixed(k))
        | (ExecutionMode::SetCoverPlan, Setting::Fixed(k))
            if r.budget == Budget::Fixed(k) =>
        {
            found(terminal(r)?, PickSource::Checkpoint)
        }
        (ExecutionMode::SetCoverPlan, Setting::Automatic) if r.budget == Budget::Auto => {
            found(terminal(r)?, PickSource::Checkpoint)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{close, episode, Spec};

    const MS: CheckpointKey = CheckpointKey::Stabilized(0.02);

    #[test]
    fn iterative_runs_serve_every_setting() {
        // 21 views: K=5 and K=10 checkpoints, no K=30; MS@0.02 at step 12.
        let spec = Spec { last: 20, ms: Some(12), ..Spec::new("o1", "rse") };
        let e = episode(&spec);
        let p = pick(&e, Setting::Fixed(5), &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (6, PickSource::Checkpoint));
        // Ended before 30 planner views: terminal.
        let p = pick(&e, Setting::Fixed(30), &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (21, PickSource::TerminalFallback));
        close(p.metrics.nsc["0.02"], spec.nsc(20));
        // K=20 is not checkpointed by the runner but the run went past it: step 20.
        let p = pick(&e, Setting::Fixed(20), &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (21, PickSource::Step));
        let p = pick(&e, Setting::Fixed(15), &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (16, PickSource::Step));
        // Automatic: MS@0.02, else terminal.
        let p = pick(&e, Setting::Automatic, &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (13, PickSource::Checkpoint));
        let e = episode(&Spec { ms: None, ..spec });
        let p = pick(&e, Setting::Automatic, &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (21, PickSource::TerminalFallback));
    }

    #[test]
    fn finite_plans_use_budget_matched_runs_at_terminal() {
        let b5 = Spec { mode: "budgeted_plan", budget: "5", last: 5, ..Spec::new("o1", "mcp") };
        let e = episode(&b5);
        assert_eq!(pick(&e, Setting::Fixed(5), &MS).unwrap().metrics.views, 6);
        assert!(pick(&e, Setting::Fixed(30), &MS).is_none());
        assert!(pick(&e, Setting::Automatic, &MS).is_none());
        let auto = Spec { mode: "set_cover_plan", budget: "auto", last: 7, ..Spec::new("o1", "scp") };
        let e = episode(&auto);
        let p = pick(&e, Setting::Automatic, &MS).unwrap();
        assert_eq!((p.metrics.views, p.source), (8, PickSource::Checkpoint));
        assert!(pick(&e, Setting::Fixed(5), &MS).is_none());
        let k5 = Spec { mode: "set_cover_plan", budget: "5", last: 5, ..Spec::new("o1", "scp") };
        assert_eq!(pick(&episode(&k5), Setting::Fixed(5), &MS).unwrap().metrics.views, 6);
    }

    #[test]
    fn settings_are_the_paper_s_plus_other_fixed_budgets() {
        let it = episode(&Spec { budget: "10", ..Spec::new("o1", "rse") });
        let plan = episode(&Spec { mode: "budgeted_plan", budget: "10", last: 10, ..Spec::new("o1", "mcp") });
        let labels = |s: Vec<Setting>| s.iter().map(|s| s.label()).collect::<Vec<_>>();
        assert_eq!(labels(settings_of(std::slice::from_ref(&it))), ["K=5", "K=30", "Automatic"]);
        assert_eq!(labels(settings_of(&[it, plan])), ["K=5", "K=10", "K=30", "Automatic"]);
    }
}
