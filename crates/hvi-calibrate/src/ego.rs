//! The calibration's surrogate search (`calibrate.method = "ego"`, the default): efficient
//! global optimisation over the refined axes ([`hvi_analysis::surrogate`]), every point run at
//! the study's seeds through the run store, a batch of points at once.
//!
//! 1. The grid's points are the first observations (at the seeds when `calibrate.seeds` names
//!    several; the runs at the scene's own seed are the grid's). With several seeds a point
//!    runs at the first, and at the others only when its objective is within
//!    `calibrate.seeds_within_decades` decades of the lowest so far (`run_points_screened`):
//!    so it is for the grid, an extended box's new points and every batch.
//! 2. Each batch: the model is of log10 J (J spans decades over a grid); its noise is the
//!    standard error of a seed mean's log10 J (pooled over the points, at least
//!    `calibrate.noise_floor`); the kriging model proposes
//!    `calibrate.batch` points by expected improvement; they run together (at the seeds as
//!    screened) through the store and are scored on their seed-mean observables.
//! 3. The search stops converged when the largest expected improvement left is below the
//!    noise (on a coarser level's prior: under the model on the prior and under the model of
//!    the level's own points alone, [`hvi_analysis::surrogate::step`]), or not converged after
//!    `calibrate.max_batches` batches (or when no candidate is left).
//! 4. The answer: the evaluated point with the lowest *predicted* objective (a single lucky
//!    seed does not win), the confidence region of the minimum as one interval per axis, and
//!    each target's observable at that point over the seeds.
//!
//! A killed calibration resumes with nothing lost: the proposals are a deterministic function
//! of the observations, so a second invocation proposes the same points and finds their runs
//! in the store.

use std::collections::BTreeMap;

use hvi_analysis::observable::{Observable, Observables};
use hvi_analysis::surrogate::{
    self, seed_mean_noise, step, Observation, Prior, SearchBox, Step, Surrogate,
};
use hvi_run::error::{Result, RunError};
use hvi_store::store::{Job, Record, RunStatus};

use crate::problem::{fmt_params, Dim, Refinement};
use crate::result::EvalStage;
use crate::result::{observed_means, shot_means, Evaluation, ParamRegion, Spread, Surface};

/// The search's settings (`[calibrate]`).
#[derive(Debug, Clone)]
pub(super) struct EgoSettings {
    /// Points per batch.
    pub batch: usize,
    /// Seeds each point runs at (empty: the scene's seed only).
    pub seeds: Vec<u64>,
    /// Batches at most.
    pub max_batches: usize,
    /// The least noise assumed for the objective (a seed mean's standard error).
    pub noise_floor: f64,
    /// The seeds after the first run only at points whose first seed's objective is within
    /// this many decades of the lowest so far ([`run_points_screened`]; infinite: all).
    pub seeds_within_decades: f64,
    /// A coarser resolution's model of log10 J: the search models the difference from it.
    pub prior: Option<Prior>,
}

/// What the search found.
#[derive(Debug, Clone)]
pub(super) struct EgoOutcome {
    /// Every observation: those the search started from, then its own points, in order, each
    /// with its runs' observables.
    pub evaluations: Vec<Scored>,
    /// Batches run.
    pub batches: usize,
    /// The point chosen (the evaluated point with the lowest predicted objective).
    pub best: Evaluation,
    /// Whether the stopping rule held.
    pub converged: bool,
    /// Why the search stopped.
    pub termination: String,
    /// The noise the search worked with (of log10 J).
    pub noise: f64,
    /// Where it comes from (measured, or the floor and why).
    pub noise_source: String,
    /// The confidence region.
    pub region: Option<ParamRegion>,
    /// The targets' observables over the seeds at the best point.
    pub spread: Vec<Spread>,
    /// The final model's prediction over two searched axes.
    pub surface: Option<Surface>,
    /// Runs simulated.
    pub runs: usize,
    /// The prior's weight in the final model (None without a prior).
    pub prior_weight: Option<f64>,
}

