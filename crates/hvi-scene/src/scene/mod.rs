//! Scene description (what a scene file says) and its validation into a ready-to-run setup.
//!
//! The spec types mirror the TOML scene files one to one (`[scene]`, `[resolution]`,
//! `[material]`, `[impactor]`, `[run]`, `[analysis]`); their keys are the keys `hvi-study run --set` accepts.
//! [`SceneSpec::build`] validates every value (naming the key and the allowed range on error)
//! and lays out the particles: simple cubic lattice at r_eq, nearest-neighbour bonds inside each
//! body, mass m = M/N per body (eq. 20), seeded Maxwell-Boltzmann thermal velocities.
//!
//! One job per file: `spec` (the types and their defaults), `analysis` (the `[analysis]`
//! settings and their defaults), `time_step` (the choice of the base step),
//! `keys` (the registry of every key: meaning, allowed values, default; the intervals the
//! checks use), `validate` (range checks of the geometry and run settings), `build` (the steps from a spec
//! to a [`Setup`], and the [`Derived`] numbers), `layout` (lattice sites, bonds, thermal
//! velocities), `resolution` (each plate's layers at this resolution, and the warnings when
//! the lattice cannot represent the scene or a change of the geometry moved sigma).
//! Everything public is re-exported here, so paths are `hvi_engine::scene::X`.

mod analysis;
mod build;
pub mod keys;
mod layout;
mod resolution;
mod spec;
mod time_step;
mod validate;

pub use analysis::{Analysis, Width, DEFAULT_FRONT_TIMES_S, DEFAULT_QUANTILE, MEASUREMENT_KEYS};
pub use build::{Derived, Setup};
pub use resolution::{
    merged_warnings, sigma_change, KeyChange, MergedWarning, Plate, ResolutionCheck,
    ResolutionIssue, ResolutionWarning, SigmaChange, MIN_PLATE_LAYERS, SIGMA_CHANGE_TOLERANCE,
    THICKNESS_TOLERANCE,
};
pub use spec::{
    Geometry, ImpactorMaterial, Material, Resolution, RunSettings, SceneSpec, SizingRule, TimeStep,
    DEFAULT_SKIN_OVER_SIGMA,
};
pub use validate::SUSPICIOUS_V0_M_S;

// The time-step constants, also at the paths they had when they were defined here.
pub use crate::step::{
    AUTO_STEP_SAFETY, DEFAULT_DT_FACTOR, DEFAULT_MAX_STRIDE,
    DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA, LOOKAHEAD_SKIN_FRACTION,
    MAX_STEP_DISPLACEMENT_OVER_SIGMA, MAX_STEP_OVER_SQRT_M_K, MAX_STRIDE,
    MAX_STRIDE_DISPLACEMENT_OVER_SIGMA,
};
