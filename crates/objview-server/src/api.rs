//! The routes of docs/server-api.md (v1). Handlers parse and validate the request, then run the
//! episode operation of [`crate::state`] on tokio's blocking pool (engine work is CPU-bound).
//! Every error is `{"error": {"code", "message"}}` with the contract's status, including unknown
//! routes (404), wrong methods (405), bodies over [`BODY_LIMIT`] (413) and bodies slower than
//! the body time limit (408).

use std::sync::Arc;
use std::time::Instant;

use axum::body::Bytes;
use axum::extract::{FromRequest, FromRequestParts, Request, State};
use axum::http::header::{HeaderName, HeaderValue, CONTENT_TYPE};
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use objview_geom::Pose;
use serde_json::{json, Value};

use crate::auth::Caller;
use crate::error::ApiError;
use crate::protocol::{
    BODY_LIMIT, CANDIDATE_SETS, DRAIN_LIMIT, MAX_FEASIBLE_POSES, STEP_HEADER, VIEW_SPACES,
};
use crate::request::CreateSpec;
use crate::state::{AppState, EpisodeState, Slot};

/// The router of the whole API over `state`.
pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/openapi.json", get(openapi))
        .route("/v1/health", get(health))
        .route("/v1/splits", get(splits))
        .route("/v1/splits/{split}", get(split))
        .route("/v1/view-spaces", get(view_spaces))
        .route("/v1/candidate-sets", get(candidate_sets))
        .route("/v1/candidate-sets/{name}", get(candidate_set))
        .route("/v1/episodes", get(list_episodes).post(create))
        .route("/v1/episodes/{id}", get(episode))
        .route("/v1/episodes/{id}/observation", get(observation))
        .route("/v1/episodes/{id}/observation/depth.npy", get(depth))
        .route("/v1/episodes/{id}/observation/rgb.png", get(rgb))
        .route("/v1/episodes/{id}/feasible", post(feasible))
        .route("/v1/episodes/{id}/actions", post(act))
        .route("/v1/episodes/{id}/abort", post(abort))
        .route("/v1/episodes/{id}/result", get(result))
        .route("/v1/methods", get(methods))
        .route("/v1/methods/{method}/results", get(method_results))
        .fallback(unknown_route)
        .method_not_allowed_fallback(wrong_method)
        .layer(axum::middleware::from_fn(crate::compress::gzip))
        .with_state(state)
}

async fn unknown_route(req: Request) -> ApiError {
    ApiError::NotFound(format!("no route {}", req.uri().path()))
}

async fn wrong_method(req: Request) -> ApiError {
    ApiError::MethodNotAllowed(format!("{} is not allowed on {}", req.method(), req.uri().path()))
}

/// A JSON request body: 413 over the limit, 408 when it does not arrive within the body time
/// limit, 400 when it is not JSON, 422 for a number out of range ([`parse_body`]).
struct Body(Value);

impl FromRequest<Arc<AppState>> for Body {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &Arc<AppState>) -> Result<Body, ApiError> {
        let limit = state.limits.body_timeout;
        // While the body arrives, the connection may be closed to make room for another.
        let receiving = req.extensions().get::<crate::conn::ConnHandle>().map(|c| c.receiving_body());
        let read = tokio::time::timeout(limit, read_limited(req)).await;
        drop(receiving);
        let bytes = read.map_err(|_| {
            ApiError::RequestTimeout(format!(
                "the body did not arrive within {} s (--body-timeout)",
                limit.as_secs_f64()
            ))
        })??;
        parse_body(&bytes).map(Body)
    }
}

