//! Exact nearest distances between a fixed point set and the fused cloud: the ground truth's
//! for CD at checkpoints (SPEC §5: CD is evaluated only where a checkpoint is recorded, as the
//! reference implementation's evaluator does), and the observable reference's SC. SC@τ/NSC@τ of
//! every step need only bounded-radius coverage: [`crate::coverage`].
//!
//! Each target point keeps d² to its nearest fused point and that point's slot. An update
//! brings the distances from the fused cloud as it was at the previous update to the cloud now;
//! only slots created or moved since then (the *changed* slots, [`FusedCloud::stamp`] later
//! than the previous update's epoch) can change a distance:
//! - *push*: every changed slot updates the targets in the 27 fine voxels around it; a target
//!   whose nearest slot moved away is recomputed. This is exact for every target whose
//!   distance was ≤ h (any point closer than h lies in those 27 voxels).
//! - *far* targets (distance > h, or none yet): the minimum with the changed slots, found
//!   block by block with box and slab pruning (a slab per changed block: far targets on the
//!   inside of a shell skip the blocks whose box, but not whose surface patch, lies within
//!   their distance). When a far target's nearest slot moved, every unchanged slot is still at
//!   least its previous distance away, so the minimum over the changed slots is the answer
//!   whenever it is no larger than that; otherwise (and for near targets whose slot moved
//!   away) a full nearest search runs, batched by target block as below.
//!
//! Targets with no nearest slot yet are searched target block by target block
//! ([`nearest_in_block`]: the block's first answer bounds the others, the fused blocks that
//! could beat those bounds are gathered once for the whole block, and a block is scanned only
//! if both its box and its slab could beat a target's best).
//!
//! When at least half of the fused slots changed since the previous update (the first update
//! of an episode, a checkpoint after many views) the update *pulls* instead: every distance is
//! found again from nothing — both directions at once from the pairs of slots and targets in
//! neighbouring voxels (each pair once), then searches for the targets and slots those do not
//! settle. The distances are the same either way (a tie between two slots at exactly the same
//! distance may name a different slot); pulling is cheaper there because it has no moved
//! nearest slots to recompute and no far targets to compare with every changed block, and its
//! far targets (never-seen inner surfaces) are searched by block.
//!
//! With a cap, distances at or above the cap are stored as +∞ and searches are bounded by it.

use crate::fusion::FusedCloud;
use crate::grid::{
    above, block_of, cell_of_key, dist2, keyed_points, local_coords, local_index, lower_best_over,
    nearest_in, nearest_in_block, nearest_in_block_with, runs_in_box, Aabb, BlockSearch, Bucketed,
    ChangedBlocks, Domain, Slab, SuperGrid, BLOCK, BLOCK_CELLS, BLOCK_SHIFT, NONE,
};
use rayon::prelude::*;

/// [`Targets::update`] searches every distance again when at least one slot in `PULL_SHARE`
/// changed since the previous update.
const PULL_SHARE: usize = 2;

/// The immutable spatial index of a target set, shared (behind an `Arc`) by every episode
/// on the same scene: building it sorts every point, which is most of an episode's set-up.
#[derive(Debug)]
struct TargetIndex {
    domain: Domain,
    /// Points sorted by (block, fine voxel).
    pts: Vec<[f64; 3]>,
    /// Domain block → index into `cell_start` (or NONE).
    table: Vec<u32>,
    /// Per target block: start offsets of its 512 voxels into `pts` (513 entries).
    cell_start: Vec<[u32; BLOCK_CELLS + 1]>,
    /// Per target block: its rows along x that hold targets (bit y + 8z of the block's local
    /// y, z), so that walks over boxes skip the empty ones without reading their offsets.
    rows: Vec<u64>,
    /// The target blocks by superblock (far nearest searches).
    supergrid: SuperGrid,
    /// Per target block: its slab for nearest searches ([`Bucketed::block_slab`]), made by
    /// the first search that needs it (the points never change, so once per scene).
    slabs: Vec<std::sync::OnceLock<Slab>>,
}

impl TargetIndex {
    /// The index range of the targets in target block `t`.
    fn block_range(&self, t: u32) -> std::ops::Range<usize> {
        let s = &self.cell_start[t as usize];
        s[0] as usize..s[BLOCK_CELLS] as usize
    }

    /// Calls `f(target block, first, end)` with the index range of the targets in the fine
    /// voxels within `r` (per axis) of voxel `k`: runs of consecutive voxels along x within one
    /// block, which are contiguous in the sorted points.
    #[inline]
    fn for_runs_around(&self, k: [i32; 3], r: i32, f: impl FnMut(u32, u32, u32)) {
        self.for_runs_in_box(k.map(|x| x - r), k.map(|x| x + r), f)
    }

    /// Calls `f(first, end)` with the index range of the targets of each row along x of the
    /// box `lo..=hi` (voxel keys) within one block, leaving out the rows of the block without
    /// targets (from the blocks' row masks, so their offsets are never read): the runs of
    /// [`TargetIndex::for_runs_in_box`] less those, in another order (callers must not depend
    /// on it). A run can still be empty where its row's targets lie outside the box.
    fn for_filled_runs_in_box(&self, lo: [i32; 3], hi: [i32; 3], mut f: impl FnMut(u32, u32)) {
        let (blo, bhi) = (block_of(lo), block_of(hi));
        // The local coordinates `lo..=hi` of the box within block `b` along an axis.
        let span = |a: usize, b: i32| {
            let base = b << BLOCK_SHIFT;
            ((lo[a].max(base) - base) as u32, (hi[a].min(base + BLOCK - 1) - base) as u32)
        };
        for bz in blo[2]..=bhi[2] {
            let (z0, z1) = span(2, bz);
            // Rows y + 8z with z in z0..=z1: bytes z0..=z1 of the mask.
            let zmask = (!0u64 >> (8 * (7 - z1))) & (!0u64 << (8 * z0));
            for by in blo[1]..=bhi[1] {
                let (y0, y1) = span(1, by);
                let ybyte = (0xffu64 >> (7 - y1)) & (0xffu64 << y0);
                let mask = zmask & (ybyte * 0x0101_0101_0101_0101);
                for bx in blo[0]..=bhi[0] {
                    let Some(b) = self.domain.block_index([bx, by, bz]) else { continue };
                    let t = self.table[b];
                    if t == NONE {
                        continue;
                    }
                    let mut m = self.rows[t as usize] & mask;
                    if m == 0 {
                        continue;
                    }
                    let (x0, x1) = span(0, bx);
                    let s = &self.cell_start[t as usize];
                    while m != 0 {
                        let row = (m.trailing_zeros() as usize) << BLOCK_SHIFT;
                        m &= m - 1;
                        f(s[row + x0 as usize], s[row + x1 as usize + 1]);
                    }
                }
            }
        }
    }

    /// [`TargetIndex::for_runs_around`] for the voxels of the box `lo..=hi` (voxel keys).
    #[inline]
    fn for_runs_in_box(&self, lo: [i32; 3], hi: [i32; 3], mut f: impl FnMut(u32, u32, u32)) {
        runs_in_box(&self.domain, lo, hi, |b, first, len| {
            let t = self.table[b];
            if t == NONE {
                return;
            }
            let starts = &self.cell_start[t as usize];
            let li = local_index(first);
            f(t, starts[li], starts[li + len]);
        });
    }
}

/// A fixed point set with its nearest-fused distances. Cloning a fresh set (before its first
/// update) is the cheap way to start another episode on the same points: the index is shared.
#[derive(Debug, Clone)]
pub struct Targets {
    ix: std::sync::Arc<TargetIndex>,
    /// Nearest-fused d² (∞: none, or ≥ cap).
    pub d2: Vec<f64>,
    /// Nearest slot, or NONE.
    nn: Vec<u32>,
    /// Targets with d² > h² at the start of the next update.
    far: Vec<u32>,
    cap2: f64,
    mark: Vec<u32>,
    epoch: u32,
    /// The fused cloud's epoch at the previous update: slots stamped later have changed since.
    seen: u32,
}

