//! Incremental fusion of observed clouds (SPEC §5): after each view, fused = voxel centroids
//! (voxel `h` = 0.005) of [previous fused points, new observed points] — the reference
//! implementation's `voxel_down_sample(concat(fused, new))`, where a previous fused point counts
//! as one point of its voxel. The grid is anchored at the origin (key floor(p / h), SPEC §4), so
//! a voxel's point never leaves its voxel and its key never changes.
//!
//! Each fused point is a *slot*; slots are never removed, only added (a voxel seen for the first
//! time) or moved (a voxel seen again). [`FusionDelta`] lists both: the coverage metrics update
//! only around them.

use crate::grid::{
    block_of, local_index, nearest_in, Bucketed, Domain, SuperGrid, SuperHandle, BLOCK_CELLS, NONE,
};

/// One allocated block: the slot of each of its fine voxels and the list of its slots.
#[derive(Debug, Clone)]
pub struct FusedBlock {
    /// The block's integer coordinates in the domain's block grid.
    pub key: [i32; 3],
    /// Slot index of each fine voxel of the block, or [`NONE`] where nothing was fused.
    pub cells: Box<[u32; BLOCK_CELLS]>,
    /// The slots of this block's occupied fine voxels, in allocation order.
    pub slots: Vec<u32>,
    /// Its entry in the cloud's [`SuperGrid`].
    pub handle: Option<SuperHandle>,
    /// The fine voxels changed by the insertion `changed_epoch` (bit = local index).
    changed_bits: [u64; BLOCK_CELLS / 64],
    changed_epoch: u32,
}

/// The fused cloud: one point per occupied fine voxel.
#[derive(Debug, Clone)]
pub struct FusedCloud {
    /// The fusion grid: origin-anchored voxels of the fusion size, grouped in blocks.
    pub domain: Domain,
    /// Block index of the domain → index into `blocks`, or [`NONE`].
    pub table: Vec<u32>,
    /// The allocated blocks, in allocation order.
    pub blocks: Vec<FusedBlock>,
    /// Position of each slot (object frame).
    pub pos: Vec<[f64; 3]>,
    /// Fine key of each slot.
    pub key: Vec<[i32; 3]>,
    /// Domain block index of each slot.
    pub block: Vec<u32>,
    /// Step at which each slot last changed (see [`FusedCloud::changed_now`]).
    pub stamp: Vec<u32>,
    /// The occupied blocks by superblock (far nearest searches).
    pub supergrid: SuperGrid,
    epoch: u32,
    /// Per slot, what the current insertion accumulates (one cache line per point).
    hot: Vec<Accum>,
}

/// A slot's sum and count of the current insertion's points, and that insertion's epoch.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct Accum {
    sum: [f64; 3],
    count: u32,
    epoch: u32,
}

/// Number of set bits.
fn count_bits(bits: &[u64]) -> usize {
    bits.iter().map(|b| b.count_ones() as usize).sum()
}

/// What one insertion changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FusionDelta {
    /// Slots created or moved by this insertion, by block and voxel.
    pub changed: Vec<u32>,
    /// How many of them are new.
    pub new_slots: usize,
    /// Observed points outside the domain (dropped; never expected for points on the mesh).
    pub dropped: usize,
}

impl FusedCloud {
    /// An empty cloud over `domain`.
    pub fn new(domain: Domain) -> FusedCloud {
        let n = domain.num_blocks();
        FusedCloud {
            supergrid: SuperGrid::new(&domain),
            domain,
            table: vec![NONE; n],
            blocks: Vec::new(),
            pos: Vec::new(),
            key: Vec::new(),
            block: Vec::new(),
            stamp: Vec::new(),
            epoch: 0,
            hot: Vec::new(),
        }
    }

    /// Number of fused points.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// Whether nothing has been fused.
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// Insertions so far.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Whether `slot` changed in the latest insertion.
    #[inline]
    pub fn changed_now(&self, slot: u32) -> bool {
        self.stamp[slot as usize] == self.epoch
    }

