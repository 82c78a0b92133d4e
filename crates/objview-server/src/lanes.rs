//! The engine's lanes: engine jobs (a create's start view, an action, a render on request) wait
//! in one first-come-first-served queue, and as many lanes as cores take them from it, each lane
//! a thread of its own that runs a job start to end.
//!
//! Why lanes: the engine's stages split their work with rayon (coverage by target block, the
//! checkpoint's CD, the renderer by rows). Run from tokio's blocking pool, concurrent jobs
//! shared the global rayon pool's threads while their callers waited idle, and a parallel
//! section that ended unevenly left a core with nothing to do while the queue was full. One
//! step on two threads is no faster than on one anyway (`objview bench episode`: 0.89× the
//! one-thread median). Each lane is a single-thread rayon pool, so a job's parallel sections
//! run on its own thread: one job per core, every core busy while jobs wait.
//!
//! Why lanes pull from a queue: a finished lane takes the next job at once. Behind a semaphore,
//! the next job would start only after a chain of wake-ups (the finished job's blocking thread,
//! its async task dropping the permit, the next task, a blocking thread for it, the lane), and
//! the core waits through each of them.
//!
//! A request dropped before a lane takes its job (the client went away) has its job skipped,
//! not run. Results do not depend on the thread count (each stage's answers are the same on any
//! number of threads).

use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex, PoisonError};

use crate::error::ServerError;

type Job = Box<dyn FnOnce() + Send>;

/// The queue and its lanes.
pub struct Lanes {
    queue: Sender<Job>,
    /// Jobs a lane ran (skipped ones not counted).
    ran: Arc<AtomicUsize>,
    /// One single-thread pool per lane, kept as long as the queue.
    pools: Vec<rayon::ThreadPool>,
}

impl std::fmt::Debug for Lanes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lanes").field("count", &self.count()).finish_non_exhaustive()
    }
}

/// Why a job gave no value.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LaneError {
    /// The job panicked (the panic message went to the server log).
    #[error("the engine job panicked")]
    Panicked,
    /// The lanes are gone (the server is shutting down).
    #[error("the engine lanes have stopped")]
    Stopped,
}

/// Sets the flag when dropped: marks a job whose request went away. Dropped after the answer
/// came, it changes nothing (the job has run, or is gone).
struct Abandon(Arc<AtomicBool>);

impl Drop for Abandon {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Lanes {
    /// `count` lanes (at least one), their threads named `objview-engine-{i}`.
    pub fn new(count: usize) -> Result<Lanes, ServerError> {
        let count = count.max(1);
        let (tx, rx) = channel::<Job>();
        let rx = Arc::new(Mutex::new(rx));
        let pools = (0..count)
            .map(|i| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(1)
                    .thread_name(move |_| format!("objview-engine-{i}"))
                    .build()
                    .map_err(|e| ServerError::Config(format!("engine lane {i}: {e}")))?;
                // The lane's loop runs as a job of its pool, so the jobs it takes run their
                // parallel sections on that pool's one thread.
                let rx = rx.clone();
                pool.spawn(move || lane_loop(&rx));
                Ok(pool)
            })
            .collect::<Result<Vec<_>, ServerError>>()?;
        Ok(Lanes { queue: tx, ran: Arc::default(), pools })
    }

    /// How many lanes there are.
    pub fn count(&self) -> usize {
        self.pools.len()
    }

    /// How many jobs the lanes have run so far.
    pub fn jobs_run(&self) -> usize {
        self.ran.load(Ordering::Relaxed)
    }

    /// Queues `f` and waits for a lane to run it. A panic in `f` is [`LaneError::Panicked`];
    /// when this future is dropped before a lane takes the job, the job is skipped.
    pub async fn run<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, LaneError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let abandoned = Arc::new(AtomicBool::new(false));
        let _abandon = Abandon(abandoned.clone());
        let ran = self.ran.clone();
        let job: Job = Box::new(move || {
            if abandoned.load(Ordering::Relaxed) {
                return;
            }
            ran.fetch_add(1, Ordering::Relaxed);
            let _ = tx.send(std::panic::catch_unwind(AssertUnwindSafe(f)));
        });
        self.queue.send(job).map_err(|_| LaneError::Stopped)?;
        match rx.await {
            Ok(Ok(v)) => Ok(v),
            Ok(Err(_)) => Err(LaneError::Panicked),
            Err(_) => Err(LaneError::Stopped),
        }
    }

    /// Occupies every lane until the returned guard is dropped (tests: an engine busy with
    /// other work). Returns once each lane runs one of the holding jobs.
    pub fn hold(&self) -> Hold {
        let (started_tx, started_rx) = channel::<()>();
        let release = Arc::new((Mutex::new(false), std::sync::Condvar::new()));
        for _ in 0..self.count() {
            let (started, release) = (started_tx.clone(), release.clone());
            let job: Job = Box::new(move || {
                let _ = started.send(());
                let (lock, cv) = &*release;
                let mut done = lock.lock().unwrap_or_else(PoisonError::into_inner);
                while !*done {
                    done = cv.wait(done).unwrap_or_else(PoisonError::into_inner);
                }
            });
            let _ = self.queue.send(job);
        }
        for _ in 0..self.count() {
            let _ = started_rx.recv();
        }
        Hold { release }
    }
}

