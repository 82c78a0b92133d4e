//! End-to-end tests of the report on a small synthetic set whose means are worked out by hand
//! (see `testutil` for how the episodes' metrics are generated).

use std::path::{Path, PathBuf};

use serde_json::json;

use crate::select::Setting;
use crate::testutil::{annotation, close, write_lines, Spec};
use crate::{build_report, Report, ReportError, ReportSettings};

const K5: Setting = Setting::Fixed(5);
const K30: Setting = Setting::Fixed(30);
const AUTO: Setting = Setting::Automatic;

fn alpha(uid: &'static str, space: &'static str) -> Spec {
    Spec { space, step_cost: 1.5, step_time: 0.05, ..Spec::new(uid, "alpha") }
}

fn beta(uid: &'static str, space: &'static str, budget: &'static str) -> Spec {
    Spec {
        family: "hybrid",
        mode: "budgeted_plan",
        space,
        budget,
        last: budget.parse().unwrap(),
        slope: if budget == "5" { 0.02 } else { 0.01 },
        step_cost: 1.0,
        step_time: 0.01,
        reason: "plan_end",
        ..Spec::new(uid, "beta")
    }
}

fn gamma(uid: &'static str, space: &'static str) -> Spec {
    Spec {
        family: "learned",
        mode: "set_cover_plan",
        space,
        slope: 0.02,
        step_cost: 3.0,
        step_time: 0.2,
        reason: "plan_end",
        ..Spec::new(uid, "gamma")
    }
}

fn oracle(uid: &'static str) -> Spec {
    Spec { family: "oracle", step_time: 0.001, reason: "candidate_exhausted", ..Spec::new(uid, "oracle") }
}

/// The synthetic set: 4 methods × objects o1, o2 (+ o3, o4 for the oracle) × whole/quarter.
fn dataset() -> Vec<Spec> {
    vec![
        // alpha, iterative: K=5 → step 5, K=30 → step 30 or terminal, Automatic → MS@0.02.
        Spec { base: 0.60, last: 35, ms: Some(10), ..alpha("o1", "whole") },
        Spec { base: 0.50, last: 20, ms: Some(12), reason: "candidate_exhausted", ..alpha("o2", "whole") },
        Spec { base: 0.50, last: 40, ms: Some(8), ..alpha("o1", "quarter") },
        // beta, budgeted plan: one run per budget.
        Spec { base: 0.70, ..beta("o1", "whole", "5") },
        Spec { base: 0.70, ..beta("o1", "whole", "30") },
        Spec { base: 0.60, ..beta("o2", "whole", "5") },
        Spec { base: 0.60, ..beta("o2", "whole", "30") },
        Spec { base: 0.60, ..beta("o1", "quarter", "5") },
        Spec { base: 0.60, ..beta("o1", "quarter", "30") },
        Spec { base: 0.50, ..beta("o2", "quarter", "5") },
        Spec { base: 0.50, ..beta("o2", "quarter", "30") },
        // gamma, set-cover plan: automatic only.
        Spec { base: 0.80, last: 8, ..gamma("o1", "whole") },
        Spec { base: 0.80, last: 6, ..gamma("o2", "whole") },
        Spec { base: 0.70, last: 10, ..gamma("o1", "quarter") },
        // oracle: exhausts its candidates; o2 never reaches MS, o3 has no annotation.
        Spec { base: 0.90, last: 10, ms: Some(4), ..oracle("o1") },
        Spec { base: 0.85, last: 15, ..oracle("o2") },
        Spec { base: 0.80, last: 20, ms: Some(6), ..oracle("o4") },
        Spec { base: 0.90, slope: 0.0, last: 3, ..oracle("o3") },
    ]
}

struct Fixture {
    _dir: tempfile::TempDir,
    results: Vec<PathBuf>,
    annotations: Vec<PathBuf>,
}

/// Two result files (the first holds a stale duplicate of alpha/o1/whole and a failure line) and
/// one annotation file.
fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let specs = dataset();
    let stale = Spec { base: 0.0, slope: 0.0, ..specs[0].clone() };
    let failure =
        json!({"uid": "o2", "method": "alpha", "view_space": "quarter", "budget": "auto", "seed": 0,
        "error": "planner crashed"})
        .to_string();
    let mut first = vec![stale.line(), failure];
    first.extend(specs[1..9].iter().map(Spec::line));
    let second: Vec<String> = std::iter::once(&specs[0]).chain(&specs[9..]).map(Spec::line).collect();
    let a = write_lines(dir.path(), "a.jsonl", &first);
    let b = write_lines(dir.path(), "b.jsonl", &second);
    let ann = [
        annotation("o1", 30, Some(10), false),
        annotation("o2", 150, None, true),
        annotation("o4", 40, Some(20), false),
        annotation("o5", 20, Some(5), false),
    ];
    let anns = write_lines(dir.path(), "ann.jsonl", &ann.iter().map(|v| v.to_string()).collect::<Vec<_>>());
    Fixture { results: vec![a, b], annotations: vec![anns], _dir: dir }
}

fn settings() -> ReportSettings {
    ReportSettings { quality_threshold: 0.65, ..ReportSettings::default() }
}

fn report() -> Report {
    let f = fixture();
    build_report(&f.results, &f.annotations, &settings()).unwrap()
}

