//! SC@τ and NSC@τ of every step (SPEC §5): how many points of a fixed set (the ground truth for
//! SC, the observable reference for NSC) have a fused point at d² < τ² *now* — instantaneous
//! coverage against the current fused cloud, as the reference implementation computes it.
//! Exact, and bounded: only distances below τ_max matter, so nothing beyond τ_max is searched.
//!
//! Each target keeps its exact nearest-fused d² below τ_max² (∞ otherwise) and that slot —
//! except a target within τ_min of its slot, which is covered at every τ: it only keeps that
//! slot as a witness, and is looked at again only when the witness moves.
//! After an insertion only the changed slots (created or moved) can change a distance, and only
//! for targets within τ_max of them; the changed slots are grouped by block
//! ([`ChangedBlocks`]) and each target block with live targets looks at the groups within
//! τ_max of it:
//! - nearest slot unchanged: the new distance is min(old, nearest changed slot);
//! - nearest slot moved: every unchanged slot is still at least the old distance away, so the
//!   nearest changed slot is the answer when it is no farther than that; otherwise a nearest
//!   search of the whole cloud, bounded by the nearest changed slot, decides.
//!
//! *Retirement* keeps the work proportional to the part of the object still being discovered:
//! a fused point never leaves its voxel, so once an occupied voxel lies entirely within the
//! smallest τ of a target, that target is covered at every τ for the rest of the episode and
//! is never looked at again. On observed surfaces that happens at the first view that sees
//! them (the target's own voxel is within h√3 ≈ 0.0087 < 0.01 of all its points). Such a
//! target is settled before any search: each target knows which of the 27 voxels around it lie
//! entirely within τ_min of it (computed once per scene), and any of them occupied — its own
//! voxel, or a neighbour where the view left its own voxel empty (pixels are ~1.4 voxels wide
//! at the SPEC's distance) — retires it. Nothing reads a retired target's distance but the
//! comparisons with each τ², which it passes for good: it is stored as 0, and the occupied
//! voxel's slot and position are never looked up.
//!
//! A live target with nothing fused within τ_max (most of the live targets an update looks
//! at: the unseen side of a wall, the far half of a block next to a new patch) can change only
//! through a changed slot within τ_max of it: the targets of an octant of their block that no
//! changed group's box comes within τ_max of (tight boxes, so the test is a lower bound of every
//! computed distance) are passed by.
//!
//! The searching targets of a block scan the changed groups together, group by group, in the
//! order and with the running bounds a per-target walk would use (same answers), so that each
//! group's box is tested against all of them while it is at hand.

use std::sync::Arc;

use rayon::prelude::*;

use crate::fusion::{FusedBlock, FusedCloud};
use crate::grid::{
    box_box_dist2, cell_of_key, dist2, keyed_points, local_coords, local_index, Aabb, ChangedBlocks, Domain,
    BLOCK, NONE,
};

/// Safety margin (units²) of the retirement test: a voxel counts as inside the ball only with
/// this much to spare, so that a centroid rounded an ulp outside its voxel cannot matter.
const RETIRE_MARGIN2: f64 = 1e-12;

/// The immutable part of a target set, shared by every episode on the same scene.
#[derive(Debug)]
struct Index {
    domain: Domain,
    /// The points, sorted by (block, fine voxel).
    pts: Vec<[f64; 3]>,
    /// Per target block: its block key and the range of its points.
    blocks: Vec<([i32; 3], u32, u32)>,
    /// Per point: the local index of its own fine voxel, so that an update need not compute
    /// the point's key again (three divisions and floors per live target and step).
    own: Vec<u16>,
    /// Per point: which of the 27 fine voxels around its own (bit [`near_bit`]) lie entirely
    /// within τ_min of it (less the margin). Any of them occupied covers the point at every τ
    /// for good, so an update retires it without a search. At the SPEC's τ_min = 0.01 = 2h no
    /// voxel outside this neighbourhood qualifies (a voxel two cells away along an axis has a
    /// corner at least √(2² + ½² + ½²)·h ≈ 2.1h from any point of the own voxel); with a
    /// larger τ_min the farther ones still retire a target, after its search
    /// ([`Coverage::permanent`]).
    near: Vec<u32>,
    /// Per target block: the box of its points in each octant ([`octant_of`]; empty where it
    /// has none). A target with no fused point within τ_max in an octant that no changed group
    /// comes within τ_max of cannot change, so an update passes it by.
    octants: Vec<[Aabb; 8]>,
}

