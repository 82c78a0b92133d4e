//! The fast depth renderer: a z-buffer rasterizer whose output equals first-hit ray casting
//! through every pixel centre (SPEC §2), i.e. the brute-force [`crate::reference`] oracle,
//! up to f32 rounding (tests: zero disagreeing pixels on random soups, closed meshes, near
//! and polar poses; relative depth difference < 1e-6).
//!
//! Why it is exact rather than "a GPU-style approximation":
//!
//! - **Coverage is the ray test itself.** For a triangle with camera-frame corners a, b, c,
//!   the edge functions are the scalar triple products e_ab(r) = (a × b)·r (and cyclic) of
//!   the pixel-centre ray r = ((u+½−cx)/fx, (v+½−cy)/fy, 1). Writing the hit point as
//!   t·r = αa + βb + γc gives e_ab = γ·D/t, e_bc = α·D/t, e_ca = β·D/t with D = [a, b, c], so
//!   "all three edge functions have the sign of D" is exactly "the ray hits the triangle at
//!   t > 0". No projection and no near-plane clipping of the triangle is needed for
//!   coverage: corners behind the camera (common at camera radius 1) are handled by the
//!   same formula. The tie rule is inclusive (≥ 0), as in the reference.
//! - **Depth is the ray–plane intersection** z = D / (n·r), n = (b−a)×(c−a) (r has z = 1, so
//!   the ray parameter is the camera-frame z); the znear ≤ z ≤ zfar test is applied per
//!   pixel, like the reference. The z-buffer stores the inverse depth w = (n·r)·(1/D), which
//!   needs no division per pixel; the depth written to the frame is 1/w.
//! - **Watertight.** The edge coefficients of edge a → b are computed as (a+b)×(b−a)
//!   (= 2 a×b, well conditioned for short edges far away), which is exactly antisymmetric
//!   in IEEE arithmetic: the neighbour computes (b+a)×(a−b), the exact negation. They are
//!   evaluated at a pixel by one fixed formula of the coefficients and the pixel, so at every
//!   pixel centre one of the two triangles sees e ≥ 0: no cracks, also along seams of
//!   duplicated vertices (nothing depends on vertex indices). Double coverage on an edge is
//!   resolved by the z-buffer like the reference's nearest-hit rule.
//! - **Deterministic.** A pixel is replaced only by a strictly nearer hit and triangles are
//!   drawn in increasing id order, so equal depths keep the lowest id (the reference's rule);
//!   the parallel renderer draws contiguous triangle ranges into per-thread buffers merged
//!   in range order with the same rule, which gives the same bytes for any thread count. The
//!   AVX2 build and the portable build perform the same IEEE operations (Rust never fuses
//!   a·b + c on its own), so they agree bit for bit too.
//!
//! Precision: vertices are transformed in f64 and stored as f32; triangle set-up and the
//! per-pixel evaluation run in f32 (coverage error ~1e-4 px, depth relative error a few
//! 1e-7). Triangles whose f32 depth error bound exceeds ~4e-6 (grazing views, including most
//! triangles that cross the near plane) take a path with f32 coverage (the shared formula,
//! to stay watertight) and f64 depth and depth-range test.
//!
//! Work layout, per frame: vertex transform ([`Renderer`] buffers), triangle set-up in
//! batches of 8 (AVX2: one 16-byte load per corner and a 4 × 4 transpose, then branch-free
//! vectorized arithmetic: depth-range rejection, screen bounding box, edge and plane
//! constants), then per surviving triangle its bounding box rows, 8 pixels at a time
//! (coverage, inverse depth, z-test and blended stores, branch-free). Boxes at most 4 pixels
//! wide (nearly every triangle of a ~100k-triangle mesh at 512 × 512: boxes of 1–4 × 1–5
//! pixels) take two rows of 4 pixels per vector instead, with the same per-pixel operations.
//! Bounding boxes only limit which pixels are tested; they come from the f32 projected
//! vertices (or, for triangles reaching behind znear/2, from the f64 triangle clipped to
//! z ≥ znear) with a small safety margin. The final pass (depth from the keys, buffer reset)
//! reads only the rows some box touched; the others are written as misses directly.
//!
//! Profile (98k-triangle `mug`, 512 × 512, one core, AVX2): about 40 % set-up of the
//! batches and per-triangle dispatch, 45 % pixel kernels, the rest vertex transform,
//! grazing-triangle f64 path and final pass; ~10 % of the drawn triangles cover no pixel
//! centre. Tried without gain: a 2 × 4 layout for boxes ≤ 2 pixels wide, straight-line code
//! for boxes ≤ 4 rows, bit-set iteration over the drawn lanes.
//!
//! Stores: the kernels write keys and triangle ids back as whole vectors, the old values
//! blended with the drawn lanes (`vpblendvb` + plain store), not with AVX2 masked stores
//! (`vpmaskmovd`). Both leave the same bytes, but a masked store is slow on AMD Zen cores:
//! on an AMD EPYC VM (2026-12-05, `objview bench render`, one thread, median per frame) the
//! blended stores took the 9.5k / 98k / 996k-triangle `mug` from 1.60 / 3.40 / 17.9 ms to
//! 0.77 / 2.08 / 13.7 ms; on Intel (Sapphire Rapids) an earlier try of them was recorded as
//! "without gain". A whole-vector write also rewrites the lanes outside the box (their own old
//! values, just read, so nothing changes; the buffers are padded by a vector and owned by one
//! thread), and where two rows' windows overlap (images narrower than a vector, or the last
//! row pair of a box being one row twice) the later row is written last or alone.

use crate::{Camera, Frame, NO_HIT};
use objview_geom::Mesh;
use rayon::prelude::*;

/// Depth key of a pixel nothing has been drawn to.
const EMPTY: u32 = u32::MAX;

/// Safety margin (pixels) added around each screen bounding box, larger than the f32 error
/// of the projected vertices and of the coverage test.
const BBOX_MARGIN: f32 = 1e-3;

/// Triangles whose f32 depth could be off by more than ~3ε·GRAZING_GAIN ≈ 4e-6 relative
/// (seen at a grazing angle) get their per-pixel depth in f64.
const GRAZING_GAIN: f32 = 20.0;

/// Pixels whose coverage is evaluated together.
const LANES: usize = 8;