/// Every lane held busy ([`Lanes::hold`]) until this is dropped.
pub struct Hold {
    release: Arc<(Mutex<bool>, std::sync::Condvar)>,
}

impl Drop for Hold {
    fn drop(&mut self) {
        let (lock, cv) = &*self.release;
        *lock.lock().unwrap_or_else(PoisonError::into_inner) = true;
        cv.notify_all();
    }
}

/// A lane: takes the next job (the lock is held only while waiting for one) and runs it, until
/// the queue is gone.
fn lane_loop(rx: &Mutex<Receiver<Job>>) {
    loop {
        let job = rx.lock().unwrap_or_else(PoisonError::into_inner).recv();
        match job {
            Ok(job) => job(),
            Err(_) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;
    use std::time::Duration;

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap()
    }

    #[test]
    fn a_job_runs_alone_on_a_named_lane() {
        let lanes = Lanes::new(2).unwrap();
        let (threads, name, sum) = runtime()
            .block_on(lanes.run(|| {
                // A parallel section inside the job stays on the lane's one thread.
                let names: Vec<String> = (0..64)
                    .into_par_iter()
                    .map(|_| std::thread::current().name().unwrap_or("").to_string())
                    .collect();
                let sum: u64 = (0..1000u64).into_par_iter().sum();
                assert!(names.iter().all(|n| n == &names[0]), "{names:?}");
                (rayon::current_num_threads(), names[0].clone(), sum)
            }))
            .unwrap();
        assert_eq!(threads, 1);
        assert!(name.starts_with("objview-engine-"), "{name}");
        assert_eq!(sum, 499_500);
        assert_eq!(lanes.jobs_run(), 1);
    }

    #[test]
    fn jobs_run_in_arrival_order_on_every_lane_and_a_panic_is_an_error() {
        let lanes = Arc::new(Lanes::new(2).unwrap());
        let rt = runtime();
        // Both lanes busy at once: two jobs that wait for each other finish.
        let barrier = Arc::new(std::sync::Barrier::new(2));
        let names = rt.block_on(async {
            let (b1, b2) = (barrier.clone(), barrier.clone());
            let a = lanes.run(move || {
                b1.wait();
                std::thread::current().name().unwrap().to_string()
            });
            let b = lanes.run(move || {
                b2.wait();
                std::thread::current().name().unwrap().to_string()
            });
            let (a, b) = tokio::join!(a, b);
            (a.unwrap(), b.unwrap())
        });
        assert_ne!(names.0, names.1);
        // Queued jobs start in the order they arrived (one lane: the order they ran in).
        let one = Arc::new(Lanes::new(1).unwrap());
        let order = Arc::new(Mutex::new(Vec::new()));
        let hold = one.hold();
        let handles: Vec<_> = (0..6)
            .map(|i| {
                let (l, o) = (one.clone(), order.clone());
                let h = rt.spawn(async move { l.run(move || o.lock().unwrap().push(i)).await });
                // Each request reaches the queue before the next is sent.
                std::thread::sleep(Duration::from_millis(20));
                h
            })
            .collect();
        drop(hold);
        for h in handles {
            rt.block_on(h).unwrap().unwrap();
        }
        assert_eq!(*order.lock().unwrap(), (0..6).collect::<Vec<_>>());
        let r = rt.block_on(lanes.run(|| -> u32 { panic!("job failed") }));
        assert_eq!(r, Err(LaneError::Panicked));
        // The lane that ran it is still there.
        assert_eq!(rt.block_on(lanes.run(|| 7)), Ok(7));
    }

    #[test]
    fn a_request_dropped_before_its_job_starts_skips_it() {
        let lanes = Arc::new(Lanes::new(1).unwrap());
        let rt = runtime();
        let ran = Arc::new(AtomicBool::new(false));
        let hold = lanes.hold();
        let (l, r) = (lanes.clone(), ran.clone());
        let h = rt.spawn(async move { l.run(move || r.store(true, Ordering::Relaxed)).await });
        std::thread::sleep(Duration::from_millis(50));
        h.abort();
        let _ = rt.block_on(h);
        drop(hold);
        // A later job runs after the skipped one.
        assert_eq!(rt.block_on(lanes.run(|| 1)), Ok(1));
        assert!(!ran.load(Ordering::Relaxed));
        assert_eq!(lanes.jobs_run(), 1);
    }
}
