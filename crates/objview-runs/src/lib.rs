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
//! - [`params`]: `NAME=VALUE` planner parameters; [`cache`]: cache locations; [`cpu`]: the
//!   instruction-set baseline of the build, checked at start-up.
//! - [`bench`](mod@bench): the measurement procedures of `objview bench …` (episode step, annotation,
//!   rendering).
//!
//! The batch driver itself (worker pool, input-order output, typed progress events) is
//! [`objview_dataset::batch`]; each plan here makes its items and notes and hands them to it.

pub mod annotate;
pub mod bench;
pub mod cache;
pub mod cpu;
pub mod demo;
pub mod episodes;
pub mod params;
pub mod pool;
pub mod provenance;
pub mod record;

pub use episodes::{EpisodePlan, RunSummary};
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
    Dataset(Box<objview_dataset::DatasetError>),
    /// Episode set-up.
    #[error(transparent)]
    Episode(Box<objview_episode::EpisodeError>),
    /// The object pool (splits).
    #[error(transparent)]
    Pool(Box<objview_pool::PoolError>),
    /// Reports.
    #[error(transparent)]
    Report(Box<objview_report::ReportError>),
    /// Figures.
    #[error(transparent)]
    Plot(Box<objview_plot::PlotError>),
    /// Geometry (the demo's objects).
    #[error(transparent)]
    Geom(Box<objview_geom::GeomError>),
    /// View sets and view spaces.
    #[error(transparent)]
    Views(Box<objview_views::ViewsError>),
    /// Voxelization.
    #[error(transparent)]
    Voxel(Box<objview_voxel::VoxelError>),
    /// Writing an image.
    #[error(transparent)]
    Image(Box<objview_render::preview::PreviewError>),
    /// Writing an output file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
}

/// `From` for each boxed source error (boxed so that `Result<_, RunError>` stays small).
macro_rules! boxed_from {
    ($($variant:ident: $t:ty),* $(,)?) => {
        $(impl From<$t> for RunError {
            fn from(e: $t) -> RunError {
                RunError::$variant(Box::new(e))
            }
        })*
    };
}

boxed_from!(
    Dataset: objview_dataset::DatasetError,
    Episode: objview_episode::EpisodeError,
    Pool: objview_pool::PoolError,
    Report: objview_report::ReportError,
    Plot: objview_plot::PlotError,
    Geom: objview_geom::GeomError,
    Views: objview_views::ViewsError,
    Voxel: objview_voxel::VoxelError,
    Image: objview_render::preview::PreviewError,
);

impl RunError {
    /// Shorthand for [`RunError::Io`].
    pub fn io(path: impl Into<std::path::PathBuf>, source: std::io::Error) -> RunError {
        RunError::Io { path: path.into(), source }
    }
}