/// An evaluated point with its runs' observables: per shot, one per seed.
pub(super) type Scored = (Evaluation, Vec<Vec<Observables>>);

/// One point's runs at every seed of every shot, scored on the seed means.
struct PointRuns {
    params: BTreeMap<String, f64>,
    /// One job per shot and seed, shot-major (Err: the scene is invalid, with why).
    jobs: Vec<std::result::Result<Job, String>>,
}

/// The seeds a point runs at (`None`: the scene's own).
pub(super) fn seed_list(settings: &EgoSettings) -> Vec<Option<u64>> {
    seeds_of(&settings.seeds)
}

/// Each point's run seeds: `seeds`, or the scene's own seed (None) when empty.
pub fn seeds_of(seeds: &[u64]) -> Vec<Option<u64>> {
    if seeds.is_empty() {
        vec![None]
    } else {
        seeds.iter().copied().map(Some).collect()
    }
}

/// The search's first observations: the grid's scored runs (each with its record), at every
/// seed of the search when it names several (the runs at the scene's own seed are the
/// grid's). Returns them with the runs simulated.
pub(super) fn seeded_grid(
    problem: &Refinement,
    settings: &EgoSettings,
    grid: &[(Evaluation, Vec<Record>)],
) -> Result<(Vec<Scored>, usize)> {
    let scored_grid = grid
        .iter()
        .filter(|(e, r)| r.iter().all(|r| r.status == RunStatus::Completed) && e.score.is_some());
    if settings.seeds.is_empty() {
        let evaluations = scored_grid
            .map(|(e, r)| {
                let mut e = e.clone();
                e.seed_objectives = vec![e.objective];
                (e, r.iter().map(|r| vec![r.observables]).collect())
            })
            .collect();
        return Ok((evaluations, 0));
    }
    let (steps, grid_points): (Vec<usize>, Vec<BTreeMap<String, f64>>) = scored_grid
        .map(|(e, _)| (e.step, refined(problem, &e.params)))
        .unzip();
    let (mut evaluations, runs) = run_points_screened(
        problem,
        EvalStage::GridSeeds,
        &grid_points,
        &seed_list(settings),
        settings,
        f64::INFINITY,
    )?;
    // Each point keeps its grid run's index (the maps slice the grid at the best one's), also
    // where a failed grid run or the initial design leaves points out.
    for ((e, _), step) in evaluations.iter_mut().zip(steps) {
        e.step = step;
    }
    Ok((evaluations, runs))
}

/// The lowest objective among `evaluations` (infinite when none is scored).
pub(super) fn lowest(evaluations: &[Scored]) -> f64 {
    evaluations
        .iter()
        .map(|(e, _)| e.objective)
        .filter(|j| j.is_finite())
        .fold(f64::INFINITY, f64::min)
}

/// How the seeds are screened, for the search's first line (empty with one seed or none).
pub(super) fn screening(settings: &EgoSettings) -> String {
    if settings.seeds.len() < 2 {
        String::new()
    } else if settings.seeds_within_decades.is_finite() {
        format!(
            " (the seeds after the first only where the first's J is within {} decade(s) of the lowest)",
            settings.seeds_within_decades
        )
    } else {
        " (every seed at every point)".to_string()
    }
}

