//! # hvi-plot
//!
//! Every picture hvi draws, from data in memory to PNG (and SVG where a user edits it):
//! particle renders of a run ([`render`]), contour maps ([`contour`]), snapshot matrices
//! ([`snapshots`]) and the paper's line figures ([`paper`]). One embedded font and one theme
//! ([`theme`]: colours, text, legend and subtitle) for all of them; no system libraries.

pub mod contour;
pub mod paper;
pub mod pareto;
pub mod render;
mod save;
pub mod snapshots;
pub mod stability_map;
pub mod theme;
