//! The protocol's fixed vocabulary and limits (docs/server-api.md): the view spaces and
//! candidate sets a server offers, the families a remote planner may declare, and the size
//! limits of requests and the step header of observations. The routes ([`crate::api`]), the
//! create request ([`crate::request`]), the OpenAPI description ([`crate::openapi`]) and the
//! client ([`crate::client`]) all read them here.

use objview_episode::Family;

/// The view spaces a server offers (SPEC §5).
pub const VIEW_SPACES: [&str; 4] = ["whole", "hemi", "quarter", "eighth"];

/// The candidate sets a server hands out.
pub const CANDIDATE_SETS: [&str; 2] = ["tammes-128", "tammes-360"];

/// Families a remote planner may declare (`oracle` is refused: it reads ground truth).
pub const FAMILIES: [Family; 4] = [Family::Classical, Family::Learned, Family::Hybrid, Family::Baseline];

/// Most poses in one feasibility query.
pub const MAX_FEASIBLE_POSES: usize = 4_096;

/// The request body limit (1 MiB).
pub const BODY_LIMIT: usize = 1 << 20;

/// How much of an oversized body the server still reads (and discards) before it answers 413,
/// so that a client that writes its whole body before reading (most blocking HTTP clients do)
/// gets the 413 instead of a broken pipe. A body announced or sent beyond this is answered at
/// once and its connection closed.
pub const DRAIN_LIMIT: usize = 16 << 20;

/// The header that carries the step of a depth or RGB observation.
pub const STEP_HEADER: &str = "x-objview-step";
