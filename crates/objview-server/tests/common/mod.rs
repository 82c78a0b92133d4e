//! Helpers of the server's integration tests: a tiny pool of built-in objects (coarse meshes,
//! small ground-truth clouds) shared by every test of a binary, servers on free loopback ports,
//! raw requests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use objview_geom::synth::{self, Detail};
use objview_server::client::{Client, RawResponse};
use objview_server::{BackgroundServer, ServerConfig};
use serde_json::{json, Value};

/// The tiny pool: `hidden.json` (cube, octahedron), `open.json` (cube; served public),
/// `broken.json` (a mesh file that does not exist), and a shared reference cache.
pub struct Fixture {
    pub dir: PathBuf,
    pub hidden: PathBuf,
    pub open: PathBuf,
    pub broken: PathBuf,
    pub cache: PathBuf,
}

pub fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        // Under cargo's per-target scratch folder, one per test binary: the reference cache
        // survives reruns.
        let dir =
            Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("fixture-{}", env!("CARGO_CRATE_NAME")));
        std::fs::create_dir_all(&dir).expect("fixture folder");
        for name in ["cube", "octahedron"] {
            let mesh = synth::build(name, Detail { segments: 8 }).expect("built-in object");
            objview_geom::write::write_obj(&dir.join(format!("{name}.obj")), &mesh).expect("writing OBJ");
            let gt = objview_geom::cloud::sample_surface(&mesh, 1500, 0);
            objview_geom::cloud::write_ply_points(&dir.join(format!("{name}.ply")), &gt)
                .expect("writing PLY");
        }
        let entry = |n: &str| json!({"uid": n, "mesh": format!("{n}.obj"), "gt_cloud": format!("{n}.ply")});
        let hidden = dir.join("hidden.json");
        std::fs::write(&hidden, json!([entry("cube"), entry("octahedron")]).to_string()).unwrap();
        let open = dir.join("open.json");
        std::fs::write(&open, json!([entry("cube")]).to_string()).unwrap();
        let broken = dir.join("broken.json");
        std::fs::write(&broken, json!([{"uid": "ghost", "mesh": "ghost.obj"}]).to_string()).unwrap();
        Fixture { cache: dir.join("cache"), hidden, open, broken, dir }
    })
}

/// A config over the fixture's splits (`open` public), with a fresh database in the returned
/// folder (keep it alive while the server runs).
pub fn config() -> (ServerConfig, tempfile::TempDir) {
    let f = fixture();
    let tmp = tempfile::tempdir().expect("temporary directory");
    let cfg = ServerConfig {
        pool: vec![f.hidden.clone(), f.open.clone(), f.broken.clone()],
        public: vec!["open".into()],
        db: tmp.path().join("server.sqlite"),
        cache_dir: Some(f.cache.clone()),
        ..Default::default()
    };
    (cfg, tmp)
}

pub fn start(cfg: &ServerConfig) -> BackgroundServer {
    objview_server::spawn(cfg, "127.0.0.1:0").expect("server starts")
}

pub fn client(s: &BackgroundServer) -> Client {
    Client::new(&s.url(), None)
}

/// A create request on the hidden split.
pub fn create_body(object: &str, space: &str, budget: Value) -> Value {
    json!({"split": "hidden", "object": object, "view_space": space, "budget": budget, "method": "test-nbv"})
}

/// Creates an episode; its 201 body.
pub fn create(c: &Client, body: &Value) -> Value {
    let r = post(c, "/v1/episodes", body);
    assert_eq!(r.status, 201, "create: {}", String::from_utf8_lossy(&r.body));
    r.json()
}

pub fn post(c: &Client, path: &str, body: &Value) -> RawResponse {
    c.raw("POST", path, Some(body.to_string().as_bytes())).expect("request")
}

pub fn post_bytes(c: &Client, path: &str, body: &[u8]) -> RawResponse {
    c.raw("POST", path, Some(body)).expect("request")
}

pub fn get(c: &Client, path: &str) -> RawResponse {
    c.raw("GET", path, None).expect("request")
}

/// Asserts an error response: status, code, and the JSON error shape.
pub fn assert_error(r: &RawResponse, status: u16, code: &str) {
    let v = r.json();
    assert_eq!(
        r.status,
        status,
        "expected {status} {code}, got {}: {}",
        r.status,
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(v["error"]["code"], code, "{v}");
    assert!(v["error"]["message"].as_str().is_some_and(|m| !m.is_empty()), "{v}");
}

pub fn action(step: usize, action: Value) -> Value {
    json!({"step": step, "action": action})
}

pub fn mv(p: [f64; 7]) -> Value {
    json!({"type": "move", "pose": p})
}

/// A feasible pose at radius 3 in direction `d` (any view space with z, y, x ≥ 0 for positive d).
pub fn pose_dir(d: [f64; 3]) -> [f64; 7] {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    [3.0 * d[0] / n, 3.0 * d[1] / n, 3.0 * d[2] / n, 0.0, 0.0, 0.0, 0.0]
}

pub fn path_str(p: &Path) -> String {
    p.display().to_string()
}
