//! A rendered view: per-pixel camera-frame depth and the id of the triangle hit, and what is
//! derived from them — the observed point cloud (pixel centres back-projected into the object
//! frame, SPEC §2).

use crate::Camera;

/// Triangle id of a pixel where nothing was hit.
pub const NO_HIT: u32 = u32::MAX;

/// One rendered view. Buffers are row-major, `width × height`, index `v · width + u`
/// (row = image v).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// The camera that rendered it (object frame pose, intrinsics).
    pub camera: Camera,
    /// Camera-frame z of the first hit through each pixel centre; 0.0 where nothing was hit.
    pub depth: Vec<f32>,
    /// Index of the triangle hit, or [`NO_HIT`].
    pub triangle: Vec<u32>,
}

impl Frame {
    /// An empty (all-miss) frame for `camera`.
    pub fn empty(camera: Camera) -> Frame {
        let n = camera.intrinsics.num_pixels();
        Frame { camera, depth: vec![0.0; n], triangle: vec![NO_HIT; n] }
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.camera.intrinsics.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.camera.intrinsics.height
    }

    /// Number of pixels with a hit.
    pub fn num_hits(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != NO_HIT).count()
    }

    /// The observed point cloud: every pixel with a hit, back-projected at its pixel centre
    /// with its depth, in the object frame; row-major pixel order.
    pub fn observed_points(&self) -> Vec<[f64; 3]> {
        let mut out = Vec::with_capacity(self.num_hits());
        self.observed_points_into(&mut out);
        out
    }

    /// [`Frame::observed_points`] into `out` (cleared first; its buffer is reused).
    ///
    /// Row by row, with each column's and row's ray slope computed once (the same divisions
    /// [`Camera::unproject`] makes per pixel), so a hit costs its transform only: the same
    /// points, bit for bit (each through [`Camera::to_object`]).
    ///
    /// Each row is read in chunks of [`UNPROJECT_CHUNK`] pixels: a chunk without a hit (the
    /// background around the object, most of an image) is passed by with one vectorized test;
    /// in a chunk with hits every pixel is transformed and written to the next free place, which
    /// only a hit then keeps. No branch depends on a single pixel, so the silhouette's ragged
    /// rows mispredict nothing, and the transforms of a chunk have no dependency between them.
    pub fn observed_points_into(&self, out: &mut Vec<[f64; 3]>) {
        out.clear();
        let w = self.width() as usize;
        if w == 0 {
            return;
        }
        let k = &self.camera.intrinsics;
        let qu: Vec<f64> = (0..w as u32).map(|u| k.pixel_ray(u, 0)[0]).collect();
        // A local copy: its axes stay in registers across the rows.
        let cam = self.camera;
        for (v, (depth, tri)) in self.depth.chunks_exact(w).zip(self.triangle.chunks_exact(w)).enumerate() {
            // A row without a hit adds nothing (and asks for no room).
            if tri.iter().fold(NO_HIT, |a, &t| a & t) == NO_HIT {
                continue;
            }
            let qv = k.pixel_ray(0, v as u32)[1];
            out.reserve(w);
            let room = out.spare_capacity_mut();
            let mut n = 0;
            for ((zs, ts), qs) in
                depth.chunks(UNPROJECT_CHUNK).zip(tri.chunks(UNPROJECT_CHUNK)).zip(qu.chunks(UNPROJECT_CHUNK))
            {
                // NO_HIT is all ones: the AND of a chunk's ids is NO_HIT iff none was hit.
                if ts.iter().fold(NO_HIT, |a, &t| a & t) == NO_HIT {
                    continue;
                }
                for ((&z, &t), &qx) in zs.iter().zip(ts).zip(qs) {
                    let z = z as f64;
                    room[n].write(cam.to_object([qx * z, qv * z, z]));
                    n += (t != NO_HIT) as usize;
                }
            }
            // SAFETY: the first `n` places of the spare capacity were written above (`n` counts
            // the hits of this row, each written at the place `n` had before it; a miss's write
            // is overwritten by the next pixel or left beyond the new length).
            unsafe { out.set_len(out.len() + n) };
        }
    }
}

/// Pixels per chunk of [`Frame::observed_points_into`]'s row scan.
pub const UNPROJECT_CHUNK: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Intrinsics;
    use objview_geom::Pose;
    use rand::{Rng, SeedableRng};

    /// Each hit of `frame` through [`Camera::unproject`], in row-major order (the definition).
    fn per_pixel(frame: &Frame) -> Vec<[u64; 3]> {
        let (w, h) = (frame.width(), frame.height());
        let mut want = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let i = (v * w + u) as usize;
                if frame.triangle[i] != NO_HIT {
                    want.push(frame.camera.unproject(u, v, frame.depth[i] as f64).map(f64::to_bits));
                }
            }
        }
        want
    }

    /// A non-square image with an off-centre principal point and different focal lengths;
    /// pixel i hits (triangle i, a random depth) where `hit(i)`.
    fn frame_with(width: u32, height: u32, hit: impl Fn(usize) -> bool) -> Frame {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let k = Intrinsics { width, height, fx: 41.3, fy: 29.7, cx: 17.2, cy: 12.9, ..Intrinsics::default() };
        let pose = Pose::from_direction([0.3, -0.8, 0.52], 2.7);
        let mut frame = Frame::empty(Camera::new(pose, k));
        for (i, (d, t)) in frame.depth.iter_mut().zip(frame.triangle.iter_mut()).enumerate() {
            let z = rng.gen_range(0.5f32..5.0);
            if hit(i) {
                *d = z;
                *t = i as u32;
            }
        }
        frame
    }

    #[test]
    fn observed_points_are_each_hit_unprojected_in_pixel_order() {
        // Random depths and hits: the row-by-row pass gives what `unproject` gives per pixel,
        // bit for bit.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let hits: Vec<bool> = (0..37 * 23).map(|_| rng.gen_bool(0.6)).collect();
        let frame = frame_with(37, 23, |i| hits[i]);
        let got: Vec<[u64; 3]> = frame.observed_points().iter().map(|p| p.map(f64::to_bits)).collect();
        assert_eq!(got.len(), frame.num_hits());
        assert!(got.len() > 400);
        assert_eq!(got, per_pixel(&frame));
    }

    #[test]
    fn rows_and_chunks_without_hits_are_passed_by_and_the_rest_kept() {
        // 53 = 3 chunks of 16 and a short one of 5. Rows without any hit (v % 4 == 1), rows
        // whose hits all lie in one chunk (the first, the third or the short last: v % 4 == 2,
        // by v), single hits at a chunk's first and last pixel (v % 4 == 3), and full rows;
        // the output buffer arrives holding points of another frame.
        let w = 53usize;
        let frame = frame_with(w as u32, 19, |i| {
            let (u, v) = (i % w, i / w);
            match v % 4 {
                0 => true,
                1 => false,
                2 => [0, 2, 3][v % 3] == u / 16,
                _ => u == 16 || u == 47 || u == 52,
            }
        });
        let mut got = vec![[1.0; 3]; 999];
        frame.observed_points_into(&mut got);
        let got: Vec<[u64; 3]> = got.iter().map(|p| p.map(f64::to_bits)).collect();
        assert_eq!(got.len(), frame.num_hits());
        assert_eq!(got, per_pixel(&frame));
        // An image without hits gives nothing.
        let empty = frame_with(w as u32, 5, |_| false);
        assert!(empty.observed_points().is_empty());
    }
}
