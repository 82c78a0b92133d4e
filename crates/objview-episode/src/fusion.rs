//! Incremental fusion of observed clouds (SPEC §5): after each view, fused = voxel centroids
//! (voxel `h` = 0.005) of [previous fused points, new observed points] — the reference
//! implementation's `voxel_down_sample(concat(fused, new))`, where a previous fused point counts
//! as one point of its voxel. The grid is anchored at the origin (key floor(p / h), SPEC §4), so
//! a voxel's point never leaves its voxel and its key never changes.
//!
//! Each fused point is a *slot*; slots are never removed, only added (a voxel seen for the first
//! time) or moved (a voxel seen again). [`FusionDelta`] lists both: the coverage metrics update
//! only around them.

use std::sync::OnceLock;

use crate::prefetch;
use crate::scratch::Pool;

use crate::grid::{
    block_of, block_runs, local_index, lower_best_over, nearest_in, runs_in_box, Aabb, Bucketed,
    ChangedBlocks, Domain, Slab, SuperGrid, SuperHandle, BLOCK_CELLS, NONE,
};

// A block row (x) is one byte of the occupancy words (`FusedBlock::row_occupancy`).
const _: () = assert!(crate::grid::BLOCK == 8);

/// The set bits of `word` below bit `b` (< 64): a voxel's place among the occupied voxels of
/// its occupancy word.
#[inline(always)]
fn ones_below(word: u64, b: u32) -> usize {
    (word & ((1u64 << b) - 1)).count_ones() as usize
}

/// One allocated block: which of its fine voxels hold a fused point, and their slots and
/// positions, by local index.
///
/// Compact on purpose: an insertion touches ~2,000 blocks per view, about half of each block's
/// voxels. With the occupancy as one bit per voxel and the slots and positions in local-index
/// order, the voxels an insertion updates (taken in local-index order) are read and written in
/// ascending memory order, instead of through 3 KB of per-voxel tables and positions in
/// allocation order (a cache miss per voxel).
#[derive(Debug, Clone)]
pub struct FusedBlock {
    /// The block's integer coordinates in the domain's block grid.
    pub key: [i32; 3],
    /// Occupied fine voxels (bit = local index).
    occupied: [u64; BLOCK_CELLS / 64],
    /// Per word of `occupied`: the occupied voxels of the words before it (the rank base).
    before: [u16; BLOCK_CELLS / 64],
    /// The slots of this block's occupied fine voxels, by local index.
    pub slots: Vec<u32>,
    /// Its entry in the cloud's [`SuperGrid`].
    pub handle: Option<SuperHandle>,
    /// The fine voxels changed by the latest insertion that touched the block (bit = local
    /// index).
    changed_bits: [u64; BLOCK_CELLS / 64],
    /// The positions of the block's slots (in `slots` order), a block-local copy of
    /// [`FusedCloud::pos`] that an insertion reads without a cache miss per voxel.
    centroids: Vec<[f64; 3]>,
    /// The block's slab for nearest searches ([`Bucketed::block_slab`]), made by the first
    /// search that needs it; cleared when an insertion changes the block.
    slab: OnceLock<Slab>,
}

impl FusedBlock {
    fn new(key: [i32; 3], handle: Option<SuperHandle>) -> FusedBlock {
        FusedBlock {
            key,
            occupied: [0; BLOCK_CELLS / 64],
            before: [0; BLOCK_CELLS / 64],
            slots: Vec::new(),
            handle,
            changed_bits: [0; BLOCK_CELLS / 64],
            centroids: Vec::new(),
            slab: OnceLock::new(),
        }
    }

    /// Whether fine voxel `li` (local index) holds a fused point.
    #[inline]
    pub fn is_occupied(&self, li: usize) -> bool {
        self.occupied[li >> 6] >> (li & 63) & 1 == 1
    }

    /// The position in `slots` of local index `li`: the occupied voxels before it.
    #[inline]
    fn rank(&self, li: usize) -> usize {
        let w = li >> 6;
        self.before[w] as usize + ones_below(self.occupied[w], (li & 63) as u32)
    }

    /// The slot of fine voxel `li` (local index), or [`NONE`].
    #[inline]
    pub fn slot(&self, li: usize) -> u32 {
        if self.is_occupied(li) {
            self.slots[self.rank(li)]
        } else {
            NONE
        }
    }

    /// The occupancy of the x-row of fine voxels at local `y`, `z` (bit = local x).
    #[inline]
    pub fn row_occupancy(&self, y: usize, z: usize) -> u8 {
        let n = crate::grid::BLOCK as usize;
        let li = n * (y + n * z);
        (self.occupied[li >> 6] >> (li & 63)) as u8
    }

    /// Calls `f(slot, position)` for the occupied voxels with local indices `li..li + len`, all
    /// in one word of the occupancy (an x-run of the block: `len` ≤ [`crate::grid::BLOCK`]).
    #[inline]
    fn for_run<F: FnMut(u32, [f64; 3])>(&self, li: usize, len: usize, f: &mut F) {
        let (w, b) = (li >> 6, li & 63);
        debug_assert!(b + len <= 64);
        let word = self.occupied[w];
        let mut bits = (word >> b) & ((1u64 << len) - 1);
        if bits == 0 {
            return;
        }
        let mut j = self.before[w] as usize + ones_below(word, b as u32);
        while bits != 0 {
            f(self.slots[j], self.centroids[j]);
            j += 1;
            bits &= bits - 1;
        }
    }

    /// Calls `f(place)` with the place in `slots` and `centroids` of each voxel the latest
    /// insertion that touched the block changed (created or moved), in local-index order.
    /// During that insertion, before its new voxels are added, these are the moved ones.
    #[inline]
    fn for_each_changed_place(&self, mut f: impl FnMut(usize)) {
        for ((&bits, &word), &base) in self.changed_bits.iter().zip(&self.occupied).zip(&self.before) {
            let mut bits = bits & word;
            while bits != 0 {
                let b = bits.trailing_zeros();
                bits &= bits - 1;
                f(base as usize + ones_below(word, b));
            }
        }
    }

