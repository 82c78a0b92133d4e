//! Statistics of an annotated pool (`objview pool stats`): what a pool holds before and after
//! splitting, to check that the splits look like the paper's (paper §4, Table 1): counts of
//! objects, failures, slow-saturation objects and main-pool objects without a proven d_plan, the
//! d_plan bucket histogram of the main pool, and mean d_sat / d_plan / r_vis per group.
//!
//! Groups are `all`, `main` and `slow_saturation` of the annotations, or, given the split files
//! written by `objview pool split`, one group per split (split objects matched to the annotations
//! by uid). Means are taken in uid order, so they do not depend on the order of the input lines;
//! the d_plan mean is over the objects with a proven positive d_plan.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use objview_dataset::{Annotation, AnnotationSet};
use serde_json::{json, Value};

use crate::error::PoolError;
use crate::split::{bucket_label, bucket_of, proven_d_plan, SplitName};

/// Width in characters of the longest histogram bar.
pub const BAR_WIDTH: usize = 40;

/// The objects of one split file.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitMembers {
    /// The split's name (`main_hidden_test`, …).
    pub name: String,
    /// The split file.
    pub path: PathBuf,
    /// Its uids, in file order.
    pub uids: Vec<String>,
}

/// Reads the split files of `dir` written by `objview pool split` (those present, in report
/// order). Errors: `dir` is not a folder, holds none of them, or one does not parse.
pub fn read_split_dir(dir: &Path) -> Result<Vec<SplitMembers>, PoolError> {
    if !dir.is_dir() {
        return Err(PoolError::mismatch(dir, "not a folder of split files"));
    }
    let mut out = Vec::new();
    for s in SplitName::ALL {
        let path = dir.join(s.file_name());
        if path.is_file() {
            let uids = objview_dataset::read_split(&path)?.into_iter().map(|o| o.uid).collect();
            out.push(SplitMembers { name: s.as_str().to_string(), path, uids });
        }
    }
    if out.is_empty() {
        let names: Vec<String> = SplitName::ALL.iter().map(|s| s.file_name()).collect();
        return Err(PoolError::mismatch(
            dir,
            format!("no split files ({}); run `objview pool split` first", names.join(", ")),
        ));
    }
    Ok(out)
}

/// Counts and means of one group of objects.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupStats {
    /// The group: `all`, `main`, `slow_saturation`, or a split's name.
    pub name: String,
    /// Objects in the group.
    pub count: usize,
    /// Objects with a proven positive d_plan (the d_plan mean is over these).
    pub with_d_plan: usize,
    /// Mean d_sat over the group's objects; `None` for an empty group.
    pub mean_d_sat: Option<f64>,
    /// Mean d_plan over the objects with a proven positive d_plan; `None` if there are none.
    pub mean_d_plan: Option<f64>,
    /// Mean r_vis over the group's objects; `None` for an empty group.
    pub mean_r_vis: Option<f64>,
    /// Objects per d_plan bucket ([`PoolStats::buckets`] entries).
    pub buckets: Vec<usize>,
}

