//! Errors: [`ApiError`] is what a request can fail with — each variant has its HTTP status and
//! wire code (docs/server-api.md) and renders as `{"error": {"code", "message"}}`; an error
//! response never changes an episode. [`ServerError`] is what starting a server can fail with.

use axum::http::header::{HeaderValue, CONNECTION};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde_json::json;

/// A failed request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApiError {
    /// 400 `malformed_json`: the body is not JSON.
    #[error("{0}")]
    MalformedJson(String),
    /// 422 `invalid_request`: JSON of the wrong shape or type, or an unknown name.
    #[error("{0}")]
    InvalidRequest(String),
    /// 401 `unauthorized`: token missing or unknown.
    #[error("{0}")]
    Unauthorized(String),
    /// 404 `not_found`: unknown route, episode, split, object or method.
    #[error("{0}")]
    NotFound(String),
    /// 405 `method_not_allowed`.
    #[error("{0}")]
    MethodNotAllowed(String),
    /// 409 `stale_step`: the action (or depth request) is not for the current step.
    #[error("{0}")]
    StaleStep(String),
    /// 409 `episode_finished`: an action or observation request after the end.
    #[error("{0}")]
    EpisodeFinished(String),
    /// 409 `episode_running`: the result was asked for before the end.
    #[error("{0}")]
    EpisodeRunning(String),
    /// 413 `payload_too_large`: the body is over the limit.
    #[error("{0}")]
    PayloadTooLarge(String),
    /// 408 `request_timeout`: the body did not arrive within the body time limit (the
    /// connection is closed after the answer).
    #[error("{0}")]
    RequestTimeout(String),
    /// 429 `too_many_episodes`: the server's cap on running episodes, in all or per token, is
    /// reached (each running episode holds its engine state in memory).
    #[error("{0}")]
    TooManyEpisodes(String),
    /// 503 `overloaded`: every connection the server keeps open is busy with a request (the
    /// connection is closed after the answer).
    #[error("{0}")]
    Overloaded(String),
    /// 500 `internal`: the server failed (an object that does not load, the database); the
    /// message never names files.
    #[error("{0}")]
    Internal(String),
}

impl ApiError {
    /// The HTTP status.
    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::MalformedJson(_) => StatusCode::BAD_REQUEST,
            ApiError::InvalidRequest(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::NotFound(_) => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed(_) => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::StaleStep(_) | ApiError::EpisodeFinished(_) | ApiError::EpisodeRunning(_) => {
                StatusCode::CONFLICT
            }
            ApiError::PayloadTooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::RequestTimeout(_) => StatusCode::REQUEST_TIMEOUT,
            ApiError::TooManyEpisodes(_) => StatusCode::TOO_MANY_REQUESTS,
            ApiError::Overloaded(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The wire code (`malformed_json`, …).
    pub fn code(&self) -> &'static str {
        match self {
            ApiError::MalformedJson(_) => "malformed_json",
            ApiError::InvalidRequest(_) => "invalid_request",
            ApiError::Unauthorized(_) => "unauthorized",
            ApiError::NotFound(_) => "not_found",
            ApiError::MethodNotAllowed(_) => "method_not_allowed",
            ApiError::StaleStep(_) => "stale_step",
            ApiError::EpisodeFinished(_) => "episode_finished",
            ApiError::EpisodeRunning(_) => "episode_running",
            ApiError::PayloadTooLarge(_) => "payload_too_large",
            ApiError::RequestTimeout(_) => "request_timeout",
            ApiError::TooManyEpisodes(_) => "too_many_episodes",
            ApiError::Overloaded(_) => "overloaded",
            ApiError::Internal(_) => "internal",
        }
    }

    /// The JSON body.
    pub fn body(&self) -> serde_json::Value {
        json!({"error": {"code": self.code(), "message": self.to_string()}})
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut r = (self.status(), axum::Json(self.body())).into_response();
        if matches!(self, ApiError::RequestTimeout(_) | ApiError::Overloaded(_)) {
            r.headers_mut().insert(CONNECTION, HeaderValue::from_static("close"));
        }
        r
    }
}

/// Starting or running a server failed.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// A split file (or its objects) could not be read.
    #[error("{0}")]
    Pool(String),
    /// The tokens file.
    #[error("{path}: {reason}")]
    Tokens {
        /// The tokens file.
        path: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The database.
    #[error("database {path}: {reason}")]
    Db {
        /// The database file.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// A bad setting (`--public` naming no split, a timeout that is not positive, …).
    #[error("{0}")]
    Config(String),
    /// Binding or serving.
    #[error("{0}")]
    Io(String),
    /// Recovering the episodes that were running when the server stopped.
    #[error("recovering episode {id}: {reason}")]
    Recovery {
        /// The episode id.
        id: String,
        /// What went wrong.
        reason: String,
    },
}
