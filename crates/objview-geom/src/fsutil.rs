//! Safe file access for untrusted inputs: the one place where objview opens files it did not
//! write itself. Every loader of this crate reads through it, and other crates (view sets,
//! rule files, split files) can too.
//!
//! * [`open_regular`] / [`read_regular`]: a file given directly (a top-level symlink is
//!   followed) must be a regular file — never a FIFO, device, socket or directory — of at most
//!   `max_bytes`. The type and size are checked from the metadata *before* the file is opened,
//!   the file is opened non-blocking (a FIFO swapped in after the check cannot hang the open)
//!   and checked again on the opened handle, and reads are bounded by the limit (a file that
//!   grows while being read cannot exceed it).
//! * [`resolve_inside`]: a file an asset refers to (a glTF buffer or image URI, an OBJ
//!   `mtllib` or `map_Kd`) is looked up only inside the asset's own folder. The reference is
//!   percent-decoded first; absolute paths and `..` components are refused without touching
//!   the file system. **Symlinks:** a referenced file (or a folder on the way to it) may be a
//!   symlink only if its canonical target stays inside the asset's folder (canonicalized
//!   too, so an asset folder that is itself reached through a symlink works). The canonical
//!   path is returned, so the check and the later open see the same file. Reading the result
//!   with [`read_regular`] adds the type and size checks.

use crate::limits::{over, Which};
use crate::GeomError;
use crate::Limits;
use std::fs::{File, Metadata};
use std::io::{Error, ErrorKind, Read};
use std::path::{Component, Path, PathBuf};

/// Why `meta` is not a regular file, e.g. "a FIFO (named pipe)"; `None` for a regular file.
fn not_regular(meta: &Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// Checks the type and size of `meta` (of `path`), naming the limit's variable when `which`
/// is given.
fn check(path: &Path, meta: &Metadata, max_bytes: u64, which: Option<Which>) -> Result<u64, GeomError> {
    if let Some(what) = not_regular(meta) {
        let msg = if what.starts_with("not") {
            what.to_string()
        } else {
            format!("not a regular file (it is {what})")
        };
        return Err(GeomError::io(path, Error::new(ErrorKind::InvalidInput, msg)));
    }
    let len = meta.len();
    if len > max_bytes {
        let tail = limit_tail(max_bytes, which);
        return Err(GeomError::io(
            path,
            Error::new(ErrorKind::InvalidInput, format!("file of {len} bytes is {tail}")),
        ));
    }
    Ok(len)
}

/// "over the limit of …": naming the limit's environment variable when `which` is given.
fn limit_tail(max_bytes: u64, which: Option<Which>) -> String {
    match which {
        Some(w) => over(w, max_bytes),
        None => format!("over the limit of {max_bytes} bytes"),
    }
}

/// Opens `path` for reading without blocking on FIFOs and without acquiring a controlling
/// terminal.
fn open_nonblocking(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY);
    }
    options.open(path)
}

/// [`open_regular`] whose size error names the limit's environment variable.
pub(crate) fn open_limited(
    path: &Path,
    max_bytes: u64,
    which: Option<Which>,
) -> Result<(File, u64), GeomError> {
    let meta = std::fs::metadata(path).map_err(|e| GeomError::io(path, e))?;
    check(path, &meta, max_bytes, which)?;
    let file = open_nonblocking(path).map_err(|e| GeomError::io(path, e))?;
    // The path may have been swapped between the check and the open: check what was opened.
    let meta = file.metadata().map_err(|e| GeomError::io(path, e))?;
    let len = check(path, &meta, max_bytes, which)?;
    Ok((file, len))
}

/// Opens a regular file of at most `max_bytes` for reading: `(file, its length)`. A symlink
/// given as `path` is followed; FIFOs, devices, sockets and directories are refused before
/// they are opened. Read the file through `take(length)` or [`read_regular`] to stay within
/// the limit if it grows.
pub fn open_regular(path: &Path, max_bytes: u64) -> Result<(File, u64), GeomError> {
    open_limited(path, max_bytes, None)
}

