//! Pictures of a run, PNG through plotters with an embedded font (no system libraries):
//!
//! - [`side_view`]: the debris cloud seen from the side at the analysis time, like the paper's
//!   Figs. 7 and 11 (impactor particles red, plate blue, axes in mm, scale bar, time stamp),
//!   with the measured front, width and original rear face drawn in, and below it the
//!   mid-plane slice that shows the cloud's inside;
//! - [`series`]: 3-D perspective views at chosen times, like Fig. 12;
//! - [`fragment_histogram`]: the fragment-size distribution by mass;
//! - [`track_plot`]: La, Lr and the front velocity over time.
//!
//! Particles are rasterised straight into the bitmap as small squares through a depth buffer
//! (nearest wins, darker with depth), never as one plotters element per particle (the paper's
//! runs have 2.7e5 of them). plotters draws axes, text and overlays. Every number shown comes
//! from `hvi_engine::cloud`; nothing here re-derives a definition.
//!
//! Each picture has its own submodule (`side`, `perspective`, `charts`, `shadowgraph`); `common`
//! holds what they share: the frame, the scene facts of the captions, the rasteriser and the
//! scale bar.

mod charts;
mod common;
mod perspective;
mod shadowgraph;
mod side;

pub use charts::{diameter_bins, fragment_histogram, track_plot, DiameterBin};
pub use perspective::series;
pub use shadowgraph::shadowgraph;
pub use side::side_view;

/// The font and PNG writer, where callers of this module have always found them.
pub use crate::save::write_png;
pub use crate::theme::{fonts, FAMILY};
pub(crate) use common::{nice_length, round_ticks};
pub use common::{Frame, SceneInfo};