/// The octant (0..8, bit per axis: the upper half of the block) of the fine voxel with local
/// index `li` in its block.
#[inline]
fn octant_of(li: usize) -> usize {
    let half = BLOCK as usize / 2;
    let [x, y, z] = local_coords(li);
    (x / half) | (y / half) << 1 | (z / half) << 2
}

/// The bit of the fine voxel at offset `d` (each −1, 0 or 1 per axis) in [`Index::near`].
#[inline]
fn near_bit(d: [i32; 3]) -> u32 {
    ((d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1)) as u32
}

const _: () = assert!(crate::grid::BLOCK_CELLS <= u16::MAX as usize + 1);

/// Per-worker buffers of [`Coverage::block_changes`], kept across target blocks.
#[derive(Default)]
struct Scratch {
    /// Changed groups within τ_max of the block: (lower bound, group).
    cand: Vec<(f64, usize)>,
    /// The targets that search the groups, their positions by coordinate and their best
    /// (d², slot) so far.
    who: Vec<u32>,
    xyz: [Vec<f64>; 3],
    best: Vec<(f64, u32)>,
}

/// One update of a target (see [`Coverage::update`]).
struct Change {
    target: u32,
    d2: f64,
    nn: u32,
    retire: bool,
}

/// Instantaneous coverage of a fixed point set at up to 8 radii.
#[derive(Debug, Clone)]
pub struct Coverage {
    ix: Arc<Index>,
    /// τ² in the order of the τ list.
    t2: Vec<f64>,
    /// τ_max².
    r2: f64,
    /// τ_min².
    tmin2: f64,
    /// τ_min² less the margin: the retirement bound.
    retire2: f64,
    /// Nearest-fused d² (∞: none below τ_max) — exact while at least τ_min²; below τ_min² it
    /// is the distance to the slot `nn`, which covers the target at every τ, and may be an
    /// overestimate (nothing needs more); frozen once retired (0 when retired by an occupied
    /// voxel of its neighbourhood, whose point is never looked up).
    d2: Vec<f64>,
    /// Nearest slot, or NONE.
    nn: Vec<u32>,
    /// Per target block: its live (not retired) targets, ascending.
    live: Vec<Vec<u32>>,
    /// Target blocks with live targets, ascending.
    live_blocks: Vec<u32>,
    /// Per τ: targets with d² < τ².
    counts: Vec<usize>,
    retired: usize,
}

