//! A small NumPy `.npy` (format 1.0) writer and reader.
//!
//! The CLI writes depth maps and point arrays as `.npy` so that Python users of the benchmark
//! can `np.load` them directly, and ground-truth clouds may come as `.npy`/`.npz` (SPEC §1).
//! Only what the project needs is supported: little-endian `<f4`, `<f8` and `<u4` written in
//! C order; `<f4`/`<f8` read (format versions 1.0, 2.0 and 3.0 headers are accepted). The
//! shape is checked against the data present before anything is allocated.

use crate::limits::Limits;
use crate::GeomError;
use std::io::Write;
use std::path::Path;

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The header bytes (magic, version 1.0, length, dict padded with spaces and ending in `\n`
/// so that magic + length + dict is a multiple of 64 bytes).
pub fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let shape_str = match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_str}, }}");
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let pad = unpadded.div_ceil(64) * 64 - unpadded;
    dict.extend(std::iter::repeat_n(' ', pad));
    dict.push('\n');
    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

fn write_npy<const W: usize>(
    path: &Path,
    descr: &str,
    shape: &[usize],
    n: usize,
    bytes_of: impl Fn(usize) -> [u8; W],
) -> Result<(), GeomError> {
    let expected: usize = shape.iter().product();
    if expected != n {
        return Err(GeomError::invalid(
            path,
            format!("npy shape {shape:?} holds {expected} values, data has {n}"),
        ));
    }
    let mut buf = npy_header(descr, shape);
    buf.reserve(n * W);
    for i in 0..n {
        buf.extend_from_slice(&bytes_of(i));
    }
    let mut f = std::fs::File::create(path).map_err(|e| GeomError::io(path, e))?;
    f.write_all(&buf).map_err(|e| GeomError::io(path, e))
}

/// Writes a C-order little-endian float32 array of the given shape.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<(), GeomError> {
    write_npy(path, "<f4", shape, data.len(), |i| data[i].to_le_bytes())
}

/// Writes a C-order little-endian float64 array of the given shape.
pub fn write_npy_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<(), GeomError> {
    write_npy(path, "<f8", shape, data.len(), |i| data[i].to_le_bytes())
}

/// Writes a C-order little-endian uint32 array of the given shape.
pub fn write_npy_u32(path: &Path, shape: &[usize], data: &[u32]) -> Result<(), GeomError> {
    write_npy(path, "<u4", shape, data.len(), |i| data[i].to_le_bytes())
}

/// Reads a `.npy` file of `<f4` or `<f8` values: `(shape, values in C order)`, as a regular
/// file within [`Limits::global`]'s `max_file_bytes` (see [`crate::fsutil`]).
pub fn read_npy_f64(path: &Path) -> Result<(Vec<usize>, Vec<f64>), GeomError> {
    read_npy_f64_with(path, Limits::for_file(path)?)
}

/// [`read_npy_f64`] within explicit `limits`.
pub fn read_npy_f64_with(path: &Path, limits: &Limits) -> Result<(Vec<usize>, Vec<f64>), GeomError> {
    let bytes = crate::io::read_input(path, limits)?;
    parse_npy_f64(path, &bytes)
}

/// Value of `'key': ...` in the header dict, up to the next top-level comma or brace.
fn dict_value<'h>(header: &'h str, key: &str) -> Option<&'h str> {
    let start = header.find(&format!("'{key}'")).or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[start + key.len() + 2..].trim_start().strip_prefix(':')?.trim_start();
    let end = if rest.starts_with('(') { rest.find(')')? + 1 } else { rest.find([',', '}'])? };
    Some(rest[..end].trim())
}

/// A checked `.npy` header: the dtype descriptor (quotes removed, e.g. `<f4`), the shape (C
/// order; empty for a 0-d array) and the offset of the data.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NpyHeader {
    /// The `descr` value, e.g. `<f4`, `|u1`.
    pub descr: String,
    /// The shape.
    pub shape: Vec<usize>,
    /// Where the data starts in the bytes.
    pub data_offset: usize,
}

