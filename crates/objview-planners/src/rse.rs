//! RSE and RSE-Mov (Delmerico et al. 2018, "A comparison of volumetric information gain metrics
//! for active 3D object reconstruction", *rear side entropy*). These are the classical
//! iterative next-best-view planners of SPEC §5, registered as `rse` and `rse-mov`.
//!
//! Each planner keeps an occupancy grid ([`crate::occupancy`]) in the **object frame**
//! (normalized object units, default 64³ voxels over [−1, 1]³), and every observation's depth
//! frame goes into it. The next view is one of the episode's candidate poses (tammes-360 at radius
//! 3): only those that are feasible in the view space and not yet visited are scored. A candidate
//! is scored by casting rays through every `stride`-th pixel centre of its camera. A ray's gain is
//! Σ visibility × entropy over the *unknown* voxels it crosses before the first occupied voxel,
//! where visibility = Π(1 − p) over the voxels before the current one. It counts only when the
//! ray ends on an occupied voxel right after unknown space, i.e. when it sees the rear side of an
//! observed surface through unexplored space. Rays that leave the grid, or that reach an occupied
//! voxel through free space, count 0. RSE moves to the argmax. RSE-Mov trades gain against travel:
//! utility = (1 − γ)·gain/Σgain − γ·cost/Σcost, with cost the Euclidean distance between camera
//! centres.
//!
//! Performance: a planning step scores up to 360 candidates × 16 384 rays through the 64³ grid,
//! too many for a plain voxel walk per ray (about 2 s on one core). Each step first condenses the
//! grid into a [`GainMap`]: per voxel, 1 − p and H(p) as f32 (all sums are f64), plus the
//! occupied shell in 4×4×4 bricks. [`GainMap::view_gain`] then works in two passes. First, it
//! splats the shell front to back into the candidate's ray grid, which gives every ray's first
//! occupied voxel and the face it enters through. Only rays that enter it from an unknown voxel
//! can count, and mid-episode those are a few dozen per view; only they are walked, skipping
//! through uniform boxes when there are many. Both passes reproduce the walk's decisions
//! exactly, so the fast gain equals the plain sum over rays ([`GainMap::view_gain_plain`]) bit
//! for bit (tested). Candidates are scored in parallel (rayon), and each candidate's sum runs over
//! its rays in a fixed order, so the result does not depend on the thread count.

use std::sync::{Arc, OnceLock};

use objview_episode::{
    Action, Environment, EpisodeContext, ExecutionMode, Family, Observation, Planner, PlannerError,
    StopReason,
};
use objview_geom::Pose;
use objview_render::Camera;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::occupancy::{
    entropy, floor_i64, probability, Dda, GridGeometry, OccupancyGrid, OccupancySettings, VoxelState,
};

/// Which of the two planners.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RseVariant {
    /// `rse`: the candidate with the largest rear-side entropy gain.
    Rse,
    /// `rse-mov`: gain traded against travel distance (weight γ).
    RseMov,
}

/// All parameters of the RSE planners.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RseSettings {
    /// `rse` or `rse-mov`.
    pub variant: RseVariant,
    /// Pixel stride of the scoring rays in u and v (rays through pixel centres u + 0.5 for
    /// u = 0, stride, 2·stride, …; same in v). Default 4 (16 384 rays for 512×512).
    pub stride: u32,
    /// RSE-Mov's movement weight γ ∈ [0, 1] (default 0.7); unused by RSE.
    pub gamma: f64,
    /// The occupancy grid.
    pub occupancy: OccupancySettings,
}

impl RseSettings {
    /// RSE with its defaults.
    pub fn rse() -> RseSettings {
        RseSettings {
            variant: RseVariant::Rse,
            stride: 4,
            gamma: 0.7,
            occupancy: OccupancySettings::default(),
        }
    }

    /// RSE-Mov with its defaults (γ = 0.7).
    pub fn rse_mov() -> RseSettings {
        RseSettings { variant: RseVariant::RseMov, ..RseSettings::rse() }
    }

    /// The method name: `rse` or `rse-mov`.
    pub fn name(&self) -> &'static str {
        match self.variant {
            RseVariant::Rse => "rse",
            RseVariant::RseMov => "rse-mov",
        }
    }

    /// Checks the parameters: stride ≥ 1, γ ∈ [0, 1], valid occupancy settings.
    pub fn validate(&self) -> Result<(), PlannerError> {
        if self.stride == 0 {
            return Err(PlannerError(format!("{}: stride must be at least 1", self.name())));
        }
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(PlannerError(format!(
                "{}: gamma must be in [0, 1], got {}",
                self.name(),
                self.gamma
            )));
        }
        self.occupancy.validate().map_err(|e| PlannerError(format!("{}: {e}", self.name())))
    }
}

/// One voxel of a [`GainMap`]: 1 − p and a state-coded entropy (H(p) > 0 for unknown, 0 for free,
/// −1 for occupied).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
struct Cell {
    q: f32,
    h: f32,
}

const OCCUPIED_H: f32 = -1.0;

/// A read-only snapshot of an [`OccupancyGrid`] condensed for ray scoring.
///
/// - Per voxel, 1 − p and a state-coded entropy, so the traversal loop needs one 8-byte load per
///   voxel.
/// - The occupied *shell*: occupied voxels with at least one face whose neighbour is not
///   occupied (or lies outside the grid), with those open faces, as one 64-bit mask per brick of
///   4×4×4 voxels. A ray's first occupied voxel is always a shell voxel that the ray enters
///   through an open face (see [`GainMap::view_gain`]).
#[derive(Debug, Clone)]
pub struct GainMap {
    geom: GridGeometry,
    cells: Vec<Cell>,
    /// Open faces per voxel (0 unless a shell voxel): bit 2a for the lower face on axis a,
    /// bit 2a + 1 for the upper face.
    open: Vec<u8>,
    /// Bricks per axis (⌈n / 4⌉).
    nb: usize,
    /// Shell voxels of each brick: bit li + 4·lj + 16·lk for local coordinates (li, lj, lk).
    bricks: Vec<u64>,
    /// Voxel-centre coordinate of each layer 0..n (any axis).
    centres: Vec<f64>,
    /// Smallest and largest voxel coordinates of the shell (None without one).
    shell_box: Option<([usize; 3], [usize; 3])>,
    /// Per voxel, the largest R such that the (2R + 1)³ box around it lies inside the grid
    /// (off its boundary layers) and holds only identical voxels: computed when first needed
    /// (see [`GainMap::ray_gain_skipping`]).
    runs: OnceLock<Vec<u8>>,
}

/// Edge of a brick in voxels (a brick's shell is one u64: 4³ = 64 bits).
const BRICK: usize = 4;
const _: () = assert!(BRICK * BRICK * BRICK == 64);
/// Smallest box radius worth a jump in [`GainMap::ray_gain_skipping`].
const MIN_SKIP: i64 = 2;
/// A view with at least this many rays to walk uses [`GainMap::ray_gain_skipping`] (which
/// needs the box radii, computed once per map).
const SKIP_FROM_RAYS: usize = 256;
/// No shell voxel hit by the ray (in [`GainScratch`]).
const NO_HIT: u32 = u32::MAX;
/// Entry-axis code of a ray that starts inside its first occupied voxel (no predecessor).
const NO_PREDECESSOR: u32 = 3;

