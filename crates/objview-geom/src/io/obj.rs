//! Wavefront OBJ loading (via `tobj`), with optional colours from the .mtl file.
//!
//! Geometry: all objects/groups of the file are merged, polygons fan-triangulated, positions
//! read in f64. Appearance: an `map_Kd` texture that exists and decodes gives
//! [`Appearance::Textured`] (texture colour multiplied by `Kd`, as the MTL format defines);
//! otherwise `Kd` colours give [`Appearance::FaceColors`]. A missing or unreadable .mtl or
//! texture is not an error — it only means the mesh has no colour (the pool's own OBJ files
//! ship without their .mtl, SPEC §1).
//!
//! Referenced files are untrusted: an `mtllib` is read only from inside the OBJ file's folder
//! and a `map_Kd` only from inside the .mtl's (or the OBJ's) folder
//! ([`crate::fsutil::resolve_inside`]: no absolute paths, no `..`, symlinks only to targets
//! inside), as size-capped regular files; each distinct .mtl is read once. A reference that
//! breaks these rules is treated like a missing file.

use super::{decode_texture, fan};
use crate::fsutil::resolve_inside;
use crate::limits::{Limits, Which};
use crate::mesh::{Appearance, Material, Texture};
use crate::{GeomError, Mesh};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::io::{BufReader, Cursor, Read};
use std::path::{Path, PathBuf};

/// Diffuse colour of faces that use no material while other faces do: Blender's default
/// material colour (0.8 grey), the exporter most pool assets come from.
const DEFAULT_DIFFUSE: [f32; 3] = [0.8, 0.8, 0.8];

