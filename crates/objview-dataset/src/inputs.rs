//! Which objects a batch command works on.
//!
//! Every command that takes objects (`annotate`, `pool`, `run`, …) accepts the same inputs: mesh
//! files, folders (searched recursively for every supported mesh format) and split files (JSON
//! arrays of objects, SPEC §6). They resolve to a list of [`ObjectRef`]s in a deterministic order
//! (inputs in the order given; a folder's files sorted by path), each with its object id (`uid`):
//! the file stem of a mesh file, or the split file's `uid` field.
//!
//! [`Shard`] takes a deterministic 1/N of a list by a hash of the uid (not by position), so that
//! a shard keeps the same objects when the folder listing of another machine is ordered
//! differently and N machines together annotate each object exactly once.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde_json::Value;

use crate::error::DatasetError;

/// The mesh formats accepted in folders, for messages.
const MESH_FORMATS: &str = "obj, ply, stl, off, gltf, glb";

/// One object of a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectRef {
    /// Object id: the mesh file stem, or a split file's `uid`.
    pub uid: String,
    /// The mesh file (split-file paths resolved against the split file's folder).
    pub mesh: PathBuf,
    /// The ground-truth cloud named by a split file, if any.
    pub gt_cloud: Option<PathBuf>,
    /// The `annotation` object of a split file entry, if any.
    pub annotation: Option<Value>,
}

impl ObjectRef {
    /// An object from a mesh file: uid = file stem.
    pub fn from_mesh(path: &Path) -> ObjectRef {
        let uid = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        ObjectRef { uid, mesh: path.to_path_buf(), gt_cloud: None, annotation: None }
    }
}

/// Whether `path` names a split file (by its `.json` extension; glTF uses `.gltf`).
pub fn is_split_file(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// Resolves command-line inputs to objects (see the module docs). Errors name the input: a path
/// that does not exist or is of an unsupported type, a split file that does not parse, or two
/// inputs with the same uid (results are keyed by uid, so this would be ambiguous).
pub fn resolve_inputs(inputs: &[PathBuf]) -> Result<Vec<ObjectRef>, DatasetError> {
    let mut out = Vec::new();
    for input in inputs {
        let meta = std::fs::metadata(input).map_err(|e| DatasetError::io(input, e))?;
        if meta.is_dir() {
            let mut files = Vec::new();
            walk(input, &mut files)?;
            files.sort();
            out.extend(files.iter().map(|f| ObjectRef::from_mesh(f)));
        } else if is_split_file(input) {
            out.extend(read_split(input)?);
        } else if objview_geom::io::is_mesh_file(input) {
            out.push(ObjectRef::from_mesh(input));
        } else {
            return Err(DatasetError::UnsupportedInput { path: input.clone(), expected: MESH_FORMATS });
        }
    }
    let mut seen: HashMap<&str, &Path> = HashMap::new();
    for o in &out {
        if let Some(first) = seen.insert(&o.uid, &o.mesh) {
            return Err(DatasetError::DuplicateUid {
                uid: o.uid.clone(),
                first: first.to_path_buf(),
                second: o.mesh.clone(),
            });
        }
    }
    Ok(out)
}

/// Mesh files under `dir`, recursively (hidden entries skipped).
fn walk(dir: &Path, files: &mut Vec<PathBuf>) -> Result<(), DatasetError> {
    let entries = std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| DatasetError::io(dir, e))?;
        let path = entry.path();
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        let kind = entry.file_type().map_err(|e| DatasetError::io(&path, e))?;
        let is_dir = if kind.is_symlink() { path.is_dir() } else { kind.is_dir() };
        if is_dir {
            walk(&path, files)?;
        } else if objview_geom::io::is_mesh_file(&path) {
            files.push(path);
        }
    }
    Ok(())
}

