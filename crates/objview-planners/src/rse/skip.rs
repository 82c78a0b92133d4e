//! The skipping ray walk of [`GainMap`]: per voxel, the radius of the box of identical voxels
//! around it ([`GainMap::runs`], an exact chamfer distance transform), and a walk that jumps
//! through such boxes while summing voxel by voxel, so its result equals the plain walk bit for
//! bit. Used when a view has many rays to walk; apart from the scoring loop because its
//! correctness argument (the traversal's own tie rule at the box exit) stands on its own.

use super::gain::{Cell, GainMap};
use crate::occupancy::{floor_i64, Dda};

/// Smallest box radius worth a jump in [`GainMap::ray_gain_skipping`].
const MIN_SKIP: i64 = 2;

impl GainMap {
    /// The box radii of [`GainMap::ray_gain_skipping`] (computed on first use).
    pub(super) fn runs(&self) -> &[u8] {
        self.runs.get_or_init(|| homogeneous_radius(&self.cells, self.geom.n))
    }

    /// [`GainMap::ray_gain`], bit for bit, skipping through boxes of identical voxels. Where the
    /// box of radius R ≥ 2 around the current voxel holds only copies of it (see `runs`), the
    /// ray's exit from the box and the voxel it is in just before are found from the
    /// traversal's own boundary parameters (with its tie rule). The number of voxels it crosses
    /// in the box is then known. The sum is accumulated voxel by voxel in the same order, so the
    /// result is identical.
    pub(super) fn ray_gain_skipping(&self, o: [f64; 3], d: [f64; 3], runs: &[u8]) -> f64 {
        let Some(mut dda) = Dda::new(&self.geom, o, d, 0.0, f64::INFINITY) else {
            return 0.0;
        };
        let n = self.geom.n as i64;
        let cells = &self.cells[..];
        let mut acc = 0.0f64;
        let mut vis = 1.0f64;
        loop {
            let idx = dda.idx as usize;
            let c = cells[idx];
            if c.h < 0.0 {
                // Only the first voxel gets here (later ones are checked after each step):
                // occupied with no predecessor.
                return 0.0;
            }
            let radius = runs[idx] as i64;
            let count = if radius >= MIN_SKIP { skip_box(&mut dda, radius) } else { 1 };
            for _ in 0..count {
                acc += vis * c.h as f64;
                vis *= c.q as f64;
            }
            let prev_unknown = c.h > 0.0;
            if !dda.advance(n) {
                return 0.0;
            }
            if cells[dda.idx as usize].h < 0.0 {
                return if prev_unknown { acc } else { 0.0 };
            }
        }
    }
}

/// Moves `dda` from its current voxel c to the last voxel it visits inside the box of radius
/// `r` around c, and returns how many voxels it visits there (c included). The traversal leaves
/// the box at the first crossing of a box face, at parameter t_box on axis a* (ties: the lowest
/// axis, as [`Dda::next_axis`]). Before that it crosses, on each axis b, every plane with
/// parameter < t_box, and also those at t_box when b < a*.
fn skip_box(dda: &mut Dda, r: i64) -> usize {
    let c = dda.ijk;
    let moving = |a: usize| dda.inv[a].is_finite();
    let mut t_box = f64::INFINITY;
    let mut exit_axis = 3;
    for (a, &ca) in c.iter().enumerate() {
        if moving(a) {
            let face = if dda.step[a] > 0 { ca + r + 1 } else { ca - r };
            let t = dda.plane_t(a, face);
            if t < t_box {
                t_box = t;
                exit_axis = a;
            }
        }
    }
    if exit_axis == 3 || !t_box.is_finite() {
        return 1;
    }
    let mut visited = 1usize;
    let mut t_enter = dda.t;
    for (b, &cb) in c.iter().enumerate() {
        if !moving(b) {
            continue;
        }
        let s = dda.step[b];
        // The parameter of the m-th crossing (m ≥ 1) on axis b, and whether it comes before
        // the exit.
        let t_of = |m: i64| dda.plane_t(b, if s > 0 { cb + m } else { cb + 1 - m });
        let before_exit = |t: f64| t < t_box || (t == t_box && b < exit_axis);
        let spacing = dda.voxel * dda.inv[b].abs();
        let estimate = (t_box - dda.t_next[b]) / spacing;
        let mut m = if estimate.is_finite() { (floor_i64(estimate) + 1).clamp(0, r) } else { 0 };
        // Invariant after the loops: crossing m (if any, at `t_m`) is before the exit, crossing
        // m + 1 (at `next`) is not, or m = r.
        let mut next = t_of(m + 1);
        let mut t_m = f64::NEG_INFINITY;
        while m > 0 {
            let t = t_of(m);
            if before_exit(t) {
                t_m = t;
                break;
            }
            next = t;
            m -= 1;
        }
        while m < r && before_exit(next) {
            m += 1;
            t_m = next;
            next = t_of(m + 1);
        }
        dda.ijk[b] = cb + s * m;
        dda.idx += dda.idx_step[b] * m;
        dda.t_next[b] = next;
        t_enter = t_enter.max(t_m);
        visited += m as usize;
    }
    // The last voxel is entered at the latest of the crossings made.
    dda.t = t_enter;
    visited
}

