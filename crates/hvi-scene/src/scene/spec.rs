//! The scene's spec types: what a scene file says, key for key.
//!
//! The types mirror the TOML scene files one to one (`[scene]`, `[resolution]`, `[material]`,
//! `[run]`, `[analysis]`); their keys are the keys `hvi-study run --set` accepts. Defaults are
//! the paper's values (`crate::paper`) and the step's (`crate::step`).

use serde::{Deserialize, Serialize};

use super::analysis::Analysis;
use crate::paper;
use crate::potential::ContactForm;
use crate::step::{DEFAULT_DT_FACTOR, DEFAULT_MAX_STRIDE, DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA};
use crate::symmetry::Symmetry;

/// A whole scene: geometry, resolution, material and run settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// The bodies and how they meet.
    pub scene: Geometry,
    /// How finely they are discretised.
    pub resolution: Resolution,
    /// The model's material parameters: the plate's, and the impactor's unless `impactor`
    /// gives its own.
    pub material: Material,
    /// The impactor's material where it differs from the plate's (docs/model.md section 3,
    /// "Two materials"); empty for one material, and then left out of the scene's JSON so
    /// that fingerprints of one-material scenes are unchanged.
    #[serde(default, skip_serializing_if = "ImpactorMaterial::is_empty")]
    pub impactor: ImpactorMaterial,
    /// Time integration and safety settings.
    #[serde(default)]
    pub run: RunSettings,
    /// What to measure of the debris cloud, and when (definitions in `hvi_engine::cloud`).
    #[serde(default)]
    pub analysis: Analysis,
}

fn default_density() -> f64 {
    paper::ALUMINIUM_DENSITY_KG_M3
}
fn default_width_over_d() -> f64 {
    paper::DEFAULT_WIDTH_OVER_D
}

/// The bodies of a scene. All lengths in m, velocities in m/s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Geometry {
    /// A sphere of diameter D striking a square plate of thickness t and side W at normal incidence.
    SphereOnPlate {
        /// Sphere diameter D, m.
        diameter_m: f64,
        /// Plate thickness over sphere diameter, t/D.
        t_over_d: f64,
        /// Plate side over sphere diameter, W/D (default 3: docs/model.md section 1).
        #[serde(default = "default_width_over_d")]
        width_over_d: f64,
        /// Impact velocity v0, m/s.
        v0_m_s: f64,
        /// Density of both bodies, kg/m^3.
        #[serde(default = "default_density")]
        density_kg_m3: f64,
        /// Extra gap between the bodies at t = 0, m (0: first contact at t = 0).
        #[serde(default)]
        standoff_m: f64,
    },
    /// A flyer plate striking a target plate of the same width (the sizing test, Fig. 4).
    FlyerPlate {
        /// Flyer thickness, m.
        flyer_thickness_m: f64,
        /// Target thickness, m.
        target_thickness_m: f64,
        /// Side of both square plates, m.
        width_m: f64,
        /// Flyer velocity v0, m/s.
        v0_m_s: f64,
        /// Density of both bodies, kg/m^3.
        #[serde(default = "default_density")]
        density_kg_m3: f64,
        /// Extra gap between the plates at t = 0, m.
        #[serde(default)]
        standoff_m: f64,
    },
}

impl Geometry {
    /// Plate thickness over sphere diameter, t/D (None for the flyer plate).
    pub fn t_over_d(&self) -> Option<f64> {
        match self {
            Geometry::SphereOnPlate { t_over_d, .. } => Some(*t_over_d),
            Geometry::FlyerPlate { .. } => None,
        }
    }

    /// Impact velocity v0, m/s.
    pub fn v0_m_s(&self) -> f64 {
        match self {
            Geometry::SphereOnPlate { v0_m_s, .. } | Geometry::FlyerPlate { v0_m_s, .. } => *v0_m_s,
        }
    }

    /// Total volume of both bodies, m^3.
    pub fn volume_m3(&self) -> f64 {
        match *self {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                width_over_d,
                ..
            } => paper::sphere_on_plate_volume_m3(diameter_m, t_over_d, width_over_d),
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                width_m,
                ..
            } => width_m * width_m * (flyer_thickness_m + target_thickness_m),
        }
    }
}

/// Resolution: a target total particle count, or particles across the sphere diameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Resolution {
    /// Target total particle count (the actual count differs by lattice rounding).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particles: Option<f64>,
    /// Lattice sites across the sphere diameter D (sphere-on-plate only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particles_across_d: Option<f64>,
}

