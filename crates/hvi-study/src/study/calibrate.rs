//! `hvi-study calibrate`: the grid of a calibration study scored against the experiments, then
//! a Nelder-Mead refinement (argmin) from the best grid point that runs real simulations
//! through the same run store.
//!
//! The study's `[calibrate]` section:
//!
//! ```toml
//! [calibrate]
//! targets = "../experiments_data/calibration-shot.toml"   # relative to the study file
//! weights = { fragment_size = 0.5 }       # optional: override target weights by name
//! refine = ["material.eps_j", "material.kappa_n_m"]   # default: every axis with > 1 value
//! log_axes = ["material.eps_j", "material.kappa_n_m"] # refined in log10 (default these two)
//! max_iters = 8          # Nelder-Mead iterations (each 1-2 runs, a shrink n more)
//! sd_tolerance = 0.02    # stop when the simplex's objective values agree this well
//! ```
//!
//! Termination is whichever comes first: `max_iters` iterations, or the standard deviation of
//! the objective over the simplex below `sd_tolerance` (argmin's criterion). The search stays in
//! the grid's box (each refined axis between its smallest and largest grid value): a point
//! outside, or one whose scene the engine rejects, costs [`OUTSIDE_COST`] without a run.

use hvi_analysis::observable::Observable;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::cli::CalibrateArgs;
use anyhow::{anyhow, bail, Result};
use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use serde::Deserialize;
use serde_json::Value;

pub use super::calibration::{CalibrationResult, Evaluation};
use super::sweep::print_failures;
use hvi_analysis::score::{objective, Score, Targets, MISSING_TERM};
use hvi_run::exec::thread_split;
use hvi_run::output::{write_atomic, write_atomic_bytes};
use hvi_run::plan::describe_values;
use hvi_run::plan::{fingerprint, validated_scene, Plan};
use hvi_run::runner::{Runner, SlurmBatches};
use hvi_run::spec::{json_to_override, round_sig, Study};
use hvi_run::store::{Job, Record, RunStatus, Store};
use hvi_run::study::job_of;
use hvi_run::table::results_table;
use hvi_run::table::Table;

/// The cost of a point outside the grid's box or with an invalid scene (no run is made).
pub const OUTSIDE_COST: f64 = 10.0 * MISSING_TERM;

/// The paper's best fit (Figs. 11-12): eps = 0.01 J, kappa = 4.56e6 N/m, rcut = 1.5 sigma.
pub const PAPER_BEST: [(&str, f64); 3] = [
    ("material.eps_j", hvi_engine::paper::BEST_EPS_J),
    ("material.kappa_n_m", hvi_engine::paper::BEST_KAPPA_N_M),
    (
        "material.rcut_over_sigma",
        hvi_engine::paper::BEST_RCUT_OVER_SIGMA,
    ),
];

fn default_log_axes() -> Vec<String> {
    vec!["material.eps_j".into(), "material.kappa_n_m".into()]
}
fn default_max_iters() -> u64 {
    8
}
fn default_sd_tolerance() -> f64 {
    0.02
}
fn default_batch() -> usize {
    2
}
fn default_max_batches() -> usize {
    8
}
fn default_noise_floor() -> f64 {
    0.02
}

/// The search after the grid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Efficient global optimisation: a kriging model of the objective, batches of runs by
    /// expected improvement, stopped when the improvement left is below the seed noise.
    #[default]
    Ego,
    /// Nelder-Mead (argmin) from the best grid point, one run at a time.
    NelderMead,
}

impl Method {
    /// The name as the study file and calibration.json spell it.
    pub fn name(self) -> &'static str {
        match self {
            Method::Ego => "ego",
            Method::NelderMead => "nelder-mead",
        }
    }
}

/// `[calibrate]` of a study file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateConfig {
    /// The target file, relative to the study file.
    pub targets: PathBuf,
    /// Weights by target name, overriding the target file's.
    #[serde(default)]
    pub weights: BTreeMap<String, f64>,
    /// The axes the refinement moves (default: every axis with more than one value).
    #[serde(default)]
    pub refine: Option<Vec<String>>,
    /// Axes refined in log10.
    #[serde(default = "default_log_axes")]
    pub log_axes: Vec<String>,
    /// Nelder-Mead iterations at most.
    #[serde(default = "default_max_iters")]
    pub max_iters: u64,
    /// Stop when the objective's standard deviation over the simplex falls below this.
    #[serde(default = "default_sd_tolerance")]
    pub sd_tolerance: f64,
    /// The search after the grid: `ego` (default) or `nelder-mead`.
    #[serde(default)]
    pub method: Method,
    /// ego: points per batch (run together; a batch of runs x seeds keeps every core busy).
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// ego: the seeds every point runs at (empty: the scene's seed only).
    #[serde(default)]
    pub seeds: Vec<u64>,
    /// ego: batches at most.
    #[serde(default = "default_max_batches")]
    pub max_batches: usize,
    /// ego: the least noise assumed for log10 of the objective (a seed mean's standard error);
    /// with one seed it is the noise.
    #[serde(default = "default_noise_floor")]
    pub noise_floor: f64,
}