/// Reads a request body of at most [`BODY_LIMIT`] bytes. A longer one is 413; it is read on
/// and discarded up to [`DRAIN_LIMIT`] first (so a client still writing it is not cut off
/// before it can read the answer), unless its announced length is beyond that already.
async fn read_limited(req: Request) -> Result<Bytes, ApiError> {
    use hyper::body::Body as _;
    let too_large = || ApiError::PayloadTooLarge(format!("the body is over the limit of {BODY_LIMIT} bytes"));
    let announced = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if announced.is_some_and(|n| n > DRAIN_LIMIT as u64) {
        return Err(too_large());
    }
    let mut body = req.into_body();
    let mut kept: Vec<u8> = Vec::new();
    let mut seen = 0usize;
    loop {
        let frame = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await;
        let Some(frame) = frame else { break };
        let frame = frame.map_err(|e| ApiError::MalformedJson(format!("the body could not be read: {e}")))?;
        let Ok(data) = frame.into_data() else { continue };
        seen = seen.saturating_add(data.len());
        if seen > DRAIN_LIMIT {
            return Err(too_large());
        }
        if seen <= BODY_LIMIT {
            kept.extend_from_slice(&data);
        }
    }
    if seen > BODY_LIMIT {
        return Err(too_large());
    }
    Ok(Bytes::from(kept))
}

/// Whether a parse error is serde_json's "number out of range": JSON syntax that is fine, with a
/// number beyond f64 (`1e400`). serde_json files it as a syntax error and exposes no code for it,
/// only its message (pinned by a test).
fn number_out_of_range(e: &serde_json::Error) -> bool {
    e.classify() == serde_json::error::Category::Syntax && e.to_string().starts_with("number out of range")
}

/// Parses a request body. Not JSON → 400 `malformed_json`; valid JSON with a number out of the
/// f64 range → 422 `invalid_request` naming where it is (`action.pose[0]`), like any other value
/// of the wrong kind.
pub fn parse_body(bytes: &[u8]) -> Result<Value, ApiError> {
    match serde_json::from_slice(bytes) {
        Ok(v) => Ok(v),
        // Out of range, but otherwise JSON (checking syntax only does not convert numbers).
        Err(e)
            if number_out_of_range(&e) && serde_json::from_slice::<serde::de::IgnoredAny>(bytes).is_ok() =>
        {
            // Again, tracking the path, to name the field.
            let mut de = serde_json::Deserializer::from_slice(bytes);
            let at = match serde_path_to_error::deserialize::<_, Value>(&mut de) {
                Err(p) => p.path().to_string(),
                Ok(_) => ".".to_string(),
            };
            Err(ApiError::InvalidRequest(format!(
                "`{at}`: a number out of range (a pose or any number must be a finite 64-bit float): {e}"
            )))
        }
        Err(e) => Err(ApiError::MalformedJson(format!("the body is not JSON: {e}"))),
    }
}

/// The last path segment parameter (an episode id, split, set or method name), as a string.
struct Param(String);

impl<S: Send + Sync> FromRequestParts<S> for Param {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Param, ApiError> {
        axum::extract::Path::<String>::from_request_parts(parts, state)
            .await
            .map(|p| Param(p.0))
            .map_err(|e| ApiError::NotFound(format!("bad path: {e}")))
    }
}

/// `?step=N`, if given.
fn step_query(parts: &axum::http::Uri) -> Result<Option<u64>, ApiError> {
    let Some(q) = parts.query() else { return Ok(None) };
    let mut step = None;
    for pair in q.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        if k == "step" {
            step = Some(v.parse::<u64>().map_err(|_| {
                ApiError::InvalidRequest(format!("`step` must be a non-negative integer, got {v:?}"))
            })?);
        }
    }
    Ok(step)
}

/// Decodes one query-string component: `%XX` escapes (UTF-8); `+` stays `+` (method names may
/// hold it, and none holds a space). `None` for a broken escape or bytes that are not UTF-8.
fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The filters of `GET /v1/episodes`: `?state=running|finished` and `?method=NAME`, each at
/// most once; any other parameter, a repeated one or an unknown state is 422 naming it.
pub fn list_query(query: Option<&str>) -> Result<(Option<EpisodeState>, Option<String>), ApiError> {
    let (mut state, mut method) = (None, None);
    for pair in query.unwrap_or("").split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let key = percent_decode(k).unwrap_or_else(|| k.to_string());
        let value = percent_decode(v).ok_or_else(|| {
            ApiError::InvalidRequest(format!("`{key}` is not a valid percent-encoded value: {v:?}"))
        })?;
        let twice = || ApiError::InvalidRequest(format!("`{key}` is given more than once"));
        match key.as_str() {
            "state" => {
                let s = EpisodeState::parse(&value).ok_or_else(|| {
                    ApiError::InvalidRequest(format!(
                        "`state` must be `running` or `finished`, got {value:?}"
                    ))
                })?;
                if state.replace(s).is_some() {
                    return Err(twice());
                }
            }
            "method" => {
                if value.is_empty() {
                    return Err(ApiError::InvalidRequest("`method` is empty".into()));
                }
                if method.replace(value).is_some() {
                    return Err(twice());
                }
            }
            _ => {
                return Err(ApiError::InvalidRequest(format!(
                    "unknown query parameter `{key}` (known: `state`, `method`)"
                )))
            }
        }
    }
    Ok((state, method))
}

