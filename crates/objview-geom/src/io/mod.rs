//! Mesh loading from the asset formats the benchmark accepts (SPEC §1): OBJ (with or without
//! .mtl), PLY (ascii and binary), STL (ascii and binary), OFF and glTF/GLB.
//!
//! [`load_mesh`] dispatches on the file extension (case-insensitive). Every loader triangulates
//! polygons as fans, keeps the file frame unchanged, and ends with [`Mesh::validate`], so a
//! mesh returned from here has triangles, finite referenced vertices, in-range indices and a
//! non-zero extent. Malformed input is reported as a [`GeomError`] naming the file and the
//! reason; as a last line of defence a panic inside a third-party parser is caught and turned
//! into an error too (without a panic report on stderr), so one bad asset never takes a batch
//! down.
//!
//! Files are opened through [`crate::fsutil`] (regular files only, size-capped, referenced
//! files only inside the asset's folder) and every loader stays within the
//! [`Limits`] ([`load_mesh`] uses [`Limits::global`], [`load_mesh_with`]
//! explicit ones).

mod gltf;
mod obj;
mod off;
pub(crate) mod ply;
mod stl;

use crate::limits::{over, Limits, Which};
use crate::{GeomError, Mesh};
use std::cell::Cell;
use std::path::Path;
use std::sync::Once;

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

/// Loads a triangle mesh, choosing the format from the extension (case-insensitive), within
/// the process-wide [`Limits::global`].
///
/// The result is validated ([`Mesh::validate`]); unknown extensions give
/// [`GeomError::Unsupported`].
pub fn load_mesh(path: &Path) -> Result<Mesh, GeomError> {
    if extension(path).filter(|e| MESH_EXTENSIONS.contains(&e.as_str())).is_none() {
        return Err(GeomError::Unsupported { path: path.to_path_buf(), expected: EXPECTED });
    }
    load_mesh_with(path, Limits::for_file(path)?)
}

/// [`load_mesh`] within explicit `limits`.
pub fn load_mesh_with(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let Some(ext) = extension(path).filter(|e| MESH_EXTENSIONS.contains(&e.as_str())) else {
        return Err(GeomError::Unsupported { path: path.to_path_buf(), expected: EXPECTED });
    };
    let mesh = catch_panic(path, || match ext.as_str() {
        "obj" => obj::load(path, limits),
        "ply" => ply::load(path, limits),
        "stl" => stl::load(path, limits),
        "off" => off::load(path, limits),
        _ => self::gltf::load(path, limits),
    })?;
    check_counts(path, mesh.positions.len(), mesh.triangles.len(), limits)?;
    mesh.validate(path)?;
    Ok(mesh)
}

/// The triangle and vertex limits, as errors naming `path`.
pub(crate) fn check_counts(
    path: &Path,
    vertices: usize,
    triangles: usize,
    limits: &Limits,
) -> Result<(), GeomError> {
    if triangles as u64 > limits.max_triangles {
        let o = over(Which::Triangles, limits.max_triangles);
        return Err(GeomError::invalid(path, format!("{triangles} triangles, {o}")));
    }
    if vertices as u64 > limits.max_vertices {
        let o = over(Which::Vertices, limits.max_vertices);
        return Err(GeomError::invalid(path, format!("{vertices} vertices, {o}")));
    }
    Ok(())
}

thread_local! {
    /// How many [`catch_panic`] calls the current thread is inside.
    static CATCHING: Cell<u32> = const { Cell::new(0) };
}

/// Installs (once per process) a panic hook that is silent on threads currently inside
/// [`catch_panic`] and delegates to the hook it replaced everywhere else.
fn install_quiet_hook() {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if CATCHING.try_with(Cell::get).unwrap_or(0) == 0 {
                previous(info);
            }
        }));
    });
}

/// Leaves the "inside catch_panic" state of the current thread when dropped (also while
/// unwinding).
struct Catching;

impl Catching {
    fn enter() -> Catching {
        CATCHING.with(|c| c.set(c.get() + 1));
        Catching
    }
}

impl Drop for Catching {
    fn drop(&mut self) {
        CATCHING.with(|c| c.set(c.get().saturating_sub(1)));
    }
}

