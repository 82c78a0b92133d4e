//! NumPy `.npz` files (a zip of `.npy` arrays) as the training data's exchange format: written
//! here so that PyTorch users can `np.load` them, read back by the Rust trainer.
//!
//! Writing is deterministic (fixed 1980-01-01 timestamps, fixed entry order, deflate level 1),
//! so the same cases give byte-identical files. Arrays are little-endian, C order, `.npy`
//! format 1.0. Reading checks every header against the entry's size and refuses what it does
//! not understand with an error naming the file and the array.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use objview_geom::npy::{npy_header, parse_npy_header};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipArchive, ZipWriter};

/// An error of reading or writing an `.npz` file, naming it.
#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    /// The file could not be opened, read or written.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
    /// An array is missing or not what it must be.
    #[error("{path}: array '{name}': {reason}")]
    Array {
        /// The file.
        path: PathBuf,
        /// The array.
        name: String,
        /// What is wrong.
        reason: String,
    },
}

/// Element types the training data uses, with their `.npy` descriptors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    /// `<f4`
    F32,
    /// `<i8`
    I64,
    /// `<i4`
    I32,
    /// `|i1`
    I8,
    /// `|u1`
    U8,
}

impl Dtype {
    /// The `.npy` descriptor string.
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::F32 => "<f4",
            Dtype::I64 => "<i8",
            Dtype::I32 => "<i4",
            Dtype::I8 => "|i1",
            Dtype::U8 => "|u1",
        }
    }
    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::F32 | Dtype::I32 => 4,
            Dtype::I64 => 8,
            Dtype::I8 | Dtype::U8 => 1,
        }
    }
    fn parse(s: &str) -> Option<Dtype> {
        Some(match s {
            "<f4" => Dtype::F32,
            "<i8" => Dtype::I64,
            "<i4" => Dtype::I32,
            "|i1" | "<i1" => Dtype::I8,
            "|u1" | "<u1" => Dtype::U8,
            _ => return None,
        })
    }
}

/// Writes an `.npz` file array by array. An array's data may be streamed in pieces after
/// [`NpzWriter::begin`]; the caller writes exactly `product(shape) · dtype.size()` bytes.
pub struct NpzWriter {
    zip: ZipWriter<BufWriter<File>>,
    path: PathBuf,
}

impl NpzWriter {
    /// Creates (truncates) `path`.
    pub fn create(path: &Path) -> Result<NpzWriter, NpzError> {
        let f = File::create(path).map_err(|e| io(path, e))?;
        Ok(NpzWriter { zip: ZipWriter::new(BufWriter::new(f)), path: path.to_path_buf() })
    }

    /// Starts array `name` (stored as `name.npy`).
    pub fn begin(&mut self, name: &str, dtype: Dtype, shape: &[usize]) -> Result<(), NpzError> {
        let opts = SimpleFileOptions::default()
            .compression_method(CompressionMethod::Deflated)
            .compression_level(Some(1))
            .last_modified_time(DateTime::default())
            .large_file(shape.iter().product::<usize>() * dtype.size() >= u32::MAX as usize / 2);
        self.zip.start_file(format!("{name}.npy"), opts).map_err(|e| io(&self.path, e))?;
        self.zip.write_all(&npy_header(dtype.descr(), shape)).map_err(|e| io(&self.path, e))
    }

