//! `hvi-study calibrate`: the grid of a calibration study scored against the experiments
//! ([`grid`]), then a search after it that runs real simulations through the same run store:
//! efficient global optimisation ([`ego`], the default) or Nelder-Mead ([`nelder_mead`]); the
//! paper's fit scored at the same tier; and the report ([`mod@report`]).
//!
//! - [`config`]: the study's `[calibrate]` section and the method it names;
//! - [`design`]: which of the grid's points the grid stage runs;
//! - [`problem`]: a parameter point as a run through the store, scored;
//! - [`result`]: what `calibration.json` holds;
//! - [`shots`]: the shot's impact, checked against the study's scene and filled into it.

mod boxes;
pub mod config;
pub mod design;
pub mod ego;
pub mod extend;
pub mod grid;
pub mod identify;
pub mod maps;
pub mod nelder_mead;
pub mod problem;
pub mod report;
pub mod result;
pub mod screen;
pub mod shots;

use std::collections::BTreeMap;
use std::path::Path;

use hvi_run::error::Result;
use hvi_store::exec::thread_split;
use hvi_store::runner::{Runner, SlurmBatches};
use hvi_store::slurm::SlurmOptions;

pub use config::{CalibrateConfig, InitialDesign, Method};
pub use grid::score_table;
pub use report::report;
pub use result::{
    CalibrationResult, EvalStage, Evaluation, ParamRegion, Spread, Surface, TargetsMet,
};
pub use shots::ShotPlan;

use boxes::ego_boxes;
use extend::{bounds_of, edges_of, limit_line, Edge, SearchedBox};
use grid::{grid_stage, Grid};
use hvi_studies::options::StudyOptions;
use nelder_mead::refine_stage;
use problem::{
    best_of, fixed_overrides, particles_of, refined_axes, Refinement, Stage, PAPER_BEST,
};
use report::{archive, draw_figures, write_outputs};
use result::PriorUse;

/// What `calibrate` takes: the study's options and the search's, as the command line or a
/// library caller gives them.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The study, its tier, output directory and threads.
    pub study: StudyOptions,
    /// Only the grid stage, every run in full (the grid's maps are the product; no screen).
    pub no_refine: bool,
    /// The search after the grid (None: `calibrate.method`).
    pub method: Option<Method>,
    /// Nelder-Mead iterations at most (None: `calibrate.max_iters`).
    pub max_iters: Option<u64>,
    /// Surrogate-search batches at most (None: `calibrate.max_batches`).
    pub max_batches: Option<usize>,
    /// The seeds of the surrogate search (None: `calibrate.seeds`).
    pub seeds: Option<Vec<u64>>,
    /// The grid stage's points (None: `calibrate.initial_design`).
    pub initial_design: Option<InitialDesign>,
    /// Extend an axis whose side the optimum or its region touches (false: report the edge).
    pub extend: bool,
    /// Run each batch as a Slurm job array with these options, asking the queue every so many
    /// seconds (None: run here).
    pub slurm: Option<(SlurmOptions, f64)>,
    /// A coarser resolution's calibration whose scored points are the surrogate search's prior
    /// (a ladder's level passes its own to the next; None: no prior).
    pub coarse: Option<Coarse>,
    /// A shot left out of the calibration and predicted at its answer (`--hold-out`).
    pub hold_out: Option<String>,
}

/// A coarser resolution's scored points, the prior of a surrogate search: the search then
/// models the difference between this resolution's log10 J and the coarse one's
/// (docs/calibration.md, "The resolution ladder").
#[derive(Debug, Clone)]
pub struct Coarse {
    /// Its particle count.
    pub particles: f64,
    /// Its answer (run first at this resolution: the coarse optimum is the one point
    /// most likely near the fine one).
    pub best: BTreeMap<String, f64>,
    /// Each scored point: its searched parameters and J over the seeds.
    pub points: Vec<(BTreeMap<String, f64>, f64)>,
    /// The noise of its log10 J.
    pub noise: f64,
    /// The calibration it was itself searched on, if any (the model is then built on it).
    pub prior: Option<Box<Coarse>>,
}

