//! Tests of RSE and RSE-Mov: hand-computed ray gains, the fast view gain against the plain sum
//! over rays (bit for bit), the skipping walk against the plain walk, selection rules,
//! candidate bookkeeping and determinism across thread counts.

use super::*;
use crate::occupancy::{entropy, OccupancySettings, VoxelState};
use objview_episode::Budget;
use objview_render::Intrinsics;
use objview_views::ViewSet;

/// Reference (slow, straightforward) ray gain in f64 on the grid itself, for tests of
/// [`GainMap::ray_gain`].
fn reference_ray_gain(grid: &OccupancyGrid, o: [f64; 3], d: [f64; 3]) -> f64 {
    let mut acc = 0.0;
    let mut vis = 1.0;
    let mut prev = None;
    let mut result = 0.0;
    grid.traverse(o, d, 0.0, f64::INFINITY, |v| {
        use std::ops::ControlFlow;
        let p = grid.probability(v.idx);
        let s = grid.state(v.idx);
        if s == VoxelState::Occupied {
            if prev == Some(VoxelState::Unknown) {
                result = acc;
            }
            return ControlFlow::Break(());
        }
        if s == VoxelState::Unknown {
            acc += vis * entropy(p);
        }
        vis *= 1.0 - p;
        prev = Some(s);
        ControlFlow::Continue(())
    });
    result
}

struct MockEnv {
    history: Vec<Pose>,
    feasible: fn(&Pose) -> bool,
}

impl Environment for MockEnv {
    fn is_feasible(&self, pose: &Pose) -> bool {
        (self.feasible)(pose)
    }
    fn history(&self) -> &[Pose] {
        &self.history
    }
}

fn tammes360() -> Arc<Vec<Pose>> {
    Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0))
}

fn start() -> Pose {
    Pose::from_direction([1.0, 1.0, 1.0], 3.0)
}

fn ctx(candidates: Arc<Vec<Pose>>) -> EpisodeContext {
    EpisodeContext {
        seed: 0,
        object_id: "sphere".into(),
        view_space: "whole".into(),
        budget: Budget::Auto,
        candidates,
        candidate_set: "tammes-360".into(),
        start_pose: start(),
        intrinsics: Intrinsics::default(),
        oracle: None,
    }
}

fn observe(mesh: &objview_geom::Mesh, pose: Pose, step: usize) -> Observation {
    let cam = Camera::new(pose, Intrinsics::default());
    let frame = objview_render::render(mesh, &cam);
    Observation { step, pose, intrinsics: cam.intrinsics, depth: Arc::new(frame.depth), rgb: None }
}

fn empty_obs(pose: Pose) -> Observation {
    let k = Intrinsics::default();
    Observation { step: 0, pose, intrinsics: k, depth: Arc::new(vec![0.0; k.num_pixels()]), rgb: None }
}

fn grid() -> OccupancyGrid {
    OccupancyGrid::new(OccupancySettings::default()).unwrap()
}

#[test]
fn hand_computed_ray_gains() {
    let mut g = grid();
    let geom = g.geometry().clone();
    let c = geom.center([32, 32, 32]);
    let (o, d) = ([3.0, c[1], c[2]], [-1.0, 0.0, 0.0]);
    let idx = |i: usize| geom.index([i, 32, 32]);
    // All unknown: the ray leaves the grid → 0.
    assert_eq!(GainMap::new(&g).ray_gain(o, d), 0.0);
    g.set_probability(idx(32), 0.7);
    // Voxels 63 … 33 unknown (p = 0.5, H = ln 2), visibility halves each time.
    let ln2 = std::f64::consts::LN_2;
    let expected = ln2 * (2.0 - 2f64.powi(-30));
    let gain = GainMap::new(&g).ray_gain(o, d);
    assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
    assert!((reference_ray_gain(&g, o, d) - expected).abs() < 1e-12);
    // Occupied right after free → 0.
    g.set_probability(idx(33), 0.4);
    assert_eq!(GainMap::new(&g).ray_gain(o, d), 0.0);
    assert_eq!(reference_ray_gain(&g, o, d), 0.0);
    // A free voxel further up only attenuates: voxels 63…41 unknown, 40 free (1 − p = 0.6),
    // 39…33 unknown.
    g.set_probability(idx(33), 0.5);
    g.set_probability(idx(40), 0.4);
    let s = |k: i32| (0..k).map(|m| 0.5f64.powi(m)).sum::<f64>();
    let expected = ln2 * (s(23) + 0.6 * 0.5f64.powi(23) * s(7));
    let gain = GainMap::new(&g).ray_gain(o, d);
    assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
    // The first occupied voxel ends the ray: one further up takes over.
    g.set_probability(idx(50), 0.9);
    let expected = ln2 * s(13);
    let gain = GainMap::new(&g).ray_gain(o, d);
    assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
    // Unknown voxels with p ≠ 0.5 weigh by H(p) and attenuate by 1 − p.
    let mut g = grid();
    g.set_probability(idx(32), 0.97);
    g.set_probability(idx(33), 0.6);
    g.set_probability(idx(34), 0.46);
    let h = entropy;
    let expected = ln2 * s(29) + 0.5f64.powi(29) * (h(0.46) + 0.54 * h(0.6));
    let gain = GainMap::new(&g).ray_gain(o, d);
    assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
}

