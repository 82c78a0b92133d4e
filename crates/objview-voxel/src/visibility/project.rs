//! The first pass of [`InverseCaster::observe_into`]: project every voxel centre into the
//! camera, mark its pixel in the per-view pixel mask and build the coarse per-cell depth bound at
//! which ray walks may start. Separate from the walks because it is the other half of the cost
//! and has its own (conservative-footprint) correctness argument.

use super::axis::fmin;
use super::InverseCaster;
use crate::key::center_of;
use objview_render::Camera;

/// Tile size (pixels) of the per-view pixel mask: one `u64` per tile.
pub(super) const TILE: usize = 8;
/// Cell size (pixels) of the per-view depth bound.
pub(super) const CELL: usize = 4;
/// Voxels whose footprint spans at most `BLOCK` × `BLOCK` depth cells update one block entry,
/// spread over the cells afterwards.
const BLOCK: usize = 4;

/// [`objview_render::Intrinsics::pixel_of`] without `f64::floor` (a libm call on baseline
/// x86-64): for a projected coordinate `x`, `floor(x) ∈ [0, w)` ⟺ `0 ≤ x < w`, and then
/// truncation is the floor. Same result for every input (tested).
#[inline]
pub(crate) fn pixel_of(k: &objview_render::Intrinsics, p: [f64; 3]) -> Option<(u32, u32)> {
    let [u, v] = k.project(p)?;
    if u >= 0.0 && v >= 0.0 && u < k.width as f64 && v < k.height as f64 {
        Some((u as u32, v as u32))
    } else {
        None
    }
}

/// The footprint factor of a voxel box of circumradius `rho` whose centre lies at camera depth
/// `z` > `rho` and distance `dist` from the camera centre: every point q of the ball of radius
/// `rho` around the centre pc has |q_x/q_z − x/z| ≤ `rho`·|pc| / (z·(z − `rho`)) (likewise
/// for y), see [`InverseCaster::project_voxels`].
#[inline(always)]
pub(super) fn footprint_factor(rho: f64, dist: f64, z: f64) -> f64 {
    rho * dist / (z * (z - rho))
}

/// The conservative footprint's half-widths (pixels) from [`footprint_factor`] `hr` and the
/// focal lengths' magnitudes (rounded up): every pixel centre whose ray meets the voxel's box
/// lies within them of the projected voxel centre (one pixel of rounding margin included).
/// Shared by the depth bound and the union's ray pruning (`prune`), which rely on the same
/// property.
#[inline(always)]
pub(super) fn footprint_half_widths(hr: f64, afx: f64, afy: f64) -> (f64, f64) {
    (afx * hr + 1.0, afy * hr + 1.0)
}

/// The constants of the conservative footprint for one view: the voxel box's circumradius
/// `rho`, the depth `z_foot` above which a footprint is bounded, and the focal lengths'
/// magnitudes rounded up. One definition for the depth bound and the union's pruning.
pub(super) struct FootprintConsts {
    pub(super) rho: f64,
    pub(super) z_foot: f64,
    pub(super) afx: f64,
    pub(super) afy: f64,
}

impl FootprintConsts {
    pub(super) fn new(r: f64, k: &objview_render::Intrinsics) -> FootprintConsts {
        let rho = 0.5 * 3f64.sqrt() * r; // circumradius of a voxel box
        FootprintConsts {
            rho,
            z_foot: rho * 1.000_001 + 1e-9,
            afx: k.fx.abs() * (1.0 + 1e-9),
            afy: k.fy.abs() * (1.0 + 1e-9),
        }
    }
}

/// Camera-frame centre of voxel `key` (resolution `r`) and its projected image coordinates:
/// `pixel_of`'s `Intrinsics::project` arithmetic inlined, so the same pixel.
#[inline(always)]
pub(super) fn project_centre(camera: &Camera, key: crate::VoxelKey, r: f64) -> ([f64; 3], f64, f64) {
    let k = &camera.intrinsics;
    let pc = camera.to_camera(center_of(key, r));
    (pc, k.fx * pc[0] / pc[2] + k.cx, k.fy * pc[1] / pc[2] + k.cy)
}