/// Pixel blocks of the parallel merge/resolve passes.
const BLOCK: usize = 16384;

/// Depth key of an inverse depth w = 1/z (positive, finite, nonzero): positive f32 bit
/// patterns order like the values, so `u32::MAX − bits(w)` orders like z (nearest smallest).
#[inline(always)]
fn depth_key(w: f32) -> u32 {
    u32::MAX - w.to_bits()
}

/// Depth of a depth key, 0 for [`EMPTY`].
#[inline(always)]
fn key_depth(key: u32) -> f32 {
    let w = f32::from_bits(u32::MAX - key);
    if key == EMPTY {
        0.0
    } else {
        1.0 / w
    }
}

/// A z-buffer: per pixel the depth key of the nearest hit so far and its triangle id (valid
/// where the key is not [`EMPTY`]). Triangles are drawn in increasing id order and a pixel
/// is only replaced by a strictly nearer hit, so ties keep the lowest id.
#[derive(Default)]
struct ZBuf {
    key: Vec<u32>,
    id: Vec<u32>,
    /// Pixel range `[lo, hi)` (whole rows) outside which every key is [`EMPTY`]; `lo ≥ hi`
    /// when nothing was drawn.
    touched: (usize, usize),
}

impl ZBuf {
    /// Extends the touched range by `[lo, hi)`.
    fn touch(&mut self, (lo, hi): (usize, usize)) {
        if lo >= hi {
            return;
        }
        self.touched = if self.touched.0 >= self.touched.1 {
            (lo, hi)
        } else {
            (self.touched.0.min(lo), self.touched.1.max(hi))
        };
    }
}

/// A vertex in the camera frame: `[x, y, z, 0]` (f32; 16 bytes, one aligned load).
type Vert = [f32; 4];

/// Per-camera, per-mesh data shared read-only by all threads of one render.
struct Setup<'a> {
    tris: &'a [[u32; 3]],
    positions: &'a [[f64; 3]],
    camera: &'a Camera,
    verts: &'a [Vert],
    /// Pixel-centre ray coordinates: px[u] = (u + ½ − cx) / fx, py[v] = (v + ½ − cy) / fy.
    px: &'a [f32],
    py: &'a [f32],
    px64: &'a [f64],
    py64: &'a [f64],
    /// Largest |px|, |py| over the image.
    pxmax: f32,
    pymax: f32,
    /// Whether the AVX2 build may be used (when the CPU has it).
    simd: bool,
}

/// Reusable buffers of the rasterizer. Create once, render many views (and meshes).
#[derive(Default)]
pub struct Renderer {
    verts: Vec<Vert>,
    /// One packed z-buffer per thread (the first is the single-thread buffer). Invariant:
    /// every buffer is all [`EMPTY`] between renders (resolving and merging reset them).
    zbufs: Vec<ZBuf>,
    px: Vec<f32>,
    py: Vec<f32>,
    px64: Vec<f64>,
    py64: Vec<f64>,
    tables_for: Option<crate::Intrinsics>,
    /// Never use the AVX2 build (tests compare the two).
    portable: bool,
}

impl Renderer {
    /// A renderer with empty buffers (they grow on first use).
    pub fn new() -> Renderer {
        Renderer::default()
    }

    /// Renders `mesh` (object frame) from `camera` (pose in the object frame; camera frame
    /// OpenCV x right / y down / z forward) into `frame` on the calling thread: first hit
    /// through every pixel centre, depth = camera-frame z in [znear, zfar] (0 = miss) and the
    /// triangle id (or [`NO_HIT`]). `frame`'s buffers are resized and overwritten and its
    /// camera set to `camera`.
    pub fn render_into(&mut self, mesh: &Mesh, camera: &Camera, frame: &mut Frame) {
        self.render_parts(mesh, camera, frame, 1);
    }

    /// Like [`Renderer::render_into`], using all threads of the current rayon pool: the
    /// triangles are split into one contiguous range per thread, each drawn into its own
    /// z-buffer, and the buffers are merged by minimum. Output is bit-identical to
    /// [`Renderer::render_into`] for any number of threads.
    pub fn render_parallel_into(&mut self, mesh: &Mesh, camera: &Camera, frame: &mut Frame) {
        let threads = rayon::current_num_threads().max(1);
        // Below a few thousand triangles per thread the extra buffers cost more than they save.
        let parts = threads.min(mesh.triangles.len() / 4096).max(1);
        self.render_parts(mesh, camera, frame, parts);
    }

    /// Forces the portable (non-AVX2) code path; for tests and comparisons. The output is
    /// identical either way.
    pub fn set_portable(&mut self, portable: bool) {
        self.portable = portable;
    }

    fn render_parts(&mut self, mesh: &Mesh, camera: &Camera, frame: &mut Frame, parts: usize) {
        let parallel = parts > 1;
        self.prepare(mesh, camera, parallel);
        let n = camera.intrinsics.num_pixels();
        let mut bufs = std::mem::take(&mut self.zbufs);
        if bufs.len() < parts {
            bufs.resize_with(parts, ZBuf::default);
        }
        for b in &mut bufs[..parts] {
            // LANES pixels of padding: rows are read LANES pixels at a time.
            if b.key.len() != n + LANES {
                b.key.clear();
                b.key.resize(n + LANES, EMPTY);
                b.touched = (0, 0);
            }
            b.id.resize(n + LANES, NO_HIT);
        }
        let ntri = mesh.triangles.len();
        {
            let setup = self.setup(mesh, camera);
            if parallel {
                bufs[..parts].par_iter_mut().enumerate().for_each(|(k, buf)| {
                    raster_range(&setup, ntri * k / parts, ntri * (k + 1) / parts, buf);
                });
                // Merge into buffer 0 in triangle-range order (resetting the others), in
                // parallel over pixel blocks: strictly nearer wins, so ties keep the lower id.
                type Block<'b> = (&'b mut [u32], &'b mut [u32]);
                for k in 1..parts {
                    let t = std::mem::take(&mut bufs[k].touched);
                    bufs[0].touch(t);
                }
                let (first, rest) = bufs.split_at_mut(1);
                let mut rest: Vec<_> = rest[..parts - 1]
                    .iter_mut()
                    .map(|b| b.key.chunks_mut(BLOCK).zip(b.id.chunks_mut(BLOCK)))
                    .collect();
                let first = &mut first[0];
                let blocks: Vec<(Block, Vec<Block>)> = first
                    .key
                    .chunks_mut(BLOCK)
                    .zip(first.id.chunks_mut(BLOCK))
                    .map(|out| (out, rest.iter_mut().map(|it| it.next().expect("same size")).collect()))
                    .collect();
                blocks.into_par_iter().for_each(|((ok, oi), others)| {
                    for (xk, xi) in others {
                        for (((ok, oi), xk), xi) in
                            ok.iter_mut().zip(oi.iter_mut()).zip(xk.iter_mut()).zip(xi.iter())
                        {
                            if *xk < *ok {
                                *ok = *xk;
                                *oi = *xi;
                            }
                            *xk = EMPTY;
                        }
                    }
                });
            } else {
                raster_range(&setup, 0, ntri, &mut bufs[0]);
            }
        }
        resolve(&mut bufs[0], camera, frame, parallel);
        self.zbufs = bufs;
    }

