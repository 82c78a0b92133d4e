//! Mesh loading from the asset formats the benchmark accepts (SPEC §1): OBJ (with or without
//! .mtl), PLY (ascii and binary), STL (ascii and binary), OFF and glTF/GLB.
//!
//! [`load_mesh`] dispatches on the file extension (case-insensitive). Every loader triangulates
//! polygons as fans, keeps the file frame unchanged, and ends with [`Mesh::validate`], so a
//! mesh returned from here has triangles, finite referenced vertices, in-range indices and a
//! non-zero extent. Malformed input is reported as a [`GeomError`] naming the file and the
//! reason; as a last line of defence a panic inside a third-party parser is caught and turned
//! into an error too, so one bad asset never takes a batch down.

mod gltf;
mod obj;
mod off;
pub(crate) mod ply;
mod stl;

use crate::{GeomError, Mesh};
use std::path::Path;

/// Extensions (lower case, without the dot) that [`load_mesh`] accepts.
pub const MESH_EXTENSIONS: &[&str] = &["obj", "ply", "stl", "off", "gltf", "glb"];

/// The list of [`MESH_EXTENSIONS`] as shown in "unsupported format" errors.
const EXPECTED: &str = "obj, ply, stl, off, gltf, glb";

/// Lower-cased extension of `path`, if any.
fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase())
}

/// Whether `path` has one of the [`MESH_EXTENSIONS`] (case-insensitive). Does not look at the
/// file itself.
pub fn is_mesh_file(path: &Path) -> bool {
    extension(path).is_some_and(|e| MESH_EXTENSIONS.contains(&e.as_str()))
}

/// Loads a triangle mesh, choosing the format from the extension (case-insensitive).
///
/// The result is validated ([`Mesh::validate`]); unknown extensions give
/// [`GeomError::Unsupported`].
pub fn load_mesh(path: &Path) -> Result<Mesh, GeomError> {
    let Some(ext) = extension(path).filter(|e| MESH_EXTENSIONS.contains(&e.as_str())) else {
        return Err(GeomError::Unsupported { path: path.to_path_buf(), expected: EXPECTED });
    };
    let mesh = catch_panic(path, || match ext.as_str() {
        "obj" => obj::load(path),
        "ply" => ply::load(path),
        "stl" => stl::load(path),
        "off" => off::load(path),
        _ => self::gltf::load(path),
    })?;
    mesh.validate(path)?;
    Ok(mesh)
}

/// Runs `f`, turning a panic inside it (a bug in a parser fed garbage) into a parse error that
/// names the file.
pub(crate) fn catch_panic<T>(path: &Path, f: impl FnOnce() -> Result<T, GeomError>) -> Result<T, GeomError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(GeomError::parse(path, format!("malformed file (parser failed: {msg})")))
        }
    }
}

/// Reads a whole file into memory, mapping the I/O error to [`GeomError::Io`].
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, GeomError> {
    std::fs::read(path).map_err(|e| GeomError::io(path, e))
}

/// Decodes an encoded image (PNG or JPEG) into a [`crate::mesh::Texture`]; `None` when the
/// bytes are not a decodable image (an unsupported texture only means "no texture").
pub(crate) fn decode_texture(bytes: &[u8]) -> Option<crate::mesh::Texture> {
    let img = image::load_from_memory(bytes).ok()?.to_rgb8();
    let (width, height) = img.dimensions();
    if width == 0 || height == 0 {
        return None;
    }
    let rgb = img.into_raw().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Some(crate::mesh::Texture { width, height, rgb })
}

/// Appends the fan triangulation of polygon `poly` (vertex indices, in order) to `out`:
/// `(p0, p1, p2), (p0, p2, p3), ...`. Polygons with fewer than three corners add nothing.
pub(crate) fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for k in 2..poly.len() {
        out.push([poly[0], poly[k - 1], poly[k]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dispatch_is_case_insensitive_and_rejects_unknown() {
        assert!(is_mesh_file(Path::new("a/b.OBJ")));
        assert!(is_mesh_file(Path::new("x.Glb")));
        assert!(!is_mesh_file(Path::new("x.fbx")));
        assert!(!is_mesh_file(Path::new("noext")));
        let e = load_mesh(Path::new("/nonexistent/m.fbx")).unwrap_err();
        assert!(matches!(e, GeomError::Unsupported { .. }));
        let s = e.to_string();
        assert!(s.contains("m.fbx") && s.contains("obj, ply"), "{s}");
        // Known extension but missing file: an I/O error naming the file, for every format.
        for ext in MESH_EXTENSIONS {
            let p = format!("/nonexistent/dir/m.{}", ext.to_uppercase());
            let e = load_mesh(Path::new(&p)).unwrap_err().to_string();
            assert!(e.contains(&p), "{e}");
        }
    }

    #[test]
    fn fan_triangulation() {
        let mut out = vec![];
        fan(&[4, 5, 6, 7, 8], &mut out);
        assert_eq!(out, vec![[4, 5, 6], [4, 6, 7], [4, 7, 8]]);
        fan(&[1, 2], &mut out);
        assert_eq!(out.len(), 3);
    }

    #[test]
    fn panics_become_errors() {
        let e = catch_panic::<()>(Path::new("p.glb"), || panic!("boom")).unwrap_err().to_string();
        assert!(e.contains("p.glb") && e.contains("boom"), "{e}");
    }
}
