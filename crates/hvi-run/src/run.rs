//! One run of one scene: the engine stepped to the end time, with the energy ledger sampled,
//! the debris cloud observed (`hvi_engine::cloud`: the track, the two front times, the full
//! measurement at the end), optional snapshots and pictures, progress, and `summary.json`,
//! `energy.csv`, `cloud_track.csv`, `fragments.csv`, `craters.csv` and the cloud's kept state
//! `state.bin` ([`crate::state`]) written atomically.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::progress::{Bar, Unit};
use hvi_engine::cloud::{
    first_step_at_or_after, size_distribution, step_at_tau, CloudObserver, CloudReport,
    CloudResult, ObserverState, TrackRow,
};
use hvi_engine::scene::{Derived, RunSettings, SceneSpec};
use hvi_engine::sim::{Energy, SimState, Simulation, Timing};
use hvi_engine::EngineError;
use serde::{Deserialize, Serialize};

use crate::checkpoint::{self, CheckpointOptions, Every, Found};
use crate::error::{Result, ResultExt, RunError};
use crate::output::{
    write_atomic_bytes, write_csv_atomic, write_lammps_data, DumpFormat, Trajectory,
    TrajectoryState,
};
use crate::screen::{screen_step, ScreenReport};
use hvi_analysis::observable::{Observable, Observables};
use hvi_plot::render::{self, Frame, SceneInfo};

/// How to run and what to write besides the summary.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Output directory (created if missing).
    pub out_dir: PathBuf,
    /// Dump the state at t = 0, at the first step at or after every this many base steps, and
    /// at the end ([`crate::output::Trajectory`]).
    pub dump_every: Option<u64>,
    /// The files the dumps go to.
    pub dump_format: DumpFormat,
    /// Write the initial state as a LAMMPS data file here.
    pub lammps_data: Option<PathBuf>,
    /// Write the scene as a runnable LAMMPS input into this directory
    /// ([`crate::lammps::write_lammps_input`]).
    pub lammps_dir: Option<PathBuf>,
    /// Show a progress bar and thermo lines on stderr.
    pub progress: bool,
    /// Write pictures: the cloud's side view at the end, the 3-D series at
    /// `analysis.render_times_s`, the fragment histogram and the cloud track.
    pub render: bool,
    /// Write checkpoints there, this often, and resume from one left by the same run
    /// ([`crate::checkpoint`]); `None`: neither.
    pub checkpoint: Option<CheckpointOptions>,
    /// Keep [`PROGRESS_FILE`] in the output directory up to date (every
    /// [`PROGRESS_EVERY`] of wall time), for `hvi-study status` to read while the run goes.
    pub progress_file: bool,
    /// Keep the run's continuation here: its state at the last landing before the first
    /// sample it takes only because it ends where it does (the end, or the default front
    /// times of a run shorter than 32 us; `CloudObserver::first_end_dependent_step`), in the
    /// checkpoint format under [`continuation_key`]. Every landing before that point a run of
    /// the same scene to a later end makes too, so that run can start from it
    /// ([`Self::extend`]) and end bit-identical to one made in one go.
    pub continuation: Option<PathBuf>,
    /// Start from the continuation at [`Self::continuation`] (left by this scene run to an
    /// earlier end), not from t = 0, unless a checkpoint of this very run is there to resume.
    /// An error, before anything is written, when it cannot: no continuation, one of another
    /// scene, flags or version, or one that lies past this run's first end-dependent sample.
    pub extend: bool,
}

/// A running run's progress, in its output directory when [`RunOptions::progress_file`].
pub const PROGRESS_FILE: &str = "progress.json";

/// How often [`PROGRESS_FILE`] is rewritten, wall time.
pub const PROGRESS_EVERY: Duration = Duration::from_secs(5);

/// What [`PROGRESS_FILE`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Base steps taken of the run's `steps`.
    pub step: u64,
    /// The run's base steps.
    pub steps: u64,
    /// Simulated time reached, s.
    pub time_s: f64,
    /// The run's end time, s.
    pub end_time_s: f64,
    /// Wall time in the step loop so far (this process), s.
    pub wall_s: f64,
}

impl Progress {
    /// Reads a run directory's progress file (None: none, or unreadable mid-write).
    pub fn read(dir: &Path) -> Option<Progress> {
        let text = std::fs::read_to_string(dir.join(PROGRESS_FILE)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// `43 % (13.8 of 32 us simulated, 2.1 min so far)`.
    pub fn describe(&self) -> String {
        let pct = 100.0 * self.step as f64 / self.steps.max(1) as f64;
        format!(
            "{pct:.0} % ({:.1} of {:.1} us simulated, {} so far)",
            self.time_s * 1e6,
            self.end_time_s * 1e6,
            hvi_analysis::number::fmt_duration(self.wall_s)
        )
    }
}

/// One row of `energy.csv`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EnergyRow {
    /// Simulated time since t = 0, s.
    pub time_s: f64,
    /// Time since first contact, s.
    pub tau_s: f64,
    /// Kinetic energy, J.
    pub kinetic_j: f64,
    /// Contact energy, J.
    pub contact_j: f64,
    /// Bond energy, J.
    pub bond_j: f64,
    /// Broken-bond energy, J.
    pub broken_j: f64,
    /// Energy the absorbing band took out (`run.absorbing_band_over_d`; 0 without one), J.
    #[serde(default)]
    pub absorbed_j: f64,
    /// Sum of the five, J.
    pub total_j: f64,
    /// Bonds broken so far.
    pub bonds_broken: u64,
    /// The step in use, s (the base step times the adaptive stride).
    pub dt_s: f64,
}

/// A number of `summary.json` read back: JSON writes a non-finite number as `null` (a run that
/// blew up), which reads back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Option::<f64>::deserialize(d).map(|v| v.unwrap_or(f64::NAN))
}

/// A vector of `summary.json` read back, each `null` component as NaN.
fn nan_if_null_3<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<[f64; 3], D::Error> {
    <[Option<f64>; 3]>::deserialize(d).map(|v| v.map(|x| x.unwrap_or(f64::NAN)))
}

/// The energy block of `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EnergySummary {
    /// Final kinetic energy, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub kinetic_j: f64,
    /// Final contact energy, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub contact_j: f64,
    /// Final bond energy, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub bond_j: f64,
    /// Final broken-bond energy, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub broken_j: f64,
    /// Energy the absorbing band took out by the end, J (0 without one).
    #[serde(default)]
    pub absorbed_j: f64,
    /// Ledger total at t = 0, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub total_initial_j: f64,
    /// Ledger total at the end, J.
    #[serde(deserialize_with = "nan_if_null")]
    pub total_final_j: f64,
    /// (final - initial) / initial.
    #[serde(deserialize_with = "nan_if_null")]
    pub relative_drift: f64,
    /// Largest |drift| over all samples.
    #[serde(deserialize_with = "nan_if_null")]
    pub max_abs_relative_drift: f64,
}

/// The momentum block of `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MomentumSummary {
    /// Total momentum at t = 0, kg m/s.
    #[serde(deserialize_with = "nan_if_null_3")]
    pub initial_kg_m_s: [f64; 3],
    /// Total momentum at the end, kg m/s.
    #[serde(deserialize_with = "nan_if_null_3")]
    pub final_kg_m_s: [f64; 3],
    /// |final - initial| / (M v0), the round-off measure.
    #[serde(deserialize_with = "nan_if_null")]
    pub relative_change: f64,
}

/// Seconds per phase.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TimingSummary {
    /// Contact repulsion.
    pub contact_s: f64,
    /// Bonds.
    pub bonds_s: f64,
    /// Neighbour-list builds.
    pub neighbour_s: f64,
    /// Integration.
    pub integrate_s: f64,
    /// Energy samples.
    pub energy_s: f64,
    /// Cloud observation: track samples, front times, the final measurement.
    pub analysis_s: f64,
    /// Pictures (`--render`).
    pub render_s: f64,
    /// Files and progress.
    pub output_s: f64,
    /// Everything else (set-up).
    pub other_s: f64,
}

