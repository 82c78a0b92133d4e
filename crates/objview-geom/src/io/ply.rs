//! PLY loading (ascii, binary little- and big-endian) via `ply-rs-bw`, for meshes and for
//! ground-truth point clouds (vertex element only).
//!
//! Read: the `vertex` element's `x`/`y`/`z` (any numeric type, usually float or double),
//! optional `red`/`green`/`blue` vertex colours (integers scaled to 0..1, floats kept), and
//! the `face` element's `vertex_indices` (or `vertex_index`) lists, fan-triangulated. Other
//! elements and properties are parsed and ignored.
//!
//! Before `ply-rs` sees the file, the header is checked here: every number in `format` and
//! `element` lines must fit in 64 bits (`ply-rs` unwraps the parse), and every element count
//! must fit in the data that follows the header (at least one byte per ascii value, the fixed
//! part of each binary record), and within the vertex/face [`Limits`], so that a 1 KB file
//! claiming 2^40 vertices fails at once instead of allocating or counting.

use super::fan;
use crate::limits::{over, Limits, Which};
use crate::mesh::Appearance;
use crate::{GeomError, Mesh};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{ElementDef, Header, Property, PropertyAccess, PropertyType};
use std::io::{BufRead, BufReader, Cursor, Read};
use std::path::Path;

/// One `vertex` element record.
#[derive(Default)]
struct Vertex {
    p: [f64; 3],
    rgb: [f32; 3],
}

/// Numeric value of a scalar property and the scale that maps its type to 0..1 for colours.
fn scalar(p: &Property) -> Option<(f64, f64)> {
    Some(match *p {
        Property::Char(v) => (v as f64, 127.0),
        Property::UChar(v) => (v as f64, 255.0),
        Property::Short(v) => (v as f64, 32767.0),
        Property::UShort(v) => (v as f64, 65535.0),
        Property::Int(v) => (v as f64, i32::MAX as f64),
        Property::UInt(v) => (v as f64, u32::MAX as f64),
        Property::Float(v) => (v as f64, 1.0),
        Property::Double(v) => (v, 1.0),
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex::default()
    }
    fn set_property(&mut self, name: String, property: Property) {
        let Some((v, scale)) = scalar(&property) else {
            return;
        };
        match name.as_str() {
            "x" => self.p[0] = v,
            "y" => self.p[1] = v,
            "z" => self.p[2] = v,
            "red" | "r" | "diffuse_red" => self.rgb[0] = (v / scale) as f32,
            "green" | "g" | "diffuse_green" => self.rgb[1] = (v / scale) as f32,
            "blue" | "b" | "diffuse_blue" => self.rgb[2] = (v / scale) as f32,
            _ => {}
        }
    }
}

/// One `face` element record: its vertex index list (`None` if an index is negative).
#[derive(Default)]
struct Face {
    indices: Option<Vec<u32>>,
}

/// Converts a signed index list, rejecting negative entries.
fn unsigned<T: Copy + TryInto<u32>>(v: &[T]) -> Option<Vec<u32>> {
    v.iter().map(|&i| i.try_into().ok()).collect()
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face { indices: Some(Vec::new()) }
    }
    fn set_property(&mut self, name: String, property: Property) {
        if name != "vertex_indices" && name != "vertex_index" {
            return;
        }
        self.indices = match property {
            Property::ListUInt(v) => Some(v),
            Property::ListInt(v) => unsigned(&v),
            Property::ListUShort(v) => unsigned(&v),
            Property::ListShort(v) => unsigned(&v),
            Property::ListUChar(v) => unsigned(&v),
            Property::ListChar(v) => unsigned(&v),
            _ => None,
        };
    }
}

/// An element whose content is not needed.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

/// What [`read`] found in a PLY file.
pub(crate) struct PlyData {
    pub positions: Vec<[f64; 3]>,
    /// Vertex colours when the vertex element has red, green and blue.
    pub colors: Option<Vec<[f32; 3]>>,
    /// Face index lists (empty when faces were not requested or there are none).
    pub faces: Vec<Vec<u32>>,
}

fn has_property(e: &ElementDef, names: &[&str]) -> bool {
    names.iter().any(|n| e.properties.contains_key(*n))
}