fn default_rcut() -> f64 {
    paper::BEST_RCUT_OVER_SIGMA
}
fn default_true() -> bool {
    true
}

/// Material parameters. Give (eps, kappa) at the reference diameter of docs/model.md section 4, or
/// the size-invariant (gamma, lambda) with eps = gamma sigma^3 and kappa = lambda sigma (eq. 12).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Contact prefactor form: "printed" (eq. 3 as printed) or "wca".
    #[serde(default)]
    pub contact: ContactForm,
    /// Repulsion strength eps at the reference sigma, J.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eps_j: Option<f64>,
    /// Spring stiffness kappa at the reference sigma, N/m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kappa_n_m: Option<f64>,
    /// Size-invariant repulsion strength gamma = eps / sigma^3, Pa.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma_pa: Option<f64>,
    /// Size-invariant stiffness lambda = kappa / sigma, Pa.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda_pa: Option<f64>,
    /// Bond break distance over sigma (must exceed r_eq/sigma = 2^(1/6)).
    #[serde(default = "default_rcut")]
    pub rcut_over_sigma: f64,
    /// Geometric sizing (eqs. 5-20): scale eps and kappa from the reference sigma to the actual
    /// one. Off only to show what goes wrong without it (Fig. 4, top).
    #[serde(default = "default_true")]
    pub sizing: bool,
    /// How eps scales with sigma under sizing: "eq12" (eps ~ sigma^3, the default) or "eqs5_6"
    /// (eps ~ sigma, as equations 5 and 6 of the paper's text print it); kappa ~ sigma in both.
    #[serde(default, skip_serializing_if = "SizingRule::is_default")]
    pub sizing_rule: SizingRule,
}

/// The impactor's own material (section `[impactor]`): every key left out is the plate's
/// (`[material]`, and `scene.density_kg_m3`). Both bodies share the lattice (one sigma), the
/// contact form and the sizing; the contact between them follows the combining rule of
/// docs/model.md section 3.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImpactorMaterial {
    /// The impactor's density, kg/m^3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density_kg_m3: Option<f64>,
    /// The impactor's repulsion strength eps at the reference sigma, J.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eps_j: Option<f64>,
    /// The impactor's spring stiffness kappa at the reference sigma, N/m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kappa_n_m: Option<f64>,
    /// The impactor's size-invariant repulsion strength gamma = eps / sigma^3, Pa.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma_pa: Option<f64>,
    /// The impactor's size-invariant stiffness lambda = kappa / sigma, Pa.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda_pa: Option<f64>,
    /// The impactor's bond break distance over sigma.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rcut_over_sigma: Option<f64>,
}

impl ImpactorMaterial {
    /// Whether no key is given (the impactor is of the plate's material).
    pub fn is_empty(&self) -> bool {
        *self == ImpactorMaterial::default()
    }
}

/// The scaling of eps with the particle diameter under geometric sizing (docs/model.md section 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum SizingRule {
    /// Eq. (12): eps = gamma sigma^3, energy per bond proportional to volume per particle.
    #[default]
    #[serde(rename = "eq12")]
    Eq12,
    /// Eqs. (5) and (6) as printed: eps proportional to sigma. A reading kept to test it
    /// (`hvi-study fidelity`), not a physical choice: it does not conserve energy per volume.
    #[serde(rename = "eqs5_6")]
    Eqs5And6,
}

impl SizingRule {
    /// Whether this is the default rule (then it is left out of the scene's JSON, so that
    /// fingerprints of scenes that do not name it are unchanged).
    pub fn is_default(&self) -> bool {
        *self == SizingRule::Eq12
    }

    /// The power of sigma that eps scales with.
    pub fn eps_power(self) -> i32 {
        match self {
            SizingRule::Eq12 => 3,
            SizingRule::Eqs5And6 => 1,
        }
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            contact: ContactForm::Printed,
            eps_j: Some(paper::BEST_EPS_J),
            kappa_n_m: Some(paper::BEST_KAPPA_N_M),
            gamma_pa: None,
            lambda_pa: None,
            rcut_over_sigma: paper::BEST_RCUT_OVER_SIGMA,
            sizing: true,
            sizing_rule: SizingRule::Eq12,
        }
    }
}

/// The time step: "auto" or a number of seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TimeStep {
    /// A fixed step, s.
    Fixed(f64),
    /// The paper's step scaled with sigma, times `run.dt_factor`.
    #[default]
    Auto,
}

