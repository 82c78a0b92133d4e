//! End-to-end tests of `objview serve`, `objview export` and `objview run --server` with the
//! real binary: a server killed with SIGKILL restarts on its database with its finished results
//! intact and its running episodes ended as `interrupted` (views scored); the export feeds
//! `objview report`; a remote run writes the file a local run writes; under a low descriptor
//! limit, a client holding idle connections cannot starve the server, and a huge pose neither
//! poisons the results nor the report.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{objview_err, objview_ok, s, tempdir};
use objview_geom::synth::{self, Detail};
use objview_server::client::Client;
use serde_json::{json, Value};

/// A tiny pool: `hidden.json` with a coarse cube and octahedron and small ground-truth clouds.
fn pool(dir: &Path) -> PathBuf {
    for name in ["cube", "octahedron"] {
        let mesh = synth::build(name, Detail { segments: 8 }).unwrap();
        objview_geom::write::write_obj(&dir.join(format!("{name}.obj")), &mesh).unwrap();
        let gt = objview_geom::cloud::sample_surface(&mesh, 1500, 0);
        objview_geom::cloud::write_ply_points(&dir.join(format!("{name}.ply")), &gt).unwrap();
    }
    let entry = |n: &str| json!({"uid": n, "mesh": format!("{n}.obj"), "gt_cloud": format!("{n}.ply")});
    let split = dir.join("hidden.json");
    std::fs::write(&split, json!([entry("cube"), entry("octahedron")]).to_string()).unwrap();
    split
}

/// A running `objview serve`, killed (SIGKILL) when dropped.
struct Server {
    child: Child,
    url: String,
    /// The line it printed when it started listening.
    line: String,
}

impl Server {
    fn start(split: &Path, db: &Path, cache: &Path) -> Server {
        Server::spawn(Command::new(env!("CARGO_BIN_EXE_objview")).args(Server::args(split, db, cache)))
    }

    /// A server whose open-file limit (`ulimit -n`) is `nofile`, with `extra` arguments.
    fn start_limited(split: &Path, db: &Path, cache: &Path, nofile: u32, extra: &[&str]) -> Server {
        let mut cmd = Command::new("sh");
        cmd.arg("-c")
            .arg(format!("ulimit -n {nofile} && exec \"$0\" \"$@\""))
            .arg(env!("CARGO_BIN_EXE_objview"))
            .args(Server::args(split, db, cache))
            .args(extra);
        Server::spawn(&mut cmd)
    }

    fn args(split: &Path, db: &Path, cache: &Path) -> Vec<String> {
        ["serve", "--pool", s(split), "--addr", "127.0.0.1:0", "--db", s(db), "--cache-dir", s(cache)]
            .iter()
            .map(|x| x.to_string())
            .collect()
    }

    fn spawn(cmd: &mut Command) -> Server {
        let mut child =
            cmd.stdout(Stdio::piped()).stderr(Stdio::inherit()).spawn().expect("starting objview serve");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .unwrap_or_else(|| panic!("no URL in {line:?}"))
            .to_string();
        Server { child, url, line }
    }

    fn kill(&mut self) {
        let _ = self.child.kill(); // SIGKILL on Unix
        let _ = self.child.wait();
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill();
    }
}

fn pose(d: [f64; 3]) -> Value {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    json!([3.0 * d[0] / n, 3.0 * d[1] / n, 3.0 * d[2] / n, 0.0, 0.0, 0.0, 0.0])
}

fn act(c: &Client, id: &str, step: usize, action: Value) -> Value {
    c.post_json(&format!("/v1/episodes/{id}/actions"), &json!({"step": step, "action": action})).unwrap()
}

