//! Renderer benchmark (`objview bench render`): times the single-thread rasterizer and the
//! parallel one per frame over a set of poses, and provides the procedural test meshes
//! (icosphere, torus) and poses the benchmark and the exactness tests use, so that numbers
//! are reproducible without any asset files.

use crate::{Camera, Frame, Intrinsics, Renderer};
use objview_geom::{Mesh, Pose};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Instant;

/// Per-frame timing statistics of one renderer variant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TimingStats {
    /// Median wall time per frame, milliseconds.
    pub median_ms: f64,
    /// 10th percentile per frame, milliseconds.
    pub p10_ms: f64,
    /// 90th percentile per frame, milliseconds.
    pub p90_ms: f64,
    /// Pixel-centre rays per second at the median, in millions (pixels / median time).
    pub mrays_per_s: f64,
}

/// Result of [`bench_render`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderBenchResult {
    /// Triangles of the benchmarked mesh.
    pub triangles: usize,
    /// Vertex positions of the benchmarked mesh.
    pub vertices: usize,
    /// Image width, pixels (default intrinsics).
    pub width: u32,
    /// Image height, pixels (default intrinsics).
    pub height: u32,
    /// Number of poses; every repeat renders each pose once with each variant.
    pub poses: usize,
    /// Timed passes over all poses (after one untimed warm-up pass).
    pub repeats: usize,
    /// Threads of the rayon pool used by the parallel variant.
    pub threads: usize,
    /// Mean fraction of pixels with a hit.
    pub hit_fraction: f64,
    /// Single-thread [`Renderer::render_into`].
    pub single: TimingStats,
    /// [`Renderer::render_parallel_into`] on the current rayon pool.
    pub parallel: TimingStats,
    /// Whether both variants produced bit-identical frames for every pose.
    pub identical: bool,
}

fn stats(mut ms: Vec<f64>, pixels: usize) -> TimingStats {
    use objview_geom::stats::{median, percentile};
    let median = median(&mut ms); // sorts
    TimingStats {
        median_ms: median,
        p10_ms: percentile(&ms, 0.1),
        p90_ms: percentile(&ms, 0.9),
        mrays_per_s: pixels as f64 / (median * 1e-3) / 1e6,
    }
}

/// Times rendering `mesh` (object frame) from every pose in `poses` (object frame, SPEC §2
/// 7-number poses, default 512×512 intrinsics), `repeats` times each, single-threaded and on
/// all threads, after one warm-up pass. Buffers are reused across frames (as in an episode),
/// so times are per frame of a warm renderer.
pub fn bench_render(mesh: &Mesh, poses: &[Pose], repeats: usize) -> RenderBenchResult {
    let intr = Intrinsics::default();
    let pixels = intr.num_pixels();
    let cams: Vec<Camera> = poses.iter().map(|&p| Camera::new(p, intr)).collect();
    let mut single = Renderer::new();
    let mut par = Renderer::new();
    let mut fa = Frame::empty(Camera::new(Pose::from_direction([1.0, 0.0, 0.0], 3.0), intr));
    let mut fb = fa.clone();
    let mut identical = true;
    let mut hits = 0usize;
    for cam in &cams {
        single.render_into(mesh, cam, &mut fa);
        par.render_parallel_into(mesh, cam, &mut fb);
        identical &= fa.depth.iter().map(|x| x.to_bits()).eq(fb.depth.iter().map(|x| x.to_bits()))
            && fa.triangle == fb.triangle;
        hits += fa.num_hits();
    }
    let (mut ts, mut tp) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        for cam in &cams {
            let t0 = Instant::now();
            single.render_into(mesh, cam, &mut fa);
            ts.push(t0.elapsed().as_secs_f64() * 1e3);
            let t0 = Instant::now();
            par.render_parallel_into(mesh, cam, &mut fb);
            tp.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    RenderBenchResult {
        triangles: mesh.num_triangles(),
        vertices: mesh.positions.len(),
        width: intr.width,
        height: intr.height,
        poses: poses.len(),
        repeats,
        threads: rayon::current_num_threads(),
        hit_fraction: hits as f64 / (pixels * cams.len().max(1)) as f64,
        single: stats(ts, pixels),
        parallel: stats(tp, pixels),
        identical,
    }
}

/// `n` poses looking at the origin from radius `radius`, directions on a Fibonacci spiral
/// (object frame, roll 0). Deterministic.
pub fn spiral_poses(n: usize, radius: f64) -> Vec<Pose> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (i as f64 + 0.5) * 2.0 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            Pose::from_direction([r * a.cos(), r * a.sin(), z], radius)
        })
        .collect()
}