#[test]
fn inputs_are_counted_and_duplicates_keep_the_last_line() {
    let r = report();
    assert_eq!(r.inputs.len(), 2);
    assert_eq!((r.inputs[0].lines, r.inputs[0].episodes, r.inputs[0].failures), (10, 9, 1));
    assert_eq!((r.inputs[1].lines, r.inputs[1].episodes), (10, 10));
    assert_eq!(r.counts.episode_lines, 19);
    assert_eq!(r.counts.episodes, 18);
    assert_eq!(r.counts.duplicates_same_key, 1);
    assert_eq!(r.duplicates[0].dropped.file, 0);
    assert_eq!(r.duplicates[0].kept.file, 1);
    assert!(
        r.warnings
            .iter()
            .any(|w| w.starts_with("Duplicate episodes (same uid, method, view space, budget, seed): 1;")),
        "{:?}",
        r.warnings
    );
    let fell_back = "`alpha` in `whole`: runs that ended before a setting's checkpoint contribute their \
                     `terminal` (K=30 1 of 2).";
    assert!(r.warnings.iter().any(|w| w == fell_back), "{:?}", r.warnings);
    // The stale copy (NSC 0) would pull alpha's K=5 mean to 0.275; the kept one gives 0.60.
    let a = r.aggregates.iter().find(|a| a.method == "alpha" && a.setting == K5 && a.view_space == "whole");
    close(a.unwrap().nsc.mean, 0.60);
    assert_eq!(r.budget_settings, [K5, K30, AUTO]);
    assert_eq!(r.methods, ["alpha", "beta", "gamma", "oracle"]);
    assert_eq!(r.taus, ["0.01", "0.02", "0.03"]);
}

#[test]
fn failure_lines_are_counted_and_listed() {
    let r = report();
    assert_eq!(r.counts.failure_lines, 1);
    assert_eq!(r.failures[0].keys.uid, "o2");
    assert_eq!(r.failures[0].error, "planner crashed");
    assert_eq!(r.failures[0].source.line, 2);
    assert!(!r.failures[0].superseded);
    let row = r.terminal.rows.iter().find(|t| t.view_space == "quarter" && t.method == "alpha").unwrap();
    assert_eq!((row.episodes, row.failures), (1, 1));
    let md = r.markdown();
    assert!(md.contains("a.jsonl:2 | o2 | alpha | quarter | auto | 0 | planner crashed |"), "{md}");

    // `objview run` failure lines keep the episode's identity in `settings`; a failure with a
    // result for the same episode (a successful retry) is superseded.
    let dir = tempfile::tempdir().unwrap();
    let run_failure = |uid: &str| {
        json!({"uid": uid, "mesh": format!("{uid}.obj"), "error": "mesh not found",
            "settings": {"command": "run", "planner": "alpha", "view_space": "whole", "budget": "auto", "seed": 0}})
        .to_string()
    };
    let lines = vec![run_failure("o1"), Spec::new("o1", "alpha").line(), run_failure("o7")];
    let path = write_lines(dir.path(), "run.jsonl", &lines);
    let r = build_report(&[path], &[], &ReportSettings::default()).unwrap();
    let got: Vec<String> = r
        .failures
        .iter()
        .map(|f| {
            format!(
                "{} {} {} {} {:?} {}",
                f.keys.uid, f.keys.method, f.keys.view_space, f.keys.budget, f.keys.seed, f.superseded
            )
        })
        .collect();
    assert_eq!(got, ["o1 alpha whole auto Some(0) true", "o7 alpha whole auto Some(0) false"]);
    assert_eq!((r.counts.failure_lines, r.counts.failures_superseded), (2, 1));
    assert_eq!(r.terminal.rows[0].failures, 1);
    assert!(r.markdown().contains("mesh not found (superseded by a result)"));
}

