//! The HTTP contract of docs/server-api.md against the real router on a free loopback port:
//! catalog routes, create validation, every protocol-robustness case of an action (malformed
//! JSON, wrong types, bad poses and reasons, infeasible poses, stale steps, actions after the
//! end, concurrent actions, oversized bodies, unknown ids), time limits, tokens, and the
//! hidden-means-hidden rule.

mod common;

use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use common::*;
use serde_json::{json, Value};

fn id_of(created: &Value) -> String {
    created["episode_id"].as_str().expect("episode_id").to_string()
}

fn ep_path(id: &str, rest: &str) -> String {
    format!("/v1/episodes/{id}{rest}")
}

/// The info of an episode (asserts 200).
fn info(c: &objview_server::client::Client, id: &str) -> Value {
    let r = get(c, &ep_path(id, ""));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    r.json()
}

#[test]
fn catalog_routes_and_route_errors() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let h = get(&c, "/v1/health").json();
    assert_eq!(h, json!({"status": "ok", "version": env!("CARGO_PKG_VERSION")}));
    let splits = get(&c, "/v1/splits").json();
    assert_eq!(splits["splits"][0], json!({"id": "hidden", "objects": 2, "public": false}));
    assert_eq!(splits["splits"][1], json!({"id": "open", "objects": 1, "public": true}));
    let one = get(&c, "/v1/splits/hidden").json();
    assert_eq!(one["object_ids"], json!(["cube", "octahedron"]));
    assert_eq!(one["objects"], 2);
    assert_error(&get(&c, "/v1/splits/nope"), 404, "not_found");
    assert_eq!(
        get(&c, "/v1/view-spaces").json()["view_spaces"],
        json!(["whole", "hemi", "quarter", "eighth"])
    );
    assert_eq!(get(&c, "/v1/candidate-sets").json()["candidate_sets"], json!(["tammes-128", "tammes-360"]));
    let set = get(&c, "/v1/candidate-sets/tammes-128").json();
    let poses = set["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 128);
    for p in poses {
        let p: Vec<f64> = p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        assert_eq!(p.len(), 7);
        assert!(((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 3.0).abs() < 1e-9);
        assert_eq!(&p[3..6], &[0.0, 0.0, 0.0]);
    }
    assert_error(&get(&c, "/v1/candidate-sets/tammes-7"), 404, "not_found");
    assert_error(&get(&c, "/v1/no-such-route"), 404, "not_found");
    assert_error(&get(&c, "/elsewhere"), 404, "not_found");
    assert_error(&c.raw("DELETE", "/v1/splits", None).unwrap(), 405, "method_not_allowed");
    assert_error(&post(&c, "/v1/health", &json!({})), 405, "method_not_allowed");
    assert_error(&get(&c, "/v1/episodes/e-0000000000000000"), 404, "not_found");
    assert_error(&get(&c, "/v1/methods/nobody/results"), 404, "not_found");
    assert_eq!(get(&c, "/v1/methods").json(), json!({"methods": []}));
}

#[test]
fn openapi_describes_every_route() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let doc = get(&client(&s), "/openapi.json").json();
    assert_eq!(doc["openapi"], "3.0.3");
    let paths = doc["paths"].as_object().unwrap();
    for (route, method) in [
        ("/openapi.json", "get"),
        ("/v1/health", "get"),
        ("/v1/splits", "get"),
        ("/v1/splits/{split}", "get"),
        ("/v1/view-spaces", "get"),
        ("/v1/candidate-sets", "get"),
        ("/v1/candidate-sets/{name}", "get"),
        ("/v1/episodes", "post"),
        ("/v1/episodes/{id}", "get"),
        ("/v1/episodes/{id}/observation", "get"),
        ("/v1/episodes/{id}/observation/depth.npy", "get"),
        ("/v1/episodes/{id}/observation/rgb.png", "get"),
        ("/v1/episodes/{id}/feasible", "post"),
        ("/v1/episodes/{id}/actions", "post"),
        ("/v1/episodes/{id}/abort", "post"),
        ("/v1/episodes/{id}/result", "get"),
        ("/v1/methods", "get"),
        ("/v1/methods/{method}/results", "get"),
    ] {
        assert!(paths.get(route).and_then(|p| p.get(method)).is_some(), "{method} {route} is not described");
    }
    assert_eq!(paths.len(), 18, "a described route the test does not know");
}

