//! RGB rendering of an already rendered [`Frame`]: the frame's triangle ids say what each
//! pixel sees, so colour is only a per-pixel lookup. The barycentric coordinates of the
//! pixel-centre ray on its triangle (f64 ray–triangle intersection) pick the interpolated
//! vertex colour or texture texel; meshes without appearance get a deterministic grey
//! Lambertian shading with the light at the camera.

use crate::{Frame, NO_HIT};
use objview_geom::vec3::{cross, dot, sub};
use objview_geom::{Appearance, Mesh};

/// Grey level of a surface seen exactly edge-on, so that grazing hits stay distinguishable
/// from the black background; a surface facing the camera is white.
pub const AMBIENT: f64 = 0.1;

/// Barycentric weights (for corners 0, 1, 2) of the point where the line `o + t·d` meets the
/// plane of `tri`, clamped to the triangle (a pixel attributed to a triangle by the
/// rasterizer may lie a hair outside it) and renormalized to sum to 1. Object frame.
/// `None` when the line is parallel to the plane or the triangle is degenerate.
pub fn barycentric(o: [f64; 3], d: [f64; 3], [a, b, c]: [[f64; 3]; 3]) -> Option<[f64; 3]> {
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let s = sub(o, a);
    let q = cross(s, e1);
    let u = dot(s, p) / det;
    let v = dot(d, q) / det;
    let w = [(1.0 - u - v).max(0.0), u.max(0.0), v.max(0.0)];
    let sum = w[0] + w[1] + w[2];
    Some([w[0] / sum, w[1] / sum, w[2] / sum])
}

#[inline]
fn to_u8(x: f64) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The RGB image (row-major like the frame, `[r, g, b]` per pixel) of `frame`, rendered from
/// `mesh` (the same mesh the frame was rendered from; object frame). Hit pixels get
/// `mesh.color_at(triangle, barycentrics)` (0..1 scaled to 0..255), or, when the mesh has no
/// appearance, grey `AMBIENT + (1 − AMBIENT)·|cos θ|` with θ the angle between the pixel ray
/// and the triangle normal (light at the camera). Misses are black.
pub fn render_rgb(mesh: &Mesh, frame: &Frame) -> Vec<[u8; 3]> {
    let cam = &frame.camera;
    let w = frame.width();
    let shaded = matches!(mesh.appearance, Appearance::None);
    frame
        .triangle
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            if t == NO_HIT {
                return [0, 0, 0];
            }
            let (u, v) = (i as u32 % w, i as u32 / w);
            let d = cam.pixel_ray_object(u, v);
            let tri = mesh.triangle(t as usize);
            if shaded {
                let n = cross(sub(tri[1], tri[0]), sub(tri[2], tri[0]));
                let nn = dot(n, n) * dot(d, d);
                let c = if nn > 0.0 { dot(n, d).abs() / nn.sqrt() } else { 0.0 };
                let g = to_u8(AMBIENT + (1.0 - AMBIENT) * c);
                return [g, g, g];
            }
            let bary = barycentric(cam.center, d, tri).unwrap_or([1.0 / 3.0; 3]);
            let bary = bary.map(|x| x as f32);
            match mesh.color_at(t as usize, bary) {
                Some(c) => c.map(|x| to_u8(x as f64)),
                None => [0, 0, 0],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Camera, Intrinsics};
    use objview_geom::Pose;

    /// Square in the plane x = 0 (|y|, |z| ≤ 0.5), camera on +x: image right = +y, down = −z.
    fn square() -> Mesh {
        Mesh::new(
            vec![[0.0, -0.5, -0.5], [0.0, 0.5, -0.5], [0.0, 0.5, 0.5], [0.0, -0.5, 0.5]],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    fn cam() -> Camera {
        Camera::new(Pose::from_direction([1.0, 0.0, 0.0], 3.0), Intrinsics::from_fov(64, 64, 45.0, 45.0))
    }

    #[test]
    fn barycentric_of_known_points() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let b = barycentric([0.25, 0.5, 2.0], [0.0, 0.0, -1.0], tri).unwrap();
        assert!((b[0] - 0.25).abs() < 1e-12 && (b[1] - 0.25).abs() < 1e-12 && (b[2] - 0.5).abs() < 1e-12);
        // Outside points are clamped onto the triangle.
        let b = barycentric([2.0, 0.0, 2.0], [0.0, 0.0, -1.0], tri).unwrap();
        assert_eq!(b, [0.0, 1.0, 0.0]);
    }

    #[test]
    fn face_colors_split_the_square_along_its_diagonal() {
        let mut m = square();
        m.appearance = Appearance::FaceColors(vec![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        let f = crate::render(&m, &cam());
        let img = render_rgb(&m, &f);
        // Triangle 0 = corners (y,z) (−.5,−.5), (.5,−.5), (.5,.5): below the diagonal y = z,
        // i.e. image bottom-right (right = +y, down = −z). Triangle 1 is top-left.
        let px = |u: usize, v: usize| img[v * 64 + u];
        assert_eq!(px(40, 40), [255, 0, 0]);
        assert_eq!(px(24, 24), [0, 0, 255]);
        assert_eq!(px(0, 0), [0, 0, 0]);
        let red = img.iter().filter(|c| **c == [255, 0, 0]).count();
        let blue = img.iter().filter(|c| **c == [0, 0, 255]).count();
        assert_eq!(red + blue, f.num_hits());
        assert!(red.abs_diff(blue) <= 26, "{red} vs {blue}");
    }

    #[test]
    fn vertex_colors_interpolate_barycentrically() {
        let mut m = square();
        // Red grows with y (image right), green with z (image up).
        m.appearance = Appearance::VertexColors(
            m.positions.iter().map(|p| [(p[1] + 0.5) as f32, (p[2] + 0.5) as f32, 0.0]).collect(),
        );
        let c = cam();
        let f = crate::render(&m, &c);
        let img = render_rgb(&m, &f);
        let mut checked = 0;
        for (i, &t) in f.triangle.iter().enumerate() {
            if t == NO_HIT {
                continue;
            }
            // Hit point in the object frame: the colour is an affine function of it.
            let p = c.unproject(i as u32 % 64, i as u32 / 64, f.depth[i] as f64);
            let want = [to_u8(p[1] + 0.5), to_u8(p[2] + 0.5), 0];
            for k in 0..3 {
                assert!((img[i][k] as i32 - want[k] as i32).abs() <= 1, "{:?} {:?}", img[i], want);
            }
            checked += 1;
        }
        assert!(checked > 500);
    }

    #[test]
    fn shading_is_white_head_on_and_grey_when_tilted() {
        let m = square();
        let f = crate::render(&m, &cam());
        let img = render_rgb(&m, &f);
        // Near the centre the ray is almost along the normal: |cos| ≈ 1.
        assert!(img[32 * 64 + 32][0] >= 254);
        // Tilt the square by 60° about z: |cos| ≈ 0.5 in the centre → 0.1 + 0.9·0.5 = 0.55.
        let (s, c) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
        let mut t = square();
        for p in &mut t.positions {
            *p = [-s * p[1], c * p[1], p[2]];
        }
        let f = crate::render(&t, &cam());
        let g = render_rgb(&t, &f)[32 * 64 + 32][0] as f64 / 255.0;
        assert!((g - 0.55).abs() < 0.02, "{g}");
        assert!(img.iter().all(|p| p[0] == p[1] && p[1] == p[2]));
    }
}