/// Reads a split file (SPEC §6): a JSON array of objects with `uid` (defaults to the mesh stem),
/// `mesh` (or the paper's `obj_path`), optional `gt_cloud` (or `pcd_path`) and optional
/// `annotation`. Relative paths are relative to the split file's folder.
pub fn read_split(path: &Path) -> Result<Vec<ObjectRef>, DatasetError> {
    let text = objview_geom::fsutil::read_text(path).map_err(|e| DatasetError::io(path, e))?;
    let bad = |reason: String| DatasetError::SplitFile { path: path.to_path_buf(), reason };
    let value: Value = serde_json::from_str(&text).map_err(|e| bad(format!("invalid JSON: {e}")))?;
    let Value::Array(items) = value else {
        return Err(bad("expected a JSON array of objects".into()));
    };
    let base = path.parent().unwrap_or(Path::new(""));
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let Value::Object(map) = item else {
            return Err(bad(format!("[{i}]: expected an object, got {}", type_name(item))));
        };
        let string_field = |names: &[&str]| -> Result<Option<String>, DatasetError> {
            for name in names {
                match map.get(*name) {
                    None | Some(Value::Null) => continue,
                    // Ids and paths with control characters (a newline in a file name) are
                    // corrupt input; they would also break one-line messages and outputs.
                    Some(Value::String(s)) if s.chars().any(char::is_control) => {
                        return Err(bad(format!(
                            "[{i}].{name}: contains a control character ('{}')",
                            crate::error::one_line(s)
                        )))
                    }
                    Some(Value::String(s)) if !s.is_empty() => return Ok(Some(s.clone())),
                    Some(other) => {
                        return Err(bad(format!(
                            "[{i}].{name}: expected a non-empty string, got {}",
                            type_name(other)
                        )))
                    }
                }
            }
            Ok(None)
        };
        let Some(mesh) = string_field(&["mesh", "obj_path"])? else {
            return Err(bad(format!("[{i}]: missing field 'mesh' (or 'obj_path')")));
        };
        let mesh = base.join(mesh);
        let uid = match string_field(&["uid"])? {
            Some(uid) => uid,
            None => ObjectRef::from_mesh(&mesh).uid,
        };
        let gt_cloud = string_field(&["gt_cloud", "pcd_path"])?.map(|p| base.join(p));
        let annotation = match map.get("annotation") {
            None | Some(Value::Null) => None,
            Some(v @ Value::Object(_)) => Some(v.clone()),
            Some(other) => {
                return Err(bad(format!("[{i}].annotation: expected an object, got {}", type_name(other))))
            }
        };
        out.push(ObjectRef { uid, mesh, gt_cloud, annotation });
    }
    Ok(out)
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// `--shard I/N`: the I-th of N disjoint parts of a batch (0 ≤ I < N).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// Which part this is, I (0-based, less than `count`).
    pub index: u64,
    /// Number of parts, N (at least 1).
    pub count: u64,
}

impl Shard {
    /// The whole batch.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Whether the object `uid` belongs to this shard: FNV-1a 64 of the uid's bytes, mod N.
    pub fn contains(&self, uid: &str) -> bool {
        fnv1a64(uid.as_bytes()) % self.count == self.index
    }

    /// The objects of `objects` in this shard, order kept.
    pub fn select(&self, objects: Vec<ObjectRef>) -> Vec<ObjectRef> {
        objects.into_iter().filter(|o| self.contains(&o.uid)).collect()
    }
}

