//! The small mesh-construction toolkit behind the procedural objects: a triangle builder with a
//! current face colour, and four generators every object is assembled from.
//!
//! * [`Builder::sheet`] connects a sequence of closed vertex rings (or single "pole" vertices)
//!   into a band of quads / fans. Surfaces of revolution, lofts with per-angle cross-sections
//!   and swept tubes are all sheets, so they share one orientation rule and one pole rule.
//! * [`Builder::revolve`] turns a 2D `(r, z)` [`Profile`] around the z axis.
//! * [`Builder::tube`] sweeps a circle along a 3D path with rotation-minimizing frames.
//! * [`Builder::cells`] emits the boundary of a union of axis-aligned grid cells (rectilinear
//!   solids: boxes, L/U shapes, hollow boxes, frames), subdivided on one shared fine grid so
//!   the result is watertight without any welding.
//!
//! Conventions. Every generator targets an edge length `h` (the detail level) so that the
//! triangle count scales like `area / h²`. Orientation is outward (counter-clockwise seen from
//! outside) by construction: a revolve profile is traversed with the solid on its left (CCW in
//! the `(r, z)` half-plane), a ring is traversed counter-clockwise around its axis. Surfaces
//! bounding a cavity from the inside therefore come out facing into the cavity, as they should.
//! Vertices at `r = 0` of a profile become single pole vertices joined by triangle fans, so no
//! generator produces zero-area triangles.

use crate::{Appearance, Mesh};
use std::collections::HashMap;
use std::f64::consts::TAU;
use std::hash::{BuildHasherDefault, Hasher};

pub(crate) type P2 = [f64; 2];
pub(crate) type P3 = [f64; 3];
pub(crate) type Rgb = [f32; 3];

fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale(a: P3, s: f64) -> P3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: P3, b: P3) -> P3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn norm(a: P3) -> f64 {
    dot(a, a).sqrt()
}
fn normalize(a: P3) -> P3 {
    scale(a, 1.0 / norm(a))
}

/// Hasher for the packed fine-grid keys of [`Builder::cells`]: a multiply and a splitmix64
/// finalizer instead of SipHash, which dominated `cells` at a million triangles. Keys are
/// produced by this module only, so no collision resistance is needed.
#[derive(Default)]
struct GridHasher(u64);

