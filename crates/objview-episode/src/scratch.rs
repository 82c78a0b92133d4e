//! Scratch buffers shared by every episode of a process. An engine step needs ~20 MB of
//! buffers that hold nothing from one step to the next (the fusion's per-point tables, the
//! observed points, the changed slots' groups, the renderer's z-buffer). Kept in each episode,
//! they made every open episode of a server that much larger (32 concurrent clients: ~0.7 GB of
//! idle buffers); kept in a [`Pool`], there are as many sets as steps that ever ran at the same
//! time (the server runs one per core), whatever the number of open episodes.
//!
//! A pooled value is taken for one call and given back after it, so no result can depend on
//! which set a call gets: every user clears or overwrites what it reads (the buffers' contents
//! never carry over; only their capacity does).

use std::sync::{Mutex, PoisonError};

/// A stack of reusable values of `T`, shared between threads.
pub(crate) struct Pool<T> {
    free: Mutex<Vec<T>>,
}

impl<T: Default> Pool<T> {
    /// An empty pool (usable in a `static`).
    pub(crate) const fn new() -> Pool<T> {
        Pool { free: Mutex::new(Vec::new()) }
    }

    /// Calls `f` with a value of the pool (a new `T::default()` when none is free) and gives it
    /// back afterwards; a panic in `f` drops it instead.
    pub(crate) fn with<R>(&self, f: impl FnOnce(&mut T) -> R) -> R {
        let taken = self.free.lock().unwrap_or_else(PoisonError::into_inner).pop();
        let mut value = taken.unwrap_or_default();
        let result = f(&mut value);
        self.free.lock().unwrap_or_else(PoisonError::into_inner).push(value);
        result
    }

    /// Values waiting in the pool (tests).
    #[cfg(test)]
    pub(crate) fn idle(&self) -> usize {
        self.free.lock().unwrap_or_else(PoisonError::into_inner).len()
    }
}

#[cfg(test)]
mod tests {
    use super::Pool;

    #[test]
    fn values_are_reused_and_one_exists_per_concurrent_user() {
        let pool: Pool<Vec<u8>> = Pool::new();
        pool.with(|v| v.reserve(1000));
        assert_eq!(pool.idle(), 1);
        // The same value comes back (its capacity shows it).
        pool.with(|v| assert!(v.capacity() >= 1000));
        // Nested users each get their own value; both go back.
        pool.with(|a| {
            pool.with(|b| {
                assert!(b.capacity() < 1000, "a second value while the first is taken");
                b.push(1);
            });
            a.push(2);
        });
        assert_eq!(pool.idle(), 2);
        // Threads at the same time: never more values than users at once.
        let pool: Pool<Vec<u8>> = Pool::new();
        let barrier = std::sync::Barrier::new(4);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    pool.with(|v| {
                        v.push(0);
                        barrier.wait();
                    })
                });
            }
        });
        assert_eq!(pool.idle(), 4);
    }

    #[test]
    fn a_panicking_user_drops_its_value() {
        let pool: Pool<Vec<u8>> = Pool::new();
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pool.with(|_| panic!("boom"))));
        assert!(r.is_err());
        assert_eq!(pool.idle(), 0);
        pool.with(|v| v.push(1));
        assert_eq!(pool.idle(), 1);
    }
}
