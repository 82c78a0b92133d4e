//! View spaces: the official rule files on hand-picked poses and on the tammes sets (counts
//! computed independently from the coordinate signs with awk), tolerance handling, OR / nested
//! rules, the blocklist, explanations, and malformed rule files.

use objview_geom::Pose;
use objview_views::feasibility::{InequalityTolerance, ViewSpace};
use objview_views::{start_pose, ViewSet, ViewsError};

const SPACES: [&str; 4] = ["whole", "hemi", "quarter", "eighth"];

fn pose(c: [f64; 3]) -> Pose {
    Pose { center: c, look_at: [0.0; 3], roll: 0.0 }
}

#[test]
fn builtin_spaces_parse_verbatim_files() {
    for name in SPACES {
        let vs = ViewSpace::resolve(name).unwrap();
        assert_eq!(vs.name, name);
        assert_eq!(vs.atol, 1e-4);
        assert!(vs.description.starts_with("Camera center") || name == "whole");
        let disk = std::fs::read_to_string(format!(
            "{}/../../data/feasibility/{name}.json",
            env!("CARGO_MANIFEST_DIR")
        ))
        .unwrap();
        if let Ok(official) =
            std::fs::read_to_string(format!("/work/shared/official/configs/feasibility/{name}.json"))
        {
            assert_eq!(disk, official, "{name}.json is not a verbatim copy");
        }
    }
    let notice = format!("{}/../../data/feasibility/NOTICE-official.md", env!("CARGO_MANIFEST_DIR"));
    assert!(std::fs::read_to_string(notice).unwrap().contains("MIT License"));
}

#[test]
fn hand_picked_poses() {
    // (pose centre, feasible in whole, hemi, quarter, eighth)
    let s = 3f64.sqrt();
    let cases: &[([f64; 3], [bool; 4])] = &[
        ([3.0 / s, 3.0 / s, 3.0 / s], [true; 4]),  // the start view
        ([0.9 / s, 0.9 / s, 0.9 / s], [false; 4]), // radius 0.9: inside the object sphere
        ([0.0, 0.0, 0.9], [false; 4]),             // radius 0.9 on the z axis
        ([0.0, 0.0, -3.0], [true, false, false, false]),
        ([0.0, -3.0, 0.5], [true, true, false, false]),
        ([-2.0, 1.0, 2.0], [true, true, true, false]),
        ([2.0, 1.0, 0.0], [true, true, true, true]), // on the z = 0 boundary
        ([1.0, 0.0, 0.0], [true, true, true, true]), // radius exactly 1
        ([0.0, 0.0, 0.9999], [false; 4]),
    ];
    for (c, want) in cases {
        for (k, name) in SPACES.iter().enumerate() {
            let vs = ViewSpace::resolve(name).unwrap();
            assert_eq!(vs.is_feasible(&pose(*c)), want[k], "{name} {c:?}");
            assert_eq!(vs.explain(&pose(*c)).is_none(), want[k], "{name} {c:?}");
        }
    }
    for name in SPACES {
        assert!(ViewSpace::resolve(name).unwrap().is_feasible(&start_pose(3.0)));
        // Non-finite poses are never feasible.
        assert!(!ViewSpace::resolve(name).unwrap().is_feasible(&pose([f64::NAN, 3.0, 3.0])));
    }
}

#[test]
fn tammes_counts_per_space() {
    // Counted independently from the coordinate signs of the files (awk).
    let expected = [(360, [360, 180, 91, 47]), (128, [128, 64, 32, 16])];
    for (n, counts) in expected {
        let poses = ViewSet::resolve(&format!("tammes-{n}")).unwrap().poses(3.0);
        for (k, name) in SPACES.iter().enumerate() {
            for tol in [InequalityTolerance::Exact, InequalityTolerance::Lenient] {
                let vs = ViewSpace::resolve(name).unwrap().with_inequality_tolerance(tol);
                let mask = vs.feasible_mask(&poses);
                assert_eq!(mask.len(), poses.len());
                let c = mask.iter().filter(|&&b| b).count();
                assert_eq!(c, counts[k], "tammes-{n} in {name} ({tol:?})");
                for (p, m) in poses.iter().zip(&mask) {
                    assert_eq!(vs.is_feasible(p), *m);
                }
            }
        }
    }
}

#[test]
fn explain_names_the_first_violated_rule() {
    let hemi = ViewSpace::resolve("hemi").unwrap();
    assert_eq!(hemi.explain(&pose([1.0, 0.0, -0.3])).unwrap(), "camera_z = -0.3 < 0 (rule 2)");
    let eighth = ViewSpace::resolve("eighth").unwrap();
    // eighth lists radius, z, y, x: x < 0 is rule 4.
    assert_eq!(eighth.explain(&pose([-2.0, 1.0, 1.0])).unwrap(), "camera_x = -2 < 0 (rule 4)");
    let r = eighth.explain(&pose([0.5, 0.0, 0.0])).unwrap();
    assert!(r.starts_with("camera_radius = 0.5 < 1 (rule 1)"), "{r}");
    assert_eq!(eighth.explain(&pose([1.0, 2.0, 2.0])), None);
}

