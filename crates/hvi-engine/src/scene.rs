//! Scene description (what a scene file says) and its validation into a ready-to-run setup.
//!
//! The spec types mirror the TOML scene files one to one (`[scene]`, `[resolution]`,
//! `[material]`, `[run]`, `[analysis]`); their keys are the keys `hvi-study run --set` accepts.
//! [`SceneSpec::build`] validates every value (naming the key and the allowed range on error)
//! and lays out the particles: simple cubic lattice at r_eq, nearest-neighbour bonds inside each
//! body, mass m = M/N per body (eq. 20), seeded Maxwell-Boltzmann thermal velocities.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::error::{check_positive, check_range, EngineError, Result};
use crate::paper;
use crate::potential::{ContactForm, Interaction};
use crate::rng;
use crate::state::{Body, Particles, BONDS_PER_PARTICLE, NO_BOND};

/// A whole scene: geometry, resolution, material and run settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// The bodies and how they meet.
    pub scene: Geometry,
    /// How finely they are discretised.
    pub resolution: Resolution,
    /// The model's material parameters.
    pub material: Material,
    /// Time integration and safety settings.
    #[serde(default)]
    pub run: RunSettings,
    /// What to measure of the debris cloud, and when (definitions in [`crate::cloud`]).
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
        /// Plate side over sphere diameter, W/D (MODEL.md decision: 3).
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

/// Material parameters. Give (eps, kappa) at the reference diameter of MODEL.md section 4, or
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
    /// `dt_factor`, capped at [`AUTO_STEP_SAFETY`] times the stability bound.
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
    /// criterion is in [`crate::sim`]: a step of m base steps is taken only while the bound on
    /// the relative speed of any two neighbours, times m dt, stays below
    /// `stride_displacement_over_sigma` sigma, and the stiffest active pair is resolved.
    /// (Omitted from the scene as written in outputs when 1, so fixed-step runs keep the
    /// fingerprints they had before the adaptive step existed; the summary's `steps`,
    /// `base_steps` and `dt_largest_s` say what the run did.)
    #[serde(skip_serializing_if = "is_fixed_stride")]
    pub max_stride: u64,
    /// The adaptive step's displacement bound: listed pairs close in by at most this fraction
    /// of sigma per step, in (0, [`MAX_STRIDE_DISPLACEMENT_OVER_SIGMA`]]; default
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
        }
    }
}

/// What a run measures of the debris cloud, and when. The observables themselves are defined in
/// [`crate::cloud`] (MODEL.md section 5); these keys only choose the quantile, the times and
/// how often. Only what is asked for is computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Analysis {
    /// Measure the cloud at the end of the run (the analysis time): fragments, N_part, N_frag,
    /// F, La, Lr, R, fragment sizes, and the front velocity va from the two front times.
    pub cloud: bool,
    /// Quantile of the cloud particles' axial and radial positions that defines the front and
    /// the radial extent (so that a few stray particles do not decide La and Lr), in [0.5, 1];
    /// 1 is the plain maximum (always reported as well).
    pub quantile: f64,
    /// The two times since first contact at which the front is located for va, s, with
    /// 0 <= t1 < t2 <= `run.end_time_s`. When not given: the experiment's 28 and 32 us if the
    /// run reaches 32 us, else 7/8 of the end time and the end time
    /// ([`Analysis::front_times_s`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub front_times_s: Option<[f64; 2]>,
    /// Steps between samples of the cloud track (front, La, Lr over time; one fragment
    /// labelling each, about the cost of one step); 0 turns the track off.
    pub track_every: u64,
    /// Times since first contact of the rendered 3-D series (`hvi-study run --render`, Fig. 12),
    /// s; times beyond the end of the run are skipped.
    pub render_times_s: Vec<f64>,
}

impl Default for Analysis {
    fn default() -> Self {
        Analysis {
            cloud: true,
            quantile: crate::cloud::DEFAULT_QUANTILE,
            front_times_s: None,
            track_every: 100,
            render_times_s: paper::FIG12_TIMES_S.to_vec(),
        }
    }
}

