//! `hvi-study calibrate --ladder N1,N2,...`: the calibration over an ascending list of
//! particle counts, each level a whole calibration in its own study directory, the coarse
//! levels steering the fine ones.
//!
//! - Level 1 searches from the study's grid, as a calibration at one resolution does.
//! - Each later level starts from a small grid (`calibrate.ladder_values` values per searched
//!   axis) over the previous level's confidence region, padded by a quarter of its width on
//!   each side and at least half a decade wide on a log axis (one grid step of the study on a
//!   linear one), and widened to hold that region moved by the trend of the last two
//!   levels' answers per decade of N when there are two (and both are inside their boxes).
//!   Its search models the difference from the level before (a multi-fidelity prior). The
//!   edge-aware search extends that box where the answer leaves it.
//! - Optionally (`--ladder-check N`, `calibrate.ladder_check`) the last answer is run at a
//!   finer resolution at the search's seeds and scored.
//! - The verdict: converged in N when the last two levels' intervals overlap on every
//!   searched parameter and both answers are interior; else not, with the trend. Beside it,
//!   model-free, the region to carry across resolutions: where the spans of the points that
//!   meet every target at the last two levels overlap on every searched parameter.
//!
//! Writes `ladder.json`, `ladder.md` and `ladder.png` beside the levels' directories
//! (`n<N>/`, each with its own calibration.json, store and maps). docs/calibration.md
//! describes it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hvi_analysis::number::round_sig;
use hvi_run::bail;
use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::files::write_atomic_bytes;
use hvi_store::exec::thread_split;
use hvi_store::plan::Plan;
use hvi_store::spec::{Axis, Study};
use hvi_store::store::{Record, Store};
use serde::{Deserialize, Serialize};

use hvi_calibrate::config::{CalibrateConfig, Method};
use hvi_calibrate::problem::{fixed_overrides, refined_axes, Dim, Stage, PAPER_BEST};
use hvi_calibrate::result::EvalStage;
use hvi_calibrate::result::{
    fmt_bounds, fmt_value, CalibrationResult, Edge, Evaluation, TargetsMet,
};
use hvi_calibrate::shots::plans_of;
use hvi_calibrate::{calibrate_plan, ego, runner_of, CalibrateOptions, Coarse};
use hvi_studies::document::Document;

/// What a ladder takes beside the calibration's options.
#[derive(Debug, Clone)]
pub struct LadderOptions {
    /// The particle counts, ascending.
    pub particles: Vec<f64>,
    /// The particle count of the check run at the last answer (None: `calibrate.ladder_check`).
    pub check: Option<f64>,
}

/// One level of the ladder.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LadderLevel {
    /// The particle count asked for.
    pub particles: f64,
    /// The particles of its runs (the lattice rounds the count).
    pub particles_run: Option<f64>,
    /// Its study directory, relative to the ladder's.
    pub dir: PathBuf,
    /// Where its first box came from, in words.
    pub steered_by: String,
    /// Its first box, per searched key (lowest, highest).
    pub first_box: BTreeMap<String, (f64, f64)>,
    /// The calibrated parameters.
    pub best: BTreeMap<String, f64>,
    /// The objective at them, over the search's seeds.
    pub objective: f64,
    /// Their confidence intervals (empty: no region).
    pub intervals: BTreeMap<String, (f64, f64)>,
    /// Whether the level's search converged with its answer inside its box.
    pub converged: bool,
    /// The sides of its last box its answer touches.
    pub edges: Vec<Edge>,
    /// The paper's fit scored at this resolution over the same seeds.
    pub paper_objective: f64,
    /// Runs in the level's store (every run it used, whether made now or before).
    pub runs: usize,
    /// Their simulated cost: the sum over those runs of wall time times threads, core-seconds.
    pub run_core_seconds: f64,
    /// Runs simulated by this invocation.
    pub runs_made: usize,
    /// Wall time of this invocation's level, s.
    pub wall_seconds: f64,
    /// The points of the level that meet every target, and their spans.
    #[serde(default)]
    pub targets_met: Option<TargetsMet>,
}

/// The last answer run at a finer resolution.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LadderCheck {
    /// The particle count asked for.
    pub particles: f64,
    /// Its directory, relative to the ladder's.
    pub dir: PathBuf,
    /// The parameters (the last level's answer).
    pub params: BTreeMap<String, f64>,
    /// The objective there over the seeds.
    pub objective: f64,
    /// Per target: (observed seed mean at the check, at the last level).
    pub observed: BTreeMap<String, (Option<f64>, Option<f64>)>,
    /// Runs in its store and their cost, core-seconds.
    pub runs: usize,
    /// Sum of wall time times threads over its runs.
    pub run_core_seconds: f64,
}

