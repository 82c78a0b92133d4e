//! A database written by an older objview (tests/fixtures/legacy-db, see its README) read by
//! this one: the stored create requests keep their exact JSON, the finished results are served
//! and exported byte for byte, and the episode that was left running is replayed to the result
//! line the old binary wrote for it — up to what SPEC v3 changed: its steps carry no `cd` (CD at
//! checkpoints only, and the checkpoint's CD is the same number) and SC/NSC are instantaneous
//! (within 10⁻³ of the old sticky values).

mod common;

use std::path::{Path, PathBuf};

use common::*;
use objview_server::db::Db;
use objview_server::request::CreateSpec;
use objview_server::ServerConfig;
use serde_json::Value;

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/legacy-db")
}

/// `line` with what SPEC v3 changed taken out (the `cd` of steps; SC and NSC everywhere), and
/// the SC/NSC values it had, in order.
fn without_v3_changes(line: &str) -> (Value, Vec<f64>) {
    let mut v: Value = serde_json::from_str(line).unwrap();
    let mut cov = Vec::new();
    let mut strip = |m: &mut Value| {
        for k in ["sc", "nsc"] {
            if let Some(Value::Object(map)) = m.as_object_mut().and_then(|o| o.remove(k)) {
                cov.extend(map.values().map(|x| x.as_f64().unwrap()));
            }
        }
    };
    if let Some(steps) = v["steps"].as_array_mut() {
        for st in steps {
            st.as_object_mut().unwrap().remove("cd");
            strip(st);
        }
    }
    if let Some(cps) = v["checkpoints"].as_object_mut() {
        for c in cps.values_mut() {
            strip(c);
        }
    }
    (v, cov)
}

/// The served/exported `got` line equals the old binary's `want`: byte for byte for a stored
/// result, up to the SPEC v3 changes for the replayed episode.
fn assert_same_result(got: &str, want: &str, what: &str) {
    if got == want {
        return;
    }
    let (g, gc) = without_v3_changes(got);
    let (w, wc) = without_v3_changes(want);
    assert!(
        g["terminal_detail"].as_str().unwrap_or("").contains("replayed"),
        "{what}: a stored line changed"
    );
    assert_eq!(g, w, "{what}");
    assert_eq!(gc.len(), wc.len(), "{what}");
    for (a, b) in gc.iter().zip(&wc) {
        assert!((a - b).abs() < 1e-3, "{what}: SC/NSC {a} vs the old sticky {b}");
    }
}

fn lines(name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(fixture_dir().join(name)).expect("fixture file");
    text.lines().map(str::to_string).collect()
}

/// A copy of the fixture database in a fresh folder (opening it writes).
fn copy_db() -> (PathBuf, tempfile::TempDir) {
    let tmp = tempfile::tempdir().expect("temporary directory");
    let db = tmp.path().join("server.sqlite");
    std::fs::copy(fixture_dir().join("server.sqlite"), &db).expect("copying the fixture database");
    (db, tmp)
}

/// Every stored create request parses, and serializes back to the very bytes stored.
fn assert_requests_round_trip(db: &Path) -> usize {
    let rows = Db::open(db).expect("database opens").episodes().expect("episodes");
    for row in &rows {
        let spec: CreateSpec = serde_json::from_str(&row.request).expect("stored request parses");
        assert_eq!(serde_json::to_string(&spec).unwrap(), row.request, "episode {}", row.id);
    }
    rows.len()
}

#[test]
fn stored_create_requests_keep_their_exact_json() {
    let (db, _tmp) = copy_db();
    assert_eq!(assert_requests_round_trip(&db), 3);
}

#[test]
fn a_database_from_before_is_replayed_served_and_exported_as_the_old_binary_did() {
    let (db, _tmp) = copy_db();
    let cfg =
        ServerConfig { pool: vec![fixture_dir().join("legacy.json")], db: db.clone(), ..Default::default() };
    let s = start(&cfg);
    let c = client(&s);
    let export = lines("expected-export.jsonl");
    for want_info in lines("expected-info.jsonl") {
        let info: Value = serde_json::from_str(&want_info).unwrap();
        let id = info["episode_id"].as_str().unwrap();
        let r = get(&c, &format!("/v1/episodes/{id}"));
        assert_eq!(r.status, 200);
        assert_eq!(String::from_utf8(r.body).unwrap(), want_info);
        let r = get(&c, &format!("/v1/episodes/{id}/result"));
        assert_eq!(r.status, 200);
        let line = String::from_utf8(r.body).unwrap();
        let method = info["method"].as_str().unwrap();
        let want = export
            .iter()
            .find(|l| serde_json::from_str::<Value>(l).unwrap()["method"] == method)
            .expect("an exported line of the method");
        assert_same_result(&line, want, &format!("episode {id}"));
    }
    // The episodes predate `created_at`: they are listed, stamped with the upgrade's time.
    let list = get(&c, "/v1/episodes").json();
    let list = list["episodes"].as_array().unwrap();
    assert_eq!(list.len(), 3);
    for e in list {
        assert_eq!(e["state"], "finished", "{e}");
        let t = e["created_at"].as_str().unwrap();
        assert!(t.len() == 24 && t.ends_with('Z') && &t[10..11] == "T", "{t}");
    }
    s.stop();
    let got = objview_server::db::export(&db, None).unwrap();
    assert_eq!(got.len(), export.len());
    for (g, w) in got.iter().zip(&export) {
        assert_same_result(g, w, "export");
    }
    assert_eq!(assert_requests_round_trip(&db), 3);
}
