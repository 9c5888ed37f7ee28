//! Where a batch of runs executes: on this machine's cores ([`crate::exec::execute`]), or on a
//! Slurm cluster as one job array that this process waits for ([`Runner::Slurm`]). Either way
//! the results land in the study's run store, so a batch interrupted on one side resumes on
//! either, and a run is never done twice: a finished run is reused, a run Slurm is already
//! running (an earlier submission of a process that was stopped) is waited for, not submitted
//! again.
//!
//! A batch submitted to Slurm is a plan of its own (`slurm/submission-NNN/plan.json`): one
//! run per job, with the jobs' parameters as its axes; the study's `plan.json` is not
//! touched. `hvi-study status` lists the batches' jobs with the study's other submissions.

use std::collections::{BTreeMap, HashSet};
use std::path::Path;
use std::time::{Duration, Instant};

use crate::exec::{execute, ExecOptions, ExecReport};
use crate::plan::{run_dir_name, Plan, PlannedRun, STUDY_FORMAT_VERSION};
use crate::slurm::{submit_batch, QueueView, SlurmOptions, TaskState};
use crate::spec::Axis;
use crate::store::{Job, Record, RunStatus, Store};
use hvi_run::error::{Result, RunError};

/// How a batch of runs is executed.
#[derive(Debug, Clone)]
pub enum Runner {
    /// Here, in parallel on this machine's cores.
    Local(ExecOptions),
    /// On Slurm: one job array per batch, waited for.
    Slurm(SlurmBatches),
}

/// Batches as Slurm job arrays.
#[derive(Debug, Clone)]
pub struct SlurmBatches {
    /// The job arrays' options (`dry_run` is not used: a batch is submitted or not at all).
    pub options: SlurmOptions,
    /// How often the queue is asked while waiting.
    pub poll: Duration,
    /// Progress lines on stderr.
    pub progress: bool,
}

/// The shortest poll interval, s (squeue asks the controller; a busy cluster's admins would
/// not thank a tighter loop).
pub const MIN_POLL_S: f64 = 0.2;
/// The longest poll interval, s.
pub const MAX_POLL_S: f64 = 3600.0;

impl SlurmBatches {
    /// Checks the options and the poll interval.
    pub fn new(options: SlurmOptions, poll_s: f64, progress: bool) -> Result<SlurmBatches> {
        options.validate()?;
        if options.dry_run {
            return Err(RunError::Input("`--dry-run` does not combine with `--slurm` here: a batch is submitted when the search reaches it (`hvi-study submit --dry-run` prints a study's job script)".into()));
        }
        if !(MIN_POLL_S..=MAX_POLL_S).contains(&poll_s) || !poll_s.is_finite() {
            return Err(RunError::Input(format!("invalid value for `--poll`: {poll_s} (allowed: {MIN_POLL_S} to {MAX_POLL_S} seconds)")));
        }
        Ok(SlurmBatches {
            options,
            poll: Duration::from_secs_f64(poll_s),
            progress,
        })
    }
}

impl Runner {
    /// The store of the study directory `out` for this runner's runs: locally, they write
    /// checkpoints as its options say (a Slurm task's run follows its job script).
    pub fn store(&self, out: &Path) -> Result<Store> {
        let store = Store::open(out)?;
        Ok(match self {
            Runner::Local(o) => store.with_checkpoint_every(o.checkpoint_every),
            Runner::Slurm(_) => store,
        })
    }

    /// Executes `jobs` into `store` (the store of the study directory `out`), labelling each
    /// with `describe` in progress lines. `template` is the study's plan: a Slurm batch's plan
    /// takes its study, tier and files from it. `who` names the batch in the job script.
    pub fn execute(
        &self,
        store: &Store,
        out: &Path,
        template: &Plan,
        jobs: &[Job],
        describe: &(dyn Fn(usize) -> String + Sync),
        who: &str,
    ) -> Result<ExecReport> {
        match self {
            Runner::Local(opts) => execute(store, jobs, describe, opts),
            Runner::Slurm(s) => s.execute(store, out, template, jobs, who),
        }
    }
}