impl Hasher for GridHasher {
    fn finish(&self) -> u64 {
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0 ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// Fewest segments on a full circle, however small: keeps thin tubes round (a 24-gon has
/// 99.7% of the circle's perimeter and 98.9% of its area).
pub(crate) const MIN_CIRCLE: usize = 24;

/// Number of pieces a length `len` is cut into at target edge length `h` (at least 1).
pub(crate) fn pieces(len: f64, h: f64) -> usize {
    ((len / h) - 1e-9).ceil().max(1.0) as usize
}

/// `n` points evenly spaced on the unit circle, counter-clockwise from +x.
pub(crate) fn circle_ring(n: usize) -> Vec<P2> {
    (0..n)
        .map(|i| {
            let a = TAU * i as f64 / n as f64;
            [a.cos(), a.sin()]
        })
        .collect()
}

/// A 2D polyline in the `(r, z)` half-plane (or any plane), resampled at the builder's edge
/// length as it is drawn, with a colour per segment.
#[derive(Debug, Clone)]
pub(crate) struct Profile {
    h: f64,
    /// Points; `r` values closer to 0 than 1e-12 are snapped to exactly 0 (poles).
    pub pts: Vec<P2>,
    /// `colors[i]` is the colour of the segment ending at `pts[i]` (`colors[0]` is the colour of
    /// the closing segment of a closed profile).
    pub colors: Vec<Rgb>,
    /// Colour of the segments drawn next.
    pub color: Rgb,
}

impl Profile {
    pub fn new(h: f64, start: P2, color: Rgb) -> Profile {
        let mut p = Profile { h, pts: vec![], colors: vec![], color };
        p.push(start);
        p
    }

    fn push(&mut self, mut q: P2) {
        if q[0].abs() < 1e-12 {
            q[0] = 0.0;
        }
        if let Some(last) = self.pts.last() {
            if (last[0] - q[0]).abs() < 1e-12 && (last[1] - q[1]).abs() < 1e-12 {
                return;
            }
        }
        self.pts.push(q);
        self.colors.push(self.color);
    }

    fn last(&self) -> P2 {
        *self.pts.last().expect("profile has a start point")
    }

    /// Straight segment to `q`, cut into pieces of length ≤ h.
    pub fn line_to(&mut self, q: P2) -> &mut Self {
        let p = self.last();
        let n = pieces(((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt(), self.h);
        for i in 1..n {
            let t = i as f64 / n as f64;
            self.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
        self.push(q);
        self
    }

    /// Elliptic arc `centre + (rx cos a, rz sin a)` for `a` from `a0` to `a1` (radians, either
    /// direction). The current point should be the arc's start; a straight segment joins it
    /// otherwise.
    pub fn arc(&mut self, centre: P2, rx: f64, rz: f64, a0: f64, a1: f64) -> &mut Self {
        let at = |a: f64| [centre[0] + rx * a.cos(), centre[1] + rz * a.sin()];
        self.line_to(at(a0));
        let turn = (a1 - a0).abs() / TAU;
        let n = pieces(rx.max(rz) * (a1 - a0).abs(), self.h)
            .max((MIN_CIRCLE as f64 * turn).ceil() as usize)
            .max(2);
        for i in 1..=n {
            self.push(at(a0 + (a1 - a0) * i as f64 / n as f64));
        }
        self
    }

    /// A smooth curve `f(t)`, `t` from 0 to 1, sampled uniformly in `t` with as many pieces as
    /// its (numerically estimated) length needs.
    pub fn curve(&mut self, f: impl Fn(f64) -> P2) -> &mut Self {
        let m = 512;
        let len: f64 = (0..m)
            .map(|i| {
                let (a, b) = (f(i as f64 / m as f64), f((i + 1) as f64 / m as f64));
                ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
            })
            .sum();
        self.line_to(f(0.0));
        let n = pieces(len, self.h).max(2);
        for i in 1..=n {
            self.push(f(i as f64 / n as f64));
        }
        self
    }

    /// Closes the profile: the last point is joined back to the first by a straight segment
    /// (resampled like any other) in the current colour.
    pub fn close(mut self) -> ClosedProfile {
        // A profile that already came back to its start (a full circle) drops the duplicate.
        let (p, q) = (self.last(), self.pts[0]);
        if self.pts.len() > 1 && (p[0] - q[0]).abs() < 1e-12 && (p[1] - q[1]).abs() < 1e-12 {
            self.pts.pop();
            let c = self.colors.pop().expect("one colour per point");
            self.colors[0] = c;
            return ClosedProfile(self);
        }
        let n = pieces(((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt(), self.h);
        for i in 1..n {
            let t = i as f64 / n as f64;
            self.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
        self.colors[0] = self.color;
        ClosedProfile(self)
    }
}

/// A profile whose last point joins its first.
#[derive(Debug, Clone)]
pub(crate) struct ClosedProfile(pub Profile);

/// Accumulates triangles with per-face colours, then normalizes them into a [`Mesh`].
#[derive(Debug)]
pub(crate) struct Builder {
    /// Target edge length.
    pub h: f64,
    /// Colour of the triangles added next.
    pub color: Rgb,
    positions: Vec<P3>,
    triangles: Vec<[u32; 3]>,
    colors: Vec<Rgb>,
}

impl Builder {
    pub fn new(h: f64) -> Builder {
        Builder { h, color: [0.7, 0.7, 0.7], positions: vec![], triangles: vec![], colors: vec![] }
    }

    /// A new profile at this builder's edge length, drawn in the current colour.
    pub fn profile(&self, start: P2) -> Profile {
        Profile::new(self.h, start, self.color)
    }

    /// Number of vertices of a closed ring of radius `r` (at least [`MIN_CIRCLE`]).
    pub fn ring_count(&self, r: f64) -> usize {
        pieces(TAU * r, self.h).max(MIN_CIRCLE)
    }

    pub fn vertex(&mut self, p: P3) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    pub fn tri(&mut self, a: u32, b: u32, c: u32) {
        self.triangles.push([a, b, c]);
        self.colors.push(self.color);
    }

    /// Quad `a → b → c → d` (one loop), split along its shorter diagonal.
    pub fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        let p = |i: u32| self.positions[i as usize];
        if norm(sub(p(a), p(c))) <= norm(sub(p(b), p(d))) {
            self.tri(a, b, c);
            self.tri(a, c, d);
        } else {
            self.tri(a, b, d);
            self.tri(b, c, d);
        }
    }

    /// Applies `f` to every vertex added so far from index `from` on.
    pub fn map_from(&mut self, from: usize, f: impl Fn(P3) -> P3) {
        for p in &mut self.positions[from..] {
            *p = f(*p);
        }
    }

    /// Number of vertices so far (to mark the start of a part for [`Builder::map_from`]).
    pub fn mark(&self) -> usize {
        self.positions.len()
    }

    /// Connects consecutive rows. Each row is a closed ring (all rings of one sheet have the
    /// same length) or a single pole vertex. `band_colors[j]` colours the band from row `j` to
    /// row `j + 1`; with `wrap`, the last row is joined back to the first.
    ///
    /// Orientation: with ring direction u and row-to-row direction v, faces point along u × v.
    pub fn sheet(&mut self, rows: &[Vec<P3>], band_colors: &[Rgb], wrap: bool) {
        let ids: Vec<Vec<u32>> = rows.iter().map(|r| r.iter().map(|&p| self.vertex(p)).collect()).collect();
        let bands = if wrap { ids.len() } else { ids.len() - 1 };
        for j in 0..bands {
            self.color = band_colors[j];
            let (a, b) = (&ids[j], &ids[(j + 1) % ids.len()]);
            match (a.len(), b.len()) {
                (1, 1) => {}
                (1, n) => (0..n).for_each(|i| self.tri(a[0], b[(i + 1) % n], b[i])),
                (n, 1) => (0..n).for_each(|i| self.tri(a[i], a[(i + 1) % n], b[0])),
                (n, m) => {
                    assert_eq!(n, m, "rings of one sheet must have equal length");
                    (0..n).for_each(|i| self.quad(a[i], a[(i + 1) % n], b[(i + 1) % n], b[i]));
                }
            }
        }
    }

    /// Surface of revolution of `profile` around the z axis, with ring shape `ring` (unit
    /// circle points from [`circle_ring`], or any star-shaped loop such as a square).
    pub fn revolve_ring(&mut self, profile: &Profile, closed: bool, ring: &[P2]) {
        let rows: Vec<Vec<P3>> = profile
            .pts
            .iter()
            .map(|&[r, z]| {
                if r == 0.0 {
                    vec![[0.0, 0.0, z]]
                } else {
                    ring.iter().map(|g| [r * g[0], r * g[1], z]).collect()
                }
            })
            .collect();
        // Band j (from point j to j+1) has the colour of the segment ending at j+1.
        let n = profile.pts.len();
        let colors: Vec<Rgb> = (0..n).map(|j| profile.colors[(j + 1) % n]).collect();
        self.sheet(&rows, &colors, closed);
    }

    /// Surface of revolution with circular rings sized for the largest radius of the profile.
    /// An open profile should start and end on the axis (r = 0) to be closed.
    pub fn revolve(&mut self, profile: &Profile) {
        let rmax = profile.pts.iter().map(|p| p[0]).fold(0.0, f64::max);
        let ring = circle_ring(self.ring_count(rmax));
        self.revolve_ring(profile, false, &ring);
    }

    /// Surface of revolution of a closed profile (a torus-like solid, the profile not touching
    /// the axis).
    pub fn revolve_closed(&mut self, profile: &ClosedProfile) {
        let rmax = profile.0.pts.iter().map(|p| p[0]).fold(0.0, f64::max);
        let ring = circle_ring(self.ring_count(rmax));
        self.revolve_ring(&profile.0, true, &ring);
    }

    /// A tube of radius `radius` around the polyline `path`. A closed path is joined end to
    /// start (its frames are untwisted so the seam matches); an open one gets flat end caps.
    pub fn tube(&mut self, path: &[P3], closed: bool, radius: f64) {
        let n = path.len();
        let tangent = |i: usize| -> P3 {
            let (a, b) = if closed {
                (path[(i + n - 1) % n], path[(i + 1) % n])
            } else {
                (path[i.saturating_sub(1)], path[(i + 1).min(n - 1)])
            };
            normalize(sub(b, a))
        };
        let ts: Vec<P3> = (0..n).map(tangent).collect();
        // Rotation-minimizing frames by projection (parallel transport for small steps).
        let t0 = ts[0];
        let seed = if t0[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
        let mut ns = vec![normalize(sub(seed, scale(t0, dot(seed, t0))))];
        for i in 1..n {
            let prev = ns[i - 1];
            ns.push(normalize(sub(prev, scale(ts[i], dot(prev, ts[i])))));
        }
        // Closed path: the frame transported once around differs from the start frame by a
        // rotation `twist` about the tangent; spread its undoing evenly along the path.
        let twist = if closed {
            let last = ns[n - 1];
            let back = normalize(sub(last, scale(t0, dot(last, t0))));
            let b0 = cross(t0, ns[0]);
            dot(back, b0).atan2(dot(back, ns[0]))
        } else {
            0.0
        };
        let m = self.ring_count(radius);
        let mut rows: Vec<Vec<P3>> = Vec::with_capacity(n + 2);
        if !closed {
            rows.push(vec![path[0]]);
        }
        for i in 0..n {
            let (t, nn) = (ts[i], ns[i]);
            let b = cross(t, nn);
            let off = -twist * i as f64 / n as f64;
            rows.push(
                (0..m)
                    .map(|k| {
                        let a = TAU * k as f64 / m as f64 + off;
                        add(path[i], add(scale(nn, radius * a.cos()), scale(b, radius * a.sin())))
                    })
                    .collect(),
            );
        }
        if !closed {
            rows.push(vec![path[n - 1]]);
        }
        let colors = vec![self.color; rows.len()];
        self.sheet(&rows, &colors, closed);
    }

    /// Boundary of a union of grid cells. The grid has cell boundaries `xs`, `ys`, `zs`
    /// (increasing); `cell(i, j, k)` returns the colour of an occupied cell, `None` for an empty
    /// one. Every cell interval is split into pieces of length ≤ h on one shared fine grid, so
    /// faces of neighbouring cells share their edge vertices (watertight). The union must not
    /// contain two cells touching only along an edge or at a corner (that would be
    /// non-manifold).
    pub fn cells(&mut self, axes: [&[f64]; 3], cell: impl Fn(usize, usize, usize) -> Option<Rgb>) {
        // Fine coordinates per axis and the fine index where each coarse boundary lands.
        let fine: Vec<(Vec<f64>, Vec<usize>)> = axes
            .iter()
            .map(|bounds| {
                let mut coords = vec![bounds[0]];
                let mut at = vec![0];
                for w in bounds.windows(2) {
                    let n = pieces(w[1] - w[0], self.h);
                    for s in 1..=n {
                        coords.push(if s == n { w[1] } else { w[0] + (w[1] - w[0]) * s as f64 / n as f64 });
                    }
                    at.push(coords.len() - 1);
                }
                (coords, at)
            })
            .collect();
        let counts = [axes[0].len() - 1, axes[1].len() - 1, axes[2].len() - 1];
        assert!(fine.iter().all(|f| f.0.len() < 1 << 21), "fine grid too large for packed keys");
        let occ = |c: [usize; 3], a: usize, lo: bool| -> Option<Rgb> {
            // Cell below (lo) or above the boundary plane c[a] along axis a.
            let mut c = c;
            if lo {
                if c[a] == 0 {
                    return None;
                }
                c[a] -= 1;
            } else if c[a] == counts[a] {
                return None;
            }
            cell(c[0], c[1], c[2])
        };
        let mut index: HashMap<u64, u32, BuildHasherDefault<GridHasher>> = HashMap::default();
        for a in 0..3 {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            for p in 0..=counts[a] {
                for jb in 0..counts[b] {
                    for jc in 0..counts[c] {
                        let mut key = [0; 3];
                        key[a] = p;
                        key[b] = jb;
                        key[c] = jc;
                        let (lo, hi) = (occ(key, a, true), occ(key, a, false));
                        let (color, outward_plus) = match (lo, hi) {
                            (Some(col), None) => (col, true),
                            (None, Some(col)) => (col, false),
                            _ => continue,
                        };
                        self.color = color;
                        let fa = fine[a].1[p];
                        let (b0, b1) = (fine[b].1[jb], fine[b].1[jb + 1]);
                        let (c0, c1) = (fine[c].1[jc], fine[c].1[jc + 1]);
                        for ib in b0..b1 {
                            for ic in c0..c1 {
                                let mut v = |db: usize, dc: usize| -> u32 {
                                    let mut f = [0; 3];
                                    f[a] = fa;
                                    f[b] = ib + db;
                                    f[c] = ic + dc;
                                    let key = ((f[0] as u64) << 42) | ((f[1] as u64) << 21) | f[2] as u64;
                                    *index.entry(key).or_insert_with(|| {
                                        let p = [fine[0].0[f[0]], fine[1].0[f[1]], fine[2].0[f[2]]];
                                        self.positions.push(p);
                                        (self.positions.len() - 1) as u32
                                    })
                                };
                                let (v00, v10, v11, v01) = (v(0, 0), v(1, 0), v(1, 1), v(0, 1));
                                // (b̂, ĉ) loop has normal b̂ × ĉ = +â.
                                if outward_plus {
                                    self.quad(v00, v10, v11, v01);
                                } else {
                                    self.quad(v00, v01, v11, v10);
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Finishes the mesh: translates the centre of the vertex bounding box to the origin and
    /// scales uniformly so the farthest vertex is at distance exactly 1 (SPEC §1 `unit`).
    /// All triangles carry face colours.
    pub fn finish(self) -> Mesh {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let c: P3 = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let mut positions: Vec<P3> = self.positions.iter().map(|&p| sub(p, c)).collect();
        let r = positions.iter().map(|&p| norm(p)).fold(0.0, f64::max);
        for p in &mut positions {
            *p = scale(*p, 1.0 / r);
        }
        Mesh { positions, triangles: self.triangles, appearance: Appearance::FaceColors(self.colors) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_resamples_and_snaps_poles() {
        let mut p = Profile::new(0.25, [1e-15, 0.0], [1.0; 3]);
        p.line_to([1.0, 0.0]).line_to([1.0, 0.0]);
        assert_eq!(p.pts, vec![[0.0, 0.0], [0.25, 0.0], [0.5, 0.0], [0.75, 0.0], [1.0, 0.0]]);
        assert_eq!(p.colors.len(), p.pts.len());
    }

    #[test]
    fn closed_profile_has_no_duplicate_point() {
        let mut p = Profile::new(1.0, [1.0, 0.0], [1.0; 3]);
        p.line_to([2.0, 0.0]).line_to([2.0, 1.0]);
        let c = p.close();
        assert_eq!(c.0.pts, vec![[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.5, 0.5]]);
        assert_eq!(c.0.colors.len(), 4);
    }

    #[test]
    fn cells_unit_cube_counts() {
        let mut b = Builder::new(0.5);
        b.cells([&[0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]], |_, _, _| Some([1.0; 3]));
        // 6 faces × 2×2 quads × 2 triangles; 3×3×3 grid nodes minus the 1 interior node.
        assert_eq!(b.triangles.len(), 48);
        assert_eq!(b.positions.len(), 26);
    }
}
