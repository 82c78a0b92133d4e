//! Image-space footprints for [`super::GainMap::view_gain`]: conservative projections of
//! boxes, bricks and voxels onto the grid of scoring rays, and the per-row bitsets of rays that
//! already have their first occupied voxel. Kept apart from the scoring loop because the bounds
//! (and their rounding margins) are what makes the splatting exact, and they are easier to
//! check on their own.

use crate::occupancy::floor_i64;

/// ⌈x⌉ as i64 (saturating; NaN → 0), without a libm call.
#[inline(always)]
fn ceil_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) < x {
        t + 1
    } else {
        t
    }
}

/// The image-space footprint of a box, as inclusive ranges of ray indices.
#[derive(Debug, Clone, Copy)]
pub(super) struct Footprint {
    pub(super) u0: usize,
    pub(super) u1: usize,
    pub(super) v0: usize,
    pub(super) v1: usize,
}

/// Per-view projection constants.
pub(super) struct Projector {
    pub(super) fx: f64,
    pub(super) fy: f64,
    pub(super) cx: f64,
    pub(super) cy: f64,
    /// 1 / stride (exact for power-of-two strides; otherwise the margin covers the rounding).
    pub(super) inv_stride: f64,
    pub(super) nu: usize,
    pub(super) nv: usize,
}

impl Projector {
    /// Conservative footprint of the camera-space box centre (x, y, z) ± (ex, ey, ez): the ray
    /// indices whose pixel centres may see it. `None` when it is empty or behind the camera.
    #[inline]
    pub(super) fn footprint(&self, x: f64, y: f64, z: f64, e: [f64; 3]) -> Option<Footprint> {
        if z + e[2] <= 0.0 {
            return None;
        }
        if z <= 4.0 * e[2] {
            // Near or across the camera plane: every ray may see it.
            return Some(Footprint { u0: 0, u1: self.nu - 1, v0: 0, v1: self.nv - 1 });
        }
        // Over the box, 1/z lies in [1/(z + ez), 1/(z − ez)] ⊂ [r·(1 − ez·r), r·(1 + 2·ez·r)]
        // for r = 1/z and ez·r ≤ 1/2 (one division instead of two).
        let r = 1.0 / z;
        let er = e[2] * r;
        let (rl, rh) = (r * (1.0 + 2.0 * er), r * (1.0 - er));
        let lo_q = |m: f64| if m < 0.0 { m * rl } else { m * rh };
        let hi_q = |m: f64| if m > 0.0 { m * rl } else { m * rh };
        // Ray i passes through pixel coordinate stride·i + 0.5; the margin absorbs rounding.
        const MARGIN: f64 = 1e-6;
        let range = |qa: f64, qb: f64, f: f64, c: f64, count: usize| -> Option<(usize, usize)> {
            let a = ceil_i64((f * qa + c - 0.5 - MARGIN) * self.inv_stride).max(0);
            let b = floor_i64((f * qb + c - 0.5 + MARGIN) * self.inv_stride).min(count as i64 - 1);
            (a <= b).then_some((a as usize, b as usize))
        };
        let (u0, u1) = range(lo_q(x - e[0]), hi_q(x + e[0]), self.fx, self.cx, self.nu)?;
        let (v0, v1) = range(lo_q(y - e[1]), hi_q(y + e[1]), self.fy, self.cy, self.nv)?;
        Some(Footprint { u0, u1, v0, v1 })
    }
}

/// The projection of one brick, linearized so that the footprints of its voxels need no
/// division.
#[derive(Debug, Clone, Copy)]
pub(super) struct BrickProjection {
    /// 1 / z at the brick centre.
    r0: f64,
    /// Half widths (u, v) in slope units that contain every voxel of the brick around its
    /// approximate projected centre, including the approximation error.
    margin: [f64; 2],
}