#[test]
fn means_and_rankings_match_hand_computation() {
    let r = report();
    let find = |setting, space: &str, method: &str| {
        r.aggregates
            .iter()
            .find(|a| a.setting == setting && a.view_space == space && a.method == method)
            .unwrap_or_else(|| panic!("no {method} {space} {setting}"))
    };
    // alpha K=30: o1 at its K=30 checkpoint (31 views, NSC 0.90, PC 45), o2 ended at step 20
    // (21 views, NSC 0.70, PC 30): terminal fallback.
    let a = find(K30, "whole", "alpha");
    assert_eq!((a.n, a.objects, a.terminal_fallback), (2, 2, 1));
    close(a.views.mean, 26.0);
    close(a.nsc.mean, 0.80);
    close(a.sc.mean, 0.64);
    close(a.path_cost.mean, 37.5);
    close(a.runtime.mean, 1.25);
    close(a.views.std.unwrap(), 50f64.sqrt());
    // alpha Automatic: MS@0.02 at steps 10 and 12.
    let a = find(AUTO, "whole", "alpha");
    close(a.views.mean, 12.0);
    close(a.nsc.mean, 0.66);
    close(a.path_cost.mean, 16.5);
    // beta: budget-matched runs only.
    let b = find(K5, "whole", "beta");
    assert_eq!(b.n, 2);
    close(b.nsc.mean, 0.75);
    close(find(K30, "whole", "beta").nsc.mean, 0.95);
    assert!(r.aggregates.iter().all(|a| !(a.method == "beta" && a.setting == AUTO)));
    // gamma: automatic only.
    let g = find(AUTO, "whole", "gamma");
    close(g.views.mean, 8.0);
    close(g.nsc.mean, 0.94);
    close(g.path_cost.mean, 21.0);
    close(g.runtime.mean, 1.4);
    assert!(r.aggregates.iter().all(|a| !(a.method == "gamma" && a.setting != AUTO)));
    // Oracle at K=30: both runs ended earlier.
    assert_eq!(find(K30, "whole", "oracle").terminal_fallback, 4);

    // Table 2 (top 3, whole).
    type Row<'a> = (Setting, Option<usize>, &'a str, String, String, String, &'a str, usize);
    let rows: Vec<Row> = r
        .quality
        .rows
        .iter()
        .map(|x| {
            (
                x.setting,
                x.rank,
                x.method.as_str(),
                format!("{:.1}", x.views),
                format!("{:.3}", x.nsc),
                format!("{:.2}", x.path_cost),
                x.time_bin.as_str(),
                x.n,
            )
        })
        .collect();
    let s = |v: &str| v.to_string();
    assert_eq!(
        rows,
        vec![
            (K5, Some(1), "beta", s("6.0"), s("0.750"), s("5.00"), "<0.1", 2),
            (K5, Some(2), "alpha", s("6.0"), s("0.600"), s("7.50"), "0.1–0.5", 2),
            (K5, None, "oracle", s("5.5"), s("0.900"), s("4.50"), "<0.1", 4),
            (K30, Some(1), "beta", s("31.0"), s("0.950"), s("30.00"), "0.1–0.5", 2),
            (K30, Some(2), "alpha", s("26.0"), s("0.800"), s("37.50"), "1–3", 2),
            (K30, None, "oracle", s("13.0"), s("0.975"), s("12.00"), "<0.1", 4),
            (AUTO, Some(1), "gamma", s("8.0"), s("0.940"), s("21.00"), "1–3", 2),
            (AUTO, Some(2), "alpha", s("12.0"), s("0.660"), s("16.50"), "0.5–1", 2),
            (AUTO, None, "oracle", s("8.0"), s("0.925"), s("7.00"), "<0.1", 4),
        ]
    );

    // Table 3 (NSC ≥ 0.65): alpha drops out at K=5, and leads the automatic setting on path.
    let rows: Vec<(Setting, Option<usize>, &str)> =
        r.path_efficient.rows.iter().map(|x| (x.setting, x.rank, x.method.as_str())).collect();
    assert_eq!(
        rows,
        vec![
            (K5, Some(1), "beta"),
            (K5, None, "oracle"),
            (K30, Some(1), "beta"),
            (K30, Some(2), "alpha"),
            (K30, None, "oracle"),
            (AUTO, Some(1), "alpha"),
            (AUTO, Some(2), "gamma"),
            (AUTO, None, "oracle"),
        ]
    );
    let counts: Vec<(usize, usize)> =
        r.path_efficient.counts.iter().map(|c| (c.qualifying, c.methods)).collect();
    assert_eq!(counts, [(1, 2), (2, 2), (2, 2)]);
    // A stricter threshold keeps fewer.
    let f = fixture();
    let strict = ReportSettings { quality_threshold: 0.9, ..settings() };
    let t = build_report(&f.results, &f.annotations, &strict).unwrap().path_efficient;
    let ranked: Vec<(Setting, &str)> =
        t.rows.iter().filter(|x| x.rank.is_some()).map(|x| (x.setting, x.method.as_str())).collect();
    assert_eq!(ranked, [(K30, "beta"), (AUTO, "gamma")]);
}

#[test]
fn table4_uses_the_maximum_view_setting_and_common_objects() {
    let r = report();
    let t = &r.reachability;
    assert_eq!(t.only_a, ["oracle"]);
    assert!(t.only_b.is_empty() && t.no_common_setting.is_empty());
    let methods: Vec<&str> = t.rows.iter().map(|x| x.method.as_str()).collect();
    // Family order: classical, learned, hybrid.
    assert_eq!(methods, ["alpha", "gamma", "beta"]);
    // alpha: whole #Views K=5 6, K=30 26, Auto 12 → K=30; only o1 ran in quarter.
    let a = &t.rows[0];
    assert_eq!((a.setting, a.paired, a.common_objects, a.n), (K30, true, 1, (1, 1)));
    close(a.views.0, 31.0);
    close(a.views.1, 31.0);
    close(a.nsc.0, 0.90);
    close(a.nsc.1, 0.80);
    close(a.delta_nsc, 0.10);
    close(a.sc.0, 0.72);
    close(a.sc.1, 0.64);
    close(a.delta_sc, 0.08);
    // gamma: automatic only, paired on o1.
    let g = &t.rows[1];
    assert_eq!((g.setting, g.common_objects), (AUTO, 1));
    close(g.views.0, 9.0);
    close(g.views.1, 11.0);
    close(g.delta_nsc, 0.96 - 0.90);
    close(g.delta_sc, 0.8 * (0.96 - 0.90));
    // beta: K=30 (31 views) over K=5; both objects in both spaces.
    let b = &t.rows[2];
    assert_eq!((b.setting, b.common_objects, b.n), (K30, 2, (2, 2)));
    close(b.nsc.0, 0.95);
    close(b.nsc.1, 0.85);
    close(b.delta_nsc, 0.10);
}