impl CalibrateConfig {
    /// Reads `[calibrate]` of a study.
    pub fn of(study: &Study) -> Result<CalibrateConfig> {
        let v = study.calibrate.clone().ok_or_else(|| {
            anyhow!(
                "study `{}` has no [calibrate] section (it needs at least targets = \"...\")",
                study.name
            )
        })?;
        let cfg: CalibrateConfig = serde_path_to_error::deserialize(v).map_err(|e| {
            let p = e.path().to_string();
            anyhow!(
                "study key `calibrate.{p}`: {}",
                e.into_inner().message().trim()
            )
        })?;
        if !(cfg.sd_tolerance.is_finite() && cfg.sd_tolerance >= 0.0) {
            bail!(
                "study key `calibrate.sd_tolerance`: {} (allowed: a number >= 0)",
                cfg.sd_tolerance
            );
        }
        if !(1..=64).contains(&cfg.batch) {
            bail!(
                "study key `calibrate.batch`: {} (allowed: 1 to 64 points per batch)",
                cfg.batch
            );
        }
        if cfg.max_batches > 1000 {
            bail!(
                "study key `calibrate.max_batches`: {} (allowed: 0 to 1000)",
                cfg.max_batches
            );
        }
        if !(cfg.noise_floor.is_finite() && cfg.noise_floor >= 0.0) {
            bail!(
                "study key `calibrate.noise_floor`: {} (allowed: a number >= 0)",
                cfg.noise_floor
            );
        }
        cfg.check_seeds("study key `calibrate.seeds`")?;
        Ok(cfg)
    }

    /// The seeds are distinct (`what` names where they came from in the error).
    fn check_seeds(&self, what: &str) -> Result<()> {
        let mut seeds = self.seeds.clone();
        seeds.sort_unstable();
        seeds.dedup();
        if seeds.len() != self.seeds.len() {
            bail!(
                "{what}: {:?} names a seed twice (allowed: distinct seeds)",
                self.seeds
            );
        }
        Ok(())
    }
}

/// The numeric value of a JSON axis value.
fn as_num(v: &Value, key: &str) -> Result<f64> {
    v.as_f64()
        .ok_or_else(|| anyhow!("axis `{key}`: value {v} is not a number (calibrate needs numbers)"))
}

/// Scores every row of a results table and adds `objective` and `score_<name>` columns.
pub fn score_table(table: &mut Table, records: &[Record], targets: &Targets) -> Vec<Score> {
    let scores: Vec<Score> = records
        .iter()
        .map(|r| objective(&targets.targets, |name| r.observables.get(name)))
        .collect();
    let num = |x: f64| {
        if x.is_finite() {
            serde_json::json!(x)
        } else {
            Value::Null
        }
    };
    table.push_column(
        "objective",
        scores.iter().map(|s| num(s.objective)).collect(),
    );
    for (k, t) in targets.targets.iter().enumerate() {
        table.push_column(
            &format!("score_{}", t.name),
            scores.iter().map(|s| num(s.terms[k].term)).collect(),
        );
    }
    scores
}

/// The refinement's problem: parameters in transformed coordinates -> objective, each point a
/// run through the store.
pub(super) struct Refinement<'a> {
    pub(super) study: &'a Study,
    pub(super) plan: &'a Plan,
    pub(super) store: &'a Store,
    pub(super) targets: &'a Targets,
    /// Fixed overrides: the plan's common ones plus the non-refined axes at the best point.
    pub(super) fixed: Vec<String>,
    /// Refined keys, whether each is in log10, and the box in transformed coordinates.
    pub(super) dims: Vec<Dim>,
    pub(super) threads: usize,
    /// Where batches of runs execute (here or as Slurm job arrays).
    pub(super) runner: &'a Runner,
    /// The study directory (the store's, and the Slurm submissions').
    pub(super) out: &'a Path,
    pub(super) progress: bool,
    pub(super) log: RefCell<Vec<Evaluation>>,
    pub(super) ran: RefCell<usize>,
}

impl Refinement<'_> {
    /// Parameter values (by key) of a point in the search's coordinates.
    pub(super) fn values(&self, x: &[f64]) -> BTreeMap<String, f64> {
        self.dims
            .iter()
            .zip(x)
            .map(|((k, log, _, _), &u)| {
                let v = if *log { 10f64.powf(u) } else { u };
                (k.clone(), round_sig(v, 6))
            })
            .collect()
    }

    /// The run of a parameter point (by key), at `seed` (None: the scene's), or why there is
    /// none (its scene is invalid).
    pub(super) fn job(
        &self,
        params: &BTreeMap<String, f64>,
        seed: Option<u64>,
    ) -> Result<std::result::Result<Job, String>> {
        let mut set = self.fixed.clone();
        for (k, v) in params {
            set.push(format!("{k}={}", json_to_override(&serde_json::json!(v))?));
        }
        let mut job_params: serde_json::Map<String, Value> = params
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::json!(v)))
            .collect();
        if let Some(seed) = seed {
            set.push(format!("run.seed={seed}"));
            job_params.insert("run.seed".into(), serde_json::json!(seed));
        }
        let scene = match validated_scene(self.study, &set) {
            Ok(s) => s,
            Err(e) => return Ok(Err(format!("invalid scene: {e:#}"))),
        };
        Ok(Ok(Job {
            fingerprint: fingerprint(&scene, &self.plan.tier)?,
            scene,
            study: self.plan.study.clone(),
            tier: self.plan.tier.clone(),
            params: job_params,
        }))
    }

    /// Evaluates a parameter point (by key), running it if the store lacks it.
    fn evaluate(&self, stage: &str, params: &BTreeMap<String, f64>) -> Result<Evaluation> {
        let step = self
            .log
            .borrow()
            .iter()
            .filter(|e| e.stage == stage)
            .count();
        let outside = |status: String| Evaluation {
            stage: stage.into(),
            step,
            params: params.clone(),
            score: None,
            objective: OUTSIDE_COST,
            status,
            cached: false,
            dir: None,
            seeds: Vec::new(),
            seed_objectives: Vec::new(),
        };
        let job = match self.job(params, None)? {
            Ok(job) => job,
            Err(why) => return Ok(outside(why)),
        };
        let fp = job.fingerprint.clone();
        let (record, cached) = match self.store.lookup(&fp)? {
            Some(r) if r.status == RunStatus::Completed => (r, true),
            _ => {
                *self.ran.borrow_mut() += 1;
                let record = match self.runner {
                    Runner::Local(_) => self.store.execute(&job, self.threads)?,
                    Runner::Slurm(_) => {
                        let describe = |_: usize| fmt_params(params);
                        let report = self.runner.execute(
                            self.store,
                            self.out,
                            self.plan,
                            std::slice::from_ref(&job),
                            &describe,
                            stage,
                        )?;
                        report
                            .records
                            .into_iter()
                            .next()
                            .ok_or_else(|| anyhow!("the run of {stage} has no record"))?
                    }
                };
                (record, false)
            }
        };
        let score = objective(&self.targets.targets, |n| record.observables.get(n));
        let e = Evaluation {
            stage: stage.into(),
            step,
            params: params.clone(),
            objective: score.objective,
            score: Some(score),
            status: match record.status {
                RunStatus::Completed => "completed".into(),
                RunStatus::Failed => format!(
                    "failed: {}",
                    record.error.as_deref().unwrap_or("(no message)")
                ),
            },
            cached,
            dir: Some(hvi_run::plan::run_dir_name(&fp)),
            seeds: Vec::new(),
            seed_objectives: Vec::new(),
        };
        Ok(e)
    }
}

