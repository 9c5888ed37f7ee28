//! The time step's stability bound and the constants of the automatic and adaptive step.
//!
//! Both the scene (which chooses the base step) and the time loop (which chooses the stride of
//! the adaptive step) read their bounds here, so the two cannot disagree about them.

/// Stability bound on the time step: a particle at v0 moves at most this fraction of sigma
/// per step, ...
pub const MAX_STEP_DISPLACEMENT_OVER_SIGMA: f64 = 0.05;
/// ... and the step is at most this fraction of sqrt(m / k) for the stiffest of kappa and the
/// contact stiffness at r_eq (velocity Verlet is unstable beyond 2/omega_max = sqrt(m/k) on a
/// chain).
pub const MAX_STEP_OVER_SQRT_M_K: f64 = 0.5;
/// The automatic step is at most this fraction of the stability bound: a margin of two on
/// every scene, whatever its velocity or stiffness.
pub const AUTO_STEP_SAFETY: f64 = 0.5;
/// The default `run.dt_factor`, the multiple of the paper's step (scaled with sigma) that the
/// automatic step takes, chosen with `hvi-study accuracy` (observables within tolerance of
/// those at the paper's step). At 6.7 km/s the automatic step's cap ([`AUTO_STEP_SAFETY`] of
/// the bound, set by the displacement bound) is about 8 times the paper's step.
pub const DEFAULT_DT_FACTOR: f64 = 6.0;
/// The adaptive step's default displacement bound for listed pairs, over sigma: the stability
/// bound itself.
pub const DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA: f64 = MAX_STEP_DISPLACEMENT_OVER_SIGMA;
/// The largest `run.stride_displacement_over_sigma`: twice the stability bound. The stride
/// stays within the stiffness bound whatever this is, so this is an accuracy knob
/// (`hvi-study accuracy` measures it), not a stability one.
pub const MAX_STRIDE_DISPLACEMENT_OVER_SIGMA: f64 = 2.0 * MAX_STEP_DISPLACEMENT_OVER_SIGMA;
/// The adaptive step's look-ahead (see `hvi_engine::sim::Simulation::step_until`) takes at most
/// this fraction of the skin: pairs not yet listed close in by at most this much in one step.
pub const LOOKAHEAD_SKIN_FRACTION: f64 = 0.5;
/// The adaptive step measures the interacting pairs' largest relative speed again between
/// builds once the growth allowed for it since the last measurement (twice the largest change
/// of a particle's velocity) exceeds this fraction of the measured speed (see
/// `hvi_engine::sim::Simulation::step_until`).
pub const SPEED_REFRESH: f64 = 0.25;
/// The default `run.max_stride`: high enough that the displacement and stiffness bounds, not
/// this cap, set the stride on the paper's scenes.
pub const DEFAULT_MAX_STRIDE: u64 = 16;
/// The largest `run.max_stride`.
pub const MAX_STRIDE: u64 = 64;
/// The adaptive step raises its stride by one base step only after the criterion has
/// allowed the larger stride for this many consecutive steps; it lowers it at once.
pub const STRIDE_RAISE_AFTER: u32 = 20;

/// The largest stable time step, s: a particle at `v0_m_s` moves at most
/// [`MAX_STEP_DISPLACEMENT_OVER_SIGMA`] sigma per step, and the step is at most
/// [`MAX_STEP_OVER_SQRT_M_K`] sqrt(m / k) for the lightest particle mass `min_mass_kg` and the
/// stiffest pair law `stiffness_n_m`.
pub fn stability_bound_s(sigma_m: f64, v0_m_s: f64, min_mass_kg: f64, stiffness_n_m: f64) -> f64 {
    (MAX_STEP_DISPLACEMENT_OVER_SIGMA * sigma_m / v0_m_s)
        .min(MAX_STEP_OVER_SQRT_M_K * (min_mass_kg / stiffness_n_m).sqrt())
}

/// The adaptive step's stiffness bound on a step, s: [`AUTO_STEP_SAFETY`] of the stiffness
/// part of the stability bound, for the lightest particle mass `min_mass_kg` and the stiffness
/// `stiffness_n_m` of the closest pair now.
pub fn stiffness_step_s(min_mass_kg: f64, stiffness_n_m: f64) -> f64 {
    AUTO_STEP_SAFETY * MAX_STEP_OVER_SQRT_M_K * (min_mass_kg / stiffness_n_m).sqrt()
}