/// What `ladder.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LadderResult {
    /// The study.
    pub study: String,
    /// The tier (its overrides other than the particle count apply at every level).
    pub tier: String,
    /// The seeds every level's search ran at.
    pub seeds: Vec<u64>,
    /// The levels, coarsest first.
    pub levels: Vec<LadderLevel>,
    /// The check at a finer resolution.
    pub check: Option<LadderCheck>,
    /// Whether the last two levels' answers agree (intervals overlap on every parameter,
    /// both interior).
    pub converged_in_n: bool,
    /// Where the last two levels' runs both meet every target: per searched key, the overlap
    /// of the two levels' spans of such points ([`TargetsMet`]); `None` when a level has none,
    /// or the spans are apart on some key. The spans bound the points, so the overlap is a
    /// box around the shared part of the valley, not a guarantee for each point inside it.
    pub targets_met_in_n: Option<BTreeMap<String, (f64, f64)>>,
    /// The verdict in words.
    pub verdict: String,
    /// Per searched key, the change of its answer per decade of N between the last two levels
    /// (in decades of the parameter on a log axis, its unit on a linear one).
    pub trend_per_decade: BTreeMap<String, f64>,
    /// Runs in all the levels' (and the check's) stores.
    pub runs: usize,
    /// Their cost, core-seconds.
    pub run_core_seconds: f64,
    /// Wall time of this invocation, s.
    pub wall_seconds: f64,
}

/// The ladder's directory: `--out`, or `runs/studies/<study>/<tier>-ladder`.
fn ladder_root(args: &CalibrateOptions, study: &Study) -> Result<PathBuf> {
    if let Some(out) = &args.study.out {
        return Ok(out.clone());
    }
    let tier = study.tier(args.study.tier.as_deref())?;
    Ok(Path::new("runs")
        .join("studies")
        .join(&study.name)
        .join(format!("{}-ladder", tier.name)))
}

/// A level's directory name: `n20000`.
fn level_dir(n: f64) -> PathBuf {
    PathBuf::from(format!("n{}", n.round() as u64))
}

/// Checks the ladder's counts: at least two, ascending, each >= 8; the check above the last.
fn check_counts(particles: &[f64], check: Option<f64>) -> Result<()> {
    if particles.len() < 2 {
        bail!(
            "invalid value for `--ladder`: {particles:?} (allowed: two or more particle counts, ascending, e.g. 2e4,8e4,2.7e5)"
        );
    }
    for &n in particles {
        if !(n.is_finite() && n >= 8.0) {
            bail!("invalid value for `--ladder`: {n} (allowed: particle counts >= 8)");
        }
    }
    if particles.windows(2).any(|w| w[1] <= w[0]) {
        bail!(
            "invalid value for `--ladder`: {particles:?} (allowed: strictly ascending particle counts)"
        );
    }
    if let Some(c) = check {
        let last = particles[particles.len() - 1];
        if !(c.is_finite() && c > last) {
            bail!(
                "invalid value for `--ladder-check`: {c} (allowed: a particle count above the ladder's last, {last})"
            );
        }
    }
    Ok(())
}