/// Reusable per-thread buffers of [`GainMap::view_gain_with`] (about 0.5 MB for 128×128 rays),
/// and counts from its last call.
#[derive(Debug, Default, Clone)]
pub struct GainScratch {
    inv: Vec<[f64; 3]>,
    octant: Vec<u8>,
    hit: Vec<u32>,
    covered: Vec<u64>,
    walk: Vec<u32>,
    first_hits: usize,
    walked: usize,
}

impl GainScratch {
    /// Rays of the last view whose first occupied voxel was found by splatting.
    pub fn first_hits(&self) -> usize {
        self.first_hits
    }

    /// Rays of the last view that were walked voxel by voxel (first occupied voxel entered
    /// from an unknown one).
    pub fn walked(&self) -> usize {
        self.walked
    }
}

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

/// Reorders the bits of a brick mask so that bit l' holds bit l' XOR f (f < 64): walking the
/// result upwards walks the brick with the axes selected by f reversed.
#[inline(always)]
fn permute_mask(mut m: u64, f: u32) -> u64 {
    const SWAPS: [(u32, u64); 6] = [
        (1, 0x5555_5555_5555_5555),
        (2, 0x3333_3333_3333_3333),
        (4, 0x0f0f_0f0f_0f0f_0f0f),
        (8, 0x00ff_00ff_00ff_00ff),
        (16, 0x0000_ffff_0000_ffff),
        (32, 0x0000_0000_ffff_ffff),
    ];
    for (shift, mask) in SWAPS {
        if f & shift != 0 {
            m = ((m & mask) << shift) | ((m >> shift) & mask);
        }
    }
    m
}

/// The image-space footprint of a box, as inclusive ranges of ray indices.
#[derive(Debug, Clone, Copy)]
struct Footprint {
    u0: usize,
    u1: usize,
    v0: usize,
    v1: usize,
}

/// Per-view projection constants.
struct Projector {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    /// 1 / stride (exact for power-of-two strides; otherwise the margin covers the rounding).
    inv_stride: f64,
    nu: usize,
    nv: usize,
}

impl Projector {
    /// Conservative footprint of the camera-space box centre (x, y, z) ± (ex, ey, ez): the ray
    /// indices whose pixel centres may see it. `None` when it is empty or behind the camera.
    #[inline]
    fn footprint(&self, x: f64, y: f64, z: f64, e: [f64; 3]) -> Option<Footprint> {
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
struct BrickProjection {
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
    fn brick(
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
    fn voxel(&self, b: &BrickProjection, x: f64, y: f64, z: f64) -> Option<Footprint> {
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

impl GainMap {
    /// Condenses `grid`.
    pub fn new(grid: &OccupancyGrid) -> GainMap {
        let mut last: Option<(f64, Cell)> = None;
        let cells: Vec<Cell> = grid
            .log_odds()
            .iter()
            .map(|&l| {
                // Runs of equal values (the prior, the clamps) are common: reuse the last result.
                if let Some((lv, c)) = last {
                    if lv.to_bits() == l.to_bits() {
                        return c;
                    }
                }
                let p = probability(l);
                let q = (1.0 - p) as f32;
                let c = match grid.state_of_log_odds(l) {
                    VoxelState::Occupied => Cell { q, h: OCCUPIED_H },
                    VoxelState::Free => Cell { q, h: 0.0 },
                    // An unknown voxel has 0 < p < 1; keep its code positive even if H rounds to 0.
                    VoxelState::Unknown => Cell { q, h: (entropy(p) as f32).max(f32::MIN_POSITIVE) },
                };
                last = Some((l, c));
                c
            })
            .collect();
        let geom = grid.geometry().clone();
        let n = geom.n;
        let nb = n.div_ceil(BRICK);
        let occupied = |i: usize, j: usize, k: usize| cells[(k * n + j) * n + i].h < 0.0;
        let mut open = vec![0u8; cells.len()];
        let mut bricks = vec![0u64; nb * nb * nb];
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    if !occupied(i, j, k) {
                        continue;
                    }
                    let c = [i, j, k];
                    let mut bits = 0u8;
                    for a in 0..3 {
                        let mut lower = c;
                        if c[a] == 0 || {
                            lower[a] = c[a] - 1;
                            !occupied(lower[0], lower[1], lower[2])
                        } {
                            bits |= 1 << (2 * a);
                        }
                        let mut upper = c;
                        if c[a] + 1 == n || {
                            upper[a] = c[a] + 1;
                            !occupied(upper[0], upper[1], upper[2])
                        } {
                            bits |= 1 << (2 * a + 1);
                        }
                    }
                    if bits != 0 {
                        open[(k * n + j) * n + i] = bits;
                        let b = ((k / BRICK) * nb + j / BRICK) * nb + i / BRICK;
                        bricks[b] |= 1 << (i % BRICK + BRICK * (j % BRICK) + BRICK * BRICK * (k % BRICK));
                    }
                }
            }
        }
        let centres = (0..n).map(|i| geom.plane(i as i64) + 0.5 * geom.voxel).collect();
        // Bounding box of the shell, in voxel coordinates.
        let mut shell_box: Option<([usize; 3], [usize; 3])> = None;
        for (b, &mask) in bricks.iter().enumerate() {
            if mask != 0 {
                let bc = [b % nb, (b / nb) % nb, b / (nb * nb)];
                let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
                let mut m = mask;
                while m != 0 {
                    let l = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let v = [bc[0] * BRICK + (l & 3), bc[1] * BRICK + (l >> 2 & 3), bc[2] * BRICK + (l >> 4)];
                    for a in 0..3 {
                        lo[a] = lo[a].min(v[a]);
                        hi[a] = hi[a].max(v[a]);
                    }
                }
                shell_box = Some(match shell_box {
                    None => (lo, hi),
                    Some((l0, h0)) => {
                        (std::array::from_fn(|a| l0[a].min(lo[a])), std::array::from_fn(|a| h0[a].max(hi[a])))
                    }
                });
            }
        }
        GainMap { geom, cells, open, nb, bricks, centres, shell_box, runs: OnceLock::new() }
    }

    /// Number of occupied voxels with an open face.
    pub fn shell_len(&self) -> usize {
        self.bricks.iter().map(|m| m.count_ones() as usize).sum()
    }

    /// Rear-side entropy gain of the ray `o + t·d`, t ≥ 0 (see the module docs), by a plain
    /// voxel walk.
    #[inline]
    pub fn ray_gain(&self, o: [f64; 3], d: [f64; 3]) -> f64 {
        let Some(mut dda) = Dda::new(&self.geom, o, d, 0.0, f64::INFINITY) else {
            return 0.0;
        };
        let n = self.geom.n as i64;
        let cells = &self.cells[..];
        let mut acc = 0.0f64;
        let mut vis = 1.0f64;
        let mut prev_unknown = false;
        loop {
            let c = cells[dda.idx as usize];
            if c.h < 0.0 {
                return if prev_unknown { acc } else { 0.0 };
            }
            // Free voxels carry h = 0: they only attenuate.
            acc += vis * c.h as f64;
            vis *= c.q as f64;
            prev_unknown = c.h > 0.0;
            if !dda.advance(n) {
                return 0.0;
            }
        }
    }

    /// Gain of the camera by walking every ray ([`GainMap::ray_gain`]): the sum over the rays
    /// through the pixel centres (u + 0.5, v + 0.5), u, v = 0, stride, 2·stride, …, row by row.
    /// This is the definition; [`GainMap::view_gain`] computes the same number faster.
    pub fn view_gain_plain(&self, camera: &Camera, stride: u32) -> f64 {
        let k = camera.intrinsics;
        let stride = stride.max(1) as usize;
        let mut sum = 0.0;
        for v in (0..k.height).step_by(stride) {
            for u in (0..k.width).step_by(stride) {
                sum += self.ray_gain(camera.center, camera.pixel_ray_object(u, v));
            }
        }
        sum
    }

    /// [`GainMap::view_gain_plain`], computed by first finding each ray's first occupied voxel
    /// and the face it enters through, for all rays at once.
    ///
    /// A ray can only count when its first occupied voxel is entered from an unknown voxel.
    /// The first occupied voxel of every ray comes from splatting the shell voxels in
    /// front-to-back order. For each octant of ray directions, bricks and then the voxels inside
    /// each brick are visited in lexicographic order, every axis running away from the camera.
    /// Along any ray of that octant the traversal indices never decrease in that sense, so this
    /// order agrees with the traversal order of every such ray. The first voxel that a ray–box
    /// test accepts (for a ray not yet covered) is the one the traversal would stop at. The test
    /// uses the traversal's own boundary parameters. Bricks and voxels whose footprint is already
    /// covered are skipped. The box test also gives the entry face, hence the predecessor voxel.
    /// Only rays whose predecessor is unknown are then walked, with [`GainMap::ray_gain`] or, when
    /// a view has many such rays, with its bit-identical variant that skips through boxes of
    /// identical voxels. The sum runs over the rays in the same order, so it equals the plain
    /// sum.
    pub fn view_gain(&self, camera: &Camera, stride: u32) -> f64 {
        self.view_gain_with(camera, stride, &mut GainScratch::default())
    }

    /// [`GainMap::view_gain`] with caller-provided buffers.
    pub fn view_gain_with(&self, camera: &Camera, stride: u32, scratch: &mut GainScratch) -> f64 {
        let k = camera.intrinsics;
        let s = stride.max(1) as usize;
        let (nu, nv) = ((k.width as usize).div_ceil(s), (k.height as usize).div_ceil(s));
        let nr = nu * nv;
        scratch.first_hits = 0;
        scratch.walked = 0;
        let Some((box_lo, box_hi)) = self.shell_box else {
            return 0.0;
        };
        if nr == 0 {
            return 0.0;
        }
        let g = &self.geom;
        let n = g.n;
        let c = camera.center;

        // Rays: 1/d (as the traversal computes it) and the octant of d (bit a set for d_a < 0).
        scratch.inv.clear();
        scratch.octant.clear();
        let proj = Projector { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, inv_stride: 1.0 / s as f64, nu, nv };
        let axes = [camera.right, camera.down, camera.forward];
        // Only rays in the footprint of the shell's bounding box can hit a shell voxel.
        let shell_fp = {
            let lo: [f64; 3] = std::array::from_fn(|a| g.plane(box_lo[a] as i64));
            let hi: [f64; 3] = std::array::from_fn(|a| g.plane(box_hi[a] as i64 + 1));
            let v: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]) - c[a]);
            let h: [f64; 3] = std::array::from_fn(|a| 0.5 * (hi[a] - lo[a]));
            let dot = |r: [f64; 3]| v[0] * r[0] + v[1] * r[1] + v[2] * r[2];
            let ext = |r: [f64; 3]| h[0] * r[0].abs() + h[1] * r[1].abs() + h[2] * r[2].abs();
            let e = axes.map(ext);
            match proj.footprint(dot(axes[0]), dot(axes[1]), dot(axes[2]), e) {
                Some(fp) => fp,
                None => return 0.0,
            }
        };
        let mut octant_rays = [0usize; 8];
        // Per column and row, the camera-frame ray slopes, exactly as `Camera::pixel_ray_object`
        // computes them.
        let qu: Vec<f64> = (0..nu).map(|iu| k.pixel_ray((iu * s) as u32, 0)[0]).collect();
        let qv: Vec<f64> = (0..nv).map(|iv| k.pixel_ray(0, (iv * s) as u32)[1]).collect();
        let (rt, dn, fw) = (camera.right, camera.down, camera.forward);
        scratch.inv.resize(nr, [0.0; 3]);
        // Rays outside the shell's footprint get no octant (never tested).
        scratch.octant.resize(nr, u8::MAX);
        for (iv, &q1) in qv.iter().enumerate().take(shell_fp.v1 + 1).skip(shell_fp.v0) {
            for (iu, &q0) in qu.iter().enumerate().take(shell_fp.u1 + 1).skip(shell_fp.u0) {
                let d: [f64; 3] = std::array::from_fn(|a| q0 * rt[a] + q1 * dn[a] + fw[a]);
                let o = (d[0] < 0.0) as u8 | ((d[1] < 0.0) as u8) << 1 | ((d[2] < 0.0) as u8) << 2;
                scratch.inv[iv * nu + iu] = d.map(|x| if x == 0.0 { f64::INFINITY } else { 1.0 / x });
                scratch.octant[iv * nu + iu] = o;
                octant_rays[o as usize] += 1;
            }
        }
        let words = nu.div_ceil(64);
        scratch.hit.clear();
        scratch.hit.resize(nr, NO_HIT);
        scratch.covered.clear();
        scratch.covered.resize(nv * words, 0);

