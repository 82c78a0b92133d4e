//! Every metric of random episodes against an independent recomputation: the visited views are
//! rendered again, fused with a hash map by the SPEC §5 rule (voxel centroids, a previous fused
//! point counting once), and scored by brute force — per-step SC@τ/NSC@τ as the instantaneous
//! fractions (strict d² < τ² against the current fused cloud), CD at every checkpoint as the
//! two exact mean squared nearest distances.

use std::collections::HashMap;
use std::sync::Arc;

use objview_episode::{
    run_episode, scene_from_parts, Action, Budget, EpisodeSettings, ExecutionMode, Scripted,
};
use objview_geom::cloud::sample_surface;
use objview_geom::Pose;
use objview_render::{Camera, Frame, Renderer};
use objview_views::{start_pose, ViewSet, ViewSpace};
use rand::{Rng, SeedableRng};

/// The SPEC §5 fusion rule, written plainly: voxel key floor(p / h) → (sum, count) of this
/// view's points, then centroid with the previous point (weight 1).
fn fuse(fused: &mut HashMap<[i64; 3], [f64; 3]>, points: &[[f64; 3]], h: f64) {
    let mut acc: HashMap<[i64; 3], ([f64; 3], f64)> = HashMap::new();
    for p in points {
        let k = [(p[0] / h).floor() as i64, (p[1] / h).floor() as i64, (p[2] / h).floor() as i64];
        let e = acc.entry(k).or_insert(([0.0; 3], 0.0));
        for (s, x) in e.0.iter_mut().zip(p) {
            *s += x;
        }
        e.1 += 1.0;
    }
    for (k, (s, n)) in acc {
        let q = match fused.get(&k) {
            Some(q) => [(q[0] + s[0]) / (n + 1.0), (q[1] + s[1]) / (n + 1.0), (q[2] + s[2]) / (n + 1.0)],
            None => [s[0] / n, s[1] / n, s[2] / n],
        };
        fused.insert(k, q);
    }
}

fn d2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Exact nearest d² from each of `a` to `b` (brute force, every pair).
fn nearest(a: &[[f64; 3]], b: &[[f64; 3]]) -> Vec<f64> {
    a.iter().map(|&p| b.iter().map(|&q| d2(p, q)).fold(f64::INFINITY, f64::min)).collect()
}

#[test]
fn per_step_coverage_and_checkpoint_cd_equal_brute_force() {
    // A small torus-like object: an icosphere squashed and shifted, so views see different parts.
    let mut mesh = objview_render::bench::icosphere(3);
    mesh.positions.iter_mut().for_each(|p| *p = [p[0] * 0.2, p[1] * 0.13, p[2] * 0.2 + 0.03]);
    let gt = sample_surface(&mesh, 3000, 3);
    let settings = EpisodeSettings { record_timings: false, enough_info: false, ..Default::default() };
    let space = ViewSpace::builtin("whole").unwrap();
    let scene = Arc::new(
        scene_from_parts(
            "blob",
            mesh.clone(),
            gt.clone(),
            "sampled".into(),
            &space,
            "whole",
            &settings,
            None,
        )
        .unwrap(),
    );
    let candidates = Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0));
    let taus = settings.taus.clone();
    for seed in 0..2u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let poses: Vec<Pose> = (0..6).map(|_| candidates[rng.gen_range(0..candidates.len())]).collect();
        let actions: Vec<Action> = poses.iter().map(Action::move_to).collect();
        let mut planner = Scripted::new(actions, ExecutionMode::Iterative);
        let r = run_episode(
            scene.clone(),
            &mut planner,
            &settings,
            Budget::Fixed(3),
            0,
            start_pose(3.0),
            candidates.clone(),
            serde_json::json!({}),
        )
        .unwrap();
        let mut fused: HashMap<[i64; 3], [f64; 3]> = HashMap::new();
        let mut renderer = Renderer::new();
        for (i, step) in r.steps.iter().enumerate() {
            let pose = Pose::from_array(step.pose).unwrap();
            let cam = Camera::new(pose, scene.intrinsics);
            let mut frame = Frame::empty(cam);
            renderer.render_into(&mesh, &cam, &mut frame);
            fuse(&mut fused, &frame.observed_points(), settings.fusion_voxel);
            let cloud: Vec<[f64; 3]> = fused.values().copied().collect();
            let gt_near = nearest(&gt, &cloud);
            let ref_near = nearest(&scene.reference.points, &cloud);
            for &tau in &taus {
                let key = objview_episode::vocab::tau_key(tau);
                let frac =
                    |near: &[f64]| near.iter().filter(|&&d| d < tau * tau).count() as f64 / near.len() as f64;
                assert_eq!(step.metrics.sc[&key], frac(&gt_near), "seed {seed} step {i} SC@{key}");
                assert_eq!(step.metrics.nsc[&key], frac(&ref_near), "seed {seed} step {i} NSC@{key}");
            }
            for (name, c) in r.checkpoints.iter().filter(|(_, c)| c.step == i) {
                let fused_near = nearest(&cloud, &gt);
                let want = gt_near.iter().sum::<f64>() / gt.len() as f64
                    + fused_near.iter().sum::<f64>() / cloud.len() as f64;
                assert!(
                    (c.metrics.cd - want).abs() <= 1e-9 * want,
                    "seed {seed} checkpoint {name}: CD {} vs brute force {want}",
                    c.metrics.cd
                );
                assert_eq!(c.metrics.sc, step.metrics.sc);
            }
        }
        assert!(
            r.checkpoints.contains_key(&"K=3".parse().unwrap())
                && r.checkpoints.contains_key(&"K=5".parse().unwrap())
        );
    }
}
