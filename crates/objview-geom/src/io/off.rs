//! Object File Format (OFF, Geomview / ModelNet) loading, hand-written: no maintained crate
//! covers it and the format is a few lines of text.
//!
//! Accepted: an `OFF`, `COFF`, `NOFF` or `CNOFF` keyword (counts may follow on the same line,
//! also glued as in ModelNet's `OFF1234 5678 0`), `#` comments and blank lines anywhere, the
//! counts line `nv nf [ne]`, one vertex per line (`x y z [nx ny nz] [r g b [a]]`) and one
//! polygon per line (`n i1 .. in [r g b [a]]`), fan-triangulated. Colours are integers 0..255
//! or reals 0..1; vertex colours (COFF) win over face colours.

use super::fan;
use crate::limits::{over, Limits, Which};
use crate::mesh::Appearance;
use crate::{GeomError, Mesh};
use std::path::Path;

/// Parses one number token, naming the line on failure.
fn num<T: std::str::FromStr>(path: &Path, tok: &str, line: usize) -> Result<T, GeomError> {
    tok.parse().map_err(|_| GeomError::parse(path, format!("invalid OFF: bad number '{tok}' on line {line}")))
}

/// Raw colour from the first 3 of 3 or 4 tokens; sets `real` when a token is written as a
/// real number (then the file's colours are 0..1, otherwise integers 0..255).
fn color(path: &Path, toks: &[&str], line: usize, real: &mut bool) -> Result<[f32; 3], GeomError> {
    let mut c = [0.0f32; 3];
    for k in 0..3 {
        *real |= toks[k].contains(['.', 'e', 'E']);
        c[k] = num(path, toks[k], line)?;
    }
    Ok(c)
}

/// Scales integer colours to 0..1.
fn scale_colors(c: &mut [[f32; 3]], real: bool) {
    if !real {
        for v in c.iter_mut().flatten() {
            *v /= 255.0;
        }
    }
}

