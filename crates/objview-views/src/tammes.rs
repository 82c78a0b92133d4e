//! Deterministic Tammes optimizer: N points on the unit sphere maximizing the minimum pairwise
//! angle (SPEC §3 view sets other than the two official ones are this optimizer's output).
//!
//! Recipe (all stages are deterministic functions of `(n, seed, effort)`; parallel multi-starts
//! are reduced in a fixed order, so the result does not depend on the thread count):
//! 1. Starts: a Fibonacci spiral, icosadeltahedral (Goldberg–Coxeter) grids when
//!    `n = 10(h²+hk+k²)+2`, seeded random starts with tetrahedral, octahedral or icosahedral
//!    rotational symmetry (random generic orbits plus special orbits — vertices, edge midpoints,
//!    face centres — whenever `n` decomposes that way; several records, e.g. N = 200, are
//!    symmetric and hard to reach otherwise), and seeded uniform random points (ChaCha8, one
//!    stream per start).
//! 2. Riesz s-energy descent with s = 6, 12, 24, 48, 96, 192 (L-BFGS on the sphere; the energy
//!    is scaled by the stage's starting minimum distance so large s does not overflow, and pairs
//!    whose contribution is below ~1e-12 of the closest one are cut off with a z-sorted sweep).
//! 3. Max–min refinement by dynamic thresholding: for a target angle θ slightly above the best
//!    minimum so far, minimize the overlap penalty Σ max(0, cos θᵢⱼ − cos θ)²; if the
//!    minimizer's true minimum angle improves it is kept, otherwise the increment is halved
//!    (down to 1e-9 relative). This spreads the slack over all near-contact pairs and converges
//!    to a local max–min optimum.
//! 4. Basin hopping on the best configuration: random tangent perturbations followed by step 3,
//!    accepted only when the minimum angle improves.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::viewset::{min_pairwise_angle_deg, normalize, ViewSet};

/// Optimizer version, written into generated file headers.
pub const OPTIMIZER_VERSION: &str = "objview-tammes 1";

/// Seed used for the shipped view sets.
pub const DEFAULT_SEED: u64 = 20_260_523;

/// How much work the optimizer does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effort {
    /// A few starts and no basin hopping: for tests and previews (seconds).
    Quick,
    /// Many starts and basin hopping: what the shipped sets were generated with.
    Full,
}

/// Per-effort budget.
#[derive(Debug, Clone, Copy)]
struct Budget {
    random_starts: usize,
    symmetric_starts: usize,
    riesz_iters: usize,
    hop_batches: usize,
}

/// Basin-hopping perturbations tried per batch (fixed, so results do not depend on threads).
const HOP_BATCH: usize = 4;

impl Effort {
    fn budget(self, n: usize) -> Budget {
        match self {
            Effort::Quick => {
                Budget { random_starts: 2, symmetric_starts: 0, riesz_iters: 300, hop_batches: 0 }
            }
            Effort::Full => Budget {
                random_starts: if n <= 300 { 24 } else { 6 },
                symmetric_starts: if n <= 64 { 2 } else { 4 },
                riesz_iters: 2000,
                hop_batches: if n <= 64 { 30 } else { 60 },
            },
        }
    }
}

/// Best-known Tammes angles (Lai et al. 2023), `N angle_deg` per line.
const BEST_KNOWN: &str = include_str!("../../../data/viewsets/tammes_best_known_deg.txt");

/// The best-known minimum angle (degrees) for `n` points, where the embedded table has one.
pub fn best_known_deg(n: usize) -> Option<f64> {
    BEST_KNOWN.lines().find_map(|l| {
        let l = l.split('#').next()?.trim();
        let mut it = l.split_whitespace();
        let k: usize = it.next()?.parse().ok()?;
        let v: f64 = it.next()?.parse().ok()?;
        (k == n).then_some(v)
    })
}

