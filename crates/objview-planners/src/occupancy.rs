//! A probabilistic occupancy grid (OctoMap-style log-odds voxels) for the classical next-best-view
//! planners, RSE and RSE-Mov ([`crate::rse`]). These planners never see the object, so they build
//! their own map from the depth frames they get: each frame is inserted by casting a ray from
//! the camera centre to every back-projected depth pixel. Voxels the ray passes through get a
//! *miss* update and the voxel containing the end point gets a *hit* update. Space that no ray
//! has reached keeps the prior (p = 0.5), which counts as *unknown*. RSE needs exactly that
//! unknown space.
//!
//! Frames and units: the grid lives in the **object frame**, in normalized object units. It is
//! the axis-aligned cube `[bounds_min, bounds_max]³` (default `[−1, 1]³`, the object's bounding
//! cube) split into `resolution³` cubic voxels (default 64³, voxel size 2/64). Voxel `(i, j, k)`
//! spans `[min + i·s, min + (i+1)·s] × …` on x, y, z; its linear index is `(k·n + j)·n + i`.
//! Only the part of a ray inside the cube is used, and an end point outside the cube records no
//! hit.
//!
//! Insertion follows OctoMap's `insertPointCloud`. First the frame's sets of free and occupied
//! cells are collected, and a cell that is both counts as occupied. Then each cell is updated once
//! (`l ← clamp(l + logit(p_hit or p_miss), logit(clamp_min), logit(clamp_max))`). Collecting the
//! sets in parallel is deterministic: merging takes the maximum of per-cell marks, and that
//! result does not depend on how the pixels were split among threads.
//!
//! Rays are walked with the exact voxel traversal of Amanatides & Woo (1987) ([`Dda`]). It visits
//! every voxel that the clipped segment passes through, in order, with the parameter interval
//! spent in each.

use std::ops::ControlFlow;
use std::sync::Arc;

use objview_render::Camera;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// All parameters of an [`OccupancyGrid`]. The defaults are those of the RSE planners.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OccupancySettings {
    /// Voxels per axis (default 64).
    pub resolution: usize,
    /// Lower corner of the cube on every axis, object frame (default −1).
    pub bounds_min: f64,
    /// Upper corner of the cube on every axis, object frame (default 1).
    pub bounds_max: f64,
    /// Occupancy probability of a hit update (default 0.7).
    pub prob_hit: f64,
    /// Occupancy probability of a miss update (default 0.4).
    pub prob_miss: f64,
    /// Lower probability clamp (default 0.12).
    pub clamp_min: f64,
    /// Upper probability clamp (default 0.97).
    pub clamp_max: f64,
    /// A voxel is free when p ≤ this (default 0.45); unknown in the open interval above it.
    pub free_max: f64,
    /// A voxel is occupied when p ≥ this (default 0.65); unknown in the open interval below it.
    pub occupied_min: f64,
}

impl Default for OccupancySettings {
    fn default() -> Self {
        OccupancySettings {
            resolution: 64,
            bounds_min: -1.0,
            bounds_max: 1.0,
            prob_hit: 0.7,
            prob_miss: 0.4,
            clamp_min: 0.12,
            clamp_max: 0.97,
            free_max: 0.45,
            occupied_min: 0.65,
        }
    }
}

/// An invalid [`OccupancySettings`] or input (e.g. a depth buffer whose size does not match its
/// intrinsics).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("occupancy grid: {0}")]
pub struct OccupancyError(pub String);

impl OccupancySettings {
    /// Checks that the settings describe a usable grid. The resolution must be 1…1024 and the
    /// bounds finite with min < max. All probabilities must lie strictly inside (0, 1), with
    /// clamp_min < clamp_max and free_max < occupied_min.
    pub fn validate(&self) -> Result<(), OccupancyError> {
        let bad = |m: String| Err(OccupancyError(m));
        if self.resolution == 0 || self.resolution > 1024 {
            return bad(format!("resolution must be in 1..=1024, got {}", self.resolution));
        }
        if !(self.bounds_min.is_finite() && self.bounds_max.is_finite() && self.bounds_min < self.bounds_max)
        {
            return bad(format!(
                "bounds must be finite with min < max, got [{}, {}]",
                self.bounds_min, self.bounds_max
            ));
        }
        for (name, p) in [
            ("prob_hit", self.prob_hit),
            ("prob_miss", self.prob_miss),
            ("clamp_min", self.clamp_min),
            ("clamp_max", self.clamp_max),
            ("free_max", self.free_max),
            ("occupied_min", self.occupied_min),
        ] {
            if !(p > 0.0 && p < 1.0) {
                return bad(format!("{name} must be a probability in (0, 1), got {p}"));
            }
        }
        if self.clamp_min >= self.clamp_max {
            return bad(format!("clamp_min {} must be below clamp_max {}", self.clamp_min, self.clamp_max));
        }
        if self.free_max >= self.occupied_min {
            return bad(format!(
                "free_max {} must be below occupied_min {} (the unknown band is between them)",
                self.free_max, self.occupied_min
            ));
        }
        Ok(())
    }
}

/// ⌊x⌋ as i64 (saturating; NaN → 0) without a libm call (the baseline x86-64 target has no
/// rounding instruction).
#[inline(always)]
pub fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t - 1
    } else {
        t
    }
}

/// Log-odds of a probability: ln(p / (1 − p)).
#[inline]
pub fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// Probability of a log-odds value: 1 / (1 + e^(−l)).
#[inline]
pub fn probability(l: f64) -> f64 {
    1.0 / (1.0 + (-l).exp())
}