    /// Transforms the vertices to the camera frame (f64, stored as f32) and projects them;
    /// builds the pixel-ray tables when the intrinsics change.
    #[inline(never)]
    fn prepare(&mut self, mesh: &Mesh, camera: &Camera, parallel: bool) {
        let k = camera.intrinsics;
        if self.tables_for != Some(k) {
            self.px64 = (0..k.width).map(|u| (u as f64 + 0.5 - k.cx) / k.fx).collect();
            self.py64 = (0..k.height).map(|v| (v as f64 + 0.5 - k.cy) / k.fy).collect();
            // Padded with NaN (no coverage) so that a row can be read LANES pixels at a time.
            self.px = self.px64.iter().map(|&x| x as f32).chain([f32::NAN; LANES]).collect();
            self.py = self.py64.iter().map(|&y| y as f32).collect();
            self.tables_for = Some(k);
        }
        let nv = mesh.positions.len();
        self.verts.resize(nv, [0.0; 4]);
        let xf = |p: &[f64; 3], out: &mut Vert| {
            let q = camera.to_camera(*p);
            *out = [q[0] as f32, q[1] as f32, q[2] as f32, 0.0];
        };
        const CH: usize = 8192;
        if parallel && nv > 2 * CH {
            mesh.positions.par_chunks(CH).zip(self.verts.par_chunks_mut(CH)).for_each(|(p, o)| {
                p.iter().zip(o).for_each(|(p, o)| xf(p, o));
            });
        } else {
            mesh.positions.iter().zip(&mut self.verts).for_each(|(p, o)| xf(p, o));
        }
    }

    fn setup<'a>(&'a self, mesh: &'a Mesh, camera: &'a Camera) -> Setup<'a> {
        Setup {
            tris: &mesh.triangles,
            positions: &mesh.positions,
            camera,
            verts: &self.verts,
            px: &self.px,
            py: &self.py,
            px64: &self.px64,
            py64: &self.py64,
            pxmax: self.px[..self.px64.len()].iter().fold(0.0, |m, x| m.max(x.abs())),
            pymax: self.py.iter().fold(0.0, |m, x| m.max(x.abs())),
            simd: !self.portable,
        }
    }
}

/// Moves a z-buffer into `frame` (depth 0 and [`NO_HIT`] where nothing was drawn) and
/// resets its keys to [`EMPTY`]. The id buffer is swapped with the frame's.
#[inline(never)]
fn resolve(zb: &mut ZBuf, camera: &Camera, frame: &mut Frame, parallel: bool) {
    let n = zb.key.len() - LANES;
    frame.camera = *camera;
    frame.depth.resize(n, 0.0);
    std::mem::swap(&mut frame.triangle, &mut zb.id);
    frame.triangle.truncate(n);
    // Outside the touched rows every key is EMPTY: no need to read or reset them.
    let (lo, hi) =
        if zb.touched.0 < zb.touched.1 { (zb.touched.0.min(n), zb.touched.1.min(n)) } else { (0, 0) };
    zb.touched = (0, 0);
    let run = |z: &mut [u32], d: &mut [f32], t: &mut [u32]| {
        for ((z, d), t) in z.iter_mut().zip(d).zip(t) {
            let key = *z;
            *z = EMPTY;
            *d = key_depth(key);
            // Branch-free (vectorizes): ids are stale where nothing was drawn.
            *t = if key == EMPTY { NO_HIT } else { *t };
        }
    };
    if parallel {
        zb.key[..n]
            .par_chunks_mut(BLOCK)
            .zip(frame.depth.par_chunks_mut(BLOCK).zip(frame.triangle.par_chunks_mut(BLOCK)))
            .for_each(|(z, (d, t))| run(z, d, t));
    } else {
        run(&mut zb.key[lo..hi], &mut frame.depth[lo..hi], &mut frame.triangle[lo..hi]);
        for r in [0..lo, hi..n] {
            frame.depth[r.clone()].fill(0.0);
            frame.triangle[r].fill(NO_HIT);
        }
    }
}

/// Screen bounding box `[umin, umax, vmin, vmax]` (continuous pixel coordinates) of the part
/// of a camera-frame triangle with z ≥ znear: clips the f64 triangle against the near plane
/// and projects the clipped polygon. `None` if nothing lies in front of the near plane.
fn clipped_bbox(tri: [[f64; 3]; 3], k: &crate::Intrinsics) -> Option<[f32; 4]> {
    let zn = k.znear;
    let mut bb = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
    let mut any = false;
    let mut add = |p: [f64; 3]| {
        let z = p[2].max(zn);
        let u = k.cx + k.fx * p[0] / z;
        let v = k.cy + k.fy * p[1] / z;
        bb = [bb[0].min(u), bb[1].max(u), bb[2].min(v), bb[3].max(v)];
        any = true;
    };
    for i in 0..3 {
        let (p, q) = (tri[i], tri[(i + 1) % 3]);
        if p[2] >= zn {
            add(p);
        }
        if (p[2] >= zn) != (q[2] >= zn) {
            let s = (zn - p[2]) / (q[2] - p[2]);
            add([p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1]), zn]);
        }
    }
    any.then(|| bb.map(|x| x.clamp(-1e9, 1e9) as f32))
}

