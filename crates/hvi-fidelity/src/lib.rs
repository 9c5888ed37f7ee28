//! `hvi-study fidelity`: the readings study. The calibration grid (Figs. 7, 9, 10) under each
//! reading of the paper that could explain a gap between our maps and the paper's, at two
//! seeds or more; each reading's R and va/v0 maps judged by the same checks as the
//! reproduction's Figs. 9 and 10 ([`hvi_reproduce::stages::fig9_checks`],
//! [`hvi_reproduce::stages::fig10_checks`]), side by side in
//! `reports/fidelity/` (`report.md`, `fidelity.json`, `readings.csv`, two maps per reading).
//!
//! Every run goes through the study store (`<runs>/<tier>/<reading>/`): a killed study resumes,
//! a repeated one runs nothing. The seeds are one more axis of the grid (`run.seed`).

pub mod config;
mod report;
pub mod result;

use std::path::{Path, PathBuf};
use std::time::Instant;

use hvi_analysis::contour::Field;
use hvi_analysis::observable::Observable;
use hvi_run::bail;
use hvi_run::error::{OptionExt, Result, ResultExt};
use hvi_store::exec::ExecOptions;
use hvi_store::plan::{build_plan, Plan, PlanRequest};
use hvi_store::spec::{Axis, Study};
use hvi_store::store::{Record, RunStatus};
use hvi_store::study::execute_plan;

use config::{check_seeds, FidelityConfig, Reading, Source};
use hvi_reproduce::report::Verdict;
use hvi_reproduce::stages::{completed_runs, fig10_checks, fig10_figure, fig9_checks, fig9_figure};
use hvi_studies::figures::sorted_axis;
use hvi_studies::reanalyse::reanalyse_run;
pub use report::write_report;
pub use result::{FidelityResult, Judged, SeedFields};

/// The key of the seed axis the study adds to the grid.
pub const SEED_KEY: &str = "run.seed";

/// One reading's run grid after execution.
struct Executed {
    plan: Plan,
    seeds: Vec<u64>,
    dir: PathBuf,
    records: Vec<Record>,
    cached: usize,
}

/// The study with the seed axis appended; it must have eps and kappa axes and no other axis
/// with more than one value.
fn seeded_study(path: &Path, seeds: &[u64]) -> Result<Study> {
    let mut study = Study::load(path)?;
    for key in ["material.eps_j", "material.kappa_n_m"] {
        if !study
            .axes
            .iter()
            .any(|a| a.key == key && a.values.len() > 1)
        {
            bail!(
                "study {}: the readings study needs an axis `{key}` with two or more values \
                 (the calibration grid, studies/calibration.toml)",
                path.display()
            );
        }
    }
    if let Some(a) = study.axes.iter().find(|a| {
        !matches!(a.key.as_str(), "material.eps_j" | "material.kappa_n_m") && a.values.len() > 1
    }) {
        bail!(
            "study {}: axis `{}` has {} values (allowed: one; the maps are over eps and kappa)",
            path.display(),
            a.key,
            a.values.len()
        );
    }
    if study.axes.iter().any(|a| a.key == SEED_KEY) {
        bail!(
            "study {}: `{SEED_KEY}` is an axis already (the readings study adds it)",
            path.display()
        );
    }
    study.axes.push(Axis {
        key: SEED_KEY.into(),
        values: seeds.iter().map(|&s| serde_json::Value::from(s)).collect(),
        label: "seed".into(),
    });
    Ok(study)
}

/// A reading's plan and the seeds it runs at.
type SeededPlan = (Plan, Vec<u64>);

/// Plans every reading with runs of its own, each with its seeds (the command line's, else the
/// reading's, else the config's); all scenes validated before anything runs.
fn plans(
    config: &FidelityConfig,
    tier: &str,
    seeds: Option<&[u64]>,
) -> Result<Vec<Option<SeededPlan>>> {
    config
        .readings
        .iter()
        .map(|r| match &r.source {
            Source::Runs { set } => {
                let seeds = seeds
                    .or(r.seeds.as_deref())
                    .unwrap_or(&config.seeds)
                    .to_vec();
                let study = seeded_study(&config.study, &seeds)?;
                let plan = build_plan(
                    &study,
                    &PlanRequest {
                        tier: Some(tier.to_string()),
                        particles: None,
                        set: config.set.iter().chain(set).cloned().collect(),
                    },
                )
                .with_context(|| format!("reading `{}`", r.name))?;
                Ok(Some((plan, seeds)))
            }
            Source::Measured { .. } => Ok(None),
        })
        .collect()
}

