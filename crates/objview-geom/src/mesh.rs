//! The triangle mesh every objview component works on: f64 vertex positions in the object
//! frame, u32 triangle indices, and an optional appearance used only for RGB rendering.
//! Geometry is never re-oriented (SPEC §1): the file frame is the object's pose on the table.

use crate::{vec3, GeomError};
use std::path::Path;

/// A texture image, row-major RGB, row 0 at the top (v = 1 in glTF/OBJ conventions is handled
/// by the loader, which stores UVs so that `(u, v)` maps to pixel `(u·w, v·h)` from the top-left).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Width of the image, pixels.
    pub width: u32,
    /// Height of the image, pixels.
    pub height: u32,
    /// `width × height` texels, row-major from the top-left, 8-bit RGB (used as is, scaled to 0..1).
    pub rgb: Vec<[u8; 3]>,
}

/// Per-triangle material of a textured mesh: a base colour (linear 0..1) and optional texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Base colour, linear RGB in 0..1; multiplies the texel colour when there is a texture.
    pub base_color: [f32; 3],
    /// Index into the mesh's `textures`, or `None` for a plain base colour.
    pub texture: Option<usize>,
}

/// How a mesh is coloured. Only RGB rendering looks at it; depth never does.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Appearance {
    /// No colour information: RGB rendering falls back to shading.
    #[default]
    None,
    /// One RGB colour (0..1) per vertex, interpolated barycentrically.
    VertexColors(Vec<[f32; 3]>),
    /// One RGB colour (0..1) per triangle.
    FaceColors(Vec<[f32; 3]>),
    /// Texture-mapped: per-triangle corner UVs and material index.
    Textured {
        /// Per triangle, the `(u, v)` texture coordinates of its three corners (repeat-wrapped;
        /// `(0, 0)` is the top-left of the image).
        corner_uvs: Vec<[[f32; 2]; 3]>,
        /// Per triangle, its index into `materials`.
        face_material: Vec<u32>,
        /// The mesh's materials.
        materials: Vec<Material>,
        /// The decoded texture images that `Material::texture` indexes.
        textures: Vec<Texture>,
    },
}

/// A triangle mesh in its object frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions (object frame).
    pub positions: Vec<[f64; 3]>,
    /// Triangles as indices into `positions`. No winding convention is assumed (no culling).
    pub triangles: Vec<[u32; 3]>,
    /// Optional colours for RGB rendering.
    pub appearance: Appearance,
}

impl Mesh {
    /// A mesh without appearance.
    pub fn new(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { positions, triangles, appearance: Appearance::None }
    }

