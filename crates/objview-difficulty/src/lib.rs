//! Pure-math core of the difficulty annotation of SPEC §4 (paper §3).
//!
//! This crate holds everything of the difficulty pipeline that does not need geometry, so that it
//! can be tested exhaustively against independently derived values:
//!
//! - [`grid`]: the saturation grid of view-set sizes N.
//! - [`normal`]: the standard normal density φ, CDF Φ and inverse Φ⁻¹ to near machine precision.
//! - [`mod@saturation`]: running maximum, lognormal-CDF fit, saturation point N*, d_sat and r_vis.
//! - [`setcover`]: the combinatorial part of d_plan: cover instances from per-view bitsets,
//!   optimum-preserving reductions, the deterministic greedy cover and exact solvers for small
//!   instances (the test oracle for the ILP).
//! - [`search`]: exact minimum cover by iterative-deepening search over 128-bit view masks (fast
//!   on the planning protocol's 128 views).
//! - [`ilp`]: the exact d_plan — reductions, LP bound, the combinatorial search and the set-cover
//!   ILP solved to proven optimality with HiGHS, with an honest time-limit status.
//! - [`warm`]: HiGHS integer solves from a warm start whose returned solution is checked
//!   against the reported objective (shared with the planners' exact solvers).
//!
//! Every constant is a named default collected in a settings struct that outputs record.

pub mod error;
pub mod grid;
pub mod ilp;
pub mod normal;
pub mod saturation;
pub mod search;
pub mod setcover;
pub mod warm;

pub use error::DifficultyError;
pub use grid::{SATURATION_GRID, SATURATION_N_MAX, SATURATION_N_MIN};
pub use ilp::{
    solve_min_cover, CoverMethod, CoverResult, CoverSettings, CoverStatus, ReductionStats,
    DEFAULT_RANDOM_SEED, DEFAULT_TIME_LIMIT_S,
};
pub use normal::{norm_cdf, norm_inv_cdf, norm_pdf, norm_sf};
pub use saturation::{
    curve_on_grid, fit_lognormal, running_max, saturation, saturation_point, CurvePoint, LognormalFit,
    Saturation, SaturationSettings, BISECTION_STEPS, MIN_SIGMA, PLATEAU_STEP, PLATEAU_TOL, PROBE_SPAN,
    PROBE_STRIDE, P_CLAMP, SLOW_SATURATION_THRESHOLD,
};
pub use search::{search_min_cover, SearchOutcome, SEARCH_MAX_VIEWS};
pub use setcover::{CoverInstance, ExactCover, Reduction, BRUTE_FORCE_MAX_VIEWS};
