//! `hvi-study plan`, `sweep` and `run-unit`: a study planned, run whole, or one of its runs
//! executed for an external scheduler; a plan's resolution warnings printed.

use crate::options::StudyOptions;
use hvi_run::error::Result;

use hvi_store::plan::Plan;
use hvi_store::spec::Study;
use hvi_store::store::{RunStatus, Store};
use hvi_store::study::{execute_plan, job};

/// `hvi-study plan`: validates a study and writes its plan.json without running anything.
pub fn plan(args: &StudyOptions) -> Result<()> {
    let (study, plan, out) = args.plan()?;
    print_resolution_warnings(&study, &plan)?;
    let store = Store::open(&out)?;
    let mut done = 0;
    for r in &plan.runs {
        if matches!(store.record(&r.fingerprint)?, Some(rec) if rec.status == RunStatus::Completed)
        {
            done += 1;
        }
    }
    log::info!(target: hvi_run::STDOUT,
        "study `{}` at tier `{}`: {} runs ({} already done); axes: {}",
        plan.study,
        plan.tier,
        plan.runs.len(),
        done,
        plan.axes
            .iter()
            .map(|a| match a.values.len() {
                1 => format!("{} (1 value)", a.key),
                n => format!("{} ({n} values)", a.key),
            })
            .collect::<Vec<_>>()
            .join(" x ")
    );
    log::info!(target: hvi_run::STDOUT, "{}", out.join("plan.json").display());
    Ok(())
}

/// `hvi-study sweep`: plans and executes every run of a study, writes results.csv/json.
pub fn sweep(args: &StudyOptions) -> Result<()> {
    let (study, plan, out) = args.plan()?;
    print_resolution_warnings(&study, &plan)?;
    let (_, report) = execute_plan(&plan, &out, &args.exec_options())?;
    log::info!("{}", report.line());
    print_failures(&report.records);
    log::info!(target: hvi_run::STDOUT, "{}", out.join("results.csv").display());
    Ok(())
}

/// Prints each distinct resolution warning of a plan once, with the runs it concerns
/// (docs/running.md, "Resolution"), as `warning: ...` on stderr.
pub fn print_resolution_warnings(study: &Study, plan: &Plan) -> Result<()> {
    for w in hvi_store::resolution::plan_warnings(study, plan)? {
        log::warn!("warning: {}", w.line(plan));
    }
    Ok(())
}

/// Prints each failed run's error (a failed run does not fail the study).
pub fn print_failures(records: &[hvi_store::store::Record]) {
    for (i, r) in records.iter().enumerate() {
        if r.status == RunStatus::Failed {
            log::info!(
                "run {i} failed: {}{}",
                r.error.as_deref().unwrap_or("(no message)"),
                if r.reproducible {
                    " (the engine fails this scene the same way every time: kept, not run \
                     again; remove its directory to run it again)"
                } else {
                    " (runs again when the study is run again)"
                }
            );
        }
    }
}

/// `hvi-study run-unit PLAN INDEX`: executes one run of a written plan (for an external
/// scheduler). A finished run is not repeated. The result goes into the run store of
/// `study_dir`, by default the plan's directory. Returns whether the run completed.
pub fn run_unit(
    plan_path: &std::path::Path,
    index: usize,
    threads: Option<usize>,
    study_dir: Option<&std::path::Path>,
    checkpoint_every: hvi_run::checkpoint::Every,
) -> Result<bool> {
    if threads == Some(0) {
        hvi_run::bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
    }
    let plan = Plan::load(plan_path)?;
    let dir = study_dir.unwrap_or_else(|| {
        plan_path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or_else(|| std::path::Path::new("."))
    });
    let job = job(&plan, index)?;
    let store = Store::open(dir)?.with_checkpoint_every(checkpoint_every);
    let record = match store.record(&job.fingerprint)? {
        Some(r) if r.is_final() => {
            log::info!("run {index}: already done");
            r
        }
        _ => {
            let threads = threads
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            let r = store.execute(&job, threads)?;
            if store.done_elsewhere() > 0 {
                log::info!("run {index}: done by another process meanwhile; its result is kept");
            }
            r
        }
    };
    let dir = store.dir(&job.fingerprint);
    match record.status {
        RunStatus::Completed => {
            log::info!(target: hvi_run::STDOUT, "{}", dir.display());
            Ok(true)
        }
        RunStatus::Failed => {
            log::info!(
                "run {index} failed: {}",
                record.error.as_deref().unwrap_or("(no message)")
            );
            log::info!(target: hvi_run::STDOUT, "{}", dir.display());
            Ok(false)
        }
    }
}