/// Loads an OBJ file (see the module documentation). The caller validates the result.
pub(super) fn load(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let (file, len) = crate::fsutil::open_limited(path, limits.max_file_bytes, Some(Which::FileBytes))?;
    let mtl_dir: RefCell<Option<PathBuf>> = RefCell::new(None);
    // Canonical paths of the .mtl files read so far: each is read once.
    let mtl_seen: RefCell<HashSet<PathBuf>> = RefCell::new(HashSet::new());
    let options =
        tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let mut reader = BufReader::new(file.take(len));
    let (models, materials) = tobj::load_obj_buf(&mut reader, &options, |mtl: &Path| {
        let unreadable = Err(tobj::LoadError::OpenFileFailed);
        let Some(name) = mtl.to_str() else { return unreadable };
        // A file name, not a URI: '%' is taken literally.
        let Ok(full) = resolve_inside(path, &name.replace('%', "%25")) else { return unreadable };
        if !mtl_seen.borrow_mut().insert(full.clone()) {
            return Ok((Vec::new(), Default::default()));
        }
        let Ok(bytes) = super::read_referenced(&full, limits) else { return unreadable };
        if mtl_dir.borrow().is_none() {
            *mtl_dir.borrow_mut() = full.parent().map(Path::to_path_buf);
        }
        tobj::load_mtl_buf(&mut Cursor::new(bytes))
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

    let appearance = appearance(&materials, mtl_dir.into_inner(), path, &tri_material, &tri_uvs, limits)?;
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

/// Builds the appearance from the per-triangle material ids and UVs; errors only when the
/// decoded textures would exceed [`Limits::max_texture_bytes`].
fn appearance(
    materials: &[tobj::Material],
    mtl_dir: Option<PathBuf>,
    obj_path: &Path,
    tri_material: &[Option<usize>],
    tri_uvs: &[Option<[[f32; 2]; 3]>],
    limits: &Limits,
) -> Result<Appearance, GeomError> {
    let diffuse = |id: Option<usize>| -> Option<[f32; 3]> {
        let d = materials.get(id?)?.diffuse?;
        Some([d[0] as f32, d[1] as f32, d[2] as f32])
    };
    // Decode each distinct texture file once.
    let mut textures: Vec<Texture> = Vec::new();
    let mut texture_bytes = 0u64;
    let mut by_name: HashMap<String, Option<usize>> = HashMap::new();
    let mut by_file: HashMap<PathBuf, Option<usize>> = HashMap::new();
    let mut mat_texture: Vec<Option<usize>> = vec![None; materials.len()];
    // Only materials that some triangle with UVs uses need their texture.
    let mut needs_texture = vec![false; materials.len()];
    for (m, uv) in tri_material.iter().zip(tri_uvs) {
        if let (Some(m), Some(_)) = (m, uv) {
            if let Some(n) = needs_texture.get_mut(*m) {
                *n = true;
            }
        }
    }
    for (i, mat) in materials.iter().enumerate() {
        let Some(name) = mat.diffuse_texture.as_deref().filter(|_| needs_texture[i]) else {
            continue;
        };
        let name = name.trim().replace('\\', "/");
        if name.is_empty() {
            continue;
        }
        if let Some(&t) = by_name.get(&name) {
            mat_texture[i] = t;
            continue;
        }
        // The first candidate that resolves inside its folder, reads and decodes; each file
        // is decoded once.
        let mut tex = None;
        for file in texture_candidates(&name, mtl_dir.as_deref(), obj_path) {
            let t = match by_file.get(&file) {
                Some(&t) => t,
                None => {
                    let decoded = match super::read_referenced(&file, limits) {
                        Ok(bytes) => decode_texture(obj_path, &bytes, &mut texture_bytes, limits)?,
                        Err(_) => None,
                    };
                    let t = decoded.map(|t| {
                        textures.push(t);
                        textures.len() - 1
                    });
                    by_file.insert(file, t);
                    t
                }
            };
            if t.is_some() {
                tex = t;
                break;
            }
        }
        by_name.insert(name, tex);
        mat_texture[i] = tex;
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
        return Ok(Appearance::Textured {
            corner_uvs: corner,
            face_material,
            materials: out_materials,
            textures,
        });
    }
    if tri_material.iter().any(|&m| diffuse(m).is_some()) {
        return Ok(Appearance::FaceColors(
            tri_material.iter().map(|&m| diffuse(m).unwrap_or(DEFAULT_DIFFUSE)).collect(),
        ));
    }
    Ok(Appearance::None)
}

/// Where a `map_Kd` file may be: relative to the .mtl (inside the .mtl's folder), relative
/// to the .obj (inside its folder), or (when the statement carries options such as
/// `-bm 1 tex.png`) its last token; canonical paths of existing files only (see
/// [`resolve_inside`]).
fn texture_candidates(name: &str, mtl_dir: Option<&Path>, obj_path: &Path) -> Vec<PathBuf> {
    let mut names = vec![name.to_string()];
    if let Some(last) = name.split_whitespace().last() {
        if last != name {
            names.push(last.to_string());
        }
    }
    // resolve_inside looks in the folder of its first argument: a stand-in file name there.
    let mtl_anchor = mtl_dir.map(|d| d.join("_.mtl"));
    let mut out = Vec::new();
    for n in &names {
        // A texture name is a path, not a URI: escape '%' so that it is taken literally.
        let reference = n.replace('%', "%25");
        for anchor in mtl_anchor.as_deref().into_iter().chain([obj_path]) {
            if let Ok(p) = resolve_inside(anchor, &reference) {
                out.push(p);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use crate::io::{load_mesh, load_mesh_with};
    use crate::limits::Limits;
    use crate::mesh::Appearance;
    use crate::test_support::within;
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

    #[test]
    fn mtllib_and_map_kd_are_read_only_inside_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for sub in ["asset/mats", "outside"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
        }
        std::fs::write(d.join("outside/evil.mtl"), b"newmtl m\nKd 1 0 0\n").unwrap();
        std::fs::write(d.join("asset/good.mtl"), b"newmtl m\nKd 0 1 0\n").unwrap();
        let geometry = "usemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let load = |mtllib: &str| {
            let p = d.join("asset/m.obj");
            std::fs::write(&p, format!("mtllib {mtllib}\n{geometry}")).unwrap();
            within(10, move || load_mesh(&p).map(|m| m.appearance))
        };
        let green = Appearance::FaceColors(vec![[0.0, 1.0, 0.0]]);
        assert_eq!(load("good.mtl").unwrap(), green);
        let outside = d.join("outside/evil.mtl").display().to_string();
        for bad in ["../outside/evil.mtl", outside.as_str(), "mats/../../outside/evil.mtl"] {
            assert_eq!(load(bad).unwrap(), Appearance::None, "mtllib {bad}");
        }
        #[cfg(unix)]
        {
            use crate::test_support::{mkfifo, symlink};
            symlink(&d.join("outside/evil.mtl"), &d.join("asset/link.mtl"));
            assert_eq!(load("link.mtl").unwrap(), Appearance::None);
            symlink(&d.join("asset/good.mtl"), &d.join("asset/mats/alias.mtl"));
            assert_eq!(load("mats/alias.mtl").unwrap(), green);
            mkfifo(&d.join("asset/fifo.mtl"));
            assert_eq!(load("fifo.mtl").unwrap(), Appearance::None);
        }

        // Textures: map_Kd outside the folder (relative, absolute) is not read; Kd stays.
        let img = image::RgbImage::from_raw(1, 1, vec![0, 0, 255]).unwrap();
        img.save(d.join("outside/tex.png")).unwrap();
        img.save(d.join("asset/tex.png")).unwrap();
        let textured = |map: &str| {
            std::fs::write(d.join("asset/t.mtl"), format!("newmtl m\nKd 1 1 1\nmap_Kd {map}\n")).unwrap();
            let p = d.join("asset/t.obj");
            std::fs::write(
                &p,
                format!("mtllib t.mtl\nvt 0 0\n{}", geometry.replace("f 1 2 3", "f 1/1 2/1 3/1")),
            )
            .unwrap();
            within(10, move || load_mesh(&p).map(|m| matches!(m.appearance, Appearance::Textured { .. })))
        };
        assert!(textured("tex.png").unwrap());
        let outside = d.join("outside/tex.png").display().to_string();
        for bad in ["../outside/tex.png", outside.as_str(), &format!("-bm 1 {outside}")] {
            assert!(!textured(bad).unwrap(), "map_Kd {bad}");
        }
        #[cfg(unix)]
        {
            crate::test_support::mkfifo(&d.join("asset/fifo.png"));
            assert!(!textured("fifo.png").unwrap());
        }
        // A decoded-texture budget below the 1x1 texture's 3 bytes is an error.
        let p = d.join("asset/t.obj");
        std::fs::write(d.join("asset/t.mtl"), b"newmtl m\nKd 1 1 1\nmap_Kd tex.png\n").unwrap();
        let e = load_mesh_with(&p, &Limits { max_texture_bytes: 2, ..Limits::default() })
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.obj") && e.contains("OBJVIEW_MAX_TEXTURE_BYTES"), "{e}");
    }
}
