//! The loop shared by batch commands (`annotate`, `run`, `pool build`): skip what a results
//! file already holds, process the rest in parallel (rayon), and append one line per item in
//! input order as soon as it and every earlier item are finished, so an interrupted batch
//! resumes where it stopped and a finished one is the same file whatever the thread count.
//!
//! [`drive`] is the one batch driver: it builds the worker pool, announces the batch
//! ([`BatchStart`]), runs [`run_batch`] and hands every finished item to a [`Progress`] as a
//! typed [`ItemProgress`] — the item's own one-line note, made from the typed value that also
//! became its line, so nothing re-parses the JSON it just wrote.

use std::fmt;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::error::DatasetError;
use crate::inputs::ObjectRef;
use crate::jsonl::{Existing, OrderedWriter, ResumableJsonl};

/// What processing one item gave: its line, whether it is a failure line, and its progress note.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemOutcome {
    /// One JSON line ([`crate::to_line`]).
    pub line: String,
    /// Whether the line records a failure.
    pub failed: bool,
    /// One line for progress output, made by the producer from the typed value (e.g.
    /// `r_vis=0.912 d_sat=12 d_plan=7 (optimal) 3.10 s`, or the error of a failure).
    pub note: String,
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

/// How a batch starts: printed once by [`drive`] through [`Progress::start`].
#[derive(Debug, Clone, PartialEq)]
pub struct BatchStart {
    /// What runs, e.g. `annotate`, `pool build`, `run rse / whole / budget auto`.
    pub what: String,
    /// A part of the input, e.g. `shard 0/4` (printed in parentheses), if any.
    pub scope: Option<String>,
    /// Items in the input.
    pub total: usize,
    /// Items the results file already holds.
    pub already: usize,
    /// Items to do now.
    pub todo: usize,
    /// The results file.
    pub out: std::path::PathBuf,
    /// A trailing remark, e.g. `640 views per object`, if any.
    pub remark: Option<String>,
}

impl fmt::Display for BatchStart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {} objects", self.what, self.total)?;
        if let Some(s) = &self.scope {
            write!(f, " ({s})")?;
        }
        write!(f, ", {} already in {}, {} to do", self.already, self.out.display(), self.todo)?;
        if let Some(r) = &self.remark {
            write!(f, "; {r}")?;
        }
        Ok(())
    }
}

/// One finished item, as progress output sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ItemProgress<'a> {
    /// Items finished so far in this batch, this one included (1-based).
    pub done: usize,
    /// Items to do in this batch.
    pub todo: usize,
    /// The item's uid.
    pub uid: &'a str,
    /// Whether it failed.
    pub failed: bool,
    /// Its note ([`ItemOutcome::note`]).
    pub note: &'a str,
}

impl fmt::Display for ItemProgress<'_> {
    /// `[3/10] mug: <note>`, or `[3/10] mug: FAILED: <note>` for a failure.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}/{}] {}: ", self.done, self.todo, self.uid)?;
        if self.failed {
            f.write_str("FAILED: ")?;
        }
        f.write_str(self.note)
    }
}

