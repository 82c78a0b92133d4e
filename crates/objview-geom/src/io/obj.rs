//! Wavefront OBJ loading (via `tobj`), with optional colours from the .mtl file.
//!
//! Geometry: all objects/groups of the file are merged, polygons fan-triangulated, positions
//! read in f64. Appearance: an `map_Kd` texture that exists and decodes gives
//! [`Appearance::Textured`] (texture colour multiplied by `Kd`, as the MTL format defines);
//! otherwise `Kd` colours give [`Appearance::FaceColors`]. A missing or unreadable .mtl or
//! texture is not an error — it only means the mesh has no colour (the pool's own OBJ files
//! ship without their .mtl, SPEC §1).

use super::{decode_texture, fan};
use crate::mesh::{Appearance, Material, Texture};
use crate::{GeomError, Mesh};
use std::cell::RefCell;
use std::collections::HashMap;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Diffuse colour of faces that use no material while other faces do: Blender's default
/// material colour (0.8 grey), the exporter most pool assets come from.
const DEFAULT_DIFFUSE: [f32; 3] = [0.8, 0.8, 0.8];

/// Loads an OBJ file (see the module documentation). The caller validates the result.
pub(super) fn load(path: &Path) -> Result<Mesh, GeomError> {
    let file = std::fs::File::open(path).map_err(|e| GeomError::io(path, e))?;
    let obj_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mtl_dir: RefCell<Option<PathBuf>> = RefCell::new(None);
    let options =
        tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let (models, materials) = tobj::load_obj_buf(&mut BufReader::new(file), &options, |mtl: &Path| {
        let full = obj_dir.join(mtl);
        if mtl_dir.borrow().is_none() {
            *mtl_dir.borrow_mut() = full.parent().map(Path::to_path_buf);
        }
        tobj::load_mtl(&full)
    })
    .map_err(|e| GeomError::parse(path, format!("invalid OBJ: {e}")))?;
    // A missing or malformed .mtl only means "no colour".
    let materials = materials.unwrap_or_default();

    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    // Per triangle: material id and corner UVs (None where the model has no UVs).
    let mut tri_material: Vec<Option<usize>> = Vec::new();
    let mut tri_uvs: Vec<Option<[[f32; 2]; 3]>> = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let base = positions.len();
        if base + m.positions.len() / 3 > u32::MAX as usize {
            return Err(GeomError::invalid(path, "more than 2^32 vertices"));
        }
        positions.extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        let has_uv = !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len();
        // With `triangulate: true` tobj fan-triangulates and leaves `face_arities` empty; the
        // general branch (polygons with arities) is kept so the loader never depends on it.
        if m.face_arities.is_empty() {
            for (k, t) in m.indices.chunks_exact(3).enumerate() {
                triangles.push([t[0] + base as u32, t[1] + base as u32, t[2] + base as u32]);
                tri_material.push(m.material_id);
                tri_uvs.push(if has_uv { corner_uvs(m, 3 * k) } else { None });
            }
        } else {
            let mut start = 0usize;
            let mut poly = Vec::new();
            for &arity in &m.face_arities {
                let end = start + arity as usize;
                let Some(ids) = m.indices.get(start..end) else {
                    return Err(GeomError::parse(path, "inconsistent face arities"));
                };
                poly.clear();
                poly.extend(ids.iter().map(|&i| i + base as u32));
                let before = triangles.len();
                fan(&poly, &mut triangles);
                for _ in before..triangles.len() {
                    tri_material.push(m.material_id);
                    tri_uvs.push(None);
                }
                start = end;
            }
        }
    }

    let appearance = appearance(&materials, mtl_dir.into_inner(), path, &tri_material, &tri_uvs);
    Ok(Mesh { positions, triangles, appearance })
}

/// Corner UVs of the triangle whose first corner is at `first` in `m.indices`, with v flipped
/// so that (0, 0) is the top-left of the image (the [`Texture`] convention).
fn corner_uvs(m: &tobj::Mesh, first: usize) -> Option<[[f32; 2]; 3]> {
    let mut out = [[0.0f32; 2]; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let ti = *m.texcoord_indices.get(first + c)? as usize;
        let u = *m.texcoords.get(2 * ti)?;
        let v = *m.texcoords.get(2 * ti + 1)?;
        *o = [u as f32, (1.0 - v) as f32];
    }
    Some(out)
}