#[test]
fn single_occupied_voxel_is_seen_only_by_a_camera_looking_at_it() {
    let mut g = grid();
    let geom = g.geometry().clone();
    g.set_probability(geom.index([32, 32, 32]), 0.9);
    let map = GainMap::new(&g);
    let k = Intrinsics::default();
    let toward = Camera::new(Pose::from_direction([1.0, 0.2, 0.1], 3.0), k);
    let c = toward.center;
    let away = Camera::new(Pose { center: c, look_at: [2.0 * c[0], 2.0 * c[1], 2.0 * c[2]], roll: 0.0 }, k);
    let side = Camera::new(Pose { center: c, look_at: [c[0], c[1] + 1.0, c[2]], roll: 0.0 }, k);
    // Stride 1: the voxel (0.031 wide at distance 3, ~6 px) is hit by a few rays.
    let g_toward = map.view_gain(&toward, 1);
    assert!(g_toward > 0.0);
    assert_eq!(map.view_gain(&away, 1), 0.0);
    assert_eq!(map.view_gain(&side, 1), 0.0);
    // Free space around the voxel (toward the camera) kills the gain.
    let mut g2 = g.clone();
    for i in 0..64 {
        for j in 0..64 {
            for kk in 0..64 {
                let p = geom.center([i, j, kk]);
                if (i, j, kk) != (32, 32, 32) && p[0] > 0.0 {
                    g2.set_probability(geom.index([i, j, kk]), 0.3);
                }
            }
        }
    }
    assert_eq!(GainMap::new(&g2).view_gain(&toward, 1), 0.0);
    // Viewed from -x instead, the ray passes unknown space only.
    let behind = Camera::new(Pose::from_direction([-1.0, 0.2, 0.1], 3.0), k);
    assert!(GainMap::new(&g2).view_gain(&behind, 1) > 0.0);
}

/// The grid after the start view of the unit sphere.
fn sphere_after_start() -> (objview_geom::Mesh, OccupancyGrid) {
    let mesh = objview_render::bench::icosphere(4);
    let mut g = grid();
    let cam = Camera::new(start(), Intrinsics::default());
    g.insert_depth(&cam, &objview_render::render(&mesh, &cam).depth).unwrap();
    (mesh, g)
}

#[test]
fn fast_gain_matches_reference_on_a_real_grid() {
    let (_, g) = sphere_after_start();
    let map = GainMap::new(&g);
    let mut positive = 0;
    for dir in [[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0], [1.0, -0.3, 0.2], [-0.2, 0.5, -1.0], [0.0, 0.0, 1.0]] {
        let cam = Camera::new(Pose::from_direction(dir, 3.0), Intrinsics::default());
        for v in (0..512).step_by(16) {
            for u in (0..512).step_by(16) {
                let d = cam.pixel_ray_object(u, v);
                let fast = map.ray_gain(cam.center, d);
                let slow = reference_ray_gain(&g, cam.center, d);
                assert!((fast - slow).abs() <= 1e-5 * slow.abs(), "{fast} vs {slow}");
                positive += (slow > 0.0) as usize;
            }
        }
    }
    assert!(positive > 100, "{positive}");
}

/// A mid-episode grid of the mug: the start view and five more.
fn mug_grid() -> OccupancyGrid {
    let mesh = objview_geom::synth::build("mug", objview_geom::synth::Detail { segments: 48 }).unwrap();
    let mut g = grid();
    for dir in [
        [1.0, 1.0, 1.0],
        [-1.0, 0.2, 0.3],
        [0.1, -1.0, -0.2],
        [0.3, 0.2, -1.0],
        [0.0, 1.0, -0.1],
        [-0.5, -0.5, 1.0],
    ] {
        let cam = Camera::new(Pose::from_direction(dir, 3.0), Intrinsics::default());
        g.insert_depth(&cam, &objview_render::render(&mesh, &cam).depth).unwrap();
    }
    g
}