#[test]
fn table4_ties_on_views_pick_the_later_setting_and_unpaired_runs_are_kept() {
    let dir = tempfile::tempdir().unwrap();
    // Ends at step 10 without MS: K=30 and Automatic both fall back to terminal (11 views).
    let w = Spec { last: 10, reason: "candidate_exhausted", ..Spec::new("o1", "delta") };
    let q = Spec { space: "quarter", base: 0.4, ..w.clone() };
    // Another method seen in different objects per space: unpaired.
    let e_w = Spec { uid: "o1", ..Spec::new("o1", "eps") };
    let e_q = Spec { uid: "o2", space: "quarter", base: 0.3, ..Spec::new("o2", "eps") };
    let lines: Vec<String> = [w, q, e_w, e_q].iter().map(Spec::line).collect();
    let path = write_lines(dir.path(), "r.jsonl", &lines);
    let r = build_report(&[path], &[], &ReportSettings::default()).unwrap();
    let d = r.reachability.rows.iter().find(|x| x.method == "delta").unwrap();
    assert_eq!(d.setting, AUTO);
    close(d.delta_nsc, 0.1);
    let e = r.reachability.rows.iter().find(|x| x.method == "eps").unwrap();
    assert_eq!((e.paired, e.common_objects, e.n), (false, 0, (1, 1)));
    close(e.delta_nsc, 0.2);
    assert!(r.markdown().contains("unpaired (1/1 runs)"));
    // No annotations: no Table 5.
    assert!(r.map_stabilization.is_none());
    assert!(r.markdown().contains("Not computed: no annotation files given"));
}

#[test]
fn table5_pools_oracle_runs_by_annotation() {
    let r = report();
    let t = r.map_stabilization.as_ref().unwrap();
    assert_eq!(t.oracle_runs, 4);
    assert_eq!(t.unannotated, ["o3"]);
    assert_eq!(t.terminal_reasons.get("candidate_exhausted"), Some(&3));
    assert_eq!(t.rows.len(), 2);
    // Main: o1 (d_sat 30, d_plan 10; MS at step 4: 5 views, NSC 0.94; terminal 1.0) and
    // o4 (40, 20; MS at step 6: 7 views, NSC 0.86; terminal 1.0).
    let m = &t.rows[0];
    assert_eq!((m.pool.as_str(), m.objects, m.runs, m.with_d_plan, m.ms_missing), ("Main", 2, 2, 2, 0));
    close(m.d_sat, 35.0);
    close(m.d_plan.unwrap(), 15.0);
    close(m.ms_views, 6.0);
    close(m.ms_nsc, 0.90);
    close(m.tammes_nsc, 1.0);
    close(m.tammes_views, 16.0);
    close(m.delta_nsc, 0.10);
    // Slow: o2 never reaches MS: terminal (16 views, NSC 1.0) for the MS columns.
    let s = &t.rows[1];
    assert_eq!((s.pool.as_str(), s.objects, s.with_d_plan, s.ms_missing), ("Slow-Saturation", 1, 0, 1));
    close(s.d_sat, 150.0);
    assert_eq!(s.d_plan, None);
    close(s.ms_views, 16.0);
    close(s.delta_nsc, 0.0);
    let md = r.markdown();
    assert!(md.contains("| Main | 2 | 35.0 | 15.0 | 6.0 | 0.900 | 1.000 | 0.1000 |"), "{md}");
    assert!(md.contains("| Slow-Saturation | 1 | 150.0 | — | 16.0 | 1.000 | 1.000 | 0.0000 |"), "{md}");
    assert!(md.contains("Left out, without an annotation: 1 object of oracle runs (`o3`)."), "{md}");
    assert!(md.contains("1 of 1 runs never reached `MS@0.02`"), "{md}");
    assert!(
        md.contains(
            "here: 3 `candidate_exhausted`; mean #Views at `terminal`: Main 16.0, Slow-Saturation 16.0."
        ),
        "{md}"
    );
    assert!(!md.contains("Some runs ended otherwise"), "{md}");
    let a = r.annotation_inputs.as_ref().unwrap();
    assert_eq!((a.annotations, a.failures), (4, 0));
}

#[test]
fn nsc_curves_carry_ended_episodes_forward() {
    let r = report();
    let c = r.curves.iter().find(|c| c.method == "alpha" && c.view_space == "whole").unwrap();
    assert_eq!((c.budget.as_deref(), c.episodes, c.points.len()), (None, 2, 36));
    let p = &c.points[0];
    assert_eq!((p.views, p.episodes, p.carried), (1, 2, 0));
    close(p.nsc, 0.55);
    // v = 30: o1 at step 29 (0.89), o2 ended at 21 views (0.70, carried).
    let p = &c.points[29];
    assert_eq!((p.views, p.episodes, p.carried), (30, 2, 1));
    close(p.nsc, (0.89 + 0.70) / 2.0);
    // Finite plans: one curve per budget.
    let budgets: Vec<Option<&str>> = r
        .curves
        .iter()
        .filter(|c| c.method == "beta" && c.view_space == "whole")
        .map(|c| c.budget.as_deref())
        .collect();
    assert_eq!(budgets, [Some("30"), Some("5")]);
    // Trade-off points: one per (space, method, setting).
    assert_eq!(r.tradeoff.len(), r.aggregates.len());
}

fn read_dir(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap())
        })
        .collect();
    files.sort();
    files
}

