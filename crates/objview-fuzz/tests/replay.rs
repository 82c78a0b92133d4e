//! Every kept crasher under `regressions/<kind>/` must now give a clean error or a valid object.

use std::path::PathBuf;

use objview_fuzz::{regressions_dir, replay, Limits};

#[test]
fn every_regression_input_is_a_clean_error_or_a_valid_object() {
    let exe = PathBuf::from(env!("CARGO_BIN_EXE_objview-fuzz"));
    let all = replay(&regressions_dir(), &exe, Limits::default(), false).expect("replay runs");
    assert!(!all.is_empty(), "no regression inputs found under {}", regressions_dir().display());
    let bad: Vec<String> = all
        .iter()
        .filter(|r| r.outcome.class.is_finding())
        .map(|r| format!("{} {}: {}", r.outcome.class.name(), r.path.display(), r.outcome.detail))
        .collect();
    assert!(bad.is_empty(), "{} of {} regression inputs fail:\n{}", bad.len(), all.len(), bad.join("\n"));
}