#[test]
fn a_killed_server_keeps_its_results_and_ends_running_episodes_as_interrupted() {
    let dir = tempdir();
    let split = pool(dir.path());
    let (db, cache) = (dir.path().join("server.sqlite"), dir.path().join("cache"));
    let mut server = Server::start(&split, &db, &cache);
    let c = Client::new(&server.url, None);
    let body = |object: &str| {
        json!({"split": "hidden", "object": object, "view_space": "whole", "budget": "auto",
               "method": "test-nbv", "family": "learned", "record_timings": false})
    };
    // One finished episode, one left running after two moves.
    let done = c.create(&body("cube")).unwrap()["episode_id"].as_str().unwrap().to_string();
    act(&c, &done, 0, json!({"type": "move", "pose": pose([1.0, 0.0, 0.5])}));
    act(&c, &done, 1, json!({"type": "move", "pose": pose([0.0, 1.0, 0.5])}));
    let end = act(&c, &done, 2, json!({"type": "stop", "reason": "plan_end"}));
    assert_eq!(end["observation"]["terminal"]["reason"], "plan_end");
    let finished_line = c.result(&done).unwrap();
    let running = c.create(&body("octahedron")).unwrap()["episode_id"].as_str().unwrap().to_string();
    act(&c, &running, 0, json!({"type": "move", "pose": pose([1.0, 0.2, 0.5])}));
    act(&c, &running, 1, json!({"type": "move", "pose": pose([-1.0, 0.2, 0.5])}));
    server.kill();
    assert!(c.health().is_err(), "the server is gone");

    let server = Server::start(&split, &db, &cache);
    let c = Client::new(&server.url, None);
    assert_eq!(c.result(&done).unwrap(), finished_line, "the finished result is intact");
    let info = c.get_json(&format!("/v1/episodes/{running}")).unwrap();
    assert_eq!(info["state"], "finished");
    assert_eq!(info["views"], 3, "its stored actions were replayed");
    assert_eq!(info["terminal"]["source"], "exception");
    assert_eq!(info["terminal"]["reason"], "interrupted");
    let err = c
        .post_json(
            &format!("/v1/episodes/{running}/actions"),
            &json!({"step": 2, "action": {"type": "move", "pose": pose([0.0, 0.0, 1.0])}}),
        )
        .unwrap_err();
    assert_eq!(err.code(), Some("episode_finished"));
    let res: Value = serde_json::from_str(&c.result(&running).unwrap()).unwrap();
    assert_eq!(res["visited_poses"].as_array().unwrap().len(), 3);
    assert_eq!(res["visited_poses"][2], pose([-1.0, 0.2, 0.5]));
    let sc = res["checkpoints"]["terminal"]["sc"]["0.02"].as_f64().unwrap();
    assert!(sc > 0.0 && sc <= 1.0, "the views taken are scored");
    // Replaying gives the metrics the engine gives: the same steps as a second restart's.
    drop(server);
    let server = Server::start(&split, &db, &cache);
    let c = Client::new(&server.url, None);
    let again: Value = serde_json::from_str(&c.result(&running).unwrap()).unwrap();
    assert_eq!(again["steps"], res["steps"]);

    // Export (the server may keep running) → objview report reads it.
    let out = dir.path().join("export/results.jsonl");
    objview_ok(&["export", "--db", s(&db), "--out", s(&out)]);
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0], finished_line.trim_end(), "the export holds the result lines as served");
    let one = dir.path().join("one.jsonl");
    objview_ok(&["export", "--db", s(&db), "--out", s(&one), "--method", "nobody"]);
    assert_eq!(std::fs::read_to_string(&one).unwrap(), "");
    let report = dir.path().join("report");
    objview_ok(&["report", s(&out), "--out", s(&report)]);
    assert!(std::fs::read_dir(&report).unwrap().count() > 0);
    assert!(objview_err(&["export", "--db", s(&dir.path().join("nope.sqlite")), "--out", s(&one)])
        .contains("nope.sqlite"));
}