/// Per voxel, the largest R such that every voxel of the box of half-size R around it is
/// identical to it (same 1 − p and entropy code) and the box stays off the grid's boundary
/// layers; capped at 255.
///
/// Let E be the set of voxels that differ from one of their six face neighbours. If every voxel
/// within Chebyshev distance D of c is at least D + 1 away from E, then no face-adjacent pair
/// inside that box differs, so the box is uniform. R = dist∞(c, E) − 1 is therefore safe. The
/// distance comes from the exact two-pass chamfer transform over the 26-neighbourhood on a grid
/// padded with E, and the padding also keeps boxes inside the grid.
fn homogeneous_radius(cells: &[Cell], n: usize) -> Vec<u8> {
    let p = n + 2;
    let key = |idx: usize| (cells[idx].q.to_bits() as u64) << 32 | cells[idx].h.to_bits() as u64;
    let mut dist = vec![0u8; p * p * p];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let idx = (k * n + j) * n + i;
                let kv = key(idx);
                let differs = |other: usize| key(other) != kv;
                let edge = (i > 0 && differs(idx - 1))
                    || (i + 1 < n && differs(idx + 1))
                    || (j > 0 && differs(idx - n))
                    || (j + 1 < n && differs(idx + n))
                    || (k > 0 && differs(idx - n * n))
                    || (k + 1 < n && differs(idx + n * n));
                dist[((k + 1) * p + j + 1) * p + i + 1] = if edge { 0 } else { u8::MAX };
            }
        }
    }
    // Neighbours in earlier rows (same row handled by the sweep): (dk, dj) with dk = −1 or
    // (dk = 0, dj = −1), di ∈ {−1, 0, 1}; as row offsets (in rows of p) and column shifts.
    let mut row_offsets = Vec::new();
    for (dk, dj) in [(-1i64, -1i64), (-1, 0), (-1, 1), (0, -1)] {
        row_offsets.push((dk * p as i64 + dj) as isize);
    }
    let relax = |target: &mut [u8], source: &[u8]| {
        for (t, s) in target.iter_mut().zip(source) {
            *t = (*t).min(s.saturating_add(1));
        }
    };
    // Forward: rows in increasing order, earlier rows are final.
    for k in 1..=n {
        for j in 1..=n {
            let row = (k * p + j) * p;
            let (before, current) = dist.split_at_mut(row);
            let cur = &mut current[1..=n];
            for &ro in &row_offsets {
                let src_row = (row as isize + ro * p as isize) as usize;
                for di in 0..3 {
                    relax(cur, &before[src_row + di..src_row + di + n]);
                }
            }
            let row_slice = &mut current[..p];
            for i in 1..=n {
                row_slice[i] = row_slice[i].min(row_slice[i - 1].saturating_add(1));
            }
        }
    }
    // Backward: rows in decreasing order, later rows are final.
    for k in (1..=n).rev() {
        for j in (1..=n).rev() {
            let row = (k * p + j) * p;
            let (upto, after) = dist.split_at_mut(row + p);
            let cur = &mut upto[row + 1..row + 1 + n];
            for &ro in &row_offsets {
                // Mirror: (−dk, −dj), relative to the start of `after` (row + p).
                let src_row = (row as isize - ro * p as isize) as usize - (row + p);
                for di in 0..3 {
                    relax(cur, &after[src_row + di..src_row + di + n]);
                }
            }
            let row_slice = &mut upto[row..row + p];
            for i in (1..=n).rev() {
                row_slice[i] = row_slice[i].min(row_slice[i + 1].saturating_add(1));
            }
        }
    }
    let mut radius = vec![0u8; n * n * n];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let d = dist[((k + 1) * p + j + 1) * p + i + 1];
                // Off the boundary layers: R < min(c_a, n − 1 − c_a).
                let inside = [i, j, k].iter().map(|&c| c.min(n - 1 - c)).min().unwrap_or(0);
                let r = (d.saturating_sub(1) as usize).min(inside.saturating_sub(1));
                radius[(k * n + j) * n + i] = r as u8;
            }
        }
    }
    radius
}