impl Coverage {
    /// The coverage of `points` at each τ of `taus` (1 to 8 positive radii), with nothing fused
    /// yet. Points outside `domain` are an error naming how many. The result's point order
    /// ([`Coverage::points`]) is by voxel, the same as [`crate::chamfer::Targets::points`].
    pub fn new(domain: Domain, points: &[[f64; 3]], taus: &[f64]) -> Result<Coverage, String> {
        if taus.is_empty() || taus.len() > 8 || taus.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(format!("coverage radii must be 1 to 8 positive numbers, got {taus:?}"));
        }
        let keyed = keyed_points(&domain, points)?;
        let pts: Vec<[f64; 3]> = keyed.order.iter().map(|&i| points[i as usize]).collect();
        let mut blocks = Vec::new();
        let mut live = Vec::new();
        for block_runs in keyed.runs.chunk_by(|a, b| cell_of_key(a.0).0 == cell_of_key(b.0).0) {
            let b = cell_of_key(block_runs[0].0).0;
            let (i, j) = (block_runs[0].1 as u32, block_runs[block_runs.len() - 1].2 as u32);
            blocks.push((domain.block_key(b), i, j));
            live.push((i..j).collect());
        }
        let n = pts.len();
        let t2: Vec<f64> = taus.iter().map(|t| t * t).collect();
        let r2 = t2.iter().cloned().fold(0.0, f64::max);
        let tmin2 = t2.iter().cloned().fold(f64::INFINITY, f64::min);
        let retire2 = tmin2 - RETIRE_MARGIN2;
        // Each point's key once: its own voxel, its octant and its neighbourhood's mask.
        let mut keys = Vec::new();
        domain.keys_into(&pts, &mut keys);
        let own: Vec<u16> = keys.iter().map(|&k| local_index(k) as u16).collect();
        let octants = blocks
            .iter()
            .map(|&(_, i, j)| {
                let mut boxes = [Aabb::EMPTY; 8];
                for t in i as usize..j as usize {
                    boxes[octant_of(own[t] as usize)].grow(pts[t]);
                }
                boxes
            })
            .collect();
        let near = pts
            .iter()
            .zip(&keys)
            .map(|(&p, &k)| {
                let mut m = 0u32;
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let kk = [k[0] + dx, k[1] + dy, k[2] + dz];
                            if max_corner_d2(domain.h, kk, p) < retire2 {
                                m |= 1 << near_bit([dx, dy, dz]);
                            }
                        }
                    }
                }
                m
            })
            .collect();
        Ok(Coverage {
            live_blocks: (0..blocks.len() as u32).collect(),
            ix: Arc::new(Index { domain, pts, blocks, own, near, octants }),
            counts: vec![0; t2.len()],
            t2,
            r2,
            tmin2,
            retire2,
            d2: vec![f64::INFINITY; n],
            nn: vec![NONE; n],
            live,
            retired: 0,
        })
    }

    /// Number of target points.
    pub fn len(&self) -> usize {
        self.ix.pts.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.ix.pts.is_empty()
    }

    /// The points (sorted by voxel: the order of [`Coverage::covered`]).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.ix.pts
    }

    /// Targets retired so far (covered at every τ for good).
    pub fn retired(&self) -> usize {
        self.retired
    }

    /// Per τ of the list: how many targets have a fused point at d² < τ² now.
    pub fn counts(&self) -> &[usize] {
        &self.counts
    }

    /// Per τ of the list: the covered fraction now (0 for an empty set).
    pub fn fractions(&self) -> Vec<f64> {
        let n = self.len().max(1) as f64;
        self.counts.iter().map(|&c| c as f64 / n).collect()
    }

    /// Whether each target (in [`Coverage::points`] order) is covered at τ_j now.
    pub fn covered(&self, j: usize) -> Vec<bool> {
        let t = self.t2[j];
        self.d2.iter().map(|&d| d < t).collect()
    }

    /// Brings the coverage to `fused` as it is now. `groups` holds the slots created or moved
    /// by its latest insertion ([`ChangedBlocks::new`] of the delta); the previous update must
    /// have seen the insertion before (one update per insertion).
    pub fn update(&mut self, fused: &FusedCloud, groups: &ChangedBlocks) {
        if groups.blocks.is_empty() || self.live_blocks.is_empty() {
            return;
        }
        let this = &*self;
        // Per run of target blocks (one per rayon split, not one per block): the changes of
        // their targets and the blocks where a target retired (their live lists shrink below).
        // Each target changes at most once, so the order of the changes does not matter.
        let changes: Vec<(Vec<Change>, Vec<u32>)> = self
            .live_blocks
            .par_iter()
            .enumerate()
            .with_min_len(16)
            .fold(
                // The scratch boxed: rayon moves the accumulator through every step of the fold,
                // and a pointer moves in registers where the buffers' headers took two memcpy
                // calls per target block.
                || (Box::<Scratch>::default(), Vec::new(), Vec::new()),
                |(mut sc, mut out, mut retired_in), (at, &tb)| {
                    if let Some(&next) = this.live_blocks.get(at + 1) {
                        this.prefetch_block(next);
                    }
                    let from = out.len();
                    this.block_changes(fused, groups, tb, &mut sc, &mut out);
                    if out[from..].iter().any(|c| c.retire) {
                        retired_in.push(tb);
                    }
                    (sc, out, retired_in)
                },
            )
            .map(|(_, out, retired_in)| (out, retired_in))
            .collect();
        let retired_in: Vec<u32> = changes.iter().flat_map(|(_, r)| r.iter().copied()).collect();
        for c in changes.iter().flat_map(|(c, _)| c) {
            let i = c.target as usize;
            let old = self.d2[i];
            if old != c.d2 {
                for (n, &t) in self.counts.iter_mut().zip(&self.t2) {
                    match (old < t, c.d2 < t) {
                        (false, true) => *n += 1,
                        (true, false) => *n -= 1,
                        _ => {}
                    }
                }
                self.d2[i] = c.d2;
                self.nn[i] = c.nn;
            }
            if c.retire {
                // Marked by NONE in `nn`: the distance is frozen below τ_min².
                self.nn[i] = NONE;
                self.retired += 1;
            }
        }
        if !retired_in.is_empty() {
            let (nn, d2) = (&self.nn, &self.d2);
            for &tb in &retired_in {
                self.live[tb as usize].retain(|&i| !(nn[i as usize] == NONE && d2[i as usize].is_finite()));
            }
            let live = &self.live;
            self.live_blocks.retain(|&tb| !live[tb as usize].is_empty());
        }
    }

    /// Asks the cache for the first data [`Coverage::block_changes`] reads of target block
    /// `tb` (a hint: see [`crate::prefetch`]).
    #[inline]
    fn prefetch_block(&self, tb: u32) {
        let live = &self.live[tb as usize];
        crate::prefetch::item(&self.ix.blocks[tb as usize]);
        crate::prefetch::range(&self.ix.octants[tb as usize..=tb as usize]);
        crate::prefetch::range(&live[..live.len().min(16)]);
        if let Some(&i) = live.first() {
            let i = i as usize;
            crate::prefetch::item(&self.d2[i]);
            crate::prefetch::item(&self.nn[i]);
            crate::prefetch::item(&self.ix.pts[i]);
            crate::prefetch::item(&self.ix.own[i]);
            crate::prefetch::item(&self.ix.near[i]);
        }
    }

    /// Appends to `out` the changes of the live targets of target block `tb` (see the module
    /// docs), using the worker's buffers `sc`.
    ///
    /// Three passes: each target is settled at once where it can be (nothing fused near it in
    /// an octant no change reaches: passed by; a qualifying voxel of its neighbourhood
    /// occupied: retired; covered by an unmoved witness: nothing to do) or gets its starting
    /// bound; then
    /// the changed groups are scanned group by group for all the searching targets together
    /// (each group's box tested against every target's bound while it is in registers,
    /// instead of every target walking the group list); then each target's answer is decided.
    /// Every target sees the groups in the same order and with the same running bound as a
    /// per-target walk would, so the answers (distances and slots) are those of one.
    fn block_changes(
        &self,
        fused: &FusedCloud,
        groups: &ChangedBlocks,
        tb: u32,
        sc: &mut Scratch,
        out: &mut Vec<Change>,
    ) {
        let domain = &self.ix.domain;
        let (key, _, _) = self.ix.blocks[tb as usize];
        sc.cand.clear();
        groups.candidates(domain, key, self.r2, &mut sc.cand);
        if sc.cand.is_empty() {
            // No changed slot within τ_max of this block: nothing in it can change.
            return;
        }
        sc.cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let epoch = fused.epoch();
        // The occupancy of the fused blocks around this target block (3×3×3) as rows along x,
        // made when the first target needs it (most blocks an update visits have none that
        // does): a target with an occupied voxel among those of its neighbourhood that lie
        // entirely within τ_min of it ([`Index::near`]) retires at once, with no search.
        let mut rows: Option<NeighbourRows> = None;
        sc.who.clear();
        sc.best.clear();
        sc.xyz.iter_mut().for_each(Vec::clear);
        // The searching targets' box and largest bound: a group at least that far from the box
        // is beyond every one of them.
        let mut tbox = Aabb::EMPTY;
        let mut reach: f64 = 0.0;
        // Per octant of the block, whether some changed group comes within τ_max of its
        // targets' box (0 no, 1 yes, 2 not asked yet).
        let mut reached = [2u8; 8];
        let octant_boxes = &self.ix.octants[tb as usize];
        for &i in &self.live[tb as usize] {
            let iu = i as usize;
            let (old, old_nn) = (self.d2[iu], self.nn[iu]);
            let li = self.ix.own[iu] as usize;
            if old_nn == NONE {
                // Nothing fused within τ_max of the target (a live target without a slot): only
                // a changed slot within τ_max can change that — or give it a witness, which lies
                // closer still. None in a group that stays τ_max away from its octant's box.
                let o = octant_of(li);
                if reached[o] == 2 {
                    let ob = &octant_boxes[o];
                    reached[o] =
                        sc.cand.iter().any(|&(_, gi)| box_box_dist2(&groups.blocks[gi].aabb, ob) < self.r2)
                            as u8;
                }
                if reached[o] == 0 {
                    continue;
                }
            }
            let rows = rows.get_or_insert_with(|| NeighbourRows::of_block(domain, fused, key));
            if rows.any_occupied(li, self.ix.near[iu]) {
                // Within τ_min of that voxel's point, for good: covered at every τ.
                out.push(Change { target: i, d2: 0.0, nn: NONE, retire: true });
                continue;
            }
            let p = self.ix.pts[iu];
            let moved = old_nn != NONE && fused.stamp[old_nn as usize] == epoch;
            if old < self.tmin2 {
                // Covered at every τ by `old_nn`: nothing to do while it stays within τ_min.
                let d = if moved { dist2(p, fused.pos[old_nn as usize]) } else { old };
                if d < self.tmin2 {
                    if d != old {
                        let retire = self.permanent(fused, p, old_nn);
                        out.push(Change { target: i, d2: d, nn: old_nn, retire });
                    }
                    continue;
                }
                // It moved away: the exact distance, from scratch.
                let (d, s) = fused.nearest(p, self.r2);
                let (d2, nn) = if s != NONE { (d, s) } else { (f64::INFINITY, NONE) };
                let retire = self.permanent(fused, p, nn);
                out.push(Change { target: i, d2, nn, retire });
                continue;
            }
            // The nearest changed slot below the bound that matters: its starting bound.
            let best = if moved {
                let d = dist2(p, fused.pos[old_nn as usize]);
                if d < self.r2 {
                    (d, old_nn)
                } else {
                    (self.r2, NONE)
                }
            } else {
                (old.min(self.r2), NONE)
            };
            sc.who.push(i);
            sc.best.push(best);
            tbox.grow(p);
            reach = reach.max(best.0);
            for (c, &x) in sc.xyz.iter_mut().zip(&p) {
                c.push(x);
            }
        }
        // The changed groups in order of their block's distance, for all searching targets.
        let (xs, ys, zs) = (&sc.xyz[0], &sc.xyz[1], &sc.xyz[2]);
        for &(lb, gi) in &sc.cand {
            let g = &groups.blocks[gi];
            if lb >= reach || box_box_dist2(&g.aabb, &tbox) >= reach {
                // Each target would skip it: its distance to the group's box is at least this.
                continue;
            }
            for (t, best) in sc.best.iter_mut().enumerate() {
                // `lb` bounds the distance to every later group too (a per-target walk stops).
                if lb >= best.0 {
                    continue;
                }
                let p = [xs[t], ys[t], zs[t]];
                if g.aabb.dist2(p) >= best.0 {
                    continue;
                }
                let (d, j) = groups.nearest_in_group(g, p);
                if d < best.0 {
                    *best = (d, groups.slots[j]);
                }
            }
        }
        for (t, (&i, &best)) in sc.who.iter().zip(&sc.best).enumerate() {
            let iu = i as usize;
            let p = [xs[t], ys[t], zs[t]];
            let (old, old_nn) = (self.d2[iu], self.nn[iu]);
            let moved = old_nn != NONE && fused.stamp[old_nn as usize] == epoch;
            let (d2, nn) = if !moved {
                if best.1 == NONE {
                    (old, old_nn)
                } else {
                    best
                }
            } else if best.1 != NONE && best.0 <= old {
                best
            } else {
                // Some unchanged slot may lie between the old distance and the best changed one.
                let bound = if best.1 == NONE { self.r2 } else { best.0 };
                let (d, s) = fused.nearest(p, bound);
                if s != NONE {
                    (d, s)
                } else if best.1 != NONE {
                    best
                } else {
                    (f64::INFINITY, NONE)
                }
            };
            if d2 != old || nn != old_nn {
                let retire = self.permanent(fused, p, nn);
                out.push(Change { target: i, d2, nn, retire });
            }
        }
    }

    /// Whether the voxel of `p`'s nearest slot `nn` lies entirely within τ_min of `p`. (The
    /// voxels around `p`'s own need no test here: [`Coverage::block_changes`] tests them
    /// first, against the same fused cloud, and retires the target at once when one passes; so
    /// this decides only for a τ_min above 2h, where voxels farther out can pass.)
    fn permanent(&self, fused: &FusedCloud, p: [f64; 3], nn: u32) -> bool {
        nn != NONE && max_corner_d2(self.ix.domain.h, fused.key[nn as usize], p) < self.retire2
    }
}