#[inline(always)]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Edge function coefficients of the edge a → b: (a + b) × (b − a) = 2·(a × b), written so
/// that it is well conditioned for short edges far from the camera and exactly antisymmetric
/// in (a, b) (a + b is symmetric, b − a antisymmetric, both exactly), with no dependence on
/// vertex indices — duplicated vertices at the same position give the same bits too.
#[inline(always)]
fn edge(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    cross([a[0] + b[0], a[1] + b[1], a[2] + b[2]], [b[0] - a[0], b[1] - a[1], b[2] - a[2]])
}

/// Triangles set up together (structure of arrays, vectorized arithmetic).
const BATCH: usize = 8;

/// What to do with a triangle of a batch.
const SKIP: u8 = 0;
/// Fully in front of znear / 2: bounding box from the projected corners, f32 depth.
const DRAW: u8 = 1;
/// As DRAW, but depth in f64 (grazing).
const PRECISE: u8 = 2;
/// Reaches behind znear / 2: bounding box from the near-clipped f64 triangle.
const CLIPPED: u8 = 3;

/// Set-up constants of a batch of triangles (lane j = triangle t0 + j).
struct Batch {
    flag: [u8; BATCH],
    bbox: [[i32; BATCH]; 4],
    /// Edge functions e_k(u, v) = a[k]·px[u] + (b[k]·py[v] + c[k]), sign-normalized.
    a: [[f32; BATCH]; 3],
    b: [[f32; BATCH]; 3],
    c: [[f32; BATCH]; 3],
    /// Sign-normalized plane n·p = d, d > 0, and 1/d.
    n: [[f32; BATCH]; 3],
    d: [f32; BATCH],
    inv_d: [f32; BATCH],
    /// Whether the f32 depth is not accurate enough (grazing view).
    grazing: [bool; BATCH],
}

/// Draws triangles `lo..hi` into `zbuf` (keeping the packed minimum per pixel), dispatching
/// to a build for the running CPU's vector extensions when available. Both builds perform
/// the same IEEE operations in the same order (Rust never fuses a·b + c on its own), so their
/// output is identical.
fn raster_range(s: &Setup, lo: usize, hi: usize, zb: &mut ZBuf) {
    #[cfg(target_arch = "x86_64")]
    {
        if s.simd && std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports the enabled features (checked just above).
            unsafe { raster_range_avx2(s, lo, hi, zb) };
            return;
        }
    }
    raster_range_impl::<false>(s, lo, hi, zb);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,sse4.1")]
#[inline(never)]
unsafe fn raster_range_avx2(s: &Setup, lo: usize, hi: usize, zb: &mut ZBuf) {
    raster_range_impl::<true>(s, lo, hi, zb);
}

/// Per-row constants of one triangle for the pixel kernels.
#[derive(Clone, Copy)]
struct RowConst {
    /// Edge functions at px: a[k]·px + r[k].
    a: [f32; 3],
    r: [f32; 3],
    /// Inverse depth at px: (n0·px + rw) · inv_d.
    n0: f32,
    rw: f32,
    inv_d: f32,
    /// Accepted inverse-depth range [1/zfar, 1/znear].
    wmin: f32,
    wmax: f32,
}

/// Draws the first `rem` (1..=LANES) of the LANES pixels whose ray coordinates are `px`:
/// a pixel is covered when all three edge functions are ≥ 0 and its inverse depth lies in
/// [wmin, wmax]; a covered pixel whose depth key is strictly smaller than `keys[j]` replaces
/// `keys[j]`, `ids[j]`.
#[inline(always)]
fn span_scalar(
    k: &RowConst,
    px: &[f32; LANES],
    keys: &mut [u32; LANES],
    ids: &mut [u32; LANES],
    rem: usize,
    id: u32,
) {
    for j in 0..rem {
        let x = px[j];
        let e0 = k.a[0] * x + k.r[0];
        let e1 = k.a[1] * x + k.r[1];
        let e2 = k.a[2] * x + k.r[2];
        let w = (k.n0 * x + k.rw) * k.inv_d;
        if (e0 >= 0.0) & (e1 >= 0.0) & (e2 >= 0.0) & (w >= k.wmin) & (w <= k.wmax) {
            let key = depth_key(w);
            if key < keys[j] {
                keys[j] = key;
                ids[j] = id;
            }
        }
    }
}

