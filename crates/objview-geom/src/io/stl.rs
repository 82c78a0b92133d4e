//! STL loading (ascii and binary) via `stl_io`.
//!
//! STL stores independent triangles; `stl_io` merges bit-identical corners into shared
//! vertices. STL has no colour. A binary file shorter than its declared triangle count is
//! an error (a truncated download), not a silently smaller mesh.

use crate::{GeomError, Mesh};
use std::io::Cursor;
use std::path::Path;

/// Loads an STL mesh. The caller validates the result.
pub(super) fn load(path: &Path) -> Result<Mesh, GeomError> {
    let bytes = super::read_bytes(path)?;
    let is_ascii = bytes.trim_ascii_start().starts_with(b"solid") && !looks_binary(&bytes);
    if !is_ascii {
        if bytes.len() < 84 {
            return Err(GeomError::parse(
                path,
                format!("invalid STL: {} bytes, shorter than the 84-byte binary header", bytes.len()),
            ));
        }
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        let need = 84 + 50 * n;
        if (bytes.len() as u64) < need {
            return Err(GeomError::parse(
                path,
                format!(
                    "invalid STL: binary header declares {n} triangles ({need} bytes) but the \
                     file has {} bytes (truncated or not an STL file)",
                    bytes.len()
                ),
            ));
        }
    }
    let mut bytes = bytes;
    if !is_ascii && bytes.starts_with(b"solid") {
        // stl_io decides "ascii" from a leading "solid "; the binary header is free text, so
        // blank it to make stl_io read the binary body.
        bytes[..5].copy_from_slice(b"     ");
    }
    let mesh = stl_io::read_stl(&mut Cursor::new(&bytes))
        .map_err(|e| GeomError::parse(path, format!("invalid STL: {e}")))?;
    let positions = mesh.vertices.iter().map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]).collect();
    let mut triangles = Vec::with_capacity(mesh.faces.len());
    for f in &mesh.faces {
        let [a, b, c] = f.vertices;
        let (Ok(a), Ok(b), Ok(c)) = (u32::try_from(a), u32::try_from(b), u32::try_from(c)) else {
            return Err(GeomError::invalid(path, "more than 2^32 vertices"));
        };
        triangles.push([a, b, c]);
    }
    Ok(Mesh::new(positions, triangles))
}

/// A binary STL whose 80-byte header happens to start with "solid": its size matches the
/// declared triangle count exactly and it contains bytes that never occur in ascii STL.
fn looks_binary(bytes: &[u8]) -> bool {
    if bytes.len() < 84 {
        return false;
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    bytes.len() as u64 == 84 + 50 * n && bytes[84..].iter().any(|&b| b == 0 || b > 127)
}

#[cfg(test)]
mod tests {
    use crate::io::load_mesh;
    use std::path::PathBuf;

    fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// Binary STL of the given triangles, with `header` (padded to 80 bytes).
    fn binary(header: &[u8], tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut b = header.to_vec();
        b.resize(80, 0);
        b.extend((tris.len() as u32).to_le_bytes());
        for t in tris {
            b.extend([0u8; 12]); // normal
            for v in t {
                for c in v {
                    b.extend(c.to_le_bytes());
                }
            }
            b.extend([0u8; 2]);
        }
        b
    }

    const TWO: [[[f32; 3]; 3]; 2] = [
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]],
    ];

    #[test]
    fn ascii_and_binary_share_vertices() {
        let dir = tempfile::tempdir().unwrap();
        let ascii = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
            vertex 0 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\n\
            vertex 1 1 0.5\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
        let files = [
            write(&dir, "a.stl", ascii.as_bytes()),
            write(&dir, "b.STL", &binary(b"exported by test", &TWO)),
            // Binary whose free-text header starts with "solid " (common in practice).
            write(&dir, "c.stl", &binary(b"solid but binary", &TWO)),
        ];
        for p in &files {
            let m = load_mesh(p).unwrap();
            assert_eq!(m.positions.len(), 4, "{}", p.display());
            assert_eq!(m.triangles.len(), 2);
            assert_eq!(m.triangle(1), [[1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]]);
            assert!((m.surface_area() - (0.5 + 0.5 * 1.5f64.sqrt())).abs() < 1e-12);
        }
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let check = |bytes: &[u8], want: &str| {
            let p = write(&dir, "bad.stl", bytes);
            let e = load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains("bad.stl") && e.contains(want), "{e}");
        };
        let good = binary(b"x", &TWO);
        check(&good[..good.len() - 10], "truncated"); // truncated binary
        check(b"garbage", "shorter than the 84-byte"); // garbage / wrong magic
        check(b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 zz\n", "invalid STL");
        let mut nan = TWO;
        nan[0][1][0] = f32::NAN;
        check(&binary(b"x", &nan), "non-finite");
        check(&binary(b"x", &[]), "no triangles");
        // STL has no indices, so "out of range" cannot occur; a degenerate file can:
        check(&binary(b"x", &[[[1.0; 3]; 3]]), "zero extent");
    }
}