impl Coarse {
    /// The scored points of a surrogate calibration at `particles` (its search's points and
    /// the paper's fit when scored at the same seeds).
    pub fn of(
        r: &CalibrationResult,
        particles: f64,
        noise_floor: f64,
        prior: Option<Coarse>,
    ) -> Coarse {
        let seeds = &r.best.seeds;
        let points = r
            .refinement
            .iter()
            .chain(std::iter::once(&r.paper).filter(|p| &p.seeds == seeds))
            .filter(|e| e.score.is_some() && e.objective.is_finite())
            .map(|e| (e.params.clone(), e.objective))
            .collect();
        Coarse {
            particles,
            best: r.best.params.clone(),
            points,
            noise: r.noise.unwrap_or(noise_floor),
            prior: prior.map(Box::new),
        }
    }
}

impl CalibrateOptions {
    /// Whether the calibration screens its runs as the study's `calibrate.screen` says (false:
    /// every run in full, as `--no-refine` asks: docs/calibration.md, "The screen").
    pub fn screens(&self) -> bool {
        !self.no_refine
    }

    /// The grid stage alone of `study`, run here, every run in full.
    pub fn grid_only(study: StudyOptions) -> CalibrateOptions {
        CalibrateOptions {
            study,
            no_refine: true,
            method: None,
            max_iters: None,
            max_batches: None,
            seeds: None,
            initial_design: None,
            extend: true,
            slurm: None,
            coarse: None,
            hold_out: None,
        }
    }
}

/// `hvi-study calibrate`: the grid scored, the search after it (ego or Nelder-Mead), the
/// paper's fit at this tier, then calibration.json, calibration.md, evaluations.csv, the maps
/// and the snapshots.
pub fn calibrate(args: &CalibrateOptions) -> Result<CalibrationResult> {
    let (study, shots, out) =
        shots::shot_plans(&args.study, args.hold_out.as_deref(), args.screens())?;
    let result = calibrate_plan(args, &study, &shots, &out)?;
    log::info!(target: hvi_run::STDOUT, "{}", out.join("calibration.json").display());
    Ok(result)
}