impl SlurmBatches {
    fn execute(
        &self,
        store: &Store,
        out: &Path,
        template: &Plan,
        jobs: &[Job],
        who: &str,
    ) -> Result<ExecReport> {
        let t0 = Instant::now();
        let plan = batch_plan(template, jobs);
        // The batch's distinct runs finished before it (each once, however often the jobs
        // name it).
        let mut done_before = HashSet::new();
        for r in &plan.runs {
            if matches!(store.record(&r.fingerprint)?, Some(rec) if rec.is_final()) {
                done_before.insert(r.fingerprint.as_str());
            }
        }
        let cached = jobs
            .iter()
            .filter(|j| done_before.contains(j.fingerprint.as_str()))
            .count();
        let needed = plan.runs.len() - done_before.len();
        let mut opts = self.options.clone();
        opts.quiet = !self.progress;
        let (job_id, earlier) = submit_batch(&plan, out, &opts, who)?;
        if self.progress && !earlier.is_empty() {
            log::info!(
                "{who}: waiting for runs an earlier submission is running (job {})",
                earlier.join(", ")
            );
        }
        let queue = self.wait(store, out, &plan, who)?;
        let mut records = Vec::with_capacity(jobs.len());
        let mut failed = 0;
        for j in jobs {
            let rec = match store.record(&j.fingerprint)? {
                Some(r) => r,
                None => no_result(j, &queue),
            };
            if rec.status == RunStatus::Failed {
                failed += 1;
            }
            records.push(rec);
        }
        // Runs finished now: by this batch's array, or by an earlier submission's.
        let finished = needed.saturating_sub(failed);
        let (ran, elsewhere) = if job_id.is_some() {
            (finished, 0)
        } else {
            (0, finished)
        };
        // The array's tasks measure runs from kept states as a local execution does: of the
        // runs finished now, those measured (each once).
        let measured = if job_id.is_some() {
            let now: HashSet<&str> = jobs
                .iter()
                .zip(&records)
                .filter(|(j, r)| {
                    r.measured_from.is_some() && !done_before.contains(j.fingerprint.as_str())
                })
                .map(|(j, _)| j.fingerprint.as_str())
                .collect();
            now.len().min(ran)
        } else {
            0
        };
        let ran = ran - measured;
        Ok(ExecReport {
            records,
            ran,
            measured,
            cached,
            elsewhere,
            failed,
            wall_seconds: t0.elapsed().as_secs_f64(),
        })
    }

    /// Waits until none of the plan's runs is queued or running; prints a line whenever the
    /// counts change. Returns the queue as last seen (for the logs of runs with no result).
    fn wait(&self, store: &Store, out: &Path, plan: &Plan, who: &str) -> Result<QueueView> {
        let mut last = None;
        loop {
            hvi_run::interrupt::check()?;
            let queue = QueueView::of(out)?;
            if !queue.known && !queue.submissions.is_empty() {
                return Err(RunError::External(format!(
                    "cannot follow the Slurm jobs of {}: {}; the submitted runs go on, and the same command picks up their results",
                    out.display(),
                    queue.note.as_deref().unwrap_or("squeue gave no answer")
                )));
            }
            let (mut running, mut queued, mut done) = (0, 0, 0);
            for r in &plan.runs {
                match queue.active.get(&r.fingerprint).map(|t| t.state) {
                    Some(TaskState::Running) => running += 1,
                    Some(TaskState::Queued) => queued += 1,
                    None => {
                        if store.record(&r.fingerprint)?.is_some() {
                            done += 1;
                        }
                    }
                }
            }
            if self.progress && last != Some((done, running, queued)) {
                log::info!(
                    "{who}: {done} of {} runs done, {running} running, {queued} queued on Slurm",
                    plan.runs.len()
                );
            }
            last = Some((done, running, queued));
            if running + queued == 0 {
                return Ok(queue);
            }
            std::thread::sleep(self.poll);
        }
    }
}

/// The record of a run whose Slurm task ended without leaving one (killed at its time
/// limit, its node lost, the binary missing): a failed run, with where to look.
fn no_result(job: &Job, queue: &QueueView) -> Record {
    let why = match queue.ended_task(&job.fingerprint) {
        Some((id, task, log)) => format!(
            "its Slurm task (job {id}, task {task}) ended without a result: see {}",
            log.display()
        ),
        None => "it has no result and Slurm is not running it".to_string(),
    };
    // Not run here: no time, no threads; it may end otherwise when submitted again.
    let failure = crate::store::Failure {
        message: why,
        reproducible: false,
    };
    Record::of(job, Some(failure), Default::default(), 0.0, 0)
}