#[test]
fn writing_gives_every_file_and_identical_bytes_twice() {
    let f = fixture();
    let r = build_report(&f.results, &f.annotations, &settings()).unwrap();
    let out1 = tempfile::tempdir().unwrap();
    let out2 = tempfile::tempdir().unwrap();
    let written = r.write(out1.path()).unwrap();
    let names: Vec<String> =
        written.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let mut expected: Vec<String> = crate::OUTPUT_FILES.iter().map(|s| s.to_string()).collect();
    for stem in
        ["nsc_vs_views_quarter", "path_cost_vs_nsc_quarter", "nsc_vs_views_whole", "path_cost_vs_nsc_whole"]
    {
        expected.push(format!("{stem}.png"));
        expected.push(format!("{stem}.svg"));
    }
    expected.push("figures.json".into());
    assert_eq!(names, expected);
    // A second report from the same inputs, written elsewhere: the same bytes.
    build_report(&f.results, &f.annotations, &settings()).unwrap().write(out2.path()).unwrap();
    let (a, b) = (read_dir(out1.path()), read_dir(out2.path()));
    assert_eq!(a.len(), expected.len());
    for ((na, da), (nb, db)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        assert!(da == db, "{na} differs between runs");
    }
    let get = |name: &str| &a.iter().find(|(n, _)| n == name).unwrap().1;
    assert!(get("nsc_vs_views_whole.png").starts_with(b"\x89PNG"));
    let svg = String::from_utf8(get("path_cost_vs_nsc_whole.svg").clone()).unwrap();
    assert!(svg.contains("Table 3 quality threshold") && svg.contains("gamma"), "SVG lacks labels");

    let md = String::from_utf8(get("report.md").clone()).unwrap();
    for text in [
        &format!("objview-report {}", crate::VERSION),
        "| `",
        "a.jsonl` | 10 | 9 | 1 | 0 | no |",
        "| K=5 | 1 | beta | Hybrid | 6.0 | 0.750 | 5.00 | <0.1 | 2 |",
        "| K=30 | ref | oracle | Oracle | 13.0 | 0.975 | 12.00 | <0.1 | 4 |",
        "| alpha | Classical | K=30 | 1 | 31.0/31.0 | 0.900/0.800 | 0.100 | 0.720/0.640 | 0.080 |",
        "![nsc_vs_views_whole](nsc_vs_views_whole.png)",
        "Methods reaching the threshold: K=5: 1 of 2; K=30: 2 of 2; Automatic: 2 of 2.",
    ] {
        assert!(md.contains(text), "report.md lacks {text}\n{md}");
    }
    assert!(md.contains(&r.markdown()));

    let json: serde_json::Value = serde_json::from_slice(get("report.json")).unwrap();
    assert_eq!(json["version"], crate::VERSION);
    assert_eq!(json["inputs"][1]["lines"], 10);
    assert_eq!(json["settings"]["quality_threshold"], 0.65);
    assert_eq!(json["counts"]["duplicates_same_key"], 1);
    assert_eq!(json["tables"]["table2_quality_top"]["rows"][0]["method"], "beta");
    let figs: serde_json::Value = serde_json::from_slice(get("figures.json")).unwrap();
    let curve = &figs["data"]["nsc_vs_views_whole"]["curves"][0];
    assert_eq!(curve["method"], "alpha");
    assert_eq!(curve["points"][29][3], 1);

    let summary = String::from_utf8(get("summary.csv").clone()).unwrap();
    let header = summary.lines().next().unwrap();
    assert!(header.starts_with("setting,view_space,method,family,execution_mode,n,objects,from_step,terminal_fallback,views_mean,views_std,nsc@0.02_mean"));
    assert!(header.contains("nsc@0.01_mean") && header.ends_with("runtime_s_std,time_bin_s"), "{header}");
    assert!(
        summary.contains("\nK=30,whole,alpha,classical,iterative,2,2,0,1,26.000000,7.071068,0.800000,"),
        "{summary}"
    );
    assert_eq!(summary.lines().count(), 1 + r.aggregates.len());
    let failures = String::from_utf8(get("failures.csv").clone()).unwrap();
    assert!(failures.ends_with(",2,o2,alpha,quarter,auto,0,false,planner crashed\n"), "{failures}");
}

#[test]
fn plots_can_be_turned_off() {
    let f = fixture();
    let s = ReportSettings { plots: false, ..settings() };
    let out = tempfile::tempdir().unwrap();
    let written = build_report(&f.results, &[], &s).unwrap().write(out.path()).unwrap();
    let names: Vec<String> =
        written.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let expected: Vec<&str> =
        crate::OUTPUT_FILES.iter().copied().filter(|n| *n != crate::report::TABLE5_CSV).collect();
    assert_eq!(names, expected);
}

/// The reasons of the lines skipped in a file of `lines` (as `line: reason`), and the report.
fn skipped(lines: &[String], settings: &ReportSettings) -> (Vec<String>, Report) {
    let dir = tempfile::tempdir().unwrap();
    let path = write_lines(dir.path(), "bad.jsonl", lines);
    let r = build_report(&[path], &[], settings).unwrap_or_else(|e| panic!("{e} for {lines:?}"));
    let reasons = r.skipped.iter().map(|s| format!("{}: {}", s.source.line, s.reason)).collect();
    (reasons, r)
}

/// The single skipped line's `line: reason` of `lines`.
fn skipped_one(lines: &[String], settings: &ReportSettings) -> String {
    let (reasons, _) = skipped(lines, settings);
    assert_eq!(reasons.len(), 1, "{reasons:?}");
    reasons[0].clone()
}