        // Camera-space offsets of the voxel-centre layers along each axis (summed per voxel),
        // and the camera-space half extents of a voxel and of a brick.
        let col = |a: usize| [axes[0][a], axes[1][a], axes[2][a]];
        let offsets: [Vec<[f64; 3]>; 3] = std::array::from_fn(|a| {
            let m = col(a);
            self.centres.iter().map(|&x| x - c[a]).map(|d| [d * m[0], d * m[1], d * m[2]]).collect()
        });
        let half = |scale: f64| -> [f64; 3] {
            std::array::from_fn(|r| 0.5 * scale * (axes[r][0].abs() + axes[r][1].abs() + axes[r][2].abs()))
        };
        let e_voxel = half(g.voxel);
        let e_brick = half(g.voxel * BRICK as f64);
        // Faces of each layer that face the camera (bits as in `open`).
        let facing: [Vec<u8>; 3] = std::array::from_fn(|a| {
            (0..n as i64)
                .map(|i| {
                    ((c[a] <= g.plane(i)) as u8) << (2 * a) | ((c[a] >= g.plane(i + 1)) as u8) << (2 * a + 1)
                })
                .collect()
        });
        let cam_layer: [i64; 3] = std::array::from_fn(|a| floor_i64((c[a] - g.lo) / g.voxel));
        // Boundary planes relative to the camera, as the traversal computes them.
        let planes: [Vec<f64>; 3] =
            std::array::from_fn(|a| (0..=n as i64).map(|j| g.plane(j) - c[a]).collect());
        let nb = self.nb as i64;