impl Analysis {
    /// The two front times for va, s since first contact, for a run that ends at `end_time_s`:
    /// the given ones, or the experiment's (28, 32) us when the run reaches 32 us, or else
    /// (7/8 T, T) with T the end time (the same ratio, so a short run still measures a speed).
    pub fn front_times_s(&self, end_time_s: f64) -> [f64; 2] {
        match self.front_times_s {
            Some(t) => t,
            None => {
                let [t1, t2] = crate::cloud::DEFAULT_FRONT_TIMES_S;
                if end_time_s >= t2 {
                    [t1, t2]
                } else {
                    [t1 / t2 * end_time_s, end_time_s]
                }
            }
        }
    }

    /// Checks every value against its allowed range, naming the key.
    pub fn validate(&self, end_time_s: f64) -> Result<()> {
        check_range("analysis.quantile", self.quantile, 0.5, false, 1.0, false)?;
        if let Some([t1, t2]) = self.front_times_s {
            let ok = t1.is_finite() && t2.is_finite() && 0.0 <= t1 && t1 < t2 && t2 <= end_time_s;
            if !ok {
                return Err(EngineError::invalid(
                    "analysis.front_times_s",
                    format!("[{t1:e}, {t2:e}]"),
                    format!(
                        "two times since first contact in s with 0 <= t1 < t2 <= run.end_time_s                          = {end_time_s:e}"
                    ),
                ));
            }
        }
        for &t in &self.render_times_s {
            if !(t.is_finite() && t >= 0.0) {
                return Err(EngineError::invalid(
                    "analysis.render_times_s",
                    t,
                    "times since first contact in s, each finite and >= 0",
                ));
            }
        }
        Ok(())
    }
}

/// Numbers derived from a scene that every run prints (and the summary records).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Derived {
    /// Particle diameter sigma at this resolution, m.
    pub sigma_m: f64,
    /// Reference diameter at which eps and kappa are given, m.
    pub sigma_ref_m: f64,
    /// Lattice spacing r_eq, m.
    pub r_eq_m: f64,
    /// gamma = eps / sigma^3, Pa.
    pub gamma_pa: f64,
    /// lambda = kappa / sigma, Pa.
    pub lambda_pa: f64,
    /// eps at this sigma, J.
    pub eps_j: f64,
    /// kappa at this sigma, N/m.
    pub kappa_n_m: f64,
    /// rcut, m.
    pub rcut_m: f64,
    /// Particle mass of the impactor (flyer), kg.
    pub mass_impactor_kg: f64,
    /// Particle mass of the target plate, kg.
    pub mass_target_kg: f64,
    /// Density of both bodies, kg/m^3 (a particle stands for the volume mass / density).
    pub density_kg_m3: f64,
    /// Time step, s.
    pub dt_s: f64,
    /// Largest step the validation accepts, s.
    pub dt_max_s: f64,
    /// Impact velocity, m/s.
    pub v0_m_s: f64,
    /// z of the target plate's rear face at t = 0, m (the debris cloud lies beyond it).
    pub plate_rear_z_m: f64,
    /// z of the target plate's front face at t = 0, m.
    pub plate_front_z_m: f64,
    /// Time of first contact, s (tau = t - this).
    pub contact_time_s: f64,
    /// Number of steps to reach the end time.
    pub steps: u64,
}

impl Derived {
    /// Derived numbers for a hand-made particle set (tests and tools): the interaction's
    /// constants, the given step, the lattice's density mass / r_eq^3, and zeros for the
    /// scene geometry.
    pub fn for_interaction(ia: &Interaction, dt_s: f64, mass_kg: f64, steps: u64) -> Derived {
        Derived {
            sigma_m: ia.sigma_m,
            sigma_ref_m: paper::reference_sigma_m(),
            r_eq_m: ia.r_eq_m,
            gamma_pa: ia.eps_j / ia.sigma_m.powi(3),
            lambda_pa: ia.kappa_n_m / ia.sigma_m,
            eps_j: ia.eps_j,
            kappa_n_m: ia.kappa_n_m,
            rcut_m: ia.rcut_m,
            mass_impactor_kg: mass_kg,
            mass_target_kg: mass_kg,
            density_kg_m3: mass_kg / ia.r_eq_m.powi(3),
            dt_s,
            dt_max_s: f64::INFINITY,
            v0_m_s: 0.0,
            plate_rear_z_m: 0.0,
            plate_front_z_m: 0.0,
            contact_time_s: 0.0,
            steps,
        }
    }
}