impl Targets {
    /// Indexes `points` in `domain` (points outside the domain are an error naming how many).
    /// `cap`: distances at or above it are only known to be "≥ cap" (∞ for exact distances).
    pub fn new(domain: Domain, points: &[[f64; 3]], cap: f64) -> Result<Targets, String> {
        let keyed = keyed_points(&domain, points)?;
        let mut table = vec![NONE; domain.num_blocks()];
        let mut cell_start: Vec<[u32; BLOCK_CELLS + 1]> = Vec::new();
        let mut rows = Vec::new();
        let mut supergrid = SuperGrid::new(&domain);
        let mut pts = Vec::with_capacity(keyed.order.len());
        // The runs of one block at a time; a voxel without points starts where the next one does.
        for block_runs in keyed.runs.chunk_by(|a, b| cell_of_key(a.0).0 == cell_of_key(b.0).0) {
            let b = cell_of_key(block_runs[0].0).0;
            let first = pts.len();
            let mut starts = [0u32; BLOCK_CELLS + 1];
            let mut next_cell = 0;
            for &(key, s, e) in block_runs {
                let c = cell_of_key(key).1;
                starts[next_cell..=c].fill(pts.len() as u32);
                pts.extend(keyed.order[s..e].iter().map(|&i| points[i as usize]));
                next_cell = c + 1;
            }
            starts[next_cell..].fill(pts.len() as u32);
            table[b] = cell_start.len() as u32;
            rows.push(row_mask(&starts));
            cell_start.push(starts);
            if let Some(h) = supergrid.add_block(domain.block_key(b)) {
                for &p in &pts[first..] {
                    supergrid.grow(h, p);
                }
            }
        }
        let n = pts.len();
        let slabs = (0..cell_start.len()).map(|_| std::sync::OnceLock::new()).collect();
        Ok(Targets {
            ix: std::sync::Arc::new(TargetIndex { domain, pts, table, cell_start, rows, supergrid, slabs }),
            d2: vec![f64::INFINITY; n],
            nn: vec![NONE; n],
            far: (0..n as u32).collect(),
            cap2: cap * cap,
            mark: vec![0; n],
            epoch: 0,
            seen: 0,
        })
    }

    /// Forgets every distance (as before the first update).
    pub fn reset(&mut self) {
        self.d2.iter_mut().for_each(|d| *d = f64::INFINITY);
        self.nn.iter_mut().for_each(|n| *n = NONE);
        self.far = (0..self.ix.pts.len() as u32).collect();
        self.epoch = 0;
        self.seen = 0;
        self.mark.iter_mut().for_each(|m| *m = 0);
    }

    /// Number of target points.
    pub fn len(&self) -> usize {
        self.ix.pts.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.ix.pts.is_empty()
    }

