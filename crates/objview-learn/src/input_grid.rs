//! The network input grid of the learned and hybrid planners: a 64³ occupancy grid over
//! `[−1, 1]³` with OctoMap's default sensor model, read out as probabilities in C order.
//!
//! Why a module of its own: every learned planner (NBV-Net, MA-SCVP) and the training-data
//! generator must build *the same* grid from the same observations, or the networks are trained
//! on one input and deployed on another. This module is that one definition.
//!
//! Semantics (those of the reference implementation, which uses OctoMap's defaults; see
//! `../shared/research/learned-baselines.md` §1.4):
//! - resolution `2 / G` (G = 64: 0.03125), cell `x` spans `[−1 + x·s, −1 + (x+1)·s)`;
//! - one observation = one scan: points outside the box (inclusive test, `|p_i| ≤ 1`) are
//!   dropped entirely (they carve nothing); for every kept point the cells on the ray from the
//!   camera origin to the point are *free*, the point's own cell is *occupied*; a cell that is
//!   both in one scan is occupied; each cell is updated once per scan;
//! - log-odds: hit `+logit(0.7)`, miss `+logit(0.4)`, clamped to
//!   `[logit(0.1192), logit(0.971)]`, initial 0 (p = 0.5, unknown);
//! - read-out: `p = 1 / (1 + e^(−L))` as f32, index `(x·G + y)·G + z` (x outermost), so a
//!   NumPy array of shape `[G, G, G]` is indexed `[x, y, z]`.
//!
//! Frames and units: the object frame, normalized object units (the unit ball). Depth frames
//! are back-projected at pixel centres (`Camera::unproject`); background pixels (depth 0) carve
//! nothing, as in the reference.
//!
//! The ray walk is the exact Amanatides–Woo traversal of
//! [`objview_planners::occupancy::OccupancyGrid`] (the RSE planners' grid), configured with the
//! settings above; only the box filter, the clamps and the read-out order are this module's.

use objview_planners::occupancy::{OccupancyGrid, OccupancySettings};
use objview_render::Camera;

/// OctoMap's default hit probability.
pub const PROB_HIT: f64 = 0.7;
/// OctoMap's default miss probability.
pub const PROB_MISS: f64 = 0.4;
/// OctoMap's default lower clamp.
pub const CLAMP_MIN: f64 = 0.1192;
/// OctoMap's default upper clamp.
pub const CLAMP_MAX: f64 = 0.971;
/// The grid size of the reference networks.
pub const GRID: usize = 64;

/// The input grid (see the module docs).
#[derive(Debug, Clone)]
pub struct InputGrid {
    grid: OccupancyGrid,
}

impl InputGrid {
    /// An empty (all unknown) `n³` grid over `[−1, 1]³`; `n` must be 1…1024.
    pub fn new(n: usize) -> InputGrid {
        let settings = OccupancySettings {
            resolution: n,
            bounds_min: -1.0,
            bounds_max: 1.0,
            prob_hit: PROB_HIT,
            prob_miss: PROB_MISS,
            clamp_min: CLAMP_MIN,
            clamp_max: CLAMP_MAX,
            ..OccupancySettings::default()
        };
        let grid = OccupancyGrid::new(settings).expect("the input grid settings are valid for n in 1..=1024");
        InputGrid { grid }
    }

    /// Cells per axis.
    pub fn size(&self) -> usize {
        self.grid.settings().resolution
    }

    /// Forgets every observation.
    pub fn clear(&mut self) {
        self.grid.clear();
    }

    /// Inserts one depth frame (camera-frame z per pixel, row-major, 0 where nothing was hit)
    /// taken by `camera` (pose in the object frame): every pixel with a finite depth > 0 is
    /// back-projected at its centre; points outside the box are dropped. Returns the number of
    /// points inserted.
    pub fn insert_depth(&mut self, camera: &Camera, depth: &[f32]) -> usize {
        let w = camera.intrinsics.width as usize;
        let mut ends = Vec::new();
        for (i, &z) in depth.iter().enumerate() {
            if z.is_finite() && z > 0.0 {
                let p = camera.unproject((i % w) as u32, (i / w) as u32, z as f64);
                if inside(p) {
                    ends.push(p);
                }
            }
        }
        self.grid.insert_points(camera.center, &ends);
        ends.len()
    }

