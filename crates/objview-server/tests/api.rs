//! The HTTP contract of docs/server-api.md against the real router on a free loopback port:
//! catalog routes, create validation, every protocol-robustness case of an action (malformed
//! JSON, wrong types, bad poses and reasons, infeasible poses, stale steps, actions after the
//! end, concurrent actions, oversized bodies, unknown ids), time limits, tokens, the
//! hidden-means-hidden rule, the episode list, gzip and keep-alive.

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
        ("/v1/episodes", "get"),
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
    assert_eq!(paths.len(), 18, "a described path the test does not know");
    let ops: usize = paths.values().map(|p| p.as_object().unwrap().len()).sum();
    assert_eq!(ops, 19, "a described route the test does not know");
    let list = &paths["/v1/episodes"]["get"];
    let names: Vec<&str> =
        list["parameters"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["state", "method"]);
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
    let listed = record("episode list", get(&c, "/v1/episodes?state=running")).json();
    assert_eq!(listed["episodes"][0]["episode_id"], id.as_str(), "{listed}");
    assert_eq!(listed["episodes"][0]["object"], "cube", "the uid the create answer named: {listed}");
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

/// Whether `t` is RFC 3339 UTC as the server writes it: `YYYY-MM-DDTHH:MM:SS.mmmZ`.
fn is_rfc3339_utc(t: &str) -> bool {
    let b = t.as_bytes();
    let digits = |r: std::ops::Range<usize>| r.clone().all(|i| b.get(i).is_some_and(u8::is_ascii_digit));
    b.len() == 24
        && digits(0..4)
        && b[4] == b'-'
        && digits(5..7)
        && b[7] == b'-'
        && digits(8..10)
        && b[10] == b'T'
        && digits(11..13)
        && b[13] == b':'
        && digits(14..16)
        && b[16] == b':'
        && digits(17..19)
        && b[19] == b'.'
        && digits(20..23)
        && b[23] == b'Z'
}