    /// The points (sorted by voxel; the order of [`Targets::d2`]).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.ix.pts
    }

    /// Number of targets with d² < τ² for each τ.
    pub fn counts(&self, taus: &[f64]) -> Vec<usize> {
        let mut counts = vec![0usize; taus.len()];
        let t2: Vec<f64> = taus.iter().map(|t| t * t).collect();
        for &d in &self.d2 {
            for (c, &t) in counts.iter_mut().zip(&t2) {
                if d < t {
                    *c += 1;
                }
            }
        }
        counts
    }

    /// Instantaneous fraction of targets with d² < τ² for each τ.
    pub fn fractions(&self, taus: &[f64]) -> Vec<f64> {
        let n = self.ix.pts.len().max(1) as f64;
        self.counts(taus).into_iter().map(|c| c as f64 / n).collect()
    }

    /// Mean d² (the GT→fused half of CD); ∞ while no fused point exists.
    pub fn mean_d2(&self) -> f64 {
        if self.ix.pts.is_empty() {
            return 0.0;
        }
        self.d2.iter().sum::<f64>() / self.ix.pts.len() as f64
    }

    /// Updates every distance to `fused` as it is now; `changed` must list every slot created or
    /// moved since the previous update (stamped after it), each once. `fused` must be on the
    /// targets' voxel grid (the same voxel size; the grid is anchored at the origin): panics
    /// otherwise.
    ///
    /// Returns, per changed slot, the squared distance to the nearest target (the fused→target
    /// distance, which the push finds for free within h; a full search otherwise).
    pub fn update(&mut self, fused: &FusedCloud, changed: &[u32]) -> Vec<f64> {
        // The push and the pairs find the targets around a slot by its voxel key.
        assert_eq!(fused.domain.h, self.ix.domain.h, "fused cloud and targets on different voxel grids");
        // Where most slots changed (the first update, a checkpoint after many views), every
        // distance is searched again; otherwise the changes are pushed to the targets near them.
        let pull = changed.len().saturating_mul(PULL_SHARE) >= fused.len();
        self.update_by(fused, changed, pull)
    }

    /// [`Targets::update`] by a full search of every distance (`pull`) or by pushing the
    /// changed slots (the same distances either way).
    fn update_by(&mut self, fused: &FusedCloud, changed: &[u32], pull: bool) -> Vec<f64> {
        if pull {
            return self.pull(fused, changed);
        }
        self.epoch += 1;
        let h2 = self.ix.domain.h * self.ix.domain.h;
        let mut recompute: Vec<u32> = Vec::new();
        // Far targets whose nearest slot moved: full search (checked before the push, which
        // may point them at slots that changed now).
        let seen = self.seen;
        self.seen = fused.epoch();
        for &i in &self.far {
            let iu = i as usize;
            if self.nn[iu] != NONE && fused.stamp[self.nn[iu] as usize] > seen {
                self.mark[iu] = self.epoch;
                recompute.push(i);
            }
        }
        let mut slot_min = vec![f64::INFINITY; changed.len()];
        // Push: targets in the 27 voxels around each changed slot.
        let ix = std::sync::Arc::clone(&self.ix);
        for (ci, &s) in changed.iter().enumerate() {
            let q = fused.pos[s as usize];
            let k = fused.key[s as usize];
            let mut own = f64::INFINITY;
            ix.for_runs_around(k, 1, |_, lo, hi| {
                for i in lo..hi {
                    let iu = i as usize;
                    let d = dist2(ix.pts[iu], q);
                    own = own.min(d);
                    if self.nn[iu] == s {
                        if d <= self.d2[iu] {
                            self.d2[iu] = if d < self.cap2 { d } else { f64::INFINITY };
                        } else if self.mark[iu] != self.epoch {
                            self.mark[iu] = self.epoch;
                            recompute.push(i);
                        }
                    } else if d < self.d2[iu] && d < self.cap2 {
                        self.d2[iu] = d;
                        self.nn[iu] = s;
                    }
                }
            });
            slot_min[ci] = own;
        }
        // Far targets: minimum with the changed slots, or a full search if their slot moved.
        // Both are pure per-target computations (run in parallel on the current rayon pool,
        // which helps a lone long episode), applied afterwards in target order.
        // Far targets with no nearest slot yet (nothing was fused near them): a nearest search
        // of the whole cloud, whose superblock index prunes far better than the changed-slot
        // groups when every slot is new to them (the first update of an episode's CD).
        let (fresh, far): (Vec<u32>, Vec<u32>) = std::mem::take(&mut self.far)
            .into_iter()
            .partition(|&i| self.nn[i as usize] == NONE && self.mark[i as usize] != self.epoch);
        if !fresh.is_empty() && !changed.is_empty() {
            // One batched search per target block (`fresh` is in voxel order, so a block's
            // targets are consecutive): the block's first answer bounds the others, and the
            // fused blocks that could beat those bounds are gathered once for all of them.
            let found = self.nearest_by_block(fused, &fresh);
            for (&i, &(d, s)) in fresh.iter().zip(&found) {
                if s != NONE {
                    self.d2[i as usize] = d;
                    self.nn[i as usize] = s;
                }
            }
        }
        if !far.is_empty() && !changed.is_empty() {
            let mut groups = ChangedBlocks::new(fused, changed);
            groups.make_slabs(self.ix.domain.h);
            // Far targets are sorted by block: one group per target block.
            let spans = self.block_spans(&far);
            let this = &*self;
            let updates: Vec<Vec<FarUpdate>> = spans
                .par_iter()
                .with_min_len(8)
                .map(|&(s, e)| {
                    this.far_block(fused, &groups, &far[s..e], this.block_of_point(far[s] as usize), seen)
                })
                .collect();
            for u in updates.iter().flatten() {
                let iu = u.target as usize;
                self.d2[iu] = u.d2;
                self.nn[iu] = u.nn;
                if u.resolved {
                    self.mark[iu] = 0;
                }
            }
        }
        // Targets whose nearest slot moved and that no changed slot settled: a full search,
        // batched by target block as for fresh targets.
        let mut todo: Vec<u32> =
            recompute.iter().copied().filter(|&i| self.mark[i as usize] == self.epoch).collect();
        todo.sort_unstable();
        let found = self.nearest_by_block(fused, &todo);
        for (&i, &(d, s)) in todo.iter().zip(&found) {
            (self.d2[i as usize], self.nn[i as usize]) =
                if s == NONE { (f64::INFINITY, NONE) } else { (d, s) };
        }
        // The next far list: previous far targets and recomputed ones still farther than h.
        let mut next: Vec<u32> =
            far.into_iter().chain(fresh).chain(recompute).filter(|&i| self.d2[i as usize] > h2).collect();
        next.sort_unstable();
        next.dedup();
        self.far = next;
        // Fused→target: exact when the push found a target within h (anything else is ≥ h);
        // otherwise a search bounded by the nearest target the push saw (∞ when none).
        for (m, &s) in slot_min.iter_mut().zip(changed) {
            if *m > h2 {
                *m = nearest_in(self, fused.pos[s as usize], *m).0;
            }
        }
        slot_min
    }

    /// Every target's distance searched again against the whole of `fused`, the targets of each
    /// target block in one batched search ([`nearest_in_block`]), with no fused → target
    /// distances: what [`Targets::counts`] needs after one insertion of a whole cloud (the
    /// observable reference's SC). With a cap, only distances below it are searched. Later
    /// [`Targets::update`]s continue from here (every slot of `fused` counts as seen).
    pub fn settle(&mut self, fused: &FusedCloud) {
        self.epoch += 1;
        self.seen = fused.epoch();
        let h2 = self.ix.domain.h * self.ix.domain.h;
        let ix = &*self.ix;
        let cap2 = self.cap2;
        let found: Vec<Vec<(f64, u32)>> = (0..ix.cell_start.len())
            .into_par_iter()
            .map_init(BlockSearch::default, |scratch, t| {
                let mut out = Vec::new();
                nearest_in_block(fused, &ix.pts[ix.block_range(t as u32)], cap2, scratch, &mut out);
                out
            })
            .collect();
        for (i, &(d, s)) in found.iter().flatten().enumerate() {
            (self.d2[i], self.nn[i]) = if s == NONE { (f64::INFINITY, NONE) } else { (d, s) };
        }
        self.far = (0..self.d2.len() as u32).filter(|&i| self.d2[i as usize] > h2).collect();
    }

    /// Every distance searched again (see [`Targets::update`]), in two stages:
    /// - *pairs*: every fused slot against the targets in the 27 fine voxels around it, each
    ///   pair once, lowering both the slot's distance and the target's (d², slot). A target or
    ///   slot whose best so found is below [`near2`] is settled: every point outside the 27
    ///   voxels around it is at least h (less rounding) away, and each point inside them was
    ///   paired with it (the 27-voxel neighbourhood is symmetric). A slot not settled so (the
    ///   ground truth is often sparser than the fusion grid) scans the 125 voxels around it,
    ///   which settle it below [`near2_at`]`(h, 2)`.
    /// - *searches* for the rest: the targets of each target block in one batched search of the
    ///   fused cloud ([`nearest_in_block`]: targets far from anything fused, such as never-seen
    ///   inner surfaces), and each slot still unsettled in a search of its own, bounded by its
    ///   best pair.
    ///
    /// A fused point lies on the observed surface, so most of both directions are settled by
    /// the pairs, each distance computed once for both. Before, every target had a batched
    /// search and every changed slot a search of its own, each starting with the lookups of the
    /// voxels around it: the mug's K = 5 checkpoint (300k targets, ~250k slots) took 140–165 ms
    /// that way, ~105 ms this way, of which ~35 ms the pairs and the rest the targets far from
    /// everything fused (one thread).
    fn pull(&mut self, fused: &FusedCloud, changed: &[u32]) -> Vec<f64> {
        self.epoch += 1;
        self.seen = fused.epoch();
        let ix = std::sync::Arc::clone(&self.ix);
        let near2 = near2(ix.domain.h);
        let h2 = ix.domain.h * ix.domain.h;
        // Pairs.
        self.d2.iter_mut().for_each(|d| *d = f64::INFINITY);
        self.nn.iter_mut().for_each(|n| *n = NONE);
        let near2_ring2 = near2_at(ix.domain.h, 2);
        let mut own = vec![f64::INFINITY; fused.len()];
        // The fused blocks in domain order (x fastest): a block's neighbours' targets were
        // mostly read shortly before.
        for &t in fused.table.iter().filter(|&&t| t != NONE) {
            let blk = &fused.blocks[t as usize];
            let base = blk.key.map(|x| x << BLOCK_SHIFT);
            blk.for_each_voxel(|li, s, p| {
                let l = local_coords(li);
                let k = [0, 1, 2].map(|a| base[a] + l[a] as i32);
                let mut best = f64::INFINITY;
                ix.for_filled_runs_in_box(k.map(|x| x - 1), k.map(|x| x + 1), |lo, hi| {
                    // The run as slices (one bounds check per run, not three per target).
                    let r = lo as usize..hi as usize;
                    let (d2s, nns) = (&mut self.d2[r.clone()], &mut self.nn[r.clone()]);
                    for ((&q, d2), nn) in ix.pts[r].iter().zip(d2s).zip(nns) {
                        let d = dist2(q, p);
                        best = best.min(d);
                        if d < *d2 || (d == *d2 && s < *nn) {
                            *d2 = d;
                            *nn = s;
                        }
                    }
                });
                // Exact below `near2` after the 27 voxels; otherwise the 125 around, exact below
                // `near2_ring2` (fused → target only: the targets' pairs are complete).
                if best >= near2 {
                    ix.for_filled_runs_in_box(k.map(|x| x - 2), k.map(|x| x + 2), |lo, hi| {
                        for &q in &ix.pts[lo as usize..hi as usize] {
                            best = best.min(dist2(q, p));
                        }
                    });
                }
                own[s as usize] = best;
            });
        }
        // Targets the pairs did not settle (in index order, so by block): a full search.
        let mut rest = Vec::new();
        for i in 0..self.d2.len() {
            if self.d2[i] >= near2 {
                rest.push(i as u32);
            } else if self.d2[i] >= self.cap2 {
                (self.d2[i], self.nn[i]) = (f64::INFINITY, NONE);
            }
        }
        // A target the pairs found nothing for has no slot in the 27 voxels around it.
        let d2 = &self.d2;
        let found = self.nearest_by_block_with(fused, &rest, |i| d2[i as usize] == f64::INFINITY);
        for (&i, &(d, s)) in rest.iter().zip(&found) {
            (self.d2[i as usize], self.nn[i as usize]) =
                if s == NONE { (f64::INFINITY, NONE) } else { (d, s) };
        }
        self.far = (0..self.d2.len() as u32).filter(|&i| self.d2[i as usize] > h2).collect();
        // Fused → target for the changed slots.
        let this = &*self;
        changed
            .par_iter()
            .with_min_len(1024)
            .map(|&s| {
                let b = own[s as usize];
                if b < near2_ring2 {
                    b
                } else {
                    let bound = if b.is_finite() { above(b) } else { f64::INFINITY };
                    nearest_in(this, fused.pos[s as usize], bound).0
                }
            })
            .collect()
    }

    /// For a target whose nearest slot moved in this step: d² to that slot's new position and
    /// the slot — an upper bound of its new distance —, or `(cap², NONE)` when that is not
    /// below the cap.
    fn moved_bound(&self, fused: &FusedCloud, i: usize) -> (f64, u32) {
        match self.nn[i] {
            NONE => (self.cap2, NONE),
            n => {
                let d = dist2(self.ix.pts[i], fused.pos[n as usize]);
                if d < self.cap2 {
                    (d, n)
                } else {
                    (self.cap2, NONE)
                }
            }
        }
    }

    /// The far targets `idx` of target block `tb` against the changed slots: the updates of
    /// those whose distance changed (`resolved`: a target whose nearest slot moved and whose
    /// answer is now known without a search).
    fn far_block(
        &self,
        fused: &FusedCloud,
        groups: &ChangedBlocks,
        idx: &[u32],
        tb: [i32; 3],
        seen: u32,
    ) -> Vec<FarUpdate> {
        let h2 = self.ix.domain.h * self.ix.domain.h;
        let mut out = Vec::new();
        let mut max_d2: f64 = 0.0;
        for &i in idx {
            let iu = i as usize;
            let bound = if self.mark[iu] == self.epoch {
                // Nearest slot moved: its new position bounds the answer.
                self.moved_bound(fused, iu).0
            } else {
                self.d2[iu].min(self.cap2)
            };
            max_d2 = max_d2.max(bound);
        }
        if max_d2 <= 0.0 {
            return out;
        }
        let mut cand: Vec<(f64, usize)> = Vec::new();
        groups.candidates(&self.ix.domain, tb, max_d2, &mut cand);
        if cand.is_empty() {
            // No changed slot is close enough to improve any target of this block.
            return out;
        }
        cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for &i in idx {
            let iu = i as usize;
            let p = self.ix.pts[iu];
            let moved = self.mark[iu] == self.epoch;
            let mut best =
                if moved { self.moved_bound(fused, iu) } else { (self.d2[iu].min(self.cap2), self.nn[iu]) };
            if !moved && best.0 <= 4.0 * h2 {
                // Close: the changed slots within √d² lie in the fine voxels within
                // ⌈√d²/h⌉ ≤ 2 of p's.
                let k = self.ix.domain.key(p);
                let r = (best.0.sqrt() / self.ix.domain.h).ceil() as i32;
                for dz in -r..=r {
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let s = fused.slot_at([k[0] + dx, k[1] + dy, k[2] + dz]);
                            if s != NONE && fused.stamp[s as usize] > seen {
                                let d = dist2(p, fused.pos[s as usize]);
                                if d < best.0 {
                                    best = (d, s);
                                }
                            }
                        }
                    }
                }
            } else {
                for &(lb, gi) in &cand {
                    if lb >= best.0 {
                        break;
                    }
                    if !groups.may_beat(gi, p, best.0) {
                        continue;
                    }
                    let (d, j) = groups.nearest_in_group(&groups.blocks[gi], p);
                    if d < best.0 {
                        best = (d, groups.slots[j]);
                    }
                }
            }
            if moved {
                // Every unchanged slot is at least as far as the stored distance (the minimum
                // before this step, or a changed slot's distance the push found): if a changed
                // slot is that close, it is the answer and no search is needed.
                if best.0 <= self.d2[iu] && best.1 != NONE {
                    out.push(FarUpdate { target: i, d2: best.0, nn: best.1, resolved: true });
                }
            } else if best.0 < self.d2[iu] && best.0 < self.cap2 {
                out.push(FarUpdate { target: i, d2: best.0, nn: best.1, resolved: false });
            }
        }
        out
    }

    /// The nearest slot below the cap of each target of `idx` (increasing): `(d², slot)` or
    /// `(cap², NONE)`, by one [`nearest_in_block`] per target block (a block's targets are
    /// consecutive), in parallel on the current rayon pool.
    fn nearest_by_block(&self, fused: &FusedCloud, idx: &[u32]) -> Vec<(f64, u32)> {
        self.nearest_by_block_with(fused, idx, |_| false)
    }

    /// [`Targets::nearest_by_block`], told which targets have no fused point in the 27 voxels
    /// around them (`nothing_near(target)`; see [`nearest_in_block_with`]).
    fn nearest_by_block_with(
        &self,
        fused: &FusedCloud,
        idx: &[u32],
        nothing_near: impl Fn(u32) -> bool + Sync,
    ) -> Vec<(f64, u32)> {
        let found: Vec<Vec<(f64, u32)>> = self
            .block_spans(idx)
            .par_iter()
            .map_init(
                || (BlockSearch::default(), Vec::new()),
                |(scratch, pts), &(s, e)| {
                    pts.clear();
                    pts.extend(idx[s..e].iter().map(|&i| self.ix.pts[i as usize]));
                    let mut out = Vec::with_capacity(e - s);
                    let span = &idx[s..e];
                    nearest_in_block_with(fused, pts, self.cap2, scratch, &mut out, |j| {
                        nothing_near(span[j])
                    });
                    out
                },
            )
            .collect();
        found.into_iter().flatten().collect()
    }

    /// The runs of `idx` (target indices in increasing order) that share a target block:
    /// `(start, end)` into `idx`.
    fn block_spans(&self, idx: &[u32]) -> Vec<(usize, usize)> {
        equal_runs(idx.len(), |j| self.block_of_point(idx[j] as usize))
    }

    /// Target-block index of point `i` (points are sorted by block).
    fn block_of_point(&self, i: usize) -> [i32; 3] {
        block_of(self.ix.domain.key(self.ix.pts[i]))
    }
}

