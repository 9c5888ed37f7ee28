//! # hvi-plot
//!
//! Every picture hvi draws, from data in memory to PNG (and SVG where a user edits it):
//! particle renders of a run ([`render`]), contour maps ([`contour`]), snapshot matrices
//! ([`snapshots`]) and the paper's line figures ([`paper`]). One embedded font and one theme
//! ([`theme`]: colours, text, legend and subtitle) for all of them; no system libraries.
//!
//! ```
//! use hvi_analysis::contour::Field;
//! use hvi_plot::contour::{contour_plot, ContourPlot};
//! // R over a 3 x 2 grid, drawn as a map with the experiment's level highlighted.
//! let field = Field::new(vec![0.01, 0.1, 1.0], vec![1e6, 4e6], vec![vec![1.1, 1.3, 1.6], vec![1.2, 1.4, 1.9]])
//!     .expect("a rectilinear grid");
//! let plot = ContourPlot {
//!     title: "R".into(), subtitle: String::new(), x_label: "eps (J)".into(),
//!     y_label: "kappa (N/m)".into(), x_log: true, y_log: true, field,
//!     value_label: "R".into(), levels: 4, highlight: Some((1.55, "experiment".into())),
//!     extra_points: Vec::new(), samples: None, markers: Vec::new(), region: None,
//!     curves: Vec::new(),
//!     bulk_colours: false,
//! };
//! let stem = std::env::temp_dir().join(format!("hvi-plot-doc-{}", std::process::id()));
//! contour_plot(&stem, &plot).expect("drawn");
//! assert!(stem.with_extension("png").exists() && stem.with_extension("svg").exists());
//! # std::fs::remove_file(stem.with_extension("png")).ok();
//! # std::fs::remove_file(stem.with_extension("svg")).ok();
//! ```

pub mod contour;
pub mod error;
mod glyphs;
pub mod ladder;
pub mod paper;
pub mod pareto;
pub mod render;
mod save;
pub mod snapshots;
pub mod stability_map;
pub mod theme;