/// [`read_regular`] whose size error names the limit's environment variable.
pub(crate) fn read_limited(path: &Path, max_bytes: u64, which: Option<Which>) -> Result<Vec<u8>, GeomError> {
    let (file, len) = open_limited(path, max_bytes, which)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| GeomError::io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        let tail = limit_tail(max_bytes, which);
        return Err(GeomError::io(
            path,
            Error::new(ErrorKind::InvalidInput, format!("file grew while read: {tail}")),
        ));
    }
    Ok(bytes)
}

/// Reads a whole regular file of at most `max_bytes` (see [`open_regular`]); a file that
/// grows past the limit while it is read is an error, not a longer read.
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, GeomError> {
    read_limited(path, max_bytes, None)
}

/// Reads a whole text file given by a user (a split file, view set, rule file, results or
/// annotation lines) with the same checks as the loaders: a regular file (a top-level symlink
/// is followed; a FIFO or device is refused instead of blocking or reading forever) of at most
/// the process-wide `OBJVIEW_MAX_FILE_BYTES`, valid UTF-8. A drop-in replacement for
/// `std::fs::read_to_string`: the error is an I/O error *without* the path, for the caller's
/// own error type to name it.
pub fn read_text(path: &Path) -> std::io::Result<String> {
    let max = Limits::global().map_err(|e| Error::new(ErrorKind::InvalidInput, e))?.max_file_bytes;
    let bytes = read_limited(path, max, Some(Which::FileBytes)).map_err(|e| match e {
        GeomError::Io { source, .. } => source,
        other => Error::new(ErrorKind::InvalidData, other.to_string()),
    })?;
    String::from_utf8(bytes)
        .map_err(|_| Error::new(ErrorKind::InvalidData, "stream did not contain valid UTF-8"))
}

/// Decodes the `%XX` escapes of a URI (invalid escapes are kept as they are).
pub fn percent_decode(s: &str) -> Vec<u8> {
    let hex = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push(h * 16 + l);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    out
}

