//! The measurement procedures of `objview bench …`, so that the command line only turns its
//! arguments into settings and prints the figures these return:
//!
//! - [`episode`]: the cost of one episode step in the environment and the planning time per
//!   step of RSE / RSE-Mov ([`episode::bench_episode`]).
//! - [`annotate`]: the difficulty annotation's cost per stage and peak memory
//!   ([`annotate::AnnotateBench`]), and how much its results depend on the ground-truth
//!   sampling seed ([`annotate::StabilityBench`]).
//! - [`render`]: depth rendering against an Open3D peer where one is installed, and O(v) per
//!   view in both visibility modes ([`render::RenderBench`]).
//! - [`host`]: the machine the figures come from (CPU model, logical CPUs, SIMD features),
//!   which every benchmark prints and records.
//!
//! Benchmarks are procedures run on demand, never timed unit tests: the tests here only check
//! the shape of the figures. Medians and percentiles are [`objview_geom::stats`]'s.

pub mod annotate;
pub mod episode;
pub mod host;
pub mod render;

use objview_geom::stats::{median, percentile};

/// Peak resident memory of this process (Linux `VmHWM`, bytes), if the OS reports it.
pub fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Resets the peak of [`peak_rss`] (Linux `clear_refs` 5); false where unsupported (the peak
/// then covers the whole process so far).
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// CPU time this process has used so far, all threads together: (user, system) seconds
/// (`getrusage`). The system time of a load run is mostly the kernel zeroing pages on their
/// first touch; on a VM its cost per page moves from run to run, so a run's throughput is read
/// next to it.
pub fn process_cpu() -> Option<(f64, f64)> {
    // SAFETY: getrusage writes one `rusage` into the zeroed value it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return None;
    }
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some((secs(u.ru_utime), secs(u.ru_stime)))
}

/// Memory per concurrent episode of a load run: the growth of the peak resident memory from
/// a warm-up with one episode (`warm`, bytes) to the run with `concurrent` episodes at once
/// (`peak`), per episode beyond the first; `None` with fewer than two episodes.
pub fn memory_per_episode(warm: u64, peak: u64, concurrent: usize) -> Option<f64> {
    (concurrent >= 2).then(|| peak.saturating_sub(warm) as f64 / (concurrent - 1) as f64)
}

/// Median, nearest-rank 90th percentile and maximum of a set of timings (seconds); NaN for
/// each when there are none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// The median.
    pub median: f64,
    /// The nearest-rank 90th percentile.
    pub p90: f64,
    /// The largest sample.
    pub max: f64,
}

impl Spread {
    /// The spread of `samples` (in any order).
    pub fn of(mut samples: Vec<f64>) -> Spread {
        let median = median(&mut samples); // sorts
        Spread { median, p90: percentile(&samples, 0.9), max: percentile(&samples, 1.0) }
    }
}

/// A rayon pool of `threads` threads.
fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, crate::RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| crate::RunError::Invalid(format!("thread pool: {e}")))
}

#[cfg(test)]
mod tests {
    use super::{memory_per_episode, process_cpu, Spread};

    #[test]
    fn memory_per_episode_is_the_peak_growth_per_further_episode() {
        assert_eq!(memory_per_episode(100, 400, 4), Some(100.0));
        assert_eq!(memory_per_episode(100, 100, 32), Some(0.0));
        // A peak below the warm-up's (a reset peak) counts as no growth.
        assert_eq!(memory_per_episode(300, 200, 2), Some(0.0));
        assert_eq!(memory_per_episode(100, 400, 1), None);
        assert_eq!(memory_per_episode(100, 400, 0), None);
    }

    #[test]
    fn process_cpu_counts_this_threads_work_and_fresh_pages() {
        let (u0, s0) = process_cpu().expect("getrusage");
        // Busy work until the user time has grown by 30 ms (bounded by a 20 s wall limit).
        let start = std::time::Instant::now();
        let mut x = 1u64;
        let u1 = loop {
            for i in 0..100_000u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
            }
            let (u, _) = process_cpu().unwrap();
            if u >= u0 + 0.03 || start.elapsed().as_secs() > 20 {
                break u;
            }
        };
        assert!(x != 0 || u1 > 0.0);
        assert!(u1 >= u0 + 0.03, "user time {u0} → {u1} s after the busy loop");
        // First touches of 256 MiB of fresh pages are system time.
        let mut v = vec![0u8; 256 << 20];
        for i in (0..v.len()).step_by(4096) {
            v[i] = 1;
        }
        let (_, s1) = process_cpu().unwrap();
        assert_eq!(v.iter().step_by(4096).filter(|&&b| b == 1).count(), 65536);
        assert!(s1 > s0, "system time {s0} → {s1} s after touching 64k fresh pages");
    }

    #[test]
    fn a_spread_is_median_p90_and_max_of_unsorted_samples() {
        let s = Spread::of(vec![5.0, 1.0, 4.0, 2.0, 3.0, 10.0, 9.0, 8.0, 7.0, 6.0]);
        assert_eq!(s, Spread { median: 5.5, p90: 9.0, max: 10.0 });
        let one = Spread::of(vec![0.25]);
        assert_eq!(one, Spread { median: 0.25, p90: 0.25, max: 0.25 });
        let none = Spread::of(Vec::new());
        assert!(none.median.is_nan() && none.p90.is_nan() && none.max.is_nan());
    }
}