/// Runs `f`, turning a panic inside it (a bug in a parser fed garbage) into a parse error that
/// names the file. The panic is not reported on stderr: the error is the one line the user
/// sees (panics of other threads, and outside `catch_panic`, are reported as before).
pub(crate) fn catch_panic<T>(path: &Path, f: impl FnOnce() -> Result<T, GeomError>) -> Result<T, GeomError> {
    install_quiet_hook();
    let result = {
        let _guard = Catching::enter();
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
    };
    match result {
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

/// Reads a whole input file given directly, within [`Limits::max_file_bytes`].
pub(crate) fn read_input(path: &Path, limits: &Limits) -> Result<Vec<u8>, GeomError> {
    crate::fsutil::read_limited(path, limits.max_file_bytes, Some(Which::FileBytes))
}

/// Reads a file an asset refers to (already resolved inside its folder), within
/// [`Limits::max_referenced_bytes`].
pub(crate) fn read_referenced(path: &Path, limits: &Limits) -> Result<Vec<u8>, GeomError> {
    crate::fsutil::read_limited(path, limits.max_referenced_bytes, Some(Which::ReferencedBytes))
}

/// Decodes an encoded image (PNG or JPEG) into a [`crate::mesh::Texture`]; `Ok(None)` when the
/// bytes are not a decodable image (an unsupported texture only means "no texture"). `used`
/// counts the decoded texture bytes of the mesh so far; a texture that takes it past
/// [`Limits::max_texture_bytes`] is an error naming `path`.
pub(crate) fn decode_texture(
    path: &Path,
    bytes: &[u8],
    used: &mut u64,
    limits: &Limits,
) -> Result<Option<crate::mesh::Texture>, GeomError> {
    let Ok(img) = image::load_from_memory(bytes) else {
        return Ok(None);
    };
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Ok(None);
    }
    let size = 3 * width as u64 * height as u64;
    if used.saturating_add(size) > limits.max_texture_bytes {
        let o = over(Which::TextureBytes, limits.max_texture_bytes);
        return Err(GeomError::invalid(
            path,
            format!("decoded textures would take {} bytes, {o}", used.saturating_add(size)),
        ));
    }
    *used += size;
    let rgb = img.to_rgb8().into_raw().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Ok(Some(crate::mesh::Texture { width, height, rgb }))
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

    #[cfg(unix)]
    #[test]
    fn fifos_devices_and_directories_are_refused_for_every_mesh_format() {
        use crate::test_support::{mkfifo, symlink, within};
        let dir = tempfile::tempdir().unwrap();
        for ext in MESH_EXTENSIONS {
            let fifo = mkfifo(&dir.path().join(format!("f.{ext}")));
            let e = within(10, move || load_mesh(&fifo).map(|m| m.triangles.len())).unwrap_err().to_string();
            assert!(e.contains(&format!("f.{ext}")) && e.contains("not a regular file (it is a FIFO"), "{e}");
            let zero = symlink(Path::new("/dev/zero"), &dir.path().join(format!("z.{ext}")));
            let e = within(10, move || load_mesh(&zero).map(|m| m.triangles.len())).unwrap_err().to_string();
            assert!(e.contains(&format!("z.{ext}")) && e.contains("(it is a character device)"), "{e}");
            let sub = dir.path().join(format!("d.{ext}"));
            std::fs::create_dir(&sub).unwrap();
            let e = load_mesh(&sub).unwrap_err().to_string();
            assert!(e.contains("(it is a directory)"), "{e}");
        }
        // A symlink to a regular file given directly is followed.
        let real =
            crate::test_support::write(dir.path(), "real.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        let link = symlink(&real, &dir.path().join("link.off"));
        assert_eq!(load_mesh(&link).unwrap().triangles.len(), 1);
    }

    #[test]
    fn a_file_over_the_size_limit_is_refused_before_it_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let text = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        for name in ["m.off", "m.obj", "m.glb"] {
            let p = crate::test_support::write(dir.path(), name, text);
            let limits = Limits { max_file_bytes: text.len() as u64 - 1, ..Limits::default() };
            let e = load_mesh_with(&p, &limits).unwrap_err().to_string();
            let want = format!(
                "file of {} bytes is over the limit of {} (OBJVIEW_MAX_FILE_BYTES raises it)",
                text.len(),
                text.len() - 1
            );
            assert!(e.contains(name) && e.contains(&want), "{e}");
        }
        let p = dir.path().join("m.off");
        assert!(
            load_mesh_with(&p, &Limits { max_file_bytes: text.len() as u64, ..Limits::default() }).is_ok()
        );
    }

    /// Run as a child process by `caught_panics_print_no_report`: a caught panic, then an
    /// uncaught one on another thread.
    fn panic_child() {
        let e = catch_panic::<()>(Path::new("p.glb"), || panic!("inside-marker")).unwrap_err();
        eprintln!("error: {e}");
        let _ = std::thread::spawn(|| panic!("outside-marker")).join();
    }

    #[test]
    fn caught_panics_print_no_report() {
        if std::env::var_os("OBJVIEW_GEOM_PANIC_CHILD").is_some() {
            return panic_child();
        }
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "io::tests::caught_panics_print_no_report", "--nocapture", "--test-threads=1"])
            .env("OBJVIEW_GEOM_PANIC_CHILD", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        let inside: Vec<&str> = err.lines().filter(|l| l.contains("inside-marker")).collect();
        assert_eq!(inside, ["error: p.glb: malformed file (parser failed: inside-marker)"], "{err}");
        // Panics outside catch_panic are still reported by the previous hook.
        assert!(err.contains("outside-marker"), "{err}");
    }
}