/// The pixel of a projected centre at depth `z` in a `wf` × `hf` image (`pixel_of` without
/// `f64::floor`), as the word of its 8×8 tile (`mtw` tiles per row) and the bit in it.
#[inline(always)]
pub(super) fn centre_bit(z: f64, uc: f64, vc: f64, wf: f64, hf: f64, mtw: usize) -> Option<(usize, u64)> {
    if z > 1e-9 && uc >= 0.0 && vc >= 0.0 && uc < wf && vc < hf {
        // In [0, w) × [0, h): truncation is the floor.
        let (u, v) = (uc as i64 as usize, vc as i64 as usize);
        Some(((v / TILE) * mtw + u / TILE, 1u64 << ((v % TILE) * TILE + u % TILE)))
    } else {
        None
    }
}

impl InverseCaster<'_> {
    /// The mask half of [`InverseCaster::project_voxels`]: marks each voxel's pixel in `mask`
    /// where the pixel's tile has a bit in `need` (the same arithmetic, so the same pixels).
    #[inline(always)]
    pub(super) fn project_centres(&self, camera: &Camera, need: &[u64], mask: &mut [u64]) {
        let set = self.set;
        let r = set.resolution();
        let k = &camera.intrinsics;
        let mtw = (k.width as usize).div_ceil(TILE);
        let (wf, hf) = (k.width as f64, k.height as f64);
        const CHUNK: usize = 64;
        let mut vals = [[0.0f64; 3]; CHUNK];
        for keys in set.keys().chunks(CHUNK) {
            for (val, key) in vals.iter_mut().zip(keys) {
                let (pc, uc, vc) = project_centre(camera, *key, r);
                *val = [pc[2], uc, vc];
            }
            for &[z, uc, vc] in &vals[..keys.len()] {
                if let Some((t, bit)) = centre_bit(z, uc, vc, wf, hf, mtw) {
                    if need[t] != 0 {
                        mask[t] |= bit;
                    }
                }
            }
        }
    }

    /// The first pass of [`InverseCaster::observe_into`]: marks each voxel's pixel in `mask`
    /// and lowers `cell_min` (per [`CELL`]×[`CELL`]-pixel cell) over each voxel's conservative
    /// footprint to the distance below which its box cannot be entered; returns that distance's
    /// minimum over the voxels whose footprint is unbounded (boxes reaching the camera plane),
    /// which bounds every cell.
    #[inline(always)]
    pub(super) fn project_voxels(&self, camera: &Camera, cell_min: &mut [f64], mask: &mut [u64]) -> f64 {
        const B: i32 = BLOCK as i32;
        let set = self.set;
        let r = set.resolution();
        let k = &camera.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let mtw = w.div_ceil(TILE);
        let (tw, th) = (w.div_ceil(CELL), h.div_ceil(CELL));
        let mut global_min = f64::INFINITY;
        let FootprintConsts { rho, z_foot, afx, afy } = FootprintConsts::new(r, k);
        let (wf, hf) = (w as f64, h as f64);
        let inv_cell = 1.0 / CELL as f64; // exact: CELL is a power of two
        let (twi, thi) = (tw as i32, th as i32);
        let mut block_min = vec![f64::INFINITY; tw * th];
        // Half-widths (pixels) below which a footprint spans less than B − 1 cells.
        let span = 0.5 * (B - 1) as f64 * CELL as f64 * (1.0 - 1e-9);
        // Per chunk of voxels, the arithmetic runs first in a branch-free loop (which the
        // compiler vectorizes; the same IEEE operations per voxel, so the same values), then
        // the data-dependent updates.
        const CHUNK: usize = 64;
        let mut vals = [[0.0f64; 5]; CHUNK];
        for keys in set.keys().chunks(CHUNK) {
            for (val, key) in vals.iter_mut().zip(keys) {
                let (pc, uc, vc) = project_centre(camera, *key, r);
                let z = pc[2];
                let dist = (pc[0] * pc[0] + pc[1] * pc[1] + z * z).sqrt();
                // Used only where z > z_foot (see below).
                let hr = footprint_factor(rho, dist, z);
                *val = [z, uc, vc, dist, hr];
            }
            for &[z, uc, vc, dist, hr] in &vals[..keys.len()] {
                if let Some((t, bit)) = centre_bit(z, uc, vc, wf, hf, mtw) {
                    mask[t] |= bit;
                }
                let near = dist - rho;
                let near = near - 1e-9 * near.abs() - 1e-12;
                if z <= z_foot || z.is_nan() {
                    if near < global_min {
                        global_min = near;
                    }
                    continue;
                }
                // Every point q of the ball B(pc, ρ) (which holds the box) has
                // |q_x/q_z − x/z| = |z·δ_x − x·δ_z| / (z·q_z) ≤ ρ·|pc| / (z·(z − ρ)), δ = q − pc
                // (Cauchy–Schwarz, q_z ≥ z − ρ > 0); same for y. A ray through a pixel centre that
                // meets the box does so at a point projecting to that centre, so the centre lies
                // within this half-width (plus one pixel of rounding margin) of the projected voxel
                // centre.
                let (hu, hv) = footprint_half_widths(hr, afx, afy);
                // Cells whose pixel centres u + 0.5 can lie in [uc − hu, uc + hu]: from a0 to a1
                // (floors) below.
                let (a0, b0) = ((uc - hu - 0.5) * inv_cell, (vc - hv - 0.5) * inv_cell);
                if a0 >= 0.0 && b0 >= 0.0 && hu < span && hv < span {
                    // Common case: a0, b0 ≥ 0, so truncation is the floor, and the footprint spans
                    // less than B − 1 cells, so a1 < ⌊a0⌋ + B (same for b): it lies in the B×B
                    // block from (⌊a0⌋, ⌊b0⌋). Blocks reaching past the image are clipped below.
                    let (tu0, tv0) = (a0 as i32, b0 as i32);
                    if tu0 < twi && tv0 < thi {
                        let m = &mut block_min[tv0 as usize * tw + tu0 as usize];
                        *m = fmin(*m, near);
                    }
                    continue;
                }
                // Truncation instead of floor: it only differs below 0, where the clamp (or an
                // extra, harmless cell) absorbs it.
                let tu0 = (((uc - hu - 0.5) * inv_cell) as i32).max(0);
                let tu1 = (((uc + hu - 0.5) * inv_cell) as i32).min(twi - 1);
                let tv0 = (((vc - hv - 0.5) * inv_cell) as i32).max(0);
                let tv1 = (((vc + hv - 0.5) * inv_cell) as i32).min(thi - 1);
                if tu1 < tu0 || tv1 < tv0 {
                    continue; // the footprint misses the image
                }
                if tu1 - tu0 < B && tv1 - tv0 < B {
                    // Within the B×B cells from (tu0, tv0): one update here, spread below.
                    let m = &mut block_min[tv0 as usize * tw + tu0 as usize];
                    *m = fmin(*m, near);
                    continue;
                }
                for tv in tv0..=tv1 {
                    for m in &mut cell_min[tv as usize * tw..][tu0 as usize..=tu1 as usize] {
                        *m = fmin(*m, near);
                    }
                }
            }
        }
        // Spread each B×B block's bound over its cells: cell (i, j) takes the minimum over the
        // blocks starting at (i − B + 1..=i, j − B + 1..=j).
        let spread = |src: &[f64], dst: &mut [f64], n: usize, stride: usize, lines: usize, lstride: usize| {
            for l in 0..lines {
                let at = |i: usize| l * lstride + i * stride;
                for i in 0..n {
                    let mut m = src[at(i)];
                    for j in 1..BLOCK.min(i + 1) {
                        m = fmin(m, src[at(i - j)]);
                    }
                    dst[at(i)] = m;
                }
            }
        };
        let mut rows = vec![f64::INFINITY; tw * th];
        spread(&block_min, &mut rows, tw, 1, th, tw);
        spread(&rows, &mut block_min, th, tw, tw, 1);
        for (m, b) in cell_min.iter_mut().zip(&block_min) {
            *m = fmin(*m, *b);
        }
        global_min
    }
}