/// A run directory's `summary.json` ([`run_scene`]), if it has one this version reads.
pub fn read_summary(run_dir: &Path) -> Option<Summary> {
    let text = std::fs::read_to_string(run_dir.join("summary.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// "completed" or "unstable".
    pub status: String,
    /// The diagnostic when not completed.
    pub error: Option<String>,
    /// hvi-study version.
    pub engine_version: String,
    /// Particles of the scene.
    pub particles: usize,
    /// Particles simulated: all of them, or a quarter under `run.symmetry = "quarter"` (the
    /// others are their mirror images).
    #[serde(default)]
    pub particles_simulated: usize,
    /// Impactor particles.
    pub particles_impactor: usize,
    /// Target particles.
    pub particles_target: usize,
    /// Intact bonds at t = 0.
    pub bonds_initial: u64,
    /// Bonds broken by the end.
    pub bonds_broken: u64,
    /// Steps taken (force evaluations).
    pub steps: u64,
    /// Time reached in base steps (`dt_s`); more than `steps` when the adaptive step strode.
    pub base_steps: u64,
    /// Base time step, s (the step of the impact; the adaptive step takes multiples of it).
    pub dt_s: f64,
    /// Largest step taken, s.
    #[serde(deserialize_with = "nan_if_null")]
    pub dt_largest_s: f64,
    /// Simulated time reached, s.
    #[serde(deserialize_with = "nan_if_null")]
    pub time_s: f64,
    /// Time since first contact reached, s.
    #[serde(deserialize_with = "nan_if_null")]
    pub tau_s: f64,
    /// Particle diameter, m.
    pub sigma_m: f64,
    /// Wall time of the whole run, s.
    #[serde(deserialize_with = "nan_if_null")]
    pub wall_seconds: f64,
    /// Simulated particles times steps over the stepping wall time.
    #[serde(deserialize_with = "nan_if_null")]
    pub particle_steps_per_second: f64,
    /// Threads used.
    pub threads: usize,
    /// The instruction set the engine's kernels ran with (`baseline` or `avx2`, chosen at
    /// run time: `hvi_engine::simd`); results do not depend on it.
    #[serde(default)]
    pub kernels_isa: String,
    /// Neighbour-list builds.
    pub neighbour_builds: u64,
    /// Measurements of the interacting pairs' speed between builds (the adaptive step's).
    #[serde(default)]
    pub speed_refreshes: u64,
    /// How often each bound of the adaptive step set the stride (all zero at a fixed step).
    pub stride_limits: hvi_engine::sim::StrideLimits,
    /// Time since first contact at which free flight began, by the ballistic cut-off's gate or
    /// at `run.free_flight_after_s`, s (null when it did not).
    pub ballistic_cutoff_tau_s: Option<f64>,
    /// What the screen measured (`run.screen_after_s`, [`crate::screen`]); absent when the
    /// scene has no screen or the run ended before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen: Option<ScreenReport>,
    /// Energy ledger.
    pub energy: EnergySummary,
    /// Momentum.
    pub momentum: MomentumSummary,
    /// Derived numbers (sigma, sigma_ref, gamma, lambda, masses, dt...).
    pub derived: Derived,
    /// Time per phase.
    pub timing: TimingSummary,
    /// The debris cloud at the analysis time (the end of the run), when the scene asks for it
    /// (`analysis.cloud`) and the run completed; definitions in `hvi_engine::cloud`.
    pub cloud: Option<CloudReport>,
    /// The scene as run (after overrides).
    pub scene: SceneSpec,
    /// The fingerprint of the stored run whose kept state this run's cloud was measured from,
    /// when a study's store measured it rather than simulated it (the run store, crate hvi-store): every
    /// number but the cloud's is that run's simulation. Absent for a simulated run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_from: Option<String>,
}

impl Summary {
    /// The run's observables: the debris cloud's (from `cloud`, `None` without one) and the
    /// run's health numbers. One arm per observable, so a new one cannot be forgotten.
    pub fn observables(&self) -> Observables {
        let cloud = self.cloud.as_ref();
        let m = cloud.map(|c| &c.measurement);
        let sil = cloud.and_then(|c| c.silhouette.as_ref());
        let wit = cloud.and_then(|c| c.witness_plate.as_ref());
        let count = |n: usize| n as f64;
        let mut o = Observables::default();
        for k in Observable::ALL {
            let value = match k {
                Observable::Particles => Some(count(self.particles)),
                Observable::Fragmentation => m.and_then(|m| m.fragmentation),
                Observable::NPart => m.map(|m| count(m.n_part)),
                Observable::NFrag => m.map(|m| count(m.n_frag)),
                Observable::LengthAxial => m.and_then(|m| m.length_axial_m),
                Observable::LengthRadial => m.and_then(|m| m.length_radial_m),
                Observable::LengthRatio => m.and_then(|m| m.length_ratio),
                Observable::LengthRadialSide => m.and_then(|m| m.length_radial_side_m),
                Observable::LengthRatioSide => m.and_then(|m| m.length_ratio_side),
                Observable::LengthRadialCylindrical => {
                    m.and_then(|m| m.length_radial_cylindrical_m)
                }
                Observable::LengthRatioCylindrical => m.and_then(|m| m.length_ratio_cylindrical),
                Observable::FrontVelocity => cloud.and_then(|c| c.front_velocity_m_s),
                Observable::FrontVelocityRatio => cloud.and_then(|c| c.front_velocity_ratio),
                Observable::LargestFragmentMassFraction => {
                    m.and_then(|m| m.largest_fragment_mass_fraction)
                }
                Observable::ImpactorLargestFragmentMassFraction => {
                    m.and_then(|m| m.impactor_largest_fragment_mass_fraction)
                }
                Observable::ImpactorIntactMassFraction => {
                    m.and_then(|m| m.impactor_intact_mass_fraction)
                }
                Observable::LargestFragmentDiameter => {
                    m.and_then(|m| m.largest_fragment_diameter_m)
                }
                Observable::MeanFragmentDiameter => m.and_then(|m| m.mean_fragment_diameter_m),
                Observable::Tau => m.map(|m| m.tau_s),
                Observable::BondsBrokenFraction => (self.bonds_initial > 0)
                    .then(|| self.bonds_broken as f64 / self.bonds_initial as f64),
                Observable::EnergyRelativeDrift => Some(self.energy.relative_drift),
                Observable::LengthAxialSilhouette => sil.and_then(|s| s.length_axial_m),
                Observable::LengthRadialSilhouette => sil.and_then(|s| s.length_radial_m),
                Observable::LengthRatioSilhouette => sil.and_then(|s| s.length_ratio),
                Observable::FrontVelocityRatioSilhouette => {
                    sil.and_then(|s| s.front_velocity_ratio)
                }
                Observable::CraterCount => wit.map(|w| count(w.crater_count)),
                Observable::CraterDiameterMedian => wit.and_then(|w| w.crater_diameter_median_m),
                Observable::CraterDiameterMax => wit.and_then(|w| w.crater_diameter_max_m),
                Observable::CentralCraterDiameter => wit.and_then(|w| w.central_crater_diameter_m),
                Observable::LargeCentralCrater => {
                    wit.map(|w| if w.large_central_crater { 1.0 } else { 0.0 })
                }
                Observable::Screened => self.screen.map(|s| if s.free_flight { 1.0 } else { 0.0 }),
            };
            o.set(k, value);
        }
        o
    }
}

/// What a run returns: its summary, and the error if it stopped early.
pub struct RunOutcome {
    /// The written summary.
    pub summary: Summary,
    /// The energy series.
    pub energy: Vec<EnergyRow>,
    /// Final state (for analysis by the caller).
    pub sim: Simulation,
    /// The cloud track.
    pub track: Vec<TrackRow>,
    /// The full cloud measurement with every fragment and the labels by id.
    pub cloud: Option<CloudResult>,
    /// The base step of the checkpoint the run resumed from, if it did.
    pub resumed_from_step: Option<u64>,
}

fn row(sim: &Simulation, e: &Energy) -> EnergyRow {
    EnergyRow {
        time_s: sim.time_s(),
        tau_s: sim.tau_s(),
        kinetic_j: e.kinetic_j,
        contact_j: e.contact_j,
        bond_j: e.bond_j,
        broken_j: e.broken_j,
        absorbed_j: e.absorbed_j,
        total_j: e.total_j(),
        bonds_broken: sim.bonds_broken,
        dt_s: sim.dt * sim.stride as f64,
    }
}

/// The lines every run prints about its resolution and parameters.
pub fn describe(d: &Derived, particles: usize, bonds: u64) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "particles {particles}, bonds {bonds}, steps {}", d.steps);
    let _ = writeln!(
        s,
        "sigma = {:.4e} m (sigma_ref = {:.4e} m, r_eq = {:.4e} m), m = {:.4e} kg (impactor) / {:.4e} kg (target)",
        d.sigma_m, d.sigma_ref_m, d.r_eq_m, d.mass_impactor_kg, d.mass_target_kg
    );
    let _ = writeln!(
        s,
        "eps = {:.4e} J, kappa = {:.4e} N/m at this sigma; gamma = {:.4e} Pa, lambda = {:.4e} Pa; rcut = {:.4e} m",
        d.eps_j, d.kappa_n_m, d.gamma_pa, d.lambda_pa, d.rcut_m
    );
    if let Some(i) = &d.impactor {
        let _ = writeln!(
            s,
            "impactor: density {} kg/m^3, eps = {:.4e} J, kappa = {:.4e} N/m, rcut = {:.4e} m; \
             plate density {} kg/m^3; contact between them eps = {:.4e} J",
            i.density_kg_m3, i.eps_j, i.kappa_n_m, i.rcut_m, d.density_kg_m3, i.cross_eps_j
        );
    }
    let _ = write!(
        s,
        "dt = {:.4e} s (stability bound {:.4e} s), v0 = {} m/s",
        d.dt_s, d.dt_max_s, d.v0_m_s
    );
    s
}