#[test]
fn create_validates_its_request() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    assert_error(&post_bytes(&c, "/v1/episodes", b"{not json"), 400, "malformed_json");
    assert_error(&post_bytes(&c, "/v1/episodes", b""), 400, "malformed_json");
    let ok = create_body("cube", "whole", json!("auto"));
    let with = |k: &str, v: Value| {
        let mut b = ok.clone();
        b[k] = v;
        b
    };
    let without = |k: &str| {
        let mut b = ok.clone();
        b.as_object_mut().unwrap().remove(k);
        b
    };
    for (body, status, code) in [
        (json!([1, 2]), 422, "invalid_request"),
        (without("split"), 422, "invalid_request"),
        (without("object"), 422, "invalid_request"),
        (without("method"), 422, "invalid_request"),
        (without("budget"), 422, "invalid_request"),
        (with("split", json!("nope")), 422, "invalid_request"),
        (with("split", json!(3)), 422, "invalid_request"),
        (with("view_space", json!("octant")), 422, "invalid_request"),
        (with("budget", json!("0")), 422, "invalid_request"),
        (with("budget", json!(-3)), 422, "invalid_request"),
        (with("budget", json!("five")), 422, "invalid_request"),
        (with("budget", json!(2.5)), 422, "invalid_request"),
        (with("candidate_set", json!("tammes-7")), 422, "invalid_request"),
        (with("family", json!("oracle")), 422, "invalid_request"),
        (with("family", json!("magic")), 422, "invalid_request"),
        (with("execution_mode", json!("greedy")), 422, "invalid_request"),
        (with("execution_mode", json!("budgeted_plan")), 422, "invalid_request"),
        (with("seed", json!("7")), 422, "invalid_request"),
        (with("seed", json!(-1)), 422, "invalid_request"),
        (with("record_timings", json!("no")), 422, "invalid_request"),
        (with("method", json!("a/b")), 422, "invalid_request"),
        (with("method", json!("")), 422, "invalid_request"),
        (with("object", json!(true)), 422, "invalid_request"),
        (with("object", json!(2)), 404, "not_found"),
        (with("object", json!("sphere")), 404, "not_found"),
    ] {
        assert_error(&post(&c, "/v1/episodes", &body), status, code);
    }
    // By index, with a numeric budget: the response of the contract.
    let created = create(&c, &with("object", json!(1)));
    assert_eq!(created["object_id"], "octahedron");
    let b = with("budget", json!(5));
    let created = create(&c, &b);
    for k in [
        "episode_id",
        "object_id",
        "split",
        "view_space",
        "budget",
        "seed",
        "candidate_set",
        "start_pose",
        "intrinsics",
        "action_timeout_s",
        "observation",
    ] {
        assert!(created.get(k).is_some(), "create response without {k}: {created}");
    }
    assert_eq!(created["budget"], "5");
    assert_eq!(created["candidate_set"], "tammes-360");
    assert_eq!(created["action_timeout_s"], 100.0);
    assert_eq!(created["intrinsics"]["width"], 512);
    assert_eq!(created["intrinsics"]["cx"], 256.0);
    assert_eq!(
        created["seed"],
        objview_episode::episode_seed(0, "cube", "whole", objview_episode::Budget::Fixed(5))
    );
    assert_eq!(
        created["observation"],
        json!({"step": 0, "pose": created["start_pose"], "intrinsics": created["intrinsics"], "done": false,
               "terminal": null})
    );
    // An object that cannot be loaded: 500 without its path.
    let r = post(
        &c,
        "/v1/episodes",
        &json!({"split": "broken", "object": 0, "view_space": "whole", "budget": "auto", "method": "m"}),
    );
    assert_error(&r, 500, "internal");
    let text = String::from_utf8_lossy(&r.body);
    assert!(!text.contains("ghost.obj") && !text.contains('/'), "{text}");
}

