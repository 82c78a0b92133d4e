//! The second pass of [`InverseCaster::observe_into`] and the reference walk: per-view plane
//! tables, per-octant constants, the ray set-up, and the Amanatides–Woo walks with leaps over
//! empty space — [`InverseCaster::cast`] in mirrored coordinates (the fast path) and
//! [`InverseCaster::first_hit_cell`] (the general one). The walks decide which voxel a ray sees,
//! so they are kept together with the tie and range rules they must reproduce exactly.

use super::axis::{camera_cell, cell_at, fmax, fmin, next_crossing, next_up, start_cell, up_cell};
use super::InverseCaster;

/// Smallest stored distance at which the walk leaps instead of stepping.
const LEAP_MIN: u8 = 4;
/// Leaps over cubes of at most this Chebyshev radius advance crossing by crossing.
const SMALL_LEAP: usize = 2;

/// Outcome of [`InverseCaster::cast`].
pub(super) enum Cast {
    /// The bitmap bit position of the first S_gt voxel entered.
    Hit(usize),
    /// No S_gt voxel is entered within range.
    Miss,
    /// Not handled by the fast walk: use [`InverseCaster::first_hit_cell`].
    General,
}

/// One ray of [`InverseCaster::observe_into`] and its start state for [`InverseCaster::cast`]
/// (see [`InverseCaster::ray_start`]).
#[derive(Clone, Copy, Default)]
pub(super) struct Ray {
    /// Unit direction.
    pub(super) d: [f64; 3],
    /// Lower bound of the entry time of any S_gt box (the depth bound).
    pub(super) t_lo: f64,
    /// `|d|` and `1/|d|` per axis.
    pub(super) ad: [f64; 3],
    pub(super) s: [f64; 3],
    /// Grid-box entry and exit times in the octant's walk coordinates.
    pub(super) t_in: f64,
    pub(super) t_out: f64,
    /// Start cell (walk coordinates) and its next crossing time per axis.
    pub(super) h: [usize; 3],
    pub(super) tn: [f64; 3],
    /// Octant index (bit a set: the ray moves down axis a).
    pub(super) oct: u8,
}

/// Per-view constants of [`InverseCaster::cast`] for one octant of ray directions (which axes
/// the ray moves down, walked in mirrored coordinates h = n − 1 − g).
pub(super) struct Octant<'v> {
    /// Per axis, the plane offsets in walk order: [`ViewPlanes`]' `planes` or `mirror`.
    pub(super) pl: [&'v [f64]; 3],
    /// Per axis, the first and last of those planes (the grid box).
    pub(super) box0: [f64; 3],
    pub(super) box1: [f64; 3],
    /// `next_up(max_range)`: a crossing at or after it is out of range.
    pub(super) past_range: f64,
    /// Field index of walk cell h: `fbase + Σ h[a]·fstep[a]` (wrapping, so that a negative
    /// step is a two's-complement one).
    pub(super) fstep: [usize; 3],
    pub(super) fbase: usize,
    /// Bitmap bit position of walk cell h, likewise.
    pub(super) bstep: [usize; 3],
    pub(super) bbase: usize,
}

/// Per-view constants: plane offsets `k·r − o` for every grid plane, per axis, and the same
/// planes mirrored (`mirror[a][j] = −planes[a][n − j]`), which let a ray moving down an axis
/// be walked as one moving up (see [`InverseCaster::cast`]).
pub(super) struct ViewPlanes {
    pub(super) planes: [Vec<f64>; 3],
    pub(super) mirror: [Vec<f64>; 3],
    /// 1/r, for start-cell guesses.
    pub(super) inv_r: f64,
}

