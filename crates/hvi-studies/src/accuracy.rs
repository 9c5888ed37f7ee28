//! `hvi-study accuracy`: run time against error.
//!
//! One scene, a reference run and a list of variants, each a set of `--set` overrides of the
//! accuracy knobs (time step, skin, shortcuts). The reference is the paper's step (1e-10 s at
//! sigma_ref, scaled with sigma: `run.dt_factor = 1`), f64, the full run to the analysis time.
//! Every variant runs to the same analysis time, and its observables are compared with the
//! reference's: the relative error in R, va/v0, F and the largest fragment, and its energy
//! drift.
//!
//! The dynamics of fragmentation are chaotic (a round-off difference grows into a different
//! crack), so two runs that differ only in the thermal seed also differ, and one run of a
//! candidate against one reference cannot separate a real error from that scatter. Hence:
//! - the reference value of each observable is the mean over the runs at the reference step
//!   (the reference and the *noise-floor* runs, other seeds: `K_r` runs);
//! - each candidate runs at `K` seeds (`--seeds`, default 1) and its value is their mean;
//! - the *seed scatter* `s` of an observable is the standard deviation of one run about its
//!   setting's mean, pooled over every setting with two or more runs (the reference step, and
//!   each candidate when `K >= 2`), relative to the reference value: chaos, not the setting,
//!   makes it, so the settings share it;
//! - the *noise floor* is two standard errors of the difference of two means,
//!   `2 s sqrt(1/K + 1/K_r)`: an error below it cannot be told from zero.
//!
//! Tolerances (one place: [`TOLERANCES`]): a variant is *within tolerance* when, for each
//! observable, |error of its mean| <= max(tolerance, noise floor), and its energy drift stays
//! within [`ENERGY_DRIFT_BOUND`] at every seed. The *recommended* setting is the cheapest
//! variant within tolerance (mean wall time over its seeds).
//!
//! Runs go through the study store (fingerprinted, complete-or-absent directories), so a
//! second invocation reuses every finished run and a killed benchmark resumes. Runs execute
//! one after another on all threads, so their wall times compare.
//!
//! Writes `accuracy.csv` (a row per variant), `accuracy-runs.csv` (a row per run),
//! `accuracy.json`, `accuracy.md` and `pareto.png` into the report directory.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::{Result, ResultExt, RunError};
use serde::Serialize;

use hvi_analysis::observable::{Observable, Observables};
use hvi_plot::pareto::{pareto_plot, ParetoPlot, ParetoPoint};
use hvi_run::output::{write_atomic_bytes, write_csv_atomic};
use hvi_run::scene_file::parse_scene;
use hvi_store::plan::fingerprint;
use hvi_store::store::{read_summary, Job, RunStatus, Store};

/// Observables compared with the reference, with their relative tolerance.
pub const TOLERANCES: [(Observable, f64); 4] = [
    (Observable::LengthRatio, 0.01),
    (Observable::FrontVelocityRatio, 0.01),
    (Observable::Fragmentation, 0.01),
    (Observable::LargestFragmentMassFraction, 0.01),
];

/// Largest |relative energy-ledger drift| over the run that a variant may have: the
/// project's ledger bound.
pub const ENERGY_DRIFT_BOUND: f64 = hvi_engine::sim::LEDGER_DRIFT_BOUND;

/// What a variant is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// The reference: the paper's step.
    Reference,
    /// Another seed at the reference step: measures the chaotic spread.
    NoiseFloor,
    /// A setting to judge.
    Candidate,
}

/// One variant: a name and the overrides that make it.
#[derive(Debug, Clone)]
pub struct Variant {
    /// Name in tables and plots.
    pub name: String,
    /// `section.key=value` overrides on top of the scene.
    pub sets: Vec<String>,
    /// Its role.
    pub role: Role,
}

impl Variant {
    fn new(name: &str, sets: &[&str], role: Role) -> Self {
        Variant {
            name: name.into(),
            sets: sets.iter().map(|s| s.to_string()).collect(),
            role,
        }
    }

    /// Parses `NAME:key=value[;key=value...]` (a candidate).
    pub fn parse(text: &str) -> Result<Variant> {
        let (name, sets) = text.split_once(':').ok_or_else(|| {
            RunError::Input(format!("--variant `{text}`: expected NAME:section.key=value[;section.key=value...], e.g. dt8:run.dt_factor=8"))
        })?;
        let name = name.trim();
        if name.is_empty() || name == "reference" {
            bail!("--variant `{text}`: the name must be non-empty and not `reference`");
        }
        let sets: Vec<String> = sets
            .split(';')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect();
        if sets.is_empty() {
            bail!("--variant `{text}`: no overrides after `:`");
        }
        Ok(Variant {
            name: name.into(),
            sets,
            role: Role::Candidate,
        })
    }
}

/// Most noise-floor seeds a benchmark takes (`--noise-seeds`).
pub const MAX_NOISE_SEEDS: u32 = 8;

/// Most seeds a candidate runs at (`--seeds`).
pub const MAX_SEEDS: u32 = MAX_NOISE_SEEDS + 1;

/// Checks `--seeds` (1 to [`MAX_SEEDS`]).
pub fn check_seeds(seeds: u32) -> Result<()> {
    if !(1..=MAX_SEEDS).contains(&seeds) {
        bail!("--seeds = {seeds} is out of range: allowed 1 to {MAX_SEEDS}");
    }
    Ok(())
}

/// The `--set` that makes the run of a variant at seed `seed` (seed 1 is the scene's own:
/// no override), the same numbering as the noise-floor runs.
fn seed_set(seed: u32) -> Option<String> {
    (seed > 1).then(|| format!("run.seed={seed}"))
}