/// A validated scene, laid out and ready to run.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The spec it came from.
    pub spec: SceneSpec,
    /// Derived numbers.
    pub derived: Derived,
    /// Interaction constants at this sigma.
    pub interaction: Interaction,
    /// Particles and bonds at t = 0.
    pub particles: Particles,
    /// Particles of the target that lie on its lateral rim at t = 0 (by id): the residual
    /// plate is the fragment that holds them (MODEL.md section 5).
    pub rim_ids: Vec<u32>,
}

/// Stability bound on the time step (documented in the README): a particle at v0 moves at most
/// this fraction of sigma per step, ...
pub const MAX_STEP_DISPLACEMENT_OVER_SIGMA: f64 = 0.05;
/// ... and the step is at most this fraction of sqrt(m / k) for the stiffest of kappa and the
/// contact stiffness at r_eq (velocity Verlet is unstable beyond 2/omega_max = sqrt(m/k) on a
/// chain).
pub const MAX_STEP_OVER_SQRT_M_K: f64 = 0.5;
/// The default multiple of the paper's step: chosen by `hvi-study accuracy`
/// (reports/accuracy): on the calibration scene at 1e5 particles, 6x keeps R, va/v0 and F
/// within 1 % of the mean at the paper's step (0.5, 0.8, 0.4 %; ledger 4e-5), while 8x misses
/// by a hair (1.07 % on R, 1.08 % on va/v0); at 3e4 particles both were within the larger
/// seed-to-seed spread. The automatic step's cap (AUTO_STEP_SAFETY of the bound) is about 8x at
/// 6.7 km/s, set by the displacement bound; the spring's bound is far larger (about 450x the
/// paper's step at the paper's kappa).
pub const DEFAULT_DT_FACTOR: f64 = 6.0;
fn is_fixed_stride(m: &u64) -> bool {
    *m == 1
}

fn is_default_stride_displacement(c: &f64) -> bool {
    *c == DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA
}

/// The adaptive step's default displacement bound for listed pairs: the stability bound
/// itself. Chosen by `hvi-study accuracy` (reports/accuracy/calibration-n1e5, engine 0.5.0): on
/// the calibration scene at 1e5 particles, base step 6x the paper's, the cheapest candidate
/// within tolerance (R -0.92 %, va/v0 +0.16 %, F -0.38 % of the mean at the paper's step,
/// 12.4x faster than it); twice it (0.1) was 10 % faster but missed R by 1.07 %, and in 0.3
/// half of it (0.025) was no more accurate within the seed-to-seed noise and 1.2x slower. These
/// are single-seed verdicts: at seeds 2 and 3 R scatters by up to 2 % for either bound (README,
/// "How far one seed decides"), so the choice of 0.05 over 0.1 is a conservative one.
pub const DEFAULT_STRIDE_DISPLACEMENT_OVER_SIGMA: f64 = MAX_STEP_DISPLACEMENT_OVER_SIGMA;
/// The largest `run.stride_displacement_over_sigma`: twice the stability bound. The stride
/// stays within the stiffness bound whatever this is, so this is an accuracy knob
/// (`hvi-study accuracy` measures it), not a stability one.
pub const MAX_STRIDE_DISPLACEMENT_OVER_SIGMA: f64 = 2.0 * MAX_STEP_DISPLACEMENT_OVER_SIGMA;
/// The adaptive step's look-ahead (see [`crate::sim::Simulation::step_until`]) takes at most
/// this fraction of the skin: pairs not yet listed close in by at most this much in one step.
pub const LOOKAHEAD_SKIN_FRACTION: f64 = 0.5;
/// The default `run.skin_over_sigma`: the largest skin whose list radius (r_eq + skin) stays
/// below the lattice's second-neighbour distance (sqrt 2 r_eq = 1.587 sigma), so intact
/// lattice lists nothing but bond partners. Measured (README, Engine benchmark): the debris
/// cloud builds its lists a third less often than at 0.3 sigma.
pub const DEFAULT_SKIN_OVER_SIGMA: f64 = 0.45;
/// The default `run.max_stride`: high enough never to bind on the paper's scenes (the
/// bounds keep the stride at 5 in the hot debris cloud at the default bound, 8 at 0.1 sigma).
pub const DEFAULT_MAX_STRIDE: u64 = 16;
/// The largest `run.max_stride`.
pub const MAX_STRIDE: u64 = 64;
/// The automatic step is at most this fraction of that bound: a margin of two on every scene,
/// whatever its velocity or stiffness (the stability map in `reports/stability` shows the
/// bound itself is stable).
pub const AUTO_STEP_SAFETY: f64 = 0.5;