    /// Inserts one scan of object-frame points seen from `origin` (the reference's training
    /// variant inserts the visible voxel centres of a view this way). Points outside the box
    /// are dropped. Returns the number of points inserted.
    pub fn insert_points(&mut self, origin: [f64; 3], points: &[[f64; 3]]) -> usize {
        let ends: Vec<[f64; 3]> = points.iter().copied().filter(|&p| inside(p)).collect();
        self.grid.insert_points(origin, &ends);
        ends.len()
    }

    /// The occupancy probability of cell `(x, y, z)`.
    pub fn probability(&self, x: usize, y: usize, z: usize) -> f32 {
        let g = self.grid.geometry();
        self.grid.probability(g.index([x, y, z])) as f32
    }

    /// All probabilities, C order `[x][y][z]` (see the module docs).
    pub fn probabilities(&self) -> Vec<f32> {
        let n = self.size();
        let mut out = Vec::with_capacity(n * n * n);
        self.write_probabilities(&mut out);
        out
    }

    /// Appends all probabilities in C order `[x][y][z]` to `out`.
    pub fn write_probabilities(&self, out: &mut Vec<f32>) {
        let n = self.size();
        let g = self.grid.geometry();
        for x in 0..n {
            for y in 0..n {
                for z in 0..n {
                    out.push(self.grid.probability(g.index([x, y, z])) as f32);
                }
            }
        }
    }
}

fn inside(p: [f64; 3]) -> bool {
    p.iter().all(|c| (-1.0..=1.0).contains(c))
}

