//! Tests of the exact set-cover ILP (`solve_min_cover`) against the brute-force oracle of
//! `setcover`, on hand-made instances, on a 128-view spherical-cap visibility instance, and under
//! a time limit.

mod common;

use common::caps;
use objview_difficulty::{
    solve_min_cover, CoverInstance, CoverMethod, CoverResult, CoverSettings, CoverStatus, DifficultyError,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn bitsets(views: &[Vec<usize>]) -> Vec<Vec<u64>> {
    let span = views.iter().flatten().max().map_or(0, |&m| m + 1);
    views
        .iter()
        .map(|list| {
            let mut set = vec![0u64; span.div_ceil(64)];
            for &e in list {
                set[e / 64] |= 1 << (e % 64);
            }
            set
        })
        .collect()
}

fn settings(k: usize) -> CoverSettings {
    CoverSettings { min_views_per_element: k, ..CoverSettings::default() }
}

/// The invariants every result must satisfy, whatever its status.
fn check_consistent(views: &[Vec<u64>], k: usize, r: &CoverResult) {
    let inst = CoverInstance::from_bitsets(views, k).unwrap();
    assert_eq!(r.universe, inst.n_elements());
    assert_eq!(r.n_views, views.len());
    assert!(inst.is_cover(&r.best_cover), "best cover {:?} does not cover U", r.best_cover);
    assert!(r.best_cover.windows(2).all(|w| w[0] < w[1]), "cover not sorted: {:?}", r.best_cover);
    assert_eq!(r.best_size, r.best_cover.len());
    assert_eq!(r.greedy_size, inst.greedy().len());
    assert!(r.best_size <= r.greedy_size);
    assert!(r.lower_bound <= r.best_size);
    assert!(r.lp_bound <= r.best_size as f64 + 1e-6, "LP bound {} > cover {}", r.lp_bound, r.best_size);
    if r.lp_solved {
        assert!(
            r.lower_bound as f64 >= r.lp_bound - 1e-6,
            "lower bound {} < LP {}",
            r.lower_bound,
            r.lp_bound
        );
    }
    match r.status {
        CoverStatus::Optimal => {
            assert_eq!(r.d_plan, Some(r.best_size));
            assert_eq!(r.lower_bound, r.best_size);
        }
        CoverStatus::TimeLimit => {
            assert_eq!(r.d_plan, None, "d_plan must be None unless proven optimal");
            assert!(r.lower_bound < r.best_size, "a closed gap must be reported optimal: {r:?}");
        }
        _ => assert_eq!(r.d_plan, None, "d_plan must be None unless proven optimal"),
    }
}

#[test]
fn matches_brute_force_on_random_small_instances() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x11f);
    let densities = [0.05, 0.12, 0.25, 0.45, 0.7];
    let mut checked = 0;
    let mut greedy_beaten = 0;
    for case in 0..300 {
        let n_views = rng.gen_range(1..=16);
        let n_elements = rng.gen_range(1..=80);
        let density = densities[case % densities.len()];
        let k = 1 + case % 2;
        let lists: Vec<Vec<usize>> =
            (0..n_views).map(|_| (0..n_elements).filter(|_| rng.gen_bool(density)).collect()).collect();
        let mut views = bitsets(&lists);
        // Pad to a common span so that elements no view sees stay outside U.
        let span = n_elements.div_ceil(64);
        for v in &mut views {
            v.resize(span, 0);
        }
        let inst = CoverInstance::from_bitsets(&views, k).unwrap();
        let oracle = inst.brute_force().unwrap();
        // Both exact methods: the default (search, ILP fallback) and the ILP alone.
        for method in [CoverMethod::Auto, CoverMethod::Ilp] {
            let r = solve_min_cover(&views, &CoverSettings { method, ..settings(k) }).unwrap();
            assert_eq!(r.status, CoverStatus::Optimal, "case {case} {method}: {r:?}");
            assert_eq!(r.d_plan, Some(oracle.len()), "case {case}: {method} vs brute force");
            check_consistent(&views, k, &r);
            assert!(r.lp_solved);
            if method == CoverMethod::Ilp {
                assert_eq!(r.search_nodes, 0);
                assert!(r.proven_by == "ilp" || r.proven_by == "reductions", "{}", r.proven_by);
            } else {
                assert!(r.proven_by == "search" || r.proven_by == "reductions", "{}", r.proven_by);
            }
        }
        let r = solve_min_cover(&views, &settings(k)).unwrap();
        greedy_beaten += usize::from(r.best_size < r.greedy_size);
        checked += 1;
    }
    assert_eq!(checked, 300);
    // The sample must exercise instances where the exact optimum beats greedy.
    assert!(greedy_beaten > 0, "no random instance had a suboptimal greedy cover");
}

