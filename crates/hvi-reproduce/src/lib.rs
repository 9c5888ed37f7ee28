//! `hvi-study reproduce`: every figure of Watson & Steinhauser (2017) regenerated through the
//! study runner and its store, and a report that puts the paper's result beside ours.
//!
//! ```text
//! studies/reproduce.toml (tier) --(config, plans)--> plans of five studies, every scene validated
//!   sizing (Fig. 4), convergence (Figs. 5, 11, 12), calibration (Figs. 7, 9, 10),
//!   front-velocity (Fig. 13), validity-map (Figs. 16, 17); Fig. 3 needs no run
//! plans --(hvi_run execute_plan + store, runs/reproduce/<tier>/<study>/runs/<fingerprint>)--> records
//! records --(stages: decide, plots)--> figures, deciding numbers, verdicts
//!   --(report)--> reports/<tier>/report.md, reproduce.json, fig*.png, fig*.csv
//! ```
//!
//! Finished runs are reused by fingerprint, so running again simulates nothing new and a run
//! stopped at any point resumes. The report is rewritten after every stage (figures not yet
//! computed say `pending`), so a long tier shows where it stands. With `--previous DIR` the
//! report lists what changed since DIR's `reproduce.json` (verdicts and deciding numbers).
//! Each finished run appends a record to the history (`history.jsonl`, or `--history FILE`)
//! and writes `index.html`, the report as a web page with every deciding number's history.
//! Every paper number comes from `hvi_engine::paper`.

pub mod config;
pub mod history;
pub mod page;
mod plans;
pub mod report;
pub mod sizing;
pub mod stages;

pub use plans::{build_plans, estimate, Plans};

use std::path::{Path, PathBuf};
use std::time::Instant;

use hvi_analysis::score::Targets;
use hvi_engine::paper;
use hvi_run::bail;
use hvi_run::error::{Result, ResultExt};

use config::{Config, TierConfig};
use hvi_store::exec::ExecOptions;
use hvi_store::spec::Study;
use report::{fmt_duration, Estimate, Figure, Machine, Reproduction, StageTiming, Verdict};
use stages::Ctx;

/// What `reproduce` runs and where it writes.
#[derive(Debug, Clone)]
pub struct ReproduceOptions {
    /// The tier, as named in the config (`quick` or `paper`).
    pub tier: String,
    /// The report directory (None: `reports/<tier>`).
    pub out: Option<PathBuf>,
    /// Where the runs are kept, one study store per stage (None: `runs/reproduce/<tier>`).
    pub runs: Option<PathBuf>,
    /// A previous report directory: list what changed since its reproduce.json.
    pub previous: Option<PathBuf>,
    /// With `previous`: fail when a verdict or deciding number changed.
    pub fail_on_change: bool,
    /// The history file each run appends its record to (None: `<out>/history.jsonl`).
    pub history: Option<PathBuf>,
    /// The reproduction's config.
    pub config: PathBuf,
    /// Worker threads in all (None: every core).
    pub threads: Option<usize>,
    /// Runs at once (None: as many as threads).
    pub jobs: Option<usize>,
    /// Validate every run and print the expected wall time; run nothing.
    pub dry_run: bool,
    /// No progress output.
    pub quiet: bool,
}

/// `hvi-study reproduce`.
pub fn reproduce(args: &ReproduceOptions) -> Result<Reproduction> {
    let t0 = Instant::now();
    // Before anything is written: a report written into the repository is not a change.
    let commit = history::current_commit();
    check_counts(args)?;
    let config = Config::load(&args.config)?;
    let tier = config.tier(&args.tier)?.clone();
    let (out, runs) = report_and_runs_dirs(args);
    // Read the previous report before anything is written (it may be --out itself).
    let previous = load_previous(args)?;
    if !args.dry_run {
        report::check_report_dir(&out, "reproduce.json", "reproduce")?;
    }
    say(
        args,
        format!("tier `{}`: planning every figure's runs", args.tier),
    );
    let plans = build_plans(&config, &args.tier)?;
    let n_runs: usize = plans.stages().iter().map(|s| s.2.runs.len()).sum();
    say(args, format!("{n_runs} runs planned, every scene valid"));
    let estimates = estimates(args, &config, &plans)?;
    if args.dry_run {
        return Ok(dry_run(args, &tier, estimates, n_runs, t0));
    }
    std::fs::create_dir_all(&runs)
        .with_context(|| format!("cannot create --runs {}", runs.display()))?;

    let mut rep = Reproduction {
        notes: model_notes(&plans, &runs),
        ..new_report(args, &tier, estimates)
    };
    rep.write(&out)?;
    let targets = calibration_targets(&plans)?;
    let inputs = StageInputs {
        ctx: stage_context(args, &out, &runs),
        plans: &plans,
        tier: &tier,
        fig13_gap: fig13_gap(&targets),
        targets,
    };
    let errors = run_stages(args, &inputs, &mut rep, &out, t0)?;
    finish(args, rep, previous.as_ref(), &out, t0, errors, commit)
}