/// Everything `objview pool stats` prints.
#[derive(Debug, Clone, PartialEq)]
pub struct PoolStats {
    /// Annotation lines (successful).
    pub annotated: usize,
    /// Failure lines.
    pub failures: usize,
    /// Annotated objects with `slow_saturation`.
    pub slow_saturation: usize,
    /// Annotated objects without `slow_saturation` (the main pool, unsolved ones included).
    pub main: usize,
    /// Of `main`, objects without a proven positive d_plan (not bucketed, left out of splits).
    pub unsolved_d_plan: usize,
    /// Number of buckets shown: up to the largest bucket of any proven d_plan.
    pub buckets: usize,
    /// Main-pool objects per d_plan bucket.
    pub histogram: Vec<usize>,
    /// Per-group counts and means.
    pub groups: Vec<GroupStats>,
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for v in values {
        sum += v;
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

fn group(name: &str, members: &[&Annotation], buckets: usize) -> GroupStats {
    let mut sorted = members.to_vec();
    sorted.sort_by(|a, b| a.uid.cmp(&b.uid));
    let d_plans: Vec<usize> = sorted.iter().filter_map(|a| proven_d_plan(a).ok()).collect();
    let mut counts = vec![0usize; buckets];
    for &d in &d_plans {
        counts[bucket_of(d).expect("proven d_plan > 0")] += 1;
    }
    GroupStats {
        name: name.to_string(),
        count: sorted.len(),
        with_d_plan: d_plans.len(),
        mean_d_sat: mean(sorted.iter().map(|a| a.d_sat as f64)),
        mean_d_plan: mean(d_plans.iter().map(|&d| d as f64)),
        mean_r_vis: mean(sorted.iter().map(|a| a.r_vis)),
        buckets: counts,
    }
}

/// The statistics of `set`; with `splits`, one group per split (every uid of a split must have an
/// annotation: an error names the split file and the uid otherwise).
pub fn pool_stats(set: &AnnotationSet, splits: Option<&[SplitMembers]>) -> Result<PoolStats, PoolError> {
    let anns = &set.annotations;
    let buckets = anns
        .iter()
        .filter_map(|a| proven_d_plan(a).ok())
        .map(|d| (d - 1) / crate::split::BUCKET_WIDTH + 1)
        .max()
        .unwrap_or(0);
    let all: Vec<&Annotation> = anns.iter().collect();
    let main: Vec<&Annotation> = anns.iter().filter(|a| !a.slow_saturation).collect();
    let slow: Vec<&Annotation> = anns.iter().filter(|a| a.slow_saturation).collect();
    let main_group = group("main", &main, buckets);
    let groups = match splits {
        None => {
            vec![group("all", &all, buckets), main_group.clone(), group("slow_saturation", &slow, buckets)]
        }
        Some(splits) => {
            let by_uid: HashMap<&str, &Annotation> = anns.iter().map(|a| (a.uid.as_str(), a)).collect();
            let mut groups = Vec::with_capacity(splits.len());
            for s in splits {
                let members = s
                    .uids
                    .iter()
                    .map(|u| {
                        by_uid.get(u.as_str()).copied().ok_or_else(|| {
                            PoolError::mismatch(
                                &s.path,
                                format!("object '{u}' has no annotation in the inputs"),
                            )
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                groups.push(group(&s.name, &members, buckets));
            }
            groups
        }
    };
    Ok(PoolStats {
        annotated: anns.len(),
        failures: set.failures.len(),
        slow_saturation: slow.len(),
        main: main.len(),
        unsolved_d_plan: main.len() - main_group.with_d_plan,
        buckets,
        histogram: main_group.buckets,
        groups,
    })
}

impl PoolStats {
    /// The statistics as JSON, with the caller's `settings` (tool, version, inputs).
    pub fn to_json(&self, settings: &Value) -> Value {
        json!({
            "settings": settings,
            "counts": {
                "annotated": self.annotated,
                "failures": self.failures,
                "slow_saturation": self.slow_saturation,
                "main": self.main,
                "unsolved_d_plan": self.unsolved_d_plan,
            },
            "bucket_labels": (0..self.buckets).map(bucket_label).collect::<Vec<_>>(),
            "main_histogram": self.histogram,
            "groups": self.groups.iter().map(|g| json!({
                "name": g.name,
                "count": g.count,
                "with_d_plan": g.with_d_plan,
                "mean_d_sat": g.mean_d_sat,
                "mean_d_plan": g.mean_d_plan,
                "mean_r_vis": g.mean_r_vis,
                "buckets": g.buckets,
            })).collect::<Vec<_>>(),
        })
    }

    /// The statistics as text: counts, the main pool's histogram with bars, a table of means.
    pub fn to_text(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(
            t,
            "objects: {} annotated, {} failed; {} slow-saturation, {} main ({} without a proven d_plan)",
            self.annotated, self.failures, self.slow_saturation, self.main, self.unsolved_d_plan
        );
        let _ =
            writeln!(t, "\nd_plan histogram of the main pool (buckets of {}):", crate::split::BUCKET_WIDTH);
        let max = self.histogram.iter().copied().max().unwrap_or(0);
        if max == 0 {
            let _ = writeln!(t, "  (no main-pool object with a proven d_plan)");
        }
        for (b, &n) in self.histogram.iter().enumerate().filter(|_| max > 0) {
            let line = format!("  {:>7} {:>6} {}", bucket_label(b), n, "#".repeat(bar(n, max)));
            let _ = writeln!(t, "{}", line.trim_end());
        }
        let _ = writeln!(
            t,
            "\n{:<20} {:>7} {:>7} {:>10} {:>11} {:>10}",
            "group", "objects", "solved", "mean d_sat", "mean d_plan", "mean r_vis"
        );
        let f = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
        for g in &self.groups {
            let _ = writeln!(
                t,
                "{:<20} {:>7} {:>7} {:>10} {:>11} {:>10}",
                g.name,
                g.count,
                g.with_d_plan,
                f(g.mean_d_sat, 2),
                f(g.mean_d_plan, 2),
                f(g.mean_r_vis, 4)
            );
        }
        t
    }
}

/// Length of the bar of `n` when the largest count is `max`: `round(BAR_WIDTH · n / max)`, at
/// least 1 for a non-zero count.
pub fn bar(n: usize, max: usize) -> usize {
    if n == 0 || max == 0 {
        return 0;
    }
    ((BAR_WIDTH as f64 * n as f64 / max as f64).round() as usize).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::split::tests::ann;
    use crate::split::{make_splits, write_splits, SplitSettings};

    fn with(uid: &str, d_plan: Option<usize>, slow: bool, d_sat: usize, r_vis: f64) -> Annotation {
        let mut a = ann(uid, d_plan, slow);
        a.d_sat = d_sat;
        a.r_vis = r_vis;
        a
    }

    fn hand_made() -> AnnotationSet {
        AnnotationSet {
            annotations: vec![
                with("d", Some(12), true, 200, 0.5),
                with("a", Some(3), false, 20, 0.8),
                with("c", None, false, 30, 0.7),
                with("b", Some(7), false, 40, 0.6),
            ],
            failures: vec![objview_dataset::Failure {
                uid: "x".into(),
                mesh: "x.obj".into(),
                error: "x.obj: mesh has no triangles".into(),
                settings: json!({}),
                version: "0".into(),
            }],
        }
    }

    #[test]
    fn counts_histogram_and_means_of_a_hand_made_set() {
        let s = pool_stats(&hand_made(), None).unwrap();
        assert_eq!((s.annotated, s.failures, s.slow_saturation, s.main, s.unsolved_d_plan), (4, 1, 1, 3, 1));
        // d_plan 12 (slow) reaches bucket 11-15: three buckets; the main pool has 3 and 7.
        assert_eq!(s.buckets, 3);
        assert_eq!(s.histogram, [1, 1, 0]);
        let names: Vec<&str> = s.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["all", "main", "slow_saturation"]);
        let close = |a: Option<f64>, b: f64| (a.unwrap() - b).abs() < 1e-12;
        let all = &s.groups[0];
        assert_eq!((all.count, all.with_d_plan, all.buckets.clone()), (4, 3, vec![1, 1, 1]));
        assert!(
            close(all.mean_d_sat, 72.5) && close(all.mean_d_plan, 22.0 / 3.0) && close(all.mean_r_vis, 0.65)
        );
        let main = &s.groups[1];
        assert_eq!((main.count, main.with_d_plan), (3, 2));
        assert!(close(main.mean_d_sat, 30.0) && close(main.mean_d_plan, 5.0) && close(main.mean_r_vis, 0.7));
        let slow = &s.groups[2];
        assert!(
            close(slow.mean_d_sat, 200.0) && close(slow.mean_d_plan, 12.0) && close(slow.mean_r_vis, 0.5)
        );

        let text = s.to_text();
        assert!(
            text.contains("4 annotated, 1 failed; 1 slow-saturation, 3 main (1 without a proven d_plan)"),
            "{text}"
        );
        assert!(text.contains(&format!("    1-5      1 {}\n", "#".repeat(40))), "{text}");
        assert!(text.contains("    11-15      0\n"), "{text}");
        assert!(
            text.contains("main                       3       2      30.00        5.00     0.7000"),
            "{text}"
        );
        let j = s.to_json(&json!({"tool": "objview"}));
        assert_eq!(j["counts"]["unsolved_d_plan"], 1);
        assert_eq!(j["bucket_labels"], json!(["1-5", "6-10", "11-15"]));
        assert_eq!(j["groups"][2]["mean_d_plan"], 12.0);
        assert_eq!(j["settings"]["tool"], "objview");
    }

    #[test]
    fn empty_groups_have_no_means() {
        let mut set = hand_made();
        set.annotations.retain(|a| !a.slow_saturation);
        let s = pool_stats(&set, None).unwrap();
        assert_eq!(s.groups[2].count, 0);
        assert_eq!(s.groups[2].mean_d_sat, None);
        assert!(s
            .to_text()
            .contains("slow_saturation            0       0          -           -          -"));
        assert_eq!(s.to_json(&json!({}))["groups"][2]["mean_r_vis"], Value::Null);
    }

    #[test]
    fn bars_scale_to_the_largest_count() {
        assert_eq!([bar(0, 10), bar(1, 1000), bar(5, 10), bar(10, 10), bar(3, 0)], [0, 1, 20, 40, 0]);
    }

    #[test]
    fn groups_follow_split_files() {
        let dir = tempfile::tempdir().unwrap();
        let mut set = hand_made();
        for i in 0..20 {
            set.annotations.push(with(&format!("m{i:02}"), Some(1 + i % 9), false, 10 + i, 0.9));
        }
        let splits = make_splits(&set, &SplitSettings { test_fraction: 0.25, ..Default::default() }).unwrap();
        write_splits(&splits, dir.path(), &json!({})).unwrap();
        let members = read_split_dir(dir.path()).unwrap();
        assert_eq!(members.len(), 5);
        let s = pool_stats(&set, Some(&members)).unwrap();
        for (g, name) in s.groups.iter().zip(SplitName::ALL) {
            assert_eq!(g.name, name.as_str());
            assert_eq!(g.count, splits.get(name).len());
            let expected = mean(splits.get(name).iter().map(|a| a.d_sat as f64));
            assert_eq!(g.mean_d_sat, expected, "{name}");
        }
        // Counts do not depend on the splits.
        assert_eq!((s.annotated, s.main, s.unsolved_d_plan), (24, 23, 1));

        // A split naming an object the annotations lack.
        let mut fewer = set.clone();
        let gone = splits.main_hidden_test[0].uid.clone();
        fewer.annotations.retain(|a| a.uid != gone);
        let err = pool_stats(&fewer, Some(&members)).unwrap_err().to_string();
        assert!(err.contains("main_hidden_test.json") && err.contains(&format!("'{gone}'")), "{err}");

        let empty = tempfile::tempdir().unwrap();
        let err = read_split_dir(empty.path()).unwrap_err().to_string();
        assert!(err.contains("no split files"), "{err}");
    }
}