/// Runs engine work off the async executor, on an engine lane in its turn ([`crate::lanes`]).
async fn engine<T: Send + 'static>(
    st: &Arc<AppState>,
    f: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    st.engine_lanes
        .run(f)
        .await
        .unwrap_or_else(|e| Err(ApiError::Internal(format!("the request failed: {e}"))))
}

/// Runs blocking episode work off the async executor.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .unwrap_or_else(|e| Err(ApiError::Internal(format!("the request failed: {e}"))))
}

async fn openapi() -> Json<Value> {
    Json(crate::openapi::document())
}

async fn health() -> Json<Value> {
    Json(json!({"status": "ok", "version": objview_runs::record::VERSION}))
}

async fn splits(State(st): State<Arc<AppState>>, _c: Caller) -> Json<Value> {
    let list: Vec<Value> = st
        .pool
        .splits
        .iter()
        .map(|s| json!({"id": s.id, "objects": s.objects.len(), "public": s.public}))
        .collect();
    Json(json!({ "splits": list }))
}

async fn split(
    State(st): State<Arc<AppState>>,
    _c: Caller,
    Param(id): Param,
) -> Result<Json<Value>, ApiError> {
    let s = st.pool.split(&id).ok_or_else(|| ApiError::NotFound(format!("no split {id:?}")))?;
    let ids: Vec<&str> = s.objects.iter().map(|o| o.uid.as_str()).collect();
    Ok(Json(json!({"id": s.id, "objects": ids.len(), "public": s.public, "object_ids": ids})))
}

async fn view_spaces(_c: Caller) -> Json<Value> {
    Json(json!({ "view_spaces": VIEW_SPACES }))
}

async fn candidate_sets(_c: Caller) -> Json<Value> {
    Json(json!({ "candidate_sets": CANDIDATE_SETS }))
}

async fn candidate_set(
    State(st): State<Arc<AppState>>,
    _c: Caller,
    Param(name): Param,
) -> Result<Json<Value>, ApiError> {
    let poses = st.candidate_set(&name).ok_or_else(|| {
        ApiError::NotFound(format!("no candidate set {name:?} (known: {})", CANDIDATE_SETS.join(", ")))
    })?;
    let poses: Vec<[f64; 7]> = poses.iter().map(|p| p.to_array()).collect();
    Ok(Json(json!({"name": name, "poses": poses})))
}

async fn create(State(st): State<Arc<AppState>>, c: Caller, Body(body): Body) -> Result<Response, ApiError> {
    let spec = CreateSpec::parse(&body, &st.pool)?;
    // A full server answers at once, before any scene or engine work (the place itself is
    // taken inside `create`, under the same check).
    st.check_running(&c.owner)?;
    // The prepared scene first, outside the engine queue: a scene being built (seconds, once per
    // object) keeps no engine lane from the steps of running episodes, and concurrent creates
    // of one object wait for that one build on the blocking pool, not in the engine's queue.
    let (s2, spec2) = (st.clone(), spec.clone());
    let scene = blocking(move || s2.scene_for(&spec2)).await?;
    let queue = st.clone();
    let v = engine(&queue, move || st.create(&c.owner, spec, scene)).await?;
    Ok((StatusCode::CREATED, Json(v)).into_response())
}

