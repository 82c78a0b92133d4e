//! Difficulty splits of the pool (SPEC §6, paper §4): which annotated objects go to the
//! Slow-Saturation diagnostic split, the Main-Hidden-Test split, Main-Train-Public and its two
//! training subsets. The splits are what the benchmark is scored on, so the rule is exact,
//! documented and reproducible: the same annotations and seed give the same files byte for byte,
//! whatever the order of the input lines.
//!
//! Rules (every constant is a setting recorded in `split_report.json`):
//! - Failure lines are ignored (counted). `slow_saturation` objects form the Slow-Saturation
//!   split, whatever their d_plan. The others form the main pool, except objects whose d_plan is
//!   not a proven optimum (`time_limit`, errors) or is 0: they cannot be bucketed and are
//!   excluded from every split, with the reason, in the report.
//! - d_plan buckets have width [`BUCKET_WIDTH`]: bucket `(d_plan − 1) / 5`, labelled `1-5`,
//!   `6-10`, …
//! - Main-Hidden-Test takes `round(test_fraction × |main|)` objects ([`hidden_test_allocation`]):
//!   stage 1 one object from every non-empty bucket (rarest buckets first when the quota is
//!   smaller than the number of buckets), stage 2 the rest of the quota in proportion to the
//!   bucket frequencies by largest remainders, capped by what a bucket has left. Main-Train-Public
//!   is the rest of the main pool.
//! - Main-Raw-Train: a uniformly random subset of Main-Train-Public (default size: half of it,
//!   rounded down). Main-Balanced-Train: the same size, an equal quota per non-empty bucket,
//!   topped up from the buckets with most objects left ([`balanced_allocation`]).
//! - Randomness: ChaCha8 seeded with `seed`, one stream per draw (0 hidden test, 1 raw train,
//!   2 balanced train); within a bucket objects are drawn by a partial Fisher–Yates shuffle of
//!   the bucket's objects sorted by uid, buckets in ascending order.
//!
//! Split files are JSON arrays in the split-file format of `objview_dataset::read_split`, with
//! paths relative to the output folder, so `objview annotate DIR/main_hidden_test.json` works.

use std::fmt;
use std::path::{Component, Path, PathBuf};

use objview_dataset::{Annotation, AnnotationSet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};

use crate::error::PoolError;

/// Width of a d_plan bucket (SPEC §6: 1–5, 6–10, …).
pub const BUCKET_WIDTH: usize = 5;
/// Default Main-Hidden-Test fraction of the main pool (SPEC §6: 528 of 5523).
pub const DEFAULT_TEST_FRACTION: f64 = 528.0 / 5523.0;
/// Default seed of the split draws.
pub const DEFAULT_SPLIT_SEED: u64 = 0;
/// ChaCha8 stream of the Main-Hidden-Test draw.
const STREAM_HIDDEN_TEST: u64 = 0;
/// ChaCha8 stream of the Main-Raw-Train draw.
const STREAM_RAW_TRAIN: u64 = 1;
/// ChaCha8 stream of the Main-Balanced-Train draw.
const STREAM_BALANCED_TRAIN: u64 = 2;
/// ChaCha8 stream of the Main-Analysis-Test draw ([`analysis_test`]).
const STREAM_ANALYSIS_TEST: u64 = 3;
/// File name of Main-Analysis-Test (written by the difficulty-aware experiment, not by
/// `objview pool split`).
pub const ANALYSIS_TEST_FILE: &str = "main_analysis_test.json";
/// Name of the report written beside the split files.
pub const REPORT_FILE: &str = "split_report.json";

/// The d_plan bucket of `d_plan` (0-based), `None` for 0 (nothing to cover).
pub fn bucket_of(d_plan: usize) -> Option<usize> {
    (d_plan > 0).then(|| (d_plan - 1) / BUCKET_WIDTH)
}

/// The label of bucket `b`: `"1-5"`, `"6-10"`, …
pub fn bucket_label(b: usize) -> String {
    format!("{}-{}", b * BUCKET_WIDTH + 1, (b + 1) * BUCKET_WIDTH)
}

/// The proven, positive d_plan of an annotation, or why there is none.
pub fn proven_d_plan(a: &Annotation) -> Result<usize, String> {
    match a.d_plan {
        Some(_) if a.d_plan_status != "optimal" => {
            Err(format!("d_plan_status '{}' is not 'optimal' but d_plan is set", a.d_plan_status))
        }
        Some(0) => Err("d_plan = 0 (nothing to cover: empty universe)".to_string()),
        Some(d) => Ok(d),
        None => Err(format!(
            "d_plan not proven optimal (status '{}', lower bound {})",
            a.d_plan_status, a.d_plan_bound
        )),
    }
}

/// The splits written by `objview pool split`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SplitName {
    /// Slow-Saturation: the diagnostic split of objects with d_sat > 128.
    SlowSaturation,
    /// Main-Hidden-Test: drawn from the main pool by the two-stage bucket rule.
    MainHiddenTest,
    /// Main-Train-Public: the main pool less Main-Hidden-Test.
    MainTrainPublic,
    /// Main-Raw-Train: a uniformly random subset of Main-Train-Public.
    MainRawTrain,
    /// Main-Balanced-Train: as large as Main-Raw-Train, an equal quota per d_plan bucket.
    MainBalancedTrain,
}

impl SplitName {
    /// Every split, in report order.
    pub const ALL: [SplitName; 5] = [
        SplitName::SlowSaturation,
        SplitName::MainHiddenTest,
        SplitName::MainTrainPublic,
        SplitName::MainRawTrain,
        SplitName::MainBalancedTrain,
    ];