fn timing_table(
    t: &Timing,
    analysis: Duration,
    render: Duration,
    output: Duration,
    total: Duration,
) -> (TimingSummary, String) {
    let secs = |d: Duration| d.as_secs_f64();
    let accounted =
        t.contact + t.bonds + t.neighbour + t.integrate + t.energy + analysis + render + output;
    let other = total.saturating_sub(accounted);
    let ts = TimingSummary {
        contact_s: secs(t.contact),
        bonds_s: secs(t.bonds),
        neighbour_s: secs(t.neighbour),
        integrate_s: secs(t.integrate),
        energy_s: secs(t.energy),
        analysis_s: secs(analysis),
        render_s: secs(render),
        output_s: secs(output),
        other_s: secs(other),
    };
    let mut s = String::from("Section   |  time (s)  | %total\n----------+------------+-------\n");
    let tot = secs(total).max(1e-12);
    for (name, v) in [
        ("Contact", ts.contact_s),
        ("Bond", ts.bonds_s),
        ("Neigh", ts.neighbour_s),
        ("Integrate", ts.integrate_s),
        ("Energy", ts.energy_s),
        ("Analysis", ts.analysis_s),
        ("Render", ts.render_s),
        ("Output", ts.output_s),
        ("Other", ts.other_s),
    ] {
        let _ = writeln!(s, "{name:<9} | {v:10.3} | {:5.1}", 100.0 * v / tot);
    }
    (ts, s)
}

/// Particle counts of a run.
#[derive(Debug, Clone, Copy)]
struct Counts {
    /// All particles of the scene.
    particles: usize,
    /// Particles simulated (a quarter of them under `run.symmetry = "quarter"`).
    simulated: usize,
    /// Impactor particles.
    impactor: usize,
}

