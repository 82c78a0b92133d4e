//! The pinhole camera of SPEC §2.
//!
//! Frames: the *object frame* is the mesh's own (normalized) frame. The *camera frame* is
//! OpenCV's: x right, y down, z forward; depth is the camera-frame z. Image coordinates: pixel
//! `(u, v)` is column `u`, row `v`; its centre is `(u + 0.5, v + 0.5)`.
//!
//! Axes from a pose: forward f = normalize(look_at − centre); if |f − (0,0,±1)| < 1e-6 then
//! f = normalize(1e-8, 1e-8, ±1) (the pole rule); right x = normalize(f × (0,0,1)); down
//! y = f × x; roll rotates (x, y) about f by the right-hand rule:
//! x' = cos r·x + sin r·y, y' = −sin r·x + cos r·y.

use objview_geom::vec3::{cross, dot, normalize, sub};
use objview_geom::Pose;

/// Pinhole intrinsics in pixels, with near/far clipping distances along the camera z axis.
/// Serialized with these field names (results, sidecars, the server's observations).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Intrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Horizontal focal length, pixels.
    pub fx: f64,
    /// Vertical focal length, pixels.
    pub fy: f64,
    /// Principal point, horizontal image coordinate, pixels from the left edge.
    pub cx: f64,
    /// Principal point, vertical image coordinate, pixels from the top edge.
    pub cy: f64,
    /// Near clipping distance along the camera z axis, object units.
    pub znear: f64,
    /// Far clipping distance along the camera z axis, object units.
    pub zfar: f64,
}

impl Default for Intrinsics {
    /// SPEC §2: 512×512, 45° field of view both ways, principal point (256, 256),
    /// znear 0.01, zfar 10.
    fn default() -> Self {
        Intrinsics::from_fov(512, 512, 45.0, 45.0)
    }
}

impl Intrinsics {
    /// Intrinsics with the given size and full horizontal/vertical field of view in degrees,
    /// principal point at the image centre, znear 0.01, zfar 10.
    pub fn from_fov(width: u32, height: u32, fov_x_deg: f64, fov_y_deg: f64) -> Self {
        let cx = width as f64 / 2.0;
        let cy = height as f64 / 2.0;
        Intrinsics {
            width,
            height,
            fx: cx / (fov_x_deg.to_radians() / 2.0).tan(),
            fy: cy / (fov_y_deg.to_radians() / 2.0).tan(),
            cx,
            cy,
            znear: 0.01,
            zfar: 10.0,
        }
    }

    /// Number of pixels.
    pub fn num_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Camera-frame direction (z = 1) of the ray through the centre of pixel (u, v).
    #[inline]
    pub fn pixel_ray(&self, u: u32, v: u32) -> [f64; 3] {
        [(u as f64 + 0.5 - self.cx) / self.fx, (v as f64 + 0.5 - self.cy) / self.fy, 1.0]
    }

    /// Projects a camera-frame point to continuous image coordinates (u, v); `None` when its
    /// z ≤ 1e-9 (behind or on the camera plane).
    #[inline]
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        if p[2] <= 1e-9 {
            return None;
        }
        Some([self.fx * p[0] / p[2] + self.cx, self.fy * p[1] / p[2] + self.cy])
    }

    /// The pixel (floor of the projected coordinates) a camera-frame point falls in, if inside
    /// the image and in front of the camera (z > 1e-9).
    #[inline]
    pub fn pixel_of(&self, p: [f64; 3]) -> Option<(u32, u32)> {
        let [u, v] = self.project(p)?;
        let (fu, fv) = (u.floor(), v.floor());
        if fu >= 0.0 && fv >= 0.0 && fu < self.width as f64 && fv < self.height as f64 {
            Some((fu as u32, fv as u32))
        } else {
            None
        }
    }
}

/// A posed camera: centre and orthonormal axes (right, down, forward) in the object frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// The pinhole intrinsics (image size, focal lengths, principal point, clipping).
    pub intrinsics: Intrinsics,
    /// The pose the camera was built from (object frame, roll in radians).
    pub pose: Pose,
    /// Camera centre, object frame.
    pub center: [f64; 3],
    /// Camera x axis (image right), object frame.
    pub right: [f64; 3],
    /// Camera y axis (image down), object frame.
    pub down: [f64; 3],
    /// Camera z axis (viewing direction), object frame.
    pub forward: [f64; 3],
}

impl Camera {
    /// The camera at `pose` (object frame, radians) with the given intrinsics. A pose whose
    /// centre equals its look-at point has no viewing direction; callers validate poses first
    /// (feasibility requires radius ≥ 1 and look-at inside), and such a pose yields NaN axes.
    pub fn new(pose: Pose, intrinsics: Intrinsics) -> Camera {
        let mut f = normalize(sub(pose.look_at, pose.center));
        for s in [1.0, -1.0] {
            let d = sub(f, [0.0, 0.0, s]);
            if dot(d, d).sqrt() < 1e-6 {
                f = normalize([1e-8, 1e-8, s]);
            }
        }
        let x = normalize(cross(f, [0.0, 0.0, 1.0]));
        let y = cross(f, x);
        let (s, c) = pose.roll.sin_cos();
        let right = [c * x[0] + s * y[0], c * x[1] + s * y[1], c * x[2] + s * y[2]];
        let down = [-s * x[0] + c * y[0], -s * x[1] + c * y[1], -s * x[2] + c * y[2]];
        Camera { intrinsics, pose, center: pose.center, right, down, forward: f }
    }