impl Serialize for TimeStep {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            TimeStep::Fixed(dt) => s.serialize_f64(*dt),
            TimeStep::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for TimeStep {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = TimeStep;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("run.dt_s: a step in seconds (e.g. 1e-10) or \"auto\"")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<TimeStep, E> {
                Ok(TimeStep::Fixed(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<TimeStep, E> {
                Ok(TimeStep::Fixed(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<TimeStep, E> {
                Ok(TimeStep::Fixed(v as f64))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<TimeStep, E> {
                if v == "auto" {
                    Ok(TimeStep::Auto)
                } else {
                    Err(E::custom(format!(
                        "invalid value for `run.dt_s`: \"{v}\" (allowed: a step in seconds or \"auto\")"
                    )))
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// Time integration and safety settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunSettings {
    /// Simulated time from first contact to the end of the run, s.
    pub end_time_s: f64,
    /// Time step, s, or "auto": the paper's 1e-10 s at sigma_ref, scaled with sigma, times
    /// `dt_factor`, capped at [`crate::step::AUTO_STEP_SAFETY`] times the stability bound.
    pub dt_s: TimeStep,
    /// Multiplier on the automatic step.
    pub dt_factor: f64,
    /// For stress tests: the step as this multiple of the stability bound, in (0, 8] (above 1
    /// is beyond the bound, where the stability map looks for the first sign of trouble);
    /// when set it replaces `dt_s` and `dt_factor`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dt_over_bound: Option<f64>,
    /// Seed of the thermal velocities.
    pub seed: u64,
    /// Per-component standard deviation of the thermal velocities, as a fraction of v0.
    pub thermal_ratio: f64,
    /// Neighbour-list skin over sigma.
    pub skin_over_sigma: f64,
    /// Side of the blocks whose mean velocity is the frame of the list's rebuild rule, over
    /// sigma (0: the classic rule, rebuild once any particle moved half the skin). Exact for
    /// any value; larger blocks let a fast cloud go longer between builds (`neighbour`).
    pub frame_block_over_sigma: f64,
    /// Adaptive step: the largest multiple of the base step (`dt_s`, the step the impact is
    /// resolved with) a step may take, a whole number in [1, 64]; 1 is a fixed step. The
    /// criterion is in `hvi_engine::sim`: a step of m base steps is taken only while the bound on
    /// the relative speed of any two neighbours, times m dt, stays below
    /// `stride_displacement_over_sigma` sigma, and the stiffest active pair is resolved.
    /// Omitted from the scene as written in outputs when 1, so a fixed-step run's fingerprint
    /// does not depend on this key; the summary's `steps`, `base_steps` and `dt_largest_s` say
    /// what the run did.
    #[serde(skip_serializing_if = "is_fixed_stride")]
    pub max_stride: u64,
    /// The adaptive step's displacement bound: listed pairs close in by at most this fraction
    /// of sigma per step, in (0, [`crate::step::MAX_STRIDE_DISPLACEMENT_OVER_SIGMA`]]; default
    /// [`DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA`].
    #[serde(skip_serializing_if = "is_default_stride_displacement")]
    pub stride_displacement_over_sigma: f64,
    /// Base steps between energy-ledger samples (an adaptive step never steps over one).
    pub energy_every: u64,
    /// Abort when |E_total - E_0| / E_0 exceeds this (a blow-up guard, not the accuracy bound).
    pub max_energy_drift: f64,
    /// Abort when two particles come closer than this times sigma.
    pub min_distance_over_sigma: f64,
    /// Ballistic cut-off: once the debris is in free flight, stop computing forces and move
    /// each fragment rigidly with its centre-of-mass velocity (see `Simulation::start_coasting`).
    pub ballistic_cutoff: bool,
    /// The cut-off is considered only after this time since first contact, s.
    pub cutoff_min_tau_s: f64,
    /// ... and only when, over this long (s), ...
    pub cutoff_quiet_s: f64,
    /// ... the broken-bond count grew by at most this fraction (0: not a single break).
    pub cutoff_break_fraction: f64,
    /// Free flight from this time after first contact on, s, whatever the cut-off's gate: the
    /// fragments as they are then move rigidly with their centre-of-mass velocities to the
    /// end (`Simulation::start_coasting`). What it costs in accuracy is measured in
    /// docs/model-decisions.md ("Free flight after a set time"). Omitted from the scene as
    /// written when unset, so runs without it keep their fingerprints.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub free_flight_after_s: Option<f64>,
    /// The screen: at the first energy sample at or after this time after first contact, s,
    /// the run measures what free flight
    /// from then would give at the analysis time (on a copy of the state), and when that
    /// measurement lies outside a window below, the run goes on in free flight from then
    /// (as `free_flight_after_s` would) instead of computing the rest. A study that only
    /// needs to know that a run is far from its targets (`hvi-study calibrate`) skips the
    /// work it does not need. Omitted from the scene as written when unset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screen_after_s: Option<f64>,
    /// The screen's window on the length ratio (the scene's reading, `analysis.width`):
    /// [low, high]; a probe outside it goes on in free flight.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screen_length_ratio: Option<[f64; 2]>,
    /// The screen's window on va / v0: [low, high].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screen_front_velocity_ratio: Option<[f64; 2]>,
    /// Width over D of the absorbing band inside the plate's lateral edge (0: none; sphere on
    /// plate only; see `hvi_engine::sim::AbsorbingBand`). Omitted from the scene as written when
    /// 0, so runs without a band keep their fingerprints.
    #[serde(skip_serializing_if = "is_zero")]
    pub absorbing_band_over_d: f64,
    /// Which part of the scene is simulated: `full`, or `quarter` (the quarter x > 0, y > 0
    /// with mirror images across both planes; normal impact on a square plate; see
    /// [`crate::symmetry`]). Omitted from the scene as written when full.
    #[serde(skip_serializing_if = "is_full")]
    pub symmetry: Symmetry,
}

impl Default for RunSettings {
    fn default() -> Self {
        RunSettings {
            end_time_s: paper::ANALYSIS_TIME_S,
            dt_s: TimeStep::default(),
            dt_factor: DEFAULT_DT_FACTOR,
            dt_over_bound: None,
            seed: 1,
            thermal_ratio: 1e-3,
            skin_over_sigma: DEFAULT_SKIN_OVER_SIGMA,
            frame_block_over_sigma: 8.0,
            max_stride: DEFAULT_MAX_STRIDE,
            stride_displacement_over_sigma: DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA,
            energy_every: 200,
            max_energy_drift: 0.05,
            min_distance_over_sigma: 0.35,
            ballistic_cutoff: false,
            cutoff_min_tau_s: 8e-6,
            cutoff_quiet_s: 2e-6,
            cutoff_break_fraction: 1e-3,
            free_flight_after_s: None,
            screen_after_s: None,
            screen_length_ratio: None,
            screen_front_velocity_ratio: None,
            absorbing_band_over_d: 0.0,
            symmetry: Symmetry::Full,
        }
    }
}

fn is_full(s: &Symmetry) -> bool {
    *s == Symmetry::Full
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_fixed_stride(m: &u64) -> bool {
    *m == 1
}

fn is_default_stride_displacement(c: &f64) -> bool {
    *c == DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA
}

/// The default `run.skin_over_sigma`: the largest skin whose list radius (r_eq + skin) stays
/// below the lattice's second-neighbour distance (sqrt 2 r_eq = 1.587 sigma), so intact
/// lattice lists nothing but bond partners.
pub const DEFAULT_SKIN_OVER_SIGMA: f64 = 0.45;

impl SceneSpec {
    /// The paper's calibration scene (docs/model.md section 1: 9.53 mm sphere at 6.7 km/s,
    /// t/D = 0.425, W = 3 D, the best-fit material) at `particles` particles, run to
    /// `end_time_s`.
    pub fn calibration(particles: f64, end_time_s: f64) -> SceneSpec {
        SceneSpec {
            impactor: ImpactorMaterial::default(),
            scene: Geometry::SphereOnPlate {
                diameter_m: paper::IMPACTOR_DIAMETER_M,
                t_over_d: paper::CALIBRATION_T_OVER_D,
                width_over_d: paper::DEFAULT_WIDTH_OVER_D,
                v0_m_s: paper::CALIBRATION_V0_M_S,
                density_kg_m3: paper::ALUMINIUM_DENSITY_KG_M3,
                standoff_m: 0.0,
            },
            resolution: Resolution {
                particles: Some(particles),
                particles_across_d: None,
            },
            material: Material::default(),
            run: RunSettings {
                end_time_s,
                ..RunSettings::default()
            },
            analysis: Default::default(),
        }
    }
}