impl FromStr for Shard {
    type Err = DatasetError;
    fn from_str(s: &str) -> Result<Shard, DatasetError> {
        let bad = || DatasetError::Shard(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: u64 = i.trim().parse().map_err(|_| bad())?;
        let count: u64 = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// 64-bit FNV-1a: a fixed, platform-independent hash (std's hasher is randomly seeded).
pub use objview_geom::hash::fnv1a64;

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(p: &Path) {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, b"x").unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_or_device_given_as_split_file_is_an_error_not_a_hang() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pool.json");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let zero = dir.path().join("zero.json");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send((
                read_split(&fifo).unwrap_err().to_string(),
                read_split(&zero).unwrap_err().to_string(),
            ));
        });
        let (a, b) = rx.recv_timeout(std::time::Duration::from_secs(20)).expect("reading a FIFO hung");
        assert!(a.contains("pool.json") && a.contains("FIFO"), "{a}");
        assert!(b.contains("zero.json") && b.contains("character device"), "{b}");
    }

    #[test]
    fn folders_are_walked_recursively_and_sorted() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["b/z.glb", "a.obj", "b/c/y.PLY", "notes.txt", ".hidden/q.obj", "b/x.stl"] {
            touch(&dir.path().join(f));
        }
        let objs = resolve_inputs(&[dir.path().to_path_buf()]).unwrap();
        let uids: Vec<&str> = objs.iter().map(|o| o.uid.as_str()).collect();
        assert_eq!(uids, ["a", "y", "x", "z"]);
    }

    #[test]
    fn split_files_resolve_relative_paths_and_aliases() {
        let dir = tempfile::tempdir().unwrap();
        let split = dir.path().join("s/split.json");
        touch(&split);
        std::fs::write(
            &split,
            r#"[{"uid":"u1","mesh":"m/1.obj","gt_cloud":"c/1.pcd","annotation":{"d_plan":3}},
                {"obj_path":"/abs/2.glb","pcd_path":"2.ply"},
                {"uid":"u3","mesh":"3.off","gt_cloud":null}]"#,
        )
        .unwrap();
        let objs = resolve_inputs(std::slice::from_ref(&split)).unwrap();
        let base = dir.path().join("s");
        assert_eq!(objs[0].uid, "u1");
        assert_eq!(objs[0].mesh, base.join("m/1.obj"));
        assert_eq!(objs[0].gt_cloud, Some(base.join("c/1.pcd")));
        assert_eq!(objs[0].annotation.as_ref().unwrap()["d_plan"], 3);
        assert_eq!(objs[1].uid, "2");
        assert_eq!(objs[1].mesh, PathBuf::from("/abs/2.glb"));
        assert_eq!(objs[1].gt_cloud, Some(base.join("2.ply")));
        assert_eq!(objs[2].gt_cloud, None);
    }

    #[test]
    fn bad_split_files_name_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let split = dir.path().join("bad.json");
        for (text, needle) in [
            ("{}", "expected a JSON array"),
            ("[1]", "[0]: expected an object, got a number"),
            (r#"[{"uid":"a"}]"#, "[0]: missing field 'mesh'"),
            (r#"[{"mesh":5}]"#, "[0].mesh: expected a non-empty string, got a number"),
            (r#"[{"mesh":"a.obj","annotation":[]}]"#, "[0].annotation: expected an object"),
            (r#"[{"mesh":"a\n.obj"}]"#, "[0].mesh: contains a control character ('a\\n.obj')"),
            (r#"[{"mesh":"a.obj","uid":"x\ty"}]"#, "[0].uid: contains a control character ('x\\ty')"),
            (r#"[{"mesh":"a.obj","gt_cloud":"\u001b[31m"}]"#, "[0].gt_cloud: contains a control character"),
            ("[", "invalid JSON"),
        ] {
            std::fs::write(&split, text).unwrap();
            let msg = resolve_inputs(std::slice::from_ref(&split)).unwrap_err().to_string();
            assert!(msg.contains("bad.json") && msg.contains(needle), "{text}: {msg}");
            assert!(!msg.contains('\n'), "one line: {msg:?}");
        }
    }

    #[test]
    fn duplicates_missing_and_unsupported_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("x/a.obj"), dir.path().join("y/a.ply"));
        touch(&a);
        touch(&b);
        let msg = resolve_inputs(&[a.clone(), b.clone()]).unwrap_err().to_string();
        assert!(msg.contains("duplicate object id 'a'"), "{msg}");
        // Ids and paths from a folder walk may hold a newline: the message stays one line.
        let (c, d) = (dir.path().join("p/new\nline.obj"), dir.path().join("q/new\nline.ply"));
        touch(&c);
        touch(&d);
        let msg = resolve_inputs(&[c, d]).unwrap_err().to_string();
        assert!(msg.contains("duplicate object id 'new\\nline'") && !msg.contains('\n'), "{msg:?}");
        let missing = dir.path().join("nope.obj");
        assert!(resolve_inputs(&[missing]).unwrap_err().to_string().contains("nope.obj"));
        let txt = dir.path().join("t.txt");
        touch(&txt);
        assert!(resolve_inputs(&[txt]).unwrap_err().to_string().contains("not a mesh file"));
    }

    #[test]
    fn shards_partition_the_batch() {
        let objs: Vec<ObjectRef> =
            (0..500).map(|i| ObjectRef::from_mesh(Path::new(&format!("{i:04x}.glb")))).collect();
        let mut all: Vec<String> = Vec::new();
        for i in 0..4 {
            let shard: Shard = format!("{i}/4").parse().unwrap();
            let part = shard.select(objs.clone());
            assert!(part.len() > 80 && part.len() < 170, "{}", part.len());
            all.extend(part.into_iter().map(|o| o.uid));
        }
        all.sort();
        let mut expected: Vec<String> = objs.iter().map(|o| o.uid.clone()).collect();
        expected.sort();
        assert_eq!(all, expected);
        assert_eq!(Shard::ALL.select(objs.clone()).len(), 500);
        for bad in ["4/4", "1", "a/2", "0/0", "-1/3"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
        // FNV-1a reference values (from the algorithm's published test vectors).
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