/// Argmin's executor owns its problem; this lends it the refinement.
struct Lend<'r, 'a>(&'r Refinement<'a>);

impl CostFunction for Lend<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> std::result::Result<f64, argmin::core::Error> {
        let this = self.0;
        this.cost_of(x)
    }
}

impl Refinement<'_> {
    fn cost_of(&self, x: &[f64]) -> Result<f64> {
        let params = self.values(x);
        let inside = self
            .dims
            .iter()
            .zip(x)
            .all(|((_, _, lo, hi), &u)| u >= lo - 1e-9 && u <= hi + 1e-9);
        let e = if inside {
            self.evaluate("refine", &params)?
        } else {
            let step = self
                .log
                .borrow()
                .iter()
                .filter(|e| e.stage == "refine")
                .count();
            Evaluation {
                stage: "refine".into(),
                step,
                params: params.clone(),
                score: None,
                objective: OUTSIDE_COST,
                status: "outside the grid's box: not run".into(),
                cached: false,
                dir: None,
                seeds: Vec::new(),
                seed_objectives: Vec::new(),
            }
        };
        if self.progress {
            eprintln!(
                "refine {:>2}: {}  J = {:.4}{}",
                e.step,
                fmt_params(&e.params),
                e.objective,
                if e.cached {
                    " (cached)".to_string()
                } else if e.status != "completed" {
                    format!(" ({})", e.status)
                } else {
                    String::new()
                }
            );
        }
        let j = e.objective;
        self.log.borrow_mut().push(e);
        Ok(j)
    }
}

pub(super) fn fmt_params(p: &BTreeMap<String, f64>) -> String {
    p.iter()
        .map(|(k, v)| format!("{}={v:.4e}", k.rsplit('.').next().unwrap_or(k)))
        .collect::<Vec<_>>()
        .join(", ")
}

fn describe_eval(e: &Evaluation) -> String {
    let mut s = format!("{}  J = {:.4}", fmt_params(&e.params), e.objective);
    if let Some(score) = &e.score {
        for t in &score.terms {
            s.push_str(&format!(
                "\n      {:<18} observed {:>12}  term {:.4} (weight {})",
                t.name,
                t.observed.map_or("n/a".to_string(), |v| format!("{v:.4e}")),
                t.term,
                t.weight
            ));
        }
    }
    s
}

