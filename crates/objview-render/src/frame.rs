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
    /// points, bit for bit.
    pub fn observed_points_into(&self, out: &mut Vec<[f64; 3]>) {
        out.clear();
        let w = self.width() as usize;
        if w == 0 {
            return;
        }
        let k = &self.camera.intrinsics;
        let qu: Vec<f64> = (0..w as u32).map(|u| k.pixel_ray(u, 0)[0]).collect();
        for (v, (depth, tri)) in self.depth.chunks_exact(w).zip(self.triangle.chunks_exact(w)).enumerate() {
            let qv = k.pixel_ray(0, v as u32)[1];
            for ((&z, &t), &qx) in depth.iter().zip(tri).zip(&qu) {
                if t != NO_HIT {
                    let z = z as f64;
                    out.push(self.camera.to_object([qx * z, qv * z, z]));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Intrinsics;
    use objview_geom::Pose;
    use rand::{Rng, SeedableRng};

    #[test]
    fn observed_points_are_each_hit_unprojected_in_pixel_order() {
        // A non-square image with an off-centre principal point and different focal lengths,
        // random depths and hits: the row-by-row pass gives what `unproject` gives per pixel,
        // bit for bit.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let k = Intrinsics {
            width: 37,
            height: 23,
            fx: 41.3,
            fy: 29.7,
            cx: 17.2,
            cy: 12.9,
            ..Intrinsics::default()
        };
        let pose = Pose::from_direction([0.3, -0.8, 0.52], 2.7);
        let mut frame = Frame::empty(Camera::new(pose, k));
        for (i, (d, t)) in frame.depth.iter_mut().zip(frame.triangle.iter_mut()).enumerate() {
            if rng.gen_bool(0.6) {
                *d = rng.gen_range(0.5f32..5.0);
                *t = i as u32;
            }
        }
        let mut want = Vec::new();
        for v in 0..k.height {
            for u in 0..k.width {
                let i = (v * k.width + u) as usize;
                if frame.triangle[i] != NO_HIT {
                    want.push(frame.camera.unproject(u, v, frame.depth[i] as f64).map(f64::to_bits));
                }
            }
        }
        let got: Vec<[u64; 3]> = frame.observed_points().iter().map(|p| p.map(f64::to_bits)).collect();
        assert_eq!(got.len(), frame.num_hits());
        assert!(got.len() > 400);
        assert_eq!(got, want);
    }
}