    /// Appends raw little-endian element bytes to the current array.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), NpzError> {
        self.zip.write_all(bytes).map_err(|e| io(&self.path, e))
    }

    /// Writes f32 values.
    pub fn write_f32(&mut self, v: &[f32]) -> Result<(), NpzError> {
        let mut b = Vec::with_capacity(v.len() * 4);
        v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
        self.write(&b)
    }

    /// A whole i32 array.
    pub fn array_i32(&mut self, name: &str, shape: &[usize], v: &[i32]) -> Result<(), NpzError> {
        self.begin(name, Dtype::I32, shape)?;
        let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.write(&b)
    }

    /// A whole i64 array.
    pub fn array_i64(&mut self, name: &str, shape: &[usize], v: &[i64]) -> Result<(), NpzError> {
        self.begin(name, Dtype::I64, shape)?;
        let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.write(&b)
    }

    /// A whole i8 array.
    pub fn array_i8(&mut self, name: &str, shape: &[usize], v: &[i8]) -> Result<(), NpzError> {
        self.begin(name, Dtype::I8, shape)?;
        let b: Vec<u8> = v.iter().map(|&x| x as u8).collect();
        self.write(&b)
    }

    /// A whole u8 array.
    pub fn array_u8(&mut self, name: &str, shape: &[usize], v: &[u8]) -> Result<(), NpzError> {
        self.begin(name, Dtype::U8, shape)?;
        self.write(v)
    }

    /// Finishes the file (central directory) and flushes it.
    pub fn finish(self) -> Result<(), NpzError> {
        let path = self.path;
        let w = self.zip.finish().map_err(|e| io(&path, e))?;
        w.into_inner().map_err(|e| io(&path, e.error()))?.sync_all().map_err(|e| io(&path, e))
    }
}

fn one_line_of(e: &impl std::fmt::Display) -> String {
    objview_geom::error::one_line(&e.to_string()).into_owned()
}

fn io(path: &Path, e: impl std::fmt::Display) -> NpzError {
    NpzError::Io {
        path: path.to_path_buf(),
        reason: objview_geom::error::one_line(&e.to_string()).into_owned(),
    }
}

/// One array read back: its type, shape and raw little-endian bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Array {
    /// Element type.
    pub dtype: Dtype,
    /// Shape (empty for a 0-d array).
    pub shape: Vec<usize>,
    /// `product(shape) · dtype.size()` bytes.
    pub data: Vec<u8>,
}

impl Array {
    /// The values as f32 (dtype must be F32).
    pub fn f32s(&self) -> Vec<f32> {
        self.data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
    }
    /// The values as i64 from any integer dtype.
    pub fn ints(&self) -> Vec<i64> {
        match self.dtype {
            Dtype::I64 => {
                self.data.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect()
            }
            Dtype::I32 => {
                self.data.chunks_exact(4).map(|c| i32::from_le_bytes(c.try_into().unwrap()) as i64).collect()
            }
            Dtype::I8 => self.data.iter().map(|&b| b as i8 as i64).collect(),
            Dtype::U8 => self.data.iter().map(|&b| b as i64).collect(),
            Dtype::F32 => self.f32s().iter().map(|&x| x as i64).collect(),
        }
    }
}

/// An `.npz` file opened for reading arrays by name.
pub struct NpzReader {
    zip: ZipArchive<File>,
    path: PathBuf,
}

/// The largest array this reader accepts (bytes): 4 GiB.
pub const MAX_ARRAY_BYTES: u64 = 4 << 30;

impl NpzReader {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<NpzReader, NpzError> {
        let f = File::open(path).map_err(|e| io(path, e))?;
        let zip = ZipArchive::new(f).map_err(|e| io(path, format!("not an npz (zip) file: {e}")))?;
        Ok(NpzReader { zip, path: path.to_path_buf() })
    }

