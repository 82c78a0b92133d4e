//! Per-view O(v) timing on a ~100k-triangle synthetic object (a level-6 icosphere plus a
//! torus, 100 352 triangles) with a ~300k-point area-weighted surface cloud, 128 view
//! directions (Fibonacci lattice, radius 3), one thread.
//!
//! `cargo run --release -p objview-voxel --example bench_visibility [repeats] [mesh_views]`

use objview_geom::{Mesh, Pose};
use objview_voxel::bench::bench_visibility;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

fn icosphere(level: u32, radius: f64, centre: [f64; 3]) -> Mesh {
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
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<[f64; 3]>| -> u32 {
            let key = (a.min(b), a.max(b));
            *mid.entry(key).or_insert_with(|| {
                let (p, q) = (pos[a as usize], pos[b as usize]);
                pos.push([(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0, (p[2] + q[2]) / 2.0]);
                (pos.len() - 1) as u32
            })
        };
        for [a, b, c] in tris {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    for p in &mut pos {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        *p = std::array::from_fn(|k| centre[k] + radius * p[k] / n);
    }
    Mesh::new(pos, tris)
}

/// Torus around the y axis through `centre`, `nu × nv` quads.
fn torus(big: f64, small: f64, nu: u32, nv: u32, centre: [f64; 3]) -> Mesh {
    let mut pos = Vec::new();
    for i in 0..nu {
        let u = i as f64 / nu as f64 * std::f64::consts::TAU;
        for j in 0..nv {
            let v = j as f64 / nv as f64 * std::f64::consts::TAU;
            let rr = big + small * v.cos();
            pos.push([centre[0] + rr * u.cos(), centre[1] + small * v.sin(), centre[2] + rr * u.sin()]);
        }
    }
    let id = |i: u32, j: u32| (i % nu) * nv + (j % nv);
    let mut tris = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Mesh::new(pos, tris)
}

fn merge(a: Mesh, b: Mesh) -> Mesh {
    let off = a.positions.len() as u32;
    let mut pos = a.positions;
    pos.extend(b.positions);
    let mut tris = a.triangles;
    tris.extend(b.triangles.iter().map(|t| [t[0] + off, t[1] + off, t[2] + off]));
    Mesh::new(pos, tris)
}

/// Area-weighted uniform samples on the triangles.
fn sample(mesh: &Mesh, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut cdf = Vec::with_capacity(mesh.num_triangles());
    let mut acc = 0.0;
    for t in 0..mesh.num_triangles() {
        let [a, b, c] = mesh.triangle(t);
        let e1: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
        let e2: [f64; 3] = std::array::from_fn(|k| c[k] - a[k]);
        let x = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        acc += 0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
        cdf.push(acc);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let s = rng.gen_range(0.0..acc);
            let t = cdf.partition_point(|&c| c < s).min(cdf.len() - 1);
            let [a, b, c] = mesh.triangle(t);
            let (mut u, mut v): (f64, f64) = (rng.gen(), rng.gen());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            std::array::from_fn(|k| a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k]))
        })
        .collect()
}

fn fibonacci(n: usize) -> Vec<[f64; 3]> {
    let ga = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let th = ga * i as f64;
            [r * th.cos(), r * th.sin(), z]
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let repeats: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(3);
    let mesh_views: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(8);
    let mesh = merge(icosphere(6, 0.55, [-0.35, 0.0, 0.0]), torus(0.3, 0.12, 128, 72, [0.5, 0.0, 0.0]));
    let cloud = sample(&mesh, 300_000, 7);
    let poses: Vec<Pose> = fibonacci(128).into_iter().map(|d| Pose::from_direction(d, 3.0)).collect();
    println!(
        "mesh: {} triangles, cloud: {} points, {} views",
        mesh.num_triangles(),
        cloud.len(),
        poses.len()
    );
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| bench_visibility(&mesh, &cloud, 0.02, &poses, repeats, mesh_views))
        .expect("bench");
    println!("{b:#?}");
    // S_gt build time at the SPEC's largest cloud size, on the caller's threads.
    let big = sample(&mesh, 2_000_000, 8);
    let mut t = Vec::new();
    for _ in 0..5 {
        let s = std::time::Instant::now();
        let set = objview_voxel::VoxelSet::from_points(&big, 0.02).expect("set");
        t.push(s.elapsed().as_secs_f64() * 1e3);
        assert!(!set.is_empty());
    }
    t.sort_by(|a, b| a.total_cmp(b));
    println!(
        "2M-point S_gt build: median {:.2} ms, min {:.2} ms ({} threads)",
        t[2],
        t[0],
        rayon::current_num_threads()
    );
}
