//! `completion-nbv`'s gain step alone: hidden point removal of one score-point set from every
//! tammes-360 candidate (radius 3), one thread, for timing and instruction counting
//! (`valgrind --tool=callgrind`) of [`objview_planners::hybrid::hpr`].
//!
//! `cargo run --release -p objview-planners --example hpr_gains [-- POINTS [REPEATS]]`
//!
//! The score points are 1/32 voxel centres of a seeded torus-like shell (like the predicted −
//! observed voxels a step scores), about POINTS of them (default 3,000, the mug's mean). It
//! prints the median time of a whole gain step over REPEATS (default 5) and a checksum of the
//! gains, which must not change when the hull code changes.

use std::collections::BTreeSet;
use std::time::Instant;

use objview_planners::hybrid::hpr::Hpr;
use objview_views::ViewSet;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn score_points(target: usize) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut keys = BTreeSet::new();
    while keys.len() < target {
        let (a, b) = (rng.gen_range(0.0..std::f64::consts::TAU), rng.gen_range(0.0..std::f64::consts::TAU));
        // Two thirds of a torus tube (a partly observed object's unseen rest).
        if b > 4.0 {
            continue;
        }
        let p = [(0.55 + 0.3 * b.cos()) * a.cos(), (0.55 + 0.3 * b.cos()) * a.sin(), 0.3 * b.sin()];
        keys.insert(p.map(|x| ((x + 1.0) / 0.03125).floor() as i64));
    }
    keys.into_iter().map(|k| k.map(|x| (x as f64 + 0.5) * 0.03125 - 1.0)).collect()
}

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3000);
    let repeats: usize = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(5);
    let points = score_points(n);
    let cameras: Vec<[f64; 3]> =
        ViewSet::resolve("tammes-360").expect("tammes-360").poses(3.0).iter().map(|p| p.center).collect();
    let mut ws = Hpr::default();
    let mut times = Vec::new();
    let mut checksum = 0u64;
    for _ in 0..repeats {
        let t = Instant::now();
        let gains: Vec<usize> = cameras.iter().map(|&c| ws.count(&points, c)).collect();
        times.push(t.elapsed().as_secs_f64());
        checksum = gains
            .iter()
            .fold(0xcbf2_9ce4_8422_2325u64, |h, &g| (h ^ g as u64).wrapping_mul(0x1000_0000_01b3));
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{} score points, {} candidates: median {:.1} ms per gain step ({:.3} ms per hull), gains checksum {checksum:016x}",
        points.len(),
        cameras.len(),
        times[times.len() / 2] * 1e3,
        times[times.len() / 2] * 1e3 / cameras.len() as f64
    );
}
