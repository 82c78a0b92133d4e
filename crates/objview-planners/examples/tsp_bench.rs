//! The exact open-path solver with and without its LP stage on the same instances (shell
//! distances of random points on the radius-3 sphere, as a plan's views are): median time per
//! node count, the ratio, and a check that both return the same length.
//! `cargo run --profile ci -p objview-planners --example tsp_bench [-- N… [SEEDS]]`
//! (defaults: 51 65 97 121 129, 5 seeds). One thread (HiGHS runs on one).

use objview_episode::path::shell_distance;
use objview_planners::tsp::{shortest_open_path_with_lp_stage_from, TspSettings, LP_CUTS_MIN_NODES};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn instance(n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pts = Vec::with_capacity(n);
    while pts.len() < n {
        let v: [f64; 3] = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
        let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if r > 1e-3 && r <= 1.0 {
            pts.push(v.map(|x| 3.0 * x / r));
        }
    }
    let mut d = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            d[i][j] = shell_distance(pts[i], pts[j]);
            d[j][i] = d[i][j];
        }
    }
    d
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    }
}

fn main() {
    let args: Vec<usize> =
        std::env::args().skip(1).map(|a| a.parse().expect("node counts, then seeds")).collect();
    let (ns, seeds) = match args.len() {
        0 => (vec![51, 65, 97, 121, 129], 5),
        1 => (args.clone(), 5),
        _ => (args[..args.len() - 1].to_vec(), args[args.len() - 1]),
    };
    let settings = TspSettings::default();
    println!(
        "exact open path, {seeds} instances per size (LP stage from {LP_CUTS_MIN_NODES} nodes by default)"
    );
    for n in ns {
        let (mut plain, mut staged) = (Vec::new(), Vec::new());
        let mut solves = (0, 0, 0);
        for seed in 0..seeds as u64 {
            let d = instance(n, seed);
            let a = shortest_open_path_with_lp_stage_from(&d, 0, &settings, usize::MAX).expect("solve");
            let b = shortest_open_path_with_lp_stage_from(&d, 0, &settings, 0).expect("solve");
            assert!(a.optimal && b.optimal, "n {n} seed {seed}: not proven");
            let tol = 1e-9 * a.length.max(1.0);
            assert!((a.length - b.length).abs() <= tol, "n {n} seed {seed}: {} vs {}", a.length, b.length);
            plain.push(a.seconds);
            staged.push(b.seconds);
            solves.0 += a.ilp_solves;
            solves.1 += b.ilp_solves;
            solves.2 += b.lp_solves;
        }
        let (mp, ms) = (median(plain.clone()), median(staged.clone()));
        let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
        println!(
            "n {n:>3}: integer loop alone median {:.3} s (max {:.3}, {} HiGHS MIP solves); with the LP stage median {:.3} s (max {:.3}, {} MIP + {} LP solves); ratio {:.2}x; same lengths",
            mp,
            max(&plain),
            solves.0,
            ms,
            max(&staged),
            solves.1,
            solves.2,
            mp / ms
        );
    }
}
