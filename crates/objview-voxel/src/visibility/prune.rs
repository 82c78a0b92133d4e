//! Ray pruning for unions of O(v) ([`InverseCaster::observe_union_into`]): which pixels of a
//! view may still see a voxel that the union does not hold yet. The annotation sweep needs only
//! |∪ O(v)| for 25 of its 26 view sets, and once the union holds the visible surface, almost
//! every ray can only re-find a voxel it already has.
//!
//! A voxel y not in the union is *live* in a view when the view's walks could enter it first.
//! For a camera outside the grid box (pruning gives up otherwise, and for a camera so far away,
//! more than 2^40 cells, that the walk's plane offsets round together):
//! - the walk is 6-connected (each step crosses one plane) and starts outside the set, so the
//!   cell it visits just before y is a face neighbour of y that is not in S_gt and that a
//!   6-connected path of cells not in S_gt joins to the grid's boundary (an *exterior* cell,
//!   [`open_faces`]); a voxel without an exterior face neighbour is never seen (a surface
//!   sealed inside another: a cavity, the end of a handle inside a wall);
//! - the walk enters y from its +x neighbour only when moving down x, across the plane
//!   x = (k_x + 1)·r, and it crosses such planes only at or below the camera's own cell:
//!   k_x + 1 ≤ ⌊o_x / r⌋ (likewise for the other faces and axes; the test allows one cell of
//!   slack, for the rounding of ⌊o_x / r⌋ against the walk's own planes).
//!
//! So y is live when it has an exterior face neighbour across a face that faces the camera.
//! A pixel is *needed* when its centre lies in the conservative projected footprint of some
//! live voxel (the depth bound's footprint of `project_voxels`: a ray through a pixel centre
//! outside it misses the voxel's box); the rays of the other pixels can only see voxels of the
//! union, and are not cast. The rays that are cast are cast exactly as by `observe_into`, so
//! the union is the same, bit for bit.

use super::caster::OpenFaces;
use super::project::{footprint_factor, footprint_half_widths, project_centre, FootprintConsts, TILE};
use super::InverseCaster;
use crate::set::VoxelSet;
use objview_render::Camera;

/// Pruning gives up when more than 1/`LIVE_LIMIT` of the voxels are live (a speed setting
/// only: the result is the same either way).
const LIVE_LIMIT: usize = 8;

/// Pruning gives up for cameras farther than this many cells from the origin on some axis.
const FAR: f64 = (1u64 << 40) as f64;

/// Widest footprint half-width (pixels) that is marked; a wider one gives up pruning.
const MAX_MARK: f64 = 64.0;

/// Per voxel of `set` (set index order), its open faces: bit 2a when the neighbour along +a is
/// an *exterior* cell, bit 2a + 1 when the one along −a is. Exterior cells are the grid cells
/// not in the set that a 6-connected path of cells not in the set joins to the grid's boundary
/// (which lies in the set's empty margin): a walk from a camera outside the grid box reaches
/// only those before its first S_gt voxel, so a voxel is entered first only from one of them
/// (surfaces sealed inside others — a cavity, the part of a handle inside a wall — have none).
pub(super) fn open_faces(set: &VoxelSet) -> Vec<u8> {
    let [nx, ny, nz] = set.grid_dims();
    let cells = nx * ny * nz;
    // Cell ids (x·ny + y)·nz + z fit in u32: a grid holds at most `MAX_GRID_CELLS` = 2^30.
    let id = |g: [usize; 3]| (g[0] * ny + g[1]) * nz + g[2];
    let cell = |i: usize| [i / (ny * nz), i / nz % ny, i % nz];
    let occupied = |g: [usize; 3]| set.bit(set.bit_of_cell(g));
    // Breadth-first flood fill from the boundary (the queue holds a wavefront, not the grid);
    // one bit per cell.
    let mut exterior = vec![0u64; cells.div_ceil(64)];
    let is_ext = |e: &[u64], i: usize| e[i >> 6] >> (i & 63) & 1 == 1;
    let mut queue = std::collections::VecDeque::new();
    let visit = |e: &mut [u64], q: &mut std::collections::VecDeque<u32>, g: [usize; 3]| {
        let i = id(g);
        if !is_ext(e, i) && !occupied(g) {
            e[i >> 6] |= 1 << (i & 63);
            q.push_back(i as u32);
        }
    };
    for x in 0..nx {
        for y in 0..ny {
            for z in 0..nz {
                if x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1 {
                    visit(&mut exterior, &mut queue, [x, y, z]);
                }
            }
        }
    }
    while let Some(i) = queue.pop_front() {
        let g = cell(i as usize);
        for a in 0..3 {
            if g[a] + 1 < [nx, ny, nz][a] {
                let mut n = g;
                n[a] += 1;
                visit(&mut exterior, &mut queue, n);
            }
            if g[a] > 0 {
                let mut n = g;
                n[a] -= 1;
                visit(&mut exterior, &mut queue, n);
            }
        }
    }
    let g0 = set.grid_origin();
    set.keys()
        .iter()
        .map(|k| {
            let g: [usize; 3] = std::array::from_fn(|a| (k[a] - g0[a]) as usize);
            let mut m = 0u8;
            for a in 0..3 {
                // The set's margin keeps every voxel's face neighbours inside the grid.
                let (mut up, mut down) = (g, g);
                up[a] += 1;
                down[a] -= 1;
                m |= (is_ext(&exterior, id(up)) as u8) << (2 * a);
                m |= (is_ext(&exterior, id(down)) as u8) << (2 * a + 1);
            }
            m
        })
        .collect()
}