#[test]
fn inequality_tolerance_modes() {
    let exact = ViewSpace::resolve("hemi").unwrap();
    assert_eq!(exact.inequality_tolerance, InequalityTolerance::Exact);
    let lenient = exact.clone().with_inequality_tolerance(InequalityTolerance::Lenient);
    // Round-off below a boundary: rejected exactly (as the reference), accepted leniently.
    let p = pose([3.0, 0.0, -1e-17]);
    assert!(!exact.is_feasible(&p));
    assert!(lenient.is_feasible(&p));
    assert!(lenient.is_feasible(&pose([3.0, 0.0, -0.99e-4])));
    assert!(!lenient.is_feasible(&pose([3.0, 0.0, -1.01e-4])));
}

fn space(json: &str) -> Result<ViewSpace, ViewsError> {
    ViewSpace::parse("custom.json", json)
}

#[test]
fn equality_and_inequality_ops_with_atol() {
    let vs = space(
        r#"{"atol": 0.001, "structured_rule": {"rules": [
            {"field": "roll_rad", "op": "==", "value": 0.5},
            {"field": "lookat_z", "op": "!=", "value": 1.0},
            {"field": "lookat_x", "op": "<", "value": 0.2},
            {"field": "lookat_y", "op": "<=", "value": 0.2},
            {"field": "camera_x", "op": ">", "value": 1.0}]}}"#,
    )
    .unwrap();
    let p = |roll: f64, lz: f64, lx: f64, ly: f64, cx: f64| Pose {
        center: [cx, 0.0, 2.0],
        look_at: [lx, ly, lz],
        roll,
    };
    assert!(vs.is_feasible(&p(0.5009, 0.0, 0.0, 0.2, 1.5)));
    assert!(!vs.is_feasible(&p(0.5011, 0.0, 0.0, 0.2, 1.5)));
    assert!(!vs.is_feasible(&p(0.5, 1.0009, 0.0, 0.2, 1.5)));
    assert!(vs.is_feasible(&p(0.5, 1.0011, 0.0, 0.2, 1.5)));
    assert!(!vs.is_feasible(&p(0.5, 0.0, 0.2, 0.2, 1.5)));
    assert!(!vs.is_feasible(&p(0.5, 0.0, 0.0, 0.2 + 1e-12, 1.5)));
    assert!(!vs.is_feasible(&p(0.5, 0.0, 0.0, 0.2, 1.0)));
    let why = vs.explain(&p(0.6, 0.0, 0.0, 0.2, 1.5)).unwrap();
    assert_eq!(why, "roll_rad = 0.6 != 0.5 (atol 0.001) (rule 1)");
}

#[test]
fn custom_or_rule_and_nesting() {
    // Radius at least 2, and (x >= 0 or y >= 0 or (z > 1 and z < 1.5)).
    let vs = space(
        r#"{"name": "custom", "structured_rule": {"logic": "and", "rules": [
            {"field": "camera_radius", "op": ">=", "value": 2.0},
            {"logic": "or", "rules": [
                {"field": "camera_x", "op": ">=", "value": 0.0},
                {"field": "camera_y", "op": ">=", "value": 0.0},
                {"logic": "and", "rules": [
                    {"field": "camera_z", "op": ">", "value": 1.0},
                    {"field": "camera_z", "op": "<", "value": 1.5}]}]}]}}"#,
    )
    .unwrap();
    assert_eq!(vs.name, "custom");
    assert!(vs.is_feasible(&pose([3.0, -1.0, 0.0])));
    assert!(vs.is_feasible(&pose([-3.0, 1.0, 0.0])));
    assert!(!vs.is_feasible(&pose([-3.0, -1.0, 0.0])));
    assert!(vs.is_feasible(&pose([-3.0, -1.0, 1.2])));
    assert!(!vs.is_feasible(&pose([-3.0, -1.0, 1.6])));
    assert!(!vs.is_feasible(&pose([1.0, 1.0, 0.0])));
    let why = vs.explain(&pose([-3.0, -1.0, 1.6])).unwrap();
    assert!(why.contains("camera_x = -3 < 0 (rule 2.1)"), "{why}");
    assert!(why.contains("camera_z = 1.6 >= 1.5 (rule 2.3.2)"), "{why}");
    // A file without a structured rule allows everything; the name defaults to the file stem.
    let all = ViewSpace::parse("dir/open.json", "{}").unwrap();
    assert_eq!(all.name, "open");
    assert!(all.is_feasible(&pose([0.0, 0.0, 0.0])));
}

