//! Typed requests: the body of `POST /v1/episodes` (docs/server-api.md) parsed and validated
//! against the pool into a [`CreateSpec`] — the split, object, view space, budget, method,
//! family, execution mode, candidate set, seed, parameters and timing switch of an episode —
//! which is what the server stores and replays after a restart. The rules of its fields (known
//! names, method names) live here; the names themselves in [`crate::protocol`].

use objview_episode::{Budget, ExecutionMode, Family};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::error::ApiError;
use crate::pool::{ObjectKey, Pool};
use crate::protocol::{CANDIDATE_SETS, FAMILIES, VIEW_SPACES};

/// A validated create request: everything needed to start the episode again (it is stored as
/// JSON, and replayed after a restart). The family, execution mode and budget are stored as
/// their wire strings (`learned`, `iterative`, `"5"` or `"auto"`), as they always were.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CreateSpec {
    /// The split id.
    pub split: String,
    /// The object's uid.
    pub object: String,
    /// The view space (one of [`VIEW_SPACES`]).
    pub view_space: String,
    /// `auto` or K.
    pub budget: Budget,
    /// The method name ([`valid_method_name`]).
    pub method: String,
    /// The declared family (one of [`FAMILIES`]).
    pub family: Family,
    /// The declared execution mode.
    pub execution_mode: ExecutionMode,
    /// The candidate set (one of [`CANDIDATE_SETS`]).
    pub candidate_set: String,
    /// The user seed.
    pub seed: u64,
    /// The planner's parameters (recorded in the result).
    pub params: Value,
    /// Whether the result records wall-clock times.
    pub record_timings: bool,
}

fn field<'a>(m: &'a serde_json::Map<String, Value>, name: &str) -> Option<&'a Value> {
    m.get(name).filter(|v| !v.is_null())
}

fn string_field(
    m: &serde_json::Map<String, Value>,
    name: &str,
    default: Option<&str>,
) -> Result<String, ApiError> {
    match field(m, name) {
        None => default
            .map(str::to_string)
            .ok_or_else(|| ApiError::InvalidRequest(format!("missing field `{name}`"))),
        Some(Value::String(s)) => Ok(s.clone()),
        Some(other) => Err(ApiError::InvalidRequest(format!("`{name}` must be a string, got {other}"))),
    }
}

/// The one of `allowed` whose wire name is `value`.
fn one_of<T: Copy + std::fmt::Display>(name: &str, value: String, allowed: &[T]) -> Result<T, ApiError> {
    allowed.iter().copied().find(|x| x.to_string() == value).ok_or_else(|| {
        ApiError::InvalidRequest(format!(
            "unknown {name} {value:?} (known: {})",
            objview_episode::vocab::wire_names(allowed)
        ))
    })
}

/// Whether `s` is a valid method name: 1–100 characters of `A-Z a-z 0-9 . _ + -`.
pub fn valid_method_name(s: &str) -> bool {
    (1..=100).contains(&s.len()) && s.chars().all(|c| c.is_ascii_alphanumeric() || "._+-".contains(c))
}