/// The reference and `noise_seeds` noise-floor runs (seeds 2, 3, ...) at the paper's step.
/// With none, the noise floor is zero and the tolerance alone applies (for scenes whose
/// reference is too expensive to repeat).
pub fn reference_variants(noise_seeds: u32) -> Result<Vec<Variant>> {
    if noise_seeds > MAX_NOISE_SEEDS {
        bail!("--noise-seeds = {noise_seeds} is out of range: allowed 0 to {MAX_NOISE_SEEDS}");
    }
    let mut list = vec![Variant::new(
        "reference",
        &["run.dt_factor=1", "run.max_stride=1"],
        Role::Reference,
    )];
    for seed in 2..noise_seeds + 2 {
        let mut sets = vec!["run.dt_factor=1".to_string(), "run.max_stride=1".into()];
        sets.extend(seed_set(seed));
        list.push(Variant {
            name: format!("seed{seed}"),
            sets,
            role: Role::NoiseFloor,
        });
    }
    Ok(list)
}

/// The default candidates (after [`reference_variants`]): fixed steps from 2 to 16 times the
/// paper's, the skin at the larger steps and the ballistic cut-off (all at a fixed step), and
/// the adaptive step (`run.max_stride`) on base steps of 4 and 6 times the paper's, at its
/// default displacement bound (0.05 sigma) and at twice that (the largest allowed).
pub fn default_candidates() -> Vec<Variant> {
    use Role::*;
    const FIXED: &str = "run.max_stride=1";
    let fixed = |name: &str, sets: &[&str]| {
        let mut all = sets.to_vec();
        all.push(FIXED);
        Variant::new(name, &all, Candidate)
    };
    vec![
        fixed("dt2", &["run.dt_factor=2"]),
        fixed("dt4", &["run.dt_factor=4"]),
        fixed("dt6", &["run.dt_factor=6"]),
        fixed("dt8", &["run.dt_factor=8"]),
        fixed("dt12", &["run.dt_factor=12"]),
        fixed("dt16", &["run.dt_factor=16"]),
        fixed(
            "dt8-skin0.3",
            &["run.dt_factor=8", "run.skin_over_sigma=0.3"],
        ),
        fixed(
            "dt8-skin0.2",
            &["run.dt_factor=8", "run.skin_over_sigma=0.2"],
        ),
        fixed(
            "dt8-cutoff",
            &["run.dt_factor=8", "run.ballistic_cutoff=true"],
        ),
        Variant::new(
            "dt4-adaptive",
            &[
                "run.dt_factor=4",
                "run.max_stride=16",
                "run.stride_displacement_over_sigma=0.05",
            ],
            Candidate,
        ),
        Variant::new(
            "dt6-adaptive",
            &[
                "run.dt_factor=6",
                "run.max_stride=16",
                "run.stride_displacement_over_sigma=0.05",
            ],
            Candidate,
        ),
        Variant::new(
            "dt6-adaptive-c0.1",
            &[
                "run.dt_factor=6",
                "run.max_stride=16",
                "run.stride_displacement_over_sigma=0.1",
            ],
            Candidate,
        ),
    ]
}

/// One row of `accuracy.csv`.
#[derive(Debug, Clone, Serialize)]
pub struct AccuracyRow {
    /// Variant name.
    pub variant: String,
    /// Its role.
    pub role: Role,
    /// Its overrides, `;`-separated.
    pub sets: String,
    /// Run status: `completed` when every seed's run completed.
    pub status: String,
    /// Completed runs averaged in this row (a candidate's seeds; 1 for the runs at the
    /// reference step, which are rows of their own).
    pub seeds: u32,
    /// Time step, s.
    pub dt_s: Option<f64>,
    /// Steps (mean over the seeds).
    pub steps: Option<u64>,
    /// Wall time of the stepping loop, s (mean over the seeds).
    pub wall_s: Option<f64>,
    /// Particles times steps per second.
    pub particle_steps_per_s: Option<f64>,
    /// Reference wall time over this one.
    pub speedup: Option<f64>,
    /// R.
    pub length_ratio: Option<f64>,
    /// va / v0.
    pub front_velocity_ratio: Option<f64>,
    /// F.
    pub fragmentation: Option<f64>,
    /// Largest fragment's share of the impactor mass.
    pub largest_fragment_mass_fraction: Option<f64>,
    /// Largest |relative ledger drift| over the run (the largest over the seeds).
    pub energy_max_drift: Option<f64>,
    /// Relative error in R (the mean over the seeds) against the reference.
    pub err_length_ratio: Option<f64>,
    /// Relative error in va/v0.
    pub err_front_velocity_ratio: Option<f64>,
    /// Relative error in F.
    pub err_fragmentation: Option<f64>,
    /// Relative error in the largest fragment.
    pub err_largest_fragment_mass_fraction: Option<f64>,
    /// Largest of the relative errors of R, va/v0 and F.
    pub max_err_rvf: Option<f64>,
    /// Every observable within max(tolerance, noise floor) and the drift within its bound.
    pub within_tolerance: bool,
    /// Whether this invocation reused every stored run of the row.
    pub cached: bool,
}

/// Values of the compared observables, in [`TOLERANCES`] order.
pub type Compared = [Option<f64>; TOLERANCES.len()];

/// The compared observables of one source (a run, a mean over runs), in [`TOLERANCES`] order.
fn compared(value: impl Fn(Observable) -> Option<f64>) -> Compared {
    TOLERANCES.map(|(o, _)| value(o))
}

impl AccuracyRow {
    /// Its means of the compared observables, in [`TOLERANCES`] order.
    pub fn values(&self) -> Compared {
        [
            self.length_ratio,
            self.front_velocity_ratio,
            self.fragmentation,
            self.largest_fragment_mass_fraction,
        ]
    }