/// Loads an OFF mesh. The caller validates the result.
pub(super) fn load(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let bytes = super::read_input(path, limits)?;
    let text =
        std::str::from_utf8(&bytes).map_err(|_| GeomError::parse(path, "invalid OFF: not a text file"))?;
    // Non-empty lines with comments removed, with their 1-based line numbers.
    let mut lines = text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.split('#').next().unwrap_or("").trim();
        (!l.is_empty()).then_some((i + 1, l))
    });

    let Some((hline, header)) = lines.next() else {
        return Err(GeomError::parse(path, "invalid OFF: empty file"));
    };
    let mut head_toks = header.split_whitespace();
    let keyword = head_toks.next().unwrap_or("");
    let Some(off_pos) = keyword.find("OFF") else {
        return Err(GeomError::parse(
            path,
            format!("invalid OFF: line {hline} should start with OFF/COFF/NOFF/CNOFF"),
        ));
    };
    let prefix = &keyword[..off_pos];
    if !prefix.chars().all(|c| c == 'C' || c == 'N') {
        return Err(GeomError::parse(
            path,
            format!("invalid OFF: unsupported variant '{prefix}OFF' (OFF, COFF, NOFF, CNOFF are)"),
        ));
    }
    let has_color = prefix.contains('C');
    let has_normal = prefix.contains('N');
    // Counts: rest of the header line (possibly glued to the keyword), else the next line.
    let glued = &keyword[off_pos + 3..];
    let mut count_toks: Vec<&str> = Vec::new();
    if !glued.is_empty() {
        count_toks.push(glued);
    }
    count_toks.extend(head_toks);
    let mut count_line = hline;
    if count_toks.is_empty() {
        let Some((l, s)) = lines.next() else {
            return Err(GeomError::parse(path, "invalid OFF: missing vertex/face counts"));
        };
        count_line = l;
        count_toks = s.split_whitespace().collect();
    }
    if count_toks.len() < 2 {
        return Err(GeomError::parse(
            path,
            format!("invalid OFF: line {count_line} should hold the vertex and face counts"),
        ));
    }
    let nv: usize = num(path, count_toks[0], count_line)?;
    let nf: usize = num(path, count_toks[1], count_line)?;
    if nv > u32::MAX as usize {
        return Err(GeomError::invalid(path, format!("{nv} vertices exceed 2^32")));
    }
    if nv as u64 > limits.max_vertices {
        return Err(GeomError::invalid(
            path,
            format!("header declares {nv} vertices, {}", over(Which::Vertices, limits.max_vertices)),
        ));
    }
    // Every vertex and face takes a line of at least one byte: a header claiming more cannot
    // be this file's (and must not make the loader count to 2^64).
    if nv.saturating_add(nf) > bytes.len() {
        return Err(GeomError::parse(
            path,
            format!("invalid OFF: header declares {nv} vertices and {nf} faces, more than a {}-byte file can hold", bytes.len()),
        ));
    }

    // Cap pre-allocation by what the file can hold (a garbage count must not exhaust memory).
    let mut positions = Vec::with_capacity(nv.min(bytes.len() / 6));
    let mut vcolors = Vec::new();
    let mut vreal = false;
    let vtoks = 3 + if has_normal { 3 } else { 0 };
    for k in 0..nv {
        let Some((l, s)) = lines.next() else {
            return Err(GeomError::parse(
                path,
                format!("invalid OFF: header declares {nv} vertices, file ends after {k}"),
            ));
        };
        let t: Vec<&str> = s.split_whitespace().collect();
        if t.len() < vtoks + if has_color { 3 } else { 0 } {
            return Err(GeomError::parse(path, format!("invalid OFF: too few values on line {l}")));
        }
        positions.push([num(path, t[0], l)?, num(path, t[1], l)?, num(path, t[2], l)?]);
        if has_color {
            vcolors.push(color(path, &t[vtoks..], l, &mut vreal)?);
        }
    }

    let mut triangles = Vec::with_capacity(nf.min(bytes.len() / 6));
    let mut fcolors: Vec<[f32; 3]> = Vec::new();
    let mut all_faces_colored = true;
    let mut freal = false;
    let mut poly: Vec<u32> = Vec::new();
    for k in 0..nf {
        let Some((l, s)) = lines.next() else {
            return Err(GeomError::parse(
                path,
                format!("invalid OFF: header declares {nf} faces, file ends after {k}"),
            ));
        };
        let t: Vec<&str> = s.split_whitespace().collect();
        let n: usize = num(path, t[0], l)?;
        if t.len() - 1 < n {
            return Err(GeomError::parse(
                path,
                format!("invalid OFF: face on line {l} declares {n} corners but lists fewer"),
            ));
        }
        poly.clear();
        for tok in &t[1..1 + n] {
            let i: i64 = num(path, tok, l)?;
            let Ok(i) = u32::try_from(i) else {
                return Err(GeomError::invalid(
                    path,
                    format!("face on line {l} has vertex index {i} outside 0..{nv}"),
                ));
            };
            poly.push(i);
        }
        let extra = &t[1 + n..];
        let before = triangles.len();
        fan(&poly, &mut triangles);
        if triangles.len() as u64 > limits.max_triangles {
            let o = over(Which::Triangles, limits.max_triangles);
            return Err(GeomError::invalid(path, format!("too many triangles, {o}")));
        }
        if extra.len() >= 3 {
            let c = color(path, extra, l, &mut freal)?;
            fcolors.extend(std::iter::repeat_n(c, triangles.len() - before));
        } else {
            all_faces_colored = false;
        }
    }

    scale_colors(&mut vcolors, vreal);
    scale_colors(&mut fcolors, freal);
    let appearance = if has_color {
        Appearance::VertexColors(vcolors)
    } else if all_faces_colored && !triangles.is_empty() {
        Appearance::FaceColors(fcolors)
    } else {
        Appearance::None
    };
    Ok(Mesh { positions, triangles, appearance })
}