async fn list_episodes(
    State(st): State<Arc<AppState>>,
    c: Caller,
    uri: axum::http::Uri,
) -> Result<Json<Value>, ApiError> {
    let (state, method) = list_query(uri.query())?;
    let list = blocking(move || st.list(&c.owner, state, method.as_deref())).await?;
    Ok(Json(json!({ "episodes": list })))
}

async fn slot_of(st: &Arc<AppState>, c: &Caller, id: &str) -> Result<Arc<Slot>, ApiError> {
    st.slot(&c.owner, id)
}

async fn episode(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
) -> Result<Json<Value>, ApiError> {
    let slot = slot_of(&st, &c, &id).await?;
    // Only a public split's info may need the engine (its running metrics).
    if st.pool.split(&slot.spec.split).is_some_and(|s| s.public) {
        let queue = st.clone();
        Ok(Json(engine(&queue, move || st.info(&slot)).await?))
    } else {
        Ok(Json(blocking(move || st.info(&slot)).await?))
    }
}

async fn observation(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
) -> Result<Json<Value>, ApiError> {
    let slot = slot_of(&st, &c, &id).await?;
    Ok(Json(blocking(move || st.observation(&slot)).await?))
}

fn step_header(step: usize) -> (HeaderName, HeaderValue) {
    (HeaderName::from_static(STEP_HEADER), HeaderValue::from(step as u64))
}

async fn depth(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
    uri: axum::http::Uri,
) -> Result<Response, ApiError> {
    let want = step_query(&uri)?;
    let slot = slot_of(&st, &c, &id).await?;
    let (step, depth) = blocking(move || st.depth(&slot, want)).await?;
    let bytes = depth_npy(&depth);
    let mut h = HeaderMap::new();
    h.insert(CONTENT_TYPE, HeaderValue::from_static("application/octet-stream"));
    let (k, v) = step_header(step);
    h.insert(k, v);
    Ok((h, bytes).into_response())
}

/// The body of `depth.npy`: NPY `<f4`, (side, side) for a square image (else (1, n)).
pub fn depth_npy(depth: &[f32]) -> Vec<u8> {
    let side = (depth.len() as f64).sqrt() as usize;
    let shape = if side * side == depth.len() { [side, side] } else { [1, depth.len()] };
    let mut bytes = objview_geom::npy::npy_header("<f4", &shape);
    bytes.reserve(depth.len() * 4);
    for d in depth {
        bytes.extend_from_slice(&d.to_le_bytes());
    }
    bytes
}

async fn rgb(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
    uri: axum::http::Uri,
) -> Result<Response, ApiError> {
    let want = step_query(&uri)?;
    let slot = slot_of(&st, &c, &id).await?;
    let queue = st.clone();
    let (step, png) = engine(&queue, move || {
        let (step, w, h, px) = st.rgb(&slot, want)?;
        let flat: Vec<u8> = px.iter().flat_map(|p| p.iter().copied()).collect();
        let img =
            image::RgbImage::from_raw(w, h, flat).ok_or_else(|| ApiError::Internal("image size".into()))?;
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .map_err(|e| ApiError::Internal(format!("encoding the PNG: {e}")))?;
        Ok((step, png))
    })
    .await?;
    let mut h = HeaderMap::new();
    h.insert(CONTENT_TYPE, HeaderValue::from_static("image/png"));
    let (k, v) = step_header(step);
    h.insert(k, v);
    Ok((h, png).into_response())
}

/// Pose `i` of a feasibility query: 7 numbers that pass [`objview_episode::check_pose`]
/// (finite, centre and look-at within the bound).
fn parse_pose(i: usize, v: &Value) -> Result<Pose, ApiError> {
    let a = v
        .as_array()
        .filter(|a| a.len() == 7)
        .ok_or_else(|| ApiError::InvalidRequest(format!("`poses[{i}]` is not 7 finite numbers: {v}")))?;
    let mut out = [0.0; 7];
    for (j, (o, x)) in out.iter_mut().zip(a).enumerate() {
        *o = x.as_f64().ok_or_else(|| {
            ApiError::InvalidRequest(format!(
                "`poses[{i}][{j}]` is not a number: {x} (a pose is 7 finite numbers)"
            ))
        })?;
    }
    objview_episode::check_pose(&out).map_err(|e| ApiError::InvalidRequest(format!("`poses[{i}]`: {e}")))
}

