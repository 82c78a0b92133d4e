//! Map stabilization MS@δ (SPEC §5, paper §5.2): n = number of voxels of size δ occupied by the
//! fused cloud; growth = (n − n_prev) / max(n_prev, 1); a step is stable when growth < 0.01,
//! and MS@δ triggers at the third stable step in a row. It is a checkpoint, never a stop.
//!
//! A fused point never leaves its fine voxel (see [`crate::fusion`]), so its δ-voxel is fixed at
//! creation: the δ-voxel of the fine voxel's centre, which for δ a multiple of the fine size
//! (0.01, 0.02, 0.03 of 0.005) is exactly the δ-voxel of every point inside it.

use objview_geom::num::floor_i32;
use rustc_hash::FxHashSet;

/// Entries of the recent-key cache of [`Stabilization::add_fine_keys`].
const RECENT: usize = 256;
/// Largest dense δ-voxel box of [`Stabilization::with_box`], in voxels (8 MiB of bits).
const DENSE_MAX: usize = 1 << 26;

/// The δ-voxels of a fixed key box as one bit each: the set's common case without hashing.
#[derive(Debug, Clone)]
struct Dense {
    lo: [i32; 3],
    dims: [usize; 3],
    bits: Vec<u64>,
    count: usize,
}

impl Dense {
    /// Adds `d` when it lies in the box (true then, whether it was new or not).
    #[inline]
    fn insert(&mut self, d: [i32; 3]) -> bool {
        let mut i = 0usize;
        for ((&x, &lo), &n) in d.iter().zip(&self.lo).zip(&self.dims) {
            let x = x.wrapping_sub(lo) as u32 as usize;
            if x >= n {
                return false;
            }
            i = i * n + x;
        }
        let (w, b) = (i >> 6, 1u64 << (i & 63));
        self.count += usize::from(self.bits[w] & b == 0);
        self.bits[w] |= b;
        true
    }
}

/// The cache entry of δ-voxel key `d`.
#[inline]
fn recent_slot(d: [i32; 3]) -> usize {
    let h = (d[0] as u32).wrapping_mul(0x9E37_79B1)
        ^ (d[1] as u32).wrapping_mul(0x85EB_CA77)
        ^ (d[2] as u32).wrapping_mul(0xC2B2_AE3D);
    (h >> 24) as usize % RECENT
}

/// The stabilization rule for one δ.
#[derive(Debug, Clone)]
pub struct Stabilization {
    /// Voxel size δ (normalized object units).
    pub delta: f64,
    /// Growth below which a step is stable (0.01).
    pub growth_threshold: f64,
    /// Stable steps in a row that trigger (3).
    pub stable_steps: usize,
    ratio: Option<i32>,
    h: f64,
    voxels: FxHashSet<[i32; 3]>,
    /// The δ-voxels inside the box given to [`Stabilization::with_box`] (then `voxels` holds
    /// only those outside it).
    dense: Option<Dense>,
    /// Direct-mapped cache of keys known to be in `voxels` (see [`Stabilization::add_fine_keys`]).
    recent: Box<[Option<[i32; 3]>; RECENT]>,
    prev: Option<usize>,
    run: usize,
    triggered_at: Option<usize>,
}

impl Stabilization {
    /// A tracker for δ over fine voxels of size `h`.
    pub fn new(delta: f64, h: f64, growth_threshold: f64, stable_steps: usize) -> Stabilization {
        let r = delta / h;
        let ratio = ((r - r.round()).abs() < 1e-9 && r.round() >= 1.0).then_some(r.round() as i32);
        Stabilization {
            delta,
            growth_threshold,
            stable_steps,
            ratio,
            h,
            voxels: FxHashSet::default(),
            dense: None,
            recent: Box::new([None; RECENT]),
            prev: None,
            run: 0,
            triggered_at: None,
        }
    }