#[test]
fn box_radii_are_uniform_boxes_and_skipping_walks_equal_plain_walks() {
    use rand::{Rng, SeedableRng};
    for (name, g) in [("sphere", sphere_after_start().1), ("mug", mug_grid())] {
        let map = GainMap::new(&g);
        let runs = map.runs();
        let geom = g.geometry().clone();
        let n = geom.n;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // Radii: the box is uniform and off the boundary layers; the bound may be one short
        // of the largest such box (see `homogeneous_radius`), never two.
        let mut big = 0;
        for _ in 0..300 {
            let c: [usize; 3] = std::array::from_fn(|_| rng.gen_range(0..n));
            let idx = geom.index(c);
            let r = runs[idx] as usize;
            let same = |rr: usize| {
                (0..3).all(|a| c[a] > rr && c[a] + rr + 1 < n)
                    && (c[2] - rr..=c[2] + rr).all(|k| {
                        (c[1] - rr..=c[1] + rr).all(|j| {
                            (c[0] - rr..=c[0] + rr)
                                .all(|i| map.cells[geom.index([i, j, k])] == map.cells[idx])
                        })
                    })
            };
            if r > 0 {
                assert!(same(r), "{name}: radius {r} at {c:?} is not uniform");
            }
            assert!(!same(r + 2), "{name}: radius at {c:?} could be {}", r + 2);
            big += (r >= 4) as usize;
        }
        assert!(big > 10, "{name}: {big}");
        // Walks: identical to the plain walk, bit for bit, on rays from the candidates.
        let mut positive = 0;
        for pose in tammes360().iter().step_by(11) {
            let cam = Camera::new(*pose, Intrinsics::default());
            for v in (0..512).step_by(8) {
                for u in (0..512).step_by(8) {
                    let d = cam.pixel_ray_object(u, v);
                    let plain = map.ray_gain(cam.center, d);
                    let skip = map.ray_gain_skipping(cam.center, d, runs);
                    assert_eq!(plain.to_bits(), skip.to_bits(), "{name}: {u},{v} {plain} vs {skip}");
                    positive += (plain > 0.0) as usize;
                }
            }
        }
        assert!(positive > 100, "{name}: {positive}");
    }
}

#[test]
fn splatted_view_gain_equals_the_plain_sum_over_rays() {
    let candidates = tammes360();
    for (name, g) in [("sphere", sphere_after_start().1), ("mug", mug_grid())] {
        let map = GainMap::new(&g);
        let mut scratch = GainScratch::default();
        let (mut positive, mut walked, mut hits) = (0, 0, 0);
        for (i, pose) in candidates.iter().enumerate().step_by(7) {
            let cam = Camera::new(*pose, Intrinsics::default());
            let fast = map.view_gain_with(&cam, 4, &mut scratch);
            let plain = map.view_gain_plain(&cam, 4);
            assert_eq!(fast.to_bits(), plain.to_bits(), "{name}, candidate {i}: {fast} vs {plain}");
            positive += (plain > 0.0) as usize;
            walked += scratch.walked();
            hits += scratch.first_hits();
        }
        // The filter is doing its job: after one view about half the rays that reach the
        // sphere see it from behind; mid-episode few rays of the mug are walked.
        let ratio = if name == "mug" { 5 } else { 1 };
        assert!(positive > 10 && walked * ratio < hits, "{name}: {positive} {walked} {hits}");
    }
    // Other strides and an off-centre, rolled camera looking past the object.
    let g = mug_grid();
    let map = GainMap::new(&g);
    let cam = Camera::new(
        Pose { center: [0.4, -2.6, 1.1], look_at: [0.3, 0.2, -0.1], roll: 0.7 },
        Intrinsics::default(),
    );
    for stride in [1, 3, 5] {
        let (fast, plain) = (map.view_gain(&cam, stride), map.view_gain_plain(&cam, stride));
        assert_eq!(fast.to_bits(), plain.to_bits(), "stride {stride}");
    }
    // A camera inside the cube (radius 1.3) and one close to the surface.
    for center in [[0.2, 1.25, 0.3], [0.0, 0.0, 1.05]] {
        let cam = Camera::new(Pose { center, look_at: [0.0, 0.0, 0.0], roll: 0.0 }, Intrinsics::default());
        assert_eq!(map.view_gain(&cam, 4).to_bits(), map.view_gain_plain(&cam, 4).to_bits(), "{center:?}");
    }
}

