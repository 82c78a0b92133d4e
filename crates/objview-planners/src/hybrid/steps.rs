//! The exact, network-free planning steps the hybrid planners share (reference behaviour:
//! `shared/research/learned-baselines.md` §5.2, §6, §7 steps 2–4):
//!
//! - [`frame_points`] / [`PartialCloud`]: each depth frame back-projected (pixel centres),
//!   clipped to the box [−1, 1]³, appended to the partial cloud, and the union voxel-filtered at
//!   [`PARTIAL_VOXEL`] = 1/64 (one centroid per occupied cell, [`voxel_filter`]);
//! - [`statistical_outlier_removal`]: PCL's StatisticalOutlierRemoval (mean distance to the k
//!   nearest neighbours, points above mean + m·σ dropped), with an exact grid k-NN;
//! - [`box_keys`]: voxelization at [`PLAN_VOXEL`] = 1/32, points in [−1, 1)³ only (the
//!   reference's octomap keys 0..63, here as [`objview_voxel::key_of`] keys −32..31: the same
//!   cells, since 1/r is an integer);
//! - [`PlanningSets`]: target = predicted − observed voxels, occluders = observed ∪ predicted,
//!   and per candidate the target voxels it sees ([`PlanningSets::covers`]) by the `inverse`
//!   rule of `objview-voxel` — the very [`InverseCaster`] the difficulty annotations use, run on
//!   the occluder set (every occluder voxel centre is projected, its pixel's ray walks the
//!   occluder grid and the first occupied voxel counts), then intersected with the target.
//!
//! Why here and not in each planner: the three hybrids must agree on every step, and each step
//! is tested on its own against hand-made or brute-force expectations.

use std::collections::HashMap;

use objview_episode::Observation;
use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use objview_voxel::{key_of, InverseCaster, VoxelKey, VoxelSet, DEFAULT_MAX_RANGE};
use rayon::prelude::*;

/// Voxel-filter leaf of the partial cloud (1/64).
pub const PARTIAL_VOXEL: f64 = 0.015625;
/// Planning voxel (1/32): target, occluders and covers.
pub const PLAN_VOXEL: f64 = 0.03125;
/// Half side of the planning box [−1, 1]³.
pub const BOX_HALF: f64 = 1.0;
/// Neighbours of the statistical outlier removal (PCL mean_k).
pub const SOR_K: usize = 16;
/// Standard-deviation multiplier of the statistical outlier removal.
pub const SOR_STD_MUL: f64 = 1.5;

/// Whether `p` is inside the closed box [−1, 1]³.
fn in_box(p: &[f64; 3]) -> bool {
    p.iter().all(|x| (-BOX_HALF..=BOX_HALF).contains(x))
}

/// The observed points of `obs`: every pixel with a finite depth z > 0 back-projected at its
/// pixel centre (object frame), points outside [−1, 1]³ dropped; row-major pixel order.
pub fn frame_points(obs: &Observation) -> Vec<[f64; 3]> {
    let cam = Camera::new(obs.pose, obs.intrinsics);
    let w = obs.intrinsics.width.max(1) as usize;
    obs.depth
        .iter()
        .enumerate()
        .filter(|(_, z)| z.is_finite() && **z > 0.0)
        .map(|(i, &z)| cam.unproject((i % w) as u32, (i / w) as u32, z as f64))
        .filter(in_box)
        .collect()
}

/// One point per occupied cell of side `leaf` (cells `key_of(p, leaf)`): the centroid of the
/// cell's points, cells in ascending key order (deterministic).
pub fn voxel_filter(points: &[[f64; 3]], leaf: f64) -> Vec<[f64; 3]> {
    let mut cells: HashMap<VoxelKey, ([f64; 3], usize)> = HashMap::new();
    for p in points {
        let e = cells.entry(key_of(*p, leaf)).or_insert(([0.0; 3], 0));
        for (s, x) in e.0.iter_mut().zip(p) {
            *s += x;
        }
        e.1 += 1;
    }
    let mut out: Vec<(VoxelKey, [f64; 3])> =
        cells.into_iter().map(|(k, (s, n))| (k, s.map(|x| x / n as f64))).collect();
    out.sort_unstable_by_key(|e| e.0);
    out.into_iter().map(|e| e.1).collect()
}

/// The partial cloud a hybrid planner keeps: after each frame, `voxel_filter(cloud ∪ frame)`.
#[derive(Debug, Clone, Default)]
pub struct PartialCloud {
    /// The current filtered cloud (object frame).
    pub points: Vec<[f64; 3]>,
}