/// A progress line on stderr (none with `--quiet`).
fn say(args: &ReproduceOptions, line: String) {
    if !args.quiet {
        log::info!("[reproduce] {line}");
    }
}

/// `--threads` and `--jobs` are counts: at least 1 when given.
fn check_counts(args: &ReproduceOptions) -> Result<()> {
    if args.threads == Some(0) {
        bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
    }
    if args.jobs == Some(0) {
        bail!("invalid value for `--jobs`: 0 (allowed: an integer >= 1)");
    }
    Ok(())
}

/// `--out` (default `reports/<tier>`) and `--runs` (default `runs/reproduce/<tier>`).
fn report_and_runs_dirs(args: &ReproduceOptions) -> (PathBuf, PathBuf) {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("reports").join(&args.tier));
    let runs = args
        .runs
        .clone()
        .unwrap_or_else(|| Path::new("runs").join("reproduce").join(&args.tier));
    (out, runs)
}

/// The report of `--previous DIR`, when given.
fn load_previous(args: &ReproduceOptions) -> Result<Option<Reproduction>> {
    args.previous
        .as_ref()
        .map(|d| {
            Reproduction::load(&d.join("reproduce.json"))
                .with_context(|| format!("--previous {}", d.display()))
        })
        .transpose()
}

/// This tier's estimate and, when `[estimate]` names another tier, that tier's (planned only).
fn estimates(args: &ReproduceOptions, config: &Config, plans: &Plans) -> Result<Vec<Estimate>> {
    let mut estimates = Vec::new();
    if let Some(e) = &config.estimate {
        estimates.push(estimate(plans, &args.tier, e)?);
        if let Some(other) = e.tier.as_ref().filter(|t| **t != args.tier) {
            say(args, format!("estimating tier `{other}` (planning only)"));
            let p = build_plans(config, other)?;
            estimates.push(estimate(&p, other, e)?);
        }
    }
    Ok(estimates)
}

/// `--dry-run`: prints the estimates and returns a report with every figure pending.
fn dry_run(
    args: &ReproduceOptions,
    tier: &TierConfig,
    estimates: Vec<Estimate>,
    n_runs: usize,
    t0: Instant,
) -> Reproduction {
    for e in &estimates {
        print_estimate(e);
    }
    if estimates.is_empty() {
        log::info!(target: hvi_run::STDOUT, "{n_runs} runs planned (the config has no [estimate] to time them)");
    }
    Reproduction {
        wall_seconds: t0.elapsed().as_secs_f64(),
        ..new_report(args, tier, estimates)
    }
}

/// A report of this tier with every figure pending, no stage run and no notes.
fn new_report(
    args: &ReproduceOptions,
    tier: &TierConfig,
    estimates: Vec<Estimate>,
) -> Reproduction {
    Reproduction {
        tier: args.tier.clone(),
        tier_description: tier.description.clone(),
        config: args.config.display().to_string(),
        version: env!("CARGO_PKG_VERSION").into(),
        machine: Machine::detect(),
        complete: false,
        figures: pending_figures(),
        stages: Vec::new(),
        wall_seconds: 0.0,
        estimates,
        notes: Vec::new(),
        changes: None,
    }
}

/// Every figure, pending, in the paper's order.
fn pending_figures() -> Vec<Figure> {
    vec![
        stages::fig3_pending(),
        stages::fig4_pending(),
        stages::fig5_pending(),
        stages::fig7_pending(),
        stages::fig9_pending(),
        stages::fig10_pending(),
        stages::fig11_pending(),
        stages::fig13_pending(),
        stages::fig16_pending(),
        stages::fig17_pending(),
    ]
}

/// The model decisions every figure depends on, and where the runs are kept.
fn model_notes(plans: &Plans, runs: &Path) -> Vec<String> {
    let contact = plans
        .calibration
        .runs
        .first()
        .map_or("?", |r| r.scene.material.contact.name());
    vec![
        format!(
            "Contact form `{contact}` (eq. 3 with the prefactor as printed is the default; \
             docs/model.md section 3); eps and kappa are the paper's values at \
             \u{3c3}_ref = {:.4} mm and are sized to each run's \u{3c3} (eq. 12).",
            paper::reference_sigma_m() * 1e3
        ),
        format!(
            "Runs are kept by fingerprint under `{}` (one study store per stage): running the \
             command again simulates only what is missing.",
            runs.display()
        ),
    ]
}