/// Runs `points` at the first of `seeds`, then at every seed only the points whose first
/// seed's objective is within `settings.seeds_within_decades` decades of the lowest so far
/// (`lowest`, or the batch's own lowest): a point a decade or more above the answer is ranked
/// by one run (the seed scatter of log10 J is a few hundredths of a decade), and the scatter is
/// measured, and the seed means taken, where the answer is decided. A point that failed or was
/// not scored keeps its one run. Every decision is a function of the runs, so a resumed
/// calibration makes the same ones from the store. Returns the evaluations in `points`' order
/// and the runs simulated.
pub(super) fn run_points_screened(
    problem: &Refinement,
    stage: EvalStage,
    points: &[BTreeMap<String, f64>],
    seeds: &[Option<u64>],
    settings: &EgoSettings,
    lowest_so_far: f64,
) -> Result<(Vec<Scored>, usize)> {
    if seeds.len() < 2 || settings.seeds_within_decades.is_infinite() {
        return run_points(problem, stage, points, seeds);
    }
    let (mut first, ran) = run_points(problem, stage, points, &seeds[..1])?;
    let cutoff = log_objective(lowest_so_far.min(lowest(&first))) + settings.seeds_within_decades;
    let chosen: Vec<usize> = (0..first.len())
        .filter(|&k| {
            let e = &first[k].0;
            e.score.is_some() && e.objective.is_finite() && log_objective(e.objective) <= cutoff
        })
        .collect();
    if chosen.is_empty() {
        return Ok((first, ran));
    }
    let again: Vec<BTreeMap<String, f64>> = chosen.iter().map(|&k| points[k].clone()).collect();
    let (more, ran_more) = run_points(problem, stage, &again, seeds)?;
    for (&k, (mut e, observables)) in chosen.iter().zip(more) {
        e.step = first[k].0.step;
        first[k] = (e, observables);
    }
    Ok((first, ran + ran_more))
}

/// Runs the search over the problem's box from the observations so far (`evaluations`, each
/// with its runs' observables); its batches are numbered from `first_batch` on.
pub(super) fn search(
    problem: &Refinement,
    settings: &EgoSettings,
    mut evaluations: Vec<Scored>,
    first_batch: usize,
) -> Result<EgoOutcome> {
    let space = SearchBox::new(problem.dims.iter().map(|d| (d.lo, d.hi)).collect())?;
    let seeds = seed_list(settings);
    let mut progress = Progress {
        runs: 0,
        batch: 0,
        started: std::time::Instant::now(),
    };
    let (converged, termination, noise, noise_source) = loop {
        let obs = observations(problem, &evaluations);
        let (noise, noise_source) = noise_of(&evaluations, settings.noise_floor);
        if obs.len() < 2 {
            return Err(RunError::Input(format!(
                "the surrogate search needs at least 2 scored points, the grid gave {}",
                obs.len()
            )));
        }
        let next = step(&space, &obs, noise, settings.batch, settings.prior.as_ref())?;
        if problem.progress {
            progress.report(settings, seeds.len(), &next, obs.len(), noise);
        }
        if let Some((converged, why)) = stop(settings, &next, progress.batch, noise) {
            break (converged, why, noise, noise_source);
        }
        let points: Vec<BTreeMap<String, f64>> = next
            .proposal
            .points
            .iter()
            .map(|x| problem.values(x))
            .collect();
        let label = EvalStage::Search(first_batch + progress.batch);
        let (evs, n) = run_points_screened(
            problem,
            label,
            &points,
            &seeds,
            settings,
            lowest(&evaluations),
        )?;
        if problem.progress {
            for (e, _) in &evs {
                log::info!("{label}: {}  J = {:.4}", fmt_params(&e.params), e.objective);
            }
        }
        evaluations.extend(evs);
        progress.runs += n;
        progress.batch += 1;
    };
    let obs = observations(problem, &evaluations);
    let model = Surrogate::fit_on(&space, &obs, noise, settings.prior.as_ref())?;
    let best_index = best_predicted(&model, problem, &evaluations)?;
    let (best, observables) = evaluations[best_index].clone();
    let region = surrogate::region(&space, &obs, noise, settings.prior.as_ref())
        .ok()
        .map(|r| param_region(problem, &r));
    let spread = spread_of(problem, &observables);
    let surface = coords(problem, &best.params).and_then(|at| surface(problem, &model, &at));
    Ok(EgoOutcome {
        evaluations,
        batches: progress.batch,
        best,
        converged,
        termination,
        noise,
        noise_source,
        region,
        spread,
        surface,
        runs: progress.runs,
        prior_weight: model.prior_weight(),
    })
}

/// How far a search has come: its runs and batches, and when it started.
struct Progress {
    runs: usize,
    batch: usize,
    started: std::time::Instant,
}