#[test]
fn finds_the_optimum_where_greedy_is_suboptimal() {
    // A = {0..6} and B = {7..13} cover U with 2 views; greedy takes the 8-element view C1 first,
    // then C2 (4 new) and C3 (2 new): 3 views.
    let lists = vec![
        (0..7).collect::<Vec<_>>(),    // view 0: A
        (7..14).collect(),             // view 1: B
        vec![0, 1, 2, 3, 7, 8, 9, 10], // view 2: C1
        vec![4, 5, 11, 12],            // view 3: C2
        vec![6, 13],                   // view 4: C3
    ];
    let views = bitsets(&lists);
    let r = solve_min_cover(&views, &settings(1)).unwrap();
    check_consistent(&views, 1, &r);
    assert_eq!(r.status, CoverStatus::Optimal);
    assert_eq!(r.greedy_size, 3);
    assert_eq!(r.d_plan, Some(2));
    assert_eq!(r.best_cover, vec![0, 1]);
    assert_eq!(r.universe, 14);
}

#[test]
fn the_ilp_alone_returns_its_optimum_not_its_warm_start() {
    // The reduced set cover of a `completion-scp` plan on procedural pool 2: no reduction
    // applies, the greedy cover has 7 views, the minimum 6 (= the LP bound). HiGHS, warm-started
    // from the greedy cover, reports objective 6 but returns the 7 start views; taking those
    // for the optimum made `--method ilp` report d_plan 7 (`objview_difficulty::warm`).
    let lists: Vec<Vec<usize>> = vec![
        vec![4, 13],
        vec![6, 10, 13],
        vec![3, 5],
        vec![5, 10],
        vec![2, 12],
        vec![8, 9],
        vec![1, 3, 11],
        vec![0, 6, 7],
        vec![5, 12],
        vec![2, 10],
        vec![9, 11],
        vec![1, 9],
        vec![8, 12],
        vec![0, 13],
        vec![4, 7],
    ];
    let views = bitsets(&lists);
    let oracle = CoverInstance::from_bitsets(&views, 1).unwrap().brute_force().unwrap();
    assert_eq!(oracle.len(), 6);
    for method in [CoverMethod::Ilp, CoverMethod::Auto] {
        let r = solve_min_cover(&views, &CoverSettings { method, ..settings(1) }).unwrap();
        check_consistent(&views, 1, &r);
        assert_eq!(r.greedy_size, 7);
        assert_eq!((r.status.clone(), r.d_plan), (CoverStatus::Optimal, Some(6)), "{method}: {r:?}");
    }
}

#[test]
fn empty_input_and_everything_forced() {
    let r = solve_min_cover(&[], &settings(1)).unwrap();
    assert_eq!((r.universe, r.d_plan, r.best_size), (0, Some(0), 0));
    assert_eq!(r.status, CoverStatus::Optimal);

    // Disjoint views: every view is forced, the reductions alone prove optimality.
    let views = bitsets(&[vec![0, 1], vec![2], vec![3, 4, 5]]);
    let r = solve_min_cover(&views, &settings(1)).unwrap();
    check_consistent(&views, 1, &r);
    assert_eq!(r.d_plan, Some(3));
    assert_eq!(r.reduction.forced_views, vec![0, 1, 2]);
    assert_eq!(r.solver_seconds, 0.0);
}

#[test]
fn invalid_settings_are_rejected() {
    let views = bitsets(&[vec![0, 1]]);
    let bad = CoverSettings { time_limit_s: 0.0, ..CoverSettings::default() };
    assert!(matches!(solve_min_cover(&views, &bad), Err(DifficultyError::InvalidSetting { .. })));
    let bad = CoverSettings { time_limit_s: f64::NAN, ..CoverSettings::default() };
    assert!(matches!(solve_min_cover(&views, &bad), Err(DifficultyError::InvalidSetting { .. })));
    assert_eq!(solve_min_cover(&views, &settings(0)), Err(DifficultyError::ZeroMinViews));
    let bad = CoverSettings { threads: 0, ..CoverSettings::default() };
    assert!(matches!(solve_min_cover(&views, &bad), Err(DifficultyError::InvalidSetting { .. })));
}

#[test]
fn serializes_status_as_lowercase_strings() {
    let views = bitsets(&[vec![0, 1], vec![1, 2]]);
    let r = solve_min_cover(&views, &settings(1)).unwrap();
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["status"], "optimal");
    assert_eq!(json["d_plan"], 2);
    assert_eq!(json["settings"]["time_limit_s"], 300.0);
    assert_eq!(serde_json::to_value(CoverStatus::TimeLimit).unwrap(), "time_limit");
    assert_eq!(serde_json::to_value(CoverStatus::Infeasible).unwrap(), "infeasible");
    let back: CoverResult = serde_json::from_value(json).unwrap();
    assert_eq!(back.best_cover, r.best_cover);
}