#[test]
fn rse_goes_to_the_far_side_of_a_sphere_and_rse_mov_gamma_0_agrees() {
    let (mesh, _) = sphere_after_start();
    let candidates = tammes360();
    let env = MockEnv { history: vec![start()], feasible: |_| true };
    let obs = observe(&mesh, start(), 0);
    let mut rse = Rse::new(RseSettings::rse());
    rse.reset(&ctx(candidates.clone()), &env).unwrap();
    let Action::Move { pose } = rse.act(&obs, &env).unwrap() else { panic!("RSE stopped") };
    let s = 1.0 / 3f64.sqrt();
    let dot = (pose[0] + pose[1] + pose[2]) * s;
    assert!(dot < 0.0, "RSE chose {pose:?} (dot with the start direction {dot})");
    let report = rse.last_step().clone();
    assert_eq!(report.candidates.len(), 360);
    // Near-side views (within 30° of the start) see the observed cap through free space and
    // only gain from rays past its rim; views near the antipode see the cap from behind
    // through the unknown interior.
    let max = report.gains.iter().cloned().fold(0.0, f64::max);
    for (k, &i) in report.candidates.iter().enumerate() {
        let c = candidates[i].center;
        let cos = (c[0] + c[1] + c[2]) * s / 3.0;
        if cos > 30f64.to_radians().cos() {
            assert!(report.gains[k] < 0.1 * max, "{cos}: {} of {max}", report.gains[k]);
        }
        if cos < -0.9 {
            assert!(report.gains[k] > 0.9 * max, "{cos}: {} of {max}", report.gains[k]);
        }
    }

    let mut mov0 = Rse::new(RseSettings { gamma: 0.0, ..RseSettings::rse_mov() });
    mov0.reset(&ctx(candidates.clone()), &env).unwrap();
    let a0 = mov0.act(&obs, &env).unwrap();
    assert_eq!(a0, Action::Move { pose });
    assert_eq!(mov0.last_step().gains, report.gains);

    // γ = 1: the nearest remaining candidate.
    let mut mov1 = Rse::new(RseSettings { gamma: 1.0, ..RseSettings::rse_mov() });
    mov1.reset(&ctx(candidates.clone()), &env).unwrap();
    mov1.act(&obs, &env).unwrap();
    let r1 = mov1.last_step();
    let nearest = (0..r1.costs.len())
        .min_by(|&a, &b| r1.costs[a].partial_cmp(&r1.costs[b]).unwrap())
        .map(|k| r1.candidates[k]);
    assert_eq!(r1.chosen, nearest);

    // The default γ = 0.7 stays closer than RSE.
    let mut mov = Rse::new(RseSettings::rse_mov());
    mov.reset(&ctx(candidates.clone()), &env).unwrap();
    mov.act(&obs, &env).unwrap();
    let rm = mov.last_step();
    let cost_of = |r: &StepReport| {
        let k = r.candidates.iter().position(|&i| Some(i) == r.chosen).unwrap();
        r.costs[k]
    };
    assert!(cost_of(rm) <= cost_of(&report));
    assert!(rm.gains[rm.candidates.iter().position(|&i| Some(i) == rm.chosen).unwrap()] > 0.0);
}

#[test]
fn selection_rules() {
    assert_eq!(select_rse(&[]), None);
    assert_eq!(select_rse(&[1.0, 3.0, 3.0, 2.0]), Some(1));
    assert_eq!(select_rse(&[0.0, 0.0]), Some(0));
    // Utility: 0.3·g/Σg − 0.7·c/Σc. g = [4, 6], c = [1, 3]: [0.12 − 0.175, 0.18 − 0.525].
    assert_eq!(select_rse_mov(&[4.0, 6.0], &[1.0, 3.0], 0.7), Some(0));
    assert_eq!(select_rse_mov(&[4.0, 6.0], &[1.0, 3.0], 0.0), Some(1));
    // All gains zero: the nearest; all costs zero too: the lowest index.
    assert_eq!(select_rse_mov(&[0.0, 0.0, 0.0], &[2.0, 1.0, 1.0], 0.7), Some(1));
    assert_eq!(select_rse_mov(&[0.0, 0.0], &[0.0, 0.0], 0.7), Some(0));
}