/// `hvi-study calibrate`: the grid scored, the search after it (ego or Nelder-Mead), the
/// paper's fit at this tier, then calibration.json, calibration.md, evaluations.csv, the maps
/// and the snapshots.
pub fn calibrate(args: &CalibrateArgs) -> Result<CalibrationResult> {
    let t0 = std::time::Instant::now();
    let (study, plan, out) = args.study.plan()?;
    let mut cfg = CalibrateConfig::of(&study)?;
    if let Some(seeds) = &args.seeds {
        cfg.seeds = seeds.clone();
        cfg.check_seeds("--seeds")?;
    }
    let base = study.path.parent().unwrap_or_else(|| Path::new("."));
    let targets =
        hvi_run::output::load_targets(&base.join(&cfg.targets))?.with_weights(&cfg.weights)?;
    let progress = !args.study.quiet;
    let (refine_keys, dims) = refined_axes(&plan, &cfg)?;
    let runner = runner_of(args)?;

    let grid = grid_stage(&plan, &out, &runner, &targets, progress)?;
    let best_grid = grid.evaluations[grid.best].clone();
    let best_run = plan.run(grid.best)?;
    let (_, threads) = thread_split(args.study.threads.unwrap_or(0), None, 1);
    let fixed = fixed_overrides(&plan, &best_run.values, |k| refine_keys.contains(k))?;
    let store = Store::open(&out)?;
    let stage = Stage {
        study: &study,
        plan: &plan,
        store: &store,
        targets: &targets,
        threads,
        runner: &runner,
        out: &out,
        progress,
    };
    let problem = stage.problem(fixed, dims);
    let method = args.method.unwrap_or(cfg.method);
    let search = search_stage(&problem, &cfg, args, method, &grid, &refine_keys)?;
    let (paper_params, paper) = paper_point(&stage, &best_run.values)?;
    let paper_runs = usize::from(!paper.cached && paper.dir.is_some());

    let best = search
        .best
        .clone()
        .unwrap_or_else(|| best_of(&best_grid, &search.evaluations));
    let ratio_to_paper = best
        .params
        .iter()
        .filter_map(|(k, v)| paper_params.get(k).map(|p| (k.clone(), v / p)))
        .collect();
    let result = CalibrationResult {
        study: plan.study.clone(),
        tier: plan.tier.clone(),
        particles: particles_of(&out, &best),
        targets_file: targets.path.clone(),
        targets: targets.targets.clone(),
        gaps: targets.gaps.clone(),
        best,
        best_grid,
        paper,
        ratio_to_paper,
        termination: search.termination,
        refinement_runs: search.runs,
        refinement: search.evaluations,
        method: search.method.into(),
        converged: search.converged,
        noise: search.noise,
        noise_source: search.noise_source,
        surface: search.surface,
        region: search.region,
        best_spread: search.spread,
        runs_made: grid.ran + search.runs + paper_runs,
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    write_outputs(&out, &result, &grid.evaluations)?;
    draw_figures(&out, &plan, &grid.records, &result, &cfg.log_axes, progress);
    if progress {
        eprint!("{}", report_text(&result));
    }
    println!("{}", out.join("calibration.json").display());
    Ok(result)
}

/// Where the calibration's runs execute: here (`--threads`, `--jobs`) or, with `--slurm`,
/// each batch as a Slurm job array.
fn runner_of(args: &CalibrateArgs) -> Result<Runner> {
    let quiet = args.study.quiet;
    if !args.slurm {
        if args.slurm_flags.any_set() {
            bail!("--partition, --time, --cpus-per-task, --array-limit and --sbatch-option are options of the Slurm job arrays: add --slurm");
        }
        return Ok(Runner::Local(args.study.exec_options()));
    }
    if args.study.threads.is_some() {
        bail!("calibrate --slurm: --threads is not used (each run gets --cpus-per-task threads)");
    }
    if args.study.jobs.is_some() {
        bail!("calibrate --slurm: --jobs is not used (--array-limit K caps the runs at once)");
    }
    let opts = args.slurm_flags.options(false, quiet)?;
    Ok(Runner::Slurm(SlurmBatches::new(opts, args.poll, !quiet)?))
}

/// What the search after the grid found.
struct SearchOutcome {
    method: &'static str,
    evaluations: Vec<Evaluation>,
    /// The chosen point, when the search chooses it (ego); else the best evaluated.
    best: Option<Evaluation>,
    termination: String,
    converged: bool,
    noise: Option<f64>,
    noise_source: Option<String>,
    surface: Option<super::ego::Surface>,
    region: Option<super::ego::ParamRegion>,
    spread: Vec<super::ego::Spread>,
    runs: usize,
}

/// Stage 2: the search after the grid (none with `--no-refine`, no axis or a zero budget).
fn search_stage(
    problem: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateArgs,
    method: Method,
    grid: &Grid,
    refine_keys: &[String],
) -> Result<SearchOutcome> {
    let none = |why: &str| SearchOutcome {
        method: "none",
        evaluations: Vec::new(),
        best: None,
        termination: why.to_string(),
        converged: false,
        noise: None,
        noise_source: None,
        surface: None,
        region: None,
        spread: Vec::new(),
        runs: 0,
    };
    if args.no_refine {
        return Ok(none("skipped (--no-refine)"));
    }
    if problem.dims.is_empty() {
        return Ok(none("skipped: no axis to refine"));
    }
    match method {
        Method::NelderMead => {
            let best_grid = &grid.evaluations[grid.best];
            let termination = refine_stage(problem, cfg, args, best_grid, refine_keys)?;
            Ok(SearchOutcome {
                method: method.name(),
                evaluations: problem.log.take(),
                best: None,
                converged: termination.starts_with("Solver converged"),
                termination,
                noise: None,
                noise_source: None,
                surface: None,
                region: None,
                spread: Vec::new(),
                runs: *problem.ran.borrow(),
            })
        }
        Method::Ego => {
            let settings = super::ego::EgoSettings {
                batch: cfg.batch,
                seeds: cfg.seeds.clone(),
                max_batches: args.max_batches.unwrap_or(cfg.max_batches),
                noise_floor: cfg.noise_floor,
            };
            if problem.progress {
                eprintln!(
                    "search: efficient global optimisation over {} (log10 for {:?}), batches of {} at seeds {:?}, at most {} batches, noise floor {}",
                    refine_keys.join(", "),
                    problem.dims.iter().filter(|d| d.1).map(|d| d.0.as_str()).collect::<Vec<_>>(),
                    settings.batch,
                    settings.seeds,
                    settings.max_batches,
                    settings.noise_floor
                );
            }
            let pairs: Vec<(Evaluation, Record)> = grid
                .evaluations
                .iter()
                .cloned()
                .zip(grid.records.iter().cloned())
                .collect();
            let o = super::ego::search(problem, &settings, &pairs)?;
            Ok(SearchOutcome {
                method: method.name(),
                evaluations: o
                    .evaluations
                    .into_iter()
                    .filter(|e| e.stage != "grid")
                    .collect(),
                best: Some(o.best),
                termination: o.termination,
                converged: o.converged,
                noise: Some(o.noise),
                noise_source: Some(o.noise_source),
                surface: o.surface,
                region: o.region,
                spread: o.spread,
                runs: o.runs,
            })
        }
    }
}

/// A refined axis: its key, whether it is refined in log10, and the grid's box on it in
/// those coordinates (lowest, highest).
pub(super) type Dim = (String, bool, f64, f64);

/// The axes the refinement moves (`calibrate.refine`, default every axis with more than one
/// value) and their coordinates.
fn refined_axes(plan: &Plan, cfg: &CalibrateConfig) -> Result<(Vec<String>, Vec<Dim>)> {
    let refine_keys: Vec<String> = match &cfg.refine {
        Some(k) => k.clone(),
        None => plan
            .axes
            .iter()
            .filter(|a| a.values.len() > 1)
            .map(|a| a.key.clone())
            .collect(),
    };
    let mut dims = Vec::new();
    for k in &refine_keys {
        let axis = plan
            .axes
            .iter()
            .find(|a| &a.key == k)
            .ok_or_else(|| anyhow!("study key `calibrate.refine`: `{k}` is not an axis"))?;
        let log = cfg.log_axes.contains(k);
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for v in &axis.values {
            let x = as_num(v, k)?;
            if log && x <= 0.0 {
                bail!("axis `{k}` is refined in log10 but has the value {x} <= 0");
            }
            let u = if log { x.log10() } else { x };
            lo = lo.min(u);
            hi = hi.max(u);
        }
        dims.push((k.clone(), log, lo, hi));
    }
    Ok((refine_keys, dims))
}

/// The grid stage's outcome.
struct Grid {
    /// Runs simulated by this invocation.
    ran: usize,
    /// Every grid run as an evaluation, in plan order.
    evaluations: Vec<Evaluation>,
    /// The runs' records, in plan order.
    records: Vec<Record>,
    /// The run with the lowest objective.
    best: usize,
}

/// Stage 1: the grid, run (or reused) through the store and scored; results.csv/json gain the
/// objective and the terms.
fn grid_stage(
    plan: &Plan,
    out: &Path,
    runner: &Runner,
    targets: &Targets,
    progress: bool,
) -> Result<Grid> {
    let stored = stored_before(plan, out)?;
    let store = Store::open(out)?;
    let jobs: Vec<Job> = (0..plan.runs.len())
        .map(|i| job_of(plan, i))
        .collect::<Result<_>>()?;
    let describe = |i: usize| describe_values(&plan.axes, &plan.runs[i].values);
    let report = runner.execute(&store, out, plan, &jobs, &describe, "grid")?;
    let mut table = results_table(
        plan,
        &report.records.iter().cloned().map(Some).collect::<Vec<_>>(),
    );
    if progress {
        eprintln!("grid: {}", report.line());
    }
    print_failures(&report.records);
    let scores = score_table(&mut table, &report.records, targets);
    table.write(out, "results")?;
    let evaluations = grid_evaluations(plan, &report.records, &scores, &stored);
    let best = (0..evaluations.len())
        .filter(|&i| evaluations[i].objective.is_finite())
        .min_by(|&a, &b| {
            evaluations[a]
                .objective
                .total_cmp(&evaluations[b].objective)
        })
        .ok_or_else(|| anyhow!("no grid run has a score"))?;
    if progress {
        eprintln!(
            "best grid point (run {best}): {}",
            describe_eval(&evaluations[best])
        );
    }
    Ok(Grid {
        ran: report.ran,
        evaluations,
        records: report.records,
        best,
    })
}

/// Whether each run of the plan was finished in the store before this invocation.
fn stored_before(plan: &Plan, out: &Path) -> Result<Vec<bool>> {
    let Ok(store) = Store::existing(out) else {
        return Ok(vec![false; plan.runs.len()]);
    };
    plan.runs
        .iter()
        .map(|r| {
            // A damaged record counts as not stored (the sweep repairs and re-runs it).
            Ok(matches!(store.lookup(&r.fingerprint),
                Ok(Some(rec)) if rec.status == RunStatus::Completed))
        })
        .collect()
}

/// The grid runs as evaluations: their numeric axis values, scores and status (`cached`: the
/// run was in the store before this invocation).
fn grid_evaluations(
    plan: &Plan,
    records: &[Record],
    scores: &[Score],
    stored: &[bool],
) -> Vec<Evaluation> {
    plan.runs
        .iter()
        .zip(records)
        .zip(scores)
        .zip(stored)
        .map(|(((run, rec), score), &cached)| {
            let params = plan
                .axes
                .iter()
                .zip(&run.values)
                .filter_map(|(a, v)| v.as_f64().map(|x| (a.key.clone(), x)))
                .collect();
            Evaluation {
                stage: "grid".into(),
                step: run.index,
                params,
                objective: score.objective,
                score: Some(score.clone()),
                status: match rec.status {
                    RunStatus::Completed => "completed".into(),
                    RunStatus::Failed => "failed".into(),
                },
                cached,
                dir: Some(run.dir.clone()),
                seeds: Vec::new(),
                seed_objectives: Vec::new(),
            }
        })
        .collect()
}

/// What the stages after the grid share: where runs go and how they are scored.
struct Stage<'a> {
    study: &'a Study,
    plan: &'a Plan,
    store: &'a Store,
    targets: &'a Targets,
    threads: usize,
    runner: &'a Runner,
    out: &'a Path,
    progress: bool,
}

