//! A hostile client against the real server on loopback, with raw sockets where a polite HTTP
//! client would not go: idle and half-sent connections (closed after their time limits), a
//! client holding every connection the server keeps (a well-behaved client still gets in at
//! once), every connection busy (503), huge and out-of-range poses, and a compact pass over the
//! protocol-robustness rules — while a well-behaved client keeps getting answers and nothing
//! about a hidden object leaks. Every loop is bounded in count and time.

mod common;

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use common::*;
use objview_server::client::Client;
use objview_server::{BackgroundServer, ServerConfig};
use serde_json::{json, Value};

/// Connects with generous socket timeouts (a test never hangs on a socket).
fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(10))).unwrap();
    s
}

/// Reads one HTTP response (head and `Content-Length` body): status and body.
fn read_response(s: &mut TcpStream) -> Option<(u16, Vec<u8>)> {
    let mut buf = Vec::new();
    let mut byte = [0u8; 1];
    while !buf.ends_with(b"\r\n\r\n") {
        match s.read(&mut byte) {
            Ok(1) => buf.push(byte[0]),
            _ => return None,
        }
        if buf.len() > 64 << 10 {
            return None;
        }
    }
    let head = String::from_utf8_lossy(&buf).to_ascii_lowercase();
    let status = head.split_whitespace().nth(1)?.parse().ok()?;
    let len: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("content-length:"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0);
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).ok()?;
    Some((status, body))
}

/// `GET /v1/health` on a fresh connection, as a well-behaved client: the time it took, or
/// `None` when no 200 came within 10 s.
fn health(addr: SocketAddr) -> Option<Duration> {
    let t = Instant::now();
    let mut s = connect(addr);
    s.write_all(b"GET /v1/health HTTP/1.1\r\nHost: objview\r\nConnection: close\r\n\r\n").ok()?;
    let (status, body) = read_response(&mut s)?;
    let v: Value = serde_json::from_slice(&body).ok()?;
    (status == 200 && v["status"] == "ok").then(|| t.elapsed())
}

/// Waits until the server closes `s` (EOF or reset), for at most `max`; how long it took.
fn closed_within(s: &mut TcpStream, max: Duration) -> Option<Duration> {
    let t = Instant::now();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    let mut buf = [0u8; 4096];
    while t.elapsed() < max {
        match s.read(&mut buf) {
            Ok(0) => return Some(t.elapsed()),
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => return Some(t.elapsed()),
        }
    }
    None
}

fn start_with(f: impl FnOnce(&mut ServerConfig)) -> (BackgroundServer, tempfile::TempDir) {
    let (mut cfg, tmp) = config();
    f(&mut cfg);
    (start(&cfg), tmp)
}