#[cfg(test)]
mod tests {
    use crate::io::load_mesh;
    use crate::mesh::Appearance;
    use std::path::PathBuf;

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn variants() {
        let dir = tempfile::tempdir().unwrap();
        let plain = "OFF\n# a comment\n4 2 0\n0 0 0\n1 0 0\n1 1 0  # trailing\n\n0 1 1\n4 0 1 2 3\n3 3 2 1\n";
        let m = load_mesh(&write(&dir, "a.off", plain)).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [3, 2, 1]]);
        assert_eq!(m.positions[3], [0.0, 1.0, 1.0]);
        assert_eq!(m.appearance, Appearance::None);
        // ModelNet's glued header.
        let glued = "OFF4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 1\n4 0 1 2 3\n";
        let m = load_mesh(&write(&dir, "b.off", glued)).unwrap();
        assert_eq!(m.triangles.len(), 2);
        // Counts on the header line, integer face colours.
        let fc = "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 255 0 51\n";
        let m = load_mesh(&write(&dir, "c.off", fc)).unwrap();
        assert_eq!(m.appearance, Appearance::FaceColors(vec![[1.0, 0.0, 0.2]]));
        // COFF with real vertex colours and alpha.
        let coff = "COFF\n3 1 0\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n0 1 0 0 0 0.5 1\n3 0 1 2\n";
        let m = load_mesh(&write(&dir, "d.off", coff)).unwrap();
        assert_eq!(
            m.appearance,
            Appearance::VertexColors(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]])
        );
        // NOFF: normals are skipped.
        let noff = "NOFF\n3 1 0\n0 0 0 0 0 1\n2 0 0 0 0 1\n0 2 0 0 0 1\n3 0 1 2\n";
        let m = load_mesh(&write(&dir, "e.off", noff)).unwrap();
        assert!((m.surface_area() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let check = |text: &str, want: &str| {
            let e = load_mesh(&write(&dir, "bad.off", text)).unwrap_err().to_string();
            assert!(e.contains("bad.off") && e.contains(want), "{e}");
        };
        check("OFF\n3 1 0\n0 0 0\n1 0 0\n", "declares 3 vertices, file ends after 2"); // truncated
        check("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n", "declares 1 faces, file ends after 0");
        check("PLY\n3 1 0\n", "should start with OFF"); // wrong magic
        std::fs::write(dir.path().join("bad.off"), [0xffu8, 0x00, 0x81]).unwrap();
        let e = load_mesh(&dir.path().join("bad.off")).unwrap_err().to_string();
        assert!(e.contains("not a text file"), "{e}"); // garbage
        check("OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "non-finite");
        check("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "references vertex 7");
        check("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "vertex index -1");
        check("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no triangles");
        check("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "lists fewer");
        check("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "bad number 'x' on line 4");
    }

    #[test]
    fn huge_counts_are_errors_without_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let check = |text: &str, want: &str| {
            let e = load_mesh(&write(&dir, "huge.off", text)).unwrap_err().to_string();
            assert!(e.contains("huge.off") && e.contains(want), "{e}");
            assert!(!e.contains("parser failed"), "a caught panic: {e}");
        };
        // A face whose corner count is 2^64 - 1 (1 + n overflowed).
        check(
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n18446744073709551615 0 1 2\n",
            "declares 18446744073709551615 corners",
        );
        // Counts far beyond what the file can hold fail at the header.
        check("OFF\n3 18446744073709551615 0\n0 0 0\n1 0 0\n0 1 0\n", "more than a 47-byte file can hold");
        check("OFF\n100000 1 0\n0 0 0\n", "declares 100000 vertices and 1 faces, more than a 21-byte");
    }

    #[test]
    fn vertex_and_triangle_limits_apply() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "q.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 1\n4 0 1 2 3\n");
        let d = crate::Limits::default();
        let at = |l: crate::Limits| crate::io::load_mesh_with(&p, &l).unwrap_err().to_string();
        assert!(
            at(crate::Limits { max_vertices: 3, ..d }).contains("declares 4 vertices, over the limit of 3")
        );
        let e = at(crate::Limits { max_triangles: 1, ..d });
        assert!(e.contains("q.off") && e.contains("OBJVIEW_MAX_TRIANGLES"), "{e}");
        assert_eq!(
            crate::io::load_mesh_with(&p, &crate::Limits { max_vertices: 4, max_triangles: 2, ..d })
                .unwrap()
                .triangles
                .len(),
            2
        );
    }
}
