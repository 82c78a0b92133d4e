//! Synthetic visibility structures for the set-cover ILP tests and the cover benchmark: elements
//! are random points on the unit sphere, views are 128 well-spread directions (a Fibonacci
//! lattice, standing in for tammes-128), and a view sees the elements within angle θ of its
//! direction — the shape of the coverage of a convex object seen from a view sphere.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` near-uniformly spread unit directions (Fibonacci lattice).
pub fn fibonacci_directions(n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect()
}

/// `n` uniformly random points on the unit sphere.
pub fn random_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let z: f64 = rng.gen_range(-1.0..1.0);
            let phi: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect()
}

/// Per-view bitsets (bit i of word i/64 = element i): view v sees element i iff the angle between
/// `directions[v]` and `points[i]` is at most `theta_deg`.
pub fn cap_views(directions: &[[f64; 3]], points: &[[f64; 3]], theta_deg: f64) -> Vec<Vec<u64>> {
    let cos_theta = theta_deg.to_radians().cos();
    directions
        .iter()
        .map(|d| {
            let mut set = vec![0u64; points.len().div_ceil(64)];
            for (i, p) in points.iter().enumerate() {
                if d[0] * p[0] + d[1] * p[1] + d[2] * p[2] >= cos_theta {
                    set[i / 64] |= 1 << (i % 64);
                }
            }
            set
        })
        .collect()
}

/// The standard cap instance of the tests and the benchmark: 128 views, `n_points` elements.
pub fn cap_instance(n_points: usize, theta_deg: f64, seed: u64) -> Vec<Vec<u64>> {
    cap_views(&fibonacci_directions(128), &random_points(n_points, seed), theta_deg)
}