#[test]
fn idle_and_half_sent_connections_are_closed_after_their_time_limits() {
    let (s, _tmp) = start_with(|c| {
        c.header_timeout_s = 0.3;
        c.body_timeout_s = 0.4;
        c.idle_timeout_s = 1.5;
    });
    let addr = s.addr;
    // A connection that never sends anything: the idle limit.
    let mut idle = connect(addr);
    let t = closed_within(&mut idle, Duration::from_secs(6)).expect("an idle connection stays open");
    eprintln!("idle connection closed after {t:?} (idle limit 1.5 s)");
    assert!(t >= Duration::from_millis(1300), "closed before its idle limit: {t:?}");
    // A keep-alive connection after an answered request: the idle limit again.
    let mut kept = connect(addr);
    kept.write_all(b"GET /v1/health HTTP/1.1\r\nHost: objview\r\n\r\n").unwrap();
    assert_eq!(read_response(&mut kept).map(|r| r.0), Some(200));
    let t =
        closed_within(&mut kept, Duration::from_secs(6)).expect("an idle keep-alive connection stays open");
    eprintln!("keep-alive connection closed {t:?} after its answer (idle limit 1.5 s)");
    assert!(t >= Duration::from_millis(1300), "{t:?}");
    // A head trickled one byte every 50 ms: the header limit counts from its first byte.
    let mut slow = connect(addr);
    slow.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    let t = Instant::now();
    let head = b"GET /v1/health HTTP/1.1\r\nHost: objview\r\nX-Slow: ".iter().chain(std::iter::repeat(&b'a'));
    let mut closed = None;
    let mut buf = [0u8; 256];
    for &b in head.take(200) {
        if slow.write_all(&[b]).is_err() {
            closed = Some(t.elapsed());
            break;
        }
        match slow.read(&mut buf) {
            Ok(0) => {
                closed = Some(t.elapsed());
                break;
            }
            Ok(_) => panic!("an answer to a head that never ended"),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => {
                closed = Some(t.elapsed());
                break;
            }
        }
    }
    let t = closed.expect("a trickled head kept its connection for 10 s");
    eprintln!("trickled head closed after {t:?} (header limit 0.3 s)");
    assert!(t >= Duration::from_millis(250) && t < Duration::from_millis(1300), "{t:?}");
    // A body that stops halfway: 408 `request_timeout` after the body limit, then closed.
    let mut half = connect(addr);
    let t = Instant::now();
    half.write_all(
        b"POST /v1/episodes HTTP/1.1\r\nHost: objview\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{\"split\":",
    )
    .unwrap();
    let (status, body) = read_response(&mut half).expect("an answer to a half-sent body");
    let waited = t.elapsed();
    eprintln!("half-sent body answered {status} after {waited:?} (body limit 0.4 s)");
    assert_eq!(status, 408, "{}", String::from_utf8_lossy(&body));
    assert_eq!(serde_json::from_slice::<Value>(&body).unwrap()["error"]["code"], "request_timeout");
    assert!(waited >= Duration::from_millis(350), "{waited:?}");
    assert!(
        closed_within(&mut half, Duration::from_secs(3)).is_some(),
        "the connection stays open after 408"
    );
    // The server answered a well-behaved client all along, and nothing is left open.
    assert!(health(addr).is_some());
    let t = Instant::now();
    while s.state.connections.open() > 0 && t.elapsed() < Duration::from_secs(3) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(s.state.connections.open(), 0);
}

