//! Helpers shared by the unit tests of the loaders: a watchdog that turns a hang into a test
//! failure, and special files (FIFOs, symlinks) to feed the loaders.

use std::path::{Path, PathBuf};
use std::time::Duration;

/// Runs `f` on its own thread and returns its result; panics (failing the test) if it does not
/// finish within `secs` seconds, so that a loader blocking on a FIFO or looping on a bomb fails
/// the suite instead of stalling it (the stuck thread is abandoned).
pub(crate) fn within<T: Send + 'static>(secs: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(Duration::from_secs(secs)) {
        Ok(v) => v,
        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => panic!("did not finish within {secs} s (hang)"),
        Err(e) => panic!("the checked code panicked: {e}"),
    }
}

/// Creates a FIFO (named pipe) at `path`.
#[cfg(unix)]
pub(crate) fn mkfifo(path: &Path) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: `c` is a valid NUL-terminated path for the duration of the call.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo {}: {}", path.display(), std::io::Error::last_os_error());
    path.to_path_buf()
}

/// Creates a symlink at `link` pointing to `target`.
#[cfg(unix)]
pub(crate) fn symlink(target: &Path, link: &Path) -> PathBuf {
    std::os::unix::fs::symlink(target, link).unwrap();
    link.to_path_buf()
}

/// Writes `bytes` to `dir/name`.
pub(crate) fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}
