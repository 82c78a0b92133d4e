//! Crash-safe, resumable JSON Lines result files (`annotate`, `run`).
//!
//! A batch writes one JSON object per line and per item. Each line is written whole with one
//! `write` call and synced before the next, so a crash (kill -9, power loss) can leave at most a
//! torn last line. [`ResumableJsonl::open`] reads what an earlier run left: complete lines are
//! kept and their keys reported as done, a torn last line (no trailing newline, or not JSON) is
//! cut off and its item redone. A complete line in the middle that is not a JSON object with the
//! key field means the file is something else: that is an error, nothing is overwritten.
//!
//! Lines whose object has an `error` field are failures; they count as done (a re-run does not
//! retry a broken file forever) unless the caller asks to retry them, in which case they are
//! removed from the file (atomically: rewrite to a temporary file, then rename) and redone.
//!
//! [`OrderedWriter`] lets parallel workers finish in any order while lines reach the file in
//! input order, so a batch's output is the same whatever the number of threads.

use std::collections::{BTreeMap, HashSet};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde_json::Value;

use crate::error::DatasetError;

/// What an earlier run left in a results file.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Existing {
    /// Keys of items with a complete line (failures included unless retried).
    pub done: HashSet<String>,
    /// Complete lines kept.
    pub lines: usize,
    /// Of those, failure lines (with an `error` field).
    pub failed: usize,
    /// Failure lines removed for retry.
    pub retried: usize,
    /// Whether a torn last line was cut off.
    pub torn: bool,
}

/// An append-only JSON Lines file that can resume an earlier run.
#[derive(Debug)]
pub struct ResumableJsonl {
    path: PathBuf,
    file: File,
    sync: bool,
}