/// Average-pools a C-order `n³` grid by `factor` (which must divide `n`): each output cell is
/// the mean of its `factor³` block, summed in C order in f64 and rounded once to f32. The 32³
/// networks see the 64³ grid pooled by 2, at training and at deployment alike.
pub fn pool_grid(grid: &[f32], n: usize, factor: usize) -> Vec<f32> {
    assert!(factor >= 1 && n.is_multiple_of(factor) && grid.len() == n * n * n, "pool_grid: bad sizes");
    if factor == 1 {
        return grid.to_vec();
    }
    let m = n / factor;
    let inv = 1.0 / (factor * factor * factor) as f64;
    let mut out = Vec::with_capacity(m * m * m);
    for x in 0..m {
        for y in 0..m {
            for z in 0..m {
                let mut s = 0.0f64;
                for dx in 0..factor {
                    for dy in 0..factor {
                        let row = ((x * factor + dx) * n + y * factor + dy) * n + z * factor;
                        for v in &grid[row..row + factor] {
                            s += *v as f64;
                        }
                    }
                }
                out.push((s * inv) as f32);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use objview_geom::Pose;
    use objview_render::Intrinsics;

    fn logit(p: f64) -> f64 {
        (p / (1.0 - p)).ln()
    }
    fn prob(l: f64) -> f32 {
        (1.0 / (1.0 + (-l).exp())) as f32
    }

    /// A 4³ grid (cell size 0.5) and one ray along +x through the row y = z = 0.25 (cells
    /// y = z = 2): from outside the box to the middle of cell x = 2. By hand: cells x = 0, 1 free,
    /// cell 2 occupied, cell 3 untouched, every other cell unknown.
    #[test]
    fn one_ray_by_hand() {
        let mut g = InputGrid::new(4);
        let n = g.insert_points([-3.0, 0.25, 0.25], &[[0.25, 0.25, 0.25]]);
        assert_eq!(n, 1);
        let miss = prob(logit(0.4));
        let hit = prob(logit(0.7));
        assert_eq!(g.probability(0, 2, 2), miss);
        assert_eq!(g.probability(1, 2, 2), miss);
        assert_eq!(g.probability(2, 2, 2), hit);
        assert_eq!(g.probability(3, 2, 2), 0.5);
        assert_eq!(g.probability(2, 1, 2), 0.5);
        // C order: index (x·4 + y)·4 + z.
        let p = g.probabilities();
        assert_eq!(p[(2 * 4 + 2) * 4 + 2], hit);
        assert_eq!(p[(4 + 2) * 4 + 2], miss, "cell (1, 2, 2)");
        assert_eq!(p.iter().filter(|&&v| v != 0.5).count(), 3);
    }

    /// Occupied wins over free within one scan; each cell is updated once per scan; clamping at
    /// OctoMap's limits after repeated scans.
    #[test]
    fn once_per_scan_occupied_wins_and_clamps() {
        let mut g = InputGrid::new(4);
        // Two rays in one scan: one ends in cell (1,2,2), the other passes through it to (3,2,2).
        g.insert_points([-3.0, 0.25, 0.25], &[[-0.25, 0.25, 0.25], [0.75, 0.25, 0.25]]);
        let hit = prob(logit(0.7));
        let miss = prob(logit(0.4));
        assert_eq!(g.probability(1, 2, 2), hit, "occupied wins over free");
        assert_eq!(g.probability(0, 2, 2), miss, "two rays through one cell: one miss update");
        assert_eq!(g.probability(2, 2, 2), miss);
        assert_eq!(g.probability(3, 2, 2), hit);
        for _ in 0..20 {
            g.insert_points([-3.0, 0.25, 0.25], &[[0.75, 0.25, 0.25]]);
        }
        assert_eq!(g.probability(0, 2, 2), prob(logit(CLAMP_MIN)));
        assert_eq!(g.probability(3, 2, 2), prob(logit(CLAMP_MAX)));
        assert!((g.probability(0, 2, 2) - 0.1192).abs() < 1e-6);
    }

    /// A point outside the box is dropped (no free space carved along its ray).
    #[test]
    fn points_outside_the_box_carve_nothing() {
        let mut g = InputGrid::new(4);
        assert_eq!(g.insert_points([-3.0, 0.25, 0.25], &[[1.5, 0.25, 0.25]]), 0);
        assert!(g.probabilities().iter().all(|&p| p == 0.5));
        // On the boundary (inclusive) it is kept.
        assert_eq!(g.insert_points([-3.0, 0.25, 0.25], &[[1.0, 0.25, 0.25]]), 1);
    }

    /// A depth frame of a camera on the −x axis looking at the origin, every pixel at depth 3
    /// (the plane x = 0): every inserted point lies on x = 0 (cell x = 32 of 64, since cells are
    /// half-open), cells x < 32 on the rays are free, nothing beyond is touched. Pixel centres
    /// of the 8×8, 45° camera sit at (u + 0.5 − 4)·3/9.657 = ±0.16, ±0.47, ±0.78, ±1.09 on the
    /// plane: the outer ring (|·| = 1.09) is outside the box and dropped, 6×6 = 36 points stay.
    #[test]
    fn depth_frame_of_a_plane() {
        let k = Intrinsics::from_fov(8, 8, 45.0, 45.0);
        let pose = Pose::from_direction([-1.0, 0.0, 0.0], 3.0);
        let cam = Camera::new(pose, k);
        let depth = vec![3.0f32; 64];
        let mut g = InputGrid::new(64);
        let n = g.insert_depth(&cam, &depth);
        assert_eq!(n, 36);
        let p = g.probabilities();
        let hit = prob(logit(0.7));
        for x in 0..64 {
            for y in 0..64 {
                for z in 0..64 {
                    let v = p[(x * 64 + y) * 64 + z];
                    if x > 32 {
                        assert_eq!(v, 0.5, "cell ({x},{y},{z}) beyond the plane");
                    }
                    if v == hit {
                        assert_eq!(x, 32);
                    }
                }
            }
        }
        assert_eq!(p.iter().filter(|&&v| v == hit).count(), 36, "6×6 pixels, distinct cells");
    }

    #[test]
    fn pooling_is_the_block_mean() {
        let grid: Vec<f32> = (0..64).map(|i| (i as f32) * 0.25).collect();
        let pooled = pool_grid(&grid, 4, 2);
        assert_eq!(pooled.len(), 8);
        for x in 0..2 {
            for y in 0..2 {
                for z in 0..2 {
                    let mut s = 0.0f64;
                    for dx in 0..2 {
                        for dy in 0..2 {
                            for dz in 0..2 {
                                s += grid[((2 * x + dx) * 4 + 2 * y + dy) * 4 + 2 * z + dz] as f64;
                            }
                        }
                    }
                    assert_eq!(pooled[(x * 2 + y) * 2 + z], (s / 8.0) as f32);
                }
            }
        }
    }
}