/// The episode ids of a `GET /v1/episodes…` answer, asserting 200.
fn listed(c: &objview_server::client::Client, path: &str) -> Vec<String> {
    let r = get(c, path);
    assert_eq!(r.status, 200, "{path}: {}", String::from_utf8_lossy(&r.body));
    r.json()["episodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["episode_id"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn episodes_are_listed_by_state_and_method_for_their_own_token_only() {
    let (mut cfg, tmp) = config();
    let tokens = tmp.path().join("tokens.txt");
    std::fs::write(&tokens, "tok-alice alice\ntok-bob bob\n").unwrap();
    cfg.tokens = Some(tokens);
    let s = start(&cfg);
    let alice = objview_server::client::Client::new(&s.url(), Some("tok-alice"));
    let bob = objview_server::client::Client::new(&s.url(), Some("tok-bob"));
    let anon = client(&s);
    let before = std::time::SystemTime::now();
    let e1 = id_of(&create(&alice, &create_body("cube", "whole", json!("auto"))));
    let mut other = create_body("octahedron", "whole", json!("auto"));
    other["method"] = json!("other+nbv");
    let e2 = id_of(&create(&alice, &other));
    let e3 = id_of(&create(&bob, &create_body("cube", "whole", json!("auto"))));
    // e1 ends (a stop at step 0); e2 moves once and is left running (an orphan).
    let stop = action(0, json!({"type": "stop", "reason": "plan_end"}));
    assert_eq!(post(&alice, &ep_path(&e1, "/actions"), &stop).status, 200);
    assert_eq!(
        post(&alice, &ep_path(&e2, "/actions"), &action(0, mv(pose_dir([1.0, 0.0, 0.0])))).status,
        200
    );

    let all = get(&alice, "/v1/episodes").json();
    let list = all["episodes"].as_array().unwrap();
    assert_eq!(list.len(), 2, "bob's episode is not alice's: {all}");
    let (a, b) = (&list[0], &list[1]);
    assert_eq!(
        (a["episode_id"].as_str(), a["split"].as_str(), a["object"].as_str(), a["method"].as_str()),
        (Some(e1.as_str()), Some("hidden"), Some("cube"), Some("test-nbv"))
    );
    assert_eq!((a["state"].as_str(), a["step"].as_u64()), (Some("finished"), Some(0)));
    assert_eq!(
        (b["episode_id"].as_str(), b["object"].as_str(), b["method"].as_str()),
        (Some(e2.as_str()), Some("octahedron"), Some("other+nbv"))
    );
    assert_eq!((b["state"].as_str(), b["step"].as_u64()), (Some("running"), Some(1)));
    let mut keys: Vec<&str> = a.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(keys, ["created_at", "episode_id", "method", "object", "split", "state", "step"]);
    let (t1, t2) = (a["created_at"].as_str().unwrap(), b["created_at"].as_str().unwrap());
    assert!(is_rfc3339_utc(t1) && is_rfc3339_utc(t2), "{t1} {t2}");
    assert!(t1 <= t2, "creation order: {t1} {t2}");
    // The year and day are today's (UTC), derived from the system clock independently.
    let days = before.duration_since(std::time::UNIX_EPOCH).unwrap().as_secs() / 86_400;
    let year_now = 1970 + days * 400 / 146_097;
    let year: u64 = t1[..4].parse().unwrap();
    assert!((year_now - 1..=year_now + 1).contains(&year), "{t1} (about {year_now})");

    assert_eq!(listed(&alice, "/v1/episodes?state=running"), [e2.as_str()]);
    assert_eq!(listed(&alice, "/v1/episodes?state=finished"), [e1.as_str()]);
    assert_eq!(listed(&alice, "/v1/episodes?method=other%2Bnbv"), [e2.as_str()]);
    assert_eq!(listed(&alice, "/v1/episodes?method=other%2Bnbv&state=finished"), Vec::<String>::new());
    assert_eq!(listed(&alice, "/v1/episodes?method=nobody"), Vec::<String>::new());
    assert_eq!(listed(&bob, "/v1/episodes"), [e3.as_str()]);
    assert_error(&get(&anon, "/v1/episodes"), 401, "unauthorized");
    let r = get(&alice, "/v1/episodes?state=done");
    assert_error(&r, 422, "invalid_request");
    assert!(r.json()["error"]["message"].as_str().unwrap().starts_with("`state` must be"), "{}", r.json());
    assert_error(&get(&alice, "/v1/episodes?stat=running"), 422, "invalid_request");

    // The Rust client: list the orphans, abort them; the result says why.
    let orphans = alice.list_episodes(Some("running")).unwrap();
    assert_eq!(orphans.len(), 1);
    assert_eq!(orphans[0]["episode_id"], e2.as_str());
    assert_eq!(alice.list_episodes(None).unwrap().len(), 2);
    let obs = alice.abort(&e2, "cleanup: the client crashed").unwrap();
    assert!(obs.done);
    assert!(alice.list_episodes(Some("running")).unwrap().is_empty());
    let res = get(&alice, &ep_path(&e2, "/result")).json();
    assert_eq!(
        (res["terminal_source"].as_str(), res["terminal_reason"].as_str(), res["terminal_detail"].as_str()),
        (Some("exception"), Some("planner_error"), Some("cleanup: the client crashed"))
    );
    assert_eq!(res["visited_poses"].as_array().unwrap().len(), 2, "the views taken are scored");
    let e = alice.list_episodes(Some("all")).unwrap_err();
    assert_eq!(e.code(), Some("invalid_request"), "{e}");
    assert_eq!(listed(&bob, "/v1/episodes?state=running"), [e3]);
}

/// One HTTP/1.1 exchange on an open connection: status, headers (lower-case names) and the
/// `Content-Length` body as sent (not decoded).
fn exchange(s: &mut std::net::TcpStream, request: &str) -> (u16, Vec<(String, String)>, Vec<u8>) {
    use std::io::{Read, Write};
    s.write_all(request.as_bytes()).unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        assert_eq!(s.read(&mut byte).unwrap(), 1, "the connection closed mid-head");
        head.push(byte[0]);
    }
    let head = String::from_utf8(head).unwrap();
    let mut lines = head.split("\r\n");
    let status = lines.next().unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let len: usize =
        headers.iter().find(|(k, _)| k == "content-length").map(|(_, v)| v.parse().unwrap()).unwrap();
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).unwrap();
    (status, headers, body)
}