impl<'a> Stage<'a> {
    /// A problem over `dims` with the other scene keys at `fixed`.
    fn problem(&self, fixed: Vec<String>, dims: Vec<Dim>) -> Refinement<'a> {
        Refinement {
            study: self.study,
            plan: self.plan,
            store: self.store,
            targets: self.targets,
            fixed,
            dims,
            threads: self.threads,
            runner: self.runner,
            out: self.out,
            progress: self.progress,
            log: RefCell::new(Vec::new()),
            ran: RefCell::new(0),
        }
    }
}

/// The plan's common overrides plus every axis at the best run's value, except the axes
/// `moved` names (those the stage sets itself).
fn fixed_overrides(
    plan: &Plan,
    best_values: &[Value],
    moved: impl Fn(&String) -> bool,
) -> Result<Vec<String>> {
    let mut fixed = plan.set.clone();
    for (a, v) in plan.axes.iter().zip(best_values) {
        if !moved(&a.key) {
            fixed.push(format!("{}={}", a.key, json_to_override(v)?));
        }
    }
    Ok(fixed)
}

/// Stage 2: Nelder-Mead from the best grid point (unless skipped). Returns why it stopped;
/// the evaluations stay in the problem's log.
fn refine_stage(
    problem: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateArgs,
    best_grid: &Evaluation,
    refine_keys: &[String],
) -> Result<String> {
    let dims = &problem.dims;
    let max_iters = args.max_iters.unwrap_or(cfg.max_iters);
    if args.no_refine || dims.is_empty() || max_iters == 0 {
        return Ok(if dims.is_empty() {
            "skipped: no axis to refine".to_string()
        } else {
            "skipped (--no-refine or max_iters = 0)".to_string()
        });
    }
    let simplex = start_simplex(problem.plan, dims, best_grid);
    if problem.progress {
        eprintln!(
            "refinement: Nelder-Mead over {} (log10 for {:?}), at most {max_iters} iterations, sd tolerance {}",
            refine_keys.join(", "),
            dims.iter().filter(|d| d.1).map(|d| d.0.as_str()).collect::<Vec<_>>(),
            cfg.sd_tolerance
        );
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(cfg.sd_tolerance)
        .map_err(|e| anyhow!("{e}"))?;
    let res = Executor::new(Lend(problem), solver)
        .configure(|s| s.max_iters(max_iters))
        .run()
        .map_err(|e| anyhow!("refinement: {e:#}"))?;
    let st = res.state();
    Ok(format!(
        "{} after {} iterations",
        st.get_termination_status(),
        st.get_iter()
    ))
}

/// The start simplex: the best grid point and one step along each refined axis (half the
/// grid's spacing on that axis, towards the inside of the box).
fn start_simplex(plan: &Plan, dims: &[Dim], best_grid: &Evaluation) -> Vec<Vec<f64>> {
    let x0: Vec<f64> = dims
        .iter()
        .map(|(k, log, _, _)| {
            let x = best_grid.params.get(k).copied().unwrap_or(f64::NAN);
            if *log {
                x.log10()
            } else {
                x
            }
        })
        .collect();
    let mut simplex = vec![x0.clone()];
    for (d, (k, _, lo, hi)) in dims.iter().enumerate() {
        let n = plan
            .axes
            .iter()
            .find(|a| &a.key == k)
            .map_or(2, |a| a.values.len());
        let step = 0.5 * (hi - lo) / (n.max(2) - 1) as f64;
        let mut v = x0.clone();
        v[d] = if x0[d] + step <= *hi + 1e-12 {
            x0[d] + step
        } else {
            x0[d] - step
        };
        simplex.push(v);
    }
    simplex
}

/// The paper's best fit at this tier, through the same store (a cache hit when the grid holds
/// it): its parameters on the plan's axes and its evaluation.
fn paper_point(
    stage: &Stage,
    best_values: &[Value],
) -> Result<(BTreeMap<String, f64>, Evaluation)> {
    let mut paper_params = BTreeMap::new();
    for (k, v) in PAPER_BEST {
        if stage.plan.axes.iter().any(|a| a.key == k) {
            paper_params.insert(k.to_string(), v);
        }
    }
    let fixed = fixed_overrides(stage.plan, best_values, |k| paper_params.contains_key(k))?;
    let paper = stage
        .problem(fixed, Vec::new())
        .evaluate("paper", &paper_params)?;
    Ok((paper_params, paper))
}

/// The best scored point over the best grid point and the refinement.
fn best_of(best_grid: &Evaluation, refinement: &[Evaluation]) -> Evaluation {
    std::iter::once(best_grid)
        .chain(refinement)
        .filter(|e| e.score.is_some() && e.objective.is_finite())
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .cloned()
        .unwrap_or_else(|| best_grid.clone())
}

/// Particles of a run, read from its record in the study directory.
fn particles_of(out: &Path, e: &Evaluation) -> Option<f64> {
    e.dir
        .as_ref()
        .and_then(|d| {
            std::fs::read_to_string(out.join(d).join("record.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<Record>(&t).ok())
        })
        .and_then(|r| r.observables.get(Observable::Particles))
}

/// The maps and the snapshot matrix; a figure that cannot be drawn is reported, not fatal.
fn draw_figures(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
    log_axes: &[String],
    progress: bool,
) {
    match super::figures::calibration_maps(out, plan, records, result, log_axes) {
        Ok(stems) if progress => {
            for s in stems {
                eprintln!("plot: {} (and .svg)", s.with_extension("png").display());
            }
        }
        Ok(_) => {}
        Err(e) => eprintln!("no maps drawn: {e:#}"),
    }
    match calibration_snapshots(out, plan, records, result) {
        Ok(path) if progress => eprintln!("snapshots: {}", path.display()),
        Ok(_) => {}
        Err(e) => eprintln!("no snapshot matrix: {e:#}"),
    }
}

/// The verdict of a calibration in one line: converged or not, and why.
fn verdict_line(r: &CalibrationResult) -> String {
    let state = match (r.method.as_str(), r.converged) {
        ("none", _) => "GRID ONLY",
        (_, true) => "CONVERGED",
        (_, false) => "NOT CONVERGED",
    };
    format!("{state} ({}): {}", r.method, r.termination)
}

/// The confidence region as one line per parameter: `key in [lo, hi]` (with a note where it
/// reaches the searched box's edge).
fn interval_lines(r: &CalibrationResult) -> Vec<String> {
    let Some(region) = &r.region else {
        return Vec::new();
    };
    region
        .intervals
        .iter()
        .map(|(k, (lo, hi))| {
            let edge = if region.at_boundary.get(k).copied().unwrap_or(false) {
                " (reaches the searched box's edge: the interval may be wider)"
            } else {
                ""
            };
            format!(
                "{k} in [{lo:.4e}, {hi:.4e}], best {:.4e}{edge}",
                r.best.params.get(k).copied().unwrap_or(f64::NAN)
            )
        })
        .collect()
}

/// The human-readable report: the verdict, best point with its interval, every term, the
/// paper's point, the gaps, runs and wall time.
pub fn report_text(r: &CalibrationResult) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "calibration of `{}` at tier `{}` ({} particles): {}\n",
        r.study,
        r.tier,
        r.particles.map_or("?".into(), |n| format!("{n}")),
        verdict_line(r),
    ));
    s.push_str(&format!("  best:        {}\n", describe_eval(&r.best)));
    for line in interval_lines(r) {
        s.push_str(&format!("  interval:    {line}\n"));
    }
    if let Some(noise) = r.noise {
        s.push_str(&format!(
            "  noise:       {noise:.4} in log10 J ({})\n",
            r.noise_source
                .as_deref()
                .unwrap_or("a seed mean's standard error, or the floor")
        ));
    }
    for sp in &r.best_spread {
        s.push_str(&format!(
            "  at the best point: {} = {:.4} +- {:.4} (sd over {} seed(s))\n",
            sp.target, sp.mean, sp.sd, sp.seeds
        ));
    }
    s.push_str(&format!("  best grid:   {}\n", describe_eval(&r.best_grid)));
    s.push_str(&format!("  paper's fit: {}\n", describe_eval(&r.paper)));
    for (k, v) in &r.ratio_to_paper {
        s.push_str(&format!("  best / paper for {k}: {v:.3}\n"));
    }
    for g in &r.gaps {
        s.push_str(&format!("  not scored (gap): {}: {}\n", g.name, g.source));
    }
    s.push_str(&format!(
        "  runs: {} simulated now ({} in the search), wall time {:.1} s\n",
        r.runs_made, r.refinement_runs, r.wall_seconds
    ));
    s
}