fn require(key: &str, value: Option<f64>) -> Result<f64> {
    value.ok_or_else(|| EngineError::invalid(key, "missing", "a finite number > 0"))
}

impl SceneSpec {
    /// The paper's calibration scene (MODEL.md 1: 9.53 mm sphere at 6.7 km/s, t/D = 0.425,
    /// W = 3 D, the best-fit material) at `particles` particles, run to `end_time_s`.
    pub fn calibration(particles: f64, end_time_s: f64) -> SceneSpec {
        SceneSpec {
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

    /// Validates the spec and lays out the scene.
    pub fn build(&self) -> Result<Setup> {
        let geometry = &self.scene;
        let v0 = check_range("scene.v0_m_s", geometry.v0_m_s(), 0.0, true, 1e5, false)?;
        let (density, standoff) = match *geometry {
            Geometry::SphereOnPlate {
                density_kg_m3,
                standoff_m,
                ..
            }
            | Geometry::FlyerPlate {
                density_kg_m3,
                standoff_m,
                ..
            } => (density_kg_m3, standoff_m),
        };
        check_positive("scene.density_kg_m3", density)?;
        if !standoff.is_finite() {
            return Err(EngineError::invalid(
                "scene.standoff_m",
                standoff,
                "a finite number >= 0",
            ));
        }
        match *geometry {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                width_over_d,
                ..
            } => {
                check_positive("scene.diameter_m", diameter_m)?;
                check_positive("scene.t_over_d", t_over_d)?;
                check_range("scene.width_over_d", width_over_d, 1.0, false, 1e3, false)?;
            }
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                width_m,
                ..
            } => {
                check_positive("scene.flyer_thickness_m", flyer_thickness_m)?;
                check_positive("scene.target_thickness_m", target_thickness_m)?;
                check_positive("scene.width_m", width_m)?;
            }
        }

        // Resolution -> lattice spacing.
        let r_eq =
            match (
                self.resolution.particles,
                self.resolution.particles_across_d,
            ) {
                (Some(n), None) => {
                    check_range("resolution.particles", n, 8.0, false, 5e8, false)?;
                    (geometry.volume_m3() / n).cbrt()
                }
                (None, Some(k)) => {
                    check_range(
                        "resolution.particles_across_d",
                        k,
                        2.0,
                        false,
                        2000.0,
                        false,
                    )?;
                    match *geometry {
                        Geometry::SphereOnPlate { diameter_m, .. } => diameter_m / k,
                        Geometry::FlyerPlate { .. } => {
                            return Err(EngineError::invalid(
                                "resolution.particles_across_d",
                                k,
                                "only for kind = \"sphere_on_plate\"; use resolution.particles",
                            ))
                        }
                    }
                }
                (Some(_), Some(_)) => return Err(EngineError::Conflict(
                    "give either resolution.particles or resolution.particles_across_d, not both"
                        .into(),
                )),
                (None, None) => {
                    return Err(EngineError::Conflict(
                        "give resolution.particles or resolution.particles_across_d".into(),
                    ))
                }
            };
        let sigma = r_eq / paper::r_eq_over_sigma();
        let sigma_ref = paper::reference_sigma_m();

        // Material, with geometric sizing (eq. 12: eps = gamma sigma^3, kappa = lambda sigma).
        let m = &self.material;
        let rcut_over_sigma = check_range(
            "material.rcut_over_sigma",
            m.rcut_over_sigma,
            paper::r_eq_over_sigma(),
            true,
            10.0,
            false,
        )?;
        let (gamma, lambda) = match (m.eps_j, m.kappa_n_m, m.gamma_pa, m.lambda_pa) {
            (eps, kappa, None, None) => {
                let eps = check_positive("material.eps_j", require("material.eps_j", eps)?)?;
                let kappa =
                    check_positive("material.kappa_n_m", require("material.kappa_n_m", kappa)?)?;
                (eps / sigma_ref.powi(3), kappa / sigma_ref)
            }
            (None, None, gamma, lambda) => {
                let gamma =
                    check_positive("material.gamma_pa", require("material.gamma_pa", gamma)?)?;
                let lambda =
                    check_positive("material.lambda_pa", require("material.lambda_pa", lambda)?)?;
                (gamma, lambda)
            }
            _ => {
                return Err(EngineError::Conflict(
                    "give material.eps_j and material.kappa_n_m, or material.gamma_pa and \
                     material.lambda_pa, not a mix"
                        .into(),
                ))
            }
        };
        let (eps, kappa) = if m.sizing {
            (gamma * sigma.powi(3), lambda * sigma)
        } else {
            // Without sizing the reference values are used at any sigma (Fig. 4, top panel).
            (gamma * sigma_ref.powi(3), lambda * sigma_ref)
        };
        let interaction = Interaction::new(sigma, eps, kappa, rcut_over_sigma * sigma, m.contact);

        // Lay out the bodies.
        let mut layout = lay_out(geometry, r_eq)?;
        let n_imp = layout.count(Body::Impactor);
        let n_tgt = layout.count(Body::Target);
        let (vol_imp, vol_tgt) = match *geometry {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                width_over_d,
                ..
            } => (
                std::f64::consts::PI / 6.0 * diameter_m.powi(3),
                (width_over_d * diameter_m).powi(2) * t_over_d * diameter_m,
            ),
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                width_m,
                ..
            } => (
                width_m * width_m * flyer_thickness_m,
                width_m * width_m * target_thickness_m,
            ),
        };
        let mass_imp = density * vol_imp / n_imp as f64;
        let mass_tgt = density * vol_tgt / n_tgt as f64;

        // Time step and its stability bound.
        let run = &self.run;
        check_positive("run.end_time_s", run.end_time_s)?;
        check_range("run.dt_factor", run.dt_factor, 0.0, true, 1e3, false)?;
        check_range(
            "run.thermal_ratio",
            run.thermal_ratio,
            0.0,
            false,
            0.1,
            false,
        )?;
        check_range(
            "run.skin_over_sigma",
            run.skin_over_sigma,
            0.0,
            true,
            2.0,
            false,
        )?;
        let b = run.frame_block_over_sigma;
        if !(b == 0.0 || (2.0..=1e3).contains(&b)) {
            return Err(EngineError::invalid(
                "run.frame_block_over_sigma",
                b,
                "0 (off) or a number in [2, 1000]",
            ));
        }
        if !(1..=MAX_STRIDE).contains(&run.max_stride) {
            return Err(EngineError::invalid(
                "run.max_stride",
                run.max_stride.to_string(),
                format!("a whole number from 1 to {MAX_STRIDE} (1: a fixed step)"),
            ));
        }
        check_range(
            "run.stride_displacement_over_sigma",
            run.stride_displacement_over_sigma,
            0.0,
            true,
            MAX_STRIDE_DISPLACEMENT_OVER_SIGMA,
            false,
        )?;
        if run.energy_every == 0 {
            return Err(EngineError::invalid(
                "run.energy_every",
                0,
                "an integer >= 1",
            ));
        }
        check_range(
            "run.max_energy_drift",
            run.max_energy_drift,
            0.0,
            true,
            f64::INFINITY,
            false,
        )?;
        check_range(
            "run.min_distance_over_sigma",
            run.min_distance_over_sigma,
            0.0,
            false,
            1.0,
            true,
        )?;
        check_range(
            "run.cutoff_min_tau_s",
            run.cutoff_min_tau_s,
            0.0,
            false,
            f64::INFINITY,
            true,
        )?;
        check_range(
            "run.cutoff_quiet_s",
            run.cutoff_quiet_s,
            0.0,
            true,
            f64::INFINITY,
            true,
        )?;
        check_range(
            "run.cutoff_break_fraction",
            run.cutoff_break_fraction,
            0.0,
            false,
            1.0,
            false,
        )?;
        self.analysis.validate(run.end_time_s)?;
        let stiffness = kappa.max(interaction.contact_stiffness_at_r_eq());
        let dt_max = (MAX_STEP_DISPLACEMENT_OVER_SIGMA * sigma / v0)
            .min(MAX_STEP_OVER_SQRT_M_K * (mass_imp.min(mass_tgt) / stiffness).sqrt());
        // "auto" never exceeds AUTO_STEP_SAFETY of the bound (fast impacts, stiff springs); a
        // fixed step beyond the bound is refused.
        let dt = match (run.dt_over_bound, run.dt_s) {
            (Some(f), _) => check_range("run.dt_over_bound", f, 0.0, true, 8.0, false)? * dt_max,
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

        // Standoff shifts the impactor back; first contact happens at standoff / v0.
        if standoff < 0.0 {
            // Check the actual closest distance: a negative standoff overlaps the bodies.
            layout.shift_impactor(-standoff);
            let d = layout.closest_impactor_target_distance();
            return Err(EngineError::Overlap {
                distance_m: d,
                r_eq_m: r_eq,
            });
        }
        layout.shift_impactor(-standoff);
        let closest = layout.closest_impactor_target_distance();
        if closest < r_eq * (1.0 - 1e-9) {
            return Err(EngineError::Overlap {
                distance_m: closest,
                r_eq_m: r_eq,
            });
        }

        let steps = ((run.end_time_s + standoff / v0) / dt).ceil() as u64;
        let derived = Derived {
            sigma_m: sigma,
            sigma_ref_m: sigma_ref,
            r_eq_m: r_eq,
            gamma_pa: gamma,
            lambda_pa: lambda,
            eps_j: eps,
            kappa_n_m: kappa,
            rcut_m: interaction.rcut_m,
            mass_impactor_kg: mass_imp,
            mass_target_kg: mass_tgt,
            density_kg_m3: density,
            dt_s: dt,
            dt_max_s: dt_max,
            v0_m_s: v0,
            plate_rear_z_m: layout.plate_rear_z,
            plate_front_z_m: 0.0,
            contact_time_s: standoff / v0,
            steps,
        };
        let particles = layout.into_particles(mass_imp, mass_tgt, v0, run.thermal_ratio, run.seed);
        let rim_ids = rim_ids(&particles, r_eq);
        Ok(Setup {
            spec: self.clone(),
            derived,
            interaction,
            particles,
            rim_ids,
        })
    }
}