    /// Number of triangles.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// The three corners of triangle `t`.
    #[inline]
    pub fn triangle(&self, t: usize) -> [[f64; 3]; 3] {
        let [a, b, c] = self.triangles[t];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Axis-aligned bounds of the vertices referenced by triangles: `(min, max)`.
    /// `None` for a mesh without triangles.
    pub fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for tri in &self.triangles {
            for &i in tri {
                let p = self.positions[i as usize];
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        if self.triangles.is_empty() {
            None
        } else {
            Some((lo, hi))
        }
    }

    /// Largest distance of a referenced vertex from the origin.
    pub fn max_radius(&self) -> f64 {
        let mut r2: f64 = 0.0;
        for tri in &self.triangles {
            for &i in tri {
                let p = self.positions[i as usize];
                r2 = r2.max(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            }
        }
        r2.sqrt()
    }

    /// Area of triangle `t`.
    pub fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangle(t);
        0.5 * vec3::norm(vec3::cross(vec3::sub(b, a), vec3::sub(c, a)))
    }

    /// Total surface area.
    pub fn surface_area(&self) -> f64 {
        (0..self.triangles.len()).map(|t| self.triangle_area(t)).sum()
    }

    /// Checks the structural invariants every consumer relies on; `path` names the source in
    /// the error. Fails on: no triangles, an index out of range, a non-finite position of a
    /// referenced vertex, zero extent (all referenced vertices coincide).
    pub fn validate(&self, path: &Path) -> Result<(), GeomError> {
        if self.triangles.is_empty() {
            return Err(GeomError::invalid(path, "mesh has no triangles"));
        }
        let n = self.positions.len();
        for (t, tri) in self.triangles.iter().enumerate() {
            for &i in tri {
                if i as usize >= n {
                    return Err(GeomError::invalid(
                        path,
                        format!("triangle {t} references vertex {i}, but there are only {n} vertices"),
                    ));
                }
                let p = self.positions[i as usize];
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(GeomError::invalid(
                        path,
                        format!("vertex {i} has a non-finite coordinate {p:?}"),
                    ));
                }
            }
        }
        let (lo, hi) = self.bounds().expect("non-empty");
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        if extent <= 0.0 {
            return Err(GeomError::invalid(path, "mesh has zero extent (all vertices coincide)"));
        }
        Ok(())
    }

    /// Colour (0..1 RGB) of triangle `t` at barycentric weights `b` (for corners 0, 1, 2), or
    /// `None` when the mesh has no appearance.
    pub fn color_at(&self, t: usize, b: [f32; 3]) -> Option<[f32; 3]> {
        match &self.appearance {
            Appearance::None => None,
            Appearance::FaceColors(c) => c.get(t).copied(),
            Appearance::VertexColors(c) => {
                let [i, j, k] = self.triangles[t];
                let (ci, cj, ck) = (c[i as usize], c[j as usize], c[k as usize]);
                Some(std::array::from_fn(|q| b[0] * ci[q] + b[1] * cj[q] + b[2] * ck[q]))
            }
            Appearance::Textured { corner_uvs, face_material, materials, textures } => {
                let m = &materials[face_material[t] as usize];
                let Some(tex) = m.texture.and_then(|ti| textures.get(ti)) else {
                    return Some(m.base_color);
                };
                let uv = corner_uvs[t];
                let u = b[0] * uv[0][0] + b[1] * uv[1][0] + b[2] * uv[2][0];
                let v = b[0] * uv[0][1] + b[1] * uv[1][1] + b[2] * uv[2][1];
                // Repeat wrapping, nearest texel.
                let x = ((u - u.floor()) * tex.width as f32) as u32;
                let y = ((v - v.floor()) * tex.height as f32) as u32;
                let px = tex.rgb[(y.min(tex.height - 1) * tex.width + x.min(tex.width - 1)) as usize];
                Some(std::array::from_fn(|q| m.base_color[q] * px[q] as f32 / 255.0))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Mesh {
        Mesh::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]])
    }

    #[test]
    fn area_bounds_radius() {
        let m = tri();
        assert!((m.surface_area() - 0.5).abs() < 1e-15);
        assert_eq!(m.bounds(), Some(([0.0; 3], [1.0, 1.0, 0.0])));
        assert!((m.max_radius() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn validate_reports_each_defect() {
        let p = Path::new("x.obj");
        assert!(tri().validate(p).is_ok());
        let e = Mesh::new(vec![], vec![]).validate(p).unwrap_err().to_string();
        assert!(e.contains("x.obj") && e.contains("no triangles"), "{e}");
        let mut m = tri();
        m.triangles[0][2] = 7;
        assert!(m.validate(p).unwrap_err().to_string().contains("references vertex 7"));
        let mut m = tri();
        m.positions[1][0] = f64::NAN;
        assert!(m.validate(p).unwrap_err().to_string().contains("non-finite"));
        let m = Mesh::new(vec![[1.0; 3]; 3], vec![[0, 1, 2]]);
        assert!(m.validate(p).unwrap_err().to_string().contains("zero extent"));
    }

    #[test]
    fn vertex_colors_interpolate() {
        let mut m = tri();
        m.appearance = Appearance::VertexColors(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let c = m.color_at(0, [0.5, 0.25, 0.25]).unwrap();
        assert_eq!(c, [0.5, 0.25, 0.25]);
    }
}
