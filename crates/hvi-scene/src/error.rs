//! The engine's one error type.

use thiserror::Error;

/// Everything that can go wrong in the engine, each naming what to fix.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EngineError {
    /// A parameter is outside its allowed range (or missing, or not a number).
    #[error("invalid value for `{key}`: {value} (allowed: {allowed})")]
    InvalidValue {
        /// The scene key, as written in a scene file (`section.name`).
        key: String,
        /// The offending value as given.
        value: String,
        /// The allowed range or set, in words.
        allowed: String,
    },
    /// Two keys that exclude each other were both given, or neither of two alternatives.
    #[error("conflicting keys: {0}")]
    Conflict(String),
    /// The bodies overlap at the start (closer than r_eq).
    #[error("bodies overlap at start: closest impactor-target pair is {distance_m:.3e} m apart, less than r_eq = {r_eq_m:.3e} m (check `scene.standoff_m`)")]
    Overlap {
        /// Closest distance found, m.
        distance_m: f64,
        /// The lattice spacing r_eq, m.
        r_eq_m: f64,
    },
    /// The run went numerically unstable; the state up to the previous step is kept.
    #[error("numerical instability at step {step} (t = {time_s:.4e} s): {reason}")]
    Unstable {
        /// Step at which the problem was detected.
        step: u64,
        /// Simulated time at detection, s.
        time_s: f64,
        /// What was seen.
        reason: String,
    },
    /// A saved state (`hvi_engine::sim::SimState`) does not fit the simulation it was restored
    /// into (another scene, or a damaged file).
    #[error("the saved state does not fit this scene: {0}")]
    StateMismatch(String),
}

impl EngineError {
    /// Whether running the same scene on the same engine fails the same way: the engine's
    /// verdict on the scene itself (an instability, a rejected value, overlapping bodies), which
    /// the engine reaches bit-identically at any thread count. A saved state that does not fit
    /// is a damaged or foreign file, not the scene's, and is not.
    pub fn is_reproducible(&self) -> bool {
        !matches!(self, EngineError::StateMismatch(_))
    }

    /// Shorthand for [`EngineError::InvalidValue`].
    pub fn invalid(key: &str, value: impl std::fmt::Display, allowed: impl Into<String>) -> Self {
        EngineError::InvalidValue {
            key: key.to_string(),
            value: value.to_string(),
            allowed: allowed.into(),
        }
    }
}

/// Result type of the engine.
pub type Result<T> = std::result::Result<T, EngineError>;

/// Checks that `value` is finite and inside `(lo, hi)` / `[lo, hi]` as `open_lo`/`open_hi` say.
pub(crate) fn check_range(
    key: &str,
    value: f64,
    lo: f64,
    open_lo: bool,
    hi: f64,
    open_hi: bool,
) -> Result<f64> {
    let above = if open_lo { value > lo } else { value >= lo };
    let below = if open_hi { value < hi } else { value <= hi };
    if value.is_finite() && above && below {
        return Ok(value);
    }
    Err(EngineError::invalid(
        key,
        value,
        describe_interval(lo, open_lo, hi, open_hi),
    ))
}

/// An interval in words, as errors and `hvi-study keys` print it: `a number > 0`,
/// `a number >= 1`, `(0, 1e5]`.
pub fn describe_interval(lo: f64, open_lo: bool, hi: f64, open_hi: bool) -> String {
    if hi.is_infinite() && lo.is_finite() {
        format!(
            "a number {} {}",
            if open_lo { ">" } else { ">=" },
            bound(lo)
        )
    } else {
        format!(
            "{}{}, {}{}",
            if open_lo { "(" } else { "[" },
            bound(lo),
            bound(hi),
            if open_hi { ")" } else { "]" }
        )
    }
}

/// A bound as written: 0, 0.05, 1000, 1e5, 5e8, inf.
fn bound(x: f64) -> String {
    if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.to_string()
    } else if x != 0.0 && !(1e-3..1e4).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A strictly positive finite number.
pub(crate) fn check_positive(key: &str, value: f64) -> Result<f64> {
    check_range(key, value, 0.0, true, f64::INFINITY, true)
}