/// The calibration of a written plan of `study` in its directory `out` (what [`calibrate`]
/// and each level of a ladder (crate hvi-ladder) run).
pub fn calibrate_plan(
    args: &CalibrateOptions,
    study: &hvi_store::spec::Study,
    shots: &[ShotPlan],
    out: &Path,
) -> Result<CalibrationResult> {
    let t0 = std::time::Instant::now();
    let cfg = config_of(study, args)?;
    let (calibrated, held_out): (Vec<&ShotPlan>, Vec<&ShotPlan>) = shots
        .iter()
        .partition(|s| args.hold_out.as_deref() != Some(s.targets.shot.id.as_str()));
    let targets: Vec<_> = calibrated.iter().map(|s| s.targets.clone()).collect();
    let plans: Vec<_> = calibrated.iter().map(|s| &s.plan).collect();
    let plan = plans[0];
    let progress = !args.study.quiet;
    announce(study, shots, progress)?;
    let (refine_keys, dims) = refined_axes(plan, &cfg)?;
    let runner = runner_of(args)?;

    // The grid stage runs the design's points of every shot's grid; the study's grid stays
    // the lattice the box extends on.
    let (designs, design) = design::design_plans(&plans, &dims, cfg.initial_design);
    let design_refs: Vec<_> = designs.iter().collect();
    let screen = screen_of(&cfg, &targets, progress);
    let grid = grid_stage(&design_refs, out, &runner, &targets, progress)?;
    let best_run = designs[0].run(grid.best)?;
    let fixed = fixed_overrides(&plans, &best_run.values, |k| refine_keys.contains(k))?;
    let store = runner.store(out)?;
    let stage = Stage {
        study,
        plan,
        plans: &plans,
        store: &store,
        targets: &targets,
        threads: thread_split(args.study.threads.unwrap_or(0), None, 1).1,
        runner: &runner,
        out,
        progress,
        screen: &screen,
    };
    let first_box = bounds_of(&dims);
    let problem = stage.problem(fixed, dims);
    let method = args.method.unwrap_or(cfg.method);
    // The paper's point is scored over the seeds the answer will be (like with like), before
    // the search: a better point outside the box pulls the box out towards it.
    let searched = !args.no_refine && !problem.dims.is_empty() && method == Method::Ego;
    let search_seeds = if searched { &cfg.seeds[..] } else { &[] };
    let paper = paper_point(&stage, &best_run.values, search_seeds)?;
    let search = search_stage(
        &stage,
        &problem,
        &cfg,
        args,
        method,
        &grid,
        &refine_keys,
        paper.3.clone(),
    )?;
    let answer = Answer::of(&grid, &search, &paper.1);
    let held_out = held_out
        .first()
        .map(|h| shots::predict_held_out(&stage, h, &best_run.values, &refine_keys, &answer.best));
    let found = Found {
        args,
        plan,
        targets: &targets,
        out,
        label: label_of(&cfg, args, method, &search, &first_box)?,
        held_out: held_out.transpose()?,
        grid_runs: grid.ran,
        design,
        paper,
        search,
        answer,
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    let result = found.into_result();
    publish(out, &designs[0], &grid, &result, &cfg, progress)?;
    Ok(result)
}

/// The answer drawn from the evaluations: the best point, the best grid point, which points
/// meet every target and what the targets identify.
struct Answer {
    best: Evaluation,
    best_grid: Evaluation,
    targets_met: Option<TargetsMet>,
    identified: BTreeMap<String, result::Identified>,
}

impl Answer {
    fn of(grid: &Grid, search: &SearchOutcome, paper: &Evaluation) -> Answer {
        // With seeds, the best grid point is the grid's best over those seeds too.
        let best_grid = search
            .evaluations
            .iter()
            .filter(|e| {
                e.stage == EvalStage::GridSeeds && e.score.is_some() && e.objective.is_finite()
            })
            .min_by(|a, b| a.objective.total_cmp(&b.objective))
            .cloned()
            .unwrap_or_else(|| grid.evaluations[grid.best].clone());
        let best = search
            .best
            .clone()
            .unwrap_or_else(|| best_of(&best_grid, &search.evaluations));
        // The grid's own runs count where the answer is at the scene's seed (no search at
        // seeds).
        let targets_met = TargetsMet::of(
            grid.evaluations
                .iter()
                .chain(&search.evaluations)
                .chain(std::iter::once(paper)),
            &best.seeds,
        );
        let identified = identify::identify(
            &search.boxes,
            search.region.as_ref(),
            targets_met.as_ref(),
            &search.edges,
        );
        Answer {
            best,
            best_grid,
            targets_met,
            identified,
        }
    }
}

/// Everything a calibration found, before it becomes its result.
struct Found<'a> {
    args: &'a CalibrateOptions,
    plan: &'a hvi_store::plan::Plan,
    targets: &'a [hvi_analysis::score::Targets],
    out: &'a Path,
    label: String,
    held_out: Option<result::HeldOut>,
    grid_runs: usize,
    design: result::DesignUse,
    paper: PaperPoint,
    search: SearchOutcome,
    answer: Answer,
    wall_seconds: f64,
}

impl Found<'_> {
    fn into_result(self) -> CalibrationResult {
        let (paper_params, paper, paper_runs, _) = self.paper;
        let Answer {
            best,
            best_grid,
            targets_met,
            identified,
        } = self.answer;
        let search = self.search;
        let targets = self.targets;
        CalibrationResult {
            study: self.plan.study.clone(),
            label: self.label,
            tier: self.plan.tier.clone(),
            particles: particles_of(self.out, &best),
            particles_asked: self.args.study.particles,
            targets_file: targets[0].path.clone(),
            targets: hvi_analysis::score::combined_targets(targets),
            gaps: targets.iter().flat_map(|t| t.gaps.clone()).collect(),
            shots: targets.iter().map(result::ShotUse::of).collect(),
            held_out: self.held_out,
            ratio_to_paper: best
                .params
                .iter()
                .filter_map(|(k, v)| paper_params.get(k).map(|p| (k.clone(), v / p)))
                .collect(),
            best,
            best_grid,
            paper,
            termination: search.termination,
            refinement_runs: search.runs,
            refinement: search.evaluations,
            method: search.method.into(),
            converged: search.converged,
            boxes: search.boxes,
            edges: search.edges,
            limit: search.limit,
            noise: search.noise,
            noise_source: search.noise_source,
            surface: search.surface,
            region: search.region,
            best_spread: search.spread,
            initial_design: Some(self.design),
            runs_made: self.grid_runs + search.runs + paper_runs,
            wall_seconds: self.wall_seconds,
            prior: self
                .args
                .coarse
                .as_ref()
                .filter(|_| search.method == Method::Ego.name())
                .map(|c| PriorUse {
                    particles: c.particles,
                    points: c.points.len(),
                    weight: search.prior_weight,
                }),
            targets_met,
            identified,
            bounded: search.bounded,
        }
    }
}