impl Projector {
    /// Linearizes the projection over a brick with camera-space centre (x, y, z) and half
    /// extents `eb`, for voxels of half size `h` (object frame) seen along the camera axes
    /// `axes` (right, down, forward). `None` when the brick comes too close to the camera plane
    /// for the bounds to hold (then voxels are projected exactly).
    #[inline(always)]
    pub(super) fn brick(
        &self,
        x: f64,
        y: f64,
        z: f64,
        eb: [f64; 3],
        h: f64,
        axes: &[[f64; 3]; 3],
    ) -> Option<BrickProjection> {
        // Every point of the brick has depth ≥ zl; voxel centres lie within ±eb of the centre.
        let (zl, zh) = (z - eb[2], z + eb[2]);
        let r0 = 1.0 / z;
        let delta = eb[2] * r0;
        if zl <= 0.0 || delta >= 0.5 {
            return None;
        }
        // r̃ = r0·(2 − z_v·r0) (one Newton step from 1/z) is within r0·δ²/(1 − δ) of 1/z_v.
        let newton = r0 * delta * delta / (1.0 - delta);
        let f = axes[2];
        let m = |c: f64, eb_a: f64, axis: [f64; 3]| {
            // A voxel point at offset δ ∈ [−h, h]³ from the centre c_v (slope q_c = X_c / Z_c)
            // has slope q_c + Σ δ_a (axis_a − q_c f_a) / Z: within h·Σ|axis_a − q_c f_a| / zl of
            // q_c. The sum is convex in q_c, so its largest value over the brick is at an end of
            // the slope range of the voxel centres.
            let (lo, hi) = (c - eb_a, c + eb_a);
            let q_lo = if lo < 0.0 { lo / zl } else { lo / zh };
            let q_hi = if hi > 0.0 { hi / zl } else { hi / zh };
            let w = |q: f64| (0..3).map(|a| (axis[a] - q * f[a]).abs()).sum::<f64>();
            let max_abs = c.abs() + eb_a;
            h * w(q_lo).max(w(q_hi)) / zl + max_abs * newton
        };
        Some(BrickProjection { r0, margin: [m(x, eb[0], axes[0]), m(y, eb[1], axes[1])] })
    }

    /// Conservative footprint of a voxel of a linearized brick, from its camera-space centre.
    #[inline(always)]
    pub(super) fn voxel(&self, b: &BrickProjection, x: f64, y: f64, z: f64) -> Option<Footprint> {
        let r = b.r0 * (2.0 - z * b.r0);
        let (qx, qy) = (x * r, y * r);
        const MARGIN: f64 = 1e-6;
        let range = |q: f64, m: f64, f: f64, c: f64, count: usize| -> Option<(usize, usize)> {
            let a = ceil_i64((f * (q - m) + c - 0.5 - MARGIN) * self.inv_stride).max(0);
            let b = floor_i64((f * (q + m) + c - 0.5 + MARGIN) * self.inv_stride).min(count as i64 - 1);
            (a <= b).then_some((a as usize, b as usize))
        };
        let (u0, u1) = range(qx, b.margin[0], self.fx, self.cx, self.nu)?;
        let (v0, v1) = range(qy, b.margin[1], self.fy, self.cy, self.nv)?;
        Some(Footprint { u0, u1, v0, v1 })
    }
}

/// Whether every ray of a footprint is covered (row bitsets of `words` words).
#[inline]
pub(super) fn covered(bits: &[u64], words: usize, fp: Footprint) -> bool {
    (fp.v0..=fp.v1).all(|v| all_set(&bits[v * words..(v + 1) * words], fp.u0, fp.u1))
}

/// Whether bits `a ..= b` of a row bitset are all set.
#[inline]
fn all_set(words: &[u64], a: usize, b: usize) -> bool {
    let (wa, wb) = (a / 64, b / 64);
    for (w, &word) in words.iter().enumerate().take(wb + 1).skip(wa) {
        let lo = if w == wa { a % 64 } else { 0 };
        let hi = if w == wb { b % 64 } else { 63 };
        let mask = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
        if word & mask != mask {
            return false;
        }
    }
    true
}