/// Resolves `reference` (a relative path or URI found in the asset file `asset_path`, with
/// `%XX` escapes) to the canonical path of an existing file inside the asset's folder (the
/// folder of `asset_path`). Refused: absolute paths, `..` components (after decoding, with `/`
/// or `\` as separator), NUL bytes, and paths whose canonical form leaves the folder (through a
/// symlink). The error names `asset_path` and the reference. The result is not opened; read
/// it with [`read_regular`] for the type and size checks.
pub fn resolve_inside(asset_path: &Path, reference: &str) -> Result<PathBuf, GeomError> {
    let refuse = |why: &str| GeomError::parse(asset_path, format!("referenced file '{reference}': {why}"));
    let decoded =
        String::from_utf8(percent_decode(reference)).map_err(|_| refuse("not UTF-8 after decoding"))?;
    if decoded.is_empty() {
        return Err(refuse("empty path"));
    }
    if decoded.contains('\0') {
        return Err(refuse("contains a NUL byte"));
    }
    let rel = Path::new(&decoded);
    let absolute = decoded.starts_with(['/', '\\'])
        || rel.is_absolute()
        || rel.components().any(|c| matches!(c, Component::Prefix(_) | Component::RootDir))
        || decoded.as_bytes().get(1) == Some(&b':') && decoded.as_bytes()[0].is_ascii_alphabetic();
    if absolute {
        return Err(refuse("absolute paths are not allowed (only files inside the asset's folder are read)"));
    }
    if decoded.split(['/', '\\']).any(|c| c == "..") {
        return Err(refuse("'..' is not allowed (only files inside the asset's folder are read)"));
    }
    let folder = match asset_path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let folder_canon = folder.canonicalize().map_err(|e| GeomError::io(folder, e))?;
    let joined = folder.join(rel);
    let canon = joined.canonicalize().map_err(|e| GeomError::io(&joined, e))?;
    if !canon.starts_with(&folder_canon) {
        return Err(refuse("resolves (through a symlink) to a file outside the asset's folder"));
    }
    Ok(canon)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_text_refuses_fifos_and_devices_and_reads_regular_files() {
        use crate::test_support::{mkfifo, symlink, within, write};
        let dir = tempfile::tempdir().unwrap();
        let ok = write(dir.path(), "split.json", b"[]\n");
        assert_eq!(read_text(&ok).unwrap(), "[]\n");
        let fifo = mkfifo(&dir.path().join("pipe.json"));
        let e = within(10, move || read_text(&fifo).unwrap_err().to_string());
        assert!(e.contains("FIFO") && !e.contains("pipe.json"), "{e}");
        let zero = symlink(Path::new("/dev/zero"), &dir.path().join("zero.jsonl"));
        let e = within(10, move || read_text(&zero).unwrap_err().to_string());
        assert!(e.contains("character device"), "{e}");
        let bad = write(dir.path(), "latin1.txt", &[0x66, 0xe9, 0x0a]);
        assert!(read_text(&bad).unwrap_err().to_string().contains("UTF-8"));
    }

    #[test]
    fn percent_decoding_keeps_invalid_escapes() {
        assert_eq!(percent_decode("my%20buf.bin"), b"my buf.bin");
        assert_eq!(percent_decode("%2e%2E/x"), b"../x");
        assert_eq!(percent_decode("a%2"), b"a%2");
        assert_eq!(percent_decode("a%zz%"), b"a%zz%");
        assert_eq!(percent_decode("%41"), b"A");
    }

    #[test]
    fn resolve_inside_accepts_only_files_inside_the_asset_folder() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir_all(d.join("asset/sub")).unwrap();
        std::fs::write(d.join("asset/sub/a b.bin"), b"x").unwrap();
        std::fs::write(d.join("secret.bin"), b"x").unwrap();
        let asset = d.join("asset/m.gltf");
        let inside = d.join("asset/sub/a b.bin").canonicalize().unwrap();
        assert_eq!(resolve_inside(&asset, "sub/a%20b.bin").unwrap(), inside);
        assert_eq!(resolve_inside(&asset, "./sub//a b.bin").unwrap(), inside);
        for (reference, want) in [
            ("../secret.bin", "'..' is not allowed"),
            ("sub/%2E%2e/../secret.bin", "'..' is not allowed"),
            ("sub\\..\\..\\secret.bin", "'..' is not allowed"),
            ("/etc/passwd", "absolute paths"),
            ("%2Fetc%2Fpasswd", "absolute paths"),
            ("C:/Windows/win.ini", "absolute paths"),
            ("a%00b", "NUL"),
            ("", "empty path"),
            ("%ff", "not UTF-8"),
        ] {
            let e = resolve_inside(&asset, reference).unwrap_err().to_string();
            assert!(e.contains("m.gltf") && e.contains(want), "{reference}: {e}");
        }
        let e = resolve_inside(&asset, "sub/missing.bin").unwrap_err().to_string();
        assert!(e.contains("missing.bin"), "{e}");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(d.join("secret.bin"), d.join("asset/out.bin")).unwrap();
            std::os::unix::fs::symlink(d.join("asset/sub"), d.join("asset/in")).unwrap();
            let e = resolve_inside(&asset, "out.bin").unwrap_err().to_string();
            assert!(e.contains("outside the asset's folder"), "{e}");
            assert_eq!(resolve_inside(&asset, "in/a%20b.bin").unwrap(), inside);
            // An asset folder reached through a symlink works.
            std::os::unix::fs::symlink(d.join("asset"), d.join("alias")).unwrap();
            assert_eq!(resolve_inside(&d.join("alias/m.gltf"), "sub/a b.bin").unwrap(), inside);
        }
    }

    #[test]
    fn read_regular_checks_the_size_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.bin");
        std::fs::write(&p, [7u8; 10]).unwrap();
        assert_eq!(read_regular(&p, 10).unwrap(), vec![7u8; 10]);
        let e = read_regular(&p, 9).unwrap_err().to_string();
        assert!(e.contains("f.bin: file of 10 bytes is over the limit of 9 bytes"), "{e}");
        let e = read_regular(dir.path(), 100).unwrap_err().to_string();
        assert!(e.contains("not a regular file (it is a directory)"), "{e}");
        assert_eq!(open_regular(&p, 10).unwrap().1, 10);
    }
}
