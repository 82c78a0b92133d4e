//! `GET /openapi.json`: the OpenAPI 3.0 description of every route, written by hand to agree
//! with docs/server-api.md (a test checks that every route of the router is described). gzip
//! (docs/server-api.md, "Compression") is HTTP's own negotiation and is not described per route.

use objview_episode::{ExecutionMode, Family, StopReason};
use serde_json::{json, Value};

fn err_ref() -> Value {
    json!({"$ref": "#/components/responses/Error"})
}

fn errors(codes: &[&str]) -> serde_json::Map<String, Value> {
    codes.iter().map(|c| (c.to_string(), err_ref())).collect()
}

fn json_body(schema: Value) -> Value {
    json!({"required": true, "content": {"application/json": {"schema": schema}}})
}

fn ok(description: &str, schema: Value) -> Value {
    json!({"description": description, "content": {"application/json": {"schema": schema}}})
}

fn id_param() -> Value {
    json!({"name": "id", "in": "path", "required": true, "schema": {"type": "string"}})
}

fn step_param() -> Value {
    json!({"name": "step", "in": "query", "required": false, "schema": {"type": "integer", "minimum": 0},
           "description": "the step the client expects; another step gives 409 stale_step"})
}

fn op(
    summary: &str,
    params: Vec<Value>,
    body: Option<Value>,
    success: (&str, Value),
    errs: &[&str],
) -> Value {
    let mut responses = errors(errs);
    responses.insert(success.0.to_string(), success.1);
    let mut o = json!({"summary": summary, "parameters": params, "responses": responses});
    if let Some(b) = body {
        o["requestBody"] = b;
    }
    o
}

