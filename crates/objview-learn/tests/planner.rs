//! The `nbv-net` planner in real episodes with a scripted network output: the stop rules of
//! the reference (repeat → `next_view_visited`, infeasible → `next_view_infeasible`, no
//! fallback), the moves go to the predicted tammes-128 views, and the grid the scorer sees
//! grows with every observation.

use std::sync::{Arc, Mutex};

use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeSettings, Planner};
use objview_geom::cloud::sample_surface;
use objview_geom::Pose;
use objview_learn::input_grid::InputGrid;
use objview_learn::planner::{NbvNetPlanner, ViewScorer};
use objview_views::{start_pose, ViewSet, ViewSpace};

/// Scores that put view `script[k]` first at call k, and records how many grid cells are known.
struct Script {
    script: Vec<usize>,
    calls: usize,
    known: Arc<Mutex<Vec<usize>>>,
}

impl ViewScorer for Script {
    fn scores(&mut self, grid: &InputGrid) -> Vec<f32> {
        let known = grid.probabilities().iter().filter(|&&p| p != 0.5).count();
        self.known.lock().unwrap().push(known);
        let mut s = vec![0.0; 128];
        s[self.script[self.calls.min(self.script.len() - 1)]] = 1.0;
        self.calls += 1;
        s
    }
    fn describe(&self) -> serde_json::Value {
        serde_json::json!("scripted")
    }
}

fn episode(space: &str, script: Vec<usize>) -> (objview_episode::EpisodeResult, Vec<usize>) {
    let mesh = objview_render::bench::icosphere(2);
    let gt = sample_surface(&mesh, 5_000, 1);
    let settings = EpisodeSettings { record_timings: false, ..Default::default() };
    let vs = ViewSpace::builtin(space).unwrap();
    let scene = Arc::new(
        scene_from_parts("sphere", mesh, gt, "sampled".into(), &vs, space, &settings, None).unwrap(),
    );
    let known = Arc::new(Mutex::new(vec![]));
    let mut p = NbvNetPlanner::with_scorer(Box::new(Script { script, calls: 0, known: known.clone() }));
    assert_eq!(p.name(), "nbv-net");
    let cands = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0));
    let r = run_episode(
        scene,
        &mut p,
        &settings,
        Budget::Fixed(30),
        0,
        start_pose(3.0),
        cands,
        serde_json::json!({}),
    )
    .unwrap();
    let k = known.lock().unwrap().clone();
    (r, k)
}

#[test]
fn repeated_prediction_stops_with_next_view_visited() {
    let (r, known) = episode("whole", vec![3, 17, 3, 40]);
    assert_eq!(r.terminal_reason, "next_view_visited");
    let t128 = ViewSet::resolve("tammes-128").unwrap().poses(3.0);
    let moved: Vec<[f64; 7]> = r.visited_poses.iter().skip(1).copied().collect();
    let want: Vec<[f64; 7]> = [3usize, 17].iter().map(|&v| t128[v].to_array()).collect();
    assert_eq!(moved, want, "moves go to the predicted tammes-128 views, start pose first");
    assert_eq!(known.len(), 3);
    assert!(known[0] > 0 && known[1] > known[0] && known[2] > known[1], "the grid grows: {known:?}");
}

#[test]
fn infeasible_prediction_stops_without_fallback() {
    let t128 = ViewSet::resolve("tammes-128").unwrap().poses(3.0);
    let quarter = ViewSpace::builtin("quarter").unwrap();
    let bad = (0..128).find(|&v| !quarter.is_feasible(&t128[v])).unwrap();
    let good = (0..128).find(|&v| quarter.is_feasible(&t128[v])).unwrap();
    let (r, _) = episode("quarter", vec![good, bad, good]);
    assert_eq!(r.terminal_reason, "next_view_infeasible");
    assert_eq!(r.visited_poses.len(), 2, "start + one move, then the stop");
    let _ = Pose::from_direction([0.0, 0.0, 1.0], 3.0);
}