/// What `fidelity` runs and where it writes.
#[derive(Debug, Clone)]
pub struct FidelityOptions {
    /// The readings config.
    pub config: PathBuf,
    /// The calibration study's tier (None: the config's `fidelity.tier`).
    pub tier: Option<String>,
    /// Thermal seeds (empty: the config's `fidelity.seeds`).
    pub seeds: Vec<u64>,
    /// The report directory (a new or empty directory, or an earlier report).
    pub out: PathBuf,
    /// Where the runs are kept: one study store per reading, `<runs>/<tier>/<reading>/`.
    pub runs: PathBuf,
    /// Worker threads in all (None: every core).
    pub threads: Option<usize>,
    /// Runs at once (None: as many as threads).
    pub jobs: Option<usize>,
    /// Validate every reading and run, print how many runs it takes; run nothing.
    pub dry_run: bool,
    /// No progress output.
    pub quiet: bool,
}

/// `hvi-study fidelity`: plans, runs (or takes from the store), measures, judges and writes
/// the report. With `--dry-run` it plans and prints what it would run.
pub fn fidelity(args: &FidelityOptions) -> Result<Option<FidelityResult>> {
    let t0 = Instant::now();
    let config = FidelityConfig::load(&args.config)?;
    let tier = args.tier.clone().unwrap_or_else(|| config.tier.clone());
    let cli_seeds = if args.seeds.is_empty() {
        None
    } else {
        check_seeds(&args.seeds, "--seeds")?;
        Some(args.seeds.as_slice())
    };
    let seeds = cli_seeds.map_or_else(|| config.seeds.clone(), <[u64]>::to_vec);
    if args.threads == Some(0) || args.jobs == Some(0) {
        bail!("invalid value for `--threads`/`--jobs`: 0 (allowed: an integer >= 1)");
    }
    seeded_study(&config.study, &seeds)?;
    if !args.dry_run {
        hvi_reproduce::report::check_report_dir(&args.out, "fidelity.json", "fidelity")?;
    }
    let plans = plans(&config, &tier, cli_seeds)?;
    let root = args.runs.join(&tier);
    let (total, todo) = count_runs(&config, &plans, &root)?;
    if !args.quiet || args.dry_run {
        log::info!(
            "readings study `{}` at tier `{tier}`, seeds {seeds:?}: {} readings, {total} runs \
             ({} in the store, {todo} to run) in {}",
            config.path.display(),
            config.readings.len(),
            total - todo,
            root.display()
        );
    }
    if args.dry_run {
        return Ok(None);
    }
    let executed = execute_readings(&config, plans, &root, args)?;
    let ran = executed
        .iter()
        .flatten()
        .map(|e| e.plan.runs.len() - e.cached)
        .sum();
    let mut judged = Vec::new();
    for (k, r) in config.readings.iter().enumerate() {
        judged.push(judge(r, k, &executed).with_context(|| format!("reading `{}`", r.name))?);
    }
    let particles = executed
        .iter()
        .flatten()
        .flat_map(|e| &e.records)
        .find_map(|rec| rec.observables.get(Observable::Particles));
    let result = FidelityResult {
        config,
        tier,
        particles,
        seeds,
        readings: judged,
        wall_seconds: t0.elapsed().as_secs_f64(),
        ran,
    };
    write_report(&result, &args.out)?;
    if !args.quiet {
        log::info!("wrote {}", args.out.join("report.md").display());
    }
    Ok(Some(result))
}

/// The runs of the readings' plans (those with runs of their own) under `root`: (in all, still
/// to run).
fn count_runs(
    config: &FidelityConfig,
    plans: &[Option<SeededPlan>],
    root: &Path,
) -> Result<(usize, usize)> {
    let (mut total, mut todo) = (0, 0);
    for (r, p) in config.readings.iter().zip(plans) {
        if let Some((p, _)) = p {
            total += p.runs.len();
            todo += p.runs.len() - completed_runs(p, &root.join(&r.name))?;
        }
    }
    Ok((total, todo))
}

/// Each reading's plan executed into its store under `root` (`<root>/<reading>`); None for a
/// reading measured from another's runs.
fn execute_readings(
    config: &FidelityConfig,
    plans: Vec<Option<SeededPlan>>,
    root: &Path,
    args: &FidelityOptions,
) -> Result<Vec<Option<Executed>>> {
    let exec = ExecOptions {
        threads: args.threads.unwrap_or(0),
        jobs: args.jobs,
        progress: !args.quiet,
        ..ExecOptions::default()
    };
    let mut executed = Vec::new();
    for (r, p) in config.readings.iter().zip(plans) {
        let Some((plan, seeds)) = p else {
            executed.push(None);
            continue;
        };
        let dir = root.join(&r.name);
        if !args.quiet {
            log::info!(
                "reading `{}`: {} runs in {}",
                r.name,
                plan.runs.len(),
                dir.display()
            );
        }
        plan.write(&dir)?;
        let (_, rep) = execute_plan(&plan, &dir, &exec)?;
        executed.push(Some(Executed {
            plan,
            seeds,
            dir,
            records: rep.records,
            cached: rep.cached,
        }));
    }
    Ok(executed)
}

