//! Running objview over objects — the procedures the command line, the demo, the benchmarks,
//! the server and training-data generation share, so that none of them lives in a binary:
//!
//! - [`episodes`]: a batch of online episodes ([`episodes::EpisodePlan`]: planner, view space,
//!   budget, seed, objects, settings), resumable, with the same-run check.
//! - [`annotate`]: a batch of difficulty annotations ([`annotate::AnnotatePlan`]), resumable and
//!   shardable.
//! - [`pool`]: splits, statistics and Figure 2 from annotation files.
//! - [`demo`]: the main job on the built-in objects, stage by stage.
//! - [`record`]: the settings record every episode result carries (shared with the server);
//!   [`provenance`]: the settings block of every other output file.
//! - [`params`]: `NAME=VALUE` planner parameters; [`cache`]: cache locations.
//! - [`bench`]: the measurement procedures of `objview bench …` (episode step, annotation,
//!   rendering).
//!
//! The batch driver itself (worker pool, input-order output, typed progress events) is
//! [`objview_dataset::batch`]; each plan here makes its items and notes and hands them to it.

pub mod annotate;
pub mod bench;
pub mod cache;
pub mod demo;
pub mod episodes;
pub mod params;
pub mod pool;
pub mod provenance;
pub mod record;

pub use episodes::{EpisodePlan, PlannerFactory, RunSummary};
pub use params::{parse_params, Params};

/// Errors of a run: bad settings found before any item runs, or a results file that cannot be
/// written. (An item that fails becomes a failure line, not an error.)
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A setting or argument is invalid (the message names it).
    #[error("{0}")]
    Invalid(String),
    /// Inputs, results files, annotation.
    #[error(transparent)]
    Dataset(#[from] objview_dataset::DatasetError),
    /// Episode set-up.
    #[error(transparent)]
    Episode(#[from] objview_episode::EpisodeError),
    /// The object pool (splits).
    #[error(transparent)]
    Pool(#[from] objview_pool::PoolError),
    /// Reports.
    #[error(transparent)]
    Report(#[from] objview_report::ReportError),
    /// Figures.
    #[error(transparent)]
    Plot(#[from] objview_plot::PlotError),
    /// Geometry (the demo's objects).
    #[error(transparent)]
    Geom(#[from] objview_geom::GeomError),
    /// View sets and view spaces.
    #[error(transparent)]
    Views(#[from] objview_views::ViewsError),
    /// Voxelization.
    #[error(transparent)]
    Voxel(#[from] objview_voxel::VoxelError),
    /// Writing an image.
    #[error(transparent)]
    Image(#[from] objview_render::preview::PreviewError),
    /// Writing an output file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
}

impl RunError {
    /// Shorthand for [`RunError::Io`].
    pub fn io(path: impl Into<std::path::PathBuf>, source: std::io::Error) -> RunError {
        RunError::Io { path: path.into(), source }
    }
}
