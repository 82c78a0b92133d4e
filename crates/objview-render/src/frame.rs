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
    pub fn observed_points_into(&self, out: &mut Vec<[f64; 3]>) {
        out.clear();
        let w = self.width();
        for (i, (&z, &t)) in self.depth.iter().zip(&self.triangle).enumerate() {
            if t != NO_HIT {
                let (u, v) = (i as u32 % w, i as u32 / w);
                out.push(self.camera.unproject(u, v, z as f64));
            }
        }
    }
}