#[test]
fn actions_that_are_refused_leave_the_episode_going() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let id = id_of(&create(&c, &create_body("cube", "whole", json!("auto"))));
    let act = ep_path(&id, "/actions");
    let good = action(0, mv(pose_dir([1.0, 0.0, 0.0])));
    assert_error(&post_bytes(&c, &act, b"{\"step\": 0, \"action\": "), 400, "malformed_json");
    assert_error(&post_bytes(&c, &act, b"move please"), 400, "malformed_json");
    assert_error(&post(&c, &act, &json!({"action": good["action"]})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!({"step": "0", "action": good["action"]})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!({"step": 0.5, "action": good["action"]})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!({"step": -1, "action": good["action"]})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!({"step": 0})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!({"step": 0, "action": "move"})), 422, "invalid_request");
    assert_error(&post(&c, &act, &json!([0, good["action"]])), 422, "invalid_request");
    assert_error(&post(&c, &act, &action(1, good["action"].clone())), 409, "stale_step");
    assert_error(&post(&c, &act, &action(7, good["action"].clone())), 409, "stale_step");
    // Oversized body: 413, nothing applied.
    let mut big = good.clone();
    big["padding"] = json!("x".repeat(1 << 20));
    assert_error(&post(&c, &act, &big), 413, "payload_too_large");
    assert_error(&post(&c, "/v1/episodes/e-ffffffffffffffff/actions", &good), 404, "not_found");
    let i = info(&c, &id);
    assert_eq!(
        (i["state"].clone(), i["step"].clone(), i["views"].clone()),
        (json!("running"), json!(0), json!(1))
    );
    // The episode goes on.
    let r = post(&c, &act, &good);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    assert_eq!(v["accepted"], true);
    assert_eq!(v["observation"]["step"], 1);
    assert_eq!(v["observation"]["pose"], json!(pose_dir([1.0, 0.0, 0.0])));
    assert!(r.server_timing.as_deref().is_some_and(|t| t.starts_with("handler;dur=")));
    // The previous step is stale now; so is a depth request for it.
    assert_error(&post(&c, &act, &good), 409, "stale_step");
    assert_error(&get(&c, &ep_path(&id, "/observation/depth.npy?step=0")), 409, "stale_step");
    assert_error(&get(&c, &ep_path(&id, "/observation/depth.npy?step=x")), 422, "invalid_request");
    let d = get(&c, &ep_path(&id, "/observation/depth.npy?step=1"));
    assert_eq!(d.status, 200);
    assert_eq!(d.step.as_deref(), Some("1"));
    let (shape, depth) = objview_geom::npy::parse_npy_f64(std::path::Path::new("d.npy"), &d.body).unwrap();
    assert_eq!(shape, vec![512, 512]);
    assert!(depth.iter().any(|&z| z > 0.0) && depth.iter().all(|&z| (0.0..10.0).contains(&z)));
    let png = get(&c, &ep_path(&id, "/observation/rgb.png"));
    assert_eq!((png.status, png.content_type.as_str()), (200, "image/png"));
    assert_eq!(&png.body[1..4], b"PNG");
    assert_eq!(get(&c, &ep_path(&id, "/observation")).json()["step"], 1);
    assert_error(&get(&c, &ep_path(&id, "/result")), 409, "episode_running");
    // Feasibility: a batch, and its refusals.
    let feas = ep_path(&id, "/feasible");
    let r =
        post(&c, &feas, &json!({"poses": [pose_dir([0.0, 0.0, 1.0]), [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]}));
    assert_eq!(r.json(), json!({"feasible": [true, false]}));
    for bad in [
        json!({"poses": [[3.0, 0.0, 0.0, 0.0, 0.0, 0.0]]}),
        json!({"poses": [[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, "0"]]}),
        json!({"poses": [[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, null]]}),
        json!({"poses": "all"}),
        json!({"pose": []}),
    ] {
        assert_error(&post(&c, &feas, &bad), 422, "invalid_request");
    }
    let many: Vec<[f64; 7]> = vec![pose_dir([0.0, 0.0, 1.0]); 10_001];
    assert_error(&post(&c, &feas, &json!({ "poses": many })), 422, "invalid_request");
    assert_error(&post_bytes(&c, &feas, b"[[["), 400, "malformed_json");
    let i = info(&c, &id);
    assert_eq!((i["state"].clone(), i["step"].clone()), (json!("running"), json!(1)));
}