    /// Its relative errors of the compared observables, in [`TOLERANCES`] order.
    pub fn errors(&self) -> Compared {
        [
            self.err_length_ratio,
            self.err_front_velocity_ratio,
            self.err_fragmentation,
            self.err_largest_fragment_mass_fraction,
        ]
    }
}

/// One row of `accuracy-runs.csv`: one run (a variant at one seed).
#[derive(Debug, Clone, Serialize)]
pub struct RunRow {
    /// Variant name.
    pub variant: String,
    /// Its role.
    pub role: Role,
    /// The thermal seed's number in the benchmark (1: the scene's own).
    pub seed: u32,
    /// Run status.
    pub status: String,
    /// Steps.
    pub steps: Option<u64>,
    /// Wall time of the stepping loop, s.
    pub wall_s: Option<f64>,
    /// R.
    pub length_ratio: Option<f64>,
    /// va / v0.
    pub front_velocity_ratio: Option<f64>,
    /// F.
    pub fragmentation: Option<f64>,
    /// Largest fragment's share of the impactor mass.
    pub largest_fragment_mass_fraction: Option<f64>,
    /// Largest |relative ledger drift| over the run.
    pub energy_max_drift: Option<f64>,
    /// Whether this invocation reused the stored run.
    pub cached: bool,
}

/// What one run gave.
#[derive(Debug, Clone)]
struct Measured {
    status: RunStatus,
    error: Option<String>,
    obs: Observables,
    dt_s: Option<f64>,
    steps: Option<u64>,
    wall_s: Option<f64>,
    rate: Option<f64>,
    max_drift: Option<f64>,
    cached: bool,
}

fn measured(store: &Store, fp: &str, cached: bool) -> Result<Measured> {
    let rec = store
        .record(fp)?
        .ok_or_else(|| RunError::Input(format!("run {} vanished from the store", &fp[..16])))?;
    let summary = read_summary(&store.dir(fp));
    let s = summary.as_ref();
    Ok(Measured {
        status: rec.status,
        error: rec.error.clone(),
        obs: rec.observables,
        dt_s: s.map(|s| s.dt_s).filter(|v| v.is_finite()),
        steps: s.map(|s| s.steps),
        wall_s: s.map(|s| s.wall_seconds).filter(|v| v.is_finite()),
        rate: s
            .map(|s| s.particle_steps_per_second)
            .filter(|v| v.is_finite()),
        max_drift: s
            .map(|s| s.energy.max_abs_relative_drift)
            .filter(|v| v.is_finite()),
        cached,
    })
}

/// The benchmark's result.
#[derive(Debug, Clone, Serialize)]
pub struct AccuracyReport {
    /// The scene file.
    pub scene: String,
    /// Overrides applied to every variant.
    pub sets: Vec<String>,
    /// Threads per run.
    pub threads: usize,
    /// Seeds per candidate (`K`).
    pub seeds: u32,
    /// Completed runs at the reference step (`K_r`).
    pub reference_runs: usize,
    /// Reference value per observable: the mean over the runs at the reference step.
    pub reference_values: Vec<(Observable, Option<f64>)>,
    /// Seed scatter per observable: the standard deviation of one run about its setting's
    /// mean, pooled over every setting with two or more runs, relative to the reference value.
    pub seed_scatter: Vec<(Observable, f64)>,
    /// Degrees of freedom of the pooled seed scatter (0: no setting ran twice).
    pub scatter_dof: usize,
    /// Noise floor per observable for a candidate at `seeds` seeds: two standard errors of the
    /// difference of its mean and the reference value, `2 s sqrt(1/K + 1/K_r)`.
    pub noise_floor: Vec<(Observable, f64)>,
    /// Tolerance per observable (relative).
    pub tolerances: Vec<(Observable, f64)>,
    /// Energy drift bound.
    pub energy_drift_bound: f64,
    /// The rows, one per variant.
    pub rows: Vec<AccuracyRow>,
    /// Every run, one per variant and seed.
    pub runs: Vec<RunRow>,
    /// The cheapest candidate within tolerance.
    pub recommended: Option<String>,
}

fn rel_err(v: Option<f64>, r: Option<f64>) -> Option<f64> {
    match (v, r) {
        (Some(v), Some(r)) if r != 0.0 => Some(((v - r) / r).abs()),
        _ => None,
    }
}

/// Pooled seed scatter of one observable: the standard deviation of one run about its
/// group's mean, pooled over the groups with two or more values, and its degrees of freedom.
fn pooled_scatter(groups: &[Vec<f64>]) -> (f64, usize) {
    let (mut sum_sq, mut dof) = (0.0f64, 0usize);
    for g in groups.iter().filter(|g| g.len() >= 2) {
        let mean = g.iter().sum::<f64>() / g.len() as f64;
        sum_sq += g.iter().map(|x| (x - mean).powi(2)).sum::<f64>();
        dof += g.len() - 1;
    }
    if dof == 0 {
        (0.0, 0)
    } else {
        ((sum_sq / dof as f64).sqrt(), dof)
    }
}

/// Two standard errors of the difference of a mean over `k` runs and one over `k_r` runs,
/// for a scatter `s` of one run: the noise floor.
fn noise_floor_of(s: f64, k: usize, k_r: usize) -> f64 {
    if k == 0 || k_r == 0 {
        return 0.0;
    }
    2.0 * s * (1.0 / k as f64 + 1.0 / k_r as f64).sqrt()
}