/// Lattice sites of both bodies with integer coordinates, before masses and velocities.
struct Layout {
    /// Integer lattice coordinates of each site.
    sites: Vec<[i32; 3]>,
    body: Vec<Body>,
    r_eq: f64,
    /// Lateral offset (0 or 1/2 r_eq) so that the lattice is symmetric about the impact axis.
    lateral_offset: f64,
    /// z shift of the impactor sites, m.
    impactor_z_shift: f64,
    plate_rear_z: f64,
}

impl Layout {
    fn count(&self, b: Body) -> usize {
        self.body.iter().filter(|&&x| x == b).count()
    }

    fn position(&self, k: usize) -> DVec3 {
        let [i, j, l] = self.sites[k];
        let mut p = DVec3::new(
            (i as f64 + self.lateral_offset) * self.r_eq,
            (j as f64 + self.lateral_offset) * self.r_eq,
            (l as f64 + 0.5) * self.r_eq,
        );
        if self.body[k] == Body::Impactor {
            p.z += self.impactor_z_shift;
        }
        p
    }

    fn shift_impactor(&mut self, dz: f64) {
        self.impactor_z_shift -= dz;
    }

    /// Closest distance between an impactor and a target site (the impactor's leading layer
    /// against the target's front layer; both lattices are aligned laterally).
    fn closest_impactor_target_distance(&self) -> f64 {
        let lead = (0..self.sites.len())
            .filter(|&k| self.body[k] == Body::Impactor)
            .map(|k| self.position(k).z)
            .fold(f64::NEG_INFINITY, f64::max);
        let front = (0..self.sites.len())
            .filter(|&k| self.body[k] == Body::Target)
            .map(|k| self.position(k).z)
            .fold(f64::INFINITY, f64::min);
        front - lead
    }

