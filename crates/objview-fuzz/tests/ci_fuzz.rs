//! The fuzzer's CI budget: a seeded campaign over every loader, a few seconds per kind, that must
//! find nothing. The seed is fixed so CI is deterministic (the same cases every time, as long as
//! the machine gets through them within the time cap); `OBJVIEW_FUZZ_SEED=N` adds a campaign
//! with that seed. Findings are written under the target's temporary folder (printed on failure)
//! and can be copied into `regressions/`.

use std::path::PathBuf;

use objview_fuzz::{fuzz, Settings, Summary};

/// The fixed CI seed.
const CI_SEED: u64 = 20_240_613;
/// Cases per kind (the seeded sequence's first ones): about 1 s per kind on 2 cores with the
/// cases in /dev/shm (about 10 000 cases/s); on a disk the time cap below decides.
const CASES_PER_KIND: u64 = 10_000;
/// Time cap of one campaign over all kinds (45 / 16 ≈ 2.8 s per kind): a slow machine runs
/// fewer cases rather than a longer test.
const SECONDS: f64 = 45.0;

fn campaign(seed: u64) -> (Summary, PathBuf) {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-findings-{seed}"));
    let _ = std::fs::remove_dir_all(&out);
    let mut s = Settings::new(PathBuf::from(env!("CARGO_BIN_EXE_objview-fuzz")), seed);
    s.seconds = SECONDS;
    s.max_cases = Some(CASES_PER_KIND);
    s.jobs = 2;
    s.out = Some(out.clone());
    // Findings are written unshrunk (shrinking costs up to 10 s each); to shrink one, rerun
    // `objview-fuzz run --seed S --kinds K --cases N+1` (N: its case number).
    s.minimize = false;
    s.verbose = true;
    (fuzz(&s).expect("campaign runs"), out)
}

fn assert_clean(seed: u64) {
    let (summary, out) = campaign(seed);
    for (kind, st) in &summary.kinds {
        assert!(st.cases > 0, "{}: no case ran", kind.name());
    }
    let lines: Vec<String> = summary
        .findings
        .iter()
        .map(|f| {
            format!(
                "{} case {} {} ({}): {} -> {}",
                f.kind.name(),
                f.case,
                f.class.name(),
                f.kind.owner(),
                f.detail,
                f.file.as_deref().map_or_else(String::new, |p| p.display().to_string())
            )
        })
        .collect();
    assert!(
        lines.is_empty(),
        "seed {seed}: {} findings (inputs under {}):\n{}",
        lines.len(),
        out.display(),
        lines.join("\n")
    );
}

#[test]
fn seeded_campaign_finds_nothing() {
    assert_clean(CI_SEED);
    if let Ok(s) = std::env::var("OBJVIEW_FUZZ_SEED") {
        let seed: u64 = s.trim().parse().expect("OBJVIEW_FUZZ_SEED is an integer");
        assert_clean(seed);
    }
}