    /// Calls `f(local index, slot, position)` for each occupied voxel of the block, in
    /// local-index order, from block-local memory.
    #[inline]
    pub fn for_each_voxel(&self, mut f: impl FnMut(usize, u32, [f64; 3])) {
        let mut j = 0;
        for (w, &word) in self.occupied.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let li = (w << 6) | bits.trailing_zeros() as usize;
                bits &= bits - 1;
                f(li, self.slots[j], self.centroids[j]);
                j += 1;
            }
        }
    }

    /// How many voxels the latest insertion that touched the block changed.
    #[inline]
    pub fn changed_count(&self) -> usize {
        self.changed_bits.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// Calls `f(slot, position)` for each voxel the latest insertion that touched the block
    /// changed (created or moved), in local-index order, from block-local memory.
    #[inline]
    pub fn for_each_change(&self, mut f: impl FnMut(u32, [f64; 3])) {
        self.for_each_changed_place(|j| f(self.slots[j], self.centroids[j]));
    }

    /// Marks the voxels `fresh` (local indices, ascending, none occupied yet) occupied and
    /// makes room for them in `slots` ([`NONE`] until assigned) and `centroids` (their
    /// positions), keeping both in local-index order.
    fn add(&mut self, fresh: impl DoubleEndedIterator<Item = (usize, [f64; 3])> + ExactSizeIterator + Clone) {
        let nf = fresh.len();
        if nf == 0 {
            return;
        }
        for (li, _) in fresh.clone() {
            self.occupied[li >> 6] |= 1 << (li & 63);
        }
        let mut acc = 0u16;
        for (b, &w) in self.before.iter_mut().zip(&self.occupied) {
            *b = acc;
            acc += w.count_ones() as u16;
        }
        let old = self.slots.len();
        self.slots.resize(old + nf, NONE);
        self.centroids.resize(old + nf, [0.0; 3]);
        // From the back: the old entries after the fi-th fresh voxel move up by fi + 1.
        let mut src = old;
        for (fi, (li, c)) in fresh.enumerate().rev() {
            let r = self.rank(li);
            let keep = r - fi;
            self.slots.copy_within(keep..src, keep + fi + 1);
            self.centroids.copy_within(keep..src, keep + fi + 1);
            self.slots[r] = NONE;
            self.centroids[r] = c;
            src = keep;
        }
    }
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
    /// Scratch of [`FusedCloud::insert`] by allocation index (0 between insertions): the
    /// block's count of point runs in this insertion, then its offset. A compact array rather
    /// than a field of each block, so the per-run counting reads no block.
    bucket: Vec<u32>,
    /// The blocks the latest insertion changed, as (domain index, allocation index), by domain
    /// index: [`FusedCloud::latest_blocks`].
    latest: Vec<(u32, u32)>,
}

/// The buffers of [`FusedCloud::insert`] (on a 100k-triangle object: the keys and the fresh
/// voxels up to one entry per point, ~78k per view; ~16k runs), shared by every cloud of the
/// process through [`INSERT_SCRATCH`]: nothing in them outlives an insertion.
struct InsertScratch {
    /// One block's sums by fine voxel (stays in cache).
    accum: Box<[Accum; BLOCK_CELLS]>,
    /// The runs of consecutive input points in one block, as (allocation index, first, end),
    /// in input order; then their (first, end) by block, in input order within each block.
    runs: Vec<(u32, u32, u32)>,
    order: Vec<(u32, u32)>,
    /// Every point's fine key.
    keys: Vec<[i32; 3]>,
    /// The voxels seen for the first time, and their indices in `fresh` in the order of their
    /// first point (the slot order; built through a per-point table when there are many).
    fresh: Vec<Fresh>,
    by_first: Vec<u32>,
}

impl Default for InsertScratch {
    fn default() -> Self {
        InsertScratch {
            accum: Box::new([Accum::default(); BLOCK_CELLS]),
            runs: Vec::new(),
            order: Vec::new(),
            keys: Vec::new(),
            fresh: Vec::new(),
            by_first: Vec::new(),
        }
    }
}

/// The insertion buffers of every fused cloud of the process (see [`crate::scratch`]).
static INSERT_SCRATCH: Pool<InsertScratch> = Pool::new();

/// A voxel's sum and count of the current insertion's points, and its first point.
#[derive(Debug, Clone, Copy, Default)]
struct Accum {
    sum: [f64; 3],
    count: u32,
    first: u32,
}