/// Binary entropy in nats: H(p) = −p ln p − (1 − p) ln(1 − p); 0 at p ∈ {0, 1}.
#[inline]
pub fn entropy(p: f64) -> f64 {
    let term = |x: f64| if x > 0.0 { -x * x.ln() } else { 0.0 };
    term(p) + term(1.0 - p)
}

/// The three voxel states of the planners.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VoxelState {
    /// p ≤ free_max.
    Free,
    /// free_max < p < occupied_min (the prior 0.5 included).
    Unknown,
    /// p ≥ occupied_min.
    Occupied,
}

/// Per-frame cell marks, as bits ORed together (the merge ORs too): a cell with
/// [`MARK_OCCUPIED`] set is occupied whatever else passed through it, else one with
/// [`MARK_FREE`] is free.
const MARK_NONE: u8 = 0;
const MARK_FREE: u8 = 1;
const MARK_OCCUPIED: u8 = 2;

/// What one inserted frame did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InsertStats {
    /// Valid (finite, positive) depth pixels, i.e. rays cast.
    pub rays: usize,
    /// Cells that got a miss update.
    pub free_cells: usize,
    /// Cells that got a hit update.
    pub occupied_cells: usize,
}

/// The geometry of a cubic voxel grid (no contents): resolution, lower corner, voxel size, and
/// the coordinates of its boundary planes.
#[derive(Debug, Clone, PartialEq)]
pub struct GridGeometry {
    /// Voxels per axis.
    pub n: usize,
    /// Lower corner (all three axes), object frame.
    pub lo: f64,
    /// Upper corner (all three axes), object frame.
    pub hi: f64,
    /// Voxel edge length.
    pub voxel: f64,
    /// Boundary plane j (0 ≤ j ≤ n) at `lo + j · voxel`, tabulated (see [`GridGeometry::plane`]).
    planes: Arc<[f64]>,
}

impl GridGeometry {
    /// The geometry of `settings` (which should be valid).
    pub fn new(settings: &OccupancySettings) -> GridGeometry {
        let n = settings.resolution;
        let (lo, hi) = (settings.bounds_min, settings.bounds_max);
        let voxel = (hi - lo) / n as f64;
        let planes = (0..=n).map(|j| lo + j as f64 * voxel).collect();
        GridGeometry { n, lo, hi, voxel, planes }
    }

    /// Number of voxels, n³.
    pub fn len(&self) -> usize {
        self.n * self.n * self.n
    }

    /// True for an empty grid (never, for a valid geometry).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Linear index of voxel (i, j, k).
    #[inline]
    pub fn index(&self, ijk: [usize; 3]) -> usize {
        (ijk[2] * self.n + ijk[1]) * self.n + ijk[0]
    }

    /// Voxel coordinates of a linear index.
    #[inline]
    pub fn coords(&self, idx: usize) -> [usize; 3] {
        [idx % self.n, (idx / self.n) % self.n, idx / (self.n * self.n)]
    }

    /// Coordinate of boundary plane `j` (0 ≤ j ≤ n) on any axis: `lo + j · voxel`, from a table.
    /// Every boundary parameter of the traversal is computed from it the same way (see [`Dda`]).
    #[inline(always)]
    pub fn plane(&self, j: i64) -> f64 {
        self.planes[j as usize]
    }

    /// All boundary planes, j = 0 ..= n.
    pub fn planes(&self) -> &[f64] {
        &self.planes
    }

    /// Centre of voxel (i, j, k), object frame.
    pub fn center(&self, ijk: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.lo + (ijk[a] as f64 + 0.5) * self.voxel)
    }

    /// The voxel containing `p` (closed cube: a point on the upper face belongs to the last
    /// voxel); `None` outside the cube or for non-finite points.
    pub fn voxel_of(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        let mut out = [0usize; 3];
        for a in 0..3 {
            if !(p[a] >= self.lo && p[a] <= self.hi) {
                return None;
            }
            out[a] = (floor_i64((p[a] - self.lo) / self.voxel).max(0) as usize).min(self.n - 1);
        }
        Some(out)
    }

    /// Clips the ray `o + t·d`, t ∈ [t_min, t_max], to the cube (slab method). Returns the
    /// parameter interval inside it, or `None` when it misses the cube or the interval is empty
    /// or a single point.
    #[inline]
    pub fn clip(&self, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (t_min, t_max);
        for a in 0..3 {
            if d[a] == 0.0 {
                if !(o[a] >= self.lo && o[a] <= self.hi) {
                    return None;
                }
            } else {
                let inv = 1.0 / d[a];
                let (mut ta, mut tb) = ((self.lo - o[a]) * inv, (self.hi - o[a]) * inv);
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
            }
        }
        // NaN-safe: a NaN bound fails the comparison.
        if t0 < t1 {
            Some((t0, t1))
        } else {
            None
        }
    }
}