/// calibration.md: what a reader needs from calibration.json, in prose and tables.
pub fn report_md(r: &CalibrationResult) -> String {
    let mut s = format!(
        "# Calibration of `{}` at tier `{}`\n\nWritten by `hvi-study calibrate` from calibration.json (regenerate it with the command; do not edit). {} particles.\n\n**{}**\n\n",
        r.study,
        r.tier,
        r.particles.map_or("?".into(), |n| format!("{n}")),
        verdict_line(r)
    );
    s.push_str("## The calibrated point\n\n| parameter | best | interval (low) | interval (high) | the paper's fit | best / paper |\n|---|---|---|---|---|---|\n");
    for (k, v) in &r.best.params {
        let (lo, hi) = r
            .region
            .as_ref()
            .and_then(|g| g.intervals.get(k))
            .map_or(("n/a".to_string(), "n/a".to_string()), |(a, b)| {
                (format!("{a:.4e}"), format!("{b:.4e}"))
            });
        s.push_str(&format!(
            "| `{k}` | {v:.4e} | {lo} | {hi} | {} | {} |\n",
            r.paper
                .params
                .get(k)
                .map_or("n/a".to_string(), |p| format!("{p:.4e}")),
            r.ratio_to_paper
                .get(k)
                .map_or("n/a".to_string(), |q| format!("{q:.3}"))
        ));
    }
    if let Some(g) = &r.region {
        s.push_str(&format!(
            "\nThe interval is the confidence region of the minimum: every point the surrogate predicts within {} noise standard errors of its lowest prediction (J < {:.4}); it covers {:.1} % of the searched box.{}\n",
            hvi_analysis::surrogate::REGION_NOISE_MULTIPLE,
            g.threshold,
            100.0 * g.share_of_box,
            if g.at_boundary.values().any(|&b| b) {
                " It reaches the box's edge on at least one axis: the parameter may lie outside what was searched."
            } else {
                ""
            }
        ));
    }
    s.push_str("\n## Every target at the best point\n\n| target | observed (seed mean) | sd over seeds | term | weight |\n|---|---|---|---|---|\n");
    if let Some(score) = &r.best.score {
        for t in &score.terms {
            let sp = r.best_spread.iter().find(|x| x.target == t.name);
            s.push_str(&format!(
                "| {} | {} | {} | {:.4} | {} |\n",
                t.name,
                t.observed.map_or("n/a".into(), |v| format!("{v:.4}")),
                sp.map_or("n/a".into(), |x| format!("{:.4} ({} seeds)", x.sd, x.seeds)),
                t.term,
                t.weight
            ));
        }
    }
    s.push_str(&format!(
        "\nObjective J = {:.4} at the best point, {:.4} at the best grid point, {:.4} at the paper's fit.\n",
        r.best.objective, r.best_grid.objective, r.paper.objective
    ));
    if let Some(noise) = r.noise {
        s.push_str(&format!(
            "The noise the search worked with: {noise:.4} in log10 J ({}).\n",
            r.noise_source
                .as_deref()
                .unwrap_or("a seed mean's standard error, at least calibrate.noise_floor")
        ));
    }
    for g in &r.gaps {
        s.push_str(&format!(
            "\nNot scored (a gap in experiments_data): {}: {}\n",
            g.name, g.source
        ));
    }
    s.push_str(&format!(
        "\n## Cost\n\n{} runs simulated by this invocation ({} in the search after the grid); {} points evaluated after the grid; wall time {:.1} s. Every evaluation is in evaluations.csv.\n",
        r.runs_made,
        r.refinement_runs,
        r.refinement.len(),
        r.wall_seconds
    ));
    s
}

