//! The classical view planners (SPEC §5, paper Table 1), each a [`objview_episode::Planner`]:
//!
//! - [`random`]: a uniformly random feasible candidate per step (sanity baseline).
//! - [`oracle`]: greedy on the ground truth (diagnostics only).
//! - [`random_tsp`]: K random feasible candidates visited along the exact shortest open path
//!   ([`tsp`]).
//! - [`rse`]: rear-side entropy (Delmerico et al. 2018) and its movement-aware variant
//!   RSE-Mov, on a probabilistic occupancy grid ([`occupancy`]).
//!
//! - [`hybrid`]: completion + NBV / set cover / max coverage (`completion-nbv`,
//!   `completion-scp`, `completion-mcp`; family hybrid), with the `identity` and `oracle`
//!   completion backends.
//!
//! [`registry`] knows them by name: one row per planner ([`registry::PlannerEntry`], next to
//! the planner), collected in [`registry::TABLE`].

pub mod hybrid;
pub mod occupancy;
pub mod oracle;
pub mod random;
pub mod random_tsp;
pub mod registry;
pub mod rse;
pub mod tsp;