#[test]
fn a_client_holding_every_connection_cannot_lock_out_a_well_behaved_one() {
    // Long time limits: only the cap's eviction can let anyone in.
    let (s, _tmp) = start_with(|c| c.max_connections = 8);
    let addr = s.addr;
    let mut held = Vec::new();
    for i in 0..200 {
        let mut c = connect(addr);
        match i % 4 {
            0 => {}
            1 => c.write_all(b"GET /v1/health HTTP/1.1\r\nHost: objv").unwrap(),
            2 => c
                .write_all(b"POST /v1/episodes HTTP/1.1\r\nHost: x\r\nContent-Length: 500\r\n\r\n{\"a\"")
                .unwrap(),
            _ => {
                // A keep-alive connection that did one request and went quiet.
                c.write_all(b"GET /v1/view-spaces HTTP/1.1\r\nHost: objview\r\n\r\n").unwrap();
                assert_eq!(read_response(&mut c).map(|r| r.0), Some(200));
            }
        }
        held.push(c);
    }
    let t = Instant::now();
    while s.state.connections.evicted() < 192 && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(s.state.connections.open() <= 8, "{} open", s.state.connections.open());
    assert!(s.state.connections.evicted() >= 192, "{} evicted", s.state.connections.evicted());
    // With the cap held, a well-behaved client gets its answers at once, fresh connection or
    // keep-alive.
    let mut slowest = Duration::ZERO;
    for _ in 0..10 {
        let took = health(addr).expect("a health check was locked out");
        slowest = slowest.max(took);
    }
    eprintln!("with the cap (8) held by idle sockets: 10 health checks, slowest {slowest:?}");
    assert!(slowest < Duration::from_secs(2), "{slowest:?}");
    let c = client(&s);
    let created = create(&c, &create_body("cube", "whole", json!("auto")));
    let id = created["episode_id"].as_str().unwrap().to_string();
    let r = post(&c, &format!("/v1/episodes/{id}/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0]))));
    assert_eq!(r.status, 200);
    // The connections closed to make room really are closed.
    let closed = held.iter_mut().take(50).filter_map(|c| closed_within(c, Duration::from_millis(100)));
    assert_eq!(closed.count(), 50);
    assert_eq!(s.state.connections.refused(), 0);
}

#[test]
fn with_every_connection_busy_a_new_one_gets_503_and_the_busy_ones_finish() {
    let (s, _tmp) = start_with(|c| c.max_connections = 2);
    let addr = s.addr;
    // Hold the engine: creates wait inside their handler, so their connections are busy.
    let gate = s.state.engine_lanes.hold();
    let body = create_body("cube", "whole", json!("auto")).to_string();
    let request = format!(
        "POST /v1/episodes HTTP/1.1\r\nHost: objview\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let mut busy: Vec<TcpStream> = (0..2).map(|_| connect(addr)).collect();
    for b in &mut busy {
        b.write_all(request.as_bytes()).unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let mut late = connect(addr);
    let _ = late.write_all(b"GET /v1/health HTTP/1.1\r\nHost: objview\r\nConnection: close\r\n\r\n");
    let (status, answer) = read_response(&mut late).expect("a clean 503");
    assert_eq!(status, 503, "{}", String::from_utf8_lossy(&answer));
    let v: Value = serde_json::from_slice(&answer).unwrap();
    assert_eq!(v["error"]["code"], "overloaded", "{v}");
    assert_eq!(s.state.connections.refused(), 1);
    drop(gate);
    for b in &mut busy {
        let (status, answer) = read_response(b).expect("the busy request's answer");
        assert_eq!(status, 201, "{}", String::from_utf8_lossy(&answer));
    }
    drop(busy);
    let t = Instant::now();
    let mut ok = health(addr);
    while ok.is_none() && t.elapsed() < Duration::from_secs(3) {
        std::thread::sleep(Duration::from_millis(20));
        ok = health(addr);
    }
    assert!(ok.is_some(), "health after the busy connections finished");
}

/// Every object key in `v`, recursively.
fn keys(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                out.push(k.clone());
                keys(x, out);
            }
        }
        Value::Array(a) => a.iter().for_each(|x| keys(x, out)),
        _ => {}
    }
}

/// Keys no answer about a running episode of a hidden split may carry.
const HIDDEN: &[&str] = &[
    "sc",
    "nsc",
    "cd",
    "coverage",
    "points",
    "vertices",
    "faces",
    "metrics",
    "checkpoints",
    "steps",
    "reference",
    "gt_points",
    "gt_source",
    "fused_points",
    "path_cost",
    "mesh",
    "gt_cloud",
];

#[test]
fn hostile_requests_get_their_errors_and_nothing_hidden_leaks() {
    let (s, tmp) = start_with(|c| {
        let tokens = c.db.with_file_name("tokens.txt");
        std::fs::write(&tokens, "tok-good good\n").unwrap();
        c.tokens = Some(tokens);
    });
    let _keep = tmp;
    let good = Client::new(&s.url(), Some("tok-good"));
    let anon = Client::new(&s.url(), None);
    let wrong = Client::new(&s.url(), Some("tok-evil"));
    let mut answers: Vec<(String, objview_server::client::RawResponse)> = Vec::new();
    let mut check = |what: &str, r: objview_server::client::RawResponse, status: u16, code: &str| {
        assert_error(&r, status, code);
        answers.push((what.to_string(), r));
        // The well-behaved client is answered between any two hostile requests.
        assert!(health(s.addr).is_some(), "health after {what}");
    };
    let created = create(&good, &create_body("cube", "whole", json!("auto")));
    let id = created["episode_id"].as_str().unwrap().to_string();
    let act = format!("/v1/episodes/{id}/actions");
    let feas = format!("/v1/episodes/{id}/feasible");
    let ok_move = action(0, mv(pose_dir([1.0, 0.0, 0.0])));
    // Tokens.
    check("no token", get(&anon, "/v1/splits"), 401, "unauthorized");
    check("wrong token", post(&wrong, &act, &ok_move), 401, "unauthorized");
    // Bodies that are not JSON, or JSON of the wrong kind.
    check("not JSON", post_bytes(&good, &act, b"{\"step\": 0, \"action\": {"), 400, "malformed_json");
    check(
        "NaN literal",
        post_bytes(&good, &feas, b"{\"poses\": [[NaN, 0, 0, 0, 0, 0, 0]]}"),
        400,
        "malformed_json",
    );
    check(
        "step as a string",
        post(&good, &act, &json!({"step": "0", "action": ok_move["action"]})),
        422,
        "invalid_request",
    );
    check("poses as a string", post(&good, &feas, &json!({"poses": "all"})), 422, "invalid_request");
    // Numbers beyond f64: valid JSON syntax, 422 naming the field; the episode goes on.
    let r = post_bytes(
        &good,
        &act,
        br#"{"step": 0, "action": {"type": "move", "pose": [1e400, 0, 0, 0, 0, 0, 0]}}"#,
    );
    let message = r.json()["error"]["message"].as_str().unwrap_or_default().to_string();
    assert!(message.starts_with("`action.pose[0]`"), "{message}");
    check("1e400 in an action", r, 422, "invalid_request");
    let r = post_bytes(&good, &feas, br#"{"poses": [[3, 0, 0, 0, 0, -1e999, 0]]}"#);
    assert!(r.json()["error"]["message"].as_str().unwrap_or_default().starts_with("`poses[0][5]`"));
    check("-1e999 in a feasibility query", r, 422, "invalid_request");
    // Huge finite poses: a feasibility query refuses them (422).
    let huge = [1e300, 1e300, 1e300, 0.0, 0.0, 0.0, 0.0];
    let r = post(&good, &feas, &json!({"poses": [pose_dir([0.0, 0.0, 1.0]), huge]}));
    assert!(r.json()["error"]["message"]
        .as_str()
        .unwrap_or_default()
        .contains("`poses[1]`: the camera centre"));
    check("huge pose in a feasibility query", r, 422, "invalid_request");
    // Stale steps, unknown episodes, oversized bodies.
    check("stale step", post(&good, &act, &action(3, ok_move["action"].clone())), 409, "stale_step");
    check(
        "unknown episode",
        post(&good, "/v1/episodes/e-0123456789abcdef/actions", &ok_move),
        404,
        "not_found",
    );
    let big = format!("{{\"poses\": [{}]}}", vec!["[3,0,0,0,0,0,0]"; 70_000].join(","));
    check("oversized body", post_bytes(&good, &feas, big.as_bytes()), 413, "payload_too_large");
    check("an unknown state filter", get(&good, "/v1/episodes?state=zombie"), 422, "invalid_request");
    check("another token's list", get(&wrong, "/v1/episodes"), 401, "unauthorized");
    // Refused requests never touched the episode.
    let info = get(&good, &format!("/v1/episodes/{id}")).json();
    assert_eq!((info["state"].clone(), info["step"].clone()), (json!("running"), json!(0)));
    let r = post(&good, &act, &ok_move);
    assert_eq!(r.status, 200);
    answers.push(("move".into(), r));
    // A huge pose as a move is an invalid action: the episode ends, its views scored, and its
    // result has numbers where numbers belong.
    let r = post(&good, &act, &action(1, mv(huge)));
    assert_eq!(r.status, 200);
    let t = &r.json()["observation"]["terminal"];
    assert_eq!(t["reason"], "invalid_action", "{t}");
    assert!(t["detail"].as_str().unwrap().contains("camera centre is 1.732e300 object units"), "{t}");
    answers.push(("huge move".into(), r));
    let r = get(&good, "/v1/episodes");
    assert_eq!(r.status, 200);
    assert_eq!(r.json()["episodes"][0]["object"], "cube", "the uid the client sent");
    answers.push(("episode list".into(), r));
    for (what, r) in &answers {
        let text = String::from_utf8_lossy(&r.body);
        assert!(!text.contains(&path_str(&fixture().dir)), "{what} names the pool's folder: {text}");
        let mut ks = Vec::new();
        keys(&r.json(), &mut ks);
        assert!(ks.iter().all(|k| !HIDDEN.contains(&k.as_str())), "{what} leaks {ks:?}: {text}");
    }
    let line = String::from_utf8(get(&good, &format!("/v1/episodes/{id}/result")).body).unwrap();
    assert!(!line.contains("null"), "{line}");
    let res: objview_episode::EpisodeResult = serde_json::from_str(&line).unwrap();
    assert_eq!((res.visited_poses.len(), res.non_finite()), (2, None));
    let all = String::from_utf8(get(&good, "/v1/methods/test-nbv/results").body).unwrap();
    assert_eq!(all.lines().count(), 1);
    assert!(!all.contains("null"), "{all}");
}

#[test]
fn an_oversized_body_gets_its_413_before_the_connection_closes() {
    let (s, _tmp) = start_with(|_| {});
    let c = client(&s);
    let created = create(&c, &create_body("cube", "whole", json!("auto")));
    let feas = format!("/v1/episodes/{}/feasible", created["episode_id"].as_str().unwrap());
    // 4 MiB: more than loopback socket buffers hold, so a server that answered without reading
    // would cut the client off mid-write (a broken pipe instead of the answer).
    let big = format!("{{\"poses\": [{}]}}", vec!["[3,0,0,0,0,0,0]"; 4 << 16].join(","));
    assert!(big.len() > 4 << 20);
    for _ in 0..5 {
        assert_error(&post_bytes(&c, &feas, big.as_bytes()), 413, "payload_too_large");
        // The connection that carried it stays usable.
        assert_eq!(get(&c, "/v1/health").status, 200);
    }
    // A body announced beyond what the server drains: answered at once, and closed.
    let mut raw = connect(s.addr);
    raw.write_all(
        b"POST /v1/episodes HTTP/1.1\r\nHost: objview\r\nContent-Type: application/json\r\nContent-Length: 1000000000\r\n\r\n{",
    )
    .unwrap();
    let (status, body) = read_response(&mut raw).expect("an answer before the body");
    assert_eq!(status, 413, "{}", String::from_utf8_lossy(&body));
    assert!(closed_within(&mut raw, Duration::from_secs(5)).is_some());
}

/// A client that creates episodes and never acts cannot fill the server's memory: every
/// running episode holds its engine state, so creates beyond `--max-running` (in all) and
/// `--max-running-per-token` get 429 `too_many_episodes` at once, and a place comes back when an
/// episode ends — by its last action, an abort or its time limit.
#[test]
fn running_episodes_are_capped_in_all_and_per_token() {
    let (s, _tmp) = start_with(|c| {
        let tokens = c.db.with_file_name("tokens.txt");
        std::fs::write(&tokens, "tok-a alice\ntok-b bob\ntok-c carol\n").unwrap();
        c.tokens = Some(tokens);
        c.max_running = 3;
        c.max_running_per_token = 2;
        c.start_timeout_s = 1.5;
    });
    let (alice, bob, carol) = (
        Client::new(&s.url(), Some("tok-a")),
        Client::new(&s.url(), Some("tok-b")),
        Client::new(&s.url(), Some("tok-c")),
    );
    let body = create_body("cube", "whole", json!(2));
    let id = |v: &Value| v["episode_id"].as_str().unwrap().to_string();
    // A refused create: 429 `too_many_episodes`, naming the limit that refused it.
    let refused = |c: &Client, limit: &str| {
        let r = post(c, "/v1/episodes", &body);
        assert_error(&r, 429, "too_many_episodes");
        let text = String::from_utf8_lossy(&r.body);
        assert!(text.contains(limit), "{limit}: {text}");
    };
    let a1 = id(&create(&alice, &body));
    let _a2 = id(&create(&alice, &body));
    // Alice's own limit; Bob still gets in.
    refused(&alice, "--max-running-per-token 2");
    let b1 = id(&create(&bob, &body));
    // The server's limit: three are running.
    refused(&carol, "--max-running 3");
    // An abort gives a place back.
    assert_eq!(post(&alice, &format!("/v1/episodes/{a1}/abort"), &json!({"detail": "done"})).status, 200);
    let c1 = id(&create(&carol, &body));
    assert_error(&post(&carol, "/v1/episodes", &body), 429, "too_many_episodes");
    // The last action of a budget gives a place back (budget 2: two moves, then stop).
    for (step, d) in [[1.0, 0.0, 0.2], [0.0, 1.0, 0.2]].into_iter().enumerate() {
        assert_eq!(
            post(&bob, &format!("/v1/episodes/{b1}/actions"), &action(step, mv(pose_dir(d)))).status,
            200
        );
    }
    let stop = json!({"step": 2, "action": {"type": "stop", "reason": "plan_end"}});
    let r = post(&bob, &format!("/v1/episodes/{b1}/actions"), &stop);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(get(&bob, &format!("/v1/episodes/{b1}")).json()["state"], "finished");
    let _b2 = id(&create(&bob, &body));
    // The time limit (1.5 s without a first action) ends the idle ones: every place comes back.
    let t = std::time::Instant::now();
    loop {
        if post(&carol, "/v1/episodes", &body).status == 201 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "no place came back after the time limits");
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = c1;
}
