//! Real episodes of the hybrid planners on built-in objects: with the `oracle` completion,
//! `completion-scp` covers the observable reference of a convex object; `identity` (no
//! completion) never ends with more coverage than `oracle`; MCP spends exactly its budget;
//! `completion-nbv` runs capped episodes with feasible, unique views.

use std::path::Path;
use std::sync::Arc;

use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeResult, EpisodeSettings, Scene};
use objview_geom::cloud::sample_surface;
use objview_geom::normalize::{normalize, Normalization};
use objview_geom::synth::{build, Detail};
use objview_planners::registry::with_params;
use objview_views::{start_pose, ViewSet, ViewSpace};
use serde_json::json;

/// How far `identity` may come out above `oracle` (NSC@0.02, a fraction of the reference
/// points). The oracle's plan is optimal for the needed 1/32 voxels, not for the 0.02 coverage
/// of single reference points, and the solver may return another plan of equal voxel value
/// (seen once in CI on a loaded machine: MCP K = 5 on the torus, identity 1.0 vs oracle
/// 0.99999, one reference point). More than 0.1 % would be a real inversion.
const BOUND_SLACK: f64 = 1e-3;

fn scene(name: &str) -> Arc<Scene> {
    let mesh = build(name, Detail { segments: 24 }).unwrap();
    let (mesh, _) = normalize(mesh, Normalization::Unit, Path::new(name)).unwrap();
    let gt = sample_surface(&mesh, 20_000, 1);
    let vs = ViewSpace::builtin("whole").unwrap();
    let settings = EpisodeSettings { record_timings: false, ..Default::default() };
    Arc::new(scene_from_parts(name, mesh, gt, "sampled".into(), &vs, "whole", &settings, None).unwrap())
}

fn run(sc: &Arc<Scene>, planner: &str, completion: &str, budget: Budget) -> EpisodeResult {
    run_capped(sc, planner, completion, budget, EpisodeSettings::default().cap)
}

fn run_capped(sc: &Arc<Scene>, planner: &str, completion: &str, budget: Budget, cap: usize) -> EpisodeResult {
    let mut p = with_params(planner, &[("completion".into(), json!(completion))]).unwrap();
    let settings = EpisodeSettings { record_timings: false, cap, ..Default::default() };
    let cands = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0));
    run_episode(sc.clone(), p.as_mut(), &settings, budget, 0, start_pose(3.0), cands, json!({})).unwrap()
}

fn nsc(r: &EpisodeResult, tau: &str) -> f64 {
    r.checkpoints[&"terminal".parse().unwrap()].metrics.nsc[tau]
}

#[test]
fn oracle_scp_covers_a_convex_object_and_identity_never_beats_oracle() {
    for name in ["cube", "torus"] {
        let sc = scene(name);
        let oracle = run(&sc, "completion-scp", "oracle", Budget::Auto);
        assert_eq!(oracle.method, "completion-scp[oracle]");
        assert_eq!(oracle.terminal_reason, "plan_end", "{name}: {}", oracle.terminal_detail);
        let identity = run(&sc, "completion-scp", "identity", Budget::Auto);
        assert_eq!(identity.method, "completion-scp[identity]");
        // No prediction, no target: the plan ends after the bootstrap (start + 1 view).
        assert_eq!((identity.terminal_reason.as_str(), identity.visited_poses.len()), ("plan_end", 2));
        let (o, i) = (nsc(&oracle, "0.02"), nsc(&identity, "0.02"));
        eprintln!(
            "{name}: SCP NSC@0.02 oracle {o:.4} ({} views), identity {i:.4}",
            oracle.visited_poses.len()
        );
        assert!(i <= o + BOUND_SLACK, "{name}: identity {i} beats oracle {o}");
        // The cube is covered by the start view and its antipode alone (nothing is needed);
        // the torus needs a real plan (7 views), and the oracle's covers all of it.
        assert!(o >= 0.99, "{name}: oracle SCP NSC@0.02 = {o}");
        if name == "torus" {
            assert!(oracle.visited_poses.len() > 2 && i < 0.95, "{name}: the plan matters here");
            // The plan's record is in the result: the set cover proven optimal, its size the
            // views planned after the bootstrap, and no wall-clock field in it.
            let plan = &oracle.planner_notes.as_ref().expect("planner_notes")["plan"];
            assert_eq!(plan["selection"]["status"], "optimal", "{plan}");
            assert_eq!(plan["selection"]["gap"], 0.0);
            let planned = plan["visit_order"].as_array().unwrap().len();
            assert_eq!(planned, oracle.visited_poses.len() - 2, "{plan}");
            assert_eq!(plan["selection"]["chosen"].as_array().unwrap().len(), planned);
            assert_eq!(plan["completion"], "oracle");
            assert!(!plan.to_string().contains("seconds"), "{plan}");
        }
        let plan = &identity.planner_notes.as_ref().expect("planner_notes")["plan"];
        assert_eq!(plan["selection"]["status"], "skipped", "{plan}");
        let k = 5;
        let om = run(&sc, "completion-mcp", "oracle", Budget::Fixed(k));
        let im = run(&sc, "completion-mcp", "identity", Budget::Fixed(k));
        for r in [&om, &im] {
            assert_eq!(r.visited_poses.len(), k + 1, "{name}: {} {}", r.method, r.terminal_detail);
            assert_eq!(r.terminal_reason, "plan_end");
        }
        let (o, i) = (nsc(&om, "0.02"), nsc(&im, "0.02"));
        eprintln!("{name}: MCP K=5 NSC@0.02 oracle {o:.4}, identity {i:.4}");
        assert!(i <= o + BOUND_SLACK, "{name}: MCP identity {i} beats oracle {o}");
    }
}