/// The rows of one triangle's box, LANES pixels at a time, branch-free: the same
/// multiplications, additions and ordered comparisons per pixel as [`span_scalar`] (so the
/// same result), an unsigned key comparison (sign-flip trick) and blended whole-vector stores
/// (see the module documentation: the same bytes as masked stores, faster on AMD).
/// Caller guarantees: AVX2; x0 ≤ x1 < width, y0 ≤ y1 < height; z-buffers of at least (y1 + 1)·width + LANES entries and a px table padded by LANES.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
#[allow(clippy::too_many_arguments)]
unsafe fn draw_rows_avx2(
    k: &RowConst,
    b: [f32; 3],
    c: [f32; 3],
    [n1, n2]: [f32; 2],
    s: &Setup,
    zb: &mut ZBuf,
    [x0, x1, y0, y1]: [usize; 4],
    id: u32,
) {
    use std::arch::x86_64::*;
    let wu = s.px.len() - LANES;
    let tv = TriVecs::new(k);
    let sign = _mm256_set1_epi32(i32::MIN);
    let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let idv = _mm256_set1_epi32(id as i32);
    let px = s.px.as_ptr();
    let kp = zb.key.as_mut_ptr();
    let ip = zb.id.as_mut_ptr();
    if x1 - x0 < LANES / 2 {
        // Narrow box (most triangles of a fine mesh): two rows of up to four pixels per
        // vector, lanes 0..4 = row v, lanes 4..8 = row v + 1. Per lane the same operations
        // as below: the row constants b·py + c and n1·py + n2 are computed lane-wise by the
        // same IEEE multiply and add.
        let x4 = _mm_loadu_ps(px.add(x0));
        let x = _mm256_set_m128(x4, x4);
        let quad = _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3);
        let in_span = _mm256_cmpgt_epi32(_mm256_set1_epi32((x1 + 1 - x0) as i32), quad);
        let low_half = _mm256_setr_epi32(-1, -1, -1, -1, 0, 0, 0, 0);
        let (b0, b1, b2) = (_mm256_set1_ps(b[0]), _mm256_set1_ps(b[1]), _mm256_set1_ps(b[2]));
        let (c0, c1, c2) = (_mm256_set1_ps(c[0]), _mm256_set1_ps(c[1]), _mm256_set1_ps(c[2]));
        let (n1v, n2v) = (_mm256_set1_ps(n1), _mm256_set1_ps(n2));
        let mut v = y0;
        while v <= y1 {
            // The second row of the last pair may lie outside the box: it then reads row v
            // again (in bounds) and its lanes are masked off.
            let (v2, rows) = if v < y1 { (v + 1, in_span) } else { (v, _mm256_and_si256(in_span, low_half)) };
            let py =
                _mm256_setr_m128(_mm_set1_ps(*s.py.get_unchecked(v)), _mm_set1_ps(*s.py.get_unchecked(v2)));
            let r0 = _mm256_add_ps(_mm256_mul_ps(b0, py), c0);
            let r1 = _mm256_add_ps(_mm256_mul_ps(b1, py), c1);
            let r2 = _mm256_add_ps(_mm256_mul_ps(b2, py), c2);
            let rw = _mm256_add_ps(_mm256_mul_ps(n1v, py), n2v);
            let (cover, key) = cover_and_key(&tv, x, [r0, r1, r2], rw);
            let (at, at2) = (v * wu + x0, v2 * wu + x0);
            let old = _mm256_loadu2_m128i(kp.add(at2) as *const __m128i, kp.add(at) as *const __m128i);
            let nearer = _mm256_cmpgt_epi32(_mm256_xor_si256(old, sign), _mm256_xor_si256(key, sign));
            let m = _mm256_and_si256(_mm256_and_si256(cover, nearer), rows);
            let old_id = _mm256_loadu2_m128i(ip.add(at2) as *const __m128i, ip.add(at) as *const __m128i);
            // Row v first, then row v2 (which wins where a narrow image makes their windows
            // overlap); when v2 is v again its half is all old values and is not written.
            let nk = _mm256_blendv_epi8(old, key, m);
            let ni = _mm256_blendv_epi8(old_id, idv, m);
            _mm_storeu_si128(kp.add(at) as *mut __m128i, _mm256_castsi256_si128(nk));
            _mm_storeu_si128(ip.add(at) as *mut __m128i, _mm256_castsi256_si128(ni));
            if v2 != v {
                _mm_storeu_si128(kp.add(at2) as *mut __m128i, _mm256_extracti128_si256::<1>(nk));
                _mm_storeu_si128(ip.add(at2) as *mut __m128i, _mm256_extracti128_si256::<1>(ni));
            }
            v += 2;
        }
        return;
    }
    for v in y0..=y1 {
        let py = *s.py.get_unchecked(v);
        // Same scalar row constants as the portable path.
        let (r0, r1, r2) = (b[0] * py + c[0], b[1] * py + c[1], b[2] * py + c[2]);
        let rw = n1 * py + n2;
        let (r0, r1, r2, rw) =
            (_mm256_set1_ps(r0), _mm256_set1_ps(r1), _mm256_set1_ps(r2), _mm256_set1_ps(rw));
        let mut u = x0;
        while u <= x1 {
            let x = _mm256_loadu_ps(px.add(u));
            let (cover, key) = cover_and_key(&tv, x, [r0, r1, r2], rw);
            let at = v * wu + u;
            let old = _mm256_loadu_si256(kp.add(at) as *const __m256i);
            let nearer = _mm256_cmpgt_epi32(_mm256_xor_si256(old, sign), _mm256_xor_si256(key, sign));
            let in_span = _mm256_cmpgt_epi32(_mm256_set1_epi32((x1 + 1 - u) as i32), iota);
            let m = _mm256_and_si256(_mm256_and_si256(cover, nearer), in_span);
            let old_id = _mm256_loadu_si256(ip.add(at) as *const __m256i);
            _mm256_storeu_si256(kp.add(at) as *mut __m256i, _mm256_blendv_epi8(old, key, m));
            _mm256_storeu_si256(ip.add(at) as *mut __m256i, _mm256_blendv_epi8(old_id, idv, m));
            u += LANES;
        }
    }
}

/// A triangle's [`RowConst`] broadcast to all lanes, for [`cover_and_key`].
#[cfg(target_arch = "x86_64")]
struct TriVecs {
    a: [std::arch::x86_64::__m256; 3],
    n0: std::arch::x86_64::__m256,
    inv_d: std::arch::x86_64::__m256,
    wmin: std::arch::x86_64::__m256,
    wmax: std::arch::x86_64::__m256,
}

#[cfg(target_arch = "x86_64")]
impl TriVecs {
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn new(k: &RowConst) -> TriVecs {
        use std::arch::x86_64::*;
        TriVecs {
            a: [_mm256_set1_ps(k.a[0]), _mm256_set1_ps(k.a[1]), _mm256_set1_ps(k.a[2])],
            n0: _mm256_set1_ps(k.n0),
            inv_d: _mm256_set1_ps(k.inv_d),
            wmin: _mm256_set1_ps(k.wmin),
            wmax: _mm256_set1_ps(k.wmax),
        }
    }
}

/// Coverage mask and depth key of the pixels whose ray coordinates are `x`, given the row
/// constants `r` (edge functions) and `rw` (inverse depth): a pixel is covered when all three
/// edge functions are ≥ 0 and its inverse depth lies in [wmin, wmax]; key = !bits(1/z), so a
/// smaller key is nearer. The same IEEE operations, in the same order, as [`span_scalar`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cover_and_key(
    t: &TriVecs,
    x: std::arch::x86_64::__m256,
    r: [std::arch::x86_64::__m256; 3],
    rw: std::arch::x86_64::__m256,
) -> (std::arch::x86_64::__m256i, std::arch::x86_64::__m256i) {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let m0 = _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_add_ps(_mm256_mul_ps(t.a[0], x), r[0]), zero);
    let m1 = _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_add_ps(_mm256_mul_ps(t.a[1], x), r[1]), zero);
    let m2 = _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_add_ps(_mm256_mul_ps(t.a[2], x), r[2]), zero);
    let w = _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(t.n0, x), rw), t.inv_d);
    let m3 = _mm256_cmp_ps::<_CMP_GE_OQ>(w, t.wmin);
    let m4 = _mm256_cmp_ps::<_CMP_LE_OQ>(w, t.wmax);
    let cover =
        _mm256_castps_si256(_mm256_and_ps(_mm256_and_ps(_mm256_and_ps(m0, m1), _mm256_and_ps(m2, m3)), m4));
    let key = _mm256_sub_epi32(_mm256_set1_epi32(-1), _mm256_castps_si256(w));
    (cover, key)
}