impl ResumableJsonl {
    /// Opens (creating it and its parent folder if needed) the results file at `path`, whose lines
    /// are keyed by the string field `key`; see the module docs.
    pub fn open(
        path: &Path,
        key: &str,
        retry_failed: bool,
    ) -> Result<(ResumableJsonl, Existing), DatasetError> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
        }
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| DatasetError::io(path, e))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(|e| DatasetError::io(path, e))?;

        let mut existing = Existing::default();
        let mut keep_end = 0usize; // byte offset after the last complete, valid line
        let mut kept: Vec<(usize, usize)> = Vec::new(); // [start, end) of kept lines incl. newline
        let mut start = 0usize;
        let mut line_no = 0usize;
        while start < bytes.len() {
            line_no += 1;
            let Some(nl) = bytes[start..].iter().position(|&b| b == b'\n') else {
                // No newline: a torn last line.
                existing.torn = true;
                break;
            };
            let end = start + nl + 1;
            let text = &bytes[start..end - 1];
            if text.iter().all(u8::is_ascii_whitespace) {
                start = end;
                keep_end = end;
                continue;
            }
            let parsed: Result<Value, _> = serde_json::from_slice(text);
            let is_last = end == bytes.len();
            let value = match parsed {
                Ok(v) => v,
                Err(_) if is_last => {
                    existing.torn = true;
                    break;
                }
                Err(e) => {
                    return Err(DatasetError::CorruptLine {
                        path: path.to_path_buf(),
                        line: line_no,
                        reason: format!("not JSON ({e})"),
                    })
                }
            };
            let Some(k) = value.get(key).and_then(Value::as_str) else {
                return Err(DatasetError::CorruptLine {
                    path: path.to_path_buf(),
                    line: line_no,
                    reason: format!("no string field '{key}'"),
                });
            };
            let failed = value.get("error").is_some();
            if failed && retry_failed {
                existing.retried += 1;
            } else {
                existing.done.insert(k.to_string());
                existing.lines += 1;
                existing.failed += usize::from(failed);
                kept.push((start, end));
            }
            keep_end = end;
            start = end;
        }

        if existing.retried > 0 {
            // Rewrite without the retried failures, atomically.
            let tmp = path.with_extension("jsonl.tmp");
            let mut out = Vec::with_capacity(keep_end);
            for &(s, e) in &kept {
                out.extend_from_slice(&bytes[s..e]);
            }
            std::fs::write(&tmp, &out).map_err(|e| DatasetError::io(&tmp, e))?;
            File::open(&tmp).and_then(|f| f.sync_all()).map_err(|e| DatasetError::io(&tmp, e))?;
            std::fs::rename(&tmp, path).map_err(|e| DatasetError::io(path, e))?;
            file = OpenOptions::new()
                .read(true)
                .write(true)
                .open(path)
                .map_err(|e| DatasetError::io(path, e))?;
            keep_end = out.len();
        } else if keep_end < bytes.len() {
            file.set_len(keep_end as u64).map_err(|e| DatasetError::io(path, e))?;
        }
        file.seek(SeekFrom::Start(keep_end as u64)).map_err(|e| DatasetError::io(path, e))?;
        Ok((ResumableJsonl { path: path.to_path_buf(), file, sync: true }, existing))
    }

    /// Whether each line is synced to disk before the next (default true).
    pub fn set_sync(&mut self, sync: bool) {
        self.sync = sync;
    }

    /// Appends one value as one line (one write call), then syncs. Struct fields keep their
    /// declaration order.
    pub fn append<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), DatasetError> {
        self.append_line(&to_line(value))
    }

    /// Appends an already serialized line ([`to_line`]), then syncs.
    pub fn append_line(&mut self, line: &str) -> Result<(), DatasetError> {
        debug_assert!(line.ends_with('\n') && !line[..line.len() - 1].contains('\n'));
        self.file.write_all(line.as_bytes()).map_err(|e| DatasetError::io(&self.path, e))?;
        if self.sync {
            self.file.sync_data().map_err(|e| DatasetError::io(&self.path, e))?;
        }
        Ok(())
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// One JSON line (compact JSON and a newline).
pub fn to_line<T: Serialize + ?Sized>(value: &T) -> String {
    let mut line = serde_json::to_string(value).expect("results always serialize to JSON");
    line.push('\n');
    line
}

/// Writes items finished in any order to a [`ResumableJsonl`] in sequence order 0, 1, 2, …:
/// an item waits in memory until every earlier one is written.
#[derive(Debug)]
pub struct OrderedWriter {
    out: ResumableJsonl,
    next: usize,
    pending: BTreeMap<usize, String>,
}

impl OrderedWriter {
    /// Starts at sequence number 0.
    pub fn new(out: ResumableJsonl) -> OrderedWriter {
        OrderedWriter { out, next: 0, pending: BTreeMap::new() }
    }

    /// Hands over item `seq` as a line ([`to_line`]); writes it and every waiting successor that
    /// is now next. Returns how many lines were written.
    pub fn push(&mut self, seq: usize, line: String) -> Result<usize, DatasetError> {
        self.pending.insert(seq, line);
        let mut written = 0;
        while let Some(line) = self.pending.remove(&self.next) {
            self.out.append_line(&line)?;
            self.next += 1;
            written += 1;
        }
        Ok(written)
    }

    /// Items still waiting for an earlier one.
    pub fn waiting(&self) -> usize {
        self.pending.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn read(path: &Path) -> String {
        std::fs::read_to_string(path).unwrap()
    }

    #[test]
    fn fresh_file_then_resume_skips_done_items() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/out.jsonl");
        let (mut w, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
        assert_eq!(ex, Existing::default());
        w.append(&json!({"uid": "a", "x": 1})).unwrap();
        w.append(&json!({"error": "bad", "uid": "b"})).unwrap();
        drop(w);
        let (mut w, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
        assert_eq!(ex.lines, 2);
        assert_eq!(ex.failed, 1);
        assert!(ex.done.contains("a") && ex.done.contains("b"));
        w.append(&json!({"uid": "c"})).unwrap();
        assert_eq!(
            read(&path),
            "{\"uid\":\"a\",\"x\":1}\n{\"error\":\"bad\",\"uid\":\"b\"}\n{\"uid\":\"c\"}\n"
        );
    }

    #[test]
    fn torn_last_line_is_cut_and_redone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.jsonl");
        for torn in ["{\"uid\":\"b\",\"x\":[1,2", "{\"uid\":\"b\",\"x\":[1,2\n"] {
            std::fs::write(&path, format!("{{\"uid\":\"a\"}}\n{torn}")).unwrap();
            let (mut w, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
            assert!(ex.torn, "{torn}");
            assert_eq!(ex.done.len(), 1);
            assert!(!ex.done.contains("b"));
            w.append(&json!({"uid": "b"})).unwrap();
            assert_eq!(read(&path), "{\"uid\":\"a\"}\n{\"uid\":\"b\"}\n");
        }
    }

    #[test]
    fn corrupt_middle_lines_are_errors_and_leave_the_file_alone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.jsonl");
        for (text, needle) in [
            ("{\"uid\":\"a\"}\nnot json\n{\"uid\":\"c\"}\n", "line 2: not JSON"),
            ("{\"uid\":\"a\"}\n{\"id\":\"b\"}\n", "line 2: no string field 'uid'"),
        ] {
            std::fs::write(&path, text).unwrap();
            let msg = ResumableJsonl::open(&path, "uid", false).unwrap_err().to_string();
            assert!(msg.contains(needle) && msg.contains("out.jsonl"), "{msg}");
            assert_eq!(read(&path), text);
        }
    }

    #[test]
    fn retry_failed_removes_failure_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.jsonl");
        std::fs::write(
            &path,
            "{\"uid\":\"a\"}\n{\"uid\":\"b\",\"error\":\"e\"}\n{\"uid\":\"c\"}\n{\"uid\":\"d\",\"x\":",
        )
        .unwrap();
        let (mut w, ex) = ResumableJsonl::open(&path, "uid", true).unwrap();
        assert_eq!((ex.lines, ex.failed, ex.retried), (2, 0, 1));
        assert!(ex.torn);
        assert!(!ex.done.contains("b") && !ex.done.contains("d"));
        w.append(&json!({"uid": "b"})).unwrap();
        assert_eq!(read(&path), "{\"uid\":\"a\"}\n{\"uid\":\"c\"}\n{\"uid\":\"b\"}\n");
    }

    #[test]
    fn ordered_writer_restores_sequence_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.jsonl");
        let (w, _) = ResumableJsonl::open(&path, "uid", false).unwrap();
        let mut ow = OrderedWriter::new(w);
        assert_eq!(ow.push(2, to_line(&json!({"uid": "2"}))).unwrap(), 0);
        assert_eq!(ow.push(1, to_line(&json!({"uid": "1"}))).unwrap(), 0);
        assert_eq!(ow.waiting(), 2);
        assert_eq!(ow.push(0, to_line(&json!({"uid": "0"}))).unwrap(), 3);
        assert_eq!(ow.push(3, to_line(&json!({"uid": "3"}))).unwrap(), 1);
        assert_eq!(read(&path), "{\"uid\":\"0\"}\n{\"uid\":\"1\"}\n{\"uid\":\"2\"}\n{\"uid\":\"3\"}\n");
    }
}