#[test]
fn net_is_refused_with_a_clear_error() {
    let err = with_params("completion-scp", &[("completion".into(), json!("net"))]).err().unwrap();
    assert!(err.contains("the net completion backend is not linked into these planner rows"), "{err}");
    assert!(with_params("completion-mcp", &[("completion".into(), json!("pointr"))]).is_err());
    // Weights are read by net only: naming them with another backend is an error.
    let err = with_params(
        "completion-scp",
        &[("completion".into(), json!("identity")), ("completion_weights".into(), json!("w.safetensors"))],
    )
    .err()
    .unwrap();
    assert!(err.contains("completion_weights is read by completion=net only"), "{err}");
    let p = with_params("completion-scp", &[("completion".into(), json!("oracle"))]).unwrap();
    assert!(p.needs_ground_truth());
    assert_eq!(p.params()["completion_bound"], "upper_bound");
}

#[test]
fn nbv_runs_short_episodes_with_feasible_unique_views() {
    let sc = scene("torus");
    // A step cap of 7 views (start included).
    let k = 6;
    let mut seen = Vec::new();
    for completion in ["oracle", "identity"] {
        let r = run_capped(&sc, "completion-nbv", completion, Budget::Auto, k + 1);
        assert_eq!(r.method, format!("completion-nbv[{completion}]"));
        let views = &r.visited_poses;
        assert!(!views.is_empty() && views.len() <= k + 1, "{completion}: {} views", views.len());
        // Unique views (no revisits), all feasible (the episode would record an infeasible
        // move as its terminal reason).
        for (i, a) in views.iter().enumerate() {
            for b in &views[..i] {
                let d: f64 = (0..3).map(|j| (a[j] - b[j]).powi(2)).sum::<f64>().sqrt();
                assert!(d > 1e-9, "{completion}: view {i} revisits {b:?}");
            }
        }
        assert!(
            !["next_view_infeasible", "next_view_visited"].contains(&r.terminal_reason.as_str()),
            "{completion}: {} {}",
            r.terminal_reason,
            r.terminal_detail
        );
        let c = nsc(&r, "0.02");
        eprintln!(
            "torus: NBV[{completion}] K={k}: {} views, NSC@0.02 {c:.4}, {}",
            views.len(),
            r.terminal_reason
        );
        seen.push(c);
    }
    // Measured: oracle 0.9986, identity 0.511 (with no prediction the target is empty, every
    // observed voxel scores, and the nearest near-best view is a small move).
    assert!(seen[0] > 0.95 && seen[1] > 0.4 && seen[1] <= seen[0], "{seen:?}");
}