    fn into_particles(
        self,
        mass_imp: f64,
        mass_tgt: f64,
        v0: f64,
        thermal: f64,
        seed: u64,
    ) -> Particles {
        let n = self.sites.len();
        let pos: Vec<DVec3> = (0..n).map(|k| self.position(k)).collect();
        // Bonds: lattice nearest neighbours of the same body, found through a dense index grid.
        let lo = self.sites.iter().fold([i32::MAX; 3], |a, s| {
            [a[0].min(s[0]), a[1].min(s[1]), a[2].min(s[2])]
        });
        let hi = self.sites.iter().fold([i32::MIN; 3], |a, s| {
            [a[0].max(s[0]), a[1].max(s[1]), a[2].max(s[2])]
        });
        let dim = [
            (hi[0] - lo[0] + 1) as usize,
            (hi[1] - lo[1] + 1) as usize,
            (hi[2] - lo[2] + 1) as usize,
        ];
        let cell = |s: [i32; 3]| -> Option<usize> {
            if (0..3).any(|a| s[a] < lo[a] || s[a] > hi[a]) {
                return None;
            }
            Some(
                ((s[2] - lo[2]) as usize * dim[1] + (s[1] - lo[1]) as usize) * dim[0]
                    + (s[0] - lo[0]) as usize,
            )
        };
        let mut grid = vec![NO_BOND; dim[0] * dim[1] * dim[2]];
        for (k, &s) in self.sites.iter().enumerate() {
            if let Some(c) = cell(s) {
                grid[c] = k as u32;
            }
        }
        const DIRS: [[i32; 3]; BONDS_PER_PARTICLE] = [
            [1, 0, 0],
            [-1, 0, 0],
            [0, 1, 0],
            [0, -1, 0],
            [0, 0, 1],
            [0, 0, -1],
        ];
        let mut bonds = vec![NO_BOND; n * BONDS_PER_PARTICLE];
        for (k, &s) in self.sites.iter().enumerate() {
            for (slot, d) in DIRS.iter().enumerate() {
                let t = [s[0] + d[0], s[1] + d[1], s[2] + d[2]];
                if let Some(c) = cell(t) {
                    let other = grid[c];
                    if other != NO_BOND && self.body[other as usize] == self.body[k] {
                        bonds[k * BONDS_PER_PARTICLE + slot] = other;
                    }
                }
            }
        }
        // Thermal velocities: Gaussian per component, counter-based on (seed, particle, axis),
        // with each body's mean removed so the impactor moves at exactly v0.
        let sd = thermal * v0;
        let mut vel: Vec<DVec3> = (0..n)
            .map(|k| {
                DVec3::new(
                    rng::normal(seed, k as u64, 0),
                    rng::normal(seed, k as u64, 1),
                    rng::normal(seed, k as u64, 2),
                ) * sd
            })
            .collect();
        for b in [Body::Impactor, Body::Target] {
            let members: Vec<usize> = (0..n).filter(|&k| self.body[k] == b).collect();
            if members.is_empty() {
                continue;
            }
            let mean = members.iter().fold(DVec3::ZERO, |a, &k| a + vel[k]) / members.len() as f64;
            let drift = if b == Body::Impactor {
                DVec3::new(0.0, 0.0, v0)
            } else {
                DVec3::ZERO
            };
            for &k in &members {
                vel[k] = vel[k] - mean + drift;
            }
        }
        let mass: Vec<f64> = self
            .body
            .iter()
            .map(|b| {
                if *b == Body::Impactor {
                    mass_imp
                } else {
                    mass_tgt
                }
            })
            .collect();
        Particles::new(pos, vel, mass, self.body, bonds)
    }
}