impl PartialCloud {
    /// Appends the observed points of `obs` and voxel-filters the union at [`PARTIAL_VOXEL`].
    pub fn add(&mut self, obs: &Observation) {
        let mut all = std::mem::take(&mut self.points);
        all.extend(frame_points(obs));
        self.points = voxel_filter(&all, PARTIAL_VOXEL);
    }
}

/// For every point, the mean Euclidean distance to its `k` nearest *other* points (exact; a
/// uniform grid searched ring by ring until no closer point can exist). Fewer than `k + 1`
/// points: all neighbours are used.
pub fn knn_mean_distances(points: &[[f64; 3]], k: usize) -> Vec<f64> {
    let n = points.len();
    if n < 2 || k == 0 {
        return vec![0.0; n];
    }
    let k = k.min(n - 1);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    // About 2·k points per cell on a surface-like cloud.
    let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f64, f64::max).max(1e-9);
    let cell = (extent * ((2 * k) as f64 / n as f64).sqrt()).max(extent / 512.0).max(1e-9);
    let key = |p: &[f64; 3]| -> [i32; 3] { std::array::from_fn(|a| ((p[a] - lo[a]) / cell).floor() as i32) };
    let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    let max_ring = (extent / cell).ceil() as i32 + 1;
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = key(p);
            // The k smallest squared distances so far, ascending.
            let mut best: Vec<f64> = Vec::with_capacity(k + 1);
            let consider = |best: &mut Vec<f64>, j: u32| {
                if j as usize == i {
                    return;
                }
                let q = &points[j as usize];
                let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
                if best.len() < k || d < best[k - 1] {
                    let at = best.partition_point(|&b| b <= d);
                    best.insert(at, d);
                    best.truncate(k);
                }
            };
            for r in 0..=max_ring {
                for dx in -r..=r {
                    for dy in -r..=r {
                        for dz in -r..=r {
                            if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                                continue;
                            }
                            if let Some(cellpts) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                                cellpts.iter().for_each(|&j| consider(&mut best, j));
                            }
                        }
                    }
                }
                // Points in rings > r are at least r·cell away.
                let bound = r as f64 * cell;
                if best.len() == k && best[k - 1] <= bound * bound {
                    break;
                }
            }
            best.iter().map(|d| d.sqrt()).sum::<f64>() / best.len() as f64
        })
        .collect()
}

/// PCL's StatisticalOutlierRemoval: per point the mean distance to its `k` nearest neighbours;
/// with μ and σ (sample standard deviation) of those means, points whose mean exceeds
/// μ + `std_mul`·σ are dropped. Fewer than `k` points → unchanged; if every point would be
/// dropped, the input is kept. Order preserved.
pub fn statistical_outlier_removal(points: &[[f64; 3]], k: usize, std_mul: f64) -> Vec<[f64; 3]> {
    if points.len() < k.max(2) {
        return points.to_vec();
    }
    let d = knn_mean_distances(points, k);
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let threshold = mean + std_mul * var.sqrt();
    let kept: Vec<[f64; 3]> =
        points.iter().zip(&d).filter(|(_, &x)| x <= threshold).map(|(p, _)| *p).collect();
    if kept.is_empty() {
        points.to_vec()
    } else {
        kept
    }
}

/// The planning-voxel keys of `points` inside the box: `key_of(p, PLAN_VOXEL)` with every
/// coordinate in −32..=31 (the reference's octomap keys 0..63 of [−1, 1]³), sorted, unique.
pub fn box_keys(points: &[[f64; 3]]) -> Vec<VoxelKey> {
    let lim = (BOX_HALF / PLAN_VOXEL).round() as i32;
    let mut keys: Vec<VoxelKey> = points
        .iter()
        .filter(|p| p.iter().all(|x| x.is_finite()))
        .map(|p| key_of(*p, PLAN_VOXEL))
        .filter(|k| k.iter().all(|&c| (-lim..lim).contains(&c)))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys
}

/// Target, occluders and candidate covers of one planning step.
#[derive(Debug, Clone)]
pub struct PlanningSets {
    /// observed ∪ predicted voxels: the occluder geometry; its indices number every element.
    pub occluders: VoxelSet,
    /// Bitset over `occluders` indices: the target (predicted − observed).
    pub target: Vec<u64>,
    /// |target|.
    pub target_len: usize,
}