        for oct in 0..8u8 {
            if octant_rays[oct as usize] == 0 {
                continue;
            }
            let up = [oct & 1 == 0, oct & 2 == 0, oct & 4 == 0];
            // Bricks away from the camera along each axis. The camera's own layer and the one
            // behind it are included (rounding); voxels behind the camera fail the box test.
            let brick_range = |a: usize| -> (i64, i64, i64) {
                if up[a] {
                    ((cam_layer[a] - 1).clamp(0, n as i64) / BRICK as i64, nb, 1)
                } else {
                    ((cam_layer[a] + 1).clamp(-1, n as i64 - 1).div_euclid(BRICK as i64), -1, -1)
                }
            };
            let flip = ((!up[0] as u32) * 3) | ((!up[1] as u32) * 12) | ((!up[2] as u32) * 48);
            let (bz0, bz1, sz) = brick_range(2);
            let (by0, by1, sy) = brick_range(1);
            let (bx0, bx1, sx) = brick_range(0);
            let mut bz = bz0;
            while bz != bz1 {
                let mut by = by0;
                while by != by1 {
                    let mut bx = bx0;
                    while bx != bx1 {
                        let bidx = ((bz * nb + by) * nb + bx) as usize;
                        let mask = self.bricks[bidx];
                        bx += sx;
                        if mask == 0 {
                            continue;
                        }
                        let base = [(bx - sx) as usize * BRICK, by as usize * BRICK, bz as usize * BRICK];
                        // Brick footprint: skip it when every ray there already has its hit.
                        let centre_of = |a: usize| {
                            let m = col(a);
                            let x = g.lo + (base[a] as f64 + 0.5 * BRICK as f64) * g.voxel - c[a];
                            [x * m[0], x * m[1], x * m[2]]
                        };
                        let (p0, p1, p2) = (centre_of(0), centre_of(1), centre_of(2));
                        let (bx_, by_, bz_) =
                            (p0[0] + p1[0] + p2[0], p0[1] + p1[1] + p2[1], p0[2] + p1[2] + p2[2]);
                        let Some(fp) = proj.footprint(bx_, by_, bz_, e_brick) else {
                            continue;
                        };
                        let linear = proj.brick(bx_, by_, bz_, e_brick, 0.5 * g.voxel, &axes);
                        if covered(&scratch.covered, words, fp) {
                            continue;
                        }
                        let mut m = permute_mask(mask, flip);
                        while m != 0 {
                            let l = m.trailing_zeros() ^ flip;
                            m &= m - 1;
                            let ijk = [
                                base[0] + (l as usize & 3),
                                base[1] + (l as usize >> 2 & 3),
                                base[2] + (l as usize >> 4),
                            ];
                            let idx = (ijk[2] * n + ijk[1]) * n + ijk[0];
                            // A ray enters its first occupied voxel through an open face that
                            // faces the camera.
                            let faces = facing[0][ijk[0]] | facing[1][ijk[1]] | facing[2][ijk[2]];
                            if faces & self.open[idx] == 0 {
                                continue;
                            }
                            let (o0, o1, o2) =
                                (&offsets[0][ijk[0]], &offsets[1][ijk[1]], &offsets[2][ijk[2]]);
                            let (x, y, z) =
                                (o0[0] + o1[0] + o2[0], o0[1] + o1[1] + o2[1], o0[2] + o1[2] + o2[2]);
                            let fp = match &linear {
                                Some(b) => proj.voxel(b, x, y, z),
                                None => proj.footprint(x, y, z, e_voxel),
                            };
                            let Some(fp) = fp else {
                                continue;
                            };
                            // Entry and exit planes of the box for this octant, relative to the camera.
                            let mut en = [0.0; 3];
                            let mut ex = [0.0; 3];
                            for a in 0..3 {
                                let (pe, px) =
                                    if up[a] { (ijk[a], ijk[a] + 1) } else { (ijk[a] + 1, ijk[a]) };
                                en[a] = planes[a][pe];
                                ex[a] = planes[a][px];
                            }
                            for iv in fp.v0..=fp.v1 {
                                let row_bits = &mut scratch.covered[iv * words..(iv + 1) * words];
                                // Walk the uncovered rays of the footprint, word by word.
                                let (w0, w1) = (fp.u0 / 64, fp.u1 / 64);
                                for (w, word) in row_bits.iter_mut().enumerate().take(w1 + 1).skip(w0) {
                                    let lo = if w == w0 { fp.u0 % 64 } else { 0 };
                                    let hi = if w == w1 { fp.u1 % 64 } else { 63 };
                                    let range = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
                                    let mut todo = !*word & range;
                                    while todo != 0 {
                                        let bit = todo.trailing_zeros() as usize;
                                        todo &= todo - 1;
                                        let ray = iv * nu + w * 64 + bit;
                                        if scratch.octant[ray] != oct {
                                            continue;
                                        }
                                        let inv = scratch.inv[ray];
                                        let te = [en[0] * inv[0], en[1] * inv[1], en[2] * inv[2]];
                                        let tx = [ex[0] * inv[0], ex[1] * inv[1], ex[2] * inv[2]];
                                        let t01 = if tx[1] < tx[0] { tx[1] } else { tx[0] };
                                        let t_out = if tx[2] < t01 { tx[2] } else { t01 };
                                        // Entry axis: the last boundary crossed (ties: the highest
                                        // axis, as the traversal steps the lowest axis first).
                                        let mut axis = 0u32;
                                        let mut t_in = te[0];
                                        if te[1] >= t_in {
                                            axis = 1;
                                            t_in = te[1];
                                        }
                                        if te[2] >= t_in {
                                            axis = 2;
                                            t_in = te[2];
                                        }
                                        if t_in < t_out && t_out > 0.0 {
                                            let code = if t_in > 0.0 { axis } else { NO_PREDECESSOR };
                                            scratch.hit[ray] = (idx as u32) << 2 | code;
                                            *word |= 1 << bit;
                                        }
                                    }
                                }
                            }
                        }
                    }
                    by += sy;
                }
                bz += sz;
            }
        }

        // Walk the rays whose first occupied voxel is entered from an unknown voxel.
        let strides = [1usize, n, n * n];
        scratch.walk.clear();
        for (ray, &code) in scratch.hit.iter().enumerate() {
            if code == NO_HIT {
                continue;
            }
            scratch.first_hits += 1;
            if code & 3 == NO_PREDECESSOR {
                continue;
            }
            let axis = (code & 3) as usize;
            let idx = (code >> 2) as usize;
            let coord = (idx / strides[axis]) % n;
            // The predecessor lies on the camera side: above on a down-going axis.
            let pred = if scratch.octant[ray] >> axis & 1 == 1 {
                if coord + 1 == n {
                    continue;
                }
                idx + strides[axis]
            } else {
                if coord == 0 {
                    continue;
                }
                idx - strides[axis]
            };
            if self.cells[pred].h > 0.0 {
                scratch.walk.push(ray as u32);
            }
        }
        scratch.walked = scratch.walk.len();
        let runs = (scratch.walk.len() >= SKIP_FROM_RAYS).then(|| self.runs());
        let mut sum = 0.0;
        for &ray in &scratch.walk {
            let (iu, iv) = (ray as usize % nu, ray as usize / nu);
            let d = camera.pixel_ray_object((iu * s) as u32, (iv * s) as u32);
            sum += match runs {
                Some(runs) => self.ray_gain_skipping(c, d, runs),
                None => self.ray_gain(c, d),
            };
        }
        sum
    }

    /// The box radii of [`GainMap::ray_gain_skipping`] (computed on first use).
    fn runs(&self) -> &[u8] {
        self.runs.get_or_init(|| homogeneous_radius(&self.cells, self.geom.n))
    }

    /// [`GainMap::ray_gain`], bit for bit, skipping through boxes of identical voxels. Where the
    /// box of radius R ≥ 2 around the current voxel holds only copies of it (see `runs`), the
    /// ray's exit from the box and the voxel it is in just before are found from the
    /// traversal's own boundary parameters (with its tie rule). The number of voxels it crosses
    /// in the box is then known. The sum is accumulated voxel by voxel in the same order, so the
    /// result is identical.
    fn ray_gain_skipping(&self, o: [f64; 3], d: [f64; 3], runs: &[u8]) -> f64 {
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

    /// [`GainMap::view_gain`] of each camera, in parallel; the result does not depend on the
    /// number of threads.
    pub fn view_gains(&self, cameras: &[Camera], stride: u32) -> Vec<f64> {
        cameras
            .par_iter()
            .map_init(GainScratch::default, |scratch, cam| self.view_gain_with(cam, stride, scratch))
            .collect()
    }
}

