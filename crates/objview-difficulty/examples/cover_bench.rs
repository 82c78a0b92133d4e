//! Benchmark of the exact set-cover ILP (`solve_min_cover`) on the synthetic spherical-cap
//! visibility instance of the tests: 128 Fibonacci-lattice views, random points on the sphere,
//! a view covering the points within θ of its direction. Prints the median wall-clock time.
//!
//! Usage: `cargo run --release -p objview-difficulty --example cover_bench -- [points] [theta_deg]
//! [repetitions] [seed]` (defaults: 30000 points, θ = 60°, 5 repetitions, seed 7).

#[path = "../tests/common/caps.rs"]
mod caps;

use std::time::Instant;

use objview_difficulty::{solve_min_cover, CoverSettings};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: f64| args.get(i).map_or(default, |s| s.parse().expect("numeric argument"));
    let points = arg(0, 30_000.0) as usize;
    let theta = arg(1, 60.0);
    let reps = (arg(2, 5.0) as usize).max(1);
    let seed = arg(3, 7.0) as u64;

    let t = Instant::now();
    let views = caps::cap_instance(points, theta, seed);
    println!(
        "instance: 128 views, {points} points, theta = {theta} deg, seed {seed} (built in {:.3} s)",
        t.elapsed().as_secs_f64()
    );

    let settings = CoverSettings::default();
    let mut times = Vec::with_capacity(reps);
    let mut first = None;
    for rep in 0..reps {
        let r = solve_min_cover(&views, &settings).expect("valid settings");
        println!(
            "rep {rep}: status {:?}, d_plan {:?}, best {}, lower bound {}, LP {:.3}, greedy {}, \
             reduced {}x{} (forced {}), {:.4} s (solver {:.4} s)",
            r.status,
            r.d_plan,
            r.best_size,
            r.lower_bound,
            r.lp_bound,
            r.greedy_size,
            r.reduction.reduced_views,
            r.reduction.reduced_elements,
            r.reduction.forced_views.len(),
            r.seconds,
            r.solver_seconds
        );
        times.push(r.seconds);
        match &first {
            None => first = Some(r.best_cover.clone()),
            Some(cover) => assert_eq!(cover, &r.best_cover, "non-deterministic cover"),
        }
    }
    times.sort_by(f64::total_cmp);
    println!("chosen views (identical in every run): {:?}", first.unwrap_or_default());
    println!("median solve time over {reps} runs: {:.4} s", times[reps / 2]);
}