/// (R, va/v0) of every run of `e`'s plan for reading `r`: from the records, or measured again
/// from each run's state when the reading changes an analysis setting.
fn values(r: &Reading, e: &Executed) -> Result<Vec<(f64, f64)>> {
    let pick = |o: &hvi_analysis::observable::Observables| {
        let v = |x: Observable| o.get(x).unwrap_or(f64::NAN);
        (v(r.length_ratio), v(r.front_velocity))
    };
    let changes = match &r.source {
        Source::Measured {
            changes, analysis, ..
        } if !analysis.is_empty() => Some(changes),
        _ => None,
    };
    let mut out = Vec::with_capacity(e.plan.runs.len());
    for (run, rec) in e.plan.runs.iter().zip(&e.records) {
        if rec.status != RunStatus::Completed {
            out.push((f64::NAN, f64::NAN));
            continue;
        }
        match changes {
            None => out.push(pick(&rec.observables)),
            Some(c) => {
                let dir = e.dir.join(&run.dir);
                let again = reanalyse_run(&dir, c)?.with_context(|| {
                    format!(
                        "run {} kept no state.bin to measure again: remove it and run the \
                         readings study again",
                        dir.display()
                    )
                })?;
                out.push(pick(&again.summary.observables()));
            }
        }
    }
    Ok(out)
}

/// The fields of one value over (eps, kappa), one per seed, and their mean.
fn seed_fields(plan: &Plan, values: &[f64], seeds: &[u64]) -> Result<SeedFields> {
    let axis = |key: &str| {
        plan.axes
            .iter()
            .position(|a| a.key == key)
            .with_context(|| format!("the plan has no axis `{key}`"))
    };
    let (ax, ay, az) = (
        axis("material.eps_j")?,
        axis("material.kappa_n_m")?,
        axis(SEED_KEY)?,
    );
    let (xs, ys) = (sorted_axis(plan, ax)?, sorted_axis(plan, ay)?);
    let field = |z: Vec<Vec<f64>>| {
        Field::new(
            xs.iter().map(|p| p.0).collect(),
            ys.iter().map(|p| p.0).collect(),
            z,
        )
        .context("the eps and kappa values must be distinct")
    };
    let mut per_seed = Vec::new();
    for (s, &seed) in seeds.iter().enumerate() {
        let mut z = vec![vec![f64::NAN; xs.len()]; ys.len()];
        for (run, &v) in plan.runs.iter().zip(values) {
            if run.coords[az] != s {
                continue;
            }
            let c = xs.iter().position(|&(_, i)| i == run.coords[ax]);
            let r = ys.iter().position(|&(_, i)| i == run.coords[ay]);
            if let (Some(c), Some(r)) = (c, r) {
                z[r][c] = v;
            }
        }
        per_seed.push((seed, field(z)?));
    }
    let mut mean = vec![vec![f64::NAN; xs.len()]; ys.len()];
    for (r, row) in mean.iter_mut().enumerate() {
        for (c, cell) in row.iter_mut().enumerate() {
            let v: Vec<f64> = per_seed.iter().map(|(_, f)| f.z[r][c]).collect();
            if v.iter().all(|x| x.is_finite()) {
                *cell = v.iter().sum::<f64>() / v.len() as f64;
            }
        }
    }
    Ok(SeedFields {
        seeds: per_seed,
        mean: field(mean)?,
    })
}

/// Measures and judges reading `k`.
fn judge(r: &Reading, k: usize, executed: &[Option<Executed>]) -> Result<Judged> {
    let base = match &r.source {
        Source::Runs { .. } => k,
        Source::Measured { from, .. } => *from,
    };
    let e = executed[base]
        .as_ref()
        .context("the reading it measures again has no runs")?;
    let v = values(r, e)?;
    let (rr, va): (Vec<f64>, Vec<f64>) = v.into_iter().unzip();
    let length_ratio = seed_fields(&e.plan, &rr, &e.seeds)?;
    let front_velocity = seed_fields(&e.plan, &va, &e.seeds)?;
    let files = |o: &str| vec![format!("{}_{o}.png", r.name)];
    let fig9 = fig9_figure(&length_ratio.mean, files("R"));
    let fig10 = fig10_figure(&front_velocity.mean, files("va"));
    let per_seed = length_ratio
        .seeds
        .iter()
        .zip(&front_velocity.seeds)
        .map(|((s, rf), (_, vf))| {
            let (a, b) = fig9_checks(rf);
            let (c, d) = fig10_checks(vf);
            (*s, Verdict::of_claims(&a, &b), Verdict::of_claims(&c, &d))
        })
        .collect();
    Ok(Judged {
        reading: r.clone(),
        seeds: e.seeds.clone(),
        runs_dir: e.dir.clone(),
        runs: e.plan.runs.len(),
        cached: if base == k { e.cached } else { 0 },
        fig9_checks: fig9_checks(&length_ratio.mean),
        fig10_checks: fig10_checks(&front_velocity.mean),
        length_ratio,
        front_velocity,
        fig9,
        fig10,
        per_seed,
    })
}
