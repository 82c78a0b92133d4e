//! Learned view planners and everything they share: the network input grid with OctoMap's
//! semantics ([`input_grid`]), oracle training data from per-view visible voxel sets
//! ([`rollout`], [`sampling`], [`dataset`], written as NumPy [`npz`] shards), the Burn models
//! ([`nbvnet`], [`mascvp`]), their training loops ([`train`], [`mascvp_train`]) and the planners
//! in episodes ([`planner`], [`mascvp_planner`], with this crate's registry [`TABLE`]).
//!
//! Why a crate of its own: Burn is a large dependency; the geometry, episode and server crates
//! never compile it. The CLI combines this crate's [`TABLE`] with the classical planners'.
//!
//! Data flow: pool → `learn dataset` (NPZ + manifest) → `learn train` (weights + sidecar JSON)
//! → planners `nbv-net` and `ma-scvp` (`weights=FILE`, default the shipped
//! `data/weights/{nbv-net,ma-scvp}.*`).
//!
//! The hybrid planners' learned completion backend `net` lives here too (it needs Burn):
//! `learn dataset --method completion` ([`completion_data`]) → `learn train completion`
//! ([`completion_train`], the network of [`completion_net`]) → [`completion_backend`], whose
//! [`completion_backend::HYBRID_TABLE`] rows replace `objview-planners`' hybrid rows in the CLI
//! (`completion=net`, `completion_weights=FILE`).

pub mod bench;
pub mod checkpoint;
pub mod completion_backend;
pub mod completion_data;
pub mod completion_net;
pub mod completion_train;
pub mod dataset;
pub mod experiment;
pub mod input_grid;
pub mod mascvp;
pub mod mascvp_planner;
pub mod mascvp_train;
pub mod nbvnet;
pub mod npz;
pub mod planner;
pub mod rollout;
pub mod sampling;
pub mod train;

use std::path::{Path, PathBuf};

pub use planner::TABLE;

/// objview's version, recorded in every output.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// An error of the learned-planner layer; messages are one line and name the file or setting.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// A file or folder could not be read or written.
    #[error("{path}: {reason}")]
    Io {
        /// The path.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
    /// A setting or input is invalid.
    #[error("{0}")]
    Invalid(String),
    /// Reading objects or annotation stages failed.
    #[error(transparent)]
    Dataset(#[from] Box<objview_dataset::DatasetError>),
    /// An NPZ file is unreadable or malformed.
    #[error(transparent)]
    Npz(#[from] npz::NpzError),
    /// The cover solver refused its settings.
    #[error(transparent)]
    Difficulty(#[from] objview_difficulty::DifficultyError),
}

impl From<objview_dataset::DatasetError> for LearnError {
    fn from(e: objview_dataset::DatasetError) -> Self {
        LearnError::Dataset(Box::new(e))
    }
}

impl LearnError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, e: impl std::fmt::Display) -> LearnError {
        LearnError::Io {
            path: path.to_path_buf(),
            reason: objview_geom::error::one_line(&e.to_string()).into_owned(),
        }
    }
}