impl Progress {
    /// The batch's line on the console: points scored, noise, the largest expected
    /// improvement (with and without the prior) and at most how much is left.
    fn report(&self, settings: &EgoSettings, seeds: usize, next: &Step, scored: usize, noise: f64) {
        let ei = next.expected_improvement;
        let own = match next.own_expected_improvement {
            Some(own) => format!(
                ", without the prior {own:.4}{}",
                if next.converged {
                    ""
                } else {
                    " (the batch is that model's)"
                }
            ),
            None => String::new(),
        };
        // What is left at most: the batches not yet run, at this search's wall time per run
        // so far (the search can stop sooner).
        let left = settings.max_batches.saturating_sub(self.batch) * settings.batch * seeds;
        let bound = if self.runs > 0 && !next.converged {
            let per_run = self.started.elapsed().as_secs_f64() / self.runs as f64;
            format!(
                "; batch {} of at most {}, at most {left} runs (about {}) left",
                self.batch + 1,
                settings.max_batches,
                hvi_analysis::number::fmt_duration(per_run * left as f64)
            )
        } else {
            String::new()
        };
        log::info!(
            "ego: {scored} points scored, noise {noise:.4}, largest expected improvement {ei:.4}{own}{bound}"
        );
    }
}

/// Whether the search stops before batch `batch`, and why: (converged, the reason in words).
fn stop(settings: &EgoSettings, next: &Step, batch: usize, noise: f64) -> Option<(bool, String)> {
    let ei = next.expected_improvement;
    if next.converged {
        let why = match next.own_expected_improvement {
            Some(own) => format!("the largest expected improvement left is below the noise of log10 J ({noise:.3e}) on the prior ({ei:.3e}) and without it ({own:.3e})"),
            None => format!("the largest expected improvement left ({ei:.3e}) is below the noise of log10 J ({noise:.3e})"),
        };
        return Some((
            true,
            format!("the stopping rule held after {batch} batch(es): {why}"),
        ));
    }
    let ei = next.proposal.max_expected_improvement;
    if next.proposal.points.is_empty() {
        return Some((false, format!("not converged: no candidate left after {batch} batch(es) (largest expected improvement {ei:.3e}, noise {noise:.3e})")));
    }
    if batch >= settings.max_batches {
        return Some((false, format!("not converged: max_batches = {} reached; the largest expected improvement left ({ei:.3e}) is above the noise of log10 J ({noise:.3e}): raise calibrate.max_batches and run again (finished runs are reused)", settings.max_batches)));
    }
    None
}

/// The model of a coarser calibration's scored points in this problem's coordinates, the
/// search's prior; built on the calibration's own prior when it had one (the model of each
/// level is then the difference from the one below, down to the first).
pub(super) fn prior_of(problem: &Refinement, coarse: &crate::Coarse) -> Result<Prior> {
    let inner = match &coarse.prior {
        Some(c) => Some(prior_of(problem, c)?),
        None => None,
    };
    let obs: Vec<Observation> = coarse
        .points
        .iter()
        .filter(|(_, j)| j.is_finite())
        .filter_map(|(p, j)| {
            coords(problem, p).map(|x| Observation {
                x,
                y: log_objective(*j),
            })
        })
        .collect();
    if obs.len() < 3 {
        return Err(RunError::Input(format!(
            "the {}-particle calibration has {} scored points with every searched key (a prior needs 3)",
            coarse.particles,
            obs.len()
        )));
    }
    Ok(Prior::fit_on(&obs, coarse.noise, inner.as_ref())?)
}

/// Points per axis of [`Surface`].
const SURFACE_POINTS: usize = 33;