/// Size in bytes of a PLY scalar type name, `None` if it is not one.
fn scalar_size(name: &str) -> Option<u64> {
    Some(match name {
        "char" | "int8" | "uchar" | "uint8" => 1,
        "short" | "int16" | "ushort" | "uint16" => 2,
        "int" | "int32" | "uint" | "uint32" | "float" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

/// Reads the header lines (up to and including `end_header`, or to the end of the file).
fn read_header_bytes(path: &Path, reader: &mut impl BufRead) -> Result<Vec<u8>, GeomError> {
    let mut header = Vec::new();
    loop {
        let start = header.len();
        let n = reader.read_until(b'\n', &mut header).map_err(|e| GeomError::io(path, e))?;
        if n == 0 || header[start..].trim_ascii() == b"end_header" {
            return Ok(header);
        }
    }
}

/// Checks the header (see the module documentation); `data_len` is the number of bytes after
/// it, `vertex_limit` the most vertices allowed, `face_limit` the most faces (if faces are
/// read). Malformed lines are left to `ply-rs` to report.
fn check_header(
    path: &Path,
    header: &[u8],
    data_len: u64,
    vertex_limit: (u64, Which),
    face_limit: Option<u64>,
) -> Result<(), GeomError> {
    let text = String::from_utf8_lossy(header);
    let bad = |why: String| GeomError::parse(path, format!("invalid PLY header: {why}"));
    let mut ascii = None;
    // (name, count, properties, fixed bytes per binary record)
    let mut elements: Vec<(String, u64, u64, u64)> = Vec::new();
    for line in text.lines() {
        let toks: Vec<&str> = line.split_whitespace().collect();
        match toks.first().copied() {
            Some(kw @ ("format" | "element")) => {
                // ply-rs unwraps the u64 parse of these numbers.
                for run in line.split(|c: char| !c.is_ascii_digit()).filter(|r| !r.is_empty()) {
                    if run.parse::<u64>().is_err() {
                        return Err(bad(format!("number {run} in '{kw}' line is out of range")));
                    }
                }
                if kw == "format" {
                    ascii = toks.get(1).map(|&e| e == "ascii");
                } else if let (Some(name), Some(Ok(count))) =
                    (toks.get(1), toks.get(2).map(|c| c.parse::<u64>()))
                {
                    elements.push((name.to_string(), count, 0, 0));
                }
            }
            Some("property") => {
                if let Some(e) = elements.last_mut() {
                    e.2 += 1;
                    // `property list <count type> <item type> name`: the count is fixed.
                    let ty = if toks.get(1) == Some(&"list") { toks.get(2) } else { toks.get(1) };
                    e.3 += ty.and_then(|t| scalar_size(t)).unwrap_or(0);
                }
            }
            _ => {}
        }
    }
    let Some(ascii) = ascii else {
        return Ok(());
    };
    for (name, count, props, fixed) in &elements {
        // Smallest possible size of one record: a byte per ascii value (a separator or line
        // break follows most), the fixed part of a binary one; at least one byte.
        let per = if ascii { *props } else { *fixed }.max(1);
        if count.saturating_mul(per) > data_len {
            return Err(bad(format!(
                "element '{name}' declares {count} records of at least {per} bytes, but only {data_len} bytes follow the header"
            )));
        }
        if name == "vertex" && *count > vertex_limit.0 {
            let o = over(vertex_limit.1, vertex_limit.0);
            return Err(GeomError::invalid(path, format!("header declares {count} vertices, {o}")));
        }
        if let (true, Some(max)) = (name == "face", face_limit) {
            if *count > max {
                let o = over(Which::Triangles, max);
                return Err(GeomError::invalid(path, format!("header declares {count} faces, {o}")));
            }
        }
    }
    Ok(())
}

/// Reads the vertex element (and, if `with_faces`, the face element) of a PLY file: a mesh
/// (vertices within [`Limits::max_vertices`], faces within [`Limits::max_triangles`]) or, without
/// faces, a point cloud (vertices within [`Limits::max_points`]).
pub(crate) fn read(path: &Path, with_faces: bool, limits: &Limits) -> Result<PlyData, GeomError> {
    let (file, len) = crate::fsutil::open_limited(path, limits.max_file_bytes, Some(Which::FileBytes))?;
    let mut body = BufReader::new(file.take(len));
    let head = read_header_bytes(path, &mut body)?;
    let (vertex_limit, face_limit) = if with_faces {
        ((limits.max_vertices, Which::Vertices), Some(limits.max_triangles))
    } else {
        ((limits.max_points, Which::Points), None)
    };
    check_header(path, &head, len.saturating_sub(head.len() as u64), vertex_limit, face_limit)?;
    let mut reader = Cursor::new(head).chain(body);
    let perr = |what: &str, e: std::io::Error| {
        // ply-rs messages span several lines; keep the error on one line.
        let msg = e.to_string().split_whitespace().collect::<Vec<_>>().join(" ");
        GeomError::parse(path, format!("invalid PLY {what}: {msg}"))
    };
    let header: Header = Parser::<Skip>::new().read_header(&mut reader).map_err(|e| perr("header", e))?;
    let Some(vdef) = header.elements.get("vertex") else {
        return Err(GeomError::parse(path, "invalid PLY: no 'vertex' element"));
    };
    for axis in ["x", "y", "z"] {
        match vdef.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            _ => {
                return Err(GeomError::parse(
                    path,
                    format!("invalid PLY: vertex element has no scalar property '{axis}'"),
                ))
            }
        }
    }
    let has_color = has_property(vdef, &["red", "r", "diffuse_red"])
        && has_property(vdef, &["green", "g", "diffuse_green"])
        && has_property(vdef, &["blue", "b", "diffuse_blue"]);

    let mut data = PlyData { positions: Vec::new(), colors: None, faces: Vec::new() };
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                let v = Parser::<Vertex>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| perr("vertex data", e))?;
                data.positions = v.iter().map(|v| v.p).collect();
                if has_color {
                    data.colors = Some(v.iter().map(|v| v.rgb).collect());
                }
            }
            "face" if with_faces => {
                if !has_property(def, &["vertex_indices", "vertex_index"]) {
                    return Err(GeomError::parse(
                        path,
                        "invalid PLY: face element has no 'vertex_indices' list",
                    ));
                }
                let faces = Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| perr("face data", e))?;
                data.faces.reserve(faces.len());
                for (k, f) in faces.into_iter().enumerate() {
                    match f.indices {
                        Some(ix) => data.faces.push(ix),
                        None => {
                            return Err(GeomError::invalid(
                                path,
                                format!("face {k} has a negative or non-integer vertex index"),
                            ))
                        }
                    }
                }
            }
            _ if !with_faces && data.positions.len() == vdef.count => {
                // Everything needed has been read; later elements are not parsed.
                break;
            }
            _ => {
                Parser::<Skip>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| perr(&format!("'{name}' data"), e))?;
            }
        }
    }
    Ok(data)
}