/// The offset (−1, 0 or 1 per axis) of bit `b` of [`Index::near`] (inverse of [`near_bit`]).
#[cfg(test)]
fn near_offset(b: u32) -> [i32; 3] {
    [(b % 3) as i32 - 1, (b / 3 % 3) as i32 - 1, (b / 9) as i32 - 1]
}

/// The fine-voxel occupancy of a target block and the layer of voxels around it, as rows
/// along x: `rows[z + 1][y + 1]` holds bit `x + 1` for local coordinates −1..=[`BLOCK`] (a
/// coordinate of −1 or `BLOCK` is in the neighbouring block), so that the occupancy of the 27
/// voxels around any voxel of the block is nine shifts and masks.
struct NeighbourRows {
    rows: [[u16; ROWS]; ROWS],
}

/// Rows (and bits per row) of [`NeighbourRows`]: the block's voxels and one on each side.
const ROWS: usize = BLOCK as usize + 2;

impl NeighbourRows {
    /// The occupancy around the target block with key `key`: [`NeighbourRows::new`] of the
    /// fused blocks of its 3×3×3 block neighbourhood.
    fn of_block(domain: &Domain, fused: &FusedCloud, key: [i32; 3]) -> NeighbourRows {
        // Offsets in `near_bit` order: x fastest.
        let mut around: [Option<&FusedBlock>; 27] = [None; 27];
        let mut slot = around.iter_mut();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    *slot.next().expect("27 offsets") = domain
                        .block_index([key[0] + dx, key[1] + dy, key[2] + dz])
                        .and_then(|bi| fused.block_at(bi));
                }
            }
        }
        NeighbourRows::new(&around)
    }

    /// The occupancy around the middle block of `around` (the fused blocks of the 3×3×3
    /// block neighbourhood, by [`near_bit`] of the block offset).
    fn new(around: &[Option<&FusedBlock>; 27]) -> NeighbourRows {
        let n = BLOCK as usize;
        let mut rows = [[0u16; ROWS]; ROWS];
        for (zi, plane) in rows.iter_mut().enumerate() {
            for (yi, row) in plane.iter_mut().enumerate() {
                // Block offset and local coordinate of row y = yi − 1, z = zi − 1.
                let (oy, ly) = (yi.div_ceil(n), (yi + n - 1) % n);
                let (oz, lz) = (zi.div_ceil(n), (zi + n - 1) % n);
                let at = |ox: usize| {
                    around[ox + 3 * (oy + 3 * oz)].map_or(0u16, |fb| fb.row_occupancy(ly, lz) as u16)
                };
                // x = −1 is the lower block's last voxel, x = BLOCK the upper block's first.
                *row = (at(0) >> (n - 1)) | at(1) << 1 | (at(2) & 1) << (n + 1);
            }
        }
        NeighbourRows { rows }
    }

    /// Whether any of the neighbours `mask` ([`Index::near`]) of the fine voxel with local
    /// index `li` is occupied.
    #[inline]
    fn any_occupied(&self, li: usize, mask: u32) -> bool {
        if mask == 0 {
            return false;
        }
        self.around(li) & mask != 0
    }

    /// The occupancy of the 27 fine voxels around the one with local index `li`: bit
    /// [`near_bit`] of the offset. Rows y − 1..=y + 1 and z − 1..=z + 1 are
    /// `rows[z..=z + 2][y..=y + 2]`, voxels x − 1..=x + 1 their bits x..=x + 2.
    #[inline]
    fn around(&self, li: usize) -> u32 {
        let [x, y, z] = local_coords(li);
        let mut occupied = 0u32;
        for dz in 0..3 {
            for dy in 0..3 {
                occupied |= ((self.rows[z + dz][y + dy] >> x) as u32 & 7) << (3 * (dy + 3 * dz));
            }
        }
        occupied
    }
}