#[test]
fn run_with_server_writes_the_file_of_a_local_run() {
    let dir = tempdir();
    let split = pool(dir.path());
    let (db, cache) = (dir.path().join("server.sqlite"), dir.path().join("cache"));
    let server = Server::start(&split, &db, &cache);
    let run_as = |planner: &str, budget: &str, out: &Path, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "run",
            "--planner",
            planner,
            "--space",
            "quarter",
            "--budget",
            budget,
            "--seed",
            "7",
            "--out",
            s(out),
            "--no-timings",
            "--quiet",
        ]
        .iter()
        .map(|x| x.to_string())
        .collect();
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    let run = |out: &Path, extra: &[&str]| run_as("random-tsp", "5", out, extra);
    let local = dir.path().join("local.jsonl");
    let args = run(&local, &["--objects", s(&split), "--cache-dir", s(&cache)]);
    objview_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let remote = dir.path().join("remote.jsonl");
    // The split file's path stands for its split on the server.
    let args = run(&remote, &["--objects", s(&split), "--server", &server.url]);
    objview_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let local_text = std::fs::read_to_string(&local).unwrap();
    assert_eq!(local_text.lines().count(), 2);
    assert_eq!(std::fs::read_to_string(&remote).unwrap(), local_text);
    // One object by index, the other by uid.
    let picked = dir.path().join("picked.jsonl");
    let args = run(&picked, &["--objects", "hidden:1", "--server", &server.url]);
    objview_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(
        std::fs::read_to_string(&picked).unwrap(),
        local_text.lines().nth(1).unwrap().to_string() + "\n"
    );
    // What a server cannot do, or does itself, is refused with one clear line.
    for (planner, budget, extra, why) in [
        ("oracle", "auto", vec!["--objects", "hidden"], "ground truth"),
        ("random-tsp", "5", vec!["--objects", "hidden", "--cap", "10"], "--cap is a setting of the server"),
        ("random-tsp", "5", vec!["--objects", "nope"], "nope"),
        ("random-tsp", "5", vec!["--objects", "hidden:sphere"], "no object \"sphere\""),
        ("random-tsp", "5", vec!["--objects", "hidden:5"], "no index 5"),
    ] {
        let out = dir.path().join("refused.jsonl");
        let mut args = run_as(planner, budget, &out, &extra);
        args.extend(["--server".to_string(), server.url.clone()]);
        let err = objview_err(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(err.contains(why), "{extra:?}: {err}");
    }
}

#[test]
fn bench_serve_runs_concurrent_clients_against_an_in_process_server() {
    let dir = tempdir();
    let json_out = dir.path().join("bench.json");
    let cache = dir.path().join("cache");
    let out = objview_ok(&[
        "bench",
        "serve",
        "--clients",
        "3",
        "--episodes-per-client",
        "2",
        "--budget",
        "2",
        "--object",
        "cube",
        "--triangles",
        "200",
        "--gt-points",
        "2000",
        "--cache-dir",
        s(&cache),
        "--json",
        s(&json_out),
    ]);
    assert!(out.contains("moves/s") && out.contains("p99"), "{out}");
    // The host the figures come from: first line of the output, and in the JSON.
    assert!(
        out.starts_with("host: ") && out.lines().next().unwrap().contains(" logical CPUs, features: "),
        "{out}"
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&json_out).unwrap()).unwrap();
    assert!(
        v["host"]["logical_cpus"].as_u64().unwrap() >= 1 && v["host"]["cpu"].is_string(),
        "{}",
        v["host"]
    );
    assert!(v["host"]["features"].is_array());
    let r = &v["report"];
    assert_eq!(r["episodes"], 6);
    assert_eq!(r["steps"], 12);
    assert_eq!(r["client"]["samples"], 12);
    assert_eq!(r["server"]["samples"], 12, "every action answer carries Server-Timing");
    assert!(r["steps_per_second"].as_f64().unwrap() > 0.0);
    // Memory: the process's peak after the warm-up episode and after the run (Linux).
    if std::path::Path::new("/proc/self/status").exists() {
        assert!(out.contains("memory (server and clients, one process): peak RSS "), "{out}");
        assert!(out.contains("per further concurrent episode (3 at once)"), "{out}");
        let m = &v["memory"];
        let (warm, peak) =
            (m["warm_peak_rss_bytes"].as_u64().unwrap(), m["peak_rss_bytes"].as_u64().unwrap());
        assert!(warm > 0 && peak >= warm, "{m}");
        assert_eq!(m["concurrent_episodes"], 3);
        assert_eq!(m["bytes_per_further_episode"].as_f64().unwrap(), (peak - warm) as f64 / 2.0, "{m}");
    }
    // CPU of the timed run: user and system seconds, and the cores that kept busy.
    assert!(out.contains("CPU of this process (server and clients) during the run: user "), "{out}");
    let c = &v["cpu"];
    let (user, system, busy) = (
        c["user_seconds"].as_f64().unwrap(),
        c["system_seconds"].as_f64().unwrap(),
        c["cores_busy"].as_f64().unwrap(),
    );
    assert!(user > 0.0 && system >= 0.0, "{c}");
    let seconds = r["seconds"].as_f64().unwrap();
    assert!((busy - (user + system) / seconds).abs() < 1e-9, "{c}");
    assert_eq!(c["cores"].as_u64().unwrap(), v["host"]["logical_cpus"].as_u64().unwrap(), "{c}");
}