    /// The camera at `pose` with the default intrinsics of SPEC §2.
    pub fn with_default_intrinsics(pose: Pose) -> Camera {
        Camera::new(pose, Intrinsics::default())
    }

    /// Object-frame point → camera-frame point.
    #[inline]
    pub fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        let d = sub(p, self.center);
        [dot(d, self.right), dot(d, self.down), dot(d, self.forward)]
    }

    /// Camera-frame point → object-frame point.
    #[inline]
    pub fn to_object(&self, q: [f64; 3]) -> [f64; 3] {
        let (r, d, f, c) = (self.right, self.down, self.forward, self.center);
        std::array::from_fn(|k| c[k] + q[0] * r[k] + q[1] * d[k] + q[2] * f[k])
    }

    /// Object-frame direction (not normalized; its camera-frame z component is 1) of the ray
    /// from the camera centre through the centre of pixel (u, v).
    #[inline]
    pub fn pixel_ray_object(&self, u: u32, v: u32) -> [f64; 3] {
        let q = self.intrinsics.pixel_ray(u, v);
        let (r, d, f) = (self.right, self.down, self.forward);
        std::array::from_fn(|k| q[0] * r[k] + q[1] * d[k] + f[k])
    }

    /// Back-projects pixel (u, v) at camera depth z to an object-frame point.
    #[inline]
    pub fn unproject(&self, u: u32, v: u32, z: f64) -> [f64; 3] {
        let q = self.intrinsics.pixel_ray(u, v);
        self.to_object([q[0] * z, q[1] * z, z])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() < tol)
    }

    #[test]
    fn default_intrinsics_match_spec() {
        let k = Intrinsics::default();
        assert_eq!((k.width, k.height, k.cx, k.cy), (512, 512, 256.0, 256.0));
        assert!((k.fx - 618.0387).abs() < 1e-4, "{}", k.fx);
        assert_eq!(k.fx, k.fy);
    }

    #[test]
    fn axes_are_orthonormal_right_handed_and_z_up() {
        let cam = Camera::with_default_intrinsics(Pose::from_direction([1.0, 0.0, 0.0], 3.0));
        assert!(close(cam.forward, [-1.0, 0.0, 0.0], 1e-12));
        assert!(close(cam.right, [0.0, 1.0, 0.0], 1e-12));
        // Image "down" is world −z: the world is upright in the image.
        assert!(close(cam.down, [0.0, 0.0, -1.0], 1e-12));
        assert!(close(cross(cam.right, cam.down), cam.forward, 1e-12));
    }

    #[test]
    fn look_at_projects_to_principal_point() {
        for (c, l, r) in [
            ([3.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0),
            ([1.0, 2.0, -0.5], [0.3, -0.2, 0.1], 0.7),
            ([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 1.3),
            ([0.0, 0.0, -2.0], [0.0, 0.0, 0.5], -2.0),
        ] {
            let cam = Camera::with_default_intrinsics(Pose { center: c, look_at: l, roll: r });
            let uv = cam.intrinsics.project(cam.to_camera(l)).unwrap();
            // Poles are perturbed by 1e-8 rad (the pole rule): ~1e-5 px off the centre.
            assert!((uv[0] - 256.0).abs() < 1e-4 && (uv[1] - 256.0).abs() < 1e-4, "{uv:?}");
            let q = cam.to_camera([0.3, 0.1, -0.2]);
            assert!(close(cam.to_object(q), [0.3, 0.1, -0.2], 1e-12));
        }
    }

    #[test]
    fn pole_rule_gives_finite_axes() {
        let cam = Camera::with_default_intrinsics(Pose::from_direction([0.0, 0.0, 1.0], 3.0));
        for a in [cam.right, cam.down, cam.forward] {
            assert!(a.iter().all(|x| x.is_finite()));
            assert!((dot(a, a) - 1.0).abs() < 1e-12);
        }
        assert!(cam.forward[2] < -0.999_999);
    }

    #[test]
    fn roll_pi_flips_the_image() {
        let p = Pose::from_direction([1.0, 1.0, 0.5], 3.0);
        let a = Camera::with_default_intrinsics(p);
        let b = Camera::with_default_intrinsics(Pose { roll: std::f64::consts::PI, ..p });
        let x = [0.2, -0.1, 0.3];
        let ua = a.intrinsics.project(a.to_camera(x)).unwrap();
        let ub = b.intrinsics.project(b.to_camera(x)).unwrap();
        assert!((ua[0] - 256.0 + (ub[0] - 256.0)).abs() < 1e-9);
        assert!((ua[1] - 256.0 + (ub[1] - 256.0)).abs() < 1e-9);
    }

    #[test]
    fn pixel_of_uses_floor_and_rejects_outside() {
        let k = Intrinsics::default();
        assert_eq!(k.pixel_of([0.0, 0.0, 1.0]), Some((256, 256)));
        assert_eq!(k.pixel_of([-1e-6, -1e-6, 1.0]), Some((255, 255)));
        assert_eq!(k.pixel_of([10.0, 0.0, 1.0]), None);
        assert_eq!(k.pixel_of([0.0, 0.0, -1.0]), None);
    }
}