    /// The slot of fine key `k`, if occupied.
    #[inline]
    pub fn slot_at(&self, k: [i32; 3]) -> u32 {
        match self.domain.block_index(block_of(k)) {
            Some(b) => {
                let t = self.table[b];
                if t == NONE {
                    NONE
                } else {
                    self.blocks[t as usize].cells[local_index(k)]
                }
            }
            None => NONE,
        }
    }

    /// The allocated block at domain block index `b`.
    #[inline]
    pub fn block_at(&self, b: usize) -> Option<&FusedBlock> {
        let t = self.table[b];
        (t != NONE).then(|| &self.blocks[t as usize])
    }

    /// Fuses `points` (object frame): per voxel, the new centroid of the previous point (if
    /// any, weight 1) and the new points in that voxel, summed in input order.
    pub fn insert(&mut self, points: &[[f64; 3]]) -> FusionDelta {
        self.epoch += 1;
        let epoch = self.epoch;
        let mut delta = FusionDelta::default();
        // Blocks touched by this insertion (domain index, allocation index).
        let mut touched: Vec<(u32, u32)> = Vec::new();
        // The previous point's block: consecutive pixels mostly share one.
        let mut last: (usize, u32) = (usize::MAX, NONE);
        for &p in points {
            let k = self.domain.key(p);
            let Some(b) = self.domain.block_index(block_of(k)) else {
                delta.dropped += 1;
                continue;
            };
            let t = if b == last.0 {
                last.1
            } else {
                let mut t = self.table[b];
                if t == NONE {
                    t = self.blocks.len() as u32;
                    self.table[b] = t;
                    let handle = self.supergrid.add_block(self.domain.block_key(b));
                    self.blocks.push(FusedBlock {
                        key: self.domain.block_key(b),
                        cells: Box::new([NONE; BLOCK_CELLS]),
                        slots: Vec::new(),
                        handle,
                        changed_bits: [0; BLOCK_CELLS / 64],
                        changed_epoch: 0,
                    });
                }
                last = (b, t);
                t
            };
            let blk = &mut self.blocks[t as usize];
            if blk.changed_epoch != epoch {
                blk.changed_epoch = epoch;
                blk.changed_bits = [0; BLOCK_CELLS / 64];
                touched.push((b as u32, t));
            }
            let li = local_index(k);
            let mut s = blk.cells[li];
            if s == NONE {
                s = self.pos.len() as u32;
                blk.cells[li] = s;
                blk.slots.push(s);
                self.pos.push(p);
                self.key.push(k);
                self.block.push(b as u32);
                self.stamp.push(0);
                self.hot.push(Accum::default());
                delta.new_slots += 1;
            }
            let h = &mut self.hot[s as usize];
            if h.epoch != epoch {
                *h = Accum { sum: [0.0; 3], count: 0, epoch };
                blk.changed_bits[li >> 6] |= 1 << (li & 63);
            }
            h.sum[0] += p[0];
            h.sum[1] += p[1];
            h.sum[2] += p[2];
            h.count += 1;
        }
        // Spatial order (block, then voxel) for cache-friendly metric updates: the touched
        // blocks by domain index, and each one's changed voxels by local index.
        touched.sort_unstable();
        let first_new = self.pos.len() - delta.new_slots;
        for &(_, t) in &touched {
            let blk = &self.blocks[t as usize];
            for (w, &bits) in blk.changed_bits.iter().enumerate() {
                let mut bits = bits;
                while bits != 0 {
                    let li = (w << 6) | bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    delta.changed.push(blk.cells[li]);
                }
            }
            for &s in &delta.changed[delta.changed.len() - count_bits(&blk.changed_bits)..] {
                let si = s as usize;
                self.stamp[si] = epoch;
                let (a, n) = (self.hot[si].sum, self.hot[si].count as f64);
                self.pos[si] = if si >= first_new {
                    [a[0] / n, a[1] / n, a[2] / n]
                } else {
                    let q = self.pos[si];
                    [(q[0] + a[0]) / (n + 1.0), (q[1] + a[1]) / (n + 1.0), (q[2] + a[2]) / (n + 1.0)]
                };
                if let Some(h) = blk.handle {
                    self.supergrid.grow(h, self.pos[si]);
                }
            }
        }
        delta
    }