/// Loads the corners of triangles `t0 .. t0 + BATCH` (all in range) into `p`: one 16-byte
/// load per corner and a 4 × 4 transpose per 128-bit half (cheaper than gathers). Returns
/// false, loading nothing, when a vertex index is out of range (the bounds-checked path then
/// reports it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather_avx2(s: &Setup, t0: usize, p: &mut [[[f32; BATCH]; 3]; 3]) -> bool {
    use std::arch::x86_64::*;
    const { assert!(BATCH == 8 && std::mem::size_of::<Vert>() == 16) };
    let tr: &[[u32; 3]; BATCH] = s.tris[t0..t0 + BATCH].try_into().expect("full batch");
    // Largest index of the batch (24 indices = three vectors), unsigned.
    let ip = tr.as_ptr() as *const __m256i;
    let m = _mm256_max_epu32(
        _mm256_max_epu32(_mm256_loadu_si256(ip), _mm256_loadu_si256(ip.add(1))),
        _mm256_loadu_si256(ip.add(2)),
    );
    let m = _mm_max_epu32(_mm256_castsi256_si128(m), _mm256_extracti128_si256::<1>(m));
    let m = _mm_max_epu32(m, _mm_shuffle_epi32::<0b01_00_11_10>(m));
    let m = _mm_max_epu32(m, _mm_shuffle_epi32::<0b10_11_00_01>(m));
    if _mm_cvtsi128_si32(m) as u32 as usize >= s.verts.len() {
        return false;
    }
    let vb = s.verts.as_ptr();
    for c in 0..3 {
        let ld = |j: usize| _mm_loadu_ps(vb.add(tr[j][c] as usize) as *const f32);
        let pair = |j: usize| _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(ld(j)), ld(j + 4));
        let (r0, r1, r2, r3) = (pair(0), pair(1), pair(2), pair(3));
        // Per half: rows (x, y, z, 0) of corners j .. j + 3 → columns.
        let t0 = _mm256_castps_pd(_mm256_unpacklo_ps(r0, r1)); // x0 x1 y0 y1
        let t1 = _mm256_castps_pd(_mm256_unpackhi_ps(r0, r1)); // z0 z1 _ _
        let t2 = _mm256_castps_pd(_mm256_unpacklo_ps(r2, r3)); // x2 x3 y2 y3
        let t3 = _mm256_castps_pd(_mm256_unpackhi_ps(r2, r3)); // z2 z3 _ _
        _mm256_storeu_ps(p[c][0].as_mut_ptr(), _mm256_castpd_ps(_mm256_unpacklo_pd(t0, t2)));
        _mm256_storeu_ps(p[c][1].as_mut_ptr(), _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t2)));
        _mm256_storeu_ps(p[c][2].as_mut_ptr(), _mm256_castpd_ps(_mm256_unpacklo_pd(t1, t3)));
    }
    true
}

/// Sets up triangles `t0 .. t0 + BATCH` (lanes past `hi` are skipped): depth-range
/// rejection, bounding boxes, edge and plane constants, all branch-free so that it
/// vectorizes.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // lane-indexed structure-of-arrays code
fn setup_batch<const AVX: bool>(s: &Setup, t0: usize, hi: usize, out: &mut Batch) {
    let k = &s.camera.intrinsics;
    let zn32 = k.znear as f32;
    let zf32 = k.zfar as f32;
    let half_near = (0.5 * k.znear) as f32;
    let (wf, hf) = (k.width as f32, k.height as f32);
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    // Corner coordinates, structure of arrays: p[corner][x, y, z][lane].
    let mut p = [[[0.0f32; BATCH]; 3]; 3];
    let last = hi - 1;
    #[cfg(target_arch = "x86_64")]
    let gathered = AVX && t0 + BATCH <= hi && {
        // SAFETY: AVX is only true in the avx2-enabled build; the batch is in range.
        unsafe { gather_avx2(s, t0, &mut p) }
    };
    #[cfg(not(target_arch = "x86_64"))]
    let gathered = false;
    if !gathered {
        for j in 0..BATCH {
            let tri = s.tris[(t0 + j).min(last)];
            for (c, &i) in tri.iter().enumerate() {
                let v = &s.verts[i as usize];
                for q in 0..3 {
                    p[c][q][j] = v[q];
                }
            }
        }
    }
    for j in 0..BATCH {
        let (x0, y0, z0) = (p[0][0][j], p[0][1][j], p[0][2][j]);
        let (x1, y1, z1) = (p[1][0][j], p[1][1][j], p[1][2][j]);
        let (x2, y2, z2) = (p[2][0][j], p[2][1][j], p[2][2][j]);
        // Projected corners (meaningful where z > znear / 2; NaN/inf elsewhere, which the
        // bounding-box clamps below turn into in-range values of an unused box). f32 error
        // ~1e-4 px inside the image, below BBOX_MARGIN.
        let proj = |x: f32, y: f32, z: f32| {
            let iz = 1.0 / z;
            (cx + fx * x * iz, cy + fy * y * iz)
        };
        let (u0, v0) = proj(x0, y0, z0);
        let (u1, v1) = proj(x1, y1, z1);
        let (u2, v2) = proj(x2, y2, z2);
        let zmin = z0.min(z1).min(z2);
        let zmax = z0.max(z1).max(z2);
        // f32 rounding is monotone, so this rejection is exact for the f64 depths.
        let in_range = (zmax >= zn32) & (zmin <= zf32) & (t0 + j <= last);
        let in_front = zmin > half_near;
        // Pixel u's centre is u + ½: candidates are ⌈umin − ½⌉ ..= ⌊umax − ½⌋.
        let bx0 = (u0.min(u1).min(u2) - 0.5 - BBOX_MARGIN).clamp(-1.0, wf).ceil().max(0.0);
        let bx1 = (u0.max(u1).max(u2) - 0.5 + BBOX_MARGIN).clamp(-1.0, wf).floor().min(wf - 1.0);
        let by0 = (v0.min(v1).min(v2) - 0.5 - BBOX_MARGIN).clamp(-1.0, hf).ceil().max(0.0);
        let by1 = (v0.max(v1).max(v2) - 0.5 + BBOX_MARGIN).clamp(-1.0, hf).floor().min(hf - 1.0);
        let nonempty = (bx0 <= bx1) & (by0 <= by1);
        // SAFETY: max/min never return NaN, so all four are integral values in [−1, w] / [−1, h].
        unsafe {
            out.bbox[0][j] = bx0.to_int_unchecked();
            out.bbox[1][j] = bx1.to_int_unchecked();
            out.bbox[2][j] = by0.to_int_unchecked();
            out.bbox[3][j] = by1.to_int_unchecked();
        }
        // Plane n·p = d with d = [p0, p1, p2]; normalize the sign so that d > 0: then "hit in
        // front" is "all edge functions ≥ 0" and depth = d / (n·r).
        let (ax, ay, az) = (x1 - x0, y1 - y0, z1 - z0);
        let (bx, by, bz) = (x2 - x0, y2 - y0, z2 - z0);
        let n = [ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx];
        let (t0x, t0y, t0z) = (n[0] * x0, n[1] * y0, n[2] * z0);
        let d = t0x + t0y + t0z;
        let sg = if d > 0.0 { 1.0f32 } else { -1.0 };
        let e = [
            edge([x0, y0, z0], [x1, y1, z1]),
            edge([x1, y1, z1], [x2, y2, z2]),
            edge([x2, y2, z2], [x0, y0, z0]),
        ];
        for q in 0..3 {
            out.a[q][j] = sg * e[q][0];
            out.b[q][j] = sg * e[q][1];
            out.c[q][j] = sg * e[q][2];
            out.n[q][j] = sg * n[q];
        }
        let d = sg * d;
        out.d[j] = d;
        out.inv_d[j] = 1.0 / d;
        // The f32 depth d / (n·r) is accurate to ~3ε·(sd / d + S / (n·r)) relative, with
        // S = |n0·px| + |n1·py| + |n2| ≤ sr and n·r = d / z ≥ d / zmax on the triangle. Where
        // that exceeds 3ε·GRAZING_GAIN (grazing views), the depth is computed in f64.
        let sd = t0x.abs() + t0y.abs() + t0z.abs();
        let sr = s.pxmax * n[0].abs() + s.pymax * n[1].abs() + n[2].abs();
        out.grazing[j] = d * GRAZING_GAIN < sd + zmax * sr;
        // d = 0: the plane passes through the camera centre; no ray meets it at z > 0.
        let plane_ok = (d > 0.0) & (d < f32::INFINITY);
        out.flag[j] = if !in_range {
            SKIP
        } else if !in_front {
            CLIPPED
        } else if !(nonempty & plane_ok) {
            SKIP
        } else {
            DRAW
        };
    }
}