fn mean(vals: impl IntoIterator<Item = f64>) -> Option<f64> {
    let (sum, n) = vals
        .into_iter()
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Runs (or reuses) every variant of the scene, candidates at `seeds` seeds each, compares it
/// with the reference and writes the report into `report_dir`.
pub fn accuracy(
    scene_path: &Path,
    common_sets: &[String],
    variants: &[Variant],
    seeds: u32,
    threads: usize,
    store_dir: &Path,
    report_dir: &Path,
) -> Result<AccuracyReport> {
    let text = std::fs::read_to_string(scene_path)
        .with_context(|| format!("cannot read scene file {}", scene_path.display()))?;
    check_seeds(seeds)?;
    check_variants(&text, common_sets, variants, seeds)?;
    let planned = plan_runs(&text, common_sets, variants, seeds)?;
    let store = Store::open(store_dir)?;
    let results = execute_runs(&store, variants, &planned, seeds, threads)?;
    let runs = runs_by_variant(variants, &planned, &results);
    let mut report = score(variants, &runs, seeds)?;
    report.scene = scene_path.display().to_string();
    report.sets = common_sets.to_vec();
    report.threads = threads;
    write_report(report_dir, &report)?;
    Ok(report)
}

/// One run of the benchmark: a variant (its index) at one seed, and its job.
struct PlannedRun {
    variant: usize,
    seed: u32,
    job: Job,
}

/// Checks the variants before anything runs: exactly one reference, and a scene seed apart
/// from the benchmark's extra seeds (numbered 2, 3, ...).
fn check_variants(
    text: &str,
    common_sets: &[String],
    variants: &[Variant],
    seeds: u32,
) -> Result<()> {
    if variants
        .iter()
        .filter(|v| v.role == Role::Reference)
        .count()
        != 1
    {
        bail!("the variants must hold exactly one reference");
    }
    let base = parse_scene(text, common_sets)?;
    let extra_seeds = variants
        .iter()
        .filter(|v| v.role == Role::NoiseFloor)
        .count()
        .max(seeds as usize - 1) as u64;
    if (2..=extra_seeds + 1).contains(&base.run.seed) {
        bail!(
            "run.seed = {} collides with the benchmark's extra seeds 2 to {}: use run.seed = 1 or above {}",
            base.run.seed,
            extra_seeds + 1,
            extra_seeds + 1
        );
    }
    Ok(())
}

/// Every run of the benchmark, validated before any runs: the candidates at seeds 1 to
/// `seeds`, the reference and the noise-floor variants once.
fn plan_runs(
    text: &str,
    common_sets: &[String],
    variants: &[Variant],
    seeds: u32,
) -> Result<Vec<PlannedRun>> {
    let mut planned = Vec::new();
    for (i, v) in variants.iter().enumerate() {
        let runs = if v.role == Role::Candidate { seeds } else { 1 };
        for seed in 1..=runs {
            let what = if runs > 1 {
                format!("variant `{}` at seed {seed}", v.name)
            } else {
                format!("variant `{}`", v.name)
            };
            let job = job_of(text, common_sets, v, seed, &what)?;
            planned.push(PlannedRun {
                variant: i,
                seed,
                job,
            });
        }
    }
    Ok(planned)
}

/// The job of variant `v` at seed `seed` (`what` in messages): the scene with the common
/// overrides, the variant's and the seed's, checked to build and to measure the cloud.
fn job_of(text: &str, common_sets: &[String], v: &Variant, seed: u32, what: &str) -> Result<Job> {
    let mut sets = common_sets.to_vec();
    sets.extend(v.sets.iter().cloned());
    sets.extend(seed_set(seed));
    let spec = parse_scene(text, &sets).with_context(|| what.to_string())?;
    spec.build().with_context(|| what.to_string())?;
    if !spec.analysis.cloud {
        bail!("{what}: analysis.cloud = false, but the benchmark compares cloud observables");
    }
    let fingerprint = fingerprint(&spec, "accuracy")?;
    let params = serde_json::Map::from_iter([(
        "variant".to_string(),
        serde_json::Value::String(v.name.clone()),
    )]);
    Ok(Job {
        fingerprint,
        scene: spec,
        study: "accuracy".into(),
        tier: "accuracy".into(),
        params,
    })
}

/// Runs each planned run one after another on all threads (a stored, completed run is
/// reused), with a progress line before and after each.
fn execute_runs(
    store: &Store,
    variants: &[Variant],
    planned: &[PlannedRun],
    seeds: u32,
    threads: usize,
) -> Result<Vec<Measured>> {
    let mut results = Vec::with_capacity(planned.len());
    for (k, run) in planned.iter().enumerate() {
        let v = &variants[run.variant];
        let label = if v.role == Role::Candidate && seeds > 1 {
            format!("{} seed {}", v.name, run.seed)
        } else {
            v.name.clone()
        };
        let progress = format!("accuracy [{}/{}] {label}", k + 1, planned.len());
        let prior = store.record(&run.job.fingerprint)?;
        let cached = prior
            .as_ref()
            .is_some_and(hvi_store::store::Record::is_final);
        if !cached {
            log::info!("{progress} ({}) ...", v.sets.join(" "));
            store.execute(&run.job, threads)?;
        }
        let m = measured(store, &run.job.fingerprint, cached)?;
        let outcome = match (m.status, m.wall_s) {
            (RunStatus::Completed, Some(w)) => format!("{w:.1} s"),
            (RunStatus::Completed, None) => "done".into(),
            (RunStatus::Failed, _) => format!("failed: {}", m.error.clone().unwrap_or_default()),
        };
        log::info!(
            "{progress}: {outcome}{}",
            if cached { " (stored)" } else { "" }
        );
        results.push(m);
    }
    Ok(results)
}

/// The runs of one variant, in seed order: (seed, what the run gave).
type VariantRuns<'a> = Vec<(u32, &'a Measured)>;

