//! `hvi-study calibrate`: the grid of a calibration study scored against the experiments
//! ([`grid`]), then a search after it that runs real simulations through the same run store:
//! efficient global optimisation ([`ego`], the default) or Nelder-Mead ([`nelder_mead`]); the
//! paper's fit scored at the same tier; and the report ([`report`]).
//!
//! - [`config`]: the study's `[calibrate]` section and the method it names;
//! - [`problem`]: a parameter point as a run through the store, scored;
//! - [`result`]: what `calibration.json` holds.

pub mod config;
pub mod ego;
pub mod grid;
pub mod nelder_mead;
pub mod problem;
pub mod report;
pub mod result;

use std::path::Path;

use anyhow::Result;
use hvi_run::exec::thread_split;
use hvi_run::runner::{Runner, SlurmBatches};
use hvi_run::slurm::SlurmOptions;
use hvi_run::store::{Record, Store};

pub use config::{CalibrateConfig, Method};
pub use grid::score_table;
pub use report::{report_md, report_text};
pub use result::{CalibrationResult, Evaluation, ParamRegion, Spread, Surface};

use super::options::StudyOptions;
use grid::{grid_stage, Grid};
use nelder_mead::refine_stage;
use problem::{
    best_of, fixed_overrides, paper_point, particles_of, refined_axes, Refinement, Stage,
};
use report::{draw_figures, write_outputs};

/// What `calibrate` takes: the study's options and the search's, as the command line or a
/// library caller gives them.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The study, its tier, output directory and threads.
    pub study: StudyOptions,
    /// Only the grid stage.
    pub no_refine: bool,
    /// The search after the grid (None: `calibrate.method`).
    pub method: Option<Method>,
    /// Nelder-Mead iterations at most (None: `calibrate.max_iters`).
    pub max_iters: Option<u64>,
    /// Surrogate-search batches at most (None: `calibrate.max_batches`).
    pub max_batches: Option<usize>,
    /// The seeds of the surrogate search (None: `calibrate.seeds`).
    pub seeds: Option<Vec<u64>>,
    /// Extend an axis whose side the optimum or its region touches (false: report the edge).
    pub extend: bool,
    /// Run each batch as a Slurm job array with these options, asking the queue every so many
    /// seconds (None: run here).
    pub slurm: Option<(SlurmOptions, f64)>,
}

impl CalibrateOptions {
    /// The grid stage alone of `study`, run here.
    pub fn grid_only(study: StudyOptions) -> CalibrateOptions {
        CalibrateOptions {
            study,
            no_refine: true,
            method: None,
            max_iters: None,
            max_batches: None,
            seeds: None,
            extend: true,
            slurm: None,
        }
    }
}

/// `hvi-study calibrate`: the grid scored, the search after it (ego or Nelder-Mead), the
/// paper's fit at this tier, then calibration.json, calibration.md, evaluations.csv, the maps
/// and the snapshots.
pub fn calibrate(args: &CalibrateOptions) -> Result<CalibrationResult> {
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

/// Where the calibration's runs execute: here (`threads`, `jobs`) or, with Slurm options,
/// each batch as a Slurm job array.
fn runner_of(args: &CalibrateOptions) -> Result<Runner> {
    Ok(match &args.slurm {
        None => Runner::Local(args.study.exec_options()),
        Some((opts, poll)) => {
            Runner::Slurm(SlurmBatches::new(opts.clone(), *poll, !args.study.quiet)?)
        }
    })
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
    surface: Option<Surface>,
    region: Option<ParamRegion>,
    spread: Vec<Spread>,
    runs: usize,
}

/// Stage 2: the search after the grid (none with `--no-refine`, no axis or a zero budget).
fn search_stage(
    problem: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateOptions,
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
            let termination = refine_stage(problem, cfg, args.max_iters, best_grid, refine_keys)?;
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
            let settings = ego::EgoSettings {
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
            let o = ego::search(problem, &settings, &pairs)?;
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