/// The study's `[calibrate]`, with the command line's seeds and initial design.
fn config_of(study: &hvi_store::spec::Study, args: &CalibrateOptions) -> Result<CalibrateConfig> {
    let mut cfg = CalibrateConfig::of(study)?;
    if let Some(seeds) = &args.seeds {
        cfg.seeds = seeds.clone();
        cfg.check_seeds("--seeds")?;
    }
    if let Some(design) = args.initial_design {
        cfg.initial_design = design;
    }
    cfg.screen &= args.screens();
    Ok(cfg)
}

/// Names each shot with the impact it is simulated at (with progress), and prints every
/// shot's resolution warnings (always).
/// The calibration's screen of `cfg` over the shots' `targets`, said on the log (which runs
/// it sends on in free flight: docs/calibration.md, "The screen").
fn screen_of(
    cfg: &CalibrateConfig,
    targets: &[hvi_analysis::score::Targets],
    progress: bool,
) -> screen::Screen {
    let screen = screen::Screen::of(cfg, targets);
    // Every shot with windows, and every shot left out for its plate's thickness (even when
    // that leaves no shot screened), says so.
    if progress {
        announce_screen(&screen);
    }
    screen
}

fn announce_screen(screen: &screen::Screen) {
    let show = |w: Option<[f64; 2]>| {
        w.map(|[lo, hi]| {
            if lo == f64::MIN {
                format!("at most {hi:.4}")
            } else {
                format!("[{lo:.4}, {hi:.4}]")
            }
        })
    };
    for (shot, s) in screen.shots.iter().enumerate() {
        if screen.too_thick(shot) {
            log::info!(
                "screen (shot {}): off, its plate (t/D = {} as simulated) is thicker than calibrate.screen_max_t_over_d = {}: behind thicker plates free flight from the screen's time moves va/v0 by more than the allowance (docs/calibration.md, \"The screen\"); its runs go in full",
                shot + 1,
                s.t_over_d,
                screen.max_t_over_d
            );
            continue;
        }
        let w = &s.windows;
        let parts: Vec<String> = [
            show(w.length_ratio).map(|s| format!("R {s}")),
            show(w.front_velocity_ratio).map(|s| format!("va/v0 {s}")),
        ]
        .into_iter()
        .flatten()
        .collect();
        if !parts.is_empty() {
            log::info!(
                "screen (shot {}): a run whose free flight from tau = {:.2} us (the later of {} transit times D/v0 and {} of the plate, t/v0) gives R or va/v0 outside {} goes on in free flight (calibrate.screen)",
                shot + 1,
                s.after_s * 1e6,
                screen.transits,
                screen.plate_transits,
                parts.join(", ")
            );
        }
    }
}

fn announce(study: &hvi_store::spec::Study, shots: &[ShotPlan], progress: bool) -> Result<()> {
    if progress {
        for s in shots {
            log::info!("{}", shots::describe_shot(&s.targets));
        }
    }
    for s in shots {
        for w in shots::resolution_warnings(study, s)? {
            log::warn!("warning: {w}");
        }
    }
    Ok(())
}