/// `hvi-study calibrate --ladder`: every level, the check and the verdict; writes ladder.json,
/// ladder.md and ladder.png.
pub fn ladder(args: &CalibrateOptions, opts: &LadderOptions) -> Result<LadderResult> {
    let t0 = std::time::Instant::now();
    let study = args.study.load_study()?;
    let cfg = CalibrateConfig::of(&study)?;
    refuse_options(args, &cfg)?;
    let check_n = opts.check.or(cfg.ladder_check);
    check_counts(&opts.particles, check_n)?;
    let root = ladder_root(args, &study)?;
    std::fs::create_dir_all(&root)
        .with_context(|| format!("cannot create the ladder's directory {}", root.display()))?;
    let mut walk = Levels::default();
    for (k, &n) in opts.particles.iter().enumerate() {
        walk.level(args, &study, &cfg, &root, (k, opts.particles.len()), n)?;
    }
    let Levels {
        levels,
        results,
        keys,
        ..
    } = walk;
    let check = match check_n {
        Some(n) => Some(check_run(args, &study, &cfg, &keys, &root, n, &results)?),
        None => None,
    };
    let InN {
        converged: converged_in_n,
        region: targets_met_in_n,
        trend: trend_per_decade,
        words: verdict,
    } = verdict(&keys, &levels);
    let runs = levels.iter().map(|l| l.runs).sum::<usize>() + check.as_ref().map_or(0, |c| c.runs);
    let run_core_seconds = levels.iter().map(|l| l.run_core_seconds).sum::<f64>()
        + check.as_ref().map_or(0.0, |c| c.run_core_seconds);
    let result = LadderResult {
        study: study.name.clone(),
        tier: results[0].tier.clone(),
        seeds: cfg.seeds.clone(),
        levels,
        check,
        converged_in_n,
        targets_met_in_n,
        verdict,
        trend_per_decade,
        runs,
        run_core_seconds,
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    publish(&root, &result, &keys, !args.study.quiet)?;
    Ok(result)
}

/// The options a ladder cannot take, refused with the reason.
fn refuse_options(args: &CalibrateOptions, cfg: &CalibrateConfig) -> Result<()> {
    if args.study.particles.is_some() {
        bail!("--ladder sets the particle count of each level: leave out --particles");
    }
    if args.hold_out.is_some() {
        bail!("--ladder holds out no shot: leave out --hold-out (or give it to a calibration at one count)");
    }
    if args.no_refine {
        bail!("--ladder needs the search after the grid (each level's confidence region steers the next): leave out --no-refine");
    }
    if args.method.unwrap_or(cfg.method) != Method::Ego {
        bail!("--ladder needs `--method ego` (its confidence region steers the next level; Nelder-Mead gives none)");
    }
    Ok(())
}

/// Writes ladder.json, ladder.md and ladder.png, and prints the report.
fn publish(root: &Path, result: &LadderResult, keys: &[Dim], progress: bool) -> Result<()> {
    write_atomic_bytes(
        &root.join("ladder.json"),
        serde_json::to_string_pretty(result)?.as_bytes(),
    )?;
    let doc = report(result, keys);
    write_atomic_bytes(&root.join("ladder.md"), doc.markdown().as_bytes())?;
    match draw(&root.join("ladder.png"), result, keys) {
        Ok(()) if progress => log::info!("plot: {}", root.join("ladder.png").display()),
        Ok(()) => {}
        Err(e) => log::info!("no ladder figure drawn: {e:#}"),
    }
    if progress {
        log::info!("{}", (doc.text()).trim_end_matches('\n'));
    }
    log::info!(target: hvi_run::STDOUT, "{}", root.join("ladder.json").display());
    Ok(())
}

impl LadderLevel {
    /// Level `n`'s summary of its calibration `r` (its runs, core and wall time left at 0).
    fn of(r: &CalibrationResult, n: f64, dir: PathBuf, steered_by: String) -> LadderLevel {
        LadderLevel {
            particles: n,
            particles_run: r.particles,
            dir,
            steered_by,
            first_box: r
                .boxes
                .first()
                .map(|b| b.bounds.clone())
                .unwrap_or_default(),
            best: r.best.params.clone(),
            objective: r.best.objective,
            intervals: r
                .region
                .as_ref()
                .map(|g| g.intervals.clone())
                .unwrap_or_default(),
            converged: r.converged,
            edges: r.edges.clone(),
            paper_objective: r.paper.objective,
            runs: 0,
            run_core_seconds: 0.0,
            runs_made: r.runs_made,
            wall_seconds: 0.0,
            targets_met: r.targets_met.clone(),
        }
    }
}

/// The levels calibrated so far.
#[derive(Default)]
struct Levels {
    levels: Vec<LadderLevel>,
    results: Vec<CalibrationResult>,
    /// The searched axes (the first level's).
    keys: Vec<Dim>,
    /// The last level's points, the next level's prior.
    coarse: Option<Coarse>,
}

impl Levels {
    /// Calibrates level `k` of `of` at `n` particles, its first box steered by the levels
    /// below.
    fn level(
        &mut self,
        args: &CalibrateOptions,
        study: &Study,
        cfg: &CalibrateConfig,
        root: &Path,
        (k, of): (usize, usize),
        n: f64,
    ) -> Result<()> {
        let t_level = std::time::Instant::now();
        let dir = level_dir(n);
        let mut level_args = args.clone();
        level_args.study.particles = Some(n);
        level_args.study.out = Some(root.join(&dir));
        let (level_study, mut steered_by) = if k == 0 {
            (study.clone(), "the study's grid".to_string())
        } else {
            steer(study, cfg, &self.keys, &self.levels, n)?
        };
        if cfg.ladder_prior {
            if let Some(c) = self.coarse.clone() {
                steered_by.push_str(&format!(
                    "; searched as the difference from the {} level's model ({} scored points{})",
                    c.particles,
                    c.points.len(),
                    if c.prior.is_some() {
                        ", itself on the levels below"
                    } else {
                        ""
                    }
                ));
                level_args.coarse = Some(c);
            }
        }
        if !args.study.quiet {
            log::info!(
                "ladder level {}/{of}: {n} particles, first box from {steered_by}",
                k + 1
            );
        }
        let (shots, out) = plans_of(
            &level_args.study,
            &level_study,
            cfg.load_shots(study)?,
            None,
            level_args.screens(),
        )?;
        if k == 0 {
            self.keys = refined_axes(&shots[0].plan, cfg)?.1;
        }
        let r = calibrate_plan(&level_args, &level_study, &shots, &out)?;
        let mut level = LadderLevel::of(&r, n, dir, steered_by);
        (level.runs, level.run_core_seconds) = store_cost(&out)?;
        level.wall_seconds = t_level.elapsed().as_secs_f64();
        self.levels.push(level);
        // The next level's prior: this level's points, on this level's own prior.
        let below = level_args.coarse.take();
        self.coarse = Some(Coarse::of(&r, n, cfg.noise_floor, below));
        self.results.push(r);
        Ok(())
    }
}

/// A value in the search's coordinate of `dim` (log10 on a log axis).
fn to_coord(dim: &Dim, v: f64) -> f64 {
    if dim.log {
        v.log10()
    } else {
        v
    }
}

/// A search coordinate of `dim` back to the parameter's value.
fn from_coord(dim: &Dim, u: f64) -> f64 {
    if dim.log {
        10f64.powf(u)
    } else {
        u
    }
}

/// The narrowest first box a steered level gets on `dim`, in its coordinate: half a decade on
/// a log axis, the study grid's smallest step on a linear one (none with a single value).
fn min_width(study: &Study, dim: &Dim) -> f64 {
    if dim.log {
        return 0.5;
    }
    let mut vals: Vec<f64> = study
        .axes
        .iter()
        .find(|a| a.key == dim.key)
        .map(|a| a.values.iter().filter_map(|v| v.as_f64()).collect())
        .unwrap_or_default();
    vals.sort_by(f64::total_cmp);
    // No step (a single value): no least width beyond the region's own.
    vals.windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .reduce(f64::min)
        .unwrap_or(0.0)
}

/// The study of a level after the first: each searched axis over the previous level's
/// confidence region, padded, widened along the trend of the last two answers, at
/// `calibrate.ladder_values` values. Returns it and where its box came from, in words.
fn steer(
    study: &Study,
    cfg: &CalibrateConfig,
    dims: &[Dim],
    levels: &[LadderLevel],
    n: f64,
) -> Result<(Study, String)> {
    let prev = levels
        .last()
        .ok_or_else(|| RunError::Input("a steered level needs a level before it".to_string()))?;
    let before = levels.len().checked_sub(2).map(|i| &levels[i]);
    let mut out = study.clone();
    let mut shifts = Vec::new();
    let mut unmoved = Vec::new();
    for dim in dims {
        let best = prev.best.get(&dim.key).copied().ok_or_else(|| {
            RunError::Input(format!(
                "level {} has no answer for {}",
                prev.particles, dim.key
            ))
        })?;
        let c = to_coord(dim, best);
        let (mut lo, mut hi) = prev
            .intervals
            .get(&dim.key)
            .map_or((c, c), |&(a, b)| (to_coord(dim, a), to_coord(dim, b)));
        lo = lo.min(c);
        hi = hi.max(c);
        // The trend of the last two answers, per decade of N, carried to this level's N; only
        // between answers inside their boxes on this axis (an answer on a side says where the
        // box ended, not where the optimum is).
        let interior = |l: &LadderLevel| !l.edges.iter().any(|e| e.key == dim.key);
        if let Some(b) = before.filter(|b| !(interior(b) && interior(prev))) {
            unmoved.push(format!(
                "{} (the {} or {} answer is on a side of its box)",
                dim.key, b.particles, prev.particles
            ));
        }
        if let Some(b) = before.filter(|b| interior(b) && interior(prev)) {
            if let Some(&v) = b.best.get(&dim.key) {
                let slope = (c - to_coord(dim, v)) / (prev.particles.log10() - b.particles.log10());
                let shift = slope * (n.log10() - prev.particles.log10());
                if shift.is_finite() && shift != 0.0 {
                    // Both the region and the region moved by the trend: two levels make a
                    // trend, not a law (the optimum may as well have stopped moving).
                    lo = lo.min(lo + shift);
                    hi = hi.max(hi + shift);
                    shifts.push(format!(
                        "{} {:+.3}{}",
                        dim.key,
                        shift,
                        if dim.log { " decades" } else { "" }
                    ));
                }
            }
        }
        let values = padded_values(study, cfg, dim, (lo, hi));
        let axis: &mut Axis = out
            .axes
            .iter_mut()
            .find(|a| a.key == dim.key)
            .ok_or_else(|| RunError::Input(format!("`{}` is not an axis of the study", dim.key)))?;
        axis.values = values.into_iter().map(|v| serde_json::json!(v)).collect();
    }
    let mut why = format!(
        "level {} particles' confidence region, padded",
        prev.particles
    );
    if !shifts.is_empty() {
        why.push_str(&format!(
            ", widened along the trend of the last two answers ({})",
            shifts.join(", ")
        ));
    }
    if !unmoved.is_empty() {
        why.push_str(&format!(", no trend on {}", unmoved.join(", ")));
    }
    Ok((out, why))
}

/// `calibrate.ladder_values` values over the span (lo, hi) of `dim`'s coordinate, padded by a
/// quarter of its width each side and to at least the axis's smallest width, at 3 significant
/// digits.
fn padded_values(
    study: &Study,
    cfg: &CalibrateConfig,
    dim: &Dim,
    (lo, hi): (f64, f64),
) -> Vec<f64> {
    let w = hi - lo;
    let pad = (0.25 * w).max(0.5 * (min_width(study, dim) - w)).max(0.0);
    let (lo, hi) = (lo - pad, hi + pad);
    let m = cfg.ladder_values;
    let mut values: Vec<f64> = (0..m)
        .map(|i| {
            round_sig(
                from_coord(dim, lo + (hi - lo) * i as f64 / (m - 1) as f64),
                3,
            )
        })
        .collect();
    values.dedup();
    values
}

/// Runs in a study directory's store and their cost (wall time times threads, summed).
fn store_cost(dir: &Path) -> Result<(usize, f64)> {
    let store = Store::open(dir)?;
    let mut runs = 0;
    let mut core = 0.0;
    for d in store.run_dirs()? {
        let text = std::fs::read_to_string(d.join("record.json"))
            .with_context(|| format!("cannot read {}", d.join("record.json").display()))?;
        let r: Record = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a record", d.join("record.json").display()))?;
        runs += 1;
        core += r.wall_seconds * r.threads.max(1) as f64;
    }
    Ok((runs, core))
}

/// The last level's answer run at `n` particles, at the search's seeds, through a store of its
/// own.
fn check_run(
    args: &CalibrateOptions,
    study: &Study,
    cfg: &CalibrateConfig,
    dims: &[Dim],
    root: &Path,
    n: f64,
    results: &[CalibrationResult],
) -> Result<LadderCheck> {
    let last = results
        .last()
        .ok_or_else(|| RunError::Input("the check needs a level".to_string()))?;
    let params: BTreeMap<String, f64> = dims
        .iter()
        .filter_map(|d| last.best.params.get(&d.key).map(|&v| (d.key.clone(), v)))
        .collect();
    let mut one = study.clone();
    for a in one.axes.iter_mut() {
        if let Some(v) = params.get(&a.key) {
            a.values = vec![serde_json::json!(v)];
        }
    }
    let dir = PathBuf::from(format!("check-n{}", n.round() as u64));
    let mut check_args = args.clone();
    check_args.study.particles = Some(n);
    check_args.study.out = Some(root.join(&dir));
    let (shots, out) = plans_of(&check_args.study, &one, cfg.load_shots(study)?, None, false)?;
    let progress = !args.study.quiet;
    if progress {
        log::info!(
            "ladder check: the last answer ({}) at {n} particles",
            hvi_calibrate::problem::fmt_params(&params)
        );
    }
    let runner = runner_of(&check_args)?;
    let store = runner.store(&out)?;
    let (_, threads) = thread_split(args.study.threads.unwrap_or(0), None, 1);
    let targets: Vec<_> = shots.iter().map(|s| s.targets.clone()).collect();
    let plans: Vec<&Plan> = shots.iter().map(|s| &s.plan).collect();
    let plan = plans[0];
    // The check is run in full.
    let off = hvi_calibrate::screen::Screen::off();
    let stage = Stage {
        study: &one,
        plan,
        plans: &plans,
        store: &store,
        targets: &targets,
        threads,
        runner: &runner,
        out: &out,
        progress,
        screen: &off,
    };
    let first = plan.run(0)?;
    let fixed = fixed_overrides(&plans, &first.values, |k| params.contains_key(k))?;
    let problem = stage.problem(fixed, Vec::new());
    let seeds = ego::seeds_of(&cfg.seeds);
    let (mut evs, _) = ego::run_points(
        &problem,
        EvalStage::Check,
        std::slice::from_ref(&params),
        &seeds,
    )?;
    let (ev, _) = evs
        .pop()
        .ok_or_else(|| RunError::Input("the check has no evaluation".to_string()))?;
    let (runs, core) = store_cost(&out)?;
    Ok(LadderCheck {
        particles: n,
        dir,
        params,
        objective: ev.objective,
        observed: observed_beside(&ev, &last.best),
        runs,
        run_core_seconds: core,
    })
}

/// Each target's observed value in the check `ev` beside the level's answer `best`'s:
/// name -> (at the check, at the level).
fn observed_beside(
    ev: &Evaluation,
    best: &Evaluation,
) -> BTreeMap<String, (Option<f64>, Option<f64>)> {
    let level_terms = best.score.as_ref().map(|s| &s.terms);
    ev.score
        .as_ref()
        .map(|s| {
            s.terms
                .iter()
                .map(|t| {
                    let at_level = level_terms
                        .and_then(|ts| ts.iter().find(|u| u.name == t.name))
                        .and_then(|u| u.observed);
                    (t.name.clone(), (t.observed, at_level))
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The verdict in N ([`verdict`]).
#[derive(Debug, Clone, PartialEq)]
struct InN {
    /// The last two levels' intervals overlap on every parameter, both answers interior.
    converged: bool,
    /// The overlap of the last two levels' spans of the points that meet every target, on
    /// every searched parameter ([`LadderResult::targets_met_in_n`]).
    region: Option<BTreeMap<String, (f64, f64)>>,
    /// Per searched key, the answer's change per decade of N between the last two levels.
    trend: BTreeMap<String, f64>,
    /// The verdict in words.
    words: String,
}

/// The overlap of two levels' spans of the points that meet every target, on every key of
/// `dims`: `None` when a level has no such point, a key has no span, or two spans are apart.
fn targets_met_overlap(
    dims: &[Dim],
    a: &LadderLevel,
    b: &LadderLevel,
) -> Option<BTreeMap<String, (f64, f64)>> {
    let (ma, mb) = (a.targets_met.as_ref()?, b.targets_met.as_ref()?);
    if ma.points == 0 || mb.points == 0 {
        return None;
    }
    dims.iter()
        .map(|dim| {
            let (sa, sb) = (ma.spans.get(&dim.key)?, mb.spans.get(&dim.key)?);
            let (lo, hi) = (sa.0.max(sb.0), sa.1.min(sb.1));
            (lo <= hi).then(|| (dim.key.clone(), (lo, hi)))
        })
        .collect()
}

/// Converged in N or not, the region that meets the targets at the last two levels, the trend
/// per decade of N between them, and the verdict in words.
fn verdict(dims: &[Dim], levels: &[LadderLevel]) -> InN {
    let (Some(a), Some(b)) = (
        levels.len().checked_sub(2).map(|i| &levels[i]),
        levels.last(),
    ) else {
        return InN {
            converged: false,
            region: None,
            trend: BTreeMap::new(),
            words: "one level: no verdict in N".into(),
        };
    };
    let (trend, apart) = trends_and_gaps(dims, a, b);
    let edges = edge_words(a, b);
    let converged = apart.is_empty() && edges.is_empty();
    let region = targets_met_overlap(dims, a, b);
    let tail = format!(
        "{}{}{}",
        met_words(dims, a, b),
        paper_warning(b),
        region_words(region.as_ref())
    );
    let trend_words = trend_words(dims, &trend);
    let words = if converged {
        format!(
            "CONVERGED IN N: the intervals at {} and {} particles overlap on every parameter ({trend_words}){tail}",
            fmt_value(a.particles),
            fmt_value(b.particles)
        )
    } else {
        let mut why = apart;
        why.extend(edges);
        format!(
            "NOT CONVERGED IN N: {}; {trend_words}{tail}",
            why.join("; ")
        )
    };
    InN {
        converged,
        region,
        trend,
        words,
    }
}

/// Per searched key, the answer's change per decade of N from level `a` to `b`, and the keys
/// whose intervals at the two levels are apart (or missing), in words.
fn trends_and_gaps(
    dims: &[Dim],
    a: &LadderLevel,
    b: &LadderLevel,
) -> (BTreeMap<String, f64>, Vec<String>) {
    let decades = b.particles.log10() - a.particles.log10();
    let mut trend = BTreeMap::new();
    let mut apart = Vec::new();
    for dim in dims {
        let (Some(&va), Some(&vb)) = (a.best.get(&dim.key), b.best.get(&dim.key)) else {
            continue;
        };
        trend.insert(
            dim.key.clone(),
            (to_coord(dim, vb) - to_coord(dim, va)) / decades,
        );
        match (a.intervals.get(&dim.key), b.intervals.get(&dim.key)) {
            (Some(&(lo_a, hi_a)), Some(&(lo_b, hi_b))) => {
                if hi_a < lo_b || hi_b < lo_a {
                    apart.push(format!(
                        "{} [{}, {}] at {} and [{}, {}] at {} do not overlap",
                        dim.key,
                        fmt_value(lo_a),
                        fmt_value(hi_a),
                        fmt_value(a.particles),
                        fmt_value(lo_b),
                        fmt_value(hi_b),
                        fmt_value(b.particles)
                    ));
                }
            }
            _ => apart.push(format!(
                "{} has no interval at one of the last two levels",
                dim.key
            )),
        }
    }
    (trend, apart)
}

/// The sides each of the two levels' answers touches, in words.
fn edge_words(a: &LadderLevel, b: &LadderLevel) -> Vec<String> {
    [a, b]
        .iter()
        .filter(|l| !l.edges.is_empty())
        .map(|l| {
            format!(
                "the answer at {} touches {}",
                fmt_value(l.particles),
                l.edges
                    .iter()
                    .map(Edge::describe)
                    .collect::<Vec<_>>()
                    .join(" and ")
            )
        })
        .collect()
}

/// How far along the valley each level's runs meet the targets (no model): read beside the
/// intervals, which are each search's around its own minimum.
fn met_words(dims: &[Dim], a: &LadderLevel, b: &LadderLevel) -> String {
    let words = dims
        .iter()
        .filter_map(|dim| {
            let span = |l: &LadderLevel| {
                l.targets_met
                    .as_ref()
                    .and_then(|m| m.spans.get(&dim.key).copied())
            };
            let (sa, sb) = (span(a)?, span(b)?);
            let meet = !(sa.1 < sb.0 || sb.1 < sa.0);
            Some(format!(
                "{} {} to {} and {} to {} ({})",
                dim.key,
                fmt_value(sa.0),
                fmt_value(sa.1),
                fmt_value(sb.0),
                fmt_value(sb.1),
                if meet { "overlapping" } else { "apart" }
            ))
        })
        .collect::<Vec<_>>();
    if words.is_empty() {
        String::new()
    } else {
        format!(
            "; the points that meet every target span {}",
            words.join(", ")
        )
    }
}

/// Each key's trend per decade of N, in words (decades for a log axis).
fn trend_words(dims: &[Dim], trend: &BTreeMap<String, f64>) -> String {
    trend
        .iter()
        .map(|(k, v)| {
            let log = dims.iter().any(|d| &d.key == k && d.log);
            if log {
                format!("{k} moves {v:+.3} decades per decade of N")
            } else {
                format!("{k} moves {v:+.4} per decade of N")
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// A known point that beats the answer at the last level: the search's box missed it.
fn paper_warning(b: &LadderLevel) -> String {
    if b.paper_objective < b.objective {
        format!(
            "; at {} particles the paper's fit scores J = {:.4}, below the answer's {:.4}: the level's box may have missed a better valley",
            fmt_value(b.particles),
            b.paper_objective,
            b.objective
        )
    } else {
        String::new()
    }
}

/// The region to carry across resolutions, in words.
fn region_words(region: Option<&BTreeMap<String, (f64, f64)>>) -> String {
    match region {
        Some(r) => format!(
            ". The region to carry across resolutions: the points that meet every target at \
             both levels overlap in {}",
            r.iter()
                .map(|(k, (lo, hi))| format!("{k} [{}, {}]", fmt_value(*lo), fmt_value(*hi)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => ". No region meets every target at both levels".into(),
    }
}

/// The ladder's report, composed once: the console prints its text, ladder.md is its
/// Markdown.
fn report(r: &LadderResult, dims: &[Dim]) -> Document {
    let mut doc = Document {
        title: format!("Resolution ladder of `{}`", r.study),
        preamble: format!(
            "Tier `{}` (its overrides other than the particle count at every level), seeds \
             {:?}.\n\n![each parameter and J against N](ladder.png)",
            r.tier, r.seeds
        ),
        verdict: r.verdict.clone(),
        sections: Vec::new(),
    };
    levels_section(&mut doc, &r.levels);
    if let Some(c) = &r.check {
        check_section(&mut doc, c);
    }
    let trend = doc.section("Trend between the last two levels");
    for (k, v) in &r.trend_per_decade {
        let log = dims.iter().any(|d| &d.key == k && d.log);
        trend.fact(
            format!("trend of {k}"),
            format!(
                "{v:+.3} {} per decade of N",
                if log { "decades" } else { "(its unit)" }
            ),
        );
    }
    doc.section("Cost")
        .fact(
            "runs",
            format!(
                "{} in all ({:.0} core-seconds of simulation); this invocation took {:.0} s",
                r.runs, r.run_core_seconds, r.wall_seconds
            ),
        )
        .note("Each level's calibration.md is in its directory (`n<N>/`).");
    doc
}

/// The report's table of levels.
fn levels_section(doc: &mut Document, levels: &[LadderLevel]) {
    let rows = levels
        .iter()
        .map(|l| {
            vec![
                l.particles_run
                    .map_or(fmt_value(l.particles), |p| format!("{p:.0}")),
                fmt_bounds(&l.first_box),
                l.steered_by.clone(),
                answer_words(l),
                format!("{:.4}", l.objective),
                format!("{:.4}", l.paper_objective),
                if l.converged {
                    "yes".to_string()
                } else if l.edges.is_empty() {
                    "no".to_string()
                } else {
                    let edges: Vec<String> = l.edges.iter().map(Edge::describe).collect();
                    format!("no: {}", edges.join("; "))
                },
                l.targets_met
                    .as_ref()
                    .map_or("n/a".to_string(), TargetsMet::describe),
                l.runs.to_string(),
                format!("{:.0}", l.run_core_seconds),
            ]
        })
        .collect();
    doc.section("The levels").table(
        &[
            "particles",
            "first box",
            "from",
            "answer [interval]",
            "J",
            "paper's fit J",
            "converged",
            "where the runs meet every target",
            "runs",
            "core-s",
        ],
        rows,
    );
}

/// The check at more particles: the answer's J and each target beside the last level's.
fn check_section(doc: &mut Document, c: &LadderCheck) {
    let f = |v: &Option<f64>| v.map_or("n/a".to_string(), |x| format!("{x:.4}"));
    let rows = c
        .observed
        .iter()
        .map(|(name, (at_check, at_level))| vec![name.clone(), f(at_check), f(at_level)])
        .collect();
    let params: Vec<String> = c
        .params
        .iter()
        .map(|(k, v)| format!("{k} = {}", fmt_value(*v)))
        .collect();
    doc.section(format!("Check at {} particles", fmt_value(c.particles)))
        .fact(
            "check",
            format!(
                "the last level's answer ({}) run at {} particles at the same seeds: J = {:.4}",
                params.join(", "),
                fmt_value(c.particles),
                c.objective
            ),
        )
        .table(
            &["target", "observed at the check", "at the last level"],
            rows,
        );
}

/// A level's answer: `material.eps_j = 0.016 [0.01, 0.03], ...`.
fn answer_words(l: &LadderLevel) -> String {
    l.best
        .iter()
        .map(|(k, v)| match l.intervals.get(k) {
            Some((lo, hi)) => format!(
                "{k} = {} [{}, {}]",
                fmt_value(*v),
                fmt_value(*lo),
                fmt_value(*hi)
            ),
            None => format!("{k} = {}", fmt_value(*v)),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// ladder.png.
fn draw(path: &Path, r: &LadderResult, dims: &[Dim]) -> Result<()> {
    use hvi_plot::ladder::{ladder_plot, LadderPanel, LadderPlot};
    let panels = dims
        .iter()
        .map(|d| LadderPanel {
            label: d.key.clone(),
            log: d.log,
            levels: r
                .levels
                .iter()
                .filter_map(|l| {
                    l.best.get(&d.key).map(|&v| {
                        (
                            l.particles_run.unwrap_or(l.particles),
                            v,
                            l.intervals.get(&d.key).copied(),
                            l.edges.iter().all(|e| e.key != d.key),
                        )
                    })
                })
                .collect(),
            met: r
                .levels
                .iter()
                .filter_map(|l| {
                    let span = l.targets_met.as_ref()?.spans.get(&d.key)?;
                    Some((l.particles_run.unwrap_or(l.particles), *span))
                })
                .collect(),
            reference: PAPER_BEST
                .iter()
                .find(|(k, _)| *k == d.key)
                .map(|(_, v)| (*v, "the paper's fit".to_string())),
        })
        .collect();
    Ok(ladder_plot(
        path,
        &LadderPlot {
            title: format!("{}: calibration against resolution", r.study),
            subtitle: r.verdict.clone(),
            panels,
            objective: r
                .levels
                .iter()
                .map(|l| (l.particles_run.unwrap_or(l.particles), l.objective))
                .collect(),
            check: r.check.as_ref().map(|c| (c.particles, c.objective)),
            reference_objective: Some((
                r.levels
                    .iter()
                    .map(|l| (l.particles_run.unwrap_or(l.particles), l.paper_objective))
                    .collect(),
                "the paper's fit".to_string(),
            )),
        },
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(n: f64, eps: f64, interval: (f64, f64)) -> LadderLevel {
        LadderLevel {
            particles: n,
            particles_run: Some(n),
            dir: level_dir(n),
            steered_by: String::new(),
            first_box: BTreeMap::new(),
            best: BTreeMap::from([("material.eps_j".to_string(), eps)]),
            objective: 0.1,
            intervals: BTreeMap::from([("material.eps_j".to_string(), interval)]),
            converged: true,
            edges: Vec::new(),
            paper_objective: 1.0,
            runs: 0,
            run_core_seconds: 0.0,
            runs_made: 0,
            wall_seconds: 0.0,
            targets_met: None,
        }
    }

    fn eps_dim() -> Dim {
        Dim::new("material.eps_j", true, -2.0, 0.0)
    }

    #[test]
    fn counts_must_ascend_and_the_check_lie_above_them() {
        assert!(check_counts(&[2e4, 8e4], Some(2.7e5)).is_ok());
        for (counts, check) in [
            (vec![2e4], None),
            (vec![8e4, 2e4], None),
            (vec![2e4, 2e4], None),
            (vec![4.0, 2e4], None),
            (vec![2e4, 8e4], Some(8e4)),
        ] {
            let e = check_counts(&counts, check).expect_err("refused");
            assert!(format!("{e}").contains("--ladder"), "{e}");
        }
    }

    #[test]
    fn overlapping_intervals_converge_in_n_and_apart_ones_do_not() {
        let dims = [eps_dim()];
        let near = [
            level(2e4, 0.02, (0.01, 0.04)),
            level(8e4, 0.03, (0.015, 0.05)),
        ];
        let v = verdict(&dims, &near);
        assert!(v.converged, "{}", v.words);
        let t = v.trend["material.eps_j"];
        assert!((t - (0.03f64 / 0.02).log10() / 4f64.log10()).abs() < 1e-12);
        let far = [level(2e4, 0.02, (0.01, 0.04)), level(8e4, 1.0, (0.5, 2.0))];
        let v = verdict(&dims, &far);
        assert!(
            !v.converged && v.words.starts_with("NOT CONVERGED IN N"),
            "{}",
            v.words
        );
        let mut edge = near.clone();
        edge[1].edges.push(Edge {
            key: "material.eps_j".into(),
            side: hvi_calibrate::result::Side::High,
            value: 0.05,
            touched_by: "confidence region".into(),
            limit: None,
            targets_met: false,
            falling: None,
        });
        assert!(!verdict(&dims, &edge).converged);
    }

    fn met(points: usize, spans: &[(&str, f64, f64)]) -> Option<TargetsMet> {
        Some(TargetsMet {
            points,
            scored: 10,
            spans: spans
                .iter()
                .map(|&(k, lo, hi)| (k.to_string(), (lo, hi)))
                .collect(),
        })
    }

    #[test]
    fn the_region_that_meets_the_targets_carries_when_the_last_two_levels_share_it() {
        let dims = [eps_dim()];
        // Intervals apart (each search's slice of a valley), the valley shared: the region is
        // the overlap of the two levels' spans, whatever the intervals say.
        let mut far = [
            level(8e4, 1.5e-3, (1.3e-3, 1.8e-3)),
            level(2.7e5, 8e-3, (4e-3, 1.1e-2)),
        ];
        far[0].targets_met = met(5, &[("material.eps_j", 7.5e-4, 1e-2)]);
        far[1].targets_met = met(9, &[("material.eps_j", 1.4e-3, 3.3e-2)]);
        let v = verdict(&dims, &far);
        assert!(!v.converged);
        assert_eq!(
            v.region,
            Some(BTreeMap::from([(
                "material.eps_j".to_string(),
                (1.4e-3, 1e-2)
            )]))
        );
        assert!(
            v.words.contains("material.eps_j [1.4e-3, 1e-2]"),
            "{}",
            v.words
        );
        // Spans apart, or a level where no point meets the targets: no region.
        far[1].targets_met = met(3, &[("material.eps_j", 2e-2, 3.3e-2)]);
        let v = verdict(&dims, &far);
        assert_eq!(v.region, None);
        assert!(
            v.words.contains("No region meets every target"),
            "{}",
            v.words
        );
        far[1].targets_met = met(0, &[]);
        assert_eq!(verdict(&dims, &far).region, None);
        // A searched key without a span at one level (it did not vary there): no region.
        let two = [eps_dim(), Dim::new("material.kappa_n_m", true, 6.0, 7.0)];
        far[0].targets_met = met(5, &[("material.eps_j", 7.5e-4, 1e-2)]);
        far[1].targets_met = met(9, &[("material.eps_j", 1.4e-3, 3.3e-2)]);
        assert_eq!(verdict(&two, &far).region, None);
    }
}