#[inline(always)]
fn raster_range_impl<const AVX: bool>(s: &Setup, lo: usize, hi: usize, zb: &mut ZBuf) {
    let k = &s.camera.intrinsics;
    let (w, h) = (k.width as i32, k.height as i32);
    if w == 0 || h == 0 || lo >= hi {
        return;
    }
    // Depth range [znear, zfar] as inverse depth.
    let wmin = (1.0 / k.zfar) as f32;
    let wmax = (1.0 / k.znear) as f32;
    let wu = w as usize;
    // The unchecked AVX2 row loop relies on these (see draw_rows_avx2).
    let n = wu * h as usize;
    assert!(zb.key.len() >= n + LANES && zb.id.len() >= n + LANES);
    assert!(s.px.len() >= wu + LANES && s.py.len() >= h as usize);
    let mut batch = Batch {
        flag: [SKIP; BATCH],
        bbox: [[0; BATCH]; 4],
        a: [[0.0; BATCH]; 3],
        b: [[0.0; BATCH]; 3],
        c: [[0.0; BATCH]; 3],
        n: [[0.0; BATCH]; 3],
        d: [0.0; BATCH],
        inv_d: [0.0; BATCH],
        grazing: [false; BATCH],
    };
    // Rows drawn to.
    let (mut ylo, mut yhi) = (usize::MAX, 0);
    let mut t0 = lo;
    while t0 < hi {
        setup_batch::<AVX>(s, t0, hi, &mut batch);
        for j in 0..BATCH {
            let mut flag = batch.flag[j];
            if flag == SKIP {
                continue;
            }
            let t = t0 + j;
            let mut bb = [batch.bbox[0][j], batch.bbox[1][j], batch.bbox[2][j], batch.bbox[3][j]];
            if flag == CLIPPED {
                let [i0, i1, i2] = s.tris[t];
                let c = |i: u32| s.camera.to_camera(s.positions[i as usize]);
                let Some([umin, umax, vmin, vmax]) = clipped_bbox([c(i0), c(i1), c(i2)], k) else {
                    continue;
                };
                bb = [
                    ((umin - 0.5 - BBOX_MARGIN).ceil() as i32).max(0),
                    ((umax - 0.5 + BBOX_MARGIN).floor() as i32).min(w - 1),
                    ((vmin - 0.5 - BBOX_MARGIN).ceil() as i32).max(0),
                    ((vmax - 0.5 + BBOX_MARGIN).floor() as i32).min(h - 1),
                ];
                let d = batch.d[j];
                if bb[0] > bb[1] || bb[2] > bb[3] || !((d > 0.0) & (d < f32::INFINITY)) {
                    continue;
                }
                flag = DRAW;
            }
            if flag == DRAW && batch.grazing[j] {
                flag = PRECISE;
            }
            let a = [batch.a[0][j], batch.a[1][j], batch.a[2][j]];
            let b = [batch.b[0][j], batch.b[1][j], batch.b[2][j]];
            let c = [batch.c[0][j], batch.c[1][j], batch.c[2][j]];
            let id = t as u32;
            let [x0, x1, y0, y1] = bb.map(|x| x as usize);
            (ylo, yhi) = (ylo.min(y0), yhi.max(y1 + 1));
            if flag == PRECISE {
                draw_precise(s, s.tris[t], [a, b, c], id, [x0, x1, y0, y1], zb);
                continue;
            }
            let n = [batch.n[0][j], batch.n[1][j], batch.n[2][j]];
            let mut rc = RowConst { a, r: [0.0; 3], n0: n[0], rw: 0.0, inv_d: batch.inv_d[j], wmin, wmax };
            #[cfg(target_arch = "x86_64")]
            if AVX {
                debug_assert!(x0 <= x1 && x1 < wu && y0 <= y1 && y1 < h as usize);
                // SAFETY: AVX is only true in the avx2-enabled build; buffer sizes are checked
                // on entry, and every box is clamped to the image (x1 < w and y1 < h: the
                // `.min(w − 1)` / `.min(wf − 1)` clamps above and in setup_batch).
                unsafe { draw_rows_avx2(&rc, b, c, [n[1], n[2]], s, zb, [x0, x1, y0, y1], id) };
                continue;
            }
            for v in y0..=y1 {
                let py = s.py[v];
                rc.r = [b[0] * py + c[0], b[1] * py + c[1], b[2] * py + c[2]];
                rc.rw = n[1] * py + n[2];
                let off = v * wu;
                let mut u = x0;
                while u <= x1 {
                    // LANES pixels at once: coverage, inverse depth, z-test, masked update.
                    // The px table is padded with NaN (never covered) and the z-buffer with
                    // LANES pixels, so full-width reads stay in bounds.
                    let pxs: &[f32; LANES] = s.px[u..u + LANES].try_into().expect("padded table");
                    let keys: &mut [u32; LANES] =
                        (&mut zb.key[off + u..off + u + LANES]).try_into().expect("padded buffer");
                    let ids: &mut [u32; LANES] =
                        (&mut zb.id[off + u..off + u + LANES]).try_into().expect("padded buffer");
                    let rem = (x1 + 1 - u).min(LANES);
                    span_scalar(&rc, pxs, keys, ids, rem, id);
                    u += LANES;
                }
            }
        }
        t0 += BATCH;
    }
    zb.touch((ylo.min(yhi) * wu, yhi * wu));
}