    /// [`Stabilization::new`] with the δ-voxels of the fine keys in `[fine_lo, fine_hi]` (the
    /// fused cloud's domain) kept as a dense bitset instead of hashed: the same set and count
    /// (keys outside the box still go to the hash set), without a hash insertion per new point.
    /// No dense box when it would exceed 2^26 voxels (8 MiB of bits).
    pub fn with_box(
        delta: f64,
        h: f64,
        growth_threshold: f64,
        stable_steps: usize,
        fine_lo: [i32; 3],
        fine_hi: [i32; 3],
    ) -> Stabilization {
        let mut s = Stabilization::new(delta, h, growth_threshold, stable_steps);
        // The δ-key map is monotone per axis, so the box's corners bound it.
        let (lo, hi) = (s.delta_key(fine_lo), s.delta_key(fine_hi));
        let dims: [usize; 3] =
            std::array::from_fn(|a| (i64::from(hi[a]) - i64::from(lo[a]) + 1).max(0) as usize);
        let n = dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d));
        if let Some(n) = n.filter(|&n| n > 0 && n <= DENSE_MAX) {
            s.dense = Some(Dense { lo, dims, bits: vec![0; n.div_ceil(64)], count: 0 });
        }
        s
    }

    /// The δ-voxel of fine voxel `k` (module docs).
    #[inline]
    fn delta_key(&self, k: [i32; 3]) -> [i32; 3] {
        match self.ratio {
            Some(m) => [k[0].div_euclid(m), k[1].div_euclid(m), k[2].div_euclid(m)],
            None => {
                let c = |x: i32| floor_i32(((x as f64 + 0.5) * self.h) / self.delta);
                [c(k[0]), c(k[1]), c(k[2])]
            }
        }
    }

    /// Adds the fine voxels of newly created fused points.
    pub fn add_fine_keys(&mut self, keys: impl IntoIterator<Item = [i32; 3]>) {
        for k in keys {
            let d = self.delta_key(k);
            if let Some(dense) = &mut self.dense {
                if dense.insert(d) {
                    continue;
                }
            }
            // Keys arrive by block and voxel, so neighbours share δ-voxels: a small cache of
            // keys already in the set skips most repeated hash insertions (same set).
            let slot = &mut self.recent[recent_slot(d)];
            if *slot != Some(d) {
                self.voxels.insert(d);
                *slot = Some(d);
            }
        }
    }

    /// Current δ-voxel count n.
    pub fn count(&self) -> usize {
        self.voxels.len() + self.dense.as_ref().map_or(0, |d| d.count)
    }

    /// Ends a step (after its voxels were added); returns true when MS@δ triggers now.
    pub fn end_step(&mut self, step: usize) -> bool {
        self.observe(self.count(), step)
    }

    /// The rule on a raw count sequence (one call per view).
    pub fn observe(&mut self, n: usize, step: usize) -> bool {
        let stable = match self.prev {
            None => false,
            Some(p) => ((n as f64 - p as f64) / (p.max(1) as f64)) < self.growth_threshold,
        };
        self.prev = Some(n);
        self.run = if stable { self.run + 1 } else { 0 };
        if self.triggered_at.is_none() && self.run >= self.stable_steps {
            self.triggered_at = Some(step);
            return true;
        }
        false
    }

    /// The step at which it triggered.
    pub fn triggered_at(&self) -> Option<usize> {
        self.triggered_at
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(counts: &[usize]) -> Option<usize> {
        let mut s = Stabilization::new(0.02, 0.005, 0.01, 3);
        for (i, &n) in counts.iter().enumerate() {
            s.observe(n, i);
        }
        s.triggered_at()
    }

    #[test]
    fn triggers_at_the_third_stable_step_in_a_row() {
        // Steps 0..: growth undefined at 0 (not stable), then 1.0, 0.005, 0.0, 0.0099 → third
        // stable step is step 4.
        assert_eq!(run(&[100, 200, 201, 201, 202]), Some(4));
        // A break resets the run: 0.005, 0.0, 0.02 (unstable), then three stable.
        assert_eq!(run(&[100, 200, 201, 201, 206, 206, 206, 206]), Some(7));
        // growth exactly 0.01 is not stable (strict <).
        assert_eq!(run(&[100, 100, 101, 102]), None);
        // Only two stable steps.
        assert_eq!(run(&[10, 10, 10]), Some(2).filter(|_| false).or(None));
        assert_eq!(run(&[10, 10, 10, 10]), Some(3));
        // From an empty map: max(n_prev, 1): 0 → 0 is stable (growth 0).
        assert_eq!(run(&[0, 0, 0, 0]), Some(3));
        // Triggers once: later steps do not move it.
        assert_eq!(run(&[5, 5, 5, 5, 5, 5, 9, 9, 9, 9]), Some(3));
    }

    #[test]
    fn delta_voxels_nest_exactly() {
        let mut s = Stabilization::new(0.02, 0.005, 0.01, 3);
        // Fine keys 0..3 share δ-voxel 0; 4 is the next; −1 is the previous.
        s.add_fine_keys([[0, 0, 0], [3, 3, 3], [4, 0, 0], [-1, 0, 0], [-4, 0, 0], [-5, 0, 0]]);
        assert_eq!(s.count(), 4);
        let mut t = Stabilization::new(0.012, 0.005, 0.01, 3); // not a multiple: centre rule
        t.add_fine_keys([[0, 0, 0], [1, 0, 0], [2, 0, 0]]); // centres 0.0025, 0.0075, 0.0125
        assert_eq!(t.count(), 2);
    }

    #[test]
    fn counts_equal_a_plain_set_of_the_delta_voxels() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for (delta, h, boxed) in [
            (0.02, 0.005, false),
            (0.012, 0.005, false),
            (0.005, 0.005, false),
            (0.02, 0.005, true),
            (0.012, 0.005, true),
            (0.005, 0.005, true),
            (0.03, 0.005, true),
        ] {
            // A box that holds most keys but not all (the rest go to the hash set).
            let mut s = if boxed {
                Stabilization::with_box(delta, h, 0.01, 3, [-30, -5, -3], [25, 9, 4])
            } else {
                Stabilization::new(delta, h, 0.01, 3)
            };
            assert_eq!(s.dense.is_some(), boxed);
            let mut plain = std::collections::HashSet::new();
            for _ in 0..50 {
                // Runs of neighbouring keys (as fusion delivers them) and scattered repeats.
                let keys: Vec<[i32; 3]> = (0..400)
                    .map(|j| {
                        if rng.gen_bool(0.3) {
                            [0; 3].map(|_: i32| rng.gen_range(-40..40))
                        } else {
                            [j % 16 - 8, (j / 16) % 8 - 4, rng.gen_range(-2..2)]
                        }
                    })
                    .collect();
                for &k in &keys {
                    let d = match s.ratio {
                        Some(m) => k.map(|x| x.div_euclid(m)),
                        None => k.map(|x| floor_i32(((x as f64 + 0.5) * h) / delta)),
                    };
                    plain.insert(d);
                }
                s.add_fine_keys(keys);
                assert_eq!(s.count(), plain.len(), "δ {delta}, box {boxed}");
            }
        }
    }
}
