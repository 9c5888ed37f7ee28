//! hvi-plot's error, [`PlotError`]: a picture that could not be drawn or written, and why.

use std::path::PathBuf;

use hvi_analysis::error::fmt_chain;

/// Everything that can go wrong while drawing a picture.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Nothing to draw, or an input the picture cannot show: the message says which.
    #[error("{0}")]
    Input(String),
    /// The drawing library failed (plotters, the embedded font, the PNG encoder).
    #[error(fmt = fmt_draw)]
    Draw {
        /// What was being drawn or encoded.
        context: String,
        /// The library's reason.
        #[source]
        source: BoxError,
    },
    /// A picture that could not be written to its path.
    #[error(fmt = fmt_write)]
    Write {
        /// The file.
        path: PathBuf,
        /// What was being done ("cannot create ...").
        context: String,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
}

fn fmt_draw(context: &str, source: &BoxError, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
    fmt_chain(context, source.as_ref(), f)
}

fn fmt_write(
    _path: &std::path::Path,
    context: &str,
    source: &std::io::Error,
    f: &mut std::fmt::Formatter<'_>,
) -> std::fmt::Result {
    fmt_chain(context, source, f)
}

/// A library's error, boxed.
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Result type of hvi-plot.
pub type Result<T> = std::result::Result<T, PlotError>;

impl PlotError {
    /// A drawing library's `source` with `context` above it.
    pub fn draw(
        context: impl Into<String>,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> Self {
        PlotError::Draw {
            context: context.into(),
            source: Box::new(source),
        }
    }
}

/// A plotters error (any backend's) as [`PlotError::Draw`].
impl<E: std::error::Error + Send + Sync + 'static> From<plotters::drawing::DrawingAreaErrorKind<E>>
    for PlotError
{
    fn from(e: plotters::drawing::DrawingAreaErrorKind<E>) -> Self {
        PlotError::draw("the picture could not be drawn", e)
    }
}
