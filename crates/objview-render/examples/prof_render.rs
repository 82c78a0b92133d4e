//! Profiling driver: renders the built-in torus of N triangles (default 100 000) from 16
//! spiral poses, single-threaded, `iters` rounds: `prof_render [N] [iters]`. Prints the
//! minimum and median per-frame time (ms) to stderr. Meant for `perf record`.

use objview_render::bench::{bench_mesh, spiral_poses};
use objview_render::{Camera, Frame, Intrinsics, Renderer};
use std::time::Instant;

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).map(|s| s.parse().expect("number")).collect();
    let n = a.first().copied().unwrap_or(100_000);
    let iters = a.get(1).copied().unwrap_or(50);
    let mesh = bench_mesh(n);
    let cams: Vec<Camera> =
        spiral_poses(16, 3.0).into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect();
    let mut r = Renderer::new();
    let mut f = Frame::empty(cams[0]);
    let mut ms = Vec::new();
    let mut hits = 0;
    for _ in 0..iters {
        for c in &cams {
            let t = Instant::now();
            r.render_into(&mesh, c, &mut f);
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            hits += f.num_hits();
        }
    }
    ms.sort_by(f64::total_cmp);
    eprintln!("{n} tris: min {:.3} ms, median {:.3} ms ({hits} hits)", ms[0], ms[ms.len() / 2]);
}