/// Builds the appearance from the per-triangle material ids and UVs.
fn appearance(
    materials: &[tobj::Material],
    mtl_dir: Option<PathBuf>,
    obj_path: &Path,
    tri_material: &[Option<usize>],
    tri_uvs: &[Option<[[f32; 2]; 3]>],
) -> Appearance {
    let diffuse = |id: Option<usize>| -> Option<[f32; 3]> {
        let d = materials.get(id?)?.diffuse?;
        Some([d[0] as f32, d[1] as f32, d[2] as f32])
    };
    // Decode each distinct texture file once.
    let obj_dir = obj_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut textures: Vec<Texture> = Vec::new();
    let mut by_file: HashMap<String, Option<usize>> = HashMap::new();
    let mut mat_texture: Vec<Option<usize>> = vec![None; materials.len()];
    for (i, mat) in materials.iter().enumerate() {
        let Some(name) = mat.diffuse_texture.as_deref() else {
            continue;
        };
        let name = name.trim().replace('\\', "/");
        if name.is_empty() {
            continue;
        }
        let entry = by_file.entry(name.clone()).or_insert_with(|| {
            let tex = texture_candidates(&name, mtl_dir.as_deref(), &obj_dir)
                .into_iter()
                .find_map(|p| std::fs::read(p).ok().and_then(|b| decode_texture(&b)))?;
            textures.push(tex);
            Some(textures.len() - 1)
        });
        mat_texture[i] = *entry;
    }

    let any_used_texture = tri_material
        .iter()
        .zip(tri_uvs)
        .any(|(m, uv)| uv.is_some() && m.and_then(|m| mat_texture.get(m).copied().flatten()).is_some());
    if any_used_texture {
        // Material table: (source material or none, textured?) -> index.
        let mut out_materials: Vec<Material> = Vec::new();
        let mut index: HashMap<(Option<usize>, bool), u32> = HashMap::new();
        let mut face_material = Vec::with_capacity(tri_material.len());
        let mut corner = Vec::with_capacity(tri_material.len());
        for (&m, uv) in tri_material.iter().zip(tri_uvs) {
            let tex = m.and_then(|m| mat_texture.get(m).copied().flatten()).filter(|_| uv.is_some());
            let key = (m.filter(|&m| m < materials.len()), tex.is_some());
            let id = *index.entry(key).or_insert_with(|| {
                out_materials.push(Material {
                    base_color: diffuse(key.0).unwrap_or(if tex.is_some() {
                        [1.0; 3]
                    } else {
                        DEFAULT_DIFFUSE
                    }),
                    texture: tex,
                });
                (out_materials.len() - 1) as u32
            });
            face_material.push(id);
            corner.push(uv.unwrap_or([[0.0; 2]; 3]));
        }
        return Appearance::Textured {
            corner_uvs: corner,
            face_material,
            materials: out_materials,
            textures,
        };
    }
    if tri_material.iter().any(|&m| diffuse(m).is_some()) {
        return Appearance::FaceColors(
            tri_material.iter().map(|&m| diffuse(m).unwrap_or(DEFAULT_DIFFUSE)).collect(),
        );
    }
    Appearance::None
}

/// Where a `map_Kd` file may be: relative to the .mtl, relative to the .obj, or (when the
/// statement carries options such as `-bm 1 tex.png`) its last token.
fn texture_candidates(name: &str, mtl_dir: Option<&Path>, obj_dir: &Path) -> Vec<PathBuf> {
    let mut names = vec![name.to_string()];
    if let Some(last) = name.split_whitespace().last() {
        if last != name {
            names.push(last.to_string());
        }
    }
    let mut out = Vec::new();
    for n in &names {
        let p = Path::new(n);
        if p.is_absolute() {
            out.push(p.to_path_buf());
            continue;
        }
        if let Some(d) = mtl_dir {
            out.push(d.join(p));
        }
        out.push(obj_dir.join(p));
    }
    out
}

#[cfg(test)]
mod tests {
    use crate::io::load_mesh;
    use crate::mesh::Appearance;
    use std::path::PathBuf;

    fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn err(dir: &tempfile::TempDir, text: &[u8]) -> String {
        let p = write(dir, "bad.obj", text);
        let e = load_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("bad.obj"), "{e}");
        e
    }

    #[test]
    fn quad_fan_exact_f64_and_kd_colours() {
        let dir = tempfile::tempdir().unwrap();
        write(&dir, "m.mtl", b"newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 0.5\n");
        let obj = b"mtllib m.mtl\nv 0.123456789012345 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n\
            usemtl red\nf 1 2 3 4\nusemtl blue\nf 1 2 5\n";
        let m = load_mesh(&write(&dir, "m.obj", obj)).unwrap();
        assert_eq!(m.positions[0][0], 0.123456789012345); // f64, not f32
        assert_eq!(m.triangles.len(), 3);
        let tri_pos: Vec<[[f64; 3]; 3]> = (0..3).map(|t| m.triangle(t)).collect();
        // Fan of the quad: (1,2,3), (1,3,4).
        assert_eq!(tri_pos[0][2], [1.0, 1.0, 0.0]);
        assert_eq!(tri_pos[1][1], [1.0, 1.0, 0.0]);
        assert_eq!(tri_pos[1][2], [0.0, 1.0, 0.0]);
        assert_eq!(tri_pos[2][2], [0.0, 0.0, 1.0]);
        assert_eq!(
            m.appearance,
            Appearance::FaceColors(vec![[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.5]])
        );
    }

    #[test]
    fn missing_mtl_means_no_colour() {
        let dir = tempfile::tempdir().unwrap();
        let obj = b"mtllib gone.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let m = load_mesh(&write(&dir, "m.obj", obj)).unwrap();
        assert_eq!(m.appearance, Appearance::None);
        assert_eq!(m.triangles.len(), 1);
    }

    #[test]
    fn map_kd_texture_with_flipped_v() {
        let dir = tempfile::tempdir().unwrap();
        // 2x2 image: top-left red, top-right green, bottom-left blue, bottom-right white.
        let img =
            image::RgbImage::from_raw(2, 2, vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255]).unwrap();
        img.save(dir.path().join("tex.png")).unwrap();
        write(&dir, "m.mtl", b"newmtl t\nKd 1 1 1\nmap_Kd tex.png\n");
        // vt (0.1, 0.9) is near the top-left in OBJ convention (v up) -> red.
        let obj = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.1 0.9\nvt 0.9 0.9\nvt 0.1 0.1\n\
            usemtl t\nf 1/1 2/2 3/3\n";
        let m = load_mesh(&write(&dir, "m.obj", obj)).unwrap();
        let Appearance::Textured { textures, .. } = &m.appearance else { panic!("{:?}", m.appearance) };
        assert_eq!(textures.len(), 1);
        assert_eq!(m.color_at(0, [1.0, 0.0, 0.0]), Some([1.0, 0.0, 0.0]));
        assert_eq!(m.color_at(0, [0.0, 1.0, 0.0]), Some([0.0, 1.0, 0.0]));
        assert_eq!(m.color_at(0, [0.0, 0.0, 1.0]), Some([0.0, 0.0, 1.0]));
        // Texture file missing: falls back to Kd face colours.
        std::fs::remove_file(dir.path().join("tex.png")).unwrap();
        let m = load_mesh(&dir.path().join("m.obj")).unwrap();
        assert_eq!(m.appearance, Appearance::FaceColors(vec![[1.0, 1.0, 1.0]]));
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        // Truncated: the file ends before its faces.
        let e = err(&dir, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n");
        assert!(e.contains("no triangles"), "{e}");
        // Truncated in the middle of a face line.
        let e = err(&dir, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2");
        assert!(e.contains("no triangles"), "{e}");
        // Garbage (binary, not UTF-8).
        let e = err(&dir, &[0xff, 0xfe, 0x00, 0x93, 0x12, 0x80, 0x0a, 0xc3]);
        assert!(e.contains("invalid OBJ") || e.contains("no triangles"), "{e}");
        // NaN coordinate.
        let e = err(&dir, b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
        assert!(e.contains("non-finite"), "{e}");
        // Out-of-range index.
        let e = err(&dir, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        assert!(e.contains("out of bounds") || e.contains("references vertex"), "{e}");
        // No faces, only a line element.
        let e = err(&dir, b"v 0 0 0\nv 1 0 0\nl 1 2\n");
        assert!(e.contains("no triangles"), "{e}");
    }
}
