//! `objview objects synth --count N --seed S` (random training pools) and
//! `objview objects list --families`: deterministic bytes, pools that grow by appending, the
//! manifest, and a pool folder that `annotate` takes as it is (the manifest is not an input).

mod common;

use common::{objview_err, objview_ok, read, s, tempdir};
use serde_json::Value;
use std::path::Path;

fn files(d: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    v.sort();
    v
}

#[test]
fn random_pools_are_deterministic_grow_by_appending_and_list_their_families() {
    let dir = tempdir();
    let (a, b, c) = (dir.path().join("a"), dir.path().join("b"), dir.path().join("c"));
    let out = objview_ok(&["objects", "synth", "--count", "6", "--seed", "9", "--out", s(&a)]);
    assert!(out.contains("wrote 6 random objects (seed 9"), "{out}");
    objview_ok(&["objects", "synth", "--count", "6", "--seed", "9", "--out", s(&b)]);
    objview_ok(&["objects", "synth", "--count", "3", "--seed", "9", "--out", s(&c)]);
    let fa = files(&a);
    assert_eq!(fa, files(&b));
    for f in &fa {
        assert!(read(&a.join(f)) == read(&b.join(f)), "{f} differs between two runs");
    }
    let objs: Vec<&String> = fa.iter().filter(|f| f.ends_with(".obj")).collect();
    assert_eq!(objs.len(), 6);
    assert!(fa.contains(&"synth.json".to_string()));
    // The smaller pool is the start of the larger one.
    let fc: Vec<String> = files(&c).into_iter().filter(|f| f != "synth.json").collect();
    assert_eq!(fc.len(), 6, "{fc:?}");
    for f in &fc {
        assert!(read(&a.join(f)) == read(&c.join(f)), "{f} differs between --count 3 and 6");
    }

    // Manifest: settings and one entry per object, named after its family.
    let m: Value = serde_json::from_slice(&read(&a.join("synth.json"))).unwrap();
    assert_eq!((m["seed"].as_u64(), m["count"].as_u64()), (Some(9), Some(6)));
    let listed = objview_ok(&["objects", "list", "--families"]);
    let families: Vec<&str> = listed.lines().map(|l| l.split_whitespace().next().unwrap()).collect();
    assert!(families.len() >= 30, "{listed}");
    assert_eq!(m["families"].as_array().unwrap().len(), families.len());
    for (i, o) in m["objects"].as_array().unwrap().iter().enumerate() {
        let (name, family) = (o["name"].as_str().unwrap(), o["family"].as_str().unwrap());
        assert_eq!(name, format!("p9-{i:05}-{family}"));
        assert!(families.contains(&family), "{family}");
        assert!(objs.contains(&&format!("{name}.obj")));
        assert!(o["params"].is_object());
        let tris = o["triangles"].as_u64().unwrap();
        assert!((2_000..=30_000).contains(&tris), "{name}: {tris} triangles");
    }

    // Without --count the built-in pool is written as before; --seed alone is refused.
    let builtin = dir.path().join("builtin");
    objview_ok(&["objects", "synth", "--out", s(&builtin)]);
    assert!(builtin.join("cube.obj").exists() && !builtin.join("synth.json").exists());
    let err = objview_err(&["objects", "synth", "--seed", "3", "--out", s(&dir.path().join("x"))]);
    assert!(err.contains("--count"), "{err}");
}

#[test]
fn annotate_takes_a_random_pool_folder() {
    let dir = tempdir();
    let pool = dir.path().join("pool");
    objview_ok(&["objects", "synth", "--count", "1", "--seed", "4", "--out", s(&pool)]);
    let out = dir.path().join("ann.jsonl");
    objview_ok(&["annotate", s(&pool), "--out", s(&out), "--threads", "2", "--time-limit", "5"]);
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 1, "{text}");
    assert!(lines[0]["uid"].as_str().unwrap().starts_with("p4-00000-"), "{text}");
    assert!(lines[0].get("error").is_none(), "{text}");
}

/// A reader that goes away (`objview objects list | head -1`) ends the command quietly by
/// SIGPIPE, as Unix tools do, instead of a panic with a backtrace ("failed printing to stdout:
/// Broken pipe"). The pipe's read end is closed before the command starts, so its first write
/// meets the closed pipe whatever the timing.
#[cfg(unix)]
#[test]
fn a_closed_output_pipe_ends_the_command_quietly() {
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::os::unix::process::ExitStatusExt;
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: `pipe` fills two new descriptors, each then owned by exactly one OwnedFd.
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0, "pipe");
    let (read_end, write_end) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
    drop(read_end);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_objview"))
        .args(["objects", "list"])
        .stdout(std::process::Stdio::from(write_end))
        .stderr(std::process::Stdio::piped())
        .output()
        .expect("running objview");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.is_empty(), "stderr: {stderr}");
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{}", out.status);
}