/// Below this d², a nearest point found among the 27 fine voxels around a point (voxel size
/// `h`) is its nearest overall: every point outside them differs by at least two voxels along
/// some axis, so lies at least h away, less the slack of the rounded voxel keys (a point filed
/// in voxel k may lie an ulp or so outside k's exact box; 1e-9 per side, as `FACE_MARGIN`
/// in the grid's scans, is millions of ulps at these coordinates).
fn near2(h: f64) -> f64 {
    near2_at(h, 1)
}

/// [`near2`] for the (2r + 1)³ voxels around a point: everything outside them is at least r·h
/// away (less the same slack).
fn near2_at(h: f64, r: i32) -> f64 {
    let d = r as f64 * h - 4e-9;
    d * d
}

/// The maximal runs `(start, end)` of `0..n` over which `key` stays the same.
fn equal_runs<K: PartialEq>(n: usize, key: impl Fn(usize) -> K) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut start = 0;
    while start < n {
        let k = key(start);
        let mut end = start + 1;
        while end < n && key(end) == k {
            end += 1;
        }
        spans.push((start, end));
        start = end;
    }
    spans
}

/// A far target's new distance (see [`Targets::far_block`]).
struct FarUpdate {
    target: u32,
    d2: f64,
    nn: u32,
    resolved: bool,
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn brute(targets: &Targets, fused: &FusedCloud, cap2: f64) -> Vec<f64> {
        targets
            .points()
            .iter()
            .map(|&p| {
                let d = fused.pos.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min);
                if d < cap2 {
                    d
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// A sphere patch of `n` targets (seeded) in a domain over [−0.6, 0.6]³ at h = 0.005, with
    /// its index (cap 0.01), and the generator to draw more from.
    fn patch_targets(seed: u64, n: usize) -> (rand_chacha::ChaCha8Rng, Domain, Vec<[f64; 3]>, Targets) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.05);
        let tp = patch(&mut rng, n);
        let t = Targets::new(domain.clone(), &tp, 0.01).unwrap();
        (rng, domain, tp, t)
    }

    /// Random "views": patches of a sphere of radius 0.5 sampled densely, with jitter, so
    /// voxels are revisited and centroids move.
    fn patch(rng: &mut rand_chacha::ChaCha8Rng, n: usize) -> Vec<[f64; 3]> {
        let c: [f64; 3] = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)];
        let cn = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        (0..n)
            .filter_map(|_| {
                let d: [f64; 3] = [
                    c[0] / cn + rng.gen_range(-0.5..0.5),
                    c[1] / cn + rng.gen_range(-0.5..0.5),
                    c[2] / cn + rng.gen_range(-0.5..0.5),
                ];
                let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                (dn > 0.0).then(|| [0.5 * d[0] / dn, 0.5 * d[1] / dn, 0.5 * d[2] / dn])
            })
            .collect()
    }

    #[test]
    fn incremental_distances_equal_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.05);
        // Targets: the sphere (radius 0.5) plus an inner sphere (never observed: stays far).
        let mut tp: Vec<[f64; 3]> = patch(&mut rng, 4000);
        tp.extend(patch(&mut rng, 4000));
        tp.extend(patch(&mut rng, 500).iter().map(|p| [p[0] * 0.5, p[1] * 0.5, p[2] * 0.5]));
        for cap in [f64::INFINITY, 0.03] {
            // Updated after every insertion, and only after every third one (as at checkpoints:
            // the changes of several insertions at once); by pushing the changes only, by
            // searching everything again only, and by turns (each way continues the other's
            // state), and as `update` chooses.
            // Four target sets, one per way, follow the same fused cloud (one brute force each).
            for every in [1usize, 3] {
                let mut fused = FusedCloud::new(domain.clone());
                let mut ts: Vec<Targets> =
                    (0..4).map(|_| Targets::new(domain.clone(), &tp, cap).unwrap()).collect();
                assert_eq!(ts[0].len(), tp.len());
                let mut seen = 0;
                for step in 0..9 {
                    let obs = patch(&mut rng, 6000);
                    fused.insert(&obs);
                    if (step + 1) % every != 0 {
                        continue;
                    }
                    let changed = fused.changed_since(seen);
                    seen = fused.epoch();
                    let want = brute(&ts[0], &fused, cap * cap);
                    let want_slot: Vec<f64> = changed
                        .iter()
                        .map(|&s| {
                            let q = fused.pos[s as usize];
                            ts[0].points().iter().map(|&p| dist2(p, q)).fold(f64::INFINITY, f64::min)
                        })
                        .collect();
                    for (mode, t) in ts.iter_mut().enumerate() {
                        let to_t = match mode {
                            0 => t.update_by(&fused, &changed, false),
                            1 => t.update_by(&fused, &changed, true),
                            2 => t.update_by(&fused, &changed, step % 2 == 1),
                            _ => t.update(&fused, &changed),
                        };
                        assert_eq!(to_t, want_slot, "fused→target distances, mode {mode} step {step}");
                        for (i, (&a, &b)) in t.d2.iter().zip(&want).enumerate() {
                            assert!(
                                a == b,
                                "cap {cap} every {every} mode {mode} step {step} target {i}: {a} vs brute {b}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    #[should_panic(expected = "different voxel grids")]
    fn an_update_from_a_cloud_on_another_grid_panics() {
        let (mut rng, _, _, mut t) = patch_targets(4, 500);
        let mut fused = FusedCloud::new(Domain::covering(0.004, [-0.6; 3], [0.6; 3], 0.05));
        fused.insert(&patch(&mut rng, 1000));
        let changed = fused.changed_since(0);
        t.update(&fused, &changed);
    }

    #[test]
    fn pulled_distances_equal_brute_force_in_every_regime() {
        // Sparse targets (a few centimetres apart, h = 5 mm) on the sphere the fused points
        // come from, plus an inner sphere: fused slots whose nearest target lies within h (the
        // pairs settle them), between h and 2h (the 125 voxels), beyond 2h (a search), and
        // targets near and far from everything fused.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.05);
        let mut tp: Vec<[f64; 3]> = patch(&mut rng, 900);
        tp.extend(patch(&mut rng, 3000));
        tp.extend(patch(&mut rng, 300).iter().map(|p| [p[0] * 0.6, p[1] * 0.6, p[2] * 0.6]));
        let h = domain.h;
        let (n1, n2) = (near2(h), near2_at(h, 2));
        for cap in [f64::INFINITY, 0.03] {
            let mut fused = FusedCloud::new(domain.clone());
            let mut hits = [0usize; 5];
            for step in 0..4 {
                fused.insert(&patch(&mut rng, 5000));
                let changed = fused.changed_since(0);
                let mut t = Targets::new(domain.clone(), &tp, cap).unwrap();
                let to_t = t.update_by(&fused, &changed, true);
                for (&s, &d) in changed.iter().zip(&to_t) {
                    let q = fused.pos[s as usize];
                    let want = tp.iter().map(|&p| dist2(p, q)).fold(f64::INFINITY, f64::min);
                    assert_eq!(d, want, "cap {cap} step {step} slot {s}");
                    hits[if d < n1 {
                        0
                    } else if d < n2 {
                        1
                    } else {
                        2
                    }] += 1;
                }
                let want = brute(&t, &fused, cap * cap);
                assert_eq!(t.d2, want, "cap {cap} step {step}");
                // The nearest slots named are at those distances, and `far` lists the targets
                // beyond h, as a push continuing from here expects.
                for (i, &d) in t.d2.iter().enumerate() {
                    if d.is_finite() {
                        assert_eq!(dist2(t.points()[i], fused.pos[t.nn[i] as usize]), d);
                    } else {
                        assert_eq!(t.nn[i], NONE);
                    }
                    hits[if d < n1 { 3 } else { 4 }] += 1;
                }
                let far: Vec<u32> = (0..t.len() as u32).filter(|&i| t.d2[i as usize] > h * h).collect();
                assert_eq!(t.far, far);
            }
            assert!(hits.iter().all(|&n| n > 0), "cap {cap}: every regime met: {hits:?}");
        }
    }

    #[test]
    fn settled_distances_equal_brute_force_and_updates_continue_from_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.05);
        let mut tp: Vec<[f64; 3]> = patch(&mut rng, 4000);
        tp.extend(patch(&mut rng, 500).iter().map(|p| [p[0] * 0.5, p[1] * 0.5, p[2] * 0.5]));
        let taus = [0.01, 0.02, 0.03];
        for cap in [f64::INFINITY, 0.03] {
            let mut fused = FusedCloud::new(domain.clone());
            // Settled once after the second insertion, then brought along by `update`.
            let mut carried = Targets::new(domain.clone(), &tp, cap).unwrap();
            let mut seen = 0;
            for step in 0..6 {
                fused.insert(&patch(&mut rng, 6000));
                let want = brute(&carried, &fused, cap * cap);
                // A fresh set settled on the cloud as it is now.
                let mut fresh = Targets::new(domain.clone(), &tp, cap).unwrap();
                fresh.settle(&fused);
                assert_eq!(fresh.d2, want, "cap {cap} step {step}: settled");
                // Counts below the cap are those of the exact distances.
                let mut exact = Targets::new(domain.clone(), &tp, f64::INFINITY).unwrap();
                exact.settle(&fused);
                assert_eq!(fresh.counts(&taus), exact.counts(&taus), "cap {cap} step {step}");
                if step == 1 {
                    carried.settle(&fused);
                    seen = fused.epoch();
                } else if step > 1 {
                    let changed = fused.changed_since(seen);
                    seen = fused.epoch();
                    carried.update(&fused, &changed);
                }
                if step >= 1 {
                    assert_eq!(carried.d2, want, "cap {cap} step {step}: updated after settling");
                }
            }
            // Some targets lie beyond the cap (the inner sphere) and some within it.
            let n_inf = carried.d2.iter().filter(|d| d.is_infinite()).count();
            assert!(n_inf > 0 || cap.is_infinite());
            assert!(n_inf < carried.len());
        }
    }

    #[test]
    fn mark_within_equals_brute_force() {
        let (mut rng, _, tp, t) = patch_targets(9, 5000);
        // Sparse points (mostly one per voxel) and dense ones around the targets (many per
        // voxel, as a fused view).
        let sparse = patch(&mut rng, 800);
        let mut dense: Vec<[f64; 3]> = (0..20_000)
            .map(|_| {
                let p = tp[rng.gen_range(0..tp.len())];
                std::array::from_fn(|a| p[a] + rng.gen_range(-0.02..0.02))
            })
            .collect();
        // And points outside the targets' domain, near it and far from it.
        dense.extend([[3.0, 0.0, 0.0], [-0.7, 0.1, 0.0], [0.0, 0.0, -1e6], [0.2, -0.69, 0.3]]);
        for (n, pts) in [("sparse", &sparse), ("dense", &dense)] {
            for tau in [0.004, 0.01, 0.023] {
                let mut bits = vec![0u64; t.len().div_ceil(64)];
                t.mark_within(pts, tau, &mut bits);
                let mut marked = 0;
                for (i, &p) in t.points().iter().enumerate() {
                    let want = pts.iter().any(|&q| dist2(p, q) < tau * tau);
                    assert_eq!(bits[i / 64] >> (i % 64) & 1 == 1, want, "n {n} tau {tau} target {i}");
                    marked += want as usize;
                }
                // Neither trivial case (the largest τ may reach every target of the dense set).
                assert!(marked > 0 && (marked < t.len() || tau > 0.02), "n {n} tau {tau}: {marked}");
            }
        }
    }

    #[test]
    fn mark_within_points_with_nan_or_infinite_coordinates_mark_nothing() {
        // Targets in voxel 0 (where a NaN coordinate is keyed) and around it.
        let h = 0.005;
        let domain = Domain::covering(h, [-0.05; 3], [0.05; 3], 0.0);
        let tp = vec![[0.001, 0.001, 0.001], [0.004, 0.002, 0.003], [-0.003, 0.0, 0.0]];
        let t = Targets::new(domain, &tp, 0.1).unwrap();
        let bad = [
            [f64::NAN, 0.001, 0.001],
            [0.001, f64::NAN, f64::NAN],
            [f64::INFINITY, 0.0, 0.0],
            [0.0, f64::NEG_INFINITY, 0.0],
        ];
        for tau in [0.002, 0.01, 0.03] {
            let mut bits = vec![0u64; 1];
            t.mark_within(&bad, tau, &mut bits);
            assert_eq!(bits[0], 0, "tau {tau}");
        }
        // A finite point among them still marks what it reaches.
        let mut bits = vec![0u64; 1];
        t.mark_within(&[bad[0], [0.002, 0.002, 0.002]], 0.01, &mut bits);
        assert_eq!(bits[0], 0b111);
    }

    #[test]
    fn mark_within_in_block_order_skips_the_sort_and_marks_the_same() {
        // A fused view's centroids (listed by block, as the oracle passes them: the no-sort
        // path) and the same points reversed (the sorting path) mark what brute force marks.
        let (mut rng, domain, tp, t) = patch_targets(33, 6000);
        let raw: Vec<[f64; 3]> = (0..30_000)
            .map(|_| {
                let p = tp[rng.gen_range(0..tp.len())];
                std::array::from_fn(|a| p[a] + rng.gen_range(-0.02..0.02))
            })
            .collect();
        let view = crate::fusion::frame_centroids(&domain, &raw);
        let reversed: Vec<[f64; 3]> = view.iter().rev().copied().collect();
        for tau in [0.006, 0.01, 0.017] {
            let brute: Vec<bool> =
                t.points().iter().map(|&p| view.iter().any(|&q| dist2(p, q) < tau * tau)).collect();
            for (name, pts, sorted) in [("block order", &view, 1), ("reversed", &reversed, 0)] {
                let before = SORTED_WALKS.with(|c| c.get());
                let mut bits = vec![0u64; t.len().div_ceil(64)];
                t.mark_within(pts, tau, &mut bits);
                assert_eq!(SORTED_WALKS.with(|c| c.get()) - before, sorted, "{name}: path taken");
                for (i, &want) in brute.iter().enumerate() {
                    assert_eq!(bits[i / 64] >> (i % 64) & 1 == 1, want, "{name} tau {tau} target {i}");
                }
            }
            let marked = brute.iter().filter(|&&b| b).count();
            assert!(marked > 0 && marked < t.len(), "tau {tau}: {marked}");
        }
    }

    #[test]
    fn filled_runs_are_the_nonempty_runs_of_the_box() {
        // Random boxes (inside, across and beyond the domain's edges) over a sphere patch:
        // the filled runs hold exactly the targets of the box's runs, each run once, and
        // leave out the runs of rows without targets.
        let (mut rng, _, _, t) = patch_targets(31, 20_000);
        let ix = &t.ix;
        let (klo, khi) = ix.domain.key_box();
        let (mut nonempty_total, mut skipped) = (0, 0);
        for case in 0..300 {
            let lo: [i32; 3] = std::array::from_fn(|a| rng.gen_range(klo[a] - 20..=khi[a]));
            let mut hi: [i32; 3] =
                std::array::from_fn(|a| lo[a] + rng.gen_range(0..if case % 3 == 0 { 60 } else { 14 }));
            if case % 10 == 0 {
                // An empty box (`mark_within` clips group boxes to the domain, which can empty
                // them along an axis): no run at all.
                hi[case / 10 % 3] = lo[case / 10 % 3] - 1 - (case / 30) as i32;
            }
            let (mut want, mut all) = (Vec::new(), 0);
            ix.for_runs_in_box(lo, hi, |_, a, b| {
                all += 1;
                if a < b {
                    want.push((a, b));
                }
            });
            let (mut got, mut filled) = (Vec::new(), 0);
            ix.for_filled_runs_in_box(lo, hi, |a, b| {
                filled += 1;
                if a < b {
                    got.push((a, b));
                }
            });
            want.sort_unstable();
            got.sort_unstable();
            assert_eq!(got, want, "box {lo:?}..={hi:?}");
            assert!(filled <= all, "box {lo:?}..={hi:?}: {filled} filled runs of {all}");
            nonempty_total += want.len();
            skipped += all - filled;
        }
        assert!(nonempty_total > 1000, "too few runs with targets: {nonempty_total}");
        assert!(
            skipped > nonempty_total,
            "rows without targets: {skipped} skipped, {nonempty_total} with targets"
        );
    }

    #[test]
    fn bit_ranges_set_exactly_their_bits() {
        for (a, b) in [(0, 0), (0, 1), (3, 64), (0, 64), (63, 65), (5, 200), (64, 128), (70, 70), (100, 191)]
        {
            let mut bits = vec![0u64; 4];
            bits[3] = 1 << 63; // a bit set before stays set
            set_bit_range(&mut bits, a, b);
            for i in 0..256 {
                let want = (a..b).contains(&i) || i == 255;
                assert_eq!(bits[i / 64] >> (i % 64) & 1 == 1, want, "range {a}..{b}, bit {i}");
            }
        }
    }

    #[test]
    fn own_voxel_marks_hold_at_the_voxel_diagonal() {
        // A target and a point at opposite corners of one voxel (d ≈ h√3) for τ just above
        // h√3 (marked without a test) and just below (the test decides: not marked), and τ
        // between the two thresholds of the shortcut (the test decides: marked).
        let h = 0.005;
        let domain = Domain::covering(h, [-0.1; 3], [0.1; 3], 0.0);
        let e = 1e-12;
        let target = [[10.0 * h + e; 3]];
        let point = [[11.0 * h - e; 3]];
        let t = Targets::new(domain, &target, 0.1).unwrap();
        let d = dist2(target[0], point[0]).sqrt();
        for (tau, want) in
            [(h * 3f64.sqrt() * 1.001, true), (d * (1.0 + 1e-7), true), (d * (1.0 - 1e-9), false)]
        {
            let mut bits = vec![0u64; 1];
            t.mark_within(&point, tau, &mut bits);
            assert_eq!(bits[0] == 1, want, "tau {tau} d {d}");
        }
    }

    #[test]
    fn mark_within_sees_points_just_outside_the_domain() {
        // Targets on the domain's faces; points outside it, within τ of them or not.
        let domain = Domain::covering(0.005, [-0.1; 3], [0.1; 3], 0.0);
        let e = 0.005 * (1 << BLOCK_SHIFT) as f64;
        let lo: [f64; 3] = std::array::from_fn(|a| domain.lo[a] as f64 * e);
        let hi: [f64; 3] = std::array::from_fn(|a| (domain.lo[a] + domain.dims[a]) as f64 * e);
        let tp = vec![
            [hi[0] - 1e-4, 0.0, 0.0],
            [lo[0] + 1e-4, 0.0, 0.0],
            [0.0, hi[1] - 1e-4, 0.0],
            [0.0, 0.0, lo[2]],
        ];
        let t = Targets::new(domain, &tp, 0.01).unwrap();
        let tau = 0.012;
        let pts = [
            [hi[0] + 0.0115, 0.0, 0.0],  // 0.0116 from the first target: marked
            [lo[0] - 0.0125, 0.0, 0.0],  // 0.0126 from the second: not marked
            [0.0, hi[1] + 0.006, 0.001], // marked
            [0.0, 0.003, lo[2] - 0.011], // marked
            [40.0, 0.0, 0.0],
        ];
        let mut bits = vec![0u64; 1];
        t.mark_within(&pts, tau, &mut bits);
        for (i, &p) in t.points().iter().enumerate() {
            let want = pts.iter().any(|&q| dist2(p, q) < tau * tau);
            assert_eq!(bits[0] >> i & 1 == 1, want, "target {i} at {p:?}");
        }
        assert_eq!(bits[0].count_ones(), 3);
    }

    #[test]
    fn mark_within_with_a_huge_tau_marks_what_brute_force_marks() {
        // τ of 2·10^7 voxels (too many possible groups to number: each point walks on its
        // own) and of 2^40 voxels (r capped): points far outside the domain, some within τ of
        // part of the targets (a nontrivial marking), one beyond τ of all of them.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.0);
        let tp: Vec<[f64; 3]> = (0..3000).map(|_| [0; 3].map(|_: i32| rng.gen_range(-0.5..0.5))).collect();
        let t = Targets::new(domain, &tp, f64::INFINITY).unwrap();
        for tau in [1e5, 0.005 * (1u64 << 40) as f64] {
            let pts = [[tau + 0.1, 0.0, 0.0], [0.0, -tau - 0.05, 0.02], [0.0, 0.0, 4.0 * tau]];
            let mut bits = vec![0u64; t.len().div_ceil(64)];
            t.mark_within(&pts, tau, &mut bits);
            let mut marked = 0;
            for (i, &p) in t.points().iter().enumerate() {
                let want = pts.iter().any(|&q| dist2(p, q) < tau * tau);
                assert_eq!(bits[i / 64] >> (i % 64) & 1 == 1, want, "tau {tau} target {i}");
                marked += want as usize;
            }
            assert!(marked > 0 && marked < t.len(), "tau {tau}: {marked} of {}", t.len());
        }
    }

    #[test]
    fn fractions_and_mean() {
        let domain = Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05);
        let tp = vec![[0.0, 0.0, 0.0], [0.015, 0.0, 0.0], [0.5, 0.0, 0.0]];
        let mut t = Targets::new(domain.clone(), &tp, f64::INFINITY).unwrap();
        let mut fused = FusedCloud::new(domain);
        fused.insert(&[[0.001, 0.0, 0.0]]);
        t.update(&fused, &fused.latest_changed());
        // Distances 0.001, 0.014, 0.499 (points sorted by voxel: same order here).
        let f = t.fractions(&[0.01, 0.02, 0.03]);
        assert_eq!(f, vec![1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0]);
        let mean = (0.001f64.powi(2) + 0.014f64.powi(2) + 0.499f64.powi(2)) / 3.0;
        assert!((t.mean_d2() - mean).abs() < 1e-12);
        assert!(
            Targets::new(Domain::covering(0.005, [0.0; 3], [0.1; 3], 0.0), &[[3.0, 0.0, 0.0]], 1.0).is_err()
        );
    }
}

impl Targets {
    /// Squared distance from `p` to the nearest target point (exact; ∞ when there are none).
    pub fn nearest_d2(&self, p: [f64; 3]) -> f64 {
        nearest_in(self, p, f64::INFINITY).0
    }

    /// Sets bit i of `bits` (targets in [`Targets::points`] order, 64 per word) for every
    /// target strictly closer than `tau` to one of `points` — the coverage of one fused view
    /// without distance bookkeeping (the oracle's per-candidate gains).
    ///
    /// When τ exceeds a voxel's diagonal, the targets in the fine voxel of a point are marked
    /// first, with no distance test (on a fused view's surface, most of what gets marked).
    /// Then the points are grouped by cubes of 8×8×8 fine voxels (with no sort when they come
    /// listed by block, as `fusion::frame_centroids` lists them); each group visits the fine
    /// voxels within ⌈τ/h⌉ of the box of its points' voxels once, as runs along x that are
    /// contiguous in the sorted targets (rows without targets skipped by the blocks' row
    /// masks), and tests each target
    /// not yet marked, first against the box of the group's points grown by τ (a target
    /// outside it is farther than τ from all of them), then against the points, four at a
    /// time, until one is close enough. A target is marked iff some point of some group is
    /// within τ: the same bits as testing every point against its own neighbourhood, with one
    /// walk per group instead of one per point and no test of a target already marked.
    pub fn mark_within(&self, points: &[[f64; 3]], tau: f64, bits: &mut [u64]) {
        let t2 = tau * tau;
        // Voxel arithmetic in i64, with r capped where every 32-bit key is within r of the
        // domain (any τ, however large, walks at most the domain's voxels).
        let r = (tau / self.ix.domain.h).ceil().min((1u64 << 34) as f64) as i64;
        // The box test's margin: a target outside the box grown by `m` differs from every
        // point by more than τ along some axis even after the rounding of `lo − m` (the
        // margin's 1e-9·τ + 1e-12 exceeds an ulp of any coordinate of a normalized scene),
        // so its computed d² (a sum of non-negative rounded squares, at least that axis's)
        // exceeds τ².
        let m = tau * (1.0 + 1e-9) + 1e-12;
        let d = &self.ix.domain;
        // The targets' voxels lie in `dlo..=dhi` (the domain's key box). A point whose voxel
        // lies more than r + 1 voxels outside them along an axis is more than τ + h from every
        // target and is left out.
        let (dlo, dhi) = d.key_box();
        let (dlo, dhi) = (dlo.map(i64::from), dhi.map(i64::from));
        let (kmin, kmax): ([i64; 3], [i64; 3]) =
            (std::array::from_fn(|a| dlo[a] - r - 1), std::array::from_fn(|a| dhi[a] + r + 1));
        let group_of = |k: [i64; 3]| k.map(|x| x >> MARK_GROUP_SHIFT);
        let (gmin, gmax) = (group_of(kmin), group_of(kmax));
        let span: [u64; 3] = std::array::from_fn(|a| (gmax[a] - gmin[a] + 1) as u64);
        let mut keys = Vec::new();
        d.keys_into(points, &mut keys);
        // Own voxels first: a target in the fine voxel of a point lies within h√3 of it (both
        // in one voxel), so when 3h² is below τ² with room to spare for rounding (1e-6
        // relative, against errors of ~1e-13 of h in the keys and the squares), every target
        // of an occupied voxel is marked at once, with no distance test — the test would mark
        // it too. The walks below skip marked targets, so on a fused view's surface they test
        // only the targets of empty voxels. (A point with a NaN coordinate, keyed to voxel 0,
        // is within τ of nothing and marks nothing here either.)
        if 3.0 * d.h * d.h * (1.0 + 1e-6) < t2 {
            for (&k, q) in keys.iter().zip(points) {
                if !q.iter().all(|x| x.is_finite()) {
                    continue;
                }
                let Some(b) = d.block_index(block_of(k)) else { continue };
                let t = self.ix.table[b];
                if t != NONE {
                    let s = &self.ix.cell_start[t as usize];
                    let li = local_index(k);
                    set_bit_range(bits, s[li] as usize, s[li + 1] as usize);
                }
            }
        }
        let kept = |j: usize| {
            let k = keys[j].map(i64::from);
            (0..3).all(|a| k[a] >= kmin[a] && k[a] <= kmax[a]).then_some(group_of(k))
        };
        // Marks the targets within τ of the points `members` (indices into `points`, kept, all
        // in one group): the voxels within r of the box of their voxels (inside the group's
        // cube, and on a surface patch often much thinner than it), clipped to the domain.
        let mut group = GroupPoints::default();
        let mut visit = |members: &mut dyn Iterator<Item = usize>| {
            let (mut klo, mut khi) = ([i64::MAX; 3], [i64::MIN; 3]);
            group.fill(members.map(|j| {
                for a in 0..3 {
                    klo[a] = klo[a].min(keys[j][a] as i64);
                    khi[a] = khi[a].max(keys[j][a] as i64);
                }
                points[j]
            }));
            let bx = group.aabb();
            let (lo, hi) = (bx.lo.map(|x| x - m), bx.hi.map(|x| x + m));
            let first: [i32; 3] = std::array::from_fn(|a| (klo[a] - r).max(dlo[a]) as i32);
            let last: [i32; 3] = std::array::from_fn(|a| (khi[a] + r).min(dhi[a]) as i32);
            self.ix.for_filled_runs_in_box(first, last, |a, b| {
                for i in a..b {
                    let (w, bit) = (i as usize / 64, 1u64 << (i % 64));
                    if bits[w] & bit == 0 {
                        let p = self.ix.pts[i as usize];
                        let inside = (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]);
                        if inside && group.any_within(p, t2) {
                            bits[w] |= bit;
                        }
                    }
                }
            });
        };
        match span[0].checked_mul(span[1]).and_then(|x| x.checked_mul(span[2])) {
            // Groups numbered within the box of possible groups (lexicographic, z first, so that
            // points listed by block as `fusion::frame_centroids` lists them come in order),
            // visited once. Points already in that order need no sort.
            Some(_) => {
                let mut numbered: Vec<(u64, u32)> = (0..points.len())
                    .filter_map(|j| {
                        let g = kept(j)?;
                        let rel: [u64; 3] = std::array::from_fn(|a| (g[a] - gmin[a]) as u64);
                        Some(((rel[2] * span[1] + rel[1]) * span[0] + rel[0], j as u32))
                    })
                    .collect();
                if numbered.is_sorted_by_key(|x| x.0) {
                    #[cfg(test)]
                    SORTED_WALKS.with(|c| c.set(c.get() + 1));
                } else {
                    numbered.sort_unstable();
                }
                for run in numbered.chunk_by(|x, y| x.0 == y.0) {
                    visit(&mut run.iter().map(|x| x.1 as usize));
                }
            }
            // Too many possible groups to number (only for a τ of millions of voxels): each
            // point walks its own neighbourhood, which marks the same targets.
            None => {
                for j in 0..points.len() {
                    if kept(j).is_some() {
                        visit(&mut std::iter::once(j));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
thread_local! {
    /// Calls of [`Targets::mark_within`] on this thread that took the no-sort path.
    static SORTED_WALKS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The points of one group of [`Targets::mark_within`], by coordinate and padded to a multiple
/// of [`GroupPoints::LANES`] with copies of the first point (a copy changes no answer), so that
/// the distance tests run a chunk of lanes at a time, which the compiler vectorizes.
#[derive(Default)]
struct GroupPoints {
    xyz: [Vec<f64>; 3],
    /// Points before the padding.
    n: usize,
}

impl GroupPoints {
    const LANES: usize = 4;

    fn fill(&mut self, points: impl Iterator<Item = [f64; 3]>) {
        self.xyz.iter_mut().for_each(Vec::clear);
        for q in points {
            for (c, x) in self.xyz.iter_mut().zip(q) {
                c.push(x);
            }
        }
        self.n = self.xyz[0].len();
        if self.n > 0 {
            let pad = self.n.next_multiple_of(Self::LANES);
            for c in &mut self.xyz {
                c.resize(pad, c[0]);
            }
        }
    }

    fn aabb(&self) -> Aabb {
        let mut bx = Aabb::EMPTY;
        for i in 0..self.n {
            bx.grow([self.xyz[0][i], self.xyz[1][i], self.xyz[2][i]]);
        }
        bx
    }

    /// Whether some point has [`dist2`] to `p` below `t2`: the same sums of squares in the
    /// same order as `dist2`, so the same answer as testing each point in turn.
    #[inline]
    fn any_within(&self, p: [f64; 3], t2: f64) -> bool {
        let [xs, ys, zs] = &self.xyz;
        xs.chunks_exact(Self::LANES).zip(ys.chunks_exact(Self::LANES)).zip(zs.chunks_exact(Self::LANES)).any(
            |((x, y), z)| {
                let mut hit = false;
                for l in 0..Self::LANES {
                    let d = [p[0] - x[l], p[1] - y[l], p[2] - z[l]];
                    hit |= d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < t2;
                }
                hit
            },
        )
    }
}

/// The rows along x of a block that hold targets (bit y + 8z), from its voxels' start offsets.
fn row_mask(starts: &[u32; BLOCK_CELLS + 1]) -> u64 {
    let b = BLOCK as usize;
    (0..b * b).filter(|&r| starts[r * b] < starts[r * b + b]).fold(0, |m, r| m | 1 << r)
}

/// Sets bits `a..b` of `bits` (64 per word).
fn set_bit_range(bits: &mut [u64], a: usize, b: usize) {
    if a >= b {
        return;
    }
    let (wa, wb) = (a / 64, (b - 1) / 64);
    let lo = !0u64 << (a % 64);
    let hi = !0u64 >> (63 - (b - 1) % 64);
    if wa == wb {
        bits[wa] |= lo & hi;
    } else {
        bits[wa] |= lo;
        bits[wa + 1..wb].iter_mut().for_each(|w| *w = !0);
        bits[wb] |= hi;
    }
}

/// [`Targets::mark_within`] groups its points by cubes of 2^this fine voxels per edge — the
/// blocks, whose order `fusion::frame_centroids` lists its centroids in (8: with
/// the own-voxel marks, the row masks and the four-lane tests, `oracle_bench` on ball-in-shell,
/// 0.005 voxels, τ = 0.01, took 15.5–16.2 ms per candidate against 18.2 ms with cubes of 4,
/// side by side; before those three changes 4 was best: time relative to fusion in the oracle's
/// runs on the mug 0.84–0.94 against 1.23 with 2, 1.10 with 8 and 1.46 with single voxels).
const MARK_GROUP_SHIFT: i32 = 3;

impl Bucketed for Targets {
    fn domain(&self) -> &Domain {
        &self.ix.domain
    }
    fn for_cell<F: FnMut(u32, [f64; 3])>(&self, k: [i32; 3], mut f: F) {
        let Some(b) = self.ix.domain.block_index(block_of(k)) else { return };
        let t = self.ix.table[b];
        if t != NONE {
            let s = &self.ix.cell_start[t as usize];
            let li = local_index(k);
            for i in s[li]..s[li + 1] {
                f(i, self.ix.pts[i as usize]);
            }
        }
    }
    fn for_block<F: FnMut(u32, [f64; 3])>(&self, b: [i32; 3], mut f: F) {
        let Some(bi) = self.ix.domain.block_index(b) else { return };
        let t = self.ix.table[bi];
        if t != NONE {
            for i in self.ix.block_range(t) {
                f(i as u32, self.ix.pts[i]);
            }
        }
    }
    fn lower_best_in_block(&self, b: [i32; 3], p: [f64; 3], best: &mut (f64, u32)) {
        let Some(bi) = self.ix.domain.block_index(b) else { return };
        let t = self.ix.table[bi];
        if t != NONE {
            let r = self.ix.block_range(t);
            let first = r.start as u32;
            lower_best_over(&self.ix.pts[r], |j| first + j as u32, p, best);
        }
    }
    fn supergrid(&self) -> &SuperGrid {
        &self.ix.supergrid
    }
    fn block_slab(&self, b: [i32; 3], aabb: &Aabb) -> Option<Slab> {
        let t = self.ix.table[self.ix.domain.block_index(b)?];
        if t == NONE {
            return None;
        }
        let ix = &self.ix;
        Some(
            *ix.slabs[t as usize]
                .get_or_init(|| Slab::of_block(aabb, ix.domain.h, &ix.pts[ix.block_range(t)])),
        )
    }
    #[inline]
    fn position(&self, index: u32) -> [f64; 3] {
        self.ix.pts[index as usize]
    }
    #[inline]
    fn for_cells_in_box<F: FnMut(u32, [f64; 3])>(&self, lo: [i32; 3], hi: [i32; 3], mut f: F) {
        self.ix.for_runs_in_box(lo, hi, |_, lo, hi| {
            for i in lo..hi {
                f(i, self.ix.pts[i as usize]);
            }
        });
    }
}

#[cfg(test)]
mod nearest_tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_27_voxel_runs_show_what_27_cell_lookups_show() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let domain = Domain::covering(0.005, [-0.1; 3], [0.1; 3], 0.0);
        let pts: Vec<[f64; 3]> = (0..6000).map(|_| [0; 3].map(|_: i32| rng.gen_range(-0.1..0.1))).collect();
        let t = Targets::new(domain, &pts, f64::INFINITY).unwrap();
        let shown = crate::grid::assert_around_matches_cells(&t, 19);
        assert!(shown > 3000, "the cases must see points: {shown}");
    }

    #[test]
    fn nearest_target_equals_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let domain = Domain::covering(0.005, [-1.0; 3], [1.0; 3], 0.05);
        let pts: Vec<[f64; 3]> = (0..3000)
            .map(|i| {
                if i % 10 == 0 {
                    [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)]
                } else {
                    [rng.gen_range(-0.2..0.2), 0.3 + rng.gen_range(-0.01..0.01), rng.gen_range(-0.2..0.2)]
                }
            })
            .collect();
        let t = Targets::new(domain, &pts, f64::INFINITY).unwrap();
        for _ in 0..500 {
            let p = [rng.gen_range(-1.0..1.0), rng.gen_range(-0.1..0.7), rng.gen_range(-1.0..1.0)];
            let want = pts.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min);
            assert_eq!(t.nearest_d2(p), want);
        }
    }
}