/// The [`Surface`] of the final model (None with fewer than two searched axes, or when the
/// prediction fails).
fn surface(problem: &Refinement, model: &Surrogate, at: &[f64]) -> Option<Surface> {
    let [Dim {
        key: kx,
        log: logx,
        lo: x0,
        hi: x1,
    }, Dim {
        key: ky,
        log: logy,
        lo: y0,
        hi: y1,
    }] = problem.dims.get(..2)?
    else {
        return None;
    };
    let axis = |lo: f64, hi: f64| -> Vec<f64> {
        (0..SURFACE_POINTS)
            .map(|k| lo + (hi - lo) * k as f64 / (SURFACE_POINTS - 1) as f64)
            .collect()
    };
    let (us, vs) = (axis(*x0, *x1), axis(*y0, *y1));
    let mut points = Vec::with_capacity(us.len() * vs.len());
    for &v in &vs {
        for &u in &us {
            let mut x = at.to_vec();
            x[0] = u;
            x[1] = v;
            points.push(x);
        }
    }
    let predicted = model.predict(&points).ok()?;
    let z = predicted
        .chunks(us.len())
        .map(|row| row.iter().map(|p| p.0).collect())
        .collect();
    let shown = |log: bool, w: &[f64]| -> Vec<f64> {
        w.iter()
            .map(|&u| if log { 10f64.powf(u) } else { u })
            .collect()
    };
    let field = hvi_analysis::contour::Field::new(shown(*logx, &us), shown(*logy, &vs), z)?;
    Some(Surface {
        keys: (kx.clone(), ky.clone()),
        field,
    })
}

/// The refined keys' values of a parameter point.
fn refined(problem: &Refinement, params: &BTreeMap<String, f64>) -> BTreeMap<String, f64> {
    problem
        .dims
        .iter()
        .filter_map(|d| params.get(&d.key).map(|v| (d.key.clone(), *v)))
        .collect()
}

/// A point in the search's coordinates.
pub(super) fn coords(problem: &Refinement, params: &BTreeMap<String, f64>) -> Option<Vec<f64>> {
    problem
        .dims
        .iter()
        .map(|Dim { key: k, log, .. }| params.get(k).map(|&v| if *log { v.log10() } else { v }))
        .collect()
}

/// The scored evaluations as the surrogate's observations.
fn observations(problem: &Refinement, evaluations: &[Scored]) -> Vec<Observation> {
    evaluations
        .iter()
        .filter(|(e, _)| e.score.is_some() && e.objective.is_finite())
        .filter_map(|(e, _)| {
            coords(problem, &e.params).map(|x| Observation {
                x,
                y: log_objective(e.objective),
            })
        })
        .collect()
}

/// The surrogate models log10 J: the objective spans decades over a grid (a squared
/// deviation per target), and its seed scatter grows with it, so that in log10 the noise is
/// about the same everywhere and the model is not ruled by the worst points. J is floored at
/// 1e-6 (every target met exactly).
pub(super) fn log_objective(j: f64) -> f64 {
    j.max(1e-6).log10()
}

/// The noise of a seed mean's log10 objective: pooled over the points, at least `floor`; and
/// where it comes from, in words.
fn noise_of(evaluations: &[Scored], floor: f64) -> (f64, String) {
    let groups: Vec<Vec<f64>> = evaluations
        .iter()
        .map(|(e, _)| {
            e.seed_objectives
                .iter()
                .map(|&j| log_objective(j))
                .collect()
        })
        .collect();
    let points = groups.iter().filter(|g| g.len() > 1).count();
    match seed_mean_noise(&groups) {
        Some(n) if n >= floor => (
            n,
            format!("measured: the pooled standard error of a seed mean over {points} points"),
        ),
        Some(n) => (
            floor,
            format!("calibrate.noise_floor: the {n:.4} measured over {points} points is below it"),
        ),
        None => (
            floor,
            "calibrate.noise_floor, not measured: with one seed the runs show no scatter, so the \
             stopping rule and the region rest on an assumed noise (run at two or more seeds, \
             calibrate.seeds, to measure it)"
                .to_string(),
        ),
    }
}