async fn feasible(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
    Body(body): Body,
) -> Result<Json<Value>, ApiError> {
    let slot = slot_of(&st, &c, &id).await?;
    let list = body
        .get("poses")
        .and_then(Value::as_array)
        .ok_or_else(|| ApiError::InvalidRequest("the body must be {\"poses\": [[7 numbers], …]}".into()))?;
    if list.len() > MAX_FEASIBLE_POSES {
        return Err(ApiError::InvalidRequest(format!(
            "`poses` has {} poses; at most {MAX_FEASIBLE_POSES} per request",
            list.len()
        )));
    }
    let poses = list.iter().enumerate().map(|(i, p)| parse_pose(i, p)).collect::<Result<Vec<_>, _>>()?;
    let mask = st.feasible(&slot, &poses)?;
    Ok(Json(json!({ "feasible": mask })))
}

async fn act(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
    Body(body): Body,
) -> Result<Response, ApiError> {
    let received = Instant::now();
    let slot = slot_of(&st, &c, &id).await?;
    let Value::Object(m) = &body else {
        return Err(ApiError::InvalidRequest("the body must be {\"step\": N, \"action\": {…}}".into()));
    };
    let step = m
        .get("step")
        .and_then(Value::as_u64)
        .ok_or_else(|| ApiError::InvalidRequest("`step` must be a non-negative integer".into()))?;
    let action = match m.get("action") {
        Some(a @ Value::Object(_)) => a.clone(),
        Some(other) => {
            return Err(ApiError::InvalidRequest(format!("`action` must be a JSON object, got {other}")))
        }
        None => return Err(ApiError::InvalidRequest("missing field `action`".into())),
    };
    let _in_flight = crate::state::InFlight::new(slot.clone());
    let queue = st.clone();
    let obs = engine(&queue, move || st.act(&slot, step, &action, received)).await?;
    let mut h = HeaderMap::new();
    let ms = received.elapsed().as_secs_f64() * 1e3;
    if let Ok(v) = HeaderValue::from_str(&format!("handler;dur={ms:.3}")) {
        h.insert(HeaderName::from_static("server-timing"), v);
    }
    Ok((h, Json(json!({"accepted": true, "observation": obs}))).into_response())
}

async fn abort(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(id): Param,
    Body(body): Body,
) -> Result<Json<Value>, ApiError> {
    let slot = slot_of(&st, &c, &id).await?;
    let detail = match body.get("detail") {
        None | Some(Value::Null) => String::new(),
        Some(Value::String(s)) => s.clone(),
        Some(other) => {
            return Err(ApiError::InvalidRequest(format!("`detail` must be a string, got {other}")))
        }
    };
    let obs = blocking(move || st.abort(&slot, detail)).await?;
    Ok(Json(json!({"accepted": true, "observation": obs})))
}

async fn result(State(st): State<Arc<AppState>>, c: Caller, Param(id): Param) -> Result<Response, ApiError> {
    let slot = slot_of(&st, &c, &id).await?;
    let line = blocking(move || st.result(&slot)).await?;
    Ok(([(CONTENT_TYPE, "application/json")], line).into_response())
}

async fn methods(State(st): State<Arc<AppState>>, c: Caller) -> Result<Json<Value>, ApiError> {
    let rows = blocking(move || {
        st.db.methods(&c.owner).map_err(|e| ApiError::Internal(format!("reading results: {e}")))
    })
    .await?;
    let list: Vec<Value> = rows.into_iter().map(|(m, n)| json!({"method": m, "finished": n})).collect();
    Ok(Json(json!({ "methods": list })))
}

