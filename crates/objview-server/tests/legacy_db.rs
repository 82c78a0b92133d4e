//! A database written by an older objview (tests/fixtures/legacy-db, see its README) read by
//! this one: the stored create requests keep their exact JSON, the finished results are served
//! and exported byte for byte, and the episode that was left running is replayed to the result
//! line the old binary wrote for it.

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
        assert_eq!(&line, want, "episode {id}");
    }
    s.stop();
    assert_eq!(objview_server::db::export(&db, None).unwrap(), export);
    assert_eq!(assert_requests_round_trip(&db), 3);
}