/// What one insertion changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FusionDelta {
    /// How many slots this insertion created (the slots it created or moved:
    /// [`FusedCloud::latest_changed`]).
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
            bucket: Vec::new(),
            latest: Vec::new(),
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
                    self.blocks[t as usize].slot(local_index(k))
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
    /// any, weight 1) and the new points in that voxel, summed in input order. New voxels get
    /// their slots in the order of their first point.
    ///
    /// The points are first bucketed by block, then each block's points are accumulated with
    /// that block's voxel table and sums in cache: in pixel order they would visit the blocks
    /// of a whole scanline again and again. What is bucketed are the *runs* of consecutive
    /// points in one block (pixels along a row mostly stay in one: ~78k points make ~16k runs
    /// on the mug), with a stable counting sort of the runs by block; each block then reads its
    /// runs' points and keys from the input, in input order. Sorting the points themselves
    /// (a 32-byte record per point, written and read back) cost ~9% more in `fusion_views`.
    pub fn insert(&mut self, points: &[[f64; 3]]) -> FusionDelta {
        INSERT_SCRATCH.with(|scratch| self.insert_with(points, scratch, None))
    }

    /// [`FusedCloud::insert`], and `groups` made the groups of the changed slots — the groups
    /// [`ChangedBlocks::new`] makes of [`FusedCloud::latest_changed`], bit for bit and in the
    /// same order (tested) — during the insertion, while each block's slots and positions are
    /// in cache, instead of reading them all again from memory afterwards.
    pub fn insert_grouped(&mut self, points: &[[f64; 3]], groups: &mut ChangedBlocks) -> FusionDelta {
        INSERT_SCRATCH.with(|scratch| self.insert_with(points, scratch, Some(groups)))
    }

    /// [`FusedCloud::insert`] with the buffers `s` (whatever they hold is overwritten), making
    /// `groups` too when given.
    fn insert_with(
        &mut self,
        points: &[[f64; 3]],
        s: &mut InsertScratch,
        mut groups: Option<&mut ChangedBlocks>,
    ) -> FusionDelta {
        if let Some(g) = groups.as_deref_mut() {
            g.reset(self);
        }
        self.epoch += 1;
        let epoch = self.epoch;
        let mut delta = FusionDelta::default();
        // Pass 1: each point's block (allocated on first use); the runs of consecutive points
        // in one block (pixels along a row mostly stay in one), counted per block.
        let mut runs = std::mem::take(&mut s.runs);
        runs.clear();
        // (domain block index, allocation index) of the touched blocks.
        let mut touched: Vec<(u32, u32)> = std::mem::take(&mut self.latest);
        touched.clear();
        let mut keys = std::mem::take(&mut s.keys);
        self.domain.keys_into(points, &mut keys);
        for (bk, first, end) in block_runs(&keys) {
            let Some(b) = self.domain.block_index(bk) else {
                delta.dropped += end - first;
                continue;
            };
            let mut t = self.table[b];
            if t == NONE {
                t = self.blocks.len() as u32;
                self.table[b] = t;
                let handle = self.supergrid.add_block(bk);
                self.blocks.push(FusedBlock::new(bk, handle));
                self.bucket.push(0);
            }
            let c = &mut self.bucket[t as usize];
            if *c == 0 {
                touched.push((b as u32, t));
            }
            *c += 1;
            runs.push((t, first as u32, end as u32));
        }
        // The blocks in domain order (the spatial order of the metric updates and of the
        // groups). Counts → start offsets, then the runs by block, in input order.
        touched.sort_unstable();
        let mut offset = 0u32;
        for &(_, t) in &touched {
            let c = &mut self.bucket[t as usize];
            let n = *c;
            *c = offset;
            offset += n;
        }
        // Every entry below `offset` is written below: no need to clear what is reused.
        let mut order = std::mem::take(&mut s.order);
        order.resize(offset as usize, (0, 0));
        for &(t, first, end) in &runs {
            let c = &mut self.bucket[t as usize];
            order[*c as usize] = (first, end);
            *c += 1;
        }
        // Pass 2: block by block, sums per voxel (in the scratch), then the new centroids of
        // the block's voxels seen before; voxels seen for the first time are kept aside with
        // their first point and centroid.
        let mut fresh = std::mem::take(&mut s.fresh);
        fresh.clear();
        let mut start = 0usize;
        for (ti, &(_, t)) in touched.iter().enumerate() {
            // Software prefetches (hints, no effect on results): the block after next, then the
            // next block's positions, slots and superblock entry, so that its first reads do
            // not wait on memory (the touched blocks are scattered over a cloud of ~30 MB), and
            // the first point and key of each of its runs (rows of the image apart).
            if let Some(&(_, t2)) = touched.get(ti + 2) {
                prefetch::range(&self.blocks[t2 as usize..=t2 as usize]);
            }
            if let Some(&(_, t1)) = touched.get(ti + 1) {
                let next = &self.blocks[t1 as usize];
                if let Some(h) = next.handle {
                    self.supergrid.prefetch(h);
                }
                prefetch::range(&next.centroids);
                prefetch::range(&next.slots);
                let (next_start, next_end) =
                    (self.bucket[t as usize] as usize, self.bucket[t1 as usize] as usize);
                for &(f, _) in &order[next_start..next_end] {
                    prefetch::item(&points[f as usize]);
                    prefetch::item(&keys[f as usize]);
                }
            }
            let end = std::mem::take(&mut self.bucket[t as usize]) as usize;
            let blk = &mut self.blocks[t as usize];
            blk.changed_bits = [0; BLOCK_CELLS / 64];
            blk.slab = OnceLock::new();
            let scratch = &mut s.accum;
            for &(first, last) in &order[start..end] {
                let (f, l) = (first as usize, last as usize);
                for (i, (&p, &k)) in (first..).zip(points[f..l].iter().zip(&keys[f..l])) {
                    let li = local_index(k);
                    let (w, bit) = (li >> 6, 1u64 << (li & 63));
                    let a = &mut scratch[li];
                    if blk.changed_bits[w] & bit == 0 {
                        blk.changed_bits[w] |= bit;
                        *a = Accum { sum: [0.0; 3], count: 0, first: i };
                    }
                    a.sum[0] += p[0];
                    a.sum[1] += p[1];
                    a.sum[2] += p[2];
                    a.count += 1;
                }
            }
            start = end;
            // The global positions and stamps of the changed voxels seen before (scattered
            // over the cloud), asked for ahead of the updates below.
            blk.for_each_changed_place(|j| {
                let s = blk.slots[j] as usize;
                prefetch::item(&self.pos[s]);
                prefetch::item(&self.stamp[s]);
            });
            // In local-index order, so the block's slots and positions are visited in
            // ascending memory order (and the group lists them in that order).
            let f0 = fresh.len();
            let mut group = groups.as_deref_mut().map(|g| g.begin_group(blk.changed_count()));
            // The box of the block's changed centroids: its group's, and what its superblock
            // entry grows by (once per block rather than once per voxel).
            let mut changed_box = Aabb::EMPTY;
            for (w, &bits) in blk.changed_bits.iter().enumerate() {
                let occupied = blk.occupied[w];
                let base = blk.before[w] as usize;
                let mut bits = bits;
                while bits != 0 {
                    let b = bits.trailing_zeros();
                    let li = (w << 6) | b as usize;
                    bits &= bits - 1;
                    let Accum { sum: a, count, first } = scratch[li];
                    let n = count as f64;
                    if occupied >> b & 1 == 0 {
                        let c = [a[0] / n, a[1] / n, a[2] / n];
                        changed_box.grow(c);
                        // Its slot is assigned below; the group's entry is filled in then.
                        let at = group.as_mut().map_or(NONE, |g| g.push(NONE, c) as u32);
                        fresh.push(Fresh { first, t, li: li as u16, c, at });
                        continue;
                    }
                    let j = base + ones_below(occupied, b);
                    let c = &mut blk.centroids[j];
                    *c = [(c[0] + a[0]) / (n + 1.0), (c[1] + a[1]) / (n + 1.0), (c[2] + a[2]) / (n + 1.0)];
                    let s = blk.slots[j] as usize;
                    self.pos[s] = *c;
                    self.stamp[s] = epoch;
                    changed_box.grow(*c);
                    if let Some(g) = group.as_mut() {
                        g.push(s as u32, *c);
                    }
                }
            }
            if let Some(h) = blk.handle {
                self.supergrid.grow_box(h, &changed_box);
            }
            if let Some(g) = group {
                g.end(blk.key, changed_box);
            }
            // The block's new voxels get their places now (slots assigned below, in the order
            // of their first points).
            blk.add(fresh[f0..].iter().map(|f| (f.li as usize, f.c)));
        }
        // New slots in the order of their first point (as one pass in input order would). Each
        // point is the first of at most one voxel: many fresh voxels (a first view) are placed
        // by their first point's index and read back in input order; a few (later views, where
        // that pass would clear and scan an entry per point) are sorted by it.
        let mut by_first = std::mem::take(&mut s.by_first);
        by_first.clear();
        if fresh.len() * FRESH_SORT_SHARE < points.len() {
            by_first.extend(0..fresh.len() as u32);
            by_first.sort_unstable_by_key(|&j| fresh[j as usize].first);
        } else {
            by_first.resize(points.len(), NONE);
            for (j, f) in fresh.iter().enumerate() {
                by_first[f.first as usize] = j as u32;
            }
            by_first.retain(|&j| j != NONE);
        }
        for &j in &by_first {
            let Fresh { first: i, t, li, c, at } = fresh[j as usize];
            let s = self.pos.len() as u32;
            if let Some(g) = groups.as_deref_mut() {
                g.set_slot(at as usize, s);
            }
            let blk = &mut self.blocks[t as usize];
            let r = blk.rank(li as usize);
            blk.slots[r] = s;
            self.pos.push(c);
            self.key.push(keys[i as usize]);
            self.block.push(self.domain.block_index(blk.key).expect("an allocated block") as u32);
            self.stamp.push(epoch);
        }
        s.by_first = by_first;
        s.keys = keys;
        delta.new_slots = fresh.len();
        s.fresh = fresh;
        if let Some(g) = groups {
            g.index(self);
        }
        self.latest = touched;
        s.runs = runs;
        s.order = order;
        delta
    }

    /// The blocks the latest insertion changed, by domain index (their changes:
    /// [`FusedBlock::for_each_change`]).
    pub fn latest_blocks(&self) -> impl Iterator<Item = &FusedBlock> + '_ {
        self.latest.iter().map(|&(_, t)| &self.blocks[t as usize])
    }

    /// The slots the latest insertion created or moved, by block (domain index) and voxel —
    /// the order of the spatial metric updates. Built on demand: the engine reads the changes
    /// block by block ([`FusedCloud::latest_blocks`]) and never needs the list.
    pub fn latest_changed(&self) -> Vec<u32> {
        let mut v = Vec::new();
        for blk in self.latest_blocks() {
            blk.for_each_changed_place(|j| v.push(blk.slots[j]));
        }
        v
    }

    /// The domain block index of allocated block `t`.
    fn table_index(&self, t: u32) -> u32 {
        self.domain.block_index(self.blocks[t as usize].key).expect("an allocated block") as u32
    }

    /// The slots created or moved by the insertions after insertion `epoch` (0: every slot), in
    /// the spatial order of [`FusedCloud::latest_changed`] (block, then voxel).
    ///
    /// Read off the blocks in domain order and each block's slots (in local order; a voxel
    /// holds at most one slot), instead of sorting the slots by that key: at a first checkpoint
    /// every slot changed, and the sort's random reads of the slots' blocks and keys cost more
    /// than a pass over the blocks.
    pub fn changed_since(&self, epoch: u32) -> Vec<u32> {
        let mut order: Vec<(u32, u32)> =
            (0..self.blocks.len() as u32).map(|t| (self.table_index(t), t)).collect();
        order.sort_unstable();
        let mut v = Vec::new();
        for &(_, t) in &order {
            for &s in &self.blocks[t as usize].slots {
                if self.stamp[s as usize] > epoch {
                    v.push(s);
                }
            }
        }
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
            // The block-local copy of the positions: contiguous, where `pos[s]` would be a
            // cache miss per slot (slots of one block are scattered over the cloud).
            for (&s, &q) in blk.slots.iter().zip(&blk.centroids) {
                f(s, q);
            }
        }
    }
    fn lower_best_in_block(&self, b: [i32; 3], p: [f64; 3], best: &mut (f64, u32)) {
        if let Some(blk) = self.domain.block_index(b).and_then(|bi| self.block_at(bi)) {
            lower_best_over(&blk.centroids, |j| blk.slots[j], p, best);
        }
    }
    fn supergrid(&self) -> &SuperGrid {
        &self.supergrid
    }
    fn block_slab(&self, b: [i32; 3], aabb: &Aabb) -> Option<Slab> {
        let blk = self.domain.block_index(b).and_then(|bi| self.block_at(bi))?;
        Some(*blk.slab.get_or_init(|| Slab::of_block(aabb, self.domain.h, &blk.centroids)))
    }
    #[inline]
    fn position(&self, index: u32) -> [f64; 3] {
        self.pos[index as usize]
    }
    #[inline]
    fn for_cells_in_box<F: FnMut(u32, [f64; 3])>(&self, lo: [i32; 3], hi: [i32; 3], mut f: F) {
        runs_in_box(&self.domain, lo, hi, |b, first, len| {
            let t = self.table[b];
            if t == NONE {
                return;
            }
            self.blocks[t as usize].for_run(local_index(first), len, &mut f);
        });
    }
}

