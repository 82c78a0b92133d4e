//! Writers for meshes: Wavefront OBJ (with a `.mtl` for per-face colours) and binary
//! little-endian PLY.
//!
//! They exist so that the built-in procedural pool ([`crate::synth`]) and any normalized or
//! generated mesh can be handed to other tools (or to the reference implementation) as plain
//! files. Output is byte-for-byte deterministic: coordinates are printed with Rust's
//! shortest-round-trip `Display` for `f64` (so reading the OBJ back gives the exact same bits),
//! colours are emitted in first-use order, and nothing time- or platform-dependent is written.
//!
//! Appearance support: OBJ writes `FaceColors` as one material per distinct colour (`usemtl`
//! switches only where the colour changes) and `VertexColors` as the common `v x y z r g b`
//! extension; PLY writes vertex colours as `uchar red green blue` on the vertex element and face
//! colours as `uchar red green blue` on the face element. Textured meshes are written with one
//! material per texture material carrying its base colour only (texture images are not
//! exported).

use crate::{Appearance, GeomError, Mesh};
use std::fmt::Write as _;
use std::path::Path;

/// The text of an OBJ file and, when the mesh has per-face materials, its companion MTL file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjText {
    /// Content of the `.obj` file.
    pub obj: String,
    /// Content of the `.mtl` file referenced by `mtllib`, if any.
    pub mtl: Option<String>,
}

/// Name of the `i`-th material written for a mesh.
fn material_name(i: usize) -> String {
    format!("color_{i:03}")
}

/// Per-triangle material index and the list of distinct material colours, in first-use order.
/// `None` when the mesh has no per-face colour information.
fn face_materials(mesh: &Mesh) -> Option<(Vec<usize>, Vec<[f32; 3]>)> {
    match &mesh.appearance {
        Appearance::FaceColors(colors) => {
            let mut palette: Vec<[f32; 3]> = Vec::new();
            let mut index = std::collections::HashMap::new();
            let mut per_face = Vec::with_capacity(mesh.triangles.len());
            for t in 0..mesh.triangles.len() {
                let c = colors.get(t).copied().unwrap_or([0.8; 3]);
                let key = c.map(f32::to_bits);
                let id = *index.entry(key).or_insert_with(|| {
                    palette.push(c);
                    palette.len() - 1
                });
                per_face.push(id);
            }
            Some((per_face, palette))
        }
        Appearance::Textured { face_material, materials, .. } => {
            let palette = materials.iter().map(|m| m.base_color).collect();
            Some((face_material.iter().map(|&m| m as usize).collect(), palette))
        }
        Appearance::None | Appearance::VertexColors(_) => None,
    }
}

/// Renders `mesh` as OBJ text. `mtl_file_name` is the name written after `mtllib` (the MTL
/// file is expected next to the OBJ); it is only used when the mesh has face materials.
pub fn obj_text(mesh: &Mesh, mtl_file_name: &str) -> ObjText {
    let mut obj = String::with_capacity(48 * mesh.positions.len() + 24 * mesh.triangles.len());
    let materials = face_materials(mesh);
    let _ = writeln!(obj, "# objview {}", crate::VERSION);
    let _ = writeln!(obj, "# vertices {} triangles {}", mesh.positions.len(), mesh.triangles.len());
    if materials.is_some() {
        let _ = writeln!(obj, "mtllib {mtl_file_name}");
    }
    let vertex_colors = match &mesh.appearance {
        Appearance::VertexColors(c) if c.len() == mesh.positions.len() => Some(c),
        _ => None,
    };
    for (i, p) in mesh.positions.iter().enumerate() {
        let _ = write!(obj, "v {} {} {}", p[0], p[1], p[2]);
        if let Some(c) = vertex_colors {
            let _ = write!(obj, " {} {} {}", c[i][0], c[i][1], c[i][2]);
        }
        obj.push('\n');
    }
    let mut current = usize::MAX;
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some((per_face, _)) = &materials {
            if per_face[t] != current {
                current = per_face[t];
                let _ = writeln!(obj, "usemtl {}", material_name(current));
            }
        }
        let _ = writeln!(obj, "f {} {} {}", tri[0] + 1, tri[1] + 1, tri[2] + 1);
    }
    let mtl = materials.map(|(_, palette)| {
        let mut mtl = String::new();
        let _ = writeln!(mtl, "# objview {}", crate::VERSION);
        for (i, c) in palette.iter().enumerate() {
            let _ = writeln!(mtl, "\nnewmtl {}", material_name(i));
            let _ = writeln!(mtl, "Ka 0 0 0");
            let _ = writeln!(mtl, "Kd {} {} {}", c[0], c[1], c[2]);
            let _ = writeln!(mtl, "Ks 0 0 0");
            let _ = writeln!(mtl, "illum 1");
        }
        mtl
    });
    ObjText { obj, mtl }
}