/// calibration.json and evaluations.csv (every evaluation: grid, refinement, paper).
fn write_outputs(out: &Path, r: &CalibrationResult, grid: &[Evaluation]) -> Result<()> {
    write_atomic_bytes(
        &out.join("calibration.json"),
        serde_json::to_string_pretty(r)?.as_bytes(),
    )?;
    write_atomic_bytes(&out.join("calibration.md"), report_md(r).as_bytes())?;
    let keys: Vec<String> = {
        let mut k: Vec<String> = grid
            .iter()
            .chain(&r.refinement)
            .flat_map(|e| e.params.keys().cloned())
            .collect();
        k.sort();
        k.dedup();
        k
    };
    let names: Vec<String> = r.targets.iter().map(|t| t.name.clone()).collect();
    write_atomic(&out.join("evaluations.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        let mut header = vec!["stage".to_string(), "step".into()];
        header.extend(keys.iter().cloned());
        header.push("objective".into());
        header.extend(names.iter().map(|n| format!("score_{n}")));
        header.extend(["seeds", "status", "cached", "dir"].map(String::from));
        csv.write_record(&header)?;
        for e in grid
            .iter()
            .chain(&r.refinement)
            .chain(std::iter::once(&r.paper))
        {
            let mut row = vec![e.stage.clone(), e.step.to_string()];
            row.extend(
                keys.iter()
                    .map(|k| e.params.get(k).map_or(String::new(), |v| v.to_string())),
            );
            // A point not run (outside the box, invalid scene, failed) has no objective.
            row.push(if e.score.is_some() && e.objective.is_finite() {
                e.objective.to_string()
            } else {
                String::new()
            });
            for k in 0..names.len() {
                row.push(
                    e.score
                        .as_ref()
                        .map_or(String::new(), |s| s.terms[k].term.to_string()),
                );
            }
            row.push(
                e.seeds
                    .iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            row.push(e.status.clone());
            row.push(e.cached.to_string());
            row.push(e.dir.clone().unwrap_or_default());
            csv.write_record(&row)?;
        }
        csv.flush()?;
        Ok(())
    })?;
    if let Some(surface) = &r.surface {
        write_surface(out, surface)?;
    }
    Ok(())
}

/// `surrogate.csv`: the search's final model over two axes (x, y, predicted log10 J).
fn write_surface(out: &Path, s: &super::ego::Surface) -> Result<()> {
    write_atomic(&out.join("surrogate.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        csv.write_record([
            s.keys.0.as_str(),
            s.keys.1.as_str(),
            "predicted_log10_objective",
        ])?;
        for (row, &y) in s.field.z.iter().zip(&s.field.y) {
            for (&z, &x) in row.iter().zip(&s.field.x) {
                csv.write_record([x.to_string(), y.to_string(), z.to_string()])?;
            }
        }
        csv.flush()?;
        Ok(())
    })
}

