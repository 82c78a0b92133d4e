//! Figures of objview, as PNG and SVG with identical content.
//!
//! - [`chart`]: general chart primitives (line, scatter, bars; log/linear axes; reference lines;
//!   legends; multi-panel figures) used by every figure, including the run reports;
//! - [`mod@figure2`]: the paper's Figure 2 (saturation curves and marginal gain, d_plan histogram,
//!   d_sat vs d_plan) from `objview annotate` results, with a `figures.json` of the plotted data;
//! - [`stats`]: correlations printed on figures; [`ticks`]: axis ticks and labels;
//! - [`font`]: the embedded font, so that text never depends on the fonts of the machine;
//!   [`png_text`]: the PNG backend that rasterizes it with exact glyph placement.
//!
//! Output is deterministic: no clocks, no system fonts, seeded jitter; the same inputs give
//! byte-identical files.

pub mod chart;
pub mod error;
pub mod figure2;
pub mod font;
pub mod png_text;
pub mod stats;
pub mod ticks;

pub use chart::{
    palette, Axis, Bar, BarSeries, Chart, Figure, Jitter, Legend, Marker, Orientation, RefLine, Rgb, Scale,
    Series, INK, PALETTE,
};
pub use error::PlotError;
pub use figure2::{figure2, Figure2Output, Figure2Settings, FIGURE2_STEMS, FIGURES_JSON};

/// objview version, recorded in figure outputs.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