fn header<'a>(h: &'a [(String, String)], name: &str) -> Option<&'a str> {
    h.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
}

fn gunzip(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(b), &mut out).unwrap();
    out
}

#[test]
fn depth_is_gzipped_for_clients_that_accept_it_and_connections_stay_alive() {
    let (cfg, _tmp) = config();
    let s = start(&cfg);
    let c = client(&s);
    let id = id_of(&create(&c, &create_body("cube", "whole", json!("auto"))));
    let depth_path = ep_path(&id, "/observation/depth.npy");
    let req = |extra: &str| format!("GET {depth_path} HTTP/1.1\r\nHost: objview\r\n{extra}\r\n");
    // Three requests on one connection: gzip, plain, gzip with a q-value.
    let admitted = s.state.connections.admitted();
    let mut sock = std::net::TcpStream::connect(s.addr).unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let (st, gz_h, gz) = exchange(&mut sock, &req("Accept-Encoding: gzip, deflate\r\n"));
    assert_eq!(st, 200);
    let (st, plain_h, plain) = exchange(&mut sock, &req(""));
    assert_eq!(st, 200);
    let (_, q_h, q) = exchange(&mut sock, &req("Accept-Encoding: br;q=1, gzip;q=0.5\r\n"));
    let (_, refused_h, refused) = exchange(&mut sock, &req("Accept-Encoding: gzip;q=0\r\n"));
    assert_eq!(s.state.connections.admitted() - admitted, 1, "four requests, one connection");
    assert_eq!(header(&gz_h, "content-encoding"), Some("gzip"));
    assert_eq!(header(&gz_h, "vary").map(str::to_ascii_lowercase).as_deref(), Some("accept-encoding"));
    assert_eq!(header(&gz_h, "x-objview-step"), Some("0"));
    assert_eq!(header(&plain_h, "content-encoding"), None, "no compression without the header");
    assert_eq!(header(&plain_h, "vary").map(str::to_ascii_lowercase).as_deref(), Some("accept-encoding"));
    assert_eq!(header(&q_h, "content-encoding"), Some("gzip"));
    assert_eq!(header(&refused_h, "content-encoding"), None);
    assert_eq!(refused, plain);
    // The plain body is the NPY of 512 × 512 floats; the gzip one decodes to it byte for byte.
    assert_eq!(plain.len(), objview_geom::npy::npy_header("<f4", &[512, 512]).len() + 512 * 512 * 4);
    assert_eq!(gunzip(&gz), plain);
    assert_eq!(gunzip(&q), plain);
    assert!(gz.len() < plain.len() / 2, "gzip {} vs plain {}", gz.len(), plain.len());
    eprintln!("depth.npy of the cube (start view): {} bytes plain, {} gzip (level 1)", plain.len(), gz.len());
    // JSON routes too, when large enough; small ones and images go out as they are.
    let (_, h, body) = exchange(
        &mut sock,
        "GET /v1/candidate-sets/tammes-360 HTTP/1.1\r\nHost: o\r\nAccept-Encoding: gzip\r\n\r\n",
    );
    assert_eq!(header(&h, "content-encoding"), Some("gzip"));
    assert_eq!(
        serde_json::from_slice::<Value>(&gunzip(&body)).unwrap()["poses"].as_array().unwrap().len(),
        360
    );
    let (_, h, body) =
        exchange(&mut sock, "GET /v1/health HTTP/1.1\r\nHost: o\r\nAccept-Encoding: gzip\r\n\r\n");
    assert_eq!(
        (header(&h, "content-encoding"), serde_json::from_slice::<Value>(&body).unwrap()["status"].as_str()),
        (None, Some("ok"))
    );
    let png = ep_path(&id, "/observation/rgb.png");
    let (_, h, body) =
        exchange(&mut sock, &format!("GET {png} HTTP/1.1\r\nHost: o\r\nAccept-Encoding: gzip\r\n\r\n"));
    assert_eq!((header(&h, "content-encoding"), &body[1..4]), (None, &b"PNG"[..]));
    assert_eq!(s.state.connections.admitted() - admitted, 1, "still one connection");

    // The Rust client asks for gzip, decodes it, and keeps its connection alive.
    let rc = client(&s);
    let admitted = s.state.connections.admitted();
    let r = rc.raw("GET", &depth_path, None).unwrap();
    assert_eq!(r.body, plain, "decoded byte for byte");
    let values = rc.depth(&id, 0).unwrap();
    let mut npy = objview_geom::npy::npy_header("<f4", &[512, 512]);
    values.iter().for_each(|v| npy.extend_from_slice(&v.to_le_bytes()));
    assert_eq!(npy, plain);
    for _ in 0..5 {
        assert_eq!(rc.health().unwrap()["status"], "ok");
        assert_eq!(rc.depth(&id, 0).unwrap(), values);
    }
    assert_eq!(s.state.connections.admitted() - admitted, 1, "the Rust client reuses its connection");
}