/// The state of an Amanatides–Woo traversal of one clipped ray: the current voxel, the
/// parameter at which the ray leaves it on each axis, and the per-axis directions. Both the
/// generic [`OccupancyGrid::traverse`] and the planners' specialized loops step it the same way.
///
/// Boundary parameters are never accumulated: the crossing of plane `j` on axis `a` is always
/// [`Dda::plane_t`]` = (plane(j) − o_a) · (1 / d_a)`, with plane(j) = [`GridGeometry::plane`].
/// Another routine (e.g. a ray–box test) that uses the same expression agrees with the traversal
/// bit for bit on which voxels the ray passes through and in which order.
#[derive(Debug, Clone, Copy)]
pub struct Dda<'a> {
    /// Current voxel.
    pub ijk: [i64; 3],
    /// Linear index of the current voxel.
    pub idx: i64,
    /// Parameter of the next voxel boundary on each axis (∞ on an axis the ray is parallel to).
    pub t_next: [f64; 3],
    /// 1 / d per axis.
    pub inv: [f64; 3],
    /// Ray origin.
    pub origin: [f64; 3],
    /// −1 or +1 per axis (+1 where d = 0; such an axis is never stepped).
    pub step: [i64; 3],
    /// Linear-index increment of a step on each axis (`step · stride`).
    pub idx_step: [i64; 3],
    /// Parameter where the ray enters the current voxel.
    pub t: f64,
    /// Parameter where the clipped ray ends.
    pub t_end: f64,
    /// Voxel size.
    pub voxel: f64,
    /// The grid's boundary planes ([`GridGeometry::planes`]).
    pub planes: &'a [f64],
}

impl<'a> Dda<'a> {
    /// Starts a traversal of `o + t·d` for t ∈ [t_min, t_max] through the grid `g`; `None`
    /// when the ray misses the cube.
    #[inline]
    pub fn new(g: &'a GridGeometry, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64) -> Option<Dda<'a>> {
        let (t0, t1) = g.clip(o, d, t_min, t_max)?;
        let n = g.n as i64;
        let strides = [1i64, n, n * n];
        let mut dda = Dda {
            ijk: [0; 3],
            idx: 0,
            t_next: [f64::INFINITY; 3],
            inv: [f64::INFINITY; 3],
            origin: o,
            step: [1; 3],
            idx_step: [0; 3],
            t: t0,
            t_end: t1,
            voxel: g.voxel,
            planes: &g.planes,
        };
        for a in 0..3 {
            let p = o[a] + t0 * d[a];
            let mut i = floor_i64((p - g.lo) / g.voxel).clamp(0, n - 1);
            if d[a] != 0.0 {
                let s: i64 = if d[a] > 0.0 { 1 } else { -1 };
                let inv = 1.0 / d[a];
                dda.inv[a] = inv;
                // Bring the index in line with the boundary parameters: the voxel entered last
                // at or before t0 (rounding at the entry point can be off by one either way).
                let t_of = |j: i64| (g.plane(j) - o[a]) * inv;
                let entry = |i: i64| if s > 0 { i } else { i + 1 };
                while (0..n).contains(&(i - s)) && t_of(entry(i)) > t0 {
                    i -= s;
                }
                while (0..n).contains(&(i + s)) && t_of(entry(i + s)) <= t0 {
                    i += s;
                }
                dda.step[a] = s;
                dda.t_next[a] = t_of(entry(i + s));
                dda.idx_step[a] = s * strides[a];
            }
            dda.ijk[a] = i;
        }
        dda.idx = dda.ijk[0] + n * (dda.ijk[1] + n * dda.ijk[2]);
        Some(dda)
    }

    /// Parameter of the crossing of boundary plane `j` on axis `a`.
    #[inline(always)]
    pub fn plane_t(&self, a: usize, j: i64) -> f64 {
        (self.planes[j as usize] - self.origin[a]) * self.inv[a]
    }

    /// The axis whose boundary comes first (ties: lowest axis).
    #[inline(always)]
    pub fn next_axis(&self) -> usize {
        let [tx, ty, tz] = self.t_next;
        if tx <= ty && tx <= tz {
            0
        } else if ty <= tz {
            1
        } else {
            2
        }
    }

    /// Parameter where the ray leaves the current voxel (capped at the end of the ray).
    #[inline(always)]
    pub fn t_exit(&self) -> f64 {
        self.t_next[self.next_axis()].min(self.t_end)
    }

    /// Moves to the next voxel; false when the ray ends in the current one (or would leave the
    /// grid of `n` voxels per axis).
    #[inline(always)]
    pub fn advance(&mut self, n: i64) -> bool {
        let a = self.next_axis();
        let t = self.t_next[a];
        if t >= self.t_end {
            return false;
        }
        let i = self.ijk[a] + self.step[a];
        if !(0..n).contains(&i) {
            return false;
        }
        self.ijk[a] = i;
        self.idx += self.idx_step[a];
        self.t = t;
        // The plane after voxel i in the step direction: i + 1 going up, i going down.
        self.t_next[a] = self.plane_t(a, if self.step[a] > 0 { i + 1 } else { i });
        true
    }
}

/// One voxel visited by [`OccupancyGrid::traverse`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelVisit {
    /// Voxel coordinates.
    pub ijk: [usize; 3],
    /// Linear index.
    pub idx: usize,
    /// Ray parameter where the ray enters the voxel (or starts).
    pub t_enter: f64,
    /// Ray parameter where the ray leaves the voxel (or ends).
    pub t_exit: f64,
}

/// A 3D log-odds occupancy grid over a cube of the object frame (see the module docs).
#[derive(Debug, Clone)]
pub struct OccupancyGrid {
    settings: OccupancySettings,
    geom: GridGeometry,
    log_odds: Vec<f64>,
    l_hit: f64,
    l_miss: f64,
    l_min: f64,
    l_max: f64,
    l_free: f64,
    l_occupied: f64,
}