/// Whether bit `i` of `set` is set.
pub fn bit(set: &[u64], i: usize) -> bool {
    set.get(i >> 6).is_some_and(|w| w >> (i & 63) & 1 == 1)
}

impl PlanningSets {
    /// The sets of `observed` and `predicted` planning-voxel keys (any order, duplicates
    /// allowed).
    pub fn new(observed: &[VoxelKey], predicted: &[VoxelKey]) -> PlanningSets {
        let all: Vec<VoxelKey> = observed.iter().chain(predicted).copied().collect();
        let occluders = VoxelSet::from_keys(&all, PLAN_VOXEL).expect("keys of the [-1,1]^3 box fit any grid");
        let mut target = vec![0u64; occluders.len().div_ceil(64)];
        for k in predicted {
            let i = occluders.index_of(*k).expect("a predicted key is an occluder");
            target[i >> 6] |= 1u64 << (i & 63);
        }
        for k in observed {
            let i = occluders.index_of(*k).expect("an observed key is an occluder");
            target[i >> 6] &= !(1u64 << (i & 63));
        }
        let target_len = target.iter().map(|w| w.count_ones() as usize).sum();
        PlanningSets { occluders, target, target_len }
    }

    /// The target voxel keys, ascending.
    pub fn target_keys(&self) -> Vec<VoxelKey> {
        (0..self.occluders.len()).filter(|&i| bit(&self.target, i)).map(|i| self.occluders.key(i)).collect()
    }

