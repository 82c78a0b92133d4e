//! Parts the random families are assembled from: closed solids drawn at a given place and
//! orientation (boxes and rectilinear cell unions, surfaces of revolution, rods, tubes, cups,
//! pipes, prisms), and the small amount of 3D linear algebra needed to place them.
//!
//! Every part is a closed, outward-oriented surface of its own (its own vertices), so an
//! assembly is a union of closed components; parts may interpenetrate (the overlap is hidden
//! inside the solid and is never observable).

use super::super::builder::{pieces, Builder, Rgb, P2, P3};
use super::super::shapes;
use std::f64::consts::TAU;

/// A 3×3 matrix, rows first.
pub(super) type M3 = [[f64; 3]; 3];

pub(super) const IDENTITY: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub(super) fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(super) fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(super) fn scale(a: P3, s: f64) -> P3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub(super) fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(super) fn cross(a: P3, b: P3) -> P3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub(super) fn norm(a: P3) -> f64 {
    dot(a, a).sqrt()
}
pub(super) fn normalize(a: P3) -> P3 {
    scale(a, 1.0 / norm(a))
}

pub(super) fn mul(m: &M3, p: P3) -> P3 {
    [dot(m[0], p), dot(m[1], p), dot(m[2], p)]
}

pub(super) fn mat_mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// Rotation by `angle` (radians) about the unit vector `axis` (Rodrigues).
pub(super) fn rot_axis(axis: P3, angle: f64) -> M3 {
    let [x, y, z] = normalize(axis);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// A rotation taking +z to the direction `d`.
pub(super) fn rot_z_to(d: P3) -> M3 {
    let d = normalize(d);
    let axis = cross([0.0, 0.0, 1.0], d);
    let s = norm(axis);
    if s < 1e-12 {
        return if d[2] > 0.0 { IDENTITY } else { rot_axis([1.0, 0.0, 0.0], std::f64::consts::PI) };
    }
    rot_axis(axis, s.atan2(d[2]))
}

/// Rotation matrix of the unit quaternion `(w, x, y, z)`.
pub(super) fn quat_matrix(q: [f64; 4]) -> M3 {
    let [w, x, y, z] = q;
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// Hamilton product `a·b` of quaternions `[w, x, y, z]` (rotation `b`, then `a`).
pub(super) fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Moves the vertices added since `mark`: `p → m·p + t`.
pub(super) fn place(b: &mut Builder, mark: usize, m: &M3, t: P3) {
    let m = *m;
    b.map_from(mark, move |p| add(mul(&m, p), t));
}

/// Revolves the polyline `pts` (in `(r, z)`, solid on its left, from the axis back to the
/// axis) around z.
pub(super) fn revolve(b: &mut Builder, pts: &[P2]) {
    let mut p = b.profile(pts[0]);
    for &q in &pts[1..] {
        p.line_to(q);
    }
    b.revolve(&p);
}

/// Revolves the closed polygon `pts` (not touching the axis, counter-clockwise in `(r, z)`).
pub(super) fn revolve_closed(b: &mut Builder, pts: &[P2]) {
    let mut p = b.profile(pts[0]);
    for &q in &pts[1..] {
        p.line_to(q);
    }
    b.revolve_closed(&p.close());
}

/// Frustum (cylinder, cone when `r1 == 0`) on the z axis from `z0` to `z1`.
pub(super) fn frustum(b: &mut Builder, r0: f64, r1: f64, z0: f64, z1: f64) {
    if r1 > 0.0 {
        revolve(b, &[[0.0, z0], [r0, z0], [r1, z1], [0.0, z1]]);
    } else {
        revolve(b, &[[0.0, z0], [r0, z0], [0.0, z1]]);
    }
}

/// Solid sphere of radius `r` centred at `c`.
pub(super) fn ball(b: &mut Builder, c: P3, r: f64) {
    shapes::ball(b, c, r, false);
}

/// Ellipsoid with semi-axes `radii`, rotated by `m`, centred at `c`.
pub(super) fn ellipsoid(b: &mut Builder, c: P3, radii: P3, m: &M3) {
    let mark = b.mark();
    shapes::ball(b, [0.0; 3], 1.0, false);
    b.map_from(mark, |q| [q[0] * radii[0], q[1] * radii[1], q[2] * radii[2]]);
    place(b, mark, m, c);
}

/// Ring torus around z: centre-circle radius `big_r`, tube radius `r`.
pub(super) fn torus(b: &mut Builder, big_r: f64, r: f64) {
    shapes::torus_at(b, big_r, r);
}

/// Round rod of radius `r` from `p` to `q` with flat ends.
pub(super) fn rod(b: &mut Builder, p: P3, q: P3, r: f64) {
    let mark = b.mark();
    frustum(b, r, r, 0.0, norm(sub(q, p)));
    place(b, mark, &rot_z_to(sub(q, p)), p);
}

/// Axis-aligned box.
pub(super) fn cuboid(b: &mut Builder, lo: P3, hi: P3) {
    let c = b.color;
    b.cells([&[lo[0], hi[0]], &[lo[1], hi[1]], &[lo[2], hi[2]]], |_, _, _| Some(c));
}

/// Box of size `size` centred at the origin, then rotated by `m` and moved to `c`.
pub(super) fn oriented_box(b: &mut Builder, c: P3, size: P3, m: &M3) {
    let mark = b.mark();
    let h = scale(size, 0.5);
    cuboid(b, [-h[0], -h[1], -h[2]], h);
    place(b, mark, m, c);
}

/// Sorted boundaries with (near-)duplicates removed.
fn clean_axis(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    v
}

/// Boundary of the union of grid cells whose centre `pred` accepts (returns a colour for).
/// The boundaries per axis may come unsorted and with duplicates. The predicate must not make
/// two cells touch only along an edge or at a corner.
pub(super) fn cells_where(
    b: &mut Builder,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    pred: impl Fn(P3) -> Option<Rgb>,
) {
    let (xs, ys, zs) = (clean_axis(xs), clean_axis(ys), clean_axis(zs));
    let mid = |v: &[f64], i: usize| 0.5 * (v[i] + v[i + 1]);
    b.cells([&xs, &ys, &zs], |i, j, k| pred([mid(&xs, i), mid(&ys, j), mid(&zs, k)]));
}

/// A closed polygon ring with `n` corners on the unit circle (the first at angle `phase`),
/// each side cut into pieces of at most `h / r` so that at radius `r` edges stay ≤ h.
pub(super) fn polygon_ring(n: usize, phase: f64, r: f64, h: f64) -> Vec<P2> {
    let corner = |k: usize| {
        let a = phase + TAU * k as f64 / n as f64;
        [a.cos(), a.sin()]
    };
    let side = 2.0 * (std::f64::consts::PI / n as f64).sin();
    let k = pieces(side * r, h).max(2);
    (0..n)
        .flat_map(|s| {
            let (u, v) = (corner(s), corner(s + 1));
            (0..k).map(move |i| {
                let t = i as f64 / k as f64;
                [u[0] + t * (v[0] - u[0]), u[1] + t * (v[1] - u[1])]
            })
        })
        .collect()
}

/// Solid of revolution of `pts` (from the axis to the axis) whose rings are the regular
/// `n`-gon: prisms, pyramids, polygonal frustums.
pub(super) fn polygonal(b: &mut Builder, pts: &[P2], n: usize, phase: f64) {
    let mut p = b.profile(pts[0]);
    for &q in &pts[1..] {
        p.line_to(q);
    }
    let rmax = pts.iter().map(|q| q[0]).fold(0.0, f64::max);
    let ring = polygon_ring(n, phase, rmax, b.h);
    b.revolve_ring(&p, false, &ring);
}

/// Open container standing on z = 0: outer radius `rb` at the bottom and `rt` at the top
/// (height `h`), wall `w` (measured horizontally), floor thickness `f`.
pub(super) fn cup(b: &mut Builder, rb: f64, rt: f64, h: f64, w: f64, f: f64, inside: Rgb) {
    let outside = b.color;
    let mut p = b.profile([0.0, 0.0]);
    p.line_to([rb, 0.0]).line_to([rt, h]);
    p.line_to([rt - w, h]);
    p.color = inside;
    let r_at_floor = rb + (rt - rb) * f / h;
    p.line_to([r_at_floor - w, f]).line_to([0.0, f]);
    b.revolve(&p);
    b.color = outside;
}

/// Thick-walled open pipe along z, centred at z = 0: radii `ri < ro`, length `len`.
pub(super) fn pipe(b: &mut Builder, ri: f64, ro: f64, len: f64) {
    revolve_closed(b, &[[ri, -0.5 * len], [ro, -0.5 * len], [ro, 0.5 * len], [ri, 0.5 * len]]);
}

/// Tube of radius `r` around the curve `f(t)`, `t` in `[0, 1]`.
pub(super) fn tube_along(b: &mut Builder, f: impl Fn(f64) -> P3, closed: bool, r: f64) {
    let path = shapes::sample_path(b, f, closed);
    b.tube(&path, closed, r);
}