impl OccupancyGrid {
    /// An all-unknown grid (every voxel at the prior p = 0.5).
    pub fn new(settings: OccupancySettings) -> Result<OccupancyGrid, OccupancyError> {
        settings.validate()?;
        let geom = GridGeometry::new(&settings);
        Ok(OccupancyGrid {
            settings,
            log_odds: vec![0.0; geom.len()],
            geom,
            l_hit: logit(settings.prob_hit),
            l_miss: logit(settings.prob_miss),
            l_min: logit(settings.clamp_min),
            l_max: logit(settings.clamp_max),
            l_free: logit(settings.free_max),
            l_occupied: logit(settings.occupied_min),
        })
    }

    /// Its settings.
    pub fn settings(&self) -> &OccupancySettings {
        &self.settings
    }

    /// Its geometry.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geom
    }

    /// Resets every voxel to the prior.
    pub fn clear(&mut self) {
        self.log_odds.fill(0.0);
    }

    /// Log-odds of every voxel, by linear index.
    pub fn log_odds(&self) -> &[f64] {
        &self.log_odds
    }

    /// Occupancy probability of voxel `idx`.
    pub fn probability(&self, idx: usize) -> f64 {
        probability(self.log_odds[idx])
    }

    /// Sets voxel `idx` to probability `p` (no clamping; for hand-made maps). The state
    /// thresholds are compared in log-odds, so setting exactly `free_max` or `occupied_min`
    /// gives the state of that boundary.
    pub fn set_probability(&mut self, idx: usize, p: f64) {
        self.log_odds[idx] = logit(p);
    }

    /// The state of a log-odds value: free at l ≤ logit(free_max), occupied at
    /// l ≥ logit(occupied_min), unknown in between.
    #[inline]
    pub fn state_of_log_odds(&self, l: f64) -> VoxelState {
        if l <= self.l_free {
            VoxelState::Free
        } else if l >= self.l_occupied {
            VoxelState::Occupied
        } else {
            VoxelState::Unknown
        }
    }

    /// The state of voxel `idx`.
    pub fn state(&self, idx: usize) -> VoxelState {
        self.state_of_log_odds(self.log_odds[idx])
    }

    /// Numbers of (free, unknown, occupied) voxels.
    pub fn state_counts(&self) -> (usize, usize, usize) {
        let mut c = (0, 0, 0);
        for &l in &self.log_odds {
            match self.state_of_log_odds(l) {
                VoxelState::Free => c.0 += 1,
                VoxelState::Unknown => c.1 += 1,
                VoxelState::Occupied => c.2 += 1,
            }
        }
        c
    }

    /// Walks the voxels the ray `o + t·d`, t ∈ [t_min, t_max], passes through inside the cube,
    /// in order (exact Amanatides–Woo traversal). `visit` may stop the walk with
    /// `ControlFlow::Break`.
    pub fn traverse<F>(&self, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64, visit: F)
    where
        F: FnMut(VoxelVisit) -> ControlFlow<()>,
    {
        traverse_geometry(&self.geom, o, d, t_min, t_max, visit)
    }

    /// Inserts one depth frame taken by `camera`. `depth` is camera-frame z, row-major
    /// (`v · width + u`), 0 (or any non-positive or non-finite value) where nothing was hit.
    /// Each valid pixel casts a ray from the camera centre to its back-projected pixel centre.
    pub fn insert_depth(&mut self, camera: &Camera, depth: &[f32]) -> Result<InsertStats, OccupancyError> {
        let k = camera.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        if depth.len() != w * h {
            return Err(OccupancyError(format!(
                "depth buffer has {} values, the {}×{} intrinsics need {}",
                depth.len(),
                w,
                h,
                w * h
            )));
        }
        let origin = camera.center;
        let geom = &self.geom;
        let (marks, rays) = depth
            .par_chunks(w.max(1))
            .enumerate()
            .fold(
                || (vec![MARK_NONE; geom.len()], 0usize),
                |(mut marks, mut rays), (v, row)| {
                    let ends =
                        row.iter().enumerate().filter(|(_, &z)| z.is_finite() && z > 0.0).map(|(u, &z)| {
                            rays += 1;
                            camera.unproject(u as u32, v as u32, z as f64)
                        });
                    mark_segments(geom, &mut marks, origin, ends);
                    (marks, rays)
                },
            )
            .reduce(|| (vec![MARK_NONE; geom.len()], 0usize), merge_marks);
        Ok(self.apply_marks(&marks, rays))
    }

    /// Inserts one "frame" of rays from `origin` to each of `ends` (object frame); see
    /// [`OccupancyGrid::insert_depth`].
    pub fn insert_points(&mut self, origin: [f64; 3], ends: &[[f64; 3]]) -> InsertStats {
        let geom = &self.geom;
        let (marks, rays) = ends
            .par_chunks(1024)
            .fold(
                || (vec![MARK_NONE; geom.len()], 0usize),
                |(mut marks, rays), chunk| {
                    mark_segments(geom, &mut marks, origin, chunk.iter().copied());
                    (marks, rays + chunk.len())
                },
            )
            .reduce(|| (vec![MARK_NONE; geom.len()], 0usize), merge_marks);
        self.apply_marks(&marks, rays)
    }

    fn apply_marks(&mut self, marks: &[u8], rays: usize) -> InsertStats {
        let mut stats = InsertStats { rays, ..InsertStats::default() };
        for (l, &m) in self.log_odds.iter_mut().zip(marks) {
            let delta = if m & MARK_OCCUPIED != 0 {
                stats.occupied_cells += 1;
                self.l_hit
            } else if m & MARK_FREE != 0 {
                stats.free_cells += 1;
                self.l_miss
            } else {
                continue;
            };
            *l = (*l + delta).clamp(self.l_min, self.l_max);
        }
        stats
    }
}