fn print_estimate(e: &Estimate) {
    log::info!(target: hvi_run::STDOUT,
        "tier `{}` on {} cores at {} particles x base steps per second:",
        e.tier,
        e.cores,
        report::fmt_num(e.particle_steps_per_second)
    );
    for r in &e.rows {
        log::info!(target: hvi_run::STDOUT,
            "  {:<15} Fig. {:<10} {:>3} runs, {:>7}-{:<7} particles, {:>10} particles x base steps, {}",
            r.stage,
            r.figures,
            r.runs,
            r.particles.0,
            r.particles.1,
            report::fmt_num(r.particle_steps),
            fmt_duration(r.seconds)
        );
    }
    log::info!(target: hvi_run::STDOUT,
        "  total: {} particles x base steps, expected {}",
        report::fmt_num(e.particle_steps()),
        fmt_duration(e.seconds())
    );
    if !e.source.is_empty() {
        log::info!(target: hvi_run::STDOUT, "  rate from: {}", e.source);
        log::info!(target: hvi_run::STDOUT, "  one machine's rate: on another CPU the time differs (docs/reproduction.md)");
    }
}

/// The calibration study's targets (experiments_data): Figs. 11-12 score the best fit
/// against them, and their gaps say what Fig. 13 cannot compare.
fn calibration_targets(plans: &Plans) -> Result<Targets> {
    let study = Study::load(&plans.calibration_study)?;
    let cfg = hvi_calibrate::CalibrateConfig::of(&study)?;
    cfg.load_targets(&study)
}

/// experiments_data's note on Fig. 13's experimental points, if it records one.
fn fig13_gap(targets: &Targets) -> Option<String> {
    targets
        .gaps
        .iter()
        .find(|g| g.name.contains("fig13"))
        .map(|g| format!("{}: {}", g.source, g.note))
}

fn stage_context(args: &ReproduceOptions, out: &Path, runs: &Path) -> Ctx {
    Ctx {
        out: out.to_path_buf(),
        runs: runs.to_path_buf(),
        exec: ExecOptions {
            threads: args.threads.unwrap_or(0),
            jobs: args.jobs,
            progress: !args.quiet,
            ..ExecOptions::default()
        },
        threads: args.threads,
        jobs: args.jobs,
        quiet: args.quiet,
    }
}

/// The stages in the order they run.
#[derive(Debug, Clone, Copy)]
enum Stage {
    Potentials,
    Sizing,
    Convergence,
    Calibration,
    FrontVelocity,
    ValidityMap,
}

impl Stage {
    const ALL: [Stage; 6] = [
        Stage::Potentials,
        Stage::Sizing,
        Stage::Convergence,
        Stage::Calibration,
        Stage::FrontVelocity,
        Stage::ValidityMap,
    ];

    /// As the progress lines name it.
    fn name(self) -> &'static str {
        match self {
            Stage::Potentials => "Fig. 3: the pair laws (no runs)",
            Stage::Sizing => "Fig. 4: sizing",
            Stage::Convergence => "Fig. 5 and Figs. 11-12: convergence and the best fit",
            Stage::Calibration => "Figs. 7, 9, 10: the calibration grid",
            Stage::FrontVelocity => "Fig. 13: va/v0 against t/D",
            Stage::ValidityMap => "Figs. 16, 17: the validity map",
        }
    }

    /// The figures it makes (they fail with it).
    fn figures(self) -> &'static [&'static str] {
        match self {
            Stage::Potentials => &["3"],
            Stage::Sizing => &["4"],
            Stage::Convergence => &["5", "11-12"],
            Stage::Calibration => &["7", "9", "10"],
            Stage::FrontVelocity => &["13"],
            Stage::ValidityMap => &["16", "17"],
        }
    }
}

/// What the stages take besides the report.
struct StageInputs<'a> {
    ctx: Ctx,
    plans: &'a Plans,
    tier: &'a TierConfig,
    targets: Targets,
    fig13_gap: Option<String>,
}

fn run_stage(stage: Stage, s: &StageInputs) -> Result<(Vec<Figure>, StageTiming)> {
    let (ctx, plans) = (&s.ctx, s.plans);
    match stage {
        Stage::Potentials => {
            let t = Instant::now();
            let figures = stages::fig3(ctx)?;
            let timing = StageTiming {
                stage: "potentials".into(),
                figures: "3".into(),
                runs: 0,
                ran: 0,
                cached: 0,
                failed: 0,
                wall_seconds: t.elapsed().as_secs_f64(),
            };
            Ok((figures, timing))
        }
        Stage::Sizing => stages::fig4(ctx, &plans.sizing),
        Stage::Convergence => stages::fig5_11_12(ctx, &plans.convergence, &s.targets),
        Stage::Calibration => stages::fig7_9_10(
            ctx,
            &plans.calibration_study,
            &s.tier.calibration,
            &plans.calibration,
        ),
        Stage::FrontVelocity => stages::fig13(ctx, &plans.front_velocity, s.fig13_gap.clone()),
        Stage::ValidityMap => stages::fig16_17(
            ctx,
            &plans.validity_study,
            &s.tier.validity,
            &plans.validity,
            &s.targets.targets,
        ),
    }
}

