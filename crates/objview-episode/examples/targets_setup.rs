//! The target indexes a scene builds once (`Targets::new` for the exact distances of the
//! checkpoint CD, `Coverage::new` for SC/NSC), timed on points sampled on the built-in mug at
//! ~100k triangles (unit-normalized), for A/B runs of their layout pass:
//!
//! `cargo run --profile ci -p objview-episode --example targets_setup [-- POINTS [REPEATS]]`
//!
//! (defaults 300000 and 7; the mug's observable reference has 514,233 points, the SPEC's
//! hollow-sphere ground truth 1.2M). Prints the median time of each and a checksum of the
//! points in index order (equal checksums: the same order).

use std::path::Path;
use std::time::Instant;

use objview_episode::chamfer::Targets;
use objview_episode::coverage::Coverage;
use objview_episode::grid::Domain;
use objview_geom::normalize::{normalize, Normalization};

fn main() {
    let mut args = std::env::args().skip(1).map(|s| s.parse::<usize>().expect("a count"));
    let n = args.next().unwrap_or(300_000);
    let repeats = args.next().unwrap_or(7).max(1);
    let mesh = objview_geom::synth::build_with_triangles("mug", 100_000);
    let (mesh, _) = normalize(mesh, Normalization::Unit, Path::new("mug")).expect("normalize");
    let (lo, hi) = mesh.bounds().expect("a non-empty mesh");
    let domain = Domain::covering(0.005, lo, hi, 0.1);
    let pts = objview_geom::cloud::sample_surface(&mesh, n, 7);
    let (mut targets, mut coverage) = (Vec::new(), Vec::new());
    let mut checksum = 0.0;
    for _ in 0..repeats {
        let t = Instant::now();
        let a = Targets::new(domain.clone(), &pts, f64::INFINITY).expect("inside the domain");
        targets.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let c = Coverage::new(domain.clone(), &pts, &[0.005, 0.01, 0.02]).expect("inside the domain");
        coverage.push(t.elapsed().as_secs_f64() * 1e3);
        checksum = a
            .points()
            .iter()
            .zip(c.points())
            .enumerate()
            .map(|(i, (p, q))| (i % 7) as f64 * p[0] + q[1])
            .sum();
    }
    targets.sort_by(f64::total_cmp);
    coverage.sort_by(f64::total_cmp);
    println!(
        "{n} points: Targets::new median {:.2} ms, Coverage::new median {:.2} ms ({repeats} repeats), checksum {checksum}",
        targets[repeats / 2],
        coverage[repeats / 2]
    );
}