/// A voxel seen for the first time by an insertion.
#[derive(Clone, Copy)]
struct Fresh {
    /// Its first point (the input index: slots are assigned in this order).
    first: u32,
    /// Its block (allocation index) and local index.
    t: u32,
    li: u16,
    /// Its centroid.
    c: [f64; 3],
    /// Its entry in the insertion's groups (NONE when none are made).
    at: u32,
}

/// [`FusedCloud::insert`] sorts its new voxels by first point when they are fewer than the
/// points / this, and places them by index otherwise.
const FRESH_SORT_SHARE: usize = 16;

/// The fused points of one frame on its own: the centroid of each voxel of `domain` that holds
/// some of `points` (points outside the domain are dropped), by block and voxel (domain block
/// index, then local index) — the positions a fresh [`FusedCloud`] holds after inserting
/// `points` (the same sums in input order, the same divisions, so the same bits; tested),
/// without its blocks, tables and slot bookkeeping. For callers that need one view's fused cloud
/// as a point set (the oracle's per-candidate coverage).
///
/// The points are grouped by block as [`FusedCloud::insert`] groups them — a counting sort of
/// the runs of consecutive points in one block (the touched blocks put in domain order, each
/// block's runs kept in input order) —, then summed per voxel in a block-local table and
/// emitted in local-index order: the order of sorting by (block index · 512 + local index,
/// input index), without sorting the points.
pub fn frame_centroids(domain: &Domain, points: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut keys = Vec::new();
    domain.keys_into(points, &mut keys);
    // Pass 1: the runs of consecutive points in one block (pixels along a row mostly stay in
    // one), each with its block's touched number; the touched blocks' run counts. Points
    // outside the domain are dropped.
    let mut number = vec![NONE; domain.num_blocks()];
    let mut touched: Vec<(u32, u32)> = Vec::new(); // (domain block index, runs)
    let mut runs: Vec<(u32, u32, u32)> = Vec::new(); // (touched number, first, end)
    for (bk, first, end) in block_runs(&keys) {
        if let Some(b) = domain.block_index(bk) {
            let t = &mut number[b];
            if *t == NONE {
                *t = touched.len() as u32;
                touched.push((b as u32, 0));
            }
            touched[*t as usize].1 += 1;
            runs.push((*t, first as u32, end as u32));
        }
    }
    // Blocks in domain order: each block's start offset, by touched-block number; then the
    // runs by block, in input order.
    let mut by_domain: Vec<u32> = (0..touched.len() as u32).collect();
    by_domain.sort_unstable_by_key(|&t| touched[t as usize].0);
    let mut next = vec![0u32; touched.len()];
    let mut offset = 0u32;
    for &t in &by_domain {
        next[t as usize] = offset;
        offset += touched[t as usize].1;
    }
    let mut order: Vec<(u32, u32)> = vec![(0, 0); offset as usize];
    for &(t, first, end) in &runs {
        let o = &mut next[t as usize];
        order[*o as usize] = (first, end);
        *o += 1;
    }
    // Pass 2, block by block: sums per voxel in input order, then the centroids by voxel.
    let mut sums = vec![([0.0f64; 3], 0u32); BLOCK_CELLS];
    let mut out = Vec::new();
    let mut start = 0usize;
    for &t in &by_domain {
        let end = start + touched[t as usize].1 as usize;
        let mut seen = [0u64; BLOCK_CELLS / 64];
        for &(first, last) in &order[start..end] {
            let (f, l) = (first as usize, last as usize);
            for (&p, &k) in points[f..l].iter().zip(&keys[f..l]) {
                let li = local_index(k);
                let (w, bit) = (li >> 6, 1u64 << (li & 63));
                let a = &mut sums[li];
                if seen[w] & bit == 0 {
                    seen[w] |= bit;
                    *a = ([0.0; 3], 0);
                }
                a.0[0] += p[0];
                a.0[1] += p[1];
                a.0[2] += p[2];
                a.1 += 1;
            }
        }
        for (w, &bits) in seen.iter().enumerate() {
            let mut bits = bits;
            while bits != 0 {
                let li = (w << 6) | bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let (s, c) = sums[li];
                let n = c as f64;
                out.push([s[0] / n, s[1] / n, s[2] / n]);
            }
        }
        start = end;
    }
    out
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
    fn frame_centroids_are_a_fresh_clouds_positions() {
        // Many points per voxel (sums of several terms), voxels with one point, negative keys
        // and points outside the domain (dropped by both); more than 2^20 points (the index in
        // 21 bits of the packed sort).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        let d = Domain::covering(0.005, [-0.2; 3], [0.2; 3], 0.0);
        for n in [1usize, 7, 500, 20_000, (1 << 20) + 3] {
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|i| {
                    let r = if i % 50 == 49 {
                        0.6
                    } else if n > 1000 {
                        0.02
                    } else {
                        0.15
                    };
                    [0; 3].map(|_: i32| rng.gen_range(-r..r))
                })
                .collect();
            let mut f = FusedCloud::new(d.clone());
            f.insert(&pts);
            let bits = |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
            // The same positions bit for bit, in the order of the insertion's changed slots
            // (block, then voxel).
            let want: Vec<[f64; 3]> = f.latest_changed().iter().map(|&s| f.pos[s as usize]).collect();
            let got = frame_centroids(&d, &pts);
            assert_eq!(bits(&got), bits(&want), "{n} points");
            assert_eq!(got.len(), f.len());
            assert!(n < 1000 || got.len() * 10 < n, "voxels with several points: {} of {n}", got.len());
        }
        // Image-like rows: long runs of points in one block, each block visited again by later
        // rows (so the order of a block's runs matters), and points outside the domain.
        let pts: Vec<[f64; 3]> = (0..30_000)
            .map(|i| {
                let (row, col) = ((i / 200) as f64, (i % 200) as f64);
                if i % 50 == 49 {
                    [0.6, 0.0, 0.0]
                } else {
                    [
                        -0.1 + col * 0.0011,
                        -0.08 + row * 0.0011,
                        0.01 * (col * 0.05).sin() + rng.gen_range(-0.001..0.001),
                    ]
                }
            })
            .collect();
        let mut f = FusedCloud::new(d.clone());
        f.insert(&pts);
        let want: Vec<[f64; 3]> = f.latest_changed().iter().map(|&s| f.pos[s as usize]).collect();
        let got = frame_centroids(&d, &pts);
        let bits = |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
        assert_eq!(bits(&got), bits(&want), "rows");
    }

    #[test]
    fn the_27_voxel_runs_show_what_27_cell_lookups_show() {
        // Points on block edges and at the domain's border (negative keys, runs cut by a
        // block boundary or by the domain), moved by later insertions (block-local positions).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let mut f = FusedCloud::new(Domain::covering(0.005, [-0.1; 3], [0.1; 3], 0.0));
        let grid = |rng: &mut rand_chacha::ChaCha8Rng| rng.gen_range(-21i32..21) as f64 * 0.005 + 0.0025;
        for _ in 0..3 {
            let pts: Vec<[f64; 3]> = (0..3000)
                .map(|_| {
                    [grid(&mut rng), grid(&mut rng), grid(&mut rng)].map(|x| x + rng.gen_range(-0.002..0.002))
                })
                .collect();
            f.insert(&pts);
        }
        let shown = crate::grid::assert_around_matches_cells(&f, 18);
        assert!(shown > 3000, "the cases must see points: {shown}");
    }

    #[test]
    fn centroids_follow_the_reference_rule() {
        let mut f = FusedCloud::new(domain());
        // Two points in voxel (0,0,0), one in (1,0,0).
        let d = f.insert(&[[0.001, 0.001, 0.001], [0.003, 0.001, 0.001], [0.006, 0.001, 0.001]]);
        assert_eq!(f.latest_changed(), vec![0, 1]); // voxel (0,0,0) then (1,0,0)
        assert_eq!(d.new_slots, 2);
        assert!((f.pos[0][0] - 0.002).abs() < 1e-15);
        // Again: previous centroid counts once: (0.002 + 0.004) / 2 = 0.003.
        let d = f.insert(&[[0.004, 0.001, 0.001]]);
        assert_eq!((f.latest_changed(), d.new_slots), (vec![0], 0));
        assert!((f.pos[0][0] - 0.003).abs() < 1e-15);
        assert!(f.changed_now(0) && !f.changed_now(1));
        // Out of domain points are counted, not fused.
        assert_eq!(f.insert(&[[5.0, 0.0, 0.0]]).dropped, 1);
        assert_eq!(f.len(), 2);
        // Each of them, also several in a row (one run of points outside the domain).
        let d = f.insert(&[[5.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.004, 0.001, 0.001], [-5.0, 0.0, 0.0]]);
        assert_eq!((d.dropped, f.len()), (3, 2));
    }

    /// The fusion rule written as one plain pass in input order (a map from voxel to slot):
    /// per insertion, each voxel's points summed in input order; a new voxel becomes the next
    /// slot, at its first point's turn, with centroid sum / n; a voxel seen before becomes
    /// (centroid + sum) / (n + 1).
    struct PlainFusion {
        slot_of: std::collections::HashMap<[i32; 3], usize>,
        pos: Vec<[f64; 3]>,
    }

    impl PlainFusion {
        /// Returns the slots created or moved (as a set) and how many are new.
        fn insert(&mut self, d: &Domain, points: &[[f64; 3]]) -> (Vec<u32>, usize) {
            let mut sums: std::collections::HashMap<[i32; 3], ([f64; 3], usize)> = Default::default();
            let mut first_seen: Vec<[i32; 3]> = Vec::new();
            for &p in points {
                let k = d.key(p);
                if d.block_index(block_of(k)).is_none() {
                    continue;
                }
                let e = sums.entry(k).or_insert_with(|| {
                    first_seen.push(k);
                    ([0.0; 3], 0)
                });
                for (s, x) in e.0.iter_mut().zip(p) {
                    *s += x;
                }
                e.1 += 1;
            }
            let mut changed = Vec::new();
            let mut new = 0;
            for k in first_seen {
                let (sum, n) = sums[&k];
                let n = n as f64;
                match self.slot_of.get(&k) {
                    Some(&s) => {
                        let c = self.pos[s];
                        self.pos[s] = std::array::from_fn(|a| (c[a] + sum[a]) / (n + 1.0));
                        changed.push(s as u32);
                    }
                    None => {
                        self.slot_of.insert(k, self.pos.len());
                        changed.push(self.pos.len() as u32);
                        self.pos.push(std::array::from_fn(|a| sum[a] / n));
                        new += 1;
                    }
                }
            }
            changed.sort_unstable();
            (changed, new)
        }
    }

    #[test]
    fn insertions_equal_a_plain_pass_in_input_order() {
        // Slot order (new voxels in the order of their first point), positions bit for bit and
        // what each insertion changed, over insertions that revisit voxels, span blocks and
        // drop points outside the domain.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let d = Domain::covering(0.005, [-0.2; 3], [0.2; 3], 0.0);
        let mut f = FusedCloud::new(d.clone());
        let mut plain = PlainFusion { slot_of: Default::default(), pos: Vec::new() };
        // Insertions whose new voxels are placed by index, and sorted (few of them).
        let mut paths = [0; 2];
        for step in 0..9 {
            // Centres close together, so that every insertion revisits voxels of the earlier ones.
            let c: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-0.03..0.03));
            let r = [0.03, 0.08, 0.02][step % 3];
            // Odd steps scan rows like an image (long runs of points in one block, each block
            // visited again by later rows, so the runs' order within a block matters); even
            // steps scatter the points (runs of one or two).
            let pts: Vec<[f64; 3]> = (0..6000)
                .map(|i| {
                    if i % 997 == 0 {
                        [0.7, 0.0, 0.0]
                    } else if step % 2 == 1 {
                        let (row, col) = ((i / 100) as f64, (i % 100) as f64);
                        let jitter = rng.gen_range(-0.001..0.001);
                        [c[0] - r + col * 0.0016, c[1] - r + row * 0.0012, c[2] + jitter + 0.0004 * col]
                    } else {
                        std::array::from_fn(|a| c[a] + rng.gen_range(-r..r))
                    }
                })
                .collect();
            let delta = f.insert(&pts);
            let (want_changed, want_new) = plain.insert(&d, &pts);
            let bits = |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
            assert_eq!(bits(&f.pos), bits(&plain.pos), "step {step}: positions in slot order");
            let mut got = f.latest_changed();
            got.sort_unstable();
            assert_eq!(got, want_changed, "step {step}: changed slots");
            assert_eq!(delta.new_slots, want_new, "step {step}");
            // Every block: the slot of each of its 512 voxels (by key, as the plain pass has
            // it), and its slots and positions in local-index order, the positions bit for bit
            // those of the slots; `slot_at`, the x-runs and `for_block` agree.
            let mut seen = 0;
            for blk in &f.blocks {
                let mut listed = Vec::new();
                for li in 0..BLOCK_CELLS {
                    let k = [0, 1, 2].map(|a| {
                        let l = [li % 8, li / 8 % 8, li / 64][a] as i32;
                        blk.key[a] * crate::grid::BLOCK + l
                    });
                    assert_eq!(local_index(k), li);
                    let want = plain.slot_of.get(&k).map_or(NONE, |&s| s as u32);
                    assert_eq!(blk.slot(li), want, "step {step}: block {:?} voxel {li}", blk.key);
                    assert_eq!(f.slot_at(k), want);
                    assert_eq!(blk.is_occupied(li), want != NONE);
                    if want != NONE {
                        listed.push((want, f.pos[want as usize].map(f64::to_bits)));
                    }
                }
                let mut own = Vec::new();
                f.for_block(blk.key, |s, q| own.push((s, q.map(f64::to_bits))));
                assert_eq!(own, listed, "step {step}: block {:?} in local order", blk.key);
                let mut runs = Vec::new();
                for row in 0..64 {
                    blk.for_run(row * 8, 8, &mut |s, q| runs.push((s, q.map(f64::to_bits))));
                }
                assert_eq!(runs, listed);
                seen += listed.len();
            }
            assert_eq!(seen, f.len(), "step {step}: every slot in one block");
            assert!(
                want_new > 0 && (step == 0 || want_changed.len() > want_new),
                "step {step}: new and moved voxels"
            );
            paths[(want_new * FRESH_SORT_SHARE < pts.len()) as usize] += 1;
        }
        assert!(paths[0] > 0 && paths[1] > 0, "both orderings of new voxels: {paths:?}");
    }

    #[test]
    fn changed_since_lists_the_changed_slots_by_block_and_voxel() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let mut f = FusedCloud::new(domain());
        // Insertions that revisit some voxels and add others, over several blocks.
        for _ in 0..6 {
            let c: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-0.15..0.15));
            let pts: Vec<[f64; 3]> =
                (0..3000).map(|_| std::array::from_fn(|a| c[a] + rng.gen_range(-0.06..0.06))).collect();
            f.insert(&pts);
        }
        for epoch in 0..=f.epoch() {
            // The definition: every slot stamped after `epoch`, sorted by (domain block, local
            // index of its voxel).
            let mut want: Vec<u32> = (0..f.len() as u32).filter(|&s| f.stamp[s as usize] > epoch).collect();
            want.sort_by_key(|&s| (f.block[s as usize], local_index(f.key[s as usize])));
            let got = f.changed_since(epoch);
            assert_eq!(got, want, "epoch {epoch}");
            assert_eq!(got.is_empty(), epoch == f.epoch());
        }
        assert_eq!(f.changed_since(0).len(), f.len());
    }

    #[test]
    fn latest_groups_equal_the_groups_of_the_delta() {
        use crate::grid::ChangedBlocks;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut f = FusedCloud::new(domain());
        let (mut latest, mut grouped, mut g) =
            (ChangedBlocks::default(), ChangedBlocks::default(), f.clone());
        for _ in 0..5 {
            let pts: Vec<[f64; 3]> = (0..4000)
                .map(|_| [rng.gen_range(-0.2..0.2), rng.gen_range(-0.2..0.2), rng.gen_range(-0.05..0.05)])
                .collect();
            let df = f.insert(&pts);
            // The groups made during the insertion: the same cloud, and exactly the groups
            // read off its blocks afterwards (entries, order, padding, boxes, lookup).
            let dg = g.insert_grouped(&pts, &mut grouped);
            let bits = |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
            assert_eq!(bits(&g.pos), bits(&f.pos));
            assert_eq!((&g.stamp, &g.latest, dg.new_slots), (&f.stamp, &f.latest, df.new_slots));
            latest.rebuild_latest(&f);
            assert_same_groups(&grouped, &latest);
            // Grouped from the slots stamped by this insertion (pos[], by slot) and read off
            // the blocks (block-local copies): the same groups.
            let of_delta = ChangedBlocks::new(&f, &f.changed_since(f.epoch() - 1));
            assert_eq!(latest.blocks.len(), of_delta.blocks.len());
            for (a, b) in latest.blocks.iter().zip(&of_delta.blocks) {
                assert_eq!(a.key, b.key);
                let set = |g: &ChangedBlocks, r: (usize, usize)| {
                    let mut v: Vec<(u32, [u64; 3])> = (r.0..r.1)
                        .filter(|&i| g.slots[i] != NONE)
                        .map(|i| {
                            (
                                g.slots[i],
                                [g.xyz[0][i].to_bits(), g.xyz[1][i].to_bits(), g.xyz[2][i].to_bits()],
                            )
                        })
                        .collect();
                    v.sort_unstable();
                    v
                };
                assert_eq!(set(&latest, a.range), set(&of_delta, b.range));
                let own: Vec<u32> = set(&latest, a.range).iter().map(|x| x.0).collect();
                assert!(own.iter().all(|&s| f.pos[s as usize][0].to_bits()
                    == latest.xyz[0][latest.slots.iter().position(|&q| q == s).unwrap()].to_bits()));
            }
        }
    }

    /// `a` and `b` hold the same groups, bit for bit and in the same order.
    fn assert_same_groups(a: &crate::grid::ChangedBlocks, b: &crate::grid::ChangedBlocks) {
        let xyz = |g: &crate::grid::ChangedBlocks| {
            g.xyz.clone().map(|c| c.into_iter().map(f64::to_bits).collect::<Vec<_>>())
        };
        let blocks = |g: &crate::grid::ChangedBlocks| {
            g.blocks
                .iter()
                .map(|x| (x.key, x.range, x.aabb.lo.map(f64::to_bits), x.aabb.hi.map(f64::to_bits)))
                .collect::<Vec<_>>()
        };
        assert_eq!(a.slots, b.slots);
        assert_eq!(xyz(a), xyz(b));
        assert_eq!(blocks(a), blocks(b));
        assert!(a.lookup == b.lookup, "lookup tables differ");
    }

    #[test]
    fn superblock_boxes_hold_every_position_a_block_ever_had() {
        // The superblock entry of a block grows once per insertion by the box of its changed
        // centroids: it must equal the box of every position any of its voxels ever had,
        // grown point by point (moves included: a box never shrinks).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        let mut f = FusedCloud::new(domain());
        let mut shadow: std::collections::HashMap<[i32; 3], Aabb> = Default::default();
        for step in 0..6 {
            let (c, r) = ([0.0, 0.0, rng.gen_range(-0.03..0.03)], 0.03 + 0.03 * step as f64);
            let pts: Vec<[f64; 3]> =
                (0..3000).map(|_| std::array::from_fn(|a| c[a] + rng.gen_range(-r..r))).collect();
            f.insert(&pts);
            for s in f.changed_since(f.epoch() - 1) {
                let key = f.domain.block_key(f.block[s as usize] as usize);
                shadow.entry(key).or_insert(Aabb::EMPTY).grow(f.pos[s as usize]);
            }
            let bits = |a: &Aabb| (a.lo.map(f64::to_bits), a.hi.map(f64::to_bits));
            for (key, want) in &shadow {
                let (_, got) = f
                    .supergrid
                    .blocks(key.map(|x| x >> crate::grid::SUPER_SHIFT))
                    .iter()
                    .find(|(k, _)| k == key)
                    .expect("every occupied block is in the supergrid");
                assert_eq!(bits(got), bits(want), "step {step}, block {key:?}");
            }
        }
    }

    #[test]
    fn groups_reused_for_another_domain_equal_fresh_ones() {
        // The engine's step buffers go from episode to episode, across objects: a value of
        // ChangedBlocks last used on one domain must group another domain's changes exactly as
        // a fresh one does — including its lookup table, which has the same size for two
        // domains of equal dimensions (here shifted by three blocks along x).
        use crate::grid::ChangedBlocks;
        let a = domain();
        let b = Domain { lo: [a.lo[0] + 3, a.lo[1], a.lo[2]], ..a };
        assert_eq!(a.num_blocks(), b.num_blocks());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let mut patch = |n: usize| -> Vec<[f64; 3]> {
            (0..n)
                .map(|_| [rng.gen_range(-0.2..0.2), rng.gen_range(-0.2..0.2), rng.gen_range(-0.05..0.05)])
                .collect()
        };
        let mut reused = ChangedBlocks::default();
        let mut fa = FusedCloud::new(a);
        fa.insert_grouped(&patch(4000), &mut reused);
        let mut fb = FusedCloud::new(b);
        for _ in 0..2 {
            fb.insert_grouped(&patch(3000), &mut reused);
            let mut fresh = ChangedBlocks::default();
            fresh.rebuild_latest(&fb);
            assert_same_groups(&reused, &fresh);
        }
    }

    #[test]
    fn a_blocks_kept_slab_bounds_its_points_and_follows_its_changes() {
        // One block (0.04 wide at h = 0.005, key [1, 1, 1]) holding a tilted plane patch; a
        // second insertion adds a patch on another plane and moves centroids, so the first
        // slab no longer bounds the block: the kept one must be made again.
        let d = Domain::covering(0.005, [-0.2; 3], [0.2; 3], 0.0);
        let mut f = FusedCloud::new(d.clone());
        let b = [1, 1, 1];
        let lo = 0.04;
        let plane = |tilt: f64, off: f64| -> Vec<[f64; 3]> {
            let mut v = Vec::new();
            for i in 0..40 {
                for j in 0..40 {
                    let (x, y) = (lo + 0.0005 + i as f64 * 0.00098, lo + 0.0005 + j as f64 * 0.00098);
                    v.push([x, y, lo + off + tilt * (x - lo) + 0.3 * tilt * (y - lo)]);
                }
            }
            v
        };
        let bounds_all = |f: &FusedCloud| {
            let (aabb, slab) = f
                .supergrid
                .blocks(b.map(|x| x >> crate::grid::SUPER_SHIFT))
                .iter()
                .find(|(k, _)| *k == b)
                .map(|(_, a)| (*a, f.block_slab(b, a).expect("an allocated block")))
                .expect("the block is in the supergrid");
            let mut n = 0;
            f.for_block(b, |_, q| {
                assert_eq!(slab.lb2(q), 0.0, "a point of the block outside its slab");
                n += 1;
            });
            assert!(n > 20);
            (aabb, slab)
        };
        f.insert(&plane(0.5, 0.005));
        let (_, first) = bounds_all(&f);
        assert!(first.lb2([lo + 0.02, lo + 0.02, lo + 0.039]) > 0.0, "the first slab is thin");
        f.insert(&plane(-0.4, 0.03));
        bounds_all(&f);
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