/// Runs `points` at every seed of every shot together (in parallel through the store) and
/// scores each on its seed-mean observables per shot. Returns the evaluations (with the runs'
/// observables) and the runs simulated.
pub fn run_points(
    problem: &Refinement,
    stage: EvalStage,
    points: &[BTreeMap<String, f64>],
    seeds: &[Option<u64>],
) -> Result<(Vec<Scored>, usize)> {
    let mut planned = Vec::new();
    for p in points {
        // Shot-major: every seed of the first shot, then of the next.
        let mut jobs = Vec::new();
        for &s in seeds {
            jobs.push(problem.jobs(p, s)?);
        }
        let shots = jobs.first().map_or(0, Vec::len);
        let jobs = (0..shots)
            .flat_map(|shot| jobs.iter().map(move |per_seed| per_seed[shot].clone()))
            .collect();
        planned.push(PointRuns {
            params: p.clone(),
            jobs,
        });
    }
    let jobs: Vec<Job> = planned
        .iter()
        .flat_map(|p| p.jobs.iter().filter_map(|j| j.as_ref().ok().cloned()))
        .collect();
    let describe = |i: usize| fmt_params(&refined_of_job(&jobs[i]));
    // Which runs the store held before this batch: a point is `cached` when all of its were.
    let mut stored = Vec::with_capacity(jobs.len());
    for j in &jobs {
        stored.push(matches!(problem.store.record(&j.fingerprint)?, Some(r) if r.is_final()));
    }
    let report = problem.runner.execute(
        problem.store,
        problem.out,
        problem.plan,
        &jobs,
        &describe,
        &stage.to_string(),
    )?;
    let mut records = report.records.into_iter();
    let mut stored = stored.into_iter();
    let mut out = Vec::new();
    for (step, p) in planned.into_iter().enumerate() {
        let mut recs: Vec<Vec<Record>> = Vec::new();
        let mut why = None;
        let mut dirs = Vec::new();
        let mut cached = true;
        for (k, j) in p.jobs.iter().enumerate() {
            if k % seeds.len() == 0 {
                recs.push(Vec::new());
            }
            match j {
                Ok(job) => {
                    let r = records.next().ok_or_else(|| {
                        RunError::Input("a run of the batch has no record".to_string())
                    })?;
                    cached &= stored.next().unwrap_or(false);
                    dirs.push(hvi_store::plan::run_dir_name(&job.fingerprint));
                    if let Some(last) = recs.last_mut() {
                        last.push(r);
                    }
                }
                Err(e) => why = Some(e.clone()),
            }
        }
        let cached = cached && !dirs.is_empty();
        let runs = PointRecords {
            recs,
            dirs,
            invalid: why,
            cached,
        };
        out.push(scored(problem, stage, step, p.params, seeds, runs));
    }
    Ok((out, report.ran))
}

/// The refined parameters of a job, for its progress line.
fn refined_of_job(job: &Job) -> BTreeMap<String, f64> {
    job.params
        .iter()
        .filter_map(|(k, v)| v.as_f64().map(|x| (k.clone(), x)))
        .collect()
}

/// A point's runs: per shot, one record per seed; their directories; why the point has no
/// runs (an invalid scene), and whether every run was in the store before.
struct PointRecords {
    recs: Vec<Vec<Record>>,
    dirs: Vec<String>,
    invalid: Option<String>,
    cached: bool,
}

