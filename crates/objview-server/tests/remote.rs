//! `run_remote` (what `objview run --server` does) against the real router: a Rust planner
//! played through the HTTP API writes the result line a local episode writes — same
//! checkpoints, steps, poses and settings record — when timings are off; a failing planner
//! ends both ways with the same `planner_error`; the oracle is refused.

mod common;

use std::sync::Arc;

use common::*;
use objview_episode::{
    load_scene, run_episode, Action, Budget, Environment, EpisodeContext, EpisodeSettings, ExecutionMode,
    Family, Observation, Planner, PlannerError, SceneSource,
};
use objview_geom::normalize::Normalization;
use objview_geom::Pose;
use objview_runs::record::RunRecord;
use objview_server::client::{run_remote, Client, ClientError, RemoteEpisode};
use objview_views::{ViewSet, ViewSpace};

/// The line a local `objview run` writes for `planner` on the hidden split's `uid`.
fn local_line(planner: &mut dyn Planner, uid: &str, space_name: &str, budget: Budget, seed: u64) -> String {
    let f = fixture();
    let objects = objview_dataset::read_split(&f.hidden).unwrap();
    let obj = objects.iter().find(|o| o.uid == uid).unwrap();
    let settings = EpisodeSettings { record_timings: false, ..Default::default() };
    let space = ViewSpace::builtin(space_name).unwrap();
    let src = SceneSource {
        uid: &obj.uid,
        mesh: &obj.mesh,
        gt_cloud: obj.gt_cloud.as_deref(),
        normalization: Normalization::Unit,
    };
    let scene = Arc::new(load_scene(&src, &space, space_name, &settings, Some(&f.cache)).unwrap());
    let candidates = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(settings.view_radius));
    let start = objview_views::start_pose(settings.view_radius);
    let record = RunRecord {
        planner: planner.name(),
        planner_params: planner.params(),
        view_space: space_name,
        space: &space,
        budget,
        seed,
        candidates: "tammes-360",
        candidate_count: candidates.len(),
        start_pose: start,
        normalize: Normalization::Unit,
        settings: &settings,
    }
    .to_json();
    let res = run_episode(scene, planner, &settings, budget, seed, start, candidates, record).unwrap();
    objview_dataset::to_line(&res)
}

fn remote_line(
    c: &Client,
    planner: &mut dyn Planner,
    uid: &str,
    space: &str,
    budget: Budget,
    seed: u64,
) -> Result<String, ClientError> {
    let ep = RemoteEpisode {
        split: "hidden".into(),
        object: uid.into(),
        view_space: space.into(),
        budget,
        candidate_set: "tammes-360".into(),
        seed,
        record_timings: false,
    };
    let candidates = Arc::new(c.candidate_set("tammes-360")?);
    run_remote(c, planner, &ep, candidates)
}

fn planner(name: &str, params: &[(&str, serde_json::Value)]) -> Box<dyn Planner> {
    let params: Vec<(String, serde_json::Value)> =
        params.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
    objview_planners::registry::with_params(name, &params).unwrap()
}

#[test]
fn remote_episodes_write_the_lines_of_local_ones() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let cheap_rse = [("stride", serde_json::json!(16))];
    for (name, params, uid, space, budget, seed) in [
        ("random-tsp", &[][..], "octahedron", "quarter", Budget::Fixed(5), 7),
        ("rse-mov", &cheap_rse[..], "cube", "hemi", Budget::Auto, 3),
    ] {
        let local = local_line(planner(name, params).as_mut(), uid, space, budget, seed);
        let remote = remote_line(&c, planner(name, params).as_mut(), uid, space, budget, seed).unwrap();
        let v: serde_json::Value = serde_json::from_str(&remote).unwrap();
        assert!(v["steps"].as_array().unwrap().len() > 3, "{name}: a real episode");
        assert_eq!(remote, local, "{name}: remote and local lines differ");
        // random-tsp keeps notes (its path solve), RSE none: both written alike either way.
        assert_eq!(
            v["planner_notes"]["plan"]["tsp"]["optimal"].as_bool(),
            (name == "random-tsp").then_some(true)
        );
    }
}

/// Moves to two candidates, then fails.
struct Flaky {
    moves: usize,
}

impl Planner for Flaky {
    fn name(&self) -> &str {
        "flaky"
    }
    fn family(&self) -> Family {
        Family::Learned
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }
    fn params(&self) -> serde_json::Value {
        serde_json::json!({"fails_after": 2})
    }
    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.moves = 0;
        assert!(env.feasible_mask(&ctx.candidates).iter().any(|&f| f));
        Ok(())
    }
    fn act(&mut self, obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        assert_eq!(env.history().last(), Some(&obs.pose));
        assert_eq!(obs.depth.len(), 512 * 512);
        self.moves += 1;
        match self.moves {
            1 => Ok(Action::move_to(&Pose::from_direction([1.0, 0.0, 0.2], 3.0))),
            2 => Ok(Action::move_to(&Pose::from_direction([0.0, 1.0, 0.2], 3.0))),
            _ => Err(PlannerError("out of ideas".into())),
        }
    }
}