/// Where a batch reports what it does (a terminal with a progress bar, a log, nothing).
/// Called from worker threads.
pub trait Progress: Sync {
    /// The results file had a torn last line, which was cut off (that item is redone).
    fn torn(&self, _out: &Path) {}
    /// The batch starts.
    fn start(&self, _start: &BatchStart) {}
    /// One item finished.
    fn item(&self, _item: &ItemProgress<'_>) {}
    /// The batch ended (successfully or not).
    fn finish(&self) {}
}

/// A [`Progress`] that reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}

/// The number of worker threads for `threads` (`None`: every core); 0 is an error.
pub fn thread_count(threads: Option<usize>) -> Result<usize, DatasetError> {
    let n = threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if n == 0 {
        return Err(DatasetError::InvalidSetting { name: "--threads", reason: "must be at least 1".into() });
    }
    Ok(n)
}

/// The batch driver of every batch command: announces the batch (`what`, `scope`, `remark`:
/// see [`BatchStart`]), runs `work` over the items not yet in the results file on `threads`
/// workers ([`thread_count`]), writes lines in input order to `out` and reports each finished
/// item to `progress`.
#[allow(clippy::too_many_arguments)]
pub fn drive<W>(
    what: &str,
    scope: Option<String>,
    remark: Option<String>,
    items: &[ObjectRef],
    out: ResumableJsonl,
    existing: &Existing,
    threads: Option<usize>,
    work: W,
    progress: &dyn Progress,
) -> Result<BatchSummary, DatasetError>
where
    W: Fn(&ObjectRef) -> ItemOutcome + Sync,
{
    let threads = thread_count(threads)?;
    if existing.torn {
        progress.torn(out.path());
    }
    let todo = items.iter().filter(|o| !existing.done.contains(&o.uid)).count();
    progress.start(&BatchStart {
        what: what.to_string(),
        scope,
        total: items.len(),
        already: items.len() - todo,
        todo,
        out: out.path().to_path_buf(),
        remark,
    });
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| {
        DatasetError::InvalidSetting { name: "--threads", reason: format!("thread pool: {e}") }
    })?;
    let done = AtomicUsize::new(0);
    let report = |obj: &ObjectRef, outcome: &ItemOutcome| {
        let i = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress.item(&ItemProgress {
            done: i,
            todo,
            uid: &obj.uid,
            failed: outcome.failed,
            note: &outcome.note,
        });
    };
    let work = &work;
    let summary = pool.install(|| run_batch(items, out, existing, work, report));
    progress.finish();
    summary
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
    let mut s = run_batches(
        vec![Batch { items, out, existing, weight: 0.0 }],
        |_, o| work(o),
        |_, o, r| progress(o, r),
    )?;
    Ok(s.remove(0))
}

/// One batch of [`run_batches`]: its items, its results file and what that file already holds.
pub struct Batch<'a> {
    /// The items, in the order their lines are written.
    pub items: &'a [ObjectRef],
    /// The results file.
    pub out: ResumableJsonl,
    /// What it already holds (those items are skipped).
    pub existing: &'a Existing,
    /// Expected cost of one item, in any unit shared by the batches of one call: the items of
    /// heavier batches start first (see [`run_batches`]). It orders the work only; lines,
    /// files and results do not depend on it.
    pub weight: f64,
}