/// [`OccupancyGrid::traverse`] on a bare geometry.
pub fn traverse_geometry<F>(g: &GridGeometry, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64, mut visit: F)
where
    F: FnMut(VoxelVisit) -> ControlFlow<()>,
{
    let Some(mut dda) = Dda::new(g, o, d, t_min, t_max) else {
        return;
    };
    let n = g.n as i64;
    loop {
        let v = VoxelVisit {
            ijk: dda.ijk.map(|i| i as usize),
            idx: dda.idx as usize,
            t_enter: dda.t,
            t_exit: dda.t_exit(),
        };
        if visit(v).is_break() || !dda.advance(n) {
            return;
        }
    }
}

fn merge_marks(mut a: (Vec<u8>, usize), b: (Vec<u8>, usize)) -> (Vec<u8>, usize) {
    for (x, &y) in a.0.iter_mut().zip(&b.0) {
        *x |= y;
    }
    (a.0, a.1 + b.1)
}

/// Rays walked at once by [`mark_segments`].
const LANES: usize = 8;

/// One ray of [`mark_segments`]: its walk and its end point's cell.
struct Lane<'a> {
    dda: Dda<'a>,
    end: Option<usize>,
}

/// [`mark_segment`] for every segment origin → end of `ends`, [`LANES`] walks interleaved.
///
/// A walk is a chain of dependent steps (each crossing time decides the next axis), so one walk
/// at a time leaves the core waiting on that chain; independent walks side by side overlap.
/// Every walk visits exactly the cells of its own [`Dda`], and the marks are ORed, so the result
/// does not depend on the order in which the walks' cells are marked.
fn mark_segments(
    g: &GridGeometry,
    marks: &mut [u8],
    origin: [f64; 3],
    mut ends: impl Iterator<Item = [f64; 3]>,
) {
    let n = g.n as i64;
    let mut lanes: [Option<Lane>; LANES] = std::array::from_fn(|_| None);
    let mut live = 0usize;
    let mut more = true;
    loop {
        if more && live < LANES {
            for slot in lanes.iter_mut().filter(|l| l.is_none()) {
                // The next segment that enters the cube (the others only mark their end).
                *slot = loop {
                    let Some(end) = ends.next() else {
                        more = false;
                        break None;
                    };
                    let d = [end[0] - origin[0], end[1] - origin[1], end[2] - origin[2]];
                    let end_idx = g.voxel_of(end).map(|ijk| g.index(ijk));
                    match Dda::new(g, origin, d, 0.0, 1.0) {
                        Some(dda) => break Some(Lane { dda, end: end_idx }),
                        None => {
                            if let Some(e) = end_idx {
                                marks[e] |= MARK_OCCUPIED;
                            }
                        }
                    }
                };
                if slot.is_none() {
                    break;
                }
                live += 1;
            }
        }
        if live == 0 {
            return;
        }
        for slot in lanes.iter_mut() {
            let Some(lane) = slot else { continue };
            let idx = lane.dda.idx as usize;
            let done = if Some(idx) == lane.end {
                true
            } else {
                marks[idx] |= MARK_FREE;
                !lane.dda.advance(n)
            };
            if done {
                if let Some(e) = lane.end {
                    marks[e] |= MARK_OCCUPIED;
                }
                *slot = None;
                live -= 1;
            }
        }
    }
}