    /// The slots created or moved by the insertions after insertion `epoch` (0: every slot), in
    /// the spatial order of [`FusionDelta::changed`] (block, then voxel).
    pub fn changed_since(&self, epoch: u32) -> Vec<u32> {
        let mut v: Vec<u32> = (0..self.len() as u32).filter(|&s| self.stamp[s as usize] > epoch).collect();
        let (block, key) = (&self.block, &self.key);
        v.sort_unstable_by_key(|&s| (block[s as usize], local_index(key[s as usize]) as u32, s));
        v
    }

    /// The nearest fused point to `p` with squared distance below `bound2` (exact; ties →
    /// smaller slot): `(d², slot)`, or `(bound2, NONE)` when there is none.
    pub fn nearest(&self, p: [f64; 3], bound2: f64) -> (f64, u32) {
        nearest_in(self, p, bound2)
    }
}

impl Bucketed for FusedCloud {
    fn domain(&self) -> &Domain {
        &self.domain
    }
    fn for_cell<F: FnMut(u32, [f64; 3])>(&self, k: [i32; 3], mut f: F) {
        let s = self.slot_at(k);
        if s != NONE {
            f(s, self.pos[s as usize]);
        }
    }
    fn for_block<F: FnMut(u32, [f64; 3])>(&self, b: [i32; 3], mut f: F) {
        if let Some(blk) = self.domain.block_index(b).and_then(|bi| self.block_at(bi)) {
            for &s in &blk.slots {
                f(s, self.pos[s as usize]);
            }
        }
    }
    fn supergrid(&self) -> &SuperGrid {
        &self.supergrid
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::dist2;
    use rand::{Rng, SeedableRng};

    fn domain() -> Domain {
        Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05)
    }

    #[test]
    fn centroids_follow_the_reference_rule() {
        let mut f = FusedCloud::new(domain());
        // Two points in voxel (0,0,0), one in (1,0,0).
        let d = f.insert(&[[0.001, 0.001, 0.001], [0.003, 0.001, 0.001], [0.006, 0.001, 0.001]]);
        assert_eq!(d.changed, vec![0, 1]); // voxel (0,0,0) then (1,0,0)
        assert_eq!(d.new_slots, 2);
        assert!((f.pos[0][0] - 0.002).abs() < 1e-15);
        // Again: previous centroid counts once: (0.002 + 0.004) / 2 = 0.003.
        let d = f.insert(&[[0.004, 0.001, 0.001]]);
        assert_eq!((d.changed.clone(), d.new_slots), (vec![0], 0));
        assert!((f.pos[0][0] - 0.003).abs() < 1e-15);
        assert!(f.changed_now(0) && !f.changed_now(1));
        // Out of domain points are counted, not fused.
        assert_eq!(f.insert(&[[5.0, 0.0, 0.0]]).dropped, 1);
        assert_eq!(f.len(), 2);
    }

    #[test]
    fn nearest_equals_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut f = FusedCloud::new(domain());
        // A clustered cloud (a patch) plus a few scattered points.
        let mut pts = Vec::new();
        for _ in 0..3000 {
            pts.push([rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1), 0.5 + rng.gen_range(-0.01..0.01)]);
        }
        for _ in 0..20 {
            pts.push([rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)]);
        }
        f.insert(&pts);
        for i in 0..400 {
            let p: [f64; 3] = if i % 2 == 0 {
                [rng.gen_range(-0.12..0.12), rng.gen_range(-0.12..0.12), rng.gen_range(0.45..0.55)]
            } else {
                [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)]
            };
            let brute = f.pos.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min);
            let (d, s) = f.nearest(p, f64::INFINITY);
            assert_eq!(d, brute);
            assert_eq!(dist2(p, f.pos[s as usize]), d);
            // Bounded: none within a bound below the true distance.
            let (d2, s2) = f.nearest(p, brute * 0.999);
            assert_eq!((d2, s2), (brute * 0.999, NONE));
        }
    }
}