/// Writes `mesh` as an OBJ file at `path`. When the mesh has face colours (or textured
/// materials), a `.mtl` file with the same stem is written next to it and referenced with
/// `mtllib`. Existing files are overwritten.
pub fn write_obj(path: &Path, mesh: &Mesh) -> Result<(), GeomError> {
    let mtl_path = path.with_extension("mtl");
    let mtl_name = mtl_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let text = obj_text(mesh, &mtl_name);
    if let Some(mtl) = &text.mtl {
        std::fs::write(&mtl_path, mtl).map_err(|e| GeomError::io(&mtl_path, e))?;
    }
    std::fs::write(path, &text.obj).map_err(|e| GeomError::io(path, e))
}

/// A 0..1 colour channel as a byte (clamped, rounded to nearest).
fn to_byte(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Encodes `mesh` as a binary little-endian PLY: `double x y z` (+ `uchar red green blue` with
/// vertex colours) per vertex, `list uchar int vertex_indices` (+ `uchar red green blue` with
/// face colours) per face.
pub fn ply_bytes(mesh: &Mesh) -> Vec<u8> {
    let vertex_colors = match &mesh.appearance {
        Appearance::VertexColors(c) if c.len() == mesh.positions.len() => Some(c),
        _ => None,
    };
    let face_colors = match &mesh.appearance {
        Appearance::FaceColors(c) if c.len() == mesh.triangles.len() => Some(c),
        _ => None,
    };
    let mut header = String::new();
    header.push_str("ply\nformat binary_little_endian 1.0\n");
    let _ = writeln!(header, "comment objview {}", crate::VERSION);
    let _ = writeln!(header, "element vertex {}", mesh.positions.len());
    header.push_str("property double x\nproperty double y\nproperty double z\n");
    if vertex_colors.is_some() {
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    let _ = writeln!(header, "element face {}", mesh.triangles.len());
    header.push_str("property list uchar int vertex_indices\n");
    if face_colors.is_some() {
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    header.push_str("end_header\n");

    let vsize = 24 + if vertex_colors.is_some() { 3 } else { 0 };
    let fsize = 13 + if face_colors.is_some() { 3 } else { 0 };
    let mut out =
        Vec::with_capacity(header.len() + vsize * mesh.positions.len() + fsize * mesh.triangles.len());
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for x in p {
            out.extend_from_slice(&x.to_le_bytes());
        }
        if let Some(c) = vertex_colors {
            out.extend(c[i].map(to_byte));
        }
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        out.push(3);
        for &i in tri {
            // Indices are u32 in memory; PLY's `int` is signed 32-bit. Meshes with more than
            // 2^31 vertices cannot be represented and do not occur in practice.
            out.extend_from_slice(&(i as i32).to_le_bytes());
        }
        if let Some(c) = face_colors {
            out.extend(c[t].map(to_byte));
        }
    }
    out
}

/// Writes `mesh` as a binary little-endian PLY file at `path` (see [`ply_bytes`]).
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<(), GeomError> {
    std::fs::write(path, ply_bytes(mesh)).map_err(|e| GeomError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit tetrahedron with awkward coordinates (values that need all 17 digits).
    fn tetra() -> Mesh {
        Mesh::new(
            vec![
                [0.1, 0.2, 0.3],
                [1.0 / 3.0, -2.0 / 7.0, 1e-300],
                [-0.7, 0.9, 5.5e10],
                [std::f64::consts::PI, 0.0, -1.0],
            ],
            vec![[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]],
        )
    }

    /// Minimal OBJ reader for the tests: `v` lines (3 or 6 numbers), `f` lines (1-based),
    /// `usemtl` switches. Returns positions, vertex colours, triangles and per-face material.
    #[allow(clippy::type_complexity)]
    fn parse_obj(text: &str) -> (Vec<[f64; 3]>, Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<String>) {
        let (mut v, mut vc, mut f, mut fm) = (vec![], vec![], vec![], vec![]);
        let mut mat = String::new();
        for line in text.lines() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let nums: Vec<&str> = it.collect();
                    v.push([0, 1, 2].map(|k| nums[k].parse::<f64>().unwrap()));
                    if nums.len() == 6 {
                        vc.push([3, 4, 5].map(|k| nums[k].parse::<f32>().unwrap()));
                    }
                }
                Some("f") => {
                    let idx: Vec<u32> = it.map(|s| s.parse::<u32>().unwrap() - 1).collect();
                    assert_eq!(idx.len(), 3);
                    f.push([idx[0], idx[1], idx[2]]);
                    fm.push(mat.clone());
                }
                Some("usemtl") => mat = it.next().unwrap().to_string(),
                _ => {}
            }
        }
        (v, vc, f, fm)
    }

    /// `newmtl` name → `Kd` colour from an MTL text.
    fn parse_mtl(text: &str) -> Vec<(String, [f32; 3])> {
        let mut out: Vec<(String, [f32; 3])> = vec![];
        for line in text.lines() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("newmtl") => out.push((it.next().unwrap().to_string(), [f32::NAN; 3])),
                Some("Kd") => {
                    let c: Vec<f32> = it.map(|s| s.parse().unwrap()).collect();
                    out.last_mut().unwrap().1 = [c[0], c[1], c[2]];
                }
                _ => {}
            }
        }
        out
    }

    #[test]
    fn obj_round_trips_positions_bit_exactly() {
        let m = tetra();
        let text = obj_text(&m, "unused.mtl");
        assert!(text.mtl.is_none());
        assert!(!text.obj.contains("mtllib"));
        let (v, vc, f, _) = parse_obj(&text.obj);
        assert!(vc.is_empty());
        assert_eq!(f, m.triangles);
        assert_eq!(v.len(), 4);
        for (a, b) in v.iter().zip(&m.positions) {
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
        // 1-based indices: the first face of the tetrahedron is literally "f 1 2 3".
        assert!(text.obj.contains("\nf 1 2 3\n"));
    }

    #[test]
    fn obj_face_colors_give_one_material_per_distinct_colour() {
        let mut m = tetra();
        let red = [1.0, 0.0, 0.0];
        let blue = [0.1, 0.2, 0.9];
        m.appearance = Appearance::FaceColors(vec![red, red, blue, red]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.obj");
        write_obj(&path, &m).unwrap();
        let obj = std::fs::read_to_string(&path).unwrap();
        let mtl = std::fs::read_to_string(dir.path().join("t.mtl")).unwrap();
        assert!(obj.contains("mtllib t.mtl\n"));
        let mats = parse_mtl(&mtl);
        assert_eq!(mats.len(), 2, "{mtl}");
        assert_eq!(mats[0], ("color_000".to_string(), red));
        assert_eq!(mats[1], ("color_001".to_string(), blue));
        let (_, _, f, fm) = parse_obj(&obj);
        assert_eq!(f, m.triangles);
        assert_eq!(fm, ["color_000", "color_000", "color_001", "color_000"]);
        // `usemtl` only where the colour changes: 3 switches for 4 faces.
        assert_eq!(obj.matches("usemtl").count(), 3);
        // Rewriting gives identical bytes.
        write_obj(&path, &m).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), obj);
    }

    #[test]
    fn obj_vertex_colors_use_the_six_number_extension() {
        let mut m = tetra();
        let cols = vec![[0.0, 0.25, 0.5], [1.0, 1.0, 1.0], [0.3, 0.6, 0.9], [0.125, 0.0, 1.0]];
        m.appearance = Appearance::VertexColors(cols.clone());
        let text = obj_text(&m, "x.mtl");
        let (v, vc, _, _) = parse_obj(&text.obj);
        assert_eq!(v, m.positions);
        assert_eq!(vc, cols);
    }

    /// Reads a binary PLY written by [`ply_bytes`] back by hand: header lines, then the
    /// fixed-size records the header announces.
    #[test]
    fn ply_header_and_layout() {
        let mut m = tetra();
        m.appearance =
            Appearance::FaceColors(vec![[1.0, 0.0, 0.0], [0.0, 0.5, 1.0], [0.2, 0.2, 0.2], [2.0, -1.0, 1.0]]);
        let bytes = ply_bytes(&m);
        let end = b"end_header\n";
        let hlen = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..hlen]).unwrap();
        let lines: Vec<&str> = header.lines().filter(|l| !l.starts_with("comment")).collect();
        assert_eq!(
            lines,
            [
                "ply",
                "format binary_little_endian 1.0",
                "element vertex 4",
                "property double x",
                "property double y",
                "property double z",
                "element face 4",
                "property list uchar int vertex_indices",
                "property uchar red",
                "property uchar green",
                "property uchar blue",
                "end_header",
            ]
        );
        let body = &bytes[hlen..];
        assert_eq!(body.len(), 4 * 24 + 4 * (1 + 12 + 3));
        for (i, p) in m.positions.iter().enumerate() {
            for (k, pk) in p.iter().enumerate() {
                let o = i * 24 + k * 8;
                let x = f64::from_le_bytes(body[o..o + 8].try_into().unwrap());
                assert_eq!(x.to_bits(), pk.to_bits());
            }
        }
        let faces = &body[4 * 24..];
        let expected_rgb = [[255, 0, 0], [0, 128, 255], [51, 51, 51], [255, 0, 255]];
        for (t, tri) in m.triangles.iter().enumerate() {
            let r = &faces[t * 16..(t + 1) * 16];
            assert_eq!(r[0], 3);
            for k in 0..3 {
                let i = i32::from_le_bytes(r[1 + 4 * k..5 + 4 * k].try_into().unwrap());
                assert_eq!(i as u32, tri[k]);
            }
            assert_eq!(&r[13..16], &expected_rgb[t]);
        }
    }

    #[test]
    fn ply_vertex_colors_and_file_write() {
        let mut m = tetra();
        m.appearance = Appearance::VertexColors(vec![[0.0; 3], [1.0; 3], [0.5, 0.0, 0.0], [0.0, 0.0, 0.996]]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        write_ply(&path, &m).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes, ply_bytes(&m));
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("property double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"));
        let hlen = text.find("end_header\n").unwrap() + "end_header\n".len();
        let body = &bytes[hlen..];
        assert_eq!(body.len(), 4 * 27 + 4 * 13);
        // Vertex 2's colour bytes follow its 24 coordinate bytes: 0.5 → 128 (rounded).
        assert_eq!(&body[2 * 27 + 24..3 * 27], &[128, 0, 0]);
        assert_eq!(&body[3 * 27 + 24..4 * 27], &[0, 0, 254]);
    }

    #[test]
    fn write_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing-dir").join("t.ply");
        let e = write_ply(&path, &tetra()).unwrap_err().to_string();
        assert!(e.contains("missing-dir"), "{e}");
    }
}