/// The OpenAPI document.
pub fn document() -> Value {
    let pose = json!({"$ref": "#/components/schemas/Pose"});
    let obs = json!({"$ref": "#/components/schemas/Observation"});
    let any = json!({"type": "object"});
    let auth = ["401"];
    let ep_errs = ["401", "404"];
    json!({
        "openapi": "3.0.3",
        "info": {
            "title": "objview evaluation server",
            "version": objview_runs::record::VERSION,
            "description": "Online view-planning episodes (SPEC §5) on hidden objects. See docs/server-api.md.",
        },
        "components": {
            "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}},
            "schemas": {
                "Pose": {"type": "array", "items": {"type": "number"}, "minItems": 7, "maxItems": 7,
                         "description": "[cx, cy, cz, lx, ly, lz, roll]: camera centre and look-at point in the object frame (normalized units, each within 100 of the origin), roll in radians; finite numbers"},
                "Terminal": {"type": "object", "nullable": true, "properties": {
                    "source": {"type": "string", "enum": ["algorithm_stop", "benchmark", "exception"]},
                    "reason": {"type": "string"}, "detail": {"type": "string"}}},
                "Observation": {"type": "object", "required": ["step", "pose", "done", "terminal"], "properties": {
                    "step": {"type": "integer"}, "pose": pose, "intrinsics": {"type": "object"}, "done": {"type": "boolean"},
                    "terminal": {"$ref": "#/components/schemas/Terminal"}}},
                "Action": {"oneOf": [
                    {"type": "object", "required": ["type", "pose"], "properties": {
                        "type": {"type": "string", "enum": ["move"]}, "pose": pose}},
                    {"type": "object", "required": ["type", "reason"], "properties": {
                        "type": {"type": "string", "enum": ["stop"]},
                        "reason": {"type": "string", "enum": StopReason::ALL}}}]},
                "CreateEpisode": {"type": "object", "required": ["split", "object", "view_space", "budget", "method"], "properties": {
                    "split": {"type": "string"},
                    "object": {"oneOf": [{"type": "integer", "minimum": 0}, {"type": "string"}]},
                    "view_space": {"type": "string", "enum": crate::protocol::VIEW_SPACES},
                    "budget": {"oneOf": [{"type": "string"}, {"type": "integer", "minimum": 1}], "description": "\"auto\" or K"},
                    "method": {"type": "string", "pattern": "^[A-Za-z0-9._+-]{1,100}$"},
                    "family": {"type": "string", "enum": crate::protocol::FAMILIES, "default": Family::Classical},
                    "execution_mode": {"type": "string", "enum": ExecutionMode::ALL, "default": ExecutionMode::Iterative},
                    "candidate_set": {"type": "string", "enum": crate::protocol::CANDIDATE_SETS, "default": "tammes-360"},
                    "seed": {"type": "integer", "minimum": 0, "default": 0},
                    "params": {"default": {}},
                    "record_timings": {"type": "boolean", "default": true}}},
                "EpisodeSummary": {"type": "object", "required": ["episode_id", "split", "object", "method", "state", "step", "created_at"], "properties": {
                    "episode_id": {"type": "string"}, "split": {"type": "string"},
                    "object": {"type": "string", "description": "the object's uid, as the create answer's object_id"},
                    "method": {"type": "string"}, "state": {"type": "string", "enum": ["running", "finished"]},
                    "step": {"type": "integer", "minimum": 0, "description": "the current (running) or last (finished) observation's step"},
                    "created_at": {"type": "string", "format": "date-time", "description": "RFC 3339 UTC, e.g. 2025-01-31T12:00:00.123Z"}}},
                "Error": {"type": "object", "required": ["error"], "properties": {"error": {"type": "object",
                    "required": ["code", "message"], "properties": {"code": {"type": "string", "enum": [
                        "malformed_json", "invalid_request", "unauthorized", "not_found", "method_not_allowed",
                        "stale_step", "episode_finished", "episode_running", "payload_too_large", "request_timeout",
                        "too_many_episodes", "internal", "overloaded"]},
                        "message": {"type": "string"}}}}},
            },
            "responses": {"Error": {"description": "an error", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}},
        },
        "security": [{"bearer": []}],
        "paths": {
            "/openapi.json": {"get": op("this document", vec![], None, ("200", ok("OpenAPI 3.0", any.clone())), &[])},
            "/v1/health": {"get": {"summary": "liveness (no token needed)", "security": [],
                "responses": {"200": ok("status and version", json!({"type": "object", "properties": {
                    "status": {"type": "string"}, "version": {"type": "string"}}}))}}},
            "/v1/splits": {"get": op("the splits", vec![], None, ("200", ok("{splits: [{id, objects, public}]}", any.clone())), &auth)},
            "/v1/splits/{split}": {"get": op("one split and its object uids",
                vec![json!({"name": "split", "in": "path", "required": true, "schema": {"type": "string"}})], None,
                ("200", ok("{id, objects, public, object_ids}", any.clone())), &ep_errs)},
            "/v1/view-spaces": {"get": op("view-space names", vec![], None, ("200", ok("{view_spaces}", any.clone())), &auth)},
            "/v1/candidate-sets": {"get": op("candidate-set names", vec![], None, ("200", ok("{candidate_sets}", any.clone())), &auth)},
            "/v1/candidate-sets/{name}": {"get": op("the poses of a candidate set (radius 3, look-at 0)",
                vec![json!({"name": "name", "in": "path", "required": true, "schema": {"type": "string"}})], None,
                ("200", ok("{name, poses}", any.clone())), &ep_errs)},
            "/v1/episodes": {"get": op("this token's episodes (every episode without tokens) in creation order: to find running ones left behind by a client and abort them",
                vec![json!({"name": "state", "in": "query", "required": false, "schema": {"type": "string", "enum": ["running", "finished"]},
                            "description": "only episodes in this state (another value: 422 invalid_request naming `state`)"}),
                     json!({"name": "method", "in": "query", "required": false, "schema": {"type": "string"},
                            "description": "only episodes of this method (percent-encoded)"})], None,
                ("200", ok("{episodes: [{episode_id, split, object, method, state, step, created_at}]}", json!({"type": "object",
                    "required": ["episodes"], "properties": {"episodes": {"type": "array", "items": {"$ref": "#/components/schemas/EpisodeSummary"}}}}))),
                &["401", "422"]),
                "post": op("create an episode (takes the start view)", vec![],
                Some(json_body(json!({"$ref": "#/components/schemas/CreateEpisode"}))),
                ("201", ok("{episode_id, object_id, split, view_space, budget, seed, candidate_set, start_pose, intrinsics, action_timeout_s, observation}", any.clone())),
                &["400", "401", "404", "408", "413", "422", "429", "500"])},
            "/v1/episodes/{id}": {"get": op("episode state (metrics only on public splits)", vec![id_param()], None,
                ("200", ok("{episode_id, object_id, split, view_space, budget, method, state, step, views, history, terminal}", any.clone())), &ep_errs)},
            "/v1/episodes/{id}/observation": {"get": op("the current observation's metadata", vec![id_param()], None,
                ("200", ok("OBS", obs.clone())), &["401", "404", "409"])},
            "/v1/episodes/{id}/observation/depth.npy": {"get": op("depth of the current view: NPY <f4 (512, 512), camera-frame z, 0 = no hit; header X-Objview-Step",
                vec![id_param(), step_param()], None,
                ("200", json!({"description": "NPY bytes", "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}})),
                &["401", "404", "409", "422"])},
            "/v1/episodes/{id}/observation/rgb.png": {"get": op("RGB8 PNG of the current view; header X-Objview-Step",
                vec![id_param(), step_param()], None,
                ("200", json!({"description": "PNG bytes", "content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}})),
                &["401", "404", "409", "422"])},
            "/v1/episodes/{id}/feasible": {"post": op("batch feasibility in the episode's view space (at most 4096 poses)", vec![id_param()],
                Some(json_body(json!({"type": "object", "required": ["poses"], "properties": {"poses": {"type": "array", "items": pose, "maxItems": 4096}}}))),
                ("200", ok("{feasible: [bool]}", any.clone())), &["400", "401", "404", "408", "413", "422"])},
            "/v1/episodes/{id}/actions": {"post": op("apply the action for the current step", vec![id_param()],
                Some(json_body(json!({"type": "object", "required": ["step", "action"], "properties": {
                    "step": {"type": "integer", "minimum": 0}, "action": {"$ref": "#/components/schemas/Action"}}}))),
                ("200", ok("{accepted: true, observation: OBS}; header Server-Timing: handler;dur=<ms>", any.clone())),
                &["400", "401", "404", "408", "409", "413", "422"])},
            "/v1/episodes/{id}/abort": {"post": op("end the episode now (the client's planner failed, or a client cleans up an episode it left running): exception / planner_error, terminal_detail = detail, views scored", vec![id_param()],
                Some(json_body(json!({"type": "object", "properties": {"detail": {"type": "string"}}}))),
                ("200", ok("{accepted: true, observation: OBS}", any.clone())), &["400", "401", "404", "408", "409", "413", "422"])},
            "/v1/episodes/{id}/result": {"get": op("the result line (objview run format) after the end", vec![id_param()], None,
                ("200", ok("one objview run result object", any.clone())), &["401", "404", "409"])},
            "/v1/methods": {"get": op("methods with finished results", vec![], None, ("200", ok("{methods: [{method, finished}]}", any.clone())), &auth)},
            "/v1/methods/{method}/results": {"get": op("every finished result of a method, one line per finished episode in finish order (re-runs and aborted runs included: no deduplication; objview report applies its duplicate rule)",
                vec![json!({"name": "method", "in": "path", "required": true, "schema": {"type": "string"}})], None,
                ("200", json!({"description": "JSON Lines", "content": {"application/x-ndjson": {"schema": {"type": "string"}}}})), &ep_errs)},
        },
    })
}
