//! The instruction-set baseline of this build, checked once at start-up.
//!
//! On x86-64 Linux the workspace is compiled with the **x86-64-v2** features
//! (`.cargo/config.toml`: POPCNT, SSE3, SSSE3, SSE4.1, SSE4.2, CMPXCHG16B, with LLVM's generic
//! tuning; every x86-64 CPU since 2009, and the baseline RHEL 9 requires; LAHF/SAHF, the seventh
//! v2 feature, is unstable in rustc and not enabled, so not checked), because the
//! hot paths count bits everywhere — the fusion's ranks in its occupancy words, the coverage and
//! cover searches' bitsets — and the generic x86-64 target has no POPCNT instruction, so each
//! `count_ones` became a dozen instructions (`docs/performance.md`, "The x86-64-v2 baseline").
//! Results do not depend on it (no floating-point operation changes; tested with the golden
//! outputs and the learned planners' training). A CPU without these instructions would stop at the first one with SIGILL
//! somewhere deep in a run; [`missing_baseline`] lets the binary say so in one line instead.
//!
//! The check reads CPUID itself: `is_x86_feature_detected!` answers `true` at compile time for
//! every feature the build enables, so it cannot tell whether the CPU has them.

/// The x86-64-v2 features as bits of the CPU's CPUID leaf 1 ECX (bit, name, whether this build
/// was compiled with it), in the order reported.
const LEAF1_ECX: [(u32, &str, bool); 6] = [
    (0, "sse3", cfg!(target_feature = "sse3")),
    (9, "ssse3", cfg!(target_feature = "ssse3")),
    (13, "cmpxchg16b", cfg!(target_feature = "cmpxchg16b")),
    (19, "sse4.1", cfg!(target_feature = "sse4.1")),
    (20, "sse4.2", cfg!(target_feature = "sse4.2")),
    (23, "popcnt", cfg!(target_feature = "popcnt")),
];

/// The features of `LEAF1_ECX` that `needed` selects and CPUID leaf 1's ECX `leaf1_ecx` lacks,
/// by name; empty when the CPU has them all.
fn missing_among(leaf1_ecx: u32, needed: impl Fn(&str, bool) -> bool) -> Vec<&'static str> {
    LEAF1_ECX
        .iter()
        .filter(|&&(bit, name, built)| needed(name, built) && leaf1_ecx >> bit & 1 == 0)
        .map(|&(_, name, _)| name)
        .collect()
}

/// The x86-64-v2 features (of CPUID leaf 1) missing from the ECX `leaf1_ecx`, by name; empty
/// when the CPU has them all.
pub fn missing_from_cpuid(leaf1_ecx: u32) -> Vec<&'static str> {
    missing_among(leaf1_ecx, |_, _| true)
}

/// The instruction-set baseline this build was compiled for: `x86-64-v2` or `x86-64` (a
/// build with `RUSTFLAGS` replacing the workspace's flags), or the target architecture
/// elsewhere. Benchmarks record it next to the host ([`crate::bench::host::Host`]).
pub fn build_baseline() -> &'static str {
    if built_for_v2() {
        "x86-64-v2"
    } else if cfg!(target_arch = "x86_64") {
        "x86-64"
    } else {
        std::env::consts::ARCH
    }
}

/// Whether this build was compiled for the x86-64-v2 baseline (POPCNT and SSE4.2 enabled at
/// compile time), so that it needs them at run time.
pub fn built_for_v2() -> bool {
    cfg!(all(target_arch = "x86_64", target_feature = "popcnt", target_feature = "sse4.2"))
}

/// The features this build was compiled with that this CPU lacks (empty: it can run this
/// build; always empty for a generic x86-64 build and off x86-64). Each feature counts by its
/// own compile-time flag, so a `RUSTFLAGS` that enables only some of them is checked for those.
pub fn missing_baseline() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        // CPUID is part of every x86-64 CPU, and leaf 1 always exists.
        #[allow(unused_unsafe)]
        let leaf1 = unsafe { std::arch::x86_64::__cpuid(1) };
        missing_among(leaf1.ecx, |_, built| built)
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec::new()
}

/// The one-line error for a CPU without the baseline (`missing` non-empty).
pub fn baseline_error(missing: &[&str]) -> String {
    format!(
        "this objview build needs an x86-64-v2 CPU (POPCNT, SSE4.2), and this CPU lacks: {}; \
         rebuild for it with RUSTFLAGS='-C target-cpu=x86-64' (same results, slower; README, Build)",
        missing.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_feature_is_named_by_its_own_bit() {
        let all = LEAF1_ECX.iter().fold(0u32, |a, &(bit, _, _)| a | 1 << bit);
        assert!(missing_from_cpuid(all).is_empty());
        // Unrelated bits do not stand in for the baseline's.
        assert_eq!(missing_from_cpuid(!all).len(), LEAF1_ECX.len());
        assert_eq!(missing_from_cpuid(all & !(1 << 23)), vec!["popcnt"]);
        assert_eq!(missing_from_cpuid(all & !(1 << 20) & !(1 << 19)), vec!["sse4.1", "sse4.2"]);
        // A pre-2008 CPU (SSE3 only).
        assert_eq!(missing_from_cpuid(1), vec!["ssse3", "cmpxchg16b", "sse4.1", "sse4.2", "popcnt"]);
        // Only the selected features count: a build without SSE4.x does not need them.
        let no_sse4 = |name: &str, _| !name.starts_with("sse4");
        assert_eq!(missing_among(1, no_sse4), vec!["ssse3", "cmpxchg16b", "popcnt"]);
    }

    #[test]
    fn this_machine_runs_this_build() {
        // The test binary itself was built with the same flags, so it got here only on a CPU
        // that runs them; the check must agree.
        assert_eq!(missing_baseline(), Vec::<&str>::new());
        // The workspace's flags enable every feature of the table (a build whose RUSTFLAGS
        // replace them is generic, enabling none; `build_baseline` then says `x86-64`).
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        if built_for_v2() {
            assert!(LEAF1_ECX.iter().all(|&(_, _, built)| built), "{LEAF1_ECX:?}");
        }
    }

    #[test]
    fn the_error_is_one_line_naming_what_is_missing() {
        let e = baseline_error(&["popcnt", "sse4.2"]);
        assert!(!e.contains('\n'));
        assert!(e.contains("lacks: popcnt, sse4.2"));
        assert!(e.contains("target-cpu=x86-64"));
    }
}