/// Writes the calibration's files and figures, keeps it beside the study's others and prints
/// its report.
fn publish(
    out: &Path,
    plan: &hvi_store::plan::Plan,
    grid: &Grid,
    result: &CalibrationResult,
    cfg: &CalibrateConfig,
    progress: bool,
) -> Result<()> {
    write_outputs(out, result, &grid.evaluations)?;
    draw_figures(out, plan, &grid.records, result, &cfg.log_axes, progress);
    let kept = archive(out, result)?;
    if progress {
        log::info!(
            "kept beside the study's other calibrations: {}",
            kept.display()
        );
        log::info!("{}", (report(result).text()).trim_end_matches('\n'));
    }
    Ok(())
}

/// Where the calibration's runs execute: here (`threads`, `jobs`) or, with Slurm options,
/// each batch as a Slurm job array.
pub fn runner_of(args: &CalibrateOptions) -> Result<Runner> {
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
    /// The answer is a bound (ego): the stopping rule held and every target is met on each
    /// side the answer touches.
    bounded: bool,
    noise: Option<f64>,
    noise_source: Option<String>,
    surface: Option<Surface>,
    region: Option<ParamRegion>,
    spread: Vec<Spread>,
    runs: usize,
    /// Every box searched, the first the grid's.
    boxes: Vec<SearchedBox>,
    /// The sides of the last box the answer touches (empty: interior).
    edges: Vec<Edge>,
    /// Where the extension stopped, in words.
    limit: Option<String>,
    /// The seeds the answer's objective is over (empty: the scene's own).
    seeds: Vec<u64>,
    /// The prior's weight in the final model (None without a prior).
    prior_weight: Option<f64>,
}

/// Stage 2: the search after the grid (none with `--no-refine`, no axis or a zero budget).
#[allow(clippy::too_many_arguments)]
fn search_stage(
    stage: &Stage,
    problem: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateOptions,
    method: Method,
    grid: &Grid,
    refine_keys: &[String],
    anchor: Option<ego::Scored>,
) -> Result<SearchOutcome> {
    let none = |why: &str| SearchOutcome {
        method: "none",
        evaluations: Vec::new(),
        best: None,
        termination: why.to_string(),
        converged: false,
        bounded: false,
        noise: None,
        noise_source: None,
        surface: None,
        region: None,
        spread: Vec::new(),
        runs: 0,
        boxes: Vec::new(),
        edges: Vec::new(),
        limit: None,
        seeds: Vec::new(),
        prior_weight: None,
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
            let refined = refine_stage(problem, cfg, args.max_iters, best_grid, refine_keys)?;
            let termination = refined.termination;
            let evaluations = problem.log.take();
            let best = best_of(best_grid, &evaluations);
            let at = ego::coords(problem, &best.params);
            let mut edges = edges_of(&problem.dims, at.as_deref(), None);
            for e in &mut edges {
                e.limit = Some(
                    "Nelder-Mead searches the grid's box only (the ego search extends it)".into(),
                );
            }
            let converged = refined.converged && edges.is_empty();
            Ok(SearchOutcome {
                method: method.name(),
                evaluations,
                best: None,
                converged,
                bounded: false,
                boxes: vec![SearchedBox {
                    bounds: bounds_of(&problem.dims),
                    termination: termination.clone(),
                    edges: edges.clone(),
                }],
                limit: limit_line(&edges),
                edges,
                termination,
                noise: None,
                noise_source: None,
                surface: None,
                region: None,
                spread: Vec::new(),
                runs: *problem.ran.borrow(),
                seeds: Vec::new(),
                prior_weight: None,
            })
        }
        Method::Ego => ego_boxes(stage, problem, cfg, args, grid, refine_keys, anchor),
    }
}

/// The paper's fit: its parameters, its evaluation, the runs simulated for it and, at seeds,
/// its evaluation with the runs' observables (as the surrogate search takes it).
type PaperPoint = (
    BTreeMap<String, f64>,
    Evaluation,
    usize,
    Option<ego::Scored>,
);