/// Plays one ending action on a fresh episode and returns (OBS, result line).
fn end_with(c: &objview_server::client::Client, space: &str, moves: usize, last: Value) -> (Value, Value) {
    let id = id_of(&create(c, &create_body("octahedron", space, json!("auto"))));
    let act = ep_path(&id, "/actions");
    let dirs = [[1.0, 1.0, 2.0], [1.0, 2.0, 1.0], [2.0, 1.0, 1.0]];
    for (i, d) in dirs.iter().take(moves).enumerate() {
        let r = post(c, &act, &action(i, mv(pose_dir(*d))));
        assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    }
    let r = post(c, &act, &action(moves, last.clone()));
    assert_eq!(r.status, 200, "{last}: {}", String::from_utf8_lossy(&r.body));
    let obs = r.json()["observation"].clone();
    assert_eq!(obs["done"], true);
    // After the end: actions and observation requests are refused; depth, RGB, info, result work.
    assert_error(&post(c, &act, &action(moves, last)), 409, "episode_finished");
    assert_error(&post(c, &act, &action(moves + 1, mv(pose_dir([0.0, 0.0, 1.0])))), 409, "episode_finished");
    assert_error(&get(c, &ep_path(&id, "/observation")), 409, "episode_finished");
    assert_error(&post(c, &ep_path(&id, "/abort"), &json!({})), 409, "episode_finished");
    let d = get(c, &ep_path(&id, "/observation/depth.npy"));
    assert_eq!((d.status, d.step.clone()), (200, Some(obs["step"].to_string())));
    assert_eq!(get(c, &ep_path(&id, "/observation/rgb.png")).status, 200);
    let i = info(c, &id);
    assert_eq!(i["state"], "finished");
    assert_eq!(i["terminal"], obs["terminal"]);
    let r = get(c, &ep_path(&id, "/result"));
    assert_eq!(r.status, 200);
    let res = r.json();
    assert_eq!(res["terminal_reason"], obs["terminal"]["reason"]);
    assert_eq!(res["terminal_source"], obs["terminal"]["source"]);
    (obs, res)
}

fn assert_scored(res: &Value, views: usize) {
    assert_eq!(res["visited_poses"].as_array().unwrap().len(), views, "{}", res["terminal_detail"]);
    assert_eq!(res["steps"].as_array().unwrap().len(), views);
    let t = &res["checkpoints"]["terminal"];
    assert_eq!(t["views"], views);
    let sc = t["sc"]["0.02"].as_f64().unwrap();
    assert!(sc > 0.0 && sc <= 1.0, "views taken are scored: {t}");
}

