//! Rear-side entropy scoring: [`GainMap`], a read-only snapshot of the occupancy grid condensed
//! for ray scoring, and the gain of a ray ([`GainMap::ray_gain`]) and of a whole view
//! ([`GainMap::view_gain`]: splat the occupied shell front to back, then walk only the rays that
//! can count). This is where a planning step spends its time, hence its own module; the image
//! footprints it splats with are in [`super::projection`], the skipping walk in [`super::skip`].

use std::sync::OnceLock;

use objview_render::Camera;
use rayon::prelude::*;

use super::projection::{covered, Projector};
use crate::occupancy::{entropy, floor_i64, probability, Dda, GridGeometry, OccupancyGrid, VoxelState};

/// One voxel of a [`GainMap`]: 1 − p and a state-coded entropy (H(p) > 0 for unknown, 0 for free,
/// −1 for occupied).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub(super) struct Cell {
    pub(super) q: f32,
    pub(super) h: f32,
}

const OCCUPIED_H: f32 = -1.0;

/// A read-only snapshot of an [`OccupancyGrid`] condensed for ray scoring.
///
/// - Per voxel, 1 − p and a state-coded entropy, so the traversal loop needs one 8-byte load per
///   voxel.
/// - The occupied *shell*: occupied voxels with at least one face whose neighbour is not
///   occupied (or lies outside the grid), with those open faces, as one 64-bit mask per brick of
///   4×4×4 voxels. A ray's first occupied voxel is always a shell voxel that the ray enters
///   through an open face (see [`GainMap::view_gain`]).
#[derive(Debug, Clone)]
pub struct GainMap {
    pub(super) geom: GridGeometry,
    pub(super) cells: Vec<Cell>,
    /// Open faces per voxel (0 unless a shell voxel): bit 2a for the lower face on axis a,
    /// bit 2a + 1 for the upper face.
    open: Vec<u8>,
    /// Bricks per axis (⌈n / 4⌉).
    nb: usize,
    /// Shell voxels of each brick: bit li + 4·lj + 16·lk for local coordinates (li, lj, lk).
    bricks: Vec<u64>,
    /// Voxel-centre coordinate of each layer 0..n (any axis).
    centres: Vec<f64>,
    /// Smallest and largest voxel coordinates of the shell (None without one).
    shell_box: Option<([usize; 3], [usize; 3])>,
    /// Per voxel, the largest R such that the (2R + 1)³ box around it lies inside the grid
    /// (off its boundary layers) and holds only identical voxels: computed when first needed
    /// (see [`GainMap::ray_gain_skipping`]).
    pub(super) runs: OnceLock<Vec<u8>>,
}

/// Edge of a brick in voxels (a brick's shell is one u64: 4³ = 64 bits).
const BRICK: usize = 4;
const _: () = assert!(BRICK * BRICK * BRICK == 64);
/// A view with at least this many rays to walk uses [`GainMap::ray_gain_skipping`] (which
/// needs the box radii, computed once per map).
const SKIP_FROM_RAYS: usize = 256;
/// No shell voxel hit by the ray (in [`GainScratch`]).
const NO_HIT: u32 = u32::MAX;
/// Entry-axis code of a ray that starts inside its first occupied voxel (no predecessor).
const NO_PREDECESSOR: u32 = 3;

/// Reusable per-thread buffers of [`GainMap::view_gain_with`] (about 0.5 MB for 128×128 rays),
/// and counts from its last call.
#[derive(Debug, Default, Clone)]
pub struct GainScratch {
    inv: Vec<[f64; 3]>,
    octant: Vec<u8>,
    hit: Vec<u32>,
    covered: Vec<u64>,
    walk: Vec<u32>,
    first_hits: usize,
    walked: usize,
}

impl GainScratch {
    /// Rays of the last view whose first occupied voxel was found by splatting.
    pub fn first_hits(&self) -> usize {
        self.first_hits
    }

    /// Rays of the last view that were walked voxel by voxel (first occupied voxel entered
    /// from an unknown one).
    pub fn walked(&self) -> usize {
        self.walked
    }
}