/// Whether every ray of a footprint is covered (row bitsets of `words` words).
#[inline]
fn covered(bits: &[u64], words: usize, fp: Footprint) -> bool {
    (fp.v0..=fp.v1).all(|v| all_set(&bits[v * words..(v + 1) * words], fp.u0, fp.u1))
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

/// The index (into `gains`) RSE chooses: the largest gain, ties to the lowest index; `None` when
/// `gains` is empty.
pub fn select_rse(gains: &[f64]) -> Option<usize> {
    argmax(gains.iter().copied())
}

/// The index RSE-Mov chooses: the largest (1 − γ)·gain/Σgain − γ·cost/Σcost (a zero sum drops
/// its term), ties to the lowest index; `None` when empty. `gains` and `costs` have the same
/// length.
pub fn select_rse_mov(gains: &[f64], costs: &[f64], gamma: f64) -> Option<usize> {
    let sg: f64 = gains.iter().sum();
    let sc: f64 = costs.iter().sum();
    let norm = |x: f64, s: f64| if s > 0.0 { x / s } else { 0.0 };
    argmax(gains.iter().zip(costs).map(|(&g, &c)| (1.0 - gamma) * norm(g, sg) - gamma * norm(c, sc)))
}

fn argmax(values: impl Iterator<Item = f64>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, v) in values.enumerate() {
        let better = match best {
            None => true,
            Some((_, b)) => v > b,
        };
        if better {
            best = Some((i, v));
        }
    }
    best.map(|(i, _)| i)
}

/// Euclidean distance between two points.
fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Camera centres closer than this (per coordinate, object units) are the same position.
const SAME_POSITION: f64 = 1e-9;

fn same_position(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= SAME_POSITION)
}

/// The per-episode state.
#[derive(Debug, Clone)]
struct Episode {
    candidates: Arc<Vec<Pose>>,
    cameras: Vec<Camera>,
    feasible: Vec<bool>,
    visited: Vec<bool>,
    grid: OccupancyGrid,
}

/// What the last planning step saw (for diagnostics and tests).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Candidate indices scored (feasible, not visited), increasing.
    pub candidates: Vec<usize>,
    /// Their gains.
    pub gains: Vec<f64>,
    /// Their travel costs from the current camera centre.
    pub costs: Vec<f64>,
    /// The chosen candidate index, if any.
    pub chosen: Option<usize>,
}

/// The RSE / RSE-Mov planner (see the module docs).
#[derive(Debug, Clone)]
pub struct Rse {
    settings: RseSettings,
    episode: Option<Episode>,
    last: StepReport,
}

impl Rse {
    /// A planner with `settings` (checked at [`Planner::reset`]).
    pub fn new(settings: RseSettings) -> Rse {
        Rse { settings, episode: None, last: StepReport::default() }
    }

    /// Its settings.
    pub fn settings(&self) -> &RseSettings {
        &self.settings
    }

    /// The occupancy grid of the current episode, if one was started.
    pub fn grid(&self) -> Option<&OccupancyGrid> {
        self.episode.as_ref().map(|e| &e.grid)
    }

    /// What the last [`Planner::act`] computed.
    pub fn last_step(&self) -> &StepReport {
        &self.last
    }
}

impl Planner for Rse {
    fn name(&self) -> &str {
        self.settings.name()
    }

    fn family(&self) -> Family {
        Family::Classical
    }

    fn execution_mode(&self) -> ExecutionMode {
        ExecutionMode::Iterative
    }

    fn params(&self) -> serde_json::Value {
        let s = &self.settings;
        let mut v = serde_json::json!({
            "stride": s.stride,
            "rays_through": "pixel centres (u + 0.5, v + 0.5), u, v = 0, stride, 2·stride, …",
            "occupancy": s.occupancy,
        });
        if s.variant == RseVariant::RseMov {
            v["gamma"] = serde_json::json!(s.gamma);
            v["cost"] = serde_json::json!("euclidean distance between camera centres");
        }
        v
    }

    fn reset(&mut self, ctx: &EpisodeContext, env: &dyn Environment) -> Result<(), PlannerError> {
        self.settings.validate()?;
        let grid = OccupancyGrid::new(self.settings.occupancy)
            .map_err(|e| PlannerError(format!("{}: {e}", self.settings.name())))?;
        let candidates = ctx.candidates.clone();
        let feasible = env.feasible_mask(&candidates);
        if feasible.len() != candidates.len() {
            return Err(PlannerError(format!(
                "{}: the feasibility mask has {} entries for {} candidates",
                self.settings.name(),
                feasible.len(),
                candidates.len()
            )));
        }
        let cameras = candidates.iter().map(|p| Camera::new(*p, ctx.intrinsics)).collect();
        let visited = vec![false; candidates.len()];
        self.episode = Some(Episode { candidates, cameras, feasible, visited, grid });
        self.last = StepReport::default();
        Ok(())
    }

    fn act(&mut self, obs: &Observation, env: &dyn Environment) -> Result<Action, PlannerError> {
        let name = self.settings.name();
        let ep =
            self.episode.as_mut().ok_or_else(|| PlannerError(format!("{name}: act called before reset")))?;
        let camera = Camera::new(obs.pose, obs.intrinsics);
        ep.grid.insert_depth(&camera, &obs.depth).map_err(|e| PlannerError(format!("{name}: {e}")))?;

        // Visited: moves issued (marked when chosen) and every position the camera has been at.
        for pose in env.history().iter().chain(std::iter::once(&obs.pose)) {
            for (i, c) in ep.candidates.iter().enumerate() {
                if same_position(c.center, pose.center) {
                    ep.visited[i] = true;
                }
            }
        }
        let remaining: Vec<usize> =
            (0..ep.candidates.len()).filter(|&i| ep.feasible[i] && !ep.visited[i]).collect();
        if remaining.is_empty() {
            self.last = StepReport::default();
            return Ok(Action::stop(StopReason::CandidateExhausted));
        }

        let map = GainMap::new(&ep.grid);
        let stride = self.settings.stride;
        let cameras: Vec<Camera> = remaining.iter().map(|&i| ep.cameras[i]).collect();
        let gains = map.view_gains(&cameras, stride);
        let costs: Vec<f64> =
            remaining.iter().map(|&i| distance(obs.pose.center, ep.candidates[i].center)).collect();
        let pick = match self.settings.variant {
            RseVariant::Rse => select_rse(&gains),
            RseVariant::RseMov => select_rse_mov(&gains, &costs, self.settings.gamma),
        };
        let Some(pick) = pick else {
            return Ok(Action::stop(StopReason::CandidateExhausted));
        };
        let chosen = remaining[pick];
        ep.visited[chosen] = true;
        self.last = StepReport { candidates: remaining, gains, costs, chosen: Some(chosen) };
        Ok(Action::move_to(&ep.candidates[chosen]))
    }
}

