//! The harness can fail: the fake `test-*` kinds panic, abort, hang and allocate without bound,
//! and each is classified as such — alone, inside a batch of other cases, and in a campaign,
//! whose findings are written, shrunk, and then fail a replay.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use objview_fuzz::exec::{Executor, Limits};
use objview_fuzz::{fuzz, replay, Class, Kind, Settings};

fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_objview-fuzz"))
}

fn limits() -> Limits {
    Limits { timeout: Duration::from_millis(2500), mem_bytes: 512 << 20 }
}

fn executor(dir: &tempfile::TempDir) -> Executor {
    Executor { exe: exe(), limits: limits(), work: dir.path().join("exec") }
}

fn file(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn each_failure_is_classified() {
    let dir = tempfile::tempdir().unwrap();
    let ex = executor(&dir);
    let f = file(&dir, "x.bin", b"anything");
    for (kind, class) in [
        (Kind::TestPanic, Class::Panic),
        (Kind::TestAbort, Class::Abort),
        (Kind::TestHang, Class::Timeout),
        (Kind::TestOom, Class::Oom),
    ] {
        let o = ex.run_one(kind, &f).unwrap();
        assert_eq!(o.class, class, "{}: {o:?}", kind.name());
    }
    // A panic the loader itself catches is still a panic.
    let o = ex.run_one(Kind::TestMixed, &file(&dir, "c.bin", &[2])).unwrap();
    assert_eq!(o.class, Class::Panic, "{o:?}");
    assert!(o.detail.contains("caught by the loader"), "{o:?}");
    // So is an allocation beyond the limit that the loader survives (`try_reserve`).
    let o = ex.run_one(Kind::TestMixed, &file(&dir, "r.bin", b"R")).unwrap();
    assert_eq!(o.class, Class::Oom, "{o:?}");
    assert!(o.detail.contains("recovered"), "{o:?}");
}

#[test]
fn crashes_inside_a_batch_are_isolated() {
    let dir = tempfile::tempdir().unwrap();
    let ex = executor(&dir);
    // test-mixed: first byte 0 ok, 1 error, 3 panic, 4 abort, 5 out of memory, 'H' hangs, 'R'
    // recovers from a failed allocation.
    let bytes: [&[u8]; 9] = [&[0], &[4], &[1], b"H", &[3], &[5], b"R", &[6], &[7]];
    let cases: Vec<(u64, PathBuf)> =
        bytes.iter().enumerate().map(|(i, b)| (i as u64 * 10, file(&dir, &format!("{i}.bin"), b))).collect();
    let got: Vec<(u64, Class)> =
        ex.run(Kind::TestMixed, &cases).unwrap().into_iter().map(|(id, o)| (id, o.class)).collect();
    assert_eq!(
        got,
        vec![
            (0, Class::Ok),
            (10, Class::Abort),
            (20, Class::Error),
            (30, Class::Timeout),
            (40, Class::Panic),
            (50, Class::Oom),
            (60, Class::Oom),
            (70, Class::Ok),
            (80, Class::Error),
        ]
    );
}

#[test]
fn a_campaign_keeps_shrunk_findings_that_then_fail_replay() {
    let out = tempfile::tempdir().unwrap();
    let mut s = Settings::new(exe(), 7);
    s.kinds = vec![Kind::TestMixed];
    s.seconds = 60.0;
    s.max_cases = Some(40);
    s.batch = 8;
    s.limits = limits();
    s.out = Some(out.path().to_path_buf());
    let summary = fuzz(&s).unwrap();
    let st = &summary.kinds[0].1;
    assert_eq!(st.cases, 40);
    assert!(st.ok > 0 && st.errors > 0 && st.findings > 0, "{st:?}");
    let classes: BTreeSet<Class> = summary.findings.iter().map(|f| f.class).collect();
    for c in [Class::Panic, Class::Abort, Class::Oom] {
        assert!(classes.contains(&c), "{c:?} not found: {:?}", summary.findings);
    }
    // The behaviour depends on the first byte only: shrinking keeps one byte.
    for f in summary.findings.iter().filter(|f| f.class != Class::Timeout) {
        assert_eq!(f.bytes, 1, "{f:?}");
        assert!(f.file.as_ref().unwrap().is_file(), "{f:?}");
    }
    let log = std::fs::read_to_string(out.path().join("findings.txt")).unwrap();
    assert!(log.contains("kind=test-mixed seed=7 case=") && log.contains("class=abort"), "{log}");
    // Same seed, same campaign.
    let out2 = tempfile::tempdir().unwrap();
    let again = fuzz(&Settings { out: Some(out2.path().to_path_buf()), ..s.clone() }).unwrap();
    let key = |v: &[objview_fuzz::Finding]| v.iter().map(|f| (f.case, f.class)).collect::<Vec<_>>();
    assert_eq!(key(&again.findings), key(&summary.findings));
    assert_eq!(again.signatures, summary.signatures);
    // The kept files fail a replay.
    let r = replay(out.path(), &exe(), limits(), true).unwrap();
    assert_eq!(r.len(), summary.findings.len());
    assert!(r.iter().all(|r| r.outcome.class.is_finding()), "{r:?}");
}

#[test]
fn command_line_exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let f = file(&dir, "x.bin", &[0]);
    let run = |args: &[&str]| Command::new(exe()).args(args).output().unwrap();
    // Test kinds need the explicit flag.
    let o = run(&["one", "test-panic", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let o = run(&["one", "test-panic", f.to_str().unwrap(), "--allow-test-kinds"]);
    assert_eq!(o.status.code(), Some(1), "{o:?}");
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("panic:"), "{o:?}");
    let o = run(&["one", "test-mixed", f.to_str().unwrap(), "--allow-test-kinds"]);
    assert_eq!(o.status.code(), Some(0), "{o:?}");
    // A clean error of a real loader.
    let g = file(&dir, "bad.off", b"not an off file");
    let o = run(&["one", "off", g.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{o:?}");
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("error:"), "{o:?}");
}
