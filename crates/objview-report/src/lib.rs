//! `objview report`: episode results (SPEC §5) → the paper's evaluation tables and figures
//! (paper §6): Table 2 (quality top-k per budget setting), Table 3 (path-efficient top-k), Table 4
//! (reachability degradation whole vs quarter), Table 5 (map stabilization of oracle runs on main
//! and slow-saturation objects, from difficulty annotations), a full per-(setting, view space,
//! method) summary, a terminal-reason/failure summary, and NSC-vs-views and path-cost-vs-NSC
//! figures.
//!
//! - [`load`]: reading and checking result files (failure lines, duplicates, torn lines);
//! - [`select`]: budget settings and the checkpoint each episode contributes to each;
//! - [`aggregate`]: per-(setting, view space, method) means and standard deviations;
//! - [`tables`]: the data of Tables 2–5 and the terminal summary; [`render`]: their Markdown and
//!   CSV; [`format`](mod@format): number formats, time bins, pipe tables;
//! - [`plots`]: the figures (PNG + SVG via `objview_plot`, data in `figures.json`);
//! - [`report`]: [`build_report`] and [`Report::write`];
//! - [`figure4`]: the paper's Figure 4 from `objview learn experiment difficulty-aware`.
//!
//! Output is deterministic: episodes are sorted before averaging, maps are ordered, numbers have
//! fixed formats, and nothing records a clock; the same inputs give byte-identical files.

pub mod aggregate;
pub mod error;
pub mod figure4;
pub mod format;
pub mod load;
pub mod plots;
pub mod render;
pub mod report;
pub mod select;
pub mod tables;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod testutil;

pub use error::ReportError;
pub use report::{build_report, Report, ReportSettings, OUTPUT_FILES};
pub use select::Setting;

/// The objview version, recorded in `report.json`, `figures.json` and the Markdown header.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