#[test]
fn a_failing_planner_ends_both_ways_alike_and_the_oracle_is_refused() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let local = local_line(&mut Flaky { moves: 0 }, "cube", "whole", Budget::Auto, 0);
    let remote = remote_line(&c, &mut Flaky { moves: 0 }, "cube", "whole", Budget::Auto, 0).unwrap();
    assert_eq!(remote, local);
    let v: serde_json::Value = serde_json::from_str(&remote).unwrap();
    assert_eq!(v["terminal_reason"], "planner_error");
    assert_eq!(v["terminal_detail"], "out of ideas");
    assert_eq!(v["visited_poses"].as_array().unwrap().len(), 3);
    let err = remote_line(&c, planner("oracle", &[]).as_mut(), "cube", "whole", Budget::Auto, 0).unwrap_err();
    assert!(matches!(err, ClientError::Unsupported(_)), "{err}");
    assert!(err.to_string().contains("ground truth"));
}

/// Asks for the feasibility of a huge, a non-finite and a good pose, moves to the first feasible
/// one, then stops.
struct Bounded {
    moves: usize,
}

impl Planner for Bounded {
    fn name(&self) -> &str {
        "bounded"
    }
    fn family(&self) -> Family {
        Family::Classical
    }
    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }
    fn params(&self) -> serde_json::Value {
        serde_json::json!({})
    }
    fn reset(&mut self, _: &EpisodeContext, _: &dyn Environment) -> Result<(), PlannerError> {
        self.moves = 0;
        Ok(())
    }
    fn act(&mut self, _: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        self.moves += 1;
        if self.moves > 1 {
            return Ok(Action::Stop { reason: "plan_end".into() });
        }
        let poses = [
            Pose { center: [1e300, 1e300, 1e300], look_at: [0.0; 3], roll: 0.0 },
            Pose { center: [f64::NAN, 0.0, 3.0], look_at: [0.0; 3], roll: 0.0 },
            Pose::from_direction([1.0, 0.0, 0.2], 3.0),
        ];
        let mask = env.feasible_mask(&poses);
        if mask != [false, false, true] {
            return Err(PlannerError(format!("feasibility {mask:?}")));
        }
        Ok(Action::move_to(&poses[2]))
    }
}

#[test]
fn poses_beyond_the_bound_are_infeasible_remotely_as_locally() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let local = local_line(&mut Bounded { moves: 0 }, "cube", "whole", Budget::Auto, 0);
    let remote = remote_line(&c, &mut Bounded { moves: 0 }, "cube", "whole", Budget::Auto, 0).unwrap();
    assert_eq!(remote, local);
    let v: serde_json::Value = serde_json::from_str(&remote).unwrap();
    assert_eq!(v["terminal_reason"], "plan_end", "{}", v["terminal_detail"]);
    assert_eq!(v["visited_poses"].as_array().unwrap().len(), 2);
}

/// A full server (its cap on running episodes reached) is waited for: the remote runner asks
/// again until a place comes back, then writes the same line as a local run.
#[test]
fn a_remote_run_waits_for_a_place_on_a_full_server() {
    let (mut cfg, _tmp) = config();
    cfg.max_running = 1;
    let s = start(&cfg);
    let c = client(&s);
    // Another client holds the only place.
    let held = c
        .create(&serde_json::json!({"split": "hidden", "object": "octahedron", "view_space": "whole",
        "budget": 5, "method": "holder"}))
        .unwrap();
    let held = held["episode_id"].as_str().unwrap().to_string();
    let url = s.url();
    let runner = std::thread::spawn(move || {
        let c = Client::new(&url, None);
        remote_line(&c, planner("random-tsp", &[]).as_mut(), "cube", "quarter", Budget::Fixed(5), 7)
    });
    std::thread::sleep(std::time::Duration::from_millis(1500));
    assert!(!runner.is_finished(), "the runner went ahead while the only place was taken");
    assert_eq!(c.raw("POST", &format!("/v1/episodes/{held}/abort"), Some(b"{}")).unwrap().status, 200);
    let remote = runner.join().unwrap().expect("the runner gets the freed place");
    let local = local_line(planner("random-tsp", &[]).as_mut(), "cube", "quarter", Budget::Fixed(5), 7);
    assert_eq!(remote, local);
}