/// Squared distance from `p` to the farthest corner of fine voxel `k` (size `h`): every point
/// of the voxel is at most that far.
fn max_corner_d2(h: f64, k: [i32; 3], p: [f64; 3]) -> f64 {
    let mut s = 0.0;
    for a in 0..3 {
        let lo = k[a] as f64 * h;
        let d = (p[a] - lo).abs().max((lo + h - p[a]).abs());
        s += d * d;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Random "views": dense patches of a sphere of radius 0.5 with jitter, so voxels are
    /// revisited and centroids move.
    fn patch(rng: &mut rand_chacha::ChaCha8Rng, n: usize, radius: f64) -> Vec<[f64; 3]> {
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
                let r = radius + rng.gen_range(-0.002..0.002);
                (dn > 0.0).then(|| [r * d[0] / dn, r * d[1] / dn, r * d[2] / dn])
            })
            .collect()
    }

    /// Brute force: per τ, the targets with some fused point at d² < τ².
    fn brute(points: &[[f64; 3]], fused: &FusedCloud, taus: &[f64]) -> Vec<Vec<bool>> {
        let near: Vec<f64> = points
            .iter()
            .map(|&p| fused.pos.iter().map(|&q| dist2(p, q)).fold(f64::INFINITY, f64::min))
            .collect();
        taus.iter().map(|t| near.iter().map(|&d| d < t * t).collect()).collect()
    }

    #[test]
    fn instantaneous_coverage_equals_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        let domain = Domain::covering(0.005, [-0.6; 3], [0.6; 3], 0.05);
        // Targets on the sphere, on a shell 0.015 inside it (covered only at the larger τ, and
        // uncovered again when centroids drift) and on an inner sphere (never covered).
        let mut tp: Vec<[f64; 3]> = patch(&mut rng, 3000, 0.5);
        tp.extend(patch(&mut rng, 3000, 0.5));
        tp.extend(patch(&mut rng, 2000, 0.485));
        tp.extend(patch(&mut rng, 300, 0.25));
        for taus in [vec![0.01, 0.02, 0.03], vec![0.03, 0.004], vec![0.012]] {
            let mut fused = FusedCloud::new(domain.clone());
            let mut cov = Coverage::new(domain.clone(), &tp, &taus).unwrap();
            assert_eq!(cov.len(), tp.len());
            for step in 0..10 {
                fused.insert(&patch(&mut rng, 5000, 0.5));
                cov.update(&fused, &ChangedBlocks::new(&fused, &fused.latest_changed()));
                let want = brute(cov.points(), &fused, &taus);
                for (j, w) in want.iter().enumerate() {
                    assert_eq!(&cov.covered(j), w, "taus {taus:?} step {step} τ #{j}");
                    let n = w.iter().filter(|&&c| c).count();
                    assert_eq!(cov.counts()[j], n, "taus {taus:?} step {step} τ #{j}");
                }
            }
            // Observed targets retire where τ_min exceeds a voxel's diagonal (h√3 ≈ 0.0087).
            let tmin = taus.iter().cloned().fold(f64::INFINITY, f64::min);
            assert_eq!(cov.retired() > 0, tmin > 0.009, "taus {taus:?}");
        }
    }

    #[test]
    fn coverage_can_drop_when_a_centroid_drifts_away() {
        // One target 0.0101 from a first observation: covered at τ = 0.0102; a second
        // observation in the same voxel moves the centroid away, and coverage drops (sticky
        // coverage would keep it).
        let domain = Domain::covering(0.005, [-0.1; 3], [0.1; 3], 0.05);
        let target = [0.0121, 0.0026, 0.0026];
        let mut cov = Coverage::new(domain.clone(), &[target], &[0.0102]).unwrap();
        let mut fused = FusedCloud::new(domain);
        fused.insert(&[[0.002, 0.0026, 0.0026]]);
        cov.update(&fused, &ChangedBlocks::new(&fused, &fused.latest_changed()));
        assert_eq!(cov.counts(), &[1]);
        fused.insert(&[[0.0001, 0.0026, 0.0026]]);
        cov.update(&fused, &ChangedBlocks::new(&fused, &fused.latest_changed()));
        // Centroid (0.002 + 0.0001) / 2 = 0.00105: 0.01105 away.
        assert_eq!(cov.counts(), &[0]);
        assert_eq!(cov.retired(), 0);
    }

    #[test]
    fn a_target_retires_by_any_occupied_neighbour_within_tau_min_not_only_its_nearest() {
        // h = 0.005, τ_min = 0.01. The target sits at the centre of voxel k: the face neighbour
        // k ± e_a lies entirely within 0.0083 of it (qualifies), the edge neighbour
        // k ± e_a + e_b reaches 0.0109 (does not). A fused point in the edge neighbour is the
        // nearest (0.0037); one in the face neighbour (0.0074) still retires the target. Along
        // each axis a, voxels at the low and high end of a block (0 and 7, −9 ≡ 7), so the face
        // neighbour is in the next block, and one inside (3).
        let h = 0.005;
        let domain = Domain::covering(h, [-0.2; 3], [0.2; 3], 0.05);
        for a in 0..3 {
            let b = (a + 1) % 3;
            for (ka, sa) in [(7, 1), (0, -1), (3, 1), (-9, -1)] {
                let mut k = [3; 3];
                k[a] = ka;
                let p: [f64; 3] = std::array::from_fn(|i| (k[i] as f64 + 0.5) * h);
                let mut face = p;
                face[a] += sa as f64 * 0.0049;
                let mut edge = p;
                edge[a] += sa as f64 * 0.0026;
                edge[b] += 0.0026;
                let (mut kf, mut ke) = (k, k);
                kf[a] += sa;
                ke[a] += sa;
                ke[b] += 1;
                assert_eq!((domain.key(face), domain.key(edge)), (kf, ke));
                let retired_with = |points: &[[f64; 3]]| {
                    let mut cov = Coverage::new(domain.clone(), &[p], &[0.01, 0.02]).unwrap();
                    let mut fused = FusedCloud::new(domain.clone());
                    fused.insert(points);
                    cov.update(&fused, &ChangedBlocks::new(&fused, &fused.latest_changed()));
                    assert_eq!(cov.counts(), &[1, 1], "axis {a}, voxel {k:?}");
                    cov.retired()
                };
                assert_eq!(retired_with(&[face, edge]), 1, "axis {a}, voxel {k:?}");
                // The edge point alone: covered, not for good.
                assert_eq!(retired_with(&[edge]), 0, "axis {a}, voxel {k:?}");
            }
        }
    }

    #[test]
    fn neighbour_rows_give_each_voxels_27_neighbours() {
        // Random occupancy of the 27 blocks around a middle block (some absent): for every voxel
        // of the middle block, each of its 27 neighbours' bits against a lookup of that voxel
        // in the blocks themselves.
        let domain = Domain::covering(0.005, [-0.2; 3], [0.2; 3], 0.05);
        let n = crate::grid::BLOCK;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for round in 0..4 {
            let mut pts = Vec::new();
            for b in 0..27u32 {
                if round > 0 && rng.gen_bool(0.2) {
                    continue;
                }
                let o = near_offset(b);
                for li in 0..crate::grid::BLOCK_CELLS {
                    if rng.gen_bool(0.3) {
                        let [x, y, z] = local_coords(li);
                        let k = [o[0] * n + x as i32, o[1] * n + y as i32, o[2] * n + z as i32];
                        pts.push(k.map(|c| (c as f64 + 0.5) * 0.005));
                    }
                }
            }
            let mut fused = FusedCloud::new(domain.clone());
            fused.insert(&pts);
            let rows = NeighbourRows::of_block(&domain, &fused, [0; 3]);
            let occupied = |k: [i32; 3]| {
                let bk = crate::grid::block_of(k);
                domain
                    .block_index(bk)
                    .and_then(|bi| fused.block_at(bi))
                    .is_some_and(|fb| fb.is_occupied(local_index(k)))
            };
            for bit in 0..27u32 {
                assert_eq!(near_bit(near_offset(bit)), bit);
            }
            for li in 0..crate::grid::BLOCK_CELLS {
                let [x, y, z] = local_coords(li).map(|c| c as i32);
                let got = rows.around(li);
                for bit in 0..27u32 {
                    let d = near_offset(bit);
                    let want = occupied([x + d[0], y + d[1], z + d[2]]);
                    assert_eq!(got >> bit & 1 == 1, want, "round {round}, voxel {li}, offset {d:?}");
                    assert_eq!(rows.any_occupied(li, 1 << bit), want);
                }
                assert_eq!(got >> 27, 0);
            }
        }
    }

    #[test]
    fn a_target_whose_own_voxel_is_occupied_retires_covered() {
        let domain = Domain::covering(0.005, [-0.1; 3], [0.1; 3], 0.05);
        let mut cov = Coverage::new(domain.clone(), &[[0.0049, 0.0049, 0.0049]], &[0.01, 0.02]).unwrap();
        let mut fused = FusedCloud::new(domain);
        fused.insert(&[[0.0001, 0.0001, 0.0001]]);
        cov.update(&fused, &ChangedBlocks::new(&fused, &fused.latest_changed()));
        assert_eq!((cov.counts(), cov.retired()), (&[1usize, 1][..], 1));
        assert!(Coverage::new(Domain::covering(0.005, [0.0; 3], [0.1; 3], 0.0), &[[3.0, 0.0, 0.0]], &[0.01])
            .is_err());
        assert!(Coverage::new(Domain::covering(0.005, [0.0; 3], [0.1; 3], 0.0), &[], &[]).is_err());
    }
}