impl CreateSpec {
    /// Validates a create request body against the pool (docs/server-api.md, `POST
    /// /v1/episodes`): 422 for a wrong shape or an unknown split, view space, candidate set or
    /// budget; 404 for an unknown object.
    pub fn parse(body: &Value, pool: &Pool) -> Result<CreateSpec, ApiError> {
        let Value::Object(m) = body else {
            return Err(ApiError::InvalidRequest("the body must be a JSON object".into()));
        };
        let split_id = string_field(m, "split", None)?;
        let split = pool.split(&split_id).ok_or_else(|| {
            ApiError::InvalidRequest(format!(
                "unknown split {split_id:?} (splits: {})",
                pool.splits.iter().map(|s| s.id.as_str()).collect::<Vec<_>>().join(", ")
            ))
        })?;
        let key = match field(m, "object") {
            None => return Err(ApiError::InvalidRequest("missing field `object`".into())),
            Some(Value::String(s)) => ObjectKey::Uid(s.clone()),
            Some(Value::Number(n)) => match n.as_u64() {
                Some(i) => ObjectKey::Index(i as usize),
                None => {
                    return Err(ApiError::InvalidRequest(format!(
                        "`object` must be an index (a non-negative integer) or a uid, got {n}"
                    )))
                }
            },
            Some(other) => {
                return Err(ApiError::InvalidRequest(format!(
                    "`object` must be an index or a uid string, got {other}"
                )))
            }
        };
        let object = split
            .object(&key)
            .ok_or_else(|| {
                ApiError::NotFound(match &key {
                    ObjectKey::Index(i) => {
                        format!("split {split_id} has no object {i} (it has {})", split.objects.len())
                    }
                    ObjectKey::Uid(u) => format!("split {split_id} has no object {u:?}"),
                })
            })?
            .uid
            .clone();
        let view_space =
            one_of("view space", string_field(m, "view_space", None)?, &VIEW_SPACES)?.to_string();
        let budget = match field(m, "budget") {
            None => return Err(ApiError::InvalidRequest("missing field `budget`".into())),
            Some(Value::String(s)) => Budget::parse(s),
            Some(Value::Number(n)) => Budget::parse(&n.to_string()),
            Some(other) => Err(format!("got {other}")),
        }
        .map_err(|e| {
            ApiError::InvalidRequest(format!("`budget` must be \"auto\" or a positive integer: {e}"))
        })?;
        let method = string_field(m, "method", None)?;
        if !valid_method_name(&method) {
            return Err(ApiError::InvalidRequest(format!(
                "`method` must be 1–100 characters of A-Z a-z 0-9 . _ + -, got {method:?}"
            )));
        }
        let family = string_field(m, "family", Some(Family::Classical.as_str()))?;
        if family == Family::Oracle.as_str() {
            return Err(ApiError::InvalidRequest(
                "family `oracle` is refused: a remote planner never reads ground truth".into(),
            ));
        }
        let family = one_of("family", family, &FAMILIES)?;
        let execution_mode = one_of(
            "execution_mode",
            string_field(m, "execution_mode", Some(ExecutionMode::Iterative.as_str()))?,
            &ExecutionMode::ALL,
        )?;
        if execution_mode == ExecutionMode::BudgetedPlan && budget == Budget::Auto {
            return Err(ApiError::InvalidRequest(
                "a budgeted_plan needs a fixed budget K, not \"auto\"".into(),
            ));
        }
        let candidate_set =
            one_of("candidate set", string_field(m, "candidate_set", Some("tammes-360"))?, &CANDIDATE_SETS)?
                .to_string();
        let seed = match field(m, "seed") {
            None => 0,
            Some(v) => v.as_u64().ok_or_else(|| {
                ApiError::InvalidRequest(format!("`seed` must be a non-negative integer, got {v}"))
            })?,
        };
        let params = field(m, "params").cloned().unwrap_or_else(|| json!({}));
        let record_timings = match field(m, "record_timings") {
            None => true,
            Some(Value::Bool(b)) => *b,
            Some(other) => {
                return Err(ApiError::InvalidRequest(format!(
                    "`record_timings` must be true or false, got {other}"
                )))
            }
        };
        Ok(CreateSpec {
            split: split_id,
            object,
            view_space,
            budget,
            method,
            family,
            execution_mode,
            candidate_set,
            seed,
            params,
            record_timings,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn method_names() {
        for ok in ["my-nbv", "rse", "a.b_c+d-1", &"x".repeat(100)] {
            assert!(valid_method_name(ok), "{ok}");
        }
        for bad in ["", "a/b", "a b", "é", &"x".repeat(101)] {
            assert!(!valid_method_name(bad), "{bad}");
        }
    }
}
