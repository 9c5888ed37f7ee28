//! hvi-analysis's error, [`AnalysisError`]: what was wrong with an input, a data file or a
//! surrogate fit, in words that name the field and what is allowed.

/// Everything that can go wrong in an analysis.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// An input out of its allowed range or shape: the message names the field and what is
    /// allowed.
    #[error("{0}")]
    Input(String),
    /// What was being done (reading a targets file, checking a relation), with the error below
    /// it as its source (a parser's reason, an [`AnalysisError::Input`]).
    #[error(fmt = fmt_context)]
    Context {
        /// What was being done.
        context: String,
        /// The error.
        #[source]
        source: BoxError,
    },
    /// A condition the code guarantees did not hold (a bug, reported rather than a panic).
    #[error("{0}")]
    Invariant(String),
    /// The surrogate could not be fitted or could not predict: the library's reason.
    #[error("{0}")]
    Surrogate(String),
}

/// `message`, and under `{:#}` the chain below it (`: cause` for each, as `anyhow` prints it);
/// hvi-plot's errors print the same way.
pub fn fmt_chain(
    message: &str,
    source: &(dyn std::error::Error + 'static),
    f: &mut std::fmt::Formatter<'_>,
) -> std::fmt::Result {
    f.write_str(message)?;
    if f.alternate() {
        let mut next = Some(source);
        while let Some(e) = next {
            write!(f, ": {e}")?;
            next = e.source();
        }
    }
    Ok(())
}

fn fmt_context(
    context: &str,
    source: &BoxError,
    f: &mut std::fmt::Formatter<'_>,
) -> std::fmt::Result {
    fmt_chain(context, source.as_ref(), f)
}

/// A library's error, boxed.
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Result type of hvi-analysis.
pub type Result<T> = std::result::Result<T, AnalysisError>;

impl AnalysisError {
    /// `source` with `context` (what was being done) above it.
    pub fn context(
        context: impl Into<String>,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> Self {
        AnalysisError::Context {
            context: context.into(),
            source: Box::new(source),
        }
    }
}

/// `return Err(AnalysisError::Input(format!(...)))`.
macro_rules! bail {
    ($($t:tt)*) => {
        return Err($crate::error::AnalysisError::Input(format!($($t)*)))
    };
}
pub(crate) use bail;
