//! What the stages share: the context (where things go, how to execute), running a study
//! through its store, and the small readings of a plan's runs the stages all make.

use std::path::{Path, PathBuf};
use std::time::Instant;

use hvi_analysis::observable::Observable;
use hvi_analysis::score::Target;
use hvi_run::error::{Result, ResultExt, RunError};

use crate::report::StageTiming;
use hvi_run::output::write_atomic_bytes;
use hvi_store::exec::ExecOptions;
use hvi_store::plan::Plan;
use hvi_store::store::{Record, RunStatus, Store};
use hvi_store::study::execute_plan;
use hvi_studies::options::StudyOptions;

/// What the stages share: where things go and how to execute.
#[derive(Debug, Clone)]
pub struct Ctx {
    /// The report directory.
    pub out: PathBuf,
    /// The runs' root (one study directory per stage below it).
    pub runs: PathBuf,
    /// How to execute runs.
    pub exec: ExecOptions,
    /// `--threads`.
    pub threads: Option<usize>,
    /// `--jobs`.
    pub jobs: Option<usize>,
    /// No progress output.
    pub quiet: bool,
}

impl Ctx {
    /// Copies a file into the report directory under `name`; returns the name, or None when
    /// the source does not exist (a failed run has no pictures).
    pub(super) fn collect(&self, from: &Path, name: &str) -> Result<Option<String>> {
        if !from.exists() {
            return Ok(None);
        }
        let bytes =
            std::fs::read(from).with_context(|| format!("cannot read {}", from.display()))?;
        write_atomic_bytes(&self.out.join(name), &bytes)?;
        Ok(Some(name.to_string()))
    }

    /// Copies each `(from, name)` that exists into the report directory; the names copied.
    pub(super) fn collect_all(&self, files: &[(PathBuf, &str)]) -> Result<Vec<String>> {
        let mut names = Vec::new();
        for (from, name) in files {
            if let Some(n) = self.collect(from, name)? {
                names.push(n);
            }
        }
        Ok(names)
    }

    /// The plain options of a stage's study: the reproduction's tier for it, its store
    /// `dir`, the reproduction's threads.
    pub(super) fn study_options(
        &self,
        study: &Path,
        r: &crate::config::StudyRef,
        dir: &Path,
    ) -> StudyOptions {
        StudyOptions {
            tier: Some(r.tier.clone()),
            particles: r.particles,
            sets: r.set.clone(),
            out: Some(dir.to_path_buf()),
            threads: self.threads,
            jobs: self.jobs,
            quiet: self.quiet,
            ..StudyOptions::new(study)
        }
    }
}

/// A stage's plan after it ran: its study directory, the runs the store held finished before,
/// and one record per run in plan order.
pub(super) struct Executed {
    pub(super) dir: PathBuf,
    pub(super) cached: usize,
    pub(super) records: Vec<Record>,
}

impl Executed {
    /// The stage's timing row, from `t0` (the stage's start) to now.
    pub(super) fn timing(
        &self,
        stage: &str,
        figures: &str,
        plan: &Plan,
        t0: Instant,
    ) -> StageTiming {
        timing(stage, figures, plan, self.cached, &self.records, t0)
    }
}

/// Runs a plan through its study store below `ctx.runs` (finished runs are reused).
pub(super) fn execute(ctx: &Ctx, plan: &Plan) -> Result<Executed> {
    let dir = ctx.runs.join(&plan.study);
    plan.write(&dir)?;
    let (_, report) = execute_plan(plan, &dir, &ctx.exec)?;
    Ok(Executed {
        dir,
        cached: report.cached,
        records: report.records,
    })
}

/// The records of every run of a plan executed in `dir`.
pub fn plan_records(plan: &Plan, dir: &Path) -> Result<Vec<Record>> {
    let store = Store::open(dir)?;
    plan.runs
        .iter()
        .map(|r| {
            store.record(&r.fingerprint)?.ok_or_else(|| {
                RunError::Input(format!(
                    "run {} of `{}` has no record in {}",
                    r.index,
                    plan.study,
                    dir.display()
                ))
            })
        })
        .collect()
}

/// How many of a plan's runs the store in `dir` holds completed (0, creating nothing, when
/// it has no store yet).
pub fn completed_runs(plan: &Plan, dir: &Path) -> Result<usize> {
    if !dir.join("runs").is_dir() {
        return Ok(0);
    }
    let store = Store::open(dir)?;
    let mut n = 0;
    for r in &plan.runs {
        if matches!(store.record(&r.fingerprint)?, Some(rec) if rec.status == RunStatus::Completed)
        {
            n += 1;
        }
    }
    Ok(n)
}

pub(super) fn timing(
    stage: &str,
    figures: &str,
    plan: &Plan,
    cached: usize,
    records: &[Record],
    t0: Instant,
) -> StageTiming {
    StageTiming {
        stage: stage.into(),
        figures: figures.into(),
        runs: plan.runs.len(),
        ran: plan.runs.len() - cached,
        cached,
        failed: records
            .iter()
            .filter(|r| r.status == RunStatus::Failed)
            .count(),
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

/// The index of `v` in sorted axis values (relative tolerance 1e-9).
pub(super) fn index_of(axis: &[f64], v: f64) -> Option<usize> {
    axis.iter()
        .position(|&a| (a - v).abs() <= 1e-9 * v.abs().max(a.abs()))
}

/// The axis of a plan with that key.
pub(super) fn axis(plan: &Plan, key: &str) -> Result<usize> {
    plan.axes.iter().position(|a| a.key == key).ok_or_else(|| {
        RunError::Input(format!(
            "study `{}` has no axis `{key}` (the figure is drawn over it)",
            plan.study
        ))
    })
}

/// The largest-fragment fraction above which a run keeps "a large central fragment": the
/// calibration shot's `at_most` bound on the largest fragment (experiments_data; None when its
/// targets have none). Figs. 7 and 16 both judge fragments by it.
pub(super) fn largest_fragment_bound(targets: &[Target]) -> Option<f64> {
    targets
        .iter()
        .find(|t| t.observable == Observable::LargestFragmentMassFraction)
        .map(|t| t.value)
}

/// Whether a run's largest fragment (fraction of the impactor mass) is a large central
/// fragment: above `bound`, as the calibration target scores it; a missing value counts as
/// large (nothing shows it is not).
pub(super) fn keeps_large_fragment(largest: f64, bound: f64) -> bool {
    largest.is_nan() || largest > bound
}

/// The mean of the finite values, None when there is none.
pub(super) fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}