    /// Per pose (skipped → empty bitset where `active[i]` is false): the target voxels visible
    /// from it by the `inverse` rule on the occluder grid (range 6.0), as bitsets over occluder
    /// indices. Parallel over poses; result i belongs to `poses[i]`.
    pub fn covers(&self, poses: &[Pose], active: &[bool], intrinsics: Intrinsics) -> Vec<Vec<u64>> {
        let words = self.target.len();
        if self.target_len == 0 {
            // Nothing to see (no occluders, the identity backend, or a prediction inside the
            // observed voxels): every cover is empty, without casting the 360 views.
            return vec![vec![0u64; words]; poses.len()];
        }
        let caster = InverseCaster::with_max_range(&self.occluders, DEFAULT_MAX_RANGE);
        poses
            .par_iter()
            .zip(active)
            .map(|(pose, &on)| {
                if !on {
                    return vec![0u64; words];
                }
                let mut bits = caster.observe_bitset(&Camera::new(*pose, intrinsics));
                for (b, t) in bits.iter_mut().zip(&self.target) {
                    *b &= t;
                }
                bits
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn voxel_filter_takes_centroids_in_key_order() {
        let l = 0.5;
        let pts = [[0.1, 0.1, 0.1], [0.3, 0.2, 0.4], [-0.1, 0.0, 0.0], [0.2, 0.0, 0.1], [-0.2, 0.0, 0.0]];
        let f = voxel_filter(&pts, l);
        // Cells: [-1,0,0] ← points 2, 4; [0,0,0] ← points 0, 1, 3.
        assert_eq!(f.len(), 2);
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-15);
        assert!(close(f[0], [-0.15, 0.0, 0.0]), "{:?}", f[0]);
        assert!(close(f[1], [0.2, 0.1, 0.2]), "{:?}", f[1]);
    }

    #[test]
    fn knn_means_match_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (n, k) in [(1usize, 16usize), (5, 16), (300, 16), (900, 4)] {
            // Points on a sphere shell plus a few far ones (uneven density).
            let mut pts: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let v: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
                    let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
                    v.map(|x| x / r * 0.7)
                })
                .collect();
            pts.extend([[3.0, 0.0, 0.0], [0.0, -2.5, 1.0]]);
            let got = knn_mean_distances(&pts, k);
            for (i, p) in pts.iter().enumerate() {
                let mut d: Vec<f64> = pts
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, q)| {
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                    })
                    .collect();
                d.sort_by(f64::total_cmp);
                d.truncate(k);
                let want = d.iter().sum::<f64>() / d.len() as f64;
                assert!((got[i] - want).abs() < 1e-12, "n {n} k {k} point {i}: {} vs {want}", got[i]);
            }
        }
    }

    #[test]
    fn sor_drops_exactly_the_planted_outliers() {
        // A dense 20×20 grid on the plane z = 0 (spacing 0.01) and 5 planted outliers far off it.
        let mut pts: Vec<[f64; 3]> =
            (0..400).map(|i| [(i % 20) as f64 * 0.01, (i / 20) as f64 * 0.01, 0.0]).collect();
        let outliers =
            [[0.1, 0.1, 0.5], [0.5, 0.5, 0.5], [-0.4, 0.1, 0.0], [0.1, -0.3, -0.2], [0.9, 0.9, 0.9]];
        for (j, o) in outliers.iter().enumerate() {
            pts.insert(j * 70, *o);
        }
        let kept = statistical_outlier_removal(&pts, SOR_K, SOR_STD_MUL);
        assert_eq!(kept.len(), 400, "exactly the outliers go");
        assert!(outliers.iter().all(|o| !kept.contains(o)));
        // Order preserved.
        let grid: Vec<[f64; 3]> = pts.iter().filter(|p| !outliers.contains(p)).copied().collect();
        assert_eq!(kept, grid);
        // Fewer than k points: unchanged.
        assert_eq!(statistical_outlier_removal(&outliers, SOR_K, SOR_STD_MUL), outliers.to_vec());
    }

    #[test]
    fn box_keys_keep_the_box_only() {
        let r = PLAN_VOXEL;
        let pts = [
            [0.0, 0.0, 0.0],
            [0.01, 0.02, 0.03],
            [-1.0, -1.0, -1.0],
            [1.0, 0.0, 0.0],
            [0.99, 0.5, -0.2],
            [2.0, 0.0, 0.0],
        ];
        let keys = box_keys(&pts);
        assert_eq!(keys, vec![[-32, -32, -32], [0, 0, 0], [31, 16, -7]]);
        assert_eq!(key_of([0.99, 0.5, -0.2], r), [31, 16, -7]);
    }

    #[test]
    fn target_and_occluders_of_hand_made_sets() {
        let observed = [[0, 0, 0], [1, 0, 0], [2, 0, 0]];
        let predicted = [[1, 0, 0], [2, 0, 0], [3, 0, 0], [0, 5, 0], [3, 0, 0]];
        let s = PlanningSets::new(&observed, &predicted);
        assert_eq!(s.occluders.keys(), &[[0, 0, 0], [0, 5, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]);
        assert_eq!(s.target_keys(), vec![[0, 5, 0], [3, 0, 0]]);
        assert_eq!(s.target_len, 2);
        // Nothing predicted: no target; nothing observed: target = predicted.
        assert_eq!(PlanningSets::new(&observed, &[]).target_len, 0);
        assert_eq!(
            PlanningSets::new(&[], &predicted).target_keys(),
            vec![[0, 5, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]
        );
    }

    #[test]
    fn covers_see_the_near_target_and_not_the_hidden_one() {
        // A row of voxels along x; observed: the middle; target: both ends. A camera on +x sees
        // the +x end only (the rest is behind it), one on −x the −x end only, one on +y both.
        let observed: Vec<VoxelKey> = (-3..=3).map(|x| [x, 0, 0]).collect();
        let predicted = vec![[-4, 0, 0], [4, 0, 0]];
        let s = PlanningSets::new(&observed, &predicted);
        let at = |c: [f64; 3]| Pose { center: c, look_at: [0.0; 3], roll: 0.0 };
        let poses = [at([3.0, 0.0, 0.0]), at([-3.0, 0.0, 0.0]), at([0.0, 3.0, 0.0]), at([0.0, 0.0, 3.0])];
        let covers = s.covers(&poses, &[true, true, true, false], Intrinsics::default());
        let keys = |b: &Vec<u64>| -> Vec<VoxelKey> {
            (0..s.occluders.len()).filter(|&i| bit(b, i)).map(|i| s.occluders.key(i)).collect()
        };
        assert_eq!(keys(&covers[0]), vec![[4, 0, 0]]);
        assert_eq!(keys(&covers[1]), vec![[-4, 0, 0]]);
        assert_eq!(keys(&covers[2]), vec![[-4, 0, 0], [4, 0, 0]]);
        assert!(keys(&covers[3]).is_empty(), "an inactive pose covers nothing");
        // No target (the prediction inside the observed voxels): empty covers of full length.
        let none = PlanningSets::new(&observed, &[[0, 0, 0], [1, 0, 0]]);
        assert_eq!(none.target_len, 0);
        let covers = none.covers(&poses, &[true; 4], Intrinsics::default());
        assert_eq!(covers, vec![vec![0u64; none.target.len()]; 4]);
        assert_eq!(none.target.len(), none.occluders.len().div_ceil(64));
    }
}