#[test]
fn bad_lines_are_skipped_and_listed_with_their_line_and_reason() {
    let ok = Spec::new("o1", "alpha").line();
    let d = ReportSettings::default();
    let (reasons, r) = skipped(&[ok.clone(), "{\"uid\": ".into(), ok.clone()], &d);
    assert!(reasons.len() == 1 && reasons[0].starts_with("2: not JSON"), "{reasons:?}");
    assert_eq!((r.counts.episodes, r.counts.episode_lines, r.counts.skipped_lines), (1, 2, 1));
    assert_eq!((r.inputs[0].lines, r.inputs[0].episodes, r.inputs[0].skipped), (3, 2, 1));
    let e = skipped_one(&[ok.clone(), "{\"uid\": \"o1\"}".into()], &d);
    assert!(e.starts_with("2: not an episode result"), "{e}");
    let e = skipped_one(&[annotation("o1", 30, Some(10), false).to_string()], &d);
    assert!(e.starts_with("1: an `objview annotate` line, not an episode result"), "{e}");
    let e = skipped_one(&["[1, 2]".into()], &d);
    assert!(e.starts_with("1: not a JSON object"), "{e}");
    let e = skipped_one(&[Spec { mode: "greedy", ..Spec::new("o1", "alpha") }.line()], &d);
    assert!(e.starts_with("1: unknown execution_mode 'greedy'"), "{e}");
    let e = skipped_one(&[Spec { budget: "many", ..Spec::new("o1", "alpha") }.line()], &d);
    assert!(e.starts_with("1: budget must be"), "{e}");
    let e = skipped_one(std::slice::from_ref(&ok), &ReportSettings { tau: "0.05".into(), ..d.clone() });
    assert!(e.starts_with("1: checkpoint `K=10` has no NSC@0.05"), "{e}");
    let mut no_terminal = Spec::new("o1", "alpha").build();
    no_terminal.checkpoints.remove(&objview_episode::CheckpointKey::Terminal);
    let e = skipped_one(&[serde_json::to_string(&no_terminal).unwrap()], &d);
    assert!(e.starts_with("1: no `terminal` checkpoint"), "{e}");
    // A later line that contradicts its method's family is the one skipped.
    let other_family = Spec { uid: "o2", family: "learned", ..Spec::new("o2", "alpha") }.line();
    let (reasons, r) = skipped(&[ok.clone(), other_family], &d);
    assert_eq!(reasons.len(), 1, "{reasons:?}");
    assert!(
        reasons[0].starts_with("2: method 'alpha' has family 'learned' here but 'classical' at"),
        "{reasons:?}"
    );
    assert!(reasons[0].ends_with("bad.jsonl:1"), "{reasons:?}");
    assert_eq!((r.counts.episodes, r.skipped[0].keys.uid.as_str()), (1, "o2"));
    // Settings and inputs are still errors.
    let e = build_report(&[], &[], &d).unwrap_err();
    assert!(matches!(e, ReportError::NoInputs));
    let dir = tempfile::tempdir().unwrap();
    let path = write_lines(dir.path(), "r.jsonl", std::slice::from_ref(&ok));
    let e =
        build_report(std::slice::from_ref(&path), &[], &ReportSettings { top: 0, ..d.clone() }).unwrap_err();
    assert!(e.to_string().contains("invalid setting top"), "{e}");
    let e = build_report(&[PathBuf::from("/no/such/file.jsonl")], &[], &d).unwrap_err().to_string();
    assert!(e.contains("/no/such/file.jsonl"), "{e}");
}

#[test]
fn names_the_result_format_does_not_know_are_skipped_with_a_reason_after_other_faults() {
    let d = ReportSettings::default();
    let e = skipped_one(&[Spec { family: "planner", ..Spec::new("o1", "alpha") }.line()], &d);
    assert_eq!(e, "1: unknown family 'planner' (classical, learned, hybrid, oracle or baseline)");
    let mut v: serde_json::Value = serde_json::from_str(&Spec::new("o1", "alpha").line()).unwrap();
    v["checkpoints"]["K=05"] = v["checkpoints"]["K=5"].clone();
    let e = skipped_one(&[v.to_string()], &d);
    assert_eq!(e, "1: unknown checkpoint name 'K=05' (K=k, MS@δ such as MS@0.02, or terminal)");
    // An unknown execution mode is reported before a bad budget or family, as before.
    let both = Spec { mode: "greedy", budget: "many", family: "planner", ..Spec::new("o1", "alpha") };
    assert!(skipped_one(&[both.line()], &d).starts_with("1: unknown execution_mode 'greedy'"));
    let both = Spec { budget: "many", family: "planner", ..Spec::new("o1", "alpha") };
    assert!(skipped_one(&[both.line()], &d).starts_with("1: budget must be"));
    // A line that is not an episode result for another reason says so first, as it did when the
    // names were plain strings.
    let mut v: serde_json::Value = serde_json::from_str(&both.line()).unwrap();
    v.as_object_mut().unwrap().remove("uid");
    assert_eq!(skipped_one(&[v.to_string()], &d), "1: not an episode result (missing field `uid`)");
    v["execution_mode"] = json!(3);
    assert_eq!(
        skipped_one(&[v.to_string()], &d),
        "1: not an episode result (invalid type: integer `3`, expected a string)"
    );
}

/// The JSON object keys of `text`, in the order they are written.
fn keys_in_order(text: &str) -> Vec<String> {
    let mut keys = Vec::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '"' {
            continue;
        }
        let mut s = String::new();
        while let Some(c) = chars.next() {
            match c {
                '\\' => s.extend(chars.next()),
                '"' => break,
                c => s.push(c),
            }
        }
        if chars.peek() == Some(&':') {
            keys.push(s);
        }
    }
    keys
}