#[test]
fn malformed_and_infeasible_actions_end_the_episode_with_views_scored() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    for (moves, last, why) in [
        (1, json!({"type": "move", "pose": [3.0, 0.0, 0.0, 0.0, 0.0, 0.0]}), "length 6"),
        (2, json!({"type": "move", "pose": [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]}), "length 8"),
        (1, json!({"type": "move", "pose": [3.0, 0.0, 0.0, 0.0, "0", 0.0, 0.0]}), "invalid type: string"),
        (1, json!({"type": "move", "pose": [3.0, 0.0, 0.0, 0.0, null, 0.0, 0.0]}), "invalid type: null"),
        (1, json!({"type": "move"}), "missing field `pose`"),
        (0, json!({"type": "jump", "pose": pose_dir([0.0, 0.0, 1.0])}), "unknown variant"),
        (0, json!({}), "missing field"),
        (1, json!({"type": "stop", "reason": "bored"}), "unknown stop reason"),
        (1, json!({"type": "stop"}), "missing field"),
        (2, json!({"type": "move", "pose": [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]}), "infeasible"),
        (1, json!({"type": "move", "pose": [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0]}), "centre equals"),
    ] {
        let (obs, res) = end_with(&c, "whole", moves, last.clone());
        assert_eq!(obs["terminal"]["source"], "benchmark", "{last}");
        assert_eq!(obs["terminal"]["reason"], "invalid_action", "{last}");
        let detail = obs["terminal"]["detail"].as_str().unwrap();
        assert!(detail.contains(why), "{last}: {detail}");
        assert_eq!(obs["step"], moves);
        assert_scored(&res, moves + 1);
    }
    // Infeasible in a restricted view space (quarter: y, z ≥ 0).
    let (obs, res) = end_with(&c, "quarter", 1, mv(pose_dir([0.0, -1.0, 1.0])));
    assert_eq!(obs["terminal"]["reason"], "invalid_action");
    assert!(obs["terminal"]["detail"].as_str().unwrap().contains("infeasible"));
    assert_scored(&res, 2);
    // A valid stop ends it as the planner's own stop.
    let (obs, res) = end_with(&c, "whole", 3, json!({"type": "stop", "reason": "plan_end"}));
    assert_eq!(
        (obs["terminal"]["source"].clone(), obs["terminal"]["reason"].clone()),
        (json!("algorithm_stop"), json!("plan_end"))
    );
    assert_scored(&res, 4);
    // Abort: the client's planner failed.
    let id = id_of(&create(&c, &create_body("cube", "whole", json!("auto"))));
    let r = post(&c, &ep_path(&id, "/abort"), &json!({"detail": "out of memory"}));
    assert_eq!(r.status, 200);
    let t = &r.json()["observation"]["terminal"];
    assert_eq!(*t, json!({"source": "exception", "reason": "planner_error", "detail": "out of memory"}));
    // Methods list the finished results of this owner.
    let m = get(&c, "/v1/methods").json();
    assert_eq!(m, json!({"methods": [{"method": "test-nbv", "finished": 14}]}));
    let lines = get(&c, "/v1/methods/test-nbv/results");
    assert_eq!(lines.content_type, "application/x-ndjson");
    let text = String::from_utf8(lines.body).unwrap();
    assert_eq!(text.lines().count(), 14);
    assert!(text.lines().all(|l| serde_json::from_str::<Value>(l).is_ok()));
}

#[test]
fn budgets_cap_and_finite_plans_end_as_locally() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let mut body = create_body("cube", "whole", json!(2));
    body["execution_mode"] = json!("budgeted_plan");
    let id = id_of(&create(&c, &body));
    let act = ep_path(&id, "/actions");
    for (i, d) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]].iter().enumerate() {
        assert_eq!(post(&c, &act, &action(i, mv(pose_dir(*d)))).json()["observation"]["done"], false);
    }
    let obs = post(&c, &act, &action(2, mv(pose_dir([0.0, 0.0, 1.0])))).json()["observation"].clone();
    assert_eq!(obs["terminal"]["reason"], "budget_reached");
    assert_eq!(obs["step"], 2, "the move beyond the budget is not executed");
    let res = get(&c, &ep_path(&id, "/result")).json();
    assert!(res["checkpoints"].get("K=2").is_none(), "K = 2 is not an iterative checkpoint");
    assert_eq!(res["execution_mode"], "budgeted_plan");
    assert_eq!(res["budget"], "2");
}

#[test]
fn of_two_concurrent_actions_exactly_one_is_applied() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let id = id_of(&create(&c, &create_body("cube", "whole", json!("auto"))));
    for step in 0..3 {
        let n = 6;
        let barrier = Arc::new(Barrier::new(n));
        let handles: Vec<_> = (0..n)
            .map(|k| {
                let (c, id, barrier) = (c.clone(), id.clone(), barrier.clone());
                std::thread::spawn(move || {
                    let body = action(step, mv(pose_dir([1.0, k as f64 + 0.5, step as f64 + 0.25])));
                    barrier.wait();
                    post(&c, &ep_path(&id, "/actions"), &body)
                })
            })
            .collect();
        let answers: Vec<_> = handles.into_iter().map(|h| h.join().unwrap()).collect();
        let won: Vec<_> = answers.iter().filter(|r| r.status == 200).collect();
        assert_eq!(won.len(), 1, "step {step}: {} actions applied", won.len());
        for r in answers.iter().filter(|r| r.status != 200) {
            assert_error(r, 409, "stale_step");
        }
        let i = info(&c, &id);
        assert_eq!(i["step"], step + 1);
        assert_eq!(i["history"].as_array().unwrap().last().unwrap(), &won[0].json()["observation"]["pose"]);
    }
}

