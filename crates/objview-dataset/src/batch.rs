//! The loop shared by batch commands: skip what a results file already holds, process the rest
//! in parallel (rayon), and append one line per item in input order as soon as it and every
//! earlier item are finished, so an interrupted batch resumes where it stopped and a finished one
//! is the same file whatever the thread count.

use std::sync::Mutex;

use rayon::prelude::*;

use crate::error::DatasetError;
use crate::inputs::ObjectRef;
use crate::jsonl::{Existing, OrderedWriter, ResumableJsonl};

/// What processing one item gave: its line and whether it is a failure line.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemOutcome {
    /// One JSON line ([`crate::to_line`]).
    pub line: String,
    /// Whether the line records a failure.
    pub failed: bool,
}

/// Counts of a finished batch.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatchSummary {
    /// Items in the input.
    pub total: usize,
    /// Items skipped because the results file already had them.
    pub skipped: usize,
    /// Items processed now.
    pub processed: usize,
    /// Of those, failures.
    pub failed: usize,
}

/// Runs `work` on every item of `items` whose uid is not in `existing.done`, in parallel on the
/// current rayon pool, writing lines to `out` in input order. `progress` is called after each
/// item with the item and its outcome (from worker threads). A write error stops the batch (what
/// was written stays valid and resumable).
pub fn run_batch<W, P>(
    items: &[ObjectRef],
    out: ResumableJsonl,
    existing: &Existing,
    work: W,
    progress: P,
) -> Result<BatchSummary, DatasetError>
where
    W: Fn(&ObjectRef) -> ItemOutcome + Sync,
    P: Fn(&ObjectRef, &ItemOutcome) + Sync,
{
    let todo: Vec<&ObjectRef> = items.iter().filter(|o| !existing.done.contains(&o.uid)).collect();
    let writer = Mutex::new(OrderedWriter::new(out));
    let failed = std::sync::atomic::AtomicUsize::new(0);
    todo.par_iter().enumerate().try_for_each(|(seq, obj)| {
        let outcome = work(obj);
        if outcome.failed {
            failed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        progress(obj, &outcome);
        let mut w = writer.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        w.push(seq, outcome.line).map(|_| ())
    })?;
    Ok(BatchSummary {
        total: items.len(),
        skipped: items.len() - todo.len(),
        processed: todo.len(),
        failed: failed.into_inner(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;
    use std::path::Path;

    fn objs(n: usize) -> Vec<ObjectRef> {
        (0..n).map(|i| ObjectRef::from_mesh(Path::new(&format!("o{i:03}.obj")))).collect()
    }

    fn work(o: &ObjectRef) -> ItemOutcome {
        // Uneven work so that items finish out of order.
        let spin = (o.uid.len() * 7919 + o.uid.bytes().map(usize::from).sum::<usize>()) % 5;
        std::thread::sleep(std::time::Duration::from_millis(spin as u64));
        let failed = o.uid.ends_with('3');
        let v = if failed { json!({"error": "boom", "uid": o.uid}) } else { json!({"uid": o.uid}) };
        ItemOutcome { line: crate::to_line(&v), failed }
    }

    #[test]
    fn output_is_in_input_order_for_any_thread_count() {
        let dir = tempfile::tempdir().unwrap();
        let items = objs(40);
        let mut outputs = Vec::new();
        for threads in [1, 4] {
            let path = dir.path().join(format!("t{threads}.jsonl"));
            let (out, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let s = pool.install(|| run_batch(&items, out, &ex, work, |_, _| {})).unwrap();
            assert_eq!((s.total, s.skipped, s.processed, s.failed), (40, 0, 40, 4));
            outputs.push(std::fs::read_to_string(&path).unwrap());
        }
        assert_eq!(outputs[0], outputs[1]);
        let uids: Vec<String> = outputs[0]
            .lines()
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["uid"].as_str().unwrap().to_string()
            })
            .collect();
        assert_eq!(uids, items.iter().map(|o| o.uid.clone()).collect::<Vec<_>>());
    }

    #[test]
    fn resume_after_a_crash_loses_and_duplicates_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let items = objs(30);
        let full = dir.path().join("full.jsonl");
        let (out, ex) = ResumableJsonl::open(&full, "uid", false).unwrap();
        run_batch(&items, out, &ex, work, |_, _| {}).unwrap();
        let expected = std::fs::read_to_string(&full).unwrap();

        // Simulated crash: the first 17 lines and a torn 18th.
        let crashed = dir.path().join("crashed.jsonl");
        let lines: Vec<&str> = expected.lines().collect();
        let mut text: String = lines[..17].iter().map(|l| format!("{l}\n")).collect();
        text.push_str(&lines[17][..lines[17].len() / 2]);
        std::fs::write(&crashed, text).unwrap();

        let (out, ex) = ResumableJsonl::open(&crashed, "uid", false).unwrap();
        assert!(ex.torn);
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let s = run_batch(&items, out, &ex, work, |_, _| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!((s.skipped, s.processed), (17, 13));
        assert_eq!(calls.into_inner(), 13);
        assert_eq!(std::fs::read_to_string(&crashed).unwrap(), expected);

        // A second resume has nothing left to do.
        let (out, ex) = ResumableJsonl::open(&crashed, "uid", false).unwrap();
        let s = run_batch(&items, out, &ex, work, |_, _| panic!("nothing to redo")).unwrap();
        assert_eq!((s.skipped, s.processed), (30, 0));
        assert_eq!(std::fs::read_to_string(&crashed).unwrap(), expected);
    }
}
