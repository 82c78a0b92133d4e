//! STL loading (ascii and binary) via `stl_io`.
//!
//! STL stores independent triangles; `stl_io` merges bit-identical corners into shared
//! vertices. STL has no colour. A binary file shorter than its declared triangle count is
//! an error (a truncated download), not a silently smaller mesh.
//!
//! ASCII files are recognised by a first line starting with `solid` (after any leading
//! whitespace), also a bare `solid` without a name and with CRLF line ends; `stl_io` insists on
//! `solid ` with a space at the very start, so the first line is normalised to that before the
//! bytes are handed over.

use crate::limits::{over, Limits, Which};
use crate::{GeomError, Mesh};
use std::io::Cursor;
use std::path::Path;

/// Loads an STL mesh. The caller validates the result.
pub(super) fn load(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let bytes = super::read_input(path, limits)?;
    let is_ascii = bytes.trim_ascii_start().starts_with(b"solid") && !looks_binary(&bytes);
    if !is_ascii {
        if bytes.len() < 84 {
            return Err(GeomError::parse(
                path,
                format!("invalid STL: {} bytes, shorter than the 84-byte binary header", bytes.len()),
            ));
        }
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        if n > limits.max_triangles {
            let o = over(Which::Triangles, limits.max_triangles);
            return Err(GeomError::invalid(path, format!("binary header declares {n} triangles, {o}")));
        }
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
    let mut bytes = if is_ascii { normalize_ascii(bytes) } else { bytes };
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

/// An ascii STL with its first line (`solid`, `solid name`, possibly indented or ending in
/// CRLF) replaced by the `solid \n` that `stl_io` requires; the rest is unchanged (`stl_io`
/// splits lines on LF and CRLF and tokens on any whitespace).
fn normalize_ascii(mut bytes: Vec<u8>) -> Vec<u8> {
    let lead = bytes.len() - bytes.trim_ascii_start().len();
    let body = bytes[lead..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| lead + i + 1);
    bytes.splice(..body, *b"solid \n");
    bytes
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

    #[test]
    fn ascii_with_bare_solid_indentation_or_crlf_loads() {
        let dir = tempfile::tempdir().unwrap();
        let body = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n\
            endfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0.5\nvertex 0 1 0\n\
            endloop\nendfacet\nendsolid\n";
        let crlf = |s: &str| s.replace('\n', "\r\n");
        for (name, text) in [
            ("bare", format!("solid\n{body}")),
            ("bare-crlf", crlf(&format!("solid\n{body}"))),
            ("named-crlf", crlf(&format!("solid part\n{body}"))),
            ("indented", format!("  \tsolid part\n{body}")),
            ("blank-line-first", format!("\n\nsolid\n{body}")),
            (
                "indented-body",
                format!("solid x\n{}", body.lines().map(|l| format!("   {l}\n")).collect::<String>()),
            ),
        ] {
            let p = write(&dir, &format!("{name}.stl"), text.as_bytes());
            let m = load_mesh(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(m.triangles.len(), 2, "{name}");
            assert_eq!(m.triangle(1), [[1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]], "{name}");
        }
    }

    #[test]
    fn binary_triangle_count_is_checked_against_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "b.stl", &binary(b"x", &TWO));
        let l = crate::Limits { max_triangles: 1, ..Default::default() };
        let e = crate::io::load_mesh_with(&p, &l).unwrap_err().to_string();
        assert!(e.contains("b.stl") && e.contains("declares 2 triangles, over the limit of 1"), "{e}");
    }
}