impl InverseCaster<'_> {
    pub(super) fn planes(&self, origin: [f64; 3]) -> ViewPlanes {
        let r = self.set.resolution();
        let g0 = self.set.grid_origin();
        let planes = std::array::from_fn(|a| {
            (0..=self.dims[a]).map(|g| (g0[a] as f64 + g as f64) * r - origin[a]).collect::<Vec<f64>>()
        });
        let mirror = std::array::from_fn(|a| planes[a].iter().rev().map(|&p| -p).collect());
        ViewPlanes { planes, mirror, inv_r: 1.0 / r }
    }

    /// The set-up of [`InverseCaster::cast`] for `ray` (whose `d`, `t_lo` and reciprocals
    /// `s = 1/|d|` are set): its octant, `|d|`, grid-box entry and exit times, start time and
    /// start cell. The start is meaningful only for a ray that `cast` walks (no zero or NaN
    /// direction component, not rejected by the entry/exit tests); for any other it is some
    /// in-range cell, unused.
    #[inline(always)]
    pub(super) fn ray_start(&self, octants: &[Octant<'_>; 8], ray: &mut Ray, inv_r: f64) {
        let (d, s) = (ray.d, ray.s);
        let ad = [d[0].abs(), d[1].abs(), d[2].abs()];
        let oct = (d[0] < 0.0) as usize | ((d[1] < 0.0) as usize) << 1 | ((d[2] < 0.0) as usize) << 2;
        let o = &octants[oct];
        let (b0, b1) = (o.box0, o.box1);
        let t_in = fmax(fmax(b0[0] * s[0], b0[1] * s[1]), b0[2] * s[2]);
        let t_out = fmin(fmin(b1[0] * s[0], b1[1] * s[1]), b1[2] * s[2]);
        // Nothing is entered before t_lo: the state after every crossing at t < t_lo; else
        // the state after every crossing at t ≤ t_in.
        let t_lo = ray.t_lo;
        let t0 = if t_lo > t_in && t_lo > 0.0 { t_lo } else { next_up(t_in) };
        for a in 0..3 {
            (ray.h[a], ray.tn[a]) = start_cell(o.pl[a], s[a], ad[a], inv_r, t0);
        }
        ray.ad = ad;
        ray.t_in = t_in;
        ray.t_out = t_out;
        ray.oct = oct as u8;
    }

    /// The [`Octant`] of direction-sign pattern `m` (bit a set: the ray moves down axis a).
    pub(super) fn octant<'v>(&self, vp: &'v ViewPlanes, m: usize) -> Octant<'v> {
        let ny = self.dims[1];
        let rb = self.set.row_words() * 64;
        let fs = self.strides;
        let bs = [ny * rb, rb, 1];
        let neg = |a: usize| m >> a & 1 == 1;
        let step = |s: [usize; 3], a: usize| if neg(a) { s[a].wrapping_neg() } else { s[a] };
        let base = |s: [usize; 3]| (0..3).filter(|&a| neg(a)).map(|a| (self.dims[a] - 1) * s[a]).sum();
        let pl: [&[f64]; 3] =
            std::array::from_fn(|a| if neg(a) { &vp.mirror[a][..] } else { &vp.planes[a][..] });
        Octant {
            pl,
            box0: std::array::from_fn(|a| pl[a][0]),
            box1: std::array::from_fn(|a| pl[a][self.dims[a]]),
            past_range: next_up(self.max_range),
            fstep: std::array::from_fn(|a| step(fs, a)),
            fbase: base(fs),
            bstep: std::array::from_fn(|a| step(bs, a)),
            bbase: base(bs),
        }
    }

    /// [`InverseCaster::first_hit_cell`] for a ray with no zero direction component in
    /// octant `o`, in cheaper bookkeeping: the bitmap bit of the hit, a miss, or
    /// [`Cast::General`] where the walk starts in the camera's cell (the caller falls back).
    ///
    /// Exactness (the same cells visited in the same order, so the same answer):
    /// - An axis the ray moves down (d < 0) is walked in mirrored coordinates — cell
    ///   h = n − 1 − g, planes `P[j] = −p[n − j]` ([`ViewPlanes`]), s = 1/(−d) — so every axis
    ///   steps +1. IEEE division and multiplication are symmetric in sign, so s = −(1/d) and
    ///   each crossing time `P[j]·s` equals the original `p[n − j]·(1/d)` bit for bit: the walk
    ///   sees the same times and compares them in the same tie order.
    /// - The start state "after every crossing at t ≤ t_in" is the state after every crossing
    ///   at t < next_up(t_in); [`start_cell`] finds the same unique cell as [`cell_at`].
    /// - Instead of testing `t > max_range` and leaving the grid separately, a step stops when
    ///   its crossing time reaches `min(t_out, next_up(max_range))`, t_out the exit time of
    ///   the grid box. Before t_out no crossing leaves the grid (crossing times are monotone in
    ///   the plane index), so the walks agree; at the first crossing at t ≥ t_out the exit
    ///   axis is already in its last layer (its previous plane is crossed strictly earlier),
    ///   which is the empty margin, so from there the original walk only visits empty cells
    ///   until it leaves the grid: a miss either way.
    /// - Leaps are those of `first_hit_cell`, mirrored the same way.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn cast(&self, o: &Octant<'_>, ray: &Ray, inv_r: f64) -> Cast {
        let tmax = self.max_range;
        let [px, py, pz] = o.pl;
        let (ad, [sx, sy, sz]) = (ray.ad, ray.s);
        let (t_in, t_out, t_lo) = (ray.t_in, ray.t_out, ray.t_lo);
        if t_in >= t_out || t_out <= 0.0 || t_in > tmax || t_lo >= t_out || t_lo > tmax {
            return Cast::Miss;
        }
        if t_in < 0.0 && t_lo <= 0.0 {
            return Cast::General; // starts in the camera's cell
        }
        let ([mut hx, mut hy, mut hz], [mut tx, mut ty, mut tz]) = (ray.h, ray.tn);
        let lim = fmin(t_out, o.past_range);
        let [fx, fy, fz] = o.fstep;
        let at = |base: usize, st: [usize; 3], h: [usize; 3]| {
            base.wrapping_add(h[0].wrapping_mul(st[0]))
                .wrapping_add(h[1].wrapping_mul(st[1]))
                .wrapping_add(h[2].wrapping_mul(st[2]))
        };
        let mut idx = at(o.fbase, o.fstep, [hx, hy, hz]);
        let field = &self.field[..];
        loop {
            let dv = field[idx];
            if dv == 0 {
                return Cast::Hit(at(o.bbase, o.bstep, [hx, hy, hz]));
            }
            if dv >= LEAP_MIN {
                let mut h = [hx, hy, hz];
                let mut tn = [tx, ty, tz];
                if !self.leap(&o.pl, [sx, sy, sz], ad, inv_r, (dv - 1) as usize, &mut h, &mut tn) {
                    return Cast::Miss;
                }
                [hx, hy, hz] = h;
                [tx, ty, tz] = tn;
                idx = at(o.fbase, o.fstep, h);
            }
            // One Amanatides–Woo step; ties: z, then y, then x.
            if tz <= ty && tz <= tx {
                if tz >= lim {
                    return Cast::Miss;
                }
                hz += 1;
                tz = pz[hz + 1] * sz;
                idx = idx.wrapping_add(fz);
            } else if ty <= tx {
                if ty >= lim {
                    return Cast::Miss;
                }
                hy += 1;
                ty = py[hy + 1] * sy;
                idx = idx.wrapping_add(fy);
            } else {
                if tx >= lim {
                    return Cast::Miss;
                }
                hx += 1;
                tx = px[hx + 1] * sx;
                idx = idx.wrapping_add(fx);
            }
        }
    }

    /// The leap of [`InverseCaster::first_hit_cell`] in [`InverseCaster::cast`]'s coordinates:
    /// the cells within Chebyshev radius `rad` of `h` are empty; move to the last cell before
    /// the ray leaves that cube. `false` when that is beyond the range.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn leap(
        &self,
        pl: &[&[f64]; 3],
        s: [f64; 3],
        ad: [f64; 3],
        inv_r: f64,
        rad: usize,
        h: &mut [usize; 3],
        tn: &mut [f64; 3],
    ) -> bool {
        let dims = self.dims;
        let mut te = f64::INFINITY;
        for a in 0..3 {
            te = te.min(pl[a][(h[a] + rad + 1).min(dims[a])] * s[a]);
        }
        if te > self.max_range {
            return false;
        }
        for a in 0..3 {
            if rad <= SMALL_LEAP {
                // Short leap: advance crossing by crossing (cheap, no guess).
                while tn[a] < te {
                    h[a] += 1;
                    tn[a] = pl[a][h[a] + 1] * s[a];
                }
            } else {
                h[a] = up_cell(pl[a], s[a], ad[a], inv_r, te, h[a], (h[a] + rad).min(dims[a] - 1));
                tn[a] = pl[a][h[a] + 1] * s[a];
            }
        }
        true
    }

    /// The grid cell of the first S_gt voxel the ray from the view origin along unit `d`
    /// enters, given that no S_gt box is entered before `t_lo` (a lower bound; −∞ if none).
    #[inline]
    pub(super) fn first_hit_cell(&self, vp: &ViewPlanes, d: [f64; 3], t_lo: f64) -> Option<[usize; 3]> {
        let dims = self.dims;
        let pl = &vp.planes;
        let tmax = self.max_range;
        let mut inv = [0.0f64; 3];
        let mut step = [0i8; 3];
        let mut t_in = f64::NEG_INFINITY;
        let mut t_out = f64::INFINITY;
        for a in 0..3 {
            let n = dims[a];
            if d[a] > 0.0 {
                inv[a] = 1.0 / d[a];
                step[a] = 1;
                t_in = t_in.max(pl[a][0] * inv[a]);
                t_out = t_out.min(pl[a][n] * inv[a]);
            } else if d[a] < 0.0 {
                inv[a] = 1.0 / d[a];
                step[a] = -1;
                t_in = t_in.max(pl[a][n] * inv[a]);
                t_out = t_out.min(pl[a][0] * inv[a]);
            } else if !(pl[a][0] <= 0.0 && 0.0 < pl[a][n]) {
                return None; // parallel to this slab and outside it
            } else if d[a].is_nan() {
                return None;
            }
        }
        // The box boundary layer is empty: grazing rays (t_in == t_out) see nothing.
        if t_in >= t_out || t_out <= 0.0 || t_in > tmax || t_lo >= t_out || t_lo > tmax {
            return None;
        }
        let r = self.set.resolution();
        let mut g = [0usize; 3];
        let mut tn = [f64::INFINITY; 3];
        let start_inside = t_in < 0.0 && t_lo <= 0.0;
        let jump = t_lo > t_in && t_lo > 0.0;
        for a in 0..3 {
            let n = dims[a];
            let p = &pl[a];
            g[a] = if step[a] == 0 || start_inside {
                // The cell containing the camera centre: p[g] ≤ 0 < p[g+1].
                camera_cell(p, r, n)
            } else if jump {
                // Nothing is entered before t_lo: the state after every crossing at t < t_lo.
                cell_at::<false>(p, inv[a], step[a], d[a], r, t_lo, 0, n - 1)
            } else {
                // The state after every crossing at t ≤ t_in.
                cell_at::<true>(p, inv[a], step[a], d[a], r, t_in, 0, n - 1)
            };
            tn[a] = next_crossing(p, inv[a], step[a], g[a]);
        }
        let mut idx = g[0] * self.strides[0] + g[1] * self.strides[1] + g[2];
        let field = &self.field[..];
        loop {
            let dv = field[idx];
            if dv == 0 {
                return Some(g);
            }
            if dv >= LEAP_MIN {
                // Cells within Chebyshev radius `rad` of g are empty: go to the last cell
                // before the ray leaves that cube.
                let rad = (dv - 1) as usize;
                let mut te = f64::INFINITY;
                for a in 0..3 {
                    if step[a] > 0 {
                        te = te.min(pl[a][(g[a] + rad + 1).min(dims[a])] * inv[a]);
                    } else if step[a] < 0 {
                        te = te.min(pl[a][g[a].saturating_sub(rad)] * inv[a]);
                    }
                }
                if te > tmax {
                    return None;
                }
                if rad <= SMALL_LEAP {
                    // Short leap: advance each axis crossing by crossing (cheap, no guess).
                    for a in 0..3 {
                        if step[a] > 0 {
                            while tn[a] < te {
                                g[a] += 1;
                                tn[a] = pl[a][g[a] + 1] * inv[a];
                            }
                        } else if step[a] < 0 {
                            while tn[a] < te {
                                g[a] -= 1;
                                tn[a] = pl[a][g[a]] * inv[a];
                            }
                        }
                    }
                } else {
                    for a in 0..3 {
                        let (lo, hi) = match step[a] {
                            1 => (g[a], (g[a] + rad).min(dims[a] - 1)),
                            -1 => (g[a].saturating_sub(rad), g[a]),
                            _ => continue,
                        };
                        g[a] = cell_at::<false>(&pl[a], inv[a], step[a], d[a], r, te, lo, hi);
                        tn[a] = next_crossing(&pl[a], inv[a], step[a], g[a]);
                    }
                }
                idx = g[0] * self.strides[0] + g[1] * self.strides[1] + g[2];
            }
            // One Amanatides–Woo step; ties: z, then y, then x.
            let a = if tn[2] <= tn[1] && tn[2] <= tn[0] {
                2
            } else if tn[1] <= tn[0] {
                1
            } else {
                0
            };
            if tn[a] > tmax {
                return None;
            }
            if step[a] > 0 {
                g[a] += 1;
                if g[a] == dims[a] {
                    return None;
                }
                tn[a] = pl[a][g[a] + 1] * inv[a];
                idx += self.strides[a];
            } else {
                if g[a] == 0 {
                    return None;
                }
                g[a] -= 1;
                tn[a] = pl[a][g[a]] * inv[a];
                idx -= self.strides[a];
            }
        }
    }
}