async fn method_results(
    State(st): State<Arc<AppState>>,
    c: Caller,
    Param(method): Param,
) -> Result<Response, ApiError> {
    let m = method.clone();
    let lines = blocking(move || {
        st.db
            .results(Some(&c.owner), Some(&m))
            .map_err(|e| ApiError::Internal(format!("reading results: {e}")))
    })
    .await?;
    if lines.is_empty() {
        return Err(ApiError::NotFound(format!("no finished results of method {method:?}")));
    }
    let mut body = String::new();
    for l in lines {
        body.push_str(&l);
        body.push('\n');
    }
    Ok(([(CONTENT_TYPE, "application/x-ndjson")], body).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_number_out_of_the_f64_range_is_a_422_naming_its_field() {
        let e = parse_body(br#"{"step": 0, "action": {"type": "move", "pose": [1e400, 0, 0, 0, 0, 0, 0]}}"#)
            .unwrap_err();
        assert_eq!(e.status(), StatusCode::UNPROCESSABLE_ENTITY, "{e}");
        assert!(e.to_string().starts_with("`action.pose[0]`: a number out of range"), "{e}");
        let e = parse_body(br#"{"poses": [[3, 0, 0, 0, 0, 0, 0], [3, 0, 0, 0, 0, -1e999, 0]]}"#).unwrap_err();
        assert!(e.to_string().starts_with("`poses[1][5]`:"), "{e}");
        let e = parse_body(b"1e400").unwrap_err();
        assert_eq!(e.code(), "invalid_request", "{e}");
    }

    #[test]
    fn what_is_not_json_stays_a_400() {
        let bad: [&[u8]; 6] = [b"{not json", b"", b"[1, 2", b"{\"a\": 1} x", b"1e", b"[1e400"];
        for bad in bad {
            let e = parse_body(bad).unwrap_err();
            assert_eq!(e.code(), "malformed_json", "{e}");
        }
        // Tiny numbers round to 0: not out of range.
        assert_eq!(parse_body(b"[1e-400]").unwrap(), json!([0.0]));
    }

    #[test]
    fn the_episode_list_takes_a_state_and_a_method_and_names_what_is_wrong() {
        assert_eq!(list_query(None).unwrap(), (None, None));
        assert_eq!(list_query(Some("")).unwrap(), (None, None));
        assert_eq!(list_query(Some("state=running")).unwrap(), (Some(EpisodeState::Running), None));
        assert_eq!(
            list_query(Some("method=my%2Bnbv.v2&state=finished")).unwrap(),
            (Some(EpisodeState::Finished), Some("my+nbv.v2".to_string()))
        );
        assert_eq!(list_query(Some("method=a+b")).unwrap().1.as_deref(), Some("a+b"));
        let err = |q: &str| {
            let e = list_query(Some(q)).unwrap_err();
            assert_eq!(e.status(), StatusCode::UNPROCESSABLE_ENTITY, "{q}: {e}");
            e.to_string()
        };
        assert_eq!(err("state=done"), "`state` must be `running` or `finished`, got \"done\"");
        assert_eq!(err("state="), "`state` must be `running` or `finished`, got \"\"");
        assert_eq!(err("state=running&state=finished"), "`state` is given more than once");
        assert_eq!(err("stat=running"), "unknown query parameter `stat` (known: `state`, `method`)");
        assert_eq!(err("method="), "`method` is empty");
        assert!(err("method=%zz").starts_with("`method` is not a valid percent-encoded value"));
        assert!(err("method=%ff").starts_with("`method` is not a valid"), "not UTF-8");
    }

    #[test]
    fn feasibility_poses_are_bounded_like_moves() {
        assert!(parse_pose(0, &json!([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])).is_ok());
        let e = parse_pose(2, &json!([1e300, 1e300, 1e300, 0.0, 0.0, 0.0, 0.0])).unwrap_err();
        assert_eq!(e.status(), StatusCode::UNPROCESSABLE_ENTITY);
        assert!(e.to_string().starts_with("`poses[2]`: the camera centre is 1.732e300 object units"), "{e}");
        let e = parse_pose(0, &json!([3.0, 0.0, 0.0, 0.0, "0", 0.0, 0.0])).unwrap_err();
        assert!(e.to_string().starts_with("`poses[0][4]` is not a number"), "{e}");
    }
}