/// Reorders the bits of a brick mask so that bit l' holds bit l' XOR f (f < 64): walking the
/// result upwards walks the brick with the axes selected by f reversed.
#[inline(always)]
fn permute_mask(mut m: u64, f: u32) -> u64 {
    const SWAPS: [(u32, u64); 6] = [
        (1, 0x5555_5555_5555_5555),
        (2, 0x3333_3333_3333_3333),
        (4, 0x0f0f_0f0f_0f0f_0f0f),
        (8, 0x00ff_00ff_00ff_00ff),
        (16, 0x0000_ffff_0000_ffff),
        (32, 0x0000_0000_ffff_ffff),
    ];
    for (shift, mask) in SWAPS {
        if f & shift != 0 {
            m = ((m & mask) << shift) | ((m >> shift) & mask);
        }
    }
    m
}

impl GainMap {
    /// Condenses `grid`.
    pub fn new(grid: &OccupancyGrid) -> GainMap {
        let mut last: Option<(f64, Cell)> = None;
        let cells: Vec<Cell> = grid
            .log_odds()
            .iter()
            .map(|&l| {
                // Runs of equal values (the prior, the clamps) are common: reuse the last result.
                if let Some((lv, c)) = last {
                    if lv.to_bits() == l.to_bits() {
                        return c;
                    }
                }
                let p = probability(l);
                let q = (1.0 - p) as f32;
                let c = match grid.state_of_log_odds(l) {
                    VoxelState::Occupied => Cell { q, h: OCCUPIED_H },
                    VoxelState::Free => Cell { q, h: 0.0 },
                    // An unknown voxel has 0 < p < 1; keep its code positive even if H rounds to 0.
                    VoxelState::Unknown => Cell { q, h: (entropy(p) as f32).max(f32::MIN_POSITIVE) },
                };
                last = Some((l, c));
                c
            })
            .collect();
        let geom = grid.geometry().clone();
        let n = geom.n;
        let nb = n.div_ceil(BRICK);
        let occupied = |i: usize, j: usize, k: usize| cells[(k * n + j) * n + i].h < 0.0;
        let mut open = vec![0u8; cells.len()];
        let mut bricks = vec![0u64; nb * nb * nb];
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    if !occupied(i, j, k) {
                        continue;
                    }
                    let c = [i, j, k];
                    let mut bits = 0u8;
                    for a in 0..3 {
                        let mut lower = c;
                        if c[a] == 0 || {
                            lower[a] = c[a] - 1;
                            !occupied(lower[0], lower[1], lower[2])
                        } {
                            bits |= 1 << (2 * a);
                        }
                        let mut upper = c;
                        if c[a] + 1 == n || {
                            upper[a] = c[a] + 1;
                            !occupied(upper[0], upper[1], upper[2])
                        } {
                            bits |= 1 << (2 * a + 1);
                        }
                    }
                    if bits != 0 {
                        open[(k * n + j) * n + i] = bits;
                        let b = ((k / BRICK) * nb + j / BRICK) * nb + i / BRICK;
                        bricks[b] |= 1 << (i % BRICK + BRICK * (j % BRICK) + BRICK * BRICK * (k % BRICK));
                    }
                }
            }
        }
        let centres = (0..n).map(|i| geom.plane(i as i64) + 0.5 * geom.voxel).collect();
        // Bounding box of the shell, in voxel coordinates.
        let mut shell_box: Option<([usize; 3], [usize; 3])> = None;
        for (b, &mask) in bricks.iter().enumerate() {
            if mask != 0 {
                let bc = [b % nb, (b / nb) % nb, b / (nb * nb)];
                let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
                let mut m = mask;
                while m != 0 {
                    let l = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let v = [bc[0] * BRICK + (l & 3), bc[1] * BRICK + (l >> 2 & 3), bc[2] * BRICK + (l >> 4)];
                    for a in 0..3 {
                        lo[a] = lo[a].min(v[a]);
                        hi[a] = hi[a].max(v[a]);
                    }
                }
                shell_box = Some(match shell_box {
                    None => (lo, hi),
                    Some((l0, h0)) => {
                        (std::array::from_fn(|a| l0[a].min(lo[a])), std::array::from_fn(|a| h0[a].max(hi[a])))
                    }
                });
            }
        }
        GainMap { geom, cells, open, nb, bricks, centres, shell_box, runs: OnceLock::new() }
    }

    /// Number of occupied voxels with an open face.
    pub fn shell_len(&self) -> usize {
        self.bricks.iter().map(|m| m.count_ones() as usize).sum()
    }

    /// Rear-side entropy gain of the ray `o + t·d`, t ≥ 0 (see the module docs), by a plain
    /// voxel walk.
    #[inline]
    pub fn ray_gain(&self, o: [f64; 3], d: [f64; 3]) -> f64 {
        let Some(mut dda) = Dda::new(&self.geom, o, d, 0.0, f64::INFINITY) else {
            return 0.0;
        };
        let n = self.geom.n as i64;
        let cells = &self.cells[..];
        let mut acc = 0.0f64;
        let mut vis = 1.0f64;
        let mut prev_unknown = false;
        loop {
            let c = cells[dda.idx as usize];
            if c.h < 0.0 {
                return if prev_unknown { acc } else { 0.0 };
            }
            // Free voxels carry h = 0: they only attenuate.
            acc += vis * c.h as f64;
            vis *= c.q as f64;
            prev_unknown = c.h > 0.0;
            if !dda.advance(n) {
                return 0.0;
            }
        }
    }

    /// Gain of the camera by walking every ray ([`GainMap::ray_gain`]): the sum over the rays
    /// through the pixel centres (u + 0.5, v + 0.5), u, v = 0, stride, 2·stride, …, row by row.
    /// This is the definition; [`GainMap::view_gain`] computes the same number faster.
    pub fn view_gain_plain(&self, camera: &Camera, stride: u32) -> f64 {
        let k = camera.intrinsics;
        let stride = stride.max(1) as usize;
        let mut sum = 0.0;
        for v in (0..k.height).step_by(stride) {
            for u in (0..k.width).step_by(stride) {
                sum += self.ray_gain(camera.center, camera.pixel_ray_object(u, v));
            }
        }
        sum
    }

    /// [`GainMap::view_gain_plain`], computed by first finding each ray's first occupied voxel
    /// and the face it enters through, for all rays at once.
    ///
    /// A ray can only count when its first occupied voxel is entered from an unknown voxel.
    /// The first occupied voxel of every ray comes from splatting the shell voxels in
    /// front-to-back order. For each octant of ray directions, bricks and then the voxels inside
    /// each brick are visited in lexicographic order, every axis running away from the camera.
    /// Along any ray of that octant the traversal indices never decrease in that sense, so this
    /// order agrees with the traversal order of every such ray. The first voxel that a ray–box
    /// test accepts (for a ray not yet covered) is the one the traversal would stop at. The test
    /// uses the traversal's own boundary parameters. Bricks and voxels whose footprint is already
    /// covered are skipped. The box test also gives the entry face, hence the predecessor voxel.
    /// Only rays whose predecessor is unknown are then walked, with [`GainMap::ray_gain`] or, when
    /// a view has many such rays, with its bit-identical variant that skips through boxes of
    /// identical voxels. The sum runs over the rays in the same order, so it equals the plain
    /// sum.
    pub fn view_gain(&self, camera: &Camera, stride: u32) -> f64 {
        self.view_gain_with(camera, stride, &mut GainScratch::default())
    }

    /// [`GainMap::view_gain`] with caller-provided buffers.
    pub fn view_gain_with(&self, camera: &Camera, stride: u32, scratch: &mut GainScratch) -> f64 {
        let k = camera.intrinsics;
        let s = stride.max(1) as usize;
        let (nu, nv) = ((k.width as usize).div_ceil(s), (k.height as usize).div_ceil(s));
        let nr = nu * nv;
        scratch.first_hits = 0;
        scratch.walked = 0;
        let Some((box_lo, box_hi)) = self.shell_box else {
            return 0.0;
        };
        if nr == 0 {
            return 0.0;
        }
        let g = &self.geom;
        let n = g.n;
        let c = camera.center;

        // Rays: 1/d (as the traversal computes it) and the octant of d (bit a set for d_a < 0).
        scratch.inv.clear();
        scratch.octant.clear();
        let proj = Projector { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, inv_stride: 1.0 / s as f64, nu, nv };
        let axes = [camera.right, camera.down, camera.forward];
        // Only rays in the footprint of the shell's bounding box can hit a shell voxel.
        let shell_fp = {
            let lo: [f64; 3] = std::array::from_fn(|a| g.plane(box_lo[a] as i64));
            let hi: [f64; 3] = std::array::from_fn(|a| g.plane(box_hi[a] as i64 + 1));
            let v: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]) - c[a]);
            let h: [f64; 3] = std::array::from_fn(|a| 0.5 * (hi[a] - lo[a]));
            let dot = |r: [f64; 3]| v[0] * r[0] + v[1] * r[1] + v[2] * r[2];
            let ext = |r: [f64; 3]| h[0] * r[0].abs() + h[1] * r[1].abs() + h[2] * r[2].abs();
            let e = axes.map(ext);
            match proj.footprint(dot(axes[0]), dot(axes[1]), dot(axes[2]), e) {
                Some(fp) => fp,
                None => return 0.0,
            }
        };
        let mut octant_rays = [0usize; 8];
        // Per column and row, the camera-frame ray slopes, exactly as `Camera::pixel_ray_object`
        // computes them.
        let qu: Vec<f64> = (0..nu).map(|iu| k.pixel_ray((iu * s) as u32, 0)[0]).collect();
        let qv: Vec<f64> = (0..nv).map(|iv| k.pixel_ray(0, (iv * s) as u32)[1]).collect();
        let (rt, dn, fw) = (camera.right, camera.down, camera.forward);
        scratch.inv.resize(nr, [0.0; 3]);
        // Rays outside the shell's footprint get no octant (never tested).
        scratch.octant.resize(nr, u8::MAX);
        for (iv, &q1) in qv.iter().enumerate().take(shell_fp.v1 + 1).skip(shell_fp.v0) {
            for (iu, &q0) in qu.iter().enumerate().take(shell_fp.u1 + 1).skip(shell_fp.u0) {
                let d: [f64; 3] = std::array::from_fn(|a| q0 * rt[a] + q1 * dn[a] + fw[a]);
                let o = (d[0] < 0.0) as u8 | ((d[1] < 0.0) as u8) << 1 | ((d[2] < 0.0) as u8) << 2;
                scratch.inv[iv * nu + iu] = d.map(|x| if x == 0.0 { f64::INFINITY } else { 1.0 / x });
                scratch.octant[iv * nu + iu] = o;
                octant_rays[o as usize] += 1;
            }
        }
        let words = nu.div_ceil(64);
        scratch.hit.clear();
        scratch.hit.resize(nr, NO_HIT);
        scratch.covered.clear();
        scratch.covered.resize(nv * words, 0);

        // Camera-space offsets of the voxel-centre layers along each axis (summed per voxel),
        // and the camera-space half extents of a voxel and of a brick.
        let col = |a: usize| [axes[0][a], axes[1][a], axes[2][a]];
        let offsets: [Vec<[f64; 3]>; 3] = std::array::from_fn(|a| {
            let m = col(a);
            self.centres.iter().map(|&x| x - c[a]).map(|d| [d * m[0], d * m[1], d * m[2]]).collect()
        });
        let half = |scale: f64| -> [f64; 3] {
            std::array::from_fn(|r| 0.5 * scale * (axes[r][0].abs() + axes[r][1].abs() + axes[r][2].abs()))
        };
        let e_voxel = half(g.voxel);
        let e_brick = half(g.voxel * BRICK as f64);
        // Faces of each layer that face the camera (bits as in `open`).
        let facing: [Vec<u8>; 3] = std::array::from_fn(|a| {
            (0..n as i64)
                .map(|i| {
                    ((c[a] <= g.plane(i)) as u8) << (2 * a) | ((c[a] >= g.plane(i + 1)) as u8) << (2 * a + 1)
                })
                .collect()
        });
        let cam_layer: [i64; 3] = std::array::from_fn(|a| floor_i64((c[a] - g.lo) / g.voxel));
        // Boundary planes relative to the camera, as the traversal computes them.
        let planes: [Vec<f64>; 3] =
            std::array::from_fn(|a| (0..=n as i64).map(|j| g.plane(j) - c[a]).collect());
        let nb = self.nb as i64;

        for oct in 0..8u8 {
            if octant_rays[oct as usize] == 0 {
                continue;
            }
            let up = [oct & 1 == 0, oct & 2 == 0, oct & 4 == 0];
            // Bricks away from the camera along each axis. The camera's own layer and the one
            // behind it are included (rounding); voxels behind the camera fail the box test.
            let brick_range = |a: usize| -> (i64, i64, i64) {
                if up[a] {
                    ((cam_layer[a] - 1).clamp(0, n as i64) / BRICK as i64, nb, 1)
                } else {
                    ((cam_layer[a] + 1).clamp(-1, n as i64 - 1).div_euclid(BRICK as i64), -1, -1)
                }
            };
            let flip = ((!up[0] as u32) * 3) | ((!up[1] as u32) * 12) | ((!up[2] as u32) * 48);
            let (bz0, bz1, sz) = brick_range(2);
            let (by0, by1, sy) = brick_range(1);
            let (bx0, bx1, sx) = brick_range(0);
            let mut bz = bz0;
            while bz != bz1 {
                let mut by = by0;
                while by != by1 {
                    let mut bx = bx0;
                    while bx != bx1 {
                        let bidx = ((bz * nb + by) * nb + bx) as usize;
                        let mask = self.bricks[bidx];
                        bx += sx;
                        if mask == 0 {
                            continue;
                        }
                        let base = [(bx - sx) as usize * BRICK, by as usize * BRICK, bz as usize * BRICK];
                        // Brick footprint: skip it when every ray there already has its hit.
                        let centre_of = |a: usize| {
                            let m = col(a);
                            let x = g.lo + (base[a] as f64 + 0.5 * BRICK as f64) * g.voxel - c[a];
                            [x * m[0], x * m[1], x * m[2]]
                        };
                        let (p0, p1, p2) = (centre_of(0), centre_of(1), centre_of(2));
                        let (bx_, by_, bz_) =
                            (p0[0] + p1[0] + p2[0], p0[1] + p1[1] + p2[1], p0[2] + p1[2] + p2[2]);
                        let Some(fp) = proj.footprint(bx_, by_, bz_, e_brick) else {
                            continue;
                        };
                        let linear = proj.brick(bx_, by_, bz_, e_brick, 0.5 * g.voxel, &axes);
                        if covered(&scratch.covered, words, fp) {
                            continue;
                        }
                        let mut m = permute_mask(mask, flip);
                        while m != 0 {
                            let l = m.trailing_zeros() ^ flip;
                            m &= m - 1;
                            let ijk = [
                                base[0] + (l as usize & 3),
                                base[1] + (l as usize >> 2 & 3),
                                base[2] + (l as usize >> 4),
                            ];
                            let idx = (ijk[2] * n + ijk[1]) * n + ijk[0];
                            // A ray enters its first occupied voxel through an open face that
                            // faces the camera.
                            let faces = facing[0][ijk[0]] | facing[1][ijk[1]] | facing[2][ijk[2]];
                            if faces & self.open[idx] == 0 {
                                continue;
                            }
                            let (o0, o1, o2) =
                                (&offsets[0][ijk[0]], &offsets[1][ijk[1]], &offsets[2][ijk[2]]);
                            let (x, y, z) =
                                (o0[0] + o1[0] + o2[0], o0[1] + o1[1] + o2[1], o0[2] + o1[2] + o2[2]);
                            let fp = match &linear {
                                Some(b) => proj.voxel(b, x, y, z),
                                None => proj.footprint(x, y, z, e_voxel),
                            };
                            let Some(fp) = fp else {
                                continue;
                            };
                            // Entry and exit planes of the box for this octant, relative to the camera.
                            let mut en = [0.0; 3];
                            let mut ex = [0.0; 3];
                            for a in 0..3 {
                                let (pe, px) =
                                    if up[a] { (ijk[a], ijk[a] + 1) } else { (ijk[a] + 1, ijk[a]) };
                                en[a] = planes[a][pe];
                                ex[a] = planes[a][px];
                            }
                            for iv in fp.v0..=fp.v1 {
                                let row_bits = &mut scratch.covered[iv * words..(iv + 1) * words];
                                // Walk the uncovered rays of the footprint, word by word.
                                let (w0, w1) = (fp.u0 / 64, fp.u1 / 64);
                                for (w, word) in row_bits.iter_mut().enumerate().take(w1 + 1).skip(w0) {
                                    let lo = if w == w0 { fp.u0 % 64 } else { 0 };
                                    let hi = if w == w1 { fp.u1 % 64 } else { 63 };
                                    let range = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
                                    let mut todo = !*word & range;
                                    while todo != 0 {
                                        let bit = todo.trailing_zeros() as usize;
                                        todo &= todo - 1;
                                        let ray = iv * nu + w * 64 + bit;
                                        if scratch.octant[ray] != oct {
                                            continue;
                                        }
                                        let inv = scratch.inv[ray];
                                        let te = [en[0] * inv[0], en[1] * inv[1], en[2] * inv[2]];
                                        let tx = [ex[0] * inv[0], ex[1] * inv[1], ex[2] * inv[2]];
                                        let t01 = if tx[1] < tx[0] { tx[1] } else { tx[0] };
                                        let t_out = if tx[2] < t01 { tx[2] } else { t01 };
                                        // Entry axis: the last boundary crossed (ties: the highest
                                        // axis, as the traversal steps the lowest axis first).
                                        let mut axis = 0u32;
                                        let mut t_in = te[0];
                                        if te[1] >= t_in {
                                            axis = 1;
                                            t_in = te[1];
                                        }
                                        if te[2] >= t_in {
                                            axis = 2;
                                            t_in = te[2];
                                        }
                                        if t_in < t_out && t_out > 0.0 {
                                            let code = if t_in > 0.0 { axis } else { NO_PREDECESSOR };
                                            scratch.hit[ray] = (idx as u32) << 2 | code;
                                            *word |= 1 << bit;
                                        }
                                    }
                                }
                            }
                        }
                    }
                    by += sy;
                }
                bz += sz;
            }
        }

        // Walk the rays whose first occupied voxel is entered from an unknown voxel.
        let strides = [1usize, n, n * n];
        scratch.walk.clear();
        for (ray, &code) in scratch.hit.iter().enumerate() {
            if code == NO_HIT {
                continue;
            }
            scratch.first_hits += 1;
            if code & 3 == NO_PREDECESSOR {
                continue;
            }
            let axis = (code & 3) as usize;
            let idx = (code >> 2) as usize;
            let coord = (idx / strides[axis]) % n;
            // The predecessor lies on the camera side: above on a down-going axis.
            let pred = if scratch.octant[ray] >> axis & 1 == 1 {
                if coord + 1 == n {
                    continue;
                }
                idx + strides[axis]
            } else {
                if coord == 0 {
                    continue;
                }
                idx - strides[axis]
            };
            if self.cells[pred].h > 0.0 {
                scratch.walk.push(ray as u32);
            }
        }
        scratch.walked = scratch.walk.len();
        let runs = (scratch.walk.len() >= SKIP_FROM_RAYS).then(|| self.runs());
        let mut sum = 0.0;
        for &ray in &scratch.walk {
            let (iu, iv) = (ray as usize % nu, ray as usize / nu);
            let d = camera.pixel_ray_object((iu * s) as u32, (iv * s) as u32);
            sum += match runs {
                Some(runs) => self.ray_gain_skipping(c, d, runs),
                None => self.ray_gain(c, d),
            };
        }
        sum
    }

    /// [`GainMap::view_gain`] of each camera, in parallel; the result does not depend on the
    /// number of threads.
    pub fn view_gains(&self, cameras: &[Camera], stride: u32) -> Vec<f64> {
        cameras
            .par_iter()
            .map_init(GainScratch::default, |scratch, cam| self.view_gain_with(cam, stride, scratch))
            .collect()
    }
}