/// [`run_batch`] for several batches at once: the items of every batch (not yet in its file)
/// form one queue of work on the current rayon pool, so the cores stay busy across batches
/// instead of idling at the end of each. `work(b, item)` processes an item of batch `b` and
/// `progress(b, item, outcome)` sees it finished (from worker threads); each batch's lines go
/// to its own file in its own input order, so every file is the one that [`run_batch`] alone
/// would write. A write error stops all batches (items not yet started are not run; what was
/// written stays valid and resumable).
///
/// Order: the queue holds the batches by descending [`Batch::weight`] (equal weights in input
/// order), each batch's items in input order, and every worker takes the next item of the queue
/// when it is free (rayon's FIFO scope). Starting the long items first and ending with the short
/// ones is the longest-processing-time rule: the last worker to finish waits for the others
/// only as long as a short item takes. (A split of the list in halves, as a parallel iterator
/// does, may leave one long item running alone at the end.)
pub fn run_batches<W, P>(
    batches: Vec<Batch<'_>>,
    work: W,
    progress: P,
) -> Result<Vec<BatchSummary>, DatasetError>
where
    W: Fn(usize, &ObjectRef) -> ItemOutcome + Sync,
    P: Fn(usize, &ObjectRef, &ItemOutcome) + Sync,
{
    let mut todo: Vec<(usize, usize, &ObjectRef)> = Vec::new();
    let mut writers = Vec::with_capacity(batches.len());
    let mut summaries = Vec::with_capacity(batches.len());
    let mut weights = Vec::with_capacity(batches.len());
    for (b, batch) in batches.into_iter().enumerate() {
        let items: Vec<&ObjectRef> =
            batch.items.iter().filter(|o| !batch.existing.done.contains(&o.uid)).collect();
        summaries.push(BatchSummary {
            total: batch.items.len(),
            skipped: batch.items.len() - items.len(),
            processed: items.len(),
            failed: 0,
        });
        todo.extend(items.into_iter().enumerate().map(|(seq, o)| (b, seq, o)));
        writers.push(Mutex::new(OrderedWriter::new(batch.out)));
        weights.push(batch.weight);
    }
    // Stable: equal weights keep the input order, and within a batch its items' order.
    todo.sort_by(|x, y| weights[y.0].total_cmp(&weights[x.0]));
    let failed: Vec<AtomicUsize> = summaries.iter().map(|_| AtomicUsize::new(0)).collect();
    // The first write error; once it is set, items not yet started are not run.
    let error: Mutex<Option<DatasetError>> = Mutex::new(None);
    let (work, progress, writers, failed, error) = (&work, &progress, &writers, &failed, &error);
    let stopped = || error.lock().unwrap_or_else(std::sync::PoisonError::into_inner).is_some();
    rayon::scope_fifo(|s| {
        for &(b, seq, obj) in &todo {
            s.spawn_fifo(move |_| {
                if stopped() {
                    return;
                }
                let outcome = work(b, obj);
                if outcome.failed {
                    failed[b].fetch_add(1, Ordering::Relaxed);
                }
                progress(b, obj, &outcome);
                let mut w = writers[b].lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                if let Err(e) = w.push(seq, outcome.line) {
                    error.lock().unwrap_or_else(std::sync::PoisonError::into_inner).get_or_insert(e);
                }
            });
        }
    });
    if let Some(e) = error.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
        return Err(e);
    }
    for (s, f) in summaries.iter_mut().zip(failed) {
        s.failed = f.load(Ordering::Relaxed);
    }
    Ok(summaries)
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
        ItemOutcome { line: crate::to_line(&v), failed, note: String::new() }
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
    fn batches_run_together_write_what_each_writes_alone() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (objs(25), objs(9));
        // Alone, one after another.
        let mut alone = Vec::new();
        for (name, items) in [("a", &a), ("b", &b)] {
            let path = dir.path().join(format!("alone-{name}.jsonl"));
            let (out, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
            run_batch(items, out, &ex, work, |_, _| {}).unwrap();
            alone.push(std::fs::read_to_string(&path).unwrap());
        }
        // Together on 3 threads; batch b already holds its first 4 lines.
        let pb = dir.path().join("together-b.jsonl");
        let first4: String = alone[1].lines().take(4).map(|l| format!("{l}\n")).collect();
        std::fs::write(&pb, first4).unwrap();
        let pa = dir.path().join("together-a.jsonl");
        let (oa, ea) = ResumableJsonl::open(&pa, "uid", false).unwrap();
        let (ob, eb) = ResumableJsonl::open(&pb, "uid", false).unwrap();
        let seen = Mutex::new(Vec::new());
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let s = pool
            .install(|| {
                run_batches(
                    vec![
                        Batch { items: &a, out: oa, existing: &ea, weight: 1.0 },
                        Batch { items: &b, out: ob, existing: &eb, weight: 2.0 },
                    ],
                    |i, o| {
                        seen.lock().unwrap().push((i, o.uid.clone()));
                        work(o)
                    },
                    |_, _, _| {},
                )
            })
            .unwrap();
        assert_eq!((s[0].total, s[0].skipped, s[0].processed, s[0].failed), (25, 0, 25, 3));
        assert_eq!((s[1].total, s[1].skipped, s[1].processed, s[1].failed), (9, 4, 5, 0));
        assert_eq!(std::fs::read_to_string(&pa).unwrap(), alone[0]);
        assert_eq!(std::fs::read_to_string(&pb).unwrap(), alone[1]);
        // Every item not yet done ran once, with its own batch's index.
        let mut seen = seen.into_inner().unwrap();
        seen.sort();
        let mut want: Vec<(usize, String)> = a.iter().map(|o| (0, o.uid.clone())).collect();
        want.extend(b[4..].iter().map(|o| (1, o.uid.clone())));
        want.sort();
        assert_eq!(seen, want);
    }

    #[test]
    fn heavier_batches_start_first_and_items_keep_their_order() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, c) = (objs(3), objs(4), objs(2));
        let open = |name: &str| ResumableJsonl::open(&dir.path().join(name), "uid", false).unwrap();
        let ((oa, ea), (ob, eb), (oc, ec)) = (open("a"), open("b"), open("c"));
        let started = Mutex::new(Vec::new());
        // One worker, so that the start order is the queue order exactly (with more, workers
        // take items in that order but may record their starts a little out of it).
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        pool.install(|| {
            run_batches(
                vec![
                    Batch { items: &a, out: oa, existing: &ea, weight: 1.0 },
                    Batch { items: &b, out: ob, existing: &eb, weight: 5.0 },
                    Batch { items: &c, out: oc, existing: &ec, weight: 1.0 },
                ],
                |i, o| {
                    started.lock().unwrap().push((i, o.uid.clone()));
                    work(o)
                },
                |_, _, _| {},
            )
        })
        .unwrap();
        let mut want: Vec<(usize, String)> = b.iter().map(|o| (1, o.uid.clone())).collect();
        want.extend(a.iter().map(|o| (0, o.uid.clone())));
        want.extend(c.iter().map(|o| (2, o.uid.clone())));
        assert_eq!(started.into_inner().unwrap(), want);
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

    /// Records every event as text.
    #[derive(Default)]
    struct Recorder(Mutex<Vec<String>>);

    impl Progress for Recorder {
        fn torn(&self, out: &Path) {
            self.0.lock().unwrap().push(format!("torn {}", out.file_name().unwrap().to_string_lossy()));
        }
        fn start(&self, s: &BatchStart) {
            self.0.lock().unwrap().push(s.to_string());
        }
        fn item(&self, p: &ItemProgress<'_>) {
            self.0.lock().unwrap().push(p.to_string());
        }
        fn finish(&self) {
            self.0.lock().unwrap().push("finish".into());
        }
    }

    fn noted(o: &ObjectRef) -> ItemOutcome {
        let failed = o.uid.ends_with('1');
        ItemOutcome {
            line: crate::to_line(&json!({"uid": o.uid})),
            failed,
            note: if failed { "boom".into() } else { format!("{} done", o.uid) },
        }
    }

    #[test]
    fn drive_announces_the_batch_and_reports_each_item_with_its_own_note() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.jsonl");
        std::fs::write(&path, "{\"uid\":\"o000\"}\n{\"uid\":\"o0").unwrap();
        let (out, ex) = ResumableJsonl::open(&path, "uid", false).unwrap();
        let rec = Recorder::default();
        let s = drive(
            "annotate",
            Some("shard 0/1".into()),
            Some("9 views".into()),
            &objs(3),
            out,
            &ex,
            Some(1),
            noted,
            &rec,
        )
        .unwrap();
        assert_eq!((s.total, s.skipped, s.processed, s.failed), (3, 1, 2, 1));
        let events = rec.0.into_inner().unwrap();
        assert_eq!(events[0], "torn r.jsonl");
        assert_eq!(
            events[1],
            format!("annotate: 3 objects (shard 0/1), 1 already in {}, 2 to do; 9 views", path.display())
        );
        // One worker: items finish in input order.
        assert_eq!(events[2..], ["[1/2] o001: FAILED: boom", "[2/2] o002: o002 done", "finish"]);
    }

    #[test]
    fn zero_threads_is_an_error_naming_the_flag() {
        assert!(thread_count(Some(0)).unwrap_err().to_string().contains("--threads"));
        assert!(thread_count(None).unwrap() >= 1);
    }
}