    /// Reads array `name`, checking its type (when `want` is given) and that the data size
    /// matches the shape.
    pub fn array(&mut self, name: &str, want: Option<Dtype>) -> Result<Array, NpzError> {
        let path = self.path.clone();
        let bad = |reason: String| NpzError::Array { path: path.clone(), name: name.to_string(), reason };
        let member = format!("{name}.npy");
        let mut entry = self.zip.by_name(&member).map_err(|_| bad("missing".into()))?;
        if entry.size() > MAX_ARRAY_BYTES {
            return Err(bad(format!("{} bytes is over the limit of {MAX_ARRAY_BYTES}", entry.size())));
        }
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry.read_to_end(&mut bytes).map_err(|e| bad(format!("unreadable: {e}")))?;
        let header = parse_npy_header(Path::new(&member), &bytes).map_err(|e| bad(one_line_of(&e)))?;
        let dtype =
            Dtype::parse(&header.descr).ok_or_else(|| bad(format!("unsupported dtype {}", header.descr)))?;
        let (shape, offset) = (header.shape, header.data_offset);
        if let Some(w) = want {
            if w != dtype {
                return Err(bad(format!("dtype {} where {} is needed", dtype.descr(), w.descr())));
            }
        }
        let n = shape
            .iter()
            .try_fold(dtype.size(), |a, &d| a.checked_mul(d))
            .ok_or_else(|| bad("shape overflows".into()))?;
        if bytes.len() - offset != n {
            return Err(bad(format!(
                "{} data bytes for shape {:?}, expected {n}",
                bytes.len() - offset,
                shape
            )));
        }
        bytes.drain(..offset);
        Ok(Array { dtype, shape, data: bytes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_of_every_dtype_parse_back() {
        for (dtype, shape) in [(Dtype::F32, vec![]), (Dtype::U8, vec![3]), (Dtype::I64, vec![2, 64, 64, 64])]
        {
            let h = npy_header(dtype.descr(), &shape);
            assert_eq!(h.len() % 64, 0);
            let p = parse_npy_header(Path::new("x.npy"), &h).unwrap();
            assert_eq!((Dtype::parse(&p.descr), p.shape, p.data_offset), (Some(dtype), shape, h.len()));
        }
    }

    #[test]
    fn round_trip_and_determinism() {
        let dir = tempfile::tempdir().unwrap();
        let write = |p: &Path| {
            let mut w = NpzWriter::create(p).unwrap();
            w.begin("grid", Dtype::F32, &[2, 2]).unwrap();
            w.write_f32(&[0.5, 0.25]).unwrap();
            w.write_f32(&[1.0, -2.0]).unwrap();
            w.array_i64("label", &[2], &[7, 127]).unwrap();
            w.array_i8("status", &[2], &[-1, 0]).unwrap();
            w.array_i32("universe", &[], &[4242]).unwrap();
            w.finish().unwrap();
        };
        let (a, b) = (dir.path().join("a.npz"), dir.path().join("b.npz"));
        write(&a);
        std::thread::sleep(std::time::Duration::from_millis(1100));
        write(&b);
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "byte-identical files");
        let mut r = NpzReader::open(&a).unwrap();
        let g = r.array("grid", Some(Dtype::F32)).unwrap();
        assert_eq!(g.shape, vec![2, 2]);
        assert_eq!(g.f32s(), vec![0.5, 0.25, 1.0, -2.0]);
        assert_eq!(r.array("label", None).unwrap().ints(), vec![7, 127]);
        assert_eq!(r.array("status", None).unwrap().ints(), vec![-1, 0]);
        let u = r.array("universe", Some(Dtype::I32)).unwrap();
        assert_eq!((u.shape.len(), u.ints()), (0, vec![4242]));
        let e = r.array("label", Some(Dtype::F32)).unwrap_err().to_string();
        assert!(e.contains("a.npz") && e.contains("'label'") && e.contains("dtype"), "{e}");
        let e = r.array("nothing", None).unwrap_err().to_string();
        assert!(e.contains("'nothing'") && e.contains("missing"), "{e}");
    }

    #[test]
    fn a_header_that_lies_about_its_size_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npz");
        let mut w = NpzWriter::create(&p).unwrap();
        w.begin("grid", Dtype::F32, &[3]).unwrap();
        w.write_f32(&[1.0]).unwrap();
        w.finish().unwrap();
        let e = NpzReader::open(&p).unwrap().array("grid", None).unwrap_err().to_string();
        assert!(e.contains("expected 12"), "{e}");
        std::fs::write(&p, b"not a zip").unwrap();
        assert!(NpzReader::open(&p).is_err());
    }
}