/// Marks the cells of the segment origin → end: the traversed cells before the end point's cell
/// free, the end point's cell (when inside the cube) occupied. One segment at a time, as the
/// marks were made before [`mark_segments`] (kept as the tests' reference).
#[cfg(test)]
fn mark_segment(g: &GridGeometry, marks: &mut [u8], origin: [f64; 3], end: [f64; 3]) {
    let d = [end[0] - origin[0], end[1] - origin[1], end[2] - origin[2]];
    let end_idx = g.voxel_of(end).map(|ijk| g.index(ijk));
    // The traversal of `traverse_geometry`, without building a visit per voxel.
    if let Some(mut dda) = Dda::new(g, origin, d, 0.0, 1.0) {
        let n = g.n as i64;
        loop {
            let idx = dda.idx as usize;
            if Some(idx) == end_idx {
                break;
            }
            if marks[idx] == MARK_NONE {
                marks[idx] = MARK_FREE;
            }
            if !dda.advance(n) {
                break;
            }
        }
    }
    if let Some(e) = end_idx {
        marks[e] = MARK_OCCUPIED;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_geom::Pose;
    use objview_render::Intrinsics;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn grid() -> OccupancyGrid {
        OccupancyGrid::new(OccupancySettings::default()).unwrap()
    }

    /// The voxels of the DDA walk, with their intervals.
    fn walk(g: &GridGeometry, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64) -> Vec<VoxelVisit> {
        let mut out = Vec::new();
        traverse_geometry(g, o, d, t0, t1, |v| {
            out.push(v);
            ControlFlow::Continue(())
        });
        out
    }

    /// Brute force: the distinct voxels (in order) of dense samples along the segment.
    fn sampled(g: &GridGeometry, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64, samples: usize) -> Vec<usize> {
        let mut out: Vec<usize> = Vec::new();
        for s in 0..=samples {
            let t = t0 + (t1 - t0) * s as f64 / samples as f64;
            let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
            // Strictly inside the cube (the segment's clipped part).
            if p.iter().all(|&x| x > g.lo && x < g.hi) {
                if let Some(ijk) = g.voxel_of(p) {
                    let idx = g.index(ijk);
                    if out.last() != Some(&idx) {
                        out.push(idx);
                    }
                }
            }
        }
        out
    }

    #[test]
    fn dda_matches_brute_force_sampling_on_random_rays() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for &n in &[64usize, 7] {
            let settings = OccupancySettings { resolution: n, ..OccupancySettings::default() };
            let g = GridGeometry::new(&settings);
            let mut checked = 0;
            for _ in 0..400 {
                let o: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-3.0..3.0));
                let e: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.5..1.5));
                let d = [e[0] - o[0], e[1] - o[1], e[2] - o[2]];
                let visits = walk(&g, o, d, 0.0, 1.0);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                // Sample spacing ~ voxel/2000 in length.
                let samples = ((len / g.voxel) * 2000.0).ceil() as usize;
                let brute = sampled(&g, o, d, 0.0, 1.0, samples);
                // Voxels crossed for less than two sample spacings may be skipped by sampling.
                let tiny = 2.0 / samples as f64;
                let dda_long: Vec<usize> =
                    visits.iter().filter(|v| v.t_exit - v.t_enter > tiny).map(|v| v.idx).collect();
                let brute_long: Vec<usize> =
                    brute.iter().copied().filter(|i| visits.iter().any(|v| v.idx == *i)).collect();
                assert_eq!(brute.len(), brute_long.len(), "sampling found a voxel the DDA missed");
                // Every long DDA voxel is seen by sampling, in the same order.
                let mut it = brute.iter();
                for idx in &dda_long {
                    assert!(it.any(|b| b == idx), "order/voxel mismatch for ray {o:?} → {e:?}");
                }
                // Intervals tile the clipped segment and each interval's midpoint lies in its voxel.
                if let Some((t0, t1)) = g.clip(o, d, 0.0, 1.0) {
                    assert!((visits[0].t_enter - t0).abs() < 1e-12);
                    assert!((visits.last().unwrap().t_exit - t1).abs() < 1e-12);
                    for w in visits.windows(2) {
                        assert_eq!(w[0].t_exit, w[1].t_enter);
                        // Face neighbours.
                        let dist: usize = (0..3).map(|a| w[0].ijk[a].abs_diff(w[1].ijk[a])).sum();
                        assert_eq!(dist, 1);
                    }
                    for v in &visits {
                        assert!(v.t_exit >= v.t_enter);
                        let tm = 0.5 * (v.t_enter + v.t_exit);
                        let p = [o[0] + tm * d[0], o[1] + tm * d[1], o[2] + tm * d[2]];
                        if v.t_exit - v.t_enter > 1e-9 {
                            assert_eq!(g.voxel_of(p), Some(v.ijk));
                        }
                    }
                    checked += 1;
                } else {
                    assert!(visits.is_empty() && brute.is_empty());
                }
            }
            assert!(checked > 100, "too few rays hit the cube: {checked}");
        }
    }

    #[test]
    fn axis_aligned_ray_visits_one_row() {
        let g = grid();
        let c = g.geometry().center([0, 10, 20]);
        let visits = walk(g.geometry(), [3.0, c[1], c[2]], [-1.0, 0.0, 0.0], 0.0, f64::INFINITY);
        let xs: Vec<usize> = visits.iter().map(|v| v.ijk[0]).collect();
        assert_eq!(xs, (0..64).rev().collect::<Vec<_>>());
        assert!(visits.iter().all(|v| v.ijk[1] == 10 && v.ijk[2] == 20));
        assert!((visits[0].t_enter - 2.0).abs() < 1e-12 && (visits[63].t_exit - 4.0).abs() < 1e-12);
    }

    #[test]
    fn log_odds_updates_and_clamping_on_one_ray() {
        let mut g = grid();
        let geom = g.geometry().clone();
        // A ray along +x through voxel centres, ending in the centre of voxel (40, 32, 32).
        let target = geom.center([40, 32, 32]);
        let origin = [-3.0, target[1], target[2]];
        let hit = geom.index([40, 32, 32]);
        let before = geom.index([39, 32, 32]);
        let behind = geom.index([41, 32, 32]);
        let stats = g.insert_points(origin, &[target]);
        assert_eq!(stats, InsertStats { rays: 1, free_cells: 40, occupied_cells: 1 });
        assert!((g.probability(hit) - 0.7).abs() < 1e-12);
        assert!((g.probability(before) - 0.4).abs() < 1e-12);
        assert_eq!(g.probability(behind), 0.5);
        assert_eq!(g.state(hit), VoxelState::Occupied);
        assert_eq!(g.state(before), VoxelState::Free);
        assert_eq!(g.state(behind), VoxelState::Unknown);
        // Two hits: 0.7² / (0.7² + 0.3²).
        g.insert_points(origin, &[target]);
        assert!((g.probability(hit) - 0.49 / 0.58).abs() < 1e-12, "{}", g.probability(hit));
        // Two misses: 0.4² / (0.4² + 0.6²) = 4/13.
        assert!((g.probability(before) - 4.0 / 13.0).abs() < 1e-12);
        // Hits saturate at 0.97, misses at 0.12.
        for _ in 0..20 {
            g.insert_points(origin, &[target]);
        }
        assert!((g.probability(hit) - 0.97).abs() < 1e-12, "{}", g.probability(hit));
        assert!((g.probability(before) - 0.12).abs() < 1e-12, "{}", g.probability(before));
        // From the clamp, one miss: logit(0.97) + logit(0.4).
        let far = geom.center([50, 32, 32]);
        g.insert_points(origin, &[far]);
        let expected = probability(logit(0.97) + logit(0.4));
        assert!((g.probability(hit) - expected).abs() < 1e-12);
        // 0.97·0.4 / (0.97·0.4 + 0.03·0.6)
        assert!((expected - 0.388 / 0.406).abs() < 1e-12);
    }

    #[test]
    fn hit_wins_over_miss_within_a_frame_and_each_cell_updates_once() {
        let mut g = grid();
        let geom = g.geometry().clone();
        let a = geom.center([20, 32, 32]);
        let b = geom.center([40, 32, 32]);
        let origin = [-3.0, a[1], a[2]];
        // Ray 1 ends at voxel 20; ray 2 passes through it to voxel 40; twice each.
        g.insert_points(origin, &[a, b, a, b]);
        assert!((g.probability(geom.index([20, 32, 32])) - 0.7).abs() < 1e-12);
        assert!((g.probability(geom.index([10, 32, 32])) - 0.4).abs() < 1e-12);
        assert!((g.probability(geom.index([30, 32, 32])) - 0.4).abs() < 1e-12);
        assert!((g.probability(geom.index([40, 32, 32])) - 0.7).abs() < 1e-12);
    }

    #[test]
    fn end_points_outside_the_cube_only_carve() {
        let mut g = grid();
        let geom = g.geometry().clone();
        let c = geom.center([0, 5, 5]);
        let stats = g.insert_points([-3.0, c[1], c[2]], &[[3.0, c[1], c[2]]]);
        assert_eq!(stats.occupied_cells, 0);
        assert_eq!(stats.free_cells, 64);
        assert_eq!(g.state_counts(), (64, 64 * 64 * 64 - 64, 0));
        // A segment that stops before the cube changes nothing.
        let stats = g.insert_points([-3.0, 0.1, 0.1], &[[-2.0, 0.1, 0.1]]);
        assert_eq!((stats.free_cells, stats.occupied_cells), (0, 0));
    }

    #[test]
    fn state_thresholds() {
        let mut g = grid();
        let cases = [
            (0.12, VoxelState::Free),
            (0.4, VoxelState::Free),
            (0.45, VoxelState::Free),
            (0.4501, VoxelState::Unknown),
            (0.5, VoxelState::Unknown),
            (0.6499, VoxelState::Unknown),
            (0.65, VoxelState::Occupied),
            (0.7, VoxelState::Occupied),
        ];
        for (p, s) in cases {
            g.set_probability(0, p);
            assert_eq!(g.state(0), s, "p = {p}");
        }
        // Prior is unknown; a single hit is occupied, a single miss free, one of each unknown.
        let g = grid();
        assert_eq!(g.state(123), VoxelState::Unknown);
        assert_eq!(g.state_of_log_odds(logit(0.7)), VoxelState::Occupied);
        assert_eq!(g.state_of_log_odds(logit(0.4)), VoxelState::Free);
        assert_eq!(g.state_of_log_odds(logit(0.7) + logit(0.4)), VoxelState::Unknown);
        // Custom band.
        let s = OccupancySettings { free_max: 0.3, occupied_min: 0.8, ..OccupancySettings::default() };
        let g = OccupancyGrid::new(s).unwrap();
        assert_eq!(g.state_of_log_odds(logit(0.7)), VoxelState::Unknown);
        assert_eq!(g.state_of_log_odds(logit(0.4)), VoxelState::Unknown);
    }

    #[test]
    fn settings_are_validated() {
        let ok = OccupancySettings::default();
        assert!(ok.validate().is_ok());
        for bad in [
            OccupancySettings { resolution: 0, ..ok },
            OccupancySettings { bounds_min: 1.0, ..ok },
            OccupancySettings { bounds_max: f64::NAN, ..ok },
            OccupancySettings { prob_hit: 1.0, ..ok },
            OccupancySettings { clamp_min: 0.98, ..ok },
            OccupancySettings { free_max: 0.7, ..ok },
        ] {
            assert!(OccupancyGrid::new(bad).is_err(), "{bad:?}");
        }
        let g = OccupancyGrid::new(OccupancySettings { resolution: 10, bounds_min: 0.0, ..ok }).unwrap();
        assert_eq!(g.geometry().voxel, 0.1);
        assert_eq!(g.geometry().voxel_of([0.95, 0.0, 1.0]), Some([9, 0, 9]));
        assert_eq!(g.geometry().voxel_of([-0.01, 0.5, 0.5]), None);
    }

    /// The marks of one segment at a time in order (the insertion before the interleaved
    /// walks): free where a walk passed a cell still unmarked, occupied at each end cell.
    fn marks_one_at_a_time(g: &GridGeometry, origin: [f64; 3], ends: &[[f64; 3]]) -> Vec<u8> {
        let mut marks = vec![MARK_NONE; g.len()];
        for &end in ends {
            mark_segment(g, &mut marks, origin, end);
        }
        marks
    }

    fn classify(m: u8) -> u8 {
        if m & MARK_OCCUPIED != 0 {
            MARK_OCCUPIED
        } else {
            m & MARK_FREE
        }
    }

    #[test]
    fn interleaved_walks_mark_exactly_the_cells_of_one_walk_at_a_time() {
        let geom = grid().geometry().clone();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        // Segments from outside, from inside, ending inside or outside the cube, missing it,
        // along axes and through cell corners (ties between axes), in random counts so that
        // the lanes refill at every phase.
        for case in 0..40 {
            let origin: [f64; 3] = if case % 4 == 0 {
                std::array::from_fn(|_| rng.gen_range(-0.9..0.9))
            } else {
                Pose::from_direction(
                    [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)],
                    3.0,
                )
                .center
            };
            let count = rng.gen_range(0..60);
            let ends: Vec<[f64; 3]> = (0..count)
                .map(|k| match k % 5 {
                    0 => std::array::from_fn(|_| rng.gen_range(-1.5..1.5)),
                    1 => geom.center(std::array::from_fn(|_| rng.gen_range(0..64))),
                    2 => [geom.plane(rng.gen_range(0..65)), geom.plane(rng.gen_range(0..65)), origin[2]],
                    3 => [origin[0] - 6.0, origin[1] + 0.01, origin[2]],
                    _ => std::array::from_fn(|_| rng.gen_range(-1.0..1.0)),
                })
                .collect();
            let expected = marks_one_at_a_time(&geom, origin, &ends);
            let mut got = vec![MARK_NONE; geom.len()];
            mark_segments(&geom, &mut got, origin, ends.iter().copied());
            for (idx, (&m, &want)) in got.iter().zip(&expected).enumerate() {
                assert_eq!(classify(m), want, "case {case}, cell {idx}");
            }
        }
        // A real frame: every cell of the grid as the one-at-a-time walks leave it.
        let mesh = objview_render::bench::icosphere(3);
        let cam = Camera::new(Pose::from_direction([1.0, 0.3, 0.5], 3.0), Intrinsics::default());
        let frame = objview_render::render(&mesh, &cam);
        let k = cam.intrinsics;
        let ends: Vec<[f64; 3]> = (0..k.height)
            .flat_map(|v| (0..k.width).map(move |u| (u, v)))
            .filter_map(|(u, v)| {
                let z = frame.depth[(v * k.width + u) as usize];
                (z.is_finite() && z > 0.0).then(|| cam.unproject(u, v, z as f64))
            })
            .collect();
        let expected = marks_one_at_a_time(&geom, cam.center, &ends);
        let mut g = grid();
        let stats = g.insert_depth(&cam, &frame.depth).unwrap();
        let (mut free, mut occupied) = (0, 0);
        for (idx, &m) in expected.iter().enumerate() {
            let want = match m {
                MARK_OCCUPIED => {
                    occupied += 1;
                    g.l_hit
                }
                MARK_FREE => {
                    free += 1;
                    g.l_miss
                }
                _ => 0.0,
            };
            assert_eq!(g.log_odds()[idx].to_bits(), want.to_bits(), "cell {idx}");
        }
        assert!(occupied > 100 && free > 10_000, "{occupied} occupied, {free} free");
        assert_eq!((stats.free_cells, stats.occupied_cells), (free, occupied));
    }

    #[test]
    fn depth_frame_of_a_sphere_and_thread_determinism() {
        let mesh = objview_render::bench::icosphere(4);
        let cam = Camera::new(Pose::from_direction([1.0, 1.0, 1.0], 3.0), Intrinsics::default());
        let frame = objview_render::render(&mesh, &cam);
        let insert = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut g = grid();
                let stats = g.insert_depth(&cam, &frame.depth).unwrap();
                (g, stats)
            })
        };
        let (g1, s1) = insert(1);
        let (g2, s2) = insert(2);
        assert_eq!(s1, s2);
        assert_eq!(g1.log_odds(), g2.log_odds());
        assert_eq!(s1.rays, frame.depth.iter().filter(|z| **z > 0.0).count());
        let geom = g1.geometry().clone();
        // The near cap is occupied, the space in front of it free, the far side and the centre unknown.
        let d = 1.0 / 3f64.sqrt();
        let near = geom.index(geom.voxel_of([d * 0.99, d * 0.99, d * 0.99]).unwrap());
        let front = geom.index(geom.voxel_of([d * 1.4, d * 1.4, d * 1.4]).unwrap());
        let far = geom.index(geom.voxel_of([-d * 0.99, -d * 0.99, -d * 0.99]).unwrap());
        let centre = geom.index(geom.voxel_of([0.0, 0.0, 0.0]).unwrap());
        assert_eq!(g1.state(near), VoxelState::Occupied);
        assert_eq!(g1.state(front), VoxelState::Free);
        assert_eq!(g1.state(far), VoxelState::Unknown);
        assert_eq!(g1.state(centre), VoxelState::Unknown);
        // Every occupied voxel touches the unit sphere (the surface the points lie on).
        for idx in 0..geom.len() {
            if g1.state(idx) == VoxelState::Occupied {
                let c = geom.center(geom.coords(idx));
                let r = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                assert!((r - 1.0).abs() <= geom.voxel * 0.87 + 0.005, "occupied voxel at radius {r}");
            }
        }
        // A wrong-size buffer is an error.
        let mut g = grid();
        assert!(g.insert_depth(&cam, &frame.depth[1..]).is_err());
    }
}
