//! The choice of a scene's base time step from `run.dt_s` ("auto" or seconds),
//! `run.dt_factor` and `run.dt_over_bound`, against the stability bound of `crate::step`.

use super::keys;
use super::spec::{RunSettings, TimeStep};
use crate::error::{check_positive, EngineError, Result};
use crate::paper;
use crate::step::{AUTO_STEP_SAFETY, MAX_STEP_DISPLACEMENT_OVER_SIGMA, MAX_STEP_OVER_SQRT_M_K};

/// The base time step, s: `run.dt_over_bound` times the stability bound `dt_max` when set,
/// else the automatic step (the paper's step scaled with sigma / sigma_ref, times
/// `run.dt_factor`, at most [`AUTO_STEP_SAFETY`] of the bound) or the fixed `run.dt_s`, which
/// must not exceed the bound.
pub(super) fn choose_time_step(
    run: &RunSettings,
    dt_max: f64,
    sigma: f64,
    sigma_ref: f64,
) -> Result<f64> {
    // "auto" never exceeds AUTO_STEP_SAFETY of the bound (fast impacts, stiff springs); a
    // fixed step beyond the bound is refused.
    let dt = match (run.dt_over_bound, run.dt_s) {
        (Some(f), _) => keys::check("run.dt_over_bound", f)? * dt_max,
        (None, TimeStep::Auto) => (paper::TIME_STEP_S * (sigma / sigma_ref) * run.dt_factor)
            .min(AUTO_STEP_SAFETY * dt_max),
        (None, TimeStep::Fixed(dt)) => {
            check_positive("run.dt_s", dt)?;
            if dt > dt_max {
                return Err(EngineError::invalid(
                    "run.dt_s",
                    format!("{dt:e} s"),
                    format!(
                        "a step of at most {dt_max:.3e} s at sigma = {sigma:.3e} m: \
                             v0 dt <= {MAX_STEP_DISPLACEMENT_OVER_SIGMA} sigma and \
                             dt <= {MAX_STEP_OVER_SQRT_M_K} sqrt(m / k)"
                    ),
                ));
            }
            dt
        }
    };
    Ok(dt)
}