/// The runs of each variant, in the variants' order.
fn runs_by_variant<'a>(
    variants: &[Variant],
    planned: &[PlannedRun],
    results: &'a [Measured],
) -> Vec<VariantRuns<'a>> {
    (0..variants.len())
        .map(|i| {
            planned
                .iter()
                .zip(results)
                .filter(|(p, _)| p.variant == i)
                .map(|(p, m)| (p.seed, m))
                .collect()
        })
        .collect()
}

fn completed(m: &&Measured) -> bool {
    m.status == RunStatus::Completed
}

/// The completed runs of a variant.
fn completed_runs<'a>(all: &VariantRuns<'a>) -> Vec<&'a Measured> {
    all.iter().map(|&(_, m)| m).filter(completed).collect()
}

/// The report of the runs of each variant (pure): the reference values, the seed scatter and
/// noise floor, a row per variant and per run, the recommendation. The scene, its overrides
/// and the threads are left for the caller.
fn score(variants: &[Variant], runs: &[VariantRuns], seeds: u32) -> Result<AccuracyReport> {
    let reference_index = variants
        .iter()
        .position(|v| v.role == Role::Reference)
        .unwrap_or(0);
    let reference = runs[reference_index][0].1;
    if reference.status != RunStatus::Completed {
        bail!(
            "the reference run failed: {}",
            reference.error.clone().unwrap_or_default()
        );
    }
    let baseline = Baseline::of(variants, runs);
    let rows: Vec<AccuracyRow> = variants
        .iter()
        .zip(runs)
        .map(|(v, all)| variant_row(v, all, &baseline, reference.wall_s))
        .collect();
    let run_rows = variants
        .iter()
        .zip(runs)
        .flat_map(|(v, all)| all.iter().map(|&(seed, m)| run_row(v, seed, m)))
        .collect();
    let noise_floor = baseline
        .seed_scatter
        .iter()
        .zip(baseline.floors(seeds as usize))
        .map(|(&(k, _), f)| (k, f))
        .collect();
    Ok(AccuracyReport {
        scene: String::new(),
        sets: Vec::new(),
        threads: 0,
        seeds,
        reference_runs: baseline.reference_runs,
        recommended: recommended(&rows),
        reference_values: baseline.reference_values,
        seed_scatter: baseline.seed_scatter,
        scatter_dof: baseline.scatter_dof,
        noise_floor,
        tolerances: TOLERANCES.to_vec(),
        energy_drift_bound: ENERGY_DRIFT_BOUND,
        rows,
        runs: run_rows,
    })
}

/// What the runs say about each compared observable before any candidate is judged.
struct Baseline {
    /// Completed runs at the reference step (`K_r`).
    reference_runs: usize,
    /// The mean over the runs at the reference step.
    reference_values: Vec<(Observable, Option<f64>)>,
    /// The pooled seed scatter of one run, relative to the reference value.
    seed_scatter: Vec<(Observable, f64)>,
    /// Degrees of freedom of the scatter.
    scatter_dof: usize,
}

impl Baseline {
    /// The reference values from the runs at the reference step (the reference and the
    /// noise-floor seeds), the scatter pooled over them and every candidate's seeds.
    fn of(variants: &[Variant], runs: &[VariantRuns]) -> Baseline {
        let (mut at_reference_step, mut candidate_groups) = (Vec::new(), Vec::new());
        for (v, all) in variants.iter().zip(runs) {
            if v.role == Role::Candidate {
                candidate_groups.push(completed_runs(all));
            } else {
                at_reference_step.extend(completed_runs(all));
            }
        }
        let reference_values: Vec<(Observable, Option<f64>)> = TOLERANCES
            .iter()
            .map(|&(key, _)| {
                let value = mean(at_reference_step.iter().filter_map(|m| m.obs.get(key)));
                (key, value)
            })
            .collect();
        let mut scatter_dof = 0;
        let seed_scatter = reference_values
            .iter()
            .map(|&(key, value)| {
                let groups: Vec<Vec<f64>> = std::iter::once(&at_reference_step)
                    .chain(&candidate_groups)
                    .map(|g| g.iter().filter_map(|m| m.obs.get(key)).collect())
                    .collect();
                let (s, dof) = pooled_scatter(&groups);
                scatter_dof = scatter_dof.max(dof);
                let rel = match value {
                    Some(r) if r != 0.0 => s / r.abs(),
                    _ => 0.0,
                };
                (key, rel)
            })
            .collect();
        Baseline {
            reference_runs: at_reference_step.len(),
            reference_values,
            seed_scatter,
            scatter_dof,
        }
    }

    /// The noise floor per observable of a mean over `k` runs.
    fn floors(&self, k: usize) -> Vec<f64> {
        self.seed_scatter
            .iter()
            .map(|(_, s)| noise_floor_of(*s, k, self.reference_runs))
            .collect()
    }
}