/// `GET /v1/health` on a fresh connection: whether a 200 came, and how long it took.
fn health(addr: &str) -> (bool, Duration) {
    let t = Instant::now();
    let Ok(mut c) = TcpStream::connect(addr) else { return (false, t.elapsed()) };
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = c.write_all(b"GET /v1/health HTTP/1.1\r\nHost: objview\r\nConnection: close\r\n\r\n");
    let mut answer = String::new();
    let _ = c.read_to_string(&mut answer);
    (answer.starts_with("HTTP/1.1 200") && answer.contains("\"ok\""), t.elapsed())
}

#[test]
fn under_a_low_descriptor_limit_idle_connections_neither_starve_the_server_nor_huge_poses_the_report() {
    let dir = tempdir();
    let split = pool(dir.path());
    let (db, cache) = (dir.path().join("server.sqlite"), dir.path().join("cache"));
    // The cap asked for (256) does not fit in 128 descriptors: it is lowered to 128 - 64.
    let server = Server::start_limited(&split, &db, &cache, 128, &["--max-connections", "256"]);
    assert!(server.line.contains("connections <= 64 (header 10 s, body 30 s, idle 60 s)"), "{}", server.line);
    let addr = server.url.trim_start_matches("http://").to_string();
    // 200 idle sockets, more than the descriptor limit: health checks still answer at once.
    let idle: Vec<TcpStream> = (0..200).map(|_| TcpStream::connect(&addr).expect("connect")).collect();
    for _ in 0..5 {
        let (ok, took) = health(&addr);
        assert!(ok && took < Duration::from_secs(3), "health check: {ok} after {took:?}");
    }
    drop(idle);
    // A huge pose ends the episode as an invalid action; the result has no null.
    let c = Client::new(&server.url, None);
    let body = json!({"split": "hidden", "object": "cube", "view_space": "whole", "budget": "auto",
                      "method": "test-nbv", "record_timings": false});
    let id = c.create(&body).unwrap()["episode_id"].as_str().unwrap().to_string();
    act(&c, &id, 0, json!({"type": "move", "pose": pose([1.0, 0.0, 0.5])}));
    let end = act(&c, &id, 1, json!({"type": "move", "pose": [1e300, 1e300, 1e300, 0, 0, 0, 0]}));
    assert_eq!(end["observation"]["terminal"]["reason"], "invalid_action");
    let line = c.result(&id).unwrap();
    assert!(!line.contains("null"), "{line}");
    // Export, plus a line that an older server wrote for such a pose: the report skips and lists
    // that line and reports the rest.
    let out = dir.path().join("results.jsonl");
    objview_ok(&["export", "--db", s(&db), "--out", s(&out)]);
    let mut poisoned: Value = serde_json::from_str(&line).unwrap();
    poisoned["uid"] = json!("octahedron");
    poisoned["steps"][1]["path_cost"] = Value::Null;
    let mut text = std::fs::read_to_string(&out).unwrap();
    text.push_str(&format!("{poisoned}\n"));
    std::fs::write(&out, text).unwrap();
    let report = dir.path().join("report");
    let o = common::objview(&["report", s(&out), "--out", s(&report), "--no-plots"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "report: skipped {}:2: not an episode result (invalid type: null, expected f64",
            s(&out)
        )),
        "{stderr}"
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("## Skipped lines"), "{stdout}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("Episodes: 1 kept of 1 result line"), "{md}");
    let failures = std::fs::read_to_string(report.join("failures.csv")).unwrap();
    assert!(
        failures.lines().any(|l| l.starts_with("skipped_line,") && l.contains(",2,octahedron,test-nbv,")),
        "{failures}"
    );
}