/// Runs a scene to its end time, writing `summary.json`, `energy.csv` and the cloud files
/// (also when it stops early on an instability: the error comes back after the files are
/// written; the cloud is then not measured, its track is kept).
pub fn run_scene(spec: &SceneSpec, opts: &RunOptions) -> Result<RunOutcome> {
    let wall0 = Instant::now();
    let (mut sim, counts) = set_up(spec, opts)?;
    let d = sim.derived;
    let mut run = Gathered::begin(&mut sim, spec, opts, wall0)?;
    let step_wall = run.step_to_end(&mut sim, spec, opts, counts.simulated)?;
    let final_energy = final_energy_row(&mut run.rows, &mut sim, &d);
    let momentum = momentum_summary(&sim, &d);
    let (cloud, track, analysis_time) = run.finish_cloud(&sim);
    run.output_time += write_tables(&opts.out_dir, &run.rows, &track, cloud.as_ref())?;
    if opts.render && run.failure.is_none() {
        let frames = &run.frames;
        let n = counts.particles;
        run.render_time += render_pictures(spec, opts, &sim, n, frames, &track, cloud.as_ref())?;
    }
    let total = run.wall_before + wall0.elapsed();
    let (timing, table) = timing_table(
        &sim.timing,
        analysis_time,
        run.render_time,
        run.output_time,
        total,
    );
    let measured = Measured {
        energy: energy_summary(&final_energy, run.e0, run.max_drift),
        momentum,
        timing,
        wall: total,
        step_wall_s: step_wall,
        cloud: cloud.as_ref().map(|c| c.report.clone()),
        error: run.failure.as_ref().map(|e| e.to_string()),
        screen: run.screen,
    };
    let summary = summarise(spec, &sim, counts, measured);
    write_atomic_bytes(
        &opts.out_dir.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    if opts.progress {
        print_end(&summary, &sim, &table);
    }
    // The run has ended (completed or failed: both are results): its checkpoint is spent, and
    // a failed run has nothing to continue.
    if let Some(c) = &opts.checkpoint {
        checkpoint::remove(&c.path)?;
    }
    if let (Some(path), Some(_)) = (&opts.continuation, &run.failure) {
        checkpoint::remove(path)?;
    }
    if let Some(e) = run.failure {
        return Err(RunError::from(e).context(format!(
            "run stopped early; what it had is in {}",
            Path::new(&opts.out_dir).display()
        )));
    }
    Ok(RunOutcome {
        summary,
        energy: run.rows,
        sim,
        track,
        cloud,
        resumed_from_step: run.resumed_from,
    })
}

/// Creates the output directory and builds the scene's simulation; with progress on, prints
/// the derived numbers and the thread count.
fn set_up(spec: &SceneSpec, opts: &RunOptions) -> Result<(Simulation, Counts)> {
    std::fs::create_dir_all(&opts.out_dir).write_context(&opts.out_dir, || {
        format!("cannot create output directory {}", opts.out_dir.display())
    })?;
    let setup = spec.build()?;
    let n = setup.particles.len();
    let n_imp = setup
        .particles
        .body
        .iter()
        .filter(|b| **b == hvi_engine::state::Body::Impactor)
        .count();
    let sim = Simulation::new(setup)?;
    let copies = sim.symmetry.copies() as usize;
    if opts.progress {
        let full = sim.full_particle_count();
        log::info!("{}", describe(&sim.derived, full, sim.bonds_initial));
        if copies > 1 {
            log::info!("quarter symmetry: {n} particles simulated, with their mirror images");
        }
        log::info!(
            "threads {}, kernels {}",
            rayon::current_num_threads(),
            hvi_engine::simd::isa().name()
        );
    }
    if let Some(problem) = hvi_engine::simd::env_setting_problem() {
        log::warn!("{problem}");
    }
    let counts = Counts {
        particles: sim.full_particle_count(),
        simulated: n,
        impactor: copies * n_imp,
    };
    Ok((sim, counts))
}

/// The render times within the run as (step, time) pairs, by step (the nearest step to each
/// time, each step once); times beyond the end are skipped, with a note when rendering is asked
/// for and progress is on. They are the scene's own (`analysis.render_times_s`), so the adaptive
/// step lands on them whether or not frames are captured: asking for pictures never changes the
/// trajectory.
fn render_steps(spec: &SceneSpec, d: &Derived, opts: &RunOptions) -> Vec<(u64, f64)> {
    let end_tau = d.steps as f64 * d.dt_s - d.contact_time_s;
    let mut render_steps: Vec<(u64, f64)> = Vec::new();
    for &t in &spec.analysis.render_times_s {
        if t <= end_tau + 0.5 * d.dt_s {
            let s = step_at_tau(d, t);
            if !render_steps.iter().any(|&(x, _)| x == s) {
                render_steps.push((s, t));
            }
        } else if opts.render && opts.progress {
            log::info!(
                "render: tau = {:.2} us is beyond the end of the run ({:.2} us), skipped",
                t * 1e6,
                end_tau * 1e6
            );
        }
    }
    render_steps.sort_by_key(|&(s, _)| s);
    render_steps
}

/// The base step at which `run.free_flight_after_s` begins free flight (the first at or after
/// that time since first contact), if it is set.
fn free_flight_step(run: &RunSettings, d: &Derived) -> Option<u64> {
    run.free_flight_after_s
        .map(|t| first_step_at_or_after(d, t))
}

/// The first base step after `s` that is a multiple of `every`.
fn next_multiple(s: u64, every: u64) -> u64 {
    (s / every + 1).saturating_mul(every)
}

/// Whether base step `s` is a multiple of `every` (an output is due there).
// `u64::is_multiple_of` needs Rust 1.87; the workspace's rust-version is 1.80.
#[allow(clippy::manual_is_multiple_of)]
fn at_multiple(s: u64, every: u64) -> bool {
    s % every == 0
}

/// What a run gathers while it steps, besides the simulation's own state: the energy series
/// and its drift, the cloud observer, the frames to render, the dumps, the first failure, the
/// checkpoints and the time spent on files and pictures.
struct Gathered {
    /// The energy series, `energy.csv`.
    rows: Vec<EnergyRow>,
    /// Ledger total at t = 0, J.
    e0: f64,
    /// Largest |relative drift| of the samples so far.
    max_drift: f64,
    /// The cloud, observed as the scene's `[analysis]` asks (None when all is off).
    observer: Option<CloudObserver>,
    /// The scene's render steps (and times): the adaptive step lands on each.
    render_steps: Vec<(u64, f64)>,
    /// Whether a frame of the 3-D series is captured at each render step (`--render`).
    capture: bool,
    /// The captured frames.
    frames: Vec<Frame>,
    /// The dumps (`--dump-every`).
    trajectory: Option<Trajectory>,
    /// The base step at or after which the next dump is taken.
    next_dump: u64,
    /// Ballistic cut-off bookkeeping: broken-bond counts at the energy samples, (tau, count).
    break_history: Vec<(f64, u64)>,
    /// The instability that stopped the run.
    failure: Option<EngineError>,
    /// What the screen measured, once it has looked.
    screen: Option<ScreenReport>,
    /// Files and progress.
    output_time: Duration,
    /// Frame captures and pictures.
    render_time: Duration,
    /// Checkpoints, when the run writes them.
    checkpoint: Option<Checkpointer>,
    /// When this process started the run.
    wall0: Instant,
    /// Wall time of the run before the checkpoint it resumed from.
    wall_before: Duration,
    /// Wall time of the stepping loop before that checkpoint.
    loop_before: Duration,
    /// The base step of the checkpoint the run resumed from.
    resumed_from: Option<u64>,
    /// Where the run keeps its continuation, when it does.
    continuation: Option<Continuation>,
}

/// When a run writes its next checkpoint, and where.
struct Checkpointer {
    opts: CheckpointOptions,
    key: [u8; 32],
    /// Wall time of the last checkpoint (or of the start).
    since: Instant,
    /// With [`Every::Steps`]: the base step at or after which the next one is due.
    next_step: u64,
    /// The base step of the last checkpoint written or resumed from.
    last_step: Option<u64>,
}

/// What a checkpoint holds ([`crate::checkpoint`]): the simulation's state and everything the
/// run has gathered up to it.
#[derive(Serialize, Deserialize)]
struct Saved {
    sim: SimState,
    rows: Vec<EnergyRow>,
    max_drift: f64,
    observer: Option<ObserverState>,
    frames: Vec<Frame>,
    trajectory: Option<TrajectoryState>,
    next_dump: u64,
    break_history: Vec<(f64, u64)>,
    #[serde(default)]
    screen: Option<ScreenReport>,
    output_time: Duration,
    render_time: Duration,
    wall: Duration,
    loop_wall: Duration,
}

/// The key of a run's checkpoint ([`crate::checkpoint::key`]): the scene and the output
/// choices that shape what the run gathers (frames captured, dumps). A command compares it
/// with [`crate::checkpoint::key_of`] to know that a run will resume before it clears a
/// directory.
pub fn checkpoint_key(spec: &SceneSpec, opts: &RunOptions) -> Result<[u8; 32]> {
    Ok(state_key("scene", serde_json::to_value(spec)?, opts))
}

/// The key of a run's continuation ([`RunOptions::continuation`]): [`checkpoint_key`] with the
/// end time left out, so that the same scene run to another end time has the same one.
pub fn continuation_key(spec: &SceneSpec, opts: &RunOptions) -> Result<[u8; 32]> {
    let mut scene = serde_json::to_value(spec)?;
    if let Some(run) = scene.get_mut("run").and_then(|r| r.as_object_mut()) {
        run.remove("end_time_s");
    }
    Ok(state_key("continuation_of", scene, opts))
}

/// The key of a saved state: the scene (as JSON, under `label`) and the output choices that
/// shape what the run gathers.
fn state_key(label: &str, scene: serde_json::Value, opts: &RunOptions) -> [u8; 32] {
    let mut what = serde_json::json!({
        "render": opts.render,
        "dump_every": opts.dump_every,
        "dump_format": format!("{:?}", opts.dump_format),
    });
    what[label] = scene;
    checkpoint::key(&what)
}

/// Where a run keeps its continuation, and the base step it must be written before.
struct Continuation {
    path: PathBuf,
    key: [u8; 32],
    /// The run's first end-dependent landing ([`RunOptions::continuation`]).
    before: u64,
    /// Written by this process.
    written: bool,
}

impl Gathered {
    /// Nothing gathered yet: the series empty, the observer and the schedules set up.
    fn new(sim: &Simulation, spec: &SceneSpec, opts: &RunOptions, wall0: Instant) -> Self {
        let analysis = &spec.analysis;
        Gathered {
            rows: Vec::new(),
            e0: sim.energy_initial.total_j(),
            max_drift: 0.0,
            observer: (analysis.cloud || analysis.track_every > 0)
                .then(|| CloudObserver::new(sim, analysis, spec.run.end_time_s)),
            render_steps: render_steps(spec, &sim.derived, opts),
            capture: opts.render,
            frames: Vec::new(),
            trajectory: None,
            next_dump: opts.dump_every.unwrap_or(u64::MAX),
            break_history: Vec::new(),
            failure: None,
            screen: None,
            output_time: Duration::ZERO,
            render_time: Duration::ZERO,
            checkpoint: None,
            wall0,
            wall_before: Duration::ZERO,
            loop_before: Duration::ZERO,
            resumed_from: None,
            continuation: None,
        }
    }

    /// The run's start: from its checkpoint when it left one ([`Self::resume`]), else at
    /// t = 0: the LAMMPS data file when asked for, the first energy sample, the cloud's first
    /// observation, a frame if one is due at step 0 and the first dump.
    fn begin(
        sim: &mut Simulation,
        spec: &SceneSpec,
        opts: &RunOptions,
        wall0: Instant,
    ) -> Result<Self> {
        let mut run = Gathered::new(sim, spec, opts, wall0);
        if let Some(c) = &opts.checkpoint {
            let every = c.every;
            run.checkpoint = Some(Checkpointer {
                opts: c.clone(),
                key: checkpoint_key(spec, opts)?,
                since: Instant::now(),
                next_step: match every {
                    Every::Steps(k) => k,
                    _ => u64::MAX,
                },
                last_step: None,
            });
        }
        if let Some(path) = &opts.continuation {
            run.continuation = Some(Continuation {
                path: path.clone(),
                key: continuation_key(spec, opts)?,
                // The screen measures at the end: from it on, runs to other ends part.
                before: run
                    .observer
                    .as_ref()
                    .map_or(sim.derived.steps, CloudObserver::first_end_dependent_step)
                    .min(screen_step(&spec.run, &sim.derived).unwrap_or(u64::MAX)),
                written: false,
            });
        }
        if run.resume(sim, opts)? {
            return Ok(run);
        }
        if opts.extend {
            run.extend(sim, opts, spec.run.end_time_s)?;
            return Ok(run);
        }
        let t = Instant::now();
        if let Some(path) = &opts.lammps_data {
            write_lammps_data(path, sim)?;
        }
        if let Some(dir) = &opts.lammps_dir {
            crate::lammps::write_lammps_input(dir, sim, spec)?;
        }
        run.rows.push(row(sim, &sim.energy_initial));
        if let Some(every) = opts.dump_every {
            let mut trajectory = Trajectory::create(&opts.out_dir, sim, opts.dump_format)?;
            trajectory.frame(sim, 0)?;
            run.trajectory = Some(trajectory);
            run.next_dump = every;
        }
        run.output_time += t.elapsed();
        run.observe(sim);
        Ok(run)
    }

    /// Takes up the run from its checkpoint, if it left one: true when it did. A checkpoint of
    /// another run, a damaged one, or one whose dumps are gone is reported on stderr and
    /// removed, and the run starts from t = 0 (`sim` untouched).
    fn resume(&mut self, sim: &mut Simulation, opts: &RunOptions) -> Result<bool> {
        let Some(c) = self.checkpoint.as_ref() else {
            return Ok(false);
        };
        let path = c.opts.path.clone();
        let start_over = |why: String| -> Result<bool> {
            log::info!(
                "checkpoint {}: {why}; the run starts from t = 0",
                path.display()
            );
            checkpoint::remove(&path)?;
            Ok(false)
        };
        // What killed processes left half-written beside the checkpoint, and the run's own
        // files (dumps, pictures, tables, the continuation): gone whether the run resumes or
        // starts over.
        if let Some(parent) = path.parent() {
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            crate::files::remove_stale_partials(parent, name.as_deref())?;
        }
        crate::files::remove_stale_partials(&opts.out_dir, None)?;
        crate::files::remove_stale_partials(&opts.out_dir.join(crate::output::VTK_DIR), None)?;
        let (step, saved) = match checkpoint::read::<Saved>(&path, &c.key)? {
            Found::Nothing => return Ok(false),
            Found::OtherRun => {
                return start_over(
                    "it is another run's (another scene, hvi-study version or output flags)".into(),
                )
            }
            Found::Damaged(why) => return start_over(format!("damaged ({why})")),
            Found::Resume { step, payload } => (step, payload),
        };
        if let Some(why) = self.take_up(sim, opts, step, saved)? {
            return start_over(why);
        }
        if opts.progress {
            log::info!(
                "resuming from checkpoint {} at base step {step} of {} (tau = {:.3} us)",
                path.display(),
                sim.derived.steps,
                sim.tau_s() * 1e6
            );
        }
        Ok(true)
    }

    /// Takes up the run from the continuation a run of the same scene to an earlier end left
    /// ([`RunOptions::extend`]); an error naming why when it cannot (`sim` and the run's
    /// files untouched then).
    fn extend(&mut self, sim: &mut Simulation, opts: &RunOptions, end_time_s: f64) -> Result<()> {
        let Some(c) = self.continuation.as_ref() else {
            return Err(RunError::Input(
                "extending a run needs the path of its continuation state".into(),
            ));
        };
        let (path, before) = (c.path.clone(), c.before);
        let fresh = "run it from t = 0 instead (`hvi-study run --fresh`)";
        let (step, saved) = match checkpoint::read::<Saved>(&path, &c.key)? {
            Found::Resume { step, payload } => (step, payload),
            Found::Nothing => {
                return Err(RunError::Store(format!(
                    "{} is missing: there is no state to extend the run from; {fresh}",
                    path.display()
                )))
            }
            Found::OtherRun => {
                return Err(RunError::Store(format!(
                    "{} is another run's (another scene apart from run.end_time_s, another \
                 hvi-study version or other output flags); {fresh}",
                    path.display()
                )))
            }
            Found::Damaged(why) => {
                return Err(RunError::parse(format!(
                    "{} is damaged ({why}); {fresh}",
                    path.display()
                )))
            }
        };
        if step >= before {
            return Err(RunError::Store(format!(
                "{} holds the state at base step {step}, at or past base step {before}, the \
                 first sample this run takes because of its end time (a front time follows \
                 the end of a run shorter than 32 us): the runs part before it, so this one \
                 cannot continue it bit-identically; {fresh}",
                path.display()
            )));
        }
        if let Some(why) = self.take_up(sim, opts, step, saved)? {
            return Err(RunError::parse(format!(
                "{}: {why}; {fresh}",
                path.display()
            )));
        }
        if opts.progress {
            log::info!(
                "extending the run from its continuation at base step {step} (tau = {:.3} us) \
                 to base step {} (tau = {:.3} us)",
                sim.tau_s() * 1e6,
                sim.derived.steps,
                end_time_s * 1e6
            );
        }
        Ok(())
    }

    /// Restores what a checkpoint or continuation saved at base step `step`: `Some(why)`, with
    /// `sim` untouched, when it cannot be taken up (its dumps are gone, the state does not
    /// fit the scene).
    fn take_up(
        &mut self,
        sim: &mut Simulation,
        opts: &RunOptions,
        step: u64,
        saved: Saved,
    ) -> Result<Option<String>> {
        let trajectory = match saved.trajectory {
            Some(t) => match Trajectory::resume(&opts.out_dir, t) {
                Ok(t) => Some(t),
                Err(e) => return Ok(Some(format!("its dumps cannot be continued ({e:#})"))),
            },
            None => None,
        };
        if let Err(e) = sim.restore_state(saved.sim) {
            return Ok(Some(e.to_string()));
        }
        if let Some(c) = self.checkpoint.as_mut() {
            if let Every::Steps(k) = c.opts.every {
                c.next_step = next_multiple(step, k);
            }
            c.last_step = Some(step);
        }
        self.rows = saved.rows;
        self.e0 = sim.energy_initial.total_j();
        self.max_drift = saved.max_drift;
        if let (Some(o), Some(state)) = (self.observer.as_mut(), saved.observer) {
            o.restore_state(state);
        }
        self.frames = saved.frames;
        self.trajectory = trajectory;
        self.next_dump = saved.next_dump;
        self.break_history = saved.break_history;
        self.screen = saved.screen;
        self.output_time = saved.output_time;
        self.render_time = saved.render_time;
        self.wall_before = saved.wall;
        self.loop_before = saved.loop_wall;
        self.resumed_from = Some(step);
        Ok(None)
    }

    /// Everything the run has gathered up to now (a landing), for a checkpoint or the
    /// continuation.
    fn gather(&mut self, sim: &Simulation, loop_wall: Duration) -> Result<Saved> {
        let trajectory = match self.trajectory.as_mut() {
            Some(t) => Some(t.save_state()?),
            None => None,
        };
        Ok(Saved {
            sim: sim.save_state(),
            rows: self.rows.clone(),
            max_drift: self.max_drift,
            observer: self.observer.as_ref().map(CloudObserver::save_state),
            frames: self.frames.clone(),
            trajectory,
            next_dump: self.next_dump,
            break_history: self.break_history.clone(),
            screen: self.screen,
            output_time: self.output_time,
            render_time: self.render_time,
            wall: self.wall_before + self.wall0.elapsed(),
            loop_wall: self.loop_before + loop_wall,
        })
    }

    /// Writes a checkpoint of the run now (a landing), unless it has one of this step.
    fn save(&mut self, sim: &Simulation, loop_wall: Duration) -> Result<()> {
        let Some(c) = self.checkpoint.as_ref() else {
            return Ok(());
        };
        if sim.step == 0 || c.last_step == Some(sim.step) {
            return Ok(());
        }
        let t = Instant::now();
        let saved = self.gather(sim, loop_wall)?;
        // Before the first end-dependent landing, the checkpoint's state is one a run to a
        // later end shares too: it is the continuation so far (so an unfinished run can be
        // extended as well as resumed).
        if let Some(c) = self.continuation.as_ref().filter(|c| sim.step < c.before) {
            checkpoint::write(&c.path, &c.key, sim.step, &saved)?;
        }
        if let Some(c) = self.checkpoint.as_mut() {
            checkpoint::write(&c.opts.path, &c.key, sim.step, &saved)?;
            c.since = Instant::now();
            c.last_step = Some(sim.step);
            if let Every::Steps(k) = c.opts.every {
                c.next_step = next_multiple(sim.step, k);
            }
        }
        self.output_time += t.elapsed();
        Ok(())
    }

    /// Keeps the continuation when the step to `next` would reach the run's first
    /// end-dependent landing: the state now is the last one a run to a later end shares.
    fn keep_continuation(
        &mut self,
        sim: &Simulation,
        next: u64,
        loop_wall: Duration,
    ) -> Result<()> {
        let due = self
            .continuation
            .as_ref()
            .is_some_and(|c| !c.written && sim.step < c.before && next >= c.before);
        if !due {
            return Ok(());
        }
        let t = Instant::now();
        let saved = self.gather(sim, loop_wall)?;
        if let Some(c) = self.continuation.as_mut() {
            checkpoint::write(&c.path, &c.key, sim.step, &saved)?;
            c.written = true;
        }
        self.output_time += t.elapsed();
        Ok(())
    }

    /// Whether a checkpoint is due at base step `s` by the interval.
    fn checkpoint_due(&self, s: u64) -> bool {
        self.checkpoint
            .as_ref()
            .is_some_and(|c| match c.opts.every {
                Every::Off => false,
                Every::Wall(d) => c.since.elapsed() >= d,
                Every::Steps(_) => s >= c.next_step,
            })
    }

    /// Steps `sim` to the end of the run, landing on every time the scene samples (energy
    /// samples, cloud samples, render times), and stops at the first instability (kept in
    /// `failure`). Dumps (`--dump-every K`) are taken at the first step at or after each
    /// multiple of K, never landed on, so asking for them does not change the trajectory.
    /// Checkpoints are written between steps when due, and when a signal stops the run.
    /// Returns the stepping wall time without the cloud observation and frame captures, s:
    /// the engine's throughput.
    fn step_to_end(
        &mut self,
        sim: &mut Simulation,
        spec: &SceneSpec,
        opts: &RunOptions,
        n: usize,
    ) -> Result<f64> {
        let bar = progress_bar(opts, sim.derived.steps);
        let step_wall0 = Instant::now();
        // The pool's other workers spin between the step's parallel loops instead of
        // sleeping (see `hvi_engine::threads`); results do not depend on it.
        hvi_engine::threads::with_awake_workers(|| {
            self.step_loop(sim, spec, opts, n, bar.as_deref(), step_wall0)
        })?;
        if let Some(b) = &bar {
            b.finish();
        }
        if let Some(t) = self.trajectory.take() {
            let t0 = Instant::now();
            t.finish()?;
            self.output_time += t0.elapsed();
        }
        let observed_in_loop = self.observer.as_ref().map_or(Duration::ZERO, |o| o.elapsed);
        Ok((self.loop_before + step_wall0.elapsed())
            .saturating_sub(observed_in_loop + self.render_time)
            .as_secs_f64())
    }

    /// The loop of [`Self::step_to_end`]: steps, samples, observes, dumps and checkpoints to
    /// the end of the run or its first failure (kept in `failure`).
    fn step_loop(
        &mut self,
        sim: &mut Simulation,
        spec: &SceneSpec,
        opts: &RunOptions,
        n: usize,
        bar: Option<&dyn Bar>,
        step_wall0: Instant,
    ) -> Result<()> {
        let d = sim.derived;
        let thermo_every = (d.steps / 20).max(1);
        let dump_every = opts.dump_every.unwrap_or(0);
        let energy_every = spec.run.energy_every;
        let from = (sim.step, sim.steps_taken);
        let mut next_thermo = next_multiple(sim.step, thermo_every);
        let mut progress_written: Option<Instant> = None;
        let free_flight = free_flight_step(&spec.run, &d);
        let screen = screen_step(&spec.run, &d);
        while sim.step < d.steps {
            if opts.progress_file && progress_written.is_none_or(|t| t.elapsed() >= PROGRESS_EVERY)
            {
                progress_written = Some(Instant::now());
                let p = Progress {
                    step: sim.step,
                    steps: d.steps,
                    time_s: sim.time_s(),
                    end_time_s: spec.run.end_time_s,
                    wall_s: step_wall0.elapsed().as_secs_f64(),
                };
                // Progress is a courtesy: a run never fails for want of it.
                let _ = crate::files::write_atomic_bytes(
                    &opts.out_dir.join(PROGRESS_FILE),
                    &serde_json::to_vec(&p).unwrap_or_default(),
                );
            }
            // Ctrl-C or SIGTERM: stop here, after a checkpoint when the run writes them (the
            // caller removes what else the run wrote).
            if let Some(sig) = crate::interrupt::requested() {
                self.save(sim, step_wall0.elapsed())?;
                return Err(crate::interrupt::Interrupted(sig).into());
            }
            if self.checkpoint_due(sim.step) {
                self.save(sim, step_wall0.elapsed())?;
            }
            let mut next = self.next_landing(sim.step, d.steps, energy_every);
            if let Some(f) = free_flight.filter(|&f| f > sim.step) {
                next = next.min(f);
            }
            self.keep_continuation(sim, next, step_wall0.elapsed())?;
            if let Err(e) = sim.step_until(next) {
                self.failure = Some(e);
                break;
            }
            let s = sim.step;
            if (at_multiple(s, energy_every) || s == d.steps) && !self.sample_energy(sim) {
                break;
            }
            self.consider_free_flight(sim, &spec.run, opts.progress, [screen, free_flight]);
            self.observe(sim);
            if self.trajectory.is_some() && (s >= self.next_dump || s == d.steps) {
                self.next_dump = next_multiple(s, dump_every);
                self.dump(sim, s)?;
            }
            if opts.progress && (s >= next_thermo || s == d.steps) {
                next_thermo = next_multiple(s, thermo_every);
                self.output_time += thermo(bar, sim, n, from, step_wall0);
            }
        }
        Ok(())
    }

    /// After a step, while the run computes forces: the screen at its step ([`crate::screen`]),
    /// then free flight at `run.free_flight_after_s` or by the ballistic cut-off's gate at an
    /// energy sample. `at` holds the screen's and free flight's steps.
    fn consider_free_flight(
        &mut self,
        sim: &mut Simulation,
        run: &RunSettings,
        progress: bool,
        at: [Option<u64>; 2],
    ) {
        let s = sim.step;
        let [screen, free_flight] = at;
        if sim.coasting_since().is_none() && self.screen.is_none() && screen.is_some_and(|f| s >= f)
        {
            self.screen_now(sim, run, progress);
        }
        if sim.coasting_since().is_none() {
            if free_flight.is_some_and(|f| s >= f) {
                self.begin_free_flight(sim, progress);
            } else if run.ballistic_cutoff && at_multiple(s, run.energy_every) {
                self.consider_cutoff(sim, run, progress);
            }
        }
    }

    /// The next base step after `s` at which the scene samples something (the end, an energy
    /// sample, a cloud sample, a render time): an adaptive step lands on it. Only the scene
    /// decides these, never the output flags.
    fn next_landing(&self, s: u64, end: u64, energy_every: u64) -> u64 {
        let mut next = end.min(next_multiple(s, energy_every));
        if let Some(due) = self.observer.as_ref().and_then(|o| o.next_due(s)) {
            next = next.min(due);
        }
        if let Some(&(r, _)) = self.render_steps.iter().find(|&&(r, _)| r > s) {
            next = next.min(r);
        }
        next
    }

    /// Samples the energy ledger and checks its drift; false (the failure kept) when it has
    /// drifted beyond `run.max_energy_drift`.
    fn sample_energy(&mut self, sim: &mut Simulation) -> bool {
        let e = sim.energy();
        self.rows.push(row(sim, &e));
        match sim.check_energy(&e) {
            Ok(drift) => {
                self.max_drift = self.max_drift.max(drift.abs());
                true
            }
            Err(err) => {
                self.max_drift = self
                    .max_drift
                    .max(((e.total_j() - self.e0) / self.e0).abs());
                self.failure = Some(err);
                false
            }
        }
    }

    /// The ballistic cut-off, checked at each energy sample: after `run.cutoff_min_tau_s`,
    /// once the broken-bond count grew by at most `run.cutoff_break_fraction` over
    /// `run.cutoff_quiet_s` and no fragments touch or close in, the fragments move rigidly.
    fn consider_cutoff(&mut self, sim: &mut Simulation, run: &RunSettings, progress: bool) {
        let tau = sim.tau_s();
        self.break_history.push((tau, sim.bonds_broken));
        // Broken-bond count one quiet window ago.
        let before = self
            .break_history
            .iter()
            .rev()
            .find(|h| tau - h.0 >= run.cutoff_quiet_s)
            .map(|h| h.1);
        let quiet = before.is_some_and(|b| {
            (sim.bonds_broken - b) as f64 <= run.cutoff_break_fraction * sim.bonds_broken as f64
        });
        if tau >= run.cutoff_min_tau_s && quiet {
            let t = Instant::now();
            let labels = hvi_engine::cloud::label_fragments(&sim.particles);
            if sim.fragments_separating(&labels) {
                sim.start_coasting(&labels);
                if progress {
                    log::info!(
                        "ballistic cut-off at tau = {:.3} us: bonds broken grew by at most {} over {:.3} us and no fragments touch or close in; fragments now move rigidly",
                        tau * 1e6,
                        run.cutoff_break_fraction,
                        run.cutoff_quiet_s * 1e6
                    );
                }
            }
            self.output_time += t.elapsed();
        }
    }

    /// Free flight from `run.free_flight_after_s` on: the fragments as they are now move
    /// rigidly to the end, whatever the cut-off's gate.
    fn begin_free_flight(&mut self, sim: &mut Simulation, progress: bool) {
        let t = Instant::now();
        let labels = hvi_engine::cloud::label_fragments(&sim.particles);
        sim.start_coasting(&labels);
        if progress {
            log::info!(
                "free flight from tau = {:.3} us (run.free_flight_after_s): fragments now move rigidly",
                sim.tau_s() * 1e6
            );
        }
        self.output_time += t.elapsed();
    }

    /// The screen ([`crate::screen`]), once, at `run.screen_after_s`.
    fn screen_now(&mut self, sim: &mut Simulation, run: &RunSettings, progress: bool) {
        let t = Instant::now();
        let report = crate::screen::screen(sim, run, self.observer.as_ref());
        if progress {
            let show = |x: Option<f64>| x.map_or("none".to_string(), |x| format!("{x:.4}"));
            log::info!(
                "screen at tau = {:.3} us: free flight from here gives R = {}, va/v0 = {}: {}",
                report.tau_s * 1e6,
                show(report.length_ratio),
                show(report.front_velocity_ratio),
                if report.free_flight {
                    "outside the screen's window, the run goes on in free flight"
                } else {
                    "inside, the run goes on in full"
                }
            );
        }
        self.screen = Some(report);
        self.output_time += t.elapsed();
    }

    /// Observes the cloud when a sample is due and captures a frame at a render step.
    fn observe(&mut self, sim: &Simulation) {
        if let Some(o) = self.observer.as_mut() {
            o.observe(sim);
        }
        if self.capture && self.render_steps.iter().any(|&(s, _)| s == sim.step) {
            let t = Instant::now();
            self.frames.push(Frame::capture(sim));
            self.render_time += t.elapsed();
        }
    }

    /// Appends the state at base step `step` to the trajectory.
    fn dump(&mut self, sim: &Simulation, step: u64) -> Result<()> {
        let t = Instant::now();
        if let Some(trajectory) = self.trajectory.as_mut() {
            trajectory.frame(sim, step)?;
        }
        self.output_time += t.elapsed();
        Ok(())
    }

    /// The full cloud measurement at the analysis time (the end of a completed run), the
    /// track, and the time the observation took in all.
    fn finish_cloud(&mut self, sim: &Simulation) -> (Option<CloudResult>, Vec<TrackRow>, Duration) {
        let cloud = match (self.observer.as_mut(), &self.failure) {
            (Some(o), None) => o.finish(sim),
            _ => None,
        };
        let track = self.observer.take().map(|o| (o.track, o.elapsed));
        let analysis_time = track.as_ref().map_or(Duration::ZERO, |t| t.1);
        let track = track.map(|t| t.0).unwrap_or_default();
        (cloud, track, analysis_time)
    }
}

/// The progress bar over `steps`, when progress is on and the command draws bars (else thermo
/// lines go to the log as text).
fn progress_bar(opts: &RunOptions, steps: u64) -> Option<Box<dyn Bar>> {
    opts.progress
        .then(|| crate::progress::bar(steps, Unit::Steps))
        .flatten()
}

/// One thermo line (time, throughput since `since`, when the run stood at `from` = (base
/// step, steps taken), bonds broken) on the progress bar when
/// there is one, else on stderr; returns the time it took.
fn thermo(
    bar: Option<&dyn Bar>,
    sim: &Simulation,
    n: usize,
    from: (u64, u64),
    since: Instant,
) -> Duration {
    let (s, steps) = (sim.step, sim.derived.steps);
    let t = Instant::now();
    let el = since.elapsed().as_secs_f64();
    let rate = n as f64 * (sim.steps_taken - from.1) as f64 / el.max(1e-9);
    let eta = (steps - s) as f64 * el / ((s - from.0) as f64).max(1.0);
    let msg = format!(
        "tau {:7.3} us  {:6.2} M particle-steps/s  bonds broken {}  ",
        sim.tau_s() * 1e6,
        rate / 1e6,
        sim.bonds_broken
    );
    match bar {
        Some(b) => b.set(s, msg),
        None => log::info!("step {s:>9}/{steps}  {msg} ETA {eta:.0} s"),
    }
    t.elapsed()
}

/// The energy at the end: the last sample when it was taken now, else a new one (appended).
fn final_energy_row(rows: &mut Vec<EnergyRow>, sim: &mut Simulation, d: &Derived) -> EnergyRow {
    match rows.last() {
        Some(r) if (r.time_s - sim.time_s()).abs() < 0.5 * d.dt_s => *r,
        _ => {
            let e = sim.energy();
            let r = row(sim, &e);
            rows.push(r);
            r
        }
    }
}

/// The momentum block: total momentum at t = 0 and now, and the change over M v0.
fn momentum_summary(sim: &Simulation, d: &Derived) -> MomentumSummary {
    let momentum = sim.momentum();
    let total_mass: f64 = sim.symmetry.copies() * sim.particles.mass.iter().sum::<f64>();
    let scale = (total_mass * d.v0_m_s).max(f64::MIN_POSITIVE);
    MomentumSummary {
        initial_kg_m_s: sim.momentum_initial.to_array(),
        final_kg_m_s: momentum.to_array(),
        relative_change: (momentum - sim.momentum_initial).length() / scale,
    }
}

/// The energy block from the final sample, the initial total `e0` and the largest drift.
fn energy_summary(last: &EnergyRow, e0: f64, max_drift: f64) -> EnergySummary {
    EnergySummary {
        kinetic_j: last.kinetic_j,
        contact_j: last.contact_j,
        bond_j: last.bond_j,
        broken_j: last.broken_j,
        absorbed_j: last.absorbed_j,
        total_initial_j: e0,
        total_final_j: last.total_j,
        relative_drift: (last.total_j - e0) / e0,
        max_abs_relative_drift: max_drift,
    }
}

/// Writes `energy.csv`, `cloud_track.csv` (when there is a track), `fragments.csv` and
/// `craters.csv` (when the cloud was measured) and `state.bin` (when its state was kept) into
/// `dir`; returns the time it took.
fn write_tables(
    dir: &Path,
    rows: &[EnergyRow],
    track: &[TrackRow],
    cloud: Option<&CloudResult>,
) -> Result<Duration> {
    let t = Instant::now();
    write_csv_atomic(&dir.join("energy.csv"), rows)?;
    if !track.is_empty() {
        write_csv_atomic(&dir.join("cloud_track.csv"), track)?;
    }
    if let Some(c) = cloud {
        write_cloud_tables(dir, c)?;
        if let Some(kept) = &c.kept {
            crate::state::write_state(&dir.join(crate::state::STATE_FILE), kept)?;
        }
    }
    Ok(t.elapsed())
}

/// The files of a run that its cloud's measurement writes (the fragment and crater tables and
/// the pictures that show the measurement): what a run measured from another's kept state
/// writes anew rather than takes over (the run store's remeasured runs, crate hvi-store).
pub const MEASURED_FILES: [&str; 5] = [
    "fragments.csv",
    "craters.csv",
    "cloud_side.png",
    "fragments.png",
    "shadowgraph.png",
];

/// Writes the cloud's tables into `dir`: `fragments.csv` (the size distribution) and
/// `craters.csv` (the witness plate).
pub fn write_cloud_tables(dir: &Path, cloud: &CloudResult) -> Result<()> {
    write_csv_atomic(
        &dir.join("fragments.csv"),
        size_distribution(&cloud.fragments),
    )?;
    write_csv_atomic(&dir.join("craters.csv"), &cloud.craters)
}

/// Draws the run's pictures of its `n` particles: the side view at the end, the 3-D series of
/// `frames`, the fragment histogram and the track; returns the time it took.
fn render_pictures(
    spec: &SceneSpec,
    opts: &RunOptions,
    sim: &Simulation,
    n: usize,
    frames: &[Frame],
    track: &[TrackRow],
    cloud: Option<&CloudResult>,
) -> Result<Duration> {
    let t = Instant::now();
    let info = SceneInfo::new(spec, &sim.derived, n);
    let dir = &opts.out_dir;
    render_measured(dir, &info, &Frame::capture(sim), cloud)?;
    if !frames.is_empty() {
        render::series(&dir.join("cloud_series.png"), frames, &info)
            .map_err(RunError::library)
            .context("rendering cloud_series.png")?;
    }
    if !track.is_empty() {
        render::track_plot(
            &dir.join("cloud_track.png"),
            track,
            cloud.map_or([None, None], |c| c.report.front_velocity_times_s),
            cloud.and_then(|c| c.report.front_velocity_ratio),
            &info,
        )
        .map_err(RunError::library)
        .context("rendering cloud_track.png")?;
    }
    let took = t.elapsed();
    if opts.progress {
        log::info!(
            "pictures: {:.2} s for {} particles ({} series frames)",
            took.as_secs_f64(),
            n,
            frames.len()
        );
    }
    Ok(took)
}

/// Draws the pictures that show the cloud's measurement into `dir`: the side view of `last`
/// (the particles at the analysis time) with La and Lr, and with a measured cloud its fragment
/// histogram and its shadowgraph.
pub fn render_measured(
    dir: &Path,
    info: &SceneInfo,
    last: &Frame,
    cloud: Option<&CloudResult>,
) -> Result<()> {
    render::side_view(
        &dir.join("cloud_side.png"),
        last,
        info,
        cloud.map(|c| &c.report.measurement),
    )
    .map_err(RunError::library)
    .context("rendering cloud_side.png")?;
    let Some(c) = cloud else { return Ok(()) };
    render::fragment_histogram(
        &dir.join("fragments.png"),
        &c.fragments,
        &c.report.measurement,
        info,
    )
    .map_err(RunError::library)
    .context("rendering fragments.png")?;
    if let (Some(image), Some(sil)) = (&c.shadowgraph, &c.report.silhouette) {
        render::shadowgraph(
            &dir.join("shadowgraph.png"),
            image,
            sil,
            info,
            c.report.measurement.tau_s,
            c.report.front_velocity_ratio,
        )
        .map_err(RunError::library)
        .context("rendering shadowgraph.png")?;
    }
    Ok(())
}

/// What the summary is assembled from besides the scene and the simulation.
struct Measured {
    energy: EnergySummary,
    momentum: MomentumSummary,
    timing: TimingSummary,
    /// Wall time of the whole run.
    wall: Duration,
    /// Stepping wall time without observation and captures, s.
    step_wall_s: f64,
    cloud: Option<CloudReport>,
    error: Option<String>,
    screen: Option<ScreenReport>,
}

/// `summary.json` of the run.
fn summarise(spec: &SceneSpec, sim: &Simulation, counts: Counts, m: Measured) -> Summary {
    let d = sim.derived;
    let n = counts.particles;
    Summary {
        status: if m.error.is_some() {
            "unstable".into()
        } else {
            "completed".into()
        },
        error: m.error,
        engine_version: env!("CARGO_PKG_VERSION").into(),
        particles: n,
        particles_simulated: counts.simulated,
        particles_impactor: counts.impactor,
        particles_target: n - counts.impactor,
        bonds_initial: sim.bonds_initial,
        bonds_broken: sim.bonds_broken,
        steps: sim.steps_taken,
        base_steps: sim.step,
        dt_s: d.dt_s,
        dt_largest_s: sim.largest_stride as f64 * d.dt_s,
        time_s: sim.time_s(),
        tau_s: sim.tau_s(),
        sigma_m: d.sigma_m,
        wall_seconds: m.wall.as_secs_f64(),
        particle_steps_per_second: counts.simulated as f64 * sim.steps_taken as f64
            / m.step_wall_s.max(1e-12),
        threads: rayon::current_num_threads(),
        kernels_isa: hvi_engine::simd::isa().name().into(),
        neighbour_builds: sim.neighbour_builds(),
        speed_refreshes: sim.speed_refreshes,
        stride_limits: sim.stride_limits,
        ballistic_cutoff_tau_s: sim
            .coasting_since()
            .map(|step| step as f64 * d.dt_s - d.contact_time_s),
        screen: m.screen,
        energy: m.energy,
        momentum: m.momentum,
        derived: d,
        timing: m.timing,
        cloud: m.cloud,
        scene: spec.clone(),
        measured_from: None,
    }
}

/// The run's last lines, through the log facade (the binary prints them): steps,
/// throughput, bonds, drift, the cloud, the timing table.
fn print_end(summary: &Summary, sim: &Simulation, table: &str) {
    log::info!(
        "{} steps ({} of {:.3e} s, largest {:.3e} s), {} particles{} in {:.2} s: {:.3e} particle-steps/s; bonds broken {} of {}; energy drift {:.2e}; {} neighbour builds",
        sim.steps_taken,
        sim.step,
        summary.dt_s,
        summary.dt_largest_s,
        summary.particles,
        if summary.particles_simulated < summary.particles {
            format!(" ({} simulated)", summary.particles_simulated)
        } else {
            String::new()
        },
        summary.wall_seconds,
        summary.particle_steps_per_second,
        sim.bonds_broken,
        sim.bonds_initial,
        summary.energy.relative_drift,
        summary.neighbour_builds
    );
    if let Some(c) = &summary.cloud {
        log::info!("{}", describe_cloud(c));
    }
    log::info!("{}", table.trim_end());
}

/// The lines a run prints about its debris cloud.
pub fn describe_cloud(c: &CloudReport) -> String {
    let m = &c.measurement;
    let f = |x: Option<f64>, k: f64, p: usize| {
        x.map_or("n/a".to_string(), |v| format!("{:.*}", p, v * k))
    };
    format!(
        "cloud at tau = {:.2} us: N_part {}, N_frag {}, F = {}; La = {} mm, Lr = {} mm, R = {} \
         ({:.1} % quantile, Lr {}; by the maxima {} / {} mm, R = {})\n\
         front velocity va = {} m/s, va/v0 = {} (front at tau = {} and {} us); largest fragment \
         {} mm, {} of the impactor mass ({} particles); largest piece of the impactor {} of its \
         mass; mass-weighted mean d = {} mm",
        m.tau_s * 1e6,
        m.n_part,
        m.n_frag,
        f(m.fragmentation, 1.0, 4),
        f(m.length_axial_m, 1e3, 2),
        f(m.length_radial_m, 1e3, 2),
        f(m.length_ratio, 1.0, 3),
        100.0 * m.quantile,
        m.width.label(),
        f(m.length_axial_max_m, 1e3, 2),
        f(m.length_radial_max_m, 1e3, 2),
        f(m.length_ratio_max, 1.0, 3),
        f(c.front_velocity_m_s, 1.0, 0),
        f(c.front_velocity_ratio, 1.0, 4),
        f(c.front_velocity_times_s[0], 1e6, 2),
        f(c.front_velocity_times_s[1], 1e6, 2),
        f(m.largest_fragment_diameter_m, 1e3, 3),
        f(m.largest_fragment_mass_fraction, 1.0, 4),
        m.largest_fragment_particles,
        f(m.impactor_largest_fragment_mass_fraction, 1.0, 4),
        f(m.mean_fragment_diameter_m, 1e3, 3),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_keeps_its_progress_file_only_when_asked() {
        let spec = SceneSpec::calibration(1000.0, 1e-6);
        let base = std::env::temp_dir().join(format!("hvi-progress-{}", std::process::id()));
        for asked in [true, false] {
            let dir = base.join(asked.to_string());
            let opts = RunOptions {
                out_dir: dir.clone(),
                progress_file: asked,
                ..RunOptions::default()
            };
            run_scene(&spec, &opts).expect("runs");
            match Progress::read(&dir) {
                Some(p) => {
                    assert!(asked);
                    // Written at the loop's first step and then every PROGRESS_EVERY: a
                    // short run leaves the first (the store removes it at the end).
                    assert!(p.step < p.steps, "{p:?}");
                    assert_eq!(p.end_time_s, spec.run.end_time_s);
                    assert!(p.describe().contains(" % ("), "{}", p.describe());
                }
                None => assert!(!asked, "no progress file"),
            }
        }
        let _ = std::fs::remove_dir_all(&base);
    }

    /// `run.free_flight_after_s`: free flight begins at the first base step at or after that
    /// time whatever the gate, the run computes no force after it, and the ledger from then on
    /// is the one at its start; the run up to it is the run without it, bit for bit.
    #[test]
    fn free_flight_after_a_set_time_begins_there_and_keeps_the_ledger_from_then() {
        let base = std::env::temp_dir().join(format!("hvi-free-flight-{}", std::process::id()));
        let mut spec = SceneSpec::calibration(1000.0, 4e-6);
        spec.run.free_flight_after_s = Some(1.5e-6);
        // No cloud samples: the two runs below land on the same steps.
        spec.analysis.cloud = false;
        let opts = |dir: &str| RunOptions {
            out_dir: base.join(dir),
            ..RunOptions::default()
        };
        let coasted = run_scene(&spec, &opts("coasted")).expect("runs");
        let s = &coasted.summary;
        let dt = s.dt_s;
        let tau = s.ballistic_cutoff_tau_s.expect("free flight began");
        assert!((1.5e-6..1.5e-6 + dt).contains(&tau), "{tau}");
        let from: Vec<_> = coasted.energy.iter().filter(|r| r.tau_s >= tau).collect();
        assert!(from.len() > 2, "samples after the start: {}", from.len());
        let ledger = |r: &EnergyRow| {
            (
                r.kinetic_j,
                r.contact_j,
                r.bond_j,
                r.total_j,
                r.bonds_broken,
            )
        };
        for r in &from {
            assert_eq!(ledger(r), ledger(from[0]));
        }
        let mut until = spec.clone();
        until.run.free_flight_after_s = None;
        until.run.end_time_s = tau;
        let plain = run_scene(&until, &opts("plain")).expect("runs");
        assert_eq!(plain.energy.last().map(ledger), Some(ledger(from[0])));
        let far = spec.clone().build().expect("valid").derived.steps;
        assert_eq!(coasted.sim.step, far);
        assert_eq!(coasted.sim.coasting_since(), Some(plain.sim.step));
        let _ = std::fs::remove_dir_all(&base);

        let mut late = SceneSpec::calibration(1000.0, 4e-6);
        late.run.free_flight_after_s = Some(4e-6);
        let err = late.build().expect_err("at the end time").to_string();
        assert!(
            err.contains("run.free_flight_after_s") && err.contains("below run.end_time_s"),
            "{err}"
        );
    }
}