#[test]
fn the_rust_client_sends_accept_encoding_gzip_and_decodes_the_answer() {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let body = json!({"status": "ok", "padding": "x".repeat(4000)}).to_string();
    let packed = objview_server::compress::gzip_bytes(body.as_bytes()).unwrap();
    let server = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut head = Vec::new();
        let mut byte = [0u8; 1];
        while !head.ends_with(b"\r\n\r\n") {
            s.read_exact(&mut byte).unwrap();
            head.push(byte[0]);
        }
        let answer = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Encoding: gzip\r\nContent-Length: {}\r\n\r\n",
            packed.len()
        );
        s.write_all(answer.as_bytes()).unwrap();
        s.write_all(&packed).unwrap();
        String::from_utf8(head).unwrap().to_ascii_lowercase()
    });
    let c = objview_server::client::Client::new(&format!("http://{addr}"), None);
    let v = c.health().unwrap();
    assert_eq!(v["padding"].as_str().map(str::len), Some(4000));
    let head = server.join().unwrap();
    let accept =
        head.lines().find_map(|l| l.strip_prefix("accept-encoding:")).unwrap_or_else(|| panic!("{head}"));
    assert!(accept.split(',').any(|c| c.trim() == "gzip"), "{head}");
}

#[test]
fn depth_sizes_of_a_built_in_mug_plain_and_gzip() {
    use objview_geom::synth::{self, Detail};
    let mesh = synth::build("mug", Detail::DEFAULT).unwrap();
    let (mesh, _) = objview_geom::normalize::normalize(
        mesh,
        objview_geom::normalize::Normalization::Unit,
        std::path::Path::new("mug.obj"),
    )
    .unwrap();
    let pose = objview_views::start_pose(objview_geom::pose::VIEW_RADIUS);
    let cam = objview_render::Camera::new(pose, objview_render::Intrinsics::default());
    let depth = objview_render::render(&mesh, &cam).depth;
    let hits = depth.iter().filter(|d| **d > 0.0).count();
    assert!(hits > 1000, "the mug is in view: {hits} pixels");
    let plain = objview_server::api::depth_npy(&depth);
    let t = Instant::now();
    let gz = objview_server::compress::gzip_bytes(&plain).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    assert_eq!(gunzip(&gz), plain);
    assert!(gz.len() < plain.len(), "gzip {} vs plain {}", gz.len(), plain.len());
    eprintln!(
        "depth.npy of the mug (start view, {hits} object pixels): {} bytes plain, {} gzip (level 1, {ms:.1} ms)",
        plain.len(),
        gz.len()
    );
}