/// A plan of these jobs (each run once, in order): the study's `template` with the jobs'
/// parameter keys as its axes (a job without a key has `null` there).
pub fn batch_plan(template: &Plan, jobs: &[Job]) -> Plan {
    let mut keys: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for j in jobs {
        for (k, v) in &j.params {
            let values = keys.entry(k.clone()).or_default();
            if !values.contains(v) {
                values.push(v.clone());
            }
        }
    }
    let axes: Vec<Axis> = keys
        .iter()
        .map(|(k, values)| Axis {
            key: k.clone(),
            values: values.clone(),
            label: k.clone(),
        })
        .collect();
    let mut runs: Vec<PlannedRun> = Vec::new();
    for j in jobs {
        if runs.iter().any(|r| r.fingerprint == j.fingerprint) {
            continue;
        }
        let values: Vec<serde_json::Value> = axes
            .iter()
            .map(|a| j.params.get(&a.key).cloned().unwrap_or_default())
            .collect();
        let coords = axes
            .iter()
            .zip(&values)
            .map(|(a, v)| a.values.iter().position(|x| x == v).unwrap_or(0))
            .collect();
        runs.push(PlannedRun {
            index: runs.len(),
            coords,
            set: j.params.iter().map(|(k, v)| format!("{k}={v}")).collect(),
            fingerprint: j.fingerprint.clone(),
            dir: run_dir_name(&j.fingerprint),
            scene: j.scene.clone(),
            values,
        });
    }
    Plan {
        format: STUDY_FORMAT_VERSION,
        axes,
        runs,
        ..template.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::ENGINE_VERSION;

    fn job(fp: &str, params: serde_json::Value) -> Job {
        let scene = hvi_run::scene_file::parse_scene(
            "[scene]\nkind = \"sphere_on_plate\"\ndiameter_m = 1e-2\nt_over_d = 0.4\nv0_m_s = 6000\n[resolution]\nparticles = 500\n[material]\n",
            &[],
        )
        .expect("scene");
        Job {
            fingerprint: fp.into(),
            scene,
            study: "s".into(),
            tier: "quick".into(),
            params: params.as_object().expect("object").clone(),
        }
    }

    #[test]
    fn a_batch_plan_has_each_run_once_with_its_parameters_as_axes() {
        let jobs = [
            job(
                "a",
                serde_json::json!({"material.eps_j": 0.1, "run.seed": 1}),
            ),
            job(
                "b",
                serde_json::json!({"material.eps_j": 0.1, "run.seed": 2}),
            ),
            job(
                "a",
                serde_json::json!({"material.eps_j": 0.1, "run.seed": 1}),
            ),
            job("c", serde_json::json!({"material.eps_j": 0.3})),
        ];
        let template = Plan {
            format: STUDY_FORMAT_VERSION,
            study: "s".into(),
            description: String::new(),
            study_file: "s.toml".into(),
            base_scene: "b.toml".into(),
            tier: "quick".into(),
            tier_description: String::new(),
            set: vec![],
            axes: vec![],
            engine_version: ENGINE_VERSION.into(),
            runs: vec![],
        };
        let p = batch_plan(&template, &jobs);
        assert_eq!(p.runs.len(), 3);
        let keys: Vec<&str> = p.axes.iter().map(|a| a.key.as_str()).collect();
        assert_eq!(keys, ["material.eps_j", "run.seed"]);
        assert_eq!(p.axes[0].values.len(), 2, "eps 0.1 and 0.3, each once");
        assert_eq!(p.runs[1].values[1], serde_json::json!(2));
        assert_eq!(p.runs[2].values[1], serde_json::Value::Null);
        assert_eq!(
            p.runs.iter().map(|r| r.index).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        // run-unit builds the same job back from the batch plan.
        let back = crate::study::job(&p, 1).expect("job");
        assert_eq!(back.fingerprint, "b");
        assert_eq!(back.params.get("run.seed"), Some(&serde_json::json!(2)));
    }
}