/// The snapshot matrix of the grid (Fig. 7): each run's side view at the end, captioned with
/// F and R and the objective; the best grid point framed red.
fn calibration_snapshots(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
) -> Result<PathBuf> {
    let axes = super::figures::map_axes(plan)?;
    let slice = result.best_grid.step;
    let (cols, rows, tiles) = super::figures::plan_tiles(plan, out, axes, slice, |i| {
        let r = &records[i];
        let f = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.2}"));
        let j = objective(&result.targets, |n| r.observables.get(n)).objective;
        (
            (i == slice).then_some(plotters::style::RED),
            format!(
                "F = {}, R = {}, J = {j:.2}",
                f(r.observables.get(Observable::Fragmentation)),
                f(r.observables.get(Observable::LengthRatio))
            ),
        )
    })?;
    let path = out.join("snapshots.png");
    let title = format!(
        "Debris clouds over ({}, {}) (Fig. 7); red frame: the best grid point",
        plan.axes[axes.0].label, plan.axes[axes.1].label
    );
    hvi_plot::snapshots::snapshot_matrix(
        &path,
        hvi_plot::snapshots::MatrixText {
            title: &title,
            columns: &cols,
            rows: &rows,
            footer: &super::figures::conditions(plan, records),
        },
        &tiles,
    )?;
    Ok(path)
}