#[test]
fn blocklist_removes_poses_within_atol() {
    let vs = space(
        r#"{"atol": 0.01, "structured_rule": {"rules": [
            {"field": "camera_radius", "op": ">=", "value": 1.0}]},
            "blocklist": {"poses": [[3, 0, 0, 0, 0, 0, 0], [0, 3, 0, 0, 0, 0, 0.5]]}}"#,
    )
    .unwrap();
    assert!(!vs.is_feasible(&pose([3.005, 0.0, 0.0])));
    assert!(vs.is_feasible(&pose([3.02, 0.0, 0.0])));
    assert!(vs.is_feasible(&pose([0.0, 3.0, 0.0])));
    let blocked = Pose { center: [0.0, 3.0, 0.0], look_at: [0.0; 3], roll: 0.5 };
    assert_eq!(vs.explain(&blocked).unwrap(), "pose is on the blocklist (entry 2)");
}

#[test]
fn malformed_rule_files_name_file_and_json_path() {
    let cases: &[(&str, &str, &str)] = &[
        (r#"{"atol": 1e-4, "bogus": 1}"#, "bogus", "unknown field"),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">=", "value": 0, "x": 1}]}}"#,
            "structured_rule.rules[0].x",
            "unknown field",
        ),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">=", "value": 0},
                {"field": "camera_y", "op": "=>", "value": 0}]}}"#,
            "structured_rule.rules[1].op",
            "unknown op",
        ),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_w", "op": ">=", "value": 0}]}}"#,
            "structured_rule.rules[0].field",
            "unknown field \"camera_w\"",
        ),
        (
            r#"{"structured_rule": {"logic": "xor", "rules": [{"field": "camera_z", "op": ">=", "value": 0}]}}"#,
            "structured_rule.logic",
            "unknown logic",
        ),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">="}]}}"#,
            "structured_rule.rules[0].value",
            "missing",
        ),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">=", "value": "NaN"}]}}"#,
            "structured_rule.rules[0].value",
            "must be a number",
        ),
        (r#"{"structured_rule": {"logic": "and", "rules": []}}"#, "structured_rule.rules", "empty"),
        (
            r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">=", "value": 0},
                {"logic": "or", "rules": []}]}}"#,
            "structured_rule.rules[1].rules",
            "empty",
        ),
        (r#"{"structured_rule": {"logic": "and"}}"#, "structured_rule.rules", "missing"),
        (r#"{"atol": -1}"#, "atol", ">= 0"),
        (r#"{"pose_format": "matrix"}"#, "pose_format", "unsupported pose format"),
        (r#"{"blocklist": {"poses": [[1, 2, 3]]}}"#, "blocklist.poses[0]", "7 numbers"),
        (r#"[1, 2]"#, "$", "must be a JSON object"),
    ];
    for (json, json_path, reason) in cases {
        let e = space(json).unwrap_err();
        match &e {
            ViewsError::Rule { path, json_path: jp, reason: r } => {
                assert_eq!(path, "custom.json");
                assert_eq!(jp, json_path, "{json}");
                assert!(r.contains(reason), "{r} should contain {reason}");
            }
            other => panic!("{json}: unexpected error {other:?}"),
        }
        let msg = e.to_string();
        assert!(msg.starts_with(&format!("custom.json: {json_path}: ")), "{msg}");
        assert!(!msg.contains('\n'));
    }
    // A key with a control character: the JSON path keeps it, the message stays one line.
    let e = space(r#"{"name\n": "x"}"#).unwrap_err();
    assert!(matches!(&e, ViewsError::Rule { json_path, .. } if json_path == "name\n"), "{e:?}");
    assert_eq!(e.to_string().lines().count(), 1, "{e}");
    assert!(e.to_string().starts_with("custom.json: name\\n: unknown field"), "{e}");
    // Invalid JSON and numbers that overflow to infinity are rejected by the JSON reader, with
    // the file, line and column.
    for json in [r#"{"atol": 1e-4,"#, r#"{"atol": 1e999}"#] {
        let e = space(json).unwrap_err();
        assert!(matches!(e, ViewsError::RuleJson { .. }), "{json}: {e:?}");
        let msg = e.to_string();
        assert!(msg.starts_with("custom.json: invalid JSON: ") && msg.contains("line 1"), "{msg}");
    }
}

#[test]
fn resolve_files_and_unknown_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("zpos.json");
    std::fs::write(&p, r#"{"structured_rule": {"rules": [{"field": "camera_z", "op": ">", "value": 0.5}]}}"#)
        .unwrap();
    let vs = ViewSpace::resolve(p.to_str().unwrap()).unwrap();
    assert_eq!(vs.name, "zpos");
    assert!(vs.is_feasible(&pose([0.0, 0.0, 1.0])));
    assert!(!vs.is_feasible(&pose([0.0, 0.0, 0.5])));
    let e = ViewSpace::resolve("half").unwrap_err();
    assert!(e.to_string().contains("\"half\""), "{e}");
    // A broken file names itself.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"structured_rule": {"rules": [{"op": ">="}]}}"#).unwrap();
    let e = ViewSpace::resolve(bad.to_str().unwrap()).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("bad.json") && msg.contains("structured_rule.rules[0].field"), "{msg}");
}