/// Reference (slow, straightforward) ray gain in f64 on the grid itself, for tests of
/// [`GainMap::ray_gain`].
#[cfg(test)]
fn reference_ray_gain(grid: &OccupancyGrid, o: [f64; 3], d: [f64; 3]) -> f64 {
    let mut acc = 0.0;
    let mut vis = 1.0;
    let mut prev = None;
    let mut result = 0.0;
    grid.traverse(o, d, 0.0, f64::INFINITY, |v| {
        use std::ops::ControlFlow;
        let p = grid.probability(v.idx);
        let s = grid.state(v.idx);
        if s == VoxelState::Occupied {
            if prev == Some(VoxelState::Unknown) {
                result = acc;
            }
            return ControlFlow::Break(());
        }
        if s == VoxelState::Unknown {
            acc += vis * entropy(p);
        }
        vis *= 1.0 - p;
        prev = Some(s);
        ControlFlow::Continue(())
    });
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_episode::Budget;
    use objview_render::Intrinsics;
    use objview_views::ViewSet;

    struct MockEnv {
        history: Vec<Pose>,
        feasible: fn(&Pose) -> bool,
    }

    impl Environment for MockEnv {
        fn is_feasible(&self, pose: &Pose) -> bool {
            (self.feasible)(pose)
        }
        fn history(&self) -> &[Pose] {
            &self.history
        }
    }

    fn tammes360() -> Arc<Vec<Pose>> {
        Arc::new(ViewSet::resolve("tammes-360").unwrap().poses(3.0))
    }

    fn start() -> Pose {
        Pose::from_direction([1.0, 1.0, 1.0], 3.0)
    }

    fn ctx(candidates: Arc<Vec<Pose>>) -> EpisodeContext {
        EpisodeContext {
            seed: 0,
            object_id: "sphere".into(),
            view_space: "whole".into(),
            budget: Budget::Auto,
            candidates,
            candidate_set: "tammes-360".into(),
            start_pose: start(),
            intrinsics: Intrinsics::default(),
            oracle: None,
        }
    }

    fn observe(mesh: &objview_geom::Mesh, pose: Pose, step: usize) -> Observation {
        let cam = Camera::new(pose, Intrinsics::default());
        let frame = objview_render::render(mesh, &cam);
        Observation { step, pose, intrinsics: cam.intrinsics, depth: Arc::new(frame.depth), rgb: None }
    }

    fn empty_obs(pose: Pose) -> Observation {
        let k = Intrinsics::default();
        Observation { step: 0, pose, intrinsics: k, depth: Arc::new(vec![0.0; k.num_pixels()]), rgb: None }
    }

    fn grid() -> OccupancyGrid {
        OccupancyGrid::new(OccupancySettings::default()).unwrap()
    }

    #[test]
    fn hand_computed_ray_gains() {
        let mut g = grid();
        let geom = g.geometry().clone();
        let c = geom.center([32, 32, 32]);
        let (o, d) = ([3.0, c[1], c[2]], [-1.0, 0.0, 0.0]);
        let idx = |i: usize| geom.index([i, 32, 32]);
        // All unknown: the ray leaves the grid → 0.
        assert_eq!(GainMap::new(&g).ray_gain(o, d), 0.0);
        g.set_probability(idx(32), 0.7);
        // Voxels 63 … 33 unknown (p = 0.5, H = ln 2), visibility halves each time.
        let ln2 = std::f64::consts::LN_2;
        let expected = ln2 * (2.0 - 2f64.powi(-30));
        let gain = GainMap::new(&g).ray_gain(o, d);
        assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
        assert!((reference_ray_gain(&g, o, d) - expected).abs() < 1e-12);
        // Occupied right after free → 0.
        g.set_probability(idx(33), 0.4);
        assert_eq!(GainMap::new(&g).ray_gain(o, d), 0.0);
        assert_eq!(reference_ray_gain(&g, o, d), 0.0);
        // A free voxel further up only attenuates: voxels 63…41 unknown, 40 free (1 − p = 0.6),
        // 39…33 unknown.
        g.set_probability(idx(33), 0.5);
        g.set_probability(idx(40), 0.4);
        let s = |k: i32| (0..k).map(|m| 0.5f64.powi(m)).sum::<f64>();
        let expected = ln2 * (s(23) + 0.6 * 0.5f64.powi(23) * s(7));
        let gain = GainMap::new(&g).ray_gain(o, d);
        assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
        // The first occupied voxel ends the ray: one further up takes over.
        g.set_probability(idx(50), 0.9);
        let expected = ln2 * s(13);
        let gain = GainMap::new(&g).ray_gain(o, d);
        assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
        // Unknown voxels with p ≠ 0.5 weigh by H(p) and attenuate by 1 − p.
        let mut g = grid();
        g.set_probability(idx(32), 0.97);
        g.set_probability(idx(33), 0.6);
        g.set_probability(idx(34), 0.46);
        let h = entropy;
        let expected = ln2 * s(29) + 0.5f64.powi(29) * (h(0.46) + 0.54 * h(0.6));
        let gain = GainMap::new(&g).ray_gain(o, d);
        assert!((gain - expected).abs() < 1e-6 * expected, "{gain} vs {expected}");
    }

    #[test]
    fn single_occupied_voxel_is_seen_only_by_a_camera_looking_at_it() {
        let mut g = grid();
        let geom = g.geometry().clone();
        g.set_probability(geom.index([32, 32, 32]), 0.9);
        let map = GainMap::new(&g);
        let k = Intrinsics::default();
        let toward = Camera::new(Pose::from_direction([1.0, 0.2, 0.1], 3.0), k);
        let c = toward.center;
        let away =
            Camera::new(Pose { center: c, look_at: [2.0 * c[0], 2.0 * c[1], 2.0 * c[2]], roll: 0.0 }, k);
        let side = Camera::new(Pose { center: c, look_at: [c[0], c[1] + 1.0, c[2]], roll: 0.0 }, k);
        // Stride 1: the voxel (0.031 wide at distance 3, ~6 px) is hit by a few rays.
        let g_toward = map.view_gain(&toward, 1);
        assert!(g_toward > 0.0);
        assert_eq!(map.view_gain(&away, 1), 0.0);
        assert_eq!(map.view_gain(&side, 1), 0.0);
        // Free space around the voxel (toward the camera) kills the gain.
        let mut g2 = g.clone();
        for i in 0..64 {
            for j in 0..64 {
                for kk in 0..64 {
                    let p = geom.center([i, j, kk]);
                    if (i, j, kk) != (32, 32, 32) && p[0] > 0.0 {
                        g2.set_probability(geom.index([i, j, kk]), 0.3);
                    }
                }
            }
        }
        assert_eq!(GainMap::new(&g2).view_gain(&toward, 1), 0.0);
        // Viewed from -x instead, the ray passes unknown space only.
        let behind = Camera::new(Pose::from_direction([-1.0, 0.2, 0.1], 3.0), k);
        assert!(GainMap::new(&g2).view_gain(&behind, 1) > 0.0);
    }

    /// The grid after the start view of the unit sphere.
    fn sphere_after_start() -> (objview_geom::Mesh, OccupancyGrid) {
        let mesh = objview_render::bench::icosphere(4);
        let mut g = grid();
        let cam = Camera::new(start(), Intrinsics::default());
        g.insert_depth(&cam, &objview_render::render(&mesh, &cam).depth).unwrap();
        (mesh, g)
    }

    #[test]
    fn fast_gain_matches_reference_on_a_real_grid() {
        let (_, g) = sphere_after_start();
        let map = GainMap::new(&g);
        let mut positive = 0;
        for dir in [[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0], [1.0, -0.3, 0.2], [-0.2, 0.5, -1.0], [0.0, 0.0, 1.0]]
        {
            let cam = Camera::new(Pose::from_direction(dir, 3.0), Intrinsics::default());
            for v in (0..512).step_by(16) {
                for u in (0..512).step_by(16) {
                    let d = cam.pixel_ray_object(u, v);
                    let fast = map.ray_gain(cam.center, d);
                    let slow = reference_ray_gain(&g, cam.center, d);
                    assert!((fast - slow).abs() <= 1e-5 * slow.abs(), "{fast} vs {slow}");
                    positive += (slow > 0.0) as usize;
                }
            }
        }
        assert!(positive > 100, "{positive}");
    }

    /// A mid-episode grid of the mug: the start view and five more.
    fn mug_grid() -> OccupancyGrid {
        let mesh = objview_geom::synth::build("mug", objview_geom::synth::Detail { segments: 48 }).unwrap();
        let mut g = grid();
        for dir in [
            [1.0, 1.0, 1.0],
            [-1.0, 0.2, 0.3],
            [0.1, -1.0, -0.2],
            [0.3, 0.2, -1.0],
            [0.0, 1.0, -0.1],
            [-0.5, -0.5, 1.0],
        ] {
            let cam = Camera::new(Pose::from_direction(dir, 3.0), Intrinsics::default());
            g.insert_depth(&cam, &objview_render::render(&mesh, &cam).depth).unwrap();
        }
        g
    }

    #[test]
    fn box_radii_are_uniform_boxes_and_skipping_walks_equal_plain_walks() {
        use rand::{Rng, SeedableRng};
        for (name, g) in [("sphere", sphere_after_start().1), ("mug", mug_grid())] {
            let map = GainMap::new(&g);
            let runs = map.runs();
            let geom = g.geometry().clone();
            let n = geom.n;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            // Radii: the box is uniform and off the boundary layers; the bound may be one short
            // of the largest such box (see `homogeneous_radius`), never two.
            let mut big = 0;
            for _ in 0..300 {
                let c: [usize; 3] = std::array::from_fn(|_| rng.gen_range(0..n));
                let idx = geom.index(c);
                let r = runs[idx] as usize;
                let same = |rr: usize| {
                    (0..3).all(|a| c[a] > rr && c[a] + rr + 1 < n)
                        && (c[2] - rr..=c[2] + rr).all(|k| {
                            (c[1] - rr..=c[1] + rr).all(|j| {
                                (c[0] - rr..=c[0] + rr)
                                    .all(|i| map.cells[geom.index([i, j, k])] == map.cells[idx])
                            })
                        })
                };
                if r > 0 {
                    assert!(same(r), "{name}: radius {r} at {c:?} is not uniform");
                }
                assert!(!same(r + 2), "{name}: radius at {c:?} could be {}", r + 2);
                big += (r >= 4) as usize;
            }
            assert!(big > 10, "{name}: {big}");
            // Walks: identical to the plain walk, bit for bit, on rays from the candidates.
            let mut positive = 0;
            for pose in tammes360().iter().step_by(11) {
                let cam = Camera::new(*pose, Intrinsics::default());
                for v in (0..512).step_by(8) {
                    for u in (0..512).step_by(8) {
                        let d = cam.pixel_ray_object(u, v);
                        let plain = map.ray_gain(cam.center, d);
                        let skip = map.ray_gain_skipping(cam.center, d, runs);
                        assert_eq!(plain.to_bits(), skip.to_bits(), "{name}: {u},{v} {plain} vs {skip}");
                        positive += (plain > 0.0) as usize;
                    }
                }
            }
            assert!(positive > 100, "{name}: {positive}");
        }
    }

    #[test]
    fn splatted_view_gain_equals_the_plain_sum_over_rays() {
        let candidates = tammes360();
        for (name, g) in [("sphere", sphere_after_start().1), ("mug", mug_grid())] {
            let map = GainMap::new(&g);
            let mut scratch = GainScratch::default();
            let (mut positive, mut walked, mut hits) = (0, 0, 0);
            for (i, pose) in candidates.iter().enumerate().step_by(7) {
                let cam = Camera::new(*pose, Intrinsics::default());
                let fast = map.view_gain_with(&cam, 4, &mut scratch);
                let plain = map.view_gain_plain(&cam, 4);
                assert_eq!(fast.to_bits(), plain.to_bits(), "{name}, candidate {i}: {fast} vs {plain}");
                positive += (plain > 0.0) as usize;
                walked += scratch.walked();
                hits += scratch.first_hits();
            }
            // The filter is doing its job: after one view about half the rays that reach the
            // sphere see it from behind; mid-episode few rays of the mug are walked.
            let ratio = if name == "mug" { 5 } else { 1 };
            assert!(positive > 10 && walked * ratio < hits, "{name}: {positive} {walked} {hits}");
        }
        // Other strides and an off-centre, rolled camera looking past the object.
        let g = mug_grid();
        let map = GainMap::new(&g);
        let cam = Camera::new(
            Pose { center: [0.4, -2.6, 1.1], look_at: [0.3, 0.2, -0.1], roll: 0.7 },
            Intrinsics::default(),
        );
        for stride in [1, 3, 5] {
            let (fast, plain) = (map.view_gain(&cam, stride), map.view_gain_plain(&cam, stride));
            assert_eq!(fast.to_bits(), plain.to_bits(), "stride {stride}");
        }
        // A camera inside the cube (radius 1.3) and one close to the surface.
        for center in [[0.2, 1.25, 0.3], [0.0, 0.0, 1.05]] {
            let cam =
                Camera::new(Pose { center, look_at: [0.0, 0.0, 0.0], roll: 0.0 }, Intrinsics::default());
            assert_eq!(
                map.view_gain(&cam, 4).to_bits(),
                map.view_gain_plain(&cam, 4).to_bits(),
                "{center:?}"
            );
        }
    }

    #[test]
    fn rse_goes_to_the_far_side_of_a_sphere_and_rse_mov_gamma_0_agrees() {
        let (mesh, _) = sphere_after_start();
        let candidates = tammes360();
        let env = MockEnv { history: vec![start()], feasible: |_| true };
        let obs = observe(&mesh, start(), 0);
        let mut rse = Rse::new(RseSettings::rse());
        rse.reset(&ctx(candidates.clone()), &env).unwrap();
        let Action::Move { pose } = rse.act(&obs, &env).unwrap() else { panic!("RSE stopped") };
        let s = 1.0 / 3f64.sqrt();
        let dot = (pose[0] + pose[1] + pose[2]) * s;
        assert!(dot < 0.0, "RSE chose {pose:?} (dot with the start direction {dot})");
        let report = rse.last_step().clone();
        assert_eq!(report.candidates.len(), 360);
        // Near-side views (within 30° of the start) see the observed cap through free space and
        // only gain from rays past its rim; views near the antipode see the cap from behind
        // through the unknown interior.
        let max = report.gains.iter().cloned().fold(0.0, f64::max);
        for (k, &i) in report.candidates.iter().enumerate() {
            let c = candidates[i].center;
            let cos = (c[0] + c[1] + c[2]) * s / 3.0;
            if cos > 30f64.to_radians().cos() {
                assert!(report.gains[k] < 0.1 * max, "{cos}: {} of {max}", report.gains[k]);
            }
            if cos < -0.9 {
                assert!(report.gains[k] > 0.9 * max, "{cos}: {} of {max}", report.gains[k]);
            }
        }

        let mut mov0 = Rse::new(RseSettings { gamma: 0.0, ..RseSettings::rse_mov() });
        mov0.reset(&ctx(candidates.clone()), &env).unwrap();
        let a0 = mov0.act(&obs, &env).unwrap();
        assert_eq!(a0, Action::Move { pose });
        assert_eq!(mov0.last_step().gains, report.gains);

        // γ = 1: the nearest remaining candidate.
        let mut mov1 = Rse::new(RseSettings { gamma: 1.0, ..RseSettings::rse_mov() });
        mov1.reset(&ctx(candidates.clone()), &env).unwrap();
        mov1.act(&obs, &env).unwrap();
        let r1 = mov1.last_step();
        let nearest = (0..r1.costs.len())
            .min_by(|&a, &b| r1.costs[a].partial_cmp(&r1.costs[b]).unwrap())
            .map(|k| r1.candidates[k]);
        assert_eq!(r1.chosen, nearest);

        // The default γ = 0.7 stays closer than RSE.
        let mut mov = Rse::new(RseSettings::rse_mov());
        mov.reset(&ctx(candidates.clone()), &env).unwrap();
        mov.act(&obs, &env).unwrap();
        let rm = mov.last_step();
        let cost_of = |r: &StepReport| {
            let k = r.candidates.iter().position(|&i| Some(i) == r.chosen).unwrap();
            r.costs[k]
        };
        assert!(cost_of(rm) <= cost_of(&report));
        assert!(rm.gains[rm.candidates.iter().position(|&i| Some(i) == rm.chosen).unwrap()] > 0.0);
    }

    #[test]
    fn selection_rules() {
        assert_eq!(select_rse(&[]), None);
        assert_eq!(select_rse(&[1.0, 3.0, 3.0, 2.0]), Some(1));
        assert_eq!(select_rse(&[0.0, 0.0]), Some(0));
        // Utility: 0.3·g/Σg − 0.7·c/Σc. g = [4, 6], c = [1, 3]: [0.12 − 0.175, 0.18 − 0.525].
        assert_eq!(select_rse_mov(&[4.0, 6.0], &[1.0, 3.0], 0.7), Some(0));
        assert_eq!(select_rse_mov(&[4.0, 6.0], &[1.0, 3.0], 0.0), Some(1));
        // All gains zero: the nearest; all costs zero too: the lowest index.
        assert_eq!(select_rse_mov(&[0.0, 0.0, 0.0], &[2.0, 1.0, 1.0], 0.7), Some(1));
        assert_eq!(select_rse_mov(&[0.0, 0.0], &[0.0, 0.0], 0.7), Some(0));
    }

    #[test]
    fn visited_and_infeasible_candidates_are_skipped_then_exhausted() {
        // Eight candidates; those with z < 0 are infeasible.
        let dirs = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1.0, 1.0, -1.0],
            [1.0, 1.0, 1.0],
        ];
        let candidates: Arc<Vec<Pose>> =
            Arc::new(dirs.iter().map(|d| Pose::from_direction(*d, 3.0)).collect());
        let mut env = MockEnv { history: vec![start()], feasible: |p| p.center[2] >= 0.0 };
        for settings in [RseSettings::rse(), RseSettings::rse_mov()] {
            env.history = vec![start()];
            let mut planner = Rse::new(settings);
            planner.reset(&ctx(candidates.clone()), &env).unwrap();
            let mut chosen = Vec::new();
            // Empty frames: every gain is 0; the planner keeps moving (to new candidates).
            loop {
                let pose = *env.history.last().unwrap();
                match planner.act(&empty_obs(pose), &env).unwrap() {
                    Action::Move { pose } => {
                        let p = Pose::from_array(pose).unwrap();
                        let i = candidates.iter().position(|c| *c == p).unwrap();
                        assert!(!chosen.contains(&i) && candidates[i].center[2] >= 0.0);
                        assert!(planner.last_step().gains.iter().all(|&g| g == 0.0));
                        chosen.push(i);
                        env.history.push(p);
                    }
                    Action::Stop { reason } => {
                        assert_eq!(reason, "candidate_exhausted");
                        break;
                    }
                }
            }
            // Candidate 7 is the start position: visited from the history.
            chosen.sort();
            assert_eq!(chosen, vec![0, 1, 2, 3, 4], "{}", settings.name());
        }
        // A move issued but not yet in the history also counts as visited.
        let env = MockEnv { history: vec![start()], feasible: |_| true };
        let mut planner = Rse::new(RseSettings::rse());
        planner.reset(&ctx(candidates.clone()), &env).unwrap();
        let a = planner.act(&empty_obs(start()), &env).unwrap();
        let b = planner.act(&empty_obs(start()), &env).unwrap();
        assert_ne!(a, b);
        assert_eq!(a, Action::move_to(&candidates[0]));
        assert_eq!(b, Action::move_to(&candidates[1]));
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let mesh = objview_geom::synth::build("mug", objview_geom::synth::Detail { segments: 48 }).unwrap();
        let candidates = tammes360();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut env = MockEnv { history: vec![start()], feasible: |p| p.center[2] >= 0.0 };
                let mut planner = Rse::new(RseSettings::rse_mov());
                planner.reset(&ctx(candidates.clone()), &env).unwrap();
                let mut out = Vec::new();
                for step in 0..3 {
                    let pose = *env.history.last().unwrap();
                    let a = planner.act(&observe(&mesh, pose, step), &env).unwrap();
                    out.push((a.clone(), planner.last_step().clone()));
                    if let Action::Move { pose } = a {
                        env.history.push(Pose::from_array(pose).unwrap());
                    }
                }
                (out, planner.grid().unwrap().log_odds().to_vec())
            })
        };
        let (a, ga) = run(1);
        let (b, gb) = run(2);
        assert_eq!(a, b);
        assert_eq!(ga, gb);
        assert!(a
            .iter()
            .all(|(act, r)| matches!(act, Action::Move { .. }) && r.gains.iter().any(|&g| g > 0.0)));
    }

    #[test]
    fn metadata_and_params() {
        let p = Rse::new(RseSettings::rse());
        assert_eq!(
            (p.name(), p.family(), p.execution_mode()),
            ("rse", Family::Classical, ExecutionMode::Iterative)
        );
        assert!(p.params().get("gamma").is_none());
        assert_eq!(p.params()["stride"], 4);
        assert_eq!(p.params()["occupancy"]["resolution"], 64);
        let m = Rse::new(RseSettings::rse_mov());
        assert_eq!(m.name(), "rse-mov");
        assert_eq!(m.params()["gamma"], 0.7);
        // Invalid settings fail at reset; act before reset is an error.
        let env = MockEnv { history: vec![start()], feasible: |_| true };
        let mut bad = Rse::new(RseSettings { stride: 0, ..RseSettings::rse() });
        assert!(bad.reset(&ctx(tammes360()), &env).is_err());
        let mut fresh = Rse::new(RseSettings::rse());
        assert!(fresh.act(&empty_obs(start()), &env).is_err());
    }
}