    /// The split's name in files and reports (`main_hidden_test`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            SplitName::SlowSaturation => "slow_saturation",
            SplitName::MainHiddenTest => "main_hidden_test",
            SplitName::MainTrainPublic => "main_train_public",
            SplitName::MainRawTrain => "main_raw_train",
            SplitName::MainBalancedTrain => "main_balanced_train",
        }
    }

    /// The split file's name (`main_hidden_test.json`, …).
    pub fn file_name(self) -> String {
        format!("{}.json", self.as_str())
    }

    /// The split of a file name written by [`write_splits`] (`main_hidden_test.json`).
    pub fn from_file_name(name: &str) -> Option<SplitName> {
        SplitName::ALL.into_iter().find(|s| s.file_name() == name)
    }
}

impl fmt::Display for SplitName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Settings of the split rule (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct SplitSettings {
    /// Seed of every draw.
    pub seed: u64,
    /// Main-Hidden-Test quota as a fraction of the main pool, in [0, 1].
    pub test_fraction: f64,
    /// Size of Main-Raw-Train and Main-Balanced-Train; `None`: half of Main-Train-Public,
    /// rounded down.
    pub train_size: Option<usize>,
}

impl Default for SplitSettings {
    fn default() -> Self {
        SplitSettings { seed: DEFAULT_SPLIT_SEED, test_fraction: DEFAULT_TEST_FRACTION, train_size: None }
    }
}

impl SplitSettings {
    /// Checks ranges; errors name the setting.
    pub fn validate(&self) -> Result<(), PoolError> {
        if !(self.test_fraction.is_finite() && (0.0..=1.0).contains(&self.test_fraction)) {
            return Err(PoolError::InvalidSetting {
                name: "test_fraction",
                reason: format!("must be a number in [0, 1], got {}", self.test_fraction),
            });
        }
        Ok(())
    }

    /// The settings as recorded in `split_report.json`.
    pub fn to_json(&self) -> Value {
        json!({
            "seed": self.seed,
            "test_fraction": self.test_fraction,
            "train_size": self.train_size,
            "bucket_width": BUCKET_WIDTH,
            "hidden_test_rule": "quota = round(test_fraction * |main|); stage 1: one object per non-empty \
                d_plan bucket (rarest first if the quota is smaller); stage 2: the rest in proportion to the \
                bucket frequencies by largest remainders (ties: lower bucket), capped by what a bucket has left",
            "balanced_rule": "floor(size / non-empty buckets) per bucket, the shortfall one object at a time \
                from the bucket with most objects left (ties: lower bucket)",
            "rng": "ChaCha8 seed_from_u64(seed), stream 0 hidden test, 1 raw train, 2 balanced train; \
                partial Fisher-Yates over uid-sorted objects, buckets ascending",
        })
    }
}

/// The Main-Hidden-Test quota: `round(fraction × main)`, at most `main`.
pub fn hidden_test_quota(main: usize, fraction: f64) -> usize {
    ((fraction * main as f64).round() as usize).min(main)
}

/// How many objects the two-stage rule takes from each bucket, given the main pool's bucket
/// counts and the quota (capped at the pool size); see the module docs.
pub fn hidden_test_allocation(counts: &[usize], quota: usize) -> Vec<usize> {
    let total: usize = counts.iter().sum();
    let quota = quota.min(total);
    let mut take = vec![0usize; counts.len()];
    // Stage 1: one per non-empty bucket, rarest first (ties: lower bucket).
    let mut nonempty: Vec<usize> = (0..counts.len()).filter(|&b| counts[b] > 0).collect();
    nonempty.sort_by_key(|&b| (counts[b], b));
    for &b in nonempty.iter().take(quota) {
        take[b] = 1;
    }
    let rest = quota - take.iter().sum::<usize>();
    if rest == 0 {
        return take;
    }
    // Stage 2: largest remainders of rest·n_b/N, in exact integer arithmetic.
    let cap: Vec<usize> = counts.iter().zip(&take).map(|(n, t)| n - t).collect();
    let (rest128, total128) = (rest as u128, total as u128);
    let mut extra = vec![0usize; counts.len()];
    let mut remainder = vec![0u128; counts.len()];
    for b in 0..counts.len() {
        let num = rest128 * counts[b] as u128;
        extra[b] = ((num / total128) as usize).min(cap[b]);
        remainder[b] = num % total128;
    }
    let mut left = rest - extra.iter().sum::<usize>();
    let mut order: Vec<usize> = (0..counts.len()).collect();
    order.sort_by(|&a, &b| remainder[b].cmp(&remainder[a]).then(a.cmp(&b)));
    while left > 0 {
        for &b in &order {
            if left == 0 {
                break;
            }
            if extra[b] < cap[b] {
                extra[b] += 1;
                left -= 1;
            }
        }
    }
    take.iter().zip(&extra).map(|(t, e)| t + e).collect()
}

/// How many objects Main-Balanced-Train takes from each bucket of Main-Train-Public (`counts`)
/// for a subset of `size` objects (capped at the total): `floor(size / non-empty buckets)` each
/// where a bucket has them, then one at a time from the bucket with most objects left (ties:
/// lower bucket).
pub fn balanced_allocation(counts: &[usize], size: usize) -> Vec<usize> {
    let total: usize = counts.iter().sum();
    let size = size.min(total);
    let nonempty = counts.iter().filter(|&&n| n > 0).count();
    if nonempty == 0 {
        return vec![0; counts.len()];
    }
    let quota = size / nonempty;
    let mut take: Vec<usize> = counts.iter().map(|&n| n.min(quota)).collect();
    let mut left = size - take.iter().sum::<usize>();
    while left > 0 {
        let mut best = 0;
        for b in 1..counts.len() {
            if counts[b] - take[b] > counts[best] - take[best] {
                best = b;
            }
        }
        take[best] += 1;
        left -= 1;
    }
    take
}

/// `k` distinct positions of `0..n`, uniformly at random (partial Fisher–Yates with 64-bit
/// draws, so the result does not depend on the platform's word size), ascending.
fn draw(rng: &mut ChaCha8Rng, n: usize, k: usize) -> Vec<usize> {
    debug_assert!(k <= n);
    let mut idx: Vec<usize> = (0..n).collect();
    for i in 0..k {
        let j = rng.gen_range(i as u64..n as u64) as usize;
        idx.swap(i, j);
    }
    let mut out = idx[..k].to_vec();
    out.sort_unstable();
    out
}

fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// A main-pool object left out of every split.
#[derive(Debug, Clone, PartialEq)]
pub struct Excluded {
    /// Object id.
    pub uid: String,
    /// Its annotation's `d_plan_status` (e.g. `time_limit`, `error: …`, or `optimal` with d_plan 0).
    pub d_plan_status: String,
    /// Why it cannot be bucketed.
    pub reason: String,
}

/// The splits of one set of annotations (every list sorted by uid).
#[derive(Debug, Clone, PartialEq)]
pub struct Splits {
    /// The Slow-Saturation split ([`SplitName::SlowSaturation`]).
    pub slow_saturation: Vec<Annotation>,
    /// The Main-Hidden-Test split ([`SplitName::MainHiddenTest`]).
    pub main_hidden_test: Vec<Annotation>,
    /// The Main-Train-Public split ([`SplitName::MainTrainPublic`]).
    pub main_train_public: Vec<Annotation>,
    /// The Main-Raw-Train split ([`SplitName::MainRawTrain`]).
    pub main_raw_train: Vec<Annotation>,
    /// The Main-Balanced-Train split ([`SplitName::MainBalancedTrain`]).
    pub main_balanced_train: Vec<Annotation>,
    /// Main-pool objects without a proven positive d_plan.
    pub excluded: Vec<Excluded>,
    /// Failure lines ignored.
    pub failures: usize,
    /// Main-pool objects per d_plan bucket (index = bucket, up to the largest non-empty one).
    pub main_buckets: Vec<usize>,
    /// The Main-Hidden-Test quota.
    pub hidden_test_quota: usize,
    /// The size of Main-Raw-Train and Main-Balanced-Train.
    pub train_size: usize,
}

impl Splits {
    /// The human summary of a split: counts, the hidden-test quota and train size, and the
    /// d_plan bucket table of the main pool and each main split (`objview pool split` prints
    /// it). `annotations` is the number of annotations read; `test_fraction` the setting.
    pub fn summary_text(&self, annotations: usize, test_fraction: f64) -> String {
        use std::fmt::Write as _;
        let mut t = String::new();
        let _ = writeln!(
            t,
            "pool split: {annotations} annotations ({} failure lines ignored): {} slow-saturation, {} main, {} excluded \
             (no proven d_plan; reasons in {REPORT_FILE})",
            self.failures,
            self.slow_saturation.len(),
            self.main(),
            self.excluded.len()
        );
        let _ = writeln!(
            t,
            "hidden-test quota {} (fraction {test_fraction}), train size {}",
            self.hidden_test_quota, self.train_size
        );
        let main_splits = &SplitName::ALL[1..];
        let short = |s: &SplitName| s.as_str().trim_start_matches("main_");
        let _ = write!(t, "\n{:<8} {:>6}", "d_plan", "main");
        for s in main_splits {
            let _ = write!(t, " {:>14}", short(s));
        }
        t.push('\n');
        let per_split: Vec<Vec<usize>> = main_splits.iter().map(|&s| self.bucket_counts(s)).collect();
        for b in 0..self.main_buckets.len() {
            let _ = write!(t, "{:<8} {:>6}", bucket_label(b), self.main_buckets[b]);
            for c in &per_split {
                let _ = write!(t, " {:>14}", c[b]);
            }
            t.push('\n');
        }
        let _ = write!(t, "{:<8} {:>6}", "total", self.main());
        for &s in main_splits {
            let _ = write!(t, " {:>14}", self.get(s).len());
        }
        t.push('\n');
        t
    }

    /// The objects of one split.
    pub fn get(&self, name: SplitName) -> &[Annotation] {
        match name {
            SplitName::SlowSaturation => &self.slow_saturation,
            SplitName::MainHiddenTest => &self.main_hidden_test,
            SplitName::MainTrainPublic => &self.main_train_public,
            SplitName::MainRawTrain => &self.main_raw_train,
            SplitName::MainBalancedTrain => &self.main_balanced_train,
        }
    }

    /// Size of the (bucketed) main pool.
    pub fn main(&self) -> usize {
        self.main_buckets.iter().sum()
    }

    /// Objects of split `name` per d_plan bucket (same length as `main_buckets`; objects without
    /// a proven d_plan or beyond the main pool's buckets, possible only in the slow split, are
    /// not counted).
    pub fn bucket_counts(&self, name: SplitName) -> Vec<usize> {
        let mut counts = vec![0; self.main_buckets.len()];
        for a in self.get(name) {
            if let Some(b) = proven_d_plan(a).ok().and_then(bucket_of) {
                if let Some(c) = counts.get_mut(b) {
                    *c += 1;
                }
            }
        }
        counts
    }

    /// The `split_report.json` content: `settings` (given by the caller, with tool, version and
    /// inputs), counts per split, per bucket, and the excluded objects with their reasons.
    pub fn report(&self, settings: &Value) -> Value {
        let mut counts = serde_json::Map::new();
        counts.insert("failures".into(), json!(self.failures));
        counts.insert("main".into(), json!(self.main()));
        counts.insert("excluded".into(), json!(self.excluded.len()));
        for s in SplitName::ALL {
            counts.insert(s.as_str().into(), json!(self.get(s).len()));
        }
        let per_split: Vec<(SplitName, Vec<usize>)> =
            SplitName::ALL[1..].iter().map(|&s| (s, self.bucket_counts(s))).collect();
        let buckets: Vec<Value> = (0..self.main_buckets.len())
            .map(|b| {
                let mut row = serde_json::Map::new();
                row.insert("bucket".into(), json!(bucket_label(b)));
                row.insert("main".into(), json!(self.main_buckets[b]));
                for (s, c) in &per_split {
                    row.insert(s.as_str().into(), json!(c[b]));
                }
                Value::Object(row)
            })
            .collect();
        let files: serde_json::Map<String, Value> =
            SplitName::ALL.iter().map(|s| (s.as_str().to_string(), json!(s.file_name()))).collect();
        json!({
            "settings": settings,
            "counts": counts,
            "hidden_test_quota": self.hidden_test_quota,
            "train_size": self.train_size,
            "buckets": buckets,
            "excluded": self.excluded.iter().map(|e| json!({
                "uid": e.uid, "d_plan_status": e.d_plan_status, "reason": e.reason,
            })).collect::<Vec<_>>(),
            "files": files,
        })
    }
}

/// Applies the split rule (module docs) to `set`. Errors: settings out of range, or a
/// `train_size` larger than Main-Train-Public.
pub fn make_splits(set: &AnnotationSet, settings: &SplitSettings) -> Result<Splits, PoolError> {
    settings.validate()?;
    let mut sorted: Vec<&Annotation> = set.annotations.iter().collect();
    sorted.sort_by(|a, b| a.uid.cmp(&b.uid));

    let mut slow = Vec::new();
    let mut excluded = Vec::new();
    let mut by_bucket: Vec<Vec<&Annotation>> = Vec::new();
    for a in sorted {
        if a.slow_saturation {
            slow.push(a.clone());
            continue;
        }
        match proven_d_plan(a) {
            Ok(d) => {
                let b = bucket_of(d).expect("d_plan > 0");
                if by_bucket.len() <= b {
                    by_bucket.resize_with(b + 1, Vec::new);
                }
                by_bucket[b].push(a);
            }
            Err(reason) => {
                excluded.push(Excluded { uid: a.uid.clone(), d_plan_status: a.d_plan_status.clone(), reason })
            }
        }
    }
    let main_buckets: Vec<usize> = by_bucket.iter().map(Vec::len).collect();
    let main: usize = main_buckets.iter().sum();

    // Main-Hidden-Test and Main-Train-Public.
    let quota = hidden_test_quota(main, settings.test_fraction);
    let alloc = hidden_test_allocation(&main_buckets, quota);
    let mut r = rng(settings.seed, STREAM_HIDDEN_TEST);
    let mut test = Vec::with_capacity(quota);
    let mut public_buckets: Vec<Vec<&Annotation>> = Vec::with_capacity(by_bucket.len());
    for (objs, &k) in by_bucket.iter().zip(&alloc) {
        let chosen = draw(&mut r, objs.len(), k);
        let mut next = chosen.iter().peekable();
        let mut rest = Vec::with_capacity(objs.len() - k);
        for (i, a) in objs.iter().enumerate() {
            if next.peek() == Some(&&i) {
                next.next();
                test.push((*a).clone());
            } else {
                rest.push(*a);
            }
        }
        public_buckets.push(rest);
    }
    let mut public: Vec<&Annotation> = public_buckets.iter().flatten().copied().collect();
    public.sort_by(|a, b| a.uid.cmp(&b.uid));
    test.sort_by(|a, b| a.uid.cmp(&b.uid));

    // Training subsets.
    let train_size = settings.train_size.unwrap_or(public.len() / 2);
    if train_size > public.len() {
        return Err(PoolError::InvalidSetting {
            name: "train_size",
            reason: format!("{train_size} exceeds Main-Train-Public ({} objects)", public.len()),
        });
    }
    let mut r = rng(settings.seed, STREAM_RAW_TRAIN);
    let raw: Vec<Annotation> =
        draw(&mut r, public.len(), train_size).into_iter().map(|i| public[i].clone()).collect();

    let public_counts: Vec<usize> = public_buckets.iter().map(Vec::len).collect();
    let balanced_alloc = balanced_allocation(&public_counts, train_size);
    let mut r = rng(settings.seed, STREAM_BALANCED_TRAIN);
    let mut balanced = Vec::with_capacity(train_size);
    for (objs, &k) in public_buckets.iter().zip(&balanced_alloc) {
        balanced.extend(draw(&mut r, objs.len(), k).into_iter().map(|i| objs[i].clone()));
    }
    balanced.sort_by(|a, b| a.uid.cmp(&b.uid));

    Ok(Splits {
        slow_saturation: slow,
        main_hidden_test: test,
        main_train_public: public.into_iter().cloned().collect(),
        main_raw_train: raw,
        main_balanced_train: balanced,
        excluded,
        failures: set.failures.len(),
        main_buckets,
        hidden_test_quota: quota,
        train_size,
    })
}

/// Main-Analysis-Test, the held-out objects of the difficulty-aware training experiment: `size`
/// objects of Main-Train-Public that are in neither Main-Raw-Train nor Main-Balanced-Train,
/// drawn by the Main-Hidden-Test two-stage rule ([`hidden_test_allocation`]: one object from
/// every non-empty d_plan bucket first, rarest first, then the rest in proportion to the bucket
/// frequencies) with ChaCha8 stream 3 of `seed` (partial Fisher–Yates over the bucket's
/// uid-sorted objects, buckets ascending), so every difficulty level the pool has is evaluated.
/// Sorted by uid. Errors: fewer than `size` objects left.
pub fn analysis_test(splits: &Splits, size: usize, seed: u64) -> Result<Vec<Annotation>, PoolError> {
    let used: std::collections::BTreeSet<&str> =
        splits.main_raw_train.iter().chain(&splits.main_balanced_train).map(|a| a.uid.as_str()).collect();
    let mut by_bucket: Vec<Vec<&Annotation>> = Vec::new();
    let mut left: Vec<&Annotation> =
        splits.main_train_public.iter().filter(|a| !used.contains(a.uid.as_str())).collect();
    left.sort_by(|a, b| a.uid.cmp(&b.uid));
    for a in left {
        let b = proven_d_plan(a).ok().and_then(bucket_of).expect("Main-Train-Public has proven d_plan");
        if by_bucket.len() <= b {
            by_bucket.resize_with(b + 1, Vec::new);
        }
        by_bucket[b].push(a);
    }
    let counts: Vec<usize> = by_bucket.iter().map(Vec::len).collect();
    let available: usize = counts.iter().sum();
    if size > available {
        return Err(PoolError::InvalidSetting {
            name: "analysis_size",
            reason: format!(
                "{size} exceeds the {available} Main-Train-Public objects in neither training subset"
            ),
        });
    }
    let alloc = hidden_test_allocation(&counts, size);
    let mut r = rng(seed, STREAM_ANALYSIS_TEST);
    let mut out: Vec<Annotation> = Vec::with_capacity(size);
    for (objs, &k) in by_bucket.iter().zip(&alloc) {
        out.extend(draw(&mut r, objs.len(), k).into_iter().map(|i| objs[i].clone()));
    }
    out.sort_by(|a, b| a.uid.cmp(&b.uid));
    Ok(out)
}

/// Whether an annotation's `gt_cloud` names a file (rather than `sampled(…)`).
pub fn gt_cloud_is_file(gt_cloud: &str) -> bool {
    !gt_cloud.is_empty() && !gt_cloud.starts_with("sampled(")
}

/// One split-file entry: `{uid, mesh, gt_cloud (files only), annotation: {…}}`, paths written
/// relative to `out_dir` where possible ([`path_for_split`]).
pub fn split_entry(a: &Annotation, out_dir: &Path) -> Value {
    let mut entry = serde_json::Map::new();
    entry.insert("uid".into(), json!(a.uid));
    entry.insert("mesh".into(), json!(path_for_split(&a.mesh, out_dir)));
    if gt_cloud_is_file(&a.gt_cloud) {
        entry.insert("gt_cloud".into(), json!(path_for_split(&a.gt_cloud, out_dir)));
    }
    entry.insert(
        "annotation".into(),
        json!({
            "d_plan": a.d_plan,
            "d_sat": a.d_sat,
            "r_vis": a.r_vis,
            "n_star": a.n_star,
            "slow_saturation": a.slow_saturation,
            "surface_voxels": a.surface_voxels,
            "universe": a.universe,
            "d_plan_status": a.d_plan_status,
        }),
    );
    Value::Object(entry)
}

/// `path` (relative to the current folder, or absolute) as seen from `dir`: a relative path when
/// both resolve to absolute paths with a common root, else the absolute path (else `path` as
/// given). Existing paths are canonicalized (symlinks resolved); others are made absolute and
/// cleaned of `.` and `..` lexically.
pub fn path_for_split(path: &str, dir: &Path) -> String {
    let (Some(p), Some(d)) = (resolve(Path::new(path)), resolve(dir)) else {
        return path.to_string();
    };
    match relative(&p, &d) {
        Some(rel) => rel.to_string_lossy().into_owned(),
        None => p.to_string_lossy().into_owned(),
    }
}

fn resolve(p: &Path) -> Option<PathBuf> {
    if let Ok(c) = p.canonicalize() {
        return Some(c);
    }
    let abs = std::path::absolute(p).ok()?;
    let mut out = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    Some(out)
}

/// `p` relative to `base` (both absolute and clean); `None` when their roots differ.
fn relative(p: &Path, base: &Path) -> Option<PathBuf> {
    let pc: Vec<Component> = p.components().collect();
    let bc: Vec<Component> = base.components().collect();
    if pc.first() != bc.first() {
        return None;
    }
    let common = pc.iter().zip(&bc).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..bc.len() {
        out.push("..");
    }
    for c in &pc[common..] {
        out.push(c);
    }
    Some(out)
}

/// Writes every split file and `split_report.json` (with `settings`) into `out_dir` (created if
/// missing) as pretty JSON; returns the paths written.
pub fn write_splits(splits: &Splits, out_dir: &Path, settings: &Value) -> Result<Vec<PathBuf>, PoolError> {
    std::fs::create_dir_all(out_dir).map_err(|e| PoolError::io(out_dir, e))?;
    let mut written = Vec::new();
    for s in SplitName::ALL {
        let entries: Vec<Value> = splits.get(s).iter().map(|a| split_entry(a, out_dir)).collect();
        let path = out_dir.join(s.file_name());
        write_pretty(&path, &Value::Array(entries))?;
        written.push(path);
    }
    let path = out_dir.join(REPORT_FILE);
    write_pretty(&path, &splits.report(settings))?;
    written.push(path);
    Ok(written)
}

/// Writes `v` as pretty JSON with a trailing newline.
pub(crate) fn write_pretty(path: &Path, v: &Value) -> Result<(), PoolError> {
    let mut s = serde_json::to_string_pretty(v).expect("JSON values serialize");
    s.push('\n');
    std::fs::write(path, s).map_err(|e| PoolError::io(path, e))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// An annotation line as `objview annotate` writes it, with the fields the split reads set.
    pub(crate) fn ann(uid: &str, d_plan: Option<usize>, slow: bool) -> Annotation {
        let status = if d_plan.is_some() { "optimal" } else { "time_limit" };
        serde_json::from_value(json!({
            "uid": uid, "mesh": format!("meshes/{uid}.obj"), "gt_cloud": "sampled(seed=0, count=20000)",
            "vertices": 8, "faces": 12, "gt_points": 20000, "surface_voxels": 1000,
            "curve": [[6, 500], [492, 990]], "mu": 2.0, "sigma": 0.5, "n_star": if slow { 200.4 } else { 40.4 },
            "d_sat": if slow { 200 } else { 40 }, "r_vis": 0.9, "grid_n": 48, "grid_r_vis": 0.91,
            "slow_saturation": slow, "degenerate_fit": false, "universe": 990,
            "d_plan": d_plan, "d_plan_status": status, "d_plan_bound": d_plan.unwrap_or(7),
            "lp_bound": 3.5, "greedy_cover": 5, "cover_views": [],
            "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
                "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1,
                "reduced_views": 0, "reduced_elements": 0},
            "solver_seconds": 0.1, "seconds": 1.0,
            "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0, "cover": 0.0},
            "settings": {}, "version": "0.1.0",
        }))
        .unwrap()
    }

    /// A main pool with `counts[b]` objects in bucket b (d_plan = 5b + 1 + i % 5), uids `b{b}_{i}`.
    fn pool(counts: &[usize]) -> AnnotationSet {
        let mut set = AnnotationSet::default();
        for (b, &n) in counts.iter().enumerate() {
            for i in 0..n {
                set.annotations.push(ann(&format!("b{b:02}_{i:04}"), Some(5 * b + 1 + i % 5), false));
            }
        }
        set
    }

    fn uids(v: &[Annotation]) -> Vec<&str> {
        v.iter().map(|a| a.uid.as_str()).collect()
    }

    /// Main-Analysis-Test: disjoint from both training subsets, inside Main-Train-Public, one
    /// object per bucket that has objects left before proportional filling, deterministic, and a
    /// size beyond what is left is an error naming the setting.
    #[test]
    fn analysis_test_is_held_out_and_covers_every_bucket() {
        let set = pool(&[40, 12, 3, 1]);
        let settings = SplitSettings { seed: 5, test_fraction: 0.1, train_size: Some(10) };
        let splits = make_splits(&set, &settings).unwrap();
        let a = analysis_test(&splits, 8, 5).unwrap();
        assert_eq!(a.len(), 8);
        assert_eq!(a, analysis_test(&splits, 8, 5).unwrap(), "deterministic");
        let public: std::collections::BTreeSet<&str> = uids(&splits.main_train_public).into_iter().collect();
        let used: std::collections::BTreeSet<&str> =
            uids(&splits.main_raw_train).into_iter().chain(uids(&splits.main_balanced_train)).collect();
        let mut left_counts = vec![0usize; 4];
        for x in &splits.main_train_public {
            if !used.contains(x.uid.as_str()) {
                left_counts[bucket_of(x.d_plan.unwrap()).unwrap()] += 1;
            }
        }
        let mut got = vec![0usize; 4];
        for x in &a {
            assert!(public.contains(x.uid.as_str()) && !used.contains(x.uid.as_str()), "{}", x.uid);
            got[bucket_of(x.d_plan.unwrap()).unwrap()] += 1;
        }
        assert_eq!(got, hidden_test_allocation(&left_counts, 8));
        for b in 0..4 {
            assert!(got[b] >= 1 || left_counts[b] == 0, "bucket {b}: {got:?} of {left_counts:?}");
        }
        let total: usize = left_counts.iter().sum();
        let err = analysis_test(&splits, total + 1, 5).unwrap_err().to_string();
        assert!(err.contains("analysis_size"), "{err}");
        assert_eq!(analysis_test(&splits, total, 5).unwrap().len(), total);
    }

    #[test]
    fn buckets_have_width_five() {
        assert_eq!(bucket_of(0), None);
        assert_eq!([1, 5, 6, 10, 11, 128].map(|d| bucket_of(d).unwrap()), [0, 0, 1, 1, 2, 25]);
        assert_eq!(bucket_label(0), "1-5");
        assert_eq!(bucket_label(2), "11-15");
    }

    #[test]
    fn hidden_test_allocation_hand_computed() {
        // N = 100, quota 20: stage 1 takes one from each of the 5 non-empty buckets; the other
        // 15 go by 15·n_b/100 = 8.25, 4.5, 1.5, 0.15, 0.6 → floors 8, 4, 1, 0, 0 (13); the 2
        // left by largest remainders: .6 (bucket 4), then .5 (bucket 1, lower than bucket 2).
        let counts = [55, 30, 10, 1, 4];
        assert_eq!(hidden_test_allocation(&counts, 20), vec![1 + 8, 1 + 5, 1 + 1, 1, 1 + 1]);
        // Rarest first, ties by lower bucket, when the quota is smaller than the bucket count.
        assert_eq!(hidden_test_allocation(&counts, 2), vec![0, 0, 0, 1, 1]);
        assert_eq!(hidden_test_allocation(&[3, 0, 2, 2, 5], 2), vec![0, 0, 1, 1, 0]);
        assert_eq!(hidden_test_allocation(&counts, 0), vec![0; 5]);
        // Caps: the whole pool when the quota is the pool (overflow goes to other buckets).
        assert_eq!(hidden_test_allocation(&counts, 100), counts.to_vec());
        assert_eq!(hidden_test_allocation(&counts, 1000), counts.to_vec());
        // Every quota gives exactly the quota, within the bucket sizes.
        for q in 0..=100 {
            let a = hidden_test_allocation(&counts, q);
            assert_eq!(a.iter().sum::<usize>(), q);
            assert!(a.iter().zip(&counts).all(|(t, n)| t <= n));
            if q >= 5 {
                assert!(a.iter().zip(&counts).all(|(t, n)| *n == 0 || *t >= 1), "{q}: {a:?}");
            }
        }
    }

    #[test]
    fn hidden_test_allocation_caps_overflow_to_next_largest_remainder() {
        // N = 12, quota 11: stage 1 takes 1 from each of 3 buckets, stage 2 distributes 8:
        // 8·10/12 = 6.67, 8·1/12 = 0.67, 8·1/12 = 0.67 → floors 6, 0, 0; remainders 8, 8, 8 (of
        // 12): buckets 1 and 2 have nothing left, so both extra objects go to bucket 0.
        assert_eq!(hidden_test_allocation(&[10, 1, 1], 11), vec![9, 1, 1]);
    }

    #[test]
    fn balanced_allocation_hand_computed() {
        // size 20 over 4 non-empty buckets: quota 5; bucket 3 has 2 and bucket 2 has 4 → 5+5+4+2
        // = 16, the 4 missing from the bucket with most left: bucket 0 (45 left) every time.
        assert_eq!(balanced_allocation(&[50, 10, 4, 2, 0], 20), vec![9, 5, 4, 2, 0]);
        // Remainder of the division: size 7 over 3 buckets = 2 each, +1 from the largest left.
        assert_eq!(balanced_allocation(&[3, 3, 5], 7), vec![2, 2, 3]);
        // Ties between buckets with equally many left go to the lower bucket.
        assert_eq!(balanced_allocation(&[4, 4, 4], 4), vec![2, 1, 1]);
        assert_eq!(balanced_allocation(&[0, 0], 3), vec![0, 0]);
        assert_eq!(balanced_allocation(&[2, 1], 3), vec![2, 1]);
    }

    #[test]
    fn splits_partition_the_pool_and_cover_every_bucket() {
        let counts = [300, 150, 60, 20, 5, 0, 1, 2];
        let set = pool(&counts);
        let s = make_splits(&set, &SplitSettings::default()).unwrap();
        let main: usize = counts.iter().sum();
        assert_eq!(s.main(), main);
        assert_eq!(s.main_buckets, counts.to_vec());
        // round(538 · 528/5523) = round(51.43) = 51.
        assert_eq!(s.hidden_test_quota, 51);
        assert_eq!(s.main_hidden_test.len(), 51);
        assert_eq!(s.bucket_counts(SplitName::MainHiddenTest), hidden_test_allocation(&counts, 51));
        for (b, (&n, &t)) in counts.iter().zip(&s.bucket_counts(SplitName::MainHiddenTest)).enumerate() {
            assert_eq!(n > 0, t > 0, "bucket {b}");
        }
        // Hidden test and public partition the main pool.
        let mut all: Vec<&str> = uids(&s.main_hidden_test);
        all.extend(uids(&s.main_train_public));
        all.sort();
        let mut expected: Vec<&str> = set.annotations.iter().map(|a| a.uid.as_str()).collect();
        expected.sort();
        assert_eq!(all, expected);
        // Sorted by uid, training subsets inside the public split, default size half of it.
        for name in SplitName::ALL {
            let u = uids(s.get(name));
            assert!(u.windows(2).all(|w| w[0] < w[1]), "{name} not sorted/unique");
        }
        assert_eq!(s.train_size, (main - 51) / 2);
        let public: std::collections::HashSet<&str> = uids(&s.main_train_public).into_iter().collect();
        for name in [SplitName::MainRawTrain, SplitName::MainBalancedTrain] {
            assert_eq!(s.get(name).len(), s.train_size);
            assert!(uids(s.get(name)).iter().all(|u| public.contains(u)), "{name}");
        }
        assert_eq!(
            s.bucket_counts(SplitName::MainBalancedTrain),
            balanced_allocation(&s.bucket_counts(SplitName::MainTrainPublic), s.train_size)
        );
    }

    #[test]
    fn slow_failures_and_unsolved_objects() {
        let mut set = pool(&[10, 5]);
        set.annotations.push(ann("slow_a", Some(12), true));
        set.annotations.push(ann("slow_b", None, true));
        set.annotations.push(ann("unsolved", None, false));
        let mut zero = ann("zero", Some(0), false);
        zero.universe = 0;
        set.annotations.push(zero);
        set.failures.push(objview_dataset::Failure {
            uid: "broken".into(),
            mesh: "broken.obj".into(),
            error: "broken.obj: mesh has no triangles".into(),
            settings: json!({}),
            version: "0.1.0".into(),
        });
        let s = make_splits(&set, &SplitSettings { test_fraction: 0.2, ..Default::default() }).unwrap();
        assert_eq!(uids(&s.slow_saturation), ["slow_a", "slow_b"]);
        assert_eq!(s.main(), 15);
        assert_eq!(s.hidden_test_quota, 3);
        assert_eq!(s.failures, 1);
        let ex: Vec<(&str, &str)> =
            s.excluded.iter().map(|e| (e.uid.as_str(), e.d_plan_status.as_str())).collect();
        assert_eq!(ex, [("unsolved", "time_limit"), ("zero", "optimal")]);
        assert!(
            s.excluded[0].reason.contains("not proven optimal") && s.excluded[0].reason.contains("bound 7")
        );
        assert!(s.excluded[1].reason.contains("d_plan = 0"));
        for name in SplitName::ALL {
            assert!(uids(s.get(name)).iter().all(|u| !["unsolved", "zero", "broken"].contains(u)));
        }
        let report = s.report(&json!({"seed": 0}));
        assert_eq!(report["counts"]["excluded"], 2);
        assert_eq!(report["counts"]["slow_saturation"], 2);
        assert_eq!(report["counts"]["main_hidden_test"], 3);
        assert_eq!(report["buckets"][1]["bucket"], "6-10");
        assert_eq!(report["buckets"][1]["main"], 5);
        assert_eq!(report["excluded"][0]["uid"], "unsolved");
    }

    #[test]
    fn deterministic_across_input_orders_and_seeds_change_the_draw() {
        let set = pool(&[40, 30, 20, 10]);
        let settings = SplitSettings::default();
        let a = make_splits(&set, &settings).unwrap();
        let mut reversed = set.clone();
        reversed.annotations.reverse();
        // A fixed permutation (stride 7 over 100 items).
        let mut shuffled = set.clone();
        shuffled.annotations = (0..100).map(|i| set.annotations[(i * 7) % 100].clone()).collect();
        assert_eq!(make_splits(&reversed, &settings).unwrap(), a);
        assert_eq!(make_splits(&shuffled, &settings).unwrap(), a);
        assert_eq!(make_splits(&set, &settings).unwrap(), a);

        let b = make_splits(&set, &SplitSettings { seed: 1, ..settings.clone() }).unwrap();
        assert_eq!(a.main_hidden_test.len(), b.main_hidden_test.len());
        assert_eq!(a.bucket_counts(SplitName::MainHiddenTest), b.bucket_counts(SplitName::MainHiddenTest));
        assert_ne!(uids(&a.main_hidden_test), uids(&b.main_hidden_test));
        assert_ne!(uids(&a.main_raw_train), uids(&b.main_raw_train));
        assert_ne!(uids(&a.main_balanced_train), uids(&b.main_balanced_train));
    }

    #[test]
    fn draws_are_uniform_within_a_bucket() {
        // One bucket of 10, quota 3 (with stage 1 that is 1 + 2): over 2000 seeds every object is
        // chosen with probability 3/10 (±4.5 standard deviations: sd = sqrt(2000·0.3·0.7) ≈ 20.5).
        let set = pool(&[10]);
        let mut hits = std::collections::HashMap::<String, usize>::new();
        for seed in 0..2000 {
            let s =
                make_splits(&set, &SplitSettings { seed, test_fraction: 0.3, train_size: Some(0) }).unwrap();
            assert_eq!(s.main_hidden_test.len(), 3);
            for a in &s.main_hidden_test {
                *hits.entry(a.uid.clone()).or_default() += 1;
            }
        }
        assert_eq!(hits.len(), 10);
        for (u, n) in hits {
            assert!((508..=692).contains(&n), "{u}: {n}");
        }
    }

    #[test]
    fn train_size_is_checked_and_balanced_takes_equal_quotas() {
        let set = pool(&[40, 30, 20, 10]);
        let s = make_splits(
            &set,
            &SplitSettings { test_fraction: 0.0, train_size: Some(40), ..Default::default() },
        )
        .unwrap();
        assert!(s.main_hidden_test.is_empty());
        assert_eq!(s.main_train_public.len(), 100);
        assert_eq!(s.main_raw_train.len(), 40);
        assert_eq!(s.bucket_counts(SplitName::MainBalancedTrain), [10, 10, 10, 10]);
        let s = make_splits(
            &set,
            &SplitSettings { test_fraction: 0.0, train_size: Some(60), ..Default::default() },
        )
        .unwrap();
        // 15 each, bucket 3 has 10: 5 more from the bucket with most left (bucket 0, 25 left).
        assert_eq!(s.bucket_counts(SplitName::MainBalancedTrain), [20, 15, 15, 10]);
        let err = make_splits(&set, &SplitSettings { train_size: Some(101), test_fraction: 0.0, seed: 0 })
            .unwrap_err()
            .to_string();
        assert!(err.contains("train_size") && err.contains("101") && err.contains("100 objects"), "{err}");
        let err = make_splits(&set, &SplitSettings { test_fraction: 1.5, ..Default::default() }).unwrap_err();
        assert!(err.to_string().contains("test_fraction"), "{err}");
    }

    #[test]
    fn split_files_round_trip_through_read_split() {
        let dir = tempfile::tempdir().unwrap();
        let meshes = dir.path().join("meshes");
        std::fs::create_dir_all(&meshes).unwrap();
        let mut set = pool(&[6, 4]);
        for a in &mut set.annotations {
            let mesh = meshes.join(format!("{}.obj", a.uid));
            std::fs::write(&mesh, "v 0 0 0\n").unwrap();
            a.mesh = mesh.display().to_string();
        }
        set.annotations[0].gt_cloud = meshes.join("cloud.pcd").display().to_string();
        let s = make_splits(&set, &SplitSettings { test_fraction: 0.3, ..Default::default() }).unwrap();
        let out = dir.path().join("splits");
        let written = write_splits(&s, &out, &json!({"seed": 0})).unwrap();
        assert_eq!(written.len(), 6);
        let text = std::fs::read_to_string(out.join("main_hidden_test.json")).unwrap();
        assert!(text.contains("\"mesh\": \"../meshes/"), "{text}");
        for name in SplitName::ALL {
            let objs = objview_dataset::read_split(&out.join(name.file_name())).unwrap();
            assert_eq!(objs.len(), s.get(name).len());
            for (o, a) in objs.iter().zip(s.get(name)) {
                assert_eq!(o.uid, a.uid);
                assert_eq!(o.mesh.canonicalize().unwrap(), Path::new(&a.mesh).canonicalize().unwrap());
                assert_eq!(o.annotation.as_ref().unwrap()["d_plan"], json!(a.d_plan));
                assert_eq!(o.gt_cloud.is_some(), a.uid == set.annotations[0].uid);
            }
        }
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join(REPORT_FILE)).unwrap()).unwrap();
        assert_eq!(report["counts"]["main"], 10);
        assert_eq!(report["settings"]["seed"], 0);
    }

    #[test]
    fn relative_paths() {
        assert_eq!(relative(Path::new("/a/b/c.obj"), Path::new("/a/d")).unwrap(), Path::new("../b/c.obj"));
        assert_eq!(relative(Path::new("/a/b/c.obj"), Path::new("/a/b")).unwrap(), Path::new("c.obj"));
        assert_eq!(relative(Path::new("/x.obj"), Path::new("/a/b")).unwrap(), Path::new("../../x.obj"));
        let cwd = std::env::current_dir().unwrap();
        assert_eq!(resolve(Path::new("no/such/../file.obj")).unwrap(), cwd.join("no/file.obj"));
    }
}