/// A variant's row: the means over its completed runs, their errors against the reference
/// values, and whether it is within tolerance.
fn variant_row(
    v: &Variant,
    all: &VariantRuns,
    baseline: &Baseline,
    reference_wall_s: Option<f64>,
) -> AccuracyRow {
    let done = completed_runs(all);
    let all_completed = !done.is_empty() && done.len() == all.len();
    let obs = |key: Observable| mean(done.iter().filter_map(|m| m.obs.get(key)));
    let errors: Compared = compared(|key| {
        let (_, reference) = baseline.reference_values.iter().find(|(k, _)| *k == key)?;
        rel_err(obs(key), *reference)
    });
    let max_drift = if all_completed {
        done.iter()
            .map(|m| m.max_drift)
            .try_fold(0.0f64, |a, d| d.map(|d| a.max(d)))
    } else {
        None
    };
    let wall_s = mean(done.iter().filter_map(|m| m.wall_s));
    let within = all_completed
        && TOLERANCES
            .iter()
            .zip(&errors)
            .zip(baseline.floors(done.len()))
            .all(|(((_, tol), e), floor)| e.is_some_and(|e| e <= tol.max(floor)))
        && max_drift.is_some_and(|d| d <= ENERGY_DRIFT_BOUND);
    let [length_ratio, front_velocity_ratio, fragmentation, largest_fragment_mass_fraction] =
        compared(obs);
    let [err_length_ratio, err_front_velocity_ratio, err_fragmentation, err_largest_fragment_mass_fraction] =
        errors;
    AccuracyRow {
        variant: v.name.clone(),
        role: v.role,
        sets: v.sets.join(";"),
        status: if all_completed { "completed" } else { "failed" }.into(),
        seeds: done.len() as u32,
        dt_s: done.first().and_then(|m| m.dt_s),
        steps: mean(done.iter().filter_map(|m| m.steps.map(|s| s as f64)))
            .map(|s| s.round() as u64),
        wall_s,
        particle_steps_per_s: mean(done.iter().filter_map(|m| m.rate)),
        speedup: match (reference_wall_s, wall_s) {
            (Some(r), Some(w)) if w > 0.0 => Some(r / w),
            _ => None,
        },
        length_ratio,
        front_velocity_ratio,
        fragmentation,
        largest_fragment_mass_fraction,
        energy_max_drift: max_drift,
        err_length_ratio,
        err_front_velocity_ratio,
        err_fragmentation,
        err_largest_fragment_mass_fraction,
        max_err_rvf: errors[..HEADLINE]
            .iter()
            .try_fold(0.0f64, |a, e| e.map(|e| a.max(e))),
        within_tolerance: within,
        cached: all.iter().all(|(_, m)| m.cached),
    }
}

/// One run's row.
fn run_row(v: &Variant, seed: u32, m: &Measured) -> RunRow {
    let [length_ratio, front_velocity_ratio, fragmentation, largest_fragment_mass_fraction] =
        compared(|key| m.obs.get(key));
    RunRow {
        variant: v.name.clone(),
        role: v.role,
        seed,
        status: if m.status == RunStatus::Completed {
            "completed"
        } else {
            "failed"
        }
        .into(),
        steps: m.steps,
        wall_s: m.wall_s,
        length_ratio,
        front_velocity_ratio,
        fragmentation,
        largest_fragment_mass_fraction,
        energy_max_drift: m.max_drift,
        cached: m.cached,
    }
}

/// The cheapest candidate within tolerance (by mean wall time).
fn recommended(rows: &[AccuracyRow]) -> Option<String> {
    rows.iter()
        .filter(|r| r.role == Role::Candidate && r.within_tolerance)
        .filter_map(|r| r.wall_s.map(|w| (w, r)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, r)| r.variant.clone())
}

/// `accuracy.csv`, `accuracy-runs.csv`, `accuracy.json`, `accuracy.md` and `pareto.png`.
fn write_report(report_dir: &Path, report: &AccuracyReport) -> Result<()> {
    std::fs::create_dir_all(report_dir)
        .with_context(|| format!("cannot create {}", report_dir.display()))?;
    write_csv_atomic(&report_dir.join("accuracy.csv"), &report.rows)?;
    write_csv_atomic(&report_dir.join("accuracy-runs.csv"), &report.runs)?;
    write_atomic_bytes(
        &report_dir.join("accuracy.json"),
        serde_json::to_string_pretty(report)?.as_bytes(),
    )?;
    write_atomic_bytes(&report_dir.join("accuracy.md"), markdown(report).as_bytes())?;
    draw_pareto(&report_dir.join("pareto.png"), report)
}