#[test]
fn result_lines_written_before_the_names_were_typed_read_and_write_back_the_same_json_less_step_cd() {
    use objview_episode::result::EpisodeResult;
    use objview_episode::{Budget, CheckpointKey, ExecutionMode, Family};
    // Two lines of `objview run --no-timings` by the binary before the change
    // (scripts/golden.sh: random-tsp K = 5 in quarter, random auto in whole).
    let text = include_str!("../testdata/before-typed-names.jsonl");
    let lines: Vec<String> = text.lines().map(str::to_string).collect();
    // Lines from before SPEC v3 carry a per-step `cd`: they still read, and write back without it.
    for line in &lines {
        let r: EpisodeResult = serde_json::from_str(line).unwrap();
        let back = serde_json::to_string(&r).unwrap();
        let mut old: serde_json::Value = serde_json::from_str(line).unwrap();
        for st in old["steps"].as_array_mut().unwrap() {
            assert!(st.as_object_mut().unwrap().remove("cd").is_some(), "the old steps had a cd");
        }
        assert_eq!(serde_json::to_value(&r).unwrap(), old);
        let old_keys: Vec<String> = keys_in_order(line).into_iter().filter(|k| k != "cd").collect();
        let back_keys: Vec<String> = keys_in_order(&back).into_iter().filter(|k| k != "cd").collect();
        assert_eq!(back_keys, old_keys, "fields and checkpoint keys in the same order");
    }
    let r: EpisodeResult = serde_json::from_str(&lines[0]).unwrap();
    assert_eq!(
        (r.family, r.execution_mode, r.budget),
        (Family::Classical, ExecutionMode::BudgetedPlan, Budget::Fixed(5))
    );
    let names: Vec<String> = r.checkpoints.keys().map(|k| k.to_string()).collect();
    assert_eq!(names, ["K=5", "MS@0.01", "MS@0.02", "MS@0.03", "terminal"]);
    let r: EpisodeResult = serde_json::from_str(&lines[1]).unwrap();
    assert_eq!(
        (r.family, r.execution_mode, r.budget),
        (Family::Baseline, ExecutionMode::Iterative, Budget::Auto)
    );
    assert_eq!(r.checkpoints.keys().next(), Some(&CheckpointKey::Budget(10)), "K=10 sorts before K=5");
    assert!(r.checkpoints.contains_key(&CheckpointKey::Stabilized(0.02)));
    // And the report reads them as results.
    let dir = tempfile::tempdir().unwrap();
    let path = write_lines(dir.path(), "before.jsonl", &lines);
    let report = build_report(&[path], &[], &ReportSettings::default()).unwrap();
    assert_eq!((report.counts.episodes, report.counts.skipped_lines), (2, 0));
}

#[test]
fn a_result_with_a_null_number_is_skipped_and_the_rest_of_the_file_is_reported() {
    // What a huge pose used to leave in a server export: `"path_cost": null`.
    let mut poisoned: serde_json::Value = serde_json::from_str(&Spec::new("o9", "alpha").line()).unwrap();
    poisoned["steps"][3]["path_cost"] = serde_json::Value::Null;
    let lines = [Spec::new("o1", "alpha").line(), poisoned.to_string(), Spec::new("o2", "alpha").line()];
    let (reasons, r) = skipped(&lines, &ReportSettings::default());
    assert_eq!(reasons.len(), 1, "{reasons:?}");
    assert!(
        reasons[0].starts_with("2: not an episode result (invalid type: null, expected f64"),
        "{reasons:?}"
    );
    let s = &r.skipped[0];
    assert_eq!(
        (s.keys.uid.as_str(), s.keys.method.as_str(), s.keys.view_space.as_str(), s.keys.seed),
        ("o9", "alpha", "whole", Some(0))
    );
    assert_eq!((r.counts.episodes, r.counts.objects), (2, 2));
    assert!(r.warnings.iter().any(|w| w.starts_with("1 line skipped")), "{:?}", r.warnings);
    // Listed in the terminal output and every file that lists failures.
    let md = r.markdown();
    assert!(md.contains("## Skipped lines"), "{md}");
    assert!(md.contains("bad.jsonl:2 | o9 | alpha | whole | auto | 0 | not an episode result"), "{md}");
    let out = tempfile::tempdir().unwrap();
    r.write(out.path()).unwrap();
    let read = |n: &str| std::fs::read_to_string(out.path().join(n)).unwrap();
    assert!(read("report.md").contains("## Skipped lines"));
    let json: serde_json::Value = serde_json::from_str(&read("report.json")).unwrap();
    assert_eq!(json["skipped_lines"][0]["source"]["line"], 2);
    assert_eq!(json["counts"]["skipped_lines"], 1);
    let csv = read("failures.csv");
    let row = csv.lines().find(|l| l.starts_with("skipped_line,")).unwrap_or_else(|| panic!("{csv}"));
    assert!(
        row.contains("bad.jsonl,2,o9,alpha,whole,auto,0,,\"not an episode result (invalid type: null"),
        "{row}"
    );
}

#[test]
fn torn_last_lines_are_skipped_and_iterative_budgets_collapse() {
    let dir = tempfile::tempdir().unwrap();
    let long = Spec { last: 40, ..Spec::new("o1", "alpha") };
    let short = Spec { budget: "5", last: 5, ..long.clone() };
    let path = dir.path().join("r.jsonl");
    std::fs::write(&path, format!("{}\n{}\n{{\"uid\": \"o2\", \"meth", long.line(), short.line())).unwrap();
    let r = build_report(&[path], &[], &ReportSettings::default()).unwrap();
    assert!(r.inputs[0].torn_last_line);
    assert_eq!(r.inputs[0].lines, 2);
    assert_eq!((r.counts.episodes, r.counts.duplicates_iterative_budgets), (1, 1));
    // The 41-view run is kept, so K=30 is its checkpoint.
    let a = r.aggregates.iter().find(|a| a.setting == K30).unwrap();
    assert_eq!((a.views.mean, a.terminal_fallback), (31.0, 0));
    assert!(r.warnings.iter().any(|w| w.contains("torn last line")));
    assert!(
        r.warnings.iter().any(|w| w.starts_with(
            "Iterative runs repeated under another budget label (same uid, method, view space, seed): 1;"
        )),
        "{:?}",
        r.warnings
    );
}