/// The pixel loop of a grazing triangle: f32 coverage (the same formula as every other
/// triangle, to stay watertight), depth and depth-range test in f64 from the f64
/// camera-frame corners.
#[inline(never)]
#[allow(clippy::needless_range_loop)] // lane-indexed structure-of-arrays code
fn draw_precise(
    s: &Setup,
    corners: [u32; 3],
    [a, b, c]: [[f32; 3]; 3],
    id: u32,
    [x0, x1, y0, y1]: [usize; 4],
    zb: &mut ZBuf,
) {
    let [p, q, r] = corners.map(|i| s.camera.to_camera(s.positions[i as usize]));
    let e1 = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
    let e2 = [r[0] - p[0], r[1] - p[1], r[2] - p[2]];
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let d = n[0] * p[0] + n[1] * p[1] + n[2] * p[2];
    let (zn, zf) = (s.camera.intrinsics.znear, s.camera.intrinsics.zfar);
    let wu = s.px64.len();
    for v in y0..=y1 {
        let py = s.py[v];
        let r0 = b[0] * py + c[0];
        let r1 = b[1] * py + c[1];
        let r2 = b[2] * py + c[2];
        let rw = n[1] * s.py64[v] + n[2];
        let rk = &mut zb.key[v * wu..v * wu + wu];
        let ri = &mut zb.id[v * wu..v * wu + wu];
        for u in x0..=x1 {
            let px = s.px[u];
            let e0 = a[0] * px + r0;
            let e1 = a[1] * px + r1;
            let e2 = a[2] * px + r2;
            if (e0 >= 0.0) & (e1 >= 0.0) & (e2 >= 0.0) {
                // d / (n·r) does not depend on the orientation of n.
                let z = d / (n[0] * s.px64[u] + rw);
                if z >= zn && z <= zf {
                    let key = depth_key((1.0 / z) as f32);
                    if key < rk[u] {
                        rk[u] = key;
                        ri[u] = id;
                    }
                }
            }
        }
    }
}

/// Renders `mesh` from `camera` on the calling thread (allocates fresh buffers; use a
/// [`Renderer`] to reuse them). Poses/cameras are in the object frame; depth is camera-frame
/// z, 0 = miss.
pub fn render(mesh: &Mesh, camera: &Camera) -> Frame {
    let mut frame = Frame::empty(*camera);
    Renderer::new().render_into(mesh, camera, &mut frame);
    frame
}

/// Renders `mesh` from `camera` with all threads of the current rayon pool; bit-identical to
/// [`render`].
pub fn render_parallel(mesh: &Mesh, camera: &Camera) -> Frame {
    let mut frame = Frame::empty(*camera);
    Renderer::new().render_parallel_into(mesh, camera, &mut frame);
    frame
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{bench_mesh, icosphere};
    use objview_geom::Pose;

    fn same(a: &Frame, b: &Frame) -> bool {
        a.depth.iter().map(|x| x.to_bits()).eq(b.depth.iter().map(|x| x.to_bits()))
            && a.triangle == b.triangle
    }

    /// Fine meshes (triangles of a few pixels: the narrow-box kernel of the AVX2 build, boxes
    /// of one to five rows) give the same bytes on the AVX2 and portable paths, and a reused
    /// renderer (touched-row bookkeeping, here across meshes covering different rows) gives
    /// the same bytes as a fresh one.
    #[test]
    fn fine_meshes_agree_across_paths_and_reuse() {
        let meshes = [bench_mesh(100_000), icosphere(5)];
        let poses = [
            Pose::from_direction([0.3, -0.8, 0.5], 3.0),
            Pose::from_direction([0.0, 0.0, 1.0], 1.2),
            Pose::from_direction([-0.6, 0.2, -0.1], 9.0),
        ];
        let (mut simd, mut portable) = (Renderer::new(), Renderer::new());
        portable.set_portable(true);
        for mesh in &meshes {
            for &p in &poses {
                let cam = Camera::with_default_intrinsics(p);
                let (mut a, mut b) = (Frame::empty(cam), Frame::empty(cam));
                simd.render_into(mesh, &cam, &mut a);
                portable.render_into(mesh, &cam, &mut b);
                assert!(a.num_hits() > 1000);
                assert!(same(&a, &b));
                assert!(same(&a, &render(mesh, &cam)));
            }
        }
    }
}