fn pct(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{:.2}", 100.0 * v))
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// The report as Markdown: how it was measured, the table, the noise floor, the rule and
/// the recommendation.
pub fn markdown(r: &AccuracyReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Run time against error: {}\n", r.scene);
    if !r.sets.is_empty() {
        let _ = writeln!(s, "Overrides on every run: `{}`\n", r.sets.join(" "));
    }
    let _ = writeln!(
        s,
        "Reference: the paper's step (run.dt_factor = 1), f64, to the analysis time; the reference value of each observable is the mean over the {} runs at that step (the reference and the other seeds). Each candidate ran at {} seed(s); its values and wall time are the means over them (`accuracy-runs.csv` holds every run). {} thread(s) per run, runs one after another. Errors are relative to the reference values, in %. Wall times are as measured on this machine, with whatever else ran on it.\n",
        r.reference_runs,
        r.seeds,
        r.threads
    );
    s.push_str(&variant_table(&r.rows));
    s.push_str(&tolerance_table(r));
    s.push_str(&verdict(r));
    s
}

/// The table of variants, a row each.
fn variant_table(rows: &[AccuracyRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| variant | role | seeds | dt (s) | steps | wall (s) | speed-up | particle-steps/s | R | va/v0 | F | largest frag. | max drift | err R % | err va % | err F % | err largest % | within |"
    );
    let _ = writeln!(s, "|{}", "---|".repeat(18));
    for row in rows {
        let mut cells = vec![
            row.variant.clone(),
            format!("{:?}", row.role),
            row.seeds.to_string(),
            row.dt_s.map_or("-".into(), |v| format!("{v:.2e}")),
            row.steps.map_or("-".into(), |v| v.to_string()),
            opt(row.wall_s, 1),
            opt(row.speedup, 2),
            row.particle_steps_per_s
                .map_or("-".into(), |v| format!("{v:.3e}")),
        ];
        cells.extend(row.values().map(|v| opt(v, 4)));
        cells.push(
            row.energy_max_drift
                .map_or("-".into(), |v| format!("{v:.1e}")),
        );
        cells.extend(row.errors().map(pct));
        cells.push(
            match (row.role, row.within_tolerance) {
                (Role::Candidate, true) => "yes",
                (Role::Candidate, false) => "no",
                _ => "",
            }
            .into(),
        );
        let _ = writeln!(s, "| {} |", cells.join(" | "));
    }
    s
}

/// The table of the tolerance, seed scatter and noise floor per observable.
fn tolerance_table(r: &AccuracyReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "\n## Tolerances and noise floor\n");
    let _ = writeln!(
        s,
        "| observable | reference value (mean at the paper's step) | tolerance % | seed scatter % (one run, pooled, {} dof) | noise floor % (2 SE, {} seed(s) against {}) | applied % |",
        r.scatter_dof, r.seeds, r.reference_runs
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for ((((k, t), (_, f)), (_, mean)), (_, sd)) in r
        .tolerances
        .iter()
        .zip(&r.noise_floor)
        .zip(&r.reference_values)
        .zip(&r.seed_scatter)
    {
        let label = k.symbol();
        let _ = writeln!(
            s,
            "| {label} | {} | {:.2} | {:.2} | {:.2} | {:.2} |",
            opt(*mean, 4),
            100.0 * t,
            100.0 * sd,
            100.0 * f,
            100.0 * t.max(*f)
        );
    }
    s
}

/// The rule a candidate is judged by, and the recommendation.
fn verdict(r: &AccuracyReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\nA candidate is within tolerance when the error of its mean is, for every observable, at most max(tolerance, noise floor), and its largest energy-ledger drift is at most {:.0e} at every seed. Fragmentation is chaotic: runs that differ only in the thermal seed differ by the seed scatter (the standard deviation of one run about its setting's mean, pooled over every setting that ran more than once), and the noise floor is two standard errors of the difference of a candidate's mean and the reference value, 2 s sqrt(1/K + 1/K_r): an error below it cannot be told from zero. More seeds (`--seeds`, `--noise-seeds`) lower it.\n",
        r.energy_drift_bound
    );
    match &r.recommended {
        Some(v) => {
            let row = r.rows.iter().find(|x| &x.variant == v);
            let _ = writeln!(
                s,
                "**Recommended: `{v}`** ({}), the cheapest candidate within tolerance{}.",
                row.map_or(String::new(), |x| x.sets.replace(';', " ")),
                row.and_then(|x| x.speedup)
                    .map_or(String::new(), |x| format!(
                        ": {x:.1}x faster than the reference"
                    ))
            );
        }
        None => {
            let _ = writeln!(s, "No candidate is within tolerance.");
        }
    }
    s
}

/// How many of [`TOLERANCES`] the headline error covers (`max_err_rvf`, the left panel of
/// `pareto.png`): the first three, R, va/v0 and F.
const HEADLINE: usize = 3;

/// `pareto.png` of a report: every row with a wall time, as plain numbers for the picture.
fn draw_pareto(path: &Path, r: &AccuracyReport) -> Result<()> {
    let points: Vec<ParetoPoint> = r
        .rows
        .iter()
        .filter_map(|row| {
            Some(ParetoPoint {
                label: row.variant.clone(),
                wall_s: row.wall_s?,
                candidate: row.role == Role::Candidate,
                within: row.within_tolerance,
                max_error: row.max_err_rvf,
                errors: row.errors().to_vec(),
            })
        })
        .collect();
    let headline: Vec<&str> = TOLERANCES[..HEADLINE]
        .iter()
        .map(|(o, _)| o.symbol())
        .collect();
    let observables: Vec<(&str, f64)> = r
        .noise_floor
        .iter()
        .map(|&(o, floor)| (o.symbol(), floor))
        .collect();
    Ok(pareto_plot(
        path,
        &ParetoPlot {
            points: &points,
            headline: &headline.join(", "),
            headline_floor: r.noise_floor[..HEADLINE]
                .iter()
                .map(|x| x.1)
                .fold(0.0, f64::max),
            observables: &observables,
            tolerance: TOLERANCES[0].1,
            seeds: r.seeds,
        },
    )?)
}

/// Default report directory for a scene: `reports/accuracy/<scene file stem>`.
pub fn default_report_dir(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    Path::new("reports").join("accuracy").join(stem)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_parse_and_reject() {
        let v = Variant::parse("dt8:run.dt_factor=8;run.skin_over_sigma=0.4").expect("parses");
        assert_eq!(v.name, "dt8");
        assert_eq!(v.sets, vec!["run.dt_factor=8", "run.skin_over_sigma=0.4"]);
        assert!(Variant::parse("dt8").is_err());
        assert!(Variant::parse("reference:run.dt_factor=2").is_err());
        assert!(Variant::parse("x:").is_err());
        assert!(default_candidates()
            .iter()
            .all(|v| v.role == Role::Candidate));
        // Noise-floor seeds: 0 leaves the reference alone; names and seeds follow the count.
        assert_eq!(reference_variants(0).expect("0 is allowed").len(), 1);
        let r = reference_variants(3).expect("3 is allowed");
        assert_eq!(r.len(), 4);
        assert_eq!(r[3].name, "seed4");
        assert!(r[3].sets.contains(&"run.seed=4".to_string()));
        let e = reference_variants(MAX_NOISE_SEEDS + 1).expect_err("out of range");
        assert!(e.to_string().contains("--noise-seeds"), "{e}");
    }

    #[test]
    fn pooled_scatter_and_noise_floor() {
        // Two groups: {1, 3} (sum of squares 2, 1 dof) and {4, 6, 8} (8, 2 dof); one-run
        // groups add nothing.
        let (s, dof) = pooled_scatter(&[vec![1.0, 3.0], vec![4.0, 6.0, 8.0], vec![100.0]]);
        assert_eq!(dof, 3);
        assert!((s - (10.0f64 / 3.0).sqrt()).abs() < 1e-12, "{s}");
        assert_eq!(pooled_scatter(&[vec![1.0], vec![2.0]]), (0.0, 0));
        // 2 SE of a difference of means: 2 s sqrt(1/K + 1/K_r).
        assert!((noise_floor_of(0.01, 1, 3) - 0.02 * (4.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!((noise_floor_of(0.01, 3, 3) - 0.02 * (2.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(noise_floor_of(0.01, 0, 3), 0.0);
        // More seeds lower the floor.
        assert!(noise_floor_of(0.01, 4, 4) < noise_floor_of(0.01, 2, 4));
        assert!(check_seeds(0).is_err());
        let e = check_seeds(MAX_SEEDS + 1).expect_err("out of range");
        assert!(e.to_string().contains("--seeds"), "{e}");
        assert_eq!(seed_set(1), None);
        assert_eq!(seed_set(3).as_deref(), Some("run.seed=3"));
    }

    fn run(values: [f64; 4], wall_s: f64) -> Measured {
        let mut obs = Observables::default();
        for ((key, _), v) in TOLERANCES.iter().zip(values) {
            obs.set(*key, Some(v));
        }
        Measured {
            status: RunStatus::Completed,
            error: None,
            obs,
            dt_s: Some(1e-10),
            steps: Some(100),
            wall_s: Some(wall_s),
            rate: Some(1e6),
            max_drift: Some(1e-6),
            cached: false,
        }
    }

    /// The header of a CSV of one row.
    fn csv_header(row: &impl Serialize) -> Vec<String> {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.serialize(row).expect("serialises");
        let bytes = w.into_inner().expect("flushes");
        let text = String::from_utf8(bytes).expect("UTF-8");
        let first = text.lines().next().expect("a header").to_string();
        first.split(',').map(String::from).collect()
    }

    #[test]
    fn scores_means_against_the_reference_step() {
        let mut variants = reference_variants(1).expect("1 is allowed");
        variants.push(Variant::parse("dt4:run.dt_factor=4").expect("parses"));
        let (reference, seed2) = (
            run([1.0, 2.0, 4.0, 8.0], 10.0),
            run([1.5, 2.0, 4.0, 8.0], 8.0),
        );
        let candidate = run([1.25, 2.5, 4.0, 8.0], 2.0);
        let runs = vec![
            vec![(1, &reference)],
            vec![(2, &seed2)],
            vec![(1, &candidate)],
        ];
        let report = score(&variants, &runs, 1).expect("the reference completed");
        assert_eq!(report.reference_runs, 2);
        assert_eq!(
            report.reference_values[0],
            (Observable::LengthRatio, Some(1.25))
        );
        assert_eq!(report.scatter_dof, 1);
        let row = &report.rows[2];
        assert_eq!(row.values(), [Some(1.25), Some(2.5), Some(4.0), Some(8.0)]);
        assert_eq!(row.errors(), [Some(0.0), Some(0.25), Some(0.0), Some(0.0)]);
        assert_eq!(row.max_err_rvf, Some(0.25));
        assert_eq!(row.speedup, Some(5.0));
        assert!(!row.within_tolerance, "va/v0 is 25 % off with no scatter");
        assert_eq!(report.recommended, None);
        assert_eq!(report.runs.len(), 3);
        assert_eq!(report.runs[1].seed, 2);
    }

    #[test]
    fn fixed_row_fields_follow_the_tolerances() {
        // accuracy.csv needs fixed serde fields; they must name TOLERANCES in order, as
        // values() and errors() read them.
        let mut variants = reference_variants(0).expect("0 is allowed");
        variants.push(Variant::parse("dt4:run.dt_factor=4").expect("parses"));
        let (reference, candidate) = (run([1.0, 2.0, 4.0, 8.0], 10.0), run([1.0; 4], 1.0));
        let runs = vec![vec![(1, &reference)], vec![(1, &candidate)]];
        let report = score(&variants, &runs, 1).expect("the reference completed");
        let names: Vec<String> = TOLERANCES.iter().map(|(o, _)| o.name().into()).collect();
        let errors: Vec<String> = names.iter().map(|n| format!("err_{n}")).collect();
        let columns = |header: &[String], wanted: &[String]| -> Vec<usize> {
            wanted
                .iter()
                .map(|n| header.iter().position(|h| h == n).expect("a column"))
                .collect()
        };
        let consecutive = |at: Vec<usize>| at.windows(2).all(|w| w[0] + 1 == w[1]);
        let header = csv_header(&report.rows[1]);
        assert!(consecutive(columns(&header, &names)), "{header:?}");
        assert!(consecutive(columns(&header, &errors)), "{header:?}");
        assert!(consecutive(columns(&csv_header(&report.runs[0]), &names)));
        assert_eq!(
            report.rows[0].values(),
            [Some(1.0), Some(2.0), Some(4.0), Some(8.0)]
        );
        assert_eq!(report.runs[1].length_ratio, Some(1.0));
        assert_eq!(report.rows[1].errors()[3], Some(0.875));
    }

    #[test]
    fn relative_error() {
        assert_eq!(
            rel_err(Some(1.01), Some(1.0)).map(|e| (e * 1e6).round()),
            Some(1e4)
        );
        assert_eq!(rel_err(None, Some(1.0)), None);
        assert_eq!(rel_err(Some(1.0), Some(0.0)), None);
    }
}
