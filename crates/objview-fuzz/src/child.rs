//! The child side: runs a list of cases through one kind's loader and reports each outcome on
//! stdout as it goes, so that when the process dies the parent knows which case killed it.
//!
//! Protocol (one line per `write(2)` call, unbuffered, so nothing is lost when the process
//! aborts): `@@ovf start ID`, then one of `@@ovf ok ID TEXT`, `@@ovf error ID TEXT`,
//! `@@ovf invalid ID TEXT`, `@@ovf panic ID caught|uncaught LOCATION MESSAGE`,
//! `@@ovf oom-recovered ID TEXT` (an allocation failed under the memory limit but the loader
//! went on: it still tried to use unbounded memory); `@@ovf oom BYTES` when an allocation fails
//! (written by [`OomMarker`], the binary's global allocator, before the runtime aborts);
//! `@@ovf done` at the end. Lines without the prefix (a library printing to stdout) are ignored.
//!
//! A panic hook records every panic, including one that the loader catches itself and turns
//! into an error (the mesh loaders' last line of defence): that is still a bug, and reported.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use crate::kinds::{Kind, Loaded};

/// Prefix of protocol lines.
pub const PREFIX: &str = "@@ovf ";

/// Writes all of `bytes` to fd 1 with `write(2)` (no allocation, no buffering).
fn raw_write(bytes: &[u8]) {
    let mut off = 0;
    while off < bytes.len() {
        // SAFETY: the pointer and length describe the live slice `bytes[off..]`.
        let n = unsafe { libc::write(1, bytes[off..].as_ptr().cast(), bytes.len() - off) };
        if n <= 0 {
            return;
        }
        off += n as usize;
    }
}

/// One text field of a protocol line: on one line, at most 400 characters.
pub fn one_line(s: &str) -> String {
    let s: String = s.chars().map(|c| if c == '\n' || c == '\r' { ' ' } else { c }).collect();
    match s.char_indices().nth(400) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s,
    }
}

fn emit(line: &str) {
    raw_write(format!("{PREFIX}{line}\n").as_bytes());
}

/// The system allocator, announcing failed allocations on stdout before the runtime aborts, so
/// that the parent can tell "out of memory" from other aborts.
pub struct OomMarker;

// SAFETY: every call is forwarded unchanged to `System`; the failure path only writes bytes
// from the stack to fd 1.
unsafe impl GlobalAlloc for OomMarker {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if p.is_null() {
            oom_line(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if p.is_null() {
            oom_line(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if p.is_null() {
            oom_line(new_size);
        }
        p
    }
}

/// Size + 1 of the first allocation that failed since the last [`take_failed_alloc`] (0: none).
static FAILED_ALLOC: AtomicU64 = AtomicU64::new(0);

/// The size of an allocation that failed since the last call, if any (the loader may have
/// recovered from it, as `try_reserve` and `std::fs::read` do: still unbounded memory).
pub fn take_failed_alloc() -> Option<u64> {
    match FAILED_ALLOC.swap(0, Ordering::Relaxed) {
        0 => None,
        n => Some(n - 1),
    }
}

/// `@@ovf oom SIZE\n`, formatted on the stack.
fn oom_line(size: usize) {
    let _ = FAILED_ALLOC.compare_exchange(0, size as u64 + 1, Ordering::Relaxed, Ordering::Relaxed);
    let mut buf = [0u8; 48];
    let head = b"@@ovf oom ";
    buf[..head.len()].copy_from_slice(head);
    let mut digits = [0u8; 20];
    let mut n = size;
    let mut k = digits.len();
    loop {
        k -= 1;
        digits[k] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    let d = &digits[k..];
    buf[head.len()..head.len() + d.len()].copy_from_slice(d);
    buf[head.len() + d.len()] = b'\n';
    raw_write(&buf[..head.len() + d.len() + 1]);
}

/// The last panic seen by the hook: (location, message).
static PANIC: Mutex<Option<(String, String)>> = Mutex::new(None);

fn install_hook() {
    std::panic::set_hook(Box::new(|info| {
        let loc =
            info.location().map_or_else(|| "unknown".to_string(), |l| format!("{}:{}", l.file(), l.line()));
        let p = info.payload();
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "non-string panic payload".into());
        if let Ok(mut g) = PANIC.lock() {
            // Keep the first panic of the case (a panic while unwinding would abort anyway).
            if g.is_none() {
                *g = Some((loc, msg));
            }
        }
    }));
}

fn take_panic() -> Option<(String, String)> {
    PANIC.lock().map(|mut g| g.take()).unwrap_or_else(|p| p.into_inner().take())
}

/// Runs the cases listed in `list` (lines `ID<TAB>PATH`) through `kind`'s loader, reporting on
/// stdout. Returns the process exit code (0; a crash never returns).
pub fn child_main(kind: Kind, list: &Path) -> i32 {
    install_hook();
    let text = match std::fs::read_to_string(list) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("objview-fuzz child: cannot read {}: {e}", list.display());
            return 2;
        }
    };
    for line in text.lines() {
        let Some((id, path)) = line.split_once('\t') else { continue };
        emit(&format!("start {id}"));
        let _ = take_panic();
        let _ = take_failed_alloc();
        let result = std::panic::catch_unwind(|| kind.load(Path::new(path)));
        let panic = take_panic();
        let failed_alloc = take_failed_alloc();
        let report = match (result, panic) {
            (_, None) if failed_alloc.is_some() => format!(
                "oom-recovered {id} an allocation of {} bytes failed under the memory limit (the loader recovered)",
                failed_alloc.unwrap_or(0)
            ),
            (Err(_), p) => {
                let (loc, msg) = p.unwrap_or_else(|| ("unknown".into(), "panic without hook record".into()));
                format!("panic {id} uncaught {} {}", one_line(&loc), one_line(&msg))
            }
            (Ok(_), Some((loc, msg))) => format!("panic {id} caught {} {}", one_line(&loc), one_line(&msg)),
            (Ok(Loaded::Ok(s)), None) => format!("ok {id} {}", one_line(&s)),
            (Ok(Loaded::Error(e)), None) => {
                if e.trim().is_empty() || e.contains('\n') {
                    format!("invalid {id} error message is not one line: {}", one_line(&format!("{e:?}")))
                } else {
                    format!("error {id} {}", one_line(&e))
                }
            }
            (Ok(Loaded::Invalid(why)), None) => format!("invalid {id} {}", one_line(&why)),
        };
        emit(&report);
    }
    emit("done");
    0
}