impl InverseCaster<'_> {
    /// Marks in `need` (a zeroed mask, one `u64` per [`TILE`]×[`TILE`] tile as in
    /// `observe_into`) every pixel whose ray may enter, as its first S_gt voxel, a voxel not
    /// in `acc` (a bitset over set indices), see the module documentation. `false` when
    /// pruning gives up for this view (then every pixel is needed): the camera is near the
    /// grid, some live voxel's footprint is unbounded or very wide, or more than
    /// 1/[`LIVE_LIMIT`] of the voxels are live (marking would cost more than it saves).
    pub(super) fn needed_pixels(&self, camera: &Camera, acc: &[u64], need: &mut [u64]) -> bool {
        let set = self.set;
        let r = set.resolution();
        let o = camera.center;
        if !o.iter().all(|x| x.is_finite()) {
            return false;
        }
        let g0 = set.grid_origin();
        let cam: [f64; 3] = std::array::from_fn(|a| (o[a] / r).floor());
        // Far away (|o / r| > 2^40 on some axis) the plane offsets `(g0 + g)·r − o` of the
        // walk round together and its start may skip cells (a walk could then begin inside a
        // sealed cavity); no view of the benchmark is near that.
        if cam.iter().any(|c| c.abs() > FAR) {
            return false;
        }
        let near_grid = (0..3)
            .all(|a| cam[a] >= g0[a] as f64 - 2.0 && cam[a] <= g0[a] as f64 + self.dims[a] as f64 + 1.0);
        if near_grid {
            return false;
        }
        let k = &camera.intrinsics;
        if k.width == 0 || k.height == 0 {
            return false;
        }
        let open = self.open.get_or_init(|| OpenFaces::of(set));
        // Live voxels, 64 per word (the bitset's words): among those not in `acc` that have an
        // open face at all.
        let keys = set.keys();
        let limit = set.len() / LIVE_LIMIT;
        let mut live = vec![0u64; acc.len()];
        let mut count = 0usize;
        for (c, (&a, &any)) in acc.iter().zip(&open.any).enumerate() {
            let mut cand = !a & any;
            while cand != 0 {
                let j = cand.trailing_zeros() as usize;
                cand &= cand - 1;
                let (key, faces) = (keys[c * 64 + j], open.faces[c * 64 + j]);
                let mut facing = 0u8;
                for a in 0..3 {
                    let ka = key[a] as f64;
                    facing |= ((ka <= cam[a]) as u8) << (2 * a) | ((ka >= cam[a]) as u8) << (2 * a + 1);
                }
                live[c] |= ((faces & facing != 0) as u64) << j;
            }
            count += live[c].count_ones() as usize;
            if count > limit {
                return false;
            }
        }
        let (w, h) = (k.width as usize, k.height as usize);
        let mtw = w.div_ceil(TILE);
        let FootprintConsts { rho, z_foot, afx, afy } = FootprintConsts::new(r, k);
        for (c, &word) in live.iter().enumerate() {
            let mut word = word;
            while word != 0 {
                let i = c * 64 + word.trailing_zeros() as usize;
                word &= word - 1;
                let (pc, uc, vc) = project_centre(camera, keys[i], r);
                let z = pc[2];
                if z <= z_foot || z.is_nan() {
                    return false; // unbounded footprint (or NaN)
                }
                let dist = (pc[0] * pc[0] + pc[1] * pc[1] + z * z).sqrt();
                // The footprint of `project_voxels`: every pixel centre whose ray meets the box
                // lies within (hu, hv) of (uc, vc).
                let hr = footprint_factor(rho, dist, z);
                let (hu, hv) = footprint_half_widths(hr, afx, afy);
                if !(hu <= MAX_MARK && hv <= MAX_MARK) {
                    return false;
                }
                // Pixel (u, v) is in when u + 0.5 ∈ [uc − hu, uc + hu]: u from
                // ⌈uc − hu − 0.5⌉ to ⌊uc + hu − 0.5⌋, taken one wider at the start (truncation
                // of a clamped, non-negative value is the floor).
                let (fu0, fu1, fv0, fv1) = (uc - hu - 0.5, uc + hu - 0.5, vc - hv - 0.5, vc + hv - 0.5);
                if !(fu1 >= 0.0 && fv1 >= 0.0 && fu0 < w as f64 && fv0 < h as f64) {
                    if !(uc.is_finite() && vc.is_finite()) {
                        return false;
                    }
                    continue; // misses the image
                }
                let u0 = fu0.max(0.0) as usize;
                let u1 = (fu1 as usize).min(w - 1);
                let v0 = fv0.max(0.0) as usize;
                let v1 = (fv1 as usize).min(h - 1);
                for tv in v0 / TILE..=v1 / TILE {
                    // Rows of this tile row within [v0, v1]: bytes r0..=r1 of the tile's word.
                    let (r0, r1) = (v0.max(tv * TILE) - tv * TILE, v1.min(tv * TILE + TILE - 1) - tv * TILE);
                    let rows = (u64::MAX >> (64 - 8 * (r1 - r0 + 1))) << (8 * r0);
                    for tu in u0 / TILE..=u1 / TILE {
                        let (c0, c1) =
                            (u0.max(tu * TILE) - tu * TILE, u1.min(tu * TILE + TILE - 1) - tu * TILE);
                        let cols = ((0xFFu64 >> (7 - (c1 - c0))) << c0) * 0x0101_0101_0101_0101;
                        need[tv * mtw + tu] |= rows & cols;
                    }
                }
            }
        }
        true
    }
}