/// The `#` header lines written above a generated set: what made it (generator, version,
/// seed), its minimum angle and the best-known value with their ratio.
pub fn file_header(vs: &ViewSet, seed: u64) -> Vec<String> {
    let n = vs.len();
    let a = vs.min_angle_deg().unwrap_or(180.0);
    vec![
        format!("tammes-{n}: {n} unit view directions approximately solving the Tammes problem"),
        format!("generator: {OPTIMIZER_VERSION} (objview_views::tammes::generate), seed {seed}"),
        format!("min_angle_deg: {a:.9}"),
        match best_known_deg(n) {
            Some(b) => format!("best_known_deg: {b:.9} (ratio {:.6})", a / b),
            None => "best_known_deg: unknown".to_string(),
        },
    ]
}

/// Runs the optimizer with [`Effort::Full`]: the way the shipped `tammes-N` files were made.
pub fn generate(n: usize, seed: u64) -> ViewSet {
    optimize(n, seed, Effort::Full)
}

/// Optimizes `n` directions (`n ≥ 1`) for the largest minimum pairwise angle.
///
/// Deterministic for `(n, seed, effort)` regardless of the number of rayon threads.
pub fn optimize(n: usize, seed: u64, effort: Effort) -> ViewSet {
    let name = format!("tammes-{n}");
    match n {
        0 => return ViewSet { name, dirs: Vec::new() },
        1 => return ViewSet { name, dirs: vec![[0.0, 0.0, 1.0]] },
        2 => return ViewSet { name, dirs: vec![[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] },
        _ => {}
    }
    let budget = effort.budget(n);
    let mut starts: Vec<Vec<f64>> = vec![flatten(&fibonacci(n))];
    for g in icosadeltahedral(n) {
        starts.push(flatten(&g));
    }
    for (g, group) in symmetry_groups().iter().enumerate() {
        for (d, orbits) in decompositions(n, group).iter().enumerate() {
            for k in 0..budget.symmetric_starts {
                let stream = 10_000 + (g as u64) * 1000 + (d as u64) * 100 + k as u64;
                let mut rng = stream_rng(seed, n, stream);
                starts.push(flatten(&symmetric_points(n, group, orbits, &mut rng)));
            }
        }
    }
    for k in 0..budget.random_starts {
        let mut rng = stream_rng(seed, n, 1 + k as u64);
        starts.push(flatten(&random_points(n, &mut rng)));
    }
    let results: Vec<(f64, Vec<f64>)> = starts
        .into_par_iter()
        .map(|x0| {
            let mut x = x0;
            riesz_schedule(&mut x, budget.riesz_iters);
            let a = refine(&mut x);
            (a, x)
        })
        .collect();
    let (mut best_a, mut best) = pick_best(results).expect("at least one start");
    for batch in 0..budget.hop_batches {
        let tries: Vec<(f64, Vec<f64>)> = (0..HOP_BATCH)
            .into_par_iter()
            .map(|t| {
                let idx = (batch * HOP_BATCH + t) as u64;
                let mut rng = stream_rng(seed, n, 1_000_000 + idx);
                let theta = best_a.to_radians();
                let mut x = best.clone();
                // Kicks alternate between global (every point, small) and local (the points
                // within 3θ of a random point, large) perturbations.
                match t % 4 {
                    0 => perturb(&mut x, 0.03 * theta, None, &mut rng),
                    1 => perturb(&mut x, 0.08 * theta, None, &mut rng),
                    2 => perturb(&mut x, 0.5 * theta, Some(3.0 * theta), &mut rng),
                    _ => perturb(&mut x, 0.15 * theta, None, &mut rng),
                }
                // Push the kicked configuration back towards the current best angle first.
                let cos_t = (theta * (1.0 + 1e-3)).cos();
                lbfgs(&mut x, 1000, 0.05 * theta, |y, g| on_sphere(y, g, |p, gp| penalty(p, gp, cos_t)));
                let a = refine(&mut x);
                (a, x)
            })
            .collect();
        let (a, x) = pick_best(tries).expect("non-empty batch");
        if a > best_a {
            best_a = a;
            best = x;
        }
    }
    ViewSet { name, dirs: unflatten(&best) }
}

fn pick_best(results: Vec<(f64, Vec<f64>)>) -> Option<(f64, Vec<f64>)> {
    // Strictly greater keeps the earliest of equal results: a fixed, thread-independent order.
    results.into_iter().fold(None, |acc, (a, x)| match acc {
        Some((ba, bx)) if ba >= a => Some((ba, bx)),
        _ => Some((a, x)),
    })
}

fn stream_rng(seed: u64, n: usize, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (n as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(stream);
    rng
}

fn flatten(p: &[[f64; 3]]) -> Vec<f64> {
    p.iter().flat_map(|v| v.iter().copied()).collect()
}

fn unflatten(x: &[f64]) -> Vec<[f64; 3]> {
    x.chunks_exact(3)
        .map(|c| normalize([c[0], c[1], c[2]]).expect("optimizer keeps points non-zero"))
        .collect()
}

fn renormalize(x: &mut [f64]) {
    for c in x.chunks_exact_mut(3) {
        let n = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        c.iter_mut().for_each(|v| *v /= n);
    }
}

/// Fibonacci (golden-angle) spiral points.
pub fn fibonacci(n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    (0..n)
        .map(|k| {
            let z = 1.0 - (2.0 * k as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * k as f64;
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect()
}

fn random_points(n: usize, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let v = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
        let r2: f64 = v.iter().map(|a| a * a).sum();
        if r2 > 1e-4 && r2 <= 1.0 {
            out.push(normalize(v).expect("non-zero"));
        }
    }
    out
}

/// Icosadeltahedral point sets (vertices of Goldberg–Coxeter subdivisions of the icosahedron,
/// projected to the sphere) with exactly `n` points, one per `(h, k)`, `h ≥ k ≥ 0`, with
/// `10(h² + hk + k²) + 2 = n`.
pub fn icosadeltahedral(n: usize) -> Vec<Vec<[f64; 3]>> {
    let mut out = Vec::new();
    if n < 12 || (n - 2) % 10 != 0 {
        return out;
    }
    let t = ((n - 2) / 10) as i64;
    let (verts, faces) = icosahedron();
    let mut h = 1_i64;
    while h * h <= t {
        for k in 0..=h {
            if h * h + h * k + k * k != t {
                continue;
            }
            let mut pts: Vec<[f64; 3]> = Vec::new();
            let r = 2 * (h + k);
            for f in &faces {
                let (a, b, c) = (verts[f[0]], verts[f[1]], verts[f[2]]);
                for i in -r..=r {
                    for j in -r..=r {
                        // Barycentric coordinates (×T) of lattice point (i, j) in the triangle
                        // 0, (h, k), (−k, h+k) of the triangular lattice.
                        let l1 = i * (h + k) + k * j;
                        let l2 = h * j - k * i;
                        if l1 < 0 || l2 < 0 || l1 + l2 > t {
                            continue;
                        }
                        let l0 = (t - l1 - l2) as f64;
                        let (l1, l2) = (l1 as f64, l2 as f64);
                        let p = normalize([
                            l0 * a[0] + l1 * b[0] + l2 * c[0],
                            l0 * a[1] + l1 * b[1] + l2 * c[1],
                            l0 * a[2] + l1 * b[2] + l2 * c[2],
                        ])
                        .expect("inside a face, non-zero");
                        let dup = pts.iter().any(|q| {
                            (p[0] - q[0]).abs() < 1e-9
                                && (p[1] - q[1]).abs() < 1e-9
                                && (p[2] - q[2]).abs() < 1e-9
                        });
                        if !dup {
                            pts.push(p);
                        }
                    }
                }
            }
            if pts.len() == n {
                out.push(pts);
            }
        }
        h += 1;
    }
    out
}

/// A finite rotation group: its matrices and its special orbits (vertices, edge midpoints and
/// face centres of the polyhedron it was built from).
struct Group {
    rots: Vec<[[f64; 3]; 3]>,
    special: Vec<Vec<[f64; 3]>>,
}

/// The tetrahedral (12), octahedral (24) and icosahedral (60) rotation groups.
fn symmetry_groups() -> Vec<Group> {
    let tet: Vec<[f64; 3]> = vec![[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]];
    let oct: Vec<[f64; 3]> = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let (ico, _) = icosahedron();
    [tet, oct, ico]
        .into_iter()
        .map(|v| {
            polyhedron_group(&v.into_iter().map(|p| normalize(p).expect("non-zero")).collect::<Vec<_>>())
        })
        .collect()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn frame(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 3] {
    let d = dot3(a, b);
    let u = normalize([b[0] - d * a[0], b[1] - d * a[1], b[2] - d * a[2]]).expect("independent");
    [a, u, cross(a, u)]
}

fn apply(r: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    [dot3(r[0], p), dot3(r[1], p), dot3(r[2], p)]
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (a[0] - b[0]).abs() < 1e-7 && (a[1] - b[1]).abs() < 1e-7 && (a[2] - b[2]).abs() < 1e-7
}

fn orbit(rots: &[[[f64; 3]; 3]], p: [f64; 3]) -> Vec<[f64; 3]> {
    let mut out: Vec<[f64; 3]> = Vec::new();
    for r in rots {
        let q = apply(r, p);
        if !out.iter().any(|o| close(*o, q)) {
            out.push(q);
        }
    }
    out
}

/// The rotation group of a regular polyhedron given by its unit vertices: every rotation maps
/// a vertex and one of its nearest neighbours to another such pair.
fn polyhedron_group(v: &[[f64; 3]]) -> Group {
    let nearest = v[1..].iter().map(|b| dot3(v[0], *b)).fold(f64::NEG_INFINITY, f64::max);
    let is_edge = |a: [f64; 3], b: [f64; 3]| (dot3(a, b) - nearest).abs() < 1e-9;
    let b0 = *v.iter().find(|b| is_edge(v[0], **b)).expect("has a neighbour");
    let f0 = frame(v[0], b0);
    let mut rots = Vec::new();
    for &a in v {
        for &b in v.iter().filter(|b| is_edge(a, **b)) {
            let f1 = frame(a, b);
            // R = F1ᵀ F0 maps the frame of (v0, b0) onto the frame of (a, b).
            let mut r = [[0.0; 3]; 3];
            for (i, row) in r.iter_mut().enumerate() {
                for (j, x) in row.iter_mut().enumerate() {
                    *x = (0..3).map(|k| f1[k][i] * f0[k][j]).sum();
                }
            }
            rots.push(r);
        }
    }
    let mut edges = Vec::new();
    for (i, &a) in v.iter().enumerate() {
        for &b in &v[i + 1..] {
            if is_edge(a, b) {
                edges.push(normalize([a[0] + b[0], a[1] + b[1], a[2] + b[2]]).expect("non-antipodal"));
            }
        }
    }
    // A face centre: the normalized sum of a vertex, a neighbour, and a common neighbour.
    let c0 = *v.iter().find(|c| is_edge(v[0], **c) && is_edge(b0, **c)).expect("triangular faces");
    let face = normalize([v[0][0] + b0[0] + c0[0], v[0][1] + b0[1] + c0[1], v[0][2] + b0[2] + c0[2]])
        .expect("non-zero");
    let special = vec![v.to_vec(), edges, orbit(&rots, face)];
    Group { rots, special }
}

/// Ways to write `n` as (generic orbits) × |G| + a subset of the special orbits, with at least
/// one generic orbit; each way is the list of special orbits used.
fn decompositions(n: usize, g: &Group) -> Vec<Vec<usize>> {
    let order = g.rots.len();
    let mut out = Vec::new();
    for mask in 0..(1usize << g.special.len()) {
        let used: Vec<usize> = (0..g.special.len()).filter(|i| mask & (1 << i) != 0).collect();
        let fixed: usize = used.iter().map(|&i| g.special[i].len()).sum();
        if n > fixed && (n - fixed) % order == 0 {
            out.push(used);
        }
    }
    out
}

/// A start with the symmetry of `g`: the chosen special orbits plus random generic orbits up
/// to `n` points.
fn symmetric_points(n: usize, g: &Group, special: &[usize], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    let mut pts: Vec<[f64; 3]> = special.iter().flat_map(|&i| g.special[i].iter().copied()).collect();
    while pts.len() < n {
        let p = random_points(1, rng)[0];
        let o = orbit(&g.rots, p);
        if o.len() == g.rots.len() && o.iter().all(|q| pts.iter().all(|r| dot3(*q, *r) < 0.999)) {
            pts.extend(o);
        }
    }
    pts
}

/// Unit icosahedron vertices and its 20 faces, each counter-clockwise seen from outside.
fn icosahedron() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let phi = (1.0 + 5.0_f64.sqrt()) / 2.0;
    let mut v = Vec::new();
    for &s1 in &[-1.0, 1.0] {
        for &s2 in &[-1.0, 1.0] {
            v.push([0.0, s1, s2 * phi]);
            v.push([s1, s2 * phi, 0.0]);
            v.push([s2 * phi, 0.0, s1]);
        }
    }
    let d2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>();
    let mut faces = Vec::new();
    for i in 0..12 {
        for j in i + 1..12 {
            for k in j + 1..12 {
                let (a, b, c) = (v[i], v[j], v[k]);
                if (d2(a, b) - 4.0).abs() < 1e-9
                    && (d2(b, c) - 4.0).abs() < 1e-9
                    && (d2(a, c) - 4.0).abs() < 1e-9
                {
                    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                    let nrm = [
                        e1[1] * e2[2] - e1[2] * e2[1],
                        e1[2] * e2[0] - e1[0] * e2[2],
                        e1[0] * e2[1] - e1[1] * e2[0],
                    ];
                    let out = nrm[0] * a[0] + nrm[1] * a[1] + nrm[2] * a[2];
                    faces.push(if out > 0.0 { [i, j, k] } else { [i, k, j] });
                }
            }
        }
    }
    let v = v.into_iter().map(|p| normalize(p).expect("non-zero")).collect();
    (v, faces)
}

/// Random tangent perturbation, each displacement uniform in a disc of radius `size` (radians,
/// small-angle). With `local = Some(r)` only the points within angle `r` of a random point move.
fn perturb(x: &mut [f64], size: f64, local: Option<f64>, rng: &mut ChaCha8Rng) {
    let n = x.len() / 3;
    let center = rng.gen_range(0..n);
    let pc = normalize([x[3 * center], x[3 * center + 1], x[3 * center + 2]]).expect("non-zero");
    for c in x.chunks_exact_mut(3) {
        let p = normalize([c[0], c[1], c[2]]).expect("non-zero");
        let mut d = loop {
            let d = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
            if d.iter().map(|v: &f64| v * v).sum::<f64>() <= 1.0 {
                break d;
            }
        };
        if let Some(r) = local {
            let cosang = p[0] * pc[0] + p[1] * pc[1] + p[2] * pc[2];
            if cosang < r.cos() {
                continue;
            }
        }
        let dp = d[0] * p[0] + d[1] * p[1] + d[2] * p[2];
        d.iter_mut().zip(p.iter()).for_each(|(di, pi)| *di -= dp * pi);
        let q = [p[0] + size * d[0], p[1] + size * d[1], p[2] + size * d[2]];
        let q = normalize(q).unwrap_or(p);
        c.copy_from_slice(&q);
    }
}

/// Indices sorted by z (the sweep order used to prune far pairs).
fn z_order(p: &[[f64; 3]]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..p.len()).collect();
    idx.sort_by(|&a, &b| p[a][2].total_cmp(&p[b][2]).then(a.cmp(&b)));
    idx
}

/// Calls `f(i, j, d²)` for every pair whose chord length is below `cut` (z-sorted sweep).
fn for_close_pairs(p: &[[f64; 3]], cut: f64, mut f: impl FnMut(usize, usize, f64)) {
    let order = z_order(p);
    let cut2 = cut * cut;
    for (a, &i) in order.iter().enumerate() {
        let pi = p[i];
        for &j in &order[a + 1..] {
            let pj = p[j];
            let dz = pj[2] - pi[2];
            if dz >= cut {
                break;
            }
            let dx = pj[0] - pi[0];
            let dy = pj[1] - pi[1];
            let d2 = dx * dx + dy * dy + dz * dz;
            if d2 < cut2 {
                f(i, j, d2);
            }
        }
    }
}

/// Minimum chord length between points of the flat array (normalized copies).
fn min_chord(x: &[f64]) -> f64 {
    let p = unflatten(x);
    let order = z_order(&p);
    let mut best2 = f64::INFINITY;
    for (a, &i) in order.iter().enumerate() {
        for &j in &order[a + 1..] {
            let dz = p[j][2] - p[i][2];
            if dz * dz >= best2 {
                break;
            }
            let dx = p[j][0] - p[i][0];
            let dy = p[j][1] - p[i][1];
            best2 = best2.min(dx * dx + dy * dy + dz * dz);
        }
    }
    best2.sqrt()
}

fn chord_to_deg(c: f64) -> f64 {
    (2.0 * (c / 2.0).min(1.0).asin()).to_degrees()
}

/// Evaluates an objective of the normalized points `p` and maps its gradient (w.r.t. `p`) back
/// to the unnormalized coordinates `x` (projection onto the tangent plane, divided by |x|).
fn on_sphere(x: &[f64], g: &mut [f64], mut obj: impl FnMut(&[[f64; 3]], &mut [[f64; 3]]) -> f64) -> f64 {
    let n = x.len() / 3;
    let mut p = Vec::with_capacity(n);
    let mut norms = Vec::with_capacity(n);
    for c in x.chunks_exact(3) {
        let r = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        norms.push(r);
        p.push([c[0] / r, c[1] / r, c[2] / r]);
    }
    let mut gp = vec![[0.0; 3]; n];
    let f = obj(&p, &mut gp);
    for i in 0..n {
        let (pi, gi) = (p[i], gp[i]);
        let dot = pi[0] * gi[0] + pi[1] * gi[1] + pi[2] * gi[2];
        for k in 0..3 {
            g[3 * i + k] = (gi[k] - dot * pi[k]) / norms[i];
        }
    }
    f
}

/// Riesz s-energy scaled by `r0`: Σ (r0/d)^s over pairs closer than `cut`.
fn riesz(p: &[[f64; 3]], gp: &mut [[f64; 3]], s: f64, r0: f64, cut: f64) -> f64 {
    let mut e = 0.0;
    let r02 = r0 * r0;
    for_close_pairs(p, cut, |i, j, d2| {
        let t = (r02 / d2).powf(0.5 * s);
        e += t;
        let c = s * t / d2;
        for k in 0..3 {
            let dk = p[i][k] - p[j][k];
            gp[i][k] -= c * dk;
            gp[j][k] += c * dk;
        }
    });
    e
}

/// Overlap penalty Σ max(0, pᵢ·pⱼ − cos θ)² over pairs closer than the target angle.
fn penalty(p: &[[f64; 3]], gp: &mut [[f64; 3]], cos_t: f64) -> f64 {
    let cut = (2.0 - 2.0 * cos_t).max(0.0).sqrt();
    let mut e = 0.0;
    for_close_pairs(p, cut, |i, j, d2| {
        let c = 1.0 - 0.5 * d2;
        let o = c - cos_t;
        if o > 0.0 {
            e += o * o;
            for k in 0..3 {
                gp[i][k] += 2.0 * o * p[j][k];
                gp[j][k] += 2.0 * o * p[i][k];
            }
        }
    });
    e
}

/// Riesz descent with increasing exponent.
fn riesz_schedule(x: &mut [f64], iters: usize) {
    for s in [6.0, 12.0, 24.0, 48.0, 96.0, 192.0] {
        let r0 = min_chord(x);
        // Cut pairs whose term is below 1e-12 of the closest pair's.
        let cut = (r0 * 10f64.powf(12.0 / s)).min(2.5);
        lbfgs(x, iters, 0.2 * r0, |x, g| on_sphere(x, g, |p, gp| riesz(p, gp, s, r0, cut)));
        renormalize(x);
    }
}

/// Dynamic-thresholding max–min refinement; returns the final minimum angle (degrees).
fn refine(x: &mut Vec<f64>) -> f64 {
    renormalize(x);
    let mut best_c = min_chord(x);
    let mut best_a = chord_to_deg(best_c);
    let mut gamma = 1e-2;
    let mut rounds = 0;
    while gamma > 1e-9 && rounds < 400 {
        rounds += 1;
        let target = (best_a * (1.0 + gamma)).to_radians();
        let cos_t = target.cos();
        let mut y = x.clone();
        lbfgs(&mut y, 400, 0.05 * best_c, |y, g| on_sphere(y, g, |p, gp| penalty(p, gp, cos_t)));
        renormalize(&mut y);
        let c = min_chord(&y);
        let a = chord_to_deg(c);
        if a > best_a {
            best_a = a;
            best_c = c;
            *x = y;
        } else {
            gamma *= 0.5;
        }
    }
    best_a
}

/// Limited-memory BFGS (memory 8) with backtracking Armijo line search. `step0` is the length
/// of the first (steepest-descent) step; later steps use the usual curvature scaling.
fn lbfgs(x: &mut [f64], max_iter: usize, step0: f64, mut f: impl FnMut(&[f64], &mut [f64]) -> f64) -> f64 {
    const M: usize = 8;
    let n = x.len();
    let mut g = vec![0.0; n];
    let mut fx = f(x, &mut g);
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut rho: Vec<f64> = Vec::new();
    let mut xn = vec![0.0; n];
    let mut gn = vec![0.0; n];
    let mut fails = 0;
    let mut stall = 0;
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(u, v)| u * v).sum::<f64>();
    for _ in 0..max_iter {
        if fx == 0.0 {
            break;
        }
        let gnorm = dot(&g, &g).sqrt();
        if gnorm == 0.0 || !gnorm.is_finite() {
            break;
        }
        // Two-loop recursion.
        let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
        let k = s_hist.len();
        let mut alpha = vec![0.0; k];
        for i in (0..k).rev() {
            alpha[i] = rho[i] * dot(&s_hist[i], &d);
            d.iter_mut().zip(&y_hist[i]).for_each(|(dv, yv)| *dv -= alpha[i] * yv);
        }
        let scale = if k > 0 {
            dot(&s_hist[k - 1], &y_hist[k - 1]) / dot(&y_hist[k - 1], &y_hist[k - 1])
        } else {
            step0 / gnorm
        };
        d.iter_mut().for_each(|v| *v *= scale);
        for i in 0..k {
            let b = rho[i] * dot(&y_hist[i], &d);
            d.iter_mut().zip(&s_hist[i]).for_each(|(dv, sv)| *dv += (alpha[i] - b) * sv);
        }
        let mut slope = dot(&g, &d);
        if slope >= 0.0 {
            // Not a descent direction: fall back to steepest descent.
            d = g.iter().map(|v| -v * step0 / gnorm).collect();
            slope = dot(&g, &d);
            s_hist.clear();
            y_hist.clear();
            rho.clear();
        }
        let mut t = 1.0;
        let mut accepted = false;
        for _ in 0..30 {
            xn.iter_mut().zip(x.iter().zip(&d)).for_each(|(a, (b, c))| *a = b + t * c);
            let fnew = f(&xn, &mut gn);
            if fnew.is_finite() && fnew <= fx + 1e-4 * t * slope {
                accepted = true;
                let s: Vec<f64> = d.iter().map(|v| t * v).collect();
                let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
                let sy = dot(&s, &y);
                if sy > 1e-300 {
                    if s_hist.len() == M {
                        s_hist.remove(0);
                        y_hist.remove(0);
                        rho.remove(0);
                    }
                    rho.push(1.0 / sy);
                    s_hist.push(s);
                    y_hist.push(y);
                }
                if fx - fnew <= 1e-14 * fx.abs() {
                    stall += 1;
                } else {
                    stall = 0;
                }
                x.copy_from_slice(&xn);
                g.copy_from_slice(&gn);
                fx = fnew;
                break;
            }
            t *= 0.5;
        }
        if !accepted {
            fails += 1;
            s_hist.clear();
            y_hist.clear();
            rho.clear();
            if fails >= 2 {
                break;
            }
        } else {
            fails = 0;
        }
        if stall >= 10 {
            break;
        }
    }
    fx
}

/// Minimum angle (degrees) of a generated set; convenience wrapper for reports.
pub fn min_angle_deg(dirs: &[[f64; 3]]) -> f64 {
    min_pairwise_angle_deg(dirs).unwrap_or(180.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_groups_have_the_right_orders_and_orbits() {
        let groups = symmetry_groups();
        let orders: Vec<usize> = groups.iter().map(|g| g.rots.len()).collect();
        assert_eq!(orders, vec![12, 24, 60]);
        let special: Vec<Vec<usize>> =
            groups.iter().map(|g| g.special.iter().map(Vec::len).collect()).collect();
        assert_eq!(special, vec![vec![4, 6, 4], vec![6, 12, 8], vec![12, 30, 20]]);
        for g in &groups {
            for r in &g.rots {
                // Orthonormal with determinant +1.
                let det = dot3(r[0], cross(r[1], r[2]));
                assert!((det - 1.0).abs() < 1e-12);
                for i in 0..3 {
                    for j in 0..3 {
                        let want = if i == j { 1.0 } else { 0.0 };
                        assert!((dot3(r[i], r[j]) - want).abs() < 1e-12);
                    }
                }
            }
        }
        // 200 = 3·60 + 20 (icosahedral, face centres) = 16·12 + 4 + 4 (tetrahedral).
        assert_eq!(decompositions(200, &groups[2]), vec![vec![2]]);
        assert!(decompositions(200, &groups[0]).contains(&vec![0, 2]));
        let mut rng = stream_rng(1, 200, 0);
        let pts = symmetric_points(200, &groups[2], &[2], &mut rng);
        assert_eq!(pts.len(), 200);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let mut rng = stream_rng(3, 10, 0);
        let x = flatten(&random_points(10, &mut rng));
        let r0 = min_chord(&x);
        let cos_t = 0.3;
        type Objective = Box<dyn Fn(&[f64], &mut [f64]) -> f64>;
        let objs: Vec<Objective> = vec![
            Box::new(move |x: &[f64], g: &mut [f64]| on_sphere(x, g, |p, gp| riesz(p, gp, 6.0, r0, 3.0))),
            Box::new(move |x: &[f64], g: &mut [f64]| on_sphere(x, g, |p, gp| penalty(p, gp, cos_t))),
        ];
        for f in objs {
            let mut g = vec![0.0; x.len()];
            f(&x, &mut g);
            let mut scratch = vec![0.0; x.len()];
            for k in 0..x.len() {
                let h = 1e-6;
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[k] += h;
                xm[k] -= h;
                let fd = (f(&xp, &mut scratch) - f(&xm, &mut scratch)) / (2.0 * h);
                assert!((fd - g[k]).abs() <= 1e-5 * (1.0 + g[k].abs()), "k={k}: {fd} vs {}", g[k]);
            }
        }
    }

    #[test]
    fn lbfgs_minimizes_a_quadratic() {
        let mut x = vec![3.0, -2.0, 1.0];
        let f = |x: &[f64], g: &mut [f64]| {
            let w = [1.0, 10.0, 100.0];
            let mut v = 0.0;
            for i in 0..3 {
                v += w[i] * (x[i] - 1.0).powi(2);
                g[i] = 2.0 * w[i] * (x[i] - 1.0);
            }
            v
        };
        let v = lbfgs(&mut x, 200, 0.1, f);
        assert!(v < 1e-12, "{v}");
        assert!(x.iter().all(|xi| (xi - 1.0).abs() < 1e-6), "{x:?}");
    }
}