fn lay_out(geometry: &Geometry, r_eq: f64) -> Result<Layout> {
    let mut sites = Vec::new();
    let mut body = Vec::new();
    match *geometry {
        Geometry::SphereOnPlate {
            diameter_m,
            t_over_d,
            width_over_d,
            ..
        } => {
            let t = t_over_d * diameter_m;
            let nz = (t / r_eq).round() as i64;
            if nz < 1 {
                return Err(EngineError::invalid(
                    "scene.t_over_d",
                    t_over_d,
                    format!(
                        "a plate at least one particle thick: t/D >= {:.4} at this resolution \
                         (r_eq = {r_eq:.3e} m); raise the resolution or t/D",
                        0.5 * r_eq / diameter_m
                    ),
                ));
            }
            let nxy = ((width_over_d * diameter_m / r_eq).round() as i64).max(1);
            let nsphere = diameter_m / r_eq;
            if nsphere < 1.0 {
                return Err(EngineError::invalid(
                    "resolution",
                    format!("r_eq = {r_eq:.3e} m"),
                    "at least one particle across the sphere diameter",
                ));
            }
            check_range(
                "resolution (total sites)",
                (nxy * nxy * nz) as f64,
                1.0,
                false,
                5e8,
                false,
            )?;
            // Symmetric about the axis: sites at integer (nxy odd) or half-integer (even) offsets.
            let lateral_offset = if nxy % 2 == 1 { 0.0 } else { 0.5 };
            let half = nxy / 2;
            let (ilo, ihi) = if nxy % 2 == 1 {
                (-half, half)
            } else {
                (-half, half - 1)
            };
            for k in 0..nz {
                for j in ilo..=ihi {
                    for i in ilo..=ihi {
                        sites.push([i as i32, j as i32, k as i32]);
                        body.push(Body::Target);
                    }
                }
            }
            // Sphere sites on the plate's lattice, symmetric about the sphere's centre in all
            // three directions, then shifted by whole lattice steps to touch the plate.
            let radius = 0.5 * diameter_m;
            let m = (radius / r_eq).ceil() as i64 + 1;
            let mut sphere = Vec::new();
            for l in -m..=m {
                for j in -m..=m {
                    for i in -m..=m {
                        let x = (i as f64 + lateral_offset) * r_eq;
                        let y = (j as f64 + lateral_offset) * r_eq;
                        let z = (l as f64 + lateral_offset) * r_eq;
                        if x * x + y * y + z * z <= radius * radius {
                            sphere.push([i as i32, j as i32, l as i32]);
                        }
                    }
                }
            }
            if sphere.is_empty() {
                return Err(EngineError::invalid(
                    "resolution",
                    format!("r_eq = {r_eq:.3e} m"),
                    "a resolution that puts at least one site inside the sphere",
                ));
            }
            // Shift the sphere's integer z so that its leading layer sits at l = -1 (one lattice
            // spacing in front of the plate's first layer at l = 0): contact starts at t = 0.
            let lead = sphere.iter().map(|s| s[2]).max().unwrap_or(0);
            for s in &mut sphere {
                s[2] -= lead + 1;
            }
            for s in sphere {
                sites.push(s);
                body.push(Body::Impactor);
            }
            Ok(Layout {
                sites,
                body,
                r_eq,
                lateral_offset,
                impactor_z_shift: 0.0,
                plate_rear_z: nz as f64 * r_eq,
            })
        }
        Geometry::FlyerPlate {
            flyer_thickness_m,
            target_thickness_m,
            width_m,
            ..
        } => {
            let nt = (target_thickness_m / r_eq).round() as i64;
            let nf = (flyer_thickness_m / r_eq).round() as i64;
            if nt < 1 {
                return Err(EngineError::invalid(
                    "scene.target_thickness_m",
                    target_thickness_m,
                    format!(
                        ">= {:.3e} m (one particle at r_eq = {r_eq:.3e} m)",
                        0.5 * r_eq
                    ),
                ));
            }
            if nf < 1 {
                return Err(EngineError::invalid(
                    "scene.flyer_thickness_m",
                    flyer_thickness_m,
                    format!(
                        ">= {:.3e} m (one particle at r_eq = {r_eq:.3e} m)",
                        0.5 * r_eq
                    ),
                ));
            }
            let nxy = ((width_m / r_eq).round() as i64).max(1);
            check_range(
                "resolution (total sites)",
                (nxy * nxy * (nt + nf)) as f64,
                1.0,
                false,
                5e8,
                false,
            )?;
            let lateral_offset = if nxy % 2 == 1 { 0.0 } else { 0.5 };
            let half = nxy / 2;
            let (ilo, ihi) = if nxy % 2 == 1 {
                (-half, half)
            } else {
                (-half, half - 1)
            };
            for k in -nf..nt {
                for j in ilo..=ihi {
                    for i in ilo..=ihi {
                        sites.push([i as i32, j as i32, k as i32]);
                        body.push(if k < 0 { Body::Impactor } else { Body::Target });
                    }
                }
            }
            Ok(Layout {
                sites,
                body,
                r_eq,
                lateral_offset,
                impactor_z_shift: 0.0,
                plate_rear_z: nt as f64 * r_eq,
            })
        }
    }
}

/// Ids of target particles on the plate's lateral rim (outermost lattice ring) at t = 0.
fn rim_ids(p: &Particles, r_eq: f64) -> Vec<u32> {
    let mut max_x: f64 = 0.0;
    for k in 0..p.len() {
        if p.body[k] == Body::Target {
            max_x = max_x.max(p.pos[k].x.abs()).max(p.pos[k].y.abs());
        }
    }
    (0..p.len())
        .filter(|&k| {
            p.body[k] == Body::Target
                && (p.pos[k].x.abs().max(p.pos[k].y.abs()) > max_x - 0.5 * r_eq)
        })
        .map(|k| p.id[k])
        .collect()
}