#[test]
fn visited_and_infeasible_candidates_are_skipped_then_exhausted() {
    // Eight candidates; those with z < 0 are infeasible.
    let dirs = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 1.0, -1.0],
        [1.0, 1.0, 1.0],
    ];
    let candidates: Arc<Vec<Pose>> = Arc::new(dirs.iter().map(|d| Pose::from_direction(*d, 3.0)).collect());
    let mut env = MockEnv { history: vec![start()], feasible: |p| p.center[2] >= 0.0 };
    for settings in [RseSettings::rse(), RseSettings::rse_mov()] {
        env.history = vec![start()];
        let mut planner = Rse::new(settings);
        planner.reset(&ctx(candidates.clone()), &env).unwrap();
        let mut chosen = Vec::new();
        // Empty frames: every gain is 0; the planner keeps moving (to new candidates).
        loop {
            let pose = *env.history.last().unwrap();
            match planner.act(&empty_obs(pose), &env).unwrap() {
                Action::Move { pose } => {
                    let p = Pose::from_array(pose).unwrap();
                    let i = candidates.iter().position(|c| *c == p).unwrap();
                    assert!(!chosen.contains(&i) && candidates[i].center[2] >= 0.0);
                    assert!(planner.last_step().gains.iter().all(|&g| g == 0.0));
                    chosen.push(i);
                    env.history.push(p);
                }
                Action::Stop { reason } => {
                    assert_eq!(reason, "candidate_exhausted");
                    break;
                }
            }
        }
        // Candidate 7 is the start position: visited from the history.
        chosen.sort();
        assert_eq!(chosen, vec![0, 1, 2, 3, 4], "{}", settings.name());
    }
    // A move issued but not yet in the history also counts as visited.
    let env = MockEnv { history: vec![start()], feasible: |_| true };
    let mut planner = Rse::new(RseSettings::rse());
    planner.reset(&ctx(candidates.clone()), &env).unwrap();
    let a = planner.act(&empty_obs(start()), &env).unwrap();
    let b = planner.act(&empty_obs(start()), &env).unwrap();
    assert_ne!(a, b);
    assert_eq!(a, Action::move_to(&candidates[0]));
    assert_eq!(b, Action::move_to(&candidates[1]));
}

#[test]
fn deterministic_across_thread_counts() {
    let mesh = objview_geom::synth::build("mug", objview_geom::synth::Detail { segments: 48 }).unwrap();
    let candidates = tammes360();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut env = MockEnv { history: vec![start()], feasible: |p| p.center[2] >= 0.0 };
            let mut planner = Rse::new(RseSettings::rse_mov());
            planner.reset(&ctx(candidates.clone()), &env).unwrap();
            let mut out = Vec::new();
            for step in 0..3 {
                let pose = *env.history.last().unwrap();
                let a = planner.act(&observe(&mesh, pose, step), &env).unwrap();
                out.push((a.clone(), planner.last_step().clone()));
                if let Action::Move { pose } = a {
                    env.history.push(Pose::from_array(pose).unwrap());
                }
            }
            (out, planner.grid().unwrap().log_odds().to_vec())
        })
    };
    let (a, ga) = run(1);
    let (b, gb) = run(2);
    assert_eq!(a, b);
    assert_eq!(ga, gb);
    assert!(a.iter().all(|(act, r)| matches!(act, Action::Move { .. }) && r.gains.iter().any(|&g| g > 0.0)));
}

#[test]
fn metadata_and_params() {
    let p = Rse::new(RseSettings::rse());
    assert_eq!(
        (p.name(), p.family(), p.execution_mode()),
        ("rse", Family::Classical, ExecutionMode::Iterative)
    );
    assert!(p.params().get("gamma").is_none());
    assert_eq!(p.params()["stride"], 4);
    assert_eq!(p.params()["occupancy"]["resolution"], 64);
    let m = Rse::new(RseSettings::rse_mov());
    assert_eq!(m.name(), "rse-mov");
    assert_eq!(m.params()["gamma"], 0.7);
    // Invalid settings fail at reset; act before reset is an error.
    let env = MockEnv { history: vec![start()], feasible: |_| true };
    let mut bad = Rse::new(RseSettings { stride: 0, ..RseSettings::rse() });
    assert!(bad.reset(&ctx(tammes360()), &env).is_err());
    let mut fresh = Rse::new(RseSettings::rse());
    assert!(fresh.act(&empty_obs(start()), &env).is_err());
}
