//! Brute-force reference renderer: for every pixel, intersect the ray through the pixel centre
//! with every triangle (Möller–Trumbore in f64, no culling) and keep the nearest hit whose
//! camera-frame depth lies in [znear, zfar]. O(pixels × triangles): for tests on small meshes,
//! never for production.

use crate::{Camera, Frame};
use objview_geom::Mesh;
use rayon::prelude::*;

/// Intersects the ray `o + t·d` with triangle (a, b, c); returns `t` (no culling, t unbounded).
#[inline]
pub fn ray_triangle(o: [f64; 3], d: [f64; 3], [a, b, c]: [[f64; 3]; 3]) -> Option<f64> {
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let p = [d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]];
    let det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = [o[0] - a[0], o[1] - a[1], o[2] - a[2]];
    let u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = [s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]];
    let v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some((e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv)
}

/// First hit through the centre of pixel (u, v): `(depth, triangle)`.
pub fn cast_pixel(mesh: &Mesh, cam: &Camera, u: u32, v: u32) -> Option<(f64, u32)> {
    // The object-frame ray direction has camera-frame z = 1, so t is the depth.
    let d = cam.pixel_ray_object(u, v);
    let (zn, zf) = (cam.intrinsics.znear, cam.intrinsics.zfar);
    let mut best: Option<(f64, u32)> = None;
    for t in 0..mesh.num_triangles() {
        if let Some(z) = ray_triangle(cam.center, d, mesh.triangle(t)) {
            if z >= zn && z <= zf && best.is_none_or(|(bz, _)| z < bz) {
                best = Some((z, t as u32));
            }
        }
    }
    best
}

/// Renders every pixel by brute force (parallel over rows).
pub fn render(mesh: &Mesh, cam: &Camera) -> Frame {
    let mut frame = Frame::empty(*cam);
    let w = cam.intrinsics.width as usize;
    frame.depth.par_chunks_mut(w).zip(frame.triangle.par_chunks_mut(w)).enumerate().for_each(
        |(v, (drow, trow))| {
            for u in 0..w {
                if let Some((z, t)) = cast_pixel(mesh, cam, u as u32, v as u32) {
                    drow[u] = z as f32;
                    trow[u] = t;
                }
            }
        },
    );
    frame
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Intrinsics, NO_HIT};
    use objview_geom::Pose;

    #[test]
    fn ray_hits_triangle_at_expected_t() {
        let tri = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(ray_triangle([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], tri), Some(2.0));
        assert_eq!(ray_triangle([5.0, 0.0, 2.0], [0.0, 0.0, -1.0], tri), None);
    }

    #[test]
    fn square_facing_camera_has_constant_depth() {
        // A 1×1 square in the plane x = 0, camera on +x at distance 3.
        let mesh = Mesh::new(
            vec![[0.0, -0.5, -0.5], [0.0, 0.5, -0.5], [0.0, 0.5, 0.5], [0.0, -0.5, 0.5]],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let cam =
            Camera::new(Pose::from_direction([1.0, 0.0, 0.0], 3.0), Intrinsics::from_fov(64, 64, 45.0, 45.0));
        let f = render(&mesh, &cam);
        let (c, _) = cast_pixel(&mesh, &cam, 32, 32).unwrap();
        assert!((c - 3.0).abs() < 1e-12);
        // Half-width 0.5 at distance 3 → 0.5·fx/3 ≈ 12.9 pixels each side of the centre.
        let hits = f.num_hits();
        assert!((24 * 24..=26 * 26).contains(&hits), "{hits}");
        assert!(f.depth.iter().all(|&z| z == 0.0 || (z - 3.0).abs() < 1e-6));
        assert!(f.triangle.contains(&NO_HIT));
    }
}