/// Loads a PLY mesh. The caller validates the result.
pub(super) fn load(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let data = read(path, true, limits)?;
    let mut triangles = Vec::with_capacity(data.faces.len());
    for f in &data.faces {
        fan(f, &mut triangles);
    }
    let appearance = match data.colors {
        Some(c) => Appearance::VertexColors(c),
        None => Appearance::None,
    };
    Ok(Mesh { positions: data.positions, triangles, appearance })
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

    /// Binary PLY: `n` double vertices (with an extra float property in between) and
    /// int-indexed faces, in the given endianness.
    fn binary(le: bool, verts: &[[f64; 3]], faces: &[Vec<i32>]) -> Vec<u8> {
        let fmt = if le { "binary_little_endian" } else { "binary_big_endian" };
        let mut b = format!(
            "ply\nformat {fmt} 1.0\ncomment test\nelement vertex {}\nproperty double x\n\
             property float quality\nproperty double y\nproperty double z\nelement face {}\n\
             property list uchar int vertex_indices\nend_header\n",
            verts.len(),
            faces.len()
        )
        .into_bytes();
        for v in verts {
            let q = 0.5f32;
            if le {
                b.extend(v[0].to_le_bytes());
                b.extend(q.to_le_bytes());
                b.extend(v[1].to_le_bytes());
                b.extend(v[2].to_le_bytes());
            } else {
                b.extend(v[0].to_be_bytes());
                b.extend(q.to_be_bytes());
                b.extend(v[1].to_be_bytes());
                b.extend(v[2].to_be_bytes());
            }
        }
        for f in faces {
            b.push(f.len() as u8);
            for &i in f {
                b.extend(if le { i.to_le_bytes() } else { i.to_be_bytes() });
            }
        }
        b
    }

    const SQUARE: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.25]];

    #[test]
    fn ascii_with_colours_and_quad() {
        let dir = tempfile::tempdir().unwrap();
        let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
            property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
            element face 1\nproperty list uchar int vertex_index\nend_header\n\
            0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0.25 51 102 153\n4 0 1 2 3\n";
        let m = load_mesh(&write(&dir, "a.ply", text.as_bytes())).unwrap();
        assert_eq!(m.positions, SQUARE.to_vec());
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let Appearance::VertexColors(c) = &m.appearance else { panic!() };
        assert_eq!(c[0], [1.0, 0.0, 0.0]);
        assert_eq!(c[3], [0.2, 0.4, 0.6]);
    }

    #[test]
    fn binary_both_endiannesses() {
        let dir = tempfile::tempdir().unwrap();
        for le in [true, false] {
            let b = binary(le, &SQUARE, &[vec![0, 1, 2, 3], vec![3, 2, 1]]);
            let m = load_mesh(&write(&dir, "b.ply", &b)).unwrap();
            assert_eq!(m.positions, SQUARE.to_vec());
            assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [3, 2, 1]]);
            assert_eq!(m.appearance, Appearance::None);
        }
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let check = |bytes: &[u8], want: &[&str]| {
            let p = write(&dir, "bad.ply", bytes);
            let e = load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains("bad.ply") && want.iter().any(|w| e.contains(w)), "{e}");
            assert!(!e.contains('\n'), "one-line error: {e}");
        };
        let good = binary(true, &SQUARE, &[vec![0, 1, 2]]);
        check(&good[..good.len() - 3], &["face data"]); // truncated
        check(b"plx\nformat ascii 1.0\nend_header\n", &["header"]); // wrong magic
        check(&[0x00, 0xff, 0x10, 0x80, 0x7f], &["header"]); // garbage
        let mut nan = SQUARE;
        nan[1][2] = f64::NAN;
        check(&binary(true, &nan, &[vec![0, 1, 2]]), &["non-finite"]);
        check(&binary(true, &SQUARE, &[vec![0, 1, 4]]), &["references vertex 4"]);
        check(&binary(true, &SQUARE, &[vec![0, -1, 2]]), &["negative"]);
        check(&binary(true, &SQUARE, &[]), &["no triangles"]);
        check(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n", &["'y'"]);
    }

    #[test]
    fn header_counts_are_checked_before_parsing() {
        let dir = tempfile::tempdir().unwrap();
        let check = |bytes: &[u8], want: &str| {
            let p = write(&dir, "hdr.ply", bytes);
            let e = crate::test_support::within(10, move || load_mesh(&p).map(|m| m.triangles.len()))
                .unwrap_err()
                .to_string();
            assert!(e.contains("hdr.ply") && e.contains(want), "{e}");
            assert!(!e.contains("parser failed"), "a caught panic: {e}");
        };
        let head =
            |fmt: &str, elements: &str| format!("ply\nformat {fmt} 1.0\n{elements}end_header\n").into_bytes();
        let xyz = "property float x\nproperty float y\nproperty float z\n";
        // 2^64 vertices: ply-rs unwraps the parse of the count.
        check(
            &head("ascii", &format!("element vertex 18446744073709551616\n{xyz}")),
            "number 18446744073709551616",
        );
        // So is the version number.
        let v = format!("ply\nformat ascii 99999999999999999999.0\nelement vertex 0\n{xyz}end_header\n");
        check(v.as_bytes(), "number 99999999999999999999 in 'format' line is out of range");
        // 2^40 vertices in a file of a few hundred bytes, binary and ascii.
        let mut b = head("binary_little_endian", &format!("element vertex 1099511627776\n{xyz}"));
        b.extend([0u8; 36]);
        check(&b, "element 'vertex' declares 1099511627776 records of at least 12 bytes, but only 36 bytes");
        check(
            &head("ascii", &format!("element vertex 1099511627776\n{xyz}")),
            "declares 1099511627776 records",
        );
        // An element without properties: ply-rs would count to 2^40 without reading.
        let junk = format!("element junk 1099511627776\nelement vertex 3\n{xyz}element face 1\nproperty list uchar int vertex_indices\n");
        let mut b = head("binary_little_endian", &junk);
        for v in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            b.extend(v.iter().flat_map(|c| c.to_le_bytes()));
        }
        b.push(3);
        b.extend([0i32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        check(&b, "element 'junk' declares 1099511627776 records");
    }

    #[test]
    fn vertex_and_face_counts_respect_the_limits() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "l.ply", &binary(true, &SQUARE, &[vec![0, 1, 2, 3]]));
        let d = crate::Limits::default();
        let at = |l: crate::Limits| crate::io::load_mesh_with(&p, &l).unwrap_err().to_string();
        assert!(
            at(crate::Limits { max_vertices: 3, ..d }).contains("declares 4 vertices, over the limit of 3")
        );
        // The one quad is two triangles.
        let e = at(crate::Limits { max_triangles: 1, ..d });
        assert!(e.contains("l.ply") && e.contains("2 triangles, over the limit of 1"), "{e}");
        // As a point cloud, the vertex count is held against max_points.
        let e =
            crate::cloud::read_cloud_with(&p, &crate::Limits { max_points: 3, ..d }).unwrap_err().to_string();
        assert!(e.contains("declares 4 vertices, over the limit of 3 (OBJVIEW_MAX_POINTS"), "{e}");
    }
}