/// Runs every stage in order, rewriting the report after each; a failed stage fails its
/// figures and the others go on. Returns the failures.
fn run_stages(
    args: &ReproduceOptions,
    inputs: &StageInputs,
    rep: &mut Reproduction,
    out: &Path,
    t0: Instant,
) -> Result<Vec<String>> {
    let n_stages = Stage::ALL.len();
    let mut errors = Vec::new();
    for (k, stage) in Stage::ALL.into_iter().enumerate() {
        let ts = Instant::now();
        let name = stage.name();
        say(args, format!("stage {}/{n_stages}: {name}", k + 1));
        match run_stage(stage, inputs) {
            Ok((figures, timing)) => {
                for f in figures {
                    say(
                        args,
                        format!("Fig. {}: {} ({})", f.id, f.verdict.word(), f.reason),
                    );
                    if let Some(slot) = rep.figures.iter_mut().find(|g| g.id == f.id) {
                        *slot = f;
                    }
                }
                rep.stages.push(timing);
            }
            Err(e) => {
                say(args, format!("stage {name} failed: {e:#}"));
                fail_figures(rep, stage.figures(), &e);
                errors.push(format!("stage {name} failed: {e:#}"));
            }
        }
        say(
            args,
            format!(
                "stage {}/{n_stages} done in {}",
                k + 1,
                fmt_duration(ts.elapsed().as_secs_f64())
            ),
        );
        rep.wall_seconds = t0.elapsed().as_secs_f64();
        rep.write(out)?;
    }
    Ok(errors)
}

/// Marks a failed stage's figures `not reproduced`, with the error as the reason.
fn fail_figures(rep: &mut Reproduction, ids: &[&str], e: &hvi_run::error::RunError) {
    for id in ids {
        if let Some(slot) = rep.figures.iter_mut().find(|g| g.id == *id) {
            slot.verdict = Verdict::Not;
            slot.ours = "the stage failed".into();
            slot.reason = format!("the stage failed: {e:#}");
        }
    }
}

/// Completes the report (the changes since `--previous`), writes it, and fails when a stage
/// failed or, with `--fail-on-change`, when a verdict or deciding number changed.
fn finish(
    args: &ReproduceOptions,
    mut rep: Reproduction,
    previous: Option<&Reproduction>,
    out: &Path,
    t0: Instant,
    mut errors: Vec<String>,
    commit: String,
) -> Result<Reproduction> {
    rep.complete = errors.is_empty();
    rep.wall_seconds = t0.elapsed().as_secs_f64();
    rep.changes = previous.map(|p| report::diff(p, &rep));
    rep.write(out)?;
    let history_path = args
        .history
        .clone()
        .unwrap_or_else(|| out.join(history::HISTORY_FILE));
    let record = history::Record::of(&rep, commit, history::now_utc());
    let history = history::History::append(&history_path, &record)?;
    for (line, why) in &history.damaged {
        log::warn!("warning: {} line {line} is not a history record and is skipped (kept in the file): {why}",
            history_path.display()
        );
    }
    page::write_page(out, &rep, &history)?;
    say(
        args,
        format!(
            "history: {} run(s) of tier `{}` in {}; page: {}",
            history.of_tier(&rep.tier).count(),
            rep.tier,
            history_path.display(),
            out.join(page::PAGE_FILE).display()
        ),
    );
    say(
        args,
        format!(
            "done in {}: {}",
            fmt_duration(rep.wall_seconds),
            rep.figures
                .iter()
                .map(|f| format!("Fig. {} {}", f.id, f.verdict.word()))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    );
    log::info!(target: hvi_run::STDOUT, "{}", out.join("report.md").display());
    if let (true, Some(changes)) = (args.fail_on_change, &rep.changes) {
        if !changes.is_empty() {
            errors.push(format!(
                "{} verdict(s) or deciding number(s) changed since {} (--fail-on-change):\n    {}",
                changes.len(),
                args.previous
                    .as_deref()
                    .map_or("the previous report".into(), |p| p.display().to_string()),
                changes.join("\n    ")
            ));
        }
    }
    if !errors.is_empty() {
        bail!("{}", errors.join("\n"));
    }
    Ok(rep)
}