/// A point's evaluation from its runs: the combined score of each shot's seed-mean
/// observables, each seed's combined objective, the status (completed only when every run
/// completed); `cached` when every run was in the store before.
fn scored(
    problem: &Refinement,
    stage: EvalStage,
    step: usize,
    params: BTreeMap<String, f64>,
    seeds: &[Option<u64>],
    runs: PointRecords,
) -> Scored {
    let PointRecords {
        recs,
        dirs,
        invalid,
        cached,
    } = runs;
    let complete = invalid.is_none()
        && recs.len() == problem.targets.len()
        && recs
            .iter()
            .all(|r| !r.is_empty() && r.iter().all(|r| r.status == RunStatus::Completed));
    let observables: Vec<Vec<Observables>> = recs
        .iter()
        .map(|r| r.iter().map(|r| r.observables).collect())
        .collect();
    let means: Vec<BTreeMap<String, f64>> = observables.iter().map(|o| observed_means(o)).collect();
    let score = complete.then(|| problem.score(|s, o: Observable| means[s].get(o.name()).copied()));
    let seed_objectives = if complete {
        (0..observables[0].len())
            .map(|k| problem.score(|s, o| observables[s][k].get(o)).objective)
            .collect()
    } else {
        Vec::new()
    };
    let status = match (&invalid, complete) {
        (Some(why), _) => why.clone(),
        (None, true) => "completed".into(),
        (None, false) => {
            let failed: Vec<String> = recs
                .iter()
                .flatten()
                .filter(|r| r.status != RunStatus::Completed)
                .map(|r| r.error.clone().unwrap_or_else(|| "(no message)".into()))
                .collect();
            format!("failed: {}", failed.join("; "))
        }
    };
    let e = Evaluation {
        stage,
        step,
        params,
        objective: score.as_ref().map_or(f64::NAN, |s| s.objective),
        score,
        status,
        cached,
        dir: dirs.first().cloned(),
        seeds: seeds.iter().flatten().copied().collect(),
        seed_objectives,
        means: shot_means(problem.targets, &observables),
    };
    (e, observables)
}

/// The evaluated point with the lowest predicted objective.
fn best_predicted(
    model: &Surrogate,
    problem: &Refinement,
    evaluations: &[Scored],
) -> Result<usize> {
    let mut best = None;
    for (i, (e, _)) in evaluations.iter().enumerate() {
        if e.score.is_none() || !e.objective.is_finite() {
            continue;
        }
        let Some(x) = coords(problem, &e.params) else {
            continue;
        };
        let m = model.predict(&[x])?[0].0;
        if best.is_none_or(|(_, b)| m < b) {
            best = Some((i, m));
        }
    }
    best.map(|b| b.0)
        .ok_or_else(|| RunError::Input("no point of the search has a score".to_string()))
}

/// The surrogate's region in the parameters' units.
fn param_region(problem: &Refinement, r: &surrogate::Region) -> ParamRegion {
    let value = |log: bool, u: f64| if log { 10f64.powf(u) } else { u };
    let mut intervals = BTreeMap::new();
    let mut at_boundary = BTreeMap::new();
    let mut sides = BTreeMap::new();
    let mut predicted_minimum = BTreeMap::new();
    for (k, Dim { key, log, .. }) in problem.dims.iter().enumerate() {
        let (lo, hi) = r.intervals[k];
        intervals.insert(key.clone(), (value(*log, lo), value(*log, hi)));
        at_boundary.insert(key.clone(), r.at_boundary[k]);
        if let Some(&side) = r.sides.get(k) {
            sides.insert(key.clone(), side);
        }
        predicted_minimum.insert(key.clone(), value(*log, r.best[k]));
    }
    ParamRegion {
        intervals,
        at_boundary,
        sides,
        predicted_minimum,
        predicted_objective: (10f64.powf(r.best_predicted.0), r.best_predicted.1),
        threshold: 10f64.powf(r.threshold),
        share_of_box: r.share_of_box,
    }
}

/// Each target's observable over the seeds, every shot's (named as the combined score names
/// its terms).
pub(super) fn spread_of(problem: &Refinement, observables: &[Vec<Observables>]) -> Vec<Spread> {
    let names = hvi_analysis::score::combined_targets(problem.targets);
    let per_shot = problem.targets.iter().zip(observables);
    per_shot
        .flat_map(|(shot, runs)| shot.targets.iter().map(move |t| (t, runs)))
        .zip(&names)
        .filter_map(|((t, runs), named)| {
            let v: Vec<f64> = runs.iter().filter_map(|o| o.get(t.observable)).collect();
            if v.is_empty() {
                return None;
            }
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let sd = if v.len() > 1 {
                (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
            } else {
                0.0
            };
            Some(Spread {
                target: named.name.clone(),
                mean,
                sd,
                seeds: v.len(),
            })
        })
        .collect()
}