#[test]
fn spherical_cap_instance_128_views_solves_to_optimality() {
    // θ = 60°: a view sees a broad patch of a convex object, as tammes-128 views do.
    let views = caps::cap_instance(30_000, 60.0, 7);
    let r = solve_min_cover(&views, &settings(1)).unwrap();
    check_consistent(&views, 1, &r);
    // The ILP alone proves the same optimum.
    let ilp = solve_min_cover(&views, &CoverSettings { method: CoverMethod::Ilp, ..settings(1) }).unwrap();
    check_consistent(&views, 1, &ilp);
    assert_eq!((ilp.status.clone(), ilp.d_plan), (CoverStatus::Optimal, r.d_plan));
    assert_eq!(ilp.proven_by, "ilp");
    assert_eq!(r.status, CoverStatus::Optimal, "{r:?}");
    assert!(r.universe > 29_000, "universe {}", r.universe);
    assert!(r.d_plan.unwrap() < r.greedy_size, "greedy {} is optimal here?", r.greedy_size);
    assert!(r.seconds < 60.0, "took {} s", r.seconds);
    // Deterministic: the same input gives the same chosen views.
    let again = solve_min_cover(&views, &settings(1)).unwrap();
    assert_eq!(again.best_cover, r.best_cover);
    assert_eq!(again.d_plan, r.d_plan);
}

/// A random instance without geometric structure: `n_views` views, every one of `n_elements`
/// elements seen by `per_element` random views (with repeats).
fn random_instance(seed: u64, n_elements: usize, n_views: usize, per_element: usize) -> Vec<Vec<u64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut views = vec![vec![0u64; n_elements / 64 + 1]; n_views];
    for e in 0..n_elements {
        for _ in 0..per_element {
            let v = rng.gen_range(0..n_views);
            views[v][e / 64] |= 1 << (e % 64);
        }
    }
    views
}

/// 128 views, every element seen by 6 random views: its LP gap makes branch and bound work for
/// a long time.
fn hard_instance() -> Vec<Vec<u64>> {
    random_instance(42, 4000, 128, 6)
}

#[test]
fn time_limit_is_reported_as_such_never_as_an_optimum() {
    let views = hard_instance();
    let tiny = CoverSettings { time_limit_s: 1e-3, ..CoverSettings::default() };
    let r = solve_min_cover(&views, &tiny).unwrap();
    check_consistent(&views, 1, &r);
    assert_eq!(r.status, CoverStatus::TimeLimit, "{r:?}");
    assert_eq!(r.d_plan, None);
    assert!(r.best_size <= r.greedy_size);
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["status"], "time_limit");
    assert!(json["d_plan"].is_null());
}

#[test]
fn time_limit_during_branch_and_bound_keeps_incumbent_and_bound() {
    let views = hard_instance();
    let short = CoverSettings { time_limit_s: 1.0, ..CoverSettings::default() };
    let r = solve_min_cover(&views, &short).unwrap();
    check_consistent(&views, 1, &r);
    assert!(r.lp_solved, "the LP relaxation takes far less than 1 s");
    assert!(r.seconds < 5.0, "time limit not honoured: {} s", r.seconds);
    if r.status == CoverStatus::TimeLimit {
        assert_eq!(r.d_plan, None);
        assert!(r.lower_bound < r.best_size, "a closed gap would have been reported optimal");
    } else {
        assert_eq!(r.status, CoverStatus::Optimal, "{r:?}");
    }
}

#[test]
fn concurrent_solves_give_the_serial_results() {
    // HiGHS runs on several threads at once (no process-wide lock; see the `ilp` module docs):
    // each solve's LP and ILP, from 4 threads at a time and in several rounds, must give exactly
    // what the same solve gives alone.
    let ilp = CoverSettings { method: CoverMethod::Ilp, ..CoverSettings::default() };
    // Every element seen by 3 of 24 views: a little branch and bound each.
    let instances: Vec<Vec<Vec<u64>>> = (0..6).map(|s| random_instance(1000 + s, 200, 24, 3)).collect();
    let key = |r: &CoverResult| {
        (r.status.clone(), r.d_plan, r.best_cover.clone(), r.lower_bound, r.proven_by.clone())
    };
    let serial: Vec<_> = instances.iter().map(|v| key(&solve_min_cover(v, &ilp).unwrap())).collect();
    for (v, s) in instances.iter().zip(&serial) {
        assert_eq!(s.0, CoverStatus::Optimal, "instance solved to optimality alone");
        assert_eq!(s.4, "ilp");
        check_consistent(v, 1, &solve_min_cover(v, &ilp).unwrap());
    }
    for round in 0..3 {
        let results: Vec<Vec<_>> = std::thread::scope(|sc| {
            let handles: Vec<_> = (0..4)
                .map(|t| {
                    let (instances, ilp) = (&instances, &ilp);
                    sc.spawn(move || {
                        // Each thread walks the instances from its own offset, so different
                        // instances overlap.
                        (0..instances.len())
                            .map(|i| {
                                let j = (i + 2 * t + round) % instances.len();
                                (j, key(&solve_min_cover(&instances[j], ilp).unwrap()))
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for per_thread in results {
            for (j, k) in per_thread {
                assert_eq!(k, serial[j], "round {round}, instance {j}");
            }
        }
    }
}