/// Waits (polling, generous) until the episode has finished; its info.
fn wait_finished(c: &objview_server::client::Client, id: &str) -> Value {
    let t = Instant::now();
    loop {
        let i = info(c, id);
        if i["state"] == "finished" {
            return i;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "episode {id} never timed out: {i}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_client_that_never_acts_loses_the_episode() {
    // The start limit: no first action.
    let (mut cfg, _tmp) = config();
    cfg.start_timeout_s = 0.3;
    let s = start(&cfg);
    let c = client(&s);
    let created = create(&c, &create_body("cube", "whole", json!("auto")));
    let id = id_of(&created);
    let i = wait_finished(&c, &id);
    assert_eq!(i["terminal"]["source"], "exception");
    assert_eq!(i["terminal"]["reason"], "timeout");
    assert_error(
        &post(&c, &ep_path(&id, "/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0])))),
        409,
        "episode_finished",
    );
    assert_scored(&get(&c, &ep_path(&id, "/result")).json(), 1);
    drop(s);
    // The action limit: one action, then silence.
    let (mut cfg, _tmp2) = config();
    cfg.action_timeout_s = 0.3;
    let s = start(&cfg);
    let c = client(&s);
    let created = create(&c, &create_body("cube", "whole", json!("auto")));
    assert_eq!(created["action_timeout_s"], 0.3);
    let id = id_of(&created);
    assert_eq!(post(&c, &ep_path(&id, "/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0])))).status, 200);
    let i = wait_finished(&c, &id);
    assert_eq!(i["terminal"]["reason"], "timeout");
    assert_eq!(i["views"], 2);
    assert_scored(&get(&c, &ep_path(&id, "/result")).json(), 2);
}

#[test]
fn tokens_guard_every_route_and_episodes_belong_to_their_token() {
    let (mut cfg, tmp) = config();
    let tokens = tmp.path().join("tokens.txt");
    std::fs::write(&tokens, "# the team\ntok-alice alice\ntok-bob   bob  # second\n\n").unwrap();
    cfg.tokens = Some(tokens);
    let s = start(&cfg);
    let anon = client(&s);
    let alice = objview_server::client::Client::new(&s.url(), Some("tok-alice"));
    let bob = objview_server::client::Client::new(&s.url(), Some("tok-bob"));
    let mallory = objview_server::client::Client::new(&s.url(), Some("tok-mallory"));
    assert_eq!(get(&anon, "/v1/health").status, 200);
    for path in ["/v1/splits", "/v1/splits/hidden", "/v1/view-spaces", "/v1/candidate-sets", "/v1/methods"] {
        assert_error(&get(&anon, path), 401, "unauthorized");
        assert_error(&get(&mallory, path), 401, "unauthorized");
        assert_eq!(get(&alice, path).status, 200, "{path}");
    }
    assert_error(
        &post(&anon, "/v1/episodes", &create_body("cube", "whole", json!("auto"))),
        401,
        "unauthorized",
    );
    let id = id_of(&create(&alice, &create_body("cube", "whole", json!("auto"))));
    assert_error(&get(&anon, &ep_path(&id, "")), 401, "unauthorized");
    assert_error(&get(&bob, &ep_path(&id, "")), 404, "not_found");
    assert_error(
        &post(&bob, &ep_path(&id, "/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0])))),
        404,
        "not_found",
    );
    assert_error(&get(&bob, &ep_path(&id, "/observation/depth.npy")), 404, "not_found");
    assert_eq!(info(&alice, &id)["state"], "running");
    let r =
        post(&alice, &ep_path(&id, "/actions"), &action(0, json!({"type": "stop", "reason": "plan_end"})));
    assert_eq!(r.status, 200);
    assert_eq!(get(&alice, "/v1/methods").json()["methods"][0]["finished"], 1);
    assert_eq!(get(&bob, "/v1/methods").json(), json!({"methods": []}));
    assert_error(&get(&bob, "/v1/methods/test-nbv/results"), 404, "not_found");
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

const METRIC_KEYS: &[&str] = &[
    "sc",
    "nsc",
    "cd",
    "coverage",
    "points",
    "vertices",
    "faces",
    "triangles",
    "metrics",
    "checkpoints",
    "steps",
    "reference",
    "gt_points",
    "gt_source",
    "fused_points",
    "observable_sc",
    "path_cost",
    "ms_voxels",
    "mesh",
    "gt_cloud",
];

/// Asserts that a response of a running episode shows no metric and no file path.
fn assert_hidden(what: &str, body: &[u8], dir: &str) {
    let text = String::from_utf8_lossy(body);
    assert!(!text.contains(dir), "{what} names the pool's folder: {text}");
    for ext in [".obj", ".ply", ".json", ".sqlite"] {
        assert!(!text.contains(ext), "{what} names a file ({ext}): {text}");
    }
    let v: Value = serde_json::from_slice(body).unwrap_or(Value::Null);
    let mut ks = Vec::new();
    keys(&v, &mut ks);
    for k in ks {
        assert!(!METRIC_KEYS.contains(&k.as_str()), "{what} has key {k:?}: {text}");
    }
}

#[test]
fn hidden_means_hidden() {
    let (cfg, _tmp) = config();
    let dir = path_str(&common::fixture().dir);
    let s = start(&cfg);
    let c = client(&s);
    let mut seen: Vec<(String, Vec<u8>)> = Vec::new();
    let mut record = |what: &str, r: objview_server::client::RawResponse| {
        seen.push((what.to_string(), r.body.clone()));
        r
    };
    for path in ["/v1/splits", "/v1/splits/hidden", "/v1/candidate-sets/tammes-360", "/v1/view-spaces"] {
        record(path, get(&c, path));
    }
    let created =
        record("create", post(&c, "/v1/episodes", &create_body("cube", "whole", json!("auto")))).json();
    let id = id_of(&created);
    let act = ep_path(&id, "/actions");
    for (i, d) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]].iter().enumerate() {
        record("action", post(&c, &act, &action(i, mv(pose_dir(*d)))));
        record("stale action", post(&c, &act, &action(i, mv(pose_dir(*d)))));
        record("info", get(&c, &ep_path(&id, "")));
        record("observation", get(&c, &ep_path(&id, "/observation")));
        record("feasible", post(&c, &ep_path(&id, "/feasible"), &json!({"poses": [pose_dir(*d)]})));
        record("bad feasible", post(&c, &ep_path(&id, "/feasible"), &json!({"poses": [[1]]})));
        record("result while running", get(&c, &ep_path(&id, "/result")));
        record("bad depth", get(&c, &ep_path(&id, "/observation/depth.npy?step=99")));
    }
    record("methods", get(&c, "/v1/methods"));
    // The ending action's answer is still about the episode, not its metrics.
    record(
        "ending action",
        post(&c, &act, &action(4, json!({"type": "move", "pose": [0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]}))),
    );
    record("info after the end", get(&c, &ep_path(&id, "")));
    assert!(seen.len() > 30);
    for (what, body) in &seen {
        assert_hidden(what, body, &dir);
    }
    // The check can fail: the result (after the end) and a public split's info show metrics.
    let res = get(&c, &ep_path(&id, "/result"));
    assert!(std::panic::catch_unwind(|| assert_hidden("result", &res.body, &dir)).is_err());
    let open = create(
        &c,
        &json!({"split": "open", "object": 0, "view_space": "whole", "budget": "auto", "method": "test-nbv"}),
    );
    let oid = id_of(&open);
    assert_eq!(post(&c, &ep_path(&oid, "/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0])))).status, 200);
    let i = info(&c, &oid);
    let sc = i["metrics"]["sc"]["0.02"].as_f64().expect("public splits show metrics while running");
    assert!(sc > 0.0 && sc <= 1.0);
    assert_eq!(i["metrics"]["views"], 2);
    // They are the metrics the result records for that step.
    assert_eq!(
        post(&c, &ep_path(&oid, "/actions"), &action(1, json!({"type": "stop", "reason": "plan_end"})))
            .status,
        200
    );
    let res = get(&c, &ep_path(&oid, "/result")).json();
    let step1 = &res["steps"][1];
    for k in ["sc", "nsc", "cd", "views", "path_cost"] {
        assert_eq!(step1[k], i["metrics"][k], "{k}");
    }
}