/// The paper's best fit at this tier, through the same store (cache hits where the grid holds
/// it), at `seeds` (the answer's, so that the two objectives compare like with like; empty:
/// the scene's own seed): its parameters on the plan's axes, its evaluation and the runs
/// simulated for it.
fn paper_point(
    stage: &Stage,
    best_values: &[serde_json::Value],
    seeds: &[u64],
) -> Result<PaperPoint> {
    let mut paper_params = BTreeMap::new();
    for (k, v) in PAPER_BEST {
        if stage.plan.axes.iter().any(|a| a.key == k) {
            paper_params.insert(k.to_string(), v);
        }
    }
    let fixed = fixed_overrides(stage.plans, best_values, |k| paper_params.contains_key(k))?;
    let problem = stage.problem(fixed, Vec::new());
    if seeds.is_empty() {
        let paper = problem.evaluate(EvalStage::Paper, &paper_params)?;
        let ran = usize::from(!paper.cached && paper.dir.is_some());
        return Ok((paper_params, paper, ran, None));
    }
    let seeds: Vec<Option<u64>> = seeds.iter().copied().map(Some).collect();
    let (mut evs, ran) = ego::run_points(
        &problem,
        EvalStage::Paper,
        std::slice::from_ref(&paper_params),
        &seeds,
    )?;
    let scored = evs.pop().ok_or_else(|| {
        hvi_run::error::RunError::Input("the paper's point has no evaluation".to_string())
    })?;
    Ok((paper_params, scored.0.clone(), ran, Some(scored)))
}

/// The calibration's label: `<method>-seeds<s1_s2...>-<digest>` (`<method>-<digest>` at the
/// scene's own seed), the digest (8 hex digits of
/// SHA-256) over every setting that can change its answer (the search's settings, the targets
/// and weights, the first box, and the command line's `--set` overrides when it has any) so that
/// two calibrations differ in label whenever they may differ in result. The overrides count
/// because one study directory can hold calibrations under several: asked again with
/// `--set analysis.width=cylindrical`, a calibration measures the stored runs from their kept
/// states, and its answer sits beside the first one's.
fn label_of(
    cfg: &CalibrateConfig,
    args: &CalibrateOptions,
    method: Method,
    search: &SearchOutcome,
    first_box: &BTreeMap<String, (f64, f64)>,
) -> Result<String> {
    use sha2::{Digest, Sha256};
    let name = if search.method == "none" {
        "grid"
    } else {
        method.name()
    };
    let mut settings = serde_json::json!({
        "method": name,
        "seeds": cfg.seeds,
        "batch": cfg.batch,
        "max_batches": args.max_batches.unwrap_or(cfg.max_batches),
        "noise_floor": cfg.noise_floor,
        "seeds_within_decades": if cfg.seeds_within_decades.is_finite() {
            serde_json::json!(cfg.seeds_within_decades)
        } else {
            serde_json::json!("inf")
        },
        "max_extensions": cfg.max_extensions,
        "extend": args.extend,
        "max_iters": args.max_iters.unwrap_or(cfg.max_iters),
        "sd_tolerance": cfg.sd_tolerance,
        "refine": cfg.refine,
        "log_axes": cfg.log_axes,
        "targets": cfg.shot_files().first(),
        "weights": cfg.weights,
        "box": first_box,
    });
    let files = cfg.shot_files();
    if files.len() > 1 {
        settings["shots"] = serde_json::json!(files);
    }
    if let Some(h) = &args.hold_out {
        settings["hold_out"] = serde_json::json!(h);
    }
    // Only when not the default, so that the labels of grid-design calibrations stay what
    // they were.
    if cfg.initial_design != InitialDesign::Grid {
        settings["initial_design"] = serde_json::json!(cfg.initial_design.name());
    }
    // Only when given, so that the labels of calibrations without overrides stay what they were.
    if !args.study.sets.is_empty() {
        settings["set"] = serde_json::json!(args.study.sets);
    }
    let digest = Sha256::digest(hvi_store::plan::canonical_json(&settings).as_bytes());
    let hex: String = digest.iter().take(4).map(|b| format!("{b:02x}")).collect();
    // The seeds the answer is over; none named for Nelder-Mead and the grid alone (the scene's
    // own seed).
    if search.seeds.is_empty() {
        return Ok(format!("{name}-{hex}"));
    }
    let seeds = search
        .seeds
        .iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join("_");
    Ok(format!("{name}-seeds{seeds}-{hex}"))
}