/// Loads `specs` as one results file, in order.
fn load_specs(specs: &[Spec]) -> crate::load::Loaded {
    let dir = tempfile::tempdir().unwrap();
    let lines: Vec<String> = specs.iter().map(Spec::line).collect();
    let path = write_lines(dir.path(), "r.jsonl", &lines);
    crate::load::load_results(&[path], "0.02").unwrap()
}

#[test]
fn a_completed_run_beats_a_failed_duplicate_before_or_after_it() {
    let done = Spec { reason: "plan_end", last: 6, ..Spec::new("o1", "alpha") };
    for failed_reason in ["planner_error", "timeout", "interrupted", "invalid_action", "aborted"] {
        let failed = Spec { reason: failed_reason, last: 3, ..done.clone() };
        // Completed, then a failed re-run: the completed one (line 1) stays.
        let l = load_specs(&[done.clone(), failed.clone()]);
        assert_eq!(l.episodes.len(), 1, "{failed_reason}");
        assert_eq!(l.episodes[0].result.terminal_reason, "plan_end", "{failed_reason}");
        assert_eq!((l.episodes[0].source.line, l.episodes[0].result.visited_poses.len()), (1, 7));
        let d = &l.duplicates[..];
        assert_eq!(d.len(), 1);
        assert_eq!((d[0].kept.line, d[0].dropped.line, d[0].failed_run_dropped), (1, 2, true));
        assert_eq!(
            (d[0].kept_terminal.as_str(), d[0].dropped_terminal.as_str()),
            ("plan_end", failed_reason)
        );
        // A failed run, then a completed one: the completed one (line 2) stays.
        let l = load_specs(&[failed.clone(), done.clone()]);
        assert_eq!(l.episodes.len(), 1);
        assert_eq!(
            (l.episodes[0].source.line, l.episodes[0].result.terminal_reason.as_str()),
            (2, "plan_end")
        );
        assert_eq!((l.duplicates[0].kept.line, l.duplicates[0].dropped.line), (2, 1));
    }
}

#[test]
fn among_runs_of_one_rank_the_last_line_wins() {
    let first = Spec { reason: "plan_end", last: 6, ..Spec::new("o1", "alpha") };
    let second = Spec { reason: "candidate_exhausted", last: 4, ..first.clone() };
    let l = load_specs(&[first.clone(), second.clone()]);
    assert_eq!(l.episodes.len(), 1);
    assert_eq!(
        (l.episodes[0].source.line, l.episodes[0].result.terminal_reason.as_str()),
        (2, "candidate_exhausted")
    );
    assert!(!l.duplicates[0].failed_run_dropped);
    // Two failed runs: the later one too.
    let a = Spec { reason: "timeout", ..first.clone() };
    let b = Spec { reason: "planner_error", ..first.clone() };
    let l = load_specs(&[a, b]);
    assert_eq!(
        (l.episodes[0].source.line, l.episodes[0].result.terminal_reason.as_str()),
        (2, "planner_error")
    );
    // Three lines, completed in the middle: it beats both failed runs around it.
    let l = load_specs(&[
        Spec { reason: "timeout", ..first.clone() },
        first.clone(),
        Spec { reason: "interrupted", ..first.clone() },
    ]);
    assert_eq!((l.episodes.len(), l.episodes[0].source.line), (1, 2));
    let pairs: Vec<(usize, usize)> = l.duplicates.iter().map(|d| (d.dropped.line, d.kept.line)).collect();
    assert_eq!(pairs, [(1, 2), (3, 2)]);
}

#[test]
fn an_iterative_run_that_failed_loses_to_a_completed_one_with_fewer_views() {
    // Iterative runs of one episode under two budget labels: the failed one has more views.
    let done = Spec { reason: "enough_info", last: 8, budget: "5", ..Spec::new("o1", "alpha") };
    let failed = Spec { reason: "timeout", last: 20, budget: "auto", ..done.clone() };
    for order in [[done.clone(), failed.clone()], [failed.clone(), done.clone()]] {
        let l = load_specs(&order);
        assert_eq!(l.episodes.len(), 1);
        assert_eq!(l.episodes[0].result.terminal_reason, "enough_info");
        assert_eq!(l.duplicates[0].kind, crate::load::DuplicateKind::IterativeBudgets);
        assert!(l.duplicates[0].failed_run_dropped);
    }
    // Both completed: the most views, as before.
    let longer = Spec { reason: "max_cap_reached", ..failed };
    let l = load_specs(&[longer, done]);
    assert_eq!(
        (l.episodes[0].result.terminal_reason.as_str(), l.episodes[0].source.line),
        ("max_cap_reached", 1)
    );
}

#[test]
fn the_printed_duplicate_note_states_the_rule() {
    let dir = tempfile::tempdir().unwrap();
    let done = Spec { reason: "plan_end", ..Spec::new("o1", "alpha") };
    let lines = [done.line(), Spec { reason: "planner_error", ..done.clone() }.line()];
    let path = write_lines(dir.path(), "r.jsonl", &lines);
    let r = build_report(&[path], &[], &ReportSettings::default()).unwrap();
    let note = r.warnings.iter().find(|w| w.starts_with("Duplicate episodes")).expect("a duplicate note");
    assert!(note.contains(": 1 (1 of them a failed run dropped for a normal one);"), "{note}");
    assert!(note.contains("a run that ended normally"), "{note}");
    assert!(note.contains("else the last line"), "{note}");
}