/// The unit icosphere: the icosahedron with every triangle split into 4, `subdiv` times,
/// vertices pushed onto the unit sphere; 20·4^subdiv triangles, consistently wound outward.
pub fn icosphere(subdiv: u32) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let unit = |p: [f64; 3]| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / n, p[1] / n, p[2] / n]
    };
    for p in &mut pos {
        *p = unit(*p);
    }
    for _ in 0..subdiv {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        for &[a, b, c] in &tris {
            let mut m = |i: u32, j: u32| {
                *mid.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    let (p, q) = (pos[i as usize], pos[j as usize]);
                    pos.push(unit([p[0] + q[0], p[1] + q[1], p[2] + q[2]]));
                    pos.len() as u32 - 1
                })
            };
            let (ab, bc, ca) = (m(a, b), m(b, c), m(c, a));
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    Mesh::new(pos, tris)
}

/// A torus around the z axis with tube-centre radius `big_r` and tube radius `small_r`,
/// `major × minor` quads split into 2·major·minor triangles (a closed mesh).
pub fn torus(major: usize, minor: usize, big_r: f64, small_r: f64) -> Mesh {
    let tau = std::f64::consts::TAU;
    let mut pos = Vec::with_capacity(major * minor);
    for i in 0..major {
        let a = tau * i as f64 / major as f64;
        for j in 0..minor {
            let b = tau * j as f64 / minor as f64;
            let r = big_r + small_r * b.cos();
            pos.push([r * a.cos(), r * a.sin(), small_r * b.sin()]);
        }
    }
    let id = |i: usize, j: usize| ((i % major) * minor + (j % minor)) as u32;
    let mut tris = Vec::with_capacity(2 * major * minor);
    for i in 0..major {
        for j in 0..minor {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    Mesh::new(pos, tris)
}

/// The built-in benchmark mesh with about `triangles` triangles: a torus (R = 0.7, r = 0.3,
/// so it fits the unit ball) with a 2:1 segment ratio. 10 000 and 1 000 000 are exact;
/// 100 000 gives 99 856.
pub fn bench_mesh(triangles: usize) -> Mesh {
    let minor = ((triangles as f64 / 4.0).sqrt().round() as usize).max(3);
    torus(2 * minor, minor, 0.7, 0.3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mesh_sizes() {
        assert_eq!(icosphere(2).num_triangles(), 320);
        assert_eq!(icosphere(2).positions.len(), 162);
        assert_eq!(bench_mesh(10_000).num_triangles(), 10_000);
        assert_eq!(bench_mesh(100_000).num_triangles(), 99_856);
        assert!((bench_mesh(10_000).max_radius() - 1.0).abs() < 1e-12);
        // Icosphere area approaches 4π from below.
        let a = icosphere(4).surface_area();
        assert!(a < 4.0 * std::f64::consts::PI && a > 0.99 * 4.0 * std::f64::consts::PI);
    }

    #[test]
    fn percentiles() {
        let s = stats((1..=10).map(|x| x as f64).collect(), 1_000_000);
        assert_eq!((s.median_ms, s.p10_ms, s.p90_ms), (5.5, 1.0, 9.0));
        assert!((s.mrays_per_s - 1.0 / 5.5e-3).abs() < 1e-9);
    }

    #[test]
    fn bench_runs_and_variants_agree() {
        let r = bench_render(&icosphere(3), &spiral_poses(3, 3.0), 1);
        assert!(r.identical);
        assert_eq!((r.poses, r.triangles), (3, 1280));
        assert!(r.hit_fraction > 0.3 && r.hit_fraction < 0.6, "{}", r.hit_fraction);
        assert!(r.single.median_ms > 0.0);
    }
}