/// Parses the header of `.npy` bytes (format versions 1.0, 2.0 and 3.0): magic, version,
/// length, `descr`, `fortran_order` (only `False` is accepted) and `shape`. Errors name `path`
/// (`invalid NPY: …`). The dtype and the data are the caller's to check.
pub fn parse_npy_header(path: &Path, bytes: &[u8]) -> Result<NpyHeader, GeomError> {
    let bad = |why: String| GeomError::parse(path, format!("invalid NPY: {why}"));
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(bad("missing \\x93NUMPY magic".into()));
    }
    let (hlen, hstart): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => {
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        v => return Err(bad(format!("unsupported format version {v}"))),
    };
    let Some(hbytes) = bytes.get(hstart..hstart.saturating_add(hlen)) else {
        return Err(bad("truncated header".into()));
    };
    let header = std::str::from_utf8(hbytes).map_err(|_| bad("header is not text".into()))?;
    let descr = dict_value(header, "descr").ok_or_else(|| bad("header has no 'descr'".into()))?;
    let descr = descr.trim_matches(|c| c == '\'' || c == '"').to_string();
    match dict_value(header, "fortran_order") {
        Some("False") => {}
        Some("True") => return Err(bad("Fortran-order arrays are unsupported".into())),
        _ => return Err(bad("header has no valid 'fortran_order'".into())),
    }
    let shape_s = dict_value(header, "shape").ok_or_else(|| bad("header has no 'shape'".into()))?;
    let inner = shape_s
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| bad(format!("bad shape '{shape_s}'")))?;
    let shape: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| bad(format!("bad shape '{shape_s}'"))))
        .collect::<Result<_, _>>()?;
    Ok(NpyHeader { descr, shape, data_offset: hstart + hlen })
}

/// Parses `.npy` bytes (see [`read_npy_f64`]); `path` names the source in errors.
pub fn parse_npy_f64(path: &Path, bytes: &[u8]) -> Result<(Vec<usize>, Vec<f64>), GeomError> {
    let bad = |why: String| GeomError::parse(path, format!("invalid NPY: {why}"));
    let NpyHeader { descr, shape, data_offset } = parse_npy_header(path, bytes)?;
    let width = match descr.as_str() {
        "<f4" => 4,
        "<f8" => 8,
        other => return Err(bad(format!("dtype '{other}' unsupported (little-endian float32/float64 are)"))),
    };
    let n = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad("shape overflows".into()))?;
    let data = &bytes[data_offset..];
    if data.len() / width < n {
        return Err(bad(format!(
            "shape {shape:?} needs {} data bytes, file has {} (truncated)",
            n.saturating_mul(width),
            data.len()
        )));
    }
    let values = if width == 4 {
        data[..4 * n].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect()
    } else {
        data[..8 * n]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect()
    };
    Ok((shape, values))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_bytes_for_known_shape() {
        let h = npy_header("<f4", &[512, 512]);
        // Written out by hand from the NPY 1.0 spec: 10 prefix bytes + dict, total 128.
        let dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (512, 512), }";
        assert_eq!(dict.len(), 63);
        let mut expect = b"\x93NUMPY\x01\x00".to_vec();
        expect.extend_from_slice(&118u16.to_le_bytes());
        expect.extend_from_slice(dict.as_bytes());
        expect.extend_from_slice(&[b' '; 54]);
        expect.push(b'\n');
        assert_eq!(h.len(), 128);
        assert_eq!(h, expect);
        let h1 = npy_header("<f8", &[7]);
        assert_eq!(h1.len() % 64, 0);
        assert!(std::str::from_utf8(&h1[10..]).unwrap().contains("'shape': (7,), }"));
    }

    #[test]
    fn round_trip_f32_f64_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let data: Vec<f32> = (0..12).map(|i| i as f32 * 0.5 - 1.0).collect();
        write_npy_f32(&p, &[4, 3], &data).unwrap();
        let (shape, v) = read_npy_f64(&p).unwrap();
        assert_eq!(shape, vec![4, 3]);
        assert_eq!(v, data.iter().map(|&x| x as f64).collect::<Vec<_>>());
        let d64 = vec![1.0 / 3.0, -2.5e-300, 7.0];
        write_npy_f64(&p, &[3], &d64).unwrap();
        assert_eq!(read_npy_f64(&p).unwrap(), (vec![3], d64));
        // Shape/data mismatch is refused.
        assert!(write_npy_f64(&p, &[2, 2], &[1.0]).is_err());
        // u32 header descr.
        write_npy_u32(&p, &[2], &[1, 2]).unwrap();
        let e = read_npy_f64(&p).unwrap_err().to_string();
        assert!(e.contains("a.npy") && e.contains("<u4"), "{e}");
        // Truncated data.
        write_npy_f32(&p, &[4, 3], &data).unwrap();
        let b = std::fs::read(&p).unwrap();
        std::fs::write(&p, &b[..b.len() - 1]).unwrap();
        assert!(read_npy_f64(&p).unwrap_err().to_string().contains("truncated"));
        // Garbage.
        std::fs::write(&p, b"hello world, not numpy").unwrap();
        assert!(read_npy_f64(&p).unwrap_err().to_string().contains("magic"));
    }
}
